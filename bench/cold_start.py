"""Time to the first step: cold (numba compiles the kernels) and warm (they load from its cache).

Each measurement is a fresh Python process that imports coop_gym, makes the env, resets it
and steps it once, timing each part. *Cold* runs get an empty ``NUMBA_CACHE_DIR`` (what a
fresh install meets: nothing compiled yet); *warm* runs reuse the cache the cold run
filled. A cold run's first calls run as Python while a background process compiles the
kernels (``estimator.compiled.background``); it then waits for them, and the time until they
are compiled is reported too. ``--kernels`` also lists the compilations of one more cold run
that compiles them in the calling process (numba's compile events, nested: a kernel's time
includes the functions compiled inside it)::

    python bench/cold_start.py                      # gym.make + make_vec x1024, 3 repeats
    python bench/cold_start.py --repeats 5 --kernels

Reported: median and range of the time from the first ``gym.make``/``make_vec`` call to the
end of the first step (the import of coop_gym is timed on its own), with the load average, and
each as a ratio to a reference timed the same way in the same run, alternating with it: a fresh
process that imports gymnasium and makes, resets and steps ``CartPole-v1`` (import included in
both: what a user waits for before the first step). ``--save`` also writes the report to
``bench/results/cold_start.json`` (``bench/result_files.py``).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import add_save_argument, save, summary

_REFERENCE = r"""
import json, time
t0 = time.perf_counter()
import gymnasium as gym
env = gym.make("CartPole-v1")
env.reset(seed=0)
env.step(env.action_space.sample())
print(json.dumps({"total_s": time.perf_counter() - t0}))
"""

_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import gymnasium as gym
import coop_gym
t1 = time.perf_counter()
from numba.core import event
env_id, n, kernels = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
with event.install_recorder("numba:compile") as rec:
    t2 = time.perf_counter()
    if n == 0:
        env = gym.make(env_id)
    else:
        env = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point")
    t3 = time.perf_counter()
    env.reset(seed=0)
    t4 = time.perf_counter()
    env.step(env.action_space.sample())
    t5 = time.perf_counter()
from estimator.compiled import background
background.wait()  # the kernels a background process compiles while their first calls run as Python
t6 = time.perf_counter()
compiles, stack = [], []
for ts, ev in rec.buffer if kernels else ():
    if ev.is_start:
        stack.append((ev.data["dispatcher"].py_func.__qualname__, ts, len(stack)))
    else:
        name, start, depth = stack.pop()
        compiles.append((start, depth, name, ts - start))
print(json.dumps({"import_s": t1 - t0, "make_s": t3 - t2, "reset_s": t4 - t3, "step_s": t5 - t4,
                  "first_step_s": t5 - t2, "total_s": t5 - t0, "compiled_s": t6 - t2, "compiles": sorted(compiles)}))
"""


def _measure(env_id: str, n: int, cache: str, kernels: bool) -> dict[str, Any]:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    if kernels:  # Numba's compile events are seen in the process that compiles: this one
        env["COOP_GYM_BACKGROUND_COMPILE"] = "0"
    out = subprocess.run(
        [sys.executable, "-c", _CHILD, env_id, str(n), "1" if kernels else "0"],
        env=env, capture_output=True, text=True, check=True,
    )  # fmt: skip
    return json.loads(out.stdout.strip().splitlines()[-1])  # type: ignore[no-any-return]


def _reference() -> float:
    out = subprocess.run([sys.executable, "-c", _REFERENCE], capture_output=True, text=True, check=True)
    return float(json.loads(out.stdout.strip().splitlines()[-1])["total_s"])


def _seconds(values: list[float]) -> str:
    return f"{statistics.median(values):6.2f} s ({min(values):.2f}..{max(values):.2f})"


def _list_kernels(env_id: str, n: int, label: str) -> None:
    """Print a cold run's compilations in the calling process (``--kernels``)."""
    with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache:
        listed = _measure(env_id, n, cache, True)
    print(f"{label}: cold compilations in the calling process (s, nested), first step {listed['first_step_s']:.2f} s")
    for _, depth, name, seconds in listed["compiles"]:
        if seconds >= 0.1:
            print(f"  {'  ' * depth}{seconds:6.2f} {name}")


def _cold_and_warm(env_id: str, n: int, repeats: int, label: str) -> dict[str, Any]:
    """``repeats`` cold runs (empty cache) each followed by a warm one, with CartPole around each; printed."""
    cold, warm, imports, cold_ratio, warm_ratio, reference, compiled = [], [], [], [], [], [], []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache:
            before = _reference()
            first = _measure(env_id, n, cache, False)
            second = _measure(env_id, n, cache, False)
            after = _reference()
        cold.append(first["first_step_s"])
        compiled.append(first["compiled_s"])
        warm.append(second["first_step_s"])
        imports.append(second["import_s"])
        # Import + make + reset + step, each over the mean of the references around it.
        ref = (before + after) / 2
        reference.append(ref)
        cold_ratio.append(first["total_s"] / ref)
        warm_ratio.append(second["total_s"] / ref)
    print(f"{label:>14}: cold {_seconds(cold)}  warm {_seconds(warm)}  import {_seconds(imports)}")
    print(f"{'':>14}  cold: the kernels compiled by the background process {_seconds(compiled).strip()} after make")
    print(
        f"{'':>14}  import+first step / CartPole-v1's ({_seconds(reference).strip()}): "
        f"cold {statistics.median(cold_ratio):.1f}x ({min(cold_ratio):.1f}..{max(cold_ratio):.1f}), "
        f"warm {statistics.median(warm_ratio):.1f}x ({min(warm_ratio):.1f}..{max(warm_ratio):.1f})"
    )
    return {
        "cold_s": summary(cold),
        "warm_s": summary(warm),
        "compiled_s": summary(compiled),
        "import_s": summary(imports),
        "reference_s": summary(reference),
        "cold_ratio": summary(cold_ratio),
        "warm_ratio": summary(warm_ratio),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="CoopGym/SitToStand-v0", help="env id (default: %(default)s)")
    parser.add_argument("--num-envs", type=int, nargs="*", default=[0, 1024], help="0 = gym.make; N = make_vec xN")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--kernels", action="store_true", help="list the cold run's compilations")
    add_save_argument(parser, "cold_start.json")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        parser.error(f"--repeats: must be a positive integer, got {args.repeats}")
    if any(n < 0 for n in args.num_envs):
        parser.error(f"--num-envs: must be >= 0, got {args.num_envs}")
    import coop_gym

    if args.env not in coop_gym.ENV_IDS:
        parser.error(f"--env: unknown env id {args.env!r}")

    results: dict[str, Any] = {
        "env_id": args.env,
        "repeats": args.repeats,
        "load_start": os.getloadavg()[0],
        "runs": {},
    }
    for n in args.num_envs:
        label = "gym.make" if n == 0 else f"make_vec x{n}"
        if args.kernels:
            _list_kernels(args.env, n, label)
        results["runs"][label] = _cold_and_warm(args.env, n, args.repeats, label)
    results["load_end"] = os.getloadavg()[0]
    print(f"load average {results['load_start']:.1f} -> {results['load_end']:.1f}")
    if args.save:
        save(args.save, "cold_start", argv, results)


if __name__ == "__main__":
    main()
