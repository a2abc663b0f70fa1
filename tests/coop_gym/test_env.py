"""The registered environments: API contracts, checkers, determinism and outcomes."""

from __future__ import annotations

import subprocess
import sys
import warnings
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env

import coop_gym
from coop_gym.envs.core import FEATURES, REWARD_TERMS
from coop_gym.envs.kernels.report import REPORT, TERMINATES

ALL_IDS = sorted(coop_gym.ENV_IDS)


def _sb3_check_env(env: gym.Env[Any, Any]) -> None:
    env_checker = pytest.importorskip("stable_baselines3.common.env_checker")
    env_checker.check_env(env, warn=True)


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_every_id_passes_gymnasium_and_sb3_checkers_without_warnings(env_id: str) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # Gymnasium's own nudge to the level's newer version (Hard...-v2): the one warning allowed.
        warnings.filterwarnings("ignore", r".*SitToStandHard\w*-v1 is out of date", DeprecationWarning)
        env = gym.make(env_id)
        gym_check_env(env.unwrapped)
        _sb3_check_env(env.unwrapped)
        env.close()
        rendered = gym.make(env_id, render_mode="rgb_array")
        gym_check_env(rendered.unwrapped)
        rendered.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_every_id_has_a_time_limit_and_steps(env_id: str) -> None:
    env = gym.make(env_id)
    assert env.spec is not None and env.spec.max_episode_steps == coop_gym.Timing().max_episode_steps
    obs, _ = env.reset(seed=0)
    assert env.observation_space.contains(obs)
    obs, reward, terminated, truncated, _ = env.step(env.action_space.sample())
    assert env.observation_space.contains(obs)
    assert isinstance(reward, float) and isinstance(terminated, bool) and isinstance(truncated, bool)


