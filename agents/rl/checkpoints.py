"""Checkpoints that let SB3 training stop at any rollout boundary and continue exactly.

:func:`save_checkpoint` writes everything training needs to go on as if it never stopped
(model, optimiser, replay buffer, RNG streams, the envs mid-episode, the episode log's
length); :func:`restore_checkpoint` puts it back onto freshly built envs;
:class:`CheckpointCallback` takes them every so many env steps and when a stop is requested
(then raising :class:`TrainingInterrupted`).
"""

from __future__ import annotations

import pickle
import random
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.vec_env import VecEnv, VecMonitor

from agents.rl.bundle import bundle_problem, load_model, read_bundle, save_model_bundle
from agents.rl.training import find_vec_normalize
from agents.run_folder import CHECKPOINTS_DIR, MODEL_FILE
from coop_gym.io import atomic_path

__all__ = ["CheckpointCallback", "TrainingInterrupted", "latest_checkpoint", "restore_checkpoint", "save_checkpoint"]


class TrainingInterrupted(Exception):
    """Training stopped on request (SIGINT/SIGTERM) at a rollout boundary, after a checkpoint."""

    def __init__(self, checkpoint: Path | None) -> None:
        """Remember where the last checkpoint went."""
        super().__init__(f"training interrupted; last checkpoint {checkpoint}")
        self.checkpoint = checkpoint


def _monitor_of(env: VecEnv) -> VecMonitor | None:
    layer: Any = env
    while layer is not None:
        if isinstance(layer, VecMonitor):
            return layer
        layer = getattr(layer, "venv", None)
    return None


def save_checkpoint(
    model: BaseAlgorithm,
    run_dir: str | Path,
    *,
    algo: str,
    env_id: str,
    extra: dict[str, Any] | None = None,
    keep: int = 2,
) -> Path:
    """Write everything needed to continue training exactly into ``run_dir/checkpoints/step_N/``.

    Taken at a rollout boundary, so nothing half-collected is lost: the model zip (policy,
    optimiser state, schedules, last observation -- as SB3 saves it -- with the
    ``VecNormalize`` statistics inside), the replay buffer of off-policy algorithms, and
    ``state.pkl`` with the RNG states (Python, NumPy, torch, action space), the pickled
    training envs (mid-episode state), the episode counters of ``VecMonitor``, the size of
    ``monitor.csv`` and ``extra`` (the caller's own state). The folder appears under its final
    name only when complete; only the newest ``keep`` are kept.

    Returns:
        The checkpoint folder.
    """
    checkpoints = Path(run_dir) / CHECKPOINTS_DIR
    checkpoints.mkdir(parents=True, exist_ok=True)
    target = checkpoints / f"step_{int(model.num_timesteps):012d}"
    env = model.get_env()
    state = _training_state(model, _monitor_of(env) if env is not None else None, extra)
    if target.exists():  # the same step again (e.g. the final checkpoint right after a periodic one)
        shutil.rmtree(target)
    with atomic_path(target) as temp:
        temp.mkdir()
        save_model_bundle(model, temp / MODEL_FILE, algo=algo, env_id=env_id, vec_normalize=find_vec_normalize(env))
        if getattr(model, "replay_buffer", None) is not None:
            model.save_replay_buffer(temp / "replay_buffer.pkl")  # type: ignore[attr-defined]
        (temp / "state.pkl").write_bytes(pickle.dumps(state))
    for old in sorted(checkpoints.glob("step_*"))[:-keep]:
        shutil.rmtree(old, ignore_errors=True)
    return target


