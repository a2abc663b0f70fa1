"""The speed sections of ``docs/BENCHMARKS.md``.

Against Gymnasium, cold start, reset, threads, time to quality, rendering, soak.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import (
    TIMES,
    Results,
    _count,
    _from_results,
    _kwargs,
    _mb,
    _missing,
    _pct,
    _provenance,
    _spread,
    _table,
)


def _ppo_rows(r: dict[str, Any], m: dict[str, Any], s: dict[str, Any]) -> list[list[str]]:
    """The SB3 PPO rows of ``bench/run.py``'s table: the adapter and the no-work bound, per setting."""
    rows = []
    for setting, suffix in (("rollout", ""), ("default", "_default")):
        rows += [
            [
                f"PPO ({setting} setting), batched env via the SB3 adapter vs `DummyVecEnv` of {s['ppo_envs']}",
                _spread(r[f"ppo_speedup_vector_adapter{suffix}"]),
                f"{_count(m[f'ppo_adapter_timesteps_per_s{suffix}']['median'])} vs "
                f"{_count(m[f'ppo_dummy_timesteps_per_s{suffix}']['median'])} steps/s",
            ],
            [
                f"PPO ({setting} setting), a VecEnv that does no work vs `DummyVecEnv`: the bound",
                _spread(r[f"ppo_speedup_upper_bound{suffix}"]),
                f"{_count(m[f'ppo_null_env_timesteps_per_s{suffix}']['median'])} steps/s",
            ],
        ]
    return rows


@_from_results("run", "## Speed\n\n### Against Gymnasium's reference", "python bench/run.py")
def against_gymnasium(report: dict[str, Any], record: dict[str, Any]) -> str:
    r, m, s = report["ratios"], report["measurements"], report["settings"]
    n = s["vector_envs"]
    rows = [
        [
            "single env via `gymnasium.make` vs `CartPole-v1`",
            _spread(r["single_ratio_vs_cartpole"]),
            f"{_count(m['single_steps_per_s']['median'])} vs "
            f"{_count(m['cartpole_single_steps_per_s']['median'])} steps/s",
        ]
    ]
    for t in s["vector_threads"]:
        default = " (the default here)" if t == min(s["vector_default_threads"], max(s["vector_threads"])) else ""
        rows.append(
            [
                f"vector env vs `CartPoleVectorEnv`, {n} envs, {t} thread{'s' if t > 1 else ''}{default}",
                _spread(r[f"vector_ratio_vs_cartpole_vector_threads{t}"]),
                f"{_count(m[f'vector_env_steps_per_s_threads{t}']['median'])} vs "
                f"{_count(m['cartpole_vector_env_steps_per_s']['median'])} env-steps/s",
            ]
        )
    if "vector_thread_scaling" in r:
        rows.append([f"vector env, {max(s['vector_threads'])} threads over 1", _spread(r["vector_thread_scaling"]), ""])
    rows += _ppo_rows(r, m, s)
    table = _table(["figure", "ratio, median (min..max)", "absolute, median"], rows)
    goal = 0.25
    vector = r["vector_ratio_vs_cartpole_vector"]
    met = "met" if vector["median"] >= goal else "**not met**"
    load = report["load"]
    return f"""`python bench/run.py` measures the envs against Gymnasium's reference in the same run: median
of {s["repeats"]} repeats, each alternating the contenders in {s["blocks_per_repeat"]} blocks (load average
{load["load_average_1min_at_start"]:.1f} at the start, {load["load_average_1min_at_end"]:.1f} at the end). Random
actions, sampled up front; the PPO settings are `rollout` ({_kwargs(s["ppo_settings"]["rollout"])}: collecting
experience dominates) and `default` ({_kwargs(s["ppo_settings"]["default"])}: SB3's epochs, gradient
steps dominate), torch on one thread.

{table}

The issue's goal of {goal}{TIMES} `CartPoleVectorEnv` is {met}: {vector["median"]:.2f}{TIMES} in the median,
{vector["max"]:.2f}{TIMES} in the best repeat.

`CartPoleVectorEnv` is single-threaded NumPy: one noiseless Euler step per env. The physics and
the filter run in compiled (numba) kernels shared by the single and the vector env; one
simulated env-step draws the person's noise, advances the person model and runs the 4-state
Kalman filter over its sub-steps, which CartPole does not have. Around the compiled step, the
vector env's bookkeeping is compiled too: actions are decoded and range-checked in one call,
step counts, rewards and episode ends in one pass, every env's infos gathered in one pass, and
the people reset in a step get their zero-order hold computed in one batch. PPO's own work
bounds the adapter's gain (the no-work VecEnv's row). What would reach the goal (a
structure-of-arrays kernel with the envs in the inner loop) is described in
[Architecture](ARCHITECTURE.md).
"""


