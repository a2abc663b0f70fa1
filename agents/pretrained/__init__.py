"""Pretrained caregivers shipped with the package, loadable by name: ``pretrained:NAME``.

Each model is a self-contained SB3 ``NAME.zip`` (:func:`agents.rl.save_agent`'s bundle) with a
card ``NAME.json`` beside it: the env id and env kwargs it plays, how it was trained (command,
seed, steps, wall time) and its held-out table (``evaluation``: success, unsafe, premature and
timeout rates with 95 % Wilson intervals and the mind-reading score, beside the best blind
policy, the prober and the oracle on the same episodes). ``check`` holds the figures of the
first episodes of that evaluation, which ``tests/agents/test_pretrained.py`` reproduces exactly.

Load one with ``agents.rl.load_agent("pretrained:hard-ppo")``, or score it with
``python -m agents.evaluate --model pretrained:hard-ppo --compare blind,prober,oracle``.
Nothing here imports torch or SB3.

Example:
    >>> from agents.pretrained import pretrained_names
    >>> "hard-ppo" in pretrained_names()
    True
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path
from typing import Any

__all__ = ["PREFIX", "is_pretrained", "pretrained_card", "pretrained_model_path", "pretrained_names"]

PREFIX = "pretrained:"
"""How a model name says it is one of these (``pretrained:hard-ppo``)."""


def _folder() -> Path:
    return Path(str(resources.files(__name__)))


def pretrained_names() -> tuple[str, ...]:
    """The names of the shipped models (those with both a card and a model file), sorted."""
    folder = _folder()
    return tuple(sorted(p.stem for p in folder.glob("*.json") if (folder / f"{p.stem}.zip").exists()))


def is_pretrained(entry: str | Path) -> bool:
    """Whether a model argument names a pretrained model (``pretrained:NAME``) rather than a path."""
    return isinstance(entry, str) and entry.startswith(PREFIX)


def _name(entry: str) -> str:
    """``NAME`` of ``pretrained:NAME`` (or of ``NAME``); ValueError listing the known names if unknown."""
    name = entry.removeprefix(PREFIX)
    known = pretrained_names()
    if name not in known:
        raise ValueError(f"unknown pretrained model {name!r}; known: {', '.join(PREFIX + k for k in known)}")
    return name


def pretrained_card(entry: str) -> dict[str, Any]:
    """The card of ``pretrained:NAME`` (or ``NAME``) as a dict.

    Raises:
        ValueError: an unknown name (the message lists the known ones).
    """
    name = _name(entry)
    card: dict[str, Any] = json.loads((_folder() / f"{name}.json").read_text())
    return card


def pretrained_model_path(entry: str) -> Path:
    """The model zip of ``pretrained:NAME`` (or ``NAME``).

    Raises:
        ValueError: an unknown name (the message lists the known ones).
    """
    return _folder() / f"{_name(entry)}.zip"
