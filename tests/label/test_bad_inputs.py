"""Bad input: worker failures, config values, recordings that give nothing or lie about their
size, silent gaps. Each case exits 2 with one line naming the file or the key, and leaves every file
under the test's folder as it was (hashed before and after)."""

from __future__ import annotations

import os
import pickle
import shutil
import subprocess
import sys
import uuid
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import command, label_cfg, png_declaring, refused, snapshot, tagged_processes

from offroad_path.label import label
from offroad_path.postprocess import run_postprocess
from offroad_path.predict import run_predict
from offroad_path.pretrain import pretrain
from offroad_path.train import train
from offroad_path.utils.atomic import write_text_atomic

ROOT = Path(__file__).resolve().parents[2]


# -- 3. Worker processes: errors reach the parent, nothing hangs ------------------------------------


def two_sequences(recordings: Path) -> Path:
    shutil.copytree(recordings / "drive", recordings / "drive_b")
    return recordings


@pytest.mark.slow(seconds=4)
def test_a_worker_error_reaches_the_parent_instead_of_hanging(recordings, tmp_path):
    two_sequences(recordings)
    frame = recordings / "drive_b" / "image_l" / "000020.png"
    frame.write_bytes(frame.read_bytes()[:300])  # truncated: found only when the worker decodes it
    before = snapshot(tmp_path)
    cli = [sys.executable, "-m", "offroad_path.label", f"label.in_dir={recordings}", f"label.out_dir={tmp_path / 'labels'}",
           f"label.metrics_path={tmp_path / 'm.json'}", "label.workers=2", "mlflow.enabled=false"]  # fmt: skip
    tag = uuid.uuid4().hex
    run = subprocess.run(cli, capture_output=True, text=True, timeout=300, env={**os.environ, "OFFROAD_TEST_TAG": tag})
    assert run.returncode == 2, run.stderr
    assert run.stderr.strip().splitlines()[-1] == f"error: {frame}: cannot be decoded as an image"
    assert snapshot(tmp_path) == before
    assert not tagged_processes(tag)  # the other worker was stopped, not orphaned


@pytest.mark.parametrize(
    ("damage", "named"),
    [
        (lambda r: (r / "drive_b" / "meta.json").unlink(), "meta.json"),
        (lambda r: (r / "drive_b" / "poses.txt").unlink(), "poses.txt"),
    ],
    ids=["no meta.json", "no poses for source=file"],
)
def test_missing_recording_files_are_found_before_any_work(compose_config, recordings, tmp_path, capsys, damage, named):
    two_sequences(recordings)
    damage(recordings)
    cfg = label_cfg(compose_config, recordings, tmp_path, "label.workers=2", "label.poses.source=file")
    refused(label, cfg, capsys, tmp_path, recordings / "drive_b", named)


# -- 4. Config values checked before any work, naming the key ---------------------------------------

BAD_VALUES = [
    ("label.stride_m=0", "label.stride_m"),
    ("label.distance_m=0", "label.distance_m"),
    ("label.distance_m=-5", "label.distance_m"),
    ("label.strategy=midwya", "must be one of: midway, stride"),
    ("label.disparity.num_disparities=50", "label.disparity.num_disparities"),
    ("label.poses.source=gps", "label.poses.source"),
    ("postprocess.sigma=-5", "postprocess.sigma"),
    ("postprocess.sigma=nan", "postprocess.sigma"),
    ("postprocess.sigma=1e9", "postprocess.sigma"),
    ("postprocess.delta=1.5", "postprocess.delta"),
    ("data.batch_size=-1", "data.batch_size"),
    ("data.width=0", "data.width"),
    ("trainer.max_epochs=0", "trainer.max_epochs"),
    ("model.name=resnet", "must be one of: fcn, segnet, unet"),
    ("predict.threshold=2", "predict.threshold"),
    ("world.fps=0", "world.fps"),
    ("split.test_fraction=1.5", "split.test_fraction"),
    ("evaluate.threshold=-0.1", "evaluate.threshold"),
]


