"""Refusals across the stages, one case a test: launcher rank variables, label shards, settings
without meaning, loggers' folders, empty splits, untrained seeds, a full disk, short videos, inspect's
arguments, decompression bombs, a bag's stereo pair. Each case exits 2 with one line naming the file
or key and leaves the test's folder as it was (helpers.refused), unless it says otherwise."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from helpers import command, label_cfg, png_declaring, refused, snapshot, user_folder

from offroad_path.config import load_config, validate_config
from offroad_path.errors import InputError
from offroad_path.evaluate import evaluate
from offroad_path.label import label
from offroad_path.split import split
from offroad_path.train import train
from offroad_path.train_steering import train_steering
from offroad_path.utils.atomic import MARKER
from offroad_path.utils.rules import ConfigValueError

# -- Rank variables of a launcher's shell switch no output rule off --------------------------------


@pytest.mark.parametrize("variable", ["RANK", "LOCAL_RANK", "SLURM_PROCID"])
def test_rank_variables_leave_the_output_rule_on_outside_training(compose_config, recordings, tmp_path, capsys, monkeypatch, variable):
    monkeypatch.setenv(variable, "1")
    meta = recordings / "drive" / "meta.json"
    refused(
        label,
        label_cfg(compose_config, recordings, tmp_path, f"label.metrics_path={meta}"),
        capsys,
        tmp_path,
        "label.metrics_path",
        "overlaps the input",
    )


def test_another_rank_of_a_training_run_obeys_the_output_rule_too(tiny_config, tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("RANK", "1")
    out = user_folder(tmp_path / "run")
    refused(train, tiny_config(tmp_path, "mlflow.enabled=false"), capsys, tmp_path, f"train.out_dir={out}", "did not write")


# -- One stage never replaces another's output by default --------------------------------------------


def test_the_slip_pilotnet_writes_beside_the_plain_one_under_its_own_stage(compose_config, split_dir, labelled_drive, tmp_path, capsys):
    plain, slip = load_config(), load_config("steering.slip=true")
    assert (plain.steering.out_dir, plain.steering.metrics_path) == ("data/steering/seed0", "metrics/steering/seed0.json")
    assert (slip.steering.out_dir, slip.steering.metrics_path) == ("data/steering_slip/seed0", "metrics/steering_slip/seed0.json")
    theirs = tmp_path / "steering"  # the plain PilotNet's output, which a slip run given the same folder must not replace
    theirs.mkdir()
    (theirs / MARKER).write_text("train_steering\n")
    (theirs / "metrics.json").write_text("{}")
    cfg = compose_config(f"split.labels_dir={labelled_drive}", f"split.out_dir={split_dir}", "steering.slip=true",
                         f"steering.out_dir={theirs}", f"steering.metrics_path={tmp_path / 'm.json'}",
                         f"steering.plots_path={tmp_path / 'p.csv'}", "mlflow.enabled=false")  # fmt: skip
    refused(train_steering, cfg, capsys, tmp_path, "steering.out_dir", "output of the train_steering stage")


def test_a_label_shard_never_replaces_a_whole_label_run(compose_config, labelled_drive, recordings, tmp_path, capsys):
    whole = tmp_path / "labels"
    shutil.copytree(labelled_drive, whole)
    cfg = label_cfg(compose_config, recordings, tmp_path, "label.shards=2", "label.shard=0")
    refused(label, cfg, capsys, tmp_path, "label.out_dir", "output of the label stage")


def test_split_refuses_a_shard_as_a_label_run(compose_config, labelled_drive, tmp_path, capsys):
    shard = tmp_path / "shard0"
    shutil.copytree(labelled_drive, shard)
    (shard / "shard.json").write_text(json.dumps({"shard": 0, "shards": 2, "sequences": ["drive"], "config": "0" * 16}))
    refused(split, compose_config(f"split.labels_dir={shard}", f"split.out_dir={tmp_path / 'split'}"), capsys, tmp_path, shard, "one shard")


@pytest.mark.parametrize("record", ["{not json", '{"shard": 0, "shards": 1}'])
def test_a_corrupt_shard_record_is_named(compose_config, labelled_drive, recordings, tmp_path, capsys, record):
    shards = tmp_path / "shards"
    shutil.copytree(labelled_drive, shards / "0")
    (shards / "0" / "shard.json").write_text(record)
    cfg = label_cfg(compose_config, recordings, tmp_path, f"label.merge_from={shards}")
    refused(label, cfg, capsys, tmp_path, shards / "0" / "shard.json")


# -- Values without a rule --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "override",
    ["world.slip.factors.grass=-2", "world.slip.factors.grass=nan", "world.slip.patch_m=1e-4", "drive.other_vehicle.wheelbase_m=0",
     "world.vehicle.max_steering_deg=0", "predict.ros.camera_pitch_deg=nan", "ingest.footprint.camera_height_m=-1",
     "synthesize.test_worlds.horizon_m=-4"],
)  # fmt: skip
def test_values_without_meaning_are_refused_naming_the_key(override):
    key = override.split("=")[0].rsplit(".", 1)[0] if "factors" in override else override.split("=")[0]
    with pytest.raises(ConfigValueError, match=key.replace(".", r"\.")):
        validate_config(load_config(override))


@pytest.mark.parametrize(
    ("override", "says"),
    [("model.dice_weight=1e39", r"must be a number >= 0 in float32, the precision it is used in"),
     ("model.lr=1e-50", r"must be a number > 0 in float32"), ("steering.weight_decay=nan", r"must be a number >= 0"),
     ("steering.momentum=1.5", r"must be a number in \[0, 1\)"), ("steering.lr_gamma=0", r"must be a number in \(0, 1\]"),
     ("steering.lr_step_epochs=0", r"must be a number >= 1")],
)  # fmt: skip
def test_a_setting_that_is_no_number_in_float32_or_a_steering_rate_without_meaning_is_refused(override, says):
    """Finite in float64 is not enough: the losses and rates are float32. And every optimiser key of
    PilotNet has a rule, as the path networks' have."""
    key = override.split("=")[0]
    with pytest.raises(ConfigValueError, match=rf"^{key.replace('.', '[.]')}=.*{says}"):
        validate_config(load_config(override))


