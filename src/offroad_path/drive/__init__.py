"""Stage `drive`: closed-loop driving in the held-out test worlds, the paper's three arguments
against end-to-end steering tested by driving (see offroad_path.drive).

    python -m offroad_path.drive [drive.worlds=2] [drive.length_m=100] [drive.arguments.vehicle='[unet-none,pilotnet]']

Writes drive.out_dir (data/drive): results.md (one table per argument), drive.json,
trajectories/<argument>/<world>.png, videos/<policy>.mp4; drive.metrics_path (metrics/drive.json,
for `dvc metrics show`); an MLflow run.
"""

from __future__ import annotations

import json
import logging
import time
from pathlib import Path

from omegaconf import DictConfig

from offroad_path.config.evaluate_schema import DRIVE_ARGUMENTS
from offroad_path.stage import hydra_stage, reads
from offroad_path.utils.atomic import atomic_directory, write_text_atomic
from offroad_path.utils.outputs import Outputs
from offroad_path.utils.parallel import map_processes
from offroad_path.utils.tracking import flatten, stage_run

log = logging.getLogger("offroad_path.drive")


def outputs(cfg: DictConfig) -> Outputs:
    drive = cfg.drive
    pilotnets = [str(path).replace("{seed}", str(seed)) for path in drive.pilotnets.values() for seed in drive.seeds]
    inputs = [drive.synthetic_dir, drive.runs_dir, *pilotnets]
    return Outputs("drive", folders={"drive.out_dir": drive.out_dir}, files={"drive.metrics_path": drive.metrics_path}, inputs=inputs)


def check_policies(d: DictConfig) -> None:
    """Every argument is known and every policy's checkpoint exists for every seed, before any world is built."""
    from offroad_path.drive.worlds import BUILT_IN, TEMPORAL, checkpoint_of, pilotnet_checkpoint

    if unknown := sorted(set(d.arguments) - set(DRIVE_ARGUMENTS)):
        raise ValueError(f"drive.arguments: unknown argument {unknown[0]!r} (arguments: {', '.join(DRIVE_ARGUMENTS)})")
    for argument, names in d.arguments.items():
        if not names:
            raise ValueError(f"drive.arguments.{argument}: lists no policy (leave the argument out instead)")
        for name in names:
            base = name.removesuffix(TEMPORAL)
            if name != base and (base in BUILT_IN or base in d.pilotnets):
                raise ValueError(f"drive.arguments.{argument}: {name!r}: the temporal filter is for path networks only")
            for seed in d.seeds:
                checkpoint = checkpoint_of(name, d, seed)
                if checkpoint is not None and not checkpoint.is_file():
                    known = ", ".join([*d.pilotnets, *BUILT_IN])
                    raise FileNotFoundError(
                        f"drive.arguments.{argument}: policy {name!r} needs {checkpoint}, which does not exist (seed {seed} of "
                        f"drive.seeds; policies: a run name of the train stage, that name{TEMPORAL}, or {known})"
                    )
                if base in d.pilotnets:
                    pilotnet_checkpoint(checkpoint)  # a path network's checkpoint given as PilotNet: refused here, not after work


@reads("drive", "world", "render", "postprocess", "label", "evaluate", "mlflow", writes=outputs)
def run_drive(cfg: DictConfig) -> dict:
    # The networks and the renderer (torch among them) once the config and outputs are checked.
    from offroad_path.drive.interventions import check_arguments_primaries, report
    from offroad_path.drive.loop import DriveLog
    from offroad_path.drive.worlds import WorldJob, check_worlds, drive_params, drive_world, test_worlds

    drive = cfg.drive
    check_policies(drive)
    for name in check_arguments_primaries(cfg.evaluate.conclusions, drive):
        log.warning("primary %s: this drive does not drive its policies: not measured", name)
    worlds = test_worlds(Path(drive.synthetic_dir), drive.worlds)
    check_worlds(worlds, cfg.world, drive)
    if len(worlds) * drive.starts_per_world < 2:
        raise ValueError(
            f"drive.starts_per_world: {len(worlds)} test world(s) x {drive.starts_per_world} start(s) is one drive; "
            "intervals need at least 2 (more starts, or more test worlds)"
        )
    params = drive_params(cfg.postprocess, drive.width, cfg.world.width)
    started = time.perf_counter()
    with atomic_directory(drive.out_dir, "drive", key="drive.out_dir") as tmp:
        jobs = [
            WorldJob(
                w,
                cfg.world,
                drive,
                tuple(drive.seeds),
                params,
                cfg.label.disparity,
                str(tmp),
                i == 0 and drive.video,
                cfg.render,
                drive.device,
            )
            for i, w in enumerate(worlds)
        ]
        results = map_processes(drive_world, jobs, drive.workers, [f"test world {w.folder}" for w in worlds], "drive")
        logs: dict[str, dict[str, list[DriveLog]]] = {argument: {} for argument in drive.arguments}
        for per_world in results:
            for argument, g in per_world:
                logs[argument].setdefault(g.policy, []).append(g)
        markdown, metrics = report(logs, drive, [w.name for w in worlds], cfg.evaluate.conclusions)
        (tmp / "results.md").write_text(markdown)
        (tmp / "drive.json").write_text(json.dumps(metrics, indent=2) + "\n")
    write_text_atomic(drive.metrics_path, json.dumps(metrics, indent=2) + "\n", "drive")
    log.info(
        "drove %d test worlds in %.0f s; %s",
        len(worlds),
        time.perf_counter() - started,
        "; ".join(f"{a}: {m['finding']}" for a, m in metrics.items() if a in DRIVE_ARGUMENTS),
    )
    log_to_mlflow(cfg, metrics)
    return metrics


def log_to_mlflow(cfg: DictConfig, metrics: dict) -> None:
    with stage_run(cfg, "drive") as run:
        if run is None:
            return
        import mlflow

        logged = flatten({a: m for a, m in metrics.items() if a in (*DRIVE_ARGUMENTS, "primaries")})
        numbers = {k: v for k, v in logged.items() if isinstance(v, int | float)}
        mlflow.log_metrics({k.replace("+", "_"): v for k, v in numbers.items() if v == v})  # NaN is not a metric
        mlflow.log_artifacts(cfg.drive.out_dir)


main = hydra_stage(run_drive)
