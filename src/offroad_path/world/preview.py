"""Contact sheets of rendered sequences: left image, semantic map and depth side by side.

python -m offroad_path.world.preview data/synthetic docs/images/world_samples.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from offroad_path.sequence.reader import Sequence, find_sequences, open_sequence
from offroad_path.utils.cli import clear_errors

# RGB per class id: sky, water, dirt, paved road, grass, foliage, tree, man-made obstacle.
CLASS_COLOURS = np.array(
    [[135, 190, 235], [30, 80, 200], [150, 100, 50], [110, 110, 110], [90, 190, 60], [30, 120, 30], [10, 70, 10], [230, 40, 40]], np.uint8
)


def colour_semantic(semantic: np.ndarray) -> np.ndarray:
    return CLASS_COLOURS[np.minimum(semantic, len(CLASS_COLOURS) - 1)]


def colour_depth(depth_m: np.ndarray, near_m: float = 2.0, far_m: float = 60.0) -> np.ndarray:
    """Inverse depth in a perceptual colour map; black where there is no depth."""
    inv = (1 / np.clip(depth_m, near_m, far_m) - 1 / far_m) / (1 / near_m - 1 / far_m)
    rgb = cv2.applyColorMap(np.uint8(255 * inv), cv2.COLORMAP_TURBO)[:, :, ::-1]
    return np.where(depth_m[..., None] > 0, rgb, 0).astype(np.uint8)


def frame_row(seq: Sequence, i: int) -> np.ndarray:
    parts = [seq.load_left(i)]
    if seq.semantic is not None:
        parts.append(colour_semantic(seq.load_semantic(i)))
    if seq.depth is not None:
        parts.append(colour_depth(seq.load_depth(i)))
    return np.hstack(parts)


def contact_sheet(root: str | Path, rows: int = 3) -> np.ndarray:
    """One row per sequence (the first `rows`), each from the middle of its drive."""
    sequences = [open_sequence(p) for p in find_sequences(root)[:rows]]
    return np.vstack([frame_row(seq, len(seq) // 2) for seq in sequences])


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m offroad_path.world.preview", description=__doc__.splitlines()[0])
    parser.add_argument("sequences", help="a sequence folder or a folder of sequences")
    parser.add_argument("out", help="PNG to write")
    parser.add_argument("--rows", type=int, default=3)
    args = parser.parse_args(argv)
    with clear_errors():
        sheet = contact_sheet(args.sequences, args.rows)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(args.out, sheet[:, :, ::-1])


if __name__ == "__main__":
    main()
