"""The :mod:`agents.ppo` learner in a ``train.py`` run: its episode log, TensorBoard, scores and checkpoints.

:class:`RunHooks` is what the run does at each of the learner's rollout ends (``PPO.learn``'s
``on_rollout``): it appends the finished episodes to ``monitor.csv`` (SB3's monitor format),
logs the losses, episode statistics and outcome rates under CleanRL's names, lets the
learning curve (:class:`~agents.rl.callbacks.PeriodicEvalCallback`) and the selection
(:class:`~agents.rl.callbacks.SelectionCallback`) score the policy the next rollout plays
when they are due -- as SB3's PPO (:func:`agents.ppo.sb3_format.to_sb3`), through their public
methods -- and checkpoints every so many steps and when a stop is asked (then raising
:class:`~agents.rl.checkpoints.TrainingInterrupted`). A checkpoint is ``step_N/`` with the
policy's ``model.zip`` and ``state.pkl`` (:meth:`agents.ppo.PPO.state`, the episode log's
length, the caller's state); :func:`restore_learner` continues from it exactly.
:func:`learn_selected` is the selection alone (``bench/learners.py``). :func:`make_learner` builds
the learner of a ``framework="jax"`` setting: :class:`agents.ppo.PPO`, or
:class:`agents.ppo.recurrent.RecurrentPPO` for ``recurrent_ppo``.
"""

from __future__ import annotations

import collections
import json
import pickle
import shutil
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from agents.ppo import PPO, PPOConfig
from agents.ppo.recurrent import RecurrentPPO, RecurrentPPOConfig
from agents.ppo.sb3_format import from_sb3, sb3_class, to_sb3
from agents.rl.bundle import bundle_problem, load_model, read_bundle, save_model_bundle
from agents.rl.callbacks import PeriodicEvalCallback, SelectionCallback
from agents.rl.checkpoints import TrainingInterrupted
from agents.rl.training import find_vec_normalize
from agents.run_folder import CHECKPOINTS_DIR, MODEL_FILE, VECNORMALIZE_FILE
from coop_gym.envs.config import Outcome
from coop_gym.io import atomic_path

__all__ = ["RunHooks", "continue_from_saved", "learn_selected", "learner_config", "make_learner", "restore_learner"]

STATE_FILE = "state.pkl"


def learner_config(config: Any) -> PPOConfig:
    """The learner's settings of ``config`` (a ``framework="jax"`` :class:`agents.hyperparams.TrainingConfig`).

    ``recurrent_ppo``: a :class:`~agents.ppo.recurrent.RecurrentPPOConfig`; ``ppo``: a :class:`~agents.ppo.PPOConfig`.

    Raises:
        ValueError: a setting the learner cannot run (the message names it).
    """
    return (RecurrentPPOConfig if config.algo == "recurrent_ppo" else PPOConfig).from_training(config)


def make_learner(config: Any, env_id: str, seed: int, env_kwargs: dict[str, Any] | None = None) -> PPO:
    """The learner of ``config`` (:func:`learner_config`) on ``env_id``'s envs of its personas.

    ``recurrent_ppo``: :class:`~agents.ppo.recurrent.RecurrentPPO`; ``ppo``: :class:`~agents.ppo.PPO`.
    """
    kwargs = {"personas": config.personas, **(env_kwargs or {})}
    settings = learner_config(config)
    if isinstance(settings, RecurrentPPOConfig):
        return RecurrentPPO(env_id, settings, seed, kwargs)
    return PPO(env_id, settings, seed, kwargs)


