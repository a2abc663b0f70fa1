"""Speed of the envs, measured against CartPole in the same run (ratios, not absolute times).

    python bench/run.py [--json] [--repeats N] [--quick] [--save [PATH]]

Three comparisons. In each repeat the contenders run in alternating blocks (4 each) so a
change in machine load hits all of them; a repeat gives one rate per contender and one
ratio. Every figure is the median over ``--repeats`` repeats with its min..max spread
(ratios are taken per repeat, then their median):

1. single env: steps/s of ``gymnasium.make("CoopGym/SitToStand-v0")`` vs
   ``gymnasium.make("CartPole-v1")`` (all wrappers ``make`` adds), random actions sampled
   up front, ``reset()`` whenever an episode ends;
2. batched env: env-steps/s of ``gymnasium.make_vec(..., num_envs=1024)`` -- our
   :class:`coop_gym.envs.vector.SitToStandVectorEnv` on 1 and on 2 threads (its ``threads``
   keyword; the results are the same numbers either way) vs Gymnasium's ``CartPoleVectorEnv``,
   which is single-threaded NumPy -- with random actions sampled up front (autoreset: next
   step). The three alternate block by block in one run;
3. SB3 PPO: timesteps/s of ``PPO("MlpPolicy").learn(T)`` on our env with 8 envs, as a
   ``DummyVecEnv`` of 8 ``Monitor``-wrapped single envs vs the batched env through
   :class:`agents.rl.sb3_vec.SB3VecEnvAdapter`. Two settings: ``rollout`` (``n_steps=64``,
   one epoch over one 512-sample batch: collecting experience dominates, where the env
   speed shows) and ``default`` (SB3's 10 epochs of 64-sample minibatches: gradient steps
   dominate and the env matters less). A third, no-work ``VecEnv`` measures PPO's own
   cost per timestep: ``ppo_speedup_upper_bound`` is the most any env could gain over
   ``DummyVecEnv`` (Amdahl's law).

Random actions lift half the time, so the single- and batched-env figures include a reset
about every second step (CartPole's random episodes last ~22 steps).
Torch runs on one thread. ``--quick`` shrinks every run (for a smoke test, not for numbers).
``--save`` also writes the report to ``bench/results/run.json`` (``bench/result_files.py``), from
which ``python bench/report.py`` renders ``docs/BENCHMARKS.md``.
JSON keys: ``single_ratio_vs_cartpole``, ``vector_ratio_vs_cartpole_vector`` (our env on as
many threads as the machine has cores, :func:`coop_gym.envs.core.available_threads`),
``vector_ratio_vs_cartpole_vector_threads1`` / ``_threads2``, ``vector_thread_scaling`` (2 threads
over 1; the load average says how busy the machine was),
``ppo_speedup_vector_adapter`` (the ``rollout`` setting), ``ppo_speedup_vector_adapter_default``,
``ppo_speedup_upper_bound[_default]``, and the absolute figures under ``measurements``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
import gymnasium as gym
import numpy as np
from result_files import add_save_argument, save, summary

from coop_gym.cli import positive_int as _positive_int
from coop_gym.envs.core import available_threads
from estimator.compiled import background

ENV_ID = "CoopGym/SitToStand-v0"
CARTPOLE_ID = "CartPole-v1"
VECTOR_ENVS = 1024
VECTOR_THREADS = (1, 2)
PPO_ENVS = 8
PPO_SETTINGS: dict[str, dict[str, Any]] = {
    "rollout": {"n_steps": 64, "batch_size": 512, "n_epochs": 1},
    "default": {"n_steps": 64, "batch_size": 64, "n_epochs": 10},
}


class SingleEnvRunner:
    """Steps one ``gymnasium.make`` env under random actions sampled up front, a block at a time."""

    def __init__(self, env_id: str, block: int, blocks: int, seed: int) -> None:
        """Make the env, sample every action and warm up (compiled code loaded, caches filled)."""
        self.env = gym.make(env_id)
        self.env.action_space.seed(seed)
        self.actions = [self.env.action_space.sample() for _ in range(block * blocks)]
        self.block = block
        self.done = 0
        self.env.reset(seed=seed)
        self._run(self.actions[:200])
        self.env.reset(seed=seed)

    def _run(self, actions: list[Any]) -> None:
        env = self.env
        for action in actions:
            _, _, terminated, truncated, _ = env.step(action)
            if terminated or truncated:
                env.reset()

    def __call__(self) -> int:
        """Run the next block; returns the steps taken."""
        actions = self.actions[self.done : self.done + self.block]
        self._run(actions)
        self.done += len(actions)
        return len(actions)


class VectorEnvRunner:
    """Steps an id's own batched env (``vector_entry_point``, 1024 envs), a block at a time."""

    def __init__(self, env_id: str, block: int, blocks: int, seed: int, **kwargs: Any) -> None:
        """Make the env (``kwargs``: its keywords), sample every action batch and warm up."""
        self.envs = gym.make_vec(env_id, num_envs=VECTOR_ENVS, vectorization_mode="vector_entry_point", **kwargs)
        self.envs.action_space.seed(seed)
        self.actions = [self.envs.action_space.sample() for _ in range(block * blocks)]
        self.block = block
        self.done = 0
        self.envs.reset(seed=seed)
        for action in self.actions[:5]:
            self.envs.step(action)

    def __call__(self) -> int:
        """Run the next block; returns the env-steps taken."""
        actions = self.actions[self.done : self.done + self.block]
        for action in actions:
            self.envs.step(action)
        self.done += len(actions)
        return len(actions) * VECTOR_ENVS


