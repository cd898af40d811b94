"""Run a trained path model on new footage: a folder of images, a stereo sequence, a video, or a ROS bag.

    python -m offroad_path.predict predict.checkpoint=data/runs/unet-none/seed0/checkpoints/best.ckpt predict.input=drive.mp4
    python -m offroad_path.predict predict.run_id=<MLflow training run> predict.input=data/synthetic/seq_001 predict.postprocess=true
    python -m offroad_path.predict predict.checkpoint=exports/segnet-none.onnx predict.input=images/
    python -m offroad_path.predict predict.checkpoint=... predict.input=drive.bag ingest.footprint.camera_height_m=1.2 \
        ingest.footprint.camera_pitch_deg=5 [ingest.topics.left=... ingest.topics.right=...]

Writes predict.out_dir: confidence/NAME.png (path confidence, 0-255), overlay/NAME.png (the
path, C > predict.threshold, tinted over the image) and, for a video, a sequence or a bag,
overlay.mp4. From a bag also bag/: the predictions as ROS messages in MCAP (predict/ros_out.py).
Post-processing uses the stereo depth mask only where the input is stereo (a sequence or a bag).
"""

from __future__ import annotations

import logging
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from contextlib import nullcontext
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
from omegaconf import DictConfig
from tqdm import tqdm

from offroad_path.inference.path_filter import PostprocessParams, postprocess
from offroad_path.predict.frame_sources import FrameSource, is_bag, open_source
from offroad_path.predict.ros_out import PredictionBag
from offroad_path.stage import hydra_stage, reads
from offroad_path.steering.pure_pursuit import GroundCamera
from offroad_path.utils.atomic import atomic_directory
from offroad_path.utils.media import VideoFile, write_image
from offroad_path.utils.outputs import Outputs
from offroad_path.utils.rules import ConfigValueError
from offroad_path.utils.threads import set_threads
from offroad_path.utils.tracking import tracking_uri
from offroad_path.viz import overlay

log = logging.getLogger("offroad_path.predict")
DEFAULT_FPS = 10.0
WRITES_AHEAD = 4  # frames the writer thread may fall behind (their images wait in memory)


def write_frame(tmp: Path, name: str, confidence: np.ndarray, shown: np.ndarray, video: VideoFile | None) -> None:
    """One frame's outputs: confidence/NAME.png, overlay/NAME.png and the video's next frame."""
    write_image(tmp / "confidence" / f"{name}.png", np.rint(np.clip(confidence, 0, 1) * 255).astype(np.uint8))
    shown = cv2.cvtColor(shown, cv2.COLOR_RGB2BGR)
    write_image(tmp / "overlay" / f"{name}.png", shown)
    if video is not None:
        video.write(shown)


def outputs(cfg: DictConfig) -> Outputs:
    predict = cfg.predict
    return Outputs("predict", folders={"predict.out_dir": predict.out_dir}, inputs=[predict.input, predict.checkpoint])


def ground_camera(cfg: DictConfig, source: FrameSource) -> GroundCamera:
    """The bag's rectified left camera over the ground, for the path message and the steering."""
    r = cfg.predict.ros
    return GroundCamera(source.K, r.camera_height_m, r.camera_pitch_deg + source.pitch_change_deg, r.rear_axle_behind_camera_m)


def check_ground(cfg: DictConfig) -> None:
    """With a bag input, before anything is read: the camera's height and pitch are given."""
    if not (Path(cfg.predict.input).exists() and is_bag(Path(cfg.predict.input))):
        return
    for key in ("camera_height_m", "camera_pitch_deg"):
        if cfg.predict.ros[key] is None:
            raise ConfigValueError(
                f"predict.ros.{key} is required with a bag input (or ingest.footprint.{key}): the path is put on the ground with it"
            )


@reads("predict", "postprocess", "label", "ingest", "mlflow", writes=outputs)
def run_predict(cfg: DictConfig) -> dict:
    from offroad_path.inference.runners import load_model  # torch: after the config is checked

    p, pp = cfg.predict, cfg.postprocess
    check_ground(cfg)
    threads = set_threads(p.threads)  # "free" by default: a busy machine gets fewer threads, not a collapse
    model = load_model(p.checkpoint, p.run_id, tracking_uri(cfg.mlflow), p.device, threads)
    source = open_source(p.input, cfg.label.disparity if p.postprocess else None, p.max_frames, p.max_image_pixels, cfg.ingest)
    camera = ground_camera(cfg, source) if source.kind == "bag" else None
    fps = p.video_fps or source.fps or DEFAULT_FPS
    frames, model_seconds, start = 0, 0.0, time.perf_counter()
    # Encoding the PNGs and the video took as long as the network: a writer thread does it (OpenCV
    # lets go of the GIL) while the next frame is read and run; one thread keeps the video in order.
    with (
        atomic_directory(p.out_dir, "predict", key="predict.out_dir") as tmp,
        ThreadPoolExecutor(1) as writer,
        PredictionBag(tmp / "bag", p.ros, camera, p.threshold) if camera else nullcontext() as bag,
    ):
        (tmp / "confidence").mkdir()
        (tmp / "overlay").mkdir()
        video, pending = None, deque()
        for frame in tqdm(source.frames, total=source.count, unit="frame", desc=f"predict {source.kind}"):
            t0 = time.perf_counter()
            (confidence,) = model([frame.image])
            model_seconds += time.perf_counter() - t0
            if p.postprocess:
                params = replace(PostprocessParams.from_config(pp), use_depth=pp.use_depth and frame.depth is not None)
                confidence = postprocess(confidence, frame.depth, params)
            shown = overlay(frame.image, confidence > p.threshold, outline=False)
            if source.kind != "folder" and video is None:
                video = VideoFile(tmp / "overlay.mp4", fps, shown.shape[1::-1])
            pending.append(writer.submit(write_frame, tmp, frame.name, confidence, shown, video))
            if bag is not None:
                bag.write(frame.header, confidence, cv2.cvtColor(shown, cv2.COLOR_RGB2BGR))
            if len(pending) > WRITES_AHEAD:
                pending.popleft().result()  # a failed write stops the run here
            frames += 1
        for write in pending:
            write.result()
        if video is not None:
            video.close()  # OSError when the file does not hold every frame (a full disk)
    seconds = time.perf_counter() - start
    summary = {
        "frames": frames,
        "threads": threads,
        "seconds": seconds,
        "fps": frames / seconds,
        "model_fps": frames / max(model_seconds, 1e-9),
    }
    print(
        f"{frames} frames in {seconds:.1f} s: {summary['fps']:.1f} frames/s end to end, {summary['model_fps']:.1f} frames/s "
        f"in the model ({type(model).__name__}, {model.width} x {model.height}, {threads} threads); written to {p.out_dir}"
    )
    return summary


main = hydra_stage(run_predict)
