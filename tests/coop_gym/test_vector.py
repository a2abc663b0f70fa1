"""The natively batched vector env, and the compiled core it shares with the single env."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
import scipy.linalg
from gymnasium.utils.passive_env_checker import check_obs
from gymnasium.vector import AutoresetMode

import coop_gym
from coop_gym.envs.config import Outcome
from coop_gym.envs.kernels.report import REPORT, TERMINATES
from coop_gym.envs.vector import SitToStandVectorEnv
from coop_gym.model.dynamics import (
    PARAM_COLUMNS,
    STATE_COLUMNS,
    initial_state_row,
    pack_person,
    zoh_coefficients,
    zoh_coefficients_batch,
    zoh_matrices,
)
from coop_gym.model.params import PersonParams, Realism, Timing
from coop_gym.model.personas import PERSONAS, Persona, sample_person

ALL_IDS = sorted(coop_gym.ENV_IDS)
SHORT = {"timing": {"episode_s": 2.0}}  # 20-step episodes, so truncation happens in short tests
SHORT_STEPS = Timing(episode_s=2.0).max_episode_steps


def _actions(space: gym.Space[Any], rng: np.random.Generator, n: int, lift_p: float) -> Any:
    """A batch of ``n`` actions that lift with probability ``lift_p``."""
    lift = rng.random(n) < lift_p
    if isinstance(space, gym.spaces.Discrete):
        return rng.integers(0, 9, n) * 2 + lift
    if isinstance(space, gym.spaces.Box):
        a = rng.uniform(-1.0, 1.0, (n, 3)).astype(np.float32)
        a[:, 2] = np.where(lift, 1.0, -1.0)
        return a
    return np.column_stack([rng.integers(0, 3, n), rng.integers(0, 3, n), lift.astype(np.int64)])


def _env_info(infos: dict[str, Any], i: int) -> dict[str, Any]:
    """Env ``i``'s entries of Gymnasium vector infos (the keys whose mask is set)."""
    out: dict[str, Any] = {}
    for key, value in infos.items():
        if key.startswith("_") or key in ("final_obs", "final_info"):
            continue
        if not infos[f"_{key}"][i]:
            continue
        out[key] = _env_info(value, i) if isinstance(value, dict) else value[i]
    return out


def _assert_same_info(vector_info: dict[str, Any], single: dict[str, Any], personas: tuple[Persona, ...]) -> None:
    for key, expected in single.items():
        got = vector_info[key]
        if isinstance(expected, dict):
            assert got == expected, key
        elif isinstance(expected, np.ndarray):
            assert np.array_equal(got, expected), key
        else:
            assert got == expected and type(got.item() if hasattr(got, "item") else got) is type(expected), key
    # The extra numeric keys agree with the labels.
    assert personas[vector_info["persona_index"]].name == single["persona"]
    assert Outcome(vector_info["outcome_code"]).label == single["outcome"]


def _run_against_singles(env_id: str, mode: AutoresetMode, n: int, steps: int, seed: int, **kwargs: Any) -> int:
    """Step a vector env and n single envs side by side; returns how many episodes ended."""
    venv = gym.make_vec(env_id, num_envs=n, autoreset_mode=mode, **kwargs)
    limit = kwargs.get("max_episode_steps", coop_gym.Timing().max_episode_steps)
    singles = [
        gym.make(env_id, max_episode_steps=limit, **{k: v for k, v in kwargs.items() if k != "max_episode_steps"})
        for _ in range(n)
    ]
    personas = venv.unwrapped.personas
    vobs, vinfos = venv.reset(seed=seed)
    for i, env in enumerate(singles):
        obs, info = env.reset(seed=seed + i)
        assert np.array_equal(vobs[i], obs)
        _assert_same_info(_env_info(vinfos, i), info, personas)
    rng = np.random.default_rng(seed)
    pending = np.zeros(n, dtype=bool)
    ended = 0
    for _ in range(steps):
        actions = _actions(venv.single_action_space, rng, n, lift_p=0.06)
        vobs, vrew, vterm, vtrunc, vinfos = venv.step(actions)
        for i, env in enumerate(singles):
            if mode == AutoresetMode.NEXT_STEP and pending[i]:
                (obs, info), reward, terminated, truncated = env.reset(), 0.0, False, False
            else:
                obs, reward, terminated, truncated, info = env.step(actions[i])
                if terminated or truncated:
                    ended += 1
                if mode == AutoresetMode.SAME_STEP and (terminated or truncated):
                    assert vinfos["_final_obs"][i] and vinfos["_final_info"][i]
                    assert np.array_equal(vinfos["final_obs"][i], obs)
                    _assert_same_info(_env_info(vinfos["final_info"], i), info, personas)
                    obs, info = env.reset()
                elif mode == AutoresetMode.SAME_STEP and "_final_obs" in vinfos:
                    assert not vinfos["_final_obs"][i] and vinfos["final_obs"][i] is None
            assert np.array_equal(vobs[i], obs)
            assert vrew[i] == reward and vterm[i] == terminated and vtrunc[i] == truncated
            _assert_same_info(_env_info(vinfos, i), info, personas)
        pending = vterm | vtrunc
    return ended


