"""Steering from a path image (pure pursuit) on hand-made paths whose angle is known."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from offroad_path.steering.pure_pursuit import GroundCamera, centre_line, steering_from_path

W, H = 512, 288
K = np.array([[305.0, 0, 256.0], [0, 305.0, 144.0], [0, 0, 1]])
CAMERA = GroundCamera(K, height_m=1.8, pitch_deg=7.0, rear_axle_behind_m=1.8)
WHEELBASE = 2.8


def ground_to_pixels(points_xz: np.ndarray, camera: GroundCamera) -> np.ndarray:
    """Ground points (x right, z forward from the rear axle) to pixels: the inverse of to_ground."""
    tilt = math.radians(camera.pitch_deg)
    rotation = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(tilt), -math.sin(tilt)], [0.0, math.sin(tilt), math.cos(tilt)]])
    level = np.stack([points_xz[:, 0], np.full(len(points_xz), camera.height_m), points_xz[:, 1] - camera.rear_axle_behind_m], axis=1)
    cam = level @ rotation.T
    return (cam[:, :2] / cam[:, 2:3]) * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]


def drawn_path(points_xz: np.ndarray, thickness: int = 15) -> np.ndarray:
    """A band of constant width in pixels along the projected centre line."""
    mask = np.zeros((H, W), np.uint8)
    pixels = ground_to_pixels(points_xz, CAMERA)
    cv2.polylines(mask, [np.rint(pixels * 16).astype(np.int32)], False, 255, thickness, cv2.LINE_8, shift=4)
    return mask > 0


def test_straight_path_steers_straight():
    z = np.linspace(3.5, 40, 200)
    assert steering_from_path(drawn_path(np.stack([np.zeros_like(z), z], axis=1)), CAMERA, 8.0, WHEELBASE) == pytest.approx(0.0, abs=1e-3)


@pytest.mark.parametrize("radius", [15.0, -25.0, 60.0])  # positive: turning right
def test_circular_path_gives_the_bicycle_angle(radius):
    """A circle of radius R through the rear axle, tangent to the vehicle's axis: atan(L / R)."""
    theta = np.linspace(0.05, 1.2, 400) * min(1.0, 40.0 / abs(radius))
    points = np.stack([radius * (1 - np.cos(theta)), abs(radius) * np.sin(theta)], axis=1)
    points = points[points[:, 1] > 3.5]  # the camera sees the ground from about 2 m ahead of itself
    angle = steering_from_path(drawn_path(points), CAMERA, 8.0, WHEELBASE)
    assert math.degrees(angle) == pytest.approx(math.degrees(math.atan(WHEELBASE / radius)), abs=0.15)


def test_centre_line_of_a_band_and_an_empty_image():
    path = np.zeros((10, 20), bool)
    path[4:, 3:9] = True
    assert centre_line(path).tolist() == [[5.5, float(r)] for r in range(9, 3, -1)]
    assert steering_from_path(np.zeros((H, W), bool), CAMERA, 8.0, WHEELBASE) is None
    sky = np.zeros((H, W), bool)
    sky[:100] = True  # above the horizon: never on the ground
    assert steering_from_path(sky, CAMERA, 8.0, WHEELBASE) is None
