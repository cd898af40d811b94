"""Driving one test world: rebuild it from its seed, make each argument's vehicle, course and
policies, drive every policy from every start, and draw the world's trajectory plots (and, for the
first world, a video per policy). One world is one job of the drive stage's worker processes.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import matplotlib
import numpy as np
import torch

from offroad_path.drive.course import Course
from offroad_path.drive.loop import Drive, DriveLog, LoopSettings, Setup, drive_together
from offroad_path.drive.policies import OraclePolicy, PathPolicy, PilotNetPolicy, Policy, StereoRig, StraightPolicy
from offroad_path.drive.vehicle import Vehicle
from offroad_path.errors import InputError
from offroad_path.geometry.stereo import sgbm
from offroad_path.inference.path_filter import PostprocessParams
from offroad_path.sequence import meta
from offroad_path.utils.media import VideoFile
from offroad_path.utils.rules import ConfigValueError
from offroad_path.world.record import check_rendered_with, rebuild_world
from offroad_path.world.render import PinholeCamera
from offroad_path.world.render_torch import torch_device
from offroad_path.world.renderer import Renderer
from offroad_path.world.scene import World
from offroad_path.world.slip import SLIP_STREAM, Slip, make_slip
from offroad_path.world.trajectory import VehicleGeometry

matplotlib.use("Agg")
TEMPORAL = "+temporal"
BUILT_IN = ("oracle", "straight")
END_MARGIN_M = 30.0  # starts leave this much reference drive beyond a drive's end, for the pursuit's look-ahead


@dataclass(frozen=True)
class TestWorld:
    name: str
    folder: str
    seed: int
    recorded: dict  # its meta.json


def test_worlds(synthetic_dir: Path, limit: int | None) -> list[TestWorld]:
    """The main test set's held-out test worlds (meta.json's "split": "test", no stress set), in name order, the first `limit`."""
    found = []
    for meta_path in sorted(synthetic_dir.glob("*/meta.json")):
        try:
            recorded = json.loads(meta_path.read_text())
        except (OSError, ValueError) as e:
            raise InputError(meta_path, f"cannot be read as JSON ({type(e).__name__}: {e})") from e
        if not isinstance(recorded, dict):
            raise InputError(meta_path, "is not a JSON object")
        if meta.held_out(recorded, meta_path) and meta.test_set(recorded) == meta.MAIN:
            if not isinstance(recorded.get("seed"), int):
                raise InputError(
                    meta_path, 'has no integer "seed": the drive stage rebuilds a test world from the seed synthesize recorded'
                )
            found.append(TestWorld(meta_path.parent.name, str(meta_path.parent), recorded["seed"], recorded))
    if not found:
        raise ValueError(f'{synthetic_dir}: no held-out test world (a meta.json with "split": "test"); run synthesize')
    return found[:limit] if limit else found


def check_worlds(worlds: list[TestWorld], world_cfg, d) -> None:
    """Before any world is built: each was rendered with `world_cfg` (world.record.check_rendered_with),
    and its drive holds d.length_m of route (a drive ends drive.respawn_m before the reference's end:
    a longer route would be cut short while the report states d.length_m)."""
    for w in worlds:
        check_rendered_with(world_cfg, Path(w.folder) / "meta.json", w.recorded)
    shortest = min(worlds, key=lambda w: float(w.recorded.get("distance_m", math.inf)))
    room = float(shortest.recorded.get("distance_m", math.inf)) - d.respawn_m
    if d.length_m > room:
        raise ConfigValueError(
            f"drive.length_m={d.length_m:g}: longer than the route test world {shortest.name} holds ({room:.1f} m: its "
            f"{shortest.recorded['distance_m']:.1f} m drive less drive.respawn_m)"
        )


def checkpoint_of(name: str, d, seed: int) -> Path | None:
    """The checkpoint a policy name needs (d: the drive config; seed: the training seed), None for none."""
    if name in ("oracle", "straight"):
        return None
    if name in d.pilotnets:
        return Path(str(d.pilotnets[name]).replace("{seed}", str(seed)))
    return Path(d.runs_dir) / name.removesuffix(TEMPORAL) / f"seed{seed}" / "checkpoints" / "best.ckpt"


def pilotnet_checkpoint(path: Path) -> dict:
    """A train_steering checkpoint (weights_only); CheckpointError naming the file for any other."""
    from offroad_path.steering.pilotnet_task import required_hyperparameters
    from offroad_path.training.checkpoints import CheckpointError, load_checkpoint

    saved = load_checkpoint(path)
    if missing := [k for k in required_hyperparameters() if k not in saved["hyper_parameters"]]:
        raise CheckpointError(f"{path}: not a PilotNet checkpoint of train_steering (no {', '.join(missing)} among its hyper-parameters)")
    return saved


def make_policy(name: str, d, seed: int, params: PostprocessParams, device: str = "cpu") -> Policy:
    if name == "oracle":
        return OraclePolicy(d.lookahead_m)
    if name == "straight":
        return StraightPolicy()
    if name in d.pilotnets:
        from offroad_path.steering.pilotnet_task import SteeringTask
        from offroad_path.training.checkpoints import load_weights

        saved = pilotnet_checkpoint(checkpoint_of(name, d, seed))
        hp = saved["hyper_parameters"]
        task = SteeringTask(**hp)
        load_weights(task, checkpoint_of(name, d, seed), saved)
        return PilotNetPolicy(task.to(device).eval(), int(hp["width"]), int(hp["height"]), name, task.max_curvature)
    from offroad_path.inference.runners import TorchModel

    model = TorchModel(checkpoint_of(name, d, seed), device)
    alpha = d.temporal_alpha if name.endswith(TEMPORAL) else None
    return PathPolicy(name, model, params, d.lookahead_m, d.threshold, alpha)


@dataclass(frozen=True)
class WorldJob:
    world: TestWorld
    world_cfg: object  # the world config node the test worlds were rendered with
    drive_cfg: object  # the drive config
    training_seeds: tuple[int, ...]  # every policy drives every start once with each seed's networks
    postprocess: PostprocessParams  # sized for the drive's camera
    disparity: object  # label.disparity
    out_dir: str  # the stage's temporary output folder
    video: bool
    render: object  # conf/render: the renderer of the drive's views
    device: str  # drive.device: where the policies' networks run


def drive_world(job: WorldJob) -> list[tuple[str, DriveLog]]:
    """Every argument's policies from every start with every training seed in one world, all in
    lockstep (loop.drive_together): (argument, log) in a fixed order (seed, argument, policy, start);
    the plots and the video show the first seed."""
    cv2.setNumThreads(1)  # one process per core
    torch.set_num_threads(1)
    d, world = job.drive_cfg, rebuild_world(job.world_cfg, Path(job.world.folder))
    camera = PinholeCamera.from_fov(d.width, d.height, job.world_cfg.hfov_deg)
    settings = LoopSettings(d.rate_hz, d.speed_mps, d.length_m, d.respawn_m, d.timeout_factor, d.water_intervenes)
    rig = stereo_rig(world, camera, job.world_cfg, job.disparity, job.render)
    device = str(torch_device(job.device))
    slip = _slip(world, job) if "traction" in d.arguments else None
    drives: list[Drive] = []
    labels: list[tuple[str, int, int]] = []  # each drive's (argument, seed, start)
    courses: dict[str, Course] = {}  # the first seed's, for the plots
    for seed in job.training_seeds:
        policies: dict[str, Policy] = {}
        for argument, names in d.arguments.items():
            geometry = VehicleGeometry.of(d.other_vehicle) if argument == "vehicle" else VehicleGeometry.of(job.world_cfg.vehicle)
            course = Course(world, geometry, d.corridor_m, tuple(d.body_band_m), d.foliage_is_obstacle)
            courses.setdefault(argument, course)
            usable = max(course.length_m - d.length_m - END_MARGIN_M, 0.0)
            for name in names:
                if name not in policies:
                    policies[name] = make_policy(name, d, seed, job.postprocess, device)
                for k in range(d.starts_per_world):
                    yaw = _yaw_factor(world, slip, job.world.seed, k) if argument == "traction" else None
                    setup = Setup(course, Vehicle(geometry, d.steering_rate_deg_s, yaw), rig, settings)
                    video = seed == job.training_seeds[0] and job.video and argument == "steering" and k == 0
                    drives.append(Drive(setup, policies[name].fresh(), usable * k / d.starts_per_world, video))
                    labels.append((argument, seed, k))
    out: list[tuple[str, DriveLog]] = []
    first: dict[str, dict[str, list[DriveLog]]] = {}  # the first seed's logs per argument and policy, for the plots
    for one, log, (argument, seed, k) in zip(drives, drive_together(drives), labels, strict=True):
        log.world, log.start, log.seed = job.world.name, k, seed
        if one.video:
            _write_video(log, Path(job.out_dir) / "videos" / f"{log.policy}.mp4", d.rate_hz)
        if seed == job.training_seeds[0]:
            first.setdefault(argument, {}).setdefault(log.policy, []).append(log)
        out.append((argument, log))
    for argument, logs in first.items():
        plot_world(world, courses[argument], logs, Path(job.out_dir) / "trajectories" / argument / f"{job.world.name}.png")
    return out


def stereo_rig(world: World, camera: PinholeCamera, world_cfg, disparity, render) -> StereoRig:
    """The driven vehicle's rig (the world's baseline and range, label.disparity's matcher), rendering
    through conf/render's renderer (world.renderer)."""
    return StereoRig(Renderer(world, camera, world_cfg.max_distance_m, render), world_cfg.rig.baseline_m, sgbm(disparity))


