"""Ingest's readers piece by piece, and bad recordings: one error line naming the topic or file,
exit status 2, nothing written."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from helpers import refused
from raw_rig import RosMessages, body_poses, write_bag, write_videos

from offroad_path.errors import InputError
from offroad_path.ingest import ingest
from offroad_path.recordings.bags import decode_image, info_topic_for
from offroad_path.recordings.rig_calibration import CameraModel, StereoRig, read_rig, write_opencv
from offroad_path.recordings.sync import SyncStats, pair_by_stamp, poses_at
from offroad_path.recordings.video import estimate_offset

LEFT, RIGHT = "/stereo/left/image_raw", "/stereo/right/image_raw"


@pytest.fixture(scope="module")
def frames(raw_drive):
    return raw_drive[:12]


def bag_config(compose_config, bag: Path, out: Path, *overrides: str):
    return compose_config(
        f"ingest.bag={bag}", f"ingest.topics.left={LEFT}", f"ingest.topics.right={RIGHT}", f"ingest.out_dir={out}", *overrides
    )


@pytest.mark.parametrize(
    "case,bag_options,overrides,named",
    [
        ("missing topic", {}, ["ingest.topics.right=/stereo/right/image_rect"], ["/stereo/right/image_rect", "its topics: /stereo/left"]),
        ("no CameraInfo", {"infos": False}, [], ["/stereo/left/camera_info", "left CameraInfo"]),
        ("right camera dropped frames", {"right_frames": slice(0, 8)}, [], ["4 of 20 images have no partner", LEFT, RIGHT]),
        ("unsynchronised stamps", {"right_delay_s": 0.05}, [], ["no left/right pair within", "50.0 ms apart"]),
        ("odometry shorter than the drive", {"poses": 6}, ["ingest.topics.odometry=/odom"], ["/odom: the poses cover"]),
        ("not a pose topic", {}, [f"ingest.topics.odometry={LEFT}"], [LEFT, "expected nav_msgs/msg/Odometry"]),
        # the drive's poses in shuffled order: once an 88 m zig-zag of a 17 m drive, exit 0
        (
            "stamps out of step with poses",
            {"poses": "shuffled", "fps": 10.0},
            ["ingest.topics.odometry=/odom"],
            ["/odom: moves", "more than ingest.max_speed_mps): its stamps are out of step"],
        ),
    ],
)
def test_bad_bags_are_refused_naming_the_topic(compose_config, drive, rig, frames, tmp_path, capsys, case, bag_options, overrides, named):
    options = dict(bag_options)
    if options.get("poses") == "shuffled":
        options["poses"] = body_poses(drive / "drive")[: len(frames)][np.random.default_rng(0).permutation(len(frames))]
    elif "poses" in options:  # /odom over the first frames only
        options["poses"] = body_poses(drive / "drive")[: options["poses"]]
    bag = write_bag(tmp_path / "drive", "sqlite3", frames, rig, **options)
    refused(ingest, bag_config(compose_config, bag, tmp_path / "out", *overrides), capsys, tmp_path, str(bag), *named)


def test_not_a_bag_and_no_source(compose_config, tmp_path, capsys):
    fake = tmp_path / "drive.bag"
    fake.write_text("not a bag")
    refused(
        ingest,
        bag_config(compose_config, fake, tmp_path / "out"),
        capsys,
        tmp_path,
        str(fake),
        "cannot be read as a ROS 1, ROS 2 or MCAP bag",
    )
    refused(ingest, compose_config(f"ingest.out_dir={tmp_path / 'out'}"), capsys, tmp_path, "ingest.bag=PATH or ingest.videos.left=PATH")


def test_videos_need_a_calibration_and_a_detectable_offset(compose_config, rig, frames, tmp_path, capsys):
    left, right = write_videos(tmp_path, frames, fps=5.0, right_offset=0)
    videos = [f"ingest.videos.left={left}", f"ingest.videos.right={right}", f"ingest.out_dir={tmp_path / 'out'}"]
    refused(ingest, compose_config(*videos), capsys, tmp_path, "ingest.calibration is required for two videos")
    missing = [f"ingest.videos.left={left}", f"ingest.videos.right={tmp_path / 'nope.mp4'}", f"ingest.out_dir={tmp_path / 'out'}"]
    refused(ingest, compose_config(*missing), capsys, tmp_path, str(tmp_path / "nope.mp4"), "is missing")
    calibration = tmp_path / "stereo.yaml"
    write_opencv(
        calibration, StereoRig(*[CameraModel(K, D, rig.size) for K, D in zip(rig.K, rig.D, strict=True)], rig.R, rig.T, calibration)
    )
    # 12 frames leave fewer than 20 overlapping frames of motion at any offset
    refused(
        ingest, compose_config(*videos, f"ingest.calibration={calibration}"), capsys, tmp_path, str(right), "ingest.videos.offset_frames"
    )
    meta = ingest(compose_config(*videos, f"ingest.calibration={calibration}", "ingest.videos.offset_frames=0"))
    assert meta["frames"] == 12 and meta["video"]["offset_correlation"] is None


def write_rig(rig, path: Path, T: np.ndarray) -> Path:
    write_opencv(path, StereoRig(*[CameraModel(K, D, rig.size) for K, D in zip(rig.K, rig.D, strict=True)], rig.R, T, path))
    return path


def test_calibration_mistakes_are_named(rig, tmp_path):
    with pytest.raises(InputError, match="left and right are swapped"):
        read_rig(write_rig(rig, tmp_path / "swapped.yaml", -rig.T))
    with pytest.raises(InputError, match="calibration_unit_m"):
        read_rig(write_rig(rig, tmp_path / "mm.yaml", rig.T * 1000))
    assert np.allclose(read_rig(tmp_path / "mm.yaml", unit_m=0.001).T, rig.T)
    (tmp_path / "other.yaml").write_text("a: 1\n")
    with pytest.raises(InputError, match="is not a stereo calibration"):
        read_rig(tmp_path / "other.yaml")


def test_kalibr_and_ros_yaml_give_the_rig(rig, tmp_path):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rig.R, rig.T
    cams = {
        f"cam{i}": {"camera_model": "pinhole", "intrinsics": K[[0, 1, 0, 1], [0, 1, 2, 2]].tolist(), "distortion_model": "radtan",
                    "distortion_coeffs": D[:4].tolist(), "resolution": list(rig.size), "rostopic": topic}
        for i, (K, D, topic) in enumerate(zip(rig.K, rig.D, (LEFT, RIGHT), strict=True))
    }  # fmt: skip
    cams["cam1"]["T_cn_cnm1"] = T.tolist()
    (tmp_path / "camchain.yaml").write_text(yaml.safe_dump(cams))
    kalibr = read_rig(tmp_path / "camchain.yaml")
    assert np.allclose(kalibr.R, rig.R) and np.allclose(kalibr.T, rig.T) and kalibr.rostopics == (LEFT, RIGHT)
    assert np.allclose(kalibr.left.K, rig.K[0]) and np.allclose(kalibr.right.D, rig.D[1][:4])
    files = []
    for side, info in zip(("left", "right"), rig.camera_infos(), strict=True):

        def block(key: str, rows: int, cols: int, info: dict = info) -> dict:
            return {"rows": rows, "cols": cols, "data": np.asarray(info[key]).tolist()}

        ros = {"image_width": info["width"], "image_height": info["height"], "camera_name": side, "distortion_model": "plumb_bob",
               "camera_matrix": block("k", 3, 3), "distortion_coefficients": block("d", 1, 5),
               "rectification_matrix": block("r", 3, 3), "projection_matrix": block("p", 3, 4)}  # fmt: skip
        files.append(tmp_path / f"{side}.yaml")
        files[-1].write_text(yaml.safe_dump(ros))
    ros_rig = read_rig(files[0], files[1])
    assert np.allclose(ros_rig.R, rig.R, atol=1e-9) and np.allclose(ros_rig.T, rig.T, atol=1e-9)


def test_kitti_style_scale_and_image_size(rig, tmp_path):
    """A calibration made at twice the recording's size scales K; another aspect is refused."""
    cam = CameraModel(rig.K[0] * [[2], [2], [1]], rig.D[0], (rig.size[0] * 2, rig.size[1] * 2))
    assert np.allclose(cam.at_size(rig.size, tmp_path).K, rig.K[0])
    with pytest.raises(InputError, match="not a uniform scale"):
        cam.at_size((rig.size[0], rig.size[0]), tmp_path)