def test_a_run_stops_at_its_first_non_finite_loss_naming_the_loss_settings(compose_config, tiny_overrides):
    """A diverging run once trained to its end on an infinite loss and failed on a checkpoint's weight."""
    import torch
    from hydra.utils import instantiate

    from offroad_path.steering.pilotnet_task import SteeringTask

    task = instantiate(compose_config(*tiny_overrides).model, num_classes=2, channels_last=False, _convert_="all")
    image = torch.full((2, 3, 48, 64), float("nan"))
    with pytest.raises(InputError, match=r"^model\.dice_weight, model\.lr, model\.weight_decay: the training loss is nan at step 0"):
        task.training_step({"image": image, "target": torch.zeros(2, 48, 64, dtype=torch.long)}, 0)
    pilotnet = SteeringTask(width=200, height=66, lr=1e-4, lr_step_epochs=5, lr_gamma=0.5, momentum=0.9, weight_decay=0.0)
    with pytest.raises(InputError, match=r"^steering\.lr, steering\.momentum, steering\.weight_decay: the training loss is nan"):
        pilotnet.training_step({"image": torch.zeros(2, 3, 66, 200), "steering": torch.tensor([0.1, float("nan")])}, 0)


@pytest.mark.parametrize("weight", ["inf", "nan", "-1"])
def test_a_look_weight_that_is_no_weight_is_refused_naming_the_weights(weight):
    """Once "Probabilities contain NaN" from NumPy, naming no key, after the world had started."""
    with pytest.raises(ConfigValueError, match=r"^world\.appearance\.weights=.*weight >= 0"):
        validate_config(load_config(f"world.appearance.weights.track.dirt={weight}"))


