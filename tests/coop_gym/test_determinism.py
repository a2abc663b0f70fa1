"""Determinism: same seed, same trajectory -- in one process, across processes, through pickling,
and through every way of vectorising the env.

A trajectory is the full record of a rollout (observations, rewards, terminated, truncated and
infos, over several episodes with resets); ``trajectory_digest`` hashes it exactly (floats by
their bits). The subprocess tests run this very file's functions in a fresh interpreter with a
different hash seed, so nothing may depend on memory addresses, hash order or global state.
"""

from __future__ import annotations

import copy
import hashlib
import os
import pickle
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import coop_gym  # noqa: F401 -- registers the ids for the in-process tests
from tests.coop_gym.twins import vector_actions

ENV_ID = "coop_gym:CoopGym/SitToStand-v0"  # importable by child processes (GYM-NOTES)
VARIANT_IDS = (
    "coop_gym:CoopGym/SitToStand-v0",
    "coop_gym:CoopGym/SitToStandRaw-v0",
    "coop_gym:CoopGym/SitToStandOracle-v0",
    "coop_gym:CoopGym/SitToStandDiscrete-v0",
    "coop_gym:CoopGym/SitToStandContinuous-v0",
    "coop_gym:CoopGym/SitToStandHeldOut-v0",
)
MM_IDS = ("coop_gym:CoopGym/SitToStandMM-v0", "coop_gym:CoopGym/SitToStandIMM-v0")

# --------------------------------------------------------------------------- rollouts


def canonical(value: Any) -> Any:
    """A hashable, exact rendering of obs/reward/info values (floats by their bits)."""
    if isinstance(value, dict):
        return tuple((k, canonical(value[k])) for k in sorted(value))
    if isinstance(value, (list, tuple)):
        return tuple(canonical(v) for v in value)
    if isinstance(value, np.ndarray):
        if value.dtype == object:  # e.g. vector infos of strings: compare the items, not pointers
            return ("object", value.shape, canonical(value.tolist()))
        return (str(value.dtype), value.shape, value.tobytes())
    if isinstance(value, (float, np.floating)):
        return float(value).hex()
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    return repr(value)


def policy_actions(env: gym.Env[Any, Any], seed: int, n: int) -> list[Any]:
    """``n`` actions from the env's own action space, seeded; lifts are rare so episodes run long."""
    space = copy.deepcopy(env.action_space)
    space.seed(seed)
    rng = np.random.default_rng(seed)
    kind = env.unwrapped.action_type
    out = []
    for _ in range(n):
        a = space.sample()
        lift = rng.random() < 0.03
        if kind == "multidiscrete":
            a[2] = int(lift)
        elif kind == "continuous":
            a[2] = 1.0 if lift else -1.0
        else:
            a = int(a - a % 2 + int(lift))  # the flat index's last digit is the lift
        out.append(a)
    return out


def rollout(env: gym.Env[Any, Any], seed: int, actions: list[Any]) -> list[Any]:
    """Reset with ``seed`` once, then play ``actions``, resetting (unseeded) when an episode ends."""
    obs, info = env.reset(seed=seed)
    records: list[Any] = [("reset", obs, info)]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        records.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            obs, info = env.reset()
            records.append(("reset", obs, info))
    return records


def trajectory_digest(env_id: str, seed: int, n_steps: int, **kwargs: Any) -> str:
    """SHA-256 of the full trajectory of ``gym.make(env_id)`` under the seeded policy."""
    env = gym.make(env_id, **kwargs)
    records = rollout(env, seed, policy_actions(env, seed + 1, n_steps))
    env.close()
    return hashlib.sha256(repr(canonical(records)).encode()).hexdigest()


def assert_same_records(a: list[Any], b: list[Any]) -> None:
    assert len(a) == len(b)
    for t, (ra, rb) in enumerate(zip(a, b, strict=True)):
        assert canonical(ra) == canonical(rb), f"trajectories differ at record {t}: {ra} vs {rb}"


