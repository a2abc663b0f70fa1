"""Scores of a trained learner on the held-out personas, beside the handbook caregiver's.

``bench/library_defaults.py`` and ``bench/cleanrl_defaults.py`` both train a learner on its
library's defaults and score it here: every agent plays the same seeded episodes (seeds
0..N-1) of the held-out personas through :func:`agents.evaluate.evaluate`, and the handbook
caregiver plays them on ``CoopGym/SitToStand-v0`` (the same model and people as the
unit-scaled ids; its observation is the one the handbook reads) as the reference.
"""

from __future__ import annotations

from typing import Any

REFERENCE_ENV_ID = "CoopGym/SitToStand-v0"


def held_out_report(
    run: dict[str, Any], agents: dict[str, tuple[Any, bool]], env_id: str, episodes: int
) -> dict[str, Any]:
    """``run`` with the scores of ``agents`` (label: (agent, deterministic)) and the handbook's."""
    from agents.evaluate import evaluate

    scores = {"handbook": evaluate("handbook", REFERENCE_ENV_ID, "test", episodes, 0).summary()}
    for label, (agent, deterministic) in agents.items():
        scores[label] = evaluate(agent, env_id, "test", episodes, 0, deterministic=deterministic).summary()
    for label, score in scores.items():
        print(f"{label:>12}: success {score['success_rate']:.3f}, unsafe {score['unsafe_rate']:.3f}")
    return {**run, "env_id": env_id, "episodes": episodes, "reference_env_id": REFERENCE_ENV_ID, "scores": scores}
