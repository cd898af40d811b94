"""Stereo rig calibrations as the tools that make them write them, read into one model.

Formats: OpenCV `FileStorage` YAML/XML from `cv2.stereoCalibrate` (K1, D1, K2, D2, R, T; M1/M2 as
OpenCV's stereo_calib sample names them), Kalibr's `camchain.yaml` (cam0, cam1 with T_cn_cnm1),
ROS camera_info YAML (one file per camera, as `camera_calibration` writes them) and ROS CameraInfo
messages. Convention throughout: a point x_l in the left camera is x_r = R x_l + T in the right
camera (OpenCV's), T in metres.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import yaml

from offroad_path.errors import InputError

MAX_BASELINE_M = 10.0  # a larger |T| is a calibration in millimetres or board squares, not metres
FISHEYE_MODELS = ("equidistant", "fisheye")
PINHOLE_MODELS = ("plumb_bob", "radtan", "rational_polynomial", "pinhole", "")
PINHOLE_COEFFICIENTS = (0, 4, 5, 8, 12, 14)  # the lengths of distortion vector OpenCV's pinhole model takes


@dataclass(frozen=True)
class CameraModel:
    K: np.ndarray  # (3, 3)
    D: np.ndarray  # (n,): OpenCV's k1 k2 p1 p2 [k3 ...], or k1..k4 for fisheye
    size: tuple[int, int] | None  # (width, height) the calibration was made at; None: the images'
    fisheye: bool = False

    def check(self, name: str, source: Path) -> None:
        """Refuse a camera no image can be rectified with: InputError naming `source`."""
        if not (np.isfinite(self.K).all() and np.isfinite(self.D).all()):
            raise InputError(source, f"{name}'s K or D holds a value that is not a finite number")
        if not (self.K[0, 0] > 0 and self.K[1, 1] > 0):
            raise InputError(source, f"{name}'s focal lengths fx = {self.K[0, 0]:g}, fy = {self.K[1, 1]:g} must be positive")
        if self.size is not None and not (self.size[0] > 0 and self.size[1] > 0):
            raise InputError(source, f"{name}'s image size {self.size[0]}x{self.size[1]} must be positive")
        if self.fisheye and self.D.size != 4:
            raise InputError(source, f"{name} is equidistant (fisheye) and needs 4 distortion coefficients, has {self.D.size}")
        if not self.fisheye and self.D.size not in PINHOLE_COEFFICIENTS:
            raise InputError(source, f"{name}'s distortion has {self.D.size} coefficients; OpenCV's model takes 0, 4, 5, 8, 12 or 14")

    def at_size(self, size: tuple[int, int], source: Path) -> CameraModel:
        """This camera for images of `size`: K scaled when the calibration was made at a uniform
        multiple of it (e.g. calibrated at 1920x1080, recorded at 960x540)."""
        if self.size is None or tuple(self.size) == tuple(size):
            return replace(self, size=tuple(size))
        sx, sy = size[0] / self.size[0], size[1] / self.size[1]
        if abs(sx - sy) > 1e-3 * max(sx, sy):
            raise InputError(
                source, f"was calibrated at {self.size[0]}x{self.size[1]}, but the images are {size[0]}x{size[1]}: not a uniform scale"
            )
        K = self.K.copy()
        K[0] *= sx
        K[1] *= sy
        return CameraModel(K, self.D, tuple(size), self.fisheye)


@dataclass(frozen=True)
class StereoRig:
    left: CameraModel
    right: CameraModel
    R: np.ndarray  # (3, 3) left camera to right camera
    T: np.ndarray  # (3,) metres
    source: Path  # the file (or bag) it came from, for messages
    rostopics: tuple[str | None, str | None] = (None, None)  # Kalibr names the image topics

    def checked(self) -> StereoRig:
        """Refuse rigs the label stage cannot use, naming the calibration: whatever it came from (a
        calibration file, two ROS YAML files, a bag's CameraInfo), the same checks."""
        for name, cam in (("left", self.left), ("right", self.right)):
            cam.check(f"the {name} camera", self.source)
        if not (np.isfinite(self.R).all() and np.isfinite(self.T).all()):
            raise InputError(self.source, "R or T holds a value that is not a finite number")
        if not np.allclose(self.R.T @ self.R, np.eye(3), atol=1e-4) or np.linalg.det(self.R) < 0:
            raise InputError(self.source, "R is not a rotation matrix")
        baseline = float(np.linalg.norm(self.T))
        if not 0 < baseline <= MAX_BASELINE_M:
            raise InputError(
                self.source,
                f"gives a baseline |T| = {baseline:g}: expected metres in (0, {MAX_BASELINE_M:g}]; "
                "set ingest.calibration_unit_m (e.g. 0.001 for millimetres)",
            )
        if abs(self.T[0]) < max(abs(self.T[1]), abs(self.T[2])):
            raise InputError(
                self.source, f"T = {np.round(self.T, 4).tolist()} is not a side-by-side rig: the cameras must be offset mainly along x"
            )
        if self.T[0] > 0:
            raise InputError(
                self.source, f"T_x = {self.T[0]:g} > 0: the 'right' camera is left of the 'left' one; left and right are swapped"
            )
        return self


def read_rig(path: str | Path, right_path: str | Path | None = None, unit_m: float = 1.0) -> StereoRig:
    """A stereo calibration file (OpenCV, Kalibr), or two ROS camera_info YAML files."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "is missing (ingest.calibration)")
    if right_path is not None:
        rig = rig_from_camera_infos(_ros_yaml(path), _ros_yaml(Path(right_path)), Path(right_path))
    elif path.suffix.lower() == ".xml" or path.read_text(errors="replace").startswith("%YAML"):
        rig = _opencv(path)
    else:
        data = _yaml(path)
        if "cam0" in data and "cam1" in data:
            rig = _kalibr(path, data)
        elif "camera_matrix" in data:
            raise InputError(path, "is one ROS camera_info file: give the right camera's as ingest.right_calibration")
        else:
            raise InputError(
                path,
                "is not a stereo calibration: expected OpenCV FileStorage (K1 D1 K2 D2 R T), Kalibr camchain (cam0, cam1) "
                "or ROS camera_info YAML",
            )
    return replace(rig, T=rig.T * unit_m).checked()


def camera_from_info(info: dict, source: Path, name: str = "left") -> tuple[CameraModel, tuple[np.ndarray, np.ndarray]]:
    """One camera from its CameraInfo (a dict of k, d, r, p, width, height, distortion_model), checked,
    with its rectifying rotation R (3, 3) and projection P (3, 4)."""
    K, D, Rr, P = (np.asarray(info[k], np.float64) for k in ("k", "d", "r", "p"))
    if K.size != 9 or Rr.size != 9 or P.size != 12 or not K.any():
        raise InputError(source, f"the {name} CameraInfo has no calibration (K, R, P empty or zero)")
    model = str(info.get("distortion_model", "")).lower()
    if model not in FISHEYE_MODELS + PINHOLE_MODELS:
        raise InputError(
            source, f"the {name} CameraInfo's distortion model {model!r} is not supported (plumb_bob, rational_polynomial, equidistant)"
        )
    size = (int(info["width"]), int(info["height"])) if info.get("width") else None
    camera = CameraModel(K.reshape(3, 3), D.ravel(), size, model in FISHEYE_MODELS)
    camera.check(f"the {name} camera", source)
    return camera, (Rr.reshape(3, 3), P.reshape(3, 4))


def rig_from_camera_infos(left: dict, right: dict, source: Path) -> StereoRig:
    """A rig from two CameraInfo (as dicts of k, d, r, p, width, height, distortion_model): ROS
    stores each camera's rectifying rotation R_i and projection P_i, whose P_right[0, 3] = -f' B;
    so x_rect_l = R_l x_l, x_rect_r = x_rect_l - (B, 0, 0) and x_r = R_r^T (R_l x_l + t)."""
    cams, rects = [], []
    for name, info in (("left", left), ("right", right)):
        camera, rectification = camera_from_info(info, source, name)
        cams.append(camera)
        rects.append(rectification)
    (R_l, _), (R_r, P_r) = rects
    if P_r[0, 3] == 0:
        raise InputError(
            source, "the right CameraInfo's P has no baseline (P[0, 3] = 0): the cameras were calibrated one by one, not as a stereo pair"
        )
    if not (np.isfinite(P_r).all() and P_r[0, 0] > 0 and P_r[1, 1] > 0):
        raise InputError(source, "the right CameraInfo's P holds a focal length that is not a positive number")
    t = np.array([P_r[0, 3] / P_r[0, 0], P_r[1, 3] / P_r[1, 1], 0.0])
    return StereoRig(cams[0], cams[1], R_r.T @ R_l, R_r.T @ t, source).checked()


def camera_info_dict(msg: Any) -> dict:
    """A CameraInfo message (ROS 1: K D R P, ROS 2: k d r p) as the dict rig_from_camera_infos reads."""
    fields = {k: getattr(msg, k) if hasattr(msg, k) else getattr(msg, k.upper()) for k in ("k", "d", "r", "p")}
    return {k: np.asarray(v, np.float64) for k, v in fields.items()} | {
        "width": int(msg.width),
        "height": int(msg.height),
        "distortion_model": str(msg.distortion_model),
    }


def _yaml(path: Path) -> dict:
    try:
        data = yaml.safe_load(path.read_text())
    except (yaml.YAMLError, UnicodeDecodeError) as e:
        raise InputError(path, f"is not valid YAML ({e})") from e
    if not isinstance(data, dict):
        raise InputError(path, "must hold a YAML mapping")
    return data


def _numbers(path: Path, value: Any, count: int | None, what: str) -> np.ndarray:
    try:
        array = np.asarray(value, np.float64).ravel()
    except (TypeError, ValueError) as e:
        raise InputError(path, f"{what} is not a list of numbers") from e
    if (count is not None and array.size != count) or not np.isfinite(array).all():
        raise InputError(path, f"{what} must be {count} finite numbers, has {array.size}")
    return array


def _opencv(path: Path) -> StereoRig:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    if not fs.isOpened():
        raise InputError(path, "cannot be opened by OpenCV's FileStorage")

    def mat(*names: str) -> np.ndarray:
        for name in names:
            node = fs.getNode(name)
            if node.isSeq():  # a plain list of numbers
                return np.array([node.at(i).real() for i in range(node.size())])
            if not node.empty():
                return node.mat()
        raise InputError(path, f"has no {' or '.join(names)}")

    K1, D1, K2, D2, R, T = mat("K1", "M1"), mat("D1"), mat("K2", "M2"), mat("D2"), mat("R"), mat("T")
    size = None
    for w, h in (("image_width", "image_height"), ("width", "height")):
        if not fs.getNode(w).empty():
            size = (int(fs.getNode(w).real()), int(fs.getNode(h).real()))
    fisheye = not fs.getNode("fisheye").empty() and bool(fs.getNode("fisheye").real())
    fs.release()
    cams = [
        CameraModel(_numbers(path, K, 9, name).reshape(3, 3), _numbers(path, D, None, f"D{i}"), size, fisheye)
        for i, (name, K, D) in enumerate((("K1", K1, D1), ("K2", K2, D2)), start=1)
    ]
    return StereoRig(cams[0], cams[1], _numbers(path, R, 9, "R").reshape(3, 3), _numbers(path, T, 3, "T"), path)


def _kalibr(path: Path, data: dict) -> StereoRig:
    cams, topics = [], []
    for name in ("cam0", "cam1"):
        cam = data[name]
        if not isinstance(cam, dict) or cam.get("camera_model", "pinhole") != "pinhole":
            raise InputError(path, f"{name}: only Kalibr's pinhole camera model is supported")
        fu, fv, pu, pv = _numbers(path, cam.get("intrinsics"), 4, f"{name}.intrinsics")
        model = str(cam.get("distortion_model", "radtan"))
        if model not in ("radtan", "equidistant", "none"):
            raise InputError(path, f"{name}: distortion model {model!r} is not supported (radtan, equidistant)")
        D = _numbers(path, cam.get("distortion_coeffs", []), None, f"{name}.distortion_coeffs")
        w, h = _numbers(path, cam.get("resolution"), 2, f"{name}.resolution")
        cams.append(CameraModel(np.array([[fu, 0, pu], [0, fv, pv], [0, 0, 1.0]]), D, (int(w), int(h)), model == "equidistant"))
        topics.append(cam.get("rostopic"))
    T_cn_cnm1 = _numbers(path, data["cam1"].get("T_cn_cnm1"), 16, "cam1.T_cn_cnm1").reshape(4, 4)
    return StereoRig(cams[0], cams[1], T_cn_cnm1[:3, :3], T_cn_cnm1[:3, 3], path, tuple(topics))


def _ros_yaml(path: Path) -> dict:
    if not path.is_file():
        raise InputError(path, "is missing (ingest.calibration)")
    data = _yaml(path)
    keys = {"k": "camera_matrix", "d": "distortion_coefficients", "r": "rectification_matrix", "p": "projection_matrix"}
    try:
        info = {k: np.asarray(data[v]["data"], np.float64) for k, v in keys.items()}
    except (KeyError, TypeError) as e:
        raise InputError(path, f"is not a ROS camera_info YAML: no {e} with data") from e
    return info | {
        "width": data.get("image_width"),
        "height": data.get("image_height"),
        "distortion_model": data.get("distortion_model", ""),
    }


def write_opencv(path: Path, rig: StereoRig, extra: dict[str, float] | None = None) -> None:
    """The rig as OpenCV FileStorage YAML (the names cv2.stereoCalibrate's outputs go by)."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    if rig.left.size is not None:
        fs.write("image_width", int(rig.left.size[0]))
        fs.write("image_height", int(rig.left.size[1]))
    for name, value in (("K1", rig.left.K), ("D1", rig.left.D), ("K2", rig.right.K), ("D2", rig.right.D), ("R", rig.R), ("T", rig.T)):
        fs.write(name, np.asarray(value, np.float64).reshape(-1, 1) if name in ("D1", "D2", "T") else np.asarray(value, np.float64))
    fs.write("fisheye", int(rig.left.fisheye))
    for key, value in (extra or {}).items():
        fs.write(key, float(value))
    fs.release()