def run_in_fresh_process(code: str, timeout: float = 300.0) -> str:
    """Run ``code`` in a new interpreter (``python -c``) with this file's functions as ``ns``."""
    prelude = f"import runpy; ns = runpy.run_path({__file__!r}); "
    # A different string-hash order than ours; the checkout on the path for the shared test helpers.
    root = str(Path(__file__).resolve().parents[2])
    pythonpath = os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH", "")) if p)
    env = {**os.environ, "PYTHONHASHSEED": "4242", "PYTHONPATH": pythonpath}
    done = subprocess.run(
        [sys.executable, "-c", prelude + code], capture_output=True, text=True, timeout=timeout, env=env, check=False
    )
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


# --------------------------------------------------------------------------- one process


@pytest.mark.parametrize("env_id", VARIANT_IDS)
def test_same_seed_same_trajectory(env_id: str) -> None:
    """Two fresh envs, same seed: identical over 700 steps (several episodes, unseeded resets)."""
    records = []
    for _ in range(2):
        env = gym.make(env_id)
        records.append(rollout(env, 123, policy_actions(env, 9, 700)))
    assert sum(1 for r in records[0] if isinstance(r[0], str)) >= 3  # the later episodes are covered too
    assert_same_records(*records)


@pytest.mark.parametrize("env_id", MM_IDS)
def test_same_seed_same_trajectory_multiple_model(env_id: str) -> None:
    assert trajectory_digest(env_id, 5, 400) == trajectory_digest(env_id, 5, 400)


def test_different_seeds_differ() -> None:
    digests = {trajectory_digest(ENV_ID, seed, 50) for seed in range(5)}
    assert len(digests) == 5
    # Same actions, different seeds: the person and noise alone make the trajectories differ.
    env_a, env_b = gym.make(ENV_ID), gym.make(ENV_ID)
    actions = policy_actions(env_a, 0, 30)
    a, b = rollout(env_a, 1, actions), rollout(env_b, 2, actions)
    assert not np.array_equal(a[-1][0], b[-1][0])


def test_reset_without_seed_continues_the_stream() -> None:
    """After ``reset(seed=s)``, unseeded resets differ from each other but repeat across instances."""
    first, second = gym.make(ENV_ID), gym.make(ENV_ID)
    obs = []
    for env in (first, second):
        env.reset(seed=77)
        obs.append([env.reset()[0] for _ in range(4)])
    np.testing.assert_array_equal(np.array(obs[0]), np.array(obs[1]))
    assert len({o.tobytes() for o in obs[0]}) == 4


def test_no_global_random_state_is_used() -> None:
    """Stirring numpy's and Python's global generators between steps changes nothing."""
    import random

    env_a, env_b = gym.make(ENV_ID), gym.make(ENV_ID)
    actions = policy_actions(env_a, 3, 200)
    clean = rollout(env_a, 8, actions)
    np.random.seed(0)
    random.seed(0)
    records: list[Any] = [("reset", *env_b.reset(seed=8))]
    for action in actions:
        np.random.random(7)
        random.random()
        obs, reward, terminated, truncated, info = env_b.step(action)
        records.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            records.append(("reset", *env_b.reset()))
    assert_same_records(clean, records)


# --------------------------------------------------------------------------- across processes


def test_same_trajectory_in_a_fresh_process() -> None:
    """Every variant id, hashed here and in a fresh ``python -c`` (which imports nothing of ours first)."""
    here = [trajectory_digest(env_id, 2024, 400) for env_id in VARIANT_IDS]
    code = f"print('\\n'.join(ns['trajectory_digest'](i, 2024, 400) for i in {VARIANT_IDS!r}))"
    there = run_in_fresh_process(code).splitlines()
    assert there == here


# --------------------------------------------------------------------------- pickling

