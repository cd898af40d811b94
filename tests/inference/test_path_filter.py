"""The paper's post-processing on hand-made maps, checked against OpenCV's blur of the same map."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from helpers import PAPER_POSTPROCESSING as PAPER

from offroad_path.inference.path_filter import blur, nearest_to_bottom_centre, postprocess

H, W = 96, 160
NEAR = np.full((H, W), 5.0, np.float32)  # every pixel 5 m away: the depth mask keeps all


def network_like_map(seed: int, h: int = 288, w: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """A confidence map as the laptop networks give it (a 128 x 72 output upsampled bilinearly),
    and stereo depth with a sharp far band across it, where the depth mask cuts the map."""
    rng = np.random.default_rng(seed)
    coarse = cv2.GaussianBlur(rng.random((72, 128)).astype(np.float32), (0, 0), 1.5) ** 2
    confidence = np.clip(cv2.resize(coarse, (w, h), interpolation=cv2.INTER_LINEAR) * 2 - 0.3, 0, 1).astype(np.float32)
    depth = np.full((h, w), 8.0, np.float32)
    depth[: h // 3] = 40.0  # beyond D: zeroed before the blur, an edge of full height
    depth[h // 3 :, : w // 5] = 0.0  # no stereo match: kept, as the paper does
    return confidence, depth


@pytest.mark.parametrize("seed", range(3))
def test_the_half_resolution_blur_stays_within_bounds_of_the_exact_one(seed):
    confidence, depth = network_like_map(seed)
    exact = postprocess(confidence, depth, PAPER)
    fast = postprocess(confidence, depth, replace(PAPER, blur_scale=2))
    assert 0 < np.abs(fast - exact).max() < 0.03  # the same bound the laptop test maps met
    flipped = ((fast > 0.5) != (exact > 0.5)).mean()
    assert flipped < 2e-4  # of the thresholded path, a few pixels along its edge
    # The blur alone, on the smooth map before the depth mask: the image border is the worst place
    # (the low-resolution reflection differs there); inside, the two agree to 1e-3.
    difference = np.abs(blur(confidence, 6.0, 2) - blurred(confidence))
    assert difference.max() < 0.02 and difference[20:-20, 20:-20].max() < 1e-3


def test_small_or_odd_sized_maps_and_narrow_blurs_get_the_exact_blur():
    rng = np.random.default_rng(0)
    odd = rng.random((95, 161)).astype(np.float32)
    assert np.array_equal(blur(odd, 6.0, 2), blurred(odd))
    even = rng.random((96, 160)).astype(np.float32)
    assert np.array_equal(blur(even, 2.0, 2), blurred(even, 2.0))  # sigma 2 at half resolution would be under a pixel
    assert not np.array_equal(blur(even, 6.0, 2), blurred(even))


def blurred(c: np.ndarray, sigma: float = 6.0) -> np.ndarray:
    return cv2.GaussianBlur(c.astype(np.float32), (0, 0), sigmaX=sigma, sigmaY=sigma, borderType=cv2.BORDER_REFLECT_101)


def test_a_far_blob_is_removed_by_the_depth_mask():
    c = np.zeros((H, W), np.float32)
    c[60:, 60:100] = 0.9  # the path under the vehicle, 8 m away
    c[10:40, 60:100] = 0.9  # a blob joined to it by a thin strip, but 35 m away
    c[40:60, 78:82] = 0.9
    depth = np.full((H, W), 8.0, np.float32)
    depth[:45] = 35.0
    depth[:, :5] = 0.0  # unknown depth: left alone by the paper's rule
    out = postprocess(c, depth, PAPER)
    masked = np.where(depth <= 20, c, 0)
    support = blurred(masked) >= 0.025
    assert not out[:20].any()  # the far blob is gone, beyond the blur's reach
    np.testing.assert_allclose(out[support], blurred(masked)[support], atol=1e-6)
    # Without the depth mask the far blob survives (it is connected to the path).
    assert postprocess(c, None, replace(PAPER, use_depth=False))[20:30, 70:90].min() > 0.5


def test_of_two_components_the_one_nearest_the_bottom_centre_survives():
    c = np.zeros((H, W), np.float32)
    c[70:, 70:90] = 0.8  # at the bottom-centre
    c[5:30, 5:40] = 1.0  # larger and more confident, but far from where the vehicle is
    out = postprocess(c, NEAR, PAPER)
    assert not out[:50].any()
    reference = blurred(c)
    keep = (reference >= 0.025) & (np.arange(H)[:, None] >= 50)
    np.testing.assert_allclose(out[keep], reference[keep], atol=1e-6)
    assert (out[~keep] == 0).all()
    # The winner is decided by distance to (w/2, h), not by size: move the small blob off-centre.
    c2 = np.zeros((H, W), np.float32)
    c2[80:, 0:10] = 0.8  # bottom-left corner: about 75 px from the bottom-centre
    c2[30:60, 70:90] = 0.8  # 36 px above the bottom-centre: nearer
    out2 = postprocess(c2, NEAR, PAPER)
    assert out2[40:50, 75:85].min() > 0.5 and not out2[85:, :4].any()


@pytest.mark.parametrize("sigma", [2.0, 6.0])
def test_sigma_and_delta_are_honoured(sigma):
    c = np.zeros((H, W), np.float32)
    c[H - 1, W // 2] = 1.0  # an impulse at the bottom-centre: the output is the Gaussian kernel
    for delta in (0.001, 0.0025):
        out = postprocess(c, NEAR, replace(PAPER, sigma=sigma, delta=delta))
        reference = blurred(c, sigma)
        np.testing.assert_allclose(out, np.where(reference >= delta, reference, 0), atol=1e-7)
        assert out.max() == pytest.approx(reference.max()) and (out > 0).sum() == (reference >= delta).sum()
    wide, narrow = ((postprocess(c, NEAR, replace(PAPER, sigma=sigma, delta=d)) > 0).sum() for d in (1e-4, 1e-3))
    assert wide > narrow  # a lower delta keeps more of the blur's tail
    # sigma 0 skips the blur: the impulse itself is the only component
    assert (postprocess(c, NEAR, replace(PAPER, sigma=0)) == c).all()


def test_an_all_zero_map_and_a_map_below_delta_become_zero():
    zero = np.zeros((H, W), np.float32)
    faint = np.full((H, W), 0.02, np.float32)  # blurred, still 0.02 < delta
    out = postprocess(np.stack([zero, faint]), np.stack([NEAR, NEAR]), PAPER)
    assert out.shape == (2, H, W) and not out.any()


def test_a_batch_equals_its_maps_one_by_one():
    rng = np.random.default_rng(0)
    maps = cv2.GaussianBlur(rng.random((H, W, 5)).astype(np.float32), (0, 0), 3).transpose(2, 0, 1) ** 4
    depth = rng.uniform(0, 30, (5, H, W)).astype(np.float32)
    batch = postprocess(maps, depth, PAPER)
    for i in range(5):
        np.testing.assert_array_equal(batch[i], postprocess(maps[i], depth[i], PAPER))


def test_bad_shapes_and_missing_depth_are_refused():
    with pytest.raises(ValueError, match="stereo depth"):
        postprocess(np.zeros((H, W)), None, PAPER)
    with pytest.raises(ValueError, match="does not match"):
        postprocess(np.zeros((2, H, W)), np.zeros((H, W)), PAPER)


def test_nearest_pixel_to_the_bottom_centre_matches_a_brute_force_search():
    rng = np.random.default_rng(1)
    for _ in range(300):
        h, w = rng.integers(4, 200, 2)
        mask = (rng.random((h, w)) < rng.random() * 0.02).astype(np.uint8)
        ys, xs = np.nonzero(mask)
        found = nearest_to_bottom_centre(mask)
        if len(xs) == 0:
            assert found is None
            continue
        best = ((xs - w / 2) ** 2 + (ys - h) ** 2).min()
        assert (found[0] - w / 2) ** 2 + (found[1] - h) ** 2 == best


def test_unknown_depth_is_kept_by_the_papers_rule_and_dropped_on_request():
    c = np.zeros((H, W), np.float32)
    c[40:, 60:100] = 0.9  # the path, 8 m away
    depth = np.full((H, W), 8.0, np.float32)
    depth[40:, 60:75] = 0.0  # a hole in the disparity on the left part of the path
    kept = postprocess(c, depth, PAPER)
    np.testing.assert_allclose(kept, postprocess(c, NEAR, PAPER), atol=1e-6)  # as if the depth were known
    dropped = postprocess(c, depth, replace(PAPER, unknown_depth="drop"))
    reference = blurred(np.where(depth > 0, c, 0))
    assert dropped[70, 62] < 0.5 < kept[70, 62]  # deep inside the hole: the blurred zeros
    np.testing.assert_allclose(dropped[70, 95], reference[70, 95], atol=1e-6)
