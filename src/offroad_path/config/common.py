"""What the schemas share: where conf/ is, the rules several settings use, and the choice lists read
from conf/ or from the registries that implement them."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from offroad_path.utils.rules import Rule, between, rule
from offroad_path.utils.threads import is_thread_setting

CONF_DIR = Path(__file__).resolve().parents[3] / "conf"
IMAGE_SIZE = between(16, 8192)  # pixels of an image side
MAX_STEPS = rule(lambda v: v == -1 or v >= 1, "must be -1 (no cap) or an integer >= 1")  # SGD steps, besides max_epochs
FINITE = rule(lambda v: True, "must be a finite number")
PITCH = between(-90, 90, low_open=True, high_open=True)  # a camera's pitch in degrees, down
THREADS = {"rule": Rule(is_thread_setting, "must be all, free or a whole number >= 1")}  # offroad_path.utils.threads


def config_names(group: str) -> Callable[[], list[str]]:
    """The choices of a config group that has one file per implemented choice (conf/<group>/<name>.yaml):
    tests check them against the registry that implements them (offroad_path.models.MODELS,
    offroad_path.training.pretrained.CHOICES), which validating a value then need not import (torch)."""
    return lambda: sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))


model_names = config_names("model")


PRETRAININGS = config_names("pretraining")
