"""Careless use and crafted files: outputs pointed at inputs or at the user's folders, and
checkpoints that are unsafe, corrupt or foreign. Each case exits 2 with one line naming the file or
the key, and leaves every file under the test's folder as it was (hashed before and after)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from helpers import command, label_cfg, refused, snapshot, user_folder

from offroad_path.evaluate import evaluate
from offroad_path.export import run_export
from offroad_path.label import label
from offroad_path.postprocess import run_postprocess
from offroad_path.predict import run_predict
from offroad_path.split import split
from offroad_path.synthesize import synthesize
from offroad_path.train import train
from offroad_path.utils.atomic import MARKER, UnsafeOutputError, write_text_atomic
from offroad_path.utils.outputs import Outputs, check_metrics_follow

ROOT = Path(__file__).resolve().parents[2]


# -- 1. Outputs never replace an input or a folder the project did not make ----------------------


@pytest.mark.parametrize("where", ["same", "inside", "around"])
def test_label_out_dir_overlapping_its_input(compose_config, recordings, tmp_path, capsys, where):
    out = {"same": recordings, "inside": recordings / "drive" / "labels", "around": tmp_path}[where]
    cfg = label_cfg(compose_config, recordings, tmp_path, f"label.out_dir={out}")
    refused(label, cfg, capsys, tmp_path, "label.out_dir", "overlaps the input")


def test_label_out_dir_that_is_a_file(compose_config, recordings, tmp_path, capsys):
    (tmp_path / "labels").write_text("a file")
    refused(label, label_cfg(compose_config, recordings, tmp_path), capsys, tmp_path, "label.out_dir", "not a folder")


def test_synthesize_into_a_users_folder(compose_config, tmp_path, capsys):
    out = user_folder(tmp_path / "mine")
    cfg = compose_config(f"synthesize.out_dir={out}", "synthesize.sequences=1", "world.frames=2")
    refused(synthesize, cfg, capsys, tmp_path, "synthesize.out_dir", "did not write")


def test_split_into_its_labels(compose_config, labelled_drive, tmp_path, capsys):
    cfg = compose_config(f"split.labels_dir={labelled_drive}", f"split.out_dir={labelled_drive}")
    refused(split, cfg, capsys, labelled_drive, "split.out_dir", "overlaps the input")


def test_train_into_a_users_folder_before_any_training(tiny_config, tmp_path, capsys):
    out = user_folder(tmp_path / "run")
    refused(train, tiny_config(tmp_path, "mlflow.enabled=false"), capsys, tmp_path, f"train.out_dir={out}", "did not write")


def test_postprocess_into_its_predictions(compose_config, trained, tmp_path, capsys):
    predictions = trained[0].parents[1] / "predictions"
    cfg = compose_config(f"postprocess.predictions_dir={predictions}", f"postprocess.out_dir={predictions}")
    refused(run_postprocess, cfg, capsys, predictions, "postprocess.out_dir", "overlaps the input")


def test_evaluate_into_a_users_folder(compose_config, split_dir, tmp_path, capsys):
    out = user_folder(tmp_path / "results")
    cfg = compose_config(
        f"evaluate.out_dir={out}", f"evaluate.runs_dir={tmp_path / 'runs'}", f"evaluate.train_manifest={split_dir / 'train.csv'}"
    )
    refused(evaluate, cfg, capsys, tmp_path, "evaluate.out_dir", "did not write")


@pytest.mark.parametrize("where", ["input", "users"])
def test_predict_into_its_input_or_a_users_folder(compose_config, trained, frames_folder, tmp_path, capsys, where):
    out = frames_folder if where == "input" else user_folder(tmp_path / "mine")
    cfg = compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={frames_folder}", f"predict.out_dir={out}")
    refused(run_predict, cfg, capsys, tmp_path, "predict.out_dir", "overlaps the input" if where == "input" else "did not write")


@pytest.mark.slow(seconds=4)
def test_a_stale_temporary_folder_of_a_killed_run_is_removed(compose_config, recordings, tmp_path):
    stale = tmp_path / ".labels.tmp-999999999-abc"  # no such process
    stale.mkdir()
    (stale / MARKER).write_text("label\n")
    label(label_cfg(compose_config, recordings, tmp_path))
    assert not stale.exists() and (tmp_path / "labels" / MARKER).read_text() == "label\n"


@pytest.mark.parametrize("name", ["notes.txt", "models"])
def test_export_never_replaces_a_file_or_folder_that_is_not_onnx(compose_config, trained, tmp_path, capsys, name):
    target = tmp_path / name
    target.write_text("mine") if name.endswith(".txt") else user_folder(target)
    refused(run_export, compose_config(f"export.checkpoint={trained[0]}", f"export.out={target}"), capsys, tmp_path, "export.out", name)


# -- 1b. Every output, file or folder, against everything the stage reads -----------------------


def test_label_metrics_path_on_a_recordings_calibration(compose_config, recordings, tmp_path, capsys):
    calib = recordings / "drive" / "calib.txt"
    cfg = label_cfg(compose_config, recordings, tmp_path, f"label.metrics_path={calib}")
    refused(label, cfg, capsys, tmp_path, f"label.metrics_path={calib}", "overlaps the input")


def test_evaluate_metrics_path_on_the_splits_manifest(compose_config, split_dir, tmp_path, capsys):
    manifest = split_dir / "train.csv"
    cfg = compose_config(f"evaluate.metrics_path={manifest}", f"evaluate.train_manifest={manifest}", f"evaluate.out_dir={tmp_path / 'e'}",
                         f"evaluate.plots_dir={tmp_path / 'p'}")  # fmt: skip
    refused(evaluate, cfg, capsys, split_dir, f"evaluate.metrics_path={manifest}", "overlaps the input")


def test_evaluate_out_dir_on_its_label_run(compose_config, labelled_drive, split_dir, tmp_path, capsys):
    cfg = compose_config(f"evaluate.out_dir={labelled_drive}", f"evaluate.labels_dir={labelled_drive}",
                         f"evaluate.train_manifest={split_dir / 'train.csv'}", f"evaluate.plots_dir={tmp_path / 'p'}")  # fmt: skip
    refused(evaluate, cfg, capsys, labelled_drive, f"evaluate.out_dir={labelled_drive}", "overlaps the input")


def test_train_out_dir_on_the_label_run_its_manifests_read(tiny_config, labelled_drive, tmp_path, capsys):
    cfg = tiny_config(tmp_path, f"train.out_dir={labelled_drive}", "mlflow.enabled=false")
    refused(train, cfg, capsys, labelled_drive, f"train.out_dir={labelled_drive}", f"overlaps the input {labelled_drive}")


def test_predict_never_replaces_another_stages_output(compose_config, trained, frames_folder, labelled_drive, capsys):
    cfg = compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={frames_folder}", f"predict.out_dir={labelled_drive}")
    refused(run_predict, cfg, capsys, labelled_drive, f"predict.out_dir={labelled_drive}", "output of the label stage")


def test_a_metrics_file_the_project_did_not_write_is_kept(compose_config, recordings, tmp_path, capsys):
    (tmp_path / "m.json").write_text("my notes")
    refused(label, label_cfg(compose_config, recordings, tmp_path), capsys, tmp_path, "label.metrics_path", "not written by this project")


def test_a_metrics_path_below_a_file_is_refused_before_any_work(compose_config, recordings, tmp_path, capsys):
    (tmp_path / "notes").write_text("mine")
    cfg = label_cfg(compose_config, recordings, tmp_path, f"label.metrics_path={tmp_path / 'notes' / 'metrics' / 'm.json'}")
    refused(label, cfg, capsys, tmp_path, "label.metrics_path", "is not a folder")


def test_outputs_of_one_stage_may_not_overlap_each_other(compose_config, recordings, tmp_path, capsys):
    cfg = label_cfg(compose_config, recordings, tmp_path, f"label.metrics_path={tmp_path / 'labels' / 'm.json'}")
    refused(label, cfg, capsys, tmp_path, "label.metrics_path", "overlaps label.out_dir")


def test_label_of_other_data_never_writes_the_pipelines_metrics(compose_config, recordings, tmp_path, capsys):
    """A copy of a recording labelled elsewhere, from a config whose metrics go to the pipeline's
    metrics folder (the committed run's, in the checkout): refused, naming label.metrics_path."""
    pipeline = tmp_path / "pipeline"
    metrics = pipeline / "metrics" / "label.json"
    metrics.parent.mkdir(parents=True)
    write_text_atomic(metrics, '{"labels": 1356}\n', "label")  # the pipeline's label run wrote it
    cfg = compose_config(f"paths.root={pipeline}", f"label.in_dir={recordings}", f"label.out_dir={tmp_path / 'elsewhere'}",
                         "label.workers=1", "mlflow.enabled=false")  # fmt: skip
    says = ("outside the pipeline's folders", "set label.metrics_path beside its outputs")
    refused(label, cfg, capsys, tmp_path, "label.metrics_path", *says)


def test_label_of_other_recordings_named_by_paths_never_writes_the_pipelines_metrics(compose_config, recordings, tmp_path, capsys):
    """The same through `paths.recordings_dir`, the pipeline's labels and metrics folders left as they
    are: the recordings lie outside the root's own folders, so the run is of other data. Refused
    naming label.metrics_path, the committed metrics and labels untouched."""
    pipeline = tmp_path / "pipeline"
    metrics = pipeline / "metrics" / "label.json"
    metrics.parent.mkdir(parents=True)
    write_text_atomic(metrics, '{"labels": 1356}\n', "label")
    cfg = compose_config(f"paths.root={pipeline}", f"paths.recordings_dir={recordings}", "label.workers=1", "mlflow.enabled=false")
    refused(label, cfg, capsys, tmp_path, "label.metrics_path", "outside the pipeline's folders", f"the input {recordings}")
    assert metrics.read_text() == '{"labels": 1356}\n' and not (pipeline / "data" / "labels").exists()


def test_metrics_beside_the_outputs_of_other_data_are_allowed(tmp_path):
    outputs = Outputs("label", folders={"label.out_dir": tmp_path / "mine" / "labels"},
                      files={"label.metrics_path": tmp_path / "mine" / "label.json"}, inputs=[tmp_path / "copy"])  # fmt: skip
    check_metrics_follow(outputs, tmp_path / "pipeline" / "metrics", [tmp_path / "pipeline" / "data"])
    pipeline_run = Outputs("label", folders={"label.out_dir": tmp_path / "pipeline" / "data" / "labels"},
                           files={"label.metrics_path": tmp_path / "pipeline" / "metrics" / "label.json"},
                           inputs=[tmp_path / "pipeline" / "data" / "synthetic"])  # fmt: skip
    check_metrics_follow(pipeline_run, tmp_path / "pipeline" / "metrics", [tmp_path / "pipeline" / "data"])
    moved_out = Outputs("label", folders={"label.out_dir": tmp_path / "mine"}, files=dict(pipeline_run.files), inputs=pipeline_run.inputs)
    with pytest.raises(UnsafeOutputError, match=r"label\.metrics_path=.*label\.out_dir="):
        check_metrics_follow(moved_out, tmp_path / "pipeline" / "metrics", [tmp_path / "pipeline" / "data"])


# -- 2. Checkpoints: weights only, and a clear line for anything else ------------------------------


class RunsCode:
    """Unpickling this runs a shell command: what a crafted checkpoint would do."""

    def __init__(self, sentinel: Path):
        self.sentinel = sentinel

    def __reduce__(self):
        return os.system, (f"touch {self.sentinel}",)


def crafted_checkpoint(path: Path, trained_checkpoint: Path) -> Path:
    saved = torch.load(trained_checkpoint, weights_only=True)
    saved["hyper_parameters"]["payload"] = RunsCode(path.parent / "pwned")
    torch.save(saved, path)
    return path


def test_predict_refuses_a_checkpoint_that_would_run_code(compose_config, trained, frames_folder, tmp_path, capsys):
    bad = crafted_checkpoint(tmp_path / "bad.ckpt", trained[0])
    cfg = compose_config(f"predict.checkpoint={bad}", f"predict.input={frames_folder}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, bad, "refused", "it would call posix.system")
    assert not (tmp_path / "pwned").exists()


def test_export_refuses_a_checkpoint_that_would_run_code(compose_config, trained, tmp_path, capsys):
    bad = crafted_checkpoint(tmp_path / "bad.ckpt", trained[0])
    refused(run_export, compose_config(f"export.checkpoint={bad}", f"export.out={tmp_path / 'm.onnx'}"), capsys, tmp_path, bad, "refused")
    assert not (tmp_path / "pwned").exists()


def test_train_refuses_a_pretraining_checkpoint_that_would_run_code(tiny_config, trained, tmp_path, capsys):
    bad = crafted_checkpoint(tmp_path / "bad.ckpt", trained[0])
    cfg = tiny_config(tmp_path, "pretraining=segmentation", f"pretraining.checkpoint={bad}", "mlflow.enabled=false")
    refused(train, cfg, capsys, tmp_path, bad, "refused")
    assert not (tmp_path / "pwned").exists()


@pytest.mark.parametrize(
    ("make", "says"),
    [
        (lambda p, good: p.write_bytes(good.read_bytes()[:5000]), "not a readable PyTorch checkpoint"),
        (lambda p, good: p.write_text("hello"), "not a readable PyTorch checkpoint"),
        (lambda p, good: p.write_bytes(b"c" + np.random.default_rng(0).bytes(4095)), "not a readable PyTorch checkpoint"),
        (lambda p, good: torch.save({"weights": torch.zeros(3)}, p), "not a checkpoint of this project"),
    ],
    ids=["truncated", "text", "random bytes", "foreign dict"],
)
def test_predict_names_a_corrupt_or_foreign_checkpoint(compose_config, trained, frames_folder, tmp_path, capsys, make, says):
    bad = tmp_path / "bad.ckpt"
    make(bad, trained[0])
    cfg = compose_config(f"predict.checkpoint={bad}", f"predict.input={frames_folder}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, bad, says)


def test_predict_refuses_a_segmentation_pretraining_checkpoint(compose_config, trained, frames_folder, tmp_path, capsys):
    semantic = tmp_path / "semantic.ckpt"
    saved = torch.load(trained[0], weights_only=True)
    saved["hyper_parameters"]["num_classes"] = 8
    torch.save(saved, semantic)
    cfg = compose_config(f"predict.checkpoint={semantic}", f"predict.input={frames_folder}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, semantic, "not a path model checkpoint")


def test_predict_refuses_weights_of_another_network(compose_config, trained, frames_folder, tmp_path, capsys):
    other = tmp_path / "other.ckpt"
    saved = torch.load(trained[0], weights_only=True)
    saved["hyper_parameters"]["model"] = "fcn"  # says FCN, holds U-Net weights
    torch.save(saved, other)
    cfg = compose_config(f"predict.checkpoint={other}", f"predict.input={frames_folder}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, other, "do not fit")


def test_a_corrupt_resume_checkpoint_is_named_and_resume_false_starts_afresh(tiny_config, tmp_path, capsys):
    cfg = tiny_config(tmp_path, "model=fcn", "trainer.max_epochs=1", "mlflow.enabled=false")
    train(cfg)
    (last,) = (tmp_path / ".resume").glob("run-*/last.ckpt")
    last.write_bytes(last.read_bytes()[:1000])
    shutil.rmtree(tmp_path / "run")
    refused(train, cfg, capsys, tmp_path, last, "resume=false")
    cfg.resume = False
    assert train(cfg)["global_step"] > 0


def test_a_resume_checkpoint_of_another_configuration_is_refused(tiny_config, tmp_path, capsys):
    first = tiny_config(tmp_path, "model=fcn", "trainer.max_epochs=1", "mlflow.enabled=false")
    train(first)
    (state_a,) = (tmp_path / ".resume").glob("run-*")
    changed = tiny_config(tmp_path, "model=fcn", "trainer.max_epochs=1", "mlflow.enabled=false", "model.lr=0.002")
    train(changed)
    (state_b,) = set((tmp_path / ".resume").glob("run-*")) - {state_a}  # a changed config never shares resume state
    shutil.copy(state_a / "last.ckpt", state_b / "last.ckpt")  # as if it did
    shutil.rmtree(tmp_path / "run")
    refused(train, changed, capsys, tmp_path, state_b / "last.ckpt", "belongs to another configuration")


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_written_files_and_folders_take_the_users_umask(tmp_path, umask):
    from offroad_path.utils.atomic import atomic_directory, write_text_atomic

    old = os.umask(umask)
    try:
        write_text_atomic(tmp_path / "metrics.json", "{}\n", "evaluate")
        with atomic_directory(tmp_path / "out", "split") as tmp:
            (tmp / "a.csv").write_text("x\n")
    finally:
        os.umask(old)
    assert (tmp_path / "metrics.json").stat().st_mode & 0o777 == 0o666 & ~umask
    assert (tmp_path / "out").stat().st_mode & 0o777 == 0o777 & ~umask


def test_paths_own_in_another_checkout_of_the_project_is_refused(tmp_path):
    """With the package installed from one checkout, `paths=own paths.root=.` run in a second one wrote
    into the second's committed metrics: the rule knew only the checkout the code runs from."""
    second = tmp_path / "second"
    for item in ("conf", "metrics", "dvc.yaml"):
        (shutil.copytree if (ROOT / item).is_dir() else shutil.copy)(ROOT / item, second / item)
    (second / "src" / "offroad_path").mkdir(parents=True)
    before = snapshot(second)
    run = command("offroad_path.label", "paths=own", "paths.root=.", "mlflow.enabled=false", cwd=second)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1, run.stderr
    assert lines[0].startswith(f"error: paths.root: . resolves to {second}, which is a checkout of this project ({second})"), lines[0]
    assert snapshot(second) == before
