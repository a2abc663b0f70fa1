"""A caregiver who has met the person before: what their history is worth to the filter.

The belief caregiver's filter weighs a bank of body hypotheses drawn around the training
personas (:func:`coop_gym.envs.switching.hypothesis_people`); with the person's TRUE
parameters it reads the held-out people better (docs/HARD_LEVEL.md). A caregiver who meets
the same person again could learn their body from the episodes before. Here each held-out
persona gives ``--residents`` people (each drawn around the persona once, then met in
``--episodes`` episodes in a row: the same body, a new mind each episode), played by the
belief caregiver on the hard level (its settings chosen for the level, with the push limit
``--recruit-until-m``) with its filter in one of four modes:

* ``nominal``: every episode starts from the default bank (what the env does);
* ``carried``: after each episode the bank is drawn again from the filter's posterior over its
  hypotheses (the particles' weights summed per hypothesis), each drawn body's varied gains
  scattered by a log-normal factor of std ``--roughen`` as a persona's people are
  (:func:`coop_gym.model.personas.sample_person`; 0: copied as they are);
* ``identified``: after each episode the body is identified from every episode so far
  (:func:`identify_body`: the filter run again over the recorded cues and readings, a search
  over bodies that keeps the ones it weighs highest), and the next bank is drawn around it;
* ``true``: the filter is given the person's true parameters (the bound).

The caregiver uses nothing it would not have: the cues it gave and the shoulder readings.
It prints, per persona, mode and episode in the row, the rates of each outcome (success with
its 95 % Wilson interval), and for ``carried`` and ``identified`` what the filter knew of the
body after the first episode: each of :data:`GAINS` over the person's own (the median and the
10th-90th percentiles over the people), for ``carried`` also how many of the bank's 128
hypotheses its posterior keeps (the effective number ``1 / sum p_h^2``). It reaches into the
env's filter (``env.unwrapped.core.mm``), so it is a measurement, not an API::

    python scripts/history.py                       # every mode, 250 people a persona, 4 episodes each
    python scripts/history.py --modes carried --roughen 0.2 --personas frail

Episode ``k`` of resident ``r`` is seeded ``20_000 + 97 r + k``; resident ``r``'s body is drawn
from ``numpy.random.default_rng(10_000 + r)``: every mode plays the same people and seeds.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import tyro
from numpy.typing import NDArray

import coop_gym  # noqa: F401  (registers the ids)
from agents.base import Agent, level_of
from agents.caregivers.belief import BeliefCaregiver
from agents.evaluate.results import wilson_interval
from coop_gym.envs.switching import SwitchingOptions, hypothesis_people, pack_at_level, switching_filter
from coop_gym.model.difficulty import get_difficulty
from coop_gym.model.dynamics import PERSON
from coop_gym.model.params import PersonParams
from coop_gym.model.personas import PERSONAS, TEST_PERSONAS, Persona, sample_person

ENV_ID = "CoopGym/SitToStandHard-v1"
MODES = ("nominal", "carried", "identified", "true")
OUTCOMES = ("success", "unsafe", "premature", "timeout")
GAINS = ("damping_rate_per_s", "voluntary_gain_per_s2", "push_compliance_m_per_s2_n")
"""The body's gains whose estimate is printed beside the person's."""

BODY = (
    ("biomechanics", "damping_rate_per_s", 0.7),
    ("biomechanics", "voluntary_gain_per_s2", 0.7),
    ("biomechanics", "push_compliance_m_per_s2_n", 1.2),
    ("biomechanics", "stiffness_factor_unresponsive", 0.4),
    ("intention", "push_gain_m_per_s_n", 0.7),
    ("intention", "verbal_gain_m_per_s", 0.7),
)
"""What :func:`identify_body` searches, with the std of the log of each in its first round: the
default bank's spread (0.7 on a gain's log; its push-compliance range of 8 is a log-uniform of
std ``log(8) / sqrt(3) = 1.2``), and a disengaged person's stiffening, which the bank holds at
the typical person's 0.5 (at most 1: no stiffening)."""
BODY_NAMES = tuple(name for _, name, _ in BODY)
"""The names of :data:`BODY`'s fields, in its order (the columns of a body's log values)."""
ROUNDS, CANDIDATES, ELITE, PARTICLES_EACH = 6, 128, 16, 8
"""The search: rounds, bodies a round, the best kept to draw the next round, particles a body."""


@dataclass
class Args:
    """Command-line arguments; each field's docstring is its ``--help``."""

    residents: int = 250
    """people drawn around each persona"""
    personas: tuple[str, ...] = TEST_PERSONAS
    """the personas the people are drawn around (default: the held-out ones)"""
    episodes: int = 4
    """episodes in a row with each person"""
    modes: tuple[str, ...] = ("nominal", "carried", "identified", "true")
    """filter modes to play: nominal, carried, identified, true"""
    roughen: float = 0.0
    """std of the log-normal factor on a carried body's varied gains"""
    recruit_until_m: float | None = 0.30
    """the belief caregiver's push limit (BeliefSettings.recruit_until_m; None: none)"""
    search_seed: int = 0
    """seed of the carried and identified modes' own draws (with the resident's number)"""


