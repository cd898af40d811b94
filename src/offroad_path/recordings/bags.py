"""ROS 1 bags, ROS 2 bags (SQLite or MCAP storage) and bare MCAP files, read with `rosbags`
(pure Python: no ROS install): stereo image topics (or one camera's), their CameraInfo and an
odometry, pose or TF topic."""

from __future__ import annotations

import contextlib
import io
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from offroad_path.errors import InputError, missing_extra
from offroad_path.recordings.rig_calibration import StereoRig, camera_info_dict, rig_from_camera_infos
from offroad_path.sequence.reader import MAX_IMAGE_PIXELS

IMAGE_TYPES = ("sensor_msgs/msg/Image", "sensor_msgs/msg/CompressedImage")
INFO_TYPE = "sensor_msgs/msg/CameraInfo"
TF_TYPE = "tf2_msgs/msg/TFMessage"  # /tf: the transforms whose child frame is ingest.tf_child_frame
POSE_TYPES = ("nav_msgs/msg/Odometry", "geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PoseWithCovarianceStamped", TF_TYPE)
# ROS encodings to OpenCV conversions to BGR (cv_bridge's table: OpenCV names Bayer by the second row).
COLOUR = {
    "rgb8": cv2.COLOR_RGB2BGR,
    "rgba8": cv2.COLOR_RGBA2BGR,
    "bgra8": cv2.COLOR_BGRA2BGR,
    "bayer_rggb8": cv2.COLOR_BayerBG2BGR,
    "bayer_bggr8": cv2.COLOR_BayerRG2BGR,
    "bayer_gbrg8": cv2.COLOR_BayerGR2BGR,
    "bayer_grbg8": cv2.COLOR_BayerGB2BGR,
}
CHANNELS = {"mono8": 1, "8uc1": 1, "bgr8": 3, "8uc3": 3, "rgb8": 3, "rgba8": 4, "bgra8": 4, "mono16": 1, "16uc1": 1} | {
    k: 1 for k in COLOUR if k.startswith("bayer")
}


def stamp_s(msg: Any) -> float:
    stamp = msg.header.stamp
    return stamp.sec + stamp.nanosec * 1e-9


def info_topic_for(image_topic: str) -> str:
    """The CameraInfo topic beside an image topic: /cam/left/image_raw(/compressed) -> /cam/left/camera_info."""
    parts = image_topic.rstrip("/").split("/")
    if parts[-1] in ("compressed", "theora"):
        parts = parts[:-1]
    return "/".join([*parts[:-1], "camera_info"])


