"""The client options of the env contract: ``observation_scale="unit"`` and ``info_mode="numeric"``."""

from __future__ import annotations

import pickle
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from gymnasium.vector import AutoresetMode

import coop_gym
from agents.caregivers.scripted import HandbookCaregiver
from coop_gym.envs.contract import (
    FEATURE_SCALES,
    FEATURES,
    NUMERIC_INFO_KEYS,
    observation_features,
    observation_scales,
    unit_observation_space,
)

UNIT_IDS = sorted(i for i, kwargs in coop_gym.ENV_IDS.items() if kwargs.get("observation_scale") == "unit")


def _physical_twin(env_id: str) -> dict[str, Any]:
    """The keywords of a unit id without its scaling: the physical env it scales."""
    return {k: v for k, v in coop_gym.ENV_IDS[env_id].items() if k != "observation_scale"}


def test_unit_ids_scale_the_paper_model_and_each_difficulty_level() -> None:
    assert UNIT_IDS == sorted(
        [
            "CoopGym/SitToStandUnit-v0",
            "CoopGym/SitToStandDiscreteUnit-v0",
            "CoopGym/SitToStandEasyUnit-v1",
            "CoopGym/SitToStandMediumUnit-v1",
            "CoopGym/SitToStandHardUnit-v1",
            "CoopGym/SitToStandHardDiscreteUnit-v1",
            "CoopGym/SitToStandHardHeldOutUnit-v1",
            "CoopGym/SitToStandHardUnit-v2",
            "CoopGym/SitToStandHardDiscreteUnit-v2",
            "CoopGym/SitToStandHardHeldOutUnit-v2",
        ]
    )
    # Each scales an id that exists, with the same version (same task, same dynamics).
    for env_id in UNIT_IDS:
        twin = env_id.replace("Unit-", "-")
        assert coop_gym.ENV_IDS[twin] == _physical_twin(env_id)


@pytest.mark.parametrize("observation_mode", ["belief", "raw", "oracle"])
@pytest.mark.parametrize("estimator", ["kalman", "imm"])
def test_the_unit_space_lies_in_minus_one_one(observation_mode: str, estimator: str) -> None:
    features = observation_features(observation_mode, estimator)
    space = unit_observation_space(features, 30.0)
    assert space.dtype == np.float32 and space.shape == (len(features),)
    assert np.all(space.low >= -1.0) and np.all(space.high == 1.0)
    # Symmetric features span [-1, 1], non-negative ones [0, 1]; the force reading dips to -20 N / 40 N.
    expected_low = {f: -1.0 if lo < 0 else 0.0 for f, (lo, _) in coop_gym.envs.contract.FEATURE_BOUNDS.items()}
    expected_low["measured_force_n"] = -0.5
    assert space.low.tolist() == [expected_low[f] for f in features]


def test_every_feature_has_a_positive_scale_and_the_clocks_take_the_episode_length() -> None:
    assert tuple(FEATURE_SCALES) == FEATURES
    scales = observation_scales(FEATURES, 12.5)
    assert np.all(scales > 0)
    assert scales[FEATURES.index("elapsed_s")] == scales[FEATURES.index("time_since_cue_onset_s")] == 12.5


@pytest.mark.parametrize("env_id", ["CoopGym/SitToStandUnit-v0", "CoopGym/SitToStandHardUnit-v1"])
def test_unit_obs_is_the_physical_obs_over_the_scale_with_the_physical_obs_in_info(env_id: str) -> None:
    unit = gym.make(env_id)
    physical = gym.make("CoopGym/SitToStand-v0", **_physical_twin(env_id))
    scales = unit.unwrapped.config.observation_scales()
    low, high = unit.observation_space.low, unit.observation_space.high
    assert scales.tolist() == [FEATURE_SCALES[f] or 30.0 for f in physical.unwrapped.features]
    rng = np.random.default_rng(0)
    for episode in range(3):
        obs_u, info_u = unit.reset(seed=episode)
        obs_p, info_p = physical.reset(seed=episode)
        done = False
        while True:
            assert obs_u.dtype == np.float32 and obs_u in unit.observation_space
            assert np.array_equal(info_u.pop("unscaled_obs"), obs_p)
            assert np.array_equal(obs_u, np.clip(obs_p / scales, low, high))
            assert info_u == info_p  # otherwise the same info
            if done:
                break
            action = np.array([rng.integers(3), rng.integers(3), int(rng.random() < 0.03)])
            obs_u, r_u, term_u, trunc_u, info_u = unit.step(action)
            obs_p, r_p, term_p, trunc_p, info_p = physical.step(action)
            assert (r_u, term_u, trunc_u) == (r_p, term_p, trunc_p)
            done = term_u or trunc_u


