"""Stage `evaluate`: every run with and without post-processing, scored the paper's way, beside
the baselines a model must beat (see offroad_path.evaluate and docs/design.md).

    python -m offroad_path.evaluate [evaluate.runs='[unet-none,unet-segmentation]'] [evaluate.threshold=0.4]

Writes evaluate.out_dir (data/evaluation): results.md (Table 5.1 layout and the baselines),
results.csv, figures/good_and_bad_cases.png (Fig. 8), figures/postprocessing.png (Fig. 5);
evaluate.metrics_path (metrics/evaluation.json, for `dvc metrics show`); evaluate.plots_dir (one
precision-recall CSV per run, for `dvc plots show`); one MLflow run linking the training runs.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import TYPE_CHECKING

from omegaconf import DictConfig

from offroad_path.data.labels import label_run_folders
from offroad_path.data.manifest import manifest_folders
from offroad_path.errors import InputError
from offroad_path.report.tables import split_run_name
from offroad_path.stage import hydra_stage, reads
from offroad_path.utils.outputs import Outputs
from offroad_path.utils.progress import Progress
from offroad_path.utils.tracking import stage_run, tracking_uri

if TYPE_CHECKING:
    from offroad_path.evaluate.scored_set import Section
    from offroad_path.statistics.scores import Record

log = logging.getLogger("offroad_path.evaluate")


def outputs(cfg: DictConfig) -> Outputs:
    """The evaluate stage's outputs and every input: the runs, their post-processed maps, the label
    runs, the split and the recordings behind it, PilotNet's predictions."""
    evaluate_cfg = cfg.evaluate
    inputs = [
        evaluate_cfg.runs_dir,
        evaluate_cfg.postprocessed_dir,
        evaluate_cfg.labels_dir,
        Path(evaluate_cfg.train_manifest).parent,
        *manifest_folders(evaluate_cfg.train_manifest),
        *(
            pilotnet.replace("{seed}", str(seed))
            for seed in evaluate_cfg.seeds
            if (pilotnet := evaluate_cfg.steering_from_paths.pilotnet_predictions)
        ),
        *(label_run_folders(evaluate_cfg.real_labels_dir) if evaluate_cfg.real_labels_dir else []),
    ]
    folders = {"evaluate.out_dir": evaluate_cfg.out_dir, "evaluate.plots_dir": evaluate_cfg.plots_dir}
    return Outputs("evaluate", folders=folders, files={"evaluate.metrics_path": evaluate_cfg.metrics_path}, inputs=inputs)


@reads("evaluate", "label", "split", "mlflow", writes=outputs)
def evaluate(cfg: DictConfig) -> list[Record]:
    # The work's modules (torch among them) once the config and outputs are checked: a refusal is fast.
    from offroad_path.evaluate.scored_set import TestSet, write_report
    from offroad_path.evaluate.sections import (
        Baselines,
        ByCondition,
        PrimaryQuestions,
        RealFootage,
        ResultsTable,
        SteeringFromPaths,
        Temporal,
    )
    from offroad_path.evaluate.stress import StressSets
    from offroad_path.evaluate.uncertainty import Uncertainty, test_bootstrap

    evaluate_cfg = cfg.evaluate
    check_primaries(evaluate_cfg)
    every = TestSet.read(evaluate_cfg)
    test = every.subset(every.main)  # the main test set: every figure but the stress sets'
    stress = StressSets(lambda samples: test_bootstrap(evaluate_cfg, samples, cfg.split.block_m))
    stress.score(every)
    del every  # the stress sets are scored: only the main set's maps stay in memory from here
    bootstrap = test_bootstrap(evaluate_cfg, test.samples, cfg.split.block_m)
    uncertainty, steering = Uncertainty(bootstrap, cfg.split.block_m), SteeringFromPaths(evaluate_cfg, bootstrap)
    results = ResultsTable(uncertainty)
    # The report, section by section, in the order of results.md and metrics.json.
    by_condition = ByCondition(bootstrap)
    sections: list[Section] = [
        results,
        uncertainty,
        Baselines(by_condition),
        steering,
        PrimaryQuestions(evaluate_cfg, uncertainty, steering),
        by_condition,
        stress,
        Temporal(evaluate_cfg, cfg.label, cfg.split.block_m),
        RealFootage(evaluate_cfg, bootstrap, cfg.split.block_m, cfg.label.distance_m),
    ]
    progress = Progress("evaluate", len(sections), "sections")
    for section in sections:
        if section is not stress:
            section.score(test)
        progress.done(type(section).__name__)
    progress.close()
    write_report(evaluate_cfg, test, sections, results.table(), results.figures(test, evaluate_cfg.figure_cases, evaluate_cfg.figure_scale))
    log_to_mlflow(cfg, sections, results.table())
    return results.table()


