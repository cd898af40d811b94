"""The GPU cost model: how long a scaled pipeline takes from nothing on the GPU host, stage by stage,
from measured unit costs and the preset's sizes (docs/scaling.md, "What a GPU run costs").

    python tools/gpu_cost.py [--pipeline gpu] [--jobs 3] [--json F]

The unit costs and where each comes from are gpu/sizing.yaml (measured on the H200 host, or on the
2-core Xeon, or assumed; the model multiplies each assumed figure by its `margin`). Each stage's
seconds alone are its unit costs times the work its preset gives it (worlds, SGD steps, runs and
seeds, metres driven); the stages then run as tools/parallel_repro.py runs them (dvc.yaml's order,
a stage once its upstream stages are done, at most --jobs at once), where k stages at once share
the host at the measured side-by-side throughput (no more than at the measured count). The total
adds the install from the wheelhouse and the results page with the archive (gpu/repro.sh). With the
design's variance components, it also prints the power of each primary at the preset's main test
set and seeds (benchmarks/test_set_design.py's power).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import yaml

from offroad_path.report.tables import grid_head, grid_row

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT / "tools"), str(ROOT / "benchmarks")]
MEASURED_DRIVES, MEASURED_FRAMES, MEASURED_BATCH = 16, 100, 32  # the H200 stage times' sizes: one epoch of 16 drives


def unit_costs(path: Path = ROOT / "gpu" / "sizing.yaml") -> tuple[dict, dict]:
    """{name: value} with every assumed value times the margin (a table's values each), and the design's variance components."""
    found = yaml.safe_load(path.read_text())
    costs: dict = {"host_cores": found["host_cores"]}
    for name, entry in found["unit_costs"].items():
        scale = found["margin"] if entry["kind"] == "assumed" else 1.0
        value = entry["value"]
        if name == "side_by_side":  # a count and a ratio, measured
            costs[name] = value
        elif isinstance(value, dict):
            costs[name] = {k: v * scale for k, v in value.items()}
        else:
            costs[name] = value * scale
    return costs, found["variance_components"]


def sizes(cfg, u: dict) -> dict[str, float]:
    """The work a preset gives the pipeline: worlds by kind, SGD steps, runs and seeds, metres driven."""
    c, per_world = cfg.synthesize.test_worlds, u["blocks_per_world"]
    frames = cfg.world.frames / MEASURED_FRAMES
    worlds = {
        "drives": cfg.synthesize.sequences,
        "main": math.ceil(c.min_blocks / per_world),
        "development": math.ceil(c.development_blocks / per_world),
        "retired": math.ceil(c.retired_blocks / per_world),
        "stress": len(c.stress_sets) * c.per_stress,
    }
    images = cfg.synthesize.sequences * u["training_images_per_drive"] * frames
    epochs = cfg.trainer.max_epochs
    steps = epochs * math.ceil(images / cfg.data.batch_size)
    if cfg.train.max_steps > 0:
        steps = min(steps, cfg.train.max_steps)
    pretrain_epochs = cfg.pretrain.max_epochs or epochs
    pretrain_steps = pretrain_epochs * math.ceil(images / cfg.data.batch_size)
    if cfg.pretrain.max_steps > 0:
        pretrain_steps = min(pretrain_steps, cfg.pretrain.max_steps)
    steering_steps = cfg.steering.max_epochs * math.ceil(cfg.synthesize.sequences * cfg.world.frames / cfg.steering.batch_size)
    policies = sum(len(p) for p in cfg.drive.arguments.values())
    driven = cfg.drive.worlds or worlds["main"]
    return {
        **worlds,
        "frames": frames,
        "steps": steps,
        "pretrain_steps": pretrain_steps,
        "steering_steps": steering_steps,
        "runs": len(cfg.evaluate.runs),
        "seeds": len(cfg.evaluate.seeds),
        "drive_worlds": driven,
        "policy_metres": driven * len(cfg.drive.seeds) * cfg.drive.starts_per_world * cfg.drive.length_m * policies,
    }


def stage_seconds(stage: str, s: dict[str, float], u: dict) -> float:
    """One stage's seconds alone on the host (DVC's own start and hashing included)."""
    kind, _, item = stage.partition("@")
    rendered = (s["drives"] + s["main"] + s["development"] + s["retired"] + s["stress"]) * s["frames"]
    measured_steps = MEASURED_DRIVES * u["training_images_per_drive"] / MEASURED_BATCH  # the one epoch inside the measured stage times
    if kind == "synthesize":
        own = rendered * u["synthesize_per_world_s"]
    elif kind == "label":
        own = rendered * u["label_per_world_s"]
    elif kind == "split":
        own = u["split_s"]
    elif kind == "pretrain":
        own = u["pretrain_s"] + max(s["pretrain_steps"] - measured_steps, 0) * max(u["step_ms"].values()) / 1000
    elif kind in ("train_scratch", "train_pretrained"):
        own = u["train_s"] + max(s["steps"] - measured_steps, 0) * u["step_ms"][item.rsplit("-", 1)[0]] / 1000
    elif kind.startswith("train_steering"):
        measured = math.ceil(MEASURED_DRIVES * MEASURED_FRAMES / 6)  # PilotNet's batch of 6
        own = u["train_steering_s"] + max(s["steering_steps"] - measured, 0) * u["pilotnet_step_ms"] / 1000
    elif kind == "postprocess":
        own = u["postprocess_s"]
    elif kind == "evaluate":
        own = s["runs"] * s["seeds"] * (s["main"] + s["stress"]) * u["evaluate_per_run_seed_world_s"]
    elif kind == "drive":
        own = s["policy_metres"] * u["drive_core_s_per_policy_m"] / min(u["host_cores"], s["drive_worlds"])
    else:
        raise SystemExit(f"error: {stage}: a stage the cost model has no unit cost for (gpu/sizing.yaml)")
    return own + u["dvc_per_stage_s"]


def throughput(running: int, side_by_side: dict) -> float:
    """How many stages' worth of work the host does per second with `running` stages at once: the
    measured gain at the measured count, linear below it, no more above it."""
    if side_by_side["stages"] <= 1:  # one at a time (--jobs 1 with --assume-gain): no gain to spread
        return 1.0
    measured = side_by_side["stages"] / side_by_side["slowdown"]
    k = min(running, side_by_side["stages"])
    return 1.0 + (measured - 1.0) * (k - 1) / (side_by_side["stages"] - 1)


def schedule(
    order: list[str], upstream: dict[str, set[str]], alone: dict[str, float], jobs: int, side_by_side: dict
) -> dict[str, tuple[float, float]]:
    """Each stage's (start, end) when run as tools/parallel_repro.py runs them: in `order`, once its
    upstream stages ended, at most `jobs` at once, the running ones sharing the host's throughput."""
    left, running, spans, now = dict(alone), {}, {}, 0.0
    while len(spans) < len(order):
        for stage in order:
            if len(running) < jobs and stage not in spans and stage not in running and upstream[stage] <= spans.keys():
                running[stage] = now
        rate = throughput(len(running), side_by_side) / len(running)
        step = min(left[stage] for stage in running) / rate
        now += step
        for stage in list(running):
            left[stage] -= step * rate
            if left[stage] <= 1e-9:
                spans[stage] = (running.pop(stage), now)
    return spans


