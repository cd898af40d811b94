"""What every stage entry point shares: clear errors on bad input, and a non-zero exit."""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator

from offroad_path.sequence.errors import SequenceError

log = logging.getLogger("offroad_path")

EXIT_BAD_INPUT = 2


@contextlib.contextmanager
def clear_errors() -> Iterator[None]:
    """Turn bad-input errors into one line naming the file, and exit status 2 (no traceback)."""
    try:
        yield
    except (SequenceError, FileNotFoundError, ValueError) as e:
        print(f"error: {e}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from e
