"""tools/gpu_cost.py: the GPU cost model schedules stages as tools/parallel_repro.py runs them, prices
every stage of the scaled pipelines from gpu/sizing.yaml, and docs/scaling.md states its current estimate."""

from __future__ import annotations

import math

import pytest
from gpu_cost import estimate, power_rows, schedule, throughput, unit_costs
from helpers import ROOT

MEASURED = {"stages": 2, "slowdown": 1.6}  # two at once: 1.25 stages' work per second


def test_side_by_side_throughput_is_the_measured_gain_and_no_more_beyond_its_count():
    three = {"stages": 3, "slowdown": 2.0}
    assert throughput(1, three) == 1.0
    assert throughput(3, three) == pytest.approx(1.5)
    assert throughput(2, three) == pytest.approx(1.25)  # linear between one and the measured count
    assert throughput(8, three) == pytest.approx(1.5)
    assert throughput(1, {"stages": 1, "slowdown": 1.0}) == 1.0  # --jobs 1 --assume-gain X: one at a time


def test_stages_run_in_order_once_upstream_is_done_sharing_the_host():
    order = ["a", "b", "c"]
    # a and b independent, 10 s each alone: side by side at 1.25x they end together at 16 s; c (5 s) after a
    spans = schedule(order, {"a": set(), "b": set(), "c": {"a"}}, {"a": 10, "b": 10, "c": 5}, jobs=2, side_by_side=MEASURED)
    assert spans["a"] == pytest.approx((0, 16)) and spans["b"] == pytest.approx((0, 16)) and spans["c"] == pytest.approx((16, 21))
    one_by_one = schedule(order, {"a": set(), "b": set(), "c": {"a"}}, {"a": 10, "b": 10, "c": 5}, jobs=1, side_by_side=MEASURED)
    assert one_by_one["c"] == pytest.approx((20, 25))  # dvc.yaml's order: b before c
    # b is short: while a and b share (0.625 each), b ends at 8 s having done 5; then a alone finishes its last 5 s
    uneven = schedule(["a", "b"], {"a": set(), "b": set()}, {"a": 10, "b": 5}, jobs=2, side_by_side=MEASURED)
    assert uneven["b"] == pytest.approx((0, 8)) and uneven["a"] == pytest.approx((0, 13))


def test_every_assumed_figure_carries_the_margin_and_a_measured_one_does_not():
    import yaml

    raw = yaml.safe_load((ROOT / "gpu" / "sizing.yaml").read_text())
    costs, components = unit_costs()
    for name, entry in raw["unit_costs"].items():
        assert entry["kind"] in ("measured", "assumed") and entry["source"], name
        if name == "side_by_side":
            assert costs[name] == entry["value"]
            continue
        scale = raw["margin"] if entry["kind"] == "assumed" else 1.0
        values = entry["value"] if isinstance(entry["value"], dict) else {"": entry["value"]}
        found = costs[name] if isinstance(entry["value"], dict) else {"": costs[name]}
        assert found == pytest.approx({k: v * scale for k, v in values.items()}), name
    assert {"central_claim", "pretraining", "postprocessing"} <= set(components)


@pytest.mark.parametrize("folder", ["gpu", "rehearsal", "tour"])
def test_every_stage_of_each_scaled_pipeline_is_priced(folder):
    found = estimate(folder, jobs=4)
    assert found["alone_s"] and all(seconds > 0 for seconds in found["alone_s"].values())
    assert found["pipeline_s"] == max(end for _, end in found["spans"].values())
    assert found["total_s"] == pytest.approx(found["install_s"] + found["pipeline_s"] + found["report_s"])


def test_the_gpu_presets_sizes_and_design_are_what_the_model_and_docs_state():
    found = estimate("gpu", jobs=4)
    design = found["design"]
    assert found["sizes"]["main"] == math.ceil(design.main_test_set.min_blocks / 4.5) and found["sizes"]["seeds"] == len(design.seeds) >= 3
    rows = {name: (role, p) for name, role, _, p in power_rows(design, unit_costs()[1])}
    assert all(p >= design.conclusions.power for name, (role, p) in rows.items() if role == "primary"), rows
    assert all(role == "left out" for name, (role, _) in rows.items() if name in ("ranking", "open_loop"))
    # docs/scaling.md quotes the model's estimate of the committed preset: it goes stale with the preset
    assert f"= {found['total_s']:.0f} s" in (ROOT / "docs" / "scaling.md").read_text(), "docs/scaling.md: rerun python tools/gpu_cost.py"
