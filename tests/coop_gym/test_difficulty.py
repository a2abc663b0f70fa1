"""The difficulty levels (-v1, the hard -v2): each realism knob does what its docstring says; the levels wire up."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import coop_gym  # noqa: F401
from coop_gym.model.difficulty import DIFFICULTIES, Difficulty, get_difficulty
from coop_gym.model.dynamics import simulate
from coop_gym.model.params import Cooperativeness, Intention, PersonParams, Realism
from coop_gym.model.personas import PERSONAS
from coop_gym.registration import LEVEL_ENV_IDS

QUIET = PersonParams().with_realism(dataclasses.replace(Realism.off(), saturation=True))


def _person(intention: dict | None = None, coop: dict | None = None) -> PersonParams:
    return dataclasses.replace(
        QUIET,
        intention=dataclasses.replace(QUIET.intention, **(intention or {})),
        cooperativeness=dataclasses.replace(QUIET.cooperativeness, **(coop or {})),
    )


def _push_then_release(person: PersonParams, push_s: float = 2.0, rest_s: float = 3.0) -> np.ndarray:
    n_push, n_rest = round(push_s / 0.02), round(rest_s / 0.02)
    push = np.r_[np.full(n_push, 10.0), np.zeros(n_rest)]
    traj = simulate(person, push, np.zeros_like(push), np.random.default_rng(0), initial_xi=0, hold_xi=True)
    return traj.true_state[:, 0]


def test_passive_follow_keeps_a_pushed_unresponsive_person_bent() -> None:
    x_off = _push_then_release(_person())
    x_on = _push_then_release(_person({"passive_follow_rate_per_s": 2.0}))
    peak_off, peak_on = x_off[:100].max(), x_on[:100].max()
    # The paper's model: the spring k1 (eta - x) pulls the released body back upright.
    assert x_off[-1] < 0.1 * peak_off
    # Passive follow: the intention followed the body, so the lean stays.
    assert x_on[-1] > 0.8 * peak_on
    assert peak_on > peak_off  # and a pushed passive person bends further


def test_spontaneous_lean_happens_when_idle_and_never_while_cued() -> None:
    person = _person({"spontaneous_lean_rate_per_s": 5.0, "spontaneous_lean_m": 0.3})
    n = 500
    # Spoken to for the first second, then left alone: a lean may come only after idle_after_s more.
    words = np.r_[np.ones(50), np.zeros(n - 50)]
    idle = simulate(person, np.zeros(n), words, np.random.default_rng(1), initial_xi=0, hold_xi=True)
    assert idle.true_state[:, 2].max() == pytest.approx(0.3)  # eta jumped to the spontaneous lean
    first = int(np.argmax(idle.true_state[:, 2] > 0.25))
    assert first * 0.02 >= 1.0 + QUIET.cooperativeness.idle_after_s
    talking = simulate(person, np.zeros(n), np.ones(n), np.random.default_rng(1), initial_xi=0, hold_xi=True)
    assert talking.true_state[:, 2].max() < 0.05  # xi = 0 does not answer words, and never idles


def _first_jump_targets(person: PersonParams, push_n: float, episodes: int = 400) -> dict[int, int]:
    counts: dict[int, int] = {}
    n = 250
    for seed in range(episodes):
        traj = simulate(person, np.full(n, push_n), np.zeros(n), np.random.default_rng(seed), initial_xi=1)
        xi = traj.true_state[:, 3]
        left = np.flatnonzero(xi != 1.0)
        if left.size:
            target = int(xi[left[0]])
            counts[target] = counts.get(target, 0) + 1
    return counts


def test_willingness_lapses_and_refuses_at_the_configured_rates() -> None:
    person = _person(coop={"lapse_rate_per_s": 1.0, "refusal_rate_per_s": 0.5, "drift_rate_per_s": 0.0})
    counts = _first_jump_targets(person, push_n=0.0)
    total = sum(counts.values())
    # 5 s at a total rate of 1.5/s: nearly everyone leaves +1, a third of them by refusing.
    assert total > 0.99 * 400
    assert counts.get(-1, 0) / total == pytest.approx(1 / 3, abs=0.08)
    assert set(counts) <= {0, -1}


def test_cooperation_is_absorbing_with_every_knob_off() -> None:
    counts = _first_jump_targets(_person(coop={"drift_rate_per_s": 0.0}), push_n=10.0, episodes=100)
    assert counts == {}


def test_pushed_lapse_acts_only_under_a_push() -> None:
    person = _person(coop={"pushed_lapse_rate_per_s": 2.0, "drift_rate_per_s": 0.0})
    assert _first_jump_targets(person, push_n=0.0, episodes=100) == {}
    pushed = _first_jump_targets(person, push_n=10.0, episodes=100)
    assert sum(pushed.values()) > 95 and set(pushed) == {0}


def test_knob_validation_names_the_field() -> None:
    with pytest.raises(ValueError, match=r"Intention\.passive_follow_rate_per_s"):
        Intention(passive_follow_rate_per_s=-1.0)
    with pytest.raises(ValueError, match=r"Cooperativeness\.lapse_rate_per_s"):
        Cooperativeness(lapse_rate_per_s=float("nan"))


def test_levels_apply_their_knobs_to_every_persona_and_price_safety() -> None:
    hard = get_difficulty("hard")
    person = hard.apply(PersonParams())
    assert person.intention.passive_follow_rate_per_s == hard.passive_follow_rate_per_s
    assert person.intention.max_m == hard.max_lean_m
    assert person.cooperativeness.pushed_lapse_rate_per_s == hard.pushed_lapse_rate_per_s
    assert person.biomechanics == PersonParams().biomechanics
    # easy is the paper's model: apply changes nothing.
    assert get_difficulty("easy").apply(PersonParams()) == PersonParams()
    env = gym.make("CoopGym/SitToStandHard-v1")
    assert env.unwrapped.config.reward.unsafe == hard.unsafe_penalty
    assert all(p.params.intention.spontaneous_lean_rate_per_s > 0 for p in env.unwrapped.personas)
    # An explicit reward wins over the level's.
    env = gym.make("CoopGym/SitToStandHard-v1", reward={"unsafe": 3.0})
    assert env.unwrapped.config.reward.unsafe == 3.0


def test_body_knobs_bend_an_unresponsive_person_further_and_are_off_by_default() -> None:
    # The two body knobs (tried by scripts/level_candidates.py, used by no shipped level).
    for level in DIFFICULTIES.values():
        assert level.apply(PersonParams()).biomechanics == PersonParams().biomechanics
    bendy = Difficulty("bendy", push_compliance_scale=2.0, stiffness_factor_unresponsive=1.0)
    body = bendy.apply(PersonParams()).biomechanics
    assert body.push_compliance_m_per_s2_n == 2.0 * PersonParams().biomechanics.push_compliance_m_per_s2_n
    assert body.stiffness_factor_unresponsive == 1.0
    plain, bent = (_push_then_release(dataclasses.replace(QUIET, biomechanics=b)) for b in (QUIET.biomechanics, body))
    assert bent.max() > 1.8 * plain.max() > 0.0  # twice the compliance (QUIET's realism does not stiffen)
    with pytest.raises(ValueError, match=r"Biomechanics\.push_compliance_m_per_s2_n"):
        Difficulty("broken", push_compliance_scale=-1.0).apply(PersonParams())


def test_unsafe_lift_never_pays_as_a_gamble() -> None:
    # A lift pays when P(success) * success > P(unsafe) * unsafe + P(premature) * premature. With
    # the -v0 weights a lift at P(success) = 0.9, P(unsafe) = 0.1 paid +0.7; at every -v1 level
    # it is a loss: a 10 % risk of an unsafe lift is never worth taking.
    v0 = gym.make("CoopGym/SitToStand-v0").unwrapped.config.reward
    assert 0.9 * v0.success - 0.1 * v0.unsafe > 0.0
    level_ids = {name: env_id for name, env_id in LEVEL_ENV_IDS.items() if name != "v0"}
    assert sorted(level_ids) == sorted(DIFFICULTIES)  # every level has its own id
    for name, env_id in level_ids.items():
        reward = gym.make(env_id).unwrapped.config.reward
        assert reward.unsafe == DIFFICULTIES[name].unsafe_penalty
        assert 0.9 * reward.success - 0.1 * reward.unsafe < 0.0


def test_hard_v2_is_the_hard_level_recruiting_slower_and_lapsing_less() -> None:
    hard, v2 = DIFFICULTIES["hard"], DIFFICULTIES["hard-v2"]
    changed = {"name", "guided_push_scale", "lapse_rate_per_s"}
    for field in dataclasses.fields(Difficulty):
        if field.name not in changed:
            assert getattr(v2, field.name) == getattr(hard, field.name), field.name
    assert v2.guided_push_scale < hard.guided_push_scale and v2.lapse_rate_per_s < hard.lapse_rate_per_s
    env = gym.make("CoopGym/SitToStandHard-v2")
    assert get_difficulty(env.unwrapped.difficulty) == v2
    for persona in env.unwrapped.personas:
        coop = persona.params.cooperativeness
        assert (
            coop.guided_push_rate_per_s == PERSONAS[persona.name].params.cooperativeness.guided_push_rate_per_s * 0.45
        )
        assert coop.lapse_rate_per_s == 0.05


def test_unknown_difficulty_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="unknown difficulty 'brutal'"):
        gym.make("CoopGym/SitToStand-v0", difficulty="brutal")
    assert isinstance(get_difficulty(DIFFICULTIES["medium"]), Difficulty)
