"""The committed run's results, as the README summarises them and docs/results.md lists them: the
composition of the tables' one renderers (offroad_path.report.rendering),
with the sentences only these pages need (the label run, PilotNet's seeds, the drive's settings).
offroad_path.report.readme splices it into the two pages."""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field

from omegaconf import DictConfig

from offroad_path.config.evaluate_schema import DRIVE_ARGUMENTS, EVERY_SCRATCH_VS_PRIOR
from offroad_path.report.rendering import (
    against_pilotnet_markdown,
    argument_markdown,
    baselines_markdown,
    bootstrap_method,
    comparisons_markdown,
    conditions_markdown,
    fmt,
    primaries_markdown,
    results_table_markdown,
    seed_check_text,
    stress_markdown,
    temporal_markdown,
)
from offroad_path.report.tables import grid
from offroad_path.statistics.bootstrap import Resampling
from offroad_path.statistics.counts import power_sentence
from offroad_path.statistics.seed_check import FAILED_BELOW_MEDIAN
from offroad_path.steering.collapse import COLLAPSE_CORRELATION, COLLAPSE_SPREAD


@dataclass(frozen=True)
class RunMetrics:
    """One run's metrics files (metrics/, or a scaled pipeline's <folder>/metrics/) as the pages read them."""

    evaluation: dict  # evaluation.json
    label: dict  # label.json
    steering: list[dict]  # PilotNet's metrics per training seed (steering/seed<k>.json), the first seed first, each with its "seed"
    variants: dict[str, list[dict]] = field(default_factory=dict)  # the drive's other PilotNets (VARIANT_TITLES' folders), per seed
    drive: dict | None = None  # drive.json, when the run drove
    timing: dict | None = None  # pipeline_time.json


def results_markdown(run: RunMetrics, e: DictConfig, block_m: float, *, full: bool = True, pipeline: str = "") -> str:
    """The results' body (between the markers) from one run's metrics; e: the evaluate config of the run
    that wrote them (its bootstrap, its primaries, its temporal filter); block_m: its split's. full:
    every table (docs/results.md); else the README's summary: Table 5.1, the primaries, the baselines
    and the stress sets. pipeline: a scaled pipeline's folder (gpu: `dvc repro gpu/dvc.yaml` under
    experiment=gpu); empty for the committed laptop run."""
    evaluation, u = run.evaluation, run.evaluation.get("uncertainty", {})
    out = [_provenance(full, pipeline)]
    if full and run.timing:
        out.append(_timing_sentence(run.timing, pipeline))
    out.append(f"{_labels(run.label)} {_test_set(evaluation, e.bootstrap, block_m)}\n")
    out += [
        results_table_markdown(evaluation, heading=""),
        *([seed_check_text(u["failed_seeds"], FAILED_BELOW_MEDIAN) + "\n"] if "failed_seeds" in u else []),
        primaries_markdown(e.conclusions, evaluation.get("primaries", {}) | (run.drive or {}).get("primaries", {})),
    ]
    if "mean_path_prior" in evaluation.get("baselines", {}):
        out += [baselines_markdown(evaluation, heading=""), ""]
    for folder, seeds in {"": run.steering, **run.variants}.items():
        if check := pilotnet_check(seeds, VARIANT_TITLES.get(folder, "")):
            out.append(check)
    out.append(stress_markdown(evaluation.get("stress_sets", {}), heading="Stress sets (exploratory). "))
    if full:
        if table := comparisons_markdown(u, skip=(EVERY_SCRATCH_VS_PRIOR,)):  # the central claim: a primary, above
            out += ["Exploratory comparisons, not corrected for multiplicity (paired: both on the same draws):\n", table]
        out += _steering(evaluation, run.steering)
        if c := evaluation.get("by_condition"):
            out += [conditions_markdown(c, heading=""), ""]
        if t := evaluation.get("temporal"):
            out += [temporal_markdown(t, e.temporal.alpha, heading=""), ""]
        out += _driving(run.drive or {}, e.conclusions)
    return "\n".join(out).rstrip("\n") + "\n"


LABELS = (
    "Labels: {labels} from {sequences} rendered sequences, {segments_dropped} segments dropped; VO drift over 20 m segments "
    "{translation_drift_pct:.2f} % (worst sequence {translation_drift_pct_worst:.2f} %), {rotation_drift_deg_per_m:.4f} deg/m"
)
DISPARITY = (
    "; the rig's disparity offset as the VO estimated it, {vo_disparity_offset_px_mean:+.3f} px on average "
    "(largest {vo_disparity_offset_px_largest:+.3f} px)"
)
TEST_SET = (
    "Test set: {frames} images (frames and their mirrored copies) from {sequences} held-out test sequences, {blocks} blocks "
    "of {block_m:g} m of driving; {seeds} training seed{plural} per network. Intervals: "
)


