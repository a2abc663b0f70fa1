"""Time to a good caregiver: held-out success against training wall-clock seconds, learner against learner.

    python bench/time_to_quality.py [--env ID] [--budget-s S] [--budget-steps N] [--eval-every-s S]
                                    [--episodes N] [--seeds 0,1,2] [--jobs J] [--targets prober,belief]
                                    [--out DIR] [--contenders a,b] [--stop-at-target] [--save [PATH]]

What a user waits for is wall-clock time from starting to train to a policy that plays as
well as a scripted caregiver. For every training seed this trains, one contender after the
other (or ``--jobs`` at a time, each in its own process):

- ``default``: ``train.py``'s configuration for ``--env`` (``agents/hyperparams.py``: its
  env count, persona set, batched env adapter, ``VecNormalize``, tuned SB3 PPO; training is
  cut by the clock, so a linearly decaying learning rate stays at its start value, unless
  ``--budget-steps N`` also ends it after ``N`` steps, the learning rate decaying over them as
  ``train.py``'s does over its budget);
- ``jax``: ``train.py``'s learner, :class:`agents.ppo.PPO` (flax networks, optax, coop_gym's
  vector env), on its own sizing (``hyperparams_for(..., framework="jax")``) with
  ``policy_lag=0`` (``train.py --policy-lag 0``), each update between two rollouts;
- ``jax-lag``: ``jax`` with ``policy_lag=1`` (each update runs on XLA's thread while the next
  rollout plays): ``train.py``'s learner on the hard level ``-v2``;
- ``default@N`` / ``jax@N`` / ``jax-lag@N``: any of these on ``N`` envs with ``n_steps`` scaled so each update still
  takes ``n_envs * n_steps`` samples (``default@N`` at the jax sizing's env count is SB3 on the
  same configuration as ``jax``); ``@N-eE`` also sets ``E`` epochs per update;
- ``first_script``: what a user writes first --
  ``PPO("MlpPolicy", make_vec_env(env_id, n_envs=8))`` with SB3's default hyperparameters
  on a ``DummyVecEnv`` of 8 ``gymnasium.make`` envs (the env's default personas: the
  training set).

Every ``--eval-every-s`` seconds of training (checked at rollout boundaries) the clock
stops and the policy plays the same ``--episodes`` seeded episodes on the held-out
personas through :func:`agents.evaluate.evaluate`; the evaluation's own time is not
counted. The ``--targets`` (scripted caregivers; default: the handbook on the paper's levels,
the prober and the belief caregiver on the hard ones) play the same episodes first. A
contender *reaches* a target at the first evaluation whose success rate is at least the
lower end of the target's 95 % Wilson interval on those episodes -- statistically no worse
than it. The report gives, per contender and seed, the steps/s and the training time to each
target (or "not within the budget"); per contender, the interquartile mean over seeds of
the success at each evaluation with a stratified bootstrap interval; and, per seed, the ratio
of each contender's steps/s to ``default``'s. Torch and XLA use one thread; the load average
before and after each run is recorded (contenders running side by side with ``--jobs 2``
share the machine evenly).

Writes ``time_to_quality_<env>.json`` and ``time_to_quality_<env>.png`` (the curves) into
``--out``; ``--save`` also writes the report to ``bench/results/time_to_quality_<env>.json``
(``bench/result_files.py``; ``<env>`` is the id with ``/`` as ``-``).
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import add_save_argument, import_learners, iqm_ci, resized, save, sizing

from coop_gym.cli import output_path_problem, positive_int, seed_list

CONTENDERS: tuple[str, ...] = ("default", "jax", "jax-lag", "first_script")
_CONFIGURED = ("default", "jax", "jax-lag")
"""The contenders built from ``train.py``'s settings (:func:`_config`), which take a sizing ``@N``."""


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}") from None
    if not value > 0 or value != value or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _contender(text: str) -> str:
    if text in CONTENDERS:
        return text
    kind, _, size = text.partition("@")
    if kind in _CONFIGURED and sizing(size) is not None:
        return text
    raise argparse.ArgumentTypeError(
        f"unknown contender {text!r}; known: {', '.join(CONTENDERS)}, default@N, jax@N, jax-lag@N "
        "(also @N-eE: E epochs)"
    )


