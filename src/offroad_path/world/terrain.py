"""Rolling terrain: a height field sampled on a grid and evaluated exactly by bilinear interpolation.

World frame (KITTI-like): x right, y down, z forward. The ground at (x, z) is the point
(x, -elevation(x, z), z): elevation is up-positive, y is down-positive.

The bilinear surface *is* the terrain: the renderer intersects rays with exactly this
function and the vehicle stands on exactly this function, so depth, images and poses agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from offroad_path.geometry.exact import norm_rows
from offroad_path.world.kernels import resize_cubic, sample_bilinear

CELL_MARGIN = 1.001  # cell coordinates stop this short of the last row and column: a bilinear lookup has a cell beyond


@dataclass
class Grid:
    """A regular 2D grid over the ground plane: cell (row, col) is at (x0 + col*step, z0 + row*step)."""

    x0: float
    z0: float
    step: float
    shape: tuple[int, int]  # (rows along z, cols along x)

    def coords(self, x: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional (col, row) of world points, as float32 maps for sample_bilinear.
        Port: world.shading_torch._grid_coords (render_torch.PORTS).
        """
        return ((x - self.x0) / self.step).astype(np.float32), ((z - self.z0) / self.step).astype(np.float32)

    def nearest(self, x: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        col = np.clip(np.rint((x - self.x0) / self.step), 0, self.shape[1] - 1).astype(np.intp)
        row = np.clip(np.rint((z - self.z0) / self.step), 0, self.shape[0] - 1).astype(np.intp)
        return row, col

    def to_pixel(self, xz: np.ndarray) -> np.ndarray:
        """World (x, z) points (N, 2) to raster pixel coordinates for cv2 drawing."""
        return (xz - np.array([self.x0, self.z0])) / self.step


class Terrain:
    """Height field with exact bilinear evaluation and smooth shading normals.
    Port: world.trace_torch._Terrain (render_torch.PORTS).
    """

    def __init__(self, heights: np.ndarray, grid: Grid):
        self.heights = np.ascontiguousarray(heights, dtype=np.float64)  # (rows, cols), metres up
        self.grid = grid
        rows, cols = self.heights.shape
        # The four corners of every cell side by side: one gather per lookup instead of four.
        # float32 keeps lookups fast; its rounding (< 0.1 mm here) is far below a pixel.
        corners = np.zeros((rows, cols, 4), np.float32)
        corners[:-1, :-1] = np.stack([heights[:-1, :-1], heights[:-1, 1:], heights[1:, :-1], heights[1:, 1:]], axis=-1)
        self._corners = corners.reshape(-1, 4)
        # Slope bound of the bilinear surface: the steepest cell edge in x and in z.
        sx = np.abs(np.diff(self.heights, axis=1)).max() / grid.step
        sz = np.abs(np.diff(self.heights, axis=0)).max() / grid.step
        self.max_slope = float(np.hypot(sx, sz))
        self.max_elevation = float(self.heights.max())
        gz, gx = np.gradient(self.heights.astype(np.float32), grid.step)
        self._grad = cv2.merge([gx, gz])  # (rows, cols, 2) float32, for shading normals only
        self._rows, self._cols = rows, cols
        # Max-filtered copies for safe long march steps: no terrain within radius_m of a node
        # rises above the filtered value there (the window is one cell wider than the radius).
        self.max_levels: list[tuple[float, np.ndarray]] = []
        for radius_m in (4.0, 16.0):
            k = int(np.ceil(radius_m / grid.step)) + 1
            kernel = np.ones((2 * k + 1, 2 * k + 1), np.uint8)
            dilated = cv2.dilate(self.heights.astype(np.float32), kernel, borderType=cv2.BORDER_REPLICATE)
            self.max_levels.append((radius_m, dilated.ravel()))

    @property
    def corners(self) -> np.ndarray:
        """(cells, 4) float32: each grid cell's corner heights h00, h01, h10, h11 (for the torch renderer)."""
        return self._corners

    @property
    def gradient(self) -> np.ndarray:
        """(rows, cols, 2) float32: the height field's x and z slopes, for shading normals."""
        return self._grad

    def cell_coords(self, x: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Fractional grid coordinates (float32), clamped inside the grid."""
        g = self.grid
        fx = np.clip((x - g.x0) * (1.0 / g.step), 0.0, self._cols - CELL_MARGIN).astype(np.float32, copy=False)
        fz = np.clip((z - g.z0) * (1.0 / g.step), 0.0, self._rows - CELL_MARGIN).astype(np.float32, copy=False)
        return fx, fz

    def elevation_at_cells(self, fx: np.ndarray, fz: np.ndarray) -> np.ndarray:
        ix = fx.astype(np.int32)
        iz = fz.astype(np.int32)
        ax = fx - ix
        az = fz - iz
        c = self._corners.take(iz * self._cols + ix, axis=0)  # (N, 4): h00, h01, h10, h11
        top = c[:, 0] + (c[:, 1] - c[:, 0]) * ax
        bottom = c[:, 2] + (c[:, 3] - c[:, 2]) * ax
        return top + (bottom - top) * az

    def elevation(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Exact bilinear elevation at world (x, z); points outside the grid see its border value."""
        return self.elevation_at_cells(*self.cell_coords(x, z))

    def max_within_at_cells(self, level: int, fx: np.ndarray, fz: np.ndarray) -> np.ndarray:
        """An upper bound of the terrain within max_levels[level]'s radius of the point."""
        nearest = (fz + 0.5).astype(np.int32) * self._cols + (fx + 0.5).astype(np.int32)
        return self.max_levels[level][1].take(nearest)

    def max_elevation_near(self, x: float, z: float, radius_m: float) -> float:
        """The highest terrain within a square of half-side radius_m around (x, z)."""
        g = self.grid
        r = int(np.ceil(radius_m / g.step)) + 1
        col, row = int((x - g.x0) / g.step), int((z - g.z0) / g.step)
        window = self.heights[max(row - r, 0) : row + r + 1, max(col - r, 0) : col + r + 1]
        return float(window.max()) if window.size else self.max_elevation

    def normals(self, x: np.ndarray, z: np.ndarray) -> np.ndarray:
        """Unit surface normals (N, 3) in the world frame (pointing up, i.e. negative y).
        Port: world.shading_torch._terrain_normals (render_torch.PORTS).
        """
        grad = sample_bilinear(self._grad, *self.grid.coords(x, z))
        n = np.stack([-grad[:, 0], -np.ones(len(grad), np.float32), -grad[:, 1]], axis=1)
        return n / norm_rows(n)[:, None]


def fourier_hills(rng: np.random.Generator, grid: Grid, height_m: float, wavelengths_m: tuple[float, float], count: int) -> np.ndarray:
    """Sum of randomly oriented cosines: smooth hills of roughly `height_m` peak to trough."""
    rows, cols = grid.shape
    x = grid.x0 + np.arange(cols) * grid.step
    z = grid.z0 + np.arange(rows) * grid.step
    xx, zz = np.meshgrid(x, z)
    out = np.zeros(grid.shape)
    for _ in range(count):
        wavelength = rng.uniform(*wavelengths_m)
        angle = rng.uniform(0, 2 * np.pi)
        phase = rng.uniform(0, 2 * np.pi)
        amplitude = rng.uniform(0.4, 1.0)
        k = 2 * np.pi / wavelength
        out += amplitude * np.cos(k * (np.cos(angle) * xx + np.sin(angle) * zz) + phase)
    peak_to_trough = out.max() - out.min()
    return out * (height_m / max(peak_to_trough, 1e-9))


def value_noise(rng: np.random.Generator, shape: tuple[int, int], cell: float) -> np.ndarray:
    """Smooth noise in [-1, 1]: random values every `cell` pixels, bicubically upsampled."""
    coarse = rng.uniform(-1, 1, (int(shape[0] / cell) + 4, int(shape[1] / cell) + 4)).astype(np.float32)
    size = (int(coarse.shape[1] * cell), int(coarse.shape[0] * cell))
    fine = resize_cubic(coarse, size)
    return np.clip(fine[: shape[0], : shape[1]], -1, 1)


def polyline_mask(grid: Grid, xz: np.ndarray, width_m: float) -> np.ndarray:
    """255 on the cells within width_m of a polyline (xz, metres), 0 elsewhere."""
    mask = np.zeros(grid.shape, np.uint8)
    pts = np.rint(grid.to_pixel(xz[::4]) * 16).astype(np.int32)  # 4 fractional bits
    cv2.polylines(mask, [pts], False, 255, max(1, round(width_m / grid.step)), cv2.LINE_8, shift=4)
    return mask
