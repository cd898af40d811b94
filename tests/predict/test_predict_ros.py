"""predict with a bag in and a bag out: the raw rig's recording of the test drive as an MCAP bag,
its stereo pair found by itself, and the predictions read back with rosbags, message by message."""

from __future__ import annotations

import json
import math
from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import refused
from raw_rig import write_bag

from offroad_path.predict import run_predict
from offroad_path.recordings.rectify import Rectifier
from offroad_path.recordings.rig_calibration import rig_from_camera_infos

FRAMES = 6


@pytest.fixture(scope="module")
def input_bag(raw_drive, rig, tmp_path_factory) -> Path:
    return write_bag(tmp_path_factory.mktemp("bag") / "drive", "mcap", raw_drive[:FRAMES], rig)


@pytest.fixture(scope="module")
def vehicle(drive) -> list[str]:
    meta = json.loads((drive / "drive" / "meta.json").read_text())
    return [f"ingest.footprint.camera_height_m={meta['camera_height_m']}", f"ingest.footprint.camera_pitch_deg={meta['camera_pitch_deg']}"]


def read_back(bag: Path) -> dict[str, list]:
    from rosbags.highlevel import AnyReader

    from offroad_path.predict.ros_out import typestore

    with AnyReader([bag], default_typestore=typestore()) as reader:
        found: dict[str, list] = {}
        for connection, time_ns, raw in reader.messages():
            found.setdefault(connection.topic, []).append((time_ns, connection.msgtype, reader.deserialize(raw, connection.msgtype)))
    return found


# The tiny U-Net's confidence is near 0.48 everywhere: a threshold of 0 makes every pixel path (its
# centre line is the image's middle column, on the ground), of 1 none (no path: stop).
@pytest.mark.parametrize(("steering", "threshold"), [("twist", 0.0), ("ackermann", 1.0)])
def test_a_bag_in_gives_one_message_of_each_kind_per_frame_back(compose_config, trained, input_bag, vehicle, rig, tmp_path, steering,
                                                                threshold):  # fmt: skip
    out = tmp_path / "out"
    run_predict(compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={input_bag}", f"predict.out_dir={out}",
                               f"predict.ros.steering={steering}", f"predict.threshold={threshold}", *vehicle))  # fmt: skip
    (mcap,) = (out / "bag").glob("*.mcap")  # one file, beside its metadata.yaml: Foxglove opens it as it is
    assert (out / "bag" / "metadata.yaml").is_file() and mcap.stat().st_size > 0
    inputs = read_back(input_bag)
    stamps = [m.header.stamp for _, _, m in inputs["/stereo/left/image_raw"]]
    got = read_back(out / "bag")
    command_type = {"ackermann": "ackermann_msgs/msg/AckermannDriveStamped", "twist": "geometry_msgs/msg/TwistStamped"}[steering]
    kinds = {"/offroad_path/confidence": "sensor_msgs/msg/Image", "/offroad_path/overlay/compressed": "sensor_msgs/msg/CompressedImage",
             "/offroad_path/path": "nav_msgs/msg/Path", "/offroad_path/steering": command_type}  # fmt: skip
    assert {topic: {t for _, t, _ in messages} for topic, messages in got.items()} == {topic: {t} for topic, t in kinds.items()}
    height, pitch = (float(v.split("=")[1]) for v in vehicle)
    rectifier = Rectifier(rig_from_camera_infos(*rig.camera_infos(), input_bag), rig.size, (512, 288), 0.0)
    tilt = math.radians(pitch + rectifier.pitch_change_deg)
    to_level = np.array([[1, 0, 0], [0, math.cos(tilt), -math.sin(tilt)], [0, math.sin(tilt), math.cos(tilt)]])  # camera = this @ level
    for topic, messages in got.items():
        assert len(messages) == FRAMES, topic
        for i, (time_ns, _, message) in enumerate(messages):
            assert (message.header.stamp.sec, message.header.stamp.nanosec) == (stamps[i].sec, stamps[i].nanosec)  # the input's, exactly
            assert time_ns == stamps[i].sec * 10**9 + stamps[i].nanosec and message.header.frame_id == "left"
    assert {len(m.poses) > 0 for _, _, m in got["/offroad_path/path"]} == {threshold == 0.0}
    for i in range(FRAMES):
        confidence = got["/offroad_path/confidence"][i][2]
        assert (confidence.encoding, confidence.width, confidence.height) == ("mono8", 512, 288)
        written = cv2.imread(str(out / "confidence" / f"{i:06d}.png"), cv2.IMREAD_GRAYSCALE)
        np.testing.assert_array_equal(confidence.data.reshape(288, 512), written)
        overlay = cv2.imdecode(got["/offroad_path/overlay/compressed"][i][2].data, cv2.IMREAD_COLOR)
        png = cv2.imread(str(out / "overlay" / f"{i:06d}.png"))
        assert overlay.shape == png.shape and np.abs(overlay.astype(int) - png).mean() < 3  # JPEG of the same overlay
        points = np.array([[p.pose.position.x, p.pose.position.y, p.pose.position.z] for p in got["/offroad_path/path"][i][2].poses])
        command = got["/offroad_path/steering"][i][2]
        if steering == "ackermann":
            angle, speed = command.drive.steering_angle, command.drive.speed
        else:
            speed = command.twist.linear.x
            angle = math.atan(command.twist.angular.z * 2.8 / speed) if speed else 0.0
        if not len(points):
            assert (angle, speed) == (0.0, 0.0)  # no path: stop
            continue
        level = points @ to_level  # each point's height below the camera, along the level frame's y (down)
        np.testing.assert_allclose(level[:, 1], height, rtol=1e-6)  # on the ground
        assert np.all(np.diff(level[:, 2]) > 0) and speed == pytest.approx(2.0)  # near to far, at the set speed
        K = rectifier.calibration.K  # every point is on the middle column's ray
        np.testing.assert_allclose(points[:, 0] / points[:, 2], (511 / 2 - K[0, 2]) / K[0, 0], atol=1e-9)
        # pure pursuit to the point 10 m from the rear axle (1 m behind the camera): delta = atan(2 L x / l_d^2), REP 103's sign
        ahead = np.hypot(level[:, 0], level[:, 2] + 1.0)
        x = np.interp(10.0, ahead, level[:, 0])
        assert angle == pytest.approx(-math.atan(2 * 2.8 * x / 10.0**2), abs=1e-6)


def test_a_bag_without_one_stereo_pair_is_refused(compose_config, trained, raw_drive, rig, vehicle, tmp_path, capsys):
    bag = write_bag(tmp_path / "in" / "left_only", "mcap", raw_drive[:2], rig, right_frames=slice(0, 0))
    cfg = compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={bag}", f"predict.out_dir={tmp_path / 'out'}", *vehicle)
    refused(run_predict, cfg, capsys, tmp_path, str(bag), "1 image topics with a CameraInfo", "/stereo/left/image_raw")
