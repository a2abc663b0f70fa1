"""Pretrained caregivers shipped with the package, loadable by name: ``pretrained:NAME``.

Each model is a self-contained SB3 ``NAME.zip`` (:func:`agents.rl.save_agent`'s bundle), or an
ensemble (:class:`agents.rl.ensemble.EnsembleAgent`) whose member zips lie in a folder ``NAME/``,
named by its card's ``members`` (paths relative to this folder). Beside each is a card
``NAME.json``: the env id and env kwargs it plays, how it was trained (command, seed, steps, wall
time) and its held-out table (``evaluation``: success, unsafe, premature and
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

__all__ = [
    "PREFIX",
    "is_pretrained",
    "pretrained_card",
    "pretrained_members",
    "pretrained_model_path",
    "pretrained_names",
]

PREFIX = "pretrained:"
"""How a model name says it is one of these (``pretrained:hard-ppo``)."""


def _folder() -> Path:
    return Path(str(resources.files(__name__)))


def pretrained_names() -> tuple[str, ...]:
    """The names of the shipped models (a card with a model file or an ensemble's folder beside it), sorted."""
    folder = _folder()
    shipped = [
        p.stem for p in folder.glob("*.json") if (folder / f"{p.stem}.zip").is_file() or (folder / p.stem).is_dir()
    ]
    return tuple(sorted(shipped))


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
    """The model zip of ``pretrained:NAME`` (or ``NAME``), a single model.

    Raises:
        ValueError: an unknown name (the message lists the known ones), or an ensemble (its members:
            :func:`pretrained_members`).
    """
    name = _name(entry)
    if pretrained_members(name):
        raise ValueError(f"{PREFIX}{name} is an ensemble, not one model zip: its members are pretrained_members()")
    return _folder() / f"{name}.zip"


def pretrained_members(entry: str) -> tuple[Path, ...]:
    """The member zips of the ensemble ``pretrained:NAME`` (its card's ``members``); ``()`` for a single model.

    Raises:
        ValueError: an unknown name, a ``members`` that is not a list of two or more paths inside this
            folder, or a member file missing (the message names it).
    """
    name = _name(entry)
    members = pretrained_card(name).get("members")
    if members is None:
        return ()
    if not isinstance(members, list) or len(members) < 2 or not all(isinstance(m, str) for m in members):
        raise ValueError(f"{PREFIX}{name}: the card's 'members' is not a list of two or more model zips")
    folder = _folder().resolve()
    paths = tuple((folder / member).resolve() for member in members)
    for member, path in zip(members, paths, strict=True):
        if not path.is_relative_to(folder):
            raise ValueError(f"{PREFIX}{name}: member {member!r} lies outside {folder}")
        if not path.is_file():
            raise ValueError(f"{PREFIX}{name}: member {member!r} is missing (no file {path})")
    return paths
