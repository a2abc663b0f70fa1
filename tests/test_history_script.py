"""scripts/history.py: the body posterior carried from one episode of a person to the next."""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np

from agents.caregivers.belief import BeliefCaregiver
from coop_gym.envs.switching import SwitchingOptions, hypothesis_people
from coop_gym.model.params import PersonParams
from coop_gym.model.personas import VARIED_PARAMETERS

ROOT = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("history_script", ROOT / "scripts" / "history.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["history_script"] = module  # dataclasses resolve the module by name
    spec.loader.exec_module(module)
    return module


def test_the_first_episode_is_the_same_and_only_later_ones_meet_the_carried_bank() -> None:
    history = _script()
    args = history.Args(residents=1, episodes=2)
    nominal, nominal_known = history.meet("frail", 3, "nominal", args)
    carried, carried_known = history.meet("frail", 3, "carried", args)
    assert nominal[0] == carried[0]  # same person, seed and bank until the first carry-over
    assert np.isnan(nominal_known).all() and 1.0 <= carried_known[0] <= SwitchingOptions().hypotheses
    assert np.all(carried_known[1:] > 0)  # posterior means over the person's gains


def test_the_carried_bank_is_drawn_from_the_posterior_over_the_hypotheses() -> None:
    history = _script()
    env = gym.make(history.ENV_ID, estimator="switching", personas=["frail"])
    agent = BeliefCaregiver.for_env(env)
    history._play(env, agent, 5)
    pf = env.unwrapped.core.mm.filter
    before = pf.params[0].copy()
    posterior = pf.hypothesis_posterior()[0]
    assert posterior.shape == (len(before),) and abs(posterior.sum() - 1.0) < 1e-12
    alive = set(np.flatnonzero(posterior > 1e-12).tolist())
    bank, known = history._carry_over(
        env.unwrapped.core, hypothesis_people(SwitchingOptions()), np.random.default_rng(0), 0.0
    )
    after = pf.params[0]
    # Every new row is one of the old bank's, and only hypotheses that held weight are drawn.
    drawn = {int(np.flatnonzero((before == row).all(axis=1))[0]) for row in after}
    assert drawn <= alive and len(drawn) < len(before)
    assert len(bank) == len(before) and 1.0 <= known[0] <= len(before)
    env.close()


def test_the_recorded_episodes_weigh_the_persons_own_body_above_the_typical_one() -> None:
    history = _script()
    body = history.sample_person(history.PERSONAS["frail"], np.random.default_rng(1))
    person = history.Persona("frail", "one resident", body, variation_relative_std=0.0)
    env = gym.make(history.ENV_ID, estimator="switching", personas=[person])
    core = env.unwrapped.core
    core.mm = recorder = history._Recorder(core.mm)
    agent = BeliefCaregiver.for_env(env)
    for seed in (11, 12):
        history._play(env, agent, seed)
    episodes = recorder.recorded()
    assert len(episodes) == 2 and all(inputs.shape[0] == 3 and inputs.shape[1] > 10 for _, inputs in episodes)
    own = np.log([getattr(getattr(body, level), name) for level, name, _ in history.BODY])
    typical = np.log([getattr(getattr(history.PERSONAS["typical"].params, lv), n) for lv, n, _ in history.BODY])
    weights = history._log_weights(core, episodes, np.stack([own, typical]), seed=0)
    assert weights[0] > weights[1]
    env.close()


def test_a_roughened_bank_scatters_the_varied_gains_of_drawn_bodies_only() -> None:
    history = _script()
    env = gym.make(history.ENV_ID, estimator="switching", personas=["frail"])
    history._play(env, BeliefCaregiver.for_env(env), 5)
    old = hypothesis_people(SwitchingOptions())
    bank, _ = history._carry_over(env.unwrapped.core, old, np.random.default_rng(0), 0.2)
    varied = [(level, name) for level, names in VARIED_PARAMETERS.items() for name in names]

    def rest(person: PersonParams) -> PersonParams:  # the person with every varied gain set to 1
        levels = {level: dataclasses.replace(getattr(person, level), **dict.fromkeys(names, 1.0))
                  for level, names in VARIED_PARAMETERS.items()}  # fmt: skip
        return dataclasses.replace(person, **levels)

    def logs(body: PersonParams, source: PersonParams) -> np.ndarray:
        return np.log([getattr(getattr(body, lv), n) / getattr(getattr(source, lv), n) for lv, n in varied])

    for body in bank:
        # Drawn from a body of the old bank (the nearest): the same but for its varied gains,
        # each scaled by a log-normal factor of std 0.2 (within 5 std), none left as it was.
        nearest = min((logs(body, o) for o in old if rest(o) == rest(body)), key=lambda d: float(d @ d))
        assert np.all(np.abs(nearest) < 1.0) and np.all(nearest != 0.0)
    env.close()
