"""The renderer's image kernels in plain NumPy arithmetic: the same bytes on every CPU.

OpenCV's GaussianBlur, resize and remap pick vector kernels by CPU (AVX2, FMA, NEON) whose float
results differ in the last bits, and the terrain, the textures and so every rendered pixel moved
with them: the embedded dataset differed between machines. Here each output is a sum of products
in a fixed order, with no fused multiply-add and no reduction whose order a library chooses, and
borders as OpenCV's defaults had them.
"""

from __future__ import annotations

import decimal
import math
from decimal import Decimal

import numpy as np


def gaussian_kernel(sigma: float, extent: float = 4.0) -> np.ndarray:
    """Normalised 1D Gaussian weights over +-extent sigma, float64 (OpenCV's extent: 4 for float
    images, 3 for 8-bit ones). The exponentials in decimal arithmetic, correctly rounded: the C
    library's exp has CPU-specific variants (FMA) too."""
    radius = max(1, math.ceil(extent * sigma))
    with decimal.localcontext(prec=40):
        weights = [(Decimal("-0.5") * (Decimal(i) / Decimal(sigma)) ** 2).exp() for i in range(-radius, radius + 1)]
        total = sum(weights)
        return np.array([float(w / total) for w in weights])


def _convolve_axis(image: np.ndarray, weights: np.ndarray, axis: int) -> np.ndarray:
    """`image` (float32 or float64) convolved with symmetric `weights` along `axis`, borders
    reflected as OpenCV's BORDER_REFLECT_101 (gfedcb|abcdefgh|gfedcba): numpy's "reflect".
    Mirrored taps are added first and multiplied once, always in the same order."""
    radius = len(weights) // 2
    n = image.shape[axis]
    pad = [(0, 0)] * image.ndim
    pad[axis] = (radius, radius)
    padded = np.pad(image, pad, mode="reflect") if n > 1 else np.pad(image, pad, mode="edge")

    def shifted(k: int) -> np.ndarray:
        window = [slice(None)] * image.ndim
        window[axis] = slice(radius + k, radius + k + n)
        return padded[tuple(window)]

    out = shifted(0) * weights[radius]
    pair = np.empty(image.shape, image.dtype)
    for k in range(1, radius + 1):
        np.add(shifted(-k), shifted(k), out=pair)
        pair *= weights[radius + k]
        out += pair
    return out


def gaussian_blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """A separable Gaussian blur of a 2D array (rows, then columns), in image's dtype."""
    integer = np.issubdtype(image.dtype, np.integer)
    work = np.float64 if image.dtype == np.float64 else np.float32  # 8-bit maps of 27 million cells: float32 halves the time
    weights = gaussian_kernel(sigma, 3.0 if integer else 4.0).astype(work)
    blurred = _convolve_axis(_convolve_axis(image.astype(work), weights, 1), weights, 0)
    if integer:  # rounded and saturated, as OpenCV's integer images
        info = np.iinfo(image.dtype)
        return np.clip(np.rint(blurred), info.min, info.max).astype(image.dtype)
    return blurred.astype(image.dtype)


def _cubic_taps(n_in: int, n_out: int) -> tuple[np.ndarray, np.ndarray]:
    """For each output index: 4 source indices (edges replicated) and their bicubic weights
    (a = -0.75, OpenCV's INTER_CUBIC), sampling at pixel centres as cv2.resize does."""
    position = (np.arange(n_out) + 0.5) * (n_in / n_out) - 0.5
    start = np.floor(position).astype(np.int64)
    t = position - start
    a = -0.75
    distances = [1.0 + t, t, 1.0 - t, 2.0 - t]
    weights = []
    for d in distances:
        near = ((a + 2.0) * d - (a + 3.0)) * d * d + 1.0  # |d| <= 1
        far = ((a * d - 5.0 * a) * d + 8.0 * a) * d - 4.0 * a  # 1 < |d| < 2
        weights.append(np.where(d <= 1.0, near, far))
    index = np.clip(start[:, None] + np.arange(-1, 3)[None, :], 0, n_in - 1)
    return index, np.stack(weights, axis=1)


def resize_cubic(image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """cv2.resize(image, size=(width, height), interpolation=INTER_CUBIC) of a 2D array, in its dtype."""
    width, height = size
    out = image.astype(np.float64)
    for axis, n_out in ((1, width), (0, height)):
        index, weights = _cubic_taps(out.shape[axis], n_out)
        shape = [1, 1]
        shape[axis] = n_out
        total = np.zeros([n_out if a == axis else out.shape[a] for a in range(2)], np.float64)
        for k in range(4):
            total += weights[:, k].reshape(shape) * np.take(out, index[:, k], axis=axis)
        out = total
    return out.astype(image.dtype)


def sample_bilinear(image: np.ndarray, mx: np.ndarray, my: np.ndarray, wrap: bool = False) -> np.ndarray:
    """Bilinear values (N,) or (N, channels) of a float `image` at fractional pixels (mx, my), in
    float32; outside the image: its border replicated, or the image tiled (wrap).
    Port: world.trace_torch.bilinear (render_torch.PORTS).
    """
    n = len(mx)
    rows, cols = image.shape[:2]
    flat = image.reshape(rows * cols, -1)
    if n == 0:
        return np.zeros((0, *image.shape[2:]), np.float32)
    x = np.asarray(mx, np.float32)
    y = np.asarray(my, np.float32)
    x0f, y0f = np.floor(x), np.floor(y)
    ax, ay = x - x0f, y - y0f
    x0, y0 = x0f.astype(np.intp), y0f.astype(np.intp)
    if wrap:
        x0, y0 = np.mod(x0, cols), np.mod(y0, rows)
        x1, y1 = np.where(x0 == cols - 1, 0, x0 + 1), np.where(y0 == rows - 1, 0, y0 + 1)
    else:
        x1, y1 = np.clip(x0 + 1, 0, cols - 1), np.clip(y0 + 1, 0, rows - 1)
        x0, y0 = np.clip(x0, 0, cols - 1), np.clip(y0, 0, rows - 1)
    y0 *= cols
    y1 *= cols
    if image.ndim == 3:
        ax, ay = ax[:, None], ay[:, None]
    else:
        flat = flat[:, 0]
    v00, v01 = flat.take(y0 + x0, axis=0), flat.take(y0 + x1, axis=0)
    v10, v11 = flat.take(y1 + x0, axis=0), flat.take(y1 + x1, axis=0)
    top = v00 + (v01 - v00) * ax
    bottom = v10 + (v11 - v10) * ax
    return (top + (bottom - top) * ay).astype(np.float32, copy=False)