def test_the_vector_env_scales_as_the_single_env_and_reports_unscaled_obs() -> None:
    n = 3
    envs = gym.make_vec("CoopGym/SitToStandHardUnit-v1", num_envs=n, autoreset_mode=AutoresetMode.SAME_STEP)
    singles = [gym.make("CoopGym/SitToStandHardUnit-v1") for _ in range(n)]
    obs, infos = envs.reset(seed=5)
    assert obs in envs.observation_space
    for i, env in enumerate(singles):
        single_obs, single_info = env.reset(seed=5 + i)
        assert np.array_equal(obs[i], single_obs)
        assert np.array_equal(infos["unscaled_obs"][i], single_info["unscaled_obs"])
    rng = np.random.default_rng(1)
    saw_final = False
    for _ in range(40):
        actions = np.stack([rng.integers(0, 3, n), rng.integers(0, 3, n), (rng.random(n) < 0.1).astype(int)], axis=1)
        obs, *_, infos = envs.step(actions)
        for i, env in enumerate(singles):
            single_obs, _, term, trunc, single_info = env.step(actions[i])
            if term or trunc:
                saw_final = True
                assert np.array_equal(infos["final_obs"][i], single_obs)
                assert np.array_equal(infos["final_info"]["unscaled_obs"][i], single_info["unscaled_obs"])
                single_obs, single_info = env.reset()
            assert np.array_equal(obs[i], single_obs)
            assert np.array_equal(infos["unscaled_obs"][i], single_info["unscaled_obs"])
    assert saw_final


def test_unit_features_are_renamed_so_physical_readers_refuse_them() -> None:
    env = gym.make("CoopGym/SitToStandUnit-v0")
    assert env.unwrapped.features == (
        "measured_position_m/0.5",
        "measured_force_n/40",
        "verbal_cue",
        "time_since_cue_onset_s/30",
        "x_hat_m/0.5",
        "xdot_hat_m_per_s/0.5",
        "eta_hat_m/0.5",
        "xi_hat/2",
        "xi_std/1.25",
        "judgment",
        "elapsed_s/30",
    )
    with pytest.raises(ValueError, match="x_hat_m"):
        HandbookCaregiver.for_env(env)


def _is_number(value: Any) -> bool:
    # NumPy scalars (TorchRL's info reader asks each value for its dtype), never bools.
    return isinstance(value, (np.int64, np.float64))