@pytest.mark.parametrize(("override", "named"), BAD_VALUES, ids=[o for o, _ in BAD_VALUES])
@pytest.mark.slow(seconds=7)
def test_bad_values_are_refused_before_any_work(compose_config, tmp_path, capsys, override, named):
    ran = []
    cfg = compose_config(override, f"label.out_dir={tmp_path / 'labels'}")
    refused(ran.append, cfg, capsys, tmp_path, override.split("=")[0], named)
    assert not ran


# -- 5. Recordings that yield nothing, or lie about their size -------------------------------------


def black_out(recordings: Path) -> None:
    for side in ("image_l", "image_r"):
        for frame in (recordings / "drive" / side).glob("*.png"):
            cv2.imwrite(str(frame), np.zeros((288, 512, 3), np.uint8))


def keep_frames(recordings: Path, n: int) -> None:
    root = recordings / "drive"
    for folder in ("image_l", "image_r", "depth", "semantic"):
        for frame in sorted((root / folder).glob("*.png"))[n:]:
            frame.unlink()
    for name in ("poses.txt", "times.txt", "steering.txt"):
        (root / name).write_text("".join((root / name).read_text().splitlines(True)[:n]))


def standing_still(recordings: Path) -> None:
    root = recordings / "drive"
    for folder in ("image_l", "image_r", "depth", "semantic"):
        first = (root / folder / "000000.png").read_bytes()
        for frame in (root / folder).glob("*.png"):
            frame.write_bytes(first)
    first_pose = (root / "poses.txt").read_text().splitlines()[0]
    (root / "poses.txt").write_text((first_pose + "\n") * 40)


@pytest.mark.parametrize(
    ("damage", "says"),
    [(black_out, "odometry steps failed"), (lambda r: keep_frames(r, 2), "over 2 frames"), (standing_still, "never gets 20 m")],
    ids=["all black", "two frames", "standing still"],
)
def test_a_recording_that_gives_no_label_says_why_and_writes_nothing(compose_config, recordings, tmp_path, capsys, damage, says):
    damage(recordings)
    write_text_atomic(tmp_path / "m.json", '{"labels": 374}\n', "label")  # the last good run's metrics stay
    refused(label, label_cfg(compose_config, recordings, tmp_path), capsys, tmp_path, recordings, "no label could be made", says)


def test_predict_refuses_a_decompression_bomb_from_its_header(compose_config, trained, frames_folder, tmp_path, capsys):
    bomb = png_declaring(frames_folder / "000001.png", 30000, 30000)
    cfg = compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={frames_folder}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, bomb, "30000x30000")


def test_predict_refuses_an_image_too_small_to_be_a_cameras_view(compose_config, trained, frames_folder, tmp_path, capsys):
    """A 1 x 1 image was once scored as a path: under 32 pixels on a side is no camera's view."""
    import cv2

    tiny = frames_folder / "000001.png"
    cv2.imwrite(str(tiny), np.zeros((1, 1, 3), np.uint8))
    cfg = compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={frames_folder}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, tiny, "is 1x1 pixels: a camera image has at least 32 on each side")


def test_label_refuses_a_decompression_bomb_in_a_recording(compose_config, recordings, tmp_path, capsys):
    bomb = png_declaring(recordings / "drive" / "image_l" / "000000.png", 30000, 30000)
    refused(label, label_cfg(compose_config, recordings, tmp_path), capsys, tmp_path, bomb, "30000x30000")


def test_predict_names_an_undecodable_image(compose_config, trained, frames_folder, tmp_path, capsys):
    (frames_folder / "000001.png").write_bytes(b"\x89PNG\r\n\x1a\n garbage")
    cfg = compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={frames_folder}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, frames_folder / "000001.png")


# -- 6. Silent gaps made loud -------------------------------------------------------------------------


def test_a_recording_without_calibration_beside_good_ones(compose_config, recordings, tmp_path, capsys):
    two_sequences(recordings)
    (recordings / "drive_b" / "calib.txt").unlink()
    refused(label, label_cfg(compose_config, recordings, tmp_path), capsys, tmp_path, recordings / "drive_b" / "calib.txt", "is missing")


def test_the_checker_decodes_every_frame(recordings):
    frame = recordings / "drive" / "image_r" / "000017.png"
    frame.write_bytes(frame.read_bytes()[:400])
    run = command("offroad_path.sequence", recordings)
    assert run.returncode == 2 and run.stderr.strip() == f"error: {frame}: cannot be decoded as an image"


