"""RL Zoo's ``-conf agents.zoo.ppo_lstm``: ``--algo ppo_lstm``'s settings (:func:`agents.zoo.zoo_hyperparams`)."""

from __future__ import annotations

from typing import Any

from agents.zoo import zoo_hyperparams

__all__ = ["hyperparams"]

hyperparams: dict[str, dict[str, Any]] = zoo_hyperparams("recurrent_ppo")
"""Keyed by env id, as RL Zoo's ``ExpManager.read_hyperparameters`` reads it."""