@pytest.mark.parametrize("key", ["world.appearance.weights", "world.appearance.weights.track", "evaluate.conclusions.primaries"])
def test_an_empty_mapping_that_would_change_nothing_is_refused(key):
    """An override merges into a mapping: `{}` would leave the defaults in place without a word."""
    with pytest.raises(InputError, match=r"^" + re.escape(f"{key}: ={{}} changes nothing") + r".*" + re.escape(f"~{key}.<entry>")):
        load_config(f"{key}={{}}")


@pytest.mark.parametrize("value", ["2", "0", "yes"])
def test_a_number_for_a_true_false_setting_is_refused(value):
    """OmegaConf reads a number as a boolean: `model.batch_norm=2` once trained with batch norm."""
    with pytest.raises(InputError, match=r"^" + re.escape(f"model.batch_norm: takes true or false, not {value}")):
        load_config("model=fcn", f"model.batch_norm={value}")


def test_true_false_and_null_are_taken():
    assert [load_config("model=fcn", f"model.batch_norm={v}").model.batch_norm for v in ("true", "False", "null")] == [True, False, None]
    deleted = load_config("~evaluate.conclusions.primaries.postprocessing").evaluate.conclusions.primaries  # a deletion has no value
    assert "postprocessing" not in deleted


def test_an_axis_override_merges_and_a_deleted_entry_is_gone():
    """What the config comment documents: `track={ruts:1}` keeps the other tracks' weights; `~` drops one."""
    merged = load_config("world.appearance.weights.track={ruts:1}").world.appearance.weights.track
    assert merged.ruts == 1 and merged.dirt == 1
    primaries = load_config("~evaluate.conclusions.primaries.postprocessing").evaluate.conclusions.primaries
    assert "postprocessing" not in primaries and "central_claim" in primaries


# -- Outputs inside inputs ----------------------------------------------------------------------------


@pytest.mark.parametrize("where", ["split", "out_dir"])
def test_a_file_loggers_folder_may_not_be_an_input_or_the_runs_output(tiny_config, split_dir, tmp_path, capsys, where):
    save_dir = split_dir if where == "split" else tmp_path / "run" / "logs"
    cfg = tiny_config(tmp_path, "logger=csv", f"logger.save_dir={save_dir}", "mlflow.enabled=false")
    refused(train, cfg, capsys, tmp_path, "logger.save_dir", "overlaps")


def test_a_split_with_no_training_sample_is_refused_before_training(compose_config, tiny_config, split_dir, tmp_path, capsys):
    empty = tmp_path / "split"
    shutil.copytree(split_dir, empty)
    rows = (empty / "train.csv").read_text().splitlines()
    (empty / "train.csv").write_text(rows[0] + "\n")
    refused(
        train,
        tiny_config(tmp_path, f"data.split_dir={empty}", "mlflow.enabled=false"),
        capsys,
        tmp_path,
        empty / "train.csv",
        "no training sample",
    )


# -- The own-data recipe's evaluate -----------------------------------------------------------------


def test_evaluate_names_a_seed_that_was_not_trained(compose_config, trained, split_dir, labelled_drive, tmp_path, capsys):
    runs = tmp_path / "runs"
    (runs / "unet-none").mkdir(parents=True)
    (runs / "unet-none" / "seed0").symlink_to(trained[0].parents[1])  # trained; seed 1 is not
    cfg = compose_config(f"evaluate.runs_dir={runs}", f"evaluate.postprocessed_dir={tmp_path / 'pp'}", "evaluate.runs=[unet-none]",
                         "evaluate.seeds=[0,1]", f"evaluate.labels_dir={labelled_drive}", f"split.out_dir={split_dir}",
                         f"evaluate.out_dir={tmp_path / 'eval'}", f"evaluate.metrics_path={tmp_path / 'e.json'}",
                         f"evaluate.plots_dir={tmp_path / 'plots'}", "mlflow.enabled=false")  # fmt: skip
    refused(evaluate, cfg, capsys, tmp_path, "evaluate.seeds lists seed")