@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
@pytest.mark.parametrize("env_id", ["CoopGym/SitToStand-v0", "CoopGym/SitToStandDiscrete-v0"])
def test_vector_env_equals_single_envs_seeded_s_plus_i_across_autoresets(env_id: str, mode: AutoresetMode) -> None:
    ended = _run_against_singles(env_id, mode, n=3, steps=70, seed=21, max_episode_steps=SHORT_STEPS, **SHORT)
    assert ended >= 8  # lifts and truncations both happened, so autoresets were exercised


@pytest.mark.parametrize(
    "env_id", ["CoopGym/SitToStandContinuous-v0", "CoopGym/SitToStandMM-v0", "CoopGym/SitToStandIMM-v0"]
)
def test_vector_env_equals_single_envs_for_other_actions_and_estimators(env_id: str) -> None:
    ended = _run_against_singles(env_id, AutoresetMode.SAME_STEP, n=2, steps=40, seed=5, **SHORT)
    assert ended >= 2


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_make_vec_builds_the_batched_env_with_consistent_spaces_for_every_id(env_id: str) -> None:
    envs = gym.make_vec(env_id, num_envs=4)
    single = gym.make(env_id)
    base = envs.unwrapped
    assert isinstance(base, SitToStandVectorEnv)
    assert base.max_episode_steps == single.spec.max_episode_steps
    assert isinstance(envs.metadata["autoreset_mode"], AutoresetMode)
    assert envs.single_observation_space == single.observation_space
    assert envs.single_action_space == single.action_space
    assert base.features == single.unwrapped.features
    obs, infos = envs.reset(seed=0)
    assert obs.shape == (4, *single.observation_space.shape) and obs.dtype == np.float32
    assert envs.observation_space.contains(obs)
    envs.action_space.seed(0)
    for _ in range(5):
        obs, rewards, terminated, truncated, infos = envs.step(envs.action_space.sample())
        for row in obs:
            check_obs(row, envs.single_observation_space, "step")
        assert envs.observation_space.contains(obs)
        assert rewards.shape == (4,) and rewards.dtype == np.float64
        assert terminated.dtype == np.bool_ and truncated.dtype == np.bool_ and terminated.shape == (4,)
        for key in ("true_xi", "true_x_m", "outcome", "outcome_code", "judgment", "persona_index", "reward_terms"):
            assert infos[f"_{key}"].all()
        assert infos["true_xi"].dtype == np.int64 and infos["outcome_code"].dtype == np.int64
        assert {k for k in infos["reward_terms"] if not k.startswith("_")} == set(coop_gym.REWARD_TERMS)
        total = sum(infos["reward_terms"][name] for name in coop_gym.REWARD_TERMS)
        assert np.allclose(total, rewards)
    envs.close()
    envs.close()  # twice is fine


def test_returned_arrays_are_fresh_each_call() -> None:
    envs = SitToStandVectorEnv(num_envs=3)
    obs0, _ = envs.reset(seed=0)
    obs1, rew1, term1, _, info1 = envs.step(np.zeros((3, 3), dtype=np.int64))
    obs2, rew2, term2, _, info2 = envs.step(np.zeros((3, 3), dtype=np.int64))
    pairs = ((obs0, obs1), (obs1, obs2), (rew1, rew2), (term1, term2), (info1["true_x_m"], info2["true_x_m"]))
    for a, b in pairs:
        assert not np.shares_memory(a, b)
    assert not np.shares_memory(obs2, envs.core.obs)
    kept = obs1.copy()
    envs.step(np.zeros((3, 3), dtype=np.int64))
    assert np.array_equal(obs1, kept)


