"""Check recordings before labelling them: `python -m offroad_path.sequence PATH [PATH ...]`.

Opens every sequence under each PATH with the same validation the label stage uses, decodes every
frame, checks the poses' steps against the vehicle's top speed as the label stage does
(label.poses.max_speed_mps, its default unless --max-speed-mps is given), and prints one line per
sequence: stereo pairs, or one camera's frames (a mono sequence, which the label stage labels from
its poses file, without occlusion). Bad input: one line naming the file, exit 2.
"""

from __future__ import annotations

import math

from omegaconf import OmegaConf

from offroad_path.config.common import CONF_DIR
from offroad_path.errors import CommandParser, clear_errors
from offroad_path.geometry.path import path_length
from offroad_path.sequence.poses import max_steps, read_poses
from offroad_path.sequence.reader import find_sequences, open_sequence


def label_max_speed_mps() -> float:
    """The label stage's default label.poses.max_speed_mps (conf/label/default.yaml)."""
    return float(OmegaConf.load(CONF_DIR / "label" / "default.yaml").poses.max_speed_mps)


def describe(path: str, max_speed_mps: float | None = None) -> list[str]:
    speed = label_max_speed_mps() if max_speed_mps is None else max_speed_mps
    setting = "label.poses.max_speed_mps" if max_speed_mps is None else "--max-speed-mps"
    lines = []
    for root in find_sequences(path):
        seq = open_sequence(root)
        if seq.poses_path is not None:  # the jump check the label stage makes on a poses file
            read_poses(seq.poses_path, len(seq), max_steps(seq.times, len(seq), speed), speed_setting=setting)
        for i in range(len(seq)):  # every frame: a truncated one in the middle must not pass
            seq.load_left(i)
            if not seq.mono:
                seq.load_right(i)
            if seq.depth is not None:
                seq.load_depth(i)
            if seq.semantic is not None:
                seq.load_semantic(i)
        w, h = seq.image_size
        travelled = "no poses" + (": label it with label.poses.source=file label.poses.file=PATTERN" if seq.mono else "")
        if seq.poses is not None:
            travelled = f"{path_length(seq.poses):.1f} m of poses"
        extras = [
            name for name, value in (("depth", seq.depth), ("semantic", seq.semantic), ("steering", seq.steering)) if value is not None
        ]
        cameras = (
            f"{len(seq)} frames of one camera (mono: labelled from poses, without occlusion) {w}x{h}, fx {seq.calibration.fx:.1f} px"
            if seq.mono
            else f"{len(seq)} stereo pairs {w}x{h}, fx {seq.calibration.fx:.1f} px, baseline {seq.calibration.baseline_m:.3f} m"
        )
        lines.append(f"{root}: {cameras}, {travelled}" + (f", with {', '.join(extras)}" if extras else ""))
    return lines


def main(argv: list[str] | None = None) -> None:
    parser = CommandParser(prog="python -m offroad_path.sequence", description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="+", help="a sequence folder, or a folder of sequences")
    parser.add_argument("--max-speed-mps", type=float, default=None, help="the top speed poses may show (default: the label stage's)")
    args = parser.parse_args(argv)
    if args.max_speed_mps is not None and not 0 < args.max_speed_mps < math.inf:
        parser.error(f"--max-speed-mps: must be a finite speed above 0 m/s, got {args.max_speed_mps}")
    with clear_errors():
        for path in args.paths:
            for line in describe(path, args.max_speed_mps):
                print(line)


if __name__ == "__main__":
    main()