def estimate(folder: str = "gpu", jobs: int = 4, overrides: tuple[str, ...] = (), gain: float | None = None) -> dict:
    """The model's seconds for a scaled pipeline from nothing (its stages, the install, the report) and the sizes behind them."""
    from parallel_repro import stage_graph
    from scaled_pipeline import PIPELINES

    from offroad_path.config import load_config

    costs, components = unit_costs()
    cfg = load_config(f"experiment={PIPELINES[folder][0]}", *overrides)
    work = sizes(cfg, costs)
    order, upstream = stage_graph(ROOT, f"{folder}/dvc.yaml")
    alone = {stage: stage_seconds(stage, work, costs) for stage in order}
    side_by_side = {"stages": jobs, "slowdown": jobs / gain} if gain else costs["side_by_side"]
    spans = schedule(order, upstream, alone, jobs, side_by_side)
    pipeline = max(end for _, end in spans.values())
    return {
        "pipeline": folder,
        "jobs": jobs,
        "sizes": work,
        "alone_s": alone,
        "spans": spans,
        "install_s": costs["install_s"],
        "pipeline_s": pipeline,
        "report_s": costs["report_s"],
        "total_s": costs["install_s"] + pipeline + costs["report_s"],
        "design": cfg.evaluate,
        "components": components,
    }


