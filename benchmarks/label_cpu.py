"""The label stage's bytes under each CPU kernel set: a small world labelled once per environment, each
output file's sha256 against the default run's (benchmarks/README.md, "The label stage's bytes on every CPU").

    python benchmarks/label_cpu.py WORK_DIR [label overrides ...]

Renders the world into WORK_DIR/world once (2 drives of 40 frames at 256 x 144), then labels it under:
the default, the same again, scalar (OpenCV's and NumPy's dispatch off, OpenBLAS Prescott), each
OPENBLAS_CORETYPE this CPU runs, OpenCV's IPP at SSE4.2 and off, OpenCV and NumPy without AVX-512.
"""

from __future__ import annotations

import argparse
import hashlib
import os
import subprocess
import sys
from pathlib import Path

from common import openblas_cores, without_vector_kernels


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("work_dir", type=Path, help="where the world and each environment's labels are written")
    parser.add_argument("overrides", nargs="*", help="label overrides (key=value)")
    args = parser.parse_args()
    if bad := [o for o in args.overrides if "=" not in o]:
        parser.error(f"overrides: {bad[0]!r} is not key=value")
    root, overrides = args.work_dir, args.overrides
    world = root / "world"
    if not world.exists():
        subprocess.run([sys.executable, "-m", "offroad_path.synthesize", "synthesize.sequences=2", "world.frames=40", "world.width=256",
                        "world.height=144", "synthesize.test_worlds.min_blocks=0", f"synthesize.out_dir={world}",
                        f"hydra.run.dir={root / 'hydra'}"], check=True)  # fmt: skip

    def label(name: str, env: dict[str, str]) -> dict[str, str]:
        out = root / name
        cli = [sys.executable, "-m", "offroad_path.label", f"label.in_dir={world}", f"label.out_dir={out / 'labels'}",
               f"label.metrics_path={out / 'm.json'}", "mlflow.enabled=false", f"hydra.run.dir={root / 'hydra'}", *overrides]  # fmt: skip
        subprocess.run(cli, env={**os.environ, **env}, check=True, capture_output=True)
        return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(out.rglob("*")) if p.is_file()}

    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    avx512 = " ".join(f for f in __cpu_dispatch__ if ("AVX512" in f or f == "X86_V4") and __cpu_features__.get(f))  # dispatched here
    envs = [("again", {}), ("scalar", without_vector_kernels()), *((c, {"OPENBLAS_CORETYPE": c}) for c in openblas_cores()),
            ("OPENCV_IPP=sse42", {"OPENCV_IPP": "sse42"}), ("OPENCV_IPP=disabled", {"OPENCV_IPP": "disabled"}),
            ("OpenCV without AVX-512", {"OPENCV_CPU_DISABLE": "AVX512-SKX"}),
            *([("NumPy without AVX-512", {"NPY_DISABLE_CPU_FEATURES": avx512})] if avx512 else [])]  # fmt: skip
    reference = label("default", {})
    print(f"default: {len(reference)} files")
    for name, env in envs:
        found = label(name.replace(" ", "_").replace("=", "_"), env)
        differ = [k for k in reference if found.get(k) != reference[k]]
        print(f"{name}: {len(differ)} files differ" + (f" ({', '.join(differ[:3])} ...)" if differ else ""), flush=True)


if __name__ == "__main__":
    main()
