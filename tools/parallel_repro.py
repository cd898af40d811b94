"""`dvc repro` of one pipeline with its independent stages side by side, as many at once as --jobs:

    python tools/parallel_repro.py gpu/dvc.yaml --jobs 4 [--json gpu/metrics/pipeline_time.json] [--log FILE]

DVC runs a pipeline's stages one by one; on one GPU that leaves it mostly idle (a training of
these networks takes a few GB of its memory and a fraction of its compute). DVC releases its
repository lock while a stage's command runs, so separate `dvc repro --single-item` processes may
run separate stages at once; `--wait-for-lock` makes each wait its turn for the lock when it reads
the pipeline or records its stage in dvc.lock. This schedules them: a stage starts once every
stage it depends on has finished, in dvc.yaml's order, at most --jobs at a time; the result is the
dvc.lock and outputs one `dvc repro` writes. Each stage's process gets OFFROAD_THREADS = the
usable cores / --jobs (the GPU preset's `threads` reads it), so that the stages share the cores
instead of each spinning on all of them.

A failed stage stops the run: no stage starts after it, the running ones finish, and the command
exits 1 naming it and its log. SIGTERM or Ctrl-C stops every stage (each deletes its unfinished
outputs, as under `dvc repro`). `--json` writes the machine, `total_s`, each stage's seconds from
its start to its end and its span from the run's start (`spans`), in the format
benchmarks/pipeline_time.py writes, rewritten as each stage finishes: a run stopped part way (a
time limit's SIGTERM) leaves the stages it finished, with `complete: false` and the stages it
stopped in `unfinished`; `--log` every stage's output, each line prefixed by its stage.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from pipeline_time import machine  # the benchmark's machine line, one wording


def stage_graph(repo_root: Path, target: str) -> tuple[list[str], dict[str, set[str]]]:
    """The stages of the pipeline `target` (a dvc.yaml, relative to the repository) in dvc.yaml's order
    (`foreach` expanded) and, for each, the stages of the same pipeline it depends on."""
    from dvc.repo import Repo

    repo = Repo(str(repo_root))
    graph = repo.index.graph
    mine = [s for s in repo.index.stages if s.path_in_repo == target]  # DVC's order: dvc.yaml's
    names = {s: s.name for s in mine}  # `addressing` is relative to the working directory: no ":" from the pipeline's own
    upstream = {names[s]: {names[d] for d in graph.successors(s) if d in names} for s in mine}
    return [names[s] for s in mine], upstream


class Scheduler:
    """Starts each stage once its upstream stages have finished, at most `jobs` at once."""

    def __init__(self, repo_root: Path, target: str, jobs: int, logs: Path, timing: Path | None = None) -> None:
        self.repo_root, self.target, self.jobs, self.logs, self.timing = repo_root, target, jobs, logs, timing
        self.order, self.upstream = stage_graph(repo_root, target)
        self.env = {**os.environ, "OFFROAD_THREADS": str(max(1, len(os.sched_getaffinity(0)) // jobs))}
        self.start = time.monotonic()
        self.running: dict[str, tuple[subprocess.Popen, float]] = {}
        self.spans: dict[str, tuple[float, float]] = {}  # finished stages: (start, end) from the run's start
        self.failed: str | None = None

    def start_ready(self) -> None:
        ready = [s for s in self.order if s not in self.spans and s not in self.running and self.upstream[s] <= self.spans.keys()]
        for stage in ready[: self.jobs - len(self.running)]:
            command = [sys.executable, "-m", "dvc", "--wait-for-lock", "repro", "--single-item", f"{self.target}:{stage}"]
            with (self.logs / f"{stage}.log").open("w") as out:  # the child holds its own copy of the file
                process = subprocess.Popen(command, cwd=self.repo_root, env=self.env, stdout=out, stderr=subprocess.STDOUT)
            self.running[stage] = (process, time.monotonic() - self.start)
            print(f"started {stage} ({len(self.running)} running)", flush=True)

    def reap(self) -> None:
        for stage, (process, began) in list(self.running.items()):
            if process.poll() is None:
                continue
            del self.running[stage]
            self.spans[stage] = (round(began, 1), round(time.monotonic() - self.start, 1))
            if process.returncode != 0 and self.failed is None:
                self.failed = stage
            seconds = self.spans[stage][1] - self.spans[stage][0]
            print(f"{'failed' if process.returncode else 'finished'} {stage} in {seconds:.1f} s", flush=True)
            self.write_timing()

    def write_timing(self, unfinished: list[str] | None = None) -> None:
        """The stage times so far (--json): complete once every stage has finished without a failure."""
        if self.timing is not None:
            complete = self.failed is None and not unfinished and self.spans.keys() == set(self.order)
            write_json(self.timing, self.spans, self.jobs, complete=complete, unfinished=unfinished or [])

    def stop(self, signum: int, frame: object) -> None:
        """SIGTERM or Ctrl-C: every running stage gets SIGTERM (it deletes its unfinished outputs)."""
        for process, _ in self.running.values():
            process.send_signal(signal.SIGTERM)
        for process, _ in self.running.values():
            process.wait()
        self.write_timing(unfinished=list(self.running))
        raise SystemExit(128 + signum)

    def run(self) -> str | None:
        """Every stage, or up to the first failure and the stages running beside it; the failed stage."""
        previous = {s: signal.signal(s, self.stop) for s in (signal.SIGTERM, signal.SIGINT)}
        try:
            while True:
                if self.failed is None:
                    self.start_ready()
                if not self.running:
                    self.write_timing()
                    return self.failed  # all done, or nothing more may start after a failure
                time.sleep(0.2)
                self.reap()
        finally:
            for s, handler in previous.items():
                signal.signal(s, handler)


def run(pipeline: Path, jobs: int, log: Path | None, timing: Path | None = None) -> tuple[dict[str, tuple[float, float]], int]:
    """Run the pipeline's stages; each finished stage's span and the exit status. timing: --json's file."""
    from dvc.repo import Repo

    repo_root = Path(Repo.find_root(str(pipeline.resolve().parent)))
    logs = Path(tempfile.mkdtemp(prefix="parallel_repro."))
    scheduler = Scheduler(repo_root, str(pipeline.resolve().relative_to(repo_root)), jobs, logs, timing)
    try:
        failed = scheduler.run()
    finally:  # a run stopped part way (a time limit) keeps the output of the stages it ran too
        if log is not None:
            with log.open("w") as out:
                for stage in scheduler.order:
                    if (logs / f"{stage}.log").is_file():
                        out.writelines(f"[{stage}] {line}" for line in (logs / f"{stage}.log").read_text().splitlines(keepends=True))
    if failed is not None:  # the logs stay for the user to read
        tail = (logs / f"{failed}.log").read_text().splitlines()[-20:]
        print(f"error: stage {failed} failed (its log: {logs / f'{failed}.log'}):\n" + "\n".join(tail), file=sys.stderr)
        return scheduler.spans, 1
    shutil.rmtree(logs)
    return scheduler.spans, 0


