"""Progress of a stage's units of work (worlds, sequences, routes): a tqdm bar on a terminal, one log
line per unit otherwise (under `dvc repro`'s log, in CI, in the tests), so that a long stage always
says how far it is and a log never fills with a bar's redraws."""

from __future__ import annotations

import logging
import sys
import time

log = logging.getLogger("offroad_path.progress")


class Progress:
    """`total` units of `what` (e.g. "render", "sequences"); `done(name)` after each."""

    def __init__(self, what: str, total: int, unit: str) -> None:
        self.what, self.total, self.unit, self.count = what, total, unit, 0
        self.start = time.perf_counter()
        self.bar = None
        if sys.stderr.isatty():
            from tqdm import tqdm

            self.bar = tqdm(total=total, desc=what, unit=unit, file=sys.stderr, dynamic_ncols=True, leave=False)

    def done(self, name: str = "") -> None:
        self.count += 1
        if self.bar is not None:
            self.bar.set_postfix_str(name, refresh=False)
            self.bar.update(1)
        else:
            elapsed = time.perf_counter() - self.start
            log.info("%s: %d/%d %s%s, %.0f s", self.what, self.count, self.total, self.unit, f" ({name})" if name else "", elapsed)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