def _config(kind: str, env_id: str) -> Any:
    """``train.py``'s PPO configuration of contender kind ``kind`` (one of :data:`_CONFIGURED`)."""
    from agents.hyperparams import hyperparams_for

    config = hyperparams_for("ppo", env_id, "sb3" if kind == "default" else "jax")
    if kind != "default":
        config = config.replace(algo_kwargs={**config.algo_kwargs, "policy_lag": int(kind.endswith("-lag"))})
    return config


def _sized_config(contender: str, env_id: str) -> Any:
    """The configuration of a contender built from ``train.py``'s settings (``KIND`` or ``KIND@SIZE``)."""
    kind, _, size = contender.partition("@")
    config = _config(kind, env_id)
    return resized(config, size) if size else config


def _build(contender: str, env_id: str, seed: int) -> Any:
    """The SB3 model of an SB3 contender (``default``, ``default@N``, ``first_script``) on fresh training envs."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env

    from agents.rl import make_model, make_train_env

    if contender.partition("@")[0] == "default":
        config = _sized_config(contender, env_id)
        env = make_train_env(env_id, config.n_envs, seed, personas=config.personas, normalize=config.normalize)
        return make_model(config, env, seed)
    # What a user writes first: SB3's defaults, 8 single envs.
    return PPO("MlpPolicy", make_vec_env(env_id, n_envs=8, seed=seed), seed=seed, device="cpu")


def _clock(
    label: str,
    budget_s: float,
    every_s: float,
    targets: dict[str, float],
    score: Callable[[], dict[str, Any]],
    points: list[dict[str, Any]],
) -> Any:
    """An SB3 callback that counts training time (not evaluation time) and scores every ``every_s``."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Clock(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.train_s = 0.0
            self.since = time.perf_counter()
            self.next_eval = every_s
            self.reached: dict[str, float | None] = dict.fromkeys(targets)
            self.final = False  # set once training has stopped: score where it stopped

        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            now = time.perf_counter()
            if self.final or self.train_s + now - self.since >= min(self.next_eval, budget_s):
                # A lagged update may still run: training time, not the evaluation's.
                getattr(self.model, "wait_for_update", lambda: None)()
                now = time.perf_counter()
            self.train_s += now - self.since
            if self.final or self.train_s >= self.next_eval or self.train_s >= budget_s:
                self.next_eval = self.train_s + every_s
                point = {"train_s": self.train_s, "timesteps": int(self.num_timesteps), **score()}
                points.append(point)
                print(
                    f"  {label}: {point['train_s']:7.1f} s {point['timesteps']:>9} steps  "
                    f"success {point['success_rate']:.3f} unsafe {point['unsafe_rate']:.3f}",
                    flush=True,
                )
                for name, level in targets.items():
                    if self.reached[name] is None and point["success_rate"] >= level:
                        self.reached[name] = self.train_s
            self.since = time.perf_counter()  # evaluation time is not training time

        def _on_training_start(self) -> None:
            self.since = time.perf_counter()

    return Clock()


def _train_with_clock(
    contender: str,
    env_id: str,
    seed: int,
    budget_s: float,
    every_s: float,
    episodes: int,
    eval_seed: int,
    targets: dict[str, float],
    stop_at_target: bool,
    budget_steps: int | None = None,
) -> dict[str, Any]:
    """Train ``contender`` for ``budget_s`` seconds of training (at most ``budget_steps`` steps), scoring on the way."""
    import torch
    from stable_baselines3.common.callbacks import BaseCallback

    from estimator.compiled import background

    torch.set_num_threads(1)
    background.wait()  # on a fresh cache: train on compiled kernels, not their Python twins
    if contender.startswith("jax"):
        return _train_ppo_with_clock(
            contender, env_id, seed, budget_s, every_s, episodes, eval_seed, targets, budget_steps
        )
    model = _build(contender, env_id, seed)
    points: list[dict[str, Any]] = []

    def score() -> dict[str, Any]:
        return _held_out(model, env_id, episodes, eval_seed)

    clock = _clock(f"{contender} seed {seed}", budget_s, every_s, targets, score, points)

    class Budget(BaseCallback):
        def _on_step(self) -> bool:
            elapsed = clock.train_s + time.perf_counter() - clock.since
            done = stop_at_target and all(t is not None for t in clock.reached.values())
            return elapsed < budget_s and not done

    load_before = os.getloadavg()
    model.learn(total_timesteps=budget_steps or 10**12, callback=[clock, Budget()])
    return _record(contender, seed, model.n_envs, int(model.num_timesteps), clock, points, load_before)


