"""Drive through a world and record it as a stereo sequence in the layout of docs/design.md."""

from __future__ import annotations

import json
import logging
import math
import time
from collections.abc import Iterator
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from omegaconf import OmegaConf

from offroad_path import __version__
from offroad_path.config.world_schema import WorldConfig
from offroad_path.geometry.exact import matmul, rigid_inverse
from offroad_path.geometry.path import path_length
from offroad_path.sequence import meta as meta_keys
from offroad_path.sequence.calibration import StereoCalibration
from offroad_path.sequence.png import FAST_PNG
from offroad_path.sequence.poses import poses_to_text
from offroad_path.utils.media import write_image
from offroad_path.utils.parallel import map_processes
from offroad_path.world.classes import CLASS_NAMES
from offroad_path.world.conditions import conditions_csv, frame_conditions
from offroad_path.world.render import PinholeCamera, View
from offroad_path.world.renderer import Renderer
from offroad_path.world.scene import World, build_world

log = logging.getLogger(__name__)

DEPTH_MAX_MM = 65535
SEMANTIC_PNG = [cv2.IMWRITE_PNG_COMPRESSION, 3]  # few classes: zlib level 3 makes these 4 KiB, FAST_PNG 19 KiB


def sequence_seed(master_seed: int, index: int) -> int:
    """Independent, reproducible per-sequence seeds from one master seed."""
    return int(np.random.SeedSequence([master_seed, index]).generate_state(1)[0])


def footprint_meta(vehicle) -> dict[str, float]:
    """meta.json's footprint entries (meta_keys.FOOTPRINT's spelling) from the vehicle config, in the order
    meta.json has always held them; the extent is along the camera's forward axis, from the camera centre."""
    footprint = {
        "camera_height_m": vehicle.camera_height_m,
        "camera_pitch_deg": vehicle.camera_pitch_deg,
        "width_m": vehicle.width_m,
        "front_m": vehicle.length_m / 2 - vehicle.camera_forward_m,
        "rear_m": -(vehicle.length_m / 2 + vehicle.camera_forward_m),
    }
    return {meta_keys.FOOTPRINT[key]: value for key, value in footprint.items()}


def camera_for(cfg: WorldConfig) -> PinholeCamera:
    return PinholeCamera.from_fov(cfg.width, cfg.height, cfg.hfov_deg)


def encode_depth(depth_m: np.ndarray) -> np.ndarray:
    """Metres to 16-bit millimetres: 0 stays 'none', hits are at least 1 mm, far ones saturate."""
    mm = np.clip(np.rint(depth_m * 1000.0), 1, DEPTH_MAX_MM)
    return np.where(depth_m > 0, mm, 0).astype(np.uint16)


