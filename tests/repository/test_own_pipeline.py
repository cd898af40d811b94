"""The own pipeline (own/dvc.yaml, experiment=own), as DVC resolves it from this checkout:
label -> split -> train -> postprocess -> evaluate, each stage's declared outputs where its config
writes, its world network among the train stage's deps."""

from __future__ import annotations

import shlex
from pathlib import Path

import pytest
import yaml
from helpers import ROOT


@pytest.fixture(scope="module")
def own_stages() -> dict:
    """{name: (cmd, deps, outs, metrics)} of own/dvc.yaml, resolved by DVC (vars, foreach)."""
    from dvc.repo import Repo

    with Repo(str(ROOT)) as repo:
        stages = {}
        for stage in repo.index.stages:
            if stage.path_in_repo == "own/dvc.yaml":
                outs = sorted(Path(o.def_path).as_posix() for o in stage.outs if not o.metric and not o.plot)
                metrics = sorted(Path(o.def_path).as_posix() for o in stage.outs if o.metric or o.plot)
                stages[stage.name] = (stage.cmd, [Path(d.def_path).as_posix() for d in stage.deps], outs, metrics)
        return stages


def stage_config(compose_config, cmd: str):
    words = shlex.split(cmd)
    assert words[:3] == ["python", "-m", words[2]] and words[2].startswith("offroad_path.")
    return words[2].removeprefix("offroad_path."), compose_config(*words[3:])


@pytest.mark.slow(seconds=4)
def test_the_own_pipeline_writes_where_dvc_tracks_it(compose_config, own_stages):
    seeds = yaml.safe_load((ROOT / "conf" / "evaluate" / "design" / "laptop.yaml").read_text())["seeds"]
    expected = ["label", "split", *(f"train@{k}" for k in range(len(seeds))), *(f"postprocess@{k}" for k in range(len(seeds))), "evaluate"]
    assert list(own_stages) == expected
    for name, (cmd, deps, outs, metrics) in own_stages.items():
        stage, cfg = stage_config(compose_config, cmd)
        assert stage == name.split("@")[0] and cfg.experiment_name == "own" and cfg.paths.root == "own"
        assert "src/offroad_path" in deps
        if stage == "label":
            assert outs == [cfg.label.out_dir] == ["own/data/labels"] and metrics == [cfg.label.metrics_path]
            assert cfg.label.in_dir in deps and cfg.label.poses.source == "file"
        elif stage == "split":
            assert outs == [cfg.split.out_dir] and cfg.split.labels_dir in deps and cfg.split.strategy == "stretch"
        elif stage == "train":
            assert outs == [cfg.train.out_dir] == [f"own/data/runs/fcn-world/seed{cfg.seed}"] and cfg.seed in seeds
            assert cfg.pretraining.name == "world" and str(Path(cfg.pretraining.checkpoint).parents[1]) in deps
            assert cfg.data.split_dir in deps
        elif stage == "postprocess":
            assert outs == [cfg.postprocess.out_dir] and str(Path(cfg.postprocess.predictions_dir).parent) in deps
            assert cfg.postprocess.use_depth is False
        else:
            assert outs == [cfg.evaluate.out_dir] and metrics == sorted([cfg.evaluate.metrics_path, cfg.evaluate.plots_dir])
            assert list(cfg.evaluate.runs) == ["fcn-world"] and list(cfg.evaluate.seeds) == seeds
            assert {cfg.evaluate.runs_dir, cfg.evaluate.postprocessed_dir, str(Path(cfg.evaluate.train_manifest).parent)} <= set(deps)
