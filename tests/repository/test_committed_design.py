"""The committed run was scored under the committed pre-registered design (conf/evaluate/design/)."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from offroad_path.evaluate.design import DESIGN_KEYS, design_record
from offroad_path.world.held_out import DEVELOPMENT_STREAM, RETIRED_STREAM, held_out_seed

ROOT = Path(__file__).resolve().parents[2]
DESIGN = ROOT / "conf" / "evaluate" / "design" / "laptop.yaml"


def test_the_committed_metrics_were_made_under_the_committed_design(compose_config):
    recorded = json.loads((ROOT / "metrics" / "evaluation.json").read_text())["design"]
    assert recorded == design_record(compose_config().evaluate), (
        "metrics/evaluation.json was made under another version of the design: a change to it after its main test set "
        "was scored needs a fresh test set (docs/conclusions.md)"
    )


def test_every_value_of_the_design_changes_its_hash(compose_config):
    committed = design_record(compose_config().evaluate)["sha256"]
    for override in ("evaluate.seeds=[0,1,2]", "evaluate.main_test_set.min_blocks=89", "evaluate.main_test_set.stream=6",
                     "evaluate.bootstrap.resamples=4001", "evaluate.conclusions.alpha=0.1",
                     "evaluate.conclusions.primaries.postprocessing.smallest_effect=0.02"):  # fmt: skip
        assert design_record(compose_config(override).evaluate)["sha256"] != committed, override
    assert design_record(compose_config("evaluate.colour_baseline_pixels=10").evaluate)["sha256"] == committed  # not the design


def test_the_design_file_holds_exactly_the_design_and_the_synthesize_stage_reads_its_test_set(compose_config):
    assert set(yaml.safe_load(DESIGN.read_text())) == set(DESIGN_KEYS)
    cfg = compose_config()
    design = cfg.evaluate.main_test_set
    assert (cfg.synthesize.test_worlds.main_stream, cfg.synthesize.test_worlds.min_blocks) == (design.stream, design.min_blocks)


def test_the_main_test_set_shares_no_world_with_an_earlier_one_or_the_development_set(compose_config):
    stream = compose_config().evaluate.main_test_set.stream
    assert stream not in (DEVELOPMENT_STREAM, RETIRED_STREAM)
    main = {held_out_seed(0, i, stream) for i in range(200)}
    earlier = {held_out_seed(0, i, s) for s in (DEVELOPMENT_STREAM, RETIRED_STREAM) for i in range(200)}
    assert len(main) == 200 and not main & earlier