def _held_out(model: Any, env_id: str, episodes: int, eval_seed: int) -> dict[str, Any]:
    """Success and unsafe rates of an SB3 ``model`` (its observation normaliser read from its env) held-out."""
    from agents.evaluate import evaluate
    from agents.rl import ObsNormalizer, SB3Agent, find_vec_normalize

    agent = SB3Agent(model, "ppo", env_id, ObsNormalizer.from_vec_normalize(find_vec_normalize(model.get_env())))
    result = evaluate(agent, env_id, "test", episodes, eval_seed, n_envs=min(64, episodes))
    return {"success_rate": result.success_rate, "unsafe_rate": result.unsafe_rate}


def _record(
    contender: str, seed: int, n_envs: int, steps: int, clock: Any, points: list[dict[str, Any]], load_before: Any
) -> dict[str, Any]:
    """One run's record, a final score taken where training stopped if the last one was not there."""
    if not points or points[-1]["timesteps"] != steps:
        clock.final = True
        clock.on_rollout_end()
    return {
        "contender": contender,
        "seed": seed,
        "n_envs": n_envs,
        "curve": points,
        "time_to_targets_s": clock.reached,
        "timesteps": steps,
        "train_s": clock.train_s,
        "steps_per_s": steps / clock.train_s if clock.train_s > 0 else None,
        "load_before": load_before,
        "load_after": os.getloadavg(),
    }


def _train_ppo_with_clock(
    contender: str,
    env_id: str,
    seed: int,
    budget_s: float,
    every_s: float,
    episodes: int,
    eval_seed: int,
    targets: dict[str, float],
    budget_steps: int | None,
) -> dict[str, Any]:
    """:func:`_train_with_clock` for :class:`agents.ppo.PPO`: the clock and the scores at its rollout ends."""
    from agents.ppo import PPO, PPOConfig
    from agents.ppo.sb3_format import to_sb3

    config = _sized_config(contender, env_id)
    learner = PPO(env_id, PPOConfig.from_training(config), seed, {"personas": config.personas})
    points: list[dict[str, Any]] = []

    def score() -> dict[str, Any]:
        return _held_out(to_sb3(learner, learner.acting_params), env_id, episodes, eval_seed)  # the next rollout's

    clock = _clock(f"{contender} seed {seed}", budget_s, every_s, targets, score, points)
    clock.model = learner  # the clock reads wait_for_update and num_timesteps

    def at_rollout_end(trained: PPO) -> bool:
        clock.num_timesteps = trained.num_timesteps
        clock.on_rollout_end()
        return clock.train_s < budget_s

    load_before = os.getloadavg()
    clock.since = time.perf_counter()
    learner.learn(budget_steps or 10**12, at_rollout_end)
    return _record(contender, seed, learner.config.n_envs, learner.num_timesteps, clock, points, load_before)


def _plot(report: dict[str, Any], path: Path) -> None:
    from agents.tools.plots import _pyplot
    from coop_gym.io import save_figure

    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for k, (contender, row) in enumerate(report["contenders"].items()):
        for run in (r for r in report["runs"] if r["contender"] == contender):
            for ax, x in zip(axes, ("train_s", "timesteps"), strict=True):
                xs = [0.0] + [p[x] for p in run["curve"]]
                ys = [0.0] + [100 * p["success_rate"] for p in run["curve"]]
                first = run["seed"] == row["seeds"][0]
                label = f"{contender} ({_median_rate(row):.0f} steps/s)" if first else None
                ax.plot(xs, ys, color=colors[k % len(colors)], alpha=0.7, lw=1, label=label)
    for ax in axes:
        for j, (name, target) in enumerate(report["targets"].items()):
            ax.axhline(100 * target["success"], color="#757575", ls=("--", ":", "-.")[j % 3], lw=1, label=name)
        ax.grid(alpha=0.3)
        ax.set_ylim(0, 100)
    axes[0].set_xlabel("training wall-clock time [s] (evaluations not counted)")
    axes[1].set_xlabel("env steps")
    axes[0].set_ylabel("held-out success [%]")
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle(f"{report['env_id']}: time to a good caregiver ({report['episodes']} episodes per point)")
    save_figure(fig, path)
    plt.close(fig)


def _median_rate(row: dict[str, Any]) -> float:
    return float(row["steps_per_s_median"] or 0.0)