@_from_results("cold_start", "### Cold start", "python bench/cold_start.py")
def cold_start(report: dict[str, Any], record: dict[str, Any]) -> str:
    rows = [
        [
            f"`{label}`",
            _spread(run["cold_s"], unit=" s"),
            "" if "compiled_s" not in run else _spread(run["compiled_s"], digits=1, unit=" s"),
            _spread(run["warm_s"], unit=" s"),
            _spread(run["import_s"], unit=" s"),
            _spread(run["cold_ratio"], digits=1),
            _spread(run["warm_ratio"], digits=1),
        ]
        for label, run in report["runs"].items()
    ]
    table = _table(
        [
            f"`{report['env_id']}`",
            "cold first step",
            "cold: kernels compiled after",
            "warm first step",
            "`import coop_gym`",
            "cold / CartPole",
            "warm / CartPole",
        ],
        rows,
    )
    goal_s = 5.0
    verdicts = []
    for label, run in report["runs"].items():
        cold = run["cold_s"]["median"]
        verdicts.append(f"{'met' if cold <= goal_s else '**not met**'} by `{label}` ({cold:.2f} s)")
    return f"""The kernels compile on a fresh install and load from numba's cache after that; while a kernel is
missing from the cache, its calls run as Python and a background process compiles it
(`estimator/compiled/background.py`). `python bench/cold_start.py` times the first
`gym.make`/`make_vec` + reset + step in fresh processes with an empty cache (cold; then how long
after `make` the background compile finished) and with the cache the cold run filled (warm),
{report["repeats"]} repeats, and the whole wait (import + make + reset + step) over the same wait for
`CartPole-v1`, timed in fresh processes around each repeat:

{table}

Every kernel is compiled with NumPy's error model (no `ZeroDivisionError` checks and their
message formatting in each division), the reset kernel copies element by element (no
shape-mismatch formatting), and the filter's rarely used covariance repair has its own 4{TIMES}4
Jacobi eigensolver instead of LAPACK's `eigh`. `--kernels` lists what compiles and for how long:
most of it is the one step kernel (`coop_gym/envs/kernels/step.py`). The goal of ≤ {goal_s:.0f} s to the cold
first step (the median) is {", ".join(verdicts)}.
"""


@_from_results("reset", "### Reset", "python bench/reset.py")
def reset(report: dict[str, Any], record: dict[str, Any]) -> str:
    n = report["num_envs"]
    per_env = 1e6 / n
    return f"""`python bench/reset.py` times `reset(seed=s)` of a `make_vec` env of {_count(n)} envs (every env's
generator seeded and its episode started) against one step of the same env, alternating,
{report["repeats"]} repeats: a reset takes {_spread(report["reset_over_step"])} steps' time
({report["reset_s"]["median"] * per_env:.2f} µs per env against {report["step_s"]["median"] * per_env:.2f} µs).
"""


def threads(results: Results) -> str:
    record = results.get("run")
    scaling = None if record is None else record["results"]["ratios"].get("vector_thread_scaling")
    settings = {} if record is None else record["results"]["settings"]
    cores = None if record is None else record["machine"]["cpu_count"]
    measured = (
        ""
        if scaling is None
        else f"""
Measured in the run above: {_spread(scaling)} for {settings["vector_envs"]} envs on
{max(settings["vector_threads"])} threads over 1, on a machine of {cores} cores shared with other
jobs (a ratio under 1 means the second thread found no free core).
"""
    )
    return f"""\
### Threads

The vector env's compiled step runs on several threads
(`gym.make_vec(id, n, vectorization_mode="vector_entry_point", threads=k)`; the default,
`threads=None`, uses every core this process may run on): each thread runs one GIL-free kernel
that claims blocks of envs from an atomic counter (`coop_gym/envs/kernels/atomics.py`) until none is
left, each env drawing only from its own generator, so the results are bit-identical whatever the
thread count (`tests/coop_gym/test_threads.py`). The calling thread does the step's autoresets
while the worker wakes, and it waits for the worker's last block by reading the counter in a
kernel, not on a lock. Small batches step on one thread (`coop_gym/envs/kernels/threads.py`). Several
processes that each step large batches on one machine (say, RLlib runners) should pass
`threads=1`: each would otherwise take every core. Numba's own `parallel=True`/`prange` is not
used: next to torch's OpenMP runtime its spinning threads slow the step down.
{measured}"""


