"""Argument types shared by the command-line tools (``train.py``, ``agents.*``, ``estimator.*``, ``bench``).

An invalid value makes argparse exit with status 2 and a message naming the flag.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

__all__ = ["SEED_LIMIT", "output_path_problem", "positive_int", "seed", "seed_list", "seed_range_problem"]

SEED_LIMIT = 2**32
"""Every seed a command uses (seed, seed + 1, ... for its episodes or envs) must be below this.

NumPy's legacy global seeding, which Stable-Baselines3 calls, takes 32-bit seeds; one range
for every command keeps a seed that works in evaluation working in training too.
"""


def _integer_at_least(text: str, minimum: int, what: str) -> int:
    """``text`` read as an integer >= ``minimum``; argparse's error otherwise, naming ``what`` was expected."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None
    if value < minimum:
        raise argparse.ArgumentTypeError(f"expected {what}, got {value}")
    return value


def positive_int(text: str) -> int:
    """An integer >= 1."""
    return _integer_at_least(text, 1, "a positive integer")


def seed(text: str) -> int:
    """A non-negative integer seed."""
    value = _integer_at_least(text, 0, "a non-negative integer seed")
    if value >= SEED_LIMIT:
        raise argparse.ArgumentTypeError(f"seeds must be below 2**32, got {value}")
    return value


def seed_list(text: str) -> list[int]:
    """An argparse type: distinct seeds >= 0 joined by ``,`` (``"0,1,2"``)."""
    try:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"seeds are whole numbers joined by ',', got {text!r}") from None
    if not seeds or min(seeds) < 0 or len(set(seeds)) != len(seeds):
        raise argparse.ArgumentTypeError(f"seeds must be distinct and >= 0, got {text!r}")
    return seeds


def seed_range_problem(name: str, seed: int, count: int = 1) -> str | None:
    """Why seeds ``seed .. seed + count - 1`` are unusable (negative, or not below :data:`SEED_LIMIT`), or None.

    Example:
        >>> seed_range_problem("--seed", 2**32 - 2, count=5)
        '--seed 4294967294: seeds 4294967294..4294967298 must be below 2**32 (here at most 4294967291)'
    """
    if seed < 0:
        return f"{name} must be >= 0, got {seed}"
    if seed + count > SEED_LIMIT:
        return (
            f"{name} {seed}: seeds {seed}..{seed + count - 1} must be below 2**32 (here at most {SEED_LIMIT - count})"
        )
    return None


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
