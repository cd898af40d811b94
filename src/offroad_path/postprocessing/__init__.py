"""The paper's post-processing of path confidence maps (Holder & Breckon 2018, section IV)."""

from offroad_path.postprocessing.filter import PostprocessParams, postprocess

__all__ = ["PostprocessParams", "postprocess"]
