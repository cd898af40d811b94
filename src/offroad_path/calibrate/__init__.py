"""Calibrate a stereo rig from board views, for `ingest.calibration`:

    python -m offroad_path.calibrate LEFT_FOLDER RIGHT_FOLDER --board 10x7 --square-m 0.04 --out stereo.yaml
    python -m offroad_path.calibrate LEFT RIGHT --board 7x5 --square-m 0.04 --marker-m 0.03 --out stereo.yaml  # ChArUco

LEFT_FOLDER and RIGHT_FOLDER hold images taken at the same instants under the same names (frames
of both action cameras at one moment, for instance). The board size counts squares, not inner
corners. Writes OpenCV FileStorage YAML (K1 D1 K2 D2 R T, T in metres) and prints the RMS
reprojection error and the baseline. Bad input: one line naming the file, exit status 2.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from offroad_path.errors import CommandParser, InputError, clear_errors, positive_number
from offroad_path.recordings.boards import Board, calibrate_stereo
from offroad_path.recordings.rig_calibration import write_opencv

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def image_pairs(left: Path, right: Path) -> tuple[list[Path], list[Path]]:
    names = []
    for folder in (left, right):
        if not folder.is_dir():
            raise InputError(folder, "is not a folder of board images")
        names.append({p.name for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES})
    common = sorted(names[0] & names[1])
    if not common:
        raise InputError(right, f"has no image named as one in {left} (a pair is two images of one name)")
    return [left / n for n in common], [right / n for n in common]


def board_size(text: str) -> tuple[int, int]:
    try:
        columns, rows = (int(v) for v in text.lower().split("x"))
    except ValueError as e:
        raise argparse.ArgumentTypeError(f"{text!r}: expected COLUMNSxROWS of squares, e.g. 10x7") from e
    if columns < 3 or rows < 3:
        raise argparse.ArgumentTypeError(f"{text!r}: a board needs at least 3 x 3 squares")
    return columns, rows


def main(argv: list[str] | None = None) -> None:
    parser = CommandParser(prog="python -m offroad_path.calibrate", description=__doc__.splitlines()[0])
    parser.add_argument("left", type=Path)
    parser.add_argument("right", type=Path)
    parser.add_argument("--board", type=board_size, required=True, help="squares across x down, e.g. 10x7")
    parser.add_argument("--square-m", type=positive_number, required=True, help="side of one square in metres")
    parser.add_argument(
        "--marker-m", type=positive_number, default=None, help="ChArUco: side of a marker in metres (no value: a chessboard)"
    )
    parser.add_argument("--dictionary", default="DICT_5X5_100", help="ChArUco: OpenCV's ArUco dictionary")
    parser.add_argument("--out", type=Path, required=True, help="the OpenCV YAML written")
    args = parser.parse_args(argv)
    with clear_errors():
        if args.out.exists():
            raise InputError(args.out, "exists; it is not replaced (choose another --out or remove it)")
        if not args.out.parent.is_dir():
            raise InputError(args.out.parent, "is not a folder: --out must name a file in an existing folder")
        left, right = image_pairs(args.left, args.right)
        board = Board(*args.board, args.square_m, args.marker_m, args.dictionary)
        result = calibrate_stereo(left, right, board, args.out)
        write_opencv(args.out, result.rig, {"rms_px": result.rms_px, "views": result.views})
    print(
        f"{args.out}: {result.views} of {len(left)} views, RMS reprojection error {result.rms_px:.3f} px, "
        f"baseline {np.linalg.norm(result.rig.T):.4f} m, fx {result.rig.left.K[0, 0]:.1f} / {result.rig.right.K[0, 0]:.1f} px"
    )
