"""How much real driving a path network needs: test IoU on a held-out stretch of a real
drive against the number of real training frames, from random weights and from the world-trained
network of the same architecture (pretraining=world), three seeds each.

    python benchmarks/few_shot.py [--model fcn] [--sizes 0 20 40 80 all] [--seeds 0 1 2] [--steps 300]
        [--recording ../shared/data/kitti00_mono] [--other ../shared/data/kitti_seq1] [--json out.json]

Run after `dvc repro` (pretraining=world reads data/runs/<model>-none/seed<k>/checkpoints/best.ckpt).
Both KITTI drives are labelled by the label stage from their true poses, occlusion off (kitti00_mono
has one camera), every frame an f0 (label.stride_m=0.5). The test set is the held-out stretch of
kitti00_mono whose f0 lies 45-75 m along the drive: straight road, then the approach to the right
turn, so its labels bend two ways and the label-centred gain is defined. Training frames: the rest
of kitti00_mono at least `split.guard_m` (10 m) from that stretch, and every labelled frame of
kitti_seq1 (another drive), drawn per seed as nested subsets (a seed's 20 are among its 40). Every
run is the train stage itself (mirrored copies, its augmentation) for the same number of optimiser
steps whatever the number of frames, and keeps its last weights (no validation set to choose by).

Columns: IoU against each test frame's own label and against the other test frames' labels (the
shuffled control: a network that paints one path for every image scores the same on both), the
label-centred gain and the far-end correlation (evaluate/real.py), and world minus random
weights paired on the same draws; the control row fine-tunes on all frames with their labels
shuffled among the frames. Intervals: 95 % bootstrap over the test stretch's 10 m blocks and the
three seeds. Writes docs/images/few_shot.png with --figure.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
from common import label_recording

ROOT = Path(__file__).resolve().parents[1]
TEST_M = (45.0, 75.0)  # the held-out stretch of kitti00_mono: its f0 lie this far along the drive
BLOCK_M = 10.0  # the bootstrap's blocks of driving inside it


def pools(recording: Path, other: Path, work: Path, guard_m: float):
    """Label both drives; (test frames, training samples) of kitti00_mono's held-out stretch and the rest."""
    from offroad_path.config import load_config
    from offroad_path.evaluate.real import RealFrames
    from offroad_path.split import labelled_frames

    cfg = load_config()
    train, test_keys = [], []
    for drive in (recording, other):
        labels = label_recording(drive, work / f"labels_{drive.name}", "label.stride_m=0.5")
        frames, samples = labelled_frames(labels)
        for frame in frames:
            sample = samples[(frame.sequence, frame.f0)]
            inside = drive == recording and TEST_M[0] <= frame.travelled_m < TEST_M[1]
            near = drive == recording and TEST_M[0] - guard_m <= frame.travelled_m < TEST_M[1] + guard_m
            if inside:
                test_keys.append((frame.sequence, frame.f0))
            elif not near:
                train.append(sample)
        if drive == recording:
            everything = RealFrames.read(labels, BLOCK_M, cfg.label.distance_m)
            test_samples = [samples[key] for key in test_keys]
    keep = [everything.groups.index(key) for key in test_keys]
    test = replace(
        everything,
        images=[everything.images[i] for i in keep],
        labels=everything.labels[keep],
        groups=[everything.groups[i] for i in keep],
        blocks=[everything.blocks[i] for i in keep],
        direction=[everything.direction[i] for i in keep],
    )
    return test, test_samples, train


def write_split(folder: Path, train: list, test: list) -> Path:
    from offroad_path.data.manifest import Sample, write_manifest

    if folder.is_dir():  # an earlier run's, with the same --work: rescoring
        return folder
    folder.mkdir(parents=True)
    write_manifest(folder / "train.csv", [s for sample in train for s in (sample, Sample(**{**asdict(sample), "mirrored": True}))])
    write_manifest(folder / "val.csv", [])
    write_manifest(folder / "test.csv", test)
    return folder


def fine_tune(split: Path, out: Path, args: argparse.Namespace, init: str, seed: int) -> Path:
    """The train stage on `split` for args.steps optimiser steps; the checkpoint it keeps (one
    already there from an earlier run of this benchmark with the same --work is kept: rescoring)."""
    from offroad_path.config import load_config
    from offroad_path.train import train

    if (out / "checkpoints" / "best.ckpt").is_file():
        return out / "checkpoints" / "best.ckpt"

    cfg = load_config(
        f"model={args.model}",
        f"pretraining={init}",
        *([f"pretraining.checkpoint={world_checkpoint(args.model, seed)}"] if init == "world" else []),
        f"data.split_dir={split}",
        f"train.out_dir={out}",
        f"seed={seed}",
        f"train.max_steps={args.steps}",
        "trainer.max_epochs=10000",
        "train.sample_images=0",
        "resume=false",
        "mlflow.enabled=false",
    )
    train(cfg)
    return out / "checkpoints" / "best.ckpt"


