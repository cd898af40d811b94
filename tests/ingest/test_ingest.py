"""The ingest stage on real inputs written here: ROS 1, ROS 2 (SQLite, MCAP) bags and two MP4 files
of a raw rig (own K and distortion per camera, the right one rotated) that recorded the rendered
test drive. Ingest must give back what the render knows: rectified images, poses and labels."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from raw_rig import body_poses, write_bag, write_videos

from offroad_path.errors import InputError
from offroad_path.ingest import ingest
from offroad_path.label import label
from offroad_path.recordings.rectify import Rectifier
from offroad_path.recordings.rig_calibration import CameraModel, StereoRig, rig_from_camera_infos, write_opencv
from offroad_path.sequence.reader import open_sequence

LEFT, RIGHT = "/stereo/left/image_raw", "/stereo/right/image_raw"


@pytest.fixture(scope="module")
def frames(raw_drive):
    return raw_drive


@pytest.fixture(scope="module")
def footprint(drive) -> list[str]:
    """The rendered vehicle, as a user gives it on the command line."""
    meta = json.loads((drive / "drive" / "meta.json").read_text())
    keys = {"width_m": "vehicle_width_m", "front_m": "footprint_front_m", "rear_m": "footprint_rear_m"}
    keys |= {"camera_height_m": "camera_height_m", "camera_pitch_deg": "camera_pitch_deg"}
    return [f"ingest.footprint.{key}={meta[meta_key]}" for key, meta_key in keys.items()]


def ingest_config(compose_config, source: list[str], out: Path, *overrides: str):
    return compose_config(*source, f"ingest.out_dir={out}", *overrides)


def bag_source(bag: Path, compressed: tuple[bool, bool] = (False, False), odometry: bool = True) -> list[str]:
    topics = [t + ("/compressed" if c else "") for t, c in zip((LEFT, RIGHT), compressed, strict=True)]
    return [f"ingest.bag={bag}", f"ingest.topics.left={topics[0]}", f"ingest.topics.right={topics[1]}"] + (
        ["ingest.topics.odometry=/odom"] if odometry else []
    )


@pytest.fixture(scope="module")
def ingested(compose_config, drive, rig, frames, footprint, tmp_path_factory) -> Path:
    """The test drive recorded by the raw rig into a ROS 2 (MCAP) bag with raw left, PNG-compressed
    right images and /odom, then ingested: a folder holding the one sequence."""
    root = tmp_path_factory.mktemp("ingest")
    bag = write_bag(root / "drive_mcap", "mcap", frames, rig, compressed=(False, True), poses=body_poses(drive / "drive"))
    ingest(ingest_config(compose_config, bag_source(bag, (False, True)), root / "sequences" / "drive", *footprint))
    return root / "sequences"


def render_to_rectified(drive: Path, rig) -> np.ndarray:
    """The homography from a rendered left pixel to the rectified left pixel: both cameras share a
    centre, so K_rect R_left K_render^-1 maps every ray exactly."""
    rectifier = Rectifier(rig_from_camera_infos(*rig.camera_infos(), drive), rig.size, rig.size, 0.0)
    return rectifier.calibration.K @ rectifier.R_left @ np.linalg.inv(rig.K_render)


def test_a_bag_becomes_the_rectified_render(drive, rig, ingested):
    seq, render = open_sequence(ingested / "drive"), open_sequence(drive / "drive")
    assert len(seq) == len(render) and seq.image_size == render.image_size
    assert seq.calibration.baseline_m == pytest.approx(render.calibration.baseline_m, rel=1e-6)
    H = render_to_rectified(drive, rig)
    for i in (0, 20, 39):  # the rectified image is the render seen through the rectified camera
        expected = cv2.warpPerspective(cv2.imread(str(render.left[i])), H, seq.image_size)
        assert np.abs(expected.astype(int) - cv2.imread(str(seq.left[i]))).mean() < 2.0
    meta = json.loads((ingested / "drive" / "meta.json").read_text())
    assert meta["epipolar_error_px"] < 0.1
    assert meta["sync"] == {"left_messages": 40, "right_messages": 40, "pairs": 40, "unpaired": 0, "worst_gap_ms": 0.0}
    assert np.loadtxt(ingested / "drive" / "times.txt") == pytest.approx(np.arange(40) / 5.0, abs=1e-6)
    assert (ingested / "drive" / "preview.jpg").is_file()


def test_odometry_topic_becomes_rectified_camera_poses(drive, rig, ingested):
    """poses.txt holds the rectified left camera: the render's camera turned by R_left."""
    rectifier = Rectifier(rig_from_camera_infos(*rig.camera_infos(), drive), rig.size, rig.size, 0.0)
    R = np.eye(4)
    R[:3, :3] = rectifier.R_left
    expected = R[None] @ open_sequence(drive / "drive").poses @ R.T[None]
    assert open_sequence(ingested / "drive").poses == pytest.approx(expected, abs=1e-6)


