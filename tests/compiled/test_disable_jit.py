"""Debug mode: with ``NUMBA_DISABLE_JIT=1`` every kernel runs as Python, on the same numbers.

The env's kernels draw through :mod:`coop_gym.compiled.rng`, whose compiled path calls the bit
generator's C functions through LLVM intrinsics; without the JIT the same C functions are
called through ctypes and NumPy's ziggurat runs in Python with libm's ``exp``/``log1p``, so a
debug run reproduces a compiled run draw for draw.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
ENV_IDS = ("CoopGym/SitToStand-v0", "CoopGym/SitToStandIMM-v0", "CoopGym/SitToStandHard-v1")

ROLLOUT = textwrap.dedent(
    """
    import json, sys
    import gymnasium as gym
    import numpy as np
    import coop_gym
    out = {}
    for env_id in sys.argv[1:]:
        env = gym.make(env_id)
        obs, info = env.reset(seed=11)
        rows = [obs.tolist()]
        actions = np.random.default_rng(4).integers(0, 3, size=(8, 3))
        for push, verbal, _ in actions:
            obs, reward, terminated, truncated, info = env.step([int(push), int(verbal), 0])
            rows.append([*obs.tolist(), reward, info["true_x_m"], info["true_xi"]])
        out[env_id] = rows
    print(json.dumps(out))
    """
)

DRAWS = textwrap.dedent(
    """
    import json
    import numpy as np
    from numba import config
    from coop_gym.compiled import rng as compiled_rng
    assert config.DISABLE_JIT
    out = []
    for bit_generator in (np.random.PCG64, np.random.MT19937, np.random.Philox, np.random.SFC64):
        rng = np.random.Generator(bit_generator(2024))
        g = compiled_rng.bit_generator_row(rng)
        draws = []
        for high in range(1, 11):
            draws.append(compiled_rng.integers(g, high))
            draws.append(compiled_rng.random(g))
        draws += [compiled_rng.standard_normal(g) for _ in range(30_000)]
        draws += rng.standard_normal(3).tolist()  # the Generator itself advanced
        out.append([float(d) for d in draws])
    print(json.dumps(out))
    """
)


def _run(code: str, *args: str, disable_jit: bool) -> object:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("NUMBA_DISABLE_JIT", None)
    if disable_jit:
        env["NUMBA_DISABLE_JIT"] = "1"
    out = subprocess.run(
        [sys.executable, "-c", code, *args], cwd=ROOT, env=env, capture_output=True, text=True, timeout=600
    )
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_debug_mode_draws_are_the_generators() -> None:
    got = _run(DRAWS, disable_jit=True)
    for k, bit_generator in enumerate((np.random.PCG64, np.random.MT19937, np.random.Philox, np.random.SFC64)):
        reference = np.random.Generator(bit_generator(2024))
        expected = []
        for high in range(1, 11):
            expected.append(float(reference.integers(high)))
            expected.append(reference.random())
        expected += reference.standard_normal(30_003).tolist()
        assert got[k] == expected, bit_generator.__name__  # type: ignore[index]
        assert np.abs(expected[20:30_020]).max() > 3.6541528853610088  # the ziggurat's tail ran


def test_debug_mode_runs_the_envs_like_the_compiled_run() -> None:
    debug = _run(ROLLOUT, *ENV_IDS, disable_jit=True)
    compiled = _run(ROLLOUT, *ENV_IDS, disable_jit=False)
    assert debug == compiled