def _labels(label: dict) -> str:
    """The label stage's sentence (label.json): labels, dropped segments, the VO's drift (and its disparity offset)."""
    return LABELS.format(**label) + (DISPARITY.format(**label) if "vo_disparity_offset_px_mean" in label else "") + "."


def _test_set(evaluation: dict, bootstrap: DictConfig, block_m: float) -> str:
    """The main test set's size and how its intervals are drawn (the one wording of report.rendering.bootstrap_method)."""
    test_set = evaluation.get("uncertainty", {}).get("test_set", {})
    blocks, seeds, worlds = test_set.get("blocks", 0), test_set.get("seeds", 1), test_set.get("worlds", "n/a")
    everything = evaluation.get("by_condition", {}).get("all", {})
    resampling = Resampling(bootstrap.resamples, bootstrap.seed, bootstrap.level)
    sizes = {"frames": everything.get("frames", "n/a"), "sequences": everything.get("sequences", "n/a"), "blocks": blocks}
    return TEST_SET.format(**sizes, block_m=block_m, seeds=seeds, plural="s" if seeds > 1 else "") + bootstrap_method(
        resampling, worlds, blocks, block_m, seeds
    )


HEADLINE = (
    "Every headline figure is the main test set's: held-out worlds drawn as the training drives are; the hard cases are "
    "the stress sets, each scored on its own.\n"
)


def _provenance(full: bool, pipeline: str) -> str:
    if not pipeline:
        return (
            "The committed run: `dvc repro` of the embedded default on a 2-core CPU (`dvc.lock`, `metrics/`; "
            + ("the evaluate stage's own report is `data/evaluation/results.md`" if full else "every other table: `docs/results.md`")
            + "). Generated from `metrics/` (`python -m offroad_path.report.readme`; a test fails when it disagrees with them). "
            + HEADLINE
        )
    return (
        f"The `experiment={pipeline}` run: `dvc repro {pipeline}/dvc.yaml` (`{pipeline}/dvc.lock`, `{pipeline}/metrics/`; the "
        f"evaluate stage's own report is `{pipeline}/data/evaluation/results.md`). Generated from `{pipeline}/metrics/` (`python -m "
        f"offroad_path.report.readme --pipeline {pipeline}`). " + HEADLINE
    )


def _timing_sentence(timing: dict, pipeline: str = "") -> str:
    minutes, seconds = divmod(round(timing["total_s"]), 60)
    if not pipeline:
        sittings = timing.get("sittings", 1)
        resumed = f", in {sittings} sittings whose logs are stitched (the time between them not counted)" if sittings > 1 else ""
        return (
            f"Time: the last `dvc repro` from nothing took {minutes} min {seconds} s on a {timing['machine']}{resumed} "
            f"(`metrics/pipeline_time.json`, written by `python benchmarks/pipeline_time.py --json`, with every stage's seconds).\n"
        )
    # A scaled run's times come from tools/parallel_repro.py: each stage's start and end on the run's clock.
    finished = "from nothing" if timing.get("complete", True) else f"stopped before {', '.join(timing['unfinished'])} finished"
    rows = [[stage, f"{start:.0f}", f"{end - start:.1f}"] for stage, (start, end) in timing.get("spans", {}).items()]
    return (
        f"Time: `dvc repro {pipeline}/dvc.yaml` {finished}, {minutes} min {seconds} s on {timing['machine']}, up to "
        f"{timing.get('jobs', 1)} stages at once (`{pipeline}/metrics/pipeline_time.json`, written by `tools/parallel_repro.py`):\n\n"
        + grid(["stage", "started (s)", "seconds"], rows)
        + "\n"
    )


def _steering(evaluation: dict, steering: list[dict]) -> list[str]:
    s = evaluation.get("steering_from_paths", {})
    if "pilotnet" not in s:
        return []
    first = steering[0] if steering else {}
    errors = [seed["mean_absolute_error"] for seed in steering]
    own = f"{fmt(first.get('mean_absolute_error', float('nan')))}" + (
        f"; over its {len(errors)} training seeds {statistics.mean(errors):.3f} ± {statistics.stdev(errors):.3f}, mean ± sd"
        if len(errors) > 1
        else ""
    )
    lines = [
        "Steering on the same test frames (mean absolute error of the normalised angle, each network's and PilotNet's pooled over "
        f"their training seeds): always straight ahead {s['straight_ahead']['mae']:.3f}, PilotNet {s['pilotnet']['mae']:.3f} "
        f"(on its own test set of {first.get('test_frames', 'n/a')} frames: {own}), the ground-truth label through pure pursuit "
        f"{s['label_ceiling']['mae']:.3f}. Each path network through pure pursuit, and its paired difference from "
        "PilotNet (below 0: closer to the true angle than PilotNet; exploratory unless `open_loop` is among the primaries above):\n",
        against_pilotnet_markdown(s),
    ]
    return lines


