"""The GPU pipeline (gpu/dvc.yaml): the main dvc.yaml's stages under experiment=gpu, every output under gpu/.

    python tools/scaled_pipeline.py        # rewrites gpu/dvc.yaml from dvc.yaml
    dvc repro gpu/dvc.yaml                              # the whole pipeline at the GPU preset's sizes

One pipeline to edit (dvc.yaml); this file is made from it (tests/test_presets.py checks that it is
up to date): each stage runs in the checkout (wdir ..) with `experiment=gpu paths.root=gpu`, reads the
checkout's code and configs and conf/experiment/gpu.yaml, and writes gpu/data/ and gpu/metrics/, so the
laptop's committed run stays as it is. The grid lists come from gpu/params.yaml (the preset's seeds).
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PRESET, FOLDER = "gpu", "gpu"
HEADER = f"""# Made by `python tools/scaled_pipeline.py` from dvc.yaml: edit that, then rerun it.
# dvc.yaml's stages under experiment={PRESET} (conf/experiment/{PRESET}.yaml), outputs under {FOLDER}/data and
# {FOLDER}/metrics:  dvc repro {FOLDER}/dvc.yaml
"""
OUTPUT = re.compile(r"(^|[\s=])((?:data|metrics)/)")


def _moved(path: str) -> str:
    """A data/ or metrics/ path of the main pipeline under the scaled pipeline's folder; others as they are."""
    return OUTPUT.sub(rf"\1{FOLDER}/\2", path)


def _entries(items: list) -> list:
    return [{_moved(k): v for k, v in item.items()} if isinstance(item, dict) else _moved(item) for item in items]


def scaled(pipeline: dict) -> dict:
    """The scaled pipeline's dvc.yaml (as a dict) from the main one's."""
    stages = {}
    for name, stage in pipeline["stages"].items():
        out = {"wdir": "..", **{k: v for k, v in stage.items() if k in ("matrix", "foreach", "do")}}
        cmd = re.sub(r"^(python -m offroad_path\.\w+)", rf"\1 experiment={PRESET} paths.root={FOLDER}", " ".join(stage["cmd"].split()))
        out["cmd"] = _moved(cmd)
        out["deps"] = _entries(stage.get("deps", []))
        out["params"] = [*stage.get("params", []), {f"conf/experiment/{PRESET}.yaml": None}]
        for key in ("outs", "metrics", "plots"):
            if key in stage:
                out[key] = _entries(stage[key])
        stages[name] = out
    return {"vars": ["params.yaml"], "stages": stages}


def render(dvc_yaml: Path = ROOT / "dvc.yaml") -> str:
    return HEADER + yaml.safe_dump(scaled(yaml.safe_load(dvc_yaml.read_text())), sort_keys=False, width=200)


def main() -> None:
    (ROOT / FOLDER / "dvc.yaml").write_text(render())


if __name__ == "__main__":
    main()
