"""Markdown of the evaluate stage's tables, rendered from its metrics (metrics/evaluation.json's
dicts), one function per table, each built by report.tables.grid: evaluate's results.md, the drive's,
the README's summary and docs/results.md (offroad_path.report.summary) all call these, so one table
has one wording wherever it shows."""

from __future__ import annotations

from math import nan

from offroad_path.config.evaluate_schema import DRIVE_ARGUMENTS, EVERY_SCRATCH_VS_PRIOR, PRIMARY_SECTIONS
from offroad_path.report.tables import (
    PP_KEY,
    TITLES,
    TemporalRow,
    baseline_name,
    baseline_row,
    comparison_title,
    fmt,
    grid,
    markdown_table,
    method_title,
    network_name,
    split_run_name,
    title,
)
from offroad_path.statistics.bootstrap import Interval, Resampling
from offroad_path.statistics.primaries import Verdict, verdicts
from offroad_path.statistics.scores import SCORES

# Holder 2018 (thesis), Table 5.1 (accuracy, IoU): their private data, full-size networks from random weights
# ("none") or pretrained on a semantic segmentation task ("segmentation"); post-processing as ours.
PAPER = {
    ("segnet", "none", "no"): (0.94, 0.75),
    ("segnet", "none", "yes"): (0.95, 0.76),
    ("segnet", "segmentation", "no"): (0.95, 0.76),
    ("fcn", "none", "no"): (0.94, 0.72),
    ("fcn", "none", "yes"): (0.94, 0.72),
    ("fcn", "segmentation", "no"): (0.93, 0.65),
    ("unet", "none", "no"): (0.95, 0.75),
    ("unet", "none", "yes"): (0.95, 0.77),
    ("unet", "segmentation", "no"): (0.93, 0.69),
}


def interval(entry: dict | None, key: str) -> Interval | None:
    """An Interval from a metrics entry (`key`: the estimate's name), None where it has no bounds."""
    return None if entry is None or entry.get("low") is None else Interval(entry[key], entry["low"], entry["high"])


def results_table_markdown(m: dict, heading: str = "\n## Results (Table 5.1 layout)\n\n") -> str:
    """Every run, raw and post-processed, pooled over the test set (the thesis's Table 5.1 beside it);
    with evaluate's `uncertainty`, each IoU's hierarchical interval and, over several seeds, their spread."""
    u = m.get("uncertainty", {})
    runs = [key for key, value in m.items() if isinstance(value, dict) and "raw" in value]
    seeds = u.get("test_set", {}).get("seeds", 1)
    lines = [
        f"{heading}Pooled over the test set, each method's training seeds together: every score (statistics.scores), IoU with "
        "its 95 % hierarchical-bootstrap interval; beside them the thesis's figures (Holder 2018, Table 5.1), which are not "
        "this run's to compare: its private data, and its networks, inputs and training differ from this run's (full-width "
        "networks on 512 x 288 images, trained with SGD for tens of thousands of steps on a GPU, against this run's narrower "
        "networks on smaller inputs for a few hundred steps: `model.width`, `data.width`, `trainer.max_epochs`); its "
        "pretraining rows pretrained on a semantic segmentation task, as ours on the world's 8 classes, its other rows from "
        "random weights.\n",
    ]
    header = [
        "network",
        "pretraining",
        "post-processing",
        *(f"{title(name)} [95 % interval]" if name == "iou" else title(name) for name in SCORES),
        *(["IoU over seeds, mean ± sd"] if seeds > 1 else []),
        "paper: accuracy",
        "paper: IoU",
    ]
    rows = []
    for run in runs:
        model, pretraining = split_run_name(run)
        for pp, key in PP_KEY.items():
            r, entry = m[run][key], u.get(f"{run}.{key}")
            found = interval(entry, "iou")
            cells = [found.text() if name == "iou" and found else fmt(nan if r[name] is None else r[name]) for name in SCORES]
            if seeds > 1:
                cells.append(f"{entry['seed_mean']:.3f} ± {entry['seed_sd']:.3f}" if entry and "seed_mean" in entry else "")
            paper = PAPER.get((model, pretraining, pp), ("", ""))
            rows.append([network_name(model), pretraining, pp, *cells, *map(str, paper)])
    return "\n".join([*lines, grid(header, rows)]) + "\n"