def test_reset_mask_resets_only_masked_envs_with_their_own_seeds() -> None:
    envs = gym.make_vec("CoopGym/SitToStand-v0", num_envs=4, autoreset_mode=AutoresetMode.DISABLED)
    envs.reset(seed=100)
    for _ in range(3):
        obs, *_ = envs.step(np.tile([1, 2, 0], (4, 1)))
    state_before = envs.unwrapped.core.state.copy()
    mask = np.array([False, True, False, True])
    new_obs, infos = envs.reset(seed=[None, 7, None, 8], options={"reset_mask": mask})
    # Unmasked envs are untouched: same observation, same state.
    assert np.array_equal(new_obs[~mask], obs[~mask])
    assert np.array_equal(envs.unwrapped.core.state[~mask], state_before[~mask])
    assert infos["_true_xi"].tolist() == mask.tolist() and infos["_reward_terms"].tolist() == mask.tolist()
    assert infos["persona"][0] is None and infos["true_x_m"][0] == 0.0  # Gymnasium's empty entries
    # Masked envs start the episode a single env seeded 7 / 8 starts.
    for i, seed in ((1, 7), (3, 8)):
        single_obs, single_info = gym.make("CoopGym/SitToStand-v0").reset(seed=seed)
        assert np.array_equal(new_obs[i], single_obs)
        assert infos["persona"][i] == single_info["persona"] and infos["true_x_m"][i] == single_info["true_x_m"]
    # Options apply to every env reset.
    obs, infos = envs.reset(options={"reset_mask": mask, "persona": "anxious", "initial_xi": -1})
    assert infos["persona"][mask].tolist() == ["anxious", "anxious"] and infos["true_xi"][mask].tolist() == [-1, -1]


def test_disabled_autoreset_refuses_to_step_finished_envs_until_they_are_reset() -> None:
    envs = SitToStandVectorEnv(num_envs=3, autoreset_mode="Disabled")
    envs.reset(seed=0)
    _, _, terminated, _, _ = envs.step(np.array([[0, 0, 1], [0, 0, 0], [0, 0, 0]]))
    assert terminated.tolist() == [True, False, False]
    with pytest.raises(RuntimeError, match=r"envs \[0\] finished"):
        envs.step(np.zeros((3, 3), dtype=np.int64))
    envs.reset(options={"reset_mask": np.array([True, False, False])})
    _, _, terminated, truncated, _ = envs.step(np.zeros((3, 3), dtype=np.int64))
    assert not terminated.any() and not truncated.any()


def test_next_step_autoreset_returns_the_reset_on_the_following_step() -> None:
    envs = SitToStandVectorEnv(num_envs=2)
    envs.reset(seed=3)
    _, rewards, terminated, _, infos = envs.step(np.array([[0, 0, 1], [1, 0, 0]]))
    assert terminated.tolist() == [True, False] and rewards[0] == -coop_gym.RewardWeights().unsafe
    assert infos["outcome"][0] == "unsafe"
    _, rewards, terminated, truncated, infos = envs.step(np.array([[2, 2, 0], [1, 0, 0]]))
    assert rewards[0] == 0.0 and not terminated[0] and not truncated[0]
    assert infos["outcome"][0] == "none" and infos["elapsed_s"][0] == 0.0 and infos["push_force_n"][0] == 0.0
    assert infos["elapsed_s"][1] == pytest.approx(0.2)


def test_truncation_happens_inside_the_vector_env_at_max_episode_steps() -> None:
    envs = SitToStandVectorEnv(num_envs=2, max_episode_steps=5, autoreset_mode=AutoresetMode.SAME_STEP)
    envs.reset(seed=0)
    for step in range(1, 6):
        _, _, terminated, truncated, infos = envs.step(np.zeros((2, 3), dtype=np.int64))
        assert truncated.tolist() == [step == 5] * 2 and not terminated.any()
    assert infos["_final_obs"].all() and infos["elapsed_s"].tolist() == [0.0, 0.0]
    assert infos["final_info"]["elapsed_s"].tolist() == pytest.approx([0.5, 0.5])


