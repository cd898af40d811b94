"""The torch renderer (world/render_torch.py) against the NumPy reference (world/render.py), on the CPU:
the same views to a fraction of a millimetre and a grey level, each view the same in any batch, and
synthesize's files the same but for those last bits."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest

from offroad_path.world.record import Drive, _shutter_metres, camera_for, record_sequence, record_sequences
from offroad_path.world.render import render_view
from offroad_path.world.render_torch import DeviceWorld, render_views, torch_device
from offroad_path.world.scene import build_world

FRAMES = [3, 17, 31]


def agree(reference, ported) -> None:
    """Where each hits, depth within 1 mm (float32 marches: measured up to 0.35 mm); the same class on
    every pixel; images (after the sensor's noise and compression) within 1 grey level on 99.5 %."""
    assert np.array_equal(reference.depth > 0, ported.depth > 0)
    assert np.abs(reference.depth - ported.depth).max() < 1e-3
    assert (reference.semantic == ported.semantic).mean() > 0.999
    difference = np.abs(reference.image.astype(int) - ported.image.astype(int))
    assert (difference <= 1).mean() > 0.995 and difference.mean() < 0.05


@pytest.fixture(scope="module")
def drive(compose_config):
    cfg = compose_config("world.frames=40").world
    return cfg, build_world(cfg, seed=23)


@pytest.mark.parametrize("look", [True, False], ids=["with a look", "no look"])
def test_the_torch_renderer_agrees_with_the_reference(drive, look):
    """On the GPU where there is one (render.device's auto), else on the CPU."""
    cfg, world = drive
    world = world if look else dataclasses.replace(world, look=None)  # the gamma alone, no sensor
    camera, max_t = camera_for(cfg), cfg.max_distance_m
    shutter = _shutter_metres(world, cfg.fps)
    keys = [(23, k, 0) for k in FRAMES]
    reference = [render_view(world, camera, world.poses[k], max_t, None, shutter[k], key) for k, key in zip(FRAMES, keys, strict=True)]
    device = torch_device("auto")
    ported = render_views(DeviceWorld(world, device), camera, world.poses[FRAMES], max_t, motion_m=shutter[FRAMES], noise_keys=keys)
    assert len(world.objects.kind) > 0 and any((v.semantic == s).any() for v in reference for s in np.unique(world.materials))
    for r, p in zip(reference, ported, strict=True):
        agree(r, p)
    # Each view is its own whatever shares its batch: alone, it renders to the same bytes.
    one = FRAMES[1:2]
    alone = render_views(DeviceWorld(world, device), camera, world.poses[one], max_t, motion_m=shutter[one], noise_keys=keys[1:2])[0]
    assert np.array_equal(alone.image, ported[1].image) and np.array_equal(alone.depth, ported[1].depth)


@pytest.mark.slow(seconds=4)
def test_synthesize_writes_the_same_sequence_with_either_renderer(compose_config, tmp_path):
    small = ("world.frames=8", "world.width=128", "world.height=72")
    cfg = compose_config(*small, "render.backend=torch", "render.device=cpu", "render.views_per_batch=6")
    numpy_dir, torch_dir = tmp_path / "numpy", tmp_path / "torch" / "test_000"
    record_sequence(cfg.world, 5, numpy_dir, "main")
    record_sequences(cfg.world, [Drive("test_000", 5, "main")], torch_dir.parent, workers=1, render=cfg.render)  # as the stage calls it
    files = sorted(p.relative_to(numpy_dir) for p in numpy_dir.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(torch_dir) for p in torch_dir.rglob("*") if p.is_file())
    assert json.loads((numpy_dir / "meta.json").read_text()) == json.loads((torch_dir / "meta.json").read_text())
    for name in ("poses.txt", "calib.txt", "steering.txt", "conditions.csv"):
        assert (numpy_dir / name).read_bytes() == (torch_dir / name).read_bytes()
    for file in (f for f in files if f.suffix == ".png"):
        a, b = (cv2.imread(str(root / file), cv2.IMREAD_UNCHANGED).astype(int) for root in (numpy_dir, torch_dir))
        difference = np.abs(a - b)
        if file.parts[0] == "depth":  # millimetres
            assert difference.max() <= 1, file
        elif file.parts[0] == "semantic":
            assert (difference > 0).mean() < 1e-3, file
        else:  # after noise and compression: a JPEG-like block may round a level the other way
            assert difference.mean() < 0.05 and difference.max() <= 10, file


def _resolve(dotted: str):
    """world.<module>.<name>[.<name>] of a PORTS entry ("render._detail", "terrain.Grid.coords")."""
    import importlib

    module, *names = dotted.split(".")
    found = importlib.import_module(f"offroad_path.world.{module}")
    for name in names:
        found = getattr(found, name)
    return found


def test_every_port_and_its_reference_name_each_other():
    """render_torch.PORTS pairs each torch function with the reference it follows step by step: both
    exist, each docstring names the other (a fix to the reference is seen to be owed to its port),
    and every function of the port modules that follows a reference is in the table."""
    import importlib
    import inspect

    from offroad_path.world.render_torch import PORTS

    for reference, port in PORTS:
        assert f"world.{port}" in inspect.getdoc(_resolve(reference)), f"{reference}'s docstring does not name its port {port}"
        assert reference.split(".", 1)[1] in inspect.getdoc(_resolve(port)), f"{port}'s docstring does not name {reference}"
    listed = {port for _, port in PORTS}
    for module in ("trace_torch", "shading_torch", "render_torch"):
        found = importlib.import_module(f"offroad_path.world.{module}")
        for name, value in vars(found).items():
            if (inspect.isfunction(value) or inspect.isclass(value)) and value.__module__ == found.__name__:
                doc = inspect.getdoc(value) or ""
                follows = any(f"{ref}." in doc for ref in ("render", "sensor", "terrain", "objects", "kernels"))
                assert not follows or f"{module}.{name}" in listed, f"{module}.{name} follows a reference but is not in PORTS"


def test_no_number_is_written_in_both_the_reference_and_its_port():
    """The port imports the reference's constants (texture scales, sky, auto gain, the march): a
    number written twice drifts when one copy is tuned. Allowed: the arithmetic's own (0, 1, 2, 3,
    -1, 0.5), parameter slices of an object's row (5, 6), a bit shift (20) and the 8-bit maximum."""
    import ast

    from helpers import ROOT

    structural = {0, 1, 2, 3, -1, 0.5, 5, 6, 20, 255}

    def numbers(names: tuple[str, ...]) -> dict[float, list[str]]:
        out: dict[float, list[str]] = {}
        for name in names:
            path = ROOT / "src" / "offroad_path" / "world" / f"{name}.py"
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Constant) and type(node.value) in (int, float) and node.value not in structural:
                    out.setdefault(node.value, []).append(f"{name}.py:{node.lineno}")
        return out

    references = numbers(("render", "objects", "sensor", "terrain", "kernels"))
    ports = numbers(("render_torch", "shading_torch", "trace_torch"))
    twice = {value: ports[value] for value in set(references) & set(ports)}
    assert not twice, f"numbers written in a port and its reference (import the reference's constant): {twice}"
