"""Where raw stereo frames come from: a ROS bag or two video files. Both are checked when opened
(topics, calibration, frame size, offset), before anything is written, and both give the same
thing: a rig calibration, the raw frame size and time-stamped raw pairs. A bag of one camera with
an odometry or TF topic (ingest.mono) gives that camera's calibration and frames (right None)."""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
from omegaconf import DictConfig

from offroad_path.errors import InputError
from offroad_path.recordings.bags import IMAGE_TYPES, INFO_TYPE, POSE_TYPES, Bag, decode_image, info_topic_for
from offroad_path.recordings.rig_calibration import StereoRig, camera_from_info, camera_info_dict, read_rig
from offroad_path.recordings.sync import SyncStats, check_pairing, pair_by_stamp, poses_at
from offroad_path.recordings.video import estimate_offset, frames, motion_signal, probe

log = logging.getLogger(__name__)
Frames = Iterator[tuple[float, np.ndarray, np.ndarray]]  # (seconds, raw left, raw right), BGR or grey
# A ROS body frame (x forward, y left, z up; REP 103) to a camera's optical frame (x right, y down, z forward).
ROS_BODY_TO_OPTICAL = np.array([[0, 0, 1, 0], [-1, 0, 0, 0], [0, -1, 0, 0], [0, 0, 0, 1]], np.float64)


def _same_size(left: np.ndarray, right: np.ndarray, source: Path) -> tuple[int, int]:
    if left.shape[:2] != right.shape[:2]:
        raise InputError(
            source,
            f"left frames are {left.shape[1]}x{left.shape[0]}, right frames {right.shape[1]}x{right.shape[0]}: "
            "a stereo pair needs one size",
        )
    return left.shape[1], left.shape[0]


def _file_rig(c: DictConfig) -> StereoRig | None:
    return read_rig(c.calibration, c.right_calibration, c.calibration_unit_m) if c.calibration else None


class BagSource:
    mono = False

    def __init__(self, c: DictConfig):
        self.c = c
        self.bag = Bag(c.bag)
        self.path = self.bag.path
        self.inputs = [self.path]
        self.stats = SyncStats()
        try:
            self._check(c)
        except BaseException:
            self.close()
            raise

    def _check(self, c: DictConfig) -> None:
        """Topics, calibration and frame size, before anything is written."""
        rig = _file_rig(c)
        self.names = {}
        for i, side in enumerate(("left", "right")):
            topic = c.topics[side] or (rig.rostopics[i] if rig else None)
            if topic is None:
                images = [t for t, (m, _) in self.bag.topics().items() if m in IMAGE_TYPES]
                raise ValueError(f"ingest.topics.{side} is required: the image topics of {self.path} are {', '.join(images) or 'none'}")
            self.names[side] = topic
        if self.names["left"] == self.names["right"]:
            raise InputError(self.path, f"left and right images are both {self.names['left']}: a stereo pair needs two topics")
        if rig is None:
            infos = [c.topics[f"{side}_info"] or info_topic_for(self.names[side]) for side in ("left", "right")]
            rig = self.bag.rig(*infos)
        self.rig = rig
        first = [decode_image(self.bag.first(t, IMAGE_TYPES, f"{s} images"), t, self.path) for s, t in self.names.items()]
        self.input_size = _same_size(*first, self.path)
        if c.topics.odometry:
            self.bag.connections(c.topics.odometry, POSE_TYPES, "odometry")

    def pairs(self, keep: Callable[[float], bool]) -> Frames:
        """The synchronised pairs; only the kept ones are decoded."""
        for t, _, left, right in self.headed_pairs(keep):
            yield t, left, right

    def headed_pairs(self, keep: Callable[[float], bool]) -> Iterator[tuple[float, Any, np.ndarray, np.ndarray]]:
        """As pairs, with the left message's header (its exact stamp and frame_id) second."""
        messages = self.bag.stereo_messages(self.names["left"], self.names["right"])
        for t, left, right in pair_by_stamp(messages, self.c.sync_tolerance_s, self.stats, self.names, self.path):
            if keep(t):
                pair = decode_image(left, self.names["left"], self.path), decode_image(right, self.names["right"], self.path)
                if _same_size(*pair, self.path) != self.input_size:  # a stream that changes size mid-way is not cropped silently
                    size = f"{pair[0].shape[1]}x{pair[0].shape[0]}"
                    first = f"{self.input_size[0]}x{self.input_size[1]}"
                    raise InputError(self.path, f"the frames at {t:.6f} s are {size}, the stream's first {first}: one recording, one size")
                yield t, left.header, *pair
        check_pairing(self.stats, self.c.max_unpaired_fraction, self.c.sync_tolerance_s, self.names, self.path)

    def camera_poses(self, times: np.ndarray) -> np.ndarray | None:
        """(N, 4, 4) raw left camera to world at `times`, from the odometry topic; None without one."""
        topic = self.c.topics.odometry
        if not topic:
            return None
        body_to_camera = (
            ROS_BODY_TO_OPTICAL if self.c.body_to_camera is None else np.asarray(self.c.body_to_camera, np.float64).reshape(4, 4)
        )
        stamps, poses = self.bag.poses(topic, self.c.tf_child_frame)
        check_speeds(stamps, poses, self.c.max_speed_mps, f"{self.path}: {topic}")
        return poses_at(stamps, poses, times, self.path, topic) @ body_to_camera

    def describe(self) -> dict:
        return {
            "source": self.path.name,
            "topics": self.names | ({"odometry": self.c.topics.odometry} if self.c.topics.odometry else {}),
            "sync": {
                "left_messages": self.stats.left,
                "right_messages": self.stats.right,
                "pairs": self.stats.pairs,
                "unpaired": self.stats.unpaired,
                "worst_gap_ms": round(self.stats.worst_gap_s * 1000, 3),
            },
        }

    def close(self) -> None:
        self.bag.__exit__()


