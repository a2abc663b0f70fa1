"""Numba's disk cache follows every project source a kernel compiles in, and nothing happens at import."""

from __future__ import annotations

import importlib
import os
import pkgutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from compiled.cache import guarded_kernels, project_sources

ROOT = Path(__file__).resolve().parents[2]
KERNEL_PACKAGES = ("compiled", "coop_gym", "estimator", "experiment")


def _relative(paths: list[Path]) -> set[str]:
    return {p.relative_to(ROOT).as_posix() for p in paths}


def test_the_env_kernels_are_keyed_by_the_model_filter_judgment_and_rng_sources() -> None:
    sources = _relative(project_sources("coop_gym.envs.core"))
    assert {
        "coop_gym/envs/core.py",
        "coop_gym/model/dynamics.py",
        "coop_gym/model/params.py",
        "estimator/kalman.py",
        "estimator/judgment.py",
        "estimator/nominal.py",
        "compiled/rng.py",
    } <= sources


def test_identification_kernel_is_keyed_by_the_multiple_model_steps_it_inlines() -> None:
    assert "estimator/multiple_model.py" in _relative(project_sources("estimator.identify"))


def _project_modules() -> list[str]:
    names = []
    for package in KERNEL_PACKAGES:
        if not (ROOT / package / "__init__.py").exists():
            continue
        names.append(package)
        module = importlib.import_module(package)
        names += [info.name for info in pkgutil.walk_packages(module.__path__, f"{package}.")]
    return names


def test_every_cached_kernel_of_the_project_is_guarded() -> None:
    unguarded = []
    for name in _project_modules():
        importlib.import_module(name)
        unguarded += [f"{name}.{k.__name__}" for k in guarded_kernels(name) if not hasattr(k._cache, "source_guard")]
    assert not unguarded, f"call compiled.cache.guard_kernel_cache(__name__) at the end of their modules: {unguarded}"


def _run(code: str, path: Path) -> str:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(path), str(ROOT)])}
    env.pop("NUMBA_DISABLE_JIT", None)
    out = subprocess.run([sys.executable, "-c", code], cwd=path, env=env, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def test_importing_the_project_touches_no_cache_file() -> None:
    code = textwrap.dedent(
        """
        import coop_gym, estimator.identify, estimator.multiple_model
        from compiled.cache import guarded_kernels
        names = ["coop_gym.envs.core", "coop_gym.model.dynamics", "estimator.identify", "compiled.rng"]
        print(any(k._cache.source_guard.checked for n in names for k in guarded_kernels(n)))
        """
    )
    assert _run(code, ROOT) == "False"


def test_editing_an_inlined_dependency_recompiles_the_kernel(tmp_path: Path) -> None:
    package = tmp_path / "toy"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "dep.py").write_text("from numba import njit\n\n@njit(inline='always')\ndef gain():\n    return 1\n")
    (package / "kern.py").write_text(
        "from numba import njit\n\nfrom compiled.cache import guard_kernel_cache\nfrom toy.dep import gain\n\n"
        "@njit(cache=True)\ndef kernel():\n    return 10 * gain()\n\nguard_kernel_cache(__name__)\n"
    )
    code = "from toy.kern import kernel; print(kernel(), kernel.stats.cache_hits)"
    assert _run(code, tmp_path).split()[0] == "10"
    assert _run(code, tmp_path).split() != ["10", "[]"]  # second run: from the cache
    (package / "dep.py").write_text("from numba import njit\n\n@njit(inline='always')\ndef gain():\n    return 2\n")
    assert _run(code, tmp_path).split()[0] == "20"


@pytest.mark.parametrize("module", ["coop_gym.envs.core", "estimator.identify", "coop_gym.model.dynamics"])
def test_project_sources_stay_inside_the_project(module: str) -> None:
    assert all(ROOT in p.parents for p in project_sources(module))
