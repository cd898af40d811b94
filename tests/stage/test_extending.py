"""docs/extending.md's recipes, each done with a stand-in and run: a score is one entry in
statistics/scores.py (tests/models/test_architectures.py does the same for a network)."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from helpers import evaluate_config, write_run

from offroad_path.data.loading import load_labels
from offroad_path.data.manifest import read_manifest
from offroad_path.evaluate import evaluate
from offroad_path.statistics import scores
from offroad_path.statistics.scores import FN, FP, TP, ratio


def dice(c):
    """A stand-in fifth score: the Dice coefficient (F1), 2 tp / (2 tp + fp + fn)."""
    return ratio(2 * c[..., TP], 2 * c[..., TP] + c[..., FP] + c[..., FN])


@pytest.mark.slow(seconds=5)
def test_a_score_added_to_the_registry_reaches_every_table_and_metrics_file(compose_config, split_dir, tmp_path, monkeypatch):
    monkeypatch.setitem(scores.SCORES, "dice", dice)
    monkeypatch.setitem(scores.TITLES, "dice", "Dice")
    labels = load_labels(read_manifest(split_dir / "test.csv")).astype(np.float32)
    shifted = 0.9 * np.roll(labels, 24, axis=2)
    write_run(compose_config, split_dir, tmp_path, "unet-none", 0, shifted)
    rows = evaluate(evaluate_config(compose_config, split_dir, tmp_path, "evaluate.runs=[unet-none]", "evaluate.bootstrap.resamples=200"))

    # The pooled counts of the shifted maps, by hand: Dice is 2 IoU / (1 + IoU) of the same counts.
    iou = rows[0]["iou"]
    assert rows[0]["dice"] == pytest.approx(2 * iou / (1 + iou), abs=1e-9)
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert metrics["unet-none"]["raw"]["dice"] == pytest.approx(rows[0]["dice"], abs=1e-6)
    assert set(metrics["baselines"]["mean_path_prior"]) == {"accuracy", "precision", "recall", "iou", "dice"}
    interval = metrics["uncertainty"]["unet-none.raw"]["dice"]
    assert interval["low"] <= interval["estimate"] <= interval["high"]
    report = (tmp_path / "evaluation" / "results.md").read_text()
    assert "| accuracy | precision | recall | IoU [95 % interval] | Dice |" in report  # Table 5.1
    assert "| Dice [95 % interval] |" in report  # the other scores' intervals
    assert "| baseline | accuracy | precision | recall | IoU | Dice |" in report
    assert (tmp_path / "evaluation" / "results.csv").read_text().splitlines()[0].endswith(",iou,dice,mean_image_iou")


def test_a_look_value_added_to_the_names_and_the_table_is_drawn_and_rendered(compose_config, monkeypatch):
    """A world look value: its name in looks.py and its colours in world/appearance.py's table, then a weight."""
    from offroad_path.config import validate_config
    from offroad_path.looks import AXIS_VALUES
    from offroad_path.utils.rules import ConfigValueError
    from offroad_path.world.appearance import TRACKS
    from offroad_path.world.classes import DIRT
    from offroad_path.world.record import camera_for
    from offroad_path.world.render import render_view
    from offroad_path.world.scene import build_world

    sand = (0.76, 0.70, 0.50)
    only_sand = [f"world.appearance.weights.track.{name}=0.0" for name in AXIS_VALUES["track"]]
    small = ("world.width=64", "world.height=36", "world.frames=20", "world.max_distance_m=40")
    with pytest.raises(ConfigValueError, match="sand"):  # a name the renderer does not know is refused
        validate_config(compose_config(*small, *only_sand, "+world.appearance.weights.track.sand=1.0"))
    monkeypatch.setitem(AXIS_VALUES, "track", (*AXIS_VALUES["track"], "sand"))
    monkeypatch.setitem(TRACKS, "sand", {"albedo": sand, "contrast": 0.2, "ruts": None})
    cfg = compose_config(*small, *only_sand, "+world.appearance.weights.track.sand=1.0")
    validate_config(cfg)
    world = build_world(cfg.world, 3)
    assert world.look.track == "sand" and not world.look.outside
    ratio = world.palette[DIRT] / np.array(sand)
    assert np.allclose(ratio, ratio[0]) and 0.85 <= ratio[0] <= 1.15  # the table's colour, jittered in brightness only
    view = render_view(world, camera_for(cfg.world), world.poses[3], cfg.world.max_distance_m)
    assert view.image.shape == (36, 64, 3) and (view.semantic == DIRT).any()  # the sand track is in view