def test_evaluate_names_a_misspelt_primary(compose_config, tmp_path, capsys):
    """A run name no grid has: refused before any work, instead of a primary left not measured."""
    key = "evaluate.conclusions.primaries.postprocessing.compare"
    cfg = compose_config(f"{key}=uncertainty/fcn-none_vs_unet-nnoe", f"evaluate.out_dir={tmp_path / 'eval'}",
                         f"evaluate.metrics_path={tmp_path / 'e.json'}", f"evaluate.plots_dir={tmp_path / 'plots'}",
                         "mlflow.enabled=false")  # fmt: skip
    refused(evaluate, cfg, capsys, tmp_path, key, "'uncertainty/fcn-none_vs_unet-nnoe' is a comparison no run makes")


# -- Checked writes: a full disk is an error, never a success -------------------------------------

# No file may grow past {limit} bytes (RLIMIT_FSIZE): a write past it fails with EFBIG, as on a full disk.
LIMIT_WRITES = """
import resource, signal
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))
"""


def limited(limit: int, module: str, *args: str, cwd: Path) -> subprocess.CompletedProcess:
    """`python -m module args...` with writes limited as LIMIT_WRITES says."""
    script = (
        LIMIT_WRITES.format(limit=limit)
        + f"import runpy, sys\nsys.argv = {[module, *args]!r}\nrunpy.run_module({module!r}, run_name='__main__')\n"
    )
    return subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=cwd)


