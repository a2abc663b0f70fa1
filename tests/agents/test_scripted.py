"""Scripted baselines: behaviour on seeded episodes, the predict protocol, feature lookup by name."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import coop_gym  # noqa: F401
from agents.base import encode_actions
from agents.caregivers.belief import TUNED_BELIEF
from agents.caregivers.scripted import (
    SCRIPTED_AGENTS,
    TUNED_BLIND,
    TUNED_PROBER,
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
from agents.evaluate import evaluate
from coop_gym.envs.sit_to_stand import observation_features
from coop_gym.model.difficulty import DIFFICULTIES


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
    # The belief caregiver reads the switching filter's P(xi = +1) (a small filter: this test is about batching).
    switching = {"estimator": "switching", "estimator_options": {"n_particles": 64, "hypotheses": 8}}
    envs = [gym.make(env_id, personas="all", **(switching if name == "belief" else {})) for _ in range(3)]
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
        "import sys, agents, agents.caregivers.scripted, agents.evaluate, agents.hyperparams; "
        "assert 'torch' not in sys.modules and 'stable_baselines3' not in sys.modules, 'torch was imported'; "
        "assert agents.HandbookCaregiver is agents.caregivers.scripted.HandbookCaregiver"
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


# --- the mental-state-blind family -----------------------------------------------------------

_BLIND_COLUMNS = ("elapsed_s", "verbal_cue", "x_hat_m")


def _old_blind_rule(settings, x, silent, now, lean_since):
    """The original one-routine blind rule, as it was before the schedules (the reference)."""
    pushes = {"none": 0, "soft": 1, "firm": 2}
    leaning = x >= settings.lean_m
    held = lean_since is not None and now - lean_since >= settings.hold_s - 1e-6
    lift = leaning and held and now >= settings.min_time_s - 1e-6
    guiding = not lift and not (leaning and settings.release_on_lean)
    push = pushes[settings.push] if guiding else 0
    verbal = 2 if guiding and silent and settings.words else 0
    return [push, verbal, int(lift)]


def _lean_walks(n_envs, steps, seed=0):
    """Shoulder estimates and utterance flags that cross every lean threshold back and forth."""
    rng = np.random.default_rng(seed)
    x = np.clip(np.cumsum(rng.normal(0.0, 0.03, size=(steps, n_envs)), axis=0) + 0.15, -0.1, 0.5)
    silent = rng.random((steps, n_envs)) < 0.6
    return x, silent


def _grid_sample(every):
    """Every ``every``-th schedule of the searched grid, each under a different one of its lift rules."""
    from agents.tune.baselines import lift_rules, schedule_grid

    picked = []
    for k, schedule in enumerate(list(schedule_grid())[::every]):
        rules = list(lift_rules(schedule))
        picked.append(rules[(37 * k) % len(rules)])
    return picked


def _blind_obs(features, now, x, silent):
    obs = np.zeros((len(x), len(features)))
    obs[:, features.index("elapsed_s")] = now
    obs[:, features.index("x_hat_m")] = x
    obs[:, features.index("verbal_cue")] = np.where(silent, 0.0, 1.0)
    return obs


def test_the_original_blind_settings_are_members_and_behave_as_before():
    from agents.caregivers.scripted import BlindAgent
    from agents.tune.baselines import lift_rules, original_blind_grid, schedule_grid

    original = list(original_blind_grid())
    assert len(original) == 648
    routines = [s for s in schedule_grid() if not s.schedule]
    assert set(original) <= {c for s in routines for c in lift_rules(s)}
    # Each env of one batched agent runs one original setting; the new rule must act as the old one.
    features = observation_features("belief", "kalman")
    agent = BlindAgent(features, settings=original)
    x, silent = _lean_walks(len(original), 120)
    lean_since = [None] * len(original)
    state = None
    for step in range(120):
        now = 0.1 * step
        actions, state = agent.predict(_blind_obs(features, now, x[step], silent[step]), state=state)
        for i, settings in enumerate(original):
            leaning = x[step, i] >= settings.lean_m
            lean_since[i] = (lean_since[i] if lean_since[i] is not None else now) if leaning else None
            assert actions[i].tolist() == _old_blind_rule(settings, x[step, i], silent[step, i], now, lean_since[i])


def test_blind_schedule_phases_run_in_order_for_their_durations():
    from agents.caregivers.scripted import BlindAgent, BlindSettings, CuePhase

    features = observation_features("belief", "kalman")
    schedule = (CuePhase("none", "forward", 1.0), CuePhase("soft", "forward", 2.0), CuePhase("none", "none", 0.5))
    held = BlindSettings(push="firm", words=False, lean_m=0.3, schedule=schedule)
    looped = BlindSettings(lean_m=0.3, schedule=schedule, repeat=True)
    agent = BlindAgent(features, settings=[held, looped])
    seen = []
    for step in range(80):
        obs = _blind_obs(features, 0.1 * step, np.zeros(2), np.ones(2, dtype=bool))
        actions, _ = agent.predict(obs)
        seen.append(actions[:, :2].tolist())
    seen = np.array(seen)  # (step, env, [push, verbal])
    expected = [[0, 2]] * 10 + [[1, 2]] * 20 + [[0, 0]] * 5  # words 1 s, guided push 2 s, silence 0.5 s
    assert seen[:35, 0].tolist() == expected and seen[35:, 0].tolist() == [[2, 0]] * 45  # then the final phase
    assert seen[:70, 1].tolist() == expected * 2 and seen[70:, 1].tolist() == expected[:10]  # or again


def test_blind_lifts_only_in_phases_that_allow_it_and_on_the_last_call():
    from agents.caregivers.scripted import BlindAgent, BlindSettings, CuePhase

    features = observation_features("belief", "kalman")
    schedule = (CuePhase("soft", "forward", 1.0, lift=False), CuePhase("none", "forward", 1.0))
    settings = [
        BlindSettings(lean_m=0.2, schedule=schedule, repeat=True),
        BlindSettings(lean_m=0.4, schedule=schedule, repeat=True, last_call_s=3.0, last_call_lean_m=0.2),
    ]
    first_lift = []
    for s in settings:
        agent = BlindAgent(features, settings=s)
        for step in range(60):
            action, _ = agent.predict(_blind_obs(features, 0.1 * step, np.full(1, 0.25), np.ones(1, dtype=bool)))
            if action[0, 2]:
                first_lift.append(step)
                break
    # Leaning from the start: the lift waits for the unpushed phase (1 s), or for the last call (3 s).
    assert first_lift == [10, 30]


def test_per_env_blind_settings_equal_one_agent_per_setting():
    from agents.caregivers.scripted import BlindAgent

    features = observation_features("belief", "kalman")
    picked = _grid_sample(38)[:24]
    batched = BlindAgent(features, settings=picked)
    singles = [BlindAgent(features, settings=s) for s in picked]
    x, silent = _lean_walks(len(picked), 200, seed=1)
    for step in range(200):
        obs = _blind_obs(features, 0.1 * step, x[step], silent[step])
        actions, _ = batched.predict(obs)
        for i, agent in enumerate(singles):
            assert np.array_equal(agent.predict(obs[i])[0], actions[i])
    with pytest.raises(ValueError, match="settings for 24 envs"):
        batched.predict(obs[:3])


def test_the_blind_family_reads_only_its_clock_its_words_and_the_lean():
    from agents.caregivers.scripted import BlindAgent

    assert set(BlindAgent.needs) == set(_BLIND_COLUMNS)
    features = observation_features("oracle", "imm")  # every mind feature there is, true xi included
    picked = _grid_sample(7)
    a, b = BlindAgent(features, settings=picked), BlindAgent(features, settings=picked)
    rng = np.random.default_rng(2)
    x, silent = _lean_walks(len(picked), 300, seed=2)
    for step in range(300):
        obs = _blind_obs(features, 0.1 * step, x[step], silent[step])
        scrambled = obs.copy()
        for k, name in enumerate(features):
            if name not in _BLIND_COLUMNS:  # xi_hat, judgment, P(xi), true_xi, ... all scrambled
                scrambled[:, k] = rng.uniform(-1.0, 1.0, len(picked))
        assert np.array_equal(a.predict(obs)[0], b.predict(scrambled)[0])


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda s, p: p(push="gentle"), r"CuePhase\.push must be one of"),
        (lambda s, p: p(verbal="sit"), r"CuePhase\.verbal must be one of"),
        (lambda s, p: p(duration_s=0.0), r"CuePhase\.duration_s must be in"),
        (lambda s, p: p(lift=1), r"CuePhase\.lift must be a bool"),
        (lambda s, p: s(push="hard"), r"BlindSettings\.push must be one of"),
        (lambda s, p: s(words="yes"), r"BlindSettings\.words must be a bool"),
        (lambda s, p: s(lean_m=2.0), r"BlindSettings\.lean_m must be in"),
        (lambda s, p: s(hold_s=-1.0), r"BlindSettings\.hold_s must be in"),
        (lambda s, p: s(schedule=[p()]), r"BlindSettings\.schedule must be a tuple of CuePhase"),
        (lambda s, p: s(schedule=({"push": "soft"},)), r"BlindSettings\.schedule must be a tuple of CuePhase"),
        (lambda s, p: s(repeat=True), r"BlindSettings\.repeat needs a non-empty BlindSettings\.schedule"),
        (lambda s, p: s(last_call_s=float("nan")), r"BlindSettings\.last_call_s must be in"),
        (lambda s, p: s(last_call_lean_m=-0.1), r"BlindSettings\.last_call_lean_m must be in"),
    ],
)
def test_bad_blind_settings_raise_naming_the_field(make, match):
    from agents.caregivers.scripted import BlindSettings, CuePhase

    with pytest.raises(ValueError, match=match):
        make(BlindSettings, CuePhase)


def test_a_level_of_ones_own_has_no_chosen_settings_and_says_so():
    # A shipped level given as its Difficulty is its name; a changed one has no chosen settings.
    assert make_scripted("blind", level=DIFFICULTIES["hard"]).settings == TUNED_BLIND["hard"]
    assert make_scripted("prober", level="medium").settings == TUNED_PROBER["medium"]
    switching = observation_features("belief", "switching")
    assert make_scripted("belief", switching, level="hard-v2").settings == TUNED_BELIEF["hard-v2"]
    mine = dataclasses.replace(DIFFICULTIES["hard"], lapse_rate_per_s=0.05)
    for name, agent in (("blind", "BlindAgent"), ("prober", "ProbingCaregiver"), ("belief", "BeliefCaregiver")):
        with pytest.raises(ValueError, match=rf"no {agent} settings were chosen for the level 'hard' \(not a shipped"):
            make_scripted(name, level=mine)
    with pytest.raises(ValueError, match=r"no BlindAgent settings .* level 'brutal'; chosen for: v0, easy"):
        make_scripted("blind", level="brutal")
    # Through the one evaluation path: the error, not a KeyError; the other agents play the level.
    with pytest.raises(ValueError, match="no BlindAgent settings"):
        evaluate("blind", "CoopGym/SitToStandHard-v1", "test", 1, 0, env_kwargs={"difficulty": mine})
    oracle = evaluate("oracle", "CoopGym/SitToStandHard-v1", "test", 4, 0, env_kwargs={"difficulty": mine})
    assert oracle.success_rate == 1.0


def test_for_env_plays_the_settings_chosen_for_the_envs_level():
    from agents.caregivers.belief import BeliefCaregiver, BeliefSettings
    from agents.caregivers.scripted import BlindAgent, ProbingCaregiver

    single = gym.make("CoopGym/SitToStandHard-v2", estimator="switching")
    vector = gym.make_vec("CoopGym/SitToStandHard-v2", num_envs=2, vectorization_mode="vector_entry_point")
    assert BeliefCaregiver.for_env(single).settings == TUNED_BELIEF["hard-v2"] != BeliefSettings()
    for env in (single, vector):  # the level is found through wrappers and on the vector env
        assert BlindAgent.for_env(env).settings == TUNED_BLIND["hard-v2"]
        assert ProbingCaregiver.for_env(env).settings == TUNED_PROBER["hard-v2"]
    assert ProbingCaregiver.for_env(gym.make("CoopGym/SitToStand-v0")).settings == TUNED_PROBER["v0"]
    mine = BeliefSettings(lift_p=0.9)
    assert BeliefCaregiver.for_env(single, settings=mine).settings is mine  # given settings win
    custom = dataclasses.replace(DIFFICULTIES["hard"], lapse_rate_per_s=0.05)
    with pytest.raises(ValueError, match=r"no ProbingCaregiver settings .* 'hard' \(not a shipped level\)"):
        ProbingCaregiver.for_env(gym.make("CoopGym/SitToStandHard-v1", difficulty=custom))
    single.close()
    vector.close()
