"""predict on a folder, a sequence and a video, and with the exported model; clear errors."""

from __future__ import annotations

import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import torch
from helpers import command

from offroad_path.export import run_export
from offroad_path.geometry.stereo import compute_disparity, depth_from_disparity, sgbm
from offroad_path.predict import run_predict
from offroad_path.predict.frame_sources import open_source
from offroad_path.sequence.reader import open_sequence


@pytest.fixture(scope="module")
def frames(drive) -> list[np.ndarray]:
    seq = open_sequence(drive / "drive")
    return [seq.load_left(i) for i in range(3)]


def predict(compose_config, source: Path, out: Path, *overrides: str) -> dict:
    return run_predict(compose_config(f"predict.input={source}", f"predict.out_dir={out}", *overrides))


def check_overlays(out: Path, frames: list[np.ndarray], threshold_level: int) -> None:
    """Overlay differs from the input exactly where the written confidence is above the threshold."""
    for i, image in enumerate(frames):
        confidence = cv2.imread(str(out / "confidence" / f"{i:06d}.png"), cv2.IMREAD_GRAYSCALE)
        shown = cv2.cvtColor(cv2.imread(str(out / "overlay" / f"{i:06d}.png")), cv2.COLOR_BGR2RGB)
        path = confidence > threshold_level
        assert 0 < path.sum() < path.size  # a real path, not all or nothing
        # 8-bit rounding makes the two levels beside the threshold ambiguous: compare everywhere else
        clear = (confidence != threshold_level) & (confidence != threshold_level + 1)
        np.testing.assert_array_equal((shown != image).any(axis=2)[clear], path[clear])


