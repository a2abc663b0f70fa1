"""The env contract (coop_gym.envs.contract) is the one place both envs and the agents read."""

from __future__ import annotations

import dataclasses
import itertools

import gymnasium as gym
import numpy as np
import pytest

import coop_gym
from coop_gym.envs.config import ACTION_TYPES, Outcome
from coop_gym.envs.contract import (
    ACTION_SHAPE,
    CMD,
    FEATURE_BOUNDS,
    FEATURES,
    REPORT,
    REPORT_COLUMNS,
    TERMINATES,
    TRUNCATES,
    ActionDecoder,
    EnvArguments,
    count_steps_and_end_episodes,
    decode_actions,
    encode_actions,
    episode_end,
    report_info,
)
from coop_gym.envs.vector import SitToStandVectorEnv
from coop_gym.model.params import Cues

CHOICES = np.array(list(itertools.product(*(range(n) for n in ACTION_SHAPE))))  # every (push, verbal, lift)


def test_every_feature_has_bounds() -> None:
    assert tuple(FEATURE_BOUNDS) == FEATURES


@pytest.mark.parametrize("action_type", ACTION_TYPES)
def test_encode_then_decode_gives_back_every_choice(action_type: str) -> None:
    cues = Cues(soft_push_n=8.0, firm_push_n=25.0)
    actions = encode_actions(CHOICES[:, 0], CHOICES[:, 1], CHOICES[:, 2], action_type, cues)
    push, verbal, lift = decode_actions(actions, action_type, cues, len(CHOICES))
    assert push.tolist() == pytest.approx([(0.0, 8.0, 25.0)[p] for p in CHOICES[:, 0]], abs=1e-5)  # float32 actions
    assert verbal.tolist() == [(0.0, -1.0, 1.0)[v] for v in CHOICES[:, 1]]
    assert lift.tolist() == [bool(x) for x in CHOICES[:, 2]]


@pytest.mark.parametrize("action_type", ACTION_TYPES)
def test_the_fast_paths_decode_as_decode_actions(action_type: str) -> None:
    cues = Cues()
    decoder = ActionDecoder(action_type, cues)
    actions = encode_actions(CHOICES[:, 0], CHOICES[:, 1], CHOICES[:, 2], action_type, cues)
    push, verbal, lift = decode_actions(actions, action_type, cues, len(CHOICES))
    want = np.stack([push, verbal, lift.astype(float)], axis=1)
    batch = np.zeros((len(CHOICES), len(CMD)))
    decoder.batch(actions, batch)
    assert np.array_equal(batch[:, : CMD.active], want)
    for k, action in enumerate(actions):
        single = action.item() if action_type == "discrete" else action
        got = decoder.single(single, np.zeros((1, len(CMD))))
        assert np.array_equal(got[0, : CMD.active], want[k])


