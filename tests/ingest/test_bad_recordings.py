"""Recordings that lie: calibrations and CameraInfo with impossible values, frames too large or of
another size mid-stream, truncated videos, one source given as both cameras, images that would
overwrite each other. Each case exits 2 with one line naming the file, topic or key, and leaves
every file under the test's folder as it was (an earlier good output included)."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from helpers import command, png_declaring, refused
from raw_rig import RosMessages, write_bag

from offroad_path.errors import InputError
from offroad_path.ingest import ingest
from offroad_path.predict import run_predict
from offroad_path.recordings.bags import decode_image
from offroad_path.recordings.rig_calibration import read_rig

LEFT, RIGHT = "/stereo/left/image_raw", "/stereo/right/image_raw"
ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def frames(raw_drive):
    return raw_drive[:12]


def bag_config(compose_config, bag: Path, out: Path, *overrides: str):
    return compose_config(f"ingest.bag={bag}", f"ingest.topics.left={LEFT}", f"ingest.topics.right={RIGHT}", f"ingest.out_dir={out}",
                          *overrides)  # fmt: skip


@pytest.fixture(scope="module")
def good_output(compose_config, rig, frames, tmp_path_factory) -> Path:
    """The output of an earlier good ingest, which a refused run must leave as it is: the tests refusing
    a run into it check that nothing changed in its folder (where a run's temporary folder would go too)."""
    root = tmp_path_factory.mktemp("good")
    bag = write_bag(root / "bag", "sqlite3", frames, rig)
    ingest(bag_config(compose_config, bag, root / "out"))
    return root / "out"


@pytest.mark.parametrize("fx,says", [(float("nan"), "not a finite number"), (-350.0, "must be positive")], ids=["NaN", "negative"])
def test_a_camera_info_with_an_impossible_focal_length(compose_config, rig, frames, good_output, tmp_path, capsys, fx, says):
    infos = rig.camera_infos()
    infos[0]["k"] = infos[0]["k"].copy()
    infos[0]["k"][0] = fx
    bag = write_bag(tmp_path / "drive", "mcap", frames, rig, camera_infos=infos)
    refused(ingest, bag_config(compose_config, bag, good_output), capsys, good_output.parent, str(bag), "left camera", says)


def ros_yaml(path: Path, info: dict) -> Path:
    def block(key: str, rows: int, cols: int) -> dict:
        return {"rows": rows, "cols": cols, "data": np.asarray(info[key]).tolist()}

    path.write_text(yaml.safe_dump({"image_width": info["width"], "image_height": info["height"], "distortion_model": "plumb_bob",
                                    "camera_matrix": block("k", 3, 3), "distortion_coefficients": block("d", 1, 5),
                                    "rectification_matrix": block("r", 3, 3), "projection_matrix": block("p", 3, 4)}))  # fmt: skip
    return path


def kalibr(path: Path, rig, coefficients: int, resolution: list[int]) -> Path:
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = rig.R, rig.T
    cams = {f"cam{i}": {"camera_model": "pinhole", "intrinsics": K[[0, 1, 0, 1], [0, 1, 2, 2]].tolist(), "distortion_model": "radtan",
                        "distortion_coeffs": D[:coefficients].tolist(), "resolution": resolution}
            for i, (K, D) in enumerate(zip(rig.K, rig.D, strict=True))}  # fmt: skip
    cams["cam1"]["T_cn_cnm1"] = T.tolist()
    path.write_text(yaml.safe_dump(cams))
    return path


def test_calibration_files_with_impossible_values(rig, tmp_path):
    left, right = rig.camera_infos()
    left["k"] = left["k"].copy()
    left["k"][4] = -left["k"][4]  # fy < 0: mirrored rows
    with pytest.raises(InputError, match="fy = -350 must be positive"):
        read_rig(ros_yaml(tmp_path / "left.yaml", left), ros_yaml(tmp_path / "right.yaml", right))
    left["k"][4] = float("nan")
    with pytest.raises(InputError, match="not a finite number"):
        read_rig(ros_yaml(tmp_path / "left.yaml", left), ros_yaml(tmp_path / "right.yaml", right))
    with pytest.raises(InputError, match="distortion has 2 coefficients"):
        read_rig(kalibr(tmp_path / "two.yaml", rig, 2, list(rig.size)))
    with pytest.raises(InputError, match="image size 0x0 must be positive"):
        read_rig(kalibr(tmp_path / "empty.yaml", rig, 4, [0, 0]))


def test_a_frame_declaring_too_many_pixels_is_refused_before_decoding(tmp_path):
    ros = RosMessages(ros1=False)
    bomb = np.frombuffer(png_declaring(tmp_path / "bomb.png", 20000, 20000).read_bytes(), np.uint8)
    compressed = ros.types["sensor_msgs/msg/CompressedImage"](header=ros.header(1.0, "left"), format="png", data=bomb)
    with pytest.raises(InputError, match=r"declares too many pixels \(Image size \(400000000 pixels"):
        decode_image(compressed, LEFT, tmp_path / "drive.mcap")
    raw = ros.types["sensor_msgs/msg/Image"](header=ros.header(1.0, "left"), height=20000, width=20000, encoding="rgb8", is_bigendian=0,
                                             step=60000, data=np.zeros(16, np.uint8))  # fmt: skip
    with pytest.raises(InputError, match="declares 20000x20000 pixels"):
        decode_image(raw, LEFT, tmp_path / "drive.mcap")


def test_a_frame_of_another_size_mid_stream(compose_config, rig, frames, good_output, tmp_path, capsys):
    cropped = [(left[:-8, :-8], right[:-8, :-8]) if i == 6 else (left, right) for i, (left, right) in enumerate(frames)]
    bag = write_bag(tmp_path / "drive", "sqlite3", cropped, rig)
    w, h = rig.size
    refused(ingest, bag_config(compose_config, bag, good_output), capsys, good_output.parent, str(bag), f"are {w - 8}x{h - 8}",
            f"first {w}x{h}")  # fmt: skip


def test_one_topic_as_both_cameras(compose_config, rig, frames, good_output, tmp_path, capsys):
    bag = write_bag(tmp_path / "drive", "sqlite3", frames, rig)
    cfg = bag_config(compose_config, bag, good_output, f"ingest.topics.right={LEFT}")
    refused(ingest, cfg, capsys, good_output.parent, str(bag), "both", LEFT)


def write_avi(path: Path, images: list[np.ndarray], fps: float = 5.0) -> Path:
    """Motion JPEG in AVI: its header declares the frame count, so a cut file still opens."""
    h, w = images[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    for image in images:
        writer.write(image)
    writer.release()
    return path


def truncate(path: Path) -> Path:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    return path


@pytest.fixture
def calibration(rig, tmp_path) -> Path:
    return kalibr(tmp_path / "camchain.yaml", rig, 4, list(rig.size))


def test_a_truncated_video_is_refused_not_half_ingested(compose_config, frames, calibration, tmp_path, capsys):
    left = write_avi(tmp_path / "left.avi", [pair[0] for pair in frames])
    right = truncate(write_avi(tmp_path / "right.avi", [pair[1] for pair in frames]))
    cfg = compose_config(f"ingest.videos.left={left}", f"ingest.videos.right={right}", f"ingest.calibration={calibration}",
                         "ingest.videos.offset_frames=0", f"ingest.out_dir={tmp_path / 'out'}")  # fmt: skip
    refused(ingest, cfg, capsys, tmp_path, str(right), f"declares {len(frames)} frames but only")


def test_a_video_pair_of_unequal_lengths_is_refused_not_half_dropped(compose_config, frames, calibration, tmp_path, capsys):
    """A bag refuses more than ingest.max_unpaired_fraction of images without a partner; two videos of
    12 and 6 frames once ingested 6 pairs and dropped the rest without a word."""
    left = write_avi(tmp_path / "left.avi", [pair[0] for pair in frames])
    right = write_avi(tmp_path / "right.avi", [pair[1] for pair in frames[: len(frames) // 2]])
    cfg = compose_config(f"ingest.videos.left={left}", f"ingest.videos.right={right}", f"ingest.calibration={calibration}",
                         "ingest.videos.offset_frames=0", f"ingest.out_dir={tmp_path / 'out'}")  # fmt: skip
    unpaired = len(frames) - len(frames) // 2
    refused(ingest, cfg, capsys, tmp_path, str(right), f"{unpaired} of {len(frames) + len(frames) // 2} frames have no partner")


def test_one_video_as_both_cameras(compose_config, frames, calibration, tmp_path, capsys):
    video = write_avi(tmp_path / "left.avi", [pair[0] for pair in frames])
    cfg = compose_config(f"ingest.videos.left={video}", f"ingest.videos.right={tmp_path / '.' / 'left.avi'}",
                         f"ingest.calibration={calibration}", f"ingest.out_dir={tmp_path / 'out'}")  # fmt: skip
    refused(ingest, cfg, capsys, tmp_path, "left.avi", "is also ingest.videos.left")


def test_predict_refuses_a_truncated_video(compose_config, trained, frames, tmp_path, capsys):
    video = truncate(write_avi(tmp_path / "drive.avi", [pair[0] for pair in frames]))
    cfg = compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={video}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, str(video), "truncated or damaged")


def test_predict_refuses_two_images_that_would_write_one_output(compose_config, trained, frames_folder, tmp_path, capsys):
    first = sorted(frames_folder.iterdir())[0]
    twin = first.with_suffix(".jpg")
    cv2.imwrite(str(twin), cv2.imread(str(first)))
    cfg = compose_config(f"predict.checkpoint={trained[0]}", f"predict.input={frames_folder}", f"predict.out_dir={tmp_path / 'out'}")
    refused(run_predict, cfg, capsys, tmp_path, str(first), f"has the name of {twin.name}")


def test_calibrate_refuses_a_zero_square_and_an_out_in_a_missing_folder(tmp_path):
    def calibrate(*args: str) -> subprocess.CompletedProcess:
        return command("offroad_path.calibrate", tmp_path, tmp_path, "--board", "10x7", *args, cwd=ROOT)

    zero = calibrate("--square-m", "0", "--out", str(tmp_path / "rig.yaml"))
    assert zero.returncode == 2 and zero.stderr.strip().splitlines() == [
        "error: python -m offroad_path.calibrate: argument --square-m: '0' is not a number > 0 (--help lists the arguments)"
    ]
    missing = calibrate("--square-m", "0.04", "--out", str(tmp_path / "nowhere" / "rig.yaml"))
    assert missing.returncode == 2
    assert missing.stderr.strip().splitlines() == [
        f"error: {tmp_path / 'nowhere'}: is not a folder: --out must name a file in an existing folder"
    ]
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "overrides,says",
    [
        (["label.strid_m=1"], "Could not override 'label.strid_m'"),
        (["label.stride_m=abc"], "label.stride_m=abc"),
        (["model=segnt"], "Could not find 'model/segnt' Available options in 'model': fcn segnet unet"),
        (["-m", "hparams_search=path_optuna", "model.lr=tag(log, interval(0.1, 0.0003))"], "The `low` value must be smaller"),
    ],
    ids=["typo", "type", "choice", "reversed search range"],
)
@pytest.mark.slow(seconds=17)
def test_hydra_and_search_errors_are_one_line_exit_2(tmp_path, overrides, says):
    stage = "train" if "-m" in overrides else "label"
    run = command(f"offroad_path.{stage}", *overrides, f"hydra.run.dir={tmp_path / 'h'}", f"hydra.sweep.dir={tmp_path / 's'}", cwd=tmp_path)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: ") and says in lines[0], run.stderr[-2000:]
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_manifest_booleans_are_read_strictly(split_dir, tmp_path):
    from offroad_path.data.manifest import read_manifest

    shutil.copytree(split_dir, tmp_path / "split")
    manifest = tmp_path / "split" / "train.csv"
    rows = manifest.read_text().splitlines()
    rows[1] = rows[1].replace(",False,", ",TRUE,").replace(",True,", ",TRUE,")  # as a spreadsheet saves it
    rows[2] = rows[2].replace(",False,", ",yes,").replace(",True,", ",yes,")
    manifest.write_text("\n".join(rows[:2]) + "\n")
    assert read_manifest(manifest)[0].mirrored is True
    manifest.write_text("\n".join(rows[:3]) + "\n")
    with pytest.raises(ValueError, match="row 3, column mirrored: 'yes' is not true, false, 1 or 0"):
        read_manifest(manifest)


def test_images_resized_after_calibrating_are_refused_naming_the_calibration(drive, tmp_path):
    """Frames at half size beside the full-size calibration: before, every label was projected off
    the image and dropped, exit 0 and no word."""
    from offroad_path.sequence.reader import open_sequence

    copy = tmp_path / "drive"
    shutil.copytree(drive / "drive", copy, ignore=shutil.ignore_patterns("depth", "semantic"))
    assert open_sequence(copy).image_size  # as recorded: accepted
    for image in [*copy.glob("image_l/*.png"), *copy.glob("image_r/*.png")]:
        frame = cv2.imread(str(image))
        cv2.imwrite(str(image), cv2.resize(frame, (frame.shape[1] // 2, frame.shape[0] // 2)))
    with pytest.raises(InputError, match=rf"^{copy / 'calib.txt'}: principal point .* the calibration is for another image size"):
        open_sequence(copy)
