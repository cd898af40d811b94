"""How the colour and depth PNGs of a sequence are written (synthesize and ingest).

zlib's Huffman coding alone of the SUB filter's differences: a 512 x 288 rendered colour image
encodes in a third of zlib level 3's time (3.6 against 11.2 ms), about half of level 1's (6.9 ms)
and decodes 30 % faster (2.1 against 2.9 ms), for 6 % more bytes than level 3; 16-bit depth
encodes 2.5x faster for 48 % more bytes (`benchmarks/png_speed.py`). The pixels are the same either
way. Semantic maps, of a few classes, stay at level 3 (4 KiB against 19)."""

import cv2

FAST_PNG = [
    cv2.IMWRITE_PNG_COMPRESSION,
    1,
    cv2.IMWRITE_PNG_STRATEGY,
    cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY,
    cv2.IMWRITE_PNG_FILTER,
    cv2.IMWRITE_PNG_FILTER_SUB,
]