def _null_vec_env(n_envs: int) -> Any:
    """A ``VecEnv`` with our spaces that does no work: PPO's own cost, the bound on any speed-up."""
    from stable_baselines3.common.vec_env import VecEnv

    single = gym.make(ENV_ID)

    class NullVecEnv(VecEnv):
        def __init__(self) -> None:
            self.render_mode = None
            super().__init__(n_envs, single.observation_space, single.action_space)
            self._obs = np.zeros((n_envs, *np.shape(single.observation_space.sample())), dtype=np.float32)
            self._count = 0

        def reset(self) -> Any:
            return self._obs.copy()

        def step_async(self, actions: Any) -> None:
            self._count += 1

        def step_wait(self) -> Any:
            # Episodes of two steps, like random actions on our env.
            dones = np.full(n_envs, self._count % 2 == 0)
            infos = [{"terminal_observation": self._obs[0]} if done else {} for done in dones]
            return self._obs.copy(), np.zeros(n_envs, dtype=np.float32), dones, infos

        def close(self) -> None:
            pass

        def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
            return [getattr(self, attr_name)] * n_envs

        def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
            setattr(self, attr_name, value)

        def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list[Any]:
            return [None] * n_envs

        def env_is_wrapped(self, wrapper_class: Any, indices: Any = None) -> list[bool]:
            return [False] * n_envs

    return NullVecEnv()


class PPORunner:
    """``PPO("MlpPolicy")`` with 8 envs on a backend ("dummy", "adapter" or "null"), learning a block at a time."""

    def __init__(self, backend: str, setting: str, block: int, seed: int) -> None:
        """Build the VecEnv and the model and warm up (torch's first passes, compiled code)."""
        from stable_baselines3 import PPO
        from stable_baselines3.common.monitor import Monitor
        from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv

        from agents.rl.sb3_vec import make_sb3_vec_env

        venv: VecEnv
        if backend == "dummy":
            venv = DummyVecEnv([lambda: Monitor(gym.make(ENV_ID)) for _ in range(PPO_ENVS)])
            venv.seed(seed)
        elif backend == "adapter":
            venv = make_sb3_vec_env(ENV_ID, PPO_ENVS, seed)
        else:
            venv = _null_vec_env(PPO_ENVS)
        self.model = PPO("MlpPolicy", venv, seed=seed, device="cpu", verbose=0, **PPO_SETTINGS[setting])
        self.model.learn(PPO_ENVS * PPO_SETTINGS[setting]["n_steps"])
        self.block = block

    def __call__(self) -> int:
        """Learn the next block of timesteps; returns the timesteps taken."""
        before = self.model.num_timesteps
        self.model.learn(self.block, reset_num_timesteps=False)
        return self.model.num_timesteps - before


