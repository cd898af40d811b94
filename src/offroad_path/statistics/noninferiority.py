"""The rule for changes that alter results: non-inferiority over training seeds (benchmarks/seed_spread.py
--compare). Per path network, a candidate preset is admissible when the one-sided 95 % lower bound
(Student's t over the seeds) of the paired (by seed) difference in pooled test IoU, candidate minus
reference, is above -margin, and no seed collapses (every seed's IoU above the mean-path prior's);
for PilotNet, when the upper bound of the paired difference in mean absolute error is below
+mae_margin and every seed is below always-straight-ahead's error. Both on the test frames both
files scored. A file: {"overrides", "labels", "prior": per-image counts, "models": {model: PER_SEED lists}}.
"""

from __future__ import annotations

import math
import statistics

import numpy as np
from scipy import stats

from offroad_path.statistics.scores import Scores

PER_SEED = ("seeds", "score", "epochs", "seconds", "counts")  # a network's lists in a file, one entry per seed


def iou(per_image: dict[str, list[int]], keys: list[str]) -> float:
    """Pooled IoU of the images `keys` (per-image counts tp, fp, tn, fn by frame key)."""
    return Scores.of(np.array([per_image[k] for k in keys]).sum(axis=0)).iou


def mae(errors: dict[str, float], keys: list[str]) -> float:
    """Mean absolute error over the frames `keys`."""
    return float(np.mean([errors[k] for k in keys]))


def merge(files: list[dict]) -> dict:
    """One file of the same preset and yardstick from several that hold other seeds, seeds in order."""
    first = files[0]
    if any((f["overrides"], f["labels"]) != (first["overrides"], first["labels"]) for f in files):
        raise ValueError("the files were made with other overrides or labels")
    models: dict[str, dict] = {}
    for f in files:
        for model, row in f["models"].items():
            into = models.setdefault(model, {key: [] for key in PER_SEED})
            for key in PER_SEED:
                into[key] += row[key]
            if "straight" in row:
                into["straight"] = row["straight"]
    for model, row in models.items():
        if len(set(row["seeds"])) != len(row["seeds"]):
            raise ValueError(f"{model} has seed {row['seeds']} twice")
        order = np.argsort(row["seeds"])
        for key in PER_SEED:
            row[key] = [row[key][i] for i in order]
    return {**first, "models": models}


def one_sided(diffs: list[float], sign: int) -> tuple[float, float, float, float]:
    """Mean, sample sd, standard error and the one-sided 95 % bound (lower for sign +1, upper for -1) of paired differences."""
    n, mean_d = len(diffs), statistics.mean(diffs)
    sd = statistics.stdev(diffs) if n > 1 else math.nan
    se = sd / math.sqrt(n)
    return mean_d, sd, se, mean_d - sign * float(stats.t.ppf(0.95, n - 1)) * se


def compare(reference: dict, candidate: dict, margin: float = 0.02, mae_margin: float = 0.01) -> bool:
    """Print the rule's table per network, on the test frames both files scored; True when every network is admissible."""
    for model, ref in reference["models"].items():
        new = candidate["models"].get(model)
        if new is None or new["seeds"] != ref["seeds"]:
            raise ValueError(f"{model} was not run with the same seeds in both files")
    paths = [m for m in reference["models"] if m != "pilotnet"]
    runs = [c for file in (reference, candidate) for model in paths for c in file["models"][model]["counts"]]
    keys = sorted(set.intersection(*(set(c) for c in [*runs, candidate["prior"]])))
    print(f"reference: {' '.join(reference['overrides']) or '(none)'}\ncandidate: {' '.join(candidate['overrides']) or '(none)'}")
    print(f"scored against: {candidate['labels']}; {len(keys)} test images both scored "
          f"(reference {len(reference['prior'])}, candidate {len(candidate['prior'])})")  # fmt: skip
    prior = iou(candidate["prior"], keys)
    print(f"mean-path prior: {prior:.4f}; margin {margin} IoU (PilotNet: {mae_margin} MAE)\n")
    print("| network | reference mean | candidate mean | paired differences (seeds in order) | mean ± sd | standard error | "
          "one-sided 95 % bound | worst seed | admissible |\n| --- | --- | --- | --- | --- | --- | --- | --- | --- |")  # fmt: skip
    admissible_all = True
    for model in reference["models"]:
        ref, new = reference["models"][model], candidate["models"][model]
        if model == "pilotnet":
            frames = sorted(set.intersection(*(set(c) for c in [*ref["counts"], *new["counts"]])))
            old_score, new_score = ([mae(c, frames) for c in row["counts"]] for row in (ref, new))
            mean_d, sd, se, bound = one_sided([b - a for a, b in zip(old_score, new_score, strict=True)], -1)
            worst, floor = max(new_score), mae(new["straight"], frames)
            ok = bound < mae_margin and worst < floor
            label, worst_text = f"pilotnet (MAE, {len(frames)} frames; straight ahead {floor:.4f})", f"{worst:.4f}"
        else:
            old_score, new_score = ([iou(c, keys) for c in row["counts"]] for row in (ref, new))
            mean_d, sd, se, bound = one_sided([b - a for a, b in zip(old_score, new_score, strict=True)], +1)
            worst = min(new_score)
            ok = bound > -margin and worst > prior
            label, worst_text = model, f"{worst:.4f}"
        admissible_all &= ok
        diffs = [b - a for a, b in zip(old_score, new_score, strict=True)]
        print(f"| {label} | {statistics.mean(old_score):.4f} | {statistics.mean(new_score):.4f} | "
              f"{', '.join(f'{d:+.3f}' for d in diffs)} | {mean_d:+.4f} ± {sd:.4f} | {se:.4f} | "
              f"{bound:+.4f} | {worst_text} | {'yes' if ok else 'no'} |")  # fmt: skip
    return admissible_all
