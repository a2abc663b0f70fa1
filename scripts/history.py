"""A caregiver who has met the person before: does the filter's own posterior over bodies carry over?

The belief caregiver's filter weighs a bank of body hypotheses drawn around the training
personas (:func:`coop_gym.envs.switching.hypothesis_people`); with the person's TRUE
parameters it reads the held-out people better (docs/HARD_LEVEL.md). A caregiver who meets
the same person again could learn their body from the episodes before. Here each held-out
persona gives ``--residents`` people (each drawn around the persona once, then met in
``--episodes`` episodes in a row: the same body, a new mind each episode), played by the
belief caregiver on the hard level with its filter in one of three modes:

* ``nominal``: every episode starts from the default bank (what the env does);
* ``carried``: after each episode the bank is drawn again from the filter's posterior over its
  hypotheses (the particles' weights summed per hypothesis), each drawn body's five varied
  gains scaled by a log-normal factor of std ``--roughen`` (0: copied as they are);
* ``true``: the filter is given the person's true parameters (the bound).

It prints, per persona, mode and episode in the row, the rates of each outcome (success with
its 95 % Wilson interval) and, for ``carried``, what the posterior over the default bank's 128
hypotheses knew after the first episode: how many it keeps (its effective number
``1 / sum p_h^2``, median) and its mean of each body gain over the person's own. It reaches into the env's
filter (``env.unwrapped.core.mm.filter``), so it is a measurement, not an API::

    python scripts/history.py --residents 250 --episodes 3 --recruit-until-m 0.30

Episode ``k`` of resident ``r`` is seeded ``20_000 + 97 r + k``; resident ``r``'s body is drawn
from ``numpy.random.default_rng(10_000 + r)``: every mode plays the same people and seeds.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import tyro
from numpy.typing import NDArray

import coop_gym  # noqa: F401  (registers the ids)
from agents.belief import BeliefCaregiver, BeliefSettings
from agents.evaluate.results import wilson_interval
from coop_gym.envs.switching import SwitchingOptions, hypothesis_people, pack_at_level
from coop_gym.model.difficulty import get_difficulty
from coop_gym.model.dynamics import PERSON
from coop_gym.model.params import PersonParams
from coop_gym.model.personas import PERSONAS, TEST_PERSONAS, VARIED_PARAMETERS, Persona, sample_person

ENV_ID = "CoopGym/SitToStandHard-v1"
OUTCOMES = ("success", "unsafe", "premature", "timeout")
GAINS = ("damping_rate_per_s", "voluntary_gain_per_s2", "push_compliance_m_per_s2_n")
"""The body's gains whose posterior is printed beside the person's."""


@dataclass
class Args:
    """Command-line arguments; each field's docstring is its ``--help``."""

    residents: int = 250
    """people drawn around each held-out persona"""
    episodes: int = 3
    """episodes in a row with each person"""
    modes: tuple[str, ...] = ("nominal", "carried", "true")
    """filter modes to play: nominal, carried, true"""
    roughen: float = 0.0
    """std of the log-normal factor on a carried body's varied gains"""
    recruit_until_m: float | None = 0.30
    """the belief caregiver's push limit (BeliefSettings.recruit_until_m; None: none)"""


def _roughened(person: PersonParams, rng: np.random.Generator, std: float) -> PersonParams:
    """``person`` with each varied gain of biomechanics and intention scaled by ``exp(std z)``."""
    levels = {}
    for level in ("biomechanics", "intention"):
        base = getattr(person, level)
        names = VARIED_PARAMETERS[level]
        levels[level] = dataclasses.replace(
            base, **{n: float(getattr(base, n) * math.exp(std * rng.standard_normal())) for n in names}
        )
    return dataclasses.replace(person, **levels)


def _play(env: gym.Env, agent: BeliefCaregiver, seed: int) -> str:
    obs, _ = env.reset(seed=seed)
    state, start, done = None, np.array([True]), False
    while not done:
        action, state = agent.predict(obs[None], state, start)
        start = np.array([False])
        obs, _, terminated, truncated, info = env.step(action[0])
        done = terminated or truncated
    return str(info["outcome"])


