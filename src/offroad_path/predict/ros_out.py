"""Predictions back into ROS: a ROS 2 bag in MCAP storage (one .mcap file and its metadata.yaml),
written with `rosbags`, that Foxglove opens as it is, `ros2 bag play` replays and Rerun shows.
One message of each kind per input frame, each stamped with its input image's stamp:

    <namespace>/confidence          sensor_msgs/Image (mono8: path confidence x 255)
    <namespace>/overlay/compressed  sensor_msgs/CompressedImage (JPEG: the path tinted over the image)
    <namespace>/path                nav_msgs/Path (the path's centre line on the ground, in the camera's frame; empty: no path)
    <namespace>/steering            ackermann_msgs/AckermannDriveStamped or geometry_msgs/TwistStamped (pure pursuit)

Steering follows REP 103: a positive angle (or yaw rate) turns left. Where no path is predicted the
command is to stop: angle 0 and speed 0.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from omegaconf import DictConfig

from offroad_path.errors import missing_extra
from offroad_path.steering.pure_pursuit import GroundCamera, centre_line, pure_pursuit

STEERING_TYPES = {"ackermann": "ackermann_msgs/msg/AckermannDriveStamped", "twist": "geometry_msgs/msg/TwistStamped"}
# ackermann_msgs is not among rosbags' built-in types: its two definitions, from ros-drivers/ackermann_msgs.
ACKERMANN = {
    "ackermann_msgs/msg/AckermannDrive": (
        "float32 steering_angle\nfloat32 steering_angle_velocity\nfloat32 speed\nfloat32 acceleration\nfloat32 jerk\n"
    ),
    "ackermann_msgs/msg/AckermannDriveStamped": "std_msgs/Header header\nackermann_msgs/AckermannDrive drive\n",
}


def typestore() -> Any:
    """ROS 2 Humble's message types with ackermann_msgs added."""
    try:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    except ImportError as e:
        raise missing_extra("predict with a bag", "ros", e.name) from e
    store = get_typestore(Stores.ROS2_HUMBLE)
    types = {}
    for name, text in ACKERMANN.items():
        types |= get_types_from_msg(text, name)
    store.register(types)
    return store


class PredictionBag:
    """The output bag, open for writing: `write` one frame's messages. The path is where the
    confidence is above `threshold`; its centre line goes onto the ground with `camera`, and pure
    pursuit steers along it."""

    def __init__(self, folder: Path, ros: DictConfig, camera: GroundCamera, threshold: float):
        """`ros`: conf/predict's ros (namespace, frame_id, steering, speed_mps, wheelbase_m, lookahead_m, jpeg_quality)."""
        from rosbags.rosbag2 import StoragePlugin, Writer

        self.store, self.ros, self.camera, self.threshold = typestore(), ros, camera, threshold
        self.writer = Writer(folder, version=9, storage_plugin=StoragePlugin.MCAP)
        self.writer.open()
        kinds = {
            "confidence": "sensor_msgs/msg/Image",
            "overlay/compressed": "sensor_msgs/msg/CompressedImage",
            "path": "nav_msgs/msg/Path",
            "steering": STEERING_TYPES[ros.steering],
        }
        ns = ros.namespace.rstrip("/")
        self.connections = {kind: self.writer.add_connection(f"{ns}/{kind}", t, typestore=self.store) for kind, t in kinds.items()}

    def __enter__(self) -> PredictionBag:
        return self

    def __exit__(self, *exc: object) -> None:
        self.writer.close()

    def header(self, stamp: Any, frame_id: str) -> Any:
        """A std_msgs/Header of the input's stamp (ROS 1 or 2) and `frame_id`."""
        t = self.store.types
        time = t["builtin_interfaces/msg/Time"](sec=int(stamp.sec), nanosec=int(stamp.nanosec))
        return t["std_msgs/msg/Header"](stamp=time, frame_id=frame_id)

    def write(self, image_header: Any, confidence: np.ndarray, overlay_bgr: np.ndarray) -> None:
        """One frame's messages, with the stamp of its image's header: the confidence (H, W) in
        [0, 1], the overlay, the path's centre line and the steering along it."""
        header = self.header(image_header.stamp, self.ros.frame_id or image_header.frame_id)
        pixels = centre_line(confidence > self.threshold)
        steering = pure_pursuit(self.camera.to_ground(pixels), self.ros.lookahead_m, self.ros.wheelbase_m)
        steering_rad = None if steering is None else -steering  # REP 103: positive turns left; pure_pursuit's turns right
        centre = self.camera.to_camera(pixels)  # (N, 3) near to far
        t = self.store.types
        grey = np.rint(np.clip(confidence, 0, 1) * 255).astype(np.uint8)
        height, width = grey.shape
        image = t["sensor_msgs/msg/Image"](
            header=header, height=height, width=width, encoding="mono8", is_bigendian=0, step=width, data=grey.ravel()
        )
        ok, jpeg = cv2.imencode(".jpg", overlay_bgr, [cv2.IMWRITE_JPEG_QUALITY, self.ros.jpeg_quality])
        if not ok:
            raise ValueError("OpenCV could not encode the overlay as JPEG")
        overlay = t["sensor_msgs/msg/CompressedImage"](header=header, format="jpeg", data=jpeg.ravel())
        identity = t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)
        poses = [
            t["geometry_msgs/msg/PoseStamped"](
                header=header,
                pose=t["geometry_msgs/msg/Pose"](
                    position=t["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z)), orientation=identity
                ),
            )
            for x, y, z in centre
        ]
        path = t["nav_msgs/msg/Path"](header=header, poses=poses)
        angle, speed = (0.0, 0.0) if steering_rad is None else (steering_rad, self.ros.speed_mps)
        if self.ros.steering == "ackermann":
            drive = t["ackermann_msgs/msg/AckermannDrive"](
                steering_angle=angle, steering_angle_velocity=0.0, speed=speed, acceleration=0.0, jerk=0.0
            )
            command = t["ackermann_msgs/msg/AckermannDriveStamped"](header=header, drive=drive)
        else:
            turn = t["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=speed * math.tan(angle) / self.ros.wheelbase_m)
            twist = t["geometry_msgs/msg/Twist"](linear=t["geometry_msgs/msg/Vector3"](x=speed, y=0.0, z=0.0), angular=turn)
            command = t["geometry_msgs/msg/TwistStamped"](header=header, twist=twist)
        nanoseconds = header.stamp.sec * 1_000_000_000 + header.stamp.nanosec
        for kind, message in (("confidence", image), ("overlay/compressed", overlay), ("path", path), ("steering", command)):
            connection = self.connections[kind]
            self.writer.write(connection, nanoseconds, self.store.serialize_cdr(message, connection.msgtype))
