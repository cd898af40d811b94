"""Contact sheets of rendered sequences: left image, semantic map and depth side by side.

python -m offroad_path.world.preview data/synthetic docs/images/world_samples.png
"""

from __future__ import annotations

from pathlib import Path

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


def main(argv: list[str] | None = None) -> None:
    parser = CommandParser(prog="python -m offroad_path.world.preview", description=__doc__.splitlines()[0])
    parser.add_argument("sequences", help="a sequence folder or a folder of sequences")
    parser.add_argument("out", help="PNG to write")
    parser.add_argument("--rows", type=int, default=3)
    args = parser.parse_args(argv)
    with clear_errors():
        sheet = contact_sheet(args.sequences, args.rows)
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        write_image(args.out, sheet[:, :, ::-1])


if __name__ == "__main__":
    main()
