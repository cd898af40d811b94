"""`dvc repro` on a tiny preset in a temporary copy of the repository: runs every stage and
checks each one's outputs against its contract, then runs nothing, then a config edit makes
exactly the stages it touches out of date."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest
import yaml
from helpers import ROOT, dvc, dvc_at_once, in_repo, run_notebook, tiny_repo

from offroad_path.data.manifest import read_manifest
from offroad_path.sequence import find_sequences

# One of the three networks, to save the suite's time: the grid's stages and tables are the same
# for any number (tests/models/test_architectures.py adds a fourth one; tests/evaluate/test_evaluate_stage.py
# compares networks).
GRID = ("unet",)


@pytest.fixture
def repo_copy(tmp_path) -> Path:
    repo = tiny_repo(tmp_path / "repo")
    grid = repo / "conf" / "evaluate" / "networks.yaml"
    text = grid.read_text()
    assert "architectures: [segnet, fcn, unet]\n" in text
    grid.write_text(text.replace("architectures: [segnet, fcn, unet]\n", f"architectures: [{', '.join(GRID)}]\n"))
    return repo


def lock_entries(repo: Path) -> dict:
    return yaml.safe_load((repo / "dvc.lock").read_text())["stages"]


def check_closed_loop(repo: Path, steering: dict) -> None:
    """train_steering_slip and drive, against their contracts."""
    slippery = json.loads((repo / "metrics" / "steering_slip" / "seed0.json").read_text())
    # the same frames, each steered at least as hard (the factors are at most 1), some harder
    assert slippery["test_frames"] == steering["test_frames"]
    assert slippery["straight_ahead_mean_absolute_error"] > steering["straight_ahead_mean_absolute_error"]
    # every argument's policies from both starts of the test world, the same as in the other place
    drove = json.loads((repo / "metrics" / "drive.json").read_text())
    assert {a: list(drove[a]["policies"]) for a in ("steering", "vehicle", "traction")} == {
        "steering": ["unet-segmentation", "pilotnet", "oracle"], "vehicle": ["unet-segmentation", "pilotnet_curvature"],
        "traction": ["unet-segmentation", "pilotnet_slip"]}  # fmt: skip
    assert {p.name for p in (repo / "data" / "drive" / "trajectories").iterdir()} == {"steering", "vehicle", "traction"}
    # The laptop family holds no closed-loop primary (the presets add them): the drive is a pilot, its rates exploratory.
    assert not drove.get("primaries")


def check_no_held_out_world_trains(repo: Path, worlds: list[dict]) -> None:
    """No frame of a held-out world (main test, development, stress) in any network's training or
    validation frames: the path split's (which pretraining and training read) and every PilotNet's,
    as the train_steering stages wrote them beside their checkpoints. A held-out world's frames do
    reach the test parts (so the check reads the right names)."""
    held_out = {w["name"] for w in worlds}
    tested = {s.sequence for s in read_manifest(repo / "data" / "split" / "test.csv")}
    assert tested and tested <= held_out
    folders = [repo / "data" / "split"] + [
        repo / "data" / pilotnet / "seed0" for pilotnet in ("steering", "steering_slip", "steering_curvature")
    ]
    for folder in folders:
        for part in ("train", "val"):
            trained = {s.sequence for s in read_manifest(folder / f"{part}.csv")}
            assert trained and not trained & held_out, (folder, part, trained & held_out)
    steered = {s.sequence for s in read_manifest(repo / "data" / "steering" / "seed0" / "test.csv")}
    assert steered <= tested and steered


def check_stress_set(metrics: dict, runs: set[str], worlds: list[dict]) -> None:
    """The tiny preset's stress world (a held-out look): scored on its own, every run against the prior; the main
    figures (by condition's "all" among them) hold the main test worlds only."""
    stress = metrics["stress_sets"]
    assert set(stress) == {"held_out_look"} and set(stress["held_out_look"]) == runs | {"worlds", "frames", "mean_path_prior"}
    assert stress["held_out_look"]["worlds"] == sum(w["test_set"] == "held_out_look" for w in worlds) == 1
    assert metrics["by_condition"]["all"]["sequences"] == sum(w["test_set"] == "main" for w in worlds) >= 1


@pytest.mark.slow(seconds=210)
def test_repro_runs_then_is_up_to_date_then_follows_a_config_edit(repo_copy, monkeypatch):  # noqa: PLR0915
    # A clone elsewhere, deeper, at the same time, must reproduce the hashes of the stages that
    # write paths (the split's manifests point into the labels and recordings): no output depends
    # on the path. (Up to the split only, to save the suite's time.)
    elsewhere = tiny_repo(repo_copy.parent / "another" / "place" / "repo")
    out, _ = dvc_at_once([(repo_copy, ["repro"]), (elsewhere, ["repro", "split"])])
    ran = set(re.findall(r"Running stage '([^']+)'", out))
    stages = {"synthesize", "label", "split", "evaluate", "drive"}
    stages |= {f"{pilotnet}@0" for pilotnet in ("train_steering", "train_steering_slip", "train_steering_curvature")}
    stages |= {f"pretrain@{m}" for m in GRID}
    stages |= {f"{s}@{m}-0" for s in ("train_scratch", "train_pretrained") for m in GRID}
    stages |= {f"postprocess@{m}-{p}-0" for m in GRID for p in ("none", "segmentation")}
    assert ran == stages
    here, there = lock_entries(repo_copy), lock_entries(elsewhere)
    assert set(there) == {"synthesize", "label", "split"}
    for stage in there:
        assert there[stage] == here[stage], stage
    worlds = json.loads((repo_copy / "data" / "synthetic" / "summary.json").read_text())["test_worlds"]
    assert len(find_sequences(repo_copy / "data" / "synthetic")) == 2 + len(worlds) and worlds  # two drives, held-out test worlds
    # the development world: in its own manifest, never in the main test set evaluate scores
    development = {s.sequence for s in read_manifest(repo_copy / "data" / "split" / "development.csv")}
    assert development == {w["name"] for w in worlds if w["test_set"] == "development"} and development
    assert not development & {s.sequence for s in read_manifest(repo_copy / "data" / "split" / "test.csv")}
    assert json.loads((repo_copy / "metrics" / "label.json").read_text())["labels"] > 0
    for model in GRID:
        for pretraining in ("none", "segmentation"):
            run = repo_copy / "data" / "runs" / f"{model}-{pretraining}" / "seed0"
            assert (run / "predictions" / "manifest.csv").is_file() and (run / "checkpoints" / "best.ckpt").is_file()
            assert (repo_copy / "data" / "postprocessed" / f"{model}-{pretraining}" / "seed0" / "manifest.csv").is_file()
    # evaluate: every run with and without post-processing, the baselines, curves and figures.
    metrics = json.loads((repo_copy / "metrics" / "evaluation.json").read_text())
    notice = metrics.pop("notice")  # the tour's preset: a smoke run says so, above its results too
    assert notice.startswith("Smoke run") and (repo_copy / "data" / "evaluation" / "results.md").read_text().startswith(f"> **{notice}**")
    assert set(metrics) == {f"{m}-{p}" for m in GRID for p in ("none", "segmentation")} | {
        "design", "uncertainty", "baselines", "steering_from_paths", "primaries", "by_condition", "stress_sets"}  # fmt: skip
    assert all(0 <= metrics[r][pp]["accuracy"] <= 1 for r in metrics if "raw" in metrics[r] for pp in ("raw", "postprocessed"))
    # path against steering: PilotNet (train_steering ran before evaluate), every run, the ceiling
    runs = {r for r in metrics if "raw" in metrics[r]}
    paired = {f"{r}_vs_pilotnet" for r in runs}  # each with its paired interval
    assert set(metrics["steering_from_paths"]) == runs | paired | {"straight_ahead", "pilotnet", "label_ceiling"}
    # The stress world (a held-out look): scored on its own, every run against the prior; the main figures leave it out.
    check_stress_set(metrics, runs, worlds)
    check_no_held_out_world_trains(repo_copy, worlds)
    scored = runs | {"mean_path_prior", "colour_classifier"}
    against_prior = {
        f"{r}.minus_prior" for r in runs | {"colour_classifier"}
    }  # each network (and the colour baseline) minus the prior, paired
    assert set(metrics["by_condition"]["all"]) == scored | {f"{r}.interval" for r in scored} | against_prior | {"frames", "sequences"}
    assert len((repo_copy / "data" / "evaluation" / "results.csv").read_text().splitlines()) == 1 + 2 * 2 * len(GRID)
    assert len(list((repo_copy / "metrics" / "precision_recall").glob("*.csv"))) == 2 * len(GRID)
    assert {p.name for p in (repo_copy / "data" / "evaluation" / "figures").iterdir()} == {"good_and_bad_cases.png", "postprocessing.png"}
    steering = json.loads((repo_copy / "metrics" / "steering" / "seed0.json").read_text())
    assert steering["test_frames"] > 0 and 0 <= steering["mean_absolute_error"] <= 2
    check_closed_loop(repo_copy, steering)
    assert "unet-none" in dvc(repo_copy, "metrics", "show")
    assert "Data and pipelines are up to date" in dvc(repo_copy, "repro")
    # A U-Net setting makes its training stages out of date and nothing else (`--dry` lists the
    # stages whose own deps changed; what follows them, DVC reruns from their outputs, as above).
    unet = repo_copy / "conf" / "model" / "unet.yaml"
    setting = unet.read_text()
    unet.write_text(re.sub(r"(?m)^lr: .*$", "lr: 0.05", setting))
    ran = set(re.findall(r"Running stage '([^']+)'", dvc(repo_copy, "repro", "--dry")))
    assert ran == {"pretrain@unet", "train_scratch@unet-0", "train_pretrained@unet-0"}
    unet.write_text(setting)
    # The notebooks run top to bottom on these outputs. The results notebook also reads the
    # evaluation's MLflow run, which the tiny preset does not log: one more evaluate logs it.
    in_repo(repo_copy, "-m", "offroad_path.evaluate", "mlflow.enabled=true")
    world = run_notebook("01_world_and_labels.ipynb", repo_copy, monkeypatch)
    assert world["kept"] and world["mask"].any()
    assert world["panel"].shape == (144, 3 * 256, 3)  # left image, semantic classes, depth of the tiny world's 256 x 144
    results = run_notebook("02_results.ipynb", repo_copy, monkeypatch)
    assert len(results["results"]) == 2 * 2 * len(GRID) and len(results["curves"]) == 2 * len(GRID)
    assert results["evaluation"].data.tags.get("stage") == "evaluate"


@pytest.mark.slow(seconds=45)
def test_the_gpu_pipeline_runs_its_stages_into_gpu(tmp_path):
    """gpu/dvc.yaml (experiment=gpu, made from dvc.yaml) on the tiny preset in a copy: its stages up to the
    split run in the checkout and write under gpu/ only, never into the laptop's data/ or metrics/ (the
    later stages' paths: tests/config/test_presets.py checks the file is dvc.yaml's stages under gpu/)."""
    repo = tiny_repo(tmp_path / "repo")
    shutil.copytree(ROOT / "gpu", repo / "gpu")
    # the copy's GPU preset is the tiny one (the real one's sizes are for a GPU): what runs here is the pipeline file
    (repo / "conf" / "experiment" / "gpu.yaml").write_text("# @package _global_\ndefaults:\n  - tiny\n  - _self_\n")
    dvc(repo, "repro", "gpu/dvc.yaml:split")
    assert (repo / "gpu" / "data" / "split" / "train.csv").is_file()
    assert json.loads((repo / "gpu" / "metrics" / "label.json").read_text())["labels"] > 0
    assert not (repo / "data").exists() and not (repo / "metrics").exists()
    locked = yaml.safe_load((repo / "gpu" / "dvc.lock").read_text())["stages"]
    assert set(locked) == {"synthesize", "label", "split"}
