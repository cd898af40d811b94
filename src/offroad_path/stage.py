"""The stage runner: what every `python -m offroad_path.<stage>` shares. The config composed by
Hydra, checked against the schemas' rules, cut down to the groups the stage declares, the process's
threads set, and bad input turned into one line and exit status 2 (offroad_path.errors).

A stage is a function of its config, declared with the groups it reads:

    @reads("train", "data", "model")
    def train(cfg: DictConfig) -> dict: ...

    main = hydra_stage(train)

Called with the whole config (as its command and the tests call it), the function sees only its
groups and the shared top-level values (SHARED), resolved and read-only: reading another stage's
group is an error wherever it is tried, so `--cfg job` and the declaration say what a stage uses.
"""

from __future__ import annotations

import functools
import logging
import os
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.errors import HydraException
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from offroad_path.config import check_overrides, register_configs, validate_config
from offroad_path.config.common import CONF_DIR
from offroad_path.errors import EXIT_BAD_INPUT, InputError, clear_errors, missing_extra, one_line
from offroad_path.utils.atomic import remove_unfinished
from offroad_path.utils.lifetime import end_with_dvc
from offroad_path.utils.outputs import Outputs, check_metrics_follow, check_outputs, claimed, release_locks
from offroad_path.utils.parallel import stop_workers
from offroad_path.utils.ranks import is_global_zero
from offroad_path.utils.threads import set_threads
from offroad_path.utils.tracking import end_open_runs_killed, end_pipeline_parent

log = logging.getLogger("offroad_path")

# Top-level values every stage may read (conf/config.yaml): the training seed, whether an interrupted
# training run resumes, the process's threads, the run's experiment name (an MLflow tag).
SHARED = ("seed", "resume", "threads", "experiment_name")


# Commands that are packages with a __main__ but no Hydra stage: the recordings' check, the rig calibration.
COMMANDS = ("calibrate", "sequence")


def stage_modules() -> list[str]:
    """Every stage, `python -m offroad_path.<name>`: the packages of offroad_path with a __main__.py,
    but the COMMANDS (listing them imports none)."""
    here = Path(__file__).parent
    return sorted(p.parent.name for p in here.glob("*/__main__.py") if p.parent.name not in COMMANDS)


Stage = Callable[[DictConfig], Any]


def stage_config(cfg: DictConfig, groups: tuple[str, ...], stage: str) -> DictConfig:
    """`cfg` cut down to `groups` and SHARED, interpolations resolved, struct and read-only."""
    if missing := [g for g in groups if g not in cfg]:
        raise KeyError(f"stage {stage} declares config groups that do not exist: {', '.join(missing)}")
    kept = {
        key: OmegaConf.to_container(cfg[key], resolve=True) if isinstance(cfg[key], DictConfig) else cfg[key]
        for key in (*groups, *SHARED)
        if key in cfg
    }
    out = OmegaConf.create(kept)
    OmegaConf.set_struct(out, True)
    OmegaConf.set_readonly(out, True)
    return out


def reads(*groups: str, writes: Callable[[DictConfig], Outputs] | None = None) -> Callable[[Stage], Stage]:
    """Declare the config groups a stage reads: the decorated function sees only those (and SHARED).
    `writes` gives, from that config, the outputs the run writes and every input it reads: they are
    checked against the output rule (utils.outputs) and locked for the run, before any work."""

    # Only a training stage (one that reads `trainer`) runs as several ranks: the rank variables
    # of a SLURM allocation or a torchrun shell mean nothing to the others.
    trains = "trainer" in groups

    def declare(stage: Stage) -> Stage:
        @functools.wraps(stage)
        def run(cfg: DictConfig) -> Any:
            own = stage_config(cfg, groups, stage.__name__)
            if writes is None:
                return stage(own)
            outputs = writes(own)
            check_outputs(outputs)  # the output rule's refusals first, then where the metrics go
            if (paths := OmegaConf.select(cfg, "paths")) is not None:
                # The pipeline's own folders are where its root puts them (conf/paths: data/, and
                # recordings/ for paths=own), never whatever paths.recordings_dir names: a run of other
                # recordings is a run of other data, whose metrics must not replace the pipeline's.
                pipeline_dirs = (paths.data_dir, os.path.join(paths.root, "recordings"))
                check_metrics_follow(outputs, paths.metrics_dir, pipeline_dirs)
            if trains and not is_global_zero():
                # Another rank of a distributed training run: rank 0 holds the locks and writes the
                # outputs; this one writes nothing, but its outputs obey the same rule (checked above).
                return stage(own)
            with claimed(outputs):
                return stage(own)

        run.reads = groups  # type: ignore[attr-defined]
        run.writes = writes  # type: ignore[attr-defined]
        return run

    return declare


