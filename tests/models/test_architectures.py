"""One list of networks: the registry (offroad_path.models.MODELS) is the truth, the pipeline's
grid (conf/evaluate/networks.yaml, which dvc.yaml's `vars` and evaluate.architectures read) is made
from it, and adding a network is its module, one registry line and its config file, then
`python tools/scaled_pipeline.py` (docs/extending.md, "Adding a network")."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import yaml
from helpers import ROOT, git
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf
from torch import nn

from offroad_path.models import MODELS, SegmentationNet
from offroad_path.train import train


def test_the_grid_lists_every_registered_network_and_each_has_a_config():
    from scaled_pipeline import networks

    made = (ROOT / "conf" / "evaluate" / "networks.yaml").read_text()
    assert made == networks(), "conf/evaluate/networks.yaml is stale: python tools/scaled_pipeline.py"
    assert yaml.safe_load(made)["architectures"] == list(MODELS)
    configs = {p.stem: yaml.safe_load(p.read_text())["name"] for p in (ROOT / "conf" / "model").glob("*.yaml")}
    assert configs == {name: name for name in MODELS}, "each registered network has conf/model/<name>.yaml, and no other"


def test_each_pretraining_the_code_implements_has_a_config_and_no_other():
    """Validation reads the choices from conf/pretraining/ (without importing torch); the code implements them."""
    from offroad_path.config.common import PRETRAININGS
    from offroad_path.training.pretrained import CHOICES

    assert sorted(PRETRAININGS()) == sorted(CHOICES)


class TinyNet(SegmentationNet):
    """A stand-in fourth network: one convolution (what a new module under models/ would hold)."""

    title = "Tiny"

    def __init__(self, num_classes: int = 2, width: float = 1.0):
        super().__init__(num_classes)
        self.classifier = nn.Conv2d(3, num_classes, 3, padding=1)

    def forward_padded(self, x):
        return self.classifier(x)

    def head_parameters(self) -> list[str]:
        return ["classifier.weight", "classifier.bias"]

    def replace_head(self, num_classes: int) -> None:
        self.classifier = nn.Conv2d(3, num_classes, 3, padding=1)


def add_network_to(root: Path) -> None:
    """What a user edits besides the module and the registry line (a config file), and the grid the
    tool then makes from the registry."""
    from scaled_pipeline import networks

    unet = (ROOT / "conf" / "model" / "unet.yaml").read_text()
    (root / "conf" / "model" / "tiny.yaml").write_text(unet.replace("name: unet", "name: tiny"))
    (root / "conf" / "evaluate" / "networks.yaml").write_text(networks())


def test_a_fourth_network_trains_and_joins_the_grid_with_no_other_edit(monkeypatch, tmp_path, split_dir, tiny_overrides):
    monkeypatch.setitem(MODELS, "tiny", TinyNet)  # the registry line
    shutil.copytree(ROOT / "conf", tmp_path / "conf")
    add_network_to(tmp_path)
    with initialize_config_dir(str(tmp_path / "conf"), version_base="1.3"):
        overrides = [
            f"data.split_dir={split_dir}",
            f"train.out_dir={tmp_path / 'run'}",
            "trainer.fast_dev_run=true",
            "mlflow.enabled=false",
        ]
        cfg = compose("config", overrides=[*tiny_overrides, "model=tiny", *overrides])
    assert cfg.evaluate.architectures == ["segnet", "fcn", "unet", "tiny"]
    assert "tiny-none" in cfg.evaluate.runs and "tiny-segmentation" in cfg.evaluate.runs
    assert 0 <= train(cfg)["test/iou"] <= 1
    assert (tmp_path / "run" / "checkpoints" / "best.ckpt").is_file()

    # DVC: the same edit gives the new network its pretrain, train and postprocess stages.
    repo = tmp_path / "repo"
    repo.mkdir()
    for item in ("conf", "dvc.yaml", ".dvcignore"):
        (shutil.copytree if (ROOT / item).is_dir() else shutil.copy)(ROOT / item, repo / item)
    add_network_to(repo)
    git(repo, "init", "-q")
    subprocess.run([sys.executable, "-m", "dvc", "init", "-q"], cwd=repo, check=True)
    listed = subprocess.run([sys.executable, "-m", "dvc", "stage", "list", "--name-only"], cwd=repo, capture_output=True, text=True)
    stages = set(listed.stdout.split())
    new = {"pretrain@tiny", "train_scratch@tiny-0", "train_pretrained@tiny-0", "postprocess@tiny-none-0", "postprocess@tiny-segmentation-0"}
    assert new <= stages, listed.stdout + listed.stderr
    grid = OmegaConf.load(repo / "conf" / "evaluate" / "default.yaml")
    seeds, drive_seeds = OmegaConf.load(repo / "conf" / "evaluate" / "design" / "laptop.yaml").seeds, grid.drive_seeds
    assert {f"train_steering@{s}" for s in seeds} <= stages  # PilotNet per seed
    assert {f"{stage}@{s}" for stage in ("train_steering_slip", "train_steering_curvature") for s in drive_seeds} <= stages  # the drive's
    # synthesize, label, split, evaluate, drive; PilotNet per seed, the drive's two PilotNets per drive seed; per network a
    # pretraining and, per seed, two trainings and two post-processings
    assert len(seeds) >= 2 and len(stages) == 5 + len(seeds) + 2 * len(drive_seeds) + 4 * (1 + 4 * len(seeds))
