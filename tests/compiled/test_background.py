"""A kernel's first calls run as Python while a background process compiles it, on the same numbers."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import numpy as np
import pytest

from coop_gym.envs.core import SitToStandCore
from coop_gym.envs.kernels.reset import draw_reset, start_episodes
from coop_gym.envs.kernels.step import step_all
from coop_gym.envs.vector import SitToStandVectorEnv
from estimator.compiled.background import ENV_SWITCH, python_twin
from estimator.compiled.cache import guard_kernel_cache
from tests.compiled.fresh import ENV_IDS, ROLLOUT, ROOT, environment, run_python, write_toy_package


def _run(code: str, *args: str, cache: Path | None, switch: str = "1", path: Path = ROOT) -> str:
    """The last line ``code`` prints in a fresh process, with the empty Numba cache folder ``cache`` (None: ours)."""
    env = environment(path, **{ENV_SWITCH: switch})
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = str(cache)
    return run_python(code, *args, env=env, cwd=path).splitlines()[-1]


def _core(n: int) -> SitToStandCore:
    env = SitToStandVectorEnv(num_envs=n)
    return env.core


def test_the_python_twins_of_the_reset_and_step_kernels_give_the_compiled_numbers() -> None:
    cores = [_core(6), _core(6)]
    for core in cores:
        core.seed_envs(np.arange(6), np.arange(6, dtype=np.uint64) + 40)
        core.reset_envs(core._all)
    twins = {kernel: python_twin(kernel) for kernel in (draw_reset, start_episodes, step_all)}
    commands = np.random.default_rng(3).integers(0, 3, size=(25, 6, 2))
    for t, command in enumerate(commands):
        for core, run in zip(cores, (lambda kernel: kernel, twins.__getitem__), strict=True):
            core.cmd[:, 0] = command[:, 0] * 10.0
            core.cmd[:, 1] = command[:, 1] - 1.0
            core.cmd[:, 2] = float(t % 9 == 8)  # a lift now and then: the episode ends
            assert run(step_all)(core.cmd, core.state, core.generators, core.obs, core.consts) == -1
        np.testing.assert_array_equal(cores[0].state, cores[1].state)
        np.testing.assert_array_equal(cores[0].obs, cores[1].obs)


ROLLOUT_AS_PYTHON = ROLLOUT + textwrap.dedent(
    """
    from estimator.compiled import background
    from coop_gym.envs.kernels.step import step_all
    out["ran_as_python"] = not step_all.signatures
    if background._compiler is not None:
        background._compiler.process.kill()  # the test needs no compiled kernels
    print(json.dumps(out))
    """
)


def test_a_cold_start_steps_the_envs_as_python_on_the_compiled_numbers(tmp_path: Path) -> None:
    python = json.loads(_run(ROLLOUT_AS_PYTHON, *ENV_IDS, cache=tmp_path / "cold"))
    assert python.pop("ran_as_python")
    compiled = json.loads(_run(ROLLOUT_AS_PYTHON, *ENV_IDS, cache=None, switch="0"))
    assert not compiled.pop("ran_as_python")
    assert python == compiled


TOY = (
    "import numpy as np\nfrom numba import njit\n\nfrom estimator.compiled.cache import guard_kernel_cache\n\n"
    "@njit(cache=True)\ndef half(x):\n    return x * 0.5\n\n"
    "@njit(cache=True)\ndef kernel(n):\n    out = np.empty(n)\n    for i in range(n):\n        out[i] = half(i)\n"
    "    return out\n\nguard_kernel_cache(__name__)\n"
)

TOY_RUN = textwrap.dedent(
    """
    from estimator.compiled import background
    from toy.kern import kernel
    first = kernel(4).tolist()
    compiled_at_once = bool(kernel.signatures)
    background.wait(300)
    second = kernel(4).tolist()
    print(first == second == [0.0, 0.5, 1.0, 1.5], compiled_at_once, kernel.stats.cache_hits != {})
    """
)


def _toy(tmp_path: Path, guard: str = "guard_kernel_cache(__name__)") -> None:
    write_toy_package(tmp_path, kern=TOY.replace("guard_kernel_cache(__name__)", guard))


def test_a_kernel_missing_from_the_cache_runs_as_python_until_the_background_process_compiled_it(
    tmp_path: Path,
) -> None:
    _toy(tmp_path)
    # As Python first, then loaded from the cache the background process filled.
    assert _run(TOY_RUN, cache=tmp_path / "cache", path=tmp_path) == "True False True"
    # Warm: loaded at the first call.
    assert _run(TOY_RUN, cache=tmp_path / "cache", path=tmp_path) == "True True True"


def test_switched_off_a_kernel_compiles_in_the_calling_process(tmp_path: Path) -> None:
    _toy(tmp_path)
    assert _run(TOY_RUN, cache=tmp_path / "cache", switch="0", path=tmp_path) == "True True False"


def test_a_kernel_named_compile_here_compiles_in_the_calling_process(tmp_path: Path) -> None:
    _toy(tmp_path, guard='guard_kernel_cache(__name__, compile_here=("kernel",))')
    assert _run(TOY_RUN, cache=tmp_path / "cache", path=tmp_path) == "True True False"


def test_compile_here_names_kernels_of_the_module() -> None:
    import estimator.particle  # noqa: F401  (the module whose kernels are named)

    with pytest.raises(ValueError, match=r"compile_here names no kernel of estimator\.particle: 'filter'"):
        guard_kernel_cache("estimator.particle", compile_here=("filter",))