def _stop(signum: int, frame: Any) -> None:
    """On SIGTERM: stop the worker processes, delete unfinished outputs, exit 128 + signal.
    Training keeps its resume checkpoints (they are not unfinished outputs).

    Done here rather than by raising SystemExit, which Python drops when the signal lands while
    the main thread runs a finaliser (seen once in CI: the stage then ran on to the end)."""
    stop_workers()
    remove_unfinished()
    release_locks()
    end_open_runs_killed()
    os._exit(128 + signum)


def stop_cleanly_on_sigterm() -> None:
    """Install _stop for SIGTERM: every stage's command does; so do the project's other commands
    that write outputs (label.inspect). Run by `dvc repro`, the process also stops so when DVC is
    gone (utils.lifetime): no stage outlives the repro."""
    signal.signal(signal.SIGTERM, _stop)
    end_with_dvc()


def objective(result: Any, metric: str | None) -> float | None:
    """What a Hydra sweeper optimises: `metric` of the stage's returned metrics (None when no
    search asks for one)."""
    if metric is None:
        return None
    if not isinstance(result, dict) or result.get(metric) is None:
        found = ", ".join(k for k, v in result.items() if isinstance(v, float)) if isinstance(result, dict) else "none"
        raise ValueError(f"optimized_metric={metric}: this stage returned no such metric (it has: {found})")
    return float(result[metric])


def run_stage(stage: Stage, cfg: DictConfig) -> Any:
    """What a stage's command does with its composed config: check every value against the schemas'
    rules, set the process's threads (`threads`), run, and turn bad input into one line and exit status 2."""
    with clear_errors():
        tracked = "mlflow" in getattr(stage, "reads", ()) and OmegaConf.select(cfg, "mlflow.enabled") is True
        failed = True
        try:
            validate_config(cfg, getattr(stage, "reads", None))
            check_root(cfg)
            set_threads(cfg.threads)
            result = stage(cfg)
            failed = False
            return result
        finally:  # under `dvc repro`: the repro's MLflow parent run ends with its last stage, FAILED when refused too
            if tracked:
                end_pipeline_parent(cfg, failed)


def check_root(cfg: DictConfig) -> None:
    """paths.root names a folder: an empty one (`paths.root=$ROOT` with ROOT unset) would put every output
    into this checkout's data/ and metrics/, over the committed run's. With `paths=own` (your data), the
    root and the folders it implies must lie outside this checkout and any other checkout of the
    project, through links too (the committed runs own what is in them), but for a checkout's own
    pipeline of your data run by DVC (own/dvc.yaml)."""
    root = OmegaConf.select(cfg, "paths.root", throw_on_missing=False)
    if isinstance(root, str) and not root.strip():
        raise InputError("paths.root", "is empty: give a folder of yours (paths.root=DIR; the checkout's own run: paths.root=.)")
    if not isinstance(root, str) or paths_choice() != "own":
        return
    pipeline = os.environ.get("DVC_STAGE", "").partition(":")[0]  # DVC names the stage it runs: own/dvc.yaml:label
    inside = not Path(pipeline).is_absolute() and ".." not in Path(pipeline).parts  # a pipeline of the checkout's own
    for key in ("root", "data_dir", "metrics_dir"):
        folder = Path(cfg.paths[key]).resolve()
        # this checkout, or another checkout of the project the folder lies in (the package may be
        # installed from elsewhere): either's committed runs own what is in it
        checkout = CONF_DIR.parent.resolve()
        if folder != checkout and checkout not in folder.parents and folder not in checkout.parents:
            checkout = next((f for f in (folder, *folder.parents) if is_checkout(f)), checkout)
        if inside and pipeline.endswith("dvc.yaml") and (checkout / pipeline).parent.resolve() == Path(root).resolve():
            continue
        where = "is" if folder == checkout else "is inside" if checkout in folder.parents else "holds" if folder in checkout.parents else ""
        if where:
            this = "this checkout" if checkout == CONF_DIR.parent.resolve() else "a checkout of this project"
            raise InputError(
                f"paths.{key}",
                f"{cfg.paths[key]} resolves to {folder}, which {where} {this} ({checkout}): with paths=own every output "
                "goes to a folder of yours outside the checkout (its committed runs own what is in it)",
            )