def test_predict_on_a_folder_of_images(compose_config, trained, frames, tmp_path):
    folder = tmp_path / "images"
    folder.mkdir()
    for i, image in enumerate(frames):
        cv2.imwrite(str(folder / f"{i:06d}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    checkpoint = trained[0]
    first = predict(compose_config, folder, tmp_path / "first", f"predict.checkpoint={checkpoint}")
    assert first["frames"] == 3 and first["fps"] > 0
    # A threshold between two 8-bit levels inside the predicted range, so that both sides are populated.
    level = int(np.median(cv2.imread(str(tmp_path / "first" / "confidence" / "000001.png"), cv2.IMREAD_GRAYSCALE)))
    predict(compose_config, folder, tmp_path / "out", f"predict.checkpoint={checkpoint}", f"predict.threshold={(level + 0.5) / 255}")
    check_overlays(tmp_path / "out", frames, level)
    assert not (tmp_path / "out" / "overlay.mp4").exists()


def test_predict_on_a_sequence_with_post_processing_writes_a_video(compose_config, trained, drive, tmp_path):
    sequence = tmp_path / "three"
    source = drive / "drive"
    (sequence / "image_l").mkdir(parents=True)
    (sequence / "image_r").mkdir()
    shutil.copy(source / "calib.txt", sequence / "calib.txt")
    for i in range(3):
        for side in ("image_l", "image_r"):
            shutil.copy(source / side / f"{i:06d}.png", sequence / side / f"{i:06d}.png")
    summary = predict(compose_config, sequence, tmp_path / "out", f"predict.checkpoint={trained[0]}", "predict.postprocess=true")
    assert summary["frames"] == 3 and len(list((tmp_path / "out" / "confidence").glob("*.png"))) == 3
    video = cv2.VideoCapture(str(tmp_path / "out" / "overlay.mp4"))
    assert video.isOpened() and int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == 3
    # Post-processed: one connected path is left in each map (every kept value is >= delta, so none rounds to 0).
    for i in range(3):
        confidence = cv2.imread(str(tmp_path / "out" / "confidence" / f"{i:06d}.png"), cv2.IMREAD_GRAYSCALE)
        assert cv2.connectedComponents((confidence > 0).astype(np.uint8), connectivity=8)[0] == 2
    # The depth mask reads the pair's StereoSGBM depth, as the label stage computes it.
    frame = next(open_source(sequence, compose_config().label.disparity).frames)
    matcher = sgbm(compose_config().label.disparity)
    seq = open_sequence(sequence)
    expected = depth_from_disparity(compute_disparity(matcher, seq.load_left(0, grey=True), seq.load_right(0, grey=True)),
                                    seq.calibration.fx, seq.calibration.baseline_m)  # fmt: skip
    np.testing.assert_array_equal(frame.depth, expected)
    assert (frame.depth > 0).mean() > 0.5
    # One camera: the same sequence without its right images is predicted without the depth mask.
    shutil.rmtree(sequence / "image_r")
    assert next(open_source(sequence, compose_config().label.disparity).frames).depth is None
    mono = predict(compose_config, sequence, tmp_path / "mono", f"predict.checkpoint={trained[0]}", "predict.postprocess=true")
    assert mono["frames"] == 3 and len(list((tmp_path / "mono" / "confidence").glob("*.png"))) == 3


def test_predict_on_a_video_and_from_an_mlflow_run(compose_config, trained, frames, tmp_path):
    path = tmp_path / "drive.mp4"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 5.0, (frames[0].shape[1], frames[0].shape[0]))
    for image in frames:
        writer.write(cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    writer.release()
    _, run_id, db = trained
    summary = predict(compose_config, path, tmp_path / "out", f"predict.run_id={run_id}", f"mlflow.tracking_uri=sqlite:///{db}")
    assert summary["frames"] == 3
    assert sorted(p.name for p in (tmp_path / "out" / "overlay").iterdir()) == ["000000.png", "000001.png", "000002.png"]
    assert (tmp_path / "out" / "overlay.mp4").stat().st_size > 0


@pytest.mark.slow(seconds=6)
def test_predict_runs_the_exported_model_like_the_checkpoint(compose_config, trained, frames, tmp_path):
    folder = tmp_path / "images"
    folder.mkdir()
    cv2.imwrite(str(folder / "000000.png"), cv2.cvtColor(frames[0], cv2.COLOR_RGB2BGR))
    onnx = tmp_path / "unet.onnx"
    assert run_export(compose_config(f"export.checkpoint={trained[0]}", f"export.out={onnx}")) < 1e-4
    predict(compose_config, folder, tmp_path / "torch", f"predict.checkpoint={trained[0]}")
    predict(compose_config, folder, tmp_path / "onnx", f"predict.checkpoint={onnx}")
    a, b = (cv2.imread(str(tmp_path / k / "confidence" / "000000.png"), cv2.IMREAD_GRAYSCALE).astype(int) for k in ("torch", "onnx"))
    assert np.abs(a - b).max() <= 1
    # predict.threads: the count it asks for, the same confidence (threads split the work, not the sums)
    one = predict(compose_config, folder, tmp_path / "one", f"predict.checkpoint={onnx}", "predict.threads=1")
    assert one["threads"] == 1 and torch.get_num_threads() == 1 and cv2.getNumThreads() == 1
    c = cv2.imread(str(tmp_path / "one" / "confidence" / "000000.png"), cv2.IMREAD_GRAYSCALE).astype(int)
    assert np.array_equal(b, c)


@pytest.mark.parametrize(("make", "message"), [
    (lambda p: (p / "empty").mkdir() or p / "empty", "holds no images"),
    (lambda p: (p / "broken.mp4").write_text("not a video") and p / "broken.mp4", "not a readable video"),
])  # fmt: skip
@pytest.mark.slow(seconds=14)
def test_bad_input_gets_one_clear_line_and_no_output(trained, tmp_path, make, message):
    source = make(tmp_path)
    cli = ["offroad_path.predict", f"predict.checkpoint={trained[0]}", f"predict.input={source}",
           f"predict.out_dir={tmp_path / 'out'}"]  # fmt: skip
    run = command(*cli)
    assert run.returncode == 2
    assert run.stderr.strip().splitlines()[-1] == f"error: {source}: {message}" + (
        " (.png, .jpg, .jpeg, .bmp)" if message == "holds no images" else " (OpenCV could not decode a frame)"
    )
    assert not (tmp_path / "out").exists()


def test_predict_without_an_input_says_what_to_give(trained):
    run = command("offroad_path.predict", f"predict.checkpoint={trained[0]}")
    assert run.returncode == 2
    assert run.stderr.strip().splitlines()[-1] == "error: predict.input is required: give it on the command line, predict.input=..."