class _Recorder:
    """The env's filter, recording what it is given: each episode's first reading, its substeps' cues and readings."""

    def __init__(self, estimator: Any) -> None:
        self._estimator = estimator
        self.episodes: list[tuple[float, list[NDArray[np.float64]]]] = []

    def __getattr__(self, name: str) -> Any:
        return getattr(self._estimator, name)

    def reset(self, indices: NDArray[np.int64], first_position_m: NDArray[np.float64]) -> None:
        self.episodes.append((float(first_position_m[0]), []))
        self._estimator.reset(indices, first_position_m)

    def run(
        self, push: NDArray[np.float64], verbal: NDArray[np.float64], y: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        self.episodes[-1][1].append(np.stack([push[0], verbal[0], y[0]]))
        return self._estimator.run(push, verbal, y)

    def recorded(self) -> list[tuple[float, NDArray[np.float64]]]:
        """Each episode's first reading and its (3, T) push force, verbal cue and reading."""
        return [(first, np.concatenate(chunks, axis=1)) for first, chunks in self.episodes if chunks]


def _packed(core: Any, people: list[PersonParams]) -> NDArray[np.float64]:
    """(K, C) ``people`` at the hard level, with the env's realism and time base, as filter hypotheses."""
    level = get_difficulty("hard")
    return np.stack([pack_at_level(person, level, core.realism, core.timing) for person in people])


def _body(log_values: NDArray[np.float64]) -> PersonParams:
    """The typical person with the :data:`BODY` values ``exp(log_values)`` (each within its field's range)."""
    base = PERSONAS["typical"].params
    changed: dict[str, dict[str, float]] = {"biomechanics": {}, "intention": {}}
    for (level, name, _), log_value in zip(BODY, log_values, strict=True):
        low, high = type(getattr(base, level)).RANGES[name]
        changed[level][name] = min(max(math.exp(log_value), max(low, 1e-6)), high)
    return dataclasses.replace(
        base, **{level: dataclasses.replace(getattr(base, level), **v) for level, v in changed.items()}
    )


def _log_weights(core: Any, episodes: list, candidates: NDArray[np.float64], seed: int) -> NDArray[np.float64]:
    """How well each candidate body explains every recorded episode: the sum of the log of its posterior weight.

    The switching filter is run again over each episode's cues and readings with the candidates
    as its hypotheses (:data:`PARTICLES_EACH` particles each, all starting equal).
    """
    n = len(candidates)
    options = SwitchingOptions(n_particles=PARTICLES_EACH * n, hypotheses=n)
    rows = _packed(core, [_body(c) for c in candidates])
    pf = switching_filter(rows[None], core.timing, [np.random.default_rng(seed)], options)
    total = np.zeros(n)
    for e, (first, inputs) in enumerate(episodes):
        pf.reset([0], [first], seeds=[seed + e])
        pf.run(inputs[0][None], inputs[1][None], inputs[2][None])
        total += np.log(pf.hypothesis_posterior()[0] + 1e-300)
    return total


def identify_body(core: Any, episodes: list, rng: np.random.Generator) -> tuple[NDArray, NDArray]:
    """The body that explains the recorded episodes: a cross-entropy search over the logs of :data:`BODY`.

    Each round draws :data:`CANDIDATES` bodies from a normal over the logs (the first around the
    typical person with :data:`BODY`'s stds), weighs them by :func:`_log_weights`, and fits the
    next round's normal to the :data:`ELITE` best. Returns the last normal's mean and std.
    """
    mean = np.log([getattr(getattr(PERSONAS["typical"].params, level), name) for level, name, _ in BODY])
    std = np.array([s for _, _, s in BODY])
    for _ in range(ROUNDS):
        candidates = _draw(mean, std, CANDIDATES, rng)
        weights = _log_weights(core, episodes, candidates, int(rng.integers(2**31)))
        best = candidates[np.argsort(weights)[::-1][:ELITE]]
        mean, std = best.mean(axis=0), np.maximum(best.std(axis=0), 0.05)
    return mean, std


def _draw(mean: NDArray, std: NDArray, n: int, rng: np.random.Generator) -> NDArray[np.float64]:
    draws = mean + std * rng.standard_normal((n, len(mean)))
    stiffening = BODY_NAMES.index("stiffness_factor_unresponsive")
    draws[:, stiffening] = np.minimum(draws[:, stiffening], 0.0)  # a factor of at most 1
    return draws


def _identified(core: Any, recorder: _Recorder, rng: np.random.Generator) -> NDArray[np.float64]:
    """Identify the body from the episodes so far and give the filter a bank drawn around it."""
    mean, std = identify_body(core, recorder.recorded(), rng)
    bank = [_body(c) for c in _draw(mean, std, SwitchingOptions().hypotheses, rng)]
    recorder.filter.params[0] = _packed(core, bank)
    true_row = core.params[0]
    return np.array([math.nan, *(math.exp(mean[BODY_NAMES.index(g)]) / true_row[getattr(PERSON, g)] for g in GAINS)])


def _carry_over(core: Any, bank: list[PersonParams], rng: np.random.Generator, roughen: float) -> tuple:
    """Draw the next bank from the filter's posterior over ``bank``.

    Returns:
        The new bank, and what the posterior knew: its effective number of hypotheses and, for
        each of :data:`GAINS`, its posterior mean over the person's true value.
    """
    pf = core.mm.filter
    posterior = pf.hypothesis_posterior()[0]
    columns = [getattr(PERSON, name) for name in GAINS]
    factors = posterior @ pf.params[0][:, columns] / core.params[0, columns]
    picked = rng.choice(len(bank), size=len(bank), p=posterior)
    # Roughened: each body's varied gains scattered as a persona's people are.
    bank = [
        bank[h]
        if roughen == 0.0
        else sample_person(Persona("hypothesis", "", bank[h], variation_relative_std=roughen), rng)
        for h in picked
    ]
    pf.params[0] = _packed(core, bank)
    return bank, np.array([1.0 / float(np.sum(posterior**2)), *factors])


def _play(env: gym.Env, agent: Agent, seed: int) -> str:
    obs, _ = env.reset(seed=seed)
    state, start, done = None, np.array([True]), False
    while not done:
        action, state = agent.predict(obs[None], state, start)
        start = np.array([False])
        obs, _, terminated, truncated, info = env.step(action[0])
        done = terminated or truncated
    return str(info["outcome"])


def meet(persona: str, resident: int, mode: str, args: Args) -> tuple[list[str], NDArray[np.float64]]:
    """Play ``args.episodes`` episodes with one person: the outcomes, and what the filter knew after the first."""
    body = sample_person(PERSONAS[persona], np.random.default_rng(10_000 + resident))
    person = Persona(persona, "one resident", body, variation_relative_std=0.0)
    options = {"true_person": mode == "true"}
    env = gym.make(ENV_ID, estimator="switching", estimator_options=options, personas=[person])
    shipped = BeliefCaregiver.chosen_settings(level_of(env))
    settings = dataclasses.replace(shipped, recruit_until_m=args.recruit_until_m)
    agent = BeliefCaregiver.for_env(env, settings=settings)
    unwrapped: Any = env.unwrapped
    core = unwrapped.core
    core.mm = recorder = _Recorder(core.mm)
    bank, rng = hypothesis_people(SwitchingOptions()), np.random.default_rng(resident + 1_000_000 * args.search_seed)
    outcomes, first = [], np.full(1 + len(GAINS), np.nan)
    for k in range(args.episodes):
        outcomes.append(_play(env, agent, 20_000 + 97 * resident + k))
        known = first
        if mode == "carried":
            bank, known = _carry_over(core, bank, rng, args.roughen)
        elif mode == "identified" and k < args.episodes - 1:
            known = _identified(core, recorder, rng)
        first = known if k == 0 else first
    env.close()
    return outcomes, first


def main(args: Args) -> None:
    """Print each persona's and mode's outcome rates by episode in the row."""
    for mode in args.modes:
        if mode not in MODES:
            raise SystemExit(f"--modes: unknown mode {mode!r} ({', '.join(MODES)})")
    for persona in args.personas:
        if persona not in PERSONAS:
            raise SystemExit(f"--personas: unknown persona {persona!r} ({', '.join(PERSONAS)})")
    for persona in args.personas:
        for mode in args.modes:
            played = [meet(persona, r, mode, args) for r in range(args.residents)]
            for k in range(args.episodes):
                outcomes = [o[k] for o, _ in played]
                wins = outcomes.count("success")
                lo, hi = wilson_interval(wins, len(outcomes))
                rates = ", ".join(f"{o} {100 * outcomes.count(o) / len(outcomes):.1f}" for o in OUTCOMES[1:])
                print(
                    f"{persona:9s} {mode:10s} episode {k + 1}: success {100 * wins / len(outcomes):.1f} % "
                    f"[{100 * lo:.1f}, {100 * hi:.1f}], {rates}",
                    flush=True,
                )
            if mode in ("carried", "identified"):
                _print_known(persona, mode, np.array([first for _, first in played]))


def _print_known(persona: str, mode: str, known: NDArray[np.float64]) -> None:
    if mode == "carried":
        print(f"{persona:9s} {mode:10s} after episode 1: hypotheses kept {np.median(known[:, 0]):.1f} (median)")
    for j, name in enumerate(GAINS, start=1):
        lo, mid, hi = np.percentile(known[:, j], [10, 50, 90])
        print(f"{persona:9s} {mode:10s} after episode 1, its / the person's {name}: {mid:.2f} ({lo:.2f}-{hi:.2f})")


if __name__ == "__main__":
    main(tyro.cli(Args))
