"""Scores of closed-loop drives, with block-bootstrap intervals across drives (a world and a start
point each, the unit resampled: offroad_path.evaluation.bootstrap), and the report's tables.

Per policy: interventions per km, autonomy (1 - interventions x intervention_s / elapsed time),
the mean and 95th-percentile lateral offset from the nearest centre line, water entries per km.
Each path policy is compared with PilotNet on the same drives, paired: the interval of the
difference in interventions per km.
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


def _per_km(s: np.ndarray) -> np.ndarray:  # (..., k) sums with interventions at 0, metres at 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(s[..., 1] > 0, 1000.0 * s[..., 0] / np.where(s[..., 1] > 0, s[..., 1], 1), np.nan)


def sums(logs: list[DriveLog]) -> np.ndarray:
    """(drives, 5): interventions, metres, seconds, summed offsets, steps; one row per drive."""
    return np.array([[len(g.interventions), g.distance_m, g.elapsed_s, sum(g.offsets), g.steps] for g in logs], float)


@dataclass(frozen=True)
class PolicyScore:
    policy: str
    drives: int
    distance_m: float
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

        return {"drives": self.drives, "distance_m": self.distance_m, "interventions": self.interventions,
                "interventions_per_km": iv(self.per_km), "autonomy_pct": iv(self.autonomy_pct),
                "mean_offset_m": iv(self.mean_offset_m), "p95_offset_m": iv(self.p95_offset_m),
                "water_entries_per_km": self.water_per_km, "no_path_steps": self.no_path_steps,
                "interventions_by_cause": self.by_cause}  # fmt: skip


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
        distance_m=float(s[:, 1].sum()),
        interventions=int(s[:, 0].sum()),
        per_km=ratio(_per_km),
        autonomy_pct=ratio(lambda c: 100.0 * (1.0 - c[..., 0] * intervention_s / c[..., 2])),
        mean_offset_m=ratio(lambda c: c[..., 3] / c[..., 4]),
        p95_offset_m=Interval(float(np.percentile(np.concatenate(offsets), 95)), *resampling.percentiles(p95)),
        water_per_km=1000.0 * sum(g.water_entries for g in logs) / max(float(s[:, 1].sum()), 1e-9),
        no_path_steps=sum(g.no_path for g in logs),
        by_cause={why: causes.count(why) for why in sorted(set(causes))},
    )


def versus_pilotnet(logs: dict[str, list[DriveLog]], resampling: Resampling) -> dict[str, Interval]:
    """Each path policy's interventions per km minus PilotNet's, paired on the same drives."""
    if "pilotnet" not in logs:
        return {}
    base = sums(logs["pilotnet"])
    return {name: paired_interval(sums(g), base, _per_km, resampling)
            for name, g in logs.items() if name not in ("pilotnet", "oracle", "straight")}  # fmt: skip


def table(scores: list[PolicyScore], comparisons: dict[str, Interval]) -> str:
    """A markdown table, one row per policy."""
    head = ("| policy | distance (m) | interventions | per km [95 % CI] | autonomy % [95 % CI] | mean offset (m) | "
            "95th pct offset (m) | water entries per km | steps without a path | - PilotNet, per km [95 % CI] |")  # fmt: skip
    rows = [head, "|" + " --- |" * 10]
    for p in scores:
        versus = comparisons[p.policy].difference_text(1) if p.policy in comparisons else ""
        rows.append(f"| {p.policy} | {p.distance_m:.0f} | {p.interventions} | {p.per_km.text(1)} | {p.autonomy_pct.text(1)} | "
                    f"{p.mean_offset_m.text(2)} | {p.p95_offset_m.text(2)} | {p.water_per_km:.1f} | {p.no_path_steps} | {versus} |")  # fmt: skip
    return "\n".join(rows)


def finding(scores: list[PolicyScore], comparisons: dict[str, Interval]) -> str:
    """One sentence: whether the path networks beat PilotNet, with the paired intervals."""
    if not comparisons:
        return "No PilotNet policy was driven: no comparison."
    better = [n for n, i in comparisons.items() if i.high < 0]
    worse = [n for n, i in comparisons.items() if i.low > 0]
    parts = [f"{n} {i.difference_text(1)}" for n, i in comparisons.items()]
    if better and not worse:
        verdict = f"{', '.join(better)} needed fewer interventions per km than PilotNet"
    elif worse and not better:
        verdict = f"{', '.join(worse)} needed more interventions per km than PilotNet"
    elif better:
        verdict = f"{', '.join(better)} needed fewer and {', '.join(worse)} more interventions per km than PilotNet"
    else:
        verdict = "no difference in interventions per km from PilotNet was measured"
    return f"{verdict} (path policy - PilotNet, per km: {'; '.join(parts)})."
