"""Schemas of evaluate (its bootstrap, temporal filter and primaries) and of the closed-loop drive."""

from __future__ import annotations

from dataclasses import dataclass, field

from omegaconf import MISSING

from offroad_path.config.common import IMAGE_SIZE, PRETRAININGS, model_names
from offroad_path.config.world_schema import VehicleConfig
from offroad_path.utils.rules import SEED, at_least, between, distinct, each, one_of, ordered_pair, positive, setting, torch_device


@dataclass
class SteeringFromPathsConfig:
    lookahead_m: float = setting(positive())  # pure pursuit's look-ahead distance from the rear axle
    steering_ratio: float = setting(positive())  # steering-wheel degrees per road-wheel degree
    pilotnet_predictions: str | None = MISSING  # train_steering's predictions.csv, {seed} for the seed; None: no PilotNet row


@dataclass
class TemporalConfig:
    enabled: bool = MISSING  # every frame of the test blocks, with and without the temporal filter (synthetic test sets)
    alpha: float = setting(between(0, 1, low_open=True))  # the current frame's weight in the fused confidence


@dataclass
class BootstrapConfig:
    """Intervals by resampling the test set's blocks of driving (offroad_path.statistics.bootstrap)."""

    resamples: int = setting(at_least(100))
    seed: int = setting(SEED)
    level: float = setting(between(0, 1, low_open=True, high_open=True))


# The drive's arguments against end-to-end steering (the keys of drive.arguments), each with the
# question it asks; the drive reports each under its name.
DRIVE_ARGUMENTS = {
    "steering": "(a) closed loop: does predicting the path drive better than predicting the steering?",
    "vehicle": "(b) another vehicle: the same networks on a vehicle with 1.5 x the wheelbase, another lock and a higher camera",
    "traction": "(c) traction: the same networks on ground where the vehicle turns less than the bicycle model says (world.slip)",
}
# The report sections a primary's compare may name, each with the quantity its comparisons measure:
# the evaluate stage's two, then the drive's arguments.
PRIMARY_SECTIONS = {"uncertainty": "IoU", "steering_from_paths": "steering error"} | dict.fromkeys(DRIVE_ARGUMENTS, "interventions per km")
# The paper's central claim as one comparison of the uncertainty section: every run without pretraining
# above the mean-path prior, an intersection-union test (Berger 1982): it rejects when each run's own
# comparison rejects, so it is answered by the weakest of them (the largest p-value; one at or below the
# prior when there is such a run).
EVERY_SCRATCH_VS_PRIOR = "every_scratch_run_vs_mean_path_prior"


@dataclass
class PrimaryConfig:
    """One primary question, declared before the run (offroad_path.statistics.primaries)."""

    claim: str = MISSING  # the claim it tests, in words
    # Which comparison answers it: <section>/<key> of the report that owns it, e.g.
    # uncertainty/unet-none_vs_segnet-none (evaluate) or steering/unet-segmentation_vs_pilotnet (drive).
    compare: str = MISSING
    # drive only: the planning rates (interventions per km, a then b) its power is computed from
    planning_per_km: list[float] | None = None
    # the smallest difference that matters, in the estimate's units: an interval within it of no
    # difference reads "no material difference" (statistics.primaries); None: none declared
    smallest_effect: float | None = None
    # the effect the design is sized to detect with `power` at Holm's strictest level (docs/conclusions.md)
    planning_effect: float | None = None


@dataclass
class ConclusionsConfig:
    """The primary questions and their family-wise error (Holm)."""

    alpha: float = setting(between(0, 1, low_open=True, high_open=True))  # family-wise, two-sided
    power: float = setting(between(0, 1, low_open=True, high_open=True))  # the drive's target power per primary
    primaries: dict[str, PrimaryConfig] = MISSING
    left_out: dict[str, str] = MISSING  # a question the design cannot power: why ({}: none; one a preset adds to primaries is asked)


@dataclass
class MainTestSetConfig:
    """The main test set the design was sized for (synthesize.test_worlds reads both)."""

    stream: int = setting(at_least(5))  # its spawn key (offroad_path.world.held_out)
    min_blocks: int = setting(at_least(0))


