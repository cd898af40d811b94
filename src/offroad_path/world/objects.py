"""Analytic scene objects (spheres, upright cylinders, yawed boxes) and their exact ray intersections.

Rays are o + t*d with d scaled so that t is the depth (camera z) of the hit. The intersection
functions are vectorised over (ray, object) pairs: row i of `d` meets object row i of `p`.
They return t = inf where a ray misses, and an outward unit normal where it hits.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from offroad_path.geometry.exact import dot_rows, norm_rows

NEAR_M = 0.05
SPHERE, CYLINDER, BOX = 0, 1, 2
PARAM_COUNT = {SPHERE: 4, CYLINDER: 5, BOX: 7}


@dataclass
class ObjectArrays:
    kind: np.ndarray  # (N,)
    params: np.ndarray  # (N, 7), each row's first PARAM_COUNT[kind] columns used
    bounds: np.ndarray  # (N, 4) bounding spheres
    cls: np.ndarray  # (N,) uint8
    color: np.ndarray  # (N, 3)


@dataclass
class Objects:
    """All objects of one world, one table row each.

    Parameters per kind: sphere (cx, cy, cz, r); cylinder (cx, cz, y_top, y_bottom, r), upright;
    box (cx, cy, cz, hx, hy, hz, yaw), yawed about the vertical axis.
    """

    kind: list[int] = field(default_factory=list)
    params: list[tuple[float, ...]] = field(default_factory=list)
    cls: list[int] = field(default_factory=list)
    color: list[tuple[float, float, float]] = field(default_factory=list)
    _arrays: ObjectArrays | None = field(default=None, repr=False, compare=False)

    def add_sphere(self, centre: np.ndarray, radius: float, cls: int, color: np.ndarray) -> None:
        self.add(SPHERE, (*map(float, centre), float(radius)), cls, color)

    def add_cylinder(self, xz: np.ndarray, y_span: tuple[float, float], radius: float, cls: int, color: np.ndarray) -> None:
        """An upright cylinder at ground position xz from height y_span[0] (top) to y_span[1] (bottom)."""
        self.add(CYLINDER, (float(xz[0]), float(xz[1]), float(y_span[0]), float(y_span[1]), float(radius)), cls, color)

    def add_box(self, centre: np.ndarray, half: np.ndarray, yaw: float, cls: int, color: np.ndarray) -> None:
        self.add(BOX, (*map(float, centre), *map(float, half), float(yaw)), cls, color)

    def add(self, kind: int, params: tuple[float, ...], cls: int, color: np.ndarray) -> None:
        """One object of `kind` (SPHERE, CYLINDER, BOX) with its parameters as the class docstring lists them."""
        self.kind.append(kind)
        self.params.append(params)
        self.cls.append(int(cls))
        self.color.append(tuple(float(c) for c in color))

    def arrays(self) -> ObjectArrays:
        """The table as arrays, for vectorised tracing (built once; objects are not added later)."""
        if self._arrays is None or len(self._arrays.kind) != len(self.kind):
            params = np.zeros((len(self.kind), 7))
            for i, p in enumerate(self.params):
                params[i, : len(p)] = p
            self._arrays = ObjectArrays(
                kind=np.array(self.kind, np.int64),
                params=params,
                bounds=self.bounding_spheres(),
                cls=np.array(self.cls, np.uint8),
                color=np.array(self.color, float).reshape(-1, 3),
            )
        return self._arrays

    def bounding_spheres(self) -> np.ndarray:
        """(N, 4) centre and radius enclosing each object, for culling."""
        out = np.zeros((len(self.kind), 4))
        for i, (kind, p) in enumerate(zip(self.kind, self.params, strict=True)):
            if kind == SPHERE:
                out[i] = p
            elif kind == CYLINDER:
                x, z, y_top, y_bottom, r = p
                half_h = (y_bottom - y_top) / 2
                out[i] = (x, y_top + half_h, z, np.hypot(half_h, r))
            else:
                out[i] = (*p[:3], norm_rows(p[3:6]))
        return out


def intersect(kind: int, p: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Depth t (M,) and normals (M, 3) of rays o + t*d[i] against objects p[i] of one kind.
    Port: world.trace_torch.intersect (render_torch.PORTS).
    """
    return (_sphere, _cylinder, _box)[kind](p[:, : PARAM_COUNT[kind]], o, d)


def _sphere(p: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centre, r = p[:, :3], p[:, 3]
    oc = o - centre
    a = dot_rows(d, d)
    b = dot_rows(d, oc)
    disc = b * b - a * (dot_rows(oc, oc) - r * r)
    root = np.sqrt(np.maximum(disc, 0.0))
    t = (-b - root) / a
    t = np.where(t > NEAR_M, t, (-b + root) / a)
    t = np.where((disc >= 0) & (t > NEAR_M), t, np.inf)
    with np.errstate(invalid="ignore"):
        normal = (oc + t[:, None] * d) / r[:, None]
    return t, normal


def _cylinder(p: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x, z, y_top, y_bottom, r = p.T
    ox, oz = o[0] - x, o[2] - z
    dx, dz = d[:, 0], d[:, 2]
    a = dx * dx + dz * dz
    b = ox * dx + oz * dz
    disc = b * b - a * (ox * ox + oz * oz - r * r)
    with np.errstate(divide="ignore", invalid="ignore"):
        t_side = (-b - np.sqrt(np.maximum(disc, 0.0))) / a
        t_cap = (y_top - o[1]) / d[:, 1]
    y_side = o[1] + t_side * d[:, 1]
    side_ok = (disc >= 0) & (a > 0) & (t_side > NEAR_M) & (y_side >= y_top) & (y_side <= y_bottom)
    cap_x, cap_z = ox + t_cap * dx, oz + t_cap * dz
    cap_ok = (t_cap > NEAR_M) & (cap_x * cap_x + cap_z * cap_z <= r * r)
    t_side = np.where(side_ok, t_side, np.inf)
    t_cap = np.where(cap_ok, t_cap, np.inf)
    use_cap = t_cap < t_side
    t = np.where(use_cap, t_cap, t_side)
    with np.errstate(invalid="ignore"):
        normal = np.stack([(ox + t * dx) / r, np.zeros_like(t), (oz + t * dz) / r], axis=1)
    normal[use_cap] = (0.0, -1.0, 0.0)
    return t, normal


def _box(p: np.ndarray, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    centre, half, yaw = p[:, :3], p[:, 3:6], p[:, 6]
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]

    def to_box(v: np.ndarray) -> np.ndarray:  # world to box axes: the box's x is world (c, 0, -s)
        return np.concatenate([c * v[:, :1] - s * v[:, 2:], v[:, 1:2], s * v[:, :1] + c * v[:, 2:]], axis=1)

    lo = to_box(o - centre)
    ld = to_box(d)
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / ld
        t1 = (-half - lo) * inv
        t2 = (half - lo) * inv
    t_near = np.nan_to_num(np.minimum(t1, t2), nan=-np.inf)
    t_far = np.nan_to_num(np.maximum(t1, t2), nan=np.inf)
    axis = np.argmax(t_near, axis=1)
    t_enter = t_near.max(axis=1)
    t = np.where((t_enter <= t_far.min(axis=1)) & (t_enter > NEAR_M), t_enter, np.inf)
    rows = np.arange(len(ld))
    n = np.zeros_like(ld)
    n[rows, axis] = -np.sign(ld[rows, axis])
    # Back to the world: the transpose of to_box.
    normal = np.concatenate([c * n[:, :1] + s * n[:, 2:], n[:, 1:2], -s * n[:, :1] + c * n[:, 2:]], axis=1)
    return t, normal