def check_speeds(stamps: np.ndarray, poses: np.ndarray, max_speed_mps: float, where: str) -> None:
    """No step between consecutive poses (in stamp order) faster than a vehicle drives: stamps out of
    step with their poses (shuffled, another clock's) would make a zig-zag of a straight drive."""
    if len(stamps) < 2:
        return
    steps = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    speeds = steps / np.diff(stamps)  # stamps strictly increase (bags.in_stamp_order)
    if len(fast := np.flatnonzero(~(speeds <= max_speed_mps))):
        i = fast[0]
        raise InputError(
            where,
            f"moves {steps[i]:.3g} m in {stamps[i + 1] - stamps[i]:.3g} s at {stamps[i + 1]:.6f} s ({speeds[i]:.3g} m/s, "
            f"more than ingest.max_speed_mps): its stamps are out of step with its poses",
        )


class MonoBagSource(BagSource):
    """One camera's image topic and an odometry, pose or TF topic (ingest.mono=true): frames with
    right None, the camera's own calibration from its CameraInfo, and poses for every frame."""

    mono = True

    def _check(self, c: DictConfig) -> None:
        if not c.topics.odometry:
            raise ValueError("ingest.mono=true needs ingest.topics.odometry: a recording of one camera is labelled from its poses")
        if c.calibration or c.topics.right:
            raise ValueError(
                "ingest.mono=true reads one camera (ingest.topics.left) and its CameraInfo: "
                "leave ingest.topics.right and ingest.calibration unset"
            )
        if not c.topics.left:
            images = [t for t, (m, _) in self.bag.topics().items() if m in IMAGE_TYPES]
            raise ValueError(f"ingest.topics.left is required: the image topics of {self.path} are {', '.join(images) or 'none'}")
        self.names = {"left": c.topics.left}
        info = camera_info_dict(self.bag.first(c.topics.left_info or info_topic_for(c.topics.left), (INFO_TYPE,), "CameraInfo"))
        first = decode_image(self.bag.first(c.topics.left, IMAGE_TYPES, "images"), c.topics.left, self.path)
        self.input_size = first.shape[1], first.shape[0]
        self.camera = camera_from_info(info, self.path)[0].at_size(self.input_size, self.path)
        self.rig = None
        self.bag.connections(c.topics.odometry, POSE_TYPES, "odometry")

    def headed_pairs(self, keep: Callable[[float], bool]) -> Iterator[tuple[float, Any, np.ndarray, None]]:
        for _, t, msg in self.bag.stereo_messages(self.names["left"], None):
            self.stats.left += 1
            if keep(t):
                image = decode_image(msg, self.names["left"], self.path)
                if (image.shape[1], image.shape[0]) != self.input_size:
                    size, first = f"{image.shape[1]}x{image.shape[0]}", f"{self.input_size[0]}x{self.input_size[1]}"
                    raise InputError(self.path, f"the frame at {t:.6f} s is {size}, the stream's first {first}: one recording, one size")
                yield t, msg.header, image, None

    def describe(self) -> dict:
        return {"source": self.path.name, "topics": self.names | {"odometry": self.c.topics.odometry}, "images": self.stats.left}


