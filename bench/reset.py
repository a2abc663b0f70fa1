"""Resetting many envs against stepping them, in the same process and run.

A ``reset(seed=s)`` of the vector env seeds every env's generator and starts its episode; a
step advances every env by one action. Both are timed on the same ``make_vec`` env, alternating,
after one untimed reset and step (the kernels compiled or loaded from the cache, the arrays
touched)::

    python bench/reset.py                          # 10^5 envs, 3 repeats
    python bench/reset.py --num-envs 1000000 --repeats 2

Reported: the median and range of a reset and of a step [s], their ratio, and the load average.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import gymnasium as gym
import numpy as np

import coop_gym  # noqa: F401  (registers the ids)


def main() -> None:
    """Time ``reset(seed=...)`` and ``step`` of one vector env, alternating."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="CoopGym/SitToStand-v0")
    parser.add_argument("--num-envs", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    envs = gym.make_vec(args.env, num_envs=args.num_envs, vectorization_mode="vector_entry_point")
    space = envs.single_action_space
    actions = np.zeros((args.num_envs, *(space.shape or ())), dtype=space.dtype)  # wait, every env
    t = time.perf_counter()
    envs.reset(seed=0)
    first_reset = time.perf_counter() - t
    envs.step(actions)
    resets, steps = [], []
    for k in range(args.repeats):
        t = time.perf_counter()
        envs.reset(seed=k + 1)
        resets.append(time.perf_counter() - t)
        t = time.perf_counter()
        envs.step(actions)
        steps.append(time.perf_counter() - t)
    reset, step = statistics.median(resets), statistics.median(steps)
    print(f"{args.env}, {args.num_envs} envs, load average {os.getloadavg()[0]:.1f}")
    print(f"first reset (compiles or loads the kernels, touches the arrays): {first_reset:.3f} s")
    print(f"reset: {reset:.3f} s ({min(resets):.3f}..{max(resets):.3f}), {reset / args.num_envs * 1e6:.2f} µs/env")
    print(f"step:  {step:.3f} s ({min(steps):.3f}..{max(steps):.3f}), {step / args.num_envs * 1e6:.2f} µs/env")
    print(f"reset / step: {reset / step:.2f}")


if __name__ == "__main__":
    main()
