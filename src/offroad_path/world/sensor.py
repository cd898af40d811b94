"""The camera between the light and the bytes: exposure and auto-gain, white balance, vignetting,
motion blur at the vehicle's speed, gamma, sensor noise, greyscale sensors and JPEG-like compression.

Same bytes on every CPU (world/kernels.py's rule): elementwise arithmetic only, the auto-gain's mean
an integer sum, the noise from uniform draws (no exp or log from a vector library), the DCT's sums
one term at a time in index order.
"""

from __future__ import annotations

import numpy as np

from offroad_path.geometry.exact import matmul
from offroad_path.world.appearance import Sensor
from offroad_path.world.kernels import sample_bilinear

LUMA = np.array([0.2126, 0.7152, 0.0722])  # linear light's luminance
BLUR_SAMPLES = 4
# JPEG's quantisation tables (ITU-T T.81, Annex K), luminance and chrominance, at quality 50.
Q_LUMA = np.array(
    [
        [16, 11, 10, 16, 24, 40, 51, 61],
        [12, 12, 14, 19, 26, 58, 60, 55],
        [14, 13, 16, 24, 40, 57, 69, 56],
        [14, 17, 22, 29, 51, 87, 80, 62],
        [18, 22, 37, 56, 68, 109, 103, 77],
        [24, 35, 55, 64, 81, 104, 113, 92],
        [49, 64, 78, 87, 103, 121, 120, 101],
        [72, 92, 95, 98, 112, 100, 103, 99],
    ],
    float,
)
Q_CHROMA = np.full((8, 8), 99.0)
Q_CHROMA[:4, :4] = [[17, 18, 24, 47], [18, 21, 26, 66], [24, 26, 56, 99], [47, 66, 99, 99]]
# cos(m pi / 16), m = 0..8, as literals: NumPy's vector cos differs between CPUs in the last bit.
_COS16 = (
    1.0,
    0.9807852804032304,
    0.9238795325112867,
    0.8314696123025452,
    0.7071067811865476,
    0.5555702330196022,
    0.3826834323650898,
    0.19509032201612825,
    0.0,
)


def _cos16(m: int) -> float:
    m %= 32
    return _COS16[m] if m <= 8 else -_COS16[16 - m] if m <= 16 else -_COS16[m - 16] if m <= 24 else _COS16[32 - m]


DCT = np.array([[(np.sqrt(1 / 8) if k == 0 else 0.5) * _cos16((2 * n + 1) * k) for n in range(8)] for k in range(8)])  # (8, 8) orthonormal


# Auto gain: luma summed as integers of LUMA_STEPS per unit (any order gives one sum), the gain clipped to GAIN_RANGE.
LUMA_STEPS, MIN_MEAN, GAIN_RANGE = 4096, 1e-6, (0.4, 3.0)


def expose(linear: np.ndarray, depth: np.ndarray, sensor: Sensor, motion_m: float) -> np.ndarray:
    """Linear light (H, W, 3) through gain, white balance, vignetting and motion blur: (H, W, 3) float64.
    depth (H, W): metres along the optical axis, 0 for sky; motion_m: metres driven while the shutter is open.
    Port: world.shading_torch.expose (render_torch.PORTS).
    """
    h, w, _ = linear.shape
    out = linear * (np.asarray(sensor.white_balance) * sensor.exposure)
    if sensor.auto_gain:
        luma = out[..., 0] * LUMA[0] + out[..., 1] * LUMA[1] + out[..., 2] * LUMA[2]
        mean = np.clip(np.rint(luma * LUMA_STEPS), 0, 1 << 20).astype(np.int64).sum() / (LUMA_STEPS * luma.size)  # integer sum: any order
        out *= np.clip(sensor.target / max(mean, MIN_MEAN), *GAIN_RANGE)
    v, u = np.mgrid[0:h, 0:w]
    r2 = ((u - (w - 1) / 2) / (w / 2)) ** 2 + ((v - (h - 1) / 2) / (h / 2)) ** 2
    out *= (1 - sensor.vignetting * r2 / 2)[..., None]
    if motion_m > 0:
        out = _motion_blur(out, depth, motion_m)
    return out


