"""The eight semantic classes of the off-road world, in the order of their ids."""

CLASS_NAMES: tuple[str, ...] = ("sky", "water", "dirt", "paved_road", "grass", "foliage", "tree", "man_made_obstacle")

SKY, WATER, DIRT, PAVED, GRASS, FOLIAGE, TREE, OBSTACLE = range(len(CLASS_NAMES))
