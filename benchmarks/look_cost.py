"""What a world's look costs: building a world and rendering one view, with and without
world.appearance, back to back in one process on one core.

    python benchmarks/look_cost.py [--worlds 8] [--views 10]

For each setting: the mean seconds of build_world over the first `worlds` seeds, and the mean
milliseconds of render_view (one camera, the default 256 x 144, motion blur of 0.1 m) over `views`
poses of each world.
"""

from __future__ import annotations

import argparse
import time

from offroad_path.config import load_config
from offroad_path.world.record import camera_for
from offroad_path.world.render import render_view
from offroad_path.world.scene import build_world


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=8)
    parser.add_argument("--views", type=int, default=10)
    args = parser.parse_args()
    for enabled in (False, True):
        cfg = load_config(f"world.appearance.enabled={str(enabled).lower()}", "threads=1")
        camera = camera_for(cfg.world)
        build = render = 0.0
        for seed in range(args.worlds):
            start = time.perf_counter()
            world = build_world(cfg.world, seed)
            build += time.perf_counter() - start
            start = time.perf_counter()
            for k in range(0, len(world.poses), max(1, len(world.poses) // args.views)):
                render_view(world, camera, world.poses[k], cfg.world.max_distance_m, motion_m=0.1, noise_key=(seed, k))
            render += (time.perf_counter() - start) / args.views
        label = "with looks" if enabled else "without (the single look)"
        print(f"{label}: build {build / args.worlds:.2f} s per world, render {1000 * render / args.worlds:.0f} ms per view")


if __name__ == "__main__":
    main()