def world_checkpoint(model: str, seed: int) -> Path:
    """Where pretraining=world starts from (conf/pretraining/world.yaml), in this checkout."""
    from offroad_path.config import load_config

    return ROOT / load_config(f"model={model}", "pretraining=world", f"seed={seed}").pretraining.checkpoint


def predict(checkpoints: list[Path], images: list[np.ndarray]) -> np.ndarray:
    from offroad_path.inference.runners import TorchModel

    return np.stack([TorchModel(path).predict_all(images) > 0.5 for path in checkpoints])  # (S, N, H, W)


def curve(args) -> dict:
    from offroad_path.config import load_config
    from offroad_path.evaluate.pixel_scores import counts
    from offroad_path.evaluate.real import real_row
    from offroad_path.statistics.bootstrap import Resampling, block_sums, paired_interval
    from offroad_path.statistics.scores import iou

    cfg = load_config()
    resampling = Resampling(cfg.evaluate.bootstrap.resamples, cfg.evaluate.bootstrap.seed)
    work = Path(tempfile.mkdtemp(prefix="few-shot-")) if args.work is None else args.work
    test, test_samples, pool = pools(args.recording, args.other, work, cfg.split.guard_m)
    sizes = [len(pool) if s == "all" else int(s) for s in args.sizes]
    if max(sizes) > len(pool):
        raise SystemExit(f"{max(sizes)} training frames asked for, the pool holds {len(pool)}")
    bends = np.bincount(np.array(test.direction) + 1, minlength=3).tolist()
    print(
        f"test: {len(test.labels)} frames of {args.recording.name} ({bends} bending left, straight, right), "
        f"{len(set(test.blocks))} blocks; training pool: {len(pool)} frames",
        flush=True,
    )
    runs = train_runs(args, pool, test_samples, work, sizes)
    predicted = {key: predict(paths, test.images) for key, paths in runs.items()}
    sums = {
        key: block_sums(np.stack([counts(p.astype(np.float32), test.labels) for p in seeds]), test.blocks)
        for key, seeds in predicted.items()
    }  # (S, B, 4)
    rows = []
    for (init, size), seeds in predicted.items():
        row = asdict(real_row(f"{init} {size}", seeds, test, resampling))
        if init == "world" and ("none", size) in sums:
            paired = paired_interval(sums[init, size], sums["none", size], iou, resampling)
            row |= {"world_minus_none": paired.estimate, "world_minus_none_low": paired.low, "world_minus_none_high": paired.high}
        rows.append({"init": init, "frames": size, **row})
    return {
        "paired": paired_rows(sums, resampling, len(pool)),
        "model": args.model,
        "steps": args.steps,
        "seeds": list(args.seeds),
        "test_frames": len(test.labels),
        "test_blocks": len(set(test.blocks)),
        "test_bends_left_straight_right": bends,
        "pool_frames": len(pool),
        "rows": rows,
    }


def shuffled_labels(samples: list, rng: np.random.Generator) -> list:
    """The samples with their labels permuted among the frames of the same recording (one image size)."""
    from offroad_path.data.manifest import Sample

    out = list(samples)
    for sequence in sorted({s.sequence for s in samples}):
        index = [i for i, s in enumerate(samples) if s.sequence == sequence]
        for i, j in zip(index, rng.permutation(index), strict=True):
            out[i] = Sample(**{**asdict(samples[i]), "label": samples[j].label})
    return out


def train_runs(args: argparse.Namespace, pool: list, test_samples: list, work: Path, sizes: list[int]) -> dict[tuple[str, int], list[Path]]:
    """The checkpoints of every (initialisation, frames), one per seed: 0 frames is the world network
    itself; 'shuffled' fine-tunes the world network on every frame with the labels permuted."""
    orders = {seed: np.random.default_rng(seed).permutation(len(pool)) for seed in args.seeds}
    runs: dict[tuple[str, int], list[Path]] = {}
    started = time.perf_counter()
    cases = [(init, size) for size in sizes for init in ("none", "world") if size or init == "world"]  # random weights untrained: nothing
    cases += [("shuffled", len(pool))] if args.shuffled else []
    for init, size in cases:
        runs[init, size] = []
        for seed in args.seeds:
            if size == 0:
                runs[init, size].append(world_checkpoint(args.model, seed))
                continue
            chosen = [pool[i] for i in orders[seed][:size]]
            if init == "shuffled":
                chosen = shuffled_labels(chosen, np.random.default_rng(1000 + seed))
            name = f"{init}-{size}-seed{seed}"
            split = (
                work / "splits" / name if (work / "splits" / name).is_dir() else write_split(work / "splits" / name, chosen, test_samples)
            )
            runs[init, size].append(fine_tune(split, work / "runs" / name, args, "world" if init == "shuffled" else init, seed))
            print(f"  {name}: {time.perf_counter() - started:.0f} s", flush=True)
    return runs