def _summary(runs: list[dict[str, Any]], contenders: tuple[str, ...], seeds: list[int]) -> dict[str, Any]:
    """Per contender: steps/s, time to each target per seed, the IQM success curve; steps/s ratios to SB3's.

    ``steps_per_s_ratio_to`` holds, per SB3 contender in the run (``default``, ``default@N``), the
    per-seed ratios of this contender's steps/s to that one's; ``steps_per_s_ratio_to_default``
    repeats those to ``default``.
    """
    out: dict[str, Any] = {}
    for contender in contenders:
        mine = [r for r in runs if r["contender"] == contender]
        rates = [r["steps_per_s"] for r in mine if r["steps_per_s"]]
        curve = []
        for k in range(min(len(r["curve"]) for r in mine)):
            found = iqm_ci([r["curve"][k]["success_rate"] for r in mine])
            curve.append(
                {
                    "train_s_median": statistics.median(r["curve"][k]["train_s"] for r in mine),
                    "timesteps_median": statistics.median(r["curve"][k]["timesteps"] for r in mine),
                    "success_iqm": found["iqm"],
                    "ci95": found["ci95"],
                }
            )
        out[contender] = {
            "seeds": [r["seed"] for r in mine],
            "steps_per_s_median": statistics.median(rates) if rates else None,
            "time_to_targets_s": {r["seed"]: r["time_to_targets_s"] for r in mine},
            "iqm_curve": curve,
        }
    bases = [c for c in contenders if c.partition("@")[0] == "default"]
    for contender in contenders:
        out[contender]["steps_per_s_ratio_to"] = {}
        for name in bases:
            ratios = []
            for seed in seeds:
                base = next(r for r in runs if r["contender"] == name and r["seed"] == seed)
                mine_run = next(r for r in runs if r["contender"] == contender and r["seed"] == seed)
                if base["steps_per_s"] and mine_run["steps_per_s"]:
                    ratios.append(mine_run["steps_per_s"] / base["steps_per_s"])
            out[contender]["steps_per_s_ratio_to"][name] = ratios
        if "default" in bases:
            out[contender]["steps_per_s_ratio_to_default"] = out[contender]["steps_per_s_ratio_to"]["default"]
    return out


