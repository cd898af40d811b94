"""The results table in the layout of the paper's Table 5.1, and the baselines table: rows are
dataclasses, and the Markdown and CSV tables are generated from their fields (a field's `title`
names its Markdown column)."""

from __future__ import annotations

import csv
import io
import math
from dataclasses import asdict, dataclass, field, fields


def _title(text: str) -> dict:
    return {"title": text}


@dataclass(frozen=True)
class ResultRow:
    network: str
    pretraining: str
    postprocessing: str = field(metadata=_title("post-processing"))
    accuracy: float
    recall: float
    precision: float
    iou: float = field(metadata=_title("IoU"))
    # per-image IoU averaged over images: not the paper's pooled IoU
    mean_image_iou: float = field(metadata=_title("per-image mean IoU"))


@dataclass(frozen=True)
class BaselineRow:
    baseline: str
    accuracy: float
    recall: float
    precision: float
    iou: float = field(metadata=_title("IoU"))


def split_run_name(run: str) -> tuple[str, str]:
    """'unet-segmentation' -> ('unet', 'segmentation')."""
    model, _, pretraining = run.partition("-")
    if not pretraining:
        raise ValueError(f"run name {run!r} is not <model>-<pretraining>")
    return model, pretraining


def network_name(model: str) -> str:
    """The registered network's title ('unet' -> 'U-Net')."""
    from offroad_path.models import MODELS

    return (MODELS[model].title if model in MODELS else "") or model


def method_title(run: str) -> str:
    """'unet-segmentation' -> 'U-Net (segmentation)': a run's name in every table."""
    model, pretraining = split_run_name(run)
    return f"{network_name(model)} ({pretraining})"


# The paper's central claim as one comparison: every run without pretraining above the mean-path prior, an
# intersection-union test (Berger 1982): it rejects when each run's own comparison rejects, so it is
# answered by the weakest of them (the largest p-value; one at or below the prior when there is such a run).
EVERY_SCRATCH_VS_PRIOR = "every_scratch_run_vs_mean_path_prior"


def comparison_title(key: str, weakest: str = "") -> str:
    """A comparison's metrics key as its row title: 'unet-none_vs_fcn-none' -> 'U-Net (none) - FCN (none)'
    (weakest: the run the intersection-union comparison rests on)."""
    if key == EVERY_SCRATCH_VS_PRIOR:
        return f"every network without pretraining - mean path prior (intersection-union: the weakest, {weakest or 'n/a'})"
    if key.endswith("_postprocessed_vs_raw"):
        return f"{method_title(key.removesuffix('_postprocessed_vs_raw'))}: post-processed - raw"
    a, _, b = key.partition("_vs_")
    return f"{method_title(a)} - {'mean path prior' if b == 'mean_path_prior' else method_title(b)}"


def baseline_name(key: str) -> str:
    """'non_corresponding.unet-none' -> 'U-Net (none) against non-corresponding ground truth'."""
    if key.startswith("non_corresponding."):
        return f"{method_title(key.removeprefix('non_corresponding.'))} against non-corresponding ground truth"
    return {
        "mean_path_prior": "mean path prior (average training label)",
        "colour_classifier": "colour classifier (RGB, HSV, row, column)",
    }.get(key, key)


def fmt(x: float | int | str) -> str:
    if isinstance(x, str):
        return x
    if isinstance(x, int):
        return str(x)
    return "n/a" if math.isnan(x) else f"{x:.3f}"


def markdown_table(rows: list) -> str:
    """A Markdown table of dataclass rows, one column per field."""
    columns = fields(rows[0])
    lines = ["| " + " | ".join(f.metadata.get("title", f.name) for f in columns) + " |", "|" + " --- |" * len(columns)]
    lines += ["| " + " | ".join(fmt(getattr(row, f.name)) for f in columns) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def csv_text(rows: list) -> str:
    """CSV of dataclass rows: a header of field names, floats rounded to 6 decimals."""
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=[f.name for f in fields(rows[0])], lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: (round(v, 6) if isinstance(v, float) else v) for k, v in asdict(r).items()} for r in rows)
    return out.getvalue()
