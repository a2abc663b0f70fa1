"""Score candidate hard levels: the hard level's knobs changed, every baseline searched on each.

A level's headroom is measured against the best blind policy *for that level*
(:class:`coop_gym.model.difficulty.Difficulty` holds the knobs), so each candidate gets the
baselines' searches of its own, on the TRAINING personas:

* the widened blind search (:func:`agents.tune.baselines.search_blind`, ``--final-episodes``
  per finalist);
* the prober's grid (:func:`agents.tune.baselines.tune` over ``prober_grid``, ``--prober-episodes``
  per setting), beside the prober at the shipped level's settings (printed, not counted);

then scores the blind winner, both probers and the belief caregiver (its shipped settings, its
filter at the candidate level) on ``--held-out-episodes`` seeded episodes of the held-out
personas (seeds 0..N-1, the same for every row), and prints one line per agent (the oracle,
who sees ``xi``, too) and the candidate's value of reading the mind (oracle - blind) and the
best reader's gain over blind. A candidate is the shipped level with some knobs replaced, as JSON::

    python scripts/level_candidates.py --knobs '{}' '{"pushed_lapse_rate_per_s": 2.0}'

The candidate replaces ``DIFFICULTIES["hard"]`` in this process only (every env made here with
``difficulty="hard"`` plays it); the registered ids are untouched.
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import tyro

if TYPE_CHECKING:
    from coop_gym.model.difficulty import Difficulty

ENV_ID = "CoopGym/SitToStandHard-v1"
UNCOUNTED = "prober at the shipped level's settings"
"""The row printed beside the others but not counted in the headroom (not chosen on the candidate)."""


@dataclass
class Args:
    """Command-line arguments; each field's docstring is its ``--help``."""

    knobs: list[str] = field(default_factory=lambda: ["{}"])
    """Candidates: JSON objects of ``Difficulty`` fields to replace on the shipped hard level."""
    final_episodes: int = 500
    """Training episodes per finalist of the blind search."""
    prober_episodes: int = 300
    """Training episodes per setting of the prober's grid."""
    held_out_episodes: int = 1000
    """Held-out episodes per agent."""


def candidate(knobs: dict[str, Any]) -> Difficulty:
    """The shipped hard level with ``knobs`` replaced (unknown field names raise ``TypeError``)."""
    from coop_gym.model.difficulty import DIFFICULTIES

    return dataclasses.replace(DIFFICULTIES["hard"], **knobs)


def score(knobs: dict[str, Any], args: Args) -> None:
    """Choose the baselines again on the candidate level and print their held-out scores."""
    from agents.caregivers.belief import BeliefCaregiver
    from agents.caregivers.scripted import BlindAgent, ProbingCaregiver
    from agents.evaluate import evaluate, headroom
    from agents.tune.baselines import describe, prober_grid, search_blind, tune
    from coop_gym.envs.contract import observation_features
    from coop_gym.model import difficulty

    shipped = difficulty.DIFFICULTIES["hard"]
    difficulty.DIFFICULTIES["hard"] = candidate(knobs)
    try:
        t0 = time.perf_counter()
        blind = search_blind(ENV_ID, None, final_episodes=args.final_episodes, log=lambda *_: None)[0][0]
        probers = tune(
            lambda s: ProbingCaregiver(settings=s), list(prober_grid()), ENV_ID, episodes=args.prober_episodes
        )
        # Named as agents.evaluate.headroom knows them: the value of reading the mind and the best
        # reader's gain come with their paired intervals. The prober at the shipped level's settings
        # is printed beside them, not counted (it was not chosen on this candidate).
        agents: dict[str, tuple[Any, dict[str, Any] | None]] = {
            "oracle": ("oracle", None),
            "blind": (BlindAgent(settings=blind), None),
            "prober": (ProbingCaregiver(settings=probers[0][0]), None),
            "belief": (BeliefCaregiver(observation_features("belief", "switching")), {"estimator": "switching"}),
            UNCOUNTED: (ProbingCaregiver(), None),
        }
        print(f"candidate {json.dumps(knobs)}: blind {describe(blind)}; prober {dataclasses.asdict(probers[0][0])}")
        results = []
        for name, (agent, env_kwargs) in agents.items():
            r = evaluate(agent, ENV_ID, "test", args.held_out_episodes, 0, env_kwargs=env_kwargs, name=name)
            lo, hi = r.interval("success")
            results.append(r)
            print(
                f"  {name:>38}: success {100 * r.success_rate:5.1f} % [{100 * lo:.1f}, {100 * hi:.1f}]  "
                f"unsafe {100 * r.unsafe_rate:.1f} %  premature {100 * r.premature_rate:.1f} %  "
                f"timeout {100 * r.timeout_rate:.1f} %"
            )
        room = headroom([r for r in results if r.agent != UNCOUNTED])
        for line in room.lines() if room is not None else ():
            print(f"  {line}")
        print(f"  ({time.perf_counter() - t0:.0f} s)", flush=True)
    finally:
        difficulty.DIFFICULTIES["hard"] = shipped


def main() -> None:
    """Score every candidate in turn."""
    args = tyro.cli(Args)
    for text in args.knobs:
        knobs = json.loads(text)
        if not isinstance(knobs, dict):
            raise SystemExit(f"--knobs: expected JSON objects of Difficulty fields, got {text!r}")
        try:
            candidate(knobs)  # a bad field fails here, before ten minutes of search
        except (TypeError, ValueError) as error:
            raise SystemExit(f"--knobs {text}: {error}") from None
        score(knobs, args)


if __name__ == "__main__":
    main()
