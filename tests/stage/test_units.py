"""In-process tests of modules that were otherwise reached only through whole stage runs: the
scores, the odometry front end's geometry, checkpoints, config rules, the output rule and the
dvc.yaml generator, each on tiny inputs (the fast tier, `pytest -m "not slow"`)."""

from __future__ import annotations

import pickle
import re
from dataclasses import dataclass, field

import numpy as np
import pytest
import torch
from omegaconf import OmegaConf

from offroad_path.evaluate.pixel_scores import non_corresponding, per_image_iou, pooled
from offroad_path.statistics.scores import SCORES, Scores, accuracy, iou, iou_per_image, precision, recall
from offroad_path.utils.atomic import UnsafeOutputError
from offroad_path.utils.outputs import Outputs, check_outputs
from offroad_path.utils.rules import ConfigValueError, between, one_of, positive, setting, validate

# Hand counts: 6 tp, 2 fp, 10 tn, 4 fn.
COUNTS = np.array([6, 2, 10, 4])


def test_the_four_scores_of_hand_counts():
    assert Scores.of(COUNTS) == Scores(accuracy=16 / 22, recall=6 / 10, precision=6 / 8, iou=6 / 12)
    assert set(SCORES) == {"accuracy", "recall", "precision", "iou"}


def test_scores_are_vectorised_and_nan_without_a_denominator():
    counts = np.array([COUNTS, [0, 0, 5, 0], [0, 3, 1, 0]], float)  # (3, 4): a resample per row
    np.testing.assert_allclose(iou(counts), [0.5, np.nan, 0.0])
    np.testing.assert_allclose(precision(counts), [0.75, np.nan, 0.0])
    np.testing.assert_allclose(recall(counts), [0.6, np.nan, np.nan])
    np.testing.assert_allclose(accuracy(counts), [16 / 22, 1.0, 0.25])
    np.testing.assert_allclose(iou_per_image(counts), [0.5, 1.0, 0.0])  # an empty image that is predicted empty is right


def test_torch_counts_score_as_numpy_counts_do():
    for score in SCORES.values():
        found = score(torch.tensor(COUNTS))
        assert found.dtype == torch.float32  # as torchmetrics divides integer counts
        assert float(found) == pytest.approx(float(score(COUNTS)))


def test_pooled_and_per_image_scores_of_two_images():
    per_image = np.array([[6, 2, 10, 4], [0, 0, 22, 0]])
    assert pooled(per_image) == Scores.of(COUNTS + np.array([0, 0, 22, 0]))
    np.testing.assert_array_equal(per_image_iou(per_image), [0.5, 1.0])


def test_non_corresponding_scores_each_prediction_against_the_other_frames_truth():
    truth = np.zeros((3, 2, 2), bool)
    truth[0, 0, 0] = truth[1, 0, 1] = truth[2, 1, 1] = True
    # Each prediction is exactly its own frame's truth: against another frame's, IoU 0 and accuracy 1/2.
    found = non_corresponding(truth.copy(), truth, groups=["a", "b", "c"])
    assert (found.iou, found.accuracy, found.recall, found.precision) == (0.0, 0.5, 0.0, 0.0)
    # Frames 0 and 1 are one group (a frame and its mirror): only pairs across groups count.
    found = non_corresponding(truth.copy(), np.stack([truth[0], truth[0], truth[0]]), groups=["a", "a", "c"])
    # Pairs (0, 2), (1, 2), (2, 0), (2, 1): only prediction 0 against truth 2 (both frame 0's path) overlaps.
    assert found.iou == pytest.approx(0.25)
    with pytest.raises(ValueError, match="at least two different frames"):
        non_corresponding(truth, truth, groups=["a", "a", "a"])


@dataclass
class FrontEndSettings:
    lk_window: int = 11
    lk_levels: int = 3
    min_disparity_px: float = 0.5
    max_depth_m: float = 60.0
    max_row_error_px: float = 1.0
    forward_backward_px: float = 1.0
    ransac_iterations: int = 200
    ransac_reprojection_px: float = 1.0
    min_inliers: int = 40


def front_end():
    from offroad_path.odometry.features import FrontEnd
    from offroad_path.sequence.calibration import StereoCalibration

    P = np.array([[400.0, 0, 256, 0], [0, 400.0, 144, 0], [0, 0, 1, 0]])
    right = P.copy()
    right[0, 3] = -400.0 * 0.3  # a 0.3 m baseline
    return FrontEnd(StereoCalibration(P, right), FrontEndSettings())


def test_the_front_end_projects_and_triangulates_points_back():
    front = front_end()
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-5, 5, 50), rng.uniform(-1, 2, 50), rng.uniform(3, 40, 50)])
    left, right = front.project(points)
    np.testing.assert_allclose(left[:, 1], right[:, 1])  # rectified: one row in both images
    np.testing.assert_allclose(front.triangulate(left, right), points, rtol=1e-4)