# The drive's other PilotNets (train_steering's metrics folders, config.steering_folder), by what they drive in.
VARIANT_TITLES = {
    "steering_slip": "PilotNet trained on slippery ground's steering (the closed loop's traction argument)",
    "steering_curvature": "PilotNet trained on the path's curvature (the closed loop's other-vehicle argument)",
}


def collapsed_seeds(steering: list[dict]) -> list[int]:
    """The PilotNet seeds that predict a near-constant (the train_steering stage's collapse check)."""
    return [seed.get("seed", k) for k, seed in enumerate(steering) if seed.get("collapsed")]


def pilotnet_check(steering: list[dict], name: str = "") -> str:
    """One sentence on every seed of one PilotNet (the stage's collapse check, steering.collapse):
    its error against straight ahead's, the spread and correlation of its predictions, and the flags;
    name: one of the drive's other PilotNets (VARIANT_TITLES), else the open-loop one with the check's rule."""
    if not steering:
        return ""
    rows = []
    for k, seed in enumerate(steering):
        low, high = seed.get("straight_ahead_margin_interval", (float("nan"), float("nan")))
        straight = seed["straight_ahead_mean_absolute_error"]
        spread = seed.get("prediction_spread_ratio")
        agreement = f"; spread {spread:.2f} of the truth's, correlation {seed['correlation_with_truth']:.2f}" if spread is not None else ""
        rows.append(
            f"seed {seed.get('seed', k)} {seed['mean_absolute_error']:.3f} (straight ahead {straight:.3f}; "
            f"margin {seed.get('straight_ahead_margin', float('nan')):+.3f} [{low:+.3f}, {high:+.3f}]{agreement})"
        )
    bad = collapsed_seeds(steering)
    weak = [
        seed.get("seed", k)
        for k, seed in enumerate(steering)
        if not seed.get("beats_straight_ahead", seed["straight_ahead_margin_interval"][0] > 0)
    ]
    verdict = (
        f"seed {', '.join(map(str, bad))} collapsed ({len(bad)} of {len(steering)}: its output hardly moves, or not with the truth), "
        "so what this PilotNet says of end-to-end steering is that weak"
        if bad
        else "no seed collapsed"
    )
    verdict += (
        f"; seed {', '.join(map(str, weak))} does not steer closer to the true angle than straight ahead (the margin's interval reaches 0)"
        if weak
        else "; every seed steers closer to the true angle than straight ahead, the margin's 95 % interval (test worlds resampled) above 0"
    )
    head = (
        f"{name}, the same check" if name
        else "PilotNet, the end-to-end baseline, on its test frames (mean absolute error of the normalised angle per training seed; "
        f"the train_steering stage's collapse check: collapsed when its predictions' spread is below {COLLAPSE_SPREAD:g} of the "
        f"truth's or their correlation with the truth at or below {COLLAPSE_CORRELATION:g})"
    )  # fmt: skip
    return f"{head}: {'; '.join(rows)}. {verdict[0].upper()}{verdict[1:]}.\n"


def _driving(drive: dict, conclusions=None) -> list[str]:
    arguments = [a for a in DRIVE_ARGUMENTS if a in drive]
    if not arguments:
        return []
    d = drive["drives"]
    lines = [
        f"Closed loop in the test worlds (`data/drive/results.md`, whose tables these are): {len(d['worlds'])} worlds x "
        f"{d['starts_per_world']} start(s) x {len(d.get('seeds', [0]))} training seed(s) x {d['length_m']:g} m of route per policy; "
        "intervals are 95 % hierarchical (worlds, starts, seeds)."
    ]
    if not drive.get("primaries"):
        lines[0] += (
            " **A pilot**: no closed-loop argument is a primary of this run (its route is far below what they need; "
            "`experiment=gpu` and `experiment=full` test them), so these counts are exploratory rates that plan the next run, "
            "and no direction they suggest is a finding."
        )
    lines += [argument_markdown(a, drive[a], heading="####") for a in arguments]
    for name, entry in drive.get("primaries", {}).items():
        if sentence := power_sentence(entry, conclusions.power if conclusions is not None else 0.8):
            lines.append(f"- Primary `{name}`: {sentence} (at its planning rates in evaluate.conclusions; Holm's strictest level).")
    return [*lines, ""]