def copy_split(split_dir: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "split"
    shutil.copytree(split_dir, copy)
    return copy


def test_a_manifest_listing_a_missing_file_fails_before_training(tiny_config, split_dir, tmp_path, capsys):
    split_copy = copy_split(split_dir, tmp_path)
    test_csv = split_copy / "test.csv"
    rows = test_csv.read_text().splitlines()
    label = rows[1].split(",")[4]
    missing = Path(label).parent / "gone.png"  # beside the labels, inside the data root
    rows[1] = rows[1].replace(label, str(missing))
    test_csv.write_text("\n".join(rows) + "\n")
    cfg = tiny_config(tmp_path, f"data.split_dir={split_copy}", "mlflow.enabled=false")
    refused(train, cfg, capsys, tmp_path, test_csv, "row 2", str(missing), "does not exist")


def test_a_manifest_row_outside_the_data_root_is_refused(tiny_config, split_dir, tmp_path, capsys):
    split_copy = copy_split(split_dir, tmp_path)
    train_csv = split_copy / "train.csv"
    rows = train_csv.read_text().splitlines()
    image = rows[1].split(",")[3]
    rows[1] = rows[1].replace(image, image.split("/recordings/")[0] + "/../../../../../../etc/passwd")
    train_csv.write_text("\n".join(rows) + "\n")
    refused(pretrain, tiny_config(tmp_path, f"data.split_dir={split_copy}", "mlflow.enabled=false"), capsys, tmp_path, train_csv,
            "outside the data root")  # fmt: skip


def test_a_predictions_manifest_pointing_outside_its_folder(compose_config, trained, tmp_path, capsys):
    predictions = tmp_path / "predictions"
    shutil.copytree(trained[0].parents[1] / "predictions", predictions)
    manifest = predictions / "manifest.csv"
    rows = manifest.read_text().splitlines()
    rows[1] = ",".join([*rows[1].split(",")[:-1], "/etc/passwd"])
    manifest.write_text("\n".join(rows) + "\n")
    cfg = compose_config(f"postprocess.predictions_dir={predictions}", f"postprocess.out_dir={tmp_path / 'pp'}")
    refused(run_postprocess, cfg, capsys, tmp_path, manifest, "outside")


def test_the_sequence_error_survives_pickling():
    from offroad_path.errors import InputError

    error = pickle.loads(pickle.dumps(InputError("/a/b.png", "is broken")))
    assert isinstance(error, InputError) and str(error) == "/a/b.png: is broken" and error.problem == "is broken"


def test_the_cli_runs_the_same_checks(tmp_path):
    run = command("offroad_path.label", "label.stride_m=0", f"label.out_dir={tmp_path / 'x'}", cwd=ROOT)
    assert run.returncode == 2 and run.stderr.strip() == "error: label.stride_m=0.0: must be a number >= 0.05"
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize(
    "overrides,named",
    [
        (["label.strategy=stride", "label.stride_m=1e-9"], ["label.stride_m=1e-09", ">= 0.05"]),
        (["label.strategy=stride", "label.stride_m=25"], ["label.stride_m=25", "at most label.distance_m (20)"]),
        (["label.footprint.width_m=-1.9"], ["label.footprint.width_m=-1.9", "must be a number > 0"]),
        (["label.footprint.front_m=-3"], ["label.footprint.front_m", "must lie ahead of the vehicle's rear"]),
    ],
    ids=["stride too short", "stride beyond D", "negative width", "front behind rear"],
)
def test_label_values_out_of_their_real_bounds(compose_config, recordings, tmp_path, capsys, overrides, named):
    refused(label, label_cfg(compose_config, recordings, tmp_path, *overrides), capsys, tmp_path, *named)


@pytest.mark.slow(seconds=5)
def test_a_dense_stride_writes_every_label_it_counts(compose_config, recordings, tmp_path):
    metrics = label(label_cfg(compose_config, recordings, tmp_path, "label.strategy=stride", "label.stride_m=0.05"))
    assert metrics["labels"] == len(list((tmp_path / "labels").glob("*/label/*.png"))) > 0