def comparisons_markdown(u: dict, skip: tuple[str, ...] = ()) -> str:
    """The IoU comparisons (a - b, paired on the same draws) from evaluate's `uncertainty` metrics."""
    found = [(key, interval(entry, "iou_difference")) for key, entry in u.items() if "iou_difference" in entry and key not in skip]
    # The intersection-union comparison is a copy of the weakest network's own against the prior: name it.
    central = u.get(EVERY_SCRATCH_VS_PRIOR)
    weakest = next(
        (k.split("_vs_")[0] for k, v in u.items() if k.endswith("_vs_mean_path_prior") and k != EVERY_SCRATCH_VS_PRIOR and v == central), ""
    )
    rows = [[comparison_title(key, weakest), difference.difference_text()] for key, difference in found]
    return grid(["comparison (IoU, a - b)", "difference [95 % interval]"], rows) + "\n" if found else ""


def bootstrap_method(resampling: Resampling, worlds: int | str, blocks: int, block_m: float, seeds: int) -> str:
    """How every interval of the evaluate stage is drawn, in one wording: evaluate's Uncertainty section
    and the results pages (statistics.bootstrap; docs/conclusions.md)."""
    return (
        f"{100 * resampling.level:g} % hierarchical bootstrap ({resampling.count} resamples, seed {resampling.seed}): the "
        f"{worlds} test worlds drawn with replacement, then within each drawn world its blocks of {block_m:g} m of driving "
        f"({blocks} in all), then the {seeds} training seed(s); every compared method is scored on the same draw (paired), "
        "each method's counts pooled over its seeds. Each interval is widened for the worlds and seeds it rests on (each "
        "level's small-sample bias and Student's t with their Welch-Satterthwaite degrees of freedom, docs/conclusions.md): "
        "where the seeds' spread is large, two seeds give a wide interval. The intervals cover which test worlds and "
        "stretches of driving were tested, not other worlds' looks (every test world is drawn from the same generator); "
        "which seeds trained the networks only in part, since a few seeds show little of the seed-to-seed spread, and a "
        "rerun on another kind of CPU trains other bytes: a primary's smallest "
        "effect of interest lies above how far a rerun moved it."
    )


def seed_check_text(failed: dict[str, list[int]], margin: float) -> str:
    """The seed check's sentence (evaluate.seed_check; `failed`: network -> its failed seeds, raw maps)."""
    rule = f"more than {margin:g} IoU below the median of its network's seeds"
    if not failed:
        return f"Seed check: no seed of any network lies {rule}."
    named = "; ".join(f"{method_title(run)}: seed {', '.join(map(str, seeds))}" for run, seeds in failed.items())
    return f"**Seed check: failed trainings** (a seed {rule}, raw maps): {named}."


def against_pilotnet_markdown(s: dict) -> str:
    """Each path network through pure pursuit against PilotNet (evaluate's `steering_from_paths` metrics):
    its MAE and the paired difference, both pooled over the seeds."""
    rows = []
    for key, row in s.items():
        if key.endswith("_vs_pilotnet") or key in ("straight_ahead", "pilotnet", "label_ceiling"):
            continue
        difference = interval(s.get(f"{key}_vs_pilotnet"), "mae_difference")
        rows.append([f"{method_title(key)} + pure pursuit", f"{row['mae']:.3f}", difference.difference_text() if difference else "n/a"])
    return grid(["method", "MAE", "minus PilotNet [95 % interval]"], rows) + "\n"


PRIMARIES_HEADER = ["primary", "claim", "a vs b", "estimate [Holm-corrected interval]", "p", "verdict"]


