"""Path prediction against end-to-end steering, on the same test frames: a steering angle from
each network's predicted path (pure pursuit, offroad_path.steering.pure_pursuit), from the
ground-truth path label (the ceiling of the method), PilotNet's own prediction, and always straight
ahead, each scored by the mean absolute error of the normalised angle and in degrees."""

from __future__ import annotations

import csv
import logging
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from offroad_path.data.labels import read_label_run
from offroad_path.data.manifest import Sample, parse_boolean
from offroad_path.steering.pure_pursuit import GroundCamera, steering_from_path

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class FrameGeometry:
    """What steering from a path needs of one test frame, and its true steering."""

    camera: GroundCamera
    wheelbase_m: float
    lock_deg: float  # road-wheel angle of normalised steering 1
    true: float  # normalised, negated for a mirrored frame


@dataclass(frozen=True)
class SteeringRow:
    method: str
    frames: int
    no_path: int = field(metadata={"title": "frames without a path (steered straight), over all seeds"})
    mae: float = field(metadata={"title": "MAE (normalised)"})
    mae_road_wheel_deg: float = field(metadata={"title": "MAE, road wheels (deg)"})
    mae_steering_wheel_deg: float = field(metadata={"title": "MAE, steering wheel (deg)"})


def frame_geometry(samples: list[Sample], labels_dir: Path) -> list[FrameGeometry] | None:
    """Per test sample; None when a sequence lacks steering.txt or the vehicle's wheelbase (real recordings)."""
    runs = {run.name: run.sequence for run in read_label_run(labels_dir)}
    out = []
    for s in samples:
        seq = runs[s.sequence]
        vehicle = seq.meta.get("vehicle", {})
        if seq.steering is None or "wheelbase_m" not in vehicle:
            log.info("%s has no steering.txt or no wheelbase in meta.json: no steering from paths", s.sequence)
            return None
        K = seq.calibration.K
        if s.mirrored:
            K[0, 2] = seq.image_size[0] - 1 - K[0, 2]
        camera = GroundCamera(
            K, seq.meta["camera_height_m"], seq.meta.get("camera_pitch_deg", 0.0), vehicle["camera_forward_m"] + vehicle["wheelbase_m"] / 2
        )
        true = float(seq.steering[s.f0]) * (-1 if s.mirrored else 1)
        out.append(FrameGeometry(camera, vehicle["wheelbase_m"], vehicle["max_steering_deg"], true))
    return out


def pursued(paths: np.ndarray, geometry: list[FrameGeometry], lookahead_m: float) -> tuple[np.ndarray, int]:
    """Normalised steering from (N, H, W) binary paths, and how many had no path (steered straight)."""
    angles, missing = [], 0
    for path, g in zip(paths, geometry, strict=True):
        delta = steering_from_path(path, g.camera, lookahead_m, g.wheelbase_m)
        missing += delta is None
        angles.append(0.0 if delta is None else np.clip(math.degrees(delta) / g.lock_deg, -1.0, 1.0))
    return np.asarray(angles), missing


def pilotnet_predictions(path: Path, samples: list[Sample]) -> np.ndarray | None:
    """PilotNet's predictions (train_steering's predictions.csv) for the samples, or None when absent."""
    if not path.is_file():
        log.info("%s: no PilotNet predictions, no PilotNet row", path)
        return None
    found = {}
    with open(path, newline="") as f:
        for number, r in enumerate(csv.DictReader(f), start=2):
            try:
                found[r["sequence"], int(r["frame"]), parse_boolean(r["mirrored"])] = float(r["predicted"])
            except (KeyError, ValueError, TypeError, AttributeError) as e:
                raise ValueError(f"{path}: row {number} is malformed ({e})") from e
    missing = [s for s in samples if (s.sequence, s.f0, s.mirrored) not in found]
    if missing:
        raise ValueError(f"{path}: has no prediction for test frame {missing[0].sequence}/{missing[0].f0} (retrain on the same split)")
    return np.array([found[s.sequence, s.f0, s.mirrored] for s in samples])


def steering_row(method: str, predicted: np.ndarray, geometry: list[FrameGeometry], no_path: int, steering_ratio: float) -> SteeringRow:
    """predicted: (N,) or per training seed (S, N); the errors pool the seeds."""
    true = np.array([g.true for g in geometry])
    lock = np.array([g.lock_deg for g in geometry])
    error = np.abs(predicted - true)  # (N,) or (S, N)
    road = float((error * lock).mean())
    return SteeringRow(method, len(true), no_path, float(error.mean()), road, road * steering_ratio)


@dataclass
class SteeringComparison:
    """The table's rows by metric key, gathered while the runs are scored (their maps are loaded
    once, there): straight_ahead, pilotnet, one per run, label_ceiling. A run's and PilotNet's rows
    pool their training seeds; `errors` keeps them apart, (S, N), for the hierarchical bootstrap."""

    e: DictConfig  # evaluate's config
    geometry: list[FrameGeometry] | None = None
    rows: dict[str, SteeringRow] = field(default_factory=dict)
    errors: dict[str, np.ndarray] = field(default_factory=dict)  # key -> (S, N) absolute error (normalised), S = 1 without seeds

    def start(self, samples: list[Sample], labels: np.ndarray, seeds: list[int]) -> None:
        self.geometry = frame_geometry(samples, Path(self.e.labels_dir))
        if self.geometry is None:
            return
        self._row("straight_ahead", "always straight ahead", np.zeros((1, len(samples))))
        predictions = self.e.steering_from_paths.pilotnet_predictions  # null: no PilotNet row; {seed}: each seed's file
        found = [pilotnet_predictions(Path(predictions.replace("{seed}", str(seed))), samples) for seed in seeds] if predictions else [None]
        if all(p is not None for p in found):
            self._row("pilotnet", "PilotNet (end to end)", np.stack(found))
        self._pursued("label_ceiling", "ground-truth path label + pure pursuit (the ceiling)", [labels])

    def add(self, key: str, method: str, paths: list[np.ndarray]) -> None:
        """paths: (N, H, W) binary paths of each training seed."""
        if self.geometry is not None:
            self._pursued(key, method, paths)

    def _pursued(self, key: str, method: str, paths: list[np.ndarray]) -> None:
        found = [pursued(p, self.geometry, self.e.steering_from_paths.lookahead_m) for p in paths]
        self._row(key, method, np.stack([angles for angles, _ in found]), sum(missing for _, missing in found))

    def _row(self, key: str, method: str, predicted: np.ndarray, no_path: int = 0) -> None:
        self.rows[key] = steering_row(method, predicted, self.geometry, no_path, self.e.steering_from_paths.steering_ratio)
        self.errors[key] = np.abs(predicted - np.array([g.true for g in self.geometry]))

    def table(self) -> list[SteeringRow]:
        """Baselines, the networks, the ceiling last."""
        return sorted(self.rows.values(), key=lambda row: row.method.startswith("ground-truth"))
