"""Interventions are counts of rare events: two policies driven over the same routes are compared by
an exact test, and the route that test needs is planned from pilot rates.

The test: with x_a interventions over L_a km of route and x_b over L_b km, given their total n the
count x_a is binomial, n trials with chance L_a / (L_a + L_b) when the two rates are equal (the
conditional test for two Poisson rates; Przyborowski & Wilenski 1940). Its two-sided p-value and the
exact (Clopper-Pearson) interval of that chance, turned into one of the rate ratio
(lambda_a / lambda_b = pi / (1 - pi) x L_b / L_a), are scipy's `binomtest`. A ratio below 1: policy
a needs fewer interventions per km. The test takes the drives' counts as Poisson: drives that differ
more than that (worlds, seeds) make it optimistic, which the hierarchical intervals beside it show.

The power: the chance that the test at level `alpha` rejects equal rates when the true rates are the
planning rates and each policy drives `km` of route, summed exactly over the Poisson total and the
binomial split; `route_needed` is the shortest route (to 10 m) that reaches the target power.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats


@dataclass(frozen=True)
class RateComparison:
    a: int  # interventions of policy a
    b: int
    route_a_km: float
    route_b_km: float
    p_value: float  # two-sided, exact
    ratio: float  # interventions per km of a over b (inf when b has none and a some; nan when neither)

    def ratio_interval(self, level: float) -> tuple[float, float]:
        """The exact interval of the rate ratio at `level` ((0, inf) with no intervention at all)."""
        n = self.a + self.b
        if n == 0:
            return 0.0, math.inf
        ci = stats.binomtest(self.a, n, self._chance).proportion_ci(level, method="exact")
        scale = self.route_b_km / self.route_a_km
        return ci.low / (1 - ci.low) * scale, (ci.high / (1 - ci.high) * scale if ci.high < 1 else math.inf)

    @property
    def _chance(self) -> float:
        return self.route_a_km / (self.route_a_km + self.route_b_km)


def rate_interval(count: int, km: float, level: float) -> tuple[float, float]:
    """The exact (Garwood 1936) interval of a Poisson rate per km from `count` events over `km`: never
    [0, 0] for no event (0 of 0 interventions says the rate is small, not that it is 0)."""
    tail = (1.0 - level) / 2.0
    low = 0.0 if count == 0 else stats.chi2.ppf(tail, 2 * count) / 2.0
    high = stats.chi2.ppf(1.0 - tail, 2 * (count + 1)) / 2.0
    return float(low / km), float(high / km)


def compare_rates(a: int, b: int, route_a_km: float, route_b_km: float) -> RateComparison:
    """The exact conditional test of equal intervention rates (module docstring)."""
    if route_a_km <= 0 or route_b_km <= 0:
        raise ValueError(f"routes must be positive, have {route_a_km} and {route_b_km} km")
    n = a + b
    p = 1.0 if n == 0 else float(stats.binomtest(a, n, route_a_km / (route_a_km + route_b_km)).pvalue)
    rate_a, rate_b = a / route_a_km, b / route_b_km
    ratio = rate_a / rate_b if rate_b > 0 else (math.inf if rate_a > 0 else math.nan)
    return RateComparison(a, b, route_a_km, route_b_km, p, ratio)


def power(rate_a: float, rate_b: float, km: float, alpha: float) -> float:
    """The chance that compare_rates rejects equal rates at `alpha` when a and b drive `km` each at
    these rates (per km)."""
    mean = (rate_a + rate_b) * km
    n = np.arange(int(stats.poisson.ppf(1 - 1e-12, mean)) + 2)
    # Equal routes: the null chance is 1/2, and the two-sided exact test rejects x <= c or x >= n - c,
    # c the largest count whose lower tail is at most alpha / 2 (-1: none).
    c = stats.binom.ppf(alpha / 2, n, 0.5)
    c = np.where(stats.binom.cdf(c, n, 0.5) > alpha / 2, c - 1, c)
    chance = rate_a / (rate_a + rate_b)
    reject = np.where(c >= 0, stats.binom.cdf(c, n, chance) + stats.binom.sf(n - c - 1, n, chance), 0.0)
    return float(np.sum(stats.poisson.pmf(n, mean) * np.minimum(reject, 1.0)))


STEP_KM, LIMIT_KM = 0.01, 100.0  # route_needed's resolution and the longest route it considers


def route_needed(rate_a: float, rate_b: float, alpha: float, target: float) -> float:
    """The shortest route per policy (km, a multiple of STEP_KM) at which `power` reaches `target`
    (bisection: power grows with the route, up to the discreteness of counts); inf past LIMIT_KM."""
    if rate_a == rate_b or power(rate_a, rate_b, LIMIT_KM, alpha) < target:
        return math.inf
    low, high = 0, round(LIMIT_KM / STEP_KM)
    while high - low > 1:
        middle = (low + high) // 2
        low, high = (middle, high) if power(rate_a, rate_b, middle * STEP_KM, alpha) < target else (low, middle)
    return round(high * STEP_KM, 2)


def power_sentence(entry: dict, target: float) -> str:
    """A drive primary's route against the route its planning rates need (its metrics entry), or "" without them."""
    needed = entry.get("route_needed_m")
    if "route_needed_m" not in entry:
        return ""
    if needed is None:
        return f"no route within {LIMIT_KM:g} km gives {target:.0%} power at its planning rates"
    if entry["route_m"] >= needed:
        return f"powered: {entry['route_m']:.0f} m of route per policy, {needed:.0f} m needed for {target:.0%} power"
    return f"underpowered: {entry['route_m']:.0f} m of the {needed:.0f} m of route per policy needed for {target:.0%} power"
