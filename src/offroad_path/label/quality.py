"""How good a label run is, per sequence, from the label stage's outputs and the recording: what
`python -m offroad_path.label.inspect` shows in Rerun and sums up in one figure per recording.

The footprint check: each label's vehicle footprint is drawn on the ground with the configured
camera height and pitch, so it has a depth at every pixel it covers; the stereo depth of f0 says
where the ground really is. Their ratio (stereo / footprint) is 1 when the geometry is right. A
camera set too high puts the footprint below the ground (ratio < 1: the labels sink), too low above
it (ratio > 1: they float); scaling the height by the median ratio gives the height the stereo
implies. A wrong pitch instead makes the ratio change with distance (near against far).
"""

from __future__ import annotations

import csv
import itertools
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from offroad_path.sequence.footprint import footprint_depth
from offroad_path.sequence.poses import read_poses
from offroad_path.sequence.reader import Sequence

RELIABLE_DEPTH_M = 15.0  # farther, a pixel of disparity is too much depth to judge the ground by
TOLERANCE = 0.1  # a median ratio (or a near-far difference) beyond 10 % is flagged
NEAR_M, FAR_M = 6.0, 10.0  # the pitch check's near and far ranges (footprint depth)


def read_rows(path: Path) -> list[dict]:
    if not path.is_file():
        return []
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@dataclass
class LabelRun:
    """One sequence's label outputs (docs/design.md, the label stage's contract)."""

    folder: Path
    poses: np.ndarray | None  # (N, 4, 4) the poses the labels were made from (VO's, or a file's copied beside them)
    steps: list[dict]
    segments: list[dict]
    drift: list[dict]

    @classmethod
    def read(cls, folder: Path) -> LabelRun:
        made_from = [folder / name for name in ("poses_vo.txt", "poses.txt") if (folder / name).is_file()]
        return cls(
            folder,
            read_poses(made_from[0]) if made_from else None,
            read_rows(folder / "steps.csv"),
            read_rows(folder / "report.csv"),
            read_rows(folder / "drift.csv"),
        )

    @property
    def kept(self) -> list[dict]:
        return [s for s in self.segments if s["kept"] == "True"]

    def disparity(self, f0: int) -> np.ndarray:
        """f0's disparity in pixels (KITTI format: uint16 = 256 x disparity), 0 where unknown."""
        return cv2.imread(str(self.folder / "disparity" / f"{f0:06d}.png"), cv2.IMREAD_UNCHANGED).astype(np.float64) / 256.0


@dataclass
class FootprintCheck:
    """Stereo depth over footprint depth on the pixels the footprints cover (within RELIABLE_DEPTH_M)."""

    ratios: list[np.ndarray] = field(default_factory=list)  # per label: (n,) ratios
    depths: list[np.ndarray] = field(default_factory=list)  # per label: (n,) footprint depths

    def add(self, seq: Sequence, disparity: np.ndarray, polygons: list[np.ndarray]) -> None:
        """One label: f0's disparity (pixels) and the label's footprint polygons in f0's camera frame (footprint.swept_polygons)."""
        z = footprint_depth(polygons, seq.calibration.K, seq.image_size)
        valid = np.isfinite(z) & (z < RELIABLE_DEPTH_M) & (disparity > 0)
        stereo = seq.calibration.fx * seq.calibration.baseline_m / disparity[valid]
        self.ratios.append(stereo / z[valid])
        self.depths.append(z[valid])

    def all(self) -> tuple[np.ndarray, np.ndarray]:
        return (np.concatenate(self.ratios), np.concatenate(self.depths)) if self.ratios else (np.zeros(0), np.zeros(0))

    def verdict(self, camera_height_m: float) -> dict:
        """The median ratio, the height it implies, the near and far medians, and which check flags what."""
        ratio, depth = self.all()
        if not len(ratio):
            return {"pixels": 0, "flags": ["no footprint pixel has stereo depth: nothing to check"]}
        median = float(np.median(ratio))
        near, far = ratio[depth < NEAR_M], ratio[depth >= FAR_M]
        out = {
            "pixels": len(ratio),
            "median_ratio": median,
            "implied_camera_height_m": camera_height_m * median,
            "near_ratio": float(np.median(near)) if len(near) else None,
            "far_ratio": float(np.median(far)) if len(far) else None,
        }
        flags = []
        if median < 1 - TOLERANCE:
            flags.append(
                f"height: labels sink (stereo/footprint {median:.2f}): camera_height_m {camera_height_m:g} is too large; "
                f"the stereo implies {out['implied_camera_height_m']:.2f} m"
            )
        elif median > 1 + TOLERANCE:
            flags.append(
                f"height: labels float (stereo/footprint {median:.2f}): camera_height_m {camera_height_m:g} is too small; "
                f"the stereo implies {out['implied_camera_height_m']:.2f} m"
            )
        if out["near_ratio"] is not None and out["far_ratio"] is not None and abs(out["far_ratio"] - out["near_ratio"]) > TOLERANCE:
            way = "too small" if out["far_ratio"] > out["near_ratio"] else "too large"
            flags.append(
                f"pitch: the ratio goes from {out['near_ratio']:.2f} under {NEAR_M:g} m to {out['far_ratio']:.2f} beyond "
                f"{FAR_M:g} m: camera_pitch_deg looks {way}"
            )
        out["flags"] = flags
        return out


