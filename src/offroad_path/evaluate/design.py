"""The pre-registered design a run was scored under (conf/evaluate/design/): its values' hash in the
metrics, so that the committed results name the design they were made under and a test can tell
when the design changed after its main test set was scored (docs/conclusions.md)."""

from __future__ import annotations

import hashlib
import json

from omegaconf import DictConfig, OmegaConf

# The keys of evaluate's config that decide a verdict: the design file sets exactly these.
DESIGN_KEYS = ("main_test_set", "seeds", "bootstrap", "conclusions")
# How the intervals are drawn is code (statistics.bootstrap): named here, so that a change of method changes the hash.
INTERVAL_METHOD = (
    "hierarchical bootstrap of worlds, blocks and seeds; percentile interval widened at the worlds' and the seeds' levels: "
    "each level's variance times n/(n-1), Student's t with their Welch-Satterthwaite degrees of freedom over z"
)


def design_values(e: DictConfig) -> dict:
    """The resolved values of the design's keys (evaluate's config), and the interval method."""
    values = {key: OmegaConf.to_container(e[key], resolve=True) if OmegaConf.is_config(e[key]) else e[key] for key in DESIGN_KEYS}
    return values | {"interval_method": INTERVAL_METHOD}


def design_record(e: DictConfig) -> dict:
    """metrics/evaluation.json's `design`: the sha256 of the design's values (keys sorted, as JSON)."""
    text = json.dumps(design_values(e), sort_keys=True, separators=(",", ":"))
    return {"sha256": hashlib.sha256(text.encode()).hexdigest(), "main_test_set": dict(design_values(e)["main_test_set"])}
