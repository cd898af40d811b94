"""The CPU kernel sets a process's numerical libraries can be pinned to (OpenBLAS's kernels by
OPENBLAS_CORETYPE, OpenCV's and NumPy's dispatched vector kernels): the label stage's workers run
pinned (`pinned_blas`), and the tests and benchmarks that want the same bytes on every CPU run stages
under each set this CPU has (`openblas_cores`, `without_vector_kernels`)."""

from __future__ import annotations

import platform
from pathlib import Path


def pinned_blas() -> dict[str, str]:
    """The environment that gives OpenBLAS the same kernels on every x86-64 CPU, for a process that
    loads numpy and OpenCV after it is set (utils.parallel's workers): OpenCV's wheel bundles its own
    OpenBLAS, whose gemm and LAPACK solvePnPRansac and Rodrigues use, and picks its kernels by CPU as
    NumPy's does. Prescott's (SSE3) run on every x86-64 CPU; the products are of 3x3 to 12x12
    matrices, where kernels make no difference to speed."""
    return {"OPENBLAS_CORETYPE": "Prescott"} if platform.machine().lower() in ("x86_64", "amd64") else {}


def without_vector_kernels() -> dict[str, str]:
    """An environment in which OpenCV and NumPy use none of their CPU-specific vector kernels (the
    dispatched ones: SSE4 and up for OpenCV, AVX-512 among them, X86_V3 and up for NumPy) and
    OpenBLAS runs its oldest x86-64 kernels."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    dispatched = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    env = {"OPENCV_CPU_DISABLE": "SSE4.1,SSE4.2,POPCNT,AVX,FP16,AVX2,FMA3,AVX512-SKX", "OPENBLAS_CORETYPE": "Prescott"}
    return env | ({"NPY_DISABLE_CPU_FEATURES": " ".join(dispatched)} if dispatched else {})


def openblas_cores() -> list[str]:
    """OpenBLAS kernel sets this CPU can run (OPENBLAS_CORETYPE): NumPy's matmul, dot and linalg
    take the newest by default (SkylakeX here, Haswell on an AVX2 machine), and each rounds differently."""
    flags = set(Path("/proc/cpuinfo").read_text().split()) if Path("/proc/cpuinfo").is_file() else set()
    return [core for core, needs in (("Prescott", "sse3"), ("Nehalem", "sse4_2"), ("Sandybridge", "avx"), ("Haswell", "avx2"),
            ("SkylakeX", "avx512f")) if needs in flags or (needs == "sse3" and "pni" in flags)]  # fmt: skip
