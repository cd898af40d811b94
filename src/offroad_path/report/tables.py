"""Rows and names of the evaluate stage's tables: the results table (the paper's Table 5.1) and the
baselines table take their score columns from the registry (statistics.scores.SCORES); Markdown and
CSV are generated from a row's keys (a Record) or fields (a dataclass, titled by its metadata)."""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields

from offroad_path.config.evaluate_schema import EVERY_SCRATCH_VS_PRIOR
from offroad_path.statistics.scores import SCORES, Record
from offroad_path.statistics.scores import TITLES as SCORE_TITLES
from offroad_path.world.groups import GROUPS

PP_KEY = {"no": "raw", "yes": "postprocessed"}  # post-processing "no"/"yes": their names in metrics.json and MLflow
# Every report table's titles for a metrics key, one lookup (title): the scores' (statistics.scores.TITLES,
# where a new score registers its own), and here the columns', the baselines' and the condition groups'
# (world.groups.GROUPS). A key without an entry is its own title; a run's comes from method_title.
TITLES: dict[str, str] = {
    "postprocessing": "post-processing",
    "mean_image_iou": "per-image mean IoU",
    "mean_path_prior": "mean path prior",
    "colour_classifier": "colour classifier",
    **{key: title for key, title, _ in GROUPS},
}


def title(key: str) -> str:
    """The title of a metrics key in every table (a score's, else TITLES; the key itself without an entry)."""
    return SCORE_TITLES.get(key) or TITLES.get(key, key)


def result_row(network: str, pretraining: str, postprocessing: str, scores: Mapping[str, float], mean_image_iou: float) -> Record:
    """A row of the results table: a run, raw or post-processed, its pooled scores (every registered
    one) and the per-image mean IoU (not the paper's pooled IoU)."""
    return Record(network=network, pretraining=pretraining, postprocessing=postprocessing, **scores, mean_image_iou=mean_image_iou)


def baseline_row(baseline: str, scores: Mapping[str, float | None]) -> Record:
    """A row of the baselines table; a score metrics.json holds as None (undefined) is nan (n/a)."""
    return Record(baseline=baseline, **{name: float("nan") if scores[name] is None else scores[name] for name in SCORES})


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


def _columns(row) -> list[tuple[str, str]]:
    """(name, title) of a row's columns: a Record's keys, or a dataclass's fields (titled by their metadata)."""
    if isinstance(row, dict):
        return [(name, title(name)) for name in row]
    return [(f.name, f.metadata.get("title", f.name)) for f in fields(row)]


def _value(row, name: str):
    return row[name] if isinstance(row, dict) else getattr(row, name)


def grid(header: Sequence[str], rows: Iterable[Sequence[object]]) -> str:
    """The one Markdown table builder of every report table (README, docs/results.md, results.md,
    the drive's) and of the benchmarks': a header row, the separator and one row per cell list; no
    trailing newline. A benchmark that prints each row as it is measured prints grid_head, then grid_row."""
    return "\n".join([grid_head(header), *(grid_row(row) for row in rows)])


def grid_head(header: Sequence[str]) -> str:
    """A table's header row and separator (grid's first two lines)."""
    return "| " + " | ".join(header) + " |\n|" + " --- |" * len(header)


def grid_row(cells: Sequence[object]) -> str:
    """One row of a table (grid's)."""
    return "| " + " | ".join(str(cell) for cell in cells) + " |"


def markdown_table(rows: list) -> str:
    """A Markdown table of rows (Records or dataclasses), one column per key or field."""
    columns = _columns(rows[0])
    return grid([title for _, title in columns], ([fmt(_value(row, name)) for name, _ in columns] for row in rows)) + "\n"


def csv_text(rows: list) -> str:
    """CSV of rows (Records or dataclasses): a header of names, floats rounded to 6 decimals."""
    out = io.StringIO()
    names = [name for name, _ in _columns(rows[0])]
    writer = csv.DictWriter(out, fieldnames=names, lineterminator="\n")
    writer.writeheader()
    writer.writerows({k: (round(v, 6) if isinstance(v, float) else v) for k, v in ((n, _value(r, n)) for n in names)} for r in rows)
    return out.getvalue()


@dataclass(frozen=True)
class TemporalRow:
    method: str
    frames: int
    iou: float = field(metadata={"title": "IoU, every frame"})
    iou_filtered: float = field(metadata={"title": "IoU, filtered"})
    stability: float
    stability_filtered: float = field(metadata={"title": "stability, filtered"})
    gain_low: float = field(default=float("nan"), metadata={"title": "filtered - raw IoU, 95 % low"})
    gain_high: float = field(default=float("nan"), metadata={"title": "filtered - raw IoU, 95 % high"})
