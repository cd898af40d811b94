"""The synthesize stage against the sequence contract of docs/design.md, and its configuration."""

from __future__ import annotations

import hashlib
import json
import os
import platform
import signal
import subprocess
import sys
import time

import cv2
import numpy as np
import pytest
from common import openblas_cores, without_vector_kernels
from helpers import command
from hydra.errors import ConfigCompositionException

from offroad_path.sequence import open_sequence
from offroad_path.synthesize import synthesize
from offroad_path.utils.atomic import MARKER, atomic_directory
from offroad_path.world.classes import CLASS_NAMES

TINY = ("synthesize.sequences=2", "world.frames=3", "world.width=160", "world.height=96", "synthesize.workers=2",
        "synthesize.test_worlds.min_blocks=0")  # fmt: skip
HELD_OUT = ("synthesize.test_worlds.min_blocks=1", "synthesize.test_worlds.per_stress=0", "synthesize.test_worlds.horizon_m=0.5",
            "synthesize.test_worlds.development_blocks=0", "synthesize.test_worlds.retired_blocks=0")  # fmt: skip


@pytest.mark.slow(seconds=10)
def test_writes_the_sequence_contract(compose_config, tmp_path):
    out = tmp_path / "synthetic"
    out.mkdir()
    (out / MARKER).write_text("synthesize\n")  # an earlier run's output: replaced whole
    (out / "stale.txt").write_text("from an earlier run")
    cfg = compose_config(*TINY, *HELD_OUT, f"synthesize.out_dir={out}", "world/rig=gopro")
    synthesize(cfg)
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "seq_000", "seq_001", "summary.json", "test_000"]  # rewritten whole
    assert open_sequence(out / "test_000").meta["split"] == "test" and "split" not in open_sequence(out / "seq_001").meta
    assert not list(tmp_path.glob(".synthetic*"))  # no temporary leftovers
    seq = open_sequence(out / "seq_000")
    assert len(seq) == 3 and seq.image_size == (160, 96)
    assert seq.calibration.baseline_m == pytest.approx(0.40)
    # 80 degrees horizontal field of view, principal point at the image centre.
    assert 2 * np.degrees(np.arctan(80 / seq.calibration.fx)) == pytest.approx(80.0)
    np.testing.assert_allclose(seq.poses[0], np.eye(4), atol=1e-9)
    np.testing.assert_allclose(seq.times, np.arange(3) / cfg.world.fps)
    assert np.all(np.abs(seq.steering) <= 1)
    depth_raw = cv2.imread(str(seq.depth[0]), cv2.IMREAD_UNCHANGED)
    assert depth_raw.dtype == np.uint16
    semantic = seq.load_semantic(0)
    sky = semantic == CLASS_NAMES.index("sky")
    assert np.all(depth_raw[sky] == 0) and np.all(depth_raw[~sky] > 0)
    assert semantic.max() < len(CLASS_NAMES)
    meta = seq.meta
    assert meta["baseline_m"] == 0.40 and meta["camera_height_m"] == 1.8 and meta["rig"] == "gopro_pair"
    assert meta["footprint_front_m"] > 0 > meta["footprint_rear_m"]
    # world_from_first_camera maps the first camera's frame into the gravity-aligned world.
    world_from_cam = np.array(meta["world_from_first_camera"])
    np.testing.assert_allclose(world_from_cam[:3, :3] @ world_from_cam[:3, :3].T, np.eye(3), atol=1e-9)
    summary = json.loads((out / "summary.json").read_text())
    assert [s["frames"] for s in summary["sequences"]] == [3, 3, 3]
    assert [(w["name"], w["blocks"]) for w in summary["test_worlds"]] == [("test_000", 1)]


