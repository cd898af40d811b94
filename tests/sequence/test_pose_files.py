"""Pose files that cannot be a vehicle's drive are refused in one line naming the file and row before any
label is written: a mirrored rotation (det R = -1), a jump no vehicle makes at the recording's frame
rate, poses scaled past any number; and an empty paths.root never writes into the checkout."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import command

from offroad_path.errors import InputError
from offroad_path.sequence.poses import max_steps, poses_to_text, read_poses

ROOT = Path(__file__).resolve().parents[2]


def drive_poses(n: int = 20, step_m: float = 1.0) -> np.ndarray:
    """A straight drive along z, one step per frame, gently yawing."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    for k in range(n):
        yaw = 0.01 * k
        poses[k, :3, :3] = [[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]]
        poses[k, 2, 3] = step_m * k
    return poses


def written(tmp_path: Path, poses: np.ndarray) -> Path:
    path = tmp_path / "poses.txt"
    path.write_text(poses_to_text(poses))
    return path


def test_a_mirrored_rotation_is_refused_naming_its_row(tmp_path):
    poses = drive_poses()
    mirrored = poses.copy()
    mirrored[3:, :3, 0] *= -1  # the x column negated from row 4 on: R^T R = I still, det R = -1
    assert np.allclose(np.einsum("nji,njk->nik", mirrored[:, :3, :3], mirrored[:, :3, :3]), np.eye(3))
    with pytest.raises(InputError, match=r"poses.txt: row 4 is a reflection, not a rotation \(det R = -1: a column negated\?\)"):
        read_poses(written(tmp_path, mirrored))
    assert len(read_poses(written(tmp_path, poses))) == 20


def test_a_step_no_vehicle_makes_is_refused_at_the_recordings_frame_rate(tmp_path):
    poses = drive_poses()
    poses[7:, 0, 3] += 1000.0  # a jump of 1000 m at frame 8
    times = np.arange(20) * 0.1  # 10 fps: 6 m per frame at 60 m/s
    limits = max_steps(times, 20, 60.0)
    assert limits == pytest.approx(np.full(19, 6.0))
    with pytest.raises(InputError, match=r"row 8 is 1e\+03 m from row 7, more than 6 m at label.poses.max_speed_mps"):
        read_poses(written(tmp_path, poses), max_steps_m=limits)
    assert len(read_poses(written(tmp_path, drive_poses(step_m=5.0)), max_steps_m=limits)) == 20  # 50 m/s: a fast car
    assert max_steps(None, 3, 60.0) == pytest.approx([60.0, 60.0])  # no times.txt: 1 s per frame


def test_the_sequence_checker_refuses_the_jump_the_label_stage_refuses(drive, tmp_path, capsys):
    copy = tmp_path / "drive"
    shutil.copytree(drive / "drive", copy, ignore=shutil.ignore_patterns("depth", "semantic"))
    poses = read_poses(copy / "poses.txt")
    poses[7:, 0, 3] += 1000.0  # a jump of 1000 m at frame 8
    (copy / "poses.txt").write_text(poses_to_text(poses))
    check = ["offroad_path.sequence", copy]
    run = command(*check)
    assert run.returncode == 2, run.stdout
    jump = r"row 8 is 1e\+03 m from row 7, more than \S+ m at label.poses.max_speed_mps"
    assert re.fullmatch(rf"error: {copy / 'poses.txt'}: {jump}\n", run.stderr)
    assert command(*check, "--max-speed-mps", "1e6").returncode == 0
    wrong = command(*check, "--max-speed-mps", "0")
    assert wrong.returncode == 2 and "--max-speed-mps" in wrong.stderr
    from offroad_path.sequence.__main__ import main as check_sequences  # the same in-process: the speed it was given is named

    for speed in ("inf", "nan"):
        with pytest.raises(SystemExit) as stopped:
            check_sequences([str(copy), "--max-speed-mps", speed])
        assert stopped.value.code == 2 and "--max-speed-mps: must be a finite speed above 0 m/s" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stopped:
        check_sequences([str(copy), "--max-speed-mps", "20"])
    assert stopped.value.code == 2 and re.search(
        r"row 8 is 1e\+03 m from row 7, more than \S+ m at --max-speed-mps$", capsys.readouterr().err.strip()
    )