class Bag:
    """An open bag; every error names the bag and the topic."""

    def __init__(self, path: str | Path):
        try:
            from rosbags.highlevel import AnyReader
            from rosbags.typesys import Stores, get_typestore
        except ImportError as e:
            raise missing_extra("ingest of a bag", "ros", e.name) from e

        self.path = Path(path)
        if not self.path.exists():
            raise InputError(self.path, "is missing (ingest.bag)")
        self._reader = AnyReader([self.path], default_typestore=get_typestore(Stores.ROS2_HUMBLE))
        try:
            self._reader.open()
        except Exception as e:  # rosbags raises its own error types for every malformed bag
            raise InputError(self.path, f"cannot be read as a ROS 1, ROS 2 or MCAP bag ({type(e).__name__}: {e})") from e

    def __enter__(self) -> Bag:
        return self

    def __exit__(self, *exc: object) -> None:
        with contextlib.suppress(Exception):
            self._reader.close()

    def topics(self) -> dict[str, tuple[str, int]]:
        """{topic: (message type, message count)}."""
        return {name: (info.msgtype, info.msgcount) for name, info in sorted(self._reader.topics.items())}

    def connections(self, topic: str, types: tuple[str, ...], role: str) -> list:
        found = [c for c in self._reader.connections if c.topic == topic]
        if not found:
            listing = ", ".join(f"{t} ({m})" for t, (m, _) in self.topics().items())
            raise InputError(self.path, f"has no topic {topic} ({role}); its topics: {listing}")
        if found[0].msgtype not in types:
            raise InputError(self.path, f"topic {topic} ({role}) carries {found[0].msgtype}, expected {' or '.join(types)}")
        return found

    def first(self, topic: str, types: tuple[str, ...], role: str) -> Any:
        for connection, _, raw in self._reader.messages(connections=self.connections(topic, types, role)):
            return self._reader.deserialize(raw, connection.msgtype)
        raise InputError(self.path, f"topic {topic} ({role}) has no messages")

    def stereo_pair(self) -> tuple[str, str]:
        """The (left, right) image topics of a bag with exactly two image topics that each have a
        CameraInfo beside them; left is the camera whose projection has no baseline term (P's Tx = 0,
        the right camera's is -fx * B). InputError listing the image topics otherwise."""
        topics = self.topics()
        images = [t for t, (m, _) in topics.items() if m in IMAGE_TYPES and topics.get(info_topic_for(t), ("",))[0] == INFO_TYPE]
        if len(images) != 2:
            listing = ", ".join(t for t, (m, _) in topics.items() if m in IMAGE_TYPES) or "none"
            raise InputError(
                self.path,
                f"holds {len(images)} image topics with a CameraInfo beside them, not one stereo pair "
                f"(its image topics: {listing}); give ingest.topics.left and ingest.topics.right",
            )
        tx = [float(camera_info_dict(self.first(info_topic_for(t), (INFO_TYPE,), "CameraInfo"))["p"][3]) for t in images]  # ROS 1: P
        if tx[0] == tx[1]:
            raise InputError(
                self.path,
                f"{images[0]} and {images[1]} have the same CameraInfo baseline term (P[3] = {tx[0]}): "
                "which is left is unknown; give ingest.topics.left and ingest.topics.right",
            )
        return (images[0], images[1]) if tx[0] > tx[1] else (images[1], images[0])

    def rig(self, left_info: str, right_info: str) -> StereoRig:
        infos = [
            camera_info_dict(self.first(topic, (INFO_TYPE,), f"{side} CameraInfo"))
            for side, topic in (("left", left_info), ("right", right_info))
        ]
        return rig_from_camera_infos(*infos, self.path)

    def stereo_messages(self, left: str, right: str | None) -> Iterator[tuple[str, float, Any]]:
        """("left" | "right", header stamp, message) in recording order (right None: one camera's);
        images are decoded later."""
        side = {}
        for name, topic in (("left", left), ("right", right)) if right else (("left", left),):
            for connection in self.connections(topic, IMAGE_TYPES, f"{name} images"):
                side[connection.id] = name
        connections = [c for c in self._reader.connections if c.id in side]
        for connection, _, raw in self._reader.messages(connections=connections):
            msg = self._reader.deserialize(raw, connection.msgtype)
            yield side[connection.id], stamp_s(msg), msg

    def poses(self, topic: str, child_frame: str = "base_link") -> tuple[np.ndarray, np.ndarray]:
        """(N,) header stamps and (N, 4, 4) poses of an odometry or pose topic, or of a TF topic's
        transforms to `child_frame` (e.g. odom -> base_link)."""
        times, poses = [], []
        connections = self.connections(topic, POSE_TYPES, "odometry")
        for connection, _, raw in self._reader.messages(connections=connections):
            msg = self._reader.deserialize(raw, connection.msgtype)
            if connection.msgtype == TF_TYPE:
                found = [
                    (stamp_s(t), t.transform.rotation, t.transform.translation) for t in msg.transforms if t.child_frame_id == child_frame
                ]
            else:
                pose = msg.pose.pose if hasattr(msg.pose, "pose") else msg.pose
                found = [(stamp_s(msg), pose.orientation, pose.position)]
            for stamp, q, p in found:
                times.append(stamp)
                poses.append(pose_matrix((q.x, q.y, q.z, q.w), (p.x, p.y, p.z), f"{self.path}: {topic} at {stamp:.6f} s"))
        if not times and connections[0].msgtype == TF_TYPE:
            raise InputError(self.path, f"{topic} has no transform to the child frame {child_frame} (ingest.tf_child_frame)")
        return in_stamp_order(np.asarray(times), np.asarray(poses).reshape(-1, 4, 4), f"{self.path}: {topic}")