def test_make_with_module_prefix_works_in_a_fresh_interpreter_without_import() -> None:
    code = (
        "import gymnasium as gym; e = gym.make('coop_gym:CoopGym/SitToStand-v0'); "
        "obs, info = e.reset(seed=0); print(obs.shape, info['persona'])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.startswith("(11,)")


def test_registration_is_idempotent() -> None:
    before = {k for k in gym.registry if k.startswith("CoopGym/")}
    coop_gym.register_envs()
    assert {k for k in gym.registry if k.startswith("CoopGym/")} == before == set(coop_gym.ENV_IDS)


def _rollout(env_id: str, seed: int, n_episodes: int = 2, **kwargs: Any) -> list[tuple[Any, ...]]:
    env = gym.make(env_id, **kwargs)
    env.action_space.seed(seed)
    records = []
    obs, info = env.reset(seed=seed)
    records.append((obs.tobytes(), repr(info)))
    episodes = 0
    while episodes < n_episodes:
        action = env.action_space.sample()
        # Lifting rarely, so episodes last long enough to exercise the dynamics.
        if env_id == "CoopGym/SitToStand-v0" and action[2] == 1 and env.np_random.random() < 0.9:
            action[2] = 0
        obs, reward, terminated, truncated, info = env.step(action)
        records.append((obs.tobytes(), reward, terminated, truncated, repr(info)))
        if terminated or truncated:
            episodes += 1
            obs, info = env.reset()
            records.append((obs.tobytes(), repr(info)))
    return records


def test_same_seed_same_trajectory_and_different_seeds_differ() -> None:
    a = _rollout("CoopGym/SitToStand-v0", seed=11)
    b = _rollout("CoopGym/SitToStand-v0", seed=11)
    c = _rollout("CoopGym/SitToStand-v0", seed=12)
    assert len(a) > 20
    assert a == b
    assert a != c


def test_info_carries_truth_outcome_judgment_and_reward_terms() -> None:
    env = gym.make("CoopGym/SitToStand-v0")
    _, info = env.reset(seed=0)
    for key in ("true_x_m", "true_eta_m", "true_xi", "outcome", "judgment", "persona", "reward_terms"):
        assert key in info
    _, reward, _, _, info = env.step([2, 2, 0])
    assert set(info["reward_terms"]) == set(REWARD_TERMS)
    assert reward == pytest.approx(sum(info["reward_terms"].values()))
    assert info["reward_terms"]["force"] < 0.0 and info["reward_terms"]["time"] < 0.0


def test_lifting_an_upright_person_is_unsafe_and_ends_the_episode() -> None:
    env = gym.make("CoopGym/SitToStand-v0")
    env.reset(seed=0)
    _, reward, terminated, truncated, info = env.step([0, 0, 1])
    assert terminated and not truncated
    assert info["outcome"] == "unsafe"
    assert reward == pytest.approx(-coop_gym.RewardWeights().unsafe)
    with pytest.raises(RuntimeError, match="reset"):
        env.step([0, 0, 0])


def _explain_push_wait_lift(env: gym.Env[Any, Any], seed: int) -> str:
    """Hand-played handbook routine: explain, gentle push, wait for a lean, lift."""
    obs, info = env.reset(seed=seed, options={"persona": "typical"})
    x_hat = env.unwrapped.features.index("x_hat_m")
    for t in range(300):
        if t < 10:
            action = [0, 2, 0]  # "lean forward"
        elif obs[x_hat] < 0.2:
            action = [1, 0, 0]  # gentle push
        else:
            action = [0, 0, 1]
        obs, _, terminated, truncated, info = env.step(action)
        if terminated or truncated:
            return str(info["outcome"])
    return "timeout"


def test_explaining_and_pushing_gently_beats_lifting_at_once_on_typical_persons() -> None:
    env = gym.make("CoopGym/SitToStand-v0")
    n = 60
    guided = [_explain_push_wait_lift(env, seed) for seed in range(n)]
    at_once = []
    for seed in range(n):
        env.reset(seed=seed, options={"persona": "typical"})
        at_once.append(env.step([0, 0, 1])[4]["outcome"])
    assert at_once.count("success") == 0
    assert guided.count("success") >= n // 3


def test_observation_modes_hold_the_documented_features() -> None:
    belief = gym.make("CoopGym/SitToStand-v0").unwrapped
    raw = gym.make("CoopGym/SitToStandRaw-v0").unwrapped
    oracle = gym.make("CoopGym/SitToStandOracle-v0").unwrapped
    assert belief.features == FEATURES[:11]
    assert raw.features == (
        "measured_position_m",
        "measured_force_n",
        "verbal_cue",
        "time_since_cue_onset_s",
        "elapsed_s",
    )
    assert oracle.features[-1] == "true_xi"
    obs, info = oracle.reset(seed=3)
    assert obs[-1] == info["true_xi"]


def test_action_types_decode_to_the_same_cues() -> None:
    multi = gym.make("CoopGym/SitToStand-v0")
    flat = gym.make("CoopGym/SitToStandDiscrete-v0")
    cont = gym.make("CoopGym/SitToStandContinuous-v0")
    for env in (multi, flat, cont):
        env.reset(seed=4)
    a = multi.step([1, 2, 0])
    b = flat.step(int(np.ravel_multi_index((1, 2, 0), (3, 3, 2))))
    soft = 2 * coop_gym.Cues().soft_push_n / coop_gym.Cues().firm_push_n - 1
    c = cont.step(np.array([soft, 1.0, -1.0], dtype=np.float32))
    assert np.array_equal(a[0], b[0]) and a[1] == b[1]
    assert np.allclose(a[0], c[0]) and a[1] == pytest.approx(c[1])


def test_episode_truncates_at_thirty_seconds_with_timeout_outcome() -> None:
    env = gym.make("CoopGym/SitToStand-v0")
    env.reset(seed=0)
    steps = 0
    while True:
        _, _, terminated, truncated, info = env.step([0, 0, 0])
        steps += 1
        if terminated or truncated:
            break
    assert truncated and not terminated and steps == 300
    assert info["outcome"] == "timeout" and info["elapsed_s"] == pytest.approx(30.0)


@pytest.mark.parametrize(
    ("action", "message"),
    [
        ([0, 0, float("nan")], "NaN"),
        ([0, 0], "shape"),
        ([0, 3, 0], "verbal 0..2"),
        ([0, -1, 0], "push 0..2"),
        ([0.5, 0, 0], "integers"),
        ("lift", "numeric"),
    ],
)
def test_bad_actions_raise_naming_the_problem_and_corrupt_nothing(action: Any, message: str) -> None:
    env = gym.make("CoopGym/SitToStand-v0")
    clean = gym.make("CoopGym/SitToStand-v0")
    env.reset(seed=1)
    clean.reset(seed=1)
    with pytest.raises(ValueError, match=message):
        env.unwrapped.step(action)
    assert np.array_equal(env.step([1, 2, 0])[0], clean.step([1, 2, 0])[0])


def test_step_before_reset_raises() -> None:
    env = coop_gym.SitToStandEnv()
    with pytest.raises(RuntimeError, match="before reset"):
        env.step([0, 0, 0])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"personas": "grumpy"}, "unknown persona 'grumpy'"),
        ({"observation_mode": "pixels"}, "observation_mode"),
        ({"action_type": "tuple"}, "action_type"),
        ({"estimator": "particle"}, "estimator"),
        ({"reward": {"sucess": 1.0}}, "sucess"),
        ({"realism": {"reaction_delay": 1}}, "Realism.reaction_delay"),
        ({"timing": {"dt_s": -1.0}}, "Timing.dt_s"),
        ({"render_mode": "ascii"}, "render_mode"),
    ],
)
def test_bad_env_arguments_raise_naming_them(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        gym.make("CoopGym/SitToStand-v0", **kwargs)


def test_reset_options_fix_persona_and_initial_xi() -> None:
    env = gym.make("CoopGym/SitToStand-v0")
    for xi in (-1, 0, 1):
        _, info = env.reset(seed=0, options={"persona": "anxious", "initial_xi": xi})
        assert info["persona"] == "anxious" and info["true_xi"] == xi
    with pytest.raises(ValueError, match="not one of this env's"):
        env.reset(options={"persona": "frail"})
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"xi": 1})


