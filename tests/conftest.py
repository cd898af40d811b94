from __future__ import annotations

import fcntl
import os
import shutil
import sqlite3
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from omegaconf import DictConfig

from offroad_path.config import load_config
from offroad_path.utils.threads import set_threads, usable_cores

ROOT = Path(__file__).resolve().parents[1]
KITTI_SNIPPET = ROOT.parent / "shared" / "data" / "kitti_seq1"
# pytest-xdist runs the suite in one process per core (pyproject's addopts): each worker and the
# stages it runs in-process get their share of the cores, so that workers never wait on each other's
# threads. Stages started as commands keep their config's count (2), with OpenMP threads that sleep
# rather than spin while they wait: two spinning 2-thread processes on 2 cores ran a training step
# 4.7x to 15x slower, sleeping ones 1.5x to 1.9x (benchmarks/wait_policy.py).
WORKERS = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
WORKER_THREADS = max(1, usable_cores() // WORKERS)
if WORKERS > 1:
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # read by a command's OpenMP when it starts
    set_threads(WORKER_THREADS)


# A test not marked slow runs its body in under this many seconds on the 2-core machine the suite
# is sized for (setup not counted: the session's fixtures are made by whichever test needs them
# first); one over it is listed at the end of the run, named, so the everyday tier (`pytest -m "not
# slow"`) stays minutes. It never fails the run: a slower or busier machine is no failing test
# (speed is measured in benchmarks). OFFROAD_NOT_SLOW_BUDGET_S sets another budget.
NOT_SLOW_BUDGET_S = float(os.environ.get("OFFROAD_NOT_SLOW_BUDGET_S", "5"))
over_budget: list[tuple[str, float]] = []


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    if report.when == "call" and "slow" not in report.keywords and report.duration > NOT_SLOW_BUDGET_S:
        over_budget.append((report.nodeid, report.duration))


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter) -> None:
    if over_budget and not hasattr(terminalreporter.config, "workerinput"):
        terminalreporter.section(f"not marked slow, yet over {NOT_SLOW_BUDGET_S:g} s (mark them slow or make them faster)")
        for nodeid, seconds in sorted(over_budget, key=lambda entry: -entry[1]):
            terminalreporter.write_line(f"{seconds:6.2f}s {nodeid}")


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The slow tests first, longest first: a pytest-xdist worker that got the longest one last
    would run on alone while the others wait."""

    def seconds(item: pytest.Item) -> float:
        slow = item.get_closest_marker("slow")
        return slow.kwargs.get("seconds", 1.0) if slow else 0.0

    items.sort(key=seconds, reverse=True)  # stable: the rest keep pytest's order


@pytest.fixture(scope="session", autouse=True)
def mlflow_store_outside_the_checkout(tmp_path_factory: pytest.TempPathFactory) -> None:
    """A stage run with the default mlflow settings logs to $MLFLOW_TRACKING_URI, else to mlflow.db
    where it runs (the checkout, for the suite): one store of the run's own instead, read by the
    commands the tests start too. A test that names its store (mlflow.tracking_uri=...) keeps it."""
    os.environ.setdefault("MLFLOW_TRACKING_URI", f"sqlite:///{tmp_path_factory.getbasetemp() / 'mlflow.db'}")


@pytest.fixture(autouse=True)
def restore_threads() -> Iterator[None]:
    """Stages run in this process set its threads (offroad_path.utils.threads): each test starts as the session did."""
    import cv2
    import torch

    saved = torch.get_num_threads(), cv2.getNumThreads(), os.environ.get("OMP_NUM_THREADS")
    yield
    torch.set_num_threads(saved[0])
    cv2.setNumThreads(saved[1])
    if saved[2] is None:
        os.environ.pop("OMP_NUM_THREADS", None)
    else:
        os.environ["OMP_NUM_THREADS"] = saved[2]


@pytest.fixture(scope="session")
def compose_config() -> Callable[..., DictConfig]:
    """The project's Hydra config, composed exactly as the stages compose it, with overrides (and,
    under pytest-xdist, the worker's share of the cores as `threads`, unless a test sets it)."""
    if WORKERS == 1:
        return load_config
    return lambda *overrides: load_config(f"threads={WORKER_THREADS}", *overrides)


@pytest.fixture(scope="session")
def kitti_snippet() -> Path:
    if not (KITTI_SNIPPET / "calib.txt").is_file():
        pytest.skip(f"the real KITTI snippet is not at {KITTI_SNIPPET} (it lives in shared/, beside the repo)")
    return KITTI_SNIPPET


