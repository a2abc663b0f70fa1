"""Recorded trajectories: every registered ``-v0`` id must keep behaving exactly as recorded.

A change of dynamics, observation or reward gets a new ``-vN``; the old ids stay bit-identical.
This test replays fixed action sequences (drawn from their own seeded generator, not from the
spaces, so a Gymnasium upgrade cannot change them) through each ``-v0`` id, single env and the
native vector env, and compares observations, rewards, termination, truncation and every info
value to the recording in ``data/recorded_v0.npz`` exactly. A selection of the ``-v1`` ids
(difficulty levels, oracle, IMM) is held the same way by ``data/recorded_v1.npz``, and the
``-v2`` ids (the level, its discrete and held-out variants) by ``data/recorded_v2.npz``. The
``Unit`` ids are their physical twins scaled (``test_client_options.py``).

Bit for bit holds at one NumPy SIMD level: NumPy's AVX-512 ``exp`` differs from its AVX2 ``exp``
in the last bit, and each person is drawn through ``np.exp``. The recording was made at the AVX2
level (``X86_V3``), and the repository's ``conftest.py`` runs every test at that level
(``NPY_DISABLE_CPU_FEATURES``), so the replay holds on any x86 CPU.

Re-record (only when a change is *meant* to alter a version, which the versioning rule forbids)::

    COOP_GYM_RECORD=1 python -m pytest tests/coop_gym/test_recorded_trajectories.py     # -v0
    COOP_GYM_RECORD_V1=1 python -m pytest tests/coop_gym/test_recorded_trajectories.py  # -v1
    COOP_GYM_RECORD_V2=1 python -m pytest tests/coop_gym/test_recorded_trajectories.py  # -v2
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import pytest

import coop_gym  # noqa: F401  (registers the ids)

DATA = Path(__file__).parent / "data" / "recorded_v0.npz"
DATA_V1 = Path(__file__).parent / "data" / "recorded_v1.npz"
DATA_V2 = Path(__file__).parent / "data" / "recorded_v2.npz"
V0_IDS = (
    "CoopGym/SitToStand-v0",
    "CoopGym/SitToStandRaw-v0",
    "CoopGym/SitToStandOracle-v0",
    "CoopGym/SitToStandDiscrete-v0",
    "CoopGym/SitToStandContinuous-v0",
    "CoopGym/SitToStandMM-v0",
    "CoopGym/SitToStandIMM-v0",
    "CoopGym/SitToStandHeldOut-v0",
)
V1_IDS = (
    "CoopGym/SitToStandEasy-v1",
    "CoopGym/SitToStandMedium-v1",
    "CoopGym/SitToStandHard-v1",
    "CoopGym/SitToStandHardOracle-v1",
    "CoopGym/SitToStandHardIMM-v1",
)
V2_IDS = (
    "CoopGym/SitToStandHard-v2",
    "CoopGym/SitToStandHardDiscrete-v2",
    "CoopGym/SitToStandHardHeldOut-v2",
)
SINGLE_SEEDS = (0, 3, 11)
SINGLE_STEPS = 400  # crosses several episode ends (lifts and a 300-step truncation)
VECTOR_SEED = 5
VECTOR_ENVS = 4
VECTOR_STEPS = 200


def _actions(env_id: str, seed: int, shape: tuple[int, ...]) -> Any:
    """A fixed action sequence: mostly pushes and "lean forward", a lift now and then."""
    rng = np.random.default_rng(10_000 + seed)
    push = rng.choice(3, size=shape, p=[0.35, 0.45, 0.2])
    verbal = rng.choice(3, size=shape, p=[0.55, 0.1, 0.35])
    # Seed 11 almost never lifts, so its episodes run into the 300-step truncation.
    lift = (rng.random(shape) < (0.001 if seed == 11 else 0.025)).astype(np.int64)
    if "Discrete-" in env_id:
        return np.ravel_multi_index((push, verbal, lift), (3, 3, 2)).astype(np.int64)
    if "Continuous-" in env_id:
        jitter = rng.uniform(-0.2, 0.2, size=(*shape, 2))
        columns = [push - 1.0 + jitter[..., 0] * (push == 1), verbal - 1.0 + jitter[..., 1], 2.0 * lift - 1.0]
        return np.clip(np.stack(columns, axis=-1), -1.0, 1.0).astype(np.float32)
    return np.stack([push, verbal, lift], axis=-1).astype(np.int64)


def _flatten(info: dict[str, Any], prefix: str = "") -> dict[str, Any]:
    flat: dict[str, Any] = {}
    for key, value in info.items():
        if isinstance(value, dict):
            flat.update(_flatten(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def _as_array(values: list[Any]) -> np.ndarray:
    array = np.asarray(values)
    if array.dtype == object:  # labels of masked-out vector entries are None
        array = np.asarray(["<none>" if v is None else v for v in array.ravel()]).reshape(array.shape)
    return array


def _append_step(
    rows: dict[str, list[Any]],
    infos: dict[str, list[Any]],
    obs: Any,
    reward: Any,
    terminated: Any,
    truncated: Any,
    info: dict[str, Any],
) -> None:
    """Record one step's results: ``rows`` by name, ``infos`` by flattened ``info.`` key."""
    rows["obs"].append(obs)
    rows["reward"].append(reward)
    rows["terminated"].append(terminated)
    rows["truncated"].append(truncated)
    for key, value in _flatten(info).items():
        infos.setdefault(f"info.{key}", []).append(value)