def primaries_markdown(conclusions, measured: dict[str, dict]) -> str:
    """The family of primaries (evaluate.conclusions) with Holm's verdicts, from the entries each stage
    recorded (`primaries` of evaluate's and the drive's metrics): each interval at the level Holm's step
    gives it. The README's: a direction only where Holm rejects no difference (Verdict.direction)."""
    if conclusions is None or not conclusions.primaries:
        return ""
    found = verdicts(conclusions.primaries, measured, conclusions.alpha)
    lines = [
        f"Primary questions, pre-registered in the design (`conf/evaluate/design/`) before its main test set was first scored: "
        f"{len(found)} in one family, Holm's "
        f"correction at family-wise {conclusions.alpha:g} (evaluate's by the hierarchical bootstrap's p-value, the drive's "
        "by the exact test of their interventions); each interval is at the level Holm's step gives it, and a verdict states a "
        "direction only when Holm rejects no difference and the interval does not lie wholly within the primary's smallest effect "
        "of interest (`smallest_effect`); an interval within it reads no material difference. Every other comparison below is "
        "exploratory.\n",
        grid(PRIMARIES_HEADER, [_primary_row(v, measured.get(v.name, {})) for v in found]),
    ]
    # a preset that adds a left-out question back to its family (experiment=gpu) asks it there
    if left_out := {name: why for name, why in (conclusions.get("left_out") or {}).items() if name not in conclusions.primaries}:
        lines.append("\nLeft out of the family, as the design cannot power them (exploratory here): "
                     + "; ".join(f"{name}: {why}" for name, why in left_out.items()) + ".\n")  # fmt: skip
    return "\n".join(lines) + "\n"


def _primary_row(v: Verdict, entry: dict) -> list[str]:
    section, _, key = v.compare.partition("/")
    a, _, b = key.replace("_postprocessed_vs_raw", "-postprocessed_vs_raw").partition("_vs_")
    if entry.get("weakest"):  # the intersection-union test rests on its weakest member
        a = f"{a} (weakest: {entry['weakest']})"
    if v.interval is None:
        return [v.name, v.claim, f"{a} vs {b}", "not measured", "", "not measured"]
    i = v.interval
    if v.null == 1.0:  # a rate ratio, a over b
        shown = f"ratio {i.estimate:.2f} [{i.low:.2f}, {i.high:.2f}]"
        counts = entry.get("interventions")
        shown += f" ({counts[0]} and {counts[1]} interventions)" if counts else ""
    else:
        shown = f"{i.estimate:+.3f} [{i.low:+.3f}, {i.high:+.3f}]"
    quantity = PRIMARY_SECTIONS[section]
    if v.negligible:
        verdict = f"no material difference (within ±{v.smallest_effect:g})"
    else:
        verdict = f"{a}'s {quantity} {v.direction}" if v.direction else "no difference measured"
    p = f"{v.p_value:.4f}" if v.p_value >= 1e-4 else "< 0.0001"
    return [v.name, v.claim, f"{a} vs {b}", f"{shown} at {100 * v.level:.2f} %", p, verdict]


def baselines_markdown(m: dict, heading: str = "\n## Baselines\n\n") -> str:
    """The baselines from the report's metrics ("baselines", and "by_condition"'s main-set row for each
    network minus the prior): results.md's section and the README's, in one wording."""
    b = m["baselines"]
    others = [v["iou"] for k, v in b.items() if k.startswith("non_corresponding.") and v.get("iou") is not None]
    spread = f" score IoU {min(others):.3f} to {max(others):.3f}" if others else " cannot be scored"
    colour = b.get("colour_classifier")
    colour_text = (
        f" A per-pixel classifier on colour and image position alone (gradient-boosted trees on RGB, HSV, row and column, "
        f"trained on the training split) scores accuracy {colour['accuracy']:.3f} and IoU {colour['iou']:.3f}: what a network "
        "scores above it needs context, the track's shape and where it leads."
        if colour and colour.get("iou") is not None
        else ""
    )
    everything = m.get("by_condition", {}).get("all", {})
    margins = [(key.removesuffix(".minus_prior"), value) for key, value in everything.items() if key.endswith(".minus_prior")]
    margin_text = (
        " Each network minus the prior on the main test set (raw maps, seeds pooled, paired hierarchical interval): "
        + "; ".join(f"{method_title(run)} {Interval(*g).difference_text()}" for run, g in margins if run != "colour_classifier")
        + "."
        if margins
        else ""
    )
    prior = b["mean_path_prior"]
    rows = [baseline_row(baseline_name(key), v) for key, v in b.items()]
    return (
        f"{heading}What a model must beat, on the same test set: the mean path prior (the average training label, thresholded, "
        f"on every image) scores accuracy {prior['accuracy']:.3f} and IoU {prior['iou']:.3f}; each network's outputs against "
        f"every *other* test frame's ground truth (the paper's non-corresponding baseline; paper: accuracy 0.84, IoU 0.41)"
        f"{spread}.{colour_text}{margin_text}\n\n" + markdown_table(rows)
    )