def record_sequence(  # noqa: PLR0913
    cfg: WorldConfig, seed: int, out_dir: Path, test_set: str | None = None, draw: str = "training", *, render: Any = None
) -> dict:
    """Render one sequence into out_dir; returns a summary (frames, distance, class pixel counts).
    test_set: None for a training drive, else a held-out test world (meta.json's "split": "test"),
    which the split stage keeps for testing, of that test set (meta.json's "test_set": main, or the
    stress set it was drawn for); draw: how its look is drawn (offroad_path.world.appearance.DRAWS);
    render: the renderer (conf/render; None: the NumPy reference)."""
    held_out = test_set is not None
    world = build_world(cfg, seed, draw)
    camera = camera_for(cfg)
    baseline = cfg.rig.baseline_m

    for sub in ("image_l", "image_r", "depth", "semantic"):
        (out_dir / sub).mkdir(parents=True)
    class_pixels = np.zeros(len(CLASS_NAMES), np.int64)
    for k, (left, right) in enumerate(stereo_views(world, camera, cfg, seed, render)):
        name = f"{k:06d}.png"
        write_image(out_dir / "image_l" / name, left.image[:, :, ::-1], FAST_PNG)
        write_image(out_dir / "image_r" / name, right.image[:, :, ::-1], FAST_PNG)
        write_image(out_dir / "depth" / name, encode_depth(left.depth), FAST_PNG)
        write_image(out_dir / "semantic" / name, left.semantic, SEMANTIC_PNG)
        class_pixels += np.bincount(left.semantic.ravel(), minlength=len(CLASS_NAMES))

    first_inv = rigid_inverse(world.poses[0])
    relative = matmul(first_inv[None], world.poses)  # KITTI convention: the first pose is the identity
    (out_dir / "calib.txt").write_text(StereoCalibration.from_intrinsics(camera.K, baseline).to_text())
    (out_dir / "poses.txt").write_text(poses_to_text(relative))
    (out_dir / "times.txt").write_text("".join(f"{k / cfg.fps:.6f}\n" for k in range(len(world.poses))))
    (out_dir / "steering.txt").write_text("".join(f"{s:.6f}\n" for s in world.steering))
    (out_dir / "conditions.csv").write_text(conditions_csv(frame_conditions(world, cfg)))
    vehicle = cfg.vehicle
    distance = path_length(world.poses)
    meta = {
        meta_keys.GENERATOR: meta_keys.RENDERED,
        "generator_version": __version__,
        "seed": seed,
        "rig": cfg.rig.name,
        "baseline_m": baseline,
        "fps": cfg.fps,
        "width": cfg.width,
        "height": cfg.height,
        "hfov_deg": cfg.hfov_deg,
        **footprint_meta(vehicle),
        "vehicle": OmegaConf.to_container(vehicle) if OmegaConf.is_config(vehicle) else asdict(vehicle),
        "steering": "bicycle-model wheel angle over max_steering_deg, in [-1, 1], positive turns right",
        "depth": "z of the left camera in millimetres (uint16), 0 for sky, 65535 for 65.535 m or farther",
        "classes": list(CLASS_NAMES),
        "world_from_first_camera": world.poses[0].tolist(),
        "world_frame": "x right, y down (gravity), z forward at the start",
        "distance_m": distance,
        "frames": len(world.poses),
        "world": world_settings(cfg),  # the drive stage and the slip targets rebuild the world from these and the seed
    } | ({meta_keys.SPLIT: meta_keys.HELD_OUT, meta_keys.TEST_SET: test_set} if held_out else {})
    if world.look is not None:  # absent: the world's single original look (world.appearance.enabled=false)
        meta["appearance"] = asdict(world.look)
    if world.slip is not None:  # absent: no slip, steering.txt is the bicycle model's angle
        meta["steering"] = (
            "the driver's input under slip (world.slip): bicycle-model wheel angle of the true curvature "
            "over the yaw-rate factor, over max_steering_deg"
        )
        meta["slip"] = OmegaConf.to_container(cfg.slip) if OmegaConf.is_config(cfg.slip) else asdict(cfg.slip)
    (out_dir / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    summary = {"name": out_dir.name, "seed": seed, "frames": len(world.poses), "distance_m": distance}
    return summary | ({meta_keys.SPLIT: meta_keys.HELD_OUT} if held_out else {}) | {"class_pixels": class_pixels.tolist()}


def stereo_views(world: World, camera: PinholeCamera, cfg: WorldConfig, seed: int, render: Any = None) -> Iterator[tuple[View, View]]:
    """Each frame's (left, right) views of the drive, in order: frame k's noise from (seed, k, camera),
    rendered through conf/render's renderer (world.renderer)."""
    to_right = np.eye(4)
    to_right[0, 3] = cfg.rig.baseline_m  # the right camera sits at +B along the left camera's x axis
    left_poses = world.poses
    right_poses = matmul(left_poses, to_right[None])
    shutter_m = _shutter_metres(world, cfg.fps)
    renderer = Renderer(world, camera, cfg.max_distance_m, render)
    per_call = max(1, renderer.views_per_batch // 2)  # frames whose two views render together (the reference: one frame)
    for start in range(0, len(left_poses), per_call):
        frames = slice(start, min(start + per_call, len(left_poses)))
        numbers = range(frames.start, frames.stop)
        poses = np.concatenate([left_poses[frames], right_poses[frames]])
        keys = [(seed, k, 0) for k in numbers] + [(seed, k, 1) for k in numbers]
        views = renderer.views(poses, np.tile(shutter_m[frames], 2), keys)
        yield from zip(views[: len(numbers)], views[len(numbers) :], strict=True)


def _shutter_metres(world: World, fps: float) -> np.ndarray:
    """Metres driven while each frame's shutter is open (its speed from the frame spacing), 0 without a look."""
    if world.look is None:
        return np.zeros(len(world.frame_s))
    speed = np.gradient(world.frame_s) * fps
    return speed * world.look.sensor.shutter_s


def _record_job(args: tuple[WorldConfig, int, str, str | None, str, Any]) -> dict:
    cv2.setNumThreads(1)  # one process per core: no nested threading
    cfg, seed, out_dir, test_set, draw, render = args
    return record_sequence(cfg, seed, Path(out_dir), test_set, draw, render=render)


@dataclass(frozen=True)
class Drive:
    """One world to render: its folder name and seed; test_set: the held-out set it belongs to (None: a
    training drive); draw: how its look was drawn (offroad_path.world.held_out)."""

    name: str
    seed: int
    test_set: str | None = None
    draw: str = "training"


def record_sequences(cfg: WorldConfig, drives: list[Drive], out_dir: Path, workers: int = 0, render: Any = None) -> list[dict]:
    """Render each drive into out_dir/<name> in parallel, one process per worker, with `render`
    (conf/render; None: the NumPy reference)."""
    jobs = [(cfg, d.seed, str(out_dir / d.name), d.test_set, d.draw, render) for d in drives]
    start = time.perf_counter()
    summaries = map_processes(_record_job, jobs, workers, [f"sequence {drive.name}" for drive in drives], "render")
    elapsed = time.perf_counter() - start
    frames = sum(s["frames"] for s in summaries)
    log.info("rendered %d sequences, %d stereo frames in %.1f s: %.2f stereo frames/s", len(drives), frames, elapsed, frames / elapsed)
    return summaries


def world_settings(cfg: WorldConfig) -> dict:
    """What draws a world and its camera: the world config less `slip` (which changes only the
    recorded steering, and which steering_under_slip and drive turn on over rendered worlds)."""
    settings = OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else asdict(cfg)
    return {k: v for k, v in settings.items() if k != "slip"}


def _flat(settings: dict, prefix: str = "") -> dict:
    out = {}
    for key, value in settings.items():
        out |= _flat(value, f"{prefix}{key}.") if isinstance(value, dict) else {f"{prefix}{key}": value}
    return out


def check_rendered_with(cfg: WorldConfig, meta_path: Path, recorded: dict) -> None:
    """ValueError naming meta.json and the first differing key when a rendered sequence was drawn
    with world settings other than `cfg`'s (meta.json's "world"; sequences rendered before it was
    recorded are checked by rebuild_world's drive length only)."""
    if "world" not in recorded:
        return
    now, then = _flat(world_settings(cfg)), _flat(recorded["world"])
    if differ := sorted(k for k in now.keys() | then.keys() if now.get(k) != then.get(k)):
        shown = "; ".join(f"world.{k}={now.get(k)!r} (rendered with {then.get(k)!r})" for k in differ[:3])
        more = f" and {len(differ) - 3} more" if len(differ) > 3 else ""
        raise ValueError(
            f"{meta_path}: rendered with other world settings than this config's: {shown}{more}; use those or rerun synthesize"
        )


def rebuild_world(cfg: WorldConfig, folder: Path) -> World:
    """The world a rendered sequence (folder, with its meta.json) was drawn from, rebuilt from its seed
    with `cfg`; a ValueError naming the folder when cfg is not the config it was rendered with."""
    meta = json.loads((folder / "meta.json").read_text())
    check_rendered_with(cfg, folder / "meta.json", meta)
    world = build_world(cfg, int(meta["seed"]), look_draw(meta.get("appearance", {})))
    if not math.isclose(path_length(world.poses), float(meta["distance_m"]), rel_tol=1e-9):
        raise ValueError(
            f"{folder}: rendered with another world config than this one (its drive is {meta['distance_m']:.3f} m, "
            f"this config's {path_length(world.poses):.3f} m); rerun synthesize"
        )
    return world


def look_draw(appearance: dict) -> str:
    """How a recorded world's look was drawn, from meta.json's "appearance" (offroad_path.world.appearance.DRAWS)."""
    return "held_out" if appearance.get("held_out") else "full_variety" if appearance.get("full_variety") else "training"


def _slip_steering_job(args: tuple[WorldConfig, str]) -> np.ndarray:
    cv2.setNumThreads(1)
    cfg, folder = args
    return rebuild_world(cfg, Path(folder)).steering


def steering_under_slip(cfg: WorldConfig, folders: list[Path], workers: int = 0) -> dict[str, np.ndarray]:
    """{sequence name: steering (frames,)}: what each rendered sequence's steering.txt would hold had
    it been synthesised with world.slip on (cfg.slip's factors): the driver's input that made the same
    true motion on slippery ground. The images, poses and so the path labels are the same either way."""
    slippery = OmegaConf.create(OmegaConf.to_container(cfg, resolve=True) if OmegaConf.is_config(cfg) else asdict(cfg))
    slippery.slip.enabled = True
    steering = map_processes(_slip_steering_job, [(slippery, str(f)) for f in folders], workers, [f"sequence {f}" for f in folders])
    return {f.name: s for f, s in zip(folders, steering, strict=True)}