def interleaved(runners: list[Callable[[], int]], blocks: int) -> list[float]:
    """Rates (units/s) of the runners, their blocks alternating so load changes hit all of them."""
    background.wait()  # compiled kernels, not their first calls' Python twins (estimator.compiled.background)
    units = [0] * len(runners)
    seconds = [0.0] * len(runners)
    for _ in range(blocks):
        for k, run_block in enumerate(runners):
            start = time.perf_counter()
            units[k] += run_block()
            seconds[k] += time.perf_counter() - start
    return [u / t for u, t in zip(units, seconds, strict=True)]


def _ppo_runners(setting: str, block: int) -> Callable[[int], list[Callable[[], int]]]:
    """Per repeat ``r``: PPO runners on the adapter, DummyVecEnv and the no-work VecEnv, seeded ``r``."""
    return lambda r: [PPORunner(backend, setting, block, r) for backend in ("adapter", "dummy", "null")]


Measure = Callable[[str, tuple[str, ...], Callable[[int], list[Callable[[], int]]]], list[list[float]]]
"""``measure(label, names, make)``: ``repeats`` interleaved measurements, rates[k][r] of runner k in repeat r."""


def _measurer(repeats: int, blocks: int) -> Measure:
    def measure(
        label: str, names: tuple[str, ...], make: Callable[[int], list[Callable[[], int]]]
    ) -> list[list[float]]:
        """``repeats`` interleaved measurements; rates[k][r] of runner k in repeat r."""
        print(label, file=sys.stderr)
        rates: list[list[float]] = [[] for _ in names]
        for r in range(repeats):
            for k, rate in enumerate(interleaved(make(r), blocks)):
                rates[k].append(rate)
            shown = "  ".join(f"{name}: {rates[k][-1]:,.0f}" for k, name in enumerate(names))
            print(f"  [{r + 1}/{repeats}] {shown}", file=sys.stderr)
        return rates

    return measure


def _ratio(a: list[float], b: list[float]) -> dict[str, float]:
    return summary([x / y for x, y in zip(a, b, strict=True)])


def _single(measure: Measure, block: int, blocks: int, measurements: dict[str, Any], ratios: dict[str, Any]) -> None:
    """The single env against CartPole-v1."""
    ours, cartpole = measure(
        "single env steps/s (gymnasium.make)",
        (ENV_ID, CARTPOLE_ID),
        lambda r: [SingleEnvRunner(i, block, blocks, r) for i in (ENV_ID, CARTPOLE_ID)],
    )
    measurements["single_steps_per_s"] = summary(ours)
    measurements["cartpole_single_steps_per_s"] = summary(cartpole)
    ratios["single_ratio_vs_cartpole"] = _ratio(ours, cartpole)


