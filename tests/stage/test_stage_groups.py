"""Each stage reads only the config groups it declares (`@reads(...)`, offroad_path.stage): at run
time a stage's function sees only those groups, so every test that runs a stage checks the code it
runs; here, each stage's view of the composed config, its own module's reads, and dvc.yaml's params."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys

import pytest
import yaml
from helpers import ROOT
from omegaconf.errors import ConfigAttributeError, ReadonlyConfigError

from offroad_path.stage import SHARED, check_search_extra, reads, stage_modules

COMMANDS = stage_modules()  # every module with a @reads stage: a new stage is checked without being listed here
GROUPS = {p.name for p in (ROOT / "conf").iterdir() if p.is_dir()} - {"experiment", "hparams_search"}  # presets, not config keys

STAGES = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]


def test_the_stages_are_the_modules_that_declare_one():
    assert {"synthesize", "label", "train", "evaluate", "drive", "predict"} <= set(COMMANDS)
    assert "stage" not in COMMANDS and "config" not in COMMANDS


def stage_of(command: str):
    module = importlib.import_module(f"offroad_path.{command}")
    found = [v for v in vars(module).values() if callable(v) and hasattr(v, "reads") and v.__module__ == module.__name__]
    assert len(found) == 1, f"offroad_path.{command}: one function declared with @reads, found {len(found)}"
    return found[0]


def groups_read(command: str) -> set[str]:
    """Every `cfg.<group>` and `cfg["<group>"]` in the stage's package, for the config's groups."""
    read = set()
    package = ROOT / "src" / "offroad_path" / command
    for node in (n for f in sorted(package.glob("*.py")) for n in ast.walk(ast.parse(f.read_text()))):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "cfg":
            read.add(node.attr)
        elif isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name) and node.value.id == "cfg" \
                and isinstance(node.slice, ast.Constant):  # fmt: skip
            read.add(node.slice.value)
    return read & GROUPS


@pytest.mark.parametrize("command", COMMANDS)
def test_a_stage_sees_its_groups_and_no_other(command, compose_config):
    stage = stage_of(command)
    assert set(stage.reads) <= GROUPS, f"{command} declares groups that conf/ does not have"
    seen = {}

    @reads(*stage.reads)
    def probe(cfg):
        seen.update({key: cfg[key] for key in cfg})
        for group in sorted(GROUPS - set(stage.reads)):
            with pytest.raises(ConfigAttributeError):
                getattr(cfg, group)
        own = cfg[stage.reads[0]]
        with pytest.raises(ReadonlyConfigError):
            own[next(iter(own))] = 1  # no stage rewrites its config

    probe(compose_config())
    assert set(seen) == set(stage.reads) | set(SHARED)


@pytest.mark.parametrize("command", COMMANDS)
def test_a_stage_module_reads_only_declared_groups(command):
    stage = stage_of(command)
    read = groups_read(command)
    assert read, f"offroad_path.{command}: found no cfg.<group> in its module"
    assert read <= set(stage.reads), f"offroad_path.{command} reads {sorted(read - set(stage.reads))} of cfg without declaring them"


@pytest.mark.parametrize("name", sorted(STAGES))
def test_dvc_params_list_the_files_of_every_declared_group(name):
    spec = STAGES[name]
    stage = stage_of(spec["cmd"].split()[2].removeprefix("offroad_path."))
    params = {next(iter(p)) if isinstance(p, dict) else p for p in spec["params"]}
    params = {p.removesuffix(":") for p in params}
    assert "conf/config.yaml" in params
    for group in stage.reads:
        files = [p for p in params if p.startswith(f"conf/{group}/")]
        assert files, f"dvc.yaml stage {name} reads {group} but lists no conf/{group}/ file in its params"


NUMBER = (int, float)


def numeric_settings(schema: type, prefix: str = "") -> dict[str, bool]:
    """Every setting of the schemas that holds numbers (int, float, optional or a tuple of them): key -> whether it has a rule."""
    import dataclasses
    import types
    import typing

    hints, out = typing.get_type_hints(schema), {}
    for f in dataclasses.fields(schema):
        if f.default_factory is not dataclasses.MISSING and dataclasses.is_dataclass(nested := f.default_factory()):
            out |= numeric_settings(type(nested), f"{prefix}{f.name}.")
            continue
        kinds = typing.get_args(hints[f.name]) if isinstance(hints[f.name], types.UnionType) or typing.get_origin(hints[f.name]) else ()
        kinds = kinds or (hints[f.name],)
        if any(kind in NUMBER for kind in kinds):
            out[f"{prefix}{f.name}"] = "rule" in f.metadata
    return out


def borrowed(raw: dict, groups: tuple[str, ...], prefix: str = "") -> list[str]:
    """Keys under `groups` whose value is an interpolation of a key of another group (unresolved config)."""
    found = []
    for key, value in raw.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            found += borrowed(value, groups, f"{name}.")
        elif isinstance(value, str) and name.split(".")[0] in groups:
            found += [name for target in re.findall(r"\$\{([\w.]+)\}", value) if target.split(".")[0] not in groups]
    return found


@pytest.mark.parametrize("command", COMMANDS)
def test_every_number_a_stage_reads_is_checked_by_its_own_rules(command, compose_config):
    """A stage checks every value it sees before any work (validate_config, on its groups alone): each
    number of its groups has a rule, and a value its groups take from another group's (an interpolation,
    as synthesize.test_worlds.horizon_m takes label.distance_m) is checked where it lands, so a bad
    value there is refused by this stage too."""
    from omegaconf import OmegaConf

    from offroad_path.config import Config

    stage, numbers = stage_of(command), numeric_settings(Config)
    unchecked = sorted(key for key, ruled in numbers.items() if key.split(".")[0] in stage.reads and not ruled)
    assert not unchecked, f"{command} reads numbers without a rule: {unchecked}"
    raw = OmegaConf.to_container(compose_config(), resolve=False)
    taken = borrowed(raw, stage.reads)
    assert all(numbers.get(key, True) for key in taken), f"{command}: {[k for k in taken if not numbers.get(k, True)]}"
    if command == "synthesize":  # the case that once slipped through: the label stage's distance, read by the test worlds
        assert "synthesize.test_worlds.horizon_m" in taken and numbers["synthesize.test_worlds.horizon_m"]


def test_reading_an_undeclared_group_fails(compose_config):
    @reads("split")
    def sloppy(cfg):
        return cfg.label.out_dir

    with pytest.raises(ConfigAttributeError, match="label"):
        sloppy(compose_config())


def test_a_search_without_the_search_extra_says_which_extra_to_install(monkeypatch, capsys):
    check_search_extra(["model=unet", "hparams_search=null"])  # no search: nothing to check
    monkeypatch.setitem(sys.modules, "hydra_plugins.hydra_optuna_sweeper", None)  # as if installed without [search]
    with pytest.raises(SystemExit) as exit_info:
        check_search_extra(["-m", "hparams_search=path_optuna"])
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == (
        "error: hparams_search: needs the [search] extra (hydra-optuna-sweeper is not installed): pip install -e '.[search]'\n"
    )


@pytest.mark.parametrize("command", ["train", "evaluate", "train_steering", "drive"])
def test_a_bad_key_and_help_are_answered_before_torch_is_imported(command):
    """The stages that train or run networks import them inside the stage function: a refusal and
    --help take about a second (benchmarks/refusal_time.py), not the 6-15 s of importing Lightning."""
    for args, code in ((["bogus_key=1"], 2), (["--help"], 0)):
        run = subprocess.run([sys.executable, "-X", "importtime", "-m", f"offroad_path.{command}", *args], capture_output=True, text=True)
        assert run.returncode == code, run.stderr[-500:]
        imported = {line.split("|")[-1].strip() for line in run.stderr.splitlines() if line.startswith("import time:")}
        heavy = imported & {"torch", "lightning", "mlflow"}
        assert not heavy, f"{command} {args[0]} imported {sorted(heavy)}"
    assert "== Config groups it reads" in run.stdout and f"Stage `{command}`" in run.stdout
