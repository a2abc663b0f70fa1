"""The batched env on several threads: the same numbers as on one, and as the single envs."""

from __future__ import annotations

import multiprocessing
import time
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from numpy.typing import NDArray

import coop_gym
from coop_gym.envs.contract import CMD
from coop_gym.envs.kernels import threads as threads_module
from coop_gym.envs.vector import SitToStandVectorEnv
from coop_gym.model.params import Timing
from estimator.compiled.rng import G_STATE

SHORT = {"timing": {"episode_s": 2.0}}  # 20-step episodes: truncations as well as lifts
TWO_THREADS = 2


@pytest.fixture
def parallel_for_small_batches(monkeypatch: pytest.MonkeyPatch) -> None:
    """Split even a handful of envs across threads (by default small batches step on one)."""
    monkeypatch.setattr(threads_module, "MIN_ENVS_PER_THREAD", 1)


def _rollout(threads: int, n: int, steps: int, mode: AutoresetMode, env_id: str = "CoopGym/SitToStand-v0") -> Any:
    """Everything a vector env returns over ``steps`` random steps (lifting often, so autoresets happen)."""
    envs = gym.make_vec(env_id, num_envs=n, autoreset_mode=mode, threads=threads, **SHORT)
    rng = np.random.default_rng(7)
    record: list[Any] = list(envs.reset(seed=100))
    for _ in range(steps):
        lift = (rng.random(n) < 0.08).astype(np.int64)
        actions = np.column_stack([rng.integers(0, 3, n), rng.integers(0, 3, n), lift])
        record.extend(envs.step(actions))
    return record, envs.unwrapped.core