def _motion_blur(image: np.ndarray, depth: np.ndarray, motion_m: float) -> np.ndarray:
    """The average over the shutter of a camera driving `motion_m` forward: a point at depth Z seen at
    pixel p was at c + (p - c) Z / (Z + s) when the camera was s metres back (sky does not move).
    Port: world.shading_torch._motion_blur (render_torch.PORTS).
    """
    h, w, _ = image.shape
    v, u = np.mgrid[0:h, 0:w].astype(np.float64)
    cx, cy = (w - 1) / 2, (h - 1) / 2
    hit = depth.ravel() > 0
    z = np.where(hit, depth.ravel(), 1.0)
    acc = image.reshape(-1, 3).astype(np.float32)
    for i in range(1, BLUR_SAMPLES):
        scale = np.where(hit, z / (z + motion_m * i / (BLUR_SAMPLES - 1)), 1.0)
        acc = acc + sample_bilinear(image, cx + (u.ravel() - cx) * scale, cy + (v.ravel() - cy) * scale)
    return (acc / BLUR_SAMPLES).reshape(h, w, 3).astype(np.float64)


def record(image: np.ndarray, sensor: Sensor, noise_key: tuple[int, ...]) -> np.ndarray:
    """The 8-bit image (H, W, 3) as the sensor writes it: noise, greyscale, compression."""
    rng = np.random.default_rng(np.random.SeedSequence(list(noise_key)))
    out = image.astype(np.float64)
    if sensor.noise_dn > 0:
        # The sum of four uniforms, scaled to the standard deviation: near Gaussian, without exp or log.
        shape = image.shape[:2] + ((1,) if sensor.greyscale else (3,))
        noise = (rng.random(shape) + rng.random(shape) + rng.random(shape) + rng.random(shape) - 2.0) * (sensor.noise_dn * np.sqrt(3.0))
        out = out + noise
    out = np.clip(np.rint(out), 0, 255)
    if sensor.greyscale:
        grey = np.floor((out[..., 0] * 77 + out[..., 1] * 150 + out[..., 2] * 29 + 128) / 256)
        out = np.repeat(grey[..., None], 3, axis=2)
    if sensor.jpeg_quality:
        out = jpeg_like(out, sensor.jpeg_quality, sensor.greyscale)
    return out.astype(np.uint8)


def _quant(table: np.ndarray, quality: int) -> np.ndarray:
    """libjpeg's scaling of a quantisation table to `quality` (1-100)."""
    scale = 5000 / quality if quality < 50 else 200 - 2 * quality
    return np.clip(np.floor((table * scale + 50) / 100), 1, 255)


def jpeg_like(image: np.ndarray, quality: int, greyscale: bool = False) -> np.ndarray:
    """JPEG's loss without its file: 8 x 8 DCTs of Y, Cb and Cr quantised with the standard tables at
    `quality` and transformed back (no chroma subsampling, no entropy coding). (H, W, 3) float, 0-255."""
    h, w, _ = image.shape
    ph, pw = -h % 8, -w % 8
    padded = np.pad(image, ((0, ph), (0, pw), (0, 0)), mode="edge")
    r, g, b = padded[..., 0], padded[..., 1], padded[..., 2]
    ycc = [0.299 * r + 0.587 * g + 0.114 * b - 128, -0.168736 * r - 0.331264 * g + 0.5 * b, 0.5 * r - 0.418688 * g - 0.081312 * b]
    tables = [_quant(Q_LUMA, quality), _quant(Q_CHROMA, quality), _quant(Q_CHROMA, quality)]
    planes = []
    for k, (plane, table) in enumerate(zip(ycc, tables, strict=True)):
        if greyscale and k:
            planes.append(np.zeros_like(plane))
            continue
        blocks = plane.reshape(plane.shape[0] // 8, 8, plane.shape[1] // 8, 8).transpose(0, 2, 1, 3)  # (rows, cols, 8, 8)
        coefficients = matmul(matmul(DCT, blocks), DCT.T)
        coefficients = np.rint(coefficients / table) * table
        back = matmul(matmul(DCT.T, coefficients), DCT)
        planes.append(back.transpose(0, 2, 1, 3).reshape(plane.shape))
    y, cb, cr = planes[0] + 128, planes[1], planes[2]
    rgb = np.stack([y + 1.402 * cr, y - 0.344136 * cb - 0.714136 * cr, y + 1.772 * cb], axis=-1)
    return np.clip(np.rint(rgb[:h, :w]), 0, 255)