def test_seeds_make_episodes_reproducible_and_distinct() -> None:
    def first_obs(seed: int | list[int]) -> np.ndarray:
        envs = SitToStandVectorEnv(num_envs=3)
        envs.reset(seed=seed)
        return envs.step(np.tile([1, 2, 0], (3, 1)))[0]

    a, b, c = first_obs(5), first_obs(5), first_obs([5, 6, 7])
    assert np.array_equal(a, b) and np.array_equal(a, c)
    assert not np.array_equal(a[0], a[1])
    assert not np.array_equal(first_obs(6)[0], a[0])


@pytest.mark.parametrize(
    ("kwargs", "error", "message"),
    [
        ({"num_envs": 0}, ValueError, "num_envs"),
        ({"num_envs": 2.5}, ValueError, "num_envs"),
        ({"num_envs": 2, "max_episode_steps": 0}, ValueError, "max_episode_steps"),
        ({"num_envs": 2, "autoreset_mode": "sometimes"}, ValueError, "autoreset_mode"),
        ({"num_envs": 2, "personas": "grumpy"}, ValueError, "unknown persona 'grumpy'"),
        ({"num_envs": 2, "render_mode": "ascii"}, ValueError, "render_mode"),
    ],
)
def test_bad_constructor_arguments_raise_naming_them(kwargs: dict[str, Any], error: type, message: str) -> None:
    with pytest.raises(error, match=message):
        SitToStandVectorEnv(**kwargs)


@pytest.mark.parametrize(
    ("action", "message"),
    [
        (np.zeros((3, 3)), "shape"),
        (np.array([[0, 0, np.nan], [0, 0, 0]]), "NaN"),
        (np.array([[0, 3, 0], [0, 0, 0]]), "verbal 0..2"),
        (np.array([[0.5, 0, 0], [0, 0, 0]]), "integers"),
        ("lift", "numeric"),
    ],
)
def test_bad_actions_raise_and_change_nothing(action: Any, message: str) -> None:
    envs, clean = SitToStandVectorEnv(num_envs=2), SitToStandVectorEnv(num_envs=2)
    envs.reset(seed=1)
    clean.reset(seed=1)
    with pytest.raises(ValueError, match=message):
        envs.step(action)
    good = np.array([[1, 2, 0], [2, 1, 0]])
    assert np.array_equal(envs.step(good)[0], clean.step(good)[0])


def test_bad_reset_arguments_raise_naming_them() -> None:
    envs = SitToStandVectorEnv(num_envs=2)
    with pytest.raises(RuntimeError, match="before reset"):
        envs.step(np.zeros((2, 3), dtype=np.int64))
    with pytest.raises(TypeError, match="numpy array"):
        envs.reset(options={"reset_mask": [True, False]})
    with pytest.raises(TypeError, match="dtype bool"):
        envs.reset(options={"reset_mask": np.array([1, 0])})
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        envs.reset(options={"reset_mask": np.array([True])})
    with pytest.raises(ValueError, match="at least one"):
        envs.reset(options={"reset_mask": np.array([False, False])})
    with pytest.raises(ValueError, match="2 entries"):
        envs.reset(seed=[1, 2, 3])
    with pytest.raises(ValueError, match="non-negative"):
        envs.reset(seed=[1, -2])
    with pytest.raises(ValueError, match="unknown reset option"):
        envs.reset(options={"xi": 1})
    options = {"reset_mask": np.array([True, True])}
    envs.reset(seed=0, options=options)
    assert "reset_mask" in options  # the caller's dict is not consumed


def test_rgb_render_shows_env_zero_as_the_single_env_draws_it() -> None:
    envs = SitToStandVectorEnv(num_envs=2, render_mode="rgb_array")
    single = coop_gym.SitToStandEnv(render_mode="rgb_array")
    envs.reset(seed=4)
    single.reset(seed=4)
    assert np.array_equal(envs.render(), single.render())
    envs.step(np.array([[2, 2, 0], [0, 0, 0]]))
    single.step(np.array([2, 2, 0]))
    frame = envs.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert np.array_equal(frame, single.render())
    envs.close()
    single.close()


# --- the compiled core ------------------------------------------------------------