PICKLE_MAKERS: dict[str, Callable[[], gym.Env[Any, Any]]] = {
    "raw": lambda: gym.make(ENV_ID).unwrapped,
    "gym.make": lambda: gym.make(ENV_ID),
    "rendered": lambda: gym.make(ENV_ID, render_mode="rgb_array"),
    "discrete": lambda: gym.make("coop_gym:CoopGym/SitToStandDiscrete-v0"),
    "continuous": lambda: gym.make("coop_gym:CoopGym/SitToStandContinuous-v0"),
    "imm": lambda: gym.make("coop_gym:CoopGym/SitToStandIMM-v0"),
}


@pytest.mark.parametrize("clone", [lambda e: pickle.loads(pickle.dumps(e)), copy.deepcopy], ids=["pickle", "deepcopy"])
@pytest.mark.parametrize("maker", PICKLE_MAKERS.values(), ids=PICKLE_MAKERS.keys())
def test_clone_mid_episode_continues_identically(
    maker: Callable[[], gym.Env[Any, Any]], clone: Callable[[Any], Any]
) -> None:
    """Clone mid-episode: the clone, the original and an untouched twin go on identically.

    The clone must own its random stream: the core once kept raw addresses of the generators'
    C state, so a clone kept drawing from (and advancing) the original's generator.
    """
    original, twin = maker(), maker()
    actions = policy_actions(original, 4, 400)
    for env in (original, twin):
        rollout(env, 31, actions[:50])
        if env.render_mode == "rgb_array":
            env.render()  # a live pygame renderer must not stop pickling
    copied = clone(original)
    futures = [rollout_from_here(env, actions[50:]) for env in (copied, original, twin)]
    assert_same_records(futures[0], futures[2])
    assert_same_records(futures[1], futures[2])
    if copied.render_mode == "rgb_array":
        assert copied.render().shape == original.render().shape


def rollout_from_here(env: gym.Env[Any, Any], actions: list[Any]) -> list[Any]:
    """``rollout`` without the first reset: continue the episode in progress."""
    records: list[Any] = []
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        records.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            records.append(("reset", *env.reset()))
    return records


def continue_pickled(blob_path: str, actions_seed: int, n_steps: int) -> str:
    """Load a pickled env and continue it (used in the fresh process)."""
    with open(blob_path, "rb") as f:
        env = pickle.load(f)
    records = rollout_from_here(env, policy_actions(env, actions_seed, n_steps))
    return hashlib.sha256(repr(canonical(records)).encode()).hexdigest()


def test_unpickled_in_a_fresh_process_continues_identically(tmp_path: Any) -> None:
    env = gym.make(ENV_ID)
    rollout(env, 99, policy_actions(env, 1, 60))
    blob = tmp_path / "env.pkl"
    blob.write_bytes(pickle.dumps(env))
    there = run_in_fresh_process(f"print(ns['continue_pickled']({str(blob)!r}, 6, 400))")
    assert there == continue_pickled(str(blob), 6, 400)  # a second copy, here
    assert (
        there
        == hashlib.sha256(repr(canonical(rollout_from_here(env, policy_actions(env, 6, 400)))).encode()).hexdigest()
    )  # the original


# --------------------------------------------------------------------------- vectorised


def vec_actions(n_envs: int, seed: int, n: int) -> list[np.ndarray]:
    """``n`` batches of multidiscrete actions, lifting rarely (3 %) so that episodes run long."""
    return vector_actions(n_envs, n, seed, lift_probability=0.03)


def sb3_trajectory(vec_cls: Any, n_envs: int, seed: int, n_steps: int, **vec_kwargs: Any) -> list[Any]:
    vec = vec_cls([lambda: gym.make(ENV_ID) for _ in range(n_envs)], **vec_kwargs)
    try:
        vec.seed(seed)
        records: list[Any] = [vec.reset()]
        for actions in vec_actions(n_envs, seed, n_steps):
            obs, rewards, dones, infos = vec.step(actions)
            # DummyVecEnv keeps rewards in a float32 buffer, SubprocVecEnv stacks the floats.
            records.append((obs, rewards.astype(np.float32), dones, infos))
    finally:
        vec.close()
    return records


