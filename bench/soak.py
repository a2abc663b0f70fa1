"""Soak test: step the env for a long time with random actions and look for slow failures.

    python bench/soak.py [--steps 10000000] [--num-envs 1024] [--seed 0] [--json] [--save [PATH]]

Steps ``gymnasium.make_vec("CoopGym/SitToStand-v0", num_envs=N)`` (the natively batched
vector env, ``coop_gym.envs.vector``) until ``--steps`` env-steps have run, with random
actions (lifting rarely, so episodes run long and the 30 s time limit is hit too). With
``--single`` -- or when the vector env does not exist -- it steps one
``gymnasium.make("CoopGym/SitToStand-v0")`` instead.

Checks: every observation and reward finite (each step), info values finite (every
``--info-every`` steps), and at the end the in-env filter covariances (``core.P``) finite,
symmetric, positive semi-definite and within the bounds the maths guarantees
(``P[0, 0] <= R``, the ``xi`` variance at most its prior plus one ``q_xi`` per filter step).

Reports: env-steps, wall time, env-steps/s, resident memory (VmRSS) at the start, after 10 %
of the run (past compilation and warm-up: growth after it would be a leak) and at the end, its
peak (VmHWM), and the largest covariance entries. Exit status 1 if a check failed.
Not part of the test run (it takes minutes); run it after changing the core or the filter.
``--save`` also writes the report to ``bench/results/soak.json`` (``bench/result_files.py``).
"""

from __future__ import annotations

import argparse
import json
import math
import resource
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
import gymnasium as gym
import numpy as np
from result_files import add_save_argument, save

import coop_gym  # noqa: F401 -- registers the ids

ENV_ID = "CoopGym/SitToStand-v0"
LIFT_PROBABILITY = 0.01  # per action: a lift every ~10 s of simulated time


def rss_mb() -> dict[str, float]:
    """Current and peak resident set size [MB] (Linux /proc; ru_maxrss elsewhere)."""
    out: dict[str, float] = {}
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(("VmRSS:", "VmHWM:")):
                    key, value, _unit = line.split()
                    out[key.rstrip(":")] = int(value) / 1024.0
    except OSError:
        pass
    out.setdefault("VmHWM", resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
    return out


def random_actions(rng: np.random.Generator, count: int, batch: int | None) -> np.ndarray:
    """``count`` MultiDiscrete([3, 3, 2]) actions (``batch`` envs each), lifting rarely."""
    shape = (count, 3) if batch is None else (count, batch, 3)
    actions = rng.integers(0, [3, 3, 2], size=shape)
    actions[..., 2] = rng.random(shape[:-1]) < LIFT_PROBABILITY
    return actions


def finite_info(info: dict[str, Any]) -> bool:
    for value in info.values():
        if isinstance(value, dict):
            if not finite_info(value):
                return False
        elif isinstance(value, (float, int, np.ndarray, np.number)) and not isinstance(value, bool):
            arr = np.asarray(value)
            if arr.dtype.kind in "fc" and not np.all(np.isfinite(arr)):
                return False
    return True


def covariance_report(core: Any) -> dict[str, Any]:
    """Checks of the filter covariances ``core.P`` (N, 4, 4) at the end of the run."""
    P = np.asarray(core.P, dtype=np.float64)
    report: dict[str, Any] = {"n_filters": int(P.shape[0])}
    finite = bool(np.all(np.isfinite(P)))
    report["finite"] = finite
    if not finite:
        report["ok"] = False
        return report
    scale = np.maximum(1.0, np.max(np.abs(P), axis=(-1, -2)))
    asym = float(np.max(np.max(np.abs(P - np.swapaxes(P, -1, -2)), axis=(-1, -2)) / scale))
    min_eig = float(np.min(np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2)))[:, 0] / scale))
    nominal = np.asarray(core.nominal)
    r, q_xi = nominal[:, 10], nominal[:, 9]
    p00_over_r = float(np.max(P[:, 0, 0] / r))
    report.update(
        max_asymmetry=asym,
        min_eigenvalue_over_scale=min_eig,
        max_p00_over_r=p00_over_r,
        max_abs_entry=float(np.max(np.abs(P))),
        max_xi_variance=float(np.max(P[:, 3, 3])),
        max_velocity_variance=float(np.max(P[:, 1, 1])),
        max_intention_variance=float(np.max(P[:, 2, 2])),
        q_xi=float(np.max(q_xi)),
    )
    # P[3, 3] grows by q_xi per filter step at most; an episode lasts at most episode_s.
    timing = core.timing
    xi_bound = 1.0 + (timing.episode_s / timing.dt_s + 1) * float(np.max(q_xi))
    report["xi_variance_bound"] = xi_bound
    report["ok"] = (
        asym <= 1e-12 and min_eig >= -1e-10 and p00_over_r <= 1 + 1e-9 and report["max_xi_variance"] <= xi_bound
    )
    return report


