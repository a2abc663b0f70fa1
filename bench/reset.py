"""Resetting many envs against stepping them, in the same process and run.

A ``reset(seed=s)`` of the vector env seeds every env's generator and starts its episode; a
step advances every env by one action. Both are timed on the same ``make_vec`` env, alternating,
after one untimed reset and step (the kernels compiled or loaded from the cache, the arrays
touched)::

    python bench/reset.py                          # 10^5 envs, 3 repeats
    python bench/reset.py --num-envs 1000000 --repeats 2

Reported: the median and range of a reset and of a step [s], their ratio (per repeat, then the
median), and the load average. ``--save`` also writes the report to ``bench/results/reset.json``
(``bench/result_files.py``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
import gymnasium as gym
import numpy as np
from result_files import add_save_argument, save, summary

import coop_gym  # noqa: F401  (registers the ids)
from coop_gym.cli import positive_int
from estimator.compiled import background


def main(argv: list[str] | None = None) -> None:
    """Time ``reset(seed=...)`` and ``step`` of one vector env, alternating."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="CoopGym/SitToStand-v0")
    parser.add_argument("--num-envs", type=positive_int, default=100_000)
    parser.add_argument("--repeats", type=positive_int, default=3)
    add_save_argument(parser, "reset.json")
    args = parser.parse_args(argv)
    envs = gym.make_vec(args.env, num_envs=args.num_envs, vectorization_mode="vector_entry_point")
    space = envs.single_action_space
    actions = np.zeros((args.num_envs, *(space.shape or ())), dtype=space.dtype)  # wait, every env
    t = time.perf_counter()
    envs.reset(seed=0)
    first_reset = time.perf_counter() - t
    envs.step(actions)
    background.wait()  # time compiled kernels, not their first calls' Python twins (a fresh cache)
    resets, steps = [], []
    for k in range(args.repeats):
        t = time.perf_counter()
        envs.reset(seed=k + 1)
        resets.append(time.perf_counter() - t)
        t = time.perf_counter()
        envs.step(actions)
        steps.append(time.perf_counter() - t)
    report = {
        "env_id": args.env,
        "num_envs": args.num_envs,
        "repeats": args.repeats,
        "first_reset_s": first_reset,
        "reset_s": summary(resets),
        "step_s": summary(steps),
        "reset_over_step": summary([r / s for r, s in zip(resets, steps, strict=True)]),
    }
    reset, step = report["reset_s"], report["step_s"]
    print(f"{args.env}, {args.num_envs} envs, load average {os.getloadavg()[0]:.1f}")
    print(f"first reset (compiles or loads the kernels, touches the arrays): {first_reset:.3f} s")
    for name, s in (("reset", reset), ("step ", step)):
        per_env = s["median"] / args.num_envs * 1e6
        print(f"{name}: {s['median']:.3f} s ({s['min']:.3f}..{s['max']:.3f}), {per_env:.2f} µs/env")
    print(f"reset / step: {report['reset_over_step']['median']:.2f}")
    if args.save:
        save(args.save, "reset", argv, report)


if __name__ == "__main__":
    main()
