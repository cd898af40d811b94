"""Render throughput of the synthetic world: stereo frames per second.

    python benchmarks/render_speed.py [--sequences 4] [--frames 40] [--set world.width=256 world.height=144]
    python benchmarks/render_speed.py --set render.backend=torch [render.device=cpu]   # the torch port (conf/render)

Renders the default world (the embedded default settings, with any `--set` overrides) into a
temporary folder with the real
synthesize code path (world build, both views, PNG writing), once on one worker and once on
every core, and prints frames per second for each, with the renderer conf/render names.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from hydra import compose, initialize_config_dir

from offroad_path.config import register_configs
from offroad_path.world.record import Drive, record_sequences, sequence_seed

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequences", type=int, default=4)
    parser.add_argument("--frames", type=int, default=40)
    parser.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE", help="Hydra overrides (world.*, render.*)")
    args = parser.parse_args()
    register_configs()
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("config", overrides=[f"world.frames={args.frames}", *args.set])
    cores = os.cpu_count() or 1
    frames = args.sequences * args.frames
    size = f"{cfg.world.width}x{cfg.world.height}"
    print(f"{args.sequences} sequences x {args.frames} stereo frames at {size}, {cores} cores, renderer {cfg.render.backend}")
    for workers in sorted({1, cores}):
        with tempfile.TemporaryDirectory() as tmp:
            start = time.perf_counter()
            drives = [Drive(f"seq_{i:03d}", sequence_seed(0, i)) for i in range(args.sequences)]
            record_sequences(cfg.world, drives, Path(tmp), workers, render=cfg.render)
            elapsed = time.perf_counter() - start
        print(f"workers={workers}: {elapsed:.1f} s, {frames / elapsed:.2f} stereo frames/s")


if __name__ == "__main__":
    main()