def find_core(env: Any) -> Any:
    for candidate in (env, getattr(env, "unwrapped", None), getattr(env, "env", None)):
        core = getattr(candidate, "core", None)
        if core is not None:
            return core
    return None


def _finish(
    env: Any,
    mode: str,
    env_steps: int,
    episodes: int,
    wall: float,
    start_rss: dict[str, float],
    warm_rss: float | None,
    bad: list[str],
) -> dict[str, Any]:
    """The report of a finished soak, with the end-of-run covariance checks; closes ``env``."""
    end_rss = rss_mb()
    result = {
        "mode": mode,
        "env_steps": env_steps,
        "episodes_ended": episodes,
        "wall_s": wall,
        "env_steps_per_s": env_steps / wall,
        "rss_start_mb": start_rss.get("VmRSS"),
        "rss_after_10pct_mb": warm_rss,
        "rss_end_mb": end_rss.get("VmRSS"),
        "rss_peak_mb": end_rss.get("VmHWM"),
        "failures": bad,
    }
    core = find_core(env)
    result["covariances"] = covariance_report(core) if core is not None else "no core found"
    env.close()
    return result


def soak_vector(num_envs: int, steps: int, seed: int, info_every: int) -> dict[str, Any]:
    env = gym.make_vec(ENV_ID, num_envs=num_envs)
    rng = np.random.default_rng(seed)
    obs, info = env.reset(seed=seed)
    start_rss = rss_mb()
    iterations = math.ceil(steps / num_envs)
    bad: list[str] = []
    episodes = 0
    t0 = time.perf_counter()
    done = 0
    warm_rss: float | None = None
    while done < iterations and not bad:
        chunk = min(1000, iterations - done, max(1, iterations // 10))  # a boundary at 10 %
        if warm_rss is None and done >= iterations // 10:
            warm_rss = rss_mb().get("VmRSS")  # after compilation, caches and the first action bank
        for k, actions in enumerate(random_actions(rng, chunk, num_envs)):
            obs, reward, terminated, truncated, info = env.step(actions)
            if not (np.all(np.isfinite(obs)) and np.all(np.isfinite(reward))):
                bad.append(f"non-finite observation or reward at iteration {done + k}")
                break
            episodes += int(np.count_nonzero(terminated | truncated))
            if (done + k) % info_every == 0 and not finite_info(info):
                bad.append(f"non-finite info at iteration {done + k}")
                break
        done += chunk
    mode = f"vector env ({type(env.unwrapped).__name__}), num_envs={num_envs}"
    return _finish(env, mode, done * num_envs, episodes, time.perf_counter() - t0, start_rss, warm_rss, bad)


def soak_single(steps: int, seed: int, info_every: int) -> dict[str, Any]:
    env = gym.make(ENV_ID)
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    start_rss = rss_mb()
    bad: list[str] = []
    episodes = 0
    done = 0
    t0 = time.perf_counter()
    warm_rss: float | None = None
    while done < steps and not bad:
        chunk = min(100_000, steps - done, max(1, steps // 10))
        if warm_rss is None and done >= steps // 10:
            warm_rss = rss_mb().get("VmRSS")
        for k, action in enumerate(random_actions(rng, chunk, None)):
            obs, reward, terminated, truncated, info = env.step(action)
            if not (np.all(np.isfinite(obs)) and math.isfinite(reward)):
                bad.append(f"non-finite observation or reward at step {done + k}: {obs}, {reward}")
                break
            if (done + k) % info_every == 0 and not finite_info(info):
                bad.append(f"non-finite info at step {done + k}: {info}")
                break
            if terminated or truncated:
                episodes += 1
                env.reset()
        done += chunk
    mode = "single env (gymnasium.make)"
    return _finish(env, mode, done, episodes, time.perf_counter() - t0, start_rss, warm_rss, bad)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=10_000_000, help="env-steps to run in total")
    parser.add_argument("--num-envs", type=int, default=1024, help="envs of the vector env")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--single", action="store_true", help="step one single env instead of the vector env")
    parser.add_argument("--info-every", type=int, default=97, help="check info values every this many steps")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    add_save_argument(parser, "soak.json")
    args = parser.parse_args(argv)
    if args.steps < 1 or args.num_envs < 1 or args.info_every < 1:
        parser.error("--steps, --num-envs and --info-every must be positive")
    if args.single:
        result = soak_single(args.steps, args.seed, args.info_every)
    else:
        result = soak_vector(args.num_envs, args.steps, args.seed, args.info_every)
    covariances = result["covariances"]
    result["ok"] = not result["failures"] and isinstance(covariances, dict) and bool(covariances.get("ok"))
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        for key, value in result.items():
            if isinstance(value, dict):
                print(f"{key}:")
                for k, v in value.items():
                    print(f"  {k}: {v}")
            else:
                print(f"{key}: {value}")
    if args.save:
        save(args.save, "soak", argv, result)
    return 0 if result["ok"] else 1


if __name__ == "__main__":
    sys.exit(main())
