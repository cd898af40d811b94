"""The rendered world against the pinhole model: depth, poses and both images agree exactly."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from offroad_path.world.classes import DIRT, GRASS, PAVED, WATER
from offroad_path.world.record import camera_for
from offroad_path.world.render import render_view
from offroad_path.world.scene import build_world

GROUND = [WATER, DIRT, PAVED, GRASS]
FRAMES = (20, 21)


@pytest.fixture(scope="module")
def rendered(compose_config):
    # The geometry without a sensor between light and bytes: a warp's residual is shading, not noise or auto-gain.
    cfg = compose_config("world.frames=40", "world.appearance.enabled=false").world
    world = build_world(cfg, seed=7)
    camera = camera_for(cfg)
    to_right = np.eye(4)
    to_right[0, 3] = cfg.rig.baseline_m
    views = {k: render_view(world, camera, world.poses[k], cfg.max_distance_m) for k in FRAMES}
    right = render_view(world, camera, world.poses[FRAMES[0]] @ to_right, cfg.max_distance_m)
    return cfg, world, camera, views, right


def back_project(camera, depth: np.ndarray) -> np.ndarray:
    """Camera-frame points (H, W, 3) of every pixel with depth z."""
    u, v = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    return np.stack([(u - camera.cx) / camera.fx * depth, (v - camera.cy) / camera.fy * depth, depth], axis=-1)


def project(camera, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return camera.fx * points[..., 0] / points[..., 2] + camera.cx, camera.fy * points[..., 1] / points[..., 2] + camera.cy


def sample(image: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return cv2.remap(
        image.astype(np.float32),
        u.astype(np.float32),
        v.astype(np.float32),
        cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )


def test_ground_pixels_lie_on_the_terrain(rendered):
    _, world, camera, views, _ = rendered
    k = FRAMES[0]
    view = views[k]
    ground = np.isin(view.semantic, GROUND) & (view.depth > 0)
    assert ground.mean() > 0.3
    pts = back_project(camera, view.depth)[ground] @ world.poses[k][:3, :3].T + world.poses[k][:3, 3]
    gap = -pts[:, 1] - world.terrain.elevation(pts[:, 0], pts[:, 2])
    assert np.abs(gap).max() < 1e-3  # metres: the hit is on the surface, not near it


def _warp(rendered, pose_error: np.ndarray | None = None):
    """Pixels of frame k moved into frame k+1 with ground-truth depth and relative pose."""
    _, world, camera, views, _ = rendered
    a, b = views[FRAMES[0]], views[FRAMES[1]]
    b_from_a = np.linalg.inv(world.poses[FRAMES[1]]) @ world.poses[FRAMES[0]]
    if pose_error is not None:
        b_from_a = pose_error @ b_from_a
    pts = back_project(camera, a.depth) @ b_from_a[:3, :3].T + b_from_a[:3, 3]
    u, v = project(camera, pts)
    inside = (a.depth > 0) & (a.depth < 40) & (pts[..., 2] > 0.5) & (u > 1) & (u < camera.width - 2) & (v > 1) & (v < camera.height - 2)
    depth_b = sample(b.depth, u, v)
    visible = inside & (np.abs(depth_b - pts[..., 2]) < 0.01 * pts[..., 2])  # not occluded in b
    return a, b, u, v, pts, inside, visible


def test_depth_and_pose_reproject_to_subpixel(rendered):
    _, world, camera, _views, _ = rendered
    _a, b, u, v, _pts, inside, visible = _warp(rendered)
    assert visible.sum() > 0.85 * inside.sum()  # a forward move hides little of the view
    # The point that frame k+1 itself sees at the warped pixel, carried back into frame k.
    depth_b = sample(b.depth, u, v)
    pts_b = np.stack([(u - camera.cx) / camera.fx * depth_b, (v - camera.cy) / camera.fy * depth_b, depth_b], axis=-1)
    a_from_b = np.linalg.inv(world.poses[FRAMES[0]]) @ world.poses[FRAMES[1]]
    back = pts_b[visible] @ a_from_b[:3, :3].T + a_from_b[:3, 3]
    ub, vb = project(camera, back)
    uu, vv = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    err = np.hypot(ub - uu[visible], vb - vv[visible])
    assert np.median(err) < 0.05
    assert np.percentile(err, 95) < 0.5


def test_depth_warp_reproduces_the_next_frame(rendered):
    a, b, u, v, _, _, visible = _warp(rendered)
    grey_a = cv2.cvtColor(a.image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    grey_b = cv2.cvtColor(b.image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    error = np.abs(sample(grey_b, u, v) - grey_a)[visible]
    # Control: the same warp with the pose off by 10 cm sideways must look clearly worse.
    nudge = np.eye(4)
    nudge[0, 3] = 0.10
    _a2, _b2, u2, v2, _, _, visible2 = _warp(rendered, nudge)
    wrong = np.abs(sample(grey_b, u2, v2) - grey_a)[visible2]
    assert np.median(error) < 3.0  # grey levels; what is left is shading and texture filtering
    assert np.median(wrong) > 2 * np.median(error)


def test_disparity_from_depth_matches_the_right_image(rendered):
    cfg, _, camera, views, right = rendered
    left = views[FRAMES[0]]
    valid = (left.depth > 1.0) & (left.depth < 40)
    disparity = np.where(valid, camera.fx * cfg.rig.baseline_m / np.where(valid, left.depth, 1), 0)
    u, v = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    ur = u - disparity
    valid &= ur > 1
    # The right camera sees the same point at the same depth, on the same row.
    depth_r = sample(right.depth, ur, v)
    seen = valid & (np.abs(depth_r - left.depth) < 0.01 * left.depth)
    assert seen.sum() > 0.9 * valid.sum()
    grey_l = cv2.cvtColor(left.image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    grey_r = cv2.cvtColor(right.image, cv2.COLOR_RGB2GRAY).astype(np.float32)
    error = np.abs(sample(grey_r, ur, v) - grey_l)[seen]
    off_by_two = np.abs(sample(grey_r, ur - 2, v) - grey_l)[seen]
    assert np.median(error) < 2.0
    assert np.median(off_by_two) > 2 * np.median(error)


def test_stereo_sgbm_recovers_ground_truth_disparity(rendered):
    cfg, _, camera, views, right = rendered
    left = views[FRAMES[0]]
    grey_l = cv2.cvtColor(left.image, cv2.COLOR_RGB2GRAY)
    grey_r = cv2.cvtColor(right.image, cv2.COLOR_RGB2GRAY)
    sgbm = cv2.StereoSGBM_create(
        minDisparity=0, numDisparities=64, blockSize=5, P1=8 * 25, P2=32 * 25, uniquenessRatio=10, speckleWindowSize=100, speckleRange=2
    )
    measured = sgbm.compute(grey_l, grey_r).astype(np.float32) / 16.0
    textured_ground = np.isin(left.semantic, [DIRT, GRASS, PAVED]) & (left.depth > 2) & (left.depth < 30)
    valid = textured_ground & (measured > 0)
    assert valid.sum() > 0.7 * textured_ground.sum()
    truth = camera.fx * cfg.rig.baseline_m / left.depth[valid]
    assert np.median(np.abs(measured[valid] - truth)) < 1.0
