"""The error every reader raises on bad input: it names the file and what is wrong with it."""

from __future__ import annotations

from pathlib import Path


class SequenceError(ValueError):
    def __init__(self, path: str | Path, problem: str):
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")

    def __reduce__(self):  # rebuilt from both arguments when it crosses from a worker process
        return type(self), (self.path, self.problem)