def _episode_ends(
    outcome: np.ndarray, stepped: np.ndarray, steps_before: int, length: int = 2, limit: int = 2
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(outcome, terminated, truncated) of count_steps_and_end_episodes for envs ``steps_before`` steps in."""
    n = len(outcome)
    report = np.zeros((n, len(REPORT_COLUMNS)))
    report[:, REPORT.outcome] = outcome
    cmd = np.zeros((n, len(CMD)))
    cmd[:, CMD.active] = stepped
    steps = np.full(n, steps_before, dtype=np.int64)
    rewards, terminated, truncated = np.empty(n), np.empty(n, dtype=bool), np.empty(n, dtype=bool)
    count_steps_and_end_episodes(report, cmd, steps, length, limit, rewards, terminated, truncated)
    return report[:, REPORT.outcome].astype(np.int64), terminated, truncated


def test_only_a_lift_or_the_episodes_length_ends_an_episode() -> None:
    lifts = [o.terminates for o in Outcome]
    outcome = np.array([float(o) for o in Outcome] * 2)
    stepped = np.array([True] * len(Outcome) + [False] * len(Outcome))
    codes, terminated, truncated = _episode_ends(outcome, stepped, steps_before=0)
    assert codes.tolist() == outcome.tolist() and terminated.tolist() == lifts + [False] * len(Outcome)
    assert not truncated.any()
    # The step that reaches the episode's length truncates every stepped env, a terminated one too (as
    # Gymnasium's TimeLimit); the ones that did not lift time out.
    codes, terminated, truncated = _episode_ends(outcome, stepped, steps_before=1)
    timed_out = [int(o) if o.terminates else int(Outcome.TIMEOUT) for o in Outcome]
    assert codes.tolist() == timed_out + outcome[len(Outcome) :].tolist()
    assert terminated.tolist() == lifts + [False] * len(Outcome)
    assert truncated.tolist() == [True] * len(Outcome) + [False] * len(Outcome)
    # A step limit under the length truncates with the step's own outcome (no timeout yet).
    codes, _, truncated = _episode_ends(outcome, stepped, steps_before=1, length=5, limit=2)
    assert codes.tolist() == outcome.tolist() and truncated.tolist() == [True] * len(Outcome) + [False] * len(Outcome)
    # A step limit over the length: the length ends the episode.
    assert episode_end(int(Outcome.NONE), 5, 5, 9) == (int(Outcome.TIMEOUT), False, True)
    assert episode_end(int(Outcome.SUCCESS), 5, 5, 9) == (int(Outcome.SUCCESS), True, True)


@pytest.mark.parametrize("lift", [0, 1])
def test_the_last_allowed_step_ends_alike_in_the_single_and_the_vector_env(lift: int) -> None:
    """A lift on the last allowed step: terminated and truncated in both (the single env's
    TimeLimit sets truncated at the limit whatever the step did); a wait: truncated only."""
    import gymnasium as gym

    env_id, limit, seed = "CoopGym/SitToStand-v0", 5, 3
    single = gym.make(env_id, max_episode_steps=limit)
    vector = gym.make_vec(env_id, num_envs=1, vectorization_mode="vector_entry_point", max_episode_steps=limit)
    single.reset(seed=seed)
    vector.reset(seed=seed)
    for step in range(limit):
        action = [2, 2, lift if step == limit - 1 else 0]
        _, r_s, term_s, trunc_s, _ = single.step(np.array(action))
        _, r_v, term_v, trunc_v, _ = vector.step(np.array([action]))
        assert (r_s, term_s, trunc_s) == (r_v[0], term_v[0], trunc_v[0]), step
    assert trunc_s and term_s == bool(lift)


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.uint8, np.uint64])
def test_the_compiled_multidiscrete_decoding_takes_any_integer_dtype_and_refuses_out_of_range(dtype: type) -> None:
    decoder = ActionDecoder("multidiscrete", Cues())
    want = np.zeros((len(CHOICES), len(CMD)))
    decoder.batch(CHOICES, want)
    got = np.zeros((len(CHOICES), len(CMD)))
    decoder.batch(CHOICES.astype(dtype), got)
    assert np.array_equal(got, want)
    for bad in ([0, 3, 0], [0, 0, 2], [3, 0, 0]):
        actions = CHOICES.astype(dtype)
        actions[-1] = bad
        cmd = np.full((len(CHOICES), len(CMD)), 7.0)
        with pytest.raises(ValueError, match="multidiscrete action must be"):
            decoder.batch(actions, cmd)
        assert (cmd == 7.0).all()  # nothing written
    with pytest.raises(ValueError, match="multidiscrete action must be"):
        decoder.batch(np.array([[0, 0, 0], [-1, 0, 0]]), np.zeros((2, len(CMD))))


def test_the_compiled_episode_end_is_the_single_envs_rule() -> None:
    rng = np.random.default_rng(5)
    n = 400
    report = np.zeros((n, len(REPORT_COLUMNS)))
    steps = rng.integers(0, 5, n)
    for length, limit in ((3, 3), (3, 2), (2, 4)):
        report[:, REPORT.outcome] = rng.choice([int(o) for o in Outcome if o is not Outcome.TIMEOUT], n)
        report[:, REPORT.reward] = rng.normal(size=n)
        cmd = np.zeros((n, len(CMD)))
        cmd[:, CMD.active] = rng.random(n) < 0.7
        stepped = cmd[:, CMD.active] > 0.5
        want_steps = steps + stepped
        codes = report[:, REPORT.outcome].astype(np.int64)
        ends = [episode_end(int(c), int(k), length, limit) for c, k in zip(codes, want_steps, strict=True)]
        want_codes = np.where(stepped, [e[0] for e in ends], codes)
        want = (stepped & TERMINATES[codes], stepped & np.array([e[2] for e in ends]))
        rewards, terminated, truncated = np.empty(n), np.empty(n, dtype=bool), np.empty(n, dtype=bool)
        count_steps_and_end_episodes(report, cmd, steps, length, limit, rewards, terminated, truncated)
        assert np.array_equal(steps, want_steps)
        assert np.array_equal(report[:, REPORT.outcome], want_codes)
        assert np.array_equal(terminated, want[0]) and np.array_equal(truncated, want[1])
        assert np.array_equal(TRUNCATES[want_codes] & stepped, stepped & ~want[0] & (want_steps >= length))
        assert np.array_equal(rewards, np.where(stepped, report[:, REPORT.reward], 0.0))


def test_the_vector_infos_hold_the_single_env_info_of_each_env() -> None:
    envs = gym.make_vec("CoopGym/SitToStandMM-v0", num_envs=3)
    envs.reset(seed=2)
    envs.step(np.array([[1, 2, 0], [0, 0, 1], [2, 1, 0]]))
    core = envs.unwrapped.core
    names = np.array([p.name for p in envs.unwrapped.personas], dtype=object)
    batched = envs.unwrapped._info.batched(core.report, None)
    for i, row in enumerate(core.report.tolist()):
        single = report_info(row, list(names), True)
        for key, value in single.items():
            if key == "reward_terms":
                assert value == {k: batched[key][k][i] for k in value}
            else:
                assert np.array_equal(batched[key][i], value), key


def _shares_memory(a: object, b: object) -> bool:
    return isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and np.shares_memory(a, b)


@pytest.mark.parametrize(
    ("env_id", "kwargs"),
    [
        ("CoopGym/SitToStand-v0", {}),
        ("CoopGym/SitToStandMM-v0", {}),
        ("CoopGym/SitToStandUnit-v0", {}),
        ("CoopGym/SitToStand-v0", {"info_mode": "numeric"}),
        ("CoopGym/SitToStandIMM-v0", {"info_mode": "numeric"}),
    ],
)
def test_the_infos_of_every_env_are_the_masked_infos_with_an_all_true_mask(env_id: str, kwargs: dict) -> None:
    # The per-step infos (mask None: one compiled gather into fresh blocks) against the masked
    # path with every env selected: the same keys in the same order, dtypes and values, and no
    # two arrays sharing memory (a caller may keep or change any of them).
    envs = gym.make_vec(env_id, num_envs=5, **kwargs)
    envs.reset(seed=4)
    builder, core = envs.unwrapped._info, envs.unwrapped.core
    for _ in range(6):
        envs.step(np.array([[1, 2, 0], [0, 0, 1], [2, 1, 0], [2, 2, 1], [0, 1, 0]]))
        fast = builder.batched(core.report, None)
        masked = builder.batched(core.report, np.ones(5, dtype=bool))
        assert list(fast) == list(masked)
        arrays = []
        for key in fast:
            pairs = (
                [(k, fast[key][k], masked[key][k]) for k in fast[key]]
                if key == "reward_terms"
                else [(key, fast[key], masked[key])]
            )
            assert isinstance(fast[key], dict) == isinstance(masked[key], dict), key
            if isinstance(fast[key], dict):
                assert list(fast[key]) == list(masked[key])
            for name, got, want in pairs:
                assert got.dtype == want.dtype and got.shape == want.shape, name
                assert got.tolist() == want.tolist(), name
                arrays.append(got)
        assert not any(_shares_memory(a, b) for a, b in itertools.combinations(arrays, 2))
        assert not any(_shares_memory(a, core.state) for a in arrays)


def test_one_list_of_env_keywords() -> None:
    names = {f.name for f in dataclasses.fields(EnvArguments)}
    for kwargs in coop_gym.ENV_IDS.values():
        assert set(kwargs) <= names
    for make in (coop_gym.SitToStandEnv, lambda **kw: SitToStandVectorEnv(2, **kw)):
        with pytest.raises(TypeError, match=r"unexpected keyword argument 'persona'.*'personas'"):
            make(persona="typical")
    env = coop_gym.SitToStandEnv(**{f.name: f.default for f in dataclasses.fields(EnvArguments)})
    assert env.config == EnvArguments().resolve()
