"""Conclusions: the exact test of intervention counts and its power, Holm's verdicts over the
declared primaries, the README check that refuses a direction inside a corrected interval, and the
PilotNet that predicts curvature steering another vehicle as pure pursuit does."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from offroad_path.errors import InputError
from offroad_path.report.readme import main
from offroad_path.report.rendering import primaries_markdown
from offroad_path.statistics.counts import compare_rates, power, route_needed
from offroad_path.statistics.primaries import check_declared, holm_levels, verdicts


def test_the_exact_test_on_hand_made_counts():
    # 2 against 12 interventions over equal routes: given 14, a's count is binomial(14, 1/2) when the
    # rates are equal, and P(X <= 2) = (1 + 14 + 91) / 2^14: twice that, two-sided.
    found = compare_rates(2, 12, 1.2, 1.2)
    assert found.p_value == pytest.approx(2 * 106 / 2**14)
    assert found.ratio == pytest.approx(1 / 6)
    low, high = found.ratio_interval(0.95)
    assert 0 < low < 1 / 6 < high < 1  # the exact interval of the rate ratio excludes 1, as p < 0.05 says
    # Unequal routes: 4 in 1 km against 4 in 2 km is a ratio of 2, and the null chance of a is 1/3.
    uneven = compare_rates(4, 4, 1.0, 2.0)
    assert uneven.ratio == pytest.approx(2.0) and uneven.p_value > 0.3
    nothing = compare_rates(0, 0, 1.0, 1.0)
    assert nothing.p_value == 1.0 and math.isnan(nothing.ratio) and nothing.ratio_interval(0.95) == (0.0, math.inf)
    with pytest.raises(ValueError, match="routes must be positive"):
        compare_rates(1, 1, 0.0, 1.0)


def test_the_power_is_what_simulated_drives_reject():
    """The planned route of argument (a)'s primary (5 and 21.2 interventions per km, Holm's strictest
    level of 7): the exact sum says 80 %, and 2000 simulated pairs of Poisson counts agree within 3 points."""
    alpha = 0.05 / 7
    km = route_needed(5.0, 21.2, alpha, 0.8)
    assert km == pytest.approx(1.25, abs=0.02)
    assert power(5.0, 21.2, km, alpha) >= 0.8 > power(5.0, 21.2, km - 0.1, alpha)
    rng = np.random.default_rng(0)
    counts = rng.poisson([5.0 * km, 21.2 * km], (2000, 2))
    rejected = np.mean([compare_rates(int(a), int(b), km, km).p_value <= alpha for a, b in counts])
    assert rejected == pytest.approx(power(5.0, 21.2, km, alpha), abs=0.03)
    assert route_needed(5.0, 5.0, alpha, 0.8) == math.inf  # equal rates: no route shows a difference


def _entry(estimate: float, p: float, interval_at: dict[int, tuple[float, float]], family: int = 3) -> dict:
    return {
        "estimate": estimate,
        "null": 0.0,
        "p_value": p,
        "intervals": [list(interval_at.get(j, (0.0, 0.0))) for j in range(1, family + 1)],
    }


def test_holm_rejects_step_by_step_and_shows_each_interval_at_its_level():
    declared = OmegaConf.create({name: {"claim": name, "compare": f"uncertainty/{name}"} for name in ("x", "y", "z")})
    # p 0.01 <= 0.05 / 3: rejected; the next, 0.03 > 0.05 / 2: not, and neither is 0.04 after it.
    measured = {
        "x": _entry(0.05, 0.01, {3: (0.01, 0.09)}),
        "y": _entry(0.04, 0.04, {2: (-0.01, 0.08)}),
        "z": _entry(0.03, 0.03, {2: (-0.005, 0.07)}),
    }
    found = {v.name: v for v in verdicts(declared, measured, 0.05)}
    assert [found[n].rejected for n in "xyz"] == [True, False, False]
    assert found["x"].level == pytest.approx(1 - 0.05 / 3) and found["x"].interval.low == 0.01 and found["x"].direction == "higher"
    # z failed at the second step (level 1 - 0.05 / 2); y, after it, is shown at that same level.
    assert found["z"].level == found["y"].level == pytest.approx(1 - 0.05 / 2)
    assert found["y"].interval.low == -0.01 and found["y"].direction == ""
    assert holm_levels(0.05, 3) == pytest.approx([0.95, 0.975, 1 - 0.05 / 3])
    # A primary not measured counts as p = 1: the others are still corrected for a family of three.
    partial = {v.name: v for v in verdicts(declared, {"x": measured["x"]}, 0.05)}
    assert partial["x"].rejected and partial["y"].interval is None and not partial["y"].rejected


def test_an_interval_within_the_smallest_effect_reads_no_material_difference_whatever_holm_says():
    declared = OmegaConf.create(
        {name: {"claim": name, "compare": f"uncertainty/{name}", "smallest_effect": 0.01} for name in ("tiny", "real", "wide", "none")}
    )
    declared["none"]["smallest_effect"] = None
    measured = {
        "tiny": _entry(-0.004, 0.0003, {4: (-0.008, -0.002)}, family=4),  # rejected, but within +-0.01: equivalent
        "real": _entry(-0.03, 0.0003, {3: (-0.047, -0.013)}, family=4),  # rejected and beyond 0.01: a direction
        "wide": _entry(-0.02, 0.06, {1: (-0.044, 0.001)}, family=4),  # not rejected, reaches beyond 0.01: undecided
        "none": _entry(-0.004, 0.0004, {2: (-0.008, -0.002)}, family=4),  # no smallest effect declared: a direction
    }
    found = {v.name: v for v in verdicts(declared, measured, 0.05)}
    assert found["tiny"].rejected and found["tiny"].negligible and found["tiny"].direction == ""
    assert not found["real"].negligible and found["real"].direction == "lower"
    assert not found["wide"].rejected and not found["wide"].negligible and found["wide"].direction == ""
    assert not found["none"].negligible and found["none"].direction == "lower"
    rows = primaries_markdown(OmegaConf.create({"alpha": 0.05, "primaries": declared}), measured)
    assert "| no material difference (within ±0.01) |" in rows and "| real's IoU lower |" in rows and "| no difference measured |" in rows
    for bad in (0, -0.01, float("nan"), "a lot"):
        with pytest.raises(InputError, match=r"evaluate.conclusions.primaries.x.smallest_effect"):
            check_declared({"x": {"claim": "x", "compare": "uncertainty/a_vs_b", "smallest_effect": bad}}, {}, ("uncertainty",))


def test_a_readme_whose_verdict_was_edited_to_claim_a_direction_fails_the_check(tmp_path, capsys):
    """The primaries' verdicts come from the metrics (Verdict.direction), never from the page: a README
    whose "no difference" was edited into a direction disagrees with its regenerated block."""
    from helpers import ROOT

    readme, results = tmp_path / "README.md", tmp_path / "results.md"
    readme.write_text((ROOT / "README.md").read_text())
    results.write_text((ROOT / "docs" / "results.md").read_text())
    arguments = ["--readme", str(readme), "--results", str(results), "--metrics", str(ROOT / "metrics"), "--check"]
    assert main(arguments) == 0
    text = readme.read_text()
    verdicts = [line for line in text.splitlines() if line.startswith("| ") and line.endswith(" |") and "no material difference" in line]
    assert verdicts, "the committed run's README has a primary without a material difference"
    readme.write_text(text.replace(verdicts[0], verdicts[0].rsplit("| no material difference", 1)[0] + "| lower |"))
    assert main(arguments) == 1
    assert f"{readme}: its results disagree" in capsys.readouterr().err


def test_a_curvature_pilotnet_steers_another_vehicle_by_its_own_wheelbase():
    """A PilotNet that outputs curvature 0.5 of the recording vehicle's tightest (lock 30 degrees,
    wheelbase 2.8 m) steers a 4.2 m vehicle atan(4.2 x 0.5 x tan 30 / 2.8); one that outputs the
    normalised angle 0.5 steers every vehicle half its own lock."""
    from types import SimpleNamespace

    from offroad_path.drive.policies import PilotNetPolicy
    from offroad_path.steering.pilotnet_task import SteeringTask

    settings = {"width": 128, "height": 68, "lr": 0.01, "lr_step_epochs": 5, "lr_gamma": 0.5, "momentum": 0.9, "weight_decay": 0.0}
    task = SteeringTask(**settings, target="curvature", lock_deg=30.0, wheelbase_m=2.8)
    last = [m for m in task.model.modules() if isinstance(m, torch.nn.Linear)][-1]
    with torch.no_grad():  # every image gives tanh(atanh(0.5)) = 0.5
        last.weight.zero_()
        last.bias.fill_(math.atanh(0.5))
    image = torch.zeros(2, 3, 68, 128)
    assert task(image).tolist() == pytest.approx([0.5, 0.5])
    # Normalised angles as the recording vehicle steers them: atan(0.5 tan 30) / 30 degrees.
    assert task.angle(image).tolist() == pytest.approx([math.atan(0.5 * math.tan(math.radians(30))) / math.radians(30)] * 2)
    assert task.learnt(torch.tensor([1.0, -1.0, 0.0])).tolist() == pytest.approx([1.0, -1.0, 0.0])  # the lock is curvature 1
    longer = SimpleNamespace(geometry=SimpleNamespace(wheelbase_m=4.2), lock_rad=math.radians(35.0))
    frame = SimpleNamespace(left=np.zeros((144, 256, 3), np.uint8), vehicle=longer)
    curvature = PilotNetPolicy(task.eval(), 128, 68, "pilotnet_curvature", task.max_curvature)
    assert curvature.steer(frame) == pytest.approx(math.atan(4.2 * 0.5 * math.tan(math.radians(30)) / 2.8))
    angle_task = SteeringTask(**settings)
    angle_task.load_state_dict(task.state_dict())
    assert angle_task.max_curvature is None
    assert PilotNetPolicy(angle_task.eval(), 128, 68).steer(frame) == pytest.approx(0.5 * math.radians(35.0))
    with pytest.raises(ValueError, match="needs the recording vehicle's lock_deg and wheelbase_m"):
        SteeringTask(**settings, target="curvature")
