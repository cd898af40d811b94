"""Primary questions: one comparison per claim, declared in the config before the run
(evaluate.conclusions.primaries), tested as one family with Holm's step-down correction (Holm 1979).
Every other comparison the reports print is exploratory.

Each stage that answers a primary records it in its metrics (`primaries`): the estimate, the
value of no difference (`null`: 0 for a difference, 1 for a rate ratio), a two-sided p-value, and
the interval at each level Holm's procedure can ask for, 1 - alpha / j for j = 1 .. m (m: the
family's size), so that a reader of the metrics draws the family's verdicts without the resamples.
evaluate answers with the hierarchical bootstrap (statistics.bootstrap.Draws), drive with an exact
test on interventions (statistics.counts). `verdicts` then orders the family's p-values and gives each
primary its Holm level: 1 - alpha / (m - k) for the k-th smallest p (from 0) while every smaller
one is rejected, and from the first that is not, the level that one failed at; so a primary's
shown interval excludes the null exactly when Holm rejects it (up to the bootstrap's ties).

A primary may declare its smallest effect of interest (`smallest_effect`, in its estimate's units):
when its interval at the Holm level lies within that distance of the null, the verdict is "no
material difference" (an equivalence test: two one-sided tests at the same level), whether or not
Holm rejects the null. One rule for a direction, here and in docs/conclusions.md: Holm rejects the
null and the interval does not lie wholly within the smallest effect (so [+0.001, +0.012] with a
smallest effect of 0.01 reads "higher": above 0, by an amount the interval shows); otherwise "no
material difference" or "no difference measured".
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from offroad_path.errors import InputError
from offroad_path.statistics.bootstrap import Draws, Interval

Levels = list[list[float]]  # [[low, high] at 1 - alpha / j for j = 1 .. m]


def holm_levels(alpha: float, family: int) -> list[float]:
    """The interval levels Holm's procedure uses: 1 - alpha / j for j = 1 .. family."""
    return [1.0 - alpha / j for j in range(1, family + 1)]


def recorded(estimate: float, p_value: float, intervals: Levels, null: float = 0.0) -> dict:
    """A primary's entry in a stage's metrics (numbers only: MLflow logs them)."""
    return {"estimate": round(estimate, 6), "null": null, "p_value": round(p_value, 8), "intervals": intervals}


def from_draws(draws: Draws, alpha: float, family: int) -> dict:
    """A bootstrap-answered primary's entry: its percentile interval at every Holm level."""
    intervals = [[round(v, 6) for v in (i.low, i.high)] for i in (draws.interval(level) for level in holm_levels(alpha, family))]
    return recorded(draws.estimate, draws.p_value(), intervals)


@dataclass(frozen=True)
class Verdict:
    name: str
    claim: str
    compare: str
    interval: Interval | None  # at its Holm level; None: not measured
    level: float
    p_value: float
    null: float
    rejected: bool  # Holm rejects "no difference"
    smallest_effect: float | None = None  # in the estimate's units; None: none declared

    @property
    def negligible(self) -> bool:
        """The interval lies within smallest_effect of the null: no material difference."""
        if self.smallest_effect is None or self.interval is None:
            return False
        return self.null - self.smallest_effect < self.interval.low and self.interval.high < self.null + self.smallest_effect

    @property
    def direction(self) -> str:
        """'higher' / 'lower' (a above or below b) when rejected, the interval excludes the null and the
        difference is not negligible, else ''."""
        if not self.rejected or self.interval is None or self.negligible:
            return ""
        if self.interval.low > self.null:
            return "higher"
        return "lower" if self.interval.high < self.null else ""


def verdicts(declared: Mapping, measured: Mapping[str, dict], alpha: float) -> list[Verdict]:
    """Holm over the declared family (name -> claim, compare); measured: name -> its recorded entry
    (a primary not measured counts as p = 1, so the others are corrected for it all the same)."""
    family = len(declared)
    p = {name: float(measured[name]["p_value"]) if name in measured else 1.0 for name in declared}
    order = sorted(declared, key=lambda name: (p[name], list(declared).index(name)))
    out: dict[str, Verdict] = {}
    failed_at: int | None = None
    for k, name in enumerate(order):
        step = k if failed_at is None else failed_at
        rejected = failed_at is None and p[name] <= alpha / (family - k)
        if not rejected and failed_at is None:
            failed_at, step = k, k
        entry = measured.get(name)
        interval = None
        if entry is not None:
            low, high = entry["intervals"][family - step - 1]
            interval = Interval(float(entry["estimate"]), float(low), float(high))
        q = declared[name]
        smallest = q.get("smallest_effect")
        out[name] = Verdict(name, q["claim"], q["compare"], interval, 1.0 - alpha / (family - step), p[name],
                            float(entry["null"]) if entry else 0.0, rejected,
                            None if smallest is None else float(smallest))  # fmt: skip
    return [out[name] for name in declared]


def owned(declared: Mapping, sections: tuple[str, ...]) -> dict[str, tuple[str, str]]:
    """The declared primaries a stage answers: name -> (section, key) for compare = <section>/<key>."""
    found = {}
    for name, q in declared.items():
        section, _, key = str(q["compare"]).partition("/")
        if section in sections:
            found[name] = (section, key)
    return found


def check_declared(
    declared: Mapping, available: Mapping[str, set[str]], sections: tuple[str, ...], where: str = "evaluate.conclusions.primaries"
) -> list[str]:
    """Before any work: InputError naming a primary whose compare names none of `sections` (every
    stage's that reports primaries: the caller's config knows them) or is not <section>/<a>_vs_<b>;
    returns the primaries this stage owns (available: section -> the comparison keys this run
    makes) but does not make, which its report gives as not measured."""
    missing = []
    for name, q in declared.items():
        smallest = q.get("smallest_effect")
        if smallest is not None and not (
            isinstance(smallest, int | float) and not isinstance(smallest, bool) and 0 < smallest < float("inf")
        ):
            raise InputError(f"{where}.{name}.smallest_effect", f"{smallest!r} must be a number > 0 (in the estimate's units) or null")
        section, _, key = str(q["compare"]).partition("/")
        if section not in sections or "_vs_" not in key:
            raise InputError(
                f"{where}.{name}.compare", f"{q['compare']!r} is not <section>/<a>_vs_<b> with a section of {', '.join(sections)}"
            )
        if section in available and key not in available[section]:
            missing.append(name)
    return missing