class VideoSource:
    mono = False

    def __init__(self, c: DictConfig):
        self.c = c
        if Path(c.videos.left).resolve() == Path(c.videos.right).resolve():
            raise InputError(c.videos.right, "is also ingest.videos.left: a stereo pair needs two videos")
        videos = [probe(Path(p)) for p in (c.videos.left, c.videos.right)]
        self.left, self.right = videos
        self.path = self.right.path
        self.inputs = [v.path for v in videos]
        if abs(self.left.fps - self.right.fps) > 0.01 * self.left.fps:
            raise InputError(
                self.path, f"runs at {self.right.fps:g} fps, {self.left.path.name} at {self.left.fps:g}: record both at one frame rate"
            )
        if self.left.size != self.right.size:
            raise InputError(
                self.path, f"is {self.right.size[0]}x{self.right.size[1]}, {self.left.path.name} {self.left.size[0]}x{self.left.size[1]}"
            )
        self.input_size = self.left.size
        self.rig = _file_rig(c)
        if self.rig is None:
            raise ValueError(
                "ingest.calibration is required for two videos: an OpenCV, Kalibr or ROS stereo calibration "
                "(python -m offroad_path.calibrate makes one)"
            )
        self.offset = c.videos.offset_frames
        self.correlation = None
        if self.offset is None:
            self.offset, self.correlation = self._estimate_offset()
        self._check_pairing()
        self.pairs_seen = 0

    def _check_pairing(self) -> None:
        """The frames either video holds that the other has none for, at the offset, are unpaired: more
        than ingest.max_unpaired_fraction of both videos' frames is refused before any work, as a bag's
        unpaired images are (a container that declares no frame count is checked as it decodes)."""
        left, right = self.left.frames, self.right.frames
        if left <= 0 or right <= 0:
            return
        pairs = max(0, min(left - max(0, -self.offset), right - max(0, self.offset)))
        unpaired = left + right - 2 * pairs
        if unpaired > self.c.max_unpaired_fraction * (left + right):
            raise InputError(
                self.path,
                f"{unpaired} of {left + right} frames have no partner at an offset of {self.offset} frames ({left} frames in "
                f"{self.left.path.name}, {right} in {self.path.name}): more than ingest.max_unpaired_fraction = "
                f"{self.c.max_unpaired_fraction:g}; the videos do not cover the same drive",
            )

    def _estimate_offset(self) -> tuple[int, float]:
        limit = self.c.videos.max_offset_frames
        length = max(20 * limit, 600)  # frames read for the signals
        signals = [motion_signal(v.path, length) for v in (self.left, self.right)]
        offset = estimate_offset(*signals, limit)
        if offset is None or offset.correlation < 0.5:
            found = f"the best correlation is {offset.correlation:.2f} at {offset.frames} frames" if offset else "the videos are too short"
            raise InputError(
                self.path, f"its time offset to {self.left.path.name} cannot be estimated ({found}); give ingest.videos.offset_frames"
            )
        if offset.runner_up > 0.95 * offset.correlation:
            log.warning(
                "%s: the time offset %d frames is ambiguous (correlation %.3f, another offset %.3f); "
                "check preview.jpg or give ingest.videos.offset_frames",
                self.path,
                offset.frames,
                offset.correlation,
                offset.runner_up,
            )
        log.info("video offset: right frame = left frame %+d (motion correlation %.3f)", offset.frames, offset.correlation)
        return offset.frames, offset.correlation

    def pairs(self, keep: Callable[[float], bool]) -> Frames:
        left_start, right_start = max(0, -self.offset), max(0, self.offset)
        for k, (left, right) in enumerate(zip(frames(self.left.path, left_start), frames(self.right.path, right_start), strict=False)):
            self.pairs_seen += 1
            t = (left_start + k) / self.left.fps  # on the left video's clock
            if keep(t):
                yield t, left, right

    def camera_poses(self, times: np.ndarray) -> None:
        return None

    def describe(self) -> dict:
        return {
            "source": [self.left.path.name, self.right.path.name],
            "video": {"fps": self.left.fps, "offset_frames": self.offset, "offset_correlation": self.correlation, "pairs": self.pairs_seen},
        }

    def close(self) -> None:
        pass


def open_source(c: DictConfig) -> BagSource | VideoSource:
    """The source ingest.bag or ingest.videos names (exactly one); ingest.mono: a bag of one camera."""
    has_videos = c.videos.left is not None or c.videos.right is not None
    if (c.bag is None) == (not has_videos):
        raise ValueError("give either ingest.bag=PATH or ingest.videos.left=PATH ingest.videos.right=PATH (exactly one source)")
    if has_videos and (c.videos.left is None or c.videos.right is None):
        raise ValueError("ingest.videos needs both left and right")
    if c.mono and c.bag is None:
        raise ValueError("ingest.mono=true reads a bag (ingest.bag=PATH) with one camera and an odometry or TF topic")
    if c.bag is None:
        return VideoSource(c)
    return MonoBagSource(c) if c.mono else BagSource(c)