def _record_single(env_id: str, seed: int) -> dict[str, np.ndarray]:
    env = gym.make(env_id)
    actions = _actions(env_id, seed, (SINGLE_STEPS,))
    obs, info = env.reset(seed=seed)
    rows: dict[str, list[Any]] = {"obs": [obs], "reward": [], "terminated": [], "truncated": []}
    infos: dict[str, list[Any]] = {f"info.{k}": [] for k in _flatten(info)}
    for t in range(SINGLE_STEPS):
        obs, reward, terminated, truncated, info = env.step(actions[t])
        _append_step(rows, infos, obs, reward, terminated, truncated, info)
        if terminated or truncated:
            obs, _ = env.reset()
            rows["obs"].append(obs)
    env.close()
    return {k: _as_array(v) for k, v in {**rows, **infos}.items()}


def _record_vector(env_id: str) -> dict[str, np.ndarray]:
    envs = gym.make_vec(env_id, num_envs=VECTOR_ENVS, vectorization_mode="vector_entry_point")
    actions = _actions(env_id, VECTOR_SEED, (VECTOR_STEPS, VECTOR_ENVS))
    obs, _ = envs.reset(seed=VECTOR_SEED)
    rows: dict[str, list[Any]] = {"obs": [obs], "reward": [], "terminated": [], "truncated": []}
    infos: dict[str, list[Any]] = {}
    for t in range(VECTOR_STEPS):
        obs, reward, terminated, truncated, info = envs.step(actions[t])
        # The vector env reuses its info arrays from step to step: keep copies.
        info = {key: np.asarray(value).copy() for key, value in _flatten(info).items()}
        _append_step(rows, infos, obs, reward, terminated, truncated, info)
    envs.close()
    return {k: _as_array(v) for k, v in {**rows, **infos}.items()}


def _cases(env_ids: tuple[str, ...] = V0_IDS) -> list[tuple[str, str, int | None]]:
    cases: list[tuple[str, str, int | None]] = []
    for env_id in env_ids:
        cases += [(env_id, "single", seed) for seed in SINGLE_SEEDS]
        cases.append((env_id, "vector", None))
    return cases


def _key(env_id: str, kind: str, seed: int | None) -> str:
    return f"{env_id}|{kind}|{seed}"


