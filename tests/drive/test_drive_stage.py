"""The drive stage end to end on a small rendered test world: a trained path network, PilotNet and
the built-in policies driven through every argument, the outputs of its contract, and bad input
refused before anything is written (the same metrics from two places: tests/repository/test_pipeline_dvc.py)."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pytest
import torch
from helpers import command, refused

from offroad_path.drive import run_drive
from offroad_path.steering.pilotnet_task import SteeringTask

SMALL_WORLD = ("world.frames=30", "world.width=128", "world.height=72")


@pytest.fixture(scope="module")
def inputs(compose_config, trained, tmp_path_factory) -> Path:
    """A folder with synthetic/test_000 (a held-out world), runs/unet-none/seed0 (the tiny U-Net)
    and pilotnet.ckpt (an untrained PilotNet, saved as train_steering saves one)."""
    from offroad_path.world.record import record_sequence

    root = tmp_path_factory.mktemp("drive_inputs")
    record_sequence(compose_config(*SMALL_WORLD).world, seed=5, out_dir=root / "synthetic" / "test_000", test_set="main")
    checkpoint = root / "runs" / "unet-none" / "seed0" / "checkpoints" / "best.ckpt"
    checkpoint.parent.mkdir(parents=True)
    shutil.copy(trained[0], checkpoint)
    hp = {"width": 96, "height": 66, "lr": 0.01, "lr_step_epochs": 5, "lr_gamma": 0.5, "momentum": 0.9, "weight_decay": 0.0}
    torch.manual_seed(0)
    torch.save({"hyper_parameters": hp, "state_dict": SteeringTask(**hp).state_dict()}, root / "pilotnet.ckpt")
    return root


def overrides(inputs: Path, out: Path) -> list[str]:
    return [*SMALL_WORLD, f"synthesize.out_dir={inputs / 'synthetic'}", f"evaluate.runs_dir={inputs / 'runs'}",
            f"drive.pilotnets.pilotnet={inputs / 'pilotnet.ckpt'}", f"drive.pilotnets.pilotnet_slip={inputs / 'pilotnet.ckpt'}",
            "drive.arguments.steering=[unet-none,unet-none+temporal,pilotnet,oracle,straight]",
            "drive.arguments.vehicle=[unet-none,pilotnet]", "drive.arguments.traction=[unet-none,pilotnet_slip,oracle]",
            "drive.length_m=8", "drive.starts_per_world=2", "drive.width=128", "drive.height=72", "drive.bootstrap.resamples=100",
            "drive.workers=1", "drive.seeds=[0]", "+evaluate/primaries@evaluate.conclusions.primaries=closed_loop",  # the presets' family
            "evaluate.conclusions.primaries.closed_loop.compare=steering/unet-none_vs_pilotnet",
            f"drive.out_dir={out / 'drive'}", f"drive.metrics_path={out / 'drive.json'}",
            f"mlflow.tracking_uri=sqlite:///{out / 'mlflow.db'}"]  # fmt: skip


@pytest.fixture(scope="module")
def driven(compose_config, inputs, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("driven")
    run_drive(compose_config(*overrides(inputs, out)))
    return out


@pytest.mark.slow(seconds=15)
def test_outputs_follow_the_contract(driven):
    drive_dir = driven / "drive"
    metrics = json.loads((driven / "drive.json").read_text())
    assert json.loads((drive_dir / "drive.json").read_text()) == metrics
    assert metrics["drives"] == {"worlds": ["test_000"], "starts_per_world": 2, "seeds": [0], "length_m": 8.0}
    assert list(metrics["steering"]["policies"]) == ["unet-none", "unet-none+temporal", "pilotnet", "oracle", "straight"]
    assert list(metrics["traction"]["path_minus_end_to_end"]) == ["unet-none - pilotnet_slip"]
    # The primary this drive answers gets the exact test of its pooled counts, at each of Holm's 7 levels
    # (the laptop's 4 and the closed loop's 3); the others name policies it did not drive and are not measured.
    closed_loop = metrics["primaries"]["closed_loop"]
    assert list(metrics["primaries"]) == ["closed_loop"] and len(closed_loop["intervals"]) == 5 and closed_loop["null"] == 1.0
    policies = metrics["steering"]["policies"]
    assert closed_loop["interventions"] == [policies["unet-none"]["interventions"], policies["pilotnet"]["interventions"]]
    # the route the planning rates (30.2 and 35.4 per km) need at 0.05 / 5, its family's strictest level
    assert 0 < closed_loop["p_value"] <= 1 and closed_loop["route_needed_m"] == pytest.approx(28680, abs=20)
    for argument in ("steering", "vehicle", "traction"):
        assert (drive_dir / "trajectories" / argument / "test_000.png").stat().st_size > 1000
        for policy in metrics[argument]["policies"].values():
            assert policy["drives"] == 2
            assert policy["route_m"] == pytest.approx(2 * 8.0, abs=0.05)  # every drive finishes its 8 m of route
            # ... driven, or skipped by the 5 m an intervention moves the vehicle on.
            assert policy["distance_m"] + 5.0 * policy["interventions"] >= policy["route_m"] - 2 * 1.0
            low, value, high = (policy["interventions_per_km"][k] for k in ("low", "value", "high"))
            assert low <= value <= high
        assert metrics[argument]["finding"].startswith("Path prediction + pure pursuit minus end-to-end steering")
    assert metrics["steering"]["policies"]["oracle"]["interventions"] == 0
    videos = sorted(p.name for p in (drive_dir / "videos").iterdir())
    assert videos == sorted(f"{name}.mp4" for name in metrics["steering"]["policies"])
    results = (drive_dir / "results.md").read_text()
    assert results.count("\n## ") == 3 and "| unet-none+temporal |" in results
    with sqlite3.connect(driven / "mlflow.db") as db:
        (run,) = db.execute("select run_uuid from runs where name = 'drive'").fetchone()
        logged = db.execute("select count(*) from metrics where run_uuid = ?", (run,)).fetchone()[0]
    assert logged > 20


@pytest.mark.slow(seconds=7)
def test_an_unknown_policy_is_refused_before_anything_is_written(inputs, tmp_path):
    run = command("offroad_path.drive", *overrides(inputs, tmp_path), "drive.arguments.vehicle=[unet-nothing]", "mlflow.enabled=false")
    assert run.returncode == 2
    line = run.stderr.strip().splitlines()[-1]
    missing = inputs / "runs" / "unet-nothing" / "seed0" / "checkpoints" / "best.ckpt"
    assert line.startswith(f"error: drive.arguments.vehicle: policy 'unet-nothing' needs {missing}, which does not exist")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    "override", ["world.max_curvature=0.05", "world.trees_per_hectare=300", "world.hfov_deg=120", "world.obstacles_per_100m=9"]
)
def test_a_world_config_that_did_not_render_the_test_world_is_refused(compose_config, inputs, tmp_path, capsys, override):
    meta = inputs / "synthetic" / "test_000" / "meta.json"
    cfg = compose_config(*overrides(inputs, tmp_path), override, "mlflow.enabled=false")
    refused(run_drive, cfg, capsys, tmp_path, meta, f"{override.split('=')[0]}={override.split('=')[1]}")


def test_a_route_longer_than_the_test_worlds_is_refused(compose_config, inputs, tmp_path, capsys):
    cfg = compose_config(*overrides(inputs, tmp_path), "drive.length_m=1e9", "mlflow.enabled=false")
    refused(run_drive, cfg, capsys, tmp_path, "drive.length_m=1e+09", "test_000")


@pytest.mark.parametrize(
    ("override", "says"),
    [("drive.arguments.steering=[]", "lists no policy"), ("drive.other_vehicle.wheelbase_m=0", "drive.other_vehicle.wheelbase_m")],
)
def test_arguments_without_meaning_are_refused_before_driving(compose_config, inputs, tmp_path, capsys, override, says):
    refused(run_drive, compose_config(*overrides(inputs, tmp_path), override, "mlflow.enabled=false"), capsys, tmp_path, says)


def test_a_path_networks_checkpoint_given_as_pilotnet_is_named(compose_config, inputs, tmp_path, capsys):
    path_network = inputs / "runs" / "unet-none" / "seed0" / "checkpoints" / "best.ckpt"
    cfg = compose_config(*overrides(inputs, tmp_path), f"drive.pilotnets.pilotnet={path_network}", "mlflow.enabled=false")
    refused(run_drive, cfg, capsys, tmp_path, path_network, "not a PilotNet checkpoint")


@pytest.mark.parametrize(
    ("damage", "says"), [(lambda m: "{broken", "cannot be read as JSON"), (lambda m: json.dumps({**m, "seed": None}), '"seed"')]
)
def test_a_test_worlds_damaged_meta_json_is_named(compose_config, inputs, tmp_path, capsys, damage, says):
    shutil.copytree(inputs, tmp_path / "inputs")
    meta = tmp_path / "inputs" / "synthetic" / "test_000" / "meta.json"
    meta.write_text(damage(json.loads(meta.read_text())))
    refused(run_drive, compose_config(*overrides(tmp_path / "inputs", tmp_path), "mlflow.enabled=false"), capsys, tmp_path, meta, says)
