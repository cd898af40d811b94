"""Agreement of two label runs, frame by frame: `python -m offroad_path.label.compare A B`.

A and B are label folders (the label stage's out_dir). Prints, over the f0 frames both labelled,
the mean and minimum IoU of the path masks, and the frames only one of them labelled.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from offroad_path.errors import CommandParser, clear_errors


def read_mask(path: Path) -> np.ndarray:
    mask = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if mask is None:
        raise ValueError(f"{path}: cannot be decoded as an image")
    return mask > 0


def compare(a: Path, b: Path) -> dict:
    """IoU per common label file; label files are <sequence>/label/NNNNNN.png."""
    files_a = {p.relative_to(a) for p in a.glob("*/label/*.png")}
    files_b = {p.relative_to(b) for p in b.glob("*/label/*.png")}
    common = sorted(files_a & files_b)
    ious = []
    for rel in common:
        ma, mb = read_mask(a / rel), read_mask(b / rel)
        union = np.logical_or(ma, mb).sum()
        ious.append(np.logical_and(ma, mb).sum() / union if union else 1.0)
    return {
        "common": len(common),
        "only_a": len(files_a - files_b),
        "only_b": len(files_b - files_a),
        "mean_iou": float(np.mean(ious)) if ious else float("nan"),
        "min_iou": float(np.min(ious)) if ious else float("nan"),
    }


def main(argv: list[str] | None = None) -> None:
    parser = CommandParser(prog="python -m offroad_path.label.compare", description=__doc__.splitlines()[0])
    parser.add_argument("a", type=Path)
    parser.add_argument("b", type=Path)
    args = parser.parse_args(argv)
    with clear_errors():
        for path in (args.a, args.b):
            if not path.is_dir():
                raise ValueError(f"{path}: is not a label folder")
        result = compare(args.a, args.b)
    print(
        f"{result['common']} frames labelled in both: mean IoU {result['mean_iou']:.4f}, min {result['min_iou']:.4f}; "
        f"only in {args.a}: {result['only_a']}, only in {args.b}: {result['only_b']}"
    )


if __name__ == "__main__":
    main()