def _record(env_id: str, kind: str, seed: int | None) -> dict[str, np.ndarray]:
    return _record_single(env_id, seed) if kind == "single" and seed is not None else _record_vector(env_id)


def _record_all(path: Path, env_ids: tuple[str, ...]) -> None:
    arrays: dict[str, np.ndarray] = {}
    for env_id, kind, seed in _cases(env_ids):
        for name, array in _record(env_id, kind, seed).items():
            arrays[f"{_key(env_id, kind, seed)}|{name}"] = array
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, **arrays)


if os.environ.get("COOP_GYM_RECORD") == "1":  # pragma: no cover - re-recording is a deliberate act
    _record_all(DATA, V0_IDS)
if os.environ.get("COOP_GYM_RECORD_V1") == "1":  # pragma: no cover - re-recording is a deliberate act
    _record_all(DATA_V1, V1_IDS)
if os.environ.get("COOP_GYM_RECORD_V2") == "1":  # pragma: no cover - re-recording is a deliberate act
    _record_all(DATA_V2, V2_IDS)


def _load(path: Path) -> dict[str, np.ndarray]:
    with np.load(path, allow_pickle=False) as data:
        return {name: data[name] for name in data.files}


@pytest.fixture(scope="module")
def recording() -> dict[str, np.ndarray]:
    return _load(DATA)


@pytest.fixture(scope="module")
def recording_v1() -> dict[str, np.ndarray]:
    return _load(DATA_V1)


@pytest.fixture(scope="module")
def recording_v2() -> dict[str, np.ndarray]:
    return _load(DATA_V2)


def _assert_replays(recording: dict[str, np.ndarray], env_id: str, kind: str, seed: int | None) -> None:
    prefix = f"{_key(env_id, kind, seed)}|"
    expected = {name[len(prefix) :]: array for name, array in recording.items() if name.startswith(prefix)}
    assert expected, f"no recording for {prefix}"
    replayed = _record(env_id, kind, seed)
    assert sorted(replayed) == sorted(expected), "the set of recorded quantities (info keys) changed"
    for name, array in expected.items():
        got = replayed[name]
        assert got.shape == array.shape, f"{name}: shape {got.shape} != recorded {array.shape}"
        assert got.dtype == array.dtype, f"{name}: dtype {got.dtype} != recorded {array.dtype}"
        # Exact, NaN-aware: bit-identical is the contract, not "close".
        assert np.array_equal(got, array, equal_nan=got.dtype.kind == "f"), f"{name} differs from the recording"


@pytest.mark.parametrize(("env_id", "kind", "seed"), _cases(), ids=lambda v: str(v))
def test_v0_trajectory_is_bit_identical_to_the_recording(
    recording: dict[str, np.ndarray], env_id: str, kind: str, seed: int | None
) -> None:
    _assert_replays(recording, env_id, kind, seed)


@pytest.mark.parametrize(("env_id", "kind", "seed"), _cases(V1_IDS), ids=lambda v: str(v))
def test_v1_trajectory_is_bit_identical_to_the_recording(
    recording_v1: dict[str, np.ndarray], env_id: str, kind: str, seed: int | None
) -> None:
    _assert_replays(recording_v1, env_id, kind, seed)


@pytest.mark.parametrize(("env_id", "kind", "seed"), _cases(V2_IDS), ids=lambda v: str(v))
def test_v2_trajectory_is_bit_identical_to_the_recording(
    recording_v2: dict[str, np.ndarray], env_id: str, kind: str, seed: int | None
) -> None:
    _assert_replays(recording_v2, env_id, kind, seed)


def test_recording_covers_episode_ends(recording: dict[str, np.ndarray]) -> None:
    # The recording must exercise lifts (termination) and the 300-step truncation, or it guards little.
    terminated = sum(int(a.sum()) for n, a in recording.items() if n.endswith("|terminated"))
    truncated = sum(int(a.sum()) for n, a in recording.items() if n.endswith("|truncated"))
    assert terminated >= 20
    assert truncated >= 1