def test_env_docstring_documents_every_section() -> None:
    doc = coop_gym.SitToStandEnv.__doc__ or ""
    for section in (
        "Description",
        "Action Space",
        "Observation Space",
        "Rewards",
        "Starting State",
        "Episode End",
        "Arguments",
        "Vectorized environment",
        "Version History",
    ):
        assert f"## {section}" in doc


def test_a_custom_episode_length_truncates_on_the_envs_own_clock() -> None:
    env = gym.make("CoopGym/SitToStand-v0", timing={"episode_s": 10.0})
    env.reset(seed=0)
    steps, terminated, truncated = 0, False, False
    while not (terminated or truncated) and steps < 300:
        _, _, terminated, truncated, info = env.step([0, 0, 0])
        steps += 1
    assert truncated and steps == 100 and info["outcome"] == "timeout"
    envs = gym.make_vec("CoopGym/SitToStand-v0", num_envs=2, timing={"episode_s": 10.0})
    envs.reset(seed=0)
    steps, done = 0, np.zeros(2, dtype=bool)
    while not done.any() and steps < 300:
        _, _, terminated_v, truncated_v, _ = envs.step(np.zeros((2, 3), dtype=np.int64))
        done = terminated_v | truncated_v
        steps += 1
    assert truncated_v.all() and steps == 100


def test_core_step_commands_library_api_matches_the_env_step() -> None:
    # SitToStandCore.step_commands (decoded cues) is the library entry point beside the env's step.
    env = gym.make("CoopGym/SitToStand-v0")
    twin = gym.make("CoopGym/SitToStand-v0")
    env.reset(seed=7)
    twin.reset(seed=7)
    cues = coop_gym.Cues()
    for action in ([1, 2, 0], [1, 0, 0], [2, 0, 0], [0, 0, 1]):
        obs, reward, terminated, _, _ = env.step(action)
        push = np.array([(0.0, cues.soft_push_n, cues.firm_push_n)[action[0]]])
        verbal = np.array([(0.0, -1.0, 1.0)[action[1]]])
        core = twin.unwrapped.core
        core.cmd[0, :3] = push[0], verbal[0], float(action[2] == 1)
        core.step_commands(core.cmd)
        assert np.array_equal(core.obs[0], obs)
        outcome = int(core.report[0, REPORT.outcome])
        assert core.report[0, REPORT.reward] == reward and bool(TERMINATES[outcome]) == terminated


def test_report_layout_check_is_not_an_assert(monkeypatch: pytest.MonkeyPatch) -> None:
    # report_info unpacks by position; the import-time check must also run under ``python -O``.
    from coop_gym.envs import info

    info._check_report_info()
    monkeypatch.setattr(info, "REPORT_COLUMNS", info.REPORT_COLUMNS[:-1])
    with pytest.raises(RuntimeError, match="update report_info"):
        info._check_report_info()
    monkeypatch.undo()
    swapped = list(info._INFO_ENTRIES)
    swapped[0], swapped[1] = (swapped[0][0], *swapped[1][1:]), (swapped[1][0], *swapped[0][1:])
    monkeypatch.setattr(info, "_INFO_ENTRIES", tuple(swapped))
    with pytest.raises(RuntimeError, match="update report_info"):
        info._check_report_info()
