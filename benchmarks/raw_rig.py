"""A raw stereo rig made from a rendered drive: each camera gets its own K and lens distortion, and
the right camera a small rotation, exactly as an unrectified real rig would record the same drive.
The bag and video writers put those raw frames where a real recording would hold them."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation

from offroad_path.recordings.sources import ROS_BODY_TO_OPTICAL
from offroad_path.sequence.reader import open_sequence

T0 = 1_700_000_000.0  # a realistic epoch stamp: float seconds must keep sub-millisecond resolution


@dataclass
class RawRig:
    K: tuple[np.ndarray, np.ndarray]  # raw left, raw right
    D: tuple[np.ndarray, np.ndarray]
    Q: np.ndarray  # the raw right camera's rotation against the ideal right camera: x_raw = Q x_ideal
    K_render: np.ndarray
    baseline_m: float
    size: tuple[int, int]

    @property
    def R(self) -> np.ndarray:
        return self.Q

    @property
    def T(self) -> np.ndarray:
        return -self.Q @ np.array([self.baseline_m, 0.0, 0.0])

    def maps(self, side: int) -> tuple[np.ndarray, np.ndarray]:
        """For every raw pixel, where it looks in the rendered (ideal) image."""
        w, h = self.size
        grid = np.stack(np.meshgrid(np.arange(w), np.arange(h)), -1).reshape(-1, 1, 2).astype(np.float64)
        to_ideal = np.eye(3) if side == 0 else self.Q.T
        exact = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)  # the default 5 steps miss at the corners
        ideal = cv2.undistortPoints(grid, self.K[side], self.D[side], R=to_ideal, P=self.K_render, criteria=exact).reshape(h, w, 2)
        return ideal[..., 0].astype(np.float32), ideal[..., 1].astype(np.float32)

    def camera_infos(self) -> list[dict]:
        """What a ROS stereo calibration stores per camera: K, D, and the rectifying R and P."""
        R1, R2, P1, P2, *_ = cv2.stereoRectify(self.K[0], self.D[0], self.K[1], self.D[1], self.size, self.R, self.T.reshape(3, 1), alpha=0)
        w, h = self.size
        return [{"k": K.ravel(), "d": D.ravel(), "r": R.ravel(), "p": P.ravel(), "width": w, "height": h, "distortion_model": "plumb_bob"}
                for K, D, R, P in ((self.K[0], self.D[0], R1, P1), (self.K[1], self.D[1], R2, P2))]  # fmt: skip


def raw_rig(drive: Path) -> RawRig:
    seq = open_sequence(drive)
    w, h = seq.image_size
    K_left = np.array([[350.0, 0, w / 2 + 2], [0, 350.0, h / 2 + 2], [0, 0, 1]])
    K_right = np.array([[352.0, 0, w / 2 - 2], [0, 351.0, h / 2 - 1], [0, 0, 1]])
    D = (np.array([-0.12, 0.02, 0.0005, -0.0005, 0.0]), np.array([-0.10, 0.015, 0.0, 0.0, 0.0]))
    Q = Rotation.from_euler("xyz", [0.4, -0.6, 0.3], degrees=True).as_matrix()
    return RawRig((K_left, K_right), D, Q, seq.calibration.K, seq.calibration.baseline_m, (w, h))


def raw_frames(drive: Path, rig: RawRig) -> list[tuple[np.ndarray, np.ndarray]]:
    """The drive's frames as the raw cameras see them (BGR)."""
    seq = open_sequence(drive)
    maps = [rig.maps(0), rig.maps(1)]
    frames = []
    for i in range(len(seq)):
        views = [cv2.imread(str(p[i])) for p in (seq.left, seq.right)]
        frames.append(
            tuple(cv2.remap(v, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT) for v, (mx, my) in zip(views, maps, strict=True))
        )
    return frames


def body_poses(drive: Path) -> np.ndarray:
    """The drive's left camera poses as a ROS odometry topic would give the vehicle's body."""
    return open_sequence(drive).poses @ np.linalg.inv(ROS_BODY_TO_OPTICAL)