def test_poses_scaled_past_any_number_are_refused(tmp_path):
    poses = drive_poses()
    poses[:, :3, :] *= 1e300  # finite numbers, but no rotation: R^T R overflows
    with pytest.raises(InputError, match=r"row 1 is not a rotation \(R\^T R differs from I by inf\)"):
        read_poses(written(tmp_path, poses))


@pytest.mark.slow(seconds=12)
def test_the_label_stage_refuses_a_mirrored_pose_file_before_any_label(drive, tmp_path):
    copy = tmp_path / "mono" / "drive"
    shutil.copytree(drive / "drive", copy, ignore=shutil.ignore_patterns("image_r", "depth", "semantic"))
    poses = read_poses(copy / "poses.txt")
    poses[:, :3, 0] *= -1
    (copy / "poses.txt").write_text(poses_to_text(poses))
    out = tmp_path / "labels"
    run = command("offroad_path.label", f"label.in_dir={copy.parent}", f"label.out_dir={out}",
                  f"label.metrics_path={tmp_path / 'label.json'}", "label.poses.source=file", "label.occlusion.enabled=false",
                  "mlflow.enabled=false")  # fmt: skip
    assert run.returncode == 2, run.stderr
    assert (
        run.stderr.strip().splitlines()[-1]
        == f"error: {copy / 'poses.txt'}: row 1 is a reflection, not a rotation (det R = -1: a column negated?)"
    )
    assert not out.exists() and not (tmp_path / "label.json").exists()


