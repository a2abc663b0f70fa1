"""What the command lines share: one parser for their typed arguments, and the checks of their values.

The package's command lines (``train.py``, ``python -m agents.evaluate``, ...) each hold a
dataclass of arguments whose field docstrings are the ``--help``; :func:`parse` reads the
command line into it with tyro (as CleanRL does). Its ``__post_init__`` raises :class:`BadArgs`
for the first value no run can use, before anything is written or started. Every usage error
comes out as argparse prints one: the usage line, then one line naming the flag; exit status 2.

The argparse types (:func:`positive_int`, :func:`seed`, :func:`seed_list`) serve the ``bench/``
scripts; :data:`PositiveInt` and :data:`Seed` are the same checks as tyro field types.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any, NoReturn, TypeVar

import tyro
from tyro.conf import DisallowNone
from tyro.constructors import PrimitiveConstructorSpec

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

__all__ = [
    "SEED_LIMIT",
    "BadArgs",
    "PositiveInt",
    "PositiveIntOrNone",
    "Seed",
    "exit_status",
    "fail",
    "one_of",
    "output_path_problem",
    "parse",
    "positive_int",
    "seed",
    "seed_list",
    "seed_range_problem",
]

ArgsT = TypeVar("ArgsT", bound="DataclassInstance")

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


def _from_text(read: Callable[[str], Any], metavar: str, choices: tuple[str, ...] | None = None) -> Any:
    """A tyro field type read by ``read`` from one word; its error names the flag (``Error parsing --seed: ...``)."""

    def instance_from_str(words: list[str]) -> Any:
        try:
            return read(words[0])
        except argparse.ArgumentTypeError as exc:  # tyro names the flag for a ValueError
            raise ValueError(str(exc)) from None

    return PrimitiveConstructorSpec(
        nargs=1,
        metavar=metavar,
        instance_from_str=instance_from_str,
        is_instance=lambda value: value is None or not isinstance(value, bool),
        str_from_instance=lambda value: [str(value)],
        choices=choices,
    )


PositiveInt = Annotated[int, _from_text(positive_int, "INT")]
"""A tyro field type: an integer >= 1 (:func:`positive_int`)."""
PositiveIntOrNone = Annotated[int | None, _from_text(positive_int, "INT")]
"""A tyro field type: an integer >= 1, or None when the flag is not given."""
Seed = Annotated[int, _from_text(seed, "INT")]
"""A tyro field type: a seed, 0 <= seed < 2**32 (:func:`seed`)."""


def one_of(choices: Sequence[str]) -> Any:
    """A tyro field's choices, taken from the tuple that defines them.

    ``Annotated[str, one_of(NAMES)]``: a ``Literal`` would write the names out a second time.
    """
    names = tuple(choices)
    return _from_text(str, "{" + ",".join(names) + "}", choices=names)


class BadArgs(Exception):
    """A command-line value no run can use; the message names the flag.

    Raised by an arguments dataclass's ``__post_init__``. Not a ``ValueError``: tyro turns
    those into a boxed message of its own, while this one reaches :func:`parse`, which prints
    the one-line usage error.
    """


def parse(
    args_type: type[ArgsT],
    argv: Sequence[str] | None,
    prog: str,
    description: str | None,
    default: ArgsT | Any = tyro.MISSING_NONPROP,
) -> ArgsT:
    """``argv`` (default: ``sys.argv[1:]``) parsed into ``args_type`` and checked; usage errors exit with status 2.

    ``default`` gives the values of the flags not given (else the dataclass's defaults).
    ``--help`` prints the fields' docstrings and exits 0.
    """
    argv = sys.argv[1:] if argv is None else list(argv)
    shown = io.StringIO()  # what tyro prints: its errors come out in one line
    try:
        with contextlib.redirect_stderr(shown):
            parsed = tyro.cli(
                args_type, args=argv, default=default, prog=prog, description=description, config=(DisallowNone,)
            )
    except BadArgs as exc:
        fail(prog, str(exc))
    except SystemExit as exc:
        if exc.code:  # tyro's own error (an unknown flag, a value of the wrong type or choice)
            fail(prog, _one_line(shown.getvalue()))
        raise
    sys.stderr.write(shown.getvalue())  # a warning, if any
    return parsed


def fail(prog: str, message: str) -> NoReturn:
    """A usage error: the usage line and one error line on stderr, exit status 2 (as argparse's)."""
    print(f"usage: {prog} [-h] [OPTIONS]\n{prog}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def _one_line(box: str) -> str:
    """The message of tyro's error box in one line, as argparse prints it."""
    lines = [re.sub(r"\x1b\[[0-9;]*m", "", line).strip(" │") for line in box.splitlines()[1:]]
    rule = next((k for k, line in enumerate(lines) if line and set(line) <= set("─╰╯")), len(lines))
    return " ".join(line for line in lines[:rule] if line) or box.strip()


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


def exit_status(main: Callable[[], int | None]) -> int:
    """``main()``'s exit status, with a reader that closed the pipe early (``... --json | head``) a quiet stop.

    What was printed before reached the reader; the rest has nowhere to go. Standard output is
    pointed at ``os.devnull`` so that Python's flush at exit raises no second ``BrokenPipeError``
    (the Python docs' recipe, "Note on SIGPIPE"); the status is 1, as for any output not written.
    """
    try:
        status = main()
        sys.stdout.flush()
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 1
    return int(status or 0)