def test_the_front_end_recovers_a_known_camera_motion_by_pnp():
    front = front_end()
    rng = np.random.default_rng(1)
    points = np.column_stack([rng.uniform(-5, 5, 80), rng.uniform(-1, 2, 80), rng.uniform(5, 30, 80)])
    angle = np.deg2rad(3.0)
    motion = np.eye(4)
    motion[:3, :3] = [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    motion[:3, 3] = [0.1, 0.0, -1.0]  # the points 1 m nearer: the camera drove forward
    moved = points @ motion[:3, :3].T + motion[:3, 3]
    uv, _ = front.project(moved)
    uv[:8] += 25.0  # outliers
    found, inliers = front.pnp(points, uv)
    assert found is not None and inliers[8:].all() and not inliers[:8].any()
    np.testing.assert_allclose(found, motion, atol=1e-4)  # float32 pixels, no noise: the refined pose is the true one


def test_a_checkpoint_round_trips_and_a_pickled_object_or_a_truncated_file_is_refused(tmp_path):
    from offroad_path.training.checkpoints import CheckpointError, load_checkpoint, load_weights, save_weights
    from offroad_path.training.task import SegmentationTask

    hp = dict(model="unet", num_classes=2, width=0.125, lr=0.01, lr_milestones=[], lr_gamma=0.1, lr_warmup=0.0, momentum=0.9,
              weight_decay=0.0, channels_last=False)  # fmt: skip
    task, other = SegmentationTask(**hp), SegmentationTask(**hp)
    save_weights(tmp_path / "best.ckpt", task, note="kept")
    saved = load_checkpoint(tmp_path / "best.ckpt")
    defaults = {"optimizer": "sgd", "lr_schedule": "step", "dice_weight": 0.0, "batch_norm": None}  # saved with the rest
    assert saved["hyper_parameters"] == hp | defaults and saved["note"] == "kept"
    load_weights(other, tmp_path / "best.ckpt")
    for name, weight in task.state_dict().items():
        assert torch.equal(weight, other.state_dict()[name])
    torch.save({"state_dict": {}, "hyper_parameters": {}, "payload": pickle.loads(pickle.dumps(Scores.of(COUNTS)))}, tmp_path / "evil.ckpt")
    with pytest.raises(CheckpointError, match=r"evil\.ckpt: refused, it holds objects that could run code"):
        load_checkpoint(tmp_path / "evil.ckpt")
    (tmp_path / "cut.ckpt").write_bytes((tmp_path / "best.ckpt").read_bytes()[:1000])
    with pytest.raises(CheckpointError, match=r"cut\.ckpt: not a readable PyTorch checkpoint"):
        load_checkpoint(tmp_path / "cut.ckpt")
    narrower = SegmentationTask(**(hp | {"width": 0.25}))
    with pytest.raises(CheckpointError, match="its weights do not fit this network"):
        load_weights(narrower, tmp_path / "best.ckpt")


@dataclass
class RuledConfig:
    rate: float = setting(positive())
    fraction: float = setting(between(0, 1, high_open=True))
    kind: str = setting(one_of(["fast", "slow"]))


@dataclass
class RuledRoot:
    x: RuledConfig = field(default_factory=RuledConfig)


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"rate": 0.0}, r"x\.rate=0\.0: must be a number > 0"),
        ({"rate": float("nan")}, r"x\.rate=nan: must be a number > 0"),
        ({"fraction": 1.0}, r"x\.fraction=1\.0: must be a number in \[0, 1\)"),
        ({"kind": "medium"}, r"x\.kind='medium': must be one of: fast, slow"),
    ],
)
def test_a_rule_refuses_a_value_naming_the_key(values, message):
    good = {"rate": 1.0, "fraction": 0.5, "kind": "fast"}
    validate(OmegaConf.create({"x": good}), RuledRoot)
    with pytest.raises(ConfigValueError, match=message):
        validate(OmegaConf.create({"x": good | values}), RuledRoot)


def test_the_output_rule_refuses_an_output_inside_an_input_or_a_folder_of_yours(tmp_path):
    (tmp_path / "recording").mkdir()
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("a folder of yours")
    with pytest.raises(UnsafeOutputError, match=r"label\.out_dir=.*overlaps the input"):
        check_outputs(Outputs("label", folders={"label.out_dir": tmp_path / "recording" / "labels"}, inputs=[tmp_path / "recording"]))
    with pytest.raises(UnsafeOutputError, match=r"label\.out_dir=.*mine"):
        check_outputs(Outputs("label", folders={"label.out_dir": tmp_path / "mine"}))
    (tmp_path / "notes.json").write_text("{}")
    with pytest.raises(UnsafeOutputError, match=r"was not written by this project"):
        check_outputs(Outputs("label", files={"label.metrics_path": tmp_path / "notes.json"}))
    check_outputs(Outputs("label", folders={"label.out_dir": tmp_path / "new"}, files={"label.metrics_path": tmp_path / "m.json"}))