@dataclass
class EvaluateConfig:
    architectures: list[str] = setting(each(one_of(model_names)))
    pretrainings: list[str] = setting(each(one_of(PRETRAININGS)))
    seeds: list[int] = setting(distinct(at_least(0), nonempty=True))  # training seeds of every run: data/runs/<run>/seed<k>
    main_test_set: MainTestSetConfig = field(default_factory=MainTestSetConfig)
    drive_seeds: list[int] = setting(distinct(at_least(0)))  # the closed loop's (drive.seeds; the slip and curvature PilotNets')
    runs: list[str] = MISSING  # <architecture>-<pretraining>; conf/ takes the grid of the two lists
    runs_dir: str = MISSING  # <run>/predictions from train
    postprocessed_dir: str = MISSING  # <run>/ from postprocess
    labels_dir: str = MISSING  # the label run: steering, calibration and vehicle of each test frame
    steering_from_paths: SteeringFromPathsConfig = field(default_factory=SteeringFromPathsConfig)
    train_manifest: str = MISSING  # for the mean-path prior
    temporal: TemporalConfig = field(default_factory=TemporalConfig)
    bootstrap: BootstrapConfig = field(default_factory=BootstrapConfig)
    conclusions: ConclusionsConfig = field(default_factory=ConclusionsConfig)
    real_labels_dir: str | None = MISSING  # a label run of real footage: every network scored on it too (null: none)
    notice: str | None = MISSING  # a line above results.md and in the metrics (a smoke run says so); null: none
    colour_baseline_pixels: int = setting(at_least(0))  # training pixels per frame of the colour baseline (0: none)
    threshold: float = setting(between(0, 1))  # path where C > threshold
    pr_thresholds: int = setting(at_least(2))
    out_dir: str = MISSING  # results table, figures
    metrics_path: str = MISSING
    plots_dir: str = MISSING  # one CSV per run, for `dvc plots`
    figure_scale: float = setting(between(0, 1, low_open=True))  # figures at half the label size keep the PNGs small
    figure_cases: int = setting(at_least(1))  # good and bad cases per network in Fig. 8, and raised and lowered in Fig. 5


@dataclass
class DriveConfig:
    """Closed-loop driving in the test worlds (offroad_path.drive)."""

    synthetic_dir: str = MISSING
    runs_dir: str = MISSING
    seeds: list[int] = setting(distinct(at_least(0), nonempty=True))  # every policy drives once with each training seed's networks
    pilotnets: dict[str, str] = MISSING  # end-to-end policy name -> train_steering checkpoint, {seed} for the seed
    out_dir: str = MISSING
    metrics_path: str = MISSING
    arguments: dict[str, list[str]] = MISSING  # steering | vehicle | traction -> policy names
    worlds: int | None = setting(at_least(1))
    starts_per_world: int = setting(at_least(1))
    length_m: float = setting(positive())
    width: int = setting(IMAGE_SIZE)
    height: int = setting(IMAGE_SIZE)
    rate_hz: float = setting(positive())
    speed_mps: float = setting(positive())
    steering_rate_deg_s: float = setting(positive())
    corridor_m: float = setting(positive())
    body_band_m: tuple[float, float] = setting(ordered_pair(0, float("inf")))
    foliage_is_obstacle: bool = MISSING
    water_intervenes: bool = MISSING
    respawn_m: float = setting(positive())
    intervention_s: float = setting(positive())
    timeout_factor: float = setting(at_least(1))
    lookahead_m: float = setting(positive())
    threshold: float = setting(between(0, 1))
    temporal_alpha: float = setting(between(0, 1, low_open=True))
    video: bool = MISSING
    other_vehicle: VehicleConfig = field(default_factory=VehicleConfig)
    bootstrap: BootstrapConfig = field(default_factory=BootstrapConfig)
    workers: int = setting(at_least(0))
    device: str = setting(torch_device())  # the policies' networks: auto (the GPU where there is one), cpu, cuda, ...