def test_atomic_directory_keeps_the_old_output_on_failure(tmp_path):
    target = tmp_path / "out"
    target.mkdir()
    (target / MARKER).write_text("test\n")
    (target / "good.txt").write_text("previous complete run")
    with pytest.raises(RuntimeError), atomic_directory(target, "test") as tmp:
        (tmp / "half.txt").write_text("partial")
        raise RuntimeError("interrupted")
    assert [p.name for p in tmp_path.iterdir()] == ["out"]
    assert sorted(p.name for p in target.iterdir()) == [MARKER, "good.txt"]


@pytest.mark.parametrize(
    ("override", "named"),
    [("world.hil_height_m=3", "hil_height_m"), ("world.frames=many", "frames"), ("world/rig=zed", "world/rig")],
)
def test_config_errors_name_the_key(compose_config, override, named):
    with pytest.raises(ConfigCompositionException) as info:
        compose_config(override)
    assert named in str(info.value) + str(info.value.__cause__)


def test_cli_refuses_a_misspelt_key_before_any_work(tmp_path):
    out = tmp_path / "never"
    run = command("offroad_path.synthesize", "world.hil_height_m=3", f"synthesize.out_dir={out}")
    assert run.returncode != 0
    assert "hil_height_m" in run.stderr
    assert not out.exists()


def test_a_stopped_stage_leaves_no_temporary_output(tmp_path):
    out = tmp_path / "synthetic"
    cli = [sys.executable, "-m", "offroad_path.synthesize", f"synthesize.out_dir={out}", "synthesize.sequences=2", "mlflow.enabled=false"]
    stage = subprocess.Popen(cli, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not list(tmp_path.glob(".synthetic.tmp-*")) and time.monotonic() < deadline and stage.poll() is None:
        time.sleep(0.2)
    assert list(tmp_path.glob(".synthetic.tmp-*")), "the stage never started writing"
    stage.send_signal(signal.SIGTERM)
    assert stage.wait(timeout=60) == 128 + signal.SIGTERM
    assert not any(tmp_path.iterdir())


@pytest.mark.skipif(platform.machine() != "x86_64", reason="the kernel sets named are x86-64's")
@pytest.mark.slow(seconds=30)
def test_the_world_renders_the_same_bytes_on_every_cpu_kernel_set(tmp_path):
    """The world rendered on an AVX2 and an AVX-512 machine differed (OpenBLAS's Haswell and
    SkylakeX kernels in the renderer's matrix products); NumPy's and OpenCV's dispatch never did."""

    def render(name: str, env: dict[str, str]) -> dict[str, str]:
        out = tmp_path / name
        # 7 renders in the stage's own process (no worker pool: the kernel sets are the point, and each run starts one)
        one_drive = [*(o for o in TINY if not o.startswith(("synthesize.sequences=", "synthesize.workers="))), "synthesize.sequences=1",
                     "synthesize.workers=1"]  # fmt: skip
        cli = [
            sys.executable,
            "-m",
            "offroad_path.synthesize",
            *one_drive,
            f"synthesize.out_dir={out}",
            f"hydra.run.dir={tmp_path / 'hydra'}",
        ]
        run = subprocess.run(cli, env={**os.environ, **env}, capture_output=True, text=True)
        assert run.returncode == 0, run.stderr[-2000:]
        return {str(p.relative_to(out)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(out.rglob("*")) if p.is_file()}

    scalar = without_vector_kernels()
    probe = "import cv2; print(cv2.getCPUFeaturesLine())"
    line = subprocess.run([sys.executable, "-c", probe], env={**os.environ, **scalar}, capture_output=True, text=True).stdout
    assert "*AVX2?" in line or "*AVX2" not in line, line  # OpenCV's AVX2 kernels are off (or were never there)
    assert "*AVX512-SKX?" in line or "*AVX512-SKX" not in line, line
    cores = openblas_cores()
    assert "Prescott" in cores and "Nehalem" in cores, cores
    reference = render("default", {})
    for name, env in [("scalar", scalar), *((core, {"OPENBLAS_CORETYPE": core}) for core in cores)]:
        assert render(name, env) == reference, f"{name} rendered other bytes"
