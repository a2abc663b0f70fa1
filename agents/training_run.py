"""The life of a ``train.py`` run folder: resuming it, stopping it cleanly, clearing up after it.

* :func:`resume_settings` -- the settings a ``--resume`` continues with: an unfinished run's
  own ``args.json`` (it resumes in place), or a saved model's algorithm and env (a new run).
* :class:`StopSignals` -- SIGINT/SIGTERM stop training at the next rollout boundary, after a
  checkpoint; a second signal stops at once (:class:`Stopped`).
* :func:`write_interrupted`, :func:`clean_leftovers`, :func:`remove_checkpoints` -- the
  markers and files around a stop and a resume.
* :func:`monitor_curve` -- the training episodes of SB3's ``monitor.csv`` for the learning curve.

No torch at import: ``train.py`` parses its arguments before it loads SB3.
"""

from __future__ import annotations

import csv
import json
import shutil
import signal
import sys
import time
from pathlib import Path
from typing import Any

from agents.run_folder import ARGS_FILE, CHECKPOINTS_DIR, INTERRUPTED_FILE, TRAINING_FILE, is_unfinished_run
from coop_gym.io import TEMP_MARKER, write_text

__all__ = [
    "RUN_FIELDS",
    "StopSignals",
    "Stopped",
    "clean_leftovers",
    "monitor_curve",
    "remove_checkpoints",
    "resume_settings",
    "write_interrupted",
]

RUN_FIELDS = (
    "algo",
    "env",
    "seed",
    "timesteps",
    "n_envs",
    "eval_episodes",
    "eval_seed",
    "eval_personas",
    "baselines",
    "eval_points",
    "select_points",
    "select_episodes",
    "checkpoint_every",
)
"""Settings that define a run: ``--resume`` of an unfinished run takes them from its ``args.json``."""


def resume_settings(path: Path) -> dict[str, Any]:
    """The settings ``--resume path`` continues with (a subset of :data:`RUN_FIELDS`).

    Raises:
        ValueError: nothing resumable at ``path``; the message starts with ``--resume``.
    """
    if not (path.exists() or path.with_suffix(".zip").exists()):
        raise ValueError(f"--resume: nothing saved at {path}")
    if not is_unfinished_run(path):  # a finished run or a model: a new run continuing the model
        from agents.rl import resolve_saved

        try:
            _, info = resolve_saved(path)
        except (OSError, ValueError) as exc:
            raise ValueError(f"--resume: {exc}") from None
        return {k: v for k, v in (("algo", info.get("algo")), ("env", info.get("env_id"))) if v}
    try:
        recorded = json.loads((path / ARGS_FILE).read_text())
        if not isinstance(recorded, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as exc:
        raise ValueError(f"--resume: {path / ARGS_FILE} is unreadable ({exc})") from None
    if recorded.get("eval_only"):
        raise ValueError(
            f"--resume: {path} was an --eval-only run; run it again: --eval-only --model {recorded.get('model')}"
        )
    recorded = _with_defaults(recorded)
    return {name: recorded[name] for name in RUN_FIELDS if name in recorded}


def _with_defaults(settings: dict[str, Any]) -> dict[str, Any]:
    """Run settings with the algorithm's defaults filled in (older args.json files hold None)."""
    from agents.hyperparams import hyperparams_for

    out = dict(settings)
    algo = out.get("algo", "ppo")
    config = hyperparams_for(algo, out.get("env") or hyperparams_for(algo).env_id)
    out["env"] = out.get("env") or config.env_id
    out["timesteps"] = out.get("timesteps") or config.total_timesteps
    out["n_envs"] = out.get("n_envs") or config.n_envs
    if out.get("checkpoint_every") is None:
        out["checkpoint_every"] = max(1, out["timesteps"] // 10)
    return out


class Stopped(Exception):
    """A second Ctrl-C/SIGTERM, or one outside training: stop now."""


class StopSignals:
    """SIGINT and SIGTERM stop training at the next rollout boundary; a second one stops at once.

    Outside training a signal stops at once. The previous handlers are restored on exit.
    """

    def __init__(self) -> None:
        """No signal yet."""
        self.signum: int | None = None
        self.in_training = False
        self._previous: dict[int, Any] = {}

    def requested(self) -> bool:
        """True once a signal arrived."""
        return self.signum is not None

    def _handle(self, signum: int, _frame: Any) -> None:
        first = self.signum is None
        self.signum = signum
        if first and self.in_training:
            print(
                f"\n{signal.Signals(signum).name}: saving a checkpoint at the next rollout boundary "
                "(send it again to stop at once)",
                file=sys.stderr,
            )
            return
        raise Stopped(signal.Signals(signum).name)

    def __enter__(self) -> StopSignals:
        """Install the handlers."""
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *_: Any) -> None:
        """Restore the previous handlers."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)


def write_interrupted(run_dir: Path, stop: StopSignals, checkpoint: Path | None) -> int:
    """Write the INTERRUPTED marker, say how to resume; the exit status is 128 + the signal number."""
    name = signal.Signals(stop.signum).name if stop.signum else "interrupt"
    if (run_dir / TRAINING_FILE).exists():
        state = "training had finished; resuming runs the evaluation"
    else:
        state = f"last checkpoint {checkpoint}" if checkpoint else "no checkpoint yet; resuming starts training over"
    message = f"{name}: stopped, {state}\nresume with: python train.py --resume {run_dir}\n"
    write_text(run_dir / INTERRUPTED_FILE, time.strftime("%Y-%m-%dT%H:%M:%S ") + message)
    print(f"\n{message}", end="", file=sys.stderr)
    return 128 + (stop.signum or signal.SIGINT)


def clean_leftovers(run_dir: Path) -> None:
    """Before resuming: drop the marker and any temporary file a killed process left behind."""
    (run_dir / INTERRUPTED_FILE).unlink(missing_ok=True)
    for leftover in list(run_dir.rglob(f"*{TEMP_MARKER}*")):
        if leftover.is_dir():
            shutil.rmtree(leftover, ignore_errors=True)
        else:
            leftover.unlink(missing_ok=True)


def remove_checkpoints(run_dir: Path) -> None:
    """Training is over: its checkpoints have served their purpose."""
    shutil.rmtree(run_dir / CHECKPOINTS_DIR, ignore_errors=True)


def monitor_curve(path: Path, start_steps: int) -> tuple[list[float], list[float]]:
    """(env step at episode end, return) of every training episode in SB3's monitor.csv."""
    import numpy as np

    if not path.exists():
        return [], []
    with path.open() as handle:
        handle.readline()  # the JSON header line
        rows = list(csv.DictReader(handle))
    lengths = [float(r["l"]) for r in rows]
    returns = [float(r["r"]) for r in rows]
    # Episodes from parallel envs interleave; their cumulative length approximates the step count.
    steps = (start_steps + np.cumsum(lengths)).tolist()
    return steps, returns