def power_rows(design, components: dict) -> list[tuple[str, str, float, float]]:
    """(primary, its role in the design, half-width, power) of each component at the design's main test set and seeds."""
    from test_set_design import BLOCKS_PER_WORLD, power

    worlds = math.ceil(design.main_test_set.min_blocks / BLOCKS_PER_WORLD)
    primaries, left_out = design.conclusions.primaries, design.conclusions.get("left_out") or {}
    level = 1 - design.conclusions.alpha / max(len(primaries), 1)
    rows = []
    for name, c in components.items():
        variances = {k: c[k] ** 2 for k in ("world", "block", "seed", "world_x_seed")}
        half, p = power(variances, worlds, len(design.seeds), c["effect"], level)
        role = "primary" if name in primaries else "left out" if name in left_out else "exploratory"
        rows.append((name, role, half, p))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pipeline", default="gpu", help="a scaled pipeline's folder (gpu, rehearsal, tour)")
    parser.add_argument("--jobs", type=int, default=4, help="stages at once, as gpu/repro.sh --jobs")
    parser.add_argument("--json", type=Path, help="write the estimate here")
    parser.add_argument(
        "--set", nargs="*", default=[], metavar="KEY=VALUE", help="overrides of the preset (sizes to try; the grid is the pipeline's)"
    )
    parser.add_argument(
        "--assume-gain",
        type=float,
        metavar="X",
        help="instead of the measured side-by-side gain: --jobs stages at once do X times one's work",
    )
    args = parser.parse_args()
    if args.jobs < 1:
        parser.error(f"--jobs: {args.jobs} is not a whole number above 0")
    found = estimate(args.pipeline, args.jobs, tuple(args.set), args.assume_gain)
    s = found["sizes"]
    print(
        f"{args.pipeline}: {s['drives']} drives, {s['main']} main test worlds, {s['stress']} stress, {s['development'] + s['retired']} "
        f"development; {s['runs']} runs x {s['seeds']} seeds, {s['steps']} SGD steps a training; "
        f"{s['policy_metres'] / 1000:.1f} km driven by all policies\n"
    )
    by_kind: dict[str, list[float]] = {}
    for stage, seconds in found["alone_s"].items():
        by_kind.setdefault(stage.split("@")[0], []).append(seconds)
    print(grid_head(["stage", "stages", "seconds each, alone", "finished at (s)"]))
    for kind, seconds in by_kind.items():
        end = max(e for stage, (_, e) in found["spans"].items() if stage.split("@")[0] == kind)
        each = f"{min(seconds):.0f}" if max(seconds) - min(seconds) < 1 else f"{min(seconds):.0f}-{max(seconds):.0f}"
        print(grid_row([kind, f"{len(seconds)}", each, f"{end:.0f}"]))
    print(
        f"\ninstall {found['install_s']:.0f} s + pipeline {found['pipeline_s']:.0f} s (--jobs {args.jobs}) + results page and archive "
        f"{found['report_s']:.0f} s = {found['total_s']:.0f} s ({found['total_s'] / 60:.1f} min)"
    )
    print("\n| primary | in the design | half-width | power |\n| --- | --- | --- | --- |")
    for name, role, half, p in power_rows(found["design"], found["components"]):
        print(grid_row([name, role, f"±{half:.3f}", f"{100 * p:.0f} %"]))
    if args.json:
        args.json.write_text(json.dumps({k: v for k, v in found.items() if k not in ("design", "components")}, indent=1) + "\n")


if __name__ == "__main__":
    main()
