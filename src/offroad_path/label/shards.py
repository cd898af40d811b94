"""Labelling split across jobs: each job (a Hydra multirun job, e.g. one per SLURM task through
the submitit launcher) labels every `shards`-th sequence from its `shard`-th into a folder of its
own; a last run merges those folders into the one layout and metrics a single run writes.

    python -m offroad_path.label -m hydra/launcher=submitit_slurm label.shards=8 'label.shard=range(8)' \
        'label.out_dir=data/label_shards/${label.shard}'
    python -m offroad_path.label label.merge_from=data/label_shards

A shard's folder holds, besides the sequences' folders and its summary.json, shard.json: which
shard it is, its sequences and the digest of the label config that made it. The merge refuses
shards of another config or input, a missing or repeated shard, or a sequence labelled twice or
not at all, naming the folder.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from omegaconf import DictConfig, OmegaConf

from offroad_path.data.labels import SHARD_FILE
from offroad_path.errors import InputError
from offroad_path.utils.rules import ConfigValueError

# Where a job writes and how it runs, not what it computes: shards and their merge may differ in these.
NOT_COMPUTED = ("out_dir", "metrics_path", "workers", "shard", "shards", "merge_from")


def config_digest(label: DictConfig) -> str:
    """What makes the labels: the label config less NOT_COMPUTED (in_dir as configured)."""
    made_by = {k: v for k, v in OmegaConf.to_container(label, resolve=True).items() if k not in NOT_COMPUTED}
    return hashlib.sha256(json.dumps(made_by, sort_keys=True).encode()).hexdigest()[:16]


def chosen(names: list[str], label: DictConfig) -> list[int]:
    """The indices of the sequences (in find_sequences' order) shard `label.shard` labels."""
    if label.shard >= label.shards:
        raise ConfigValueError(f"label.shard={label.shard}: must be less than label.shards ({label.shards})")
    return list(range(label.shard, len(names), label.shards))


def shard_record(label: DictConfig, names: list[str]) -> str:
    return json.dumps({"shard": label.shard, "shards": label.shards, "sequences": names, "config": config_digest(label)}, indent=2) + "\n"


def _shard_record(path: Path) -> dict:
    """A shard.json with the keys the merge reads; InputError naming the file otherwise."""
    try:
        record = json.loads(path.read_text())
    except (OSError, ValueError) as e:
        raise InputError(path, f"cannot be read as a shard record ({type(e).__name__}: {e})") from e
    kinds = {"shard": int, "shards": int, "sequences": list, "config": str}
    if not isinstance(record, dict) or (bad := [k for k, kind in kinds.items() if not isinstance(record.get(k), kind)]):
        wrong = ", ".join(bad) if isinstance(record, dict) else "all"
        raise InputError(path, f"is not a shard record: {wrong} missing or of the wrong type (written by label with label.shards > 1)")
    return record


def read_shards(label: DictConfig, names: list[str]) -> list[tuple[Path, dict]]:
    """(folder, summary of one sequence) for every sequence of `names`, in that order, from the
    shard folders under label.merge_from; InputError naming the folder when they do not make
    exactly this config's run."""
    root = Path(label.merge_from)  # named in every error: the setting's value is the folder
    folders = sorted(p.parent for p in root.glob(f"*/{SHARD_FILE}"))
    if not folders:
        raise InputError(root, f"holds no shard folder (a label.out_dir of a run with label.shards > 1, with {SHARD_FILE})")
    digest, found, seen = config_digest(label), {}, set()
    for folder in folders:
        record = _shard_record(folder / SHARD_FILE)
        if record["config"] != digest:
            raise InputError(folder, f"was labelled with another label config (digest {record['config']}, this one {digest})")
        if record["shard"] in seen or record["shards"] != len(folders):
            raise InputError(
                folder,
                f"shard {record['shard']} of {record['shards']}, but {root} holds {len(folders)} shard folders "
                f"(shards {sorted(seen | {record['shard']})} so far)",
            )
        seen.add(record["shard"])
        summaries = json.loads((folder / "summary.json").read_text())["sequences"]
        for summary in summaries:
            if summary["name"] in found:
                raise InputError(folder, f"labels {summary['name']} again (also in {found[summary['name']][0]})")
            found[summary["name"]] = (folder, summary)
    if missing := [n for n in names if n not in found]:
        raise InputError(root, f"no shard labelled {', '.join(missing)} of {label.in_dir}")
    if extra := sorted(set(found) - set(names)):
        raise InputError(root, f"labels {', '.join(extra)}, which {label.in_dir} does not hold")
    return [found[n] for n in names]