HELLO_STAGE = '''"""Stage `hello`: a stand-in stage (tests/stage/test_extending.py) that writes a greeting."""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig

from offroad_path.stage import hydra_stage, reads
from offroad_path.utils.outputs import Outputs


def outputs(cfg: DictConfig) -> Outputs:
    return Outputs("hello", files={"hello.out_path": cfg.hello.out_path})


@reads("hello", writes=outputs)
def hello(cfg: DictConfig) -> None:
    Path(cfg.hello.out_path).write_text(cfg.hello.greeting * cfg.hello.times + "\\n")


main = hydra_stage(hello)
'''
HELLO_SCHEMA = '''"""The stand-in stage's schema."""

from __future__ import annotations

from dataclasses import dataclass

from omegaconf import MISSING

from offroad_path.utils.rules import at_least, setting


@dataclass
class HelloConfig:
    greeting: str = MISSING
    times: int = setting(at_least(1))
    out_path: str = MISSING
'''


@pytest.mark.slow(seconds=3)
def test_a_stage_added_as_the_docs_say_runs_checks_its_settings_and_gets_its_dvc_deps(tmp_path):
    """A stage: its package (@reads in __init__.py, a __main__.py), conf group, schema, Config field, defaults line, dvc.yaml stage."""
    import shutil
    import subprocess
    import sys

    import yaml
    from helpers import ROOT

    for item in ("src", "conf", "tools", "dvc.yaml"):
        (shutil.copytree if (ROOT / item).is_dir() else shutil.copy)(ROOT / item, tmp_path / item)
    package = tmp_path / "src" / "offroad_path"
    (package / "hello").mkdir()
    (package / "hello" / "__init__.py").write_text(HELLO_STAGE)
    (package / "hello" / "__main__.py").write_text("from offroad_path.hello import main\n\nmain()\n")
    (package / "config" / "hello.py").write_text(HELLO_SCHEMA)
    init = (package / "config" / "__init__.py").read_text()
    schema = "\nfrom offroad_path.config.hello import HelloConfig\n\n\n@dataclass\nclass Config:\n"
    init = init.replace("\n\n@dataclass\nclass Config:\n", schema)
    field_line = "    hello: HelloConfig = field(default_factory=HelloConfig)\n    mlflow: MlflowConfig"
    (package / "config" / "__init__.py").write_text(init.replace("    mlflow: MlflowConfig", field_line))
    (tmp_path / "conf" / "hello").mkdir()
    (tmp_path / "conf" / "hello" / "default.yaml").write_text("greeting: hello\ntimes: 2\nout_path: ${paths.data_dir}/hello.txt\n")
    primary = (tmp_path / "conf" / "config.yaml").read_text()
    (tmp_path / "conf" / "config.yaml").write_text(primary.replace("  - mlflow: default\n", "  - mlflow: default\n  - hello: default\n"))
    stage = "  hello:\n    cmd: python -m offroad_path.hello\n    deps:\n      - src/offroad_path/hello\n"  # dvc_deps writes the rest
    stage += "    outs:\n      - data/hello.txt\n"
    pipeline = (tmp_path / "dvc.yaml").read_text()
    (tmp_path / "dvc.yaml").write_text(pipeline.replace("\nplots:\n", f"\n{stage}\nplots:\n", 1))

    def run(*args: str) -> subprocess.CompletedProcess:
        env = {**os.environ, "PYTHONPATH": str(tmp_path / "src")}
        return subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=tmp_path, env=env)

    done = run("-m", "offroad_path.hello")
    assert done.returncode == 0, done.stderr[-1500:]
    assert (tmp_path / "data" / "hello.txt").read_text() == "hellohello\n"
    refused = run("-m", "offroad_path.hello", "hello.times=0")
    assert refused.returncode == 2 and "hello.times" in refused.stderr, refused.stderr[-800:]
    listed = run("-c", "from offroad_path.stage import stage_modules; print(stage_modules())")
    assert "'hello'" in listed.stdout, listed.stderr[-800:]
    assert run("tools/dvc_deps.py").returncode == 0
    deps = yaml.safe_load((tmp_path / "dvc.yaml").read_text())["stages"]["hello"]["deps"]
    assert "src/offroad_path/hello" in deps and "src/offroad_path/stage.py" in deps
