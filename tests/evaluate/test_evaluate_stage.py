"""postprocess and evaluate as stages, on a real labelled drive with predictions whose scores are
known: the labels themselves (perfect) and the labels shifted sideways."""

from __future__ import annotations

import itertools
import json
import sqlite3
from pathlib import Path

import numpy as np
import pytest
from helpers import command, write_run
from helpers import evaluate_config as stage_config

from offroad_path.data.loading import load_labels
from offroad_path.data.manifest import read_manifest, read_predictions_manifest
from offroad_path.evaluate import evaluate
from offroad_path.evaluate.pixel_scores import counts, pooled
from offroad_path.evaluate.uncertainty import sample_blocks

SHIFT_PX = 24


@pytest.fixture(scope="module")
def scored(compose_config, split_dir, tmp_path_factory):
    """(rows, labels, maps, root): evaluate over two made-up runs, once for the tests that read it (they only read)."""
    root = tmp_path_factory.mktemp("scored")
    samples = read_manifest(split_dir / "test.csv")
    labels = load_labels(samples).astype(np.float32)
    made = {"unet-none": labels, "fcn-none": 0.9 * np.roll(labels, SHIFT_PX, axis=2)}
    for run, maps in made.items():
        write_run(compose_config, split_dir, root, run, 0, maps)
    write_pilotnet_predictions(samples, root / "steering" / "predictions.csv")
    # ranking, pretraining and the open loop join the family as the GPU and full presets add them
    # (conf/evaluate/primaries/seed_spread.yaml and open_loop.yaml)
    open_loop = "+evaluate/primaries@evaluate.conclusions.primaries=[seed_spread,open_loop]"
    rows = evaluate(stage_config(compose_config, split_dir, root, "evaluate.runs=[unet-none,fcn-none]", open_loop))
    return rows, labels.astype(bool), made, root


def true_steering(samples) -> np.ndarray:
    sequences = {}
    for s in samples:  # the label run's sequence folder names its source in summary.json
        if s.sequence not in sequences:
            summary = json.loads((Path(s.label).parents[2] / "summary.json").read_text())
            root = next(e["root"] for e in summary["sequences"] if e["name"] == s.sequence)
            sequences[s.sequence] = np.loadtxt(Path(root) / "steering.txt")
    return np.array([sequences[s.sequence][s.f0] * (-1 if s.mirrored else 1) for s in samples])


def write_pilotnet_predictions(samples, path: Path) -> None:
    """What train_steering writes, for a PilotNet whose every answer is 0.1 too far right."""
    path.parent.mkdir(parents=True)
    rows = [f"{s.sequence},{s.f0},{s.mirrored},{t:.6f},{t + 0.1:.6f}\n" for s, t in zip(samples, true_steering(samples), strict=True)]
    path.write_text("sequence,frame,mirrored,true,predicted\n" + "".join(rows))


def test_scores_match_the_known_predictions(scored):
    rows, labels, made, _ = scored
    perfect, perfect_post, shifted, shifted_post = rows
    assert [(r.network, r.postprocessing) for r in rows] == [("U-Net", "no"), ("U-Net", "yes"), ("FCN", "no"), ("FCN", "yes")]
    assert shifted_post.iou < perfect_post.iou
    assert perfect.iou == perfect.accuracy == perfect.recall == perfect.precision == perfect.mean_image_iou == 1.0
    predicted = made["fcn-none"] > 0.5
    tp, fp, fn = (predicted & labels).sum(), (predicted & ~labels).sum(), (~predicted & labels).sum()
    assert shifted.iou == pytest.approx(tp / (tp + fp + fn)) and shifted.recall == pytest.approx(tp / (tp + fn))
    assert shifted.accuracy == pytest.approx(1 - (fp + fn) / labels.size)
    # The blur widens a perfect path a little (its edges pass 0.5 further out): IoU falls, but not far.
    assert 0.8 < perfect_post.iou < 1.0 and perfect_post.recall > 0.95