def paired_rows(sums: dict, resampling, pool: int) -> list[dict]:
    """IoU differences on the same resampled blocks and seeds: every fine-tuned network minus the world
    network it started from (0 frames), and real labels minus shuffled ones (every frame)."""
    from offroad_path.statistics.bootstrap import paired_interval
    from offroad_path.statistics.scores import iou

    pairs = [((init, size), ("world", 0)) for init, size in sums if size and init != "shuffled"]
    pairs += [(("world", pool), ("shuffled", pool))] if ("shuffled", pool) in sums else []
    rows = []
    for a, b in pairs:
        found = paired_interval(sums[a], sums[b], iou, resampling)
        rows.append({"a": f"{a[0]} {a[1]}", "b": f"{b[0]} {b[1]}", "difference": found.estimate, "low": found.low, "high": found.high})
    return rows


def table(result: dict) -> str:
    lines = [
        "| initialisation | real training frames | IoU [95 %] | vs other frames' labels | label-centred gain [95 %] | "
        "far-end correlation [95 %] | world minus random [95 %] |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in result["rows"]:
        paired = (
            f"{r['world_minus_none']:+.3f} [{r['world_minus_none_low']:+.3f}, {r['world_minus_none_high']:+.3f}]"
            if "world_minus_none" in r
            else ""
        )
        lines.append(
            f"| {r['init']} | {r['frames']} | {r['iou']:.3f} [{r['iou_low']:.3f}, {r['iou_high']:.3f}] | "
            f"{r['non_corresponding_iou']:.3f} | "
            f"{r['gain']:+.3f} [{r['gain_low']:+.3f}, {r['gain_high']:+.3f}] | "
            f"{r['far_end']:+.2f} [{r['far_end_low']:+.2f}, {r['far_end_high']:+.2f}] | {paired} |"
        )
    lines += ["", "| paired IoU difference | estimate [95 %] |", "| --- | --- |"]
    lines += [f"| {r['a']} minus {r['b']} | {r['difference']:+.3f} [{r['low']:+.3f}, {r['high']:+.3f}] |" for r in result["paired"]]
    return "\n".join(lines)


def figure(result: dict, path: Path) -> None:
    """Test IoU against real training frames, both initialisations and the control, with 95 % intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 3.8), dpi=120)
    styles = {
        "none": ("random weights", "o-"),
        "world": ("from the world (pretraining=world)", "s-"),
        "shuffled": ("world, labels shuffled", "x"),
    }
    for init, (title, style) in styles.items():
        rows = sorted((r for r in result["rows"] if r["init"] == init), key=lambda r: r["frames"])
        if rows:
            x = np.array([r["frames"] for r in rows]) + {"none": -1.0, "world": 1.0, "shuffled": 0.0}[init]
            y = np.array([r["iou"] for r in rows])
            err = np.array([[r["iou"] - r["iou_low"] for r in rows], [r["iou_high"] - r["iou"] for r in rows]])
            ax.errorbar(x, y, yerr=err, fmt=style, capsize=3, label=title)
    ax.set_xlabel("real training frames")
    ax.set_ylabel("test IoU, held-out stretch")
    ax.set_title(f"{result['model']} on kitti00_mono, {len(result['seeds'])} seeds, 95 % intervals", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=ROOT.parent / "shared/data/kitti00_mono")
    parser.add_argument("--other", type=Path, default=ROOT.parent / "shared/data/kitti_seq1")
    parser.add_argument("--model", default="fcn")
    parser.add_argument("--sizes", nargs="+", default=["0", "20", "40", "80", "all"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2])
    parser.add_argument("--steps", type=int, default=300)
    parser.add_argument("--no-shuffled", dest="shuffled", action="store_false", help="skip the shuffled-label control")
    parser.add_argument("--work", type=Path, default=None, help="keep labels, splits and runs here (default: a temporary folder)")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--figure", type=Path, default=None, help="e.g. docs/images/few_shot.png")
    args = parser.parse_args()
    for drive in (args.recording, args.other):
        if not (drive / "poses.txt").is_file():
            sys.exit(f"{drive}: not found (a recording with poses.txt); nothing measured")
    result = curve(args)
    print(table(result))
    if args.json:
        args.json.write_text(json.dumps(result, indent=2) + "\n")
    if args.figure:
        figure(result, args.figure)


if __name__ == "__main__":
    main()
