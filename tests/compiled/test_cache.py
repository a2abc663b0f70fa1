"""Numba's disk cache follows every project source a kernel compiles in, and nothing happens at import."""

from __future__ import annotations

import importlib
import json
import os
import pkgutil
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from estimator.compiled.background import ENV_SWITCH
from estimator.compiled.cache import guarded_kernels, project_sources
from tests.compiled.fresh import ROOT, environment, run_python, write_toy_package

KERNEL_PACKAGES = ("coop_gym", "estimator")


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
        "estimator/compiled/rng.py",
    } <= sources


def test_identification_kernel_is_keyed_by_the_multiple_model_steps_it_inlines() -> None:
    assert "estimator/mode_kernels.py" in _relative(project_sources("estimator.identification.identify"))


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
    assert not unguarded, (
        f"call estimator.compiled.cache.guard_kernel_cache(__name__) at the end of their modules: {unguarded}"
    )


def _compiled_here(*paths: Path, **variables: str) -> dict[str, str]:
    # Kernels compile in the calling process: these tests are about the cache.
    return environment(*paths, **variables, **{ENV_SWITCH: "0"})


def _run(code: str, path: Path) -> str:
    return run_python(code, env=_compiled_here(path), cwd=path, timeout=300)


def test_importing_the_project_touches_no_cache_file() -> None:
    code = textwrap.dedent(
        """
        import coop_gym.envs, estimator.identification.identify, estimator.multiple_model
        from estimator.compiled.cache import guarded_kernels
        names = ["coop_gym.envs.core", "coop_gym.model.dynamics", "estimator.identification.identify",
                 "estimator.compiled.rng"]
        print(any(k._cache.source_guard.checked for n in names for k in guarded_kernels(n)))
        """
    )
    assert _run(code, ROOT) == "False"


_GAIN = "from numba import njit\n\n@njit(inline='always')\ndef gain():\n    return {}\n"


def test_editing_an_inlined_dependency_recompiles_the_kernel(tmp_path: Path) -> None:
    write_toy_package(
        tmp_path,
        dep=_GAIN.format(1),
        kern="from numba import njit\n\nfrom estimator.compiled.cache import guard_kernel_cache\n"
        "from toy.dep import gain\n\n"
        "@njit(cache=True)\ndef kernel():\n    return 10 * gain()\n\nguard_kernel_cache(__name__)\n",
    )
    code = "from toy.kern import kernel; print(kernel(), kernel.stats.cache_hits)"
    assert _run(code, tmp_path).split()[0] == "10"
    assert _run(code, tmp_path).split() != ["10", "[]"]  # second run: from the cache
    (tmp_path / "toy" / "dep.py").write_text(_GAIN.format(2))
    assert _run(code, tmp_path).split()[0] == "20"


@pytest.mark.parametrize(
    "module", ["coop_gym.envs.core", "estimator.identification.identify", "coop_gym.model.dynamics"]
)
def test_project_sources_stay_inside_the_project(module: str) -> None:
    assert all(ROOT in p.parents for p in project_sources(module))


def _read_only_copy(tmp_path: Path) -> tuple[Path, dict[str, str]]:
    """A copy of the packages where no cache folder Numba knows of can be created, and its environment.

    Permissions do not stop root, so each folder is blocked by a regular file where the folder
    would go: ``__pycache__`` in every package, ``HOME`` (hence ``~/.cache``) and
    ``NUMBA_CACHE_DIR`` under a file.
    """
    site = tmp_path / "site"
    for package in ("coop_gym", "estimator"):
        shutil.copytree(ROOT / package, site / package, ignore=shutil.ignore_patterns("__pycache__"))
    for folder in [site, *(p for p in site.rglob("*") if p.is_dir())]:
        (folder / "__pycache__").write_text("")
    home = tmp_path / "home"
    home.write_text("")
    env = {**os.environ, "PYTHONPATH": str(site), "HOME": str(home), "NUMBA_CACHE_DIR": str(home / "numba")}
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    for name in ("XDG_CACHE_HOME", "NUMBA_DISABLE_JIT", "NUMBA_CACHE_LOCATOR_CLASSES"):
        env.pop(name, None)
    env[ENV_SWITCH] = "0"
    return site, env


def _first_steps(env_id: str) -> list[list[float]]:
    import gymnasium as gym

    import coop_gym  # noqa: F401

    env = gym.make(env_id)
    rows = [env.reset(seed=5)[0].tolist()]
    rows += [env.step([1, 2, 0])[0].tolist() for _ in range(3)]
    return rows