def test_intervals_on_every_iou_and_every_comparison(scored, split_dir):
    rows, _, _, root = scored
    found = json.loads((root / "metrics.json").read_text())["uncertainty"]
    labels_dir = Path(read_manifest(split_dir / "test.csv")[0].label).parents[2]
    blocks = sample_blocks(read_manifest(split_dir / "test.csv"), labels_dir, 1.0)
    assert found["test_set"]["blocks"] == len(set(blocks)) >= 2
    perfect = {"estimate": 1.0, "low": 1.0, "high": 1.0}
    assert found["unet-none.raw"] == {"iou": 1.0, "low": 1.0, "high": 1.0} | dict.fromkeys(("precision", "recall", "accuracy"), perfect)
    shifted = found["fcn-none.raw"]
    assert shifted["low"] <= shifted["iou"] <= shifted["high"] and shifted["iou"] == pytest.approx(rows[2].iou, abs=1e-6)
    for name, value in (("precision", rows[2].precision), ("recall", rows[2].recall), ("accuracy", rows[2].accuracy)):
        assert shifted[name]["low"] <= shifted[name]["estimate"] <= shifted[name]["high"]
        assert shifted[name]["estimate"] == pytest.approx(value, abs=1e-6)
    # Steering: the perfect maps steer as the label does; paired against PilotNet on the same frames.
    steering = json.loads((root / "metrics.json").read_text())["steering_from_paths"]
    against = steering["unet-none_vs_pilotnet"]
    assert against["mae_difference"] == pytest.approx(steering["unet-none"]["mae"] - steering["pilotnet"]["mae"], abs=1e-5)
    assert against["low"] <= against["mae_difference"] <= against["high"]
    # By condition: an interval beside every group with frames in at least two blocks, around its IoU.
    groups = json.loads((root / "metrics.json").read_text())["by_condition"]
    assert groups["all"]["sequences"] == 1 and groups["all"]["unet-none.interval"] == [1.0, 1.0]
    low, high = groups["all"]["fcn-none.interval"]
    assert low <= groups["all"]["fcn-none"] <= high
    # The perfect maps beat the shifted ones in every block: the paired interval lies above 0.
    difference = found["unet-none_vs_fcn-none"]
    assert difference["iou_difference"] == pytest.approx(1 - rows[2].iou, abs=1e-6) and difference["low"] > 0
    assert set(found) == {"test_set", "unet-none.raw", "unet-none.postprocessed", "fcn-none.raw", "fcn-none.postprocessed",
                          "unet-none_vs_mean_path_prior", "fcn-none_vs_mean_path_prior", "every_scratch_run_vs_mean_path_prior",
                          "unet-none_vs_fcn-none", "unet-none_postprocessed_vs_raw", "fcn-none_postprocessed_vs_raw"}  # fmt: skip
    report = (root / "evaluation" / "results.md").read_text()
    assert "## Uncertainty" in report and "| U-Net (none) - FCN (none) |" in report
    assert found["test_set"]["worlds"] == 1  # one rendered drive: its blocks are resampled within it
    # The primaries this run makes (the central claim over the two runs without pretraining, U-Net's
    # post-processing, U-Net against PilotNet open loop), each at Holm's levels (a family of 5) around the same estimate
    # as its comparison; the others (runs not evaluated): not measured.
    primaries = json.loads((root / "metrics.json").read_text())["primaries"]
    assert set(primaries) == {"central_claim", "postprocessing", "open_loop"}
    assert primaries["open_loop"]["estimate"] == pytest.approx(against["mae_difference"], abs=1e-6)
    assert primaries["postprocessing"]["estimate"] == pytest.approx(found["unet-none_postprocessed_vs_raw"]["iou_difference"], abs=1e-6)
    for entry in primaries.values():
        levels = entry["intervals"]
        assert len(levels) == 5 and all(a[0] >= b[0] and a[1] <= b[1] for a, b in itertools.pairwise(levels))
    assert "## Primary questions" in report and "| ranking |" in report and "not measured" in report


def test_the_central_claim_rests_on_the_weakest_network_against_the_prior(scored):
    *_, root = scored
    metrics = json.loads((root / "metrics.json").read_text())
    found, prior = metrics["uncertainty"], metrics["baselines"]["mean_path_prior"]["iou"]
    # each network without pretraining minus the prior painted on every test frame, paired
    for run in ("unet-none", "fcn-none"):
        assert found[f"{run}_vs_mean_path_prior"]["iou_difference"] == pytest.approx(metrics[run]["raw"]["iou"] - prior, abs=1e-6)
    assert found["unet-none_vs_mean_path_prior"]["low"] > 0  # the labels themselves beat any one path
    # the intersection-union test is the weaker one's: the shifted maps, below the perfect ones
    weakest = found["fcn-none_vs_mean_path_prior"]
    assert found["every_scratch_run_vs_mean_path_prior"] == weakest
    assert metrics["primaries"]["central_claim"]["estimate"] == pytest.approx(weakest["iou_difference"], abs=1e-6)
    report = (root / "evaluation" / "results.md").read_text()
    assert "every network without pretraining - mean path prior (intersection-union: the weakest, fcn-none)" in report


