"""The full-size presets: experiment=paper is Holder & Breckon 2018 as published (every number
below is quoted from the paper), experiment=full the same sizes with this project's fixes; both
train on a CPU at full size for one batch."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import hand_counted_iou
from omegaconf import OmegaConf

from offroad_path.split import split
from offroad_path.train import train
from offroad_path.world.trajectory import frame_arc_lengths

# "Training continues until ... 60,000 iterations for SegNet, 30,000 iterations for U-Net, and
# 100,000 iterations for FCN"; "for both SegNet and U-Net ... 1x10^-3, while for FCN it was
# 1x10^-10" (Caffe's loss summed over the 512 x 288 pixels: 1e-10 * P for a per-pixel mean).
PAPER_NETWORKS = {"segnet": (60_000, 1e-3), "unet": (30_000, 1e-3), "fcn": (100_000, 1e-10 * 512 * 288)}


@pytest.mark.parametrize("model", list(PAPER_NETWORKS))
def test_paper_preset_has_the_publications_numbers(compose_config, model):
    cfg = compose_config("experiment=paper", f"model={model}")
    steps, lr = PAPER_NETWORKS[model]
    assert cfg.train.max_steps == steps and cfg.model.lr == pytest.approx(lr, rel=1e-3)
    assert (cfg.model.momentum, cfg.model.weight_decay, cfg.data.batch_size) == (0.9, 5e-4, 6)
    # SegNet's step function (its milestones this project's choice), a fixed rate otherwise; no warm-up.
    assert list(cfg.model.lr_milestones) == ([0.5, 0.75] if model == "segnet" else []) and cfg.model.lr_warmup == 0
    assert (cfg.data.width, cfg.data.height, cfg.model.width) == (512, 288, 1.0)
    assert (cfg.world.width, cfg.world.height, cfg.postprocess.sigma) == (512, 288, 6.0)  # the camera's images; "sigma = 6"
    # Labels: 10 fps, the next D = 20 m, restarted midway, no occlusion handling.
    assert (cfg.world.fps, cfg.label.distance_m, cfg.label.strategy, cfg.label.occlusion.enabled) == (10.0, 20.0, "midway", False)
    # "the 10% of our dataset that was set aside for testing", per image, mirrored copies, no validation set.
    assert (cfg.split.strategy, cfg.split.test_fraction, cfg.split.val_fraction, cfg.split.mirror) == ("random", 0.1, 0.0, True)
    assert cfg.data.augment is False
    assert cfg.pretrain.max_steps == 30_000  # the thesis's pretraining length
    assert cfg.synthesize.test_worlds.min_blocks == 0  # no held-out test worlds: the paper's per-image split


def test_full_preset_is_the_paper_size_with_the_projects_fixes(compose_config):
    """The same sizes as the paper preset, which trains at that size below."""
    paper, full = compose_config("experiment=paper"), compose_config("experiment=full")
    for key in ("data.width", "data.height", "model.width", "model.lr", "world.fps", "world.frames", "world.width", "synthesize.sequences"):
        assert paper[key.split(".")[0]][key.split(".")[1]] == full[key.split(".")[0]][key.split(".")[1]], key
    assert (full.split.strategy, full.split.val_fraction, full.label.occlusion.enabled, full.data.augment) == ("grouped", 0.1, True, True)
    assert full.train.max_steps == -1 and full.callbacks.early_stopping.patience > 0
    # More held-out test worlds than the laptop's 30 blocks: the drive's powered route needs them.
    assert full.synthesize.test_worlds.min_blocks > compose_config().synthesize.test_worlds.min_blocks


def test_full_preset_drives_every_network_at_the_worlds_size(compose_config):
    laptop, full = compose_config(), compose_config("experiment=full")
    runs = list(full.evaluate.runs)
    assert len(runs) == 6
    pilots = {"pilotnet", "pilotnet_curvature"}
    assert set(full.drive.arguments.steering) == {*runs, *(f"{r}+temporal" for r in runs), *pilots, "oracle", "straight"}
    assert set(full.drive.arguments.traction) == {*runs, "pilotnet_slip", *pilots, "oracle", "straight"}
    assert (full.drive.width, full.drive.height) == (full.world.width, full.world.height) == (512, 288)
    assert full.drive.starts_per_world * full.drive.length_m > laptop.drive.starts_per_world * laptop.drive.length_m
    # The laptop drives fewer networks, smaller; slip stays off in synthesis for both.
    assert set(laptop.drive.arguments.steering) < set(full.drive.arguments.steering)
    assert not laptop.world.slip.enabled and not full.world.slip.enabled


def test_laptop_reference_is_the_defaults_reference_one_override_away(compose_config):
    """The reference of the rule for changes that alter results (CHANGELOG.md's benchmark history, "Three seeds"): the
    world at 512 x 288 and 4 epochs of pretraining; everything else is the default's."""
    laptop, reference = compose_config(), compose_config("experiment=laptop_reference")
    changed = {"world.width": 512, "world.height": 288, "postprocess.sigma": 6.0, "evaluate.figure_scale": 0.5,
               "pretrain.max_epochs": 4}  # fmt: skip
    for key, value in changed.items():
        group, name = key.split(".")
        assert reference[group][name] == value != laptop[group][name], key
    for group in ("data", "model", "trainer", "label", "split", "synthesize", "steering"):  # the rest is the default's
        assert reference[group] == laptop[group], group


def full_size_on_cpu(tmp_path, split_dir) -> list[str]:
    """One batch of 1 at 512 x 288 through the width-1 U-Net, on the CPU in fp32."""
    return ["model=unet", "data.batch_size=1", "trainer.accelerator=cpu", "trainer.precision=32-true", "trainer.fast_dev_run=true",
            "data.num_workers=0", "data.pin_memory=false", "mlflow.enabled=false", f"data.split_dir={split_dir}",
            f"train.out_dir={tmp_path / 'run'}"]  # fmt: skip


@pytest.mark.slow(seconds=27)
def test_paper_preset_trains_without_a_validation_set(compose_config, labelled_drive, tmp_path):
    split_dir = tmp_path / "split"
    split(compose_config("experiment=paper", f"split.labels_dir={labelled_drive}", f"split.out_dir={split_dir}"))
    summary = json.loads((split_dir / "summary.json").read_text())
    assert summary["samples"]["val"] == 0 and summary["samples"]["test"] == 2 * round(0.1 * summary["frames"])
    cfg = compose_config("experiment=paper", *full_size_on_cpu(tmp_path, split_dir))
    metrics = train(cfg)
    assert metrics["best_val_iou"] is None and metrics["global_step"] == 1
    assert metrics["test/iou"] == pytest.approx(hand_counted_iou(cfg, tmp_path / "run" / "checkpoints" / "best.ckpt"), abs=1e-6)
    assert (tmp_path / "run" / "checkpoints" / "best.ckpt").is_file()


def test_every_trained_network_writes_one_folder_per_seed_and_evaluate_reads_the_grids_first(compose_config):
    """Seeds are a grid axis (dvc.yaml's matrices read evaluate.seeds): the path networks', post-processing's and
    both PilotNets' outputs are per seed, so that the stages of three seeds never share a file."""
    cfg = compose_config("seed=2", "model=fcn")
    assert list(compose_config().evaluate.seeds) == [0, 1] and list(compose_config("experiment=gpu").evaluate.seeds) == [0, 1, 2]
    for path in (cfg.train.out_dir, cfg.postprocess.out_dir, cfg.steering.out_dir):
        assert "/seed2" in path, path
    assert cfg.steering.metrics_path.endswith("metrics/steering/seed2.json")
    assert cfg.steering.plots_path.endswith("metrics/steering/seed2_scatter.csv")
    curvature = compose_config("seed=2", "steering.target=curvature").steering
    assert (curvature.out_dir, curvature.metrics_path) == ("data/steering_curvature/seed2", "metrics/steering_curvature/seed2.json")
    # The drive reads evaluate.drive_seeds (the laptop: seed 0), evaluate's path-against-steering section every seed: {seed} in their paths.
    assert list(cfg.drive.seeds) == [0] and list(compose_config("experiment=gpu").drive.seeds) == [0, 1, 2]
    for name, folder in (("pilotnet", "steering"), ("pilotnet_slip", "steering_slip"), ("pilotnet_curvature", "steering_curvature")):
        assert cfg.drive.pilotnets[name] == f"data/{folder}/seed{{seed}}/checkpoints/best.ckpt"
    assert cfg.evaluate.steering_from_paths.pilotnet_predictions == "data/steering/seed{seed}/predictions.csv"
    assert list(compose_config("evaluate.drive_seeds=[3,4]").drive.seeds) == [3, 4]


def test_gpu_preset_scales_the_laptop_pipeline_and_its_dvc_file_is_made_from_dvc_yaml(compose_config, monkeypatch):
    """experiment=gpu: every look alike, twice the drives, full-width networks on larger inputs, every core
    working, a pre-registered design of its own on a main test set no other run scores; gpu/dvc.yaml is
    dvc.yaml's stages under it (made by tools/scaled_pipeline.py, its design file among the params), its grid gpu/params.yaml."""
    import yaml
    from omegaconf import OmegaConf
    from scaled_pipeline import ROOT, grid, render

    from offroad_path.looks import axis_values

    laptop, gpu = compose_config(), compose_config("experiment=gpu")
    assert all(gpu.world.appearance.weights[axis][value] > 0 for axis in gpu.world.appearance.weights for value in axis_values()[axis])
    assert gpu.synthesize.sequences >= 2 * laptop.synthesize.sequences and gpu.model.width == 1.0
    assert gpu.synthesize.test_worlds.main_stream == gpu.evaluate.main_test_set.stream != laptop.evaluate.main_test_set.stream
    assert gpu.synthesize.test_worlds.min_blocks == gpu.evaluate.main_test_set.min_blocks and len(gpu.evaluate.seeds) >= 3
    assert gpu.data.width * gpu.data.height > laptop.data.width * laptop.data.height and gpu.data.num_workers > 0
    assert gpu.synthesize.workers == gpu.label.workers == gpu.drive.workers == 0  # 0: one per core
    assert (gpu.drive.width, gpu.drive.height) == (gpu.world.width, gpu.world.height)  # the camera the networks trained on
    for preset in (laptop, gpu, compose_config("experiment=full")):  # every test world holds the drive's route (drive.check_worlds)
        w = preset.world
        speeds = (w.speed_min_mps, w.speed_max_mps)
        drives = [frame_arc_lengths(np.random.default_rng(seed), w.frames, w.fps, speeds)[-1] for seed in range(500)]
        assert preset.drive.length_m + preset.drive.respawn_m < min(drives), preset.experiment_name
    # Every core, or the share tools/parallel_repro.py gives each stage it runs at once (the tests' config sets 1).
    threads = OmegaConf.create({"threads": yaml.safe_load((ROOT / "conf" / "experiment" / "gpu.yaml").read_text())["threads"]})
    monkeypatch.delenv("OFFROAD_THREADS", raising=False)
    assert threads.threads == "all"
    monkeypatch.setenv("OFFROAD_THREADS", "4")
    assert threads.threads == "4"
    assert {"no_track", "grass_track"} <= set(gpu.synthesize.test_worlds.stress_sets)  # in its training distribution
    assert (ROOT / "gpu" / "dvc.yaml").read_text() == render(), "gpu/dvc.yaml is stale: python tools/scaled_pipeline.py"
    pipeline, main = yaml.safe_load(render()), yaml.safe_load((ROOT / "dvc.yaml").read_text())
    assert list(pipeline["stages"]) == list(main["stages"])
    for name, stage in pipeline["stages"].items():
        assert "experiment=gpu paths.root=gpu" in stage["cmd"] and stage["wdir"] == ".."
        assert "conf/evaluate/design/laptop.yaml" not in str(stage["params"]), name
        outputs = [next(iter(o)) if isinstance(o, dict) else o for key in ("outs", "metrics") for o in stage.get(key, [])]
        assert outputs and all(o.startswith(("gpu/data/", "gpu/metrics/")) for o in outputs), name
    assert (ROOT / "gpu" / "params.yaml").read_text() == grid("gpu"), "gpu/params.yaml is stale: python tools/scaled_pipeline.py"
    assert yaml.safe_load(grid("gpu"))["seeds"] == list(gpu.evaluate.seeds)


@pytest.mark.parametrize("folder", ["tour", "rehearsal"])
def test_the_tour_and_the_rehearsal_are_every_stage_on_tiny_worlds_into_their_own_folder(compose_config, folder):
    """tour/dvc.yaml and rehearsal/dvc.yaml: dvc.yaml's stages under experiment=tour (the suite's tiny
    repro runs the same preset, tests/repository/test_pipeline_dvc.py) or experiment=rehearsal, outputs
    under their folder, an MLflow experiment of their own."""
    import yaml
    from scaled_pipeline import ROOT, grid, render

    preset = compose_config(f"experiment={folder}")
    assert (ROOT / folder / "dvc.yaml").read_text() == render(folder), f"{folder}/dvc.yaml is stale: python tools/scaled_pipeline.py"
    pipeline, main = yaml.safe_load(render(folder)), yaml.safe_load((ROOT / "dvc.yaml").read_text())
    assert list(pipeline["stages"]) == list(main["stages"])
    for name, stage in pipeline["stages"].items():
        assert f"experiment={folder} paths.root={folder}" in stage["cmd"], name
        outputs = [next(iter(o)) if isinstance(o, dict) else o for key in ("outs", "metrics") for o in stage.get(key, [])]
        assert outputs and all(o.startswith((f"{folder}/data/", f"{folder}/metrics/")) for o in outputs), name
    assert (ROOT / folder / "params.yaml").read_text() == grid(folder), f"{folder}/params.yaml is stale: python tools/scaled_pipeline.py"
    assert yaml.safe_load(grid(folder))["architectures"] == list(preset.evaluate.architectures)
    assert preset.mlflow.experiment not in (compose_config().mlflow.experiment, compose_config("experiment=gpu").mlflow.experiment)
    assert preset.trainer.max_epochs == 1 and preset.world.frames == compose_config("experiment=tour").world.frames


def test_the_rehearsal_is_the_gpu_presets_settings_at_the_tours_sizes(compose_config):
    """experiment=rehearsal runs what the GPU preset runs that can fail on a GPU host (its renderer,
    bf16, the loader's workers, every network, the closed loop's networks on auto) on tiny worlds, and
    on a CPU where there is no GPU."""
    gpu, tour, rehearsal = (compose_config(f"experiment={name}") for name in ("gpu", "tour", "rehearsal"))
    same = ("render", "drive.device", "trainer.precision", "data.num_workers", "data.pin_memory", "synthesize.workers",
            "label.workers", "drive.workers", "evaluate.pretrainings", "world.appearance")  # fmt: skip
    for key in same:
        assert OmegaConf.select(rehearsal, key) == OmegaConf.select(gpu, key), key
    assert sorted(rehearsal.evaluate.architectures) == sorted(gpu.evaluate.architectures)  # every network (conf/model/)
    sizes = ("world.frames", "world.width", "synthesize.sequences", "synthesize.test_worlds.min_blocks", "data.width")
    for key in (*sizes, "synthesize.test_worlds.stress_sets", "model.width", "drive.length_m", "drive.worlds", "trainer.max_epochs"):
        assert OmegaConf.select(rehearsal, key) == OmegaConf.select(tour, key), key
    assert gpu.trainer.accelerator == "gpu" and rehearsal.trainer.accelerator == "auto"


def test_the_gpu_and_tour_presets_leave_mlflow_off_when_the_host_says_so(monkeypatch):
    """gpu/repro.sh runs the GPU preset where MLflow is not installed: OFFROAD_MLFLOW=false turns it
    off for the presets it runs, never for the committed laptop run."""
    from offroad_path.config import load_config

    monkeypatch.setenv("OFFROAD_MLFLOW", "false")
    assert load_config("experiment=gpu").mlflow.enabled is False and load_config("experiment=tour").mlflow.enabled is False
    assert load_config().mlflow.enabled is True
    monkeypatch.delenv("OFFROAD_MLFLOW")
    assert load_config("experiment=gpu").mlflow.enabled is True