class RosMessages:
    """Messages of one ROS version, built with rosbags' type store."""

    def __init__(self, ros1: bool):
        from rosbags.typesys import Stores, get_typestore

        self.ros1 = ros1
        self.store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        self.types = self.store.types

    def serialize(self, msg) -> bytes:
        return (self.store.serialize_ros1 if self.ros1 else self.store.serialize_cdr)(msg, msg.__msgtype__)

    def header(self, t: float, frame: str):
        stamp = self.types["builtin_interfaces/msg/Time"](sec=int(t), nanosec=round((t - int(t)) * 1e9))
        return self.types["std_msgs/msg/Header"](**({"seq": 0} if self.ros1 else {}), stamp=stamp, frame_id=frame)

    def image(self, t: float, bgr: np.ndarray, side: str, packed: bool):
        if packed:
            data = np.frombuffer(cv2.imencode(".png", bgr)[1], np.uint8)
            return self.types["sensor_msgs/msg/CompressedImage"](header=self.header(t, side), format="png", data=data)
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        h, w = rgb.shape[:2]
        return self.types["sensor_msgs/msg/Image"](
            header=self.header(t, side), height=h, width=w, encoding="rgb8", is_bigendian=0, step=w * 3, data=rgb.ravel()
        )

    def camera_info(self, t: float, info: dict, side: str):
        roi = self.types["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
        fields = {k.upper() if self.ros1 else k: np.asarray(info[k], np.float64) for k in ("d", "k", "r", "p")}
        return self.types["sensor_msgs/msg/CameraInfo"](
            header=self.header(t, side), height=info["height"], width=info["width"], distortion_model=info["distortion_model"],
            binning_x=0, binning_y=0, roi=roi, **fields,
        )  # fmt: skip

    def odometry(self, t: float, T: np.ndarray):
        g = self.types
        q = Rotation.from_matrix(T[:3, :3]).as_quat()
        point = g["geometry_msgs/msg/Point"](x=T[0, 3], y=T[1, 3], z=T[2, 3])
        pose = g["geometry_msgs/msg/Pose"](position=point, orientation=g["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]))
        zero = g["geometry_msgs/msg/Vector3"](x=0, y=0, z=0)
        still = g["geometry_msgs/msg/Twist"](linear=zero, angular=zero)
        return g["nav_msgs/msg/Odometry"](
            header=self.header(t, "odom"), child_frame_id="base_link",
            pose=g["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
            twist=g["geometry_msgs/msg/TwistWithCovariance"](twist=still, covariance=np.zeros(36)),
        )  # fmt: skip

    def stamped(self, t: float, T: np.ndarray, parent: str, child: str):
        g = self.types
        q = Rotation.from_matrix(T[:3, :3]).as_quat()
        transform = g["geometry_msgs/msg/Transform"](
            translation=g["geometry_msgs/msg/Vector3"](x=T[0, 3], y=T[1, 3], z=T[2, 3]),
            rotation=g["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        )
        return g["geometry_msgs/msg/TransformStamped"](header=self.header(t, parent), child_frame_id=child, transform=transform)

    def transforms(self, t: float, T: np.ndarray):
        """A /tf message: odom -> base_link (the pose), beside base_link -> camera (another frame's)."""
        mount = np.eye(4)
        mount[:3, 3] = (0.5, 0.0, 1.2)
        stamped = [self.stamped(t, mount, "base_link", "camera"), self.stamped(t, T, "odom", "base_link")]
        return self.types["tf2_msgs/msg/TFMessage"](transforms=stamped)


def write_bag(path: Path, kind: str, frames: list, rig: RawRig, *, compressed: tuple[bool, bool] = (False, False),
              poses: np.ndarray | None = None, fps: float = 5.0, infos: bool = True, right_delay_s: float = 0.0,
              right_frames: slice = slice(None), camera_infos: list[dict] | None = None, pose_topic: str = "/odom") -> Path:  # fmt: skip
    """A ROS 1 bag (kind "ros1") or ROS 2 bag ("sqlite3", "mcap") of the raw frames, written with
    rosbags: /stereo/{left,right}/image_raw (or .../compressed, PNG), their camera_info, and the
    poses on /odom (nav_msgs/Odometry) or, with pose_topic="/tf", as TF transforms odom -> base_link."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer as Writer2

    ros = RosMessages(kind == "ros1")
    camera_infos = camera_infos or rig.camera_infos()
    right_indices = set(range(len(frames))[right_frames])
    messages = []  # (receive time, topic, message): a recorder stores them as they arrive
    for i, (left, right) in enumerate(frames):
        t = T0 + i / fps
        for side, bgr, packed, delay in (("left", left, compressed[0], 0.0), ("right", right, compressed[1], right_delay_s)):
            if side == "left" or i in right_indices:
                topic = f"/stereo/{side}/image_raw" + ("/compressed" if packed else "")
                messages.append((t + delay + 0.001, topic, ros.image(t + delay, bgr, side, packed)))
            if infos:
                messages.append(
                    (t + delay + 0.001, f"/stereo/{side}/camera_info", ros.camera_info(t + delay, camera_infos[side == "right"], side))
                )
        if poses is not None and i < len(poses):
            messages.append((t, pose_topic, ros.transforms(t, poses[i]) if pose_topic == "/tf" else ros.odometry(t, poses[i])))
    storage = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer1(path) if ros.ros1 else Writer2(path, version=9, storage_plugin=storage) as writer:
        connections = {}
        for receive, topic, msg in sorted(messages, key=lambda m: m[0]):
            if topic not in connections:
                connections[topic] = writer.add_connection(topic, msg.__msgtype__, typestore=ros.store)
            writer.write(connections[topic], round(receive * 1e9), ros.serialize(msg))
    return path


def write_videos(folder: Path, frames: list, fps: float, right_offset: int) -> tuple[Path, Path]:
    """Two MP4 files of the raw frames; the right camera started `right_offset` frames later."""
    paths = folder / "left.mp4", folder / "right.mp4"
    h, w = frames[0][0].shape[:2]
    for path, side, start in ((paths[0], 0, 0), (paths[1], 1, right_offset)):
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
        for pair in frames[start:]:
            writer.write(pair[side])
        writer.release()
    return paths