def check_primaries(e: DictConfig) -> None:
    """Each primary names a comparison that can exist (before any work); one this run does not make
    (evaluate.runs without its runs) is reported as not measured."""
    from offroad_path.config.evaluate_schema import EVERY_SCRATCH_VS_PRIOR, PRIMARY_SECTIONS
    from offroad_path.evaluate.uncertainty import comparisons
    from offroad_path.statistics.primaries import check_declared

    pairs = comparisons(list(e.runs))
    scratch = {EVERY_SCRATCH_VS_PRIOR} if any(key.endswith("_vs_mean_path_prior") for key, *_ in pairs) else set()
    keys = {"uncertainty": {key for key, *_ in pairs} | scratch, "steering_from_paths": {f"{run}_vs_pilotnet" for run in e.runs}}
    for name in check_declared(e.conclusions.primaries, keys, PRIMARY_SECTIONS):
        refuse_unmakeable(name, e.conclusions.primaries[name].compare)
        log.warning("primary %s (%s) is not among this run's comparisons: not measured", name, e.conclusions.primaries[name].compare)


def refuse_unmakeable(name: str, compare: str) -> None:
    """A primary's comparison that no grid of the registered networks and pretrainings makes, in
    either order of evaluate.architectures (a misspelt run or baseline): InputError naming its key,
    instead of a primary not measured."""
    from offroad_path.config.common import PRETRAININGS, model_names
    from offroad_path.config.evaluate_schema import EVERY_SCRATCH_VS_PRIOR
    from offroad_path.evaluate.uncertainty import comparisons

    grid = [f"{model}-{pretraining}" for model in model_names() for pretraining in PRETRAININGS()]
    pairs = comparisons(grid) + comparisons(grid[::-1])  # evaluate.architectures' order sets a pair's
    makeable = {f"uncertainty/{key}" for key, *_ in pairs} | {f"uncertainty/{EVERY_SCRATCH_VS_PRIOR}"}
    makeable |= {f"steering_from_paths/{run}_vs_pilotnet" for run in grid}
    if compare not in makeable:
        raise InputError(
            f"evaluate.conclusions.primaries.{name}.compare",
            f"{compare!r} is a comparison no run makes: <model>-<pretraining> with a model of {', '.join(model_names())} "
            f"and a pretraining of {', '.join(PRETRAININGS())} (the report's metrics keys name the comparisons)",
        )


def training_runs(cfg: DictConfig) -> dict[str, str]:
    """The latest MLflow training run of each evaluated model-pretraining pair."""
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri(cfg.mlflow))
    experiment = client.get_experiment_by_name(cfg.mlflow.experiment)
    found = {}
    for run in cfg.evaluate.runs if experiment else []:
        model, pretraining = split_run_name(run)
        query = f"tags.stage = 'train' and tags.model = '{model}' and tags.pretraining = '{pretraining}'"
        hits = client.search_runs([experiment.experiment_id], query, max_results=1, order_by=["attributes.start_time DESC"])
        if hits:
            found[run] = hits[0].info.run_id
    return found


def flat(metrics: dict, prefix: str = "") -> dict[str, float]:
    """metrics.json's nested numbers as MLflow metric names (a.b.c; list items a.b.0; True as 1; text
    left out)."""
    out: dict[str, float] = {}
    items = metrics.items() if isinstance(metrics, dict) else enumerate(metrics)
    for key, value in items:
        name = f"{prefix}{key}"
        if isinstance(value, dict | list):
            out |= flat(value, f"{name}.")
        elif value is not None and not isinstance(value, str):
            out[name] = float(value)
    return out


def log_to_mlflow(cfg: DictConfig, sections: list[Section], table: list[Record]) -> None:
    with stage_run(cfg, "evaluate") as run:
        if run is None:
            return
        import mlflow

        from offroad_path.evaluate.scored_set import report_metrics

        mlflow.log_metrics(flat(report_metrics(sections)))  # <run>.raw.iou, baselines.mean_path_prior.iou, ...
        linked = training_runs(cfg)
        mlflow.set_tags({f"training_run.{name}": run_id for name, run_id in linked.items()})
        mlflow.log_table({k: [r[k] for r in table] for k in table[0]}, artifact_file="results.json")
        mlflow.log_artifacts(cfg.evaluate.out_dir)
        mlflow.log_artifacts(cfg.evaluate.plots_dir, "precision_recall")
        log.info("MLflow run %s, linked to %d training runs", run.info.run_id, len(linked))


main = hydra_stage(evaluate)
