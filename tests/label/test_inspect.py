"""`python -m offroad_path.label.inspect`: the label run of the test drive in a Rerun recording,
read back entity by entity, and the footprint check that catches a wrong camera height."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from offroad_path.label.inspect import main


def entities(rrd: Path) -> dict[str, dict[str, list]]:
    """{entity: {component column: its non-null values, in row order}} of a .rrd file."""
    from rerun.chunk import RrdReader

    found: dict[str, dict[str, list]] = {}
    for chunk in RrdReader(rrd).stream().to_chunks():
        batch = chunk.to_record_batch()
        for name in batch.schema.names:
            if ":" in name:
                values = [v for v in batch.column(name).to_pylist() if v is not None]
                found.setdefault(str(chunk.entity_path), {}).setdefault(name, []).extend(values)
    return found


@pytest.fixture(scope="module")
def inspected(labelled_drive, drive, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("inspect") / "out"
    main([str(labelled_drive), "--recording", str(drive), "--out", str(out)])
    return out


def test_the_recording_holds_every_frame_label_and_step(inspected, labelled_drive):
    assert sorted(p.name for p in inspected.iterdir() if not p.name.startswith(".")) == ["checks.json", "drive.rrd", "summary.png"]
    logged = entities(inspected / "drive.rrd")
    with open(labelled_drive / "drive" / "report.csv") as f:
        kept = [row for row in csv.DictReader(f) if row["kept"] == "True"]
    with open(labelled_drive / "drive" / "steps.csv") as f:
        inliers = [float(row["inliers"]) for row in csv.DictReader(f) if row["inliers"]]
    poses = np.loadtxt(labelled_drive / "drive" / "poses_vo.txt").reshape(-1, 3, 4)
    assert len(logged["/world/camera/image"]["EncodedImage:blob"]) == len(poses) == 40  # every frame's image (JPEG)
    assert len(logged["/world/camera"]["Transform3D:translation"]) == len(poses)
    assert len(logged["/world/camera/image/label"]["SegmentationImage:buffer"]) == len(kept) > 0  # each label over its f0
    assert len(logged["/world/points"]["Points3D:positions"]) == len(kept)  # f0's point cloud per label
    assert len(logged["/world/footprint"]["LineStrips3D:strips"]) == len(kept)
    assert len(logged["/checks/stereo_over_footprint"]["Scalars:scalars"]) == len(kept)
    assert [v[0] for v in logged["/vo/inliers"]["Scalars:scalars"]] == inliers
    (vo,) = logged["/world/vo_trajectory"]["LineStrips3D:strips"]
    np.testing.assert_allclose(np.array(vo[0]), poses[:, :, 3], atol=1e-5)  # float32 in the file
    assert "/world/recorded_trajectory" in logged  # the rendered drive has its own poses


def test_the_footprint_check_finds_the_camera_height_and_flags_a_wrong_one(inspected, labelled_drive, drive, tmp_path, capsys):
    meta = json.loads((drive / "drive" / "meta.json").read_text())
    right = json.loads((inspected / "checks.json").read_text())["drive"]
    assert right["flags"] == [] and right["implied_camera_height_m"] == pytest.approx(meta["camera_height_m"], rel=0.05)
    # The same recording told that its camera is 30 % higher than it is: the footprint lies below the ground.
    wrong = tmp_path / "recording"
    shutil.copytree(drive, wrong)
    (wrong / "drive" / "meta.json").write_text(json.dumps({**meta, "camera_height_m": 1.3 * meta["camera_height_m"]}))
    main([str(labelled_drive), "--recording", str(wrong), "--out", str(tmp_path / "out")])
    checked = json.loads((tmp_path / "out" / "checks.json").read_text())["drive"]
    assert checked["median_ratio"] < 0.9 and checked["flags"][0].startswith("height: labels sink")
    assert checked["implied_camera_height_m"] == pytest.approx(meta["camera_height_m"], rel=0.05)  # the true height, from the stereo
    assert "FLAG height: labels sink" in capsys.readouterr().out


def test_a_folder_without_label_runs_is_refused_in_one_line(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    with pytest.raises(SystemExit) as exit_info:
        main([str(tmp_path / "empty"), "--out", str(tmp_path / "out")])
    assert exit_info.value.code == 2
    (line,) = [line for line in capsys.readouterr().err.splitlines() if line.startswith("error: ")]
    assert str(tmp_path / "empty") in line and "holds no label run" in line and not (tmp_path / "out").exists()


def test_a_mono_label_run_is_inspected_without_point_clouds(compose_config, drive, tmp_path):
    """One camera: image, label and footprint per label, the recorded poses; no stereo point
    cloud and no footprint check, which need disparity."""
    from offroad_path.label import label

    recordings = tmp_path / "mono"
    shutil.copytree(drive, recordings, ignore=shutil.ignore_patterns("image_r"))
    label(compose_config(f"label.in_dir={recordings}", f"label.out_dir={tmp_path / 'labels'}", f"label.metrics_path={tmp_path / 'm.json'}",
                         "label.workers=1", "label.poses.source=file", "mlflow.enabled=false"))  # fmt: skip
    main([str(tmp_path / "labels"), "--recording", str(recordings), "--out", str(tmp_path / "out")])
    logged = entities(tmp_path / "out" / "drive.rrd")
    kept = len(list((tmp_path / "labels" / "drive" / "label").glob("*.png")))
    assert (
        len(logged["/world/camera/image/label"]["SegmentationImage:buffer"])
        == len(logged["/world/footprint"]["LineStrips3D:strips"])
        == kept
        > 0
    )
    assert "/world/points" not in logged and "/world/vo_trajectory" not in logged and "/world/recorded_trajectory" in logged
    assert json.loads((tmp_path / "out" / "checks.json").read_text()) == {}
