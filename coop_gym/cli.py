"""Argument types shared by the command-line tools (``train.py``, ``agents.*``, ``estimator.*``, ``bench``).

An invalid value makes argparse exit with status 2 and a message naming the flag.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

__all__ = ["output_path_problem", "positive_int", "seed"]


def positive_int(text: str) -> int:
    """An integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {value}")
    return value


def seed(text: str) -> int:
    """A non-negative integer seed."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer seed, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"expected a non-negative integer seed, got {value}")
    return value


def output_path_problem(path: str | Path, folder: bool = False) -> str | None:
    """Why ``path`` (a file, or with ``folder`` a folder) cannot be written, or None if it can.

    Checked before any work starts, so a bad output path fails in a second, not after a run:
    the nearest existing ancestor must be a writable folder (missing folders are created later).
    """
    target = Path(path)
    if folder and target.exists() and not target.is_dir():
        return f"{target} exists and is not a folder"
    if not folder and target.is_dir():
        return f"{target} is a folder, not a file"
    ancestor = target if folder else target.parent
    while not ancestor.exists():
        if ancestor.parent == ancestor:
            break
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"cannot create {target}: {ancestor} is not a folder"
    if not os.access(ancestor, os.W_OK | os.X_OK):
        return f"cannot create {target}: {ancestor} is not writable"
    return None
