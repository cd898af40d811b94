"""Frame selection (label.frame_selection): which frames start a label segment, on hand-made trajectories."""

from __future__ import annotations

import numpy as np
import pytest

from offroad_path.label.frame_selection import select_segments


def line(n: int, step: float, still: int = 0) -> np.ndarray:
    z = np.concatenate([np.zeros(still), np.arange(n) * step])
    return np.stack([np.zeros_like(z), np.zeros_like(z), z], axis=1)


def test_midway_restart_as_the_paper():
    # 1 m per frame: fn is the first frame more than 20 m away, i.e. f0 + 21; restart at the middle.
    assert select_segments(line(60, 1.0), 20.0, "midway", 5.0, 0.01) == [(0, 21), (10, 31), (20, 41), (30, 51)]


def test_starts_at_first_motion():
    segments = select_segments(line(30, 1.0, still=5), 20.0, "midway", 5.0, 0.01)
    assert segments[0] == (5, 26)  # frames 0..5 stand at z = 0; frame 5 is the first to move on


def test_stride_along_the_path():
    assert select_segments(line(30, 1.0), 20.0, "stride", 2.5, 0.01) == [(0, 21), (3, 24), (5, 26), (8, 29)]


def test_a_stride_shorter_than_the_frames_spacing_labels_each_frame_once():
    # 1 m between frames, a mark every 5 cm: each frame starts one label, none twice (the marks
    # between two frames would otherwise all pick the next frame and overwrite its label).
    assert select_segments(line(30, 1.0), 20.0, "stride", 0.05, 0.01) == [(f0, f0 + 21) for f0 in range(9)]


def test_distance_is_straight_line_from_f0():
    # A U-turn never gets 20 m from its start, so it gets no label however long it drives.
    angle = np.linspace(0, np.pi, 200)
    u_turn = np.stack([9 * np.sin(angle), np.zeros(200), 9 * (1 - np.cos(angle))], axis=1)
    assert select_segments(u_turn, 20.0, "midway", 5.0, 0.01) == []


def test_unknown_strategy_lists_valid_ones():
    with pytest.raises(ValueError, match="midway, stride"):
        select_segments(line(30, 1.0), 20.0, "every", 5.0, 0.01)