class RunHooks:
    """The run's work at each rollout end (see the module docstring); call it as ``on_rollout``.

    Args:
        run_dir: The run folder (``monitor.csv``, ``checkpoints/``).
        algo, env_id: What the saved zips record.
        logger: SB3's logger (:func:`agents.rl.cleanrl_logger`).
        curve, selection: The learning curve and the selection, or None.
        every: Env steps between checkpoints (0: only when stopping).
        stop_requested: True once training should stop.
        extra: The caller's state, stored with each checkpoint.
        start_steps: The learner's step count when the run (or its resume) began.
        monitor_append: Add to an existing ``monitor.csv`` (a resumed run) instead of starting one.
        progress: A progress bar (``tqdm``'s) to advance by the steps of each rollout, or None.
    """

    def __init__(
        self,
        run_dir: Path,
        *,
        algo: str,
        env_id: str,
        logger: Any,
        curve: PeriodicEvalCallback | None,
        selection: SelectionCallback | None,
        every: int,
        stop_requested: Callable[[], bool],
        extra: Callable[[], dict[str, Any]],
        start_steps: int,
        monitor_append: bool,
        progress: Any = None,
    ) -> None:
        """Open ``monitor.csv``; nothing else happens before the first rollout ends."""
        self.run_dir, self.algo, self.env_id, self.logger = Path(run_dir), algo, env_id, logger
        self.curve, self.selection, self.every = curve, selection, every
        self.stop_requested, self.extra = stop_requested, extra
        self._next = (start_steps // every + 1) * every if every > 0 else None
        self.recent: collections.deque[tuple[float, int, int]] = collections.deque(maxlen=200)
        self.monitor = self.run_dir / "monitor.csv"
        if not (monitor_append and self.monitor.exists()):
            header = json.dumps({"t_start": time.time(), "env_id": env_id})
            self.monitor.write_text(f"#{header}\nr,l,t,outcome\n", encoding="utf-8")
        self.last: Path | None = None
        self.progress, self._shown = progress, start_steps
        self._clock: tuple[float, int] | None = None  # when the last rollout ended, and at which step

    def __call__(self, learner: PPO) -> bool:
        """The rollout end: log, score when due, checkpoint when due; raise TrainingInterrupted on a stop."""
        if self.progress is not None:
            self.progress.update(learner.num_timesteps - self._shown)
            self._shown = learner.num_timesteps
        self._log(learner)
        steps, shadow = learner.num_timesteps, None
        for scorer in (self.curve, self.selection):
            if scorer is not None and scorer.due(steps):
                if shadow is None:
                    shadow = to_sb3(learner, learner.acting_params)  # the policy the next rollout plays
                    shadow.set_logger(self.logger)
                scorer.model, scorer.num_timesteps = shadow, steps
                if scorer is self.curve:
                    scorer.on_step()  # scores, and sets when the next score is due
                else:
                    scorer.on_rollout_start()
        stop = self.stop_requested()
        if stop or (self._next is not None and steps >= self._next):
            self.last = save_learner(learner, self.run_dir, algo=self.algo, env_id=self.env_id, extra=self.extra())
            if self._next is not None:
                self._next = (steps // self.every + 1) * self.every
        if stop:
            raise TrainingInterrupted(self.last)
        return True

    def _log(self, learner: PPO) -> None:
        episodes = learner.take_episodes()
        labels = [Outcome(code).label for code in episodes["outcome"].tolist()]
        with self.monitor.open("a", encoding="utf-8") as log:
            rows = zip(episodes["r"].tolist(), episodes["l"].tolist(), episodes["t"].tolist(), labels, strict=True)
            log.writelines(f"{r},{n},{round(t, 6)},{label}\n" for r, n, t, label in rows)
        self.recent.extend(
            zip(episodes["r"].tolist(), episodes["l"].tolist(), episodes["outcome"].tolist(), strict=True)
        )
        for name, value in learner.stats.items():
            self.logger.record(f"train/{name}", value)
        self.logger.record("train/learning_rate", learner.learning_rate)
        now = time.perf_counter()
        if self._clock is not None:
            self.logger.record(
                "time/fps", int((learner.num_timesteps - self._clock[1]) / max(now - self._clock[0], 1e-9))
            )
        self._clock = (now, learner.num_timesteps)
        if self.recent:
            returns, lengths, outcomes = zip(*self.recent, strict=True)
            self.logger.record("rollout/ep_rew_mean", float(np.mean(returns[-100:])))
            self.logger.record("rollout/ep_len_mean", float(np.mean(lengths[-100:])))
            for outcome in (o for o in Outcome if o is not Outcome.NONE):
                self.logger.record(f"charts/{outcome.label}_rate", outcomes.count(int(outcome)) / len(outcomes))
        self.logger.dump(learner.num_timesteps)


def save_learner(learner: PPO, run_dir: Path, *, algo: str, env_id: str, extra: dict[str, Any], keep: int = 2) -> Path:
    """Write ``run_dir/checkpoints/step_N/`` (``model.zip`` and ``state.pkl``), whole or not at all; keep ``keep``."""
    checkpoints = Path(run_dir) / CHECKPOINTS_DIR
    checkpoints.mkdir(parents=True, exist_ok=True)
    target = checkpoints / f"step_{learner.num_timesteps:012d}"
    monitor = Path(run_dir) / "monitor.csv"
    state = {
        "num_timesteps": learner.num_timesteps,
        "learner": learner.state(),
        "monitor": {"csv_bytes": monitor.stat().st_size if monitor.exists() else None},
        "extra": dict(extra),
    }
    if target.exists():
        shutil.rmtree(target)
    with atomic_path(target) as temp:
        temp.mkdir()
        model = to_sb3(learner, learner.acting_params)
        stats = find_vec_normalize(model.get_env())
        save_model_bundle(model, temp / MODEL_FILE, algo=algo, env_id=env_id, vec_normalize=stats)
        (temp / STATE_FILE).write_bytes(pickle.dumps(state))
    for old in sorted(checkpoints.glob("step_*"))[:-keep]:
        shutil.rmtree(old, ignore_errors=True)
    return target


def restore_learner(
    checkpoint: Path, learner: PPO, run_dir: Path, expected: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Continue ``learner`` from a :func:`save_learner` folder, ``monitor.csv`` cut back to its length; its extra.

    The checkpoint's ``model.zip`` must be its own (its step count ``state.pkl``'s) and the run's
    (``expected``: e.g. its algorithm, env, framework and envs).

    Raises:
        ValueError: an unreadable ``state.pkl``, or a model of another checkpoint or run (the message names it).
    """
    path = Path(checkpoint) / STATE_FILE
    try:
        state = pickle.loads(path.read_bytes())
        steps = {"num_timesteps": state["num_timesteps"]}
    except (OSError, EOFError, KeyError, TypeError, pickle.UnpicklingError, AttributeError) as exc:
        raise ValueError(f"{path}: unreadable checkpoint state ({type(exc).__name__}: {exc})") from None
    model_path = Path(checkpoint) / MODEL_FILE
    info, _ = read_bundle(model_path)
    problem = bundle_problem(model_path, info, steps, "its checkpoint's state.pkl")
    if problem := problem or bundle_problem(model_path, info, expected, "the run"):
        raise ValueError(f"{problem}: the model is not this checkpoint's")
    try:
        learner.restore(state["learner"])
    except (KeyError, TypeError, ValueError, AttributeError, pickle.UnpicklingError) as exc:
        raise ValueError(f"{path}: not a checkpoint of this learner ({type(exc).__name__}: {exc})") from None
    size = state["monitor"]["csv_bytes"]
    monitor = Path(run_dir) / "monitor.csv"
    if size is not None and monitor.exists():
        with monitor.open("r+b") as log:
            log.truncate(size)
    return dict(state["extra"])


def continue_from_saved(learner: PPO, path: str | Path) -> None:
    """Start ``learner`` from a saved PPO (a run folder or its zip): its weights, statistics and step count."""
    model_path = Path(path) / MODEL_FILE if Path(path).is_dir() else Path(path)
    info, stats = read_bundle(model_path)
    if stats is None and (model_path.parent / VECNORMALIZE_FILE).exists():
        stats = pickle.loads((model_path.parent / VECNORMALIZE_FILE).read_bytes())
    model, _ = load_model(model_path)
    expected = sb3_class(learner)
    if not isinstance(model, expected):
        raise ValueError(f"{model_path}: a {type(model).__name__}, not a {expected.__name__}")
    from_sb3(learner, model)
    if stats is not None and learner.normalizer is not None:
        rms: Any = stats.obs_rms
        learner.normalizer.restore(float(rms.count), np.asarray(rms.mean), np.asarray(rms.var))
    learner.num_timesteps = int(info.get("num_timesteps", model.num_timesteps))


def learn_selected(
    learner: PPO, total_timesteps: int, selection: SelectionCallback | None
) -> tuple[Any, dict[str, Any] | None]:
    """``(model, selected)``: train to ``total_timesteps``; the kept policy as SB3's (:func:`to_sb3`) and the record.

    The selection scores the policy the next rollout plays, at the rollouts it asks for; without
    one the final policy is kept and the record is None.
    """

    def score(trained: PPO) -> bool:
        if selection is not None and selection.due(trained.num_timesteps):
            selection.model = to_sb3(trained, trained.acting_params)
            selection.num_timesteps = trained.num_timesteps
            selection.on_rollout_start()
        return True

    learner.learn(total_timesteps, score)
    model = to_sb3(learner)
    if selection is None:
        return model, None
    return model, selection.finish(model)