@pytest.mark.slow(seconds=6)
def test_predict_onto_a_full_disk_fails_in_one_line_and_leaves_nothing(trained, frames_folder, tmp_path):
    out = tmp_path / "out"
    run = limited(8192, "offroad_path.predict", f"predict.checkpoint={trained[0]}", f"predict.input={frames_folder}",
                  f"predict.out_dir={out}", "mlflow.enabled=false", cwd=tmp_path)  # fmt: skip
    assert run.returncode == 2, run.stderr[-1500:]
    errors = [line for line in run.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and ".png" in errors[0] and "could not be written" in errors[0], run.stderr[-1500:]
    assert not out.exists() and not [p for p in tmp_path.iterdir() if p.name.startswith(".out")]


def test_ingest_onto_a_full_disk_fails_in_one_line_and_leaves_nothing(drive, rig, raw_drive, tmp_path):
    """Once an AttributeError traceback from the epipolar check; then checked by hand only."""
    from raw_rig import write_bag

    bag = write_bag(tmp_path / "drive_mcap", "mcap", raw_drive[:6], rig)
    meta = json.loads((drive / "drive" / "meta.json").read_text())
    out = tmp_path / "ingested" / "drive"
    run = limited(65536, "offroad_path.ingest", f"ingest.bag={bag}", "ingest.topics.left=/stereo/left/image_raw",
                  "ingest.topics.right=/stereo/right/image_raw", f"ingest.out_dir={out}", "mlflow.enabled=false",
                  f"ingest.footprint.width_m={meta['vehicle_width_m']}", f"ingest.footprint.front_m={meta['footprint_front_m']}",
                  f"ingest.footprint.rear_m={meta['footprint_rear_m']}", f"ingest.footprint.camera_height_m={meta['camera_height_m']}",
                  f"ingest.footprint.camera_pitch_deg={meta['camera_pitch_deg']}", cwd=tmp_path)  # fmt: skip
    assert run.returncode == 2, run.stderr[-1500:]
    errors = [line for line in run.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and ".png" in errors[0] and "could not be written" in errors[0], run.stderr[-1500:]
    assert "Traceback" not in run.stderr
    assert not out.exists()
    assert not (tmp_path / "ingested").exists() or not list((tmp_path / "ingested").iterdir())  # no partial or temporary folder


@pytest.mark.slow(seconds=5)
def test_label_onto_a_full_disk_fails_in_one_line_naming_the_file_and_leaves_nothing(drive, tmp_path):
    """Once an error naming no file (the worker's OSError lost its path on the way back)."""
    out, metrics = tmp_path / "labels", tmp_path / "label.json"
    run = limited(1024, "offroad_path.label", f"label.in_dir={drive}", f"label.out_dir={out}", f"label.metrics_path={metrics}",
                  "label.workers=1", "mlflow.enabled=false", cwd=tmp_path)  # fmt: skip
    assert run.returncode == 2, run.stderr[-1500:]
    errors = [line for line in run.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and str(tmp_path) in errors[0] and "could not be written" in errors[0], run.stderr[-1500:]
    assert "Traceback" not in run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no labels, no metrics, no temporary folder


def test_inspect_onto_a_full_disk_fails_in_one_line_and_leaves_nothing(labelled_drive, drive, tmp_path):
    """Rerun's writer fails in a thread of its own: once a RuntimeError traceback, then not tested."""
    out = tmp_path / "inspected"
    args = (str(labelled_drive), "--recording", str(drive), "--out", str(out))
    run = limited(100_000, "offroad_path.label.inspect", *args, cwd=tmp_path)
    assert run.returncode == 2, run.stderr[-1500:]
    errors = [line for line in run.stderr.splitlines() if line.startswith("error: ")]
    assert len(errors) == 1 and errors[0].startswith(f"error: {out / 'drive.rrd'}: the recording could not be written"), run.stderr[-1500:]
    assert "Traceback" not in run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # no output, no temporary folder


def test_a_video_that_does_not_hold_every_frame_is_an_error(tmp_path):
    script = (
        "import numpy as np\nfrom offroad_path.utils.media import VideoFile\n"
        f"with VideoFile({str(tmp_path / 'v.mp4')!r}, 10, (320, 240)) as v:\n"
        "    for i in range(60):\n        v.write(np.random.default_rng(i).integers(0, 255, (240, 320, 3), dtype=np.uint8))\n"
    )
    full = subprocess.run([sys.executable, "-c", LIMIT_WRITES.format(limit=16384) + script], capture_output=True, text=True)
    assert full.returncode == 1 and "v.mp4" in full.stderr and "frames readable" in full.stderr, full.stderr[-800:]
    ok = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr[-800:]


# -- label.inspect ------------------------------------------------------------------------------


def inspect_cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return command("offroad_path.label.inspect", *args, cwd=cwd)


def test_inspect_refuses_bad_arguments_and_outputs_inside_its_inputs(labelled_drive, drive, tmp_path):
    before = snapshot(labelled_drive)
    for args, says in (
        (["--points-every", "-2"], "not a whole number >= 1"),
        (["--out", labelled_drive / "inspect"], "overlaps the input"),
        (["--recording", drive, "--out", drive / "drive" / "inspect"], "overlaps the input"),
    ):
        run = inspect_cli(labelled_drive, *args, cwd=tmp_path)
        assert run.returncode == 2 and run.stderr.count("error: ") == 1 and says in run.stderr, run.stderr[-800:]
    assert snapshot(labelled_drive) == before


def test_inspect_refuses_a_recording_shorter_than_its_labels(labelled_drive, drive, tmp_path):
    short = tmp_path / "recording"
    shutil.copytree(drive, short)
    for sub in ("image_l", "image_r", "depth", "semantic"):  # the first 10 of its 40 frames
        for png in sorted((short / "drive" / sub).glob("*.png"))[10:]:
            png.unlink()
    for name, header in (("poses.txt", 0), ("times.txt", 0), ("steering.txt", 0), ("conditions.csv", 1)):
        rows = (short / "drive" / name).read_text().splitlines()
        (short / "drive" / name).write_text("\n".join(rows[: header + 10]) + "\n")
    run = inspect_cli(labelled_drive, "--recording", short, "--out", tmp_path / "out", cwd=tmp_path)
    assert run.returncode == 2 and "fewer than the" in run.stderr, run.stderr[-800:]


@pytest.mark.slow(seconds=10)
def test_inspect_stopped_by_sigterm_leaves_no_temporary_folder(labelled_drive, drive, tmp_path):
    pytest.importorskip("rerun")
    command = [
        sys.executable,
        "-m",
        "offroad_path.label.inspect",
        str(labelled_drive),
        "--recording",
        str(drive),
        "--out",
        str(tmp_path / "out"),
    ]
    process = subprocess.Popen(command, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".out.tmp-*/*.rrd")) and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.05)
    assert process.poll() is None, "inspect ended before it could be stopped"
    os.kill(process.pid, signal.SIGTERM)
    assert process.wait(30) == 128 + signal.SIGTERM
    assert sorted(p.name for p in tmp_path.iterdir()) == []


# -- Calibration views --------------------------------------------------------------------------------


def test_calibrate_refuses_a_decompression_bomb_among_its_views(tmp_path):
    from offroad_path.errors import InputError
    from offroad_path.recordings.boards import read_view

    bomb = png_declaring(tmp_path / "view.png", 40000, 40000)
    with pytest.raises(InputError, match="declares 40000x40000"):
        read_view(bomb)


# -- Bags and label runs given to the wrong place -----------------------------------------------------


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_the_stereo_pair_of_a_bag_is_found_from_its_camera_infos(raw_drive, rig, tmp_path, kind):
    pytest.importorskip("rosbags")
    from raw_rig import write_bag

    from offroad_path.recordings.bags import Bag

    bag = write_bag(tmp_path / ("drive.bag" if kind == "ros1" else "drive_mcap"), kind, raw_drive[:3], rig)
    with Bag(bag) as opened:  # ROS 1's CameraInfo spells the projection P, ROS 2's p
        assert opened.stereo_pair() == ("/stereo/left/image_raw", "/stereo/right/image_raw")


@pytest.mark.slow(seconds=7)
def test_evaluate_names_a_label_run_that_is_not_the_splits(compose_config, trained, split_dir, recordings, tmp_path, capsys):
    other = tmp_path / "other_labels"  # a label run of another recording name than the split's
    label(label_cfg(compose_config, recordings, tmp_path, f"label.out_dir={other}", "mlflow.enabled=false"))
    shutil.move(other / "drive", other / "field")
    summary = json.loads((other / "summary.json").read_text())
    summary["sequences"][0]["name"] = "field"
    (other / "summary.json").write_text(json.dumps(summary))
    runs = tmp_path / "runs"
    (runs / "unet-none").mkdir(parents=True)
    (runs / "unet-none" / "seed0").symlink_to(trained[0].parents[1])
    pp = tmp_path / "pp" / "unet-none"
    pp.mkdir(parents=True)
    (pp / "seed0").symlink_to(trained[0].parents[1] / "predictions")
    cfg = compose_config(f"evaluate.runs_dir={runs}", f"evaluate.postprocessed_dir={tmp_path / 'pp'}", "evaluate.runs=[unet-none]",
                         "evaluate.seeds=[0]", f"evaluate.labels_dir={other}", f"split.out_dir={split_dir}",
                         f"evaluate.out_dir={tmp_path / 'eval'}", f"evaluate.metrics_path={tmp_path / 'e.json'}",
                         f"evaluate.plots_dir={tmp_path / 'plots'}", "mlflow.enabled=false", "evaluate.temporal.enabled=false")  # fmt: skip
    refused(evaluate, cfg, capsys, tmp_path, other, "holds no sequence drive of the test manifest")


@pytest.mark.parametrize(
    ("override", "key"),
    [("render.device=bogus", "render.device"), ("drive.device=bogus", "drive.device"), ("drive.device=''", "drive.device"),
     ("drive.device=3", "drive.device"), ("render.device=cuda:99", "render.device"), ("trainer.accelerator=tpu", "trainer.accelerator")],
)  # fmt: skip
def test_a_device_torch_cannot_parse_or_this_machine_lacks_is_refused_before_any_work(override, key):
    """Not 12-118 s in with a torch traceback: one line naming the key and what the machine has."""
    import torch

    with pytest.raises(ConfigValueError, match=rf"^{key.replace('.', '[.]')}=.*: must be auto or .* this machine has: cpu") as found:
        validate_config(load_config(override))
    assert len(str(found.value).splitlines()) == 1
    if not torch.cuda.is_available():  # a GPU this machine lacks, named as what it has
        for missing in ("render.device=cuda", "drive.device=cuda", "trainer.accelerator=gpu"):
            with pytest.raises(ConfigValueError, match=r"this machine has: cpu"):
                validate_config(load_config(missing))
    validate_config(load_config("render.device=cpu", "drive.device=auto", "trainer.accelerator=auto"))
