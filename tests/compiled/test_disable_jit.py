"""Debug mode: with ``NUMBA_DISABLE_JIT=1`` every kernel runs as Python, on the same numbers.

The env's kernels draw through :mod:`estimator.compiled.rng`, whose compiled path calls the bit
generator's C functions through LLVM intrinsics; without the JIT the same C functions are
called through ctypes and NumPy's ziggurat runs in Python with libm's ``exp``/``log1p``, so a
debug run reproduces a compiled run draw for draw.
"""

from __future__ import annotations

import json
import textwrap

import numpy as np

from tests.compiled.fresh import ENV_IDS, ROLLOUT, environment, run_python

DRAWS = textwrap.dedent(
    """
    import json
    import numpy as np
    from numba import config
    from estimator.compiled import rng as compiled_rng
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
    env = environment(NUMBA_DISABLE_JIT="1") if disable_jit else environment()
    return json.loads(run_python(code, *args, env=env).splitlines()[-1])


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
    rollout = ROLLOUT + "print(json.dumps(out))\n"
    debug = _run(rollout, *ENV_IDS, disable_jit=True)
    compiled = _run(rollout, *ENV_IDS, disable_jit=False)
    assert debug == compiled