def _sb3() -> Any:
    return pytest.importorskip("stable_baselines3.common.vec_env", reason="stable-baselines3 not installed")


@pytest.mark.slow  # two spawned interpreters importing torch
def test_sb3_subproc_spawn_matches_dummy() -> None:
    """Spawned children import the env by its ``coop_gym:`` id; 350 steps cross the time limit."""
    vec_env = _sb3()
    dummy = sb3_trajectory(vec_env.DummyVecEnv, 2, 17, 350)
    assert any(np.any(r[2]) for r in dummy[1:])  # episodes ended (lifts and the 300-step limit)
    spawned = sb3_trajectory(vec_env.SubprocVecEnv, 2, 17, 350, start_method="spawn")
    assert_same_records(dummy, spawned)


@pytest.mark.slow
def test_sb3_subproc_forkserver_matches_dummy() -> None:
    vec_env = _sb3()
    dummy = sb3_trajectory(vec_env.DummyVecEnv, 3, 5, 350)
    forked = sb3_trajectory(vec_env.SubprocVecEnv, 3, 5, 350, start_method="forkserver")
    assert_same_records(dummy, forked)


def gym_vec_trajectory(mode: str, n_envs: int, seed: int, n_steps: int, **kwargs: Any) -> list[Any]:
    vec = gym.make_vec(ENV_ID, num_envs=n_envs, vectorization_mode=mode, **kwargs)
    try:
        records: list[Any] = [vec.reset(seed=seed)]
        for actions in vec_actions(n_envs, seed, n_steps):
            records.append(vec.step(actions))
    finally:
        vec.close()
    return records


def test_make_vec_async_matches_sync() -> None:
    sync = gym_vec_trajectory("sync", 2, 40, 320)
    assert_same_records(sync, gym_vec_trajectory("async", 2, 40, 320))


def test_make_vec_sync_matches_single_envs_seeded_s_plus_i() -> None:
    """Env ``i`` of a vector env seeded ``s`` is the single env seeded ``s + i`` (first episode)."""
    sync = gym_vec_trajectory("sync", 3, 60, 40)
    actions = vec_actions(3, 60, 40)
    for i in range(3):
        env = gym.make(ENV_ID)
        obs, _ = env.reset(seed=60 + i)
        np.testing.assert_array_equal(sync[0][0][i], obs)
        for t, a in enumerate(actions):
            obs, reward, terminated, truncated, _ = env.step(a[i])
            np.testing.assert_array_equal(sync[t + 1][0][i], obs, err_msg=f"env {i} step {t}")
            assert sync[t + 1][1][i] == reward
            if terminated or truncated:
                break


def assert_same_vector_records(native: list[Any], reference: list[Any]) -> None:
    """Like ``assert_same_records``; the native env's infos may carry extra keys (e.g. ``outcome_code``)."""
    assert len(native) == len(reference)
    for t, (got, want) in enumerate(zip(native, reference, strict=True)):
        *got_arrays, got_info = got
        *want_arrays, want_info = want
        assert canonical(got_arrays) == canonical(want_arrays), f"obs/rewards/dones differ at record {t}"
        common = _restrict(got_info, want_info, f"record {t}")
        assert canonical(common) == canonical(want_info), f"infos differ at record {t}: {common} vs {want_info}"


def _restrict(got: dict[str, Any], want: dict[str, Any], where: str) -> dict[str, Any]:
    """``got`` cut down to ``want``'s keys, recursively (``final_info`` is a dict too)."""
    missing = set(want) - set(got)
    assert not missing, f"{where}: native infos lack {sorted(missing)}"
    return {k: _restrict(got[k], want[k], where) if isinstance(want[k], dict) else got[k] for k in want}