def write_json(path: Path, spans: dict[str, tuple[float, float]], jobs: int, *, complete: bool, unfinished: list[str]) -> None:
    timed = {
        "machine": machine(),
        "total_s": max((end for _, end in spans.values()), default=0.0),
        "jobs": jobs,
        "complete": complete,
        "unfinished": unfinished,
        "stages": {stage: round(end - began, 1) for stage, (began, end) in spans.items()},
        "spans": {stage: list(span) for stage, span in spans.items()},
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(path.name + ".partial")
    partial.write_text(json.dumps(timed, indent=2) + "\n")
    partial.replace(path)  # whole or not at all, even when the run is stopped while writing


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("pipeline", type=Path, help="a dvc.yaml in a DVC repository")
    parser.add_argument("--jobs", type=int, default=4, help="stages at once (default 4)")
    parser.add_argument("--json", type=Path, help="write the machine, total_s and each stage's seconds here")
    parser.add_argument("--log", type=Path, help="write every stage's output here")
    args = parser.parse_args(argv)
    if args.jobs < 1:
        print(f"error: --jobs {args.jobs}: must be 1 or more", file=sys.stderr)
        return 2
    if not args.pipeline.is_file() or args.pipeline.name != "dvc.yaml":
        print(f"error: {args.pipeline}: not a dvc.yaml", file=sys.stderr)
        return 2
    from dvc.exceptions import NotDvcRepoError

    try:
        _, status = run(args.pipeline, args.jobs, args.log, args.json)
    except NotDvcRepoError:
        print(f"error: {args.pipeline}: not in a DVC repository (dvc init)", file=sys.stderr)
        return 2
    return status


if __name__ == "__main__":
    raise SystemExit(main())
