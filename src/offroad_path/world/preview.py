"""Contact sheets of rendered sequences: left image, semantic map and depth side by side, or (with
--looks) a grid of many worlds' left images, each captioned with its look (world.appearance).

python -m offroad_path.world.preview data/synthetic docs/images/world_samples.png
python -m offroad_path.world.preview data/synthetic docs/images/world_looks.jpg --looks 4
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from offroad_path.errors import CommandParser, clear_errors
from offroad_path.sequence.reader import Sequence, find_sequences, open_sequence
from offroad_path.utils.media import write_image
from offroad_path.viz import colour_depth, colour_semantic


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


def caption(meta: dict) -> str:
    """A world's look in a few words: track, season, light (grey sensor, held out) from its meta.json."""
    look = meta.get("appearance")
    if look is None:
        return "the single look (no world.appearance)"
    words = [look["track"], look["season"], look["light"], look["vegetation"]]
    words += ["grey"] if look["sensor"]["greyscale"] else []
    words += ["HELD-OUT"] if look["held_out"] else []
    return " / ".join(words)


def look_grid(root: str | Path, columns: int = 4, width: int = 512) -> np.ndarray:
    """Every sequence's middle left image at `width` pixels, captioned with its look, `columns` to a row (RGB)."""
    tiles = []
    for path in find_sequences(root):
        seq = open_sequence(path)
        image = seq.load_left(len(seq) // 2)
        image = cv2.resize(image, (width, round(image.shape[0] * width / image.shape[1])), interpolation=cv2.INTER_LINEAR)
        text = f"{Path(path).name}: {caption(json.loads((Path(path) / 'meta.json').read_text()))}"
        for colour, thickness in (((0, 0, 0), 3), ((255, 255, 255), 1)):  # white on a black outline
            cv2.putText(image, text, (6, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45 * width / 512, colour, thickness, cv2.LINE_AA)
        tiles.append(image)
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % columns)
    return np.vstack([np.hstack(tiles[i : i + columns]) for i in range(0, len(tiles), columns)])


def main(argv: list[str] | None = None) -> None:
    parser = CommandParser(prog="python -m offroad_path.world.preview", description=__doc__.splitlines()[0])
    parser.add_argument("sequences", help="a sequence folder or a folder of sequences")
    parser.add_argument("out", help="PNG to write")
    parser.add_argument("--rows", type=int, default=3)
    parser.add_argument("--looks", type=int, default=0, metavar="COLUMNS", help="a grid of every world's look, COLUMNS wide")
    args = parser.parse_args(argv)
    with clear_errors():
        sheet = look_grid(args.sequences, args.looks) if args.looks else contact_sheet(args.sequences, args.rows)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        write_image(args.out, sheet[:, :, ::-1])


if __name__ == "__main__":
    main()
