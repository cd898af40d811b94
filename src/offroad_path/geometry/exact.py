"""Vector algebra without BLAS: the same bytes on every CPU.

NumPy's matmul, dot, 1-D norm and linalg call OpenBLAS, which picks its kernels by CPU (Haswell,
SkylakeX, Zen ...) at run time: products of the same arrays differ in the last bits between an AVX2
and an AVX-512 machine. The renderer's pixels moved with them (`OPENBLAS_CORETYPE=Haswell` rendered
other bytes on an AVX-512 machine), and so did the visual odometry's poses and with them the labels
(tests/synthesize/test_synthesize_stage.py, tests/label/test_label_stage.py). These sum the products one term at a
time, in index order, with NumPy's elementwise multiply and add: no fused multiply-add, no blocking.
NumPy's elementwise arithmetic and its reductions along an axis give the same bytes whatever its
vector dispatch (AVX2, AVX-512): the tests run with it off.
"""

from __future__ import annotations

import numpy as np


def matmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a @ b for a (..., n, k) or (k,) and b (..., k, m) or (k,), as NumPy's matmul broadcasts."""
    a, b = np.asarray(a), np.asarray(b)
    a2 = a[None] if a.ndim == 1 else a
    b2 = b[:, None] if b.ndim == 1 else b
    out = a2[..., :, 0, None] * b2[..., 0, None, :]
    for i in range(1, a2.shape[-1]):
        out = out + a2[..., :, i, None] * b2[..., i, None, :]
    if b.ndim == 1:
        out = out[..., 0]
    return out[0] if a.ndim == 1 else out


def dot_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The dot product along the last axis (a · b per row), broadcast."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    out = a[..., 0] * b[..., 0]
    for i in range(1, a.shape[-1]):
        out = out + a[..., i] * b[..., i]
    return out


def norm_rows(a: np.ndarray) -> np.ndarray:
    """The Euclidean length along the last axis (np.linalg.norm(a, axis=-1))."""
    return np.sqrt(dot_rows(a, a))


def rigid_inverse(pose: np.ndarray) -> np.ndarray:
    """The inverse of rigid 4x4 transforms (..., 4, 4): [R^T, -R^T t] (np.linalg.inv goes through LAPACK)."""
    rotation_t = np.swapaxes(pose[..., :3, :3], -1, -2)
    out = np.zeros_like(pose)
    out[..., :3, :3] = rotation_t
    out[..., :3, 3] = -matmul(rotation_t, pose[..., :3, 3, None])[..., 0]
    out[..., 3, 3] = 1.0
    return out


def solve(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """x with a @ x = b for one small square a (n, n) and b (n,): Gaussian elimination with partial
    pivoting, row operations in index order (np.linalg.solve goes through LAPACK). LinAlgError when a
    is singular."""
    m = np.concatenate([np.array(a, np.float64), np.array(b, np.float64)[:, None]], axis=1)  # (n, n + 1)
    n = len(m)
    for col in range(n):
        pivot = col + int(np.argmax(np.abs(m[col:, col])))
        if m[pivot, col] == 0.0:
            raise np.linalg.LinAlgError("Singular matrix")
        m[[col, pivot]] = m[[pivot, col]]
        below = m[col + 1 :, col] / m[col, col]
        m[col + 1 :] = m[col + 1 :] - below[:, None] * m[col]
    x = np.zeros(n)
    for row in range(n - 1, -1, -1):
        tail = float(dot_rows(m[row, row + 1 : n], x[row + 1 :])) if row < n - 1 else 0.0
        x[row] = (m[row, n] - tail) / m[row, row]
    return x


def power(transform: np.ndarray, k: int) -> np.ndarray:
    """transform multiplied by itself k >= 0 times, left to right (np.linalg.matrix_power's squarings use BLAS)."""
    out = np.eye(len(transform))
    for _ in range(k):
        out = matmul(out, transform)
    return out
