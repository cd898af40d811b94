"""What the robustness and interruption tests share: hashing a folder, running a stage as its
command does (in this process, or in one of its own where the process is the subject), finding
the processes a test started (through /proc, Linux)."""

from __future__ import annotations

import contextlib
import hashlib
import io
import logging
import os
import re
import runpy
import shutil
import signal
import subprocess
import sys
import warnings
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import yaml
from common import tagged_processes  # noqa: F401  (benchmarks/common.py: the tests' import of it)

from offroad_path.inference.path_filter import PostprocessParams
from offroad_path.stage import run_stage

ROOT = Path(__file__).resolve().parents[1]
# Holder & Breckon's post-processing (the postprocess stage's config and the path filter's tests)
PAPER_POSTPROCESSING = PostprocessParams(max_depth_m=20.0, sigma=6.0, delta=0.025, use_depth=True, unknown_depth="keep")


def snapshot(root: Path) -> dict[str, str]:
    """Every file and folder under root with a hash of its bytes."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir" for p in sorted(root.rglob("*"))}


def command(module: str, *args: object, cwd: Path | None = None, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """`python -m MODULE ARGS` (or `python SCRIPT.py ARGS`) run in this process, answered as
    subprocess.run answers: the exit status and what it printed. Its imports are already made, so it
    takes about 2 s less than a command of its own. For every test whose subject is not the process;
    signals, kills, imports, CPU kernel sets and other environments keep subprocess.run."""
    argv, here, environ, on_sigterm = sys.argv[:], os.getcwd(), dict(os.environ), signal.getsignal(signal.SIGTERM)
    root = logging.getLogger()
    handlers, level = root.handlers[:], root.level  # Hydra configures logging for its job; pytest's caplog is a root handler
    disabled = {name: logger.disabled for name, logger in logging.Logger.manager.loggerDict.items() if isinstance(logger, logging.Logger)}
    out, err = io.StringIO(), io.StringIO()
    status = 0
    sys.argv = [module, *map(str, args)]
    try:
        if cwd is not None:
            os.chdir(cwd)
        if env is not None:
            os.environ.clear()
            os.environ.update(env)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
            # runpy's warning that the package imported the module it runs: it has, in the tests' process
            warnings.filterwarnings("ignore", "'offroad_path.* found in sys.modules", RuntimeWarning)
            try:
                if module.endswith(".py"):
                    runpy.run_path(module, run_name="__main__")
                else:
                    runpy.run_module(module, run_name="__main__", alter_sys=False)
            except SystemExit as e:
                if isinstance(e.code, str):
                    print(e.code, file=sys.stderr)  # as Python does when it exits with a message
                status = e.code if isinstance(e.code, int) else 0 if e.code is None else 1
    finally:
        sys.argv = argv
        os.chdir(here)
        os.environ.clear()
        os.environ.update(environ)
        signal.signal(signal.SIGTERM, on_sigterm)  # a stage's command installs its own (stage.stop_cleanly_on_sigterm)
        root.handlers[:] = handlers
        root.setLevel(level)
        for name, was in disabled.items():
            logging.getLogger(name).disabled = was
    called = [module] if module.endswith(".py") else ["-m", module]
    return subprocess.CompletedProcess([sys.executable, *called, *map(str, args)], status, out.getvalue(), err.getvalue())


def refused(stage: Callable, cfg, capsys, root: Path, *named: str) -> str:
    """Run `stage` as its command does; assert exit 2, one error line naming `named`, nothing changed under root."""
    before = snapshot(root)
    with pytest.raises(SystemExit) as exit_info:
        run_stage(stage, cfg)
    assert exit_info.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error: ")]
    assert len(lines) == 1, lines
    for text in named:
        assert str(text) in lines[0], lines[0]
    assert snapshot(root) == before
    if record := os.environ.get("OFFROAD_RECORD_MESSAGES"):  # collects the messages for the docs
        with open(record, "a") as f:
            f.write(f"{os.environ.get('PYTEST_CURRENT_TEST', '').split(' ')[0]}\t{lines[0]}\n")
    return lines[0]


def hand_counted_iou(cfg, checkpoint: Path) -> float:
    """The path IoU of a published checkpoint on the first test batch (all that `fast_dev_run`
    tests), counted with NumPy from the argmax at the network's input size, as the task's test
    metric should count it."""
    import torch
    from hydra.utils import instantiate

    from offroad_path.inference.runners import TorchModel

    data = instantiate(cfg.data, target="path", seed=cfg.seed)
    data.setup()
    batch = next(iter(data.test_dataloader()))
    with torch.no_grad():
        predicted = TorchModel(checkpoint).task(batch["image"]).argmax(1).numpy() == 1
    target = batch["target"].numpy() == 1
    tp, fp, fn = (predicted & target).sum(), (predicted & ~target).sum(), (~predicted & target).sum()
    return float(tp / (tp + fp + fn)) if tp + fp + fn else 0.0


def user_folder(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "thesis.tex").write_text("months of work")
    return path


def label_cfg(compose_config, in_dir: Path, tmp_path: Path, *overrides: str):
    return compose_config(f"label.in_dir={in_dir}", f"label.out_dir={tmp_path / 'labels'}", f"label.metrics_path={tmp_path / 'm.json'}",
                          "label.workers=1", "mlflow.enabled=false", *overrides)  # fmt: skip


GIT_IDENTITY = {"GIT_AUTHOR_NAME": "test", "GIT_AUTHOR_EMAIL": "test@example.com", "GIT_COMMITTER_NAME": "test",
                "GIT_COMMITTER_EMAIL": "test@example.com"}  # fmt: skip


def git(repo: Path, *args: str) -> None:
    subprocess.run(["git", *args], cwd=repo, env={**os.environ, **GIT_IDENTITY}, check=True, capture_output=True)


def dvc_command(repo: Path, *args: str) -> dict:
    env = {**{k: v for k, v in os.environ.items() if k != "MLFLOW_TRACKING_URI"}, **GIT_IDENTITY}  # the copy's own mlflow.db
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env['PATH']}"  # `python` in dvc.yaml is this one
    env["PYTHONPATH"] = str(repo / "src")  # the copy's code, not the installed checkout's
    return {"args": [sys.executable, "-m", "dvc", *args], "cwd": repo, "env": env, "text": True}


def in_repo(repo: Path, *args: str) -> str:
    """`python ARGS` in `repo`, on the copy's code (as its dvc stages run)."""
    command = dvc_command(repo)
    run = subprocess.run(**(command | {"args": [sys.executable, *args]}), capture_output=True)
    assert run.returncode == 0, run.stdout + run.stderr
    return run.stdout