def _vector(measure: Measure, block: int, blocks: int, measurements: dict[str, Any], ratios: dict[str, Any]) -> None:
    """The batched env on each thread count against CartPoleVectorEnv."""
    threads = list(VECTOR_THREADS)
    *ours_by_threads, cartpole = measure(
        f"batched env-steps/s ({VECTOR_ENVS} envs; ours on {threads} threads, CartPole's single-threaded NumPy)",
        (*(f"{ENV_ID} threads={t}" for t in threads), "CartPoleVectorEnv"),
        lambda r: [
            *(VectorEnvRunner(ENV_ID, block, blocks, r, threads=t) for t in threads),
            VectorEnvRunner(CARTPOLE_ID, block, blocks, r),
        ],
    )
    measurements["cartpole_vector_env_steps_per_s"] = summary(cartpole)
    for t, ours in zip(threads, ours_by_threads, strict=True):
        measurements[f"vector_env_steps_per_s_threads{t}"] = summary(ours)
        ratios[f"vector_ratio_vs_cartpole_vector_threads{t}"] = _ratio(ours, cartpole)
    # The headline figures: our env as users get it, with the default thread count.
    default = min(available_threads(), max(threads))
    measurements["vector_env_steps_per_s"] = measurements[f"vector_env_steps_per_s_threads{default}"]
    ratios["vector_ratio_vs_cartpole_vector"] = ratios[f"vector_ratio_vs_cartpole_vector_threads{default}"]
    if len(threads) > 1:
        ratios["vector_thread_scaling"] = _ratio(ours_by_threads[-1], ours_by_threads[0])


def _ppo(measure: Measure, block: int, measurements: dict[str, Any], ratios: dict[str, Any]) -> None:
    """SB3 PPO through the adapter, through DummyVecEnv and on a no-work VecEnv, per setting."""
    for setting in PPO_SETTINGS:
        adapter, dummy, null = measure(
            f"PPO timesteps/s, {PPO_ENVS} envs, setting {setting!r} {PPO_SETTINGS[setting]}",
            ("adapter", "DummyVecEnv", "no-work VecEnv (PPO's own cost)"),
            _ppo_runners(setting, block),
        )
        suffix = "" if setting == "rollout" else f"_{setting}"
        measurements[f"ppo_adapter_timesteps_per_s{suffix}"] = summary(adapter)
        measurements[f"ppo_dummy_timesteps_per_s{suffix}"] = summary(dummy)
        measurements[f"ppo_null_env_timesteps_per_s{suffix}"] = summary(null)
        ratios[f"ppo_speedup_vector_adapter{suffix}"] = _ratio(adapter, dummy)
        # No env can make PPO faster than the no-work VecEnv does.
        ratios[f"ppo_speedup_upper_bound{suffix}"] = _ratio(null, dummy)


def run(repeats: int, quick: bool) -> dict[str, Any]:
    """All measurements; returns the JSON-ready report."""
    import torch

    torch.set_num_threads(1)
    load_at_start = os.getloadavg()[0]
    blocks = 1 if quick else 4
    single_block = 1_000 if quick else 8_000
    vector_block = 5 if quick else 50
    ppo_block = 512 if quick else 2_048  # 4 blocks of 4 rollouts of 8 x 64 = 8192 timesteps
    measurements: dict[str, Any] = {}
    ratios: dict[str, Any] = {}
    measure = _measurer(repeats, blocks)
    _single(measure, single_block, blocks, measurements, ratios)
    _vector(measure, vector_block, blocks, measurements, ratios)
    _ppo(measure, ppo_block, measurements, ratios)
    return {
        **{key: value["median"] for key, value in ratios.items()},
        "ratios": ratios,
        "measurements": measurements,
        "settings": {
            "repeats": repeats,
            "quick": quick,
            "blocks_per_repeat": blocks,
            "single_steps_per_repeat": single_block * blocks,
            "vector_envs": VECTOR_ENVS,
            "vector_steps_per_repeat": vector_block * blocks,
            "vector_threads": list(VECTOR_THREADS),
            "vector_default_threads": available_threads(),
            "ppo_envs": PPO_ENVS,
            "ppo_timesteps_per_repeat": ppo_block * blocks,
            "ppo_settings": PPO_SETTINGS,
            "torch_threads": 1,
        },
        "load": {
            "load_average_1min_at_end": os.getloadavg()[0],
            "load_average_1min_at_start": load_at_start,
            "cpu_count": os.cpu_count(),
        },
    }


