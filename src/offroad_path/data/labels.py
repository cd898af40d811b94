"""Reading a label run (the label stage's output): its summary, and per sequence the recording,
the folder of labels and disparities, and the poses the labels were made from."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from offroad_path.errors import InputError
from offroad_path.geometry.path import distance_along
from offroad_path.sequence.poses import read_poses
from offroad_path.sequence.reader import Sequence, open_sequence

SHARD_FILE = "shard.json"  # in a label shard's folder (label/shards.py): a shard is not a whole run


@dataclass(frozen=True)
class LabelledSequence:
    name: str
    sequence: Sequence
    folder: Path  # <labels_dir>/<name>: label/, disparity/ (stereo), poses_vo.txt and steps.csv (VO) or poses.txt (a file's)
    poses: np.ndarray  # (N, 4, 4): the poses the labels were made from

    def distance(self) -> np.ndarray:
        """(N,) metres driven at each frame, along `poses`."""
        return distance_along(self.poses)

    def labels(self) -> list[Path]:
        """The label PNGs, NNNNNN.png named by their f0, in frame order."""
        return sorted((self.folder / "label").glob("*.png"))


def label_run_folders(labels_dir: str | Path) -> list[Path]:
    """The label run and the recordings its summary.json names, for the output rule
    (utils.outputs); just the run when its summary cannot be read (the stage reports that)."""
    try:
        entries = json.loads((Path(labels_dir) / "summary.json").read_text())["sequences"]
        return [Path(labels_dir), *(Path(e["root"]) for e in entries)]
    except (OSError, ValueError, KeyError, TypeError):
        return [Path(labels_dir)]


def read_label_run(labels_dir: Path) -> list[LabelledSequence]:
    """Every sequence of the label run in labels_dir, in the order of its summary.json."""
    summary_path = labels_dir / "summary.json"
    if not summary_path.is_file():
        raise FileNotFoundError(f"{summary_path}: missing (run the label stage first)")
    if (labels_dir / SHARD_FILE).is_file():
        raise InputError(
            labels_dir, "is one shard of a sharded label run, not a whole run: merge the shards first (label.merge_from=<their folder>)"
        )
    out = []
    for entry in json.loads(summary_path.read_text())["sequences"]:
        name, seq = entry["name"], open_sequence(entry["root"])
        made_from = [labels_dir / name / f for f in ("poses_vo.txt", "poses.txt") if (labels_dir / name / f).is_file()]
        poses = read_poses(made_from[0], len(seq)) if made_from else seq.poses
        out.append(LabelledSequence(name, seq, labels_dir / name, poses))
    return out
