"""The postprocess stage: the paper's values in its config, and a start without torch."""

from __future__ import annotations

import subprocess
import sys
from dataclasses import replace

from helpers import PAPER_POSTPROCESSING as PAPER

from offroad_path.inference.path_filter import PostprocessParams


def test_the_config_holds_the_papers_values(compose_config):
    paper = PostprocessParams.from_config(compose_config("experiment=paper").postprocess)
    assert replace(paper, blur_scale=1) == PAPER and paper.blur_scale == 2  # the blur at half resolution, bounded below
    laptop = compose_config()  # the paper's sigma in pixels of its 512-pixel-wide images, at the laptop world's width
    assert PostprocessParams.from_config(laptop.postprocess) == replace(paper, sigma=6.0 * laptop.world.width / 512)


def test_the_postprocess_stage_starts_without_torch():
    # Six postprocess stages run in the laptop pipeline; torch's and albumentations' imports were
    # about 3 of each one's 4.8 s (benchmarks/README.md). The file readers live in data/loading.py for this.
    check = "import sys, offroad_path.postprocess; print(sorted({'torch', 'albumentations', 'lightning'} & set(sys.modules)))"
    run = subprocess.run([sys.executable, "-c", check], capture_output=True, text=True, check=True)
    assert run.stdout.strip() == "[]"
