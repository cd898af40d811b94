"""The calibration helper on board views rendered here through a known distorted, rotated rig."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from helpers import command
from scipy.spatial.transform import Rotation

from offroad_path.recordings.boards import Board
from offroad_path.recordings.rectify import Rectifier
from offroad_path.recordings.rig_calibration import read_rig

SIZE = (640, 480)
K = (np.array([[520.0, 0, 322], [0, 518, 236], [0, 0, 1]]), np.array([[515.0, 0, 316], [0, 516, 243], [0, 0, 1]]))
D = (np.array([-0.20, 0.08, 0.001, -0.0005, 0.0]), np.array([-0.18, 0.06, -0.0008, 0.0004, 0.0]))
R = Rotation.from_euler("xyz", [0.5, 1.5, -0.4], degrees=True).as_matrix()
T = np.array([-0.30, 0.004, 0.002])  # the right camera 30 cm to the right


EXACT = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)  # undistortPoints' default 5 steps miss by pixels at the corners
SQUARE_PX, PAD_PX = 80, 80  # the board texture: pixels per square, white margin


def board_texture(board: Board) -> tuple[np.ndarray, np.ndarray]:
    """The board's picture with a white margin, and the map from its pixels to board metres (the
    frame of Board.corners_3d: a chessboard's first inner corner, a ChArUco board's outer corner)."""
    if board.marker_m is None:
        squares = np.indices((board.rows, board.columns)).sum(axis=0) % 2
        texture, origin_px = np.kron(squares, np.ones((SQUARE_PX, SQUARE_PX))).astype(np.uint8) * 255, PAD_PX + SQUARE_PX
    else:
        texture, origin_px = board.charuco().generateImage((board.columns * SQUARE_PX, board.rows * SQUARE_PX), marginSize=0), PAD_PX
    texture = cv2.copyMakeBorder(texture, PAD_PX, PAD_PX, PAD_PX, PAD_PX, cv2.BORDER_CONSTANT, value=255)
    m_per_px = board.square_m / SQUARE_PX
    return texture, np.array([[m_per_px, 0, -origin_px * m_per_px], [0, m_per_px, -origin_px * m_per_px], [0, 0, 1]])


def render_view(texture: np.ndarray, to_metres: np.ndarray, K: np.ndarray, D: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """The board at `pose` (board to camera) seen by a camera with K and distortion D."""
    ideal = cv2.warpPerspective(texture, K @ pose[:3][:, [0, 1, 3]] @ to_metres, SIZE, borderValue=128)
    grid = np.stack(np.meshgrid(np.arange(SIZE[0]), np.arange(SIZE[1])), -1).reshape(-1, 1, 2).astype(np.float64)
    where = cv2.undistortPoints(grid, K, D, P=K, criteria=EXACT).reshape(SIZE[1], SIZE[0], 2).astype(np.float32)
    return cv2.remap(ideal, where[..., 0], where[..., 1], cv2.INTER_LINEAR, borderValue=128)


def render_views(board: Board, folder: Path, count: int = 20) -> None:
    """Views of the board from poses spread in front of the rig, through both cameras."""
    texture, to_metres = board_texture(board)
    to_right = np.eye(4)
    to_right[:3, :3], to_right[:3, 3] = R, T
    rng = np.random.default_rng(7)
    for side in ("left", "right"):
        (folder / side).mkdir(parents=True)
    centre = board.corners_3d().mean(axis=0)
    for i in range(count):
        pose = np.eye(4)  # turn the board about its centre, then place that centre between the cameras
        pose[:3, :3] = Rotation.from_euler("xyz", rng.uniform([-30, -30, -15], [30, 30, 15]), degrees=True).as_matrix()
        pose[:3, 3] = [rng.uniform(-0.1, 0.4), rng.uniform(-0.15, 0.15), rng.uniform(0.8, 1.3)] - pose[:3, :3] @ centre
        for side, k, d, p in (("left", K[0], D[0], pose), ("right", K[1], D[1], to_right @ pose)):
            cv2.imwrite(str(folder / side / f"{i:03d}.png"), render_view(texture, to_metres, k, d, p))


def rectified_row_error(rig) -> float:
    """Points 2 to 30 m ahead, seen through the true rig and rectified with the estimated one: the
    largest vertical disparity, in pixels (what stereo matching and odometry suffer)."""
    rng = np.random.default_rng(3)
    points = rng.uniform([-8, -3, 2], [8, 3, 30], (500, 3))
    points = points[(np.abs(points[:, 0] / points[:, 2]) < 0.5) & (np.abs(points[:, 1] / points[:, 2]) < 0.35)]  # inside both views
    rectifier = Rectifier(rig, SIZE, SIZE, 0.0)
    rows = []
    for k, d, r, t, R_i, P_i in ((K[0], D[0], np.eye(3), np.zeros(3), rectifier.R_left, rectifier.calibration.P_left),
                                 (K[1], D[1], R, T, None, rectifier.calibration.P_right)):  # fmt: skip
        raw, _ = cv2.projectPoints(points, cv2.Rodrigues(r)[0], t, k, d)
        cam = rig.left if R_i is not None else rig.right
        R_i = R_i if R_i is not None else rectifier.R_right
        rows.append(cv2.undistortPoints(raw, cam.K, cam.D, R=R_i, P=P_i, criteria=EXACT).reshape(-1, 2)[:, 1])
    return float(np.abs(rows[0] - rows[1]).max())


# Measured on these views: RMS reprojection error 0.12 px and worst row error 0.34 px for the
# chessboard; ChArUco corners come from marker homographies, which lens distortion bends: 0.23 px
# and 0.54 px.
@pytest.mark.parametrize(
    "board,max_row_error_px", [(Board(10, 7, 0.04), 0.5), (Board(7, 5, 0.07, marker_m=0.05), 0.8)], ids=["chessboard", "charuco"]
)
@pytest.mark.slow(seconds=17)
def test_calibrate_recovers_the_rig(board, max_row_error_px, tmp_path):
    render_views(board, tmp_path / "views")
    out = tmp_path / "stereo.yaml"
    args = [str(tmp_path / "views" / "left"), str(tmp_path / "views" / "right"), "--board", f"{board.columns}x{board.rows}",
            "--square-m", str(board.square_m), "--out", str(out)]  # fmt: skip
    args += ["--marker-m", str(board.marker_m)] if board.marker_m else []
    run = command("offroad_path.calibrate", *args)
    assert run.returncode == 0, run.stderr
    assert "RMS reprojection error" in run.stdout
    rig = read_rig(out)
    assert np.linalg.norm(rig.T) == pytest.approx(0.30, rel=0.01)
    for got, want in zip((rig.left.K, rig.right.K), K, strict=True):
        assert got[0, 0] == pytest.approx(want[0, 0], rel=0.01) and got[:2, 2] == pytest.approx(want[:2, 2], abs=4)
    assert rectified_row_error(rig) < max_row_error_px


def test_calibrate_refuses_too_few_views(tmp_path):
    for side in ("left", "right"):
        (tmp_path / side).mkdir()
        cv2.imwrite(str(tmp_path / side / "000.png"), np.full((48, 64), 128, np.uint8))
    args = [str(tmp_path / "left"), str(tmp_path / "right"), "--board", "10x7", "--square-m", "0.04", "--out", str(tmp_path / "s.yaml")]
    run = command("offroad_path.calibrate", *args)
    assert run.returncode == 2 and "found in both cameras in 0 of 1 views" in run.stderr and str(tmp_path / "left") in run.stderr
    assert not (tmp_path / "s.yaml").exists()
