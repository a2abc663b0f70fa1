"""Fresh Python processes for the compiled-boundary tests: their environment, a run, a toy package, a rollout.

Shared by ``test_background.py``, ``test_cache.py`` and ``test_disable_jit.py``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

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
        for push, verbal in np.random.default_rng(4).integers(0, 3, size=(8, 2)):
            obs, reward, terminated, truncated, info = env.step([int(push), int(verbal), 0])
            rows.append([*obs.tolist(), reward, info["true_x_m"], info["true_xi"]])
        out[env_id] = rows
    """
)
"""Eight steps of each env id given as an argument (observations, rewards, the true state) into ``out``;
the code a test appends prints it."""


def environment(*paths: Path, **variables: str) -> dict[str, str]:
    """This process's environment for a child: ``paths`` and the checkout importable, the JIT on, ``variables`` set."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([*(str(p) for p in paths), str(ROOT)])}
    env.pop("NUMBA_DISABLE_JIT", None)
    env.update(variables)
    return env


def run_python(code: str, *args: str, env: dict[str, str], cwd: Path = ROOT, timeout: float = 600) -> str:
    """What ``code``, run with ``args`` in a fresh process that must succeed, prints (stripped)."""
    out = subprocess.run(
        [sys.executable, "-c", code, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout
    )
    assert out.returncode == 0, out.stderr
    return out.stdout.strip()


def write_toy_package(folder: Path, **modules: str) -> None:
    """Package ``toy`` under ``folder``, with a module of each keyword's name and source."""
    package = folder / "toy"
    package.mkdir()
    (package / "__init__.py").write_text("")
    for name, source in modules.items():
        (package / f"{name}.py").write_text(source)
