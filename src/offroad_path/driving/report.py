"""Scores of closed-loop drives, with block-bootstrap intervals across drives (a world and a start
point each, the unit resampled: offroad_path.evaluation.bootstrap), and the report's tables.

Per policy: interventions per km of route (progress along the reference drive, the same for every
policy that finishes its drives, so that a paired difference is one of counts alone); autonomy,
1 - interventions x intervention_s / elapsed time (Bojarski et al. 2016; below 0 when interventions
come faster than one per intervention_s); the mean and 95th-percentile lateral offset from the
nearest centre line; water entries per km. Each path policy is compared with each end-to-end one on
the same drives, paired: the interval of the difference in interventions per km.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offroad_path.driving.loop import DriveLog
from offroad_path.evaluation.bootstrap import Interval, Resampling, paired_interval

ARGUMENTS = {
    "steering": "(a) closed loop: does predicting the path drive better than predicting the steering?",
    "vehicle": "(b) another vehicle: the same networks on a vehicle with 1.5 x the wheelbase, another lock and a higher camera",
    "traction": "(c) traction: the same networks on ground where the vehicle turns less than the bicycle model says (world.slip)",
}


def _per_km(s: np.ndarray) -> np.ndarray:  # (..., k) sums with interventions at 0, metres of route at 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(s[..., 1] > 0, 1000.0 * s[..., 0] / np.where(s[..., 1] > 0, s[..., 1], 1), np.nan)


def sums(logs: list[DriveLog]) -> np.ndarray:
    """(drives, 5): interventions, metres of route, seconds, summed offsets, steps; one row per drive."""
    return np.array([[len(g.interventions), g.progress_m, g.elapsed_s, sum(g.offsets), g.steps] for g in logs], float)


@dataclass(frozen=True)
class PolicyScore:
    policy: str
    drives: int
    route_m: float  # progress along the reference drives
    distance_m: float  # driven
    interventions: int
    per_km: Interval
    autonomy_pct: Interval
    mean_offset_m: Interval
    p95_offset_m: Interval
    water_per_km: float
    no_path_steps: int
    by_cause: dict[str, int]

    def as_dict(self) -> dict:
        def iv(i: Interval) -> dict:
            return {"value": i.estimate, "low": i.low, "high": i.high}

        return {
            "drives": self.drives,
            "route_m": self.route_m,
            "distance_m": self.distance_m,
            "interventions": self.interventions,
            "interventions_per_km": iv(self.per_km),
            "autonomy_pct": iv(self.autonomy_pct),
            "mean_offset_m": iv(self.mean_offset_m),
            "p95_offset_m": iv(self.p95_offset_m),
            "water_entries_per_km": self.water_per_km,
            "no_path_steps": self.no_path_steps,
            "interventions_by_cause": self.by_cause,
        }


def score(logs: list[DriveLog], intervention_s: float, resampling: Resampling) -> PolicyScore:
    """One policy's drives (one per world and start, in a fixed order) scored with intervals."""
    s = sums(logs)
    index = resampling.indices(len(logs))  # (count, drives)
    drawn = s[index].sum(axis=1)  # (count, 5)

    def ratio(fn) -> Interval:
        return Interval(float(fn(s.sum(axis=0))), *resampling.percentiles(fn(drawn)))

    offsets = [np.asarray(g.offsets) for g in logs]
    p95 = np.array([np.percentile(np.concatenate([offsets[i] for i in row]), 95) for row in index])
    causes = [why for g in logs for _, _, why in g.interventions]
    return PolicyScore(
        policy=logs[0].policy,
        drives=len(logs),
        route_m=float(s[:, 1].sum()),
        distance_m=sum(g.distance_m for g in logs),
        interventions=int(s[:, 0].sum()),
        per_km=ratio(_per_km),
        autonomy_pct=ratio(lambda c: 100.0 * (1.0 - c[..., 0] * intervention_s / c[..., 2])),
        mean_offset_m=ratio(lambda c: c[..., 3] / c[..., 4]),
        p95_offset_m=Interval(float(np.percentile(np.concatenate(offsets), 95)), *resampling.percentiles(p95)),
        water_per_km=1000.0 * sum(g.water_entries for g in logs) / max(float(s[:, 1].sum()), 1e-9),  # per km of route
        no_path_steps=sum(g.no_path for g in logs),
        by_cause={why: causes.count(why) for why in sorted(set(causes))},
    )


