"""Scripted baselines: behaviour on seeded episodes, the predict protocol, feature lookup by name."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import coop_gym  # noqa: F401
from agents.base import encode_actions
from agents.scripted import (
    SCRIPTED_AGENTS,
    HandbookCaregiver,
    HandbookSettings,
    LiftAtOnceAgent,
    OracleAgent,
    PhaseState,
    PushThenLiftAgent,
    PushThenLiftSettings,
    RandomAgent,
    make_scripted,
)
from coop_gym.envs.sit_to_stand import observation_features


def rollout(agent, env, seed, options=None):
    """One episode; returns (observations seen before each action, actions, final info, infos)."""
    obs, info = env.reset(seed=seed, options=options)
    seen, actions, infos = [], [], [info]
    state = None
    start = True
    while True:
        action, state = agent.predict(obs[None], state=state, episode_start=np.array([start]))
        start = False
        seen.append(obs)
        actions.append(action[0])
        obs, _, terminated, truncated, info = env.step(action[0])
        infos.append(info)
        if terminated or truncated:
            return np.array(seen), np.array(actions), info, infos


def test_lift_at_once_lifts_at_the_first_step():
    env = gym.make("CoopGym/SitToStand-v0", personas="test")
    agent = LiftAtOnceAgent.for_env(env)
    for seed in range(5):
        _, actions, info, _ = rollout(agent, env, seed)
        assert actions.tolist() == [[0, 0, 1]]
        assert info["outcome"] == "unsafe"  # an upright person lifted without warning


def test_handbook_lifts_only_on_a_cooperative_judgment_and_a_lean():
    env = gym.make("CoopGym/SitToStand-v0", personas="all")
    agent = HandbookCaregiver.for_env(env)
    names = env.unwrapped.features
    j, x = names.index("judgment"), names.index("x_hat_m")
    outcomes = []
    for seed in range(24):
        seen, actions, info, _ = rollout(agent, env, seed)
        lifts = np.flatnonzero(actions[:, 2] == 1)
        # Never lifts while its judgment is uncooperative or unresponsive, nor before the lean.
        assert np.all(seen[lifts, j] == 1.0)
        assert np.all(seen[lifts, x] >= agent.settings.lean_m)
        # Explains first, never a firm push and never "lean back".
        assert actions[0].tolist() == [0, 2, 0]
        assert not np.any(actions[:, 0] == 2) and not np.any(actions[:, 1] == 1)
        outcomes.append(info["outcome"])
    assert "unsafe" not in outcomes
    assert outcomes.count("success") >= 22


def test_handbook_re_explains_after_an_uncooperative_judgment():
    env = gym.make("CoopGym/SitToStand-v0", personas="anxious")
    agent = HandbookCaregiver.for_env(env)
    j = env.unwrapped.features.index("judgment")
    found = False
    for seed in range(12):
        obs, _ = env.reset(seed=seed, options={"initial_xi": -1})
        state, prev_phase = None, None
        for _ in range(300):
            action, state = agent.predict(obs, state)
            if prev_phase == HandbookCaregiver.PUSH and state.phase[0] == HandbookCaregiver.EXPLAIN and obs[j] < 0:
                assert action.tolist() == [0, 2, 0]  # the push stops and the explanation starts again
                found = True
            prev_phase = int(state.phase[0])
            obs, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                break
    assert found, "no uncooperative judgment was met; the test needs other seeds"


def test_oracle_never_lifts_unsafely_and_only_when_cooperative():
    env = gym.make("CoopGym/SitToStandOracle-v0", personas="all")
    agent = OracleAgent.for_env(env)
    xi = env.unwrapped.features.index("true_xi")
    for seed in range(24):
        seen, actions, info, _ = rollout(agent, env, seed)
        lifts = np.flatnonzero(actions[:, 2] == 1)
        assert np.all(seen[lifts, xi] == 1.0)
        assert info["outcome"] == "success"


def test_push_then_lift_pushes_escalates_and_lifts_when_leaning():
    env = gym.make("CoopGym/SitToStand-v0", personas="frail")
    agent = PushThenLiftAgent.for_env(env)
    x = env.unwrapped.features.index("x_hat_m")
    settings = PushThenLiftSettings()
    escalate_step = round(settings.escalate_after_s / 0.1)
    unsafe = 0
    for seed in range(16):
        seen, actions, info, _ = rollout(agent, env, seed)
        assert not np.any(actions[:, 1])  # never a word
        guiding = actions[:-1] if actions[-1, 2] == 1 else actions
        assert np.all(guiding[:escalate_step, 0] == 1) and np.all(guiding[escalate_step:, 0] == 2)
        if actions[-1, 2] == 1:
            assert seen[-1, x] >= settings.lean_m and np.all(seen[:-1, x] < settings.lean_m)
        unsafe += info["outcome"] == "unsafe"
    # The paper's failure scenario: frail people pushed into a lean are lifted while resisting.
    assert unsafe >= 4


def test_failure_scenario_push_then_lift_unsafe_on_frail_handbook_not():
    env = gym.make("CoopGym/SitToStand-v0", personas="frail")
    push_then_lift, handbook = PushThenLiftAgent.for_env(env), HandbookCaregiver.for_env(env)
    unsafe = {"push_then_lift": 0, "handbook": 0}
    for seed in range(30):
        unsafe["push_then_lift"] += rollout(push_then_lift, env, seed)[2]["outcome"] == "unsafe"
        unsafe["handbook"] += rollout(handbook, env, seed)[2]["outcome"] == "unsafe"
    assert unsafe["push_then_lift"] >= 8
    assert unsafe["handbook"] == 0


def test_random_agent_is_seeded_and_valid():
    env = gym.make("CoopGym/SitToStand-v0")
    obs, _ = env.reset(seed=0)
    batch = np.repeat(obs[None], 50, axis=0)
    a1, _ = RandomAgent.for_env(env, seed=3).predict(batch)
    a2, _ = RandomAgent.for_env(env, seed=3).predict(batch)
    a3, _ = RandomAgent.for_env(env, seed=4).predict(batch)
    assert np.array_equal(a1, a2) and not np.array_equal(a1, a3)
    assert all(env.action_space.contains(a) for a in a1)


@pytest.mark.parametrize("name", sorted(SCRIPTED_AGENTS))
def test_batched_equals_one_by_one_and_state_is_not_mutated(name):
    env_id = "CoopGym/SitToStandOracle-v0"
    envs = [gym.make(env_id, personas="all") for _ in range(3)]
    features = envs[0].unwrapped.features
    batched = make_scripted(name, features, seed=0)
    singles = [make_scripted(name, features, seed=0) for _ in envs]
    obs = np.stack([e.reset(seed=10 + i)[0] for i, e in enumerate(envs)])
    state, states = None, [None] * 3
    alive = np.ones(3, dtype=bool)
    for _ in range(40):
        before = None if state is None else state.copy()
        actions, new_state = batched.predict(obs, state=state)
        if before is not None:  # predict returns a new state; the one passed in is untouched
            assert np.array_equal(before.phase, state.phase) and np.array_equal(before.count, state.count)
        state = new_state
        for i, env in enumerate(envs):
            if name != "random":  # the random agent's draws depend on the batch size
                single, states[i] = singles[i].predict(obs[i], state=states[i])
                assert np.array_equal(single, actions[i])
            if alive[i]:
                obs[i], _, terminated, truncated, _ = env.step(actions[i])
                alive[i] = not (terminated or truncated)
        if not alive.any():
            break


def test_memory_is_kept_without_state_and_reset_on_episode_start():
    env = gym.make("CoopGym/SitToStand-v0", personas="typical")
    agent = HandbookCaregiver.for_env(env)
    obs, _ = env.reset(seed=1)
    for _ in range(12):  # explain (1 s), pause, then pushes: memory kept across calls
        action, state = agent.predict(obs)
        obs, *_ = env.step(action)
    assert state.phase[0] in (HandbookCaregiver.PUSH, HandbookCaregiver.LEAN)
    assert action[0] == 1
    action, state = agent.predict(obs, episode_start=np.array([True]))
    assert state.phase[0] == HandbookCaregiver.EXPLAIN and action.tolist() == [0, 2, 0]
    # A new episode (elapsed time 0) also resets the memory, even without episode_start.
    obs, _ = env.reset(seed=2)
    _, state = agent.predict(obs, state=PhaseState(np.array([3]), np.array([5.0]), np.array([1]), np.array([True])))
    assert state.phase[0] == HandbookCaregiver.EXPLAIN


def test_discrete_action_type_plays_the_same_episodes():
    multi = gym.make("CoopGym/SitToStand-v0", personas="test")
    flat = gym.make("CoopGym/SitToStandDiscrete-v0", personas="test")
    for seed in range(4):
        _, a_multi, info_multi, _ = rollout(HandbookCaregiver.for_env(multi), multi, seed)
        _, a_flat, info_flat, _ = rollout(HandbookCaregiver.for_env(flat), flat, seed)
        assert a_flat.ndim == 1
        assert np.array_equal(np.ravel_multi_index(a_multi.T, (3, 3, 2)), a_flat)
        assert info_multi["outcome"] == info_flat["outcome"]


def test_encode_actions_continuous_matches_env_decoding():
    from coop_gym.envs.contract import decode_actions
    from coop_gym.model.params import Cues

    push, verbal, lift = np.array([0, 1, 2]), np.array([2, 0, 1]), np.array([0, 0, 1])
    force, cue, lifted = decode_actions(encode_actions(push, verbal, lift, "continuous"), "continuous", Cues(), 3)
    assert force == pytest.approx([0.0, 10.0, 30.0])
    assert cue.tolist() == [1.0, 0.0, -1.0] and lifted.tolist() == [False, False, True]
    with pytest.raises(ValueError, match="action_type"):
        encode_actions(push, verbal, lift, "tuple")


def test_features_are_found_by_name():
    # The multiple-model estimator adds three features: same behaviour, other columns.
    mm = gym.make("CoopGym/SitToStandMM-v0", personas="test")
    plain = gym.make("CoopGym/SitToStand-v0", personas="test")
    assert len(mm.unwrapped.features) != len(plain.unwrapped.features)
    _, a_mm, _, _ = rollout(HandbookCaregiver.for_env(mm), mm, 3)
    _, a_plain, _, _ = rollout(HandbookCaregiver.for_env(plain), plain, 3)
    assert np.array_equal(a_mm, a_plain)
    with pytest.raises(ValueError, match=r"judgment"):
        HandbookCaregiver(observation_features("raw", "kalman"))
    with pytest.raises(ValueError, match=r"true_xi"):
        OracleAgent(observation_features("belief", "kalman"))
    PushThenLiftAgent(observation_features("raw", "kalman"))  # falls back to the measured position


def test_bad_input_is_rejected_with_clear_errors():
    agent = HandbookCaregiver()
    with pytest.raises(ValueError, match="shape"):
        agent.predict(np.zeros(5))
    with pytest.raises(ValueError, match="NaN"):
        agent.predict(np.full(11, np.nan))
    with pytest.raises(ValueError, match="episode_start"):
        agent.predict(np.zeros((2, 11)), episode_start=np.array([True]))
    with pytest.raises(ValueError, match="action_type"):
        HandbookCaregiver(action_type="tuple")
    with pytest.raises(ValueError, match="unknown scripted agent"):
        make_scripted("nurse")
    with pytest.raises(ValueError, match="lean_m"):
        HandbookSettings(lean_m=-1.0)
    with pytest.raises(ValueError, match="pushes_per_explanation"):
        HandbookSettings(pushes_per_explanation=0)


def test_scripted_agents_and_evaluation_import_without_torch():
    import subprocess
    import sys

    code = (
        "import sys, agents, agents.scripted, agents.evaluate, agents.hyperparams; "
        "assert 'torch' not in sys.modules and 'stable_baselines3' not in sys.modules, 'torch was imported'; "
        "assert agents.HandbookCaregiver is agents.scripted.HandbookCaregiver"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


@pytest.mark.parametrize(
    ("settings", "kwargs", "match"),
    [
        (HandbookSettings, {"lean_m": True}, r"HandbookSettings\.lean_m must be a number, got True"),
        (HandbookSettings, {"pause_s": 61.0}, r"HandbookSettings\.pause_s must be in \[0\.0, 60\.0\], got 61\.0"),
        (PushThenLiftSettings, {"lean_m": np.array([0.2])}, r"PushThenLiftSettings\.lean_m must be a number"),
        (PushThenLiftSettings, {"lean_m": float("nan")}, r"PushThenLiftSettings\.lean_m must be in"),
    ],
)
def test_settings_refuse_bools_arrays_and_out_of_range_values_by_name(settings, kwargs, match):
    with pytest.raises(ValueError, match=match):
        settings(**kwargs)


def test_settings_accept_numpy_scalars():
    assert HandbookSettings(lean_m=np.float32(0.2)).lean_m == np.float32(0.2)
    assert PushThenLiftSettings(escalate_after_s=np.int64(3)).escalate_after_s == 3