@pytest.mark.slow(seconds=14)
def test_the_readmes_own_data_recipe_with_root_unset_writes_nothing(tmp_path):
    """`OWN="paths=own paths.root=$ROOT"` with ROOT unset is `paths.root=`: one line, exit 2, nothing written
    where it runs (the checkout's data/ and metrics/ are relative to it)."""
    env = {k: v for k, v in os.environ.items() if k != "ROOT"}
    recipe = f'OWN="paths=own paths.root=$ROOT"; {sys.executable} -m offroad_path.label $OWN label.footprint.width_m=1.8'
    run = subprocess.run(["bash", "-c", recipe], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert run.returncode == 2
    assert run.stderr.strip().splitlines()[-1] == (
        "error: paths.root: is empty: give a folder of yours (paths.root=DIR; the checkout's own run: paths.root=.)"
    )
    assert list(tmp_path.iterdir()) == []
    unset = command("offroad_path.label", "experiment=own", cwd=tmp_path)
    assert unset.returncode == 2 and unset.stderr.strip().splitlines()[-1] == (
        "error: paths.root is required (for label.in_dir): give it on the command line, paths.root=..."
    )
    assert list(tmp_path.iterdir()) == []


def test_bag_poses_are_put_in_stamp_order_and_conflicting_or_broken_ones_refused():
    from offroad_path.recordings.bags import in_stamp_order, pose_matrix

    where = "field.bag: /tf"
    poses = np.stack([pose_matrix((0, 0, 0, 1), (0, 0, z), where) for z in (0.0, 1.0, 2.0, 3.0)])
    times = np.array([0.0, 0.2, 0.1, 0.3])  # recorded as they arrived: 0.2 before 0.1
    t, p = in_stamp_order(times, poses, where)
    assert list(t) == [0.0, 0.1, 0.2, 0.3] and list(p[:, 2, 3]) == [0.0, 2.0, 1.0, 3.0]
    t, p = in_stamp_order(np.array([0.0, 0.1, 0.1]), poses[[0, 1, 1]], where)  # the same pose twice: once
    assert list(t) == [0.0, 0.1] and len(p) == 2
    with pytest.raises(InputError, match=r"field.bag: /tf: two different poses at the same stamp 0.100000 s"):
        in_stamp_order(np.array([0.0, 0.1, 0.1]), poses[:3], where)
    with pytest.raises(InputError, match=r"field.bag: /tf at 3.5 s: a pose whose orientation quaternion \(0, 0, 0, 0\) has zero norm"):
        pose_matrix((0, 0, 0, 0), (1, 2, 3), "field.bag: /tf at 3.5 s")
    with pytest.raises(InputError, match=r"a pose with a non-finite value \(orientation \(0, 0, 0, nan\)"):
        pose_matrix((0, 0, 0, float("nan")), (1, 2, 3), where)
    with pytest.raises(InputError, match=r"position \(nan, 2, 3\)"):
        pose_matrix((0, 0, 0, 1), (float("nan"), 2, 3), where)


@pytest.mark.slow(seconds=15)  # a stage's process each: its imports take most of it
@pytest.mark.parametrize("root", [".", "./", "{checkout}", "../{name}", "{link}", "{metrics_link}", "/", "..@../dvc.yaml:label"])
def test_a_root_that_is_in_or_holds_the_checkout_is_refused_and_nothing_is_written(tmp_path, root):
    """`paths=own` with a root that is the checkout, in it, holding it, or reaching it through a link
    (the root itself, or its metrics/): one line naming the key, exit 2, the committed metrics untouched.
    The exception for the checkout's own pipelines run by DVC holds for those alone: a DVC_STAGE naming
    a dvc.yaml outside the checkout (`../dvc.yaml`, whose folder holds it) is no exception."""
    from helpers import ROOT

    (tmp_path / "link").symlink_to(ROOT)
    (tmp_path / "own").mkdir()
    (tmp_path / "own" / "metrics").symlink_to(ROOT / "metrics")
    root, _, dvc_stage = root.format(checkout=ROOT, name=ROOT.name, link=tmp_path / "link", metrics_link=tmp_path / "own").partition("@")
    env = {k: v for k, v in os.environ.items() if k != "DVC_STAGE"} | ({"DVC_STAGE": dvc_stage} if dvc_stage else {})
    before = {p: p.stat().st_mtime_ns for p in (ROOT / "metrics").rglob("*") if p.is_file()}
    run = command("offroad_path.label", "paths=own", f"paths.root={root}", cwd=ROOT, env=env)
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1, run.stderr
    assert re.match(r"error: paths\.(root|metrics_dir): .* resolves to .*, which (is|is inside|holds) this checkout", lines[0])
    assert {p: p.stat().st_mtime_ns for p in (ROOT / "metrics").rglob("*") if p.is_file()} == before


@pytest.mark.parametrize(
    ("times", "says"),
    [
        ([0.0, 0.1, 0.05, 0.3], r"row 3 \(0.05\) is not after row 2 \(0.1\)"),
        ([0.0, 0.0, 0.0, 0.0], r"row 2 \(0\) is not after row 1 \(0\)"),
        ([0.0, 100.0, 200.0, 300.0], r"frames are 100 apart \(median\).*these look like milliseconds"),
        ([0.0, 1e8, 2e8, 3e8], r"frames are 1e\+08 apart \(median\).*these look like nanoseconds"),
    ],
)
def test_times_txt_is_checked_on_its_own(tmp_path, times, says):
    from offroad_path.sequence.reader import read_times

    path = tmp_path / "times.txt"
    path.write_text("".join(f"{t}\n" for t in times))
    with pytest.raises(InputError, match=rf"times\.txt: {says}"):
        read_times(path, len(times))
    path.write_text("0\n0.1\n0.2\n0.3\n")
    assert list(read_times(path, 4)) == [0.0, 0.1, 0.2, 0.3]
