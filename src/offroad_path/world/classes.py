"""The eight semantic classes of the off-road world, in the order of their ids."""

import numpy as np

CLASS_NAMES: tuple[str, ...] = ("sky", "water", "dirt", "paved_road", "grass", "foliage", "tree", "man_made_obstacle")

SKY, WATER, DIRT, PAVED, GRASS, FOLIAGE, TREE, OBSTACLE = range(len(CLASS_NAMES))

BASE_COLORS: dict[int, tuple[float, float, float]] = {  # linear RGB albedo before per-world jitter
    WATER: (0.10, 0.13, 0.12),
    DIRT: (0.50, 0.38, 0.26),
    PAVED: (0.36, 0.36, 0.37),
    GRASS: (0.26, 0.42, 0.14),
    FOLIAGE: (0.14, 0.30, 0.09),
    TREE: (0.09, 0.22, 0.07),
    OBSTACLE: (0.55, 0.50, 0.45),
}
TRUNK_COLOR = (0.28, 0.20, 0.13)
TEXTURE_CONTRAST = np.array([0.0, 0.05, 0.45, 0.15, 0.5, 0.5, 0.4, 0.2])  # per class: the detail texture's strength
