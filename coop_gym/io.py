"""Atomic file output: every file is written beside its target under a temporary name, then renamed.

A crash, a full disk or Ctrl-C while writing leaves either the old file or the new one,
never half a file. The writer (``json.dumps``, ``csv``, matplotlib's ``savefig``, Pillow,
moviepy, SB3's ``save``) writes the temporary path; :func:`atomic_path` flushes it to disk and
``os.replace``-s it onto the target (atomic on POSIX within one filesystem, which is why the
temporary file lives in the same folder). The temporary name keeps the target's suffix, so
writers that pick the format from the extension still do.

Example:
    >>> import json, tempfile
    >>> folder = Path(tempfile.mkdtemp())
    >>> write_json(folder / "a.json", {"x": 1}).name
    'a.json'
    >>> json.loads((folder / "a.json").read_text())
    {'x': 1}
    >>> sorted(p.name for p in folder.iterdir())  # no temporary file left
    ['a.json']
"""

from __future__ import annotations

import contextlib
import itertools
import json
import os
import secrets
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

__all__ = [
    "TEMP_MARKER",
    "atomic_open",
    "atomic_path",
    "make_unique_folder",
    "save_figure",
    "save_with",
    "write_bytes",
    "write_json",
    "write_text",
]

TEMP_MARKER = ".tmp-"
"""Part of every temporary name (``.{stem}.tmp-{random}{suffix}``); such files are never results."""


def _fsync(path: Path) -> None:
    """Flush a written file to disk (a module function so tests can make it fail like a full disk)."""
    with path.open("rb") as handle:
        os.fsync(handle.fileno())


def _temp_path(path: Path) -> Path:
    return path.with_name(f".{path.stem}{TEMP_MARKER}{secrets.token_hex(4)}{path.suffix}")


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path to write; on success it replaces ``path``, on any error it is removed.

    Args:
        path: The target file. Its folder must exist (create it first).

    Raises:
        OSError: Whatever the writer or the disk raised (e.g. ``ENOSPC``); the target is
            untouched and no temporary file remains.
    """
    target = Path(path)
    temp = _temp_path(target)
    try:
        yield temp
        if temp.is_dir():  # a writer that makes folders (a checkpoint) is synced file by file
            for child in temp.rglob("*"):
                if child.is_file():
                    _fsync(child)
        else:
            _fsync(temp)
        os.replace(temp, target)
    except BaseException:
        _remove(temp)
        raise


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        import shutil

        shutil.rmtree(path, ignore_errors=True)
    else:
        path.unlink(missing_ok=True)


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "w", **kwargs: Any) -> Iterator[IO[Any]]:
    """``open`` for writing whose file appears at ``path`` only once it is complete."""
    if not mode.startswith(("w", "x")):
        raise ValueError(f"atomic_open writes whole files: mode must start with 'w' or 'x', got {mode!r}")
    with atomic_path(path) as temp, temp.open(mode, **kwargs) as handle:
        yield handle


def write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns ``path``."""
    with atomic_open(path, "wb") as handle:
        handle.write(data)
    return Path(path)


def write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically; returns ``path``."""
    with atomic_open(path, "w", encoding="utf-8") as handle:
        handle.write(text)
    return Path(path)


def write_json(path: str | Path, payload: Any, indent: int | None = 2) -> Path:
    """Write ``payload`` as JSON (with a final newline) atomically; returns ``path``."""
    return write_text(path, json.dumps(payload, indent=indent) + "\n")


def save_figure(fig: Any, path: str | Path, **kwargs: Any) -> Path:
    """``fig.savefig(path, **kwargs)`` atomically (the format follows the suffix of ``path``)."""
    with atomic_path(path) as temp:
        fig.savefig(temp, **kwargs)
    return Path(path)


def save_with(path: str | Path, writer: Callable[[Path], Any]) -> Path:
    """Call ``writer(temporary_path)`` and move the result onto ``path`` atomically."""
    with atomic_path(path) as temp:
        writer(temp)
    return Path(path)


def make_unique_folder(parent: str | Path, name: str) -> Path:
    """Create and return ``parent/name``, or ``parent/name_1``, ``name_2``, ... if taken.

    ``os.mkdir`` fails if the folder exists, so two processes that start in the same second
    never share a folder, and the counter has no ceiling.
    """
    parent = Path(parent)
    parent.mkdir(parents=True, exist_ok=True)
    for k in itertools.count():
        candidate = parent / (name if k == 0 else f"{name}_{k}")
        try:
            os.mkdir(candidate)
        except FileExistsError:
            continue
        return candidate
    raise AssertionError("unreachable")  # itertools.count() never ends