@pytest.mark.slow(seconds=4)
def test_labels_and_drift_of_an_ingested_bag_match_the_render(compose_config, drive, rig, ingested, labelled_drive, tmp_path):
    out = tmp_path / "labels"
    label(compose_config(f"label.in_dir={ingested}", f"label.out_dir={out}", f"label.metrics_path={tmp_path / 'm.json'}",
                         "label.workers=1", "mlflow.enabled=false"))  # fmt: skip
    H = render_to_rectified(drive, rig)
    ious = []
    for path in sorted((labelled_drive / "drive" / "label").glob("*.png")):
        ours = out / "drive" / "label" / path.name
        if ours.is_file():
            expected = cv2.warpPerspective(cv2.imread(str(path), cv2.IMREAD_GRAYSCALE), H, rig.size, flags=cv2.INTER_NEAREST) > 0
            got = cv2.imread(str(ours), cv2.IMREAD_GRAYSCALE) > 0
            ious.append((expected & got).sum() / (expected | got).sum())
    assert len(ious) >= 0.8 * len(list((labelled_drive / "drive" / "label").glob("*.png")))
    assert min(ious) >= 0.95, ious
    ingested_drift = json.loads((out / "summary.json").read_text())["metrics"]["translation_drift_pct"]
    render_drift = json.loads((labelled_drive / "summary.json").read_text())["metrics"]["translation_drift_pct"]
    assert ingested_drift < max(1.5 * render_drift, 0.6), (ingested_drift, render_drift)


@pytest.mark.parametrize("kind,compressed", [("ros1", (True, True)), ("sqlite3", (False, False))])
def test_ros1_and_ros2_bags_give_the_same_sequence(compose_config, drive, rig, frames, ingested, footprint, kind, compressed, tmp_path):
    """Raw and PNG-compressed topics, ROS 1 and ROS 2 storage: the same pixels and poses."""
    bag = write_bag(tmp_path / ("drive.bag" if kind == "ros1" else "drive"), kind, frames, rig, compressed=compressed,
                    poses=body_poses(drive / "drive"))  # fmt: skip
    ingest(ingest_config(compose_config, bag_source(bag, compressed), tmp_path / "out", *footprint))
    for name in ("calib.txt", "poses.txt", "times.txt", "image_l/000017.png", "image_r/000039.png"):
        assert (tmp_path / "out" / name).read_bytes() == (ingested / "drive" / name).read_bytes(), name


def test_calibration_file_instead_of_camera_info(compose_config, drive, rig, frames, ingested, tmp_path):
    """A bag without CameraInfo, with the rig in OpenCV's stereoCalibrate YAML: the same images."""
    bag = write_bag(tmp_path / "drive", "sqlite3", frames, rig, infos=False)
    calibration = tmp_path / "stereo.yaml"
    cameras = [CameraModel(K, D, rig.size) for K, D in zip(rig.K, rig.D, strict=True)]
    write_opencv(calibration, StereoRig(*cameras, rig.R, rig.T, calibration))
    ingest(ingest_config(compose_config, bag_source(bag, odometry=False), tmp_path / "out", f"ingest.calibration={calibration}"))
    ours, reference = (
        cv2.imread(str(tmp_path / "out" / "image_l" / "000010.png")),
        cv2.imread(str(ingested / "drive" / "image_l" / "000010.png")),
    )
    assert np.abs(ours.astype(int) - reference).max() <= 1  # the rig rebuilt from CameraInfo differs by rounding only
    assert not (tmp_path / "out" / "poses.txt").exists()


def test_fps_subsamples_by_time(compose_config, rig, frames, tmp_path):
    bag = write_bag(tmp_path / "drive", "sqlite3", frames, rig)
    ingest(ingest_config(compose_config, bag_source(bag, odometry=False), tmp_path / "out", "ingest.fps=2.5"))
    assert np.loadtxt(tmp_path / "out" / "times.txt") == pytest.approx(np.arange(20) * 0.4, abs=1e-6)


