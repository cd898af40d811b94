"""What a network loses on a look it never saw: its IoU on the test worlds drawn with a held-out
appearance (world.appearance.held_out, which no training drive shows) minus its IoU on the other
test worlds, each network's seeds pooled. The two sets are different worlds, so the interval is
over the hierarchical bootstrap of all test worlds (blocks within them, the training seeds) with
both sets' IoU computed on the same draw; a draw that holds no world of one set is left out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from offroad_path.evaluation.bootstrap import Interval
from offroad_path.evaluation.conditions import read_conditions
from offroad_path.evaluation.metrics import pooled
from offroad_path.evaluation.report import TestSet
from offroad_path.evaluation.scores import iou as iou_score
from offroad_path.evaluation.tables import markdown_table, method_title
from offroad_path.evaluation.uncertainty import HierarchicalBootstrap


@dataclass
class LookRow:
    method: str = field(metadata={"title": "method"})
    seen: float = field(metadata={"title": "IoU, seen looks"})
    held_out: float = field(metadata={"title": "IoU, held-out looks"})
    loss: str = field(metadata={"title": "held-out minus seen [95 % interval]"})


class HeldOutLooks:
    """The report section (evaluate), present when the test worlds hold both kinds of look."""

    def __init__(self, bootstrap: HierarchicalBootstrap) -> None:
        self.bootstrap = bootstrap
        self.rows: dict[str, tuple[float, float, Interval | None]] = {}
        self.worlds: tuple[int, int] = (0, 0)

    def score(self, test: TestSet) -> None:
        conditions = read_conditions(test.samples)
        if conditions is None:
            return
        held = np.array([row["look"] == "held_out" for row in conditions])
        if held.all() or not held.any():
            return
        sequences = np.array([s.sequence for s in test.samples])
        self.worlds = (len(set(sequences[~held])), len(set(sequences[held])))
        per_image = {run: np.stack(test.seed_counts[run, "no"]) for run in test.runs} | {"mean_path_prior": test.prior_counts}
        if test.colour_counts is not None:
            per_image["colour_classifier"] = test.colour_counts
        for key, counts in per_image.items():
            seen, out = counts * ~held[:, None], counts * held[:, None]  # each set's counts, zero on the other's frames
            loss = self.bootstrap.paired(out, seen, iou_score)
            self.rows[key] = (pooled(seen.reshape(-1, 4)).iou, pooled(out.reshape(-1, 4)).iou, loss)

    def markdown(self) -> str:
        if not self.rows:
            return ""
        rows = [
            LookRow(look_title(key), seen, out, "" if loss is None else loss.difference_text())
            for key, (seen, out, loss) in self.rows.items()
        ]
        return (
            f"\n## Held-out appearance\n\nPooled IoU (raw maps) on the {self.worlds[1]} test worlds drawn with a look no training "
            f"drive shows (world.appearance.held_out) and on the other {self.worlds[0]}, and the difference with its 95 % "
            "hierarchical-bootstrap interval (all test worlds resampled, both sets scored on each draw, the training seeds "
            "drawn together). Negative: lost outside the training looks; an interval containing 0: no difference measured. "
            "The sets are different worlds, so the difference also holds how hard each set's drives are: the mean path "
            "prior's row shows that part.\n\n" + markdown_table(rows)
        )

    def metrics(self) -> dict:
        def entry(seen: float, out: float, loss: Interval | None) -> dict:
            found = {"seen_iou": seen, "held_out_iou": out}
            if loss is not None:
                found |= {"loss": loss.estimate, "loss_low": loss.low, "loss_high": loss.high}
            return found

        return {"held_out_looks": {key: entry(*row) for key, row in self.rows.items()}} if self.rows else {}


BASELINES = {"mean_path_prior": "mean path prior", "colour_classifier": "colour classifier"}


def look_title(key: str) -> str:
    """A row's name: a baseline's, or a run's method title."""
    return BASELINES[key] if key in BASELINES else method_title(key)
