"""The README's "Check your labels" figures from the committed pipeline's labels: runs
`python -m offroad_path.label.inspect data/labels --recording data/synthetic`, copies the summary
page, and draws one sequence's .rrd, read back with rerun.chunk.RrdReader, as a still (no browser
runs here to screenshot the viewer): the image with its label at one labelled frame, and the scene
from above (trajectories, that label's footprints, that frame's point cloud). Prints the time taken.

    python benchmarks/inspect_figures.py [--sequence test_000] [--frame 30] [--out /tmp/labels_inspect]
"""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

import cv2
import matplotlib
import numpy as np

from offroad_path.label.inspect import main as inspect

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def rows(rrd: Path) -> dict[str, list[tuple[int | None, dict]]]:
    """{entity: [(frame or None when static, {component: value})]} of a .rrd file."""
    from rerun.chunk import RrdReader

    found: dict[str, list] = {}
    for chunk in RrdReader(rrd).stream().to_chunks():
        table = chunk.to_record_batch().to_pylist()
        for row in table:
            values = {k: v for k, v in row.items() if ":" in k and v is not None}
            if values:
                found.setdefault(str(chunk.entity_path), []).append((row.get("frame"), values))
    return found


def at(entity: list, frame: int | None, component: str):
    """The latest value of `component` logged at or before `frame` (a static one when frame is None)."""
    chosen = None
    for when, values in entity:
        if component in values and (when is None or frame is None or when <= frame):
            chosen = values[component]
    return chosen


def draw(rrd: Path, frame: int, path: Path) -> None:
    logged = rows(rrd)
    image = cv2.imdecode(np.frombuffer(bytes(at(logged["/world/camera/image"], frame, "EncodedImage:blob")[0]), np.uint8), cv2.IMREAD_COLOR)
    label_format = at(logged["/world/camera/image/label"], frame, "SegmentationImage:format")[0]
    label = np.asarray(at(logged["/world/camera/image/label"], frame, "SegmentationImage:buffer")[0], np.uint8)
    label = label.reshape(label_format["height"], label_format["width"])
    shown = image[:, :, ::-1].copy()
    shown[label > 0] = (0.5 * shown[label > 0] + 0.5 * np.array([0, 220, 0])).astype(np.uint8)
    fig, axes = plt.subplots(1, 2, figsize=(14, 4.6), gridspec_kw={"width_ratios": [1.6, 1]}, constrained_layout=True)
    axes[0].imshow(shown)
    axes[0].set(title=f"world/camera/image and its label at frame {frame}")
    axes[0].axis("off")
    ax = axes[1]
    points = np.asarray(at(logged["/world/points"], frame, "Points3D:positions"))
    colours = np.asarray(at(logged["/world/points"], frame, "Points3D:colors"), np.uint32)
    rgb = np.stack([(colours >> 24) & 255, (colours >> 16) & 255, (colours >> 8) & 255], axis=1) / 255.0
    ax.scatter(points[:, 0], points[:, 2], s=0.3, c=rgb)
    for strip in at(logged["/world/footprint"], frame, "LineStrips3D:strips"):
        xyz = np.asarray(strip)
        ax.plot(xyz[:, 0], xyz[:, 2], color=(0, 0.75, 0), lw=0.6)
    for entity, colour, name in (("/world/recorded_trajectory", (0.3, 0.6, 1), "recorded poses"),
                                 ("/world/vo_trajectory", (1, 0.55, 0), "VO")):  # fmt: skip
        xyz = np.asarray(at(logged[entity], None, "LineStrips3D:strips")[0])
        ax.plot(xyz[:, 0], xyz[:, 2], color=colour, lw=1.5, label=name)
    ax.set(title="from above: trajectories, the label's footprints, the point cloud", xlabel="x, m", ylabel="z, m", aspect="equal")
    ax.legend(fontsize=8)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sequence", default="test_000")
    parser.add_argument("--frame", type=int, default=30)
    parser.add_argument("--out", type=Path, default=Path("/tmp/labels_inspect"))
    args = parser.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    start = time.perf_counter()
    inspect(["data/labels", "--recording", "data/synthetic", "--out", str(args.out)])
    print(f"inspect took {time.perf_counter() - start:.1f} s")
    shutil.copy(args.out / "summary.png", "docs/images/label_summary.png")
    draw(args.out / f"{args.sequence}.rrd", args.frame, Path("docs/images/inspect_view.png"))
    print("wrote docs/images/label_summary.png and docs/images/inspect_view.png")


if __name__ == "__main__":
    main()