def run_notebook(name: str, root: Path, monkeypatch) -> dict:
    """Execute a notebook's code cells top to bottom from `root` (a repository with pipeline outputs); its namespace."""
    import json

    monkeypatch.chdir(root)
    notebook = json.loads((ROOT / "notebooks" / name).read_text())
    namespace: dict = {}
    for cell in notebook["cells"]:
        if cell["cell_type"] == "code":
            exec(compile("".join(cell["source"]), name, "exec"), namespace)
    return namespace


def dvc(repo: Path, *args: str) -> str:
    run = subprocess.run(**dvc_command(repo, *args), capture_output=True)
    assert run.returncode == 0, run.stdout + run.stderr
    return run.stdout


def dvc_at_once(commands: list[tuple[Path, list[str]]]) -> list[str]:
    """dvc commands, each (repository, arguments), in several repositories at the same time (their
    stages are mostly single-threaded start-up: two at once take little longer than one)."""
    runs = [subprocess.Popen(**dvc_command(repo, *args), stdout=subprocess.PIPE, stderr=subprocess.PIPE) for repo, args in commands]
    outputs = [run.communicate() for run in runs]
    for run, (out, err) in zip(runs, outputs, strict=True):
        assert run.returncode == 0, out + err
    return [out for out, _ in outputs]


def tiny_repo(repo: Path) -> Path:
    """The project's pipeline in a fresh git + DVC repo at `repo`, on a tiny preset."""
    for item in ("conf", "src", "dvc.yaml", ".dvcignore"):
        (shutil.copytree if (ROOT / item).is_dir() else shutil.copy)(ROOT / item, repo / item)
    # The tour's preset (conf/experiment/tour.yaml: 12 frames of two drives and a test world, one epoch),
    # with one thread per stage, since two pipelines run at once (tests/repository/test_pipeline_dvc.py).
    tiny = yaml.safe_load((ROOT / "conf" / "experiment" / "tour.yaml").read_text()) | {"threads": 1, "experiment_name": "tiny"}
    del tiny["evaluate"]["architectures"]  # every network of the grid, as conf/evaluate/networks.yaml lists them
    del tiny["mlflow"]  # the default experiment, which the notebooks read (their config is the checkout's)
    (repo / "conf" / "experiment" / "tiny.yaml").write_text("# @package _global_\n" + yaml.safe_dump(tiny))
    primary = repo / "conf" / "config.yaml"
    text = primary.read_text()
    assert "\n  - experiment: null" in text
    primary.write_text(text.replace("\n  - experiment: null", "\n  - experiment: tiny"))
    (repo / "conf" / "mlflow" / "default.yaml").write_text(
        "enabled: false\nexperiment: offroad-path\ntracking_uri: null\nlog_models: true\n"
    )
    grid = repo / "conf" / "evaluate" / "design" / "laptop.yaml"  # one training seed: dvc.yaml's grid reads the list from this file
    text = grid.read_text()
    assert re.search(r"(?m)^seeds: \[0(, \d+)*\]", text)
    grid.write_text(re.sub(r"(?m)^seeds: \[0(, \d+)*\].*$", "seeds: [0]", text, count=1))
    git(repo, "init", "-q")
    subprocess.run([sys.executable, "-m", "dvc", "init", "-q"], cwd=repo, check=True)
    return repo


