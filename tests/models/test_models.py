"""The three architectures: sizes of the originals, any input size, training steps, head swap."""

from __future__ import annotations

import pytest
import torch

from offroad_path.models import MODELS, build_model


@pytest.mark.parametrize(("name", "millions"), [("segnet", 29.4), ("fcn", 134.3), ("unet", 31.0)])
def test_width_one_matches_the_original_parameter_count(name, millions):
    model = build_model(name, num_classes=2, width=1.0)
    assert sum(p.numel() for p in model.parameters()) / 1e6 == pytest.approx(millions, abs=0.1)


@pytest.mark.parametrize("name", sorted(MODELS))
def test_odd_sized_input_forward_and_backward(name):
    torch.manual_seed(0)
    model = build_model(name, num_classes=2, width=0.125)
    x = torch.randn(2, 3, 37, 53)
    scores = model(x)
    assert scores.shape == (2, 2, 37, 53)
    loss = torch.nn.functional.cross_entropy(scores, torch.randint(0, 2, (2, 37, 53)))
    loss.backward()
    grads = [p.grad for p in model.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert sum(g.abs().sum() for g in grads) > 0


@pytest.mark.parametrize("name", sorted(MODELS))
def test_head_swap_keeps_every_other_weight(name):
    model = build_model(name, num_classes=8, width=0.125)
    before = {k: v.clone() for k, v in model.state_dict().items()}
    head = set(model.head_parameters())
    model.replace_head(2)
    after = model.state_dict()
    for key, value in before.items():
        if key in head:
            assert after[key].shape[0] == 2 or after[key].shape[1] == 2
        else:
            assert torch.equal(after[key], value), key
    assert model(torch.randn(1, 3, 32, 32)).shape[1] == 2


@pytest.mark.parametrize("name", ["unet", "segnet"])
def test_batch_norm_is_refused_where_it_is_no_choice(name):
    """Once `model.batch_norm=false` trained U-Net without batch norm, the config saying it is no choice there."""
    with pytest.raises(ValueError, match=rf"^model\.batch_norm=False: {name} has batch norm after every convolution as published"):
        build_model(name, 2, 0.125, batch_norm=False)
    assert any(isinstance(m, torch.nn.BatchNorm2d) for m in build_model("fcn", 2, 0.125, batch_norm=True).modules())


def test_unknown_model_lists_valid_names():
    with pytest.raises(ValueError, match="valid: " + ", ".join(sorted(MODELS))):
        build_model("deeplab")
