"""Predictions back into ROS, end to end on the committed pipeline's data: a held-out test world of
data/synthetic recorded into an MCAP bag (its rectified pair with CameraInfo, as a robot's driver
publishes it), `predict` with the U-Net checkpoint writing the output bag, and the output read back
with rosbags. Prints frames per second end to end and draws docs/images/predictions_ros.png.

    python benchmarks/predict_ros.py [--world test_000] [--frames 60] [--run unet-segmentation] [--out /tmp/predict_ros]

The figure: one overlay message, every path message from above (camera frame: x right, z forward),
and the steering messages over time beside the drive's recorded steering, both in REP 103's sign.
"""

from __future__ import annotations

import argparse
import math
import shutil
import time
from pathlib import Path

import cv2
import matplotlib
import numpy as np

from offroad_path.config import load_config
from offroad_path.predict import run_predict
from offroad_path.predict.ros_out import typestore
from offroad_path.sequence.reader import open_sequence

matplotlib.use("Agg")
import matplotlib.pyplot as plt


def record_bag(sequence: Path, frames: int, path: Path) -> None:
    """The sequence's first `frames` pairs as /stereo/{left,right}/image_rect (rgb8) and camera_info."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    seq = open_sequence(sequence)
    store, t = typestore(), typestore().types
    P = {"left": seq.calibration.P_left, "right": seq.calibration.P_right}
    width, height = seq.image_size
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        for i in range(min(frames, len(seq))):
            stamp_ns = 1_700_000_000_000_000_000 + int(seq.times[i] * 1e9)
            stamp = t["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
            for side, image in (("left", seq.load_left(i)), ("right", seq.load_right(i))):
                header = t["std_msgs/msg/Header"](stamp=stamp, frame_id=f"camera_{side}")
                info = t["sensor_msgs/msg/CameraInfo"](
                    header=header, height=height, width=width, distortion_model="plumb_bob", d=np.zeros(5), k=P[side][:, :3].ravel(),
                    r=np.eye(3).ravel(), p=P[side].ravel(), binning_x=0, binning_y=0,
                    roi=t["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False))  # fmt: skip
                msg = t["sensor_msgs/msg/Image"](header=header, height=height, width=width, encoding="rgb8", is_bigendian=0,
                                                 step=3 * width, data=image.ravel())  # fmt: skip
                for topic, message in ((f"/stereo/{side}/image_rect", msg), (f"/stereo/{side}/camera_info", info)):
                    if topic not in connections:
                        connections[topic] = writer.add_connection(topic, message.__msgtype__, typestore=store)
                    writer.write(connections[topic], stamp_ns, store.serialize_cdr(message, message.__msgtype__))


def read_back(bag: Path) -> dict[str, list]:
    from rosbags.highlevel import AnyReader

    found: dict[str, list] = {}
    with AnyReader([bag], default_typestore=typestore()) as reader:
        for connection, _, raw in reader.messages():
            found.setdefault(connection.topic, []).append(reader.deserialize(raw, connection.msgtype))
    return found


def figure(got: dict[str, list], recorded_deg: np.ndarray, path: Path, shown: int) -> None:
    fig, axes = plt.subplots(1, 3, figsize=(15, 3.8), gridspec_kw={"width_ratios": [1.6, 1, 1.3]}, constrained_layout=True)
    overlay = cv2.imdecode(np.asarray(got["/offroad_path/overlay/compressed"][shown].data), cv2.IMREAD_COLOR)[:, :, ::-1]
    axes[0].imshow(overlay)
    axes[0].set(title=f"/offroad_path/overlay/compressed, frame {shown}")
    axes[0].axis("off")
    paths = got["/offroad_path/path"]
    colours = plt.cm.viridis(np.linspace(0, 1, len(paths)))
    for message, colour in zip(paths, colours, strict=True):
        xz = np.array([[p.pose.position.x, p.pose.position.z] for p in message.poses]).reshape(-1, 2)
        axes[1].plot(xz[:, 0], xz[:, 1], color=colour, lw=0.8)
    axes[1].set(title="/offroad_path/path, every frame (camera frame)", xlabel="x, m (right)", ylabel="z, m (ahead)", aspect="equal")
    angles = [math.degrees(m.drive.steering_angle) for m in got["/offroad_path/steering"]]
    axes[2].plot(angles, label="pure pursuit on the predicted path")
    axes[2].plot(recorded_deg[: len(angles)], label="the drive's recorded steering", ls="--")
    axes[2].set(title="/offroad_path/steering (REP 103: + left)", xlabel="frame", ylabel="road-wheel angle, deg")
    axes[2].legend(fontsize=8)
    fig.savefig(path, dpi=80)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--world", default="test_000")
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--run", default="unet-segmentation")
    parser.add_argument("--out", type=Path, default=Path("/tmp/predict_ros"))
    parser.add_argument("--figure", type=Path, default=Path("docs/images/predictions_ros.png"))
    args = parser.parse_args()
    shutil.rmtree(args.out, ignore_errors=True)
    args.out.mkdir(parents=True)
    sequence = Path("data/synthetic") / args.world
    record_bag(sequence, args.frames, args.out / "input")
    seq = open_sequence(sequence)
    vehicle = seq.meta["vehicle"]
    cfg = load_config(f"predict.checkpoint=data/runs/{args.run}/seed0/checkpoints/best.ckpt", f"predict.input={args.out / 'input'}",
                      f"predict.out_dir={args.out / 'predictions'}", "predict.postprocess=true", "threads=2",
                      f"ingest.footprint.camera_height_m={seq.meta['camera_height_m']}",
                      f"ingest.footprint.camera_pitch_deg={seq.meta['camera_pitch_deg']}",
                      f"predict.ros.wheelbase_m={vehicle['wheelbase_m']}",
                      f"predict.ros.rear_axle_behind_camera_m={vehicle['camera_forward_m'] + vehicle['wheelbase_m'] / 2}")  # fmt: skip
    start = time.perf_counter()
    summary = run_predict(cfg)
    seconds = time.perf_counter() - start
    got = read_back(args.out / "predictions" / "bag")
    counts = ", ".join(f"{topic} {len(messages)}" for topic, messages in got.items())
    print(f"{summary['frames']} frames in {seconds:.1f} s ({summary['frames'] / seconds:.1f} frames/s end to end, "
          f"{summary['model_fps']:.1f} in the model); messages per topic: {counts}")  # fmt: skip
    recorded_deg = -seq.steering * vehicle["max_steering_deg"]  # steering.txt: + right, over the lock
    figure(got, recorded_deg, args.figure, shown=min(20, summary["frames"] - 1))
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
