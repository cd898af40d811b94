"""Value rules for config schemas: `field(default=..., metadata=positive())`, checked by `validate`
before a stage does any work, with a message that names the key."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np
from omegaconf import MISSING, DictConfig, OmegaConf
from omegaconf.errors import MissingMandatoryValue


class ConfigValueError(ValueError):
    pass


@dataclasses.dataclass(frozen=True)
class Rule:
    test: Callable[[Any], bool]
    says: str | Callable[[], str]  # a callable when the message depends on the machine (its devices)


# Losses, weights and rates are computed in float32: a setting must be a number there too (1e39 is
# finite in float64, infinite in float32; 1e-50 is above 0 in float64, 0 in float32).
FLOAT32 = np.finfo(np.float32)


def _number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v) and abs(v) <= FLOAT32.max


def _float64_only(v: Any) -> bool:
    """A number finite in float64 that float32, the precision it is used in, makes infinite or 0."""
    return (
        isinstance(v, int | float)
        and not isinstance(v, bool)
        and math.isfinite(v)
        and (abs(v) > FLOAT32.max or 0 < abs(v) < float(FLOAT32.smallest_subnormal) / 2)
    )


def rule(test: Callable[[float], bool], says: str) -> dict:
    """A rule on a number finite in float32 (NaN and infinity never pass)."""
    return {"rule": Rule(lambda v: _number(v) and test(v), says)}


def positive() -> dict:
    return rule(lambda v: v > 0 and np.float32(v) > 0, "must be a number > 0")


def at_least(low: float) -> dict:
    return rule(lambda v: v >= low, f"must be a number >= {low:g}")


def between(low: float, high: float, low_open: bool = False, high_open: bool = False) -> dict:
    lo, hi = "(" if low_open else "[", ")" if high_open else "]"
    return rule(
        lambda v: (v > low if low_open else v >= low) and (v < high if high_open else v <= high),
        f"must be a number in {lo}{low:g}, {high:g}{hi}",
    )


def one_of(choices: Iterable[str] | Callable[[], Iterable[str]]) -> dict:
    """A choice; `choices` may be a callable so that a registry is read only when checking."""

    def valid() -> list[str]:
        return sorted(choices() if callable(choices) else choices)

    return {"rule": Rule(lambda v: v in valid(), "")} | {"choices": valid}


def machine_devices() -> list[str]:
    """The torch devices this machine has: cpu, and cuda, cuda:0 ... and mps where there are."""
    import torch

    found = ["cpu"]
    if torch.cuda.is_available():
        found += ["cuda", *(f"cuda:{i}" for i in range(torch.cuda.device_count()))]
    if torch.backends.mps.is_available():
        found.append("mps")
    return found


def has_device(name: str) -> bool:
    """Whether torch can parse `name` as a device and this machine has it."""
    if name == "cpu":
        return True  # without importing torch: the usual value is checked at no cost
    import torch

    try:
        device = torch.device(name)
    except (RuntimeError, TypeError, ValueError):
        return False
    if device.type == "cuda":
        return torch.cuda.is_available() and (device.index is None or device.index < torch.cuda.device_count())
    if device.type == "mps":
        return torch.backends.mps.is_available()
    return device.type == "cpu"


def torch_device() -> dict:
    """`auto` (the GPU where there is one, else the CPU) or a torch device this machine has."""

    def says() -> str:
        return f"must be auto or a torch device this machine has: {', '.join(machine_devices())}"

    return {"rule": Rule(lambda v: isinstance(v, str) and (v == "auto" or has_device(v)), says)}


ACCELERATORS = {"cpu": "cpu", "gpu": "cuda", "cuda": "cuda", "mps": "mps"}  # Lightning's accelerator -> the torch device it needs


def accelerator() -> dict:
    """Lightning's `auto` or an accelerator whose device this machine has."""

    def says() -> str:
        have = [name for name, device in ACCELERATORS.items() if has_device(device)]
        return f"must be auto or an accelerator this machine has: {', '.join(have)} (its devices: {', '.join(machine_devices())})"

    return {"rule": Rule(lambda v: v == "auto" or (v in ACCELERATORS and has_device(ACCELERATORS[v])), says)}


def ordered_pair(low: float, high: float, low_open: bool = False) -> dict:
    """[a, b], two finite numbers with low <= a <= b <= high (low < a when low_open)."""

    def test(v: Any) -> bool:
        return len(v) == 2 and all(_number(x) for x in v) and (low < v[0] if low_open else low <= v[0]) and v[0] <= v[1] <= high

    bound = f"{'(' if low_open else '['}{low:g}, {high:g}]"
    return {"rule": Rule(test, f"must be [low, high], two finite numbers in {bound} with low <= high")}


# A seed: what NumPy's SeedSequence and Lightning's seed_everything take (a negative one is refused or redrawn).
SEED = rule(lambda v: 0 <= v <= 2**32 - 1, "must be a whole number in [0, 4294967295]")
FINITE = rule(lambda v: True, "must be a finite number")


def numbers(count: int) -> dict:
    """A list of exactly `count` finite numbers."""
    return {"rule": Rule(lambda v: len(v) == count and all(_number(x) for x in v), f"must be a list of {count} finite numbers")}


def each(inner: dict) -> dict:
    """The inner rule on every item of a list, or every value of a mapping (choices listed as the
    inner rule lists them)."""
    check: Rule = inner["rule"]
    return inner | {"rule": Rule(lambda v: all(check.test(x) for x in (v.values() if isinstance(v, Mapping) else v)), check.says)}


def distinct(inner: dict, nonempty: bool = False) -> dict:
    """`each(inner)` on a list that names nothing twice (and, with nonempty, names something)."""
    check: Rule = each(inner)["rule"]

    def test(v: Any) -> bool:
        items = list(v)
        return check.test(items) and len(set(map(str, items))) == len(items) and (bool(items) or not nonempty)

    item = check.says.removeprefix("must be ") or "one of the valid names"
    return each(inner) | {"rule": Rule(test, f"must list {'at least one value, ' if nonempty else ''}no value twice, each {item}")}


def setting(rules: dict | None = None) -> Any:
    """A config field: its value lives in conf/ (never here), its rules here."""
    return dataclasses.field(default=MISSING, metadata=rules or {})


def validate(cfg: DictConfig, schema: type, prefix: str = "", only: Iterable[str] | None = None) -> None:
    """Check every value of `cfg` that has a rule in the dataclass `schema`, recursively (of the
    groups `only` and the plain values, when given); values left unset (`???`) or None are skipped.
    Raises ConfigValueError naming the first bad key."""
    for f in dataclasses.fields(schema):
        key = f"{prefix}{f.name}"
        nested_schema = f.default_factory is not dataclasses.MISSING
        if only is not None and nested_schema and f.name not in only:
            continue
        try:
            value = OmegaConf.select(cfg, f.name, throw_on_missing=True)
        except MissingMandatoryValue:
            continue
        if f.default_factory is not dataclasses.MISSING and dataclasses.is_dataclass(nested := f.default_factory()):
            if isinstance(value, DictConfig):
                validate(value, type(nested), f"{key}.")
            continue
        check = f.metadata.get("rule")
        if check is not None and value is not None and not check.test(value):
            says = (check.says() if callable(check.says) else check.says) or f"must be one of: {', '.join(f.metadata['choices']())}"
            if _float64_only(value):
                says += " in float32, the precision it is used in"
            if check.says and "choices" in f.metadata:  # a list of choices with a rule of its own (distinct)
                says += f"; valid: {', '.join(f.metadata['choices']())}"
            raise ConfigValueError(f"{key}={value!r}: {says}")