def run(
    env_id: str,
    budget_s: float,
    every_s: float,
    episodes: int,
    seeds: list[int],
    contenders: tuple[str, ...] = CONTENDERS,
    targets: tuple[str, ...] = ("handbook",),
    stop_at_target: bool = False,
    jobs: int = 1,
    budget_steps: int | None = None,
) -> dict[str, Any]:
    """Measure every contender on every seed; returns the report (see the module docstring)."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    from agents.evaluate import evaluate

    eval_seed = 1_000_000
    references = {name: evaluate(name, env_id, "test", episodes, eval_seed) for name in targets}
    levels = {name: ref.interval("success")[0] for name, ref in references.items()}
    for name, ref in references.items():
        print(
            f"{env_id}: {name} {ref.success_rate:.3f} success on {episodes} held-out episodes; "
            f"target {levels[name]:.3f} (its 95 % interval's lower end)",
            flush=True,
        )
    tasks = [
        (c, env_id, seed, budget_s, every_s, episodes, eval_seed, levels, stop_at_target, budget_steps)
        for seed in seeds
        for c in contenders
    ]
    if jobs == 1:
        runs = [_train_with_clock(*task) for task in tasks]
    else:
        with ProcessPoolExecutor(jobs, mp_context=get_context("spawn")) as pool:
            runs = list(pool.map(_train_with_clock, *zip(*tasks, strict=True)))
    return {
        "env_id": env_id,
        "episodes": episodes,
        "eval_seed": eval_seed,
        "seeds": seeds,
        "budget_s": budget_s,
        "budget_steps": budget_steps,
        "jobs": jobs,
        "targets": {
            name: {"success": ref.success_rate, "unsafe": ref.unsafe_rate, "level": levels[name]}
            for name, ref in references.items()
        },
        "runs": runs,
        "contenders": _summary(runs, contenders, seeds),
        "cpu_count": os.cpu_count(),
    }


def _checked_contenders(parser: argparse.ArgumentParser, env_id: str, spec: str) -> tuple[str, ...]:
    """The contenders of ``--contenders`` for ``--env``; a parser error names whichever flag is wrong."""
    contenders = tuple(c for c in spec.split(",") if c)
    if not contenders:
        parser.error(f"--contenders: empty; known: {', '.join(CONTENDERS)}, default@N")
    for c in contenders:
        try:
            _contender(c)
        except argparse.ArgumentTypeError as error:
            parser.error(f"--contenders: {error}")

    import coop_gym

    if env_id not in coop_gym.ENV_IDS:
        parser.error(f"--env: unknown env id {env_id!r}; coop_gym ids: {', '.join(coop_gym.ENV_IDS)}")
    for c in contenders:
        if "@" in c:
            try:
                kind, _, size = c.partition("@")
                resized(_config(kind, env_id), size)
            except ValueError as error:
                parser.error(f"--contenders: {c}: {error}")
    return contenders


def _targets(parser: argparse.ArgumentParser, env_id: str, text: str | None) -> tuple[str, ...]:
    """``--targets``: scripted caregivers (default: the handbook; the prober and the belief caregiver on hard ids)."""
    from agents.caregivers.scripted import SCRIPTED_AGENTS

    if text is None:
        return ("prober", "belief") if "Hard" in env_id else ("handbook",)
    names = tuple(n.strip() for n in text.split(",") if n.strip())
    unknown = [n for n in names if n not in SCRIPTED_AGENTS]
    if unknown or not names:
        parser.error(f"--targets: unknown scripted caregiver(s) {unknown}; known: {', '.join(SCRIPTED_AGENTS)}")
    return names


def _parser() -> argparse.ArgumentParser:
    from coop_gym.registration import HARD_ENV_ID

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--env", default=HARD_ENV_ID, help=f"env id (default: the hard level, {HARD_ENV_ID})")
    parser.add_argument("--budget-s", type=_positive_float, default=300.0, help="training seconds per contender")
    parser.add_argument("--eval-every-s", type=_positive_float, default=15.0, help="training seconds between scores")
    parser.add_argument("--episodes", type=positive_int, default=500, help="held-out episodes per score")
    parser.add_argument("--seeds", type=seed_list, default=[0, 1, 2, 3, 4], help="training seeds, joined by ','")
    parser.add_argument("--jobs", type=positive_int, default=1, help="runs at a time, each in its own process")
    parser.add_argument("--targets", default=None, help="scripted caregivers to reach, joined by ','")
    parser.add_argument("--out", default="bench/out", help="folder for time_to_quality.{json,png}")
    parser.add_argument(
        "--contenders",
        default="default,jax",
        help="comma-separated contenders: default, jax, jax-lag, first_script, default@N, jax@N or jax-lag@N "
        "(the config on N envs, the same samples per update)",
    )
    parser.add_argument("--stop-at-target", action="store_true", help="stop a run once it reaches every target")
    parser.add_argument(
        "--budget-steps",
        type=positive_int,
        default=None,
        help="train at most N env steps, the learning rate decaying over them as train.py's (default: the clock alone)",
    )
    add_save_argument(parser, "time_to_quality_<env>.json")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Parse the flags, measure, write the JSON and the PNG."""
    from coop_gym.io import write_json

    parser = _parser()
    args = parser.parse_args(argv)
    contenders = _checked_contenders(parser, args.env, args.contenders)
    targets = _targets(parser, args.env, args.targets)
    problem = output_path_problem(args.out, folder=True)
    if problem:
        parser.error(f"--out: {problem}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report = run(
        args.env,
        args.budget_s,
        args.eval_every_s,
        args.episodes,
        args.seeds,
        contenders,
        targets,
        args.stop_at_target,
        args.jobs,
        args.budget_steps,
    )
    stem = args.env.replace("/", "-")
    write_json(out / f"time_to_quality_{stem}.json", report)
    _plot(report, out / f"time_to_quality_{stem}.png")
    for name, row in report["contenders"].items():
        times = {target: [t[target] for t in row["time_to_targets_s"].values()] for target in report["targets"]}
        reached = "; ".join(
            f"{target}: " + ", ".join("-" if t is None else f"{t:.0f} s" for t in ts) for target, ts in times.items()
        )
        ratio_text = "".join(
            f", x{statistics.median(ratios):.2f} {base}'s"
            for base, ratios in row["steps_per_s_ratio_to"].items()
            if ratios and base != name
        )
        print(f"{name:>13}: {_median_rate(row):.0f} steps/s{ratio_text}; time to {reached}")
    if args.save:
        import_learners(jax=any(c.startswith("jax") for c in contenders))  # trained in workers with --jobs
        save(args.save.replace("<env>", stem), "time_to_quality", argv, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