@pytest.mark.parametrize(
    ("env_id", "extra"),
    [
        ("CoopGym/SitToStand-v0", ()),
        ("CoopGym/SitToStandIMM-v0", ("p_uncooperative", "p_unresponsive", "p_cooperative")),
        ("CoopGym/SitToStandHardUnit-v1", ("unscaled_obs",)),
    ],
)
def test_numeric_info_holds_numbers_under_flat_keys(env_id: str, extra: tuple[str, ...]) -> None:
    numeric = gym.make(env_id, info_mode="numeric")
    default = gym.make(env_id)
    names = [p.name for p in numeric.unwrapped.personas]
    rng = np.random.default_rng(3)
    for seed in range(3):
        pairs = [(numeric.reset(seed=seed)[1], default.reset(seed=seed)[1])]
        done = False
        while not done:
            action = np.array([rng.integers(3), rng.integers(3), int(rng.random() < 0.05)])
            *_, term, trunc, info_n = numeric.step(action)
            *_, info_d = default.step(action)
            pairs.append((info_n, info_d))
            done = term or trunc
        for info_n, info_d in pairs:
            assert tuple(info_n) == NUMERIC_INFO_KEYS + extra
            assert all(_is_number(v) for k, v in info_n.items() if k != "unscaled_obs")
            # The default info's content, as numbers.
            assert names[info_n["persona_index"]] == info_d["persona"]
            assert coop_gym.Outcome(info_n["outcome_code"]).label == info_d["outcome"]
            for term_name, value in info_d["reward_terms"].items():
                assert info_n[f"reward_{term_name}"] == value
            if "xi_probabilities" in info_d:
                probabilities = [info_n["p_uncooperative"], info_n["p_unresponsive"], info_n["p_cooperative"]]
                assert np.array_equal(probabilities, info_d["xi_probabilities"])
            for key in ("true_x_m", "true_xi", "judgment", "xi_estimate", "push_force_n", "verbal_cue", "elapsed_s"):
                assert info_n[key] == info_d[key]
        assert pairs[-1][0]["outcome_code"] != 0


def test_numeric_vector_infos_are_numeric_arrays_matching_the_single_env() -> None:
    n = 4
    envs = gym.make_vec("CoopGym/SitToStandIMM-v0", num_envs=n, info_mode="numeric", autoreset_mode="SameStep")
    singles = [gym.make("CoopGym/SitToStandIMM-v0", info_mode="numeric") for _ in range(n)]
    _, infos = envs.reset(seed=11)
    single_infos = [env.reset(seed=11 + i)[1] for i, env in enumerate(singles)]
    rng = np.random.default_rng(2)
    for _ in range(30):
        for key, value in infos.items():
            if key in ("final_obs", "final_info"):
                continue
            assert isinstance(value, np.ndarray) and value.dtype.kind in "bif", key
            if not key.startswith("_"):
                assert value.shape == (n,)
                assert value.tolist() == [info[key] for info in single_infos], key
        actions = np.stack([rng.integers(0, 3, n), rng.integers(0, 3, n), (rng.random(n) < 0.1).astype(int)], axis=1)
        *_, infos = envs.step(actions)
        single_infos = []
        for i, env in enumerate(singles):
            *_, term, trunc, info = env.step(actions[i])
            if term or trunc:
                final = infos["final_info"]
                assert all(final[k][i] == info[k] for k in NUMERIC_INFO_KEYS)
                info = env.reset()[1]
            single_infos.append(info)


@pytest.mark.parametrize("env_id", ["CoopGym/SitToStandMM-v0", "CoopGym/SitToStandHardDiscreteUnit-v2"])
def test_numeric_info_envs_pass_both_checkers(env_id: str) -> None:
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        env = gym.make(env_id, info_mode="numeric")
        gym_check_env(env.unwrapped)
        env_checker.check_env(env.unwrapped, warn=True)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"info_mode": "json"}, "info_mode must be one of"),
        ({"info_mode": None}, "info_mode must be one of"),
        ({"observation_scale": "raw"}, "observation_scale must be one of"),
        ({"observation_scale": 1.0}, "observation_scale must be one of"),
    ],
)
def test_bad_client_options_raise_naming_them(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        gym.make("CoopGym/SitToStand-v0", **kwargs)
    with pytest.raises(ValueError, match=message):
        gym.make_vec("CoopGym/SitToStand-v0", num_envs=2, **kwargs)


def test_a_unit_env_pickles_and_goes_on_alike() -> None:
    env = gym.make("CoopGym/SitToStandUnit-v0", info_mode="numeric").unwrapped
    env.reset(seed=0)
    env.step(np.array([1, 2, 0]))
    clone = pickle.loads(pickle.dumps(env))
    a, b = env.step(np.array([1, 0, 0])), clone.step(np.array([1, 0, 0]))
    assert np.array_equal(a[0], b[0]) and a[1:4] == b[1:4]
    assert np.array_equal(a[4].pop("unscaled_obs"), b[4].pop("unscaled_obs")) and a[4] == b[4]