def _slip(world: World, job: WorldJob) -> Slip:
    """The traction argument's ground: world.slip's surfaces and patches over the whole world."""
    grid = world.material_grid
    lo = np.array([grid.x0, grid.z0])
    return world.slip or make_slip(job.world_cfg.slip, job.world.seed, lo, lo + np.array(grid.shape[::-1]) * grid.step)


def _yaw_factor(world: World, slip: Slip, seed: int, start: int):
    """The yaw-rate factor on `slip`'s ground, with per-sub-step noise drawn from a generator of the
    world (seed) and start, the same sequence for every policy."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, SLIP_STREAM, 2, start]))

    def factor(xz: np.ndarray) -> float:
        here = xz[None]
        return max(float(slip.factor(world.surface(here), here)[0]) * (1.0 + slip.noise * rng.normal()), 0.05)

    return factor


def _write_video(log: DriveLog, path: Path, fps: float) -> None:
    h, w = log.frames[0].shape[:2]
    with VideoFile(path, fps, (w, h)) as video:
        for image in log.frames:
            video.write(cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    log.frames = []  # the frames are not sent back to the stage


def plot_world(world: World, course: Course, logs: dict[str, list[DriveLog]], path: Path) -> None:
    """Top down: track and forks, the reference drive, objects in the body's height band, each
    policy's path, and its interventions (x)."""
    import matplotlib.pyplot as plt

    path.parent.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(6, 6), dpi=100)
    ax.plot(*world.track.xz.T, color="0.75", linewidth=6, solid_capstyle="round", label="track")
    for fork in world.forks:
        ax.plot(*fork.xz.T, color="0.85", linewidth=5)
    ax.plot(*world.drive.xz.T, "k--", linewidth=0.8, label="reference drive")
    xy = np.array([t for group in logs.values() for g in group for t in g.trajectory])
    lo, hi = np.nanmin(xy, axis=0) - 10, np.nanmax(xy, axis=0) + 10
    for f in course.footprints:
        if np.all(f.xz > lo) and np.all(f.xz < hi):
            ax.add_patch(plt.Circle(tuple(f.xz), f.radius, color="sienna", alpha=0.6))
    for i, (name, group) in enumerate(logs.items()):
        colour = f"C{i}"
        for j, g in enumerate(group):
            ax.plot(*np.array(g.trajectory).T, color=colour, linewidth=1.2, label=name if j == 0 else None)
            for x, z, _ in g.interventions:
                ax.plot(x, z, "x", color=colour, markersize=8, markeredgewidth=2)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, right at the start)")
    ax.set_ylabel("z (m, forward at the start)")
    ax.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def drive_params(postprocess_cfg, drive_width: int, world_width: int) -> PostprocessParams:
    """The post-processing settings for the drive's camera: the blur's sigma scaled to its width."""
    params = PostprocessParams.from_config(postprocess_cfg)
    return replace(params, sigma=params.sigma * drive_width / world_width)