def _assert_identical(a: Any, b: Any) -> None:
    """Equal bit for bit: arrays (NaN in the same places), dicts key by key, object arrays item by item."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            _assert_identical(a[key], b[key])
    elif isinstance(a, np.ndarray) and a.dtype == object:
        assert a.shape == b.shape
        for x, y in zip(a, b, strict=True):
            _assert_identical(x, y)
    elif isinstance(a, np.ndarray):
        assert a.dtype == b.dtype and a.shape == b.shape
        assert np.array_equal(a.view(np.uint8), b.view(np.uint8))
    else:
        assert a == b


@pytest.mark.usefixtures("parallel_for_small_batches")
@pytest.mark.parametrize("mode", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_two_threads_give_bit_identical_results_to_one(mode: AutoresetMode) -> None:
    one, serial_core = _rollout(1, 37, 300, mode)  # 37: the threads' ranges have unequal lengths
    two, parallel_core = _rollout(TWO_THREADS, 37, 300, mode)
    assert serial_core._chunks == 1
    assert parallel_core._chunks == TWO_THREADS
    ended = sum(int(np.sum(x)) for x in one[4::5]) + sum(int(np.sum(x)) for x in one[5::5])  # terminated, truncated
    assert ended > 300  # lifts and truncations: autoresets were exercised
    assert len(one) == len(two)
    for a, b in zip(one, two, strict=True):
        _assert_identical(a, b)
    np.testing.assert_array_equal(serial_core.state, parallel_core.state)


@pytest.mark.usefixtures("parallel_for_small_batches")
def test_two_threads_give_bit_identical_results_with_the_imm_estimator() -> None:
    one, _ = _rollout(1, 8, 60, AutoresetMode.NEXT_STEP, "CoopGym/SitToStandIMM-v0")
    two, core = _rollout(TWO_THREADS, 8, 60, AutoresetMode.NEXT_STEP, "CoopGym/SitToStandIMM-v0")
    assert core._chunks == TWO_THREADS
    for a, b in zip(one, two, strict=True):
        _assert_identical(a, b)


@pytest.mark.usefixtures("parallel_for_small_batches")
def test_env_i_on_two_threads_plays_what_a_single_env_seeded_s_plus_i_plays() -> None:
    n, steps, seed = 12, 120, 40
    limit = Timing(episode_s=2.0).max_episode_steps
    envs = gym.make_vec("CoopGym/SitToStand-v0", num_envs=n, threads=TWO_THREADS, max_episode_steps=limit, **SHORT)
    singles = [gym.make("CoopGym/SitToStand-v0", max_episode_steps=limit, **SHORT) for _ in range(n)]
    vobs, _ = envs.reset(seed=seed)
    for i, env in enumerate(singles):
        assert np.array_equal(env.reset(seed=seed + i)[0], vobs[i])
    rng = np.random.default_rng(3)
    pending = np.zeros(n, dtype=bool)
    for _ in range(steps):
        actions = np.column_stack([rng.integers(0, 3, n), rng.integers(0, 3, n), rng.random(n) < 0.06])
        vobs, vrew, vterm, vtrunc, vinfos = envs.step(actions)
        for i, env in enumerate(singles):
            if pending[i]:
                obs, info = env.reset()
                reward, terminated, truncated = 0.0, False, False
            else:
                obs, reward, terminated, truncated, info = env.step(actions[i])
            assert np.array_equal(vobs[i], obs)
            assert (vrew[i], vterm[i]) == (reward, terminated)
            # (A lift on the last step: TimeLimit also truncates the single env; the vector env does not.)
            assert (vterm[i] or vtrunc[i]) == (terminated or truncated)
            assert vinfos["true_x_m"][i] == info["true_x_m"] and vinfos["xi_estimate"][i] == info["xi_estimate"]
        pending = vterm | vtrunc
    assert envs.unwrapped.core._chunks == TWO_THREADS


@pytest.mark.parametrize("threads", [0, -1, 2.5, True, "2"])
def test_bad_threads_raise_naming_the_argument(threads: Any) -> None:
    with pytest.raises(ValueError, match=r"threads must be None or a positive int, got"):
        SitToStandVectorEnv(num_envs=2, threads=threads)


def test_threads_default_to_the_cores_and_small_batches_step_on_one() -> None:
    assert SitToStandVectorEnv(num_envs=4, threads=1).threads == 1
    envs = SitToStandVectorEnv(num_envs=4)
    assert envs.threads == threads_module.available_threads() >= 1
    envs.reset(seed=0)
    envs.step(envs.action_space.sample())
    assert envs.core._chunks == 1  # 4 envs: below MIN_ENVS_PER_THREAD on any thread count
    single = coop_gym.SitToStandEnv()
    single.reset(seed=0)
    single.step(single.action_space.sample())
    assert single.core._chunks == 1


@pytest.mark.usefixtures("parallel_for_small_batches")
def test_envs_sharing_a_generator_step_on_one_thread_in_env_order() -> None:
    envs = SitToStandVectorEnv(num_envs=4, threads=TWO_THREADS)
    envs.reset(seed=0)
    core = envs.core
    assert core._plan_chunks() == TWO_THREADS
    shared = np.random.default_rng(0)
    core.reset_env(1, shared)
    core.reset_env(2, shared)
    assert core._plan_chunks() == 1


@pytest.mark.usefixtures("parallel_for_small_batches")
def test_stepping_an_env_never_reset_raises_before_any_env_moves() -> None:
    envs = SitToStandVectorEnv(num_envs=6, threads=TWO_THREADS)
    core = envs.core
    for i in (0, 1, 2, 4):
        core.reset_env(i, np.random.default_rng(i))
    before = core.state.copy()
    with pytest.raises(RuntimeError, match="env 3 was stepped before it was reset"):
        core.step_commands(core.cmd)  # no push, no cue, no lift, every env active
    np.testing.assert_array_equal(core.state, before)


def _step_in_child(queue: Any) -> None:
    envs = SitToStandVectorEnv(num_envs=8, threads=TWO_THREADS, **SHORT)
    envs.reset(seed=1)
    obs = envs.step(np.ones((8, 3), dtype=np.int64))[0]
    queue.put(obs)


@pytest.mark.usefixtures("parallel_for_small_batches")
@pytest.mark.skipif("fork" not in multiprocessing.get_all_start_methods(), reason="no fork on this platform")
def test_a_child_forked_after_a_parallel_step_still_steps_and_agrees() -> None:
    # The parent's worker threads do not exist in a forked child: it must start its own.
    envs = SitToStandVectorEnv(num_envs=8, threads=TWO_THREADS, **SHORT)
    envs.reset(seed=1)
    expected = envs.step(np.ones((8, 3), dtype=np.int64))[0]
    context = multiprocessing.get_context("fork")
    queue = context.Queue()
    child = context.Process(target=_step_in_child, args=(queue,))
    child.start()
    obs = queue.get(timeout=120)
    child.join(timeout=60)
    assert child.exitcode == 0
    np.testing.assert_array_equal(obs, expected)


def _stepped_core(threads: int) -> Any:
    """A core of 300 envs a few steps into its episodes (split over threads: parallel_for_small_batches)."""
    envs = gym.make_vec("CoopGym/SitToStand-v0", num_envs=300, threads=threads, **SHORT)
    envs.reset(seed=5)
    rng = np.random.default_rng(3)
    for _ in range(4):
        envs.step(np.column_stack([rng.integers(0, 3, 300), rng.integers(0, 3, 300), np.zeros(300, dtype=np.int64)]))
    return envs.unwrapped.core


def _commands(core: Any, active: NDArray[np.bool_]) -> NDArray[np.float64]:
    cmd = core.cmd.copy()
    cmd[:, CMD.push_force_n] = 10.0
    cmd[:, CMD.verbal_cue] = 1.0
    cmd[:, CMD.lift] = 0.0
    cmd[:, CMD.active] = active
    return cmd


@pytest.mark.usefixtures("parallel_for_small_batches")
@pytest.mark.parametrize("threads", [1, TWO_THREADS])
def test_a_step_with_resets_equals_the_step_then_the_resets(threads: int) -> None:
    together, apart = _stepped_core(threads), _stepped_core(threads)
    active = np.random.default_rng(0).random(300) < 0.6
    reset = np.flatnonzero(~active).astype(np.int64)
    together.step_commands(_commands(together, active), reset=reset)
    assert together._chunks == threads
    apart.step_commands(_commands(apart, active))
    apart.reset_envs(reset)
    np.testing.assert_array_equal(together.state, apart.state)
    np.testing.assert_array_equal(together.obs, apart.obs)
    for a, b in zip(together.rngs, apart.rngs, strict=True):
        assert a.bit_generator.state == b.bit_generator.state


@pytest.mark.usefixtures("parallel_for_small_batches")
@pytest.mark.parametrize("threads", [1, TWO_THREADS])
def test_a_step_that_would_reset_a_stepped_env_or_one_without_a_generator_changes_nothing(threads: int) -> None:
    core = _stepped_core(threads)
    before = core.state.copy()
    draws = [rng.bit_generator.state for rng in core.rngs]
    active = np.ones(300, dtype=bool)
    active[10:20] = False
    with pytest.raises(ValueError, match="both stepped and reset"):
        core.step_commands(_commands(core, active), reset=np.arange(5, 15, dtype=np.int64))
    core.generators[12, G_STATE] = 0  # as if env 12 had never had a generator
    with pytest.raises(RuntimeError, match="env 12 has no random generator"):
        core.step_commands(_commands(core, active), reset=np.arange(10, 20, dtype=np.int64))
    np.testing.assert_array_equal(core.state, before)
    assert [rng.bit_generator.state for rng in core.rngs] == draws


@pytest.mark.usefixtures("parallel_for_small_batches")
def test_a_worker_that_starts_after_its_step_is_over_changes_nothing() -> None:
    # On a busy machine a worker may be scheduled only after the calling thread stepped every
    # block: it must neither step an env twice nor take a block of the next step.
    core = _stepped_core(TWO_THREADS)
    cmd = _commands(core, np.ones(300, dtype=bool))
    core.step_commands(cmd)
    assert core._chunks == TWO_THREADS
    before = core.state.copy()
    draws = [rng.bit_generator.state for rng in core.rngs]
    arrays = (cmd, core.state, core.generators, core.obs, core.consts)
    blocks = 300 // threads_module.ENVS_PER_BLOCK
    step = int(core._control[threads_module._CLAIM] >> 32)
    threads_module.step_claimed(step, blocks, core._control, *arrays)  # this step's worker, late: none left
    core._control[threads_module._CLAIM] = (step + 1) << 32  # the next step has begun, no block claimed yet
    threads_module.step_claimed(step, blocks, core._control, *arrays)  # the late worker finds another step
    assert core._control[threads_module._CLAIM] == (step + 1) << 32
    np.testing.assert_array_equal(core.state, before)
    assert [rng.bit_generator.state for rng in core.rngs] == draws


@pytest.mark.usefixtures("parallel_for_small_batches")
def test_an_interrupted_threaded_step_leaves_no_worker_running(monkeypatch: pytest.MonkeyPatch) -> None:
    # Ctrl-C while the calling thread resets envs, before the worker has woken: when
    # the exception leaves step_commands, no worker may go on to step the envs behind its back.
    core = _stepped_core(TWO_THREADS)
    active = np.ones(300, dtype=bool)
    active[:10] = False

    def interrupted_reset(indices: Any) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(core, "reset_envs", interrupted_reset)
    with pytest.raises(KeyboardInterrupt):
        core.step_commands(_commands(core, active), reset=np.arange(10, dtype=np.int64))
    claimed = int(core._control[threads_module._CLAIM] & threads_module._LOW32)
    blocks = 300 // threads_module.ENVS_PER_BLOCK
    assert claimed == blocks  # closed: nothing is left to claim
    after = core.state.copy()
    time.sleep(0.05)  # the worker wakes meanwhile, and must find the step over
    np.testing.assert_array_equal(core.state, after)


@pytest.mark.usefixtures("parallel_for_small_batches")
def test_step_numbers_wrap_without_overflowing_the_claim_word() -> None:
    # After 2**31 - 1 threaded steps the next number is 0 (a shift of 2**31 would overflow int64).
    core = _stepped_core(TWO_THREADS)
    twin = _stepped_core(TWO_THREADS)
    core._control[threads_module._CLAIM] = (threads_module._STEP_NUMBERS - 1) << 32
    cmd = _commands(core, np.ones(300, dtype=bool))
    core.step_commands(cmd)
    twin.step_commands(_commands(twin, np.ones(300, dtype=bool)))
    blocks = 300 // threads_module.ENVS_PER_BLOCK
    assert core._control[threads_module._CLAIM] == blocks  # step 0, every block claimed
    np.testing.assert_array_equal(core.state, twin.state)
