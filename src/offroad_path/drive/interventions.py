"""Scores of closed-loop drives, with hierarchical-bootstrap intervals (the test worlds, then the
starts within each drawn world, then the training seeds: offroad_path.statistics.bootstrap), the
exact test of each primary comparison's counts (statistics.counts), and the report (its tables:
offroad_path.report.rendering).

Per policy: interventions per km of route (progress along the reference drive, the same for every
policy that finishes its drives, so that a paired difference is one of counts alone); autonomy,
1 - interventions x intervention_s / elapsed time (Bojarski et al. 2016; below 0 when interventions
come faster than one per intervention_s); the mean and 95th-percentile lateral offset from the
nearest centre line; water entries per km. Each path policy is compared with each end-to-end one on
the same drives, paired: the interval of the difference in interventions per km (exploratory). The
primaries of evaluate.conclusions that name an argument get the exact test, their interval at every
Holm level, and the route their planning rates need for the target power (statistics.primaries).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from offroad_path.config.evaluate_schema import DRIVE_ARGUMENTS, PRIMARY_SECTIONS
from offroad_path.drive.loop import DriveLog
from offroad_path.report.rendering import argument_markdown
from offroad_path.statistics.bootstrap import Draws, Interval, Resampling, drawn, paired_draws, whole
from offroad_path.statistics.counts import compare_rates, power_sentence, rate_interval, route_needed
from offroad_path.statistics.primaries import check_declared, holm_levels, owned, recorded


def _per_km(s: np.ndarray) -> np.ndarray:  # (..., k) sums with interventions at 0, metres of route at 1
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(s[..., 1] > 0, 1000.0 * s[..., 0] / np.where(s[..., 1] > 0, s[..., 1], 1), np.nan)


def ordered(logs: list[DriveLog]) -> list[DriveLog]:
    """A policy's drives in the order every policy's are paired in: seed, world, start."""
    return sorted(logs, key=lambda g: (g.seed, g.world, g.start))


def sums(logs: list[DriveLog]) -> tuple[np.ndarray, list[str]]:
    """(seeds, drives per seed, 5): interventions, metres of route, seconds, summed offsets, steps; and
    the world of each drive (a world and a start), for the hierarchical draw."""
    logs = ordered(logs)
    seeds = sorted({g.seed for g in logs})
    rows = np.array([[len(g.interventions), g.progress_m, g.elapsed_s, sum(g.offsets), g.steps] for g in logs], float)
    per_seed = rows.reshape(len(seeds), -1, 5)
    return per_seed, [g.world for g in logs[: per_seed.shape[1]]]


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
    """One policy's drives (one per seed, world and start) scored with hierarchical intervals."""
    s, worlds = sums(logs)
    blocks, seeds = resampling.weights(worlds, s.shape[0])  # (count, drives), (count, seeds)
    resampled = drawn(s, blocks, seeds)  # (count, 5)

    def ratio(fn) -> Interval:  # widened for the worlds it resamples, as evaluate's and the paired intervals are
        return Draws(float(fn(whole(s))), fn(resampled), resampling, len(set(worlds))).interval()

    logs = ordered(logs)
    offsets = [np.asarray(g.offsets) for g in logs]
    causes = [why for g in logs for _, _, why in g.interventions]
    total = whole(s)
    # Interventions are rare counts: their rate's interval is the exact Poisson one (the exact test's kind),
    # which a resample of drives with none cannot give.
    p95 = float(np.percentile(np.concatenate(offsets), 95))
    rate = Interval(float(_per_km(total)), *rate_interval(int(total[0]), float(total[1]) / 1000.0, resampling.level))
    return PolicyScore(
        policy=logs[0].policy,
        drives=len(logs),
        route_m=float(total[1]),
        distance_m=sum(g.distance_m for g in logs),
        interventions=int(total[0]),
        per_km=rate,
        autonomy_pct=ratio(lambda c: 100.0 * (1.0 - c[..., 0] * intervention_s / c[..., 2])),
        mean_offset_m=ratio(lambda c: c[..., 3] / c[..., 4]),
        p95_offset_m=Draws(p95, _p95(offsets, blocks, seeds), resampling, len(set(worlds))).interval(),
        water_per_km=1000.0 * sum(g.water_entries for g in logs) / max(float(total[1]), 1e-9),  # per km of route
        no_path_steps=sum(g.no_path for g in logs),
        by_cause={why: causes.count(why) for why in sorted(set(causes))},
    )