def _table(report: dict[str, Any]) -> str:
    m, r = report["measurements"], report["ratios"]

    def fmt(s: dict[str, Any]) -> str:
        return f"{s['median']:>14,.0f}  ({s['min']:,.0f} .. {s['max']:,.0f})"

    def rfmt(s: dict[str, Any]) -> str:
        return f"{s['median']:>14.3f}  ({s['min']:.3f} .. {s['max']:.3f})"

    lines = [
        f"median (min .. max) of {report['settings']['repeats']} repeats",
        f"single env steps/s, {ENV_ID:<28}{fmt(m['single_steps_per_s'])}",
        f"single env steps/s, {CARTPOLE_ID:<28}{fmt(m['cartpole_single_steps_per_s'])}",
        f"  ratio single_ratio_vs_cartpole{'':<17}{rfmt(r['single_ratio_vs_cartpole'])}",
    ]
    for t in report["settings"]["vector_threads"]:
        label = f"vector env-steps/s, SitToStandVectorEnv x{VECTOR_ENVS} threads={t}"
        lines += [
            f"{label:<48}{fmt(m[f'vector_env_steps_per_s_threads{t}'])}",
            f"{f'  ratio vector_ratio_vs_cartpole_vector_threads{t}':<48}"
            f"{rfmt(r[f'vector_ratio_vs_cartpole_vector_threads{t}'])}",
        ]
    default = report["settings"]["vector_default_threads"]
    lines += [
        f"{f'vector env-steps/s, CartPoleVectorEnv x{VECTOR_ENVS}':<48}{fmt(m['cartpole_vector_env_steps_per_s'])}",
        f"{f'  ratio vector_ratio_vs_cartpole_vector (threads={default})':<48}"
        f"{rfmt(r['vector_ratio_vs_cartpole_vector'])}",
    ]
    if "vector_thread_scaling" in r:
        lines.append(f"{'  ratio vector_thread_scaling (2 threads / 1)':<48}{rfmt(r['vector_thread_scaling'])}")
    for setting in PPO_SETTINGS:
        suffix = "" if setting == "rollout" else f"_{setting}"
        lines += [
            f"PPO timesteps/s [{setting}], adapter x{PPO_ENVS:<17}{fmt(m[f'ppo_adapter_timesteps_per_s{suffix}'])}",
            f"PPO timesteps/s [{setting}], DummyVecEnv x{PPO_ENVS:<13}{fmt(m[f'ppo_dummy_timesteps_per_s{suffix}'])}",
            f"  ratio ppo_speedup_vector_adapter{suffix:<15}{rfmt(r[f'ppo_speedup_vector_adapter{suffix}'])}",
            f"PPO timesteps/s [{setting}], no-work VecEnv x{PPO_ENVS:<10}"
            f"{fmt(m[f'ppo_null_env_timesteps_per_s{suffix}'])}",
            f"  bound ppo_speedup_upper_bound{suffix:<18}{rfmt(r[f'ppo_speedup_upper_bound{suffix}'])}",
        ]
    machine = report["load"]
    lines.append(
        f"load average (1 min) at the start: {machine['load_average_1min_at_start']:.2f}, "
        f"at the end: {machine['load_average_1min_at_end']:.2f} (on {machine['cpu_count']} cores)"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Parse the flags, run, print a table (or JSON with ``--json``)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", action="store_true", help="print the report as JSON on stdout")
    parser.add_argument("--repeats", type=_positive_int, default=5, help="repeats of each measurement (default 5)")
    parser.add_argument("--quick", action="store_true", help="small runs: a smoke test, not numbers")
    add_save_argument(parser, "run.json")
    args = parser.parse_args(argv)
    report = run(args.repeats, args.quick)
    print(json.dumps(report, indent=2) if args.json else _table(report))
    if args.save:
        save(args.save, "run", argv, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
