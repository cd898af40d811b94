"""The project's bad-input error, and how every command reports it: one line naming the file or
key, exit status 2, no traceback. The lowest layer: it imports nothing of the project."""

from __future__ import annotations

import argparse
import contextlib
import re
import sys
from collections.abc import Iterator
from pathlib import Path

from omegaconf.errors import InterpolationToMissingValueError, MissingMandatoryValue

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130  # 128 + SIGINT, as a shell reports a command Ctrl-C stopped


class InputError(ValueError):
    """Bad input: `path` names the file, folder or setting, `problem` what is wrong with it."""

    def __init__(self, path: str | Path, problem: str):
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")

    def __reduce__(self):  # rebuilt from both arguments when it crosses from a worker process
        return type(self), (self.path, self.problem)


def missing_extra(command: str, extra: str, module: str | None) -> InputError:
    """The error of a command whose optional dependencies (`pip install -e '.[extra]'`) are not installed."""
    return InputError(command, f"needs the [{extra}] extra ({module} is not installed): pip install -e '.[{extra}]'")


@contextlib.contextmanager
def clear_errors() -> Iterator[None]:
    """Turn bad-input errors into one line naming the file or key, and exit status 2."""
    try:
        yield
    except MissingMandatoryValue as e:  # a required setting (`???` in conf/) was not given
        print(f"error: {e.full_key} is required: give it on the command line, {e.full_key}=...", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from e
    except InterpolationToMissingValueError as e:  # a setting made from a required one (label.in_dir from paths.root)
        missing = re.search(r"Missing mandatory value: (\S+)", str(e))
        key = missing.group(1) if missing else e.full_key
        print(f"error: {key} is required (for {e.full_key}): give it on the command line, {key}=...", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from e
    except OSError as e:  # a missing file, a full disk, a folder that may not be written
        print(f"error: {e.filename}: {e.strerror}" if e.filename and e.strerror else f"error: {e}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from e
    except ValueError as e:  # InputError, CheckpointError, ConfigValueError are ValueErrors
        print(f"error: {one_line(e)}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from e
    except KeyboardInterrupt:  # Ctrl-C: the outputs' own clean-up has run on the way out; no traceback
        print("interrupted: unfinished outputs removed", file=sys.stderr)
        raise SystemExit(EXIT_INTERRUPTED) from None


def one_line(error: BaseException, with_cause: bool = False) -> str:
    """An error's message on one line (Hydra's and OmegaConf's span several), and with_cause, its
    cause's first line (OmegaConf says there which key was wrong)."""
    text = " ".join(line.strip() for line in str(error).split("\nConfig search path")[0].splitlines() if line.strip())
    cause = error.__cause__
    if with_cause and cause is not None and str(cause).strip() and str(cause).strip() not in text:
        text += f" ({str(cause).strip().splitlines()[0]})"
    return text


class CommandParser(argparse.ArgumentParser):
    """argparse for the project's small commands: a bad argument is one `error:` line and exit 2,
    as bad input is everywhere else (argparse prints its usage first)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        print(f"error: {self.prog}: {message} (--help lists the arguments)", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT)


def positive_number(text: str) -> float:
    """An argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not (value > 0 and value != float("inf")):
        raise argparse.ArgumentTypeError(f"{text!r} is not a number > 0")
    return value


def positive_int(text: str) -> int:
    """An argparse type: a whole number >= 1."""
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number >= 1")
    return value
