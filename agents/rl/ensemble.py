"""Several trained caregivers as one: the greedy action of their averaged action probabilities.

An :class:`EnsembleAgent` holds saved MLP policies (``train.py`` runs, the seeds of a ``--seeds`` run) of
one env and observation. Each member normalises the observation with its own statistics and gives
its probabilities per action head; the ensemble takes, per head, the action of highest mean
probability. It follows the agents' ``predict`` protocol, so :func:`agents.evaluate.evaluate`
scores it as any other agent. ``train.py --seeds N`` (``--keep ensemble``, PPO's default) keeps its
seeds this way: the run folder's ``ensemble.json`` names them, and :func:`agents.rl.load_agent` of the
folder gives :func:`load_run_ensemble`; a pretrained ensemble (``pretrained:NAME`` whose card names
``members``) loads as :func:`load_pretrained_ensemble`.

Example:
    >>> from agents.rl.ensemble import load_ensemble
    >>> agent = load_ensemble(["runs/a", "runs/b"])  # doctest: +SKIP
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from agents.pretrained import PREFIX, is_pretrained, pretrained_card, pretrained_members
from agents.rl.bundle import GreedyActor, SB3Agent
from agents.rl.bundle import load_agent as load_saved
from agents.run_folder import ENSEMBLE_FILE, ENSEMBLE_PREFIX

__all__ = [
    "ENSEMBLE_PREFIX",
    "EnsembleAgent",
    "load_agent",
    "load_ensemble",
    "load_pretrained_ensemble",
    "load_run_ensemble",
]


class EnsembleAgent(SB3Agent):
    """The greedy action of the members' mean action probabilities (see the module docstring).

    An :class:`SB3Agent` whose env, features, env kwargs, algorithm (and ``model``: the first member's, for
    what reads a model's settings) are its members'; only :meth:`predict` plays them all.

    Raises:
        ValueError: fewer than two members, a member that is not a feed-forward actor-critic on a
            ``Discrete`` or ``MultiDiscrete`` action, or members of other envs, features or env kwargs.
    """

    def __init__(self, members: Sequence[SB3Agent], name: str | None = None) -> None:
        """Check that the members agree on what they play (their env, features and kwargs are the ensemble's)."""
        if len(members) < 2:
            raise ValueError(f"an ensemble needs at least 2 members, got {len(members)}")
        self.members, self.actors = list(members), [GreedyActor.of(m.model.policy) for m in members]
        first = self.members[0]
        for index, (member, actor) in enumerate(zip(self.members, self.actors, strict=True)):
            if actor is None or member.frame_stack != 1:
                raise ValueError(f"ensemble member {index} ({member.name}): MLP actor-critics only, no frame stack")
            for what in ("env_id", "features", "env_kwargs", "action_space"):
                if getattr(member, what) != getattr(first, what):
                    raise ValueError(
                        f"ensemble member {index} ({member.name}) has {what} {getattr(member, what)!r}, "
                        f"member 0 has {getattr(first, what)!r}"
                    )
        super().__init__(
            first.model, first.algo, first.env_id, first.obs_normalizer, first.features, first.env_kwargs, name
        )
        self.name = name or f"ensemble of {len(self.members)}"

    def probabilities(self, observation: NDArray[Any]) -> list[NDArray[np.float64]]:
        """Per action head, the members' mean probabilities ``(N, n_head)`` for a batch ``(N, D)``."""
        import torch

        total: list[NDArray[np.float64]] | None = None
        for member, actor in zip(self.members, self.actors, strict=True):
            assert actor is not None
            heads = actor.head_logits(member.normalize(np.asarray(observation).reshape(-1, self._width())))
            probs = [torch.softmax(h.double(), dim=1).numpy() for h in heads]
            total = probs if total is None else [t + p for t, p in zip(total, probs, strict=True)]
        assert total is not None
        return [t / len(self.members) for t in total]

    def _width(self) -> int:
        return int(np.prod(self.observation_space.shape or (1,)))

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[NDArray[Any], Any]:
        """``(actions, state)``: per head the action of highest mean probability (``deterministic`` only)."""
        if not deterministic:
            raise ValueError("EnsembleAgent plays greedy only (deterministic=True)")
        single = np.asarray(observation).ndim == 1
        heads = [p.argmax(axis=1) for p in self.probabilities(observation)]
        actions = heads[0] if self.actors[0].heads is None else np.stack(heads, axis=1)  # type: ignore[union-attr]
        return (actions[0] if single else actions), state


def load_ensemble(paths: Sequence[str | Path], name: str | None = None) -> EnsembleAgent:
    """The saved agents at ``paths`` (run folders, ``model.zip`` files or ``pretrained:NAME``) as one ensemble."""
    return EnsembleAgent([load_saved(path) for path in paths], name)


def load_run_ensemble(folder: Path) -> EnsembleAgent:
    """The ensemble a run folder's ``ensemble.json`` names (its members' folders, relative to it).

    Raises:
        ValueError: the file is unreadable, names no members, or a member outside the folder or not saved.
    """
    file = folder / ENSEMBLE_FILE
    try:
        members = json.loads(file.read_text(encoding="utf-8"))["members"]
        if not isinstance(members, list) or not all(isinstance(m, str) for m in members):
            raise ValueError("'members' is not a list of folder names")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        expected = '{"members": ["seeds/seed_0", ...]}'
        raise ValueError(f"{file} is unreadable ({exc!r}); it should be {expected}") from None
    paths = [(folder / member).resolve() for member in members]
    for member, path in zip(members, paths, strict=True):
        if not path.is_relative_to(folder.resolve()) or not path.exists():
            raise ValueError(f"{file}: member {member!r} is not a saved agent inside {folder}")
    return load_ensemble(paths, name=f"ensemble of {len(paths)} ({folder.name})")


def load_pretrained_ensemble(entry: str) -> EnsembleAgent:
    """The ensemble ``pretrained:NAME`` whose card names its ``members``, named ``pretrained:NAME``.

    Its card's env kwargs come along (``agent.env_kwargs``), as a single pretrained model's do.

    Raises:
        ValueError: an unknown name, not an ensemble, or a member missing or not loadable (the message names it).
    """
    card, paths = pretrained_card(entry), pretrained_members(entry)
    name = PREFIX + card["name"]
    if not paths:
        raise ValueError(f"{name} is one model, not an ensemble: load it with agents.rl.load_agent")
    members = []
    for member, path in zip(card["members"], paths, strict=True):
        try:
            members.append(load_saved(path))
        except (OSError, ValueError) as exc:
            raise ValueError(f"{name}: member {member!r} does not load ({exc})") from None
    agent = EnsembleAgent(members, name=name)
    agent.env_kwargs = dict(card.get("env_kwargs") or {})
    return agent


def load_agent(path: str | Path) -> SB3Agent:
    """A saved agent for evaluation (``agents.rl.load_agent``), a run folder of seeds played as one included.

    ``ensemble:MODEL+MODEL+...`` loads those saved models as one, a pretrained ensemble
    (:func:`load_pretrained_ensemble`) the members its card names, and a run folder kept as an ensemble (its
    ``ensemble.json``) its members; its ``model.zip`` (the member best on the validation people) and
    anything else load as :func:`agents.rl.bundle.load_agent` loads them.

    Raises:
        FileNotFoundError, ValueError: as :func:`agents.rl.bundle.load_agent`, or a damaged ``ensemble.json``.
    """
    if isinstance(path, str) and path.startswith(ENSEMBLE_PREFIX):
        return load_ensemble(path.removeprefix(ENSEMBLE_PREFIX).split("+"), name=path)
    if is_pretrained(path) and pretrained_members(str(path)):
        return load_pretrained_ensemble(str(path))
    if not is_pretrained(path) and Path(path).is_dir() and (Path(path) / ENSEMBLE_FILE).is_file():
        return load_run_ensemble(Path(path))
    return load_saved(path)
