"""The OpenBLAS kernels the label stage's workers are pinned to (`pinned_blas`), so that labels are the
same bytes on every x86-64 CPU (benchmarks/common.py holds the kernel sets the tests check that with)."""

from __future__ import annotations

import platform


def pinned_blas() -> dict[str, str]:
    """The environment that gives OpenBLAS the same kernels on every x86-64 CPU, for a process that
    loads numpy and OpenCV after it is set (utils.parallel's workers): OpenCV's wheel bundles its own
    OpenBLAS, whose gemm and LAPACK solvePnPRansac and Rodrigues use, and picks its kernels by CPU as
    NumPy's does. Prescott's (SSE3) run on every x86-64 CPU; the products are of 3x3 to 12x12
    matrices, where kernels make no difference to speed."""
    return {"OPENBLAS_CORETYPE": "Prescott"} if platform.machine().lower() in ("x86_64", "amd64") else {}
