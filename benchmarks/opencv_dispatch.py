"""Which OpenCV calls of the world builder and renderer give other bytes with other CPU kernels.

    python benchmarks/opencv_dispatch.py

Not a speed figure: a reproducibility check. OpenCV picks a kernel per CPU (AVX-512, AVX2 with
FMA, AVX, SSE4); a kernel that fuses a multiply and an add rounds once instead of twice, so the
same call can return other bytes on another machine, and a rendered pixel one level off moves
every downstream number. This runs each call the world uses (`src/offroad_path/world/`) on fixed
random inputs in a fresh process per kernel set (OPENCV_CPU_DISABLE is read when cv2 loads) and
prints a hash of each output.
"""

from __future__ import annotations

import os
import subprocess
import sys

from offroad_path.report.tables import grid_head, grid_row

CALLS = """
import hashlib, cv2, numpy as np
rng = np.random.default_rng(0)
f32, f64 = rng.random((256, 256)).astype(np.float32), rng.random((256, 256))
mx, my = ((rng.random((300, 300)) * 255).astype(np.float32) for _ in range(2))
out = {
    "remap (float32, bilinear)": cv2.remap(f32, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP),
    "GaussianBlur (float32)": cv2.GaussianBlur(f32, (0, 0), 3.0),
    "GaussianBlur (float64)": cv2.GaussianBlur(f64, (0, 0), 3.0),
    "resize (float32, cubic)": cv2.resize(f32, (512, 512), interpolation=cv2.INTER_CUBIC),
    "resize (float64, cubic)": cv2.resize(f64, (512, 512), interpolation=cv2.INTER_CUBIC),
    "dilate (float32)": cv2.dilate(f32, np.ones((5, 5), np.uint8)),
}
for name, array in out.items():
    print(name + "\\t" + hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()[:10])
"""
KERNEL_SETS = {
    "every kernel this CPU has": "",
    "no AVX-512": "AVX512-SKX",
    "no AVX-512, AVX2, FMA": "AVX512-SKX,AVX2,FMA3",
    "SSE only": "AVX512-SKX,AVX2,FMA3,AVX,FP16",
}


def hashes(disabled: str) -> dict[str, str]:
    env = {**os.environ, "OPENCV_CPU_DISABLE": disabled} if disabled else {**os.environ}
    out = subprocess.run([sys.executable, "-c", CALLS], env=env, capture_output=True, text=True, check=True).stdout
    return dict(line.split("\t") for line in out.splitlines())


def main() -> None:
    import cv2

    print(f"OpenCV {cv2.__version__}; this CPU: {cv2.getCPUFeaturesLine()}")
    results = {name: hashes(disabled) for name, disabled in KERNEL_SETS.items()}
    print(grid_head(["call", *results]))
    for call in next(iter(results.values())):
        print(grid_row([call, *(r[call] for r in results.values())]))


if __name__ == "__main__":
    main()