def test_a_stress_set_is_scored_on_its_own_and_kept_out_of_the_main_figures(compose_config, split_dir, tmp_path):
    """The test drive's meta.json made a stress world of the `all` group, beside the same drive as the main
    set: its frames leave every main figure and get a row of their own against the prior."""
    from offroad_path.evaluate.scored_set import TestSet
    from offroad_path.evaluate.stress import StressSets
    from offroad_path.evaluate.uncertainty import test_bootstrap

    samples = read_manifest(split_dir / "test.csv")
    labels = load_labels(samples).astype(np.float32)
    write_run(compose_config, split_dir, tmp_path, "unet-none", 0, labels)
    cfg = stage_config(compose_config, split_dir, tmp_path, "evaluate.runs=[unet-none]", "evaluate.bootstrap.resamples=200")
    every = TestSet.read(cfg.evaluate)
    assert list(every.sets) == ["main"] * len(samples) and every.main.all()  # a meta.json without test_set: main
    every.sets = np.array(["all" if s.f0 % 2 else "main" for s in samples], dtype=object)  # every other frame: both span the blocks
    main = every.subset(every.main)
    kept = [s for s in samples if s.f0 % 2 == 0]
    half = len(kept)
    assert main.samples == kept and main.labels.shape[0] == half and main.seed_counts["unet-none", "no"][0].shape == (half, 4)
    assert (main.prior == every.prior).all()  # the training set's prior, whatever the test frames
    stress = StressSets(lambda part: test_bootstrap(cfg.evaluate, part, 1.0))
    stress.score(every)
    row = stress.metrics()["stress_sets"]["all"]
    assert row["frames"] == len(samples) - half and row["worlds"] == 1
    part = every.subset(~every.main)
    assert row["mean_path_prior"] == pytest.approx(pooled(part.prior_counts).iou, abs=1e-6)
    assert row["unet-none"]["iou"] == 1.0 and row["unet-none"]["minus_prior"] == pytest.approx(1.0 - row["mean_path_prior"], abs=1e-6)
    assert row["unet-none"]["low"] <= row["unet-none"]["minus_prior"] <= row["unet-none"]["high"]
    assert "## Stress sets" in stress.markdown() and "| all test frames | 1 |" in stress.markdown()
    main_only = StressSets(lambda part: test_bootstrap(cfg.evaluate, part, 1.0))
    main_only.score(main)
    assert main_only.markdown() == "" and main_only.metrics() == {}


def test_outputs_follow_the_contract(scored):
    *_, root = scored
    metrics = json.loads((root / "metrics.json").read_text())
    sections = {"uncertainty", "baselines", "steering_from_paths", "primaries", "by_condition"}
    assert set(metrics) == {"design", "unet-none", "fcn-none", *sections}
    assert metrics["unet-none"]["raw"]["iou"] == 1.0
    # by condition (the rendered drive's conditions.csv): the perfect maps score 1 in every group that has frames
    groups = metrics["by_condition"]
    assert groups["all"]["frames"] == len(read_predictions_manifest(root / "runs/unet-none/seed0/predictions/manifest.csv"))
    assert all(g["unet-none"] == 1.0 for g in groups.values() if g["frames"])
    assert groups["all"]["fcn-none"] == metrics["fcn-none"]["raw"]["iou"]
    assert "## Results by condition" in (root / "evaluation" / "results.md").read_text()
    assert set(metrics["baselines"]) == {
        "non_corresponding.unet-none",
        "non_corresponding.fcn-none",
        "mean_path_prior",
        "colour_classifier",
    }
    assert "| U-Net | none | no | 1.000 | 1.000 | 1.000 | 1.000 [1.000, 1.000] |" in (root / "evaluation" / "results.md").read_text()
    assert len((root / "evaluation" / "results.csv").read_text().splitlines()) == 5
    curve = np.loadtxt(root / "pr" / "unet-none.csv", delimiter=",", skiprows=1)
    assert curve.shape == (101, 3) and np.allclose(curve[1:-1, 1:], 1.0)  # perfect at every threshold inside (0, 1)
    assert sorted(p.name for p in (root / "evaluation" / "figures").iterdir()) == ["good_and_bad_cases.png", "postprocessing.png"]
    raw = read_predictions_manifest(root / "runs/unet-none/seed0/predictions/manifest.csv")
    post = read_predictions_manifest(root / "post/unet-none/seed0/manifest.csv")
    assert [s for s, _ in post] == [s for s, _ in raw]
    for (_, a), (_, b) in zip(raw, post, strict=True):
        before, after = np.load(a), np.load(b)
        assert after.dtype == np.float16 and after.shape == before.shape and Path(b).parent.parent == root / "post/unet-none/seed0"
    with sqlite3.connect(root / "mlflow.db") as db:
        (value,) = db.execute("select value from metrics where key = 'unet-none.raw.iou'").fetchone()
    assert value == 1.0


