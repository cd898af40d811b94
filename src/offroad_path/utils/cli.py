"""What every stage entry point shares: clear errors on bad input, and a non-zero exit."""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
from collections.abc import Callable, Iterator
from typing import Any

import hydra
from omegaconf import DictConfig
from omegaconf.errors import MissingMandatoryValue

from offroad_path.sequence.errors import SequenceError
from offroad_path.utils.atomic import remove_unfinished
from offroad_path.utils.parallel import stop_workers
from offroad_path.utils.threads import set_threads

log = logging.getLogger("offroad_path")

EXIT_BAD_INPUT = 2


@contextlib.contextmanager
def clear_errors() -> Iterator[None]:
    """Turn bad-input errors into one line naming the file, and exit status 2 (no traceback)."""
    try:
        yield
    except MissingMandatoryValue as e:  # a required setting (`???` in conf/) was not given
        print(f"error: {e.full_key} is required: give it on the command line, {e.full_key}=...", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from e
    except (SequenceError, FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from e


def _stop(signum: int, frame: Any) -> None:
    """On SIGTERM: stop the worker processes, delete unfinished outputs, exit 128 + signal.
    Training keeps its resume checkpoints (they are not unfinished outputs).

    Done here rather than by raising SystemExit, which Python drops when the signal lands while
    the main thread runs a finaliser (seen once in CI: the stage then ran on to the end)."""
    stop_workers()  # the pools first, so that none starts a replacement worker; then wait for them
    remove_unfinished()
    os._exit(128 + signum)


def objective(result: Any, metric: str | None) -> float | None:
    """What a Hydra sweeper optimises: `metric` of the stage's returned metrics (None when no
    search asks for one)."""
    if metric is None:
        return None
    if not isinstance(result, dict) or result.get(metric) is None:
        found = ", ".join(k for k, v in result.items() if isinstance(v, float)) if isinstance(result, dict) else "none"
        raise ValueError(f"optimized_metric={metric}: this stage returned no such metric (it has: {found})")
    return float(result[metric])


def run_stage(stage: Callable[[DictConfig], Any], cfg: DictConfig) -> Any:
    """What a stage's command does with its composed config: check every value against the schemas'
    rules, set the process's threads (`threads`), run, and turn bad input into one line and exit status 2."""
    from offroad_path.config import validate_config

    with clear_errors():
        validate_config(cfg)
        set_threads(cfg.threads)
        return stage(cfg)


def hydra_stage(stage: Callable[[DictConfig], Any]) -> Callable[[], None]:
    """The Hydra entry point of a stage: the project's config, typed by its schemas, and clear
    errors on bad input."""
    from offroad_path.config import CONF_DIR, register_configs

    register_configs()

    @hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
    def main(cfg: DictConfig) -> float | None:
        # A stop (kill, `dvc` interrupted) deletes the temporary folders of unfinished outputs
        # instead of leaving them beside the outputs.
        signal.signal(signal.SIGTERM, _stop)
        result = run_stage(stage, cfg)
        with clear_errors():
            return objective(result, cfg.get("optimized_metric"))

    return main
