"""PNG encoding and decoding of a rendered frame: zlib level 3 (synthesize before), level 1, and the
Huffman-only SUB filter that synthesize and ingest now write (offroad_path.sequence.png.FAST_PNG).

    python benchmarks/png_speed.py [--sequence data/synthetic/seq_001] [--frame 10] [--repeats 30]

Needs a rendered sequence (`dvc repro synthesize`). Times cv2.imencode and cv2.imdecode of the
frame's colour image, 16-bit depth and semantic map, one OpenCV thread, and prints the sizes.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2

from offroad_path.report.tables import grid_head, grid_row
from offroad_path.sequence.png import FAST_PNG

OPTIONS = {
    "zlib level 3": [cv2.IMWRITE_PNG_COMPRESSION, 3],
    "zlib level 1": [cv2.IMWRITE_PNG_COMPRESSION, 1],
    "Huffman only, SUB": FAST_PNG,
}


def per_call_ms(fn, repeats: int) -> float:
    start = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - start) / repeats * 1000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sequence", default="data/synthetic/seq_001")
    parser.add_argument("--frame", type=int, default=10)
    parser.add_argument("--repeats", type=int, default=30)
    args = parser.parse_args()
    cv2.setNumThreads(1)
    name = f"{args.frame:06d}.png"
    print(grid_head(["image", "writer", "encode, ms", "decode, ms", "KiB"]))
    for kind in ("image_l", "depth", "semantic"):
        image = cv2.imread(str(Path(args.sequence) / kind / name), cv2.IMREAD_UNCHANGED)
        for label, options in OPTIONS.items():
            encoded = cv2.imencode(".png", image, options)[1]
            encode = per_call_ms(lambda image=image, options=options: cv2.imencode(".png", image, options), args.repeats)
            decode = per_call_ms(lambda encoded=encoded: cv2.imdecode(encoded, cv2.IMREAD_UNCHANGED), args.repeats)
            print(grid_row([f"{kind} ({image.dtype})", label, f"{encode:.2f}", f"{decode:.2f}", f"{len(encoded) / 1024:.0f}"]))


if __name__ == "__main__":
    main()
