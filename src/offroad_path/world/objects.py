"""Analytic scene objects (spheres, upright cylinders, yawed boxes) and their exact ray intersections.

Rays are o + t*d with d scaled so that t is the depth (camera z) of the hit: every function
returns t = inf where a ray misses, and an outward unit normal where it hits.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

NEAR_M = 0.05


@dataclass
class Objects:
    """All objects of one world. `kind` is 0 sphere, 1 cylinder, 2 box; rows share one table."""

    kind: list[int] = field(default_factory=list)
    # sphere: cx, cy, cz, r; cylinder: cx, cz, y_top, y_bottom, r; box: cx, cy, cz, hx, hy, hz, yaw
    params: list[tuple[float, ...]] = field(default_factory=list)
    cls: list[int] = field(default_factory=list)
    color: list[tuple[float, float, float]] = field(default_factory=list)

    def add_sphere(self, centre: np.ndarray, radius: float, cls: int, color: np.ndarray) -> None:
        self._add(0, (*map(float, centre), float(radius)), cls, color)

    def add_cylinder(self, x: float, z: float, y_top: float, y_bottom: float, radius: float, cls: int, color: np.ndarray) -> None:
        self._add(1, (float(x), float(z), float(y_top), float(y_bottom), float(radius)), cls, color)

    def add_box(self, centre: np.ndarray, half: np.ndarray, yaw: float, cls: int, color: np.ndarray) -> None:
        self._add(2, (*map(float, centre), *map(float, half), float(yaw)), cls, color)

    def _add(self, kind: int, params: tuple[float, ...], cls: int, color: np.ndarray) -> None:
        self.kind.append(kind)
        self.params.append(params)
        self.cls.append(int(cls))
        self.color.append(tuple(float(c) for c in color))

    def bounding_spheres(self) -> np.ndarray:
        """(N, 4) centre and radius enclosing each object, for culling."""
        out = np.zeros((len(self.kind), 4))
        for i, (kind, p) in enumerate(zip(self.kind, self.params, strict=True)):
            if kind == 0:
                out[i] = p
            elif kind == 1:
                x, z, y_top, y_bottom, r = p
                half_h = (y_bottom - y_top) / 2
                out[i] = (x, y_top + half_h, z, np.hypot(half_h, r))
            else:
                out[i] = (*p[:3], np.linalg.norm(p[3:6]))
        return out


def intersect(kind: int, params: tuple[float, ...], o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth t (M,) and normals (M, 3) of rays o + t*d (d: (M, 3)) against one object."""
    if kind == 0:
        return _sphere(params, o, d)
    if kind == 1:
        return _cylinder(params, o, d)
    return _box(params, o, d)


def _sphere(p: tuple[float, ...], o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    c = np.array(p[:3])
    r = p[3]
    oc = o - c
    a = np.einsum("ij,ij->i", d, d)
    b = d @ oc
    disc = b * b - a * (oc @ oc - r * r)
    root = np.sqrt(np.maximum(disc, 0.0))
    t = (-b - root) / a
    t = np.where(t > NEAR_M, t, (-b + root) / a)
    t = np.where((disc >= 0) & (t > NEAR_M), t, np.inf)
    normal = (o + t[:, None] * d - c) / r
    return t, normal


def _cylinder(p: tuple[float, ...], o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x, z, y_top, y_bottom, r = p
    ox, oz = o[0] - x, o[2] - z
    dx, dz = d[:, 0], d[:, 2]
    a = dx * dx + dz * dz
    b = ox * dx + oz * dz
    disc = b * b - a * (ox * ox + oz * oz - r * r)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_side = (-b - np.sqrt(np.maximum(disc, 0.0))) / a
    y_side = o[1] + t_side * d[:, 1]
    side_ok = (disc >= 0) & (a > 0) & (t_side > NEAR_M) & (y_side >= y_top) & (y_side <= y_bottom)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_cap = (y_top - o[1]) / d[:, 1]
    cap_x, cap_z = ox + t_cap * dx, oz + t_cap * dz
    cap_ok = (t_cap > NEAR_M) & (cap_x * cap_x + cap_z * cap_z <= r * r)
    t_side = np.where(side_ok, t_side, np.inf)
    t_cap = np.where(cap_ok, t_cap, np.inf)
    use_cap = t_cap < t_side
    t = np.where(use_cap, t_cap, t_side)
    hit_x, hit_z = ox + t * dx, oz + t * dz
    normal = np.stack([hit_x / r, np.zeros_like(t), hit_z / r], axis=1)
    normal[use_cap] = (0.0, -1.0, 0.0)
    return t, normal


def _box(p: tuple[float, ...], o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centre, half, yaw = np.array(p[:3]), np.array(p[3:6]), p[6]
    c, s = np.cos(yaw), np.sin(yaw)
    # World-to-box rotation about y (the box's local x is the world direction (c, 0, -s)).
    rot = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    lo = rot @ (o - centre)
    ld = d @ rot.T
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / ld
        t1 = (-half - lo) * inv
        t2 = (half - lo) * inv
    t_near = np.nan_to_num(np.minimum(t1, t2), nan=-np.inf)
    t_far = np.nan_to_num(np.maximum(t1, t2), nan=np.inf)
    axis = np.argmax(t_near, axis=1)
    t_enter = t_near.max(axis=1)
    t_exit = t_far.min(axis=1)
    t = np.where((t_enter <= t_exit) & (t_enter > NEAR_M), t_enter, np.inf)
    local_n = np.zeros_like(ld)
    rows = np.arange(len(ld))
    local_n[rows, axis] = -np.sign(ld[rows, axis])
    return t, local_n @ rot
