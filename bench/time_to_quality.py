"""Time to a good caregiver: held-out success against training wall-clock seconds.

    python bench/time_to_quality.py [--env ID] [--budget-s S] [--eval-every-s S] [--episodes N]
                                    [--seed S] [--out DIR] [--contenders a,b] [--save [PATH]]

What a user waits for is wall-clock time from starting to train to a policy that beats
the handbook caregiver. In one run, one after the other, this trains

- ``default``: ``train.py``'s configuration for ``--env`` (``agents/trainer/hyperparams.py``: its
  env count, persona set, batched env adapter, ``VecNormalize``, tuned PPO; training is
  cut by the clock, not a step budget, so a linearly decaying learning rate stays at its
  start value);
- ``default@N``: the same on ``N`` envs with ``n_steps`` scaled so each update still takes
  ``n_envs * n_steps`` samples (learner sizing: fewer, wider policy calls per sample);
- ``first_script``: what a user writes first --
  ``PPO("MlpPolicy", make_vec_env(env_id, n_envs=8))`` with SB3's default hyperparameters
  on a ``DummyVecEnv`` of 8 ``gymnasium.make`` envs (the env's default personas: the
  training set).

Every ``--eval-every-s`` seconds of training (checked at rollout boundaries) the clock
stops and the policy plays the same ``--episodes`` seeded episodes on the held-out
personas through :func:`agents.evaluate.evaluate`; the evaluation's own time is not
counted. The handbook caregiver plays the same episodes first. A contender *reaches
handbook level* at the first evaluation whose success rate is at least the lower end of
the handbook's 95 % Wilson interval on those episodes -- statistically no worse than the
handbook (on the paper's model the handbook succeeds ~100 % of the time, and demanding
500/500 would time a lucky draw, not a caregiver). The report gives each contender's time to that point (or
"not within the budget") and the ratio ``default / first_script`` (an upper bound when
the first script never got there). Torch uses one thread; both contenders train on the
same machine in the same process, so a change of load between them is the main source of
error -- the report records the load average before and after each.

Writes ``time_to_quality_<env>.json`` and ``time_to_quality_<env>.png`` (the curves) into
``--out``; ``--save`` also writes the report to ``bench/results/time_to_quality_<env>.json``
(``bench/result_files.py``; ``<env>`` is the id with ``/`` as ``-``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import add_save_argument, save

from coop_gym.cli import output_path_problem, positive_int

CONTENDERS: tuple[str, ...] = ("default", "first_script")


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}") from None
    if not value > 0 or value != value or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _resized(config: Any, n_envs: int) -> Any:
    """``config`` on ``n_envs`` envs with the same samples per update (``n_envs * n_steps``)."""
    batch = config.n_envs * config.algo_kwargs["n_steps"]
    if n_envs < 1 or batch % n_envs:
        raise ValueError(f"default@N: N must divide the {batch}-step rollout of train.py's config, got {n_envs}")
    return config.replace(n_envs=n_envs, algo_kwargs={**config.algo_kwargs, "n_steps": batch // n_envs})


def _contender(text: str) -> str:
    if text in CONTENDERS:
        return text
    if text.startswith("default@") and text.partition("@")[2].isdigit() and int(text.partition("@")[2]) > 0:
        return text
    raise argparse.ArgumentTypeError(f"unknown contender {text!r}; known: {', '.join(CONTENDERS)}, default@N")


def _build(contender: str, env_id: str, seed: int) -> Any:
    """The SB3 model of ``contender`` on fresh training envs."""
    from stable_baselines3 import PPO
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import VecNormalize

    from agents.rl import make_model, make_train_env
    from agents.trainer.hyperparams import hyperparams_for

    if contender == "default" or contender.startswith("default@"):
        config = hyperparams_for("ppo", env_id)
        if contender != "default":
            config = _resized(config, int(contender.partition("@")[2]))
        env = make_train_env(env_id, config.n_envs, seed, personas=config.personas)
        if config.normalize:
            env = VecNormalize(env, norm_obs=True, norm_reward=False)
        return make_model(config, env, seed)
    # What a user writes first: SB3's defaults, 8 single envs.
    return PPO("MlpPolicy", make_vec_env(env_id, n_envs=8, seed=seed), seed=seed, device="cpu")


def _clock(
    contender: str,
    budget_s: float,
    every_s: float,
    target: float,
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
            self.reached: float | None = None

        def _on_step(self) -> bool:
            return True

        def _on_rollout_end(self) -> None:
            now = time.perf_counter()
            self.train_s += now - self.since
            if self.train_s >= self.next_eval or self.train_s >= budget_s:
                self.next_eval = self.train_s + every_s
                point = {"train_s": self.train_s, "timesteps": int(self.num_timesteps), **score()}
                points.append(point)
                print(
                    f"  {contender}: {point['train_s']:7.1f} s {point['timesteps']:>9} steps  "
                    f"success {point['success_rate']:.3f} unsafe {point['unsafe_rate']:.3f}",
                    flush=True,
                )
                if self.reached is None and point["success_rate"] >= target:
                    self.reached = self.train_s
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
    target: float,
    stop_at_target: bool,
) -> dict[str, Any]:
    """Train ``contender`` for ``budget_s`` seconds of training time, evaluating on the way."""
    from stable_baselines3.common.callbacks import BaseCallback

    from agents.evaluate import evaluate
    from agents.rl import ObsNormalizer, SB3Agent, find_vec_normalize

    model = _build(contender, env_id, seed)
    points: list[dict[str, Any]] = []

    def score() -> dict[str, Any]:
        normalizer = ObsNormalizer.from_vec_normalize(find_vec_normalize(model.get_env()))
        agent = SB3Agent(model, "ppo", env_id, normalizer)
        result = evaluate(agent, env_id, "test", episodes, eval_seed, n_envs=min(64, episodes))
        return {"success_rate": result.success_rate, "unsafe_rate": result.unsafe_rate}

    clock = _clock(contender, budget_s, every_s, target, score, points)

    class Budget(BaseCallback):
        def _on_step(self) -> bool:
            elapsed = clock.train_s + time.perf_counter() - clock.since
            return elapsed < budget_s and not (stop_at_target and clock.reached is not None)

    load_before = os.getloadavg()
    model.learn(total_timesteps=10**12, callback=[clock, Budget()])
    if not points or points[-1]["timesteps"] != int(model.num_timesteps):
        clock._on_rollout_end()  # a final point where training stopped
    return {
        "contender": contender,
        "curve": points,
        "time_to_target_s": clock.reached,
        "timesteps": int(model.num_timesteps),
        "train_s": clock.train_s,
        "steps_per_s": int(model.num_timesteps) / clock.train_s if clock.train_s > 0 else None,
        "load_before": load_before,
        "load_after": os.getloadavg(),
    }


def _plot(report: dict[str, Any], path: Path) -> None:
    from agents.tools.plots import _pyplot
    from coop_gym.io import save_figure

    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(7, 4))
    for run in report["runs"]:
        xs = [0.0] + [p["train_s"] for p in run["curve"]]
        ys = [0.0] + [100 * p["success_rate"] for p in run["curve"]]
        ax.plot(xs, ys, marker="o", ms=3, label=f"{run['contender']} ({run['steps_per_s'] or 0:.0f} steps/s)")
    ax.axhline(100 * report["handbook_success"], color="#757575", ls="--", label="handbook caregiver")
    ax.axhline(100 * report["target_success"], color="#757575", ls=":", label="target (handbook's 95 % CI low end)")
    ax.set_xlabel("training wall-clock time [s] (evaluations not counted)")
    ax.set_ylabel("held-out success [%]")
    ax.set_ylim(0, 100)
    ax.set_title(f"{report['env_id']}: time to a good caregiver ({report['episodes']} episodes per point)")
    ax.legend(loc="lower right", fontsize=8)
    ax.grid(alpha=0.3)
    save_figure(fig, path)
    plt.close(fig)


def run(
    env_id: str,
    budget_s: float,
    every_s: float,
    episodes: int,
    seed: int,
    contenders: tuple[str, ...] = CONTENDERS,
    stop_at_target: bool = False,
) -> dict[str, Any]:
    """Measure every contender; returns the report (see the module docstring)."""
    import torch

    from agents.evaluate import evaluate

    torch.set_num_threads(1)
    eval_seed = 1_000_000
    handbook = evaluate("handbook", env_id, "test", episodes, eval_seed)
    from estimator.compiled import background

    background.wait()  # on a fresh cache: train on compiled kernels, not their Python twins
    target = handbook.interval("success")[0]
    print(
        f"{env_id}: handbook {handbook.success_rate:.3f} success on {episodes} held-out episodes; "
        f"target {target:.3f} (its 95 % interval's lower end)",
        flush=True,
    )
    runs = [
        _train_with_clock(c, env_id, seed, budget_s, every_s, episodes, eval_seed, target, stop_at_target)
        for c in contenders
    ]
    times = {r["contender"]: r["time_to_target_s"] for r in runs}
    ratio: dict[str, Any] | None = None
    if "default" in times and "first_script" in times and times["default"] is not None:
        first = times["first_script"]
        ratio = {
            "value": times["default"] / (first if first is not None else budget_s),
            "bound": "exact" if first is not None else "upper (first_script did not reach the target)",
        }
    return {
        "env_id": env_id,
        "episodes": episodes,
        "eval_seed": eval_seed,
        "seed": seed,
        "budget_s": budget_s,
        "handbook_success": handbook.success_rate,
        "handbook_unsafe": handbook.unsafe_rate,
        "target_success": target,
        "runs": runs,
        "time_ratio_default_vs_first_script": ratio,
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
    from agents.trainer.hyperparams import hyperparams_for

    for c in contenders:
        if c.startswith("default@"):
            try:
                _resized(hyperparams_for("ppo", env_id), int(c.partition("@")[2]))
            except ValueError as error:
                parser.error(f"--contenders: {error}")
    return contenders


def main(argv: list[str] | None = None) -> int:
    """Parse the flags, measure, write the JSON and the PNG."""
    from coop_gym.io import write_json
    from coop_gym.registration import HARD_ENV_ID

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--env", default=HARD_ENV_ID, help=f"env id (default: the hard level, {HARD_ENV_ID})")
    parser.add_argument("--budget-s", type=_positive_float, default=900.0, help="training seconds per contender")
    parser.add_argument("--eval-every-s", type=_positive_float, default=30.0, help="training seconds between scores")
    parser.add_argument("--episodes", type=positive_int, default=500, help="held-out episodes per score")
    parser.add_argument("--seed", type=int, default=0, help="training seed")
    parser.add_argument("--out", default="bench/out", help="folder for time_to_quality.{json,png}")
    parser.add_argument(
        "--contenders",
        default=",".join(CONTENDERS),
        help="comma-separated contenders: default, first_script, or default@N (train.py's config on N envs, "
        "the same samples per update)",
    )
    parser.add_argument("--stop-at-target", action="store_true", help="stop a contender once it reaches the target")
    add_save_argument(parser, "time_to_quality_<env>.json")
    args = parser.parse_args(argv)
    contenders = _checked_contenders(parser, args.env, args.contenders)
    problem = output_path_problem(args.out, folder=True)
    if problem:
        parser.error(f"--out: {problem}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report = run(args.env, args.budget_s, args.eval_every_s, args.episodes, args.seed, contenders, args.stop_at_target)
    stem = args.env.replace("/", "-")
    write_json(out / f"time_to_quality_{stem}.json", report)
    _plot(report, out / f"time_to_quality_{stem}.png")
    for r in report["runs"]:
        reached = "not within the budget" if r["time_to_target_s"] is None else f"{r['time_to_target_s']:.0f} s"
        rate = f"{r['steps_per_s']:.0f} steps/s"
        print(f"{r['contender']:>13}: handbook level after {reached} ({r['timesteps']} steps, {rate})")
    ratio = report["time_ratio_default_vs_first_script"]
    if ratio is not None:
        print(f"time ratio default / first script: {ratio['value']:.3f} ({ratio['bound']})")
    if args.save:
        save(args.save.replace("<env>", stem), "time_to_quality", argv, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
