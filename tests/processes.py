"""Finding the processes a test started, through /proc (Linux)."""

from __future__ import annotations

from pathlib import Path


def tagged_processes(tag: str) -> list[int]:
    """Live processes started with OFFROAD_TEST_TAG=tag in their environment (workers inherit it,
    and keep it when their parent dies and they are re-parented)."""
    found = []
    for environ in Path("/proc").glob("[0-9]*/environ"):
        try:
            if f"OFFROAD_TEST_TAG={tag}".encode() in environ.read_bytes().split(b"\0"):
                state = (environ.parent / "stat").read_text().split(")")[-1].split()[0]
                if state != "Z":
                    found.append(int(environ.parent.name))
        except OSError:
            continue
    return found
