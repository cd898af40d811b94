"""PilotNet, its scores, the straight-ahead bias's remedies and the collapse check, on hand-made angles."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from offroad_path.data.dataset import EpochSampler
from offroad_path.steering.balance import balance_weights, distance_from_mean, inverse_frequency
from offroad_path.steering.collapse import error_by_magnitude, steering_metrics
from offroad_path.steering.pilotnet import PilotNet, feature_size
from offroad_path.steering.pilotnet_task import weighted_mse


def test_pilotnet_parameters_and_output():
    net = PilotNet(256, 136)
    # convolutions: 1824 + 21636 + 43248 + 27712 + 36928; fully connected from 64 x 10 x 25 features:
    # 16000 * 100 + 100, 100 * 50 + 50, 50 * 10 + 10, 10 + 1
    assert feature_size(256, 136) == (10, 25)
    assert sum(p.numel() for p in net.parameters()) == 131_348 + 1_600_100 + 5_050 + 510 + 11
    out = net(torch.randn(3, 3, 136, 256) * 50)  # large inputs: the output still stays in [-1, 1]
    assert out.shape == (3,) and out.abs().max() <= 1
    with pytest.raises(ValueError, match="too small"):
        PilotNet(40, 30)


def test_scores_on_hand_made_angles():
    true = np.array([0.0, 0.05, -0.3, 0.8])
    predicted = np.array([0.1, 0.05, -0.1, 0.4])
    m = steering_metrics(true, predicted, lock_deg=36.0, steering_ratio=15.0)
    assert m["mean_absolute_error"] == pytest.approx((0.1 + 0 + 0.2 + 0.4) / 4)
    # the paper's reading: 0.175 of a 36-degree lock is 6.3 degrees at the road wheels, 94.5 at the steering wheel
    assert m["mean_absolute_error_road_wheel_deg"] == pytest.approx(6.3) and m["mean_absolute_error_steering_wheel_deg"] == pytest.approx(
        94.5
    )
    assert m["largest_predicted_magnitude"] == pytest.approx(0.4) and m["straight_ahead_mean_absolute_error"] == pytest.approx(1.15 / 4)
    bins = {b["true_magnitude"]: b for b in error_by_magnitude(true, predicted)}
    assert bins["0.0-0.1"]["frames"] == 2 and bins["0.0-0.1"]["mean_absolute_error"] == pytest.approx(0.05)
    assert bins["0.3-0.4"]["mean_absolute_error"] == pytest.approx(0.2)
    assert bins["0.5-1.0"]["mean_predicted_magnitude"] == pytest.approx(0.4)
    assert bins["0.1-0.2"]["frames"] == 0 and bins["0.1-0.2"]["mean_absolute_error"] is None


def test_balance_weights_on_hand_made_angles():
    # |s| bins of 0.1: three frames in [0, 0.1), one in [0.2, 0.3): each bin gets the same total weight
    assert inverse_frequency(np.array([0.01, -0.02, 0.03, 0.25])) == pytest.approx([2 / 3, 2 / 3, 2 / 3, 2])
    # mean 0, distances 1, 0, 1 (mean 2/3): 1 + d / (2/3) = 2.5, 1, 2.5, then mean 1
    assert distance_from_mean(np.array([-1.0, 0.0, 1.0])) == pytest.approx([1.25, 0.5, 1.25])
    assert balance_weights(np.zeros(3), "none") == (None, None)
    with pytest.raises(ValueError, match="valid: none, oversample, weighted"):
        balance_weights(np.zeros(3), "smote")
    # the weighted loss: (2 * 0.1^2 + 0.5 * 0.4^2) / 2
    loss = weighted_mse(torch.tensor([0.1, 0.4]), torch.tensor([0.0, 0.0]), torch.tensor([2.0, 0.5]))
    assert loss.item() == pytest.approx((0.02 + 0.08) / 2)


def test_oversampling_draws_by_weight_and_replays_each_epoch():
    sampler = EpochSampler(4, seed=3, weights=np.array([0.0, 3.0, 0.0, 1.0]))
    sampler.set_epoch(1)
    drawn = [i for i, _ in sampler]
    assert set(drawn) <= {1, 3} and len(drawn) == 4 and drawn == [i for i, _ in sampler]
    counts = np.bincount([i for e in range(200) for i, _ in (sampler.set_epoch(e) or sampler)], minlength=4)
    assert counts[1] / counts[3] == pytest.approx(3.0, rel=0.15)


def test_the_collapse_check_flags_a_constant_and_a_zero_pilotnet_and_passes_an_under_steering_one():
    from offroad_path.steering.collapse import collapse_check

    rng = np.random.default_rng(0)
    worlds = [f"w{i // 50}" for i in range(400)]  # 8 worlds of 50 frames
    true = np.clip(rng.normal(0, 0.25, 400), -1, 1)
    for output in (np.full(400, 0.02), np.zeros(400)):  # a constant, and straight ahead itself
        constant = collapse_check(true, output, worlds)
        assert constant["collapsed"] and len(constant["collapse_reasons"]) == 2 and not constant["beats_straight_ahead"]
        assert constant["prediction_spread_ratio"] == 0 and constant["correlation_with_truth"] == 0
    steering = collapse_check(true, true + rng.normal(0, 0.03, 400), worlds)
    low, high = steering["straight_ahead_margin_interval"]
    assert not steering["collapsed"] and steering["beats_straight_ahead"] and 0 < low < steering["straight_ahead_margin"] < high
    # under-steering (the committed slip PilotNet's kind): 0.4 of the angle, largest output far below the
    # truth's, yet it moves with the truth and beats straight ahead: weak, not collapsed
    under = collapse_check(true, 0.4 * true + rng.normal(0, 0.03, 400), worlds)
    assert np.abs(0.4 * true).max() < 0.5 * np.abs(true).max()
    assert not under["collapsed"] and under["beats_straight_ahead"] and under["prediction_spread_ratio"] == pytest.approx(0.4, abs=0.05)
    # noise as large as the angles: moves, but not with the truth: collapsed on the correlation, and no better than straight ahead
    noisy = collapse_check(true, rng.normal(0, 0.4, 400), worlds)
    assert noisy["collapsed"] and noisy["collapse_reasons"] == ["correlation with the truth at or below 0.1"]
    assert not noisy["beats_straight_ahead"]


def test_the_thesis_step_decay_multiplies_the_rate_every_lr_step_epochs():
    """optimizer sgd: the rate times lr_gamma every lr_step_epochs epochs (the one optimiser builder's
    step milestones), measured at each epoch's start of a real run of 5 epochs of 2 steps."""
    import lightning as L
    from torch.utils.data import DataLoader

    from offroad_path.steering.pilotnet_task import SteeringTask

    task = SteeringTask(width=200, height=66, lr=0.1, lr_step_epochs=2, lr_gamma=0.5, momentum=0.9, weight_decay=0.0, optimizer="sgd")
    rates = []

    class RateAtEpochStart(L.Callback):
        def on_train_epoch_start(self, trainer: L.Trainer, module: L.LightningModule) -> None:
            rates.append(trainer.optimizers[0].param_groups[0]["lr"])

    frames = [{"image": torch.rand(3, 66, 200), "steering": torch.tensor(0.1)} for _ in range(2)]
    trainer = L.Trainer(max_epochs=5, callbacks=[RateAtEpochStart()], logger=False, enable_checkpointing=False,
                        enable_progress_bar=False, enable_model_summary=False, accelerator="cpu")  # fmt: skip
    trainer.fit(task, DataLoader(frames, batch_size=1))
    assert rates == pytest.approx([0.1, 0.1, 0.05, 0.05, 0.025])


def test_the_steering_config_builds_its_task_by_instantiate(compose_config):
    """conf/steering's `_target_` takes SteeringTask's arguments from the node by name: the config's
    values, the vehicle's lock and wheelbase for a curvature PilotNet alone, and no stage setting."""
    from hydra.utils import instantiate

    from offroad_path.steering.pilotnet_task import SteeringTask, required_hyperparameters

    angle = instantiate(compose_config("steering.lr=0.003").steering, _convert_="all")
    assert isinstance(angle, SteeringTask) and angle.hparams.lr == 0.003 and angle.hparams.lock_deg is None
    curvature = compose_config("steering.target=curvature")
    task = instantiate(curvature.steering, _convert_="all")
    vehicle = curvature.world.vehicle
    assert (task.hparams.lock_deg, task.hparams.wheelbase_m) == (vehicle.max_steering_deg, vehicle.wheelbase_m)
    assert set(required_hyperparameters()) <= set(task.hparams) and "batch_size" not in task.hparams