def saved_epochs(out: Path) -> int:
    """Epochs a training run under `out` has in its resume checkpoint so far (0 before the first)."""
    import torch

    for last in out.glob(".resume/run-*/last.ckpt"):
        try:
            return int(torch.load(last, map_location="cpu", weights_only=True)["epoch"]) + 1
        except Exception:  # being replaced this very moment
            return 0
    return 0


def file_hashes(folder: Path) -> dict[str, str]:
    """sha256 of every file under folder, by its path below it."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.rglob("*")) if p.is_file()}


def png_declaring(path: Path, width: int, height: int) -> Path:
    """A small, valid PNG header and IDAT that declares width x height pixels: a decompression bomb."""

    def chunk(kind: bytes, data: bytes) -> bytes:
        return len(data).to_bytes(4, "big") + kind + data + zlib.crc32(kind + data).to_bytes(4, "big")

    header = width.to_bytes(4, "big") + height.to_bytes(4, "big") + bytes([8, 2, 0, 0, 0])
    rows = zlib.compress(b"\x00" * (1 + 3 * width) * 64, 9)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header) + chunk(b"IDAT", rows) + chunk(b"IEND", b""))
    return path


def evaluate_config(compose_config, split_dir: Path, root: Path, *overrides: str):
    """The evaluate (and postprocess) config over the split fixture's test set, every output under `root`."""
    from offroad_path.data.manifest import read_manifest

    labels_dir = Path(read_manifest(split_dir / "test.csv")[0].label).parents[2]  # <labels>/<sequence>/label/NNNNNN.png
    return compose_config(
        f"split.out_dir={split_dir}", f"split.labels_dir={labels_dir}",
        f"evaluate.steering_from_paths.pilotnet_predictions={root / 'steering' / 'predictions.csv'}",
        "evaluate.seeds=[0]",  # the runs these tests write; one test writes two seeds
        f"evaluate.runs_dir={root / 'runs'}", f"evaluate.postprocessed_dir={root / 'post'}",
        f"evaluate.out_dir={root / 'evaluation'}", f"evaluate.metrics_path={root / 'metrics.json'}",
        f"evaluate.plots_dir={root / 'pr'}", f"mlflow.tracking_uri=sqlite:///{root / 'mlflow.db'}",
        "evaluate.temporal.enabled=false",  # made-up maps, no networks to run on every frame (tests/evaluate/test_temporal.py)
        "split.block_m=1", *overrides,  # the split fixture's test set is one 4 m block: resampled in blocks of 1 m
    )  # fmt: skip


def write_run(compose_config, split_dir: Path, root: Path, run: str, seed: int, maps: np.ndarray) -> None:
    """What train and postprocess write for `run` at `seed`, with `maps` as its predictions."""
    from offroad_path.data.manifest import prediction_name, read_manifest, write_predictions_manifest
    from offroad_path.postprocess import run_postprocess

    samples = read_manifest(split_dir / "test.csv")
    out = root / "runs" / run / f"seed{seed}" / "predictions"
    rows = []
    for sample, m in zip(samples, maps, strict=True):
        (out / sample.sequence).mkdir(parents=True, exist_ok=True)
        np.save(out / prediction_name(sample), m.astype(np.float16))
        rows.append((sample, str(out / prediction_name(sample))))
    write_predictions_manifest(out / "manifest.csv", rows)
    model, pretraining = run.split("-")
    post = root / "post" / run / f"seed{seed}"
    run_postprocess(evaluate_config(compose_config, split_dir, root, f"model={model}", f"pretraining={pretraining}",
                                 f"postprocess.predictions_dir={out}", f"postprocess.out_dir={post}"))  # fmt: skip