def pose_matrix(quaternion: tuple[float, ...], position: tuple[float, ...], where: str) -> np.ndarray:
    """The 4 x 4 pose of a quaternion (x, y, z, w) and a position; InputError naming `where` (bag, topic,
    stamp) for a non-finite value or a quaternion of (nearly) zero norm."""
    if not np.isfinite([*quaternion, *position]).all():
        raise InputError(where, f"a pose with a non-finite value (orientation {quaternion}, position {position})")
    if np.linalg.norm(quaternion) < 1e-6:
        raise InputError(where, f"a pose whose orientation quaternion {quaternion} has zero norm")
    T = np.eye(4)
    T[:3, :3] = Rotation.from_quat(quaternion).as_matrix()
    T[:3, 3] = position
    return T


def in_stamp_order(times: np.ndarray, poses: np.ndarray, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Poses sorted by their stamps (a bag records messages as they arrived); repeats of a stamp kept once
    when they agree, an InputError naming the stamp when they do not."""
    order = np.argsort(times, kind="stable")
    times, poses = times[order], poses[order]
    repeat = np.flatnonzero(np.diff(times) == 0)
    if len(conflict := [i for i in repeat if not np.allclose(poses[i], poses[i + 1], atol=1e-9)]):
        raise InputError(where, f"two different poses at the same stamp {times[conflict[0]]:.6f} s")
    keep = np.ones(len(times), bool)
    keep[repeat + 1] = False
    return times[keep], poses[keep]


def compressed_size(msg: Any, topic: str, source: Path) -> tuple[int, int]:
    """(width, height) a CompressedImage declares in its JPEG or PNG header, without decoding it."""
    from PIL import Image

    try:
        with Image.open(io.BytesIO(bytes(msg.data))) as image:
            return image.size
    except Image.DecompressionBombError as e:
        raise InputError(source, f"{topic}: a compressed image at {stamp_s(msg):.6f} s declares too many pixels ({e}); not decoded") from e
    except (OSError, SyntaxError, ValueError) as e:
        raise InputError(source, f"{topic}: a compressed image ({msg.format!r}) at {stamp_s(msg):.6f} s cannot be decoded ({e})") from e


def decode_image(msg: Any, topic: str, source: Path, max_pixels: int = MAX_IMAGE_PIXELS) -> np.ndarray:
    """A sensor_msgs Image or CompressedImage as uint8 BGR (H, W, 3) or grey (H, W); refused from
    its header when it declares more than max_pixels."""
    width, height = compressed_size(msg, topic, source) if hasattr(msg, "format") else (msg.width, msg.height)
    if width * height > max_pixels:
        raise InputError(
            source,
            f"{topic}: a frame at {stamp_s(msg):.6f} s declares {width}x{height} pixels, more than the "
            f"{max_pixels:,} allowed; it is not decoded",
        )
    if hasattr(msg, "format"):  # CompressedImage: JPEG or PNG bytes
        image = cv2.imdecode(np.asarray(msg.data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise InputError(source, f"{topic}: a compressed image ({msg.format!r}) at {stamp_s(msg):.6f} s cannot be decoded")
        if image.ndim == 3 and image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
        return (image >> 8).astype(np.uint8) if image.dtype == np.uint16 else image
    encoding = msg.encoding.lower()
    if encoding not in CHANNELS:
        raise InputError(source, f"{topic}: image encoding {msg.encoding!r} is not supported ({', '.join(sorted(CHANNELS))})")
    wide = encoding in ("mono16", "16uc1")
    row_bytes = msg.width * CHANNELS[encoding] * (2 if wide else 1)
    if msg.step < row_bytes or len(msg.data) < msg.step * msg.height:
        raise InputError(
            source, f"{topic}: a {msg.width}x{msg.height} {encoding} image has {len(msg.data)} bytes (step {msg.step}); it is truncated"
        )
    rows = np.asarray(msg.data, np.uint8)[: msg.step * msg.height].reshape(msg.height, msg.step)[:, :row_bytes]
    if wide:
        image = rows.copy().view(">u2" if msg.is_bigendian else "<u2").reshape(msg.height, msg.width)
        return (image >> 8).astype(np.uint8)
    image = rows.reshape(msg.height, msg.width, CHANNELS[encoding]) if CHANNELS[encoding] > 1 else rows
    return cv2.cvtColor(image, COLOUR[encoding]) if encoding in COLOUR else np.ascontiguousarray(image)