def time_to_quality(results: Results) -> str:
    head = "### Time to a good caregiver\n"
    records = [(stem, r) for stem, r in sorted(results.items()) if stem.startswith("time_to_quality_")]
    intro = """
`python bench/time_to_quality.py --env ID` trains learners one after another (or two at a time,
each in its own process, with `--jobs 2`), scoring held-out success on the same episodes at
intervals of training time (evaluation time not counted), and reports the training time each
needs to reach a scripted caregiver's level (the low end of its 95 % interval on those
episodes; the target counts successes only). Contenders: `default` is `train.py --framework sb3`'s
configuration, `jax` `train.py`'s learner (`agents.ppo`) with `--policy-lag 0` on its sizing,
`default@N` SB3 on `N` envs with the same samples per update (`default@16` is SB3 on `jax`'s
configuration), `jax-lag` `jax` with `policy_lag=1` (each update runs on a second core while the
next rollout plays: `train.py`'s learner on `-v2`), `jax@N-eE` `jax` on `N` envs with `E` epochs
per update, `first_script` SB3's defaults on 8 `gymnasium.make` envs. In records saved while
`JaxPPO` was the JAX learner, `jax` / `jax-lag` name `JaxPPO` and `ppo` / `ppo-lag` `agents.ppo`. A change of load
between runs moves the ratios (the results file holds the load average before and after each).
"""
    if not records:
        return head + intro + "\n" + _missing("python bench/time_to_quality.py") + "\n"
    sections = [head + intro]
    for stem, record in records:
        report = record["results"]
        body = _ttq_seeds(report, f"img/{stem}.png") if "contenders" in report else _ttq_one_seed(report)
        sections.append(f"{_provenance(record)}\n\n{body}")
    return "\n".join(sections)


def _ttq_seeds(report: dict[str, Any], image: str) -> str:
    """A record of several seeds and targets: per contender, steps/s, ratio, time to each target per seed, IQM.

    ``image``: the bench's PNG of the record, copied into ``docs/img`` under the record's name.
    """
    import statistics

    targets = report["targets"]
    rows = []
    first = next(iter(report["contenders"].values()))
    # Ratios to each SB3 contender of the run (older files: to `default` only).
    bases = list(first.get("steps_per_s_ratio_to", {"default": None}))
    for name, row in report["contenders"].items():
        cells = [f"`{name}`", _count(row["steps_per_s_median"] or 0)]
        for base in bases:
            ratios = (row.get("steps_per_s_ratio_to") or {"default": row.get("steps_per_s_ratio_to_default")})[base]
            cells.append(f"{statistics.median(ratios):.2f}{TIMES}" if ratios else "")
        for target in targets:
            times = [t[target] for t in row["time_to_targets_s"].values()]
            reached = sorted(t for t in times if t is not None)
            median = f"median {statistics.median(reached):.0f} s" if len(reached) == len(times) else ""
            cells.append(
                f"{len(reached)}/{len(times)} seeds; "
                + ", ".join("-" if t is None else f"{t:.0f}" for t in times)
                + (f" s; {median}" if median else " s")
            )
        last = row["iqm_curve"][-1] if row["iqm_curve"] else None
        cells.append(
            ""
            if last is None
            else f"{_pct(last['success_iqm'])} [{_pct(last['ci95'][0])}, {_pct(last['ci95'][1])}] at "
            f"{last['train_s_median']:.0f} s, {_count(last['timesteps_median'])} steps"
        )
        rows.append(cells)
    header = ["contender", "steps/s (median)"]
    header += [f"steps/s {TIMES} `{base}`'s (median over seeds)" for base in bases]
    header += [f"time to the {t} level (per seed)" for t in targets]
    header += ["held-out success at the last score, IQM over seeds"]
    levels = ", ".join(f"{name} {_pct(t['success'])} (target {_pct(t['level'])})" for name, t in targets.items())
    seeds = ", ".join(str(s) for s in report["seeds"])
    steps = report.get("budget_steps")
    budget = f"{report['budget_s']:.0f} s of training per run" + (
        f" and at most {_count(steps)} env steps, the learning rate decaying to 0 over them as in `train.py`"
        if steps
        else " (the learning rate at its start value: no step budget)"
    )
    return f"""`{report["env_id"]}`, training seeds {seeds}, {report["episodes"]} held-out
episodes per score, a budget of {budget}, {report.get("jobs", 1)} run(s) at a
time; on those episodes: {levels}:

{_table(header, rows)}

![Held-out success against training seconds and env steps, every seed of every contender]({image})
"""