def test_the_configured_callbacks_follow_the_task_and_name_a_bad_one():
    from lightning.pytorch.callbacks import EarlyStopping, LearningRateMonitor

    from offroad_path.steering.pilotnet_task import SteeringTask
    from offroad_path.training.callbacks import configured_callbacks
    from offroad_path.training.task import SegmentationTask

    callbacks = OmegaConf.create(
        {
            "early_stopping": {"_target_": "lightning.pytorch.callbacks.EarlyStopping", "patience": 3},
            "lr_monitor": {"_target_": "lightning.pytorch.callbacks.LearningRateMonitor"},
        }
    )
    stopping, monitor = configured_callbacks(callbacks, SegmentationTask, validate=True, patience=None)
    assert isinstance(stopping, EarlyStopping) and isinstance(monitor, LearningRateMonitor)
    assert (stopping.monitor, stopping.mode, stopping.patience) == ("val/iou", "max", 3)
    (stopping, _) = configured_callbacks(callbacks, SteeringTask, validate=True, patience=7)
    assert (stopping.monitor, stopping.mode, stopping.patience) == ("val/mae", "min", 7)
    assert [type(c) for c in configured_callbacks(callbacks, SegmentationTask, validate=False, patience=None)] == [LearningRateMonitor]
    bad = OmegaConf.create({"mine": {"_target_": "lightning.pytorch.callbacks.NoSuchCallback"}})
    with pytest.raises(ValueError, match=r"callbacks\.mine: cannot be built"):
        configured_callbacks(bad, SegmentationTask, validate=True, patience=None)


def test_each_epoch_is_seeded_from_the_run_seed_and_the_epoch():
    from offroad_path.training.callbacks import SeedEachEpoch

    @dataclass
    class AtEpoch:
        current_epoch: int

    def draws(seed: int, epoch: int) -> tuple[float, float]:
        SeedEachEpoch(seed).on_train_epoch_start(AtEpoch(epoch), None)
        return float(torch.rand(1)), float(np.random.rand())

    assert draws(0, 1) == draws(0, 1)  # a resumed epoch draws what the uninterrupted one drew
    assert len({draws(0, 0), draws(0, 1), draws(1, 0)}) == 3


def test_a_checkpoint_with_nan_weights_is_refused_naming_the_weight(tmp_path):
    from offroad_path.training.checkpoints import CheckpointError, load_checkpoint, save_weights
    from offroad_path.training.task import SegmentationTask

    task = SegmentationTask(model="unet", num_classes=2, width=0.125, lr=0.01, lr_milestones=[], lr_gamma=0.1, lr_warmup=0.0,
                            momentum=0.9, weight_decay=0.0, channels_last=False)  # fmt: skip
    first = next(name for name, weight in task.state_dict().items() if weight.is_floating_point())
    with torch.no_grad():
        task.state_dict()[first].view(-1)[0] = float("nan")
    save_weights(tmp_path / "diverged.ckpt", task)
    with pytest.raises(CheckpointError, match=rf"diverged\.ckpt: weight {re.escape(first)} holds NaN or infinite values"):
        load_checkpoint(tmp_path / "diverged.ckpt")


def test_a_checkpoint_with_flipped_bytes_is_refused_naming_the_damaged_member(tmp_path):
    """64 flipped bytes inside a weight tensor load as finite, wrong weights; the zip's CRC tells."""
    from offroad_path.training.checkpoints import CheckpointError, load_checkpoint, save_weights
    from offroad_path.training.task import SegmentationTask

    task = SegmentationTask(model="unet", num_classes=2, width=0.125, lr=0.01, lr_milestones=[], lr_gamma=0.1, lr_warmup=0.0,
                            momentum=0.9, weight_decay=0.0, channels_last=False)  # fmt: skip
    save_weights(tmp_path / "best.ckpt", task)
    data = bytearray((tmp_path / "best.ckpt").read_bytes())
    middle = len(data) // 2  # inside the largest tensor's stored bytes
    data[middle : middle + 64] = bytes(b ^ 0x01 for b in data[middle : middle + 64])  # low bits: still finite floats
    (tmp_path / "flipped.ckpt").write_bytes(bytes(data))
    with pytest.raises(CheckpointError, match=r"flipped\.ckpt: damaged, its member \S+ fails the archive's CRC check"):
        load_checkpoint(tmp_path / "flipped.ckpt")
    assert load_checkpoint(tmp_path / "best.ckpt")["hyper_parameters"]["model"] == "unet"  # the intact copy loads