def test_two_videos_with_an_unknown_offset(compose_config, drive, rig, frames, ingested, tmp_path):
    """An action-camera pair: the right camera started 3 frames late; the offset is found from
    motion, and the rectified frames are the bag's (up to MP4 compression)."""
    left, right = write_videos(tmp_path, frames, fps=5.0, right_offset=3)
    calibration = tmp_path / "stereo.yaml"
    cameras = [CameraModel(K, D, rig.size) for K, D in zip(rig.K, rig.D, strict=True)]
    write_opencv(calibration, StereoRig(*cameras, rig.R, rig.T, calibration))
    source = [
        f"ingest.videos.left={left}",
        f"ingest.videos.right={right}",
        f"ingest.calibration={calibration}",
        "ingest.videos.max_offset_frames=8",
    ]
    meta = ingest(ingest_config(compose_config, source, tmp_path / "out"))
    assert meta["video"]["offset_frames"] == -3  # right frame k shows the instant of left frame k + 3
    assert meta["frames"] == 37
    assert meta["epipolar_error_px"] < 0.5
    for k in (0, 30):  # pair k starts at left frame 3: the bag's frame k + 3
        ours = cv2.imread(str(tmp_path / "out" / "image_r" / f"{k:06d}.png")).astype(int)
        assert np.abs(ours - cv2.imread(str(ingested / "drive" / "image_r" / f"{k + 3:06d}.png"))).mean() < 6.0


@pytest.mark.parametrize("kind", ["mcap", "sqlite3"])
def test_a_bag_of_one_camera_and_tf_becomes_a_mono_sequence_that_labels(compose_config, drive, rig, frames, footprint, kind, tmp_path):
    """ingest.mono: the left camera alone (no right images in the bag) with its poses on
    /tf; the sequence is the render seen through one undistorted pinhole camera, its poses the
    render's, and the label stage labels it from them."""
    from offroad_path.recordings.rectify import Undistorter

    bag = write_bag(
        tmp_path / f"mono_{kind}", kind, frames, rig, poses=body_poses(drive / "drive"), right_frames=slice(0), pose_topic="/tf"
    )
    source = [f"ingest.bag={bag}", "ingest.mono=true", f"ingest.topics.left={LEFT}", "ingest.topics.odometry=/tf"]
    ingest(ingest_config(compose_config, source, tmp_path / "recordings" / "drive", *footprint, "mlflow.enabled=false"))
    out = tmp_path / "recordings" / "drive"
    assert not (out / "image_r").exists() and len((out / "calib.txt").read_text().splitlines()) == 1
    seq, render = open_sequence(out), open_sequence(drive / "drive")
    assert seq.mono and len(seq) == len(render) == 40 and seq.image_size == render.image_size
    camera = rig_from_camera_infos(*rig.camera_infos(), drive).left
    H = Undistorter(camera, rig.size, rig.size, 0.0).calibration.K @ np.linalg.inv(rig.K_render)  # same centre, same axes
    np.testing.assert_allclose(seq.calibration.K, H @ rig.K_render, atol=1e-9)
    for i in (0, 20, 39):
        expected = cv2.warpPerspective(cv2.imread(str(render.left[i])), H, seq.image_size)
        assert np.abs(expected.astype(int) - cv2.imread(str(seq.left[i]))).mean() < 2.0
    assert seq.poses == pytest.approx(render.poses, abs=1e-6)  # the base_link transforms, not the camera mount's
    meta = json.loads((out / "meta.json").read_text())
    assert meta["images"] == 40 and meta["topics"] == {"left": LEFT, "odometry": "/tf"} and meta["epipolar_error_px"] is None
    metrics = label(compose_config(f"label.in_dir={tmp_path / 'recordings'}", f"label.out_dir={tmp_path / 'labels'}",
                                   f"label.metrics_path={tmp_path / 'm.json'}", "label.workers=1", "label.poses.source=file",
                                   "mlflow.enabled=false"))  # fmt: skip
    assert metrics["labels"] >= 8 and metrics["one_camera_sequences"] == 1


def test_a_mono_ingest_without_poses_or_with_a_right_topic_is_refused(compose_config, drive, rig, frames, tmp_path):
    bag = write_bag(tmp_path / "mono", "mcap", frames[:3], rig, poses=body_poses(drive / "drive")[:3], right_frames=slice(0))
    base = [f"ingest.bag={bag}", "ingest.mono=true", f"ingest.topics.left={LEFT}"]
    with pytest.raises(ValueError, match=r"ingest\.mono=true needs ingest\.topics\.odometry"):
        ingest(ingest_config(compose_config, base, tmp_path / "out", "mlflow.enabled=false"))
    with pytest.raises(ValueError, match=r"leave ingest\.topics\.right and ingest\.calibration unset"):
        ingest(ingest_config(compose_config, [*base, "ingest.topics.odometry=/odom", f"ingest.topics.right={RIGHT}"], tmp_path / "out"))
    from offroad_path.recordings.bags import Bag

    tf = write_bag(tmp_path / "tf", "mcap", frames[:3], rig, poses=body_poses(drive / "drive")[:3], pose_topic="/tf")
    with pytest.raises(InputError, match="/tf has no transform to the child frame nowhere"), Bag(tf) as opened:
        opened.poses("/tf", "nowhere")
    assert not (tmp_path / "out").exists()
