"""Every stage of dvc.yaml depends on all the code it runs: each module its entry point imports,
directly or not (imports inside functions included), lies under one of the stage's deps, and the
deps are what tools/dvc_deps.py generates. A missing dep means `dvc repro` keeps a stale
output after a code change."""

from __future__ import annotations

import pytest
import yaml
from dvc_deps import code_deps, has_code, imported_files, main, rewrite
from helpers import ROOT

DVC_YAML = yaml.safe_load((ROOT / "dvc.yaml").read_text())
STAGES = DVC_YAML["stages"]


@pytest.mark.parametrize("stage", sorted(STAGES))
def test_the_stage_depends_on_every_module_it_imports(stage):
    spec = STAGES[stage]
    entry = spec["cmd"].split()[2]  # python -m offroad_path.<stage> ...
    deps = [ROOT / d for d in spec["deps"] if d.startswith("src/")]
    ran = {f for f in imported_files(entry) if has_code(f)}
    missing = sorted(str(f.relative_to(ROOT)) for f in ran if not any(f == d or d in f.parents for d in deps))
    assert not missing, f"dvc.yaml stage {stage} runs these files but does not list them in its deps: {missing}"


def test_dvc_yaml_holds_the_generated_code_deps():
    assert main(["--check"]) == 0, "run: python tools/dvc_deps.py"


def test_the_generator_lists_a_new_import_and_drops_a_removed_one(tmp_path):
    text = (ROOT / "dvc.yaml").read_text()
    split = STAGES["split"]
    stale = text.replace(f"      - {code_deps('offroad_path.split')[-1]}\n", "      - src/offroad_path/viz\n", 1)
    assert stale != text
    (tmp_path / "dvc.yaml").write_text(stale)
    assert main(["--check", "--dvc-yaml", str(tmp_path / "dvc.yaml")]) == 1
    assert main(["--dvc-yaml", str(tmp_path / "dvc.yaml")]) == 0
    assert (tmp_path / "dvc.yaml").read_text() == rewrite(text) == text
    assert split["deps"][0] == "data/labels"  # data deps stay first, as written


def test_every_pretraining_of_the_grid_has_a_training_stage():
    """postprocess and evaluate iterate `pretrainings` (conf/evaluate): each needs a train stage
    that writes its runs, or postprocess would have stages with no producer."""
    grid = yaml.safe_load((ROOT / "conf" / "evaluate" / "default.yaml").read_text())
    trained = {cmd.split("pretraining=")[1].split()[0] for cmd in (s["cmd"] for s in STAGES.values()) if "offroad_path.train " in cmd}
    missing = sorted(set(grid["pretrainings"]) - trained)
    assert not missing, f"pretrainings {missing} of conf/evaluate/default.yaml have no train stage in dvc.yaml"


@pytest.mark.parametrize("pipeline", ["dvc.yaml", "own/dvc.yaml", "gpu/dvc.yaml"])
def test_committed_metrics_are_kept_in_place_while_their_stage_reruns(pipeline):
    """DVC deletes a stage's outputs before running it unless they persist: a committed metrics file (not in
    DVC's cache) would be lost by a stopped run. Every stage writes its own atomically, so it may persist."""
    stages = yaml.safe_load((ROOT / pipeline).read_text())["stages"]
    committed = [
        (name, path, entry)
        for name, stage in stages.items()
        for key in ("outs", "metrics", "plots")
        for item in stage.get(key, [])
        if isinstance(item, dict)
        for path, entry in item.items()
        if (entry or {}).get("cache") is False
    ]
    assert committed and all(entry.get("persist") is True for _, _, entry in committed), [
        (n, p) for n, p, e in committed if not e.get("persist")
    ]
