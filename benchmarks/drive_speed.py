"""Closed-loop driving throughput: control steps per second of the loop (render + policy + move +
judge), per kind of policy, on one core, in one held-out test world of the committed pipeline.

    python benchmarks/drive_speed.py [--policies unet-segmentation unet-segmentation+temporal pilotnet oracle]
                                     [--metres 40] [--together 1] [--set drive.width=512 drive.height=288]

Runs the drive stage's own code (offroad_path.drive) with its config (conf/drive, conf/render, any
`--set` overrides: render.backend=torch drive.device=auto for the GPU) on data/synthetic's first
test world, with the checkpoints the pipeline trained (data/runs, data/steering), and prints
milliseconds per control step and steps per second for each policy: --together drives of it from
evenly spaced starts in lockstep (their views rendered in batches, the network run once per step).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import torch

from offroad_path.config import load_config
from offroad_path.drive.course import Course
from offroad_path.drive.loop import Drive, LoopSettings, Setup, drive_together
from offroad_path.drive.vehicle import Vehicle
from offroad_path.drive.worlds import END_MARGIN_M, drive_params, make_policy, stereo_rig, test_worlds
from offroad_path.world.record import rebuild_world
from offroad_path.world.render import PinholeCamera
from offroad_path.world.render_torch import torch_device
from offroad_path.world.trajectory import VehicleGeometry


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policies", nargs="*", default=["unet-segmentation", "unet-segmentation+temporal", "pilotnet", "oracle"])
    parser.add_argument("--metres", type=float, default=40.0)
    parser.add_argument("--together", type=int, default=1, help="drives of each policy in lockstep")
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="Hydra overrides")
    args = parser.parse_args()
    cv2.setNumThreads(1)  # as in the stage's workers: one process per core
    torch.set_num_threads(1)
    cfg = load_config(*args.set)
    d = cfg.drive
    world_info = test_worlds(Path(d.synthetic_dir), 1)[0]
    start = time.perf_counter()
    world = rebuild_world(cfg.world, Path(world_info.folder))
    print(f"{world_info.name}: rebuilt in {time.perf_counter() - start:.1f} s; camera {d.width} x {d.height}, {args.metres:g} m per policy")
    geometry = VehicleGeometry.of(cfg.world.vehicle)
    camera = PinholeCamera.from_fov(d.width, d.height, cfg.world.hfov_deg)
    rig = stereo_rig(world, camera, cfg.world, cfg.label.disparity, cfg.render)
    settings = LoopSettings(d.rate_hz, d.speed_mps, args.metres, d.respawn_m, d.timeout_factor, d.water_intervenes)
    course = Course(world, geometry, d.corridor_m, tuple(d.body_band_m), d.foliage_is_obstacle)
    setup = Setup(course, Vehicle(geometry, d.steering_rate_deg_s), rig, settings)
    params = drive_params(cfg.postprocess, d.width, cfg.world.width)
    usable = max(course.length_m - args.metres - END_MARGIN_M, 0.0)
    for name in args.policies:
        policy = make_policy(name, d, cfg.seed, params, str(torch_device(d.device)))
        drives = [Drive(setup, policy.fresh(), usable * k / args.together) for k in range(args.together)]
        start = time.perf_counter()
        steps = sum(log.steps for log in drive_together(drives))
        elapsed = time.perf_counter() - start
        print(f"{name:32s} {steps:5d} steps  {1000 * elapsed / steps:7.1f} ms/step  {steps / elapsed:7.1f} steps/s")


if __name__ == "__main__":
    main()