@pytest.mark.parametrize("mode", ["NEXT_STEP", "SAME_STEP"])
def test_native_vector_env_matches_sync_vector_of_single_envs(mode: str) -> None:
    """The batched env and a SyncVectorEnv of single envs, same seed and autoreset mode: identical."""
    from gymnasium.vector import AutoresetMode

    autoreset = AutoresetMode[mode]
    n_steps = 620  # two 300-step time limits, lifts in between
    assert_same_vector_records(
        gym_vec_trajectory("vector_entry_point", 3, 13, n_steps, autoreset_mode=autoreset),
        gym_vec_trajectory("sync", 3, 13, n_steps, vector_kwargs={"autoreset_mode": autoreset}),
    )


def test_native_vector_env_with_the_particle_filter_matches_single_envs() -> None:
    """Env ``i`` seeded ``s`` is the single env seeded ``s`` with ``estimator="switching"`` too,
    whatever the other envs reset beside it (their particle seeds span all 64 bits)."""
    from gymnasium.vector import AutoresetMode

    kwargs: dict[str, Any] = {
        "estimator": "switching",
        "estimator_options": {"n_particles": 64, "hypotheses": 8},
        "personas": ["frail", "forgetful"],
    }
    actions = [np.array([1 if t < 20 else 0, 2 if t % 10 == 0 else 0, 0]) for t in range(30)]

    def single(seed: int) -> list[Any]:
        env = gym.make("CoopGym/SitToStandHard-v2", **kwargs)
        return [env.reset(seed=seed)[0]] + [env.step(a)[0] for a in actions]

    vec = gym.make_vec(
        "CoopGym/SitToStandHard-v2", num_envs=4, vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.DISABLED, **kwargs,
    )  # fmt: skip
    batch = [vec.reset(seed=[7, 8, 9, 10])[0]] + [vec.step(np.stack([a] * 4))[0] for a in actions]
    for i, seed in enumerate((7, 8, 9, 10)):
        np.testing.assert_array_equal(np.array([obs[i] for obs in batch]), np.array(single(seed)), err_msg=f"env {i}")
    mask = np.array([False, False, True, False])
    again = [vec.reset(seed=[None, None, 9, None], options={"reset_mask": mask})[0]]
    again += [vec.step(np.stack([a] * 4))[0] for a in actions]
    np.testing.assert_array_equal(np.array([obs[2] for obs in again]), np.array(single(9)), err_msg="masked reset")


def test_native_vector_env_clone_mid_run_continues_identically() -> None:
    original, twin = (gym.make_vec(ENV_ID, num_envs=4) for _ in range(2))
    actions = vec_actions(4, 2, 400)
    for env in (original, twin):
        env.reset(seed=12)
        for a in actions[:100]:
            env.step(a)
    copied = pickle.loads(pickle.dumps(original))
    futures = [[env.step(a) for a in actions[100:]] for env in (copied, original, twin)]
    assert_same_records(futures[0], futures[2])
    assert_same_records(futures[1], futures[2])


@pytest.mark.slow
def test_native_vector_env_matches_async_vector_of_single_envs() -> None:
    native = gym.make_vec(ENV_ID, num_envs=2)
    mode = native.metadata.get("autoreset_mode")
    native.close()
    vector_kwargs = {"autoreset_mode": mode} if mode is not None else {}
    assert_same_vector_records(
        gym_vec_trajectory("vector_entry_point", 2, 8, 320),
        gym_vec_trajectory("async", 2, 8, 320, vector_kwargs=vector_kwargs),
    )


@pytest.mark.slow
def test_native_vector_env_same_seed_same_trajectory_in_a_fresh_process() -> None:
    code = (
        "import hashlib; "
        "r = ns['gym_vec_trajectory']('vector_entry_point', 4, 3, 400); "
        "print(hashlib.sha256(repr(ns['canonical'](r)).encode()).hexdigest())"
    )
    here = hashlib.sha256(repr(canonical(gym_vec_trajectory("vector_entry_point", 4, 3, 400))).encode()).hexdigest()
    assert run_in_fresh_process(code) == here