def made_once(tmp_path_factory: pytest.TempPathFactory, name: str, make: Callable[[Path], object]) -> Path:
    """Folder `name`, made by make(folder) once per run: under pytest-xdist, the first worker to need
    it makes it and the others wait for it and read it (session fixtures are otherwise made once
    per worker, each time at the cost of both cores). Tests must not change what is in it."""
    base = tmp_path_factory.getbasetemp()
    root = base.parent if WORKERS > 1 else base  # the run's folder, above each worker's own
    folder, done = root / "shared" / name, root / "shared" / f"{name}.done"
    folder.parent.mkdir(exist_ok=True)
    with open(root / "shared" / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if not done.is_file():
            shutil.rmtree(folder, ignore_errors=True)  # what a worker that failed making it left
            folder.mkdir()
            make(folder)
            done.touch()
    return folder


@pytest.fixture(scope="session")
def drive(compose_config, tmp_path_factory) -> Path:
    """A folder with one 40-frame drive (about 40 m) of the laptop world at the paper's 512 x 288,
    rendered once per run: the odometry tests' bounds are for that size and for the world's single
    look before world.appearance (its VO on every look is the committed run's label metrics)."""
    from offroad_path.world.record import record_sequence

    def make(root: Path) -> None:
        cfg = compose_config("world.frames=40", "world.width=512", "world.height=288", "world.appearance.enabled=false")
        record_sequence(cfg.world, seed=21, out_dir=root / "drive")

    return made_once(tmp_path_factory, "recordings", make)


@pytest.fixture(scope="session")
def rig(drive):
    """A raw stereo rig that recorded `drive` (tests/raw_rig.py): own K and distortion per camera, the right one turned."""
    from raw_rig import raw_rig

    return raw_rig(drive / "drive")


@pytest.fixture(scope="session")
def raw_drive(drive, rig) -> list:
    """`drive`'s frames as the raw rig saw them: (left, right) BGR per frame."""
    from raw_rig import raw_frames

    return raw_frames(drive / "drive", rig)


@pytest.fixture(scope="session")
def labelled_drive(compose_config, drive, tmp_path_factory) -> Path:
    """The label stage's output for `drive` (VO poses), made once per run."""
    from offroad_path.label import label

    def make(out: Path) -> None:
        label(compose_config(f"label.in_dir={drive}", f"label.out_dir={out / 'labels'}", f"label.metrics_path={out / 'm.json'}",
                             "label.workers=1", "mlflow.enabled=false"))  # fmt: skip

    return made_once(tmp_path_factory, "labelled", make) / "labels"


@pytest.fixture(scope="session")
def split_dir(compose_config, labelled_drive, tmp_path_factory) -> Path:
    """Manifests over `labelled_drive`, with blocks small enough that every part gets frames."""
    from offroad_path.split import split

    def make(out: Path) -> None:
        split(compose_config(f"split.labels_dir={labelled_drive}", f"split.out_dir={out / 'split'}", "split.block_m=4", "split.guard_m=3"))

    return made_once(tmp_path_factory, "split", make) / "split"


TINY_TRAINING = (
    "model.width=0.125",
    "data.width=64",
    "data.height=48",
    "data.batch_size=2",
    "trainer.accelerator=cpu",
    "train.sample_images=1",
)


@pytest.fixture(scope="session")
def tiny_overrides() -> tuple[str, ...]:
    """Overrides that make training small enough for a test: narrow networks on 64 x 48 inputs."""
    return TINY_TRAINING


@pytest.fixture(scope="session")
def tiny_config(compose_config, split_dir) -> Callable[..., DictConfig]:
    """Training config on `split_dir` with networks and inputs small enough for a test, writing under `out`."""

    def _compose(out: Path, *overrides: str) -> DictConfig:
        return compose_config(
            *TINY_TRAINING, f"data.split_dir={split_dir}", f"train.out_dir={out / 'run'}", f"pretrain.out_dir={out / 'pretrain'}",
            f"mlflow.tracking_uri=sqlite:///{out / 'mlflow.db'}", *overrides,
        )  # fmt: skip

    return _compose


@pytest.fixture(scope="session")
def trained(tiny_config, tmp_path_factory) -> tuple[Path, str, Path]:
    """(checkpoint, MLflow run id, tracking db) of a U-Net trained for one epoch on the test drive."""
    from offroad_path.train import train

    out = made_once(tmp_path_factory, "trained", lambda out: train(tiny_config(out, "model=unet", "trainer.max_epochs=1")))
    with sqlite3.connect(out / "mlflow.db") as db:
        (run_id,) = db.execute("select run_uuid from runs where name = 'train unet-none seed0'").fetchone()
    return out / "run" / "checkpoints" / "best.ckpt", run_id, out / "mlflow.db"


@pytest.fixture
def recordings(drive, tmp_path) -> Path:
    """A copy of the test drive the case may damage."""
    shutil.copytree(drive, tmp_path / "recordings")
    return tmp_path / "recordings"


@pytest.fixture
def frames_folder(drive, tmp_path) -> Path:
    folder = tmp_path / "images"
    folder.mkdir()
    for i in range(2):
        shutil.copy(drive / "drive" / "image_l" / f"{i:06d}.png", folder / f"{i:06d}.png")
    return folder