def conditions_markdown(c: dict[str, dict], heading: str = "\n## Results by condition\n\n") -> str:
    """IoU by condition from its metrics (condition -> frames, sequences, each method's IoU, interval and
    margin over the prior), and the off-track group against the prior: results.md's and docs/results.md's."""
    methods = [k for k in next(iter(c.values())) if k not in ("frames", "sequences") and "." not in k]
    lines = [
        f"{heading}Pooled IoU (raw maps) over the test frames of each group, from what the world knows about the next 20 m "
        "of driving (conditions.csv of each sequence); a frame can be in several groups. The mean path prior shows how hard "
        "a group is for a network that ignores the image. Each figure pools the method's training seeds, with its 95 % "
        "hierarchical-bootstrap interval (the test worlds that hold the group's frames, their blocks, the seeds), and the "
        "number of test sequences they come from; a group within one or two sequences says little, and an interval marked † "
        "rests on one world: it resamples that world's blocks alone, without the widening for few worlds and without any "
        "spread between worlds. Exploratory: no correction for multiplicity.\n",
    ]
    header = ["condition", "test images", "test sequences", *(title(m) if m in TITLES else method_title(m) for m in methods)]
    rows = [[title(key), row["frames"], row.get("sequences", ""), *(_condition_cell(row, m) for m in methods)] for key, row in c.items()]
    return "\n".join([*lines, grid(header, rows)]) + "\n" + _against_prior(c.get("off_track", {}), title("off_track"))


def _condition_cell(row: dict, method: str) -> str:
    """A method's IoU in one group, with its interval where the group's blocks allow one; an interval
    whose frames lie in one world resamples that world's blocks alone, unwidened, and says so (†)."""
    iou = fmt(row[method]) if row.get(method) is not None else "n/a"
    if f"{method}.interval" not in row:
        return iou
    one_world = "†" if row.get("sequences") == 1 else ""
    return iou + " [{:.3f}, {:.3f}]{}".format(*row[f"{method}.interval"], one_world)


def _against_prior(row: dict, title: str) -> str:
    """One group's networks against the mean path prior, paired (exploratory): a direction only where the interval excludes 0."""
    margins = {key.removesuffix(".minus_prior"): g for key, g in row.items() if key.endswith(".minus_prior")}
    gaps = {run: g for run, g in margins.items() if run != "colour_classifier"}  # the networks
    if not gaps or row.get("mean_path_prior") is None:
        return ""
    below = [run for run, (_, _, high) in gaps.items() if high < 0]
    above = [run for run, (_, low, _) in gaps.items() if low > 0]
    same = len(gaps) - len(below) - len(above)
    ious = [row[run] for run in gaps]
    verdict = f"{len(below)} of {len(gaps)} networks score below it and {len(above)} above it (paired intervals excluding 0)" + (
        f"; no difference measured for {same}" if same else ""
    )
    spread = ", ".join(f"{method_title(run)} {g[0]:+.3f} [{g[1]:+.3f}, {g[2]:+.3f}]" for run, g in gaps.items())
    return (
        f"\nExploratory: {title}, {row['frames']} test images from {row.get('sequences', 'n/a')} sequences. The networks score "
        f"IoU {min(ious):.3f} to {max(ious):.3f} against the mean path prior's {row['mean_path_prior']:.3f}; {verdict}. Network "
        f"minus prior: {spread}.\n"
    )


def temporal_markdown(t: dict[str, dict], alpha: float, heading: str = "\n## Temporal consistency\n\n") -> str:
    """The temporal section from its metrics (run -> TemporalRow's numbers): results.md's and docs/results.md's."""
    rows = [TemporalRow(method=method_title(run), **entry) for run, entry in t.items()]
    gains = {run: row["iou_filtered"] - row["iou"] for run, row in t.items()}
    lower = [run for run, row in t.items() if row.get("gain_high") is not None and row["gain_high"] < 0]
    higher = [run for run, row in t.items() if row.get("gain_low") is not None and row["gain_low"] > 0]
    return (
        f"{heading}Every frame from the first to the last test frame of each block of driving, labelled exactly from the "
        "world's true poses and depth (so IoU here is not the table's, which scores VO labels). Filtered: the previous fused "
        "confidence carried into each frame by the VO pose and stereo depth, then averaged with the current prediction "
        f"(weight {alpha:g} on the current). Stability: the mean IoU of each thresholded path with the previous one carried "
        "into its frame by the true pose and depth. The filter's gain: a paired 95 % block-bootstrap interval of filtered "
        "minus raw IoU (0 inside: no difference measured).\n\n"
        + markdown_table(rows)
        + f"\nThe temporal filter (exploratory) changes IoU by {min(gains.values()):+.3f} to {max(gains.values()):+.3f}: lower "
        f"for {len(lower)} and higher for {len(higher)} of {len(gains)} networks by intervals excluding 0 (the first training "
        "seed of each).\n"
    )