def _ttq_one_seed(report: dict[str, Any]) -> str:
    """A record of one seed and the handbook target (the format before several seeds)."""
    rows = []
    for run in report["runs"]:
        reached = run["time_to_target_s"]
        at = next((p for p in run["curve"] if reached is not None and p["train_s"] == reached), None)
        rows.append(
            [
                f"`{run['contender']}`",
                "not within the budget" if reached is None else f"{reached:.0f} s",
                ""
                if at is None
                else f"{_count(at['timesteps'])} steps, {_pct(at['success_rate'])} success, "
                f"{_pct(at['unsafe_rate'])} unsafe",
                _count(run["steps_per_s"] or 0),
            ]
        )
    table = _table(["contender", "time to the handbook level", "there", "steps/s"], rows)
    ratio = report["time_ratio_default_vs_first_script"]
    ratio_text = (
        "no ratio: the default did not reach the target"
        if ratio is None
        else f"ratio default / first script **{ratio['value']:.2f}** ({ratio['bound']})"
    )
    return f"""`{report["env_id"]}`, one training seed ({report["seed"]}), {report["episodes"]} held-out
episodes per score, a budget of {report["budget_s"]:.0f} s of training per contender; the handbook succeeds on
{_pct(report["handbook_success"])} of them (target {_pct(report["target_success"])}):

{table}

{ratio_text}.
"""


@_from_results("render", "### Rendering", "python bench/render.py")
def rendering(report: dict[str, Any], record: dict[str, Any]) -> str:
    return f"""`python bench/render.py` times `render()` of `rgb_array` frames of `CoopGym/SitToStand-v0` and of
`CartPole-v1` (both pygame, 600 {TIMES} 400, a step between frames, alternating blocks;
{report["repeats"]} repeats of {report["frames_per_repeat"]} frames): ours
{_spread(report["ours_ms_per_frame"], unit=" ms")} a frame, CartPole's
{_spread(report["cartpole_ms_per_frame"], unit=" ms")}, a ratio of **{_spread(report["ratio"])}**.
Rendering speed is measured here, against a reference, not asserted in a test.
"""


@_from_results("soak", "### Soak", "python bench/soak.py")
def soak(report: dict[str, Any], record: dict[str, Any]) -> str:
    cov = report["covariances"]
    checks = "no NaN or infinity" if not report["failures"] else "failures: " + "; ".join(report["failures"])
    spd = (
        "covariances symmetric positive definite and within their bounds at the end"
        if isinstance(cov, dict) and cov.get("ok")
        else "covariance checks **failed**"
    )
    return f"""Long run, not in the test suite: `python bench/soak.py` steps the {report["mode"]} with random
actions: {_count(report["env_steps"])} env-steps ({_count(report["episodes_ended"])} episodes ended) in
{report["wall_s"]:.0f} s, {checks}; resident memory {_mb(report["rss_start_mb"])} at the start,
{_mb(report["rss_after_10pct_mb"])} after 10 % of the run (compilation and warm-up behind it: growth after it
would be a leak), {_mb(report["rss_end_mb"])} at the end (peak {_mb(report["rss_peak_mb"])}); {spd}.
"""