@pytest.mark.parametrize("realism", [Realism(), Realism.off()])
def test_fast_reset_builds_the_person_sample_person_and_pack_person_build(realism: Realism) -> None:
    personas = tuple(PERSONAS.values())
    timing = Timing()
    env = coop_gym.SitToStandEnv(personas=list(PERSONAS), realism=realism)
    core = env.core
    for seed in range(40):
        env.reset(seed=seed)
        # Replay the documented draws on a generator seeded the same way.
        rng = np.random.default_rng(seed)
        k = int(rng.integers(len(personas)))
        person = sample_person(personas[k], rng, vary=realism.person_variation).with_realism(realism)
        coop = person.cooperativeness
        u = rng.random()
        xi = -1 if u < coop.initial_p_uncooperative else (1 if u > 1.0 - coop.initial_p_cooperative else 0)
        x0 = float(rng.normal(0.0, 0.005))
        assert core.persona_index[0] == k
        assert np.array_equal(core.params[0], pack_person(person, timing))
        assert np.array_equal(core.person[0], initial_state_row(xi, x0))
        assert np.array_equal(core.P[0], np.diag(np.diag(core.P[0])))
    assert len(PARAM_COLUMNS) == core.params.shape[1] and len(STATE_COLUMNS) == core.person.shape[1]


def test_a_different_variation_std_per_persona_is_respected() -> None:
    wide = Persona("wide", "varies a lot", PersonParams(), 0.5)
    narrow = Persona("narrow", "varies little", PersonParams(), 0.01)
    env = coop_gym.SitToStandEnv(personas=[wide, narrow])
    for seed in range(10):
        env.reset(seed=seed)
        rng = np.random.default_rng(seed)
        k = int(rng.integers(2))
        person = sample_person((wide, narrow)[k], rng)
        assert np.array_equal(env.core.params[0], pack_person(person, Timing()))


def test_zero_order_hold_agrees_with_scipy_expm() -> None:
    rng = np.random.default_rng(0)
    for _ in range(300):
        damping, gain, dt = rng.uniform(0.1, 60.0), rng.uniform(0.1, 400.0), rng.choice([0.005, 0.02, 0.1])
        block = np.array([[0.0, 1.0, 0.0], [-gain, -damping, 1.0], [0.0, 0.0, 0.0]]) * dt
        expected = scipy.linalg.expm(block)[:2]
        got = zoh_matrices(damping, gain, dt)
        assert np.max(np.abs(got - expected)) <= 1e-13 * np.max(np.abs(expected))
    assert all(np.isnan(zoh_coefficients(float("inf"), 9.0, 0.02)))  # terminates on bad input


def test_the_batched_zero_order_hold_equals_the_scalar_one_bit_for_bit() -> None:
    # Resets compute the ZOH of all their people in one batch; the person must stay the one
    # pack_person builds, to the last bit, whatever the gains (squarings from 0 to the cap).
    rng = np.random.default_rng(1)
    m = 2000
    damping = np.concatenate([rng.uniform(0.1, 60.0, m), [np.inf, np.nan, 0.0, 1e300]])
    gain = np.concatenate([rng.uniform(0.1, 400.0, m), [9.0, 9.0, 0.0, 1e300]])
    dt = np.concatenate([rng.choice([0.005, 0.02, 0.1, 1.0], m), [0.02, 0.02, 0.02, 0.02]])
    out = np.empty((len(dt), 6))
    zoh_coefficients_batch(damping, gain, dt, out)
    want = np.array([zoh_coefficients(*args) for args in zip(damping, gain, dt, strict=True)])
    assert np.array_equal(out.view(np.uint64), want.view(np.uint64))


def test_step_before_reset_and_unknown_generator_raise_in_the_core() -> None:
    env = coop_gym.SitToStandEnv()
    core = env.core
    with pytest.raises(RuntimeError, match="stepped before it was reset"):
        core.step_commands(core.cmd)
    with pytest.raises(RuntimeError, match="no random generator"):
        core.reset_envs(np.array([0]))


def test_core_step_arrays_stay_consistent_with_the_info() -> None:
    env = coop_gym.SitToStandEnv()
    env.reset(seed=2)
    _, reward, terminated, _, info = env.step(np.array([0, 0, 1]))
    report = env.core.report[0]
    assert report[REPORT.outcome] == Outcome.UNSAFE and TERMINATES[int(report[REPORT.outcome])] and terminated
    assert report[REPORT.reward] == reward and report[REPORT.push_force_n] == 0.0
    assert info["outcome"] == "unsafe"