def test_steering_from_paths_against_pilotnet(scored, split_dir):
    *_, root = scored
    steering = json.loads((root / "metrics.json").read_text())["steering_from_paths"]
    assert list(steering) == [
        "straight_ahead",
        "pilotnet",
        "label_ceiling",
        "unet-none",
        "fcn-none",
        "unet-none_vs_pilotnet",
        "fcn-none_vs_pilotnet",
    ]
    true = true_steering(read_manifest(split_dir / "test.csv"))
    assert steering["straight_ahead"]["mae"] == pytest.approx(np.abs(true).mean(), abs=1e-6)
    assert steering["pilotnet"]["mae"] == pytest.approx(0.1, abs=1e-5)
    assert steering["pilotnet"]["mae_road_wheel_deg"] == pytest.approx(3.0, abs=1e-4)  # 0.1 of the 30-degree lock
    assert steering["pilotnet"]["mae_steering_wheel_deg"] == pytest.approx(45.0, abs=1e-3)  # at a steering ratio of 15
    assert steering["unet-none"] == steering["label_ceiling"]  # its maps are the labels
    assert steering["label_ceiling"]["mae"] < steering["straight_ahead"]["mae"]
    table = (root / "evaluation" / "results.md").read_text().split("## Path prediction against end-to-end steering")[1]
    assert "| PilotNet (end to end) |" in table and "| U-Net (none) + pure pursuit |" in table


@pytest.mark.slow(seconds=9)
def test_a_missing_run_names_its_manifest_and_writes_nothing(split_dir, tmp_path):
    cli = ["offroad_path.evaluate", f"split.out_dir={split_dir}", f"evaluate.runs_dir={tmp_path / 'runs'}",
           "evaluate.runs=[segnet-none]", f"evaluate.out_dir={tmp_path / 'evaluation'}", f"evaluate.metrics_path={tmp_path / 'm.json'}",
           f"evaluate.plots_dir={tmp_path / 'pr'}", "mlflow.enabled=false"]  # fmt: skip
    run = command(*cli)
    assert run.returncode == 2
    manifest = tmp_path / "runs" / "segnet-none" / "seed0" / "predictions" / "manifest.csv"
    assert run.stderr.strip().splitlines()[-1] == (
        f"error: {manifest}: missing: evaluate.seeds lists seed 0; run train seed=0 for segnet-none, or list only seeds trained"
    )
    assert not any(tmp_path.iterdir())


@pytest.mark.slow(seconds=4)
def test_several_seeds_pool_their_counts_and_show_their_spread(compose_config, split_dir, tmp_path):
    samples = read_manifest(split_dir / "test.csv")
    labels = load_labels(samples)
    seeds = {0: np.roll(labels, SHIFT_PX, axis=2), 1: np.roll(labels, 2 * SHIFT_PX, axis=2)}  # fcn: two seeds, two shifts
    for seed, maps in seeds.items():
        write_run(compose_config, split_dir, tmp_path, "unet-none", seed, labels.astype(np.float32))
        write_run(compose_config, split_dir, tmp_path, "fcn-none", seed, maps.astype(np.float32))
    write_pilotnet_predictions(samples, tmp_path / "steering" / "predictions.csv")
    evaluate(stage_config(compose_config, split_dir, tmp_path, "evaluate.runs=[unet-none,fcn-none]", "evaluate.seeds=[0,1]",
                          "mlflow.enabled=false"))  # fmt: skip
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    per_seed = [pooled(counts(maps.astype(np.float32), labels)) for maps in seeds.values()]
    summed = pooled(np.sum([counts(maps.astype(np.float32), labels) for maps in seeds.values()], axis=0))
    assert metrics["fcn-none"]["raw"]["iou"] == pytest.approx(summed.iou, abs=1e-6)  # counts pooled over the seeds
    fcn = metrics["uncertainty"]["fcn-none.raw"]
    ious = [s.iou for s in per_seed]
    assert (fcn["seed_mean"], fcn["seed_sd"]) == pytest.approx((np.mean(ious), np.std(ious, ddof=1)), abs=1e-6)
    assert metrics["uncertainty"]["unet-none.raw"]["seed_sd"] == 0 and metrics["uncertainty"]["test_set"]["seeds"] == 2
    assert "| IoU [95 % interval] | IoU over seeds, mean ± sd |" in (tmp_path / "evaluation" / "results.md").read_text()
