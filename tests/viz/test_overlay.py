"""The path drawn over the image."""

from __future__ import annotations

import numpy as np

from offroad_path.viz import OUTLINE, overlay


def test_overlay_blends_the_path_toward_green_and_leaves_the_rest():
    image = np.full((20, 30, 3), 100, np.uint8)
    path = np.zeros((20, 30), bool)
    path[5:15, 10:20] = True
    plain = overlay(image, path, alpha=0.5, outline=False)
    assert (plain[path] == [50, 178, 50]).all()  # rint(0.5 * 100 + 0.5 * (0, 255, 0))
    assert (plain[~path] == 100).all()
    outlined = overlay(image, path, alpha=0.5)
    red, green, blue = outlined[5, 12].astype(int)  # the border, drawn anti-aliased in yellow
    assert red > 200 and green > 200 and blue < 40 and OUTLINE == (255, 255, 0)
    assert (outlined[10, 15] == [50, 178, 50]).all()
    assert (outlined[0, 0] == 100).all()
