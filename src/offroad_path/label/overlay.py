"""Path labels drawn over the images they were made for (the drawing: offroad_path.viz.overlay).

    python -m offroad_path.label.overlay SEQUENCE LABELS OUT.png [--frame F0]

SEQUENCE is a recording, LABELS the label stage's folder for it (with label/NNNNNN.png); without
--frame, the first labelled frame is drawn.
"""

from __future__ import annotations

from pathlib import Path

import cv2

from offroad_path.errors import CommandParser, clear_errors
from offroad_path.sequence.reader import open_sequence
from offroad_path.utils.media import write_image
from offroad_path.viz import overlay


def main(argv: list[str] | None = None) -> None:
    parser = CommandParser(prog="python -m offroad_path.label.overlay", description=__doc__.splitlines()[0])
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
        write_image(args.out, overlay(image, mask)[:, :, ::-1])


if __name__ == "__main__":
    main()
