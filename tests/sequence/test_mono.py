"""Recordings of one camera: a folder without right images is a mono sequence, labelled
from its poses exactly as a stereo one with occlusion off; what needs stereo refuses it in one line."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import command

from offroad_path.errors import InputError
from offroad_path.label import label
from offroad_path.label.labeller import measured_depth
from offroad_path.sequence import open_sequence

KITTI00_MONO = Path(__file__).resolve().parents[3] / "shared" / "data" / "kitti00_mono"


def mono_copy(drive: Path, into: Path, one_row: bool = False) -> Path:
    """The test drive without its right images (and with only the left calibration row when one_row)."""
    shutil.copytree(drive, into, ignore=shutil.ignore_patterns("image_r"))
    if one_row:
        calib = into / "drive" / "calib.txt"
        calib.write_text(calib.read_text().splitlines()[0] + "\n")
    return into


def label_config(compose_config, in_dir: Path, out: Path, *overrides: str):
    return compose_config(
        f"label.in_dir={in_dir}", f"label.out_dir={out / 'labels'}", f"label.metrics_path={out / 'label.json'}",
        "label.workers=1", "label.poses.source=file", "mlflow.enabled=false", *overrides,
    )  # fmt: skip


def test_a_folder_without_right_images_opens_as_one_camera(drive, tmp_path):
    mono = open_sequence(mono_copy(drive, tmp_path / "mono", one_row=True) / "drive")
    stereo = open_sequence(drive / "drive")
    assert mono.mono and not stereo.mono and mono.right is None
    assert len(mono) == len(stereo) == 40 and mono.image_size == stereo.image_size
    np.testing.assert_array_equal(mono.calibration.K, stereo.calibration.K)  # from the one row
    assert mono.calibration.baseline_m == 0.0
    np.testing.assert_array_equal(mono.load_left(3), stereo.load_left(3))
    with pytest.raises(InputError, match=r"/drive: has one camera \(no right images\): the right image needs a stereo pair"):
        mono.load_right(3)


def test_the_sequence_command_accepts_a_mono_recording(drive, tmp_path):
    recordings = [mono_copy(drive, tmp_path / "mono") / "drive"]
    recordings += [KITTI00_MONO] if (KITTI00_MONO / "calib.txt").is_file() else []  # the real one, where shared/ has it
    run = command("offroad_path.sequence", *recordings)
    assert run.returncode == 0, run.stderr
    lines = run.stdout.strip().splitlines()
    assert len(lines) == len(recordings)
    assert lines[0].startswith(f"{recordings[0]}: 40 frames of one camera (mono: labelled from poses, without occlusion) 512x288")
    if len(recordings) == 2:
        assert lines[1].startswith(f"{KITTI00_MONO}: 160 frames of one camera") and "117.2 m of poses" in lines[1]


@pytest.mark.slow(seconds=4)
def test_mono_labels_equal_stereo_labels_with_occlusion_off(compose_config, drive, tmp_path, caplog):
    """The same drive labelled from the same poses: without its right images, and with them but
    occlusion off. Every label is the same pixels; only the disparity is missing."""
    mono_in = mono_copy(drive, tmp_path / "mono_in")
    with caplog.at_level(logging.WARNING, logger="offroad_path.label"):
        metrics = label(label_config(compose_config, mono_in, tmp_path / "mono"))  # occlusion on: it cannot apply, and says so
    label(label_config(compose_config, drive, tmp_path / "stereo", "label.occlusion.enabled=false"))
    mono, stereo = tmp_path / "mono" / "labels" / "drive", tmp_path / "stereo" / "labels" / "drive"
    names = sorted(p.name for p in (stereo / "label").iterdir())
    assert len(names) >= 8 and names == sorted(p.name for p in (mono / "label").iterdir())
    for name in names:
        np.testing.assert_array_equal(cv2.imread(str(mono / "label" / name)), cv2.imread(str(stereo / "label" / name)), err_msg=name)
    assert (mono / "report.csv").read_text() == (stereo / "report.csv").read_text()
    assert (stereo / "disparity").is_dir() and not (mono / "disparity").exists()
    assert (mono / "poses.txt").read_text() == (stereo / "poses.txt").read_text()  # the poses the labels were made from
    assert metrics["one_camera_sequences"] == 1 and metrics["labels"] == len(names)
    assert json.loads((tmp_path / "mono" / "labels" / "summary.json").read_text())["sequences"][0]["one_camera"] is True
    said = [r.getMessage() for r in caplog.records if "one camera" in r.getMessage()]
    assert said == ["1 of 1 sequences have one camera: labelled from their poses without occlusion and disparity (they need a right image)"]


def test_the_split_of_a_mono_recording_has_no_disparity(compose_config, drive, tmp_path):
    from offroad_path.data.manifest import read_manifest
    from offroad_path.split import split

    label(label_config(compose_config, mono_copy(drive, tmp_path / "mono_in"), tmp_path))
    split(
        compose_config(
            f"split.labels_dir={tmp_path / 'labels'}", f"split.out_dir={tmp_path / 'split'}", "split.block_m=2", "split.guard_m=0"
        )
    )
    samples = [s for part in ("train", "val", "test") for s in read_manifest(tmp_path / "split" / f"{part}.csv", check_files=True)]
    assert samples and all(s.disparity == "" for s in samples)


def one_line_error(arguments: list[str]) -> str:
    run = command(*arguments, "mlflow.enabled=false")
    assert run.returncode == 2, run.stderr
    assert not run.stdout.strip()
    (line,) = run.stderr.strip().splitlines()
    return line


def test_what_needs_stereo_refuses_a_mono_recording_in_one_line(compose_config, drive, tmp_path):
    mono_in = mono_copy(drive, tmp_path / "mono_in")
    out = [f"label.in_dir={mono_in}", f"label.out_dir={tmp_path / 'labels'}", f"label.metrics_path={tmp_path / 'm.json'}"]
    line = one_line_error(["offroad_path.label", *out])  # the default poses: stereo visual odometry
    assert line == (
        f"error: {mono_in / 'drive'}: has one camera (no right images): the stereo odometry "
        "(label.poses.source=vo; give poses.txt and label.poses.source=file) needs a stereo pair"
    )
    assert not (tmp_path / "labels").exists()
    seq = open_sequence(mono_in / "drive")
    occlusion = compose_config().label.occlusion
    with pytest.raises(InputError, match=r"has one camera .*: occlusion from stereo depth .* needs a stereo pair"):
        measured_depth(seq, 0, None, occlusion)
    from offroad_path.config.label_schema import OdometryConfig
    from offroad_path.odometry.sequence_trajectory import run_odometry

    with pytest.raises(InputError, match="the stereo odometry and its disparity offset needs a stereo pair"):
        run_odometry(seq, OdometryConfig(**compose_config().label.odometry))


def test_postprocessing_refuses_the_depth_mask_without_stereo_and_runs_without_it(compose_config, drive, tmp_path, caplog):
    from offroad_path.data.manifest import Sample, read_predictions_manifest, write_predictions_manifest
    from offroad_path.postprocess import run_postprocess

    predictions = tmp_path / "predictions"
    (predictions / "drive").mkdir(parents=True)
    rows = []
    for f0 in (0, 5):
        confidence = np.zeros((36, 64), np.float16)
        confidence[20:, 24:40] = 0.9
        np.save(predictions / "drive" / f"{f0:06d}.npy", confidence)
        sample = Sample("drive", f0, False, str(drive / "drive" / "image_l" / f"{f0:06d}.png"), "unused.png", "", "", 700.0, 0.0)
        rows.append((sample, str(predictions / "drive" / f"{f0:06d}.npy")))
    write_predictions_manifest(predictions / "manifest.csv", rows)
    out = tmp_path / "postprocessed"
    settings = [f"postprocess.predictions_dir={predictions}", f"postprocess.out_dir={out}"]
    line = one_line_error(["offroad_path.postprocess", *settings])
    assert line == (
        f"error: {predictions / 'manifest.csv'}: drive has no disparity (a recording of one camera): the depth mask needs stereo; "
        "postprocess.use_depth=false post-processes without it"
    )
    assert not out.exists()
    with caplog.at_level(logging.INFO, logger="offroad_path.postprocess"):
        assert run_postprocess(compose_config(*settings, "postprocess.use_depth=false", "mlflow.enabled=false")) == 2
    assert any("without the depth mask (postprocess.use_depth=false)" in r.getMessage() for r in caplog.records)
    filtered = np.load(read_predictions_manifest(out / "manifest.csv", "postprocess")[0][1])
    assert filtered.shape == (36, 64) and filtered[28, 32] > 0.5 and filtered[2, 2] == 0  # blurred, thresholded, no depth cut


def test_the_report_says_which_test_images_were_post_processed_without_the_depth_mask():
    from types import SimpleNamespace

    from offroad_path.data.manifest import Sample
    from offroad_path.evaluate.sections import ResultsTable

    def sample(disparity: str) -> Sample:
        return Sample("drive", 0, False, "image.png", "label.png", disparity, "", 700.0, 0.0)

    counts = {("unet-none", "no"): np.array([[1.0, 1, 1, 1]]), ("unet-none", "yes"): np.array([[2.0, 1, 1, 0]])}  # tp fp tn fn
    said = "2 of 3 test images come from a recording of one camera: post-processed without the depth mask"
    table = ResultsTable()
    table.score(SimpleNamespace(runs=["unet-none"], samples=[sample(""), sample(""), sample("d.png")], counts=counts))
    assert said in table.markdown()
    assert "| U-Net | none | no | 0.500 | 0.500 | 0.500 | 0.333 |" in table.markdown()  # tp 1, fp 1, fn 1: IoU 1/3
    table.score(SimpleNamespace(runs=["unet-none"], samples=[sample("d.png")] * 3, counts=counts))
    assert "one camera" not in table.markdown()


def test_a_mono_label_run_decodes_its_images_and_names_a_broken_one(compose_config, drive, tmp_path):
    mono_in = mono_copy(drive, tmp_path / "mono_in")
    image = mono_in / "drive" / "image_l" / "000000.png"
    image.write_bytes(image.read_bytes()[:2000])  # truncated: the header and a little of the data
    with pytest.raises(InputError, match=r"image_l/000000.png: cannot be decoded as an image"):
        label(label_config(compose_config, mono_in, tmp_path, "label.occlusion.enabled=false"))
    assert not (tmp_path / "labels").exists() and not (tmp_path / "label.json").exists()
