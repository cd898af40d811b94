"""The scaled pipelines: the main dvc.yaml's stages under a preset, every output under a folder of their own.

    python tools/scaled_pipeline.py    # rewrites conf/evaluate/networks.yaml, and gpu/, tour/ and rehearsal/dvc.yaml and params.yaml
    dvc repro gpu/dvc.yaml             # the whole pipeline at the GPU preset's sizes
    dvc repro tour/dvc.yaml            # the five-minute tour: every stage on tiny worlds (a smoke run)
    dvc repro rehearsal/dvc.yaml       # the GPU preset's settings at the tour's sizes, on any machine

One pipeline to edit (dvc.yaml); these files are made from it (tests/config/test_presets.py checks that they
are up to date): each stage runs in the checkout (wdir ..) with `experiment=<preset> paths.root=<folder>`,
reads the checkout's code and configs and conf/experiment/<preset>.yaml (and the presets it is made of), and writes <folder>/data/ and
<folder>/metrics/, so the committed run stays as it is. The grid lists come from <folder>/params.yaml,
made from the composed preset (its networks, pretrainings and seeds). Every pipeline's networks are
the model registry's (offroad_path.models.MODELS), written in its order to conf/evaluate/networks.yaml,
which the main dvc.yaml's grid and the config's `evaluate.architectures` read.
"""

from __future__ import annotations

import re
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
# folder: its preset (conf/experiment/<preset>.yaml), then the presets that one's defaults list
PIPELINES = {"gpu": ("gpu",), "tour": ("tour",), "rehearsal": ("rehearsal", "gpu", "tour")}
# folder: its pre-registered design (conf/evaluate/design/<design>.yaml), where it is not the laptop's
DESIGNS = {"gpu": "gpu", "rehearsal": "gpu"}
LAPTOP_DESIGN = "conf/evaluate/design/laptop.yaml"
OUTPUT = re.compile(r"(^|[\s=])((?:data|metrics)/)")


def header(folder: str) -> str:
    return f"""# Made by `python tools/scaled_pipeline.py` from dvc.yaml: edit that, then rerun it.
# dvc.yaml's stages under experiment={PIPELINES[folder][0]} (conf/experiment/{PIPELINES[folder][0]}.yaml), outputs under
# {folder}/data and {folder}/metrics:  dvc repro {folder}/dvc.yaml
"""


def _moved(path: str, folder: str) -> str:
    """A data/ or metrics/ path of the main pipeline under the scaled pipeline's folder; others as they are."""
    return OUTPUT.sub(rf"\1{folder}/\2", path)


def _entries(items: list, folder: str) -> list:
    return [{_moved(k, folder): v for k, v in item.items()} if isinstance(item, dict) else _moved(item, folder) for item in items]


def scaled(pipeline: dict, folder: str) -> dict:
    """The scaled pipeline's dvc.yaml (as a dict) from the main one's."""
    presets, stages = PIPELINES[folder], {}
    for name, stage in pipeline["stages"].items():
        out = {"wdir": "..", **{k: v for k, v in stage.items() if k in ("matrix", "foreach", "do")}}
        cmd = re.sub(r"^(python -m offroad_path\.\w+)", rf"\1 experiment={presets[0]} paths.root={folder}", " ".join(stage["cmd"].split()))
        out["cmd"] = _moved(cmd, folder)
        out["deps"] = _entries(stage.get("deps", []), folder)
        design = f"conf/evaluate/design/{DESIGNS.get(folder, 'laptop')}.yaml"
        params = [
            {design if k == LAPTOP_DESIGN else k: v for k, v in p.items()} if isinstance(p, dict) else p for p in stage.get("params", [])
        ]
        out["params"] = [*params, *({f"conf/experiment/{preset}.yaml": None} for preset in presets)]
        for key in ("outs", "metrics", "plots"):
            if key in stage:
                out[key] = _entries(stage[key], folder)
        stages[name] = out
    return {"vars": ["params.yaml"], "stages": stages}


def render(folder: str = "gpu", dvc_yaml: Path = ROOT / "dvc.yaml") -> str:
    return header(folder) + yaml.safe_dump(scaled(yaml.safe_load(dvc_yaml.read_text()), folder), sort_keys=False, width=200)


def grid(folder: str) -> str:
    """<folder>/params.yaml: the grid of the scaled pipeline's matrix stages (its dvc.yaml's vars), as its preset composes it."""
    from offroad_path.config import load_config

    evaluate = load_config(f"experiment={PIPELINES[folder][0]}").evaluate
    lists = {key: list(evaluate[key]) for key in ("architectures", "pretrainings", "seeds", "drive_seeds")}
    return (
        f"# Made by `python tools/scaled_pipeline.py` from experiment={PIPELINES[folder][0]}: {folder}/dvc.yaml's grid (its vars).\n"
        + yaml.safe_dump(lists, default_flow_style=None, sort_keys=False)
    )


def networks() -> str:
    """conf/evaluate/networks.yaml: evaluate.architectures, the model registry's networks in its order."""
    from offroad_path.models import MODELS

    return (
        "# Made by `python tools/scaled_pipeline.py` from the model registry (offroad_path.models.MODELS): edit that, then\n"
        "# rerun it. The laptop pipeline's networks, in the registry's order (the first of a compared pair is a).\n"
        + yaml.safe_dump({"architectures": list(MODELS)}, default_flow_style=None, sort_keys=False)
    )


def main() -> None:
    (ROOT / "conf" / "evaluate" / "networks.yaml").write_text(networks())
    for folder in PIPELINES:
        (ROOT / folder / "dvc.yaml").write_text(render(folder))
        (ROOT / folder / "params.yaml").write_text(grid(folder))


if __name__ == "__main__":
    main()
