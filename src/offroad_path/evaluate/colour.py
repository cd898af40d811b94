"""The colour baseline: a per-pixel classifier on colour and image position alone, trained on the
training split and scored like the networks. What a network scores above it needs context (the
track's shape, where it leads); a world whose tracks a colour gives away lets a network score
without any.

scikit-learn's HistGradientBoostingClassifier on eight features per pixel: R, G, B, H, S, V (each in
[0, 1]) and the pixel's row and column (fractions of the image). Training pixels are drawn evenly
from every training frame, mirrored copies included, with a fixed seed.
"""

from __future__ import annotations

import cv2
import numpy as np
from sklearn.ensemble import HistGradientBoostingClassifier

from offroad_path.data.loading import load_labels, mirror, read
from offroad_path.data.manifest import Sample

FEATURES = ("r", "g", "b", "h", "s", "v", "row", "col")


def pixel_features(image_rgb: np.ndarray) -> np.ndarray:
    """(H * W, 8) float32 features of an (H, W, 3) uint8 RGB image, in FEATURES order."""
    h, w, _ = image_rgb.shape
    hsv = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2HSV_FULL)  # 8-bit: integer arithmetic, every CPU alike
    rows, cols = np.mgrid[0:h, 0:w]
    parts = [
        image_rgb.reshape(-1, 3) / 255.0,
        hsv.reshape(-1, 3) / 255.0,
        (rows / max(h - 1, 1)).reshape(-1, 1),
        (cols / max(w - 1, 1)).reshape(-1, 1),
    ]
    return np.concatenate(parts, axis=1).astype(np.float32)


def load_image(sample: Sample, shape: tuple[int, int]) -> np.ndarray:
    """The sample's left image as (H, W, 3) uint8 RGB at the labels' `shape`, mirrored where it says so."""
    image = cv2.cvtColor(read(sample.image, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB)
    if image.shape[:2] != shape:
        image = cv2.resize(image, (shape[1], shape[0]), interpolation=cv2.INTER_AREA)
    return mirror(image) if sample.mirrored else image


class ColourBaseline:
    """Fit on training frames, then paint a path probability on any frame."""

    def __init__(self, pixels_per_frame: int = 400, seed: int = 0) -> None:
        self.pixels_per_frame = pixels_per_frame
        self.seed = seed
        self.model = HistGradientBoostingClassifier(max_iter=100, learning_rate=0.1, max_leaf_nodes=31, random_state=seed)

    def fit(self, samples: list[Sample]) -> ColourBaseline:
        labels = load_labels(samples)  # (N, H, W) bool
        shape = labels.shape[1:]
        rng = np.random.default_rng(self.seed)
        xs, ys = [], []
        for sample, label in zip(samples, labels, strict=True):
            pick = rng.choice(label.size, size=min(self.pixels_per_frame, label.size), replace=False)
            xs.append(pixel_features(load_image(sample, shape))[pick])
            ys.append(label.ravel()[pick])
        y = np.concatenate(ys)
        if y.all() or not y.any():
            raise ValueError("the training labels hold one class only: no colour baseline")
        self.model.fit(np.concatenate(xs), y)
        return self

    def predict(self, samples: list[Sample], shape: tuple[int, int]) -> np.ndarray:
        """(N, H, W) float32 path probabilities at the labels' shape."""
        path_column = list(self.model.classes_).index(True)
        out = np.empty((len(samples), *shape), np.float32)
        for i, sample in enumerate(samples):
            out[i] = self.model.predict_proba(pixel_features(load_image(sample, shape)))[:, path_column].reshape(shape)
        return out