def drift_per_segment(run: LabelRun) -> np.ndarray:
    """(M,) translation drift in % of each ~label.distance_m segment (drift.csv), empty without recorded poses."""
    return np.array([float(r["translation_pct"]) for r in run.drift])


def summary_figure(name: str, runs: dict[str, LabelRun], checks: dict[str, dict], path: Path) -> None:
    """One page per recording: drift per segment, label coverage and drops, the footprint check."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, 2, figsize=(12, 8), constrained_layout=True)
    ax = axes[0, 0]
    for seq, run in runs.items():
        drift = drift_per_segment(run)
        if len(drift):
            ax.plot(drift, marker=".", label=seq)
    ax.set(title="VO drift per segment (against the recording's poses)", xlabel="segment (by f0)", ylabel="translation drift, %")
    if ax.lines:
        ax.legend(fontsize=6, ncol=3)
    else:
        ax.text(0.5, 0.5, "no recorded poses to compare with", ha="center", transform=ax.transAxes)
    ax = axes[0, 1]
    names = list(runs)
    kept = [len(r.kept) for r in runs.values()]
    reasons = sorted({s["reason"] or "dropped" for r in runs.values() for s in r.segments if s["kept"] != "True"})
    ax.bar(names, kept, label="kept")
    bottom = np.array(kept, float)
    for reason in reasons:
        counts = np.array(
            [sum(1 for s in r.segments if s["kept"] != "True" and (s["reason"] or "dropped") == reason) for r in runs.values()]
        )
        ax.bar(names, counts, bottom=bottom, label=reason[:60])
        bottom += counts
    ax.set(title="label coverage: segments kept and dropped, by reason", ylabel="segments")
    ax.legend(fontsize=7)
    ax.tick_params(axis="x", labelrotation=30, labelsize=7)
    ax = axes[1, 0]
    for seq, check in checks.items():
        if check.get("pixels"):
            ax.plot(check["curve_depth"], check["curve_ratio"], marker=".", label=seq)
    ax.axhline(1.0, color="k", lw=0.8)
    ax.axhspan(1 - TOLERANCE, 1 + TOLERANCE, color="g", alpha=0.1)
    ax.set(
        title="footprint against stereo: <1 sinks, >1 floats; a slope is a pitch error",
        xlabel="footprint depth, m",
        ylabel="median stereo / footprint depth",
    )
    if ax.lines[1:]:
        ax.legend(fontsize=6, ncol=3)
    ax = axes[1, 1]
    ax.axis("off")
    lines = []
    for seq, check in checks.items():
        head = f"{seq}: {check.get('pixels', 0):,} px"
        if check.get("median_ratio") is not None:
            head += f", ratio {check['median_ratio']:.3f}, implied height {check['implied_camera_height_m']:.2f} m"
        lines += [head + ("" if check["flags"] else ", no flag"), *(f"  FLAG {f}" for f in check["flags"])]
    ax.text(0, 1, "\n".join(lines) or "no recording given: no footprint check", va="top", family="monospace", fontsize=6, wrap=True)
    fig.suptitle(f"labels in {name}")
    fig.savefig(path, dpi=90)
    plt.close(fig)


def ratio_curve(check: FootprintCheck, bins: np.ndarray) -> tuple[list[float], list[float]]:
    """Median ratio per footprint-depth bin (bins with pixels only)."""
    ratio, depth = check.all()
    centres, medians = [], []
    for lo, hi in itertools.pairwise(bins):
        inside = (depth >= lo) & (depth < hi)
        if inside.sum() >= 20:
            centres.append(float((lo + hi) / 2))
            medians.append(float(np.median(ratio[inside])))
    return centres, medians
