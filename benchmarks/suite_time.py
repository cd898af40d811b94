"""The test suite's two tiers, timed: `pytest` (the README's test command, what .ci/run runs) and
`pytest -m "not slow"` (the everyday one), in this checkout and, with --against REV, in a clean
worktree of REV, alternated tier by tier (back to back: this machine is noisy).

    python benchmarks/suite_time.py [--tiers full,everyday] [--against REV] [--repeats N] [--json OUT]

Each run is a fresh `python -m pytest` with the checkout's own pyproject (xdist, one worker per core
up to 4) and its source first on the path, so REV's tree runs its own code with this environment's
packages. The table gives each run's wall seconds as pytest reports them, and its counts.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
from pathlib import Path

from common import positive_int

from offroad_path.report.tables import grid

ROOT = Path(__file__).resolve().parents[1]
TIERS = {"full": [], "everyday": ["-m", "not slow"]}
SUMMARY = re.compile(r"^=*\s*(\d+ (?:passed|failed|errors?|skipped)\b.*) in ([0-9.]+)s", re.M)  # pytest's last line, with -q or not


def run_tier(tree: Path, tier: str) -> dict:
    """One run of a tier in `tree`: its seconds and its counts (passed, failed, skipped, ...), and its exit status."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tree / "src"), os.environ.get("PYTHONPATH", "")])}
    command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", *TIERS[tier]]
    done = subprocess.run(command, cwd=tree, env=env, capture_output=True, text=True)
    found = SUMMARY.findall(done.stdout)
    if not found:
        raise SystemExit(f"{tree}: pytest printed no summary line (exit {done.returncode}):\n{done.stdout[-2000:]}{done.stderr[-2000:]}")
    counts, seconds = found[-1]
    parsed = {name: int(n) for n, name in re.findall(r"(\d+) (passed|failed|skipped|errors?|xfailed|xpassed)", counts)}
    return {"seconds": float(seconds), "exit": done.returncode, **parsed}


def cpu_name() -> str:
    """The CPU's model name (/proc/cpuinfo), else the platform's word for it."""
    cpuinfo = Path("/proc/cpuinfo")
    lines = cpuinfo.read_text().splitlines() if cpuinfo.is_file() else []
    names = [line.split(":", 1)[1].strip() for line in lines if line.startswith("model name")]
    return names[0] if names else platform.processor() or platform.machine()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tiers", default="full,everyday", help=f"comma-separated, of {', '.join(TIERS)}")
    parser.add_argument("--against", help="a commit to time back to back with this checkout, in a clean worktree of it")
    parser.add_argument("--repeats", type=positive_int, default=1)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    tiers = args.tiers.split(",")
    if unknown := [t for t in tiers if t not in TIERS]:
        parser.exit(2, f"error: --tiers: unknown {unknown[0]!r}; valid: {', '.join(TIERS)}\n")
    with tempfile.TemporaryDirectory() as tmp:
        trees = {"this checkout": ROOT}
        if args.against:
            other = Path(tmp) / "against"
            subprocess.run(["git", "worktree", "add", "--detach", "-q", str(other), args.against], cwd=ROOT, check=True)
            trees[args.against] = other
        runs = []
        try:
            for _ in range(args.repeats):
                for tier in tiers:
                    for name, tree in trees.items():
                        runs.append({"tree": name, "tier": tier, **run_tier(tree, tier)})
                        print(f"{name}, {tier}: {runs[-1]['seconds']:.0f} s", file=sys.stderr, flush=True)
        finally:
            if args.against:
                subprocess.run(["git", "worktree", "remove", "--force", str(trees[args.against])], cwd=ROOT, check=False)
    print(f"{cpu_name()}, {os.cpu_count()} cores")
    columns = ["tree", "tier", "seconds", "passed", "failed", "skipped", "exit"]
    print(grid(columns, ([run.get(c, 0) for c in columns] for run in runs)))
    if args.json:
        args.json.write_text(json.dumps(runs, indent=2) + "\n")


if __name__ == "__main__":
    main()