def _p95(offsets: list[np.ndarray], blocks: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """The 95th percentile of the offsets each resample draws (drive k of seed s weighted by how
    often the draw takes its world-start and its seed): (count,)."""
    per_seed = len(offsets) // seeds.shape[1]
    values = np.concatenate(offsets)
    drive = np.repeat(np.arange(len(offsets)), [len(o) for o in offsets])
    order = np.argsort(values, kind="stable")
    values, drive = values[order], drive[order]
    weight = (seeds[:, drive // per_seed] * blocks[:, drive % per_seed]).cumsum(axis=1)  # (count, values)
    at = np.array([np.searchsorted(row, 0.95 * row[-1]) for row in weight])
    return values[np.minimum(at, len(values) - 1)]


Comparison = tuple[Interval, float]  # the paired interval of a - b per km, and the exact test's two-sided p


def versus_end_to_end(logs: dict[str, list[DriveLog]], end_to_end: list[str], resampling: Resampling) -> dict[tuple[str, str], Comparison]:
    """{(path policy, PilotNet policy): (path's interventions per km minus PilotNet's, paired on the same
    drives and seeds; the exact test's p of their pooled counts)}: exploratory, unless a primary names it."""
    pilots = [name for name in logs if name in end_to_end]
    paths = [name for name in logs if name not in end_to_end and name not in ("oracle", "straight")]
    found = {}
    for b in pilots:
        for a in paths:
            (sums_a, worlds), (sums_b, _) = sums(logs[a]), sums(logs[b])
            total_a, total_b = whole(sums_a), whole(sums_b)
            exact = compare_rates(int(total_a[0]), int(total_b[0]), total_a[1] / 1000.0, total_b[1] / 1000.0)
            found[a, b] = paired_draws(sums_a, sums_b, _per_km, resampling, worlds).interval(), exact.p_value
    return found


def primary(logs: dict[str, list[DriveLog]], name: str, key: str, conclusions) -> dict:
    """A primary's entry (statistics.primaries.recorded): the exact test of a's and b's pooled counts,
    the rate ratio a / b at every Holm level (null 1), and with planning rates the route each policy
    drove against the route their power needs at Holm's strictest level (alpha / family). key: a_vs_b."""
    a, _, b = key.partition("_vs_")
    family, planning = len(conclusions.primaries), conclusions.primaries[name].planning_per_km
    (sums_a, _), (sums_b, _) = sums(logs[a]), sums(logs[b])
    total_a, total_b = whole(sums_a), whole(sums_b)
    test = compare_rates(int(total_a[0]), int(total_b[0]), total_a[1] / 1000.0, total_b[1] / 1000.0)
    intervals = [[round(v, 6) for v in test.ratio_interval(level)] for level in holm_levels(conclusions.alpha, family)]
    entry = recorded(test.ratio, test.p_value, intervals, null=1.0) | {"interventions": [test.a, test.b]}
    entry["route_m"] = round(min(total_a[1], total_b[1]), 1)
    if planning:
        needed = route_needed(planning[0], planning[1], conclusions.alpha / family, conclusions.power)
        entry["route_needed_m"] = round(needed * 1000.0, 1) if needed != float("inf") else None
    return entry


def finding(comparisons: dict[tuple[str, str], Comparison]) -> str:
    """One sentence: which path policies needed fewer or more interventions per km than which
    end-to-end policy, by paired intervals that exclude 0, each with the exact test's p beside it (a
    few counts: the two can disagree); or that no difference was measured."""
    if not comparisons:
        return "No end-to-end policy was driven: no comparison."
    better = [f"{a} - {b} ({i.difference_text(2)} per km; exact p {p:.4f})" for (a, b), (i, p) in comparisons.items() if i.high < 0]
    worse = [f"{a} - {b} ({i.difference_text(2)} per km; exact p {p:.4f})" for (a, b), (i, p) in comparisons.items() if i.low > 0]
    same = [f"{a} and {b} (exact p {p:.4f})" for (a, b), (i, p) in comparisons.items() if i.contains_zero]
    parts = ([f"interval below 0: {'; '.join(better)}"] if better else []) + ([f"above 0: {'; '.join(worse)}"] if worse else [])
    parts += [f"interval holding 0 between {', '.join(same)}"] if same else []
    return (
        "Path prediction + pure pursuit minus end-to-end steering, interventions per km paired on the same drives "
        "(exploratory, uncorrected hierarchical intervals: a direction is a finding only where a primary's exact test rejects): "
        + "; ".join(parts)
        + "."
    )


def report(logs: dict[str, dict[str, list[DriveLog]]], d, worlds: list[str], conclusions) -> tuple[str, dict]:
    """results.md and the metrics of every argument's drives (logs: argument -> policy -> drives; d:
    the drive config; conclusions: evaluate.conclusions, whose primaries naming an argument are tested here)."""
    resampling = Resampling(d.bootstrap.resamples, d.bootstrap.seed, d.bootstrap.level)
    seeds = list(d.seeds)
    water = ", or into water" if d.water_intervenes else ""
    sections = [
        f"# Closed-loop driving\n\n{len(worlds)} test worlds x {d.starts_per_world} start(s) x {len(seeds)} training seed(s) "
        f"({', '.join(map(str, seeds))}), {d.length_m:g} m of route each, at {d.speed_mps:g} m/s with {d.rate_hz:g} Hz control; "
        f"{100 * d.bootstrap.level:g} % hierarchical-bootstrap intervals ({d.bootstrap.resamples} resamples: the worlds drawn with "
        "replacement, then the starts within each, then the seeds; every policy on the same draw). An intervention: the body "
        f"more than {d.corridor_m:g} m from every centre line (track, forks, reference drive), or into an object{water}.\n"
    ]
    metrics: dict = {}
    mine = owned(conclusions.primaries, tuple(DRIVE_ARGUMENTS))
    primaries: dict[str, dict] = {}
    for argument, by_policy in logs.items():
        scores = [score(group, d.intervention_s, resampling) for group in by_policy.values()]
        comparisons = versus_end_to_end(by_policy, list(d.pilotnets), resampling)
        sentence = finding(comparisons)
        metrics[argument] = {
            "policies": {s.policy: s.as_dict() for s in scores},
            "path_minus_end_to_end": {
                f"{a} - {b}": {"value": i.estimate, "low": i.low, "high": i.high, "exact_p": p} for (a, b), (i, p) in comparisons.items()
            },
            "finding": sentence,
        }
        sections.append(argument_markdown(argument, metrics[argument]))
        for name, (section, key) in mine.items():
            a, _, b = key.partition("_vs_")
            if section == argument and a in by_policy and b in by_policy:
                primaries[name] = primary(by_policy, name, key, conclusions)
                sections.append(_primary_text(name, conclusions, primaries[name]))
    metrics["drives"] = {"worlds": worlds, "starts_per_world": d.starts_per_world, "seeds": seeds, "length_m": d.length_m}
    if primaries:
        metrics["primaries"] = primaries
    return "".join(sections), metrics


def _primary_text(name: str, conclusions, entry: dict) -> str:
    a, b = entry["interventions"]
    low, high = entry["intervals"][0]
    power = power_sentence(entry, conclusions.power)
    return (
        f"\n**Primary `{name}`** ({conclusions.primaries[name].claim}): {a} against {b} interventions over "
        f"{entry['route_m']:.0f} m of route each; rate ratio {entry['estimate']:.2f} [95 %: {low:.2f}, {high:.2f}], exact "
        f"two-sided p = {entry['p_value']:.4f} (uncorrected; the README draws the family's Holm verdicts)"
        + (f"; {power}" if power else "")
        + ".\n"
    )


def check_arguments_primaries(conclusions, d) -> list[str]:
    """Before any drive: the primaries are well formed; returns those naming an argument that this
    drive does not answer (its policies not driven), which are not measured."""
    available = {argument: {f"{a}_vs_{b}" for a in names for b in names if a != b} for argument, names in d.arguments.items()}
    return check_declared(conclusions.primaries, {a: available.get(a, set()) for a in DRIVE_ARGUMENTS}, PRIMARY_SECTIONS)