def test_pairing_by_stamp_drops_and_counts_the_unmatched(tmp_path):
    left = [("left", 10.0 + 0.1 * k + 0.001 * (k % 3), k) for k in range(10)]
    right = [("right", 10.0 + 0.1 * k - 0.002, k) for k in range(10) if k != 4]  # frame 4 was dropped
    right.append(("right", 10.95, 99))  # a stray frame between two left ones
    stream = sorted(left + right, key=lambda m: m[1])
    stats = SyncStats()
    pairs = list(pair_by_stamp(stream, 0.005, stats, {"left": LEFT, "right": RIGHT}, tmp_path))
    assert [(a, b) for _, a, b in pairs] == [(k, k) for k in range(10) if k != 4]
    assert (stats.left, stats.right, stats.pairs, stats.unpaired) == (10, 10, 9, 2)
    assert stats.worst_gap_s == pytest.approx(0.004)
    backwards = [("left", 1.0, 0), ("left", 0.9, 1)]
    with pytest.raises(InputError, match=f"{LEFT}: stamps do not rise"):
        list(pair_by_stamp(backwards, 0.005, SyncStats(), {"left": LEFT, "right": RIGHT}, tmp_path))


def test_poses_are_interpolated_between_messages(tmp_path):
    turn = np.eye(4)
    turn[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90 degrees about z
    turn[:3, 3] = (2.0, 0.0, 0.0)
    halfway = poses_at(np.array([0.0, 1.0]), np.stack([np.eye(4), turn]), np.array([0.5]), tmp_path, "/odom")[0]
    c = math.cos(math.pi / 4)
    assert halfway[:3, :3] == pytest.approx(np.array([[c, -c, 0], [c, c, 0], [0, 0, 1]]))
    assert halfway[:3, 3] == pytest.approx([1.0, 0.0, 0.0])


def test_image_encodings(tmp_path):
    ros = RosMessages(ros1=False)
    bgr = np.random.default_rng(0).integers(0, 255, (4, 6, 3), dtype=np.uint8)
    image = ros.types["sensor_msgs/msg/Image"]
    header = ros.header(1.0, "cam")
    padded = np.zeros((4, 20), np.uint8)
    padded[:, :18] = bgr[:, :, ::-1].reshape(4, 18)  # rgb8 rows with 2 bytes of padding
    assert (
        decode_image(image(header=header, height=4, width=6, encoding="rgb8", is_bigendian=0, step=20, data=padded.ravel()), "t", tmp_path)
        == bgr
    ).all()
    wide = (np.arange(24, dtype=np.uint16).reshape(4, 6) * 2000).astype(">u2")
    mono16 = image(
        header=header, height=4, width=6, encoding="mono16", is_bigendian=1, step=12, data=np.frombuffer(wide.tobytes(), np.uint8)
    )
    assert (decode_image(mono16, "t", tmp_path) == (wide.astype(np.uint16) >> 8)).all()
    with pytest.raises(InputError, match="t: a 6x4 rgb8 image has 10 bytes"):
        decode_image(
            image(header=header, height=4, width=6, encoding="rgb8", is_bigendian=0, step=18, data=np.zeros(10, np.uint8)), "t", tmp_path
        )
    with pytest.raises(InputError, match="encoding 'yuv422' is not supported"):
        decode_image(
            image(header=header, height=4, width=6, encoding="yuv422", is_bigendian=0, step=12, data=np.zeros(48, np.uint8)), "t", tmp_path
        )
    assert info_topic_for("/cam/left/image_raw/compressed") == "/cam/left/camera_info"


def test_offset_from_motion_signals():
    rng = np.random.default_rng(1)
    motion = rng.random(200)
    found = estimate_offset(motion[5:105], motion[:100], max_offset=10)  # the right video started 5 frames early
    assert found.frames == 5 and found.correlation == pytest.approx(1.0) and found.runner_up < 0.5


def test_fisheye_rig_from_kalibr_is_rectified(tmp_path):
    """An equidistant (fisheye) rig: points seen through it land on one row in both rectified
    images, and the rectification maps send each rectified pixel back to its raw pixel."""
    import cv2
    from scipy.spatial.transform import Rotation

    from offroad_path.recordings.rectify import Rectifier

    size, K = (640, 480), np.array([[280.0, 0, 321], [0, 281, 238], [0, 0, 1]])
    D = np.array([0.05, -0.01, 0.002, -0.0005])
    R = Rotation.from_euler("xyz", [0.3, -0.8, 0.2], degrees=True).as_matrix()
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, -R @ [0.12, 0.0, 0.0]
    cams = {f"cam{i}": {"camera_model": "pinhole", "intrinsics": K[[0, 1, 0, 1], [0, 1, 2, 2]].tolist(), "distortion_model": "equidistant",
                        "distortion_coeffs": D.tolist(), "resolution": list(size)} for i in range(2)}  # fmt: skip
    cams["cam1"]["T_cn_cnm1"] = T.tolist()
    (tmp_path / "camchain.yaml").write_text(yaml.safe_dump(cams))
    rig = read_rig(tmp_path / "camchain.yaml")
    assert rig.left.fisheye and rig.right.fisheye
    rectifier = Rectifier(rig, size, (512, 384), 0.0)
    points = np.random.default_rng(0).uniform([-4, -1.5, 3], [4, 1.5, 20], (300, 3)).reshape(-1, 1, 3)
    rows, rectified = [], []
    for r, t, R_i, P in ((np.eye(3), np.zeros(3), rectifier.R_left, rectifier.calibration.P_left),
                         (R, T[:3, 3], rectifier.R_right, rectifier.calibration.P_right)):  # fmt: skip
        raw, _ = cv2.fisheye.projectPoints(points, cv2.Rodrigues(r)[0], t, K, D)
        rect = cv2.fisheye.undistortPoints(raw, K, D, R=R_i, P=P).reshape(-1, 2)
        rows.append(rect[:, 1])
        rectified.append((raw.reshape(-1, 2), rect))
    assert np.abs(rows[0] - rows[1]).max() < 0.01
    map_x, map_y = cv2.convertMaps(*rectifier.maps[0], cv2.CV_32FC1)
    raw, rect = rectified[0]
    inside = (rect[:, 0] >= 0) & (rect[:, 0] < 511) & (rect[:, 1] >= 0) & (rect[:, 1] < 383)
    u, v = np.rint(rect[inside]).astype(int).T
    looked_up = np.stack([map_x[v, u], map_y[v, u]], axis=1)
    assert inside.sum() > 100 and np.abs(looked_up - raw[inside]).max() < 1.5  # rounding to a pixel moves the raw point by < 1.5 px


def test_a_bag_without_the_ros_extra_says_which_extra_to_install(compose_config, drive, rig, frames, tmp_path, capsys, monkeypatch):
    bag = write_bag(tmp_path / "drive", "sqlite3", frames, rig)
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # as if `pip install -e .` without [ros]: importing it fails
    line = refused(ingest, bag_config(compose_config, bag, tmp_path / "out"), capsys, tmp_path, "[ros]", "rosbags.highlevel")
    assert "pip install -e '.[ros]'" in line