MIN_WORLDS = 4  # a set scored on fewer worlds (those whose test frames show its case) is an example: no interval
STRESS_INTRO = (
    "Each hard case is a set of test worlds drawn to show it, scored on its frames that show it and never pooled into "
    "the main test set's figures: the mean-path prior's IoU, then each network's IoU (raw maps, its seeds pooled) and its "
    "margin over the prior with a 95 % paired interval from the hierarchical bootstrap of the set's own worlds, blocks and "
    "seeds (few worlds: wide intervals). An interval that holds 0: no difference measured. A set whose case shows in fewer "
    f"than {MIN_WORLDS} of its worlds' test frames is an example: its IoUs alone, without a margin or interval."
)


def stress_markdown(found: dict, heading: str = "\n## Stress sets\n\n") -> str:
    """The section from its metrics (metrics.json's "stress_sets"): the report and the README render the same table."""
    if not found:
        return ""
    runs = [key for key, value in next(iter(found.values())).items() if isinstance(value, dict)]
    header = ["stress set", "worlds", "test images", "mean-path prior", *(method_title(r) for r in runs)]
    rows = []
    for name, row in found.items():
        cells = [_stress_cell(row[r]) if row["worlds"] >= MIN_WORLDS else f"{row[r]['iou']:.3f}" for r in runs]
        rows.append([title(name), row["worlds"], row["frames"], f"{row['mean_path_prior']:.3f}", *cells])
    return heading + STRESS_INTRO + "\n\n" + grid(header, rows) + "\n"


def _stress_cell(entry: dict) -> str:
    if "minus_prior" not in entry:
        return f"{entry['iou']:.3f}"
    return f"{entry['iou']:.3f}, {Interval(entry['minus_prior'], entry['low'], entry['high']).difference_text()}"


def _interval_of(entry: dict) -> Interval:
    return Interval(entry["value"], entry["low"], entry["high"])


def drive_table(policies: dict[str, dict]) -> str:
    """A markdown table, one row per policy, from each policy's metrics (PolicyScore.as_dict)."""
    header = ["policy", "driven (m)", "interventions", "per km of route [95 % CI]", "autonomy % [95 % CI]", "mean offset (m) [95 % CI]",
              "95th pct offset (m) [95 % CI]", "water entries per km", "steps without a path"]  # fmt: skip
    rows = [
        [
            name,
            f"{p['distance_m']:.0f}",
            p["interventions"],
            _interval_of(p["interventions_per_km"]).text(1),
            _interval_of(p["autonomy_pct"]).text(1),
            _interval_of(p["mean_offset_m"]).text(2),
            _interval_of(p["p95_offset_m"]).text(2),
            f"{p['water_entries_per_km']:.1f}",
            p["no_path_steps"],
        ]
        for name, p in policies.items()
    ]
    return grid(header, rows)


def comparison_table(differences: dict[str, dict]) -> str:
    """Path minus end to end per pair ("a - b" -> value, low, high, exact_p: the metrics' path_minus_end_to_end),
    with the exact test of the pooled counts beside the hierarchical interval."""
    rows = [[*pair.split(" - ", 1), _interval_of(i).difference_text(2), f"{i['exact_p']:.4f}" if "exact_p" in i else ""]
            for pair, i in differences.items()]  # fmt: skip
    return grid(["path policy", "end to end", "interventions per km, path - end to end [95 % CI]", "exact test p"], rows)


def argument_markdown(argument: str, entry: dict, heading: str = "##") -> str:
    """One argument's section from its metrics (drive.json's entry): the drive stage's results.md and
    docs/results.md render it with this, and only this."""
    return (
        f"\n{heading} {DRIVE_ARGUMENTS[argument]}\n\n{drive_table(entry['policies'])}\n\n{comparison_table(entry['path_minus_end_to_end'])}"
        f"\n\nExploratory: {entry['finding']}\n"
    )
