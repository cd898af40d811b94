"""Path labels drawn over the images they were made for.

    python -m offroad_path.labelling.overlay SEQUENCE LABELS OUT.png [--frame F0]

SEQUENCE is a recording, LABELS the label stage's folder for it (with label/NNNNNN.png); without
--frame, the first labelled frame is drawn.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from offroad_path.sequence.reader import open_sequence
from offroad_path.utils.cli import clear_errors

PATH_TINT = np.array([0, 255, 0], np.float32)


def overlay(image: np.ndarray, mask: np.ndarray, alpha: float = 0.45) -> np.ndarray:
    """RGB image with the path (mask > 0) tinted green and outlined."""
    out = image.astype(np.float32)
    path = mask > 0
    out[path] = (1 - alpha) * out[path] + alpha * PATH_TINT
    out = out.astype(np.uint8)
    contours, _ = cv2.findContours(path.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_SIMPLE)
    cv2.drawContours(out, contours, -1, (255, 255, 0), 1, cv2.LINE_AA)
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(prog="python -m offroad_path.labelling.overlay", description=__doc__.splitlines()[0])
    parser.add_argument("sequence", type=Path)
    parser.add_argument("labels", type=Path)
    parser.add_argument("out", type=Path)
    parser.add_argument("--frame", type=int, default=None)
    args = parser.parse_args(argv)
    with clear_errors():
        seq = open_sequence(args.sequence)
        files = sorted((args.labels / "label").glob("*.png"))
        if not files:
            raise ValueError(f"{args.labels / 'label'}: holds no labels")
        path = args.labels / "label" / f"{args.frame:06d}.png" if args.frame is not None else files[0]
        mask = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if mask is None:
            raise ValueError(f"{path}: cannot be read as a label")
        image = seq.load_left(int(path.stem))
        args.out.parent.mkdir(parents=True, exist_ok=True)
        cv2.imwrite(str(args.out), overlay(image, mask)[:, :, ::-1])


if __name__ == "__main__":
    main()