def is_checkout(folder: Path) -> bool:
    """A checkout of this project: its pipeline, its config and its code."""
    return (folder / "dvc.yaml").is_file() and (folder / "conf" / "config.yaml").is_file() and (folder / "src" / "offroad_path").is_dir()


def paths_choice() -> str | None:
    """The `paths` config group chosen (default, own), when Hydra composed the config."""
    return HydraConfig.get().runtime.choices.get("paths") if HydraConfig.initialized() else None


def check_search_extra(argv: list[str]) -> None:
    """A search (hparams_search=...) needs the Optuna sweeper, the [search] extra: without it,
    one line that says so and exit 2, instead of Hydra's missing-config error."""
    if not any(a.startswith("hparams_search=") and a != "hparams_search=null" for a in argv):
        return
    try:
        import hydra_plugins.hydra_optuna_sweeper  # noqa: F401
    except ImportError as e:
        with clear_errors():
            raise missing_extra("hparams_search", "search", "hydra-optuna-sweeper") from e


def stage_help(stage: Stage, overrides: list[str]) -> str:
    """What `--help` prints: the stage's docstring, the config groups it reads with their choices,
    and its part of the composed config. Hydra's own help lists every option of every group by
    composing each one (about 6 s with this project's schemas); this reads conf/ instead."""
    from offroad_path.config import load_config

    module = sys.modules.get(stage.__module__)
    groups = getattr(stage, "reads", ())
    lines = [(module.__doc__ or "").strip(), "", "== Config groups it reads (group=option) =="]
    for group in groups:
        options = sorted(p.stem for p in (CONF_DIR / group).glob("*.yaml"))
        lines.append(f"{group}: {', '.join(options)}")
    cfg = load_config(*overrides)
    own = OmegaConf.masked_copy(cfg, [g for g in (*groups, *SHARED) if g in cfg])
    lines += [
        "",
        "== Config (override any value: key=value; --cfg job --resolve prints it resolved) ==",
        OmegaConf.to_yaml(own),
        "Presets: experiment=paper|full|laptop_reference; your own data: paths=own paths.root=DIR. Hydra's help: --hydra-help.",
    ]
    return "\n".join(lines)


def hydra_stage(stage: Stage) -> Callable[[], None]:
    """The Hydra entry point of a stage: the project's config, typed by its schemas, and clear
    errors on bad input."""
    register_configs()

    @hydra.main(config_path=str(CONF_DIR), config_name="config", version_base="1.3")
    def main(cfg: DictConfig) -> float | None:
        # A stop (kill, `dvc` interrupted) deletes the temporary folders of unfinished outputs
        # instead of leaving them beside the outputs.
        stop_cleanly_on_sigterm()
        with clear_errors():
            check_overrides(cfg, HydraConfig.get().overrides.task)
        result = run_stage(stage, cfg)
        with clear_errors():
            return objective(result, cfg.get("optimized_metric"))

    def entry() -> None:
        check_search_extra(sys.argv[1:])
        # Hydra prints its own errors (a mistyped key, a bad override, a search's bad range) over
        # several lines and exits 1; told to raise them instead, they become one line and exit 2.
        os.environ.setdefault("HYDRA_FULL_ERROR", "1")
        try:
            if "--help" in sys.argv[1:] or "-h" in sys.argv[1:]:
                print(stage_help(stage, [a for a in sys.argv[1:] if a not in ("--help", "-h")]))
            else:
                main()
        except (HydraException, OmegaConfBaseException, ValueError) as e:
            print(f"error: {one_line(e, with_cause=True)}", file=sys.stderr)
            raise SystemExit(EXIT_BAD_INPUT) from e

    return entry