def _training_state(model: BaseAlgorithm, monitor: VecMonitor | None, extra: dict[str, Any] | None) -> dict[str, Any]:
    """What a checkpoint keeps beside the model zip: RNG states, envs, episode counters, the caller's state."""
    import torch

    monitor_csv = None
    if monitor is not None and monitor.results_writer is not None:
        monitor.results_writer.file_handler.flush()
        monitor_csv = Path(monitor.results_writer.file_handler.name).stat().st_size
    return {
        "num_timesteps": int(model.num_timesteps),
        "rng": {
            "python": random.getstate(),
            "numpy": np.random.get_state(),
            "torch": torch.get_rng_state(),
            "action_space": model.action_space.np_random.bit_generator.state,
        },
        "envs": pickle.dumps(monitor.venv) if monitor is not None else None,
        "monitor": None
        if monitor is None
        else {
            "episode_returns": monitor.episode_returns,
            "episode_lengths": monitor.episode_lengths,
            "episode_count": monitor.episode_count,
            "csv_bytes": monitor_csv,
        },
        "extra": dict(extra or {}),
        # RecurrentPPO's load rebuilds its LSTM state as zeros; the real one is kept here.
        "lstm_states": getattr(model, "_last_lstm_states", None),
    }


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The newest complete checkpoint folder of a run (None if there is none)."""
    found = sorted(p for p in (Path(run_dir) / CHECKPOINTS_DIR).glob("step_*") if (p / "state.pkl").exists())
    return found[-1] if found else None


def restore_checkpoint(
    checkpoint: str | Path, env: VecEnv, expected: dict[str, Any] | None = None
) -> tuple[BaseAlgorithm, dict[str, Any]]:
    """Load a :func:`save_checkpoint` folder onto a freshly built training ``env`` (``VecMonitor`` inside).

    The model continues exactly where it stopped: same envs mid-episode, same normaliser,
    same optimiser, same RNG streams. ``monitor.csv`` (if ``env`` writes one, in append
    mode) is cut back to its size at the checkpoint, dropping episodes logged after it.
    Before anything is touched, the model zip must be the checkpoint's own (its step count
    that of ``state.pkl``) and of the run (``expected``: e.g. ``algo``, ``framework``, ``n_envs``).

    Returns:
        ``(model, extra)``: the model on ``env`` (wrapped in the saved ``VecNormalize`` if
        there was one) and the caller's ``extra`` state.

    Raises:
        ValueError: an unreadable checkpoint, or a model zip foreign to it or to the run.
    """
    import torch

    folder = Path(checkpoint)
    try:
        state = pickle.loads((folder / "state.pkl").read_bytes())
    except (OSError, EOFError, pickle.UnpicklingError) as exc:
        raise ValueError(f"{folder}: unreadable checkpoint state ({exc})") from None
    info, stats = read_bundle(folder / MODEL_FILE)
    steps = {"num_timesteps": state.get("num_timesteps")}
    problem = bundle_problem(folder / MODEL_FILE, info, steps, "its checkpoint's state.pkl")
    problem = problem or bundle_problem(folder / MODEL_FILE, info, expected, "the run")
    if problem:
        raise ValueError(f"{problem}: the model is not this checkpoint's")
    monitor = _monitor_of(env)
    if monitor is not None and state["monitor"] is not None:
        writer = monitor.results_writer
        if writer is not None and state["monitor"]["csv_bytes"] is not None:
            writer.file_handler.flush()
            writer.file_handler.truncate(state["monitor"]["csv_bytes"])
            writer.file_handler.seek(0, 2)
        for key in ("episode_returns", "episode_lengths", "episode_count"):
            setattr(monitor, key, state["monitor"][key])
    if stats is not None:
        stats.set_venv(env)
        env = stats
    # force_reset=False keeps the saved last observation: the envs are restored mid-episode below.
    model, _ = load_model(folder / MODEL_FILE, env=env, force_reset=False)
    if (folder / "replay_buffer.pkl").exists():
        model.load_replay_buffer(folder / "replay_buffer.pkl")  # type: ignore[attr-defined]
    if monitor is not None and state["envs"] is not None:
        monitor.venv.close()
        monitor.venv = pickle.loads(state["envs"])
    if state.get("lstm_states") is not None:
        model._last_lstm_states = state["lstm_states"]  # type: ignore[attr-defined]
    # After load: SB3's load re-seeds the global RNGs and the action space from the model's seed.
    rng = state["rng"]
    random.setstate(rng["python"])
    np.random.set_state(rng["numpy"])
    torch.set_rng_state(rng["torch"])
    model.action_space.np_random.bit_generator.state = rng["action_space"]
    return model, dict(state["extra"])


class CheckpointCallback(BaseCallback):
    """Checkpoints every ``every`` env steps and stops cleanly when asked, both at rollout boundaries.

    A checkpoint taken when a rollout starts holds no half-collected data, so training
    resumed from it follows the same path as training that never stopped.

    Args:
        run_dir: The run folder (checkpoints go to ``run_dir/checkpoints``).
        every: Env steps between checkpoints (0: only when stopping).
        algo: Algorithm name (stored in the checkpoint's model zip).
        env_id: Env id (stored likewise).
        stop_requested: Returns True once training should stop (e.g. a signal arrived).
        extra: Returns the caller's state to store with each checkpoint.
        start_steps: Step count training starts from.
    """

    def __init__(
        self,
        run_dir: str | Path,
        every: int,
        *,
        algo: str,
        env_id: str,
        stop_requested: Callable[[], bool] = lambda: False,
        extra: Callable[[], dict[str, Any]] = dict,
        start_steps: int = 0,
    ) -> None:
        """Store the settings; checkpoints happen during ``learn``."""
        super().__init__()
        self.run_dir, self.every, self.algo, self.env_id = Path(run_dir), every, algo, env_id
        self.stop_requested, self.extra = stop_requested, extra
        self._next = (start_steps // every + 1) * every if every > 0 else None
        self.last: Path | None = None

    def save(self) -> Path:
        """Write a checkpoint now."""
        self.last = save_checkpoint(self.model, self.run_dir, algo=self.algo, env_id=self.env_id, extra=self.extra())
        return self.last

    def _on_rollout_start(self) -> None:
        stop = self.stop_requested()
        if stop or (self._next is not None and self.num_timesteps >= self._next):
            self.save()
            if self._next is not None:
                self._next = (self.num_timesteps // self.every + 1) * self.every
        if stop:
            raise TrainingInterrupted(self.last)

    def _on_step(self) -> bool:
        return True