def versus_end_to_end(logs: dict[str, list[DriveLog]], end_to_end: list[str], resampling: Resampling) -> dict[tuple[str, str], Interval]:
    """{(path policy, PilotNet policy): path's interventions per km minus PilotNet's}, paired on the same drives."""
    pilots = [name for name in logs if name in end_to_end]
    paths = [name for name in logs if name not in end_to_end and name not in ("oracle", "straight")]
    return {(a, b): paired_interval(sums(logs[a]), sums(logs[b]), _per_km, resampling) for b in pilots for a in paths}


def table(scores: list[PolicyScore]) -> str:
    """A markdown table, one row per policy."""
    rows = [
        "| policy | driven (m) | interventions | per km of route [95 % CI] | autonomy % [95 % CI] | mean offset (m) [95 % CI] | "
        "95th pct offset (m) [95 % CI] | water entries per km | steps without a path |",
        "|" + " --- |" * 9,
    ]
    for p in scores:
        rows.append(
            f"| {p.policy} | {p.distance_m:.0f} | {p.interventions} | {p.per_km.text(1)} | {p.autonomy_pct.text(1)} | "
            f"{p.mean_offset_m.text(2)} | {p.p95_offset_m.text(2)} | {p.water_per_km:.1f} | {p.no_path_steps} |"
        )
    return "\n".join(rows)


def comparison_table(comparisons: dict[tuple[str, str], Interval]) -> str:
    rows = ["| path policy | end to end | interventions per km, path - end to end [95 % CI] |", "| --- | --- | --- |"]
    rows += [f"| {a} | {b} | {i.difference_text(2)} |" for (a, b), i in comparisons.items()]
    return "\n".join(rows)


def finding(comparisons: dict[tuple[str, str], Interval]) -> str:
    """One sentence: which path policies needed fewer or more interventions per km than which
    end-to-end policy, by paired intervals that exclude 0; or that no difference was measured."""
    if not comparisons:
        return "No end-to-end policy was driven: no comparison."
    better = [f"{a} than {b} ({i.difference_text(2)} per km)" for (a, b), i in comparisons.items() if i.high < 0]
    worse = [f"{a} than {b} ({i.difference_text(2)} per km)" for (a, b), i in comparisons.items() if i.low > 0]
    same = [f"{a} and {b}" for (a, b), i in comparisons.items() if i.contains_zero]
    parts = ([f"fewer interventions: {'; '.join(better)}"] if better else []) + ([f"more: {'; '.join(worse)}"] if worse else [])
    parts += [f"no difference measured between {', '.join(same)}"] if same else []
    return "Path prediction + pure pursuit against end-to-end steering, paired on the same drives: " + "; ".join(parts) + "."


def report(logs: dict[str, dict[str, list[DriveLog]]], d, worlds: list[str]) -> tuple[str, dict]:
    """results.md and the metrics of every argument's drives (logs: argument -> policy -> drives in
    world and start order; d: the drive config)."""
    resampling = Resampling(d.bootstrap.resamples, d.bootstrap.seed, d.bootstrap.level)
    drives = len(worlds) * d.starts_per_world
    water = ", or into water" if d.water_intervenes else ""
    sections = [
        f"# Closed-loop driving\n\n{len(worlds)} test worlds x {d.starts_per_world} start(s), {d.length_m:g} m of route each, "
        f"at {d.speed_mps:g} m/s with {d.rate_hz:g} Hz control; {100 * d.bootstrap.level:g} % intervals by resampling the "
        f"{drives} drives ({d.bootstrap.resamples} resamples). An intervention: the body more than {d.corridor_m:g} m from "
        f"every centre line (track, forks, reference drive), or into an object{water}.\n"
    ]
    metrics: dict = {}
    for argument, by_policy in logs.items():
        scores = [score(group, d.intervention_s, resampling) for group in by_policy.values()]
        comparisons = versus_end_to_end(by_policy, list(d.pilotnets), resampling)
        sentence = finding(comparisons)
        metrics[argument] = {
            "policies": {s.policy: s.as_dict() for s in scores},
            "path_minus_end_to_end": {
                f"{a} - {b}": {"value": i.estimate, "low": i.low, "high": i.high} for (a, b), i in comparisons.items()
            },
            "finding": sentence,
        }
        sections.append(f"\n## {ARGUMENTS[argument]}\n\n{table(scores)}\n\n{comparison_table(comparisons)}\n\n{sentence}\n")
    metrics["drives"] = {"worlds": worlds, "starts_per_world": d.starts_per_world, "length_m": d.length_m}
    return "".join(sections), metrics