def _carry_over(env: gym.Env, bank: list[PersonParams], rng: np.random.Generator, roughen: float) -> tuple:
    """Draw the next bank from the filter's posterior over ``bank``.

    Returns:
        The new bank, and what the posterior knew: its effective number of hypotheses and, for
        each of :data:`GAINS`, its posterior mean over the person's true value (printed as the
        median and, in brackets, the 10th-90th percentiles over the people).
    """
    core = env.unwrapped.core
    pf = core.mm.filter
    log_w = pf.log_w[0]
    w = np.exp(log_w - log_w.max())
    posterior = np.bincount(pf.particles[0, :, -1].astype(int), weights=w / w.sum(), minlength=len(bank))
    columns = [getattr(PERSON, name) for name in GAINS]
    factors = posterior @ pf.params[0][:, columns] / core.params[0, columns]
    picked = rng.choice(len(bank), size=len(bank), p=posterior)
    bank = [bank[h] if roughen == 0.0 else _roughened(bank[h], rng, roughen) for h in picked]
    level = get_difficulty("hard")
    pf.params[0] = np.stack([pack_at_level(p, level, core.realism, core.timing) for p in bank])
    return bank, np.array([1.0 / float(np.sum(posterior**2)), *factors])


def meet(persona: str, resident: int, mode: str, args: Args) -> tuple[list[str], NDArray[np.float64]]:
    """Play ``args.episodes`` episodes with one person: the outcomes, and what the posterior knew after the first."""
    body = sample_person(PERSONAS[persona], np.random.default_rng(10_000 + resident))
    person = Persona(persona, "one resident", body, variation_relative_std=0.0)
    options = {"true_person": mode == "true"}
    env = gym.make(ENV_ID, estimator="switching", estimator_options=options, personas=[person])
    agent = BeliefCaregiver.for_env(env, settings=BeliefSettings(recruit_until_m=args.recruit_until_m))
    bank, rng = hypothesis_people(SwitchingOptions()), np.random.default_rng(resident)
    outcomes, first = [], np.full(1 + len(GAINS), np.nan)
    for k in range(args.episodes):
        outcomes.append(_play(env, agent, 20_000 + 97 * resident + k))
        if mode == "carried":
            bank, known = _carry_over(env, bank, rng, args.roughen)
            first = known if k == 0 else first
    env.close()
    return outcomes, first


def main(args: Args) -> None:
    """Print each persona's and mode's outcome rates by episode in the row."""
    for mode in args.modes:
        if mode not in ("nominal", "carried", "true"):
            raise SystemExit(f"--modes: unknown mode {mode!r} (nominal, carried, true)")
    for persona in TEST_PERSONAS:
        for mode in args.modes:
            played = [meet(persona, r, mode, args) for r in range(args.residents)]
            for k in range(args.episodes):
                outcomes = [o[k] for o, _ in played]
                wins = outcomes.count("success")
                lo, hi = wilson_interval(wins, len(outcomes))
                rates = ", ".join(f"{o} {100 * outcomes.count(o) / len(outcomes):.1f}" for o in OUTCOMES[1:])
                print(
                    f"{persona:9s} {mode:8s} episode {k + 1}: success {100 * wins / len(outcomes):.1f} % "
                    f"[{100 * lo:.1f}, {100 * hi:.1f}], {rates}",
                    flush=True,
                )
            if mode == "carried":
                known = np.array([first for _, first in played])
                print(f"{persona:9s} carried  after episode 1: hypotheses kept {np.median(known[:, 0]):.1f} (median)")
                for j, name in enumerate(GAINS, start=1):
                    lo, mid, hi = np.percentile(known[:, j], [10, 50, 90])
                    print(f"{persona:9s} carried    posterior mean / true {name}: {mid:.2f} ({lo:.2f}-{hi:.2f})")


if __name__ == "__main__":
    main(tyro.cli(Args))