READ_ONLY_RUN = """
import json, warnings
warnings.simplefilter("always")
with warnings.catch_warnings(record=True) as caught:
    import gymnasium as gym
    import coop_gym
    env = gym.make("CoopGym/SitToStand-v0")
    rows = [env.reset(seed=5)[0].tolist()]
    rows += [env.step([1, 2, 0])[0].tolist() for _ in range(3)]
print(json.dumps({"file": coop_gym.__file__, "rows": rows,
                  "warnings": [f"{w.category.__name__}: {w.message}" for w in caught]}))
"""


def test_a_read_only_install_runs_uncached_with_one_warning(tmp_path: Path) -> None:
    site, env = _read_only_copy(tmp_path)
    before = sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*"))
    result = json.loads(run_python(READ_ONLY_RUN, env=env, cwd=tmp_path).splitlines()[-1])
    assert Path(result["file"]).is_relative_to(site)
    cache_warnings = [w for w in result["warnings"] if w.startswith("KernelCacheWarning")]
    assert len(cache_warnings) == 1, result["warnings"]
    assert "NUMBA_CACHE_DIR" in cache_warnings[0]
    assert result["rows"] == _first_steps("CoopGym/SitToStand-v0")  # the cached kernels' numbers
    assert sorted(p.relative_to(tmp_path) for p in tmp_path.rglob("*")) == before  # nothing written


def test_kernels_of_modules_outside_the_compiled_boundary_keep_numbas_error(tmp_path: Path) -> None:
    """The last-resort locator serves only modules built on ``compiled``; others fail as before."""
    _, env = _read_only_copy(tmp_path)
    (tmp_path / "site" / "plain.py").write_text(
        "from numba import njit\n\n@njit(cache=True)\ndef kernel():\n    return 1\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", "import estimator.compiled.cache, plain"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert out.returncode != 0
    assert "no locator available" in out.stderr


def _toy_package(tmp_path: Path, kernels: str) -> dict[str, str]:
    """Package ``toy`` with module ``kern`` (``kernels``, guarded) under ``tmp_path``; the environment to run it in."""
    write_toy_package(
        tmp_path,
        kern="import numpy as np\nfrom numba import njit\n\nfrom estimator.compiled.cache import guard_kernel_cache\n\n"
        f"{kernels}\n\nguard_kernel_cache(__name__)\n",
    )
    return _compiled_here(tmp_path, NUMBA_CACHE_DIR=str(tmp_path / "cache"))


def test_a_cache_folder_that_fails_later_costs_one_warning_not_the_run(tmp_path: Path) -> None:
    """Writable when the kernels were decorated, gone when they compile: they run uncached."""
    env = _toy_package(
        tmp_path,
        "@njit(cache=True)\ndef kernel(x):\n    return 2 * x\n\n"
        "@njit(cache=True)\ndef other(x):\n    return kernel(x) + 1",
    )
    code = textwrap.dedent(
        """
        import os, shutil, warnings
        warnings.simplefilter("always")
        from toy.kern import kernel, other
        shutil.rmtree(os.environ["NUMBA_CACHE_DIR"])
        open(os.environ["NUMBA_CACHE_DIR"], "w").close()  # a file where the folder was
        with warnings.catch_warnings(record=True) as caught:
            print(kernel(3), other(3.0), [w.category.__name__ for w in caught])
        """
    )
    assert run_python(code, env=env, timeout=300).split(maxsplit=2) == ["6", "7.0", "['KernelCacheWarning']"]


def test_a_warm_start_loads_kernels_without_numbas_registries_or_parsing_sources(tmp_path: Path) -> None:
    """Loading from the cache imports none of Numba's implementation registries and parses no source."""
    env = _toy_package(
        tmp_path,
        "@njit(cache=True)\ndef kernel(n):\n    out = np.empty(n)\n    for i in range(n):\n        out[i] = i * 0.5\n"
        "    return out",
    )
    code = textwrap.dedent(
        """
        import sys
        from estimator.compiled import cache
        parsed = []
        original = cache._imported_names
        cache._imported_names = lambda *args: parsed.append(args) or original(*args)
        from toy.kern import kernel
        print(kernel(4).tolist(), "numba.np.arraymath" in sys.modules, len(parsed))
        """
    )
    outputs = [run_python(code, env=env, timeout=300) for _ in range(2)]
    cold, warm = (output.split("]")[1].split() for output in outputs)
    assert cold[0] == "True" and int(cold[1]) > 0  # compiled: registries imported, sources parsed
    assert warm == ["False", "0"]
    assert outputs[1].startswith("[0.0, 0.5, 1.0, 1.5]")
