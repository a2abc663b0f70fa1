"""The life of a ``train.py`` run folder: resuming it, stopping it cleanly, clearing up after it.

* :class:`Plan` -- what a run does (folder, algorithm, env, budget), settled before any work.
* :class:`StopSignals` -- SIGINT/SIGTERM stop training at the next rollout boundary, after a
  checkpoint; a second signal stops at once (:class:`Stopped`); after training, at once or at
  the next :meth:`StopSignals.check`.
* :func:`write_interrupted`, :func:`clean_leftovers`, :func:`remove_checkpoints` -- the
  markers and files around a stop and a resume; :func:`write_failed` -- a file that could not
  be written.

The settings a ``--resume`` continues with are :func:`agents.trainer.train_args.resume_settings`.

No torch at import: ``train.py`` parses its arguments before it loads SB3.
"""

from __future__ import annotations

import errno
import shutil
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from agents.run_folder import CHECKPOINTS_DIR, INTERRUPTED_FILE, TRAINING_FILE, is_unfinished_run
from agents.trainer.train_args import PROG
from coop_gym.io import TEMP_MARKER, write_text

if TYPE_CHECKING:
    from agents.hyperparams import TrainingConfig

__all__ = [
    "Plan",
    "StopSignals",
    "Stopped",
    "clean_leftovers",
    "remove_checkpoints",
    "run_folder_of",
    "write_failed",
    "write_interrupted",
]


@dataclass(frozen=True)
class Plan:
    """What a run does, settled before any work: the folder, the algorithm, the env and the budget."""

    run_dir: Path
    algo: str
    env_id: str
    config: TrainingConfig
    timesteps: int
    n_envs: int
    checkpoint_every: int
    source_model: str | None


class Stopped(Exception):
    """A second Ctrl-C/SIGTERM, or one outside training: stop now."""


class StopSignals:
    """SIGINT and SIGTERM stop training at the next rollout boundary; a second one stops at once.

    Outside training a signal stops at once: the handler raises :class:`Stopped`. Where that
    exception is lost -- raised inside a ctypes callback (numba's), Python prints "Exception
    ignored" and goes on -- the signal is still recorded, and :meth:`check` at the next boundary
    stops the run. The previous handlers are restored on exit.
    """

    def __init__(self) -> None:
        """No signal yet."""
        self.signum: int | None = None
        self.in_training = False
        self._previous: dict[int, Any] = {}

    def requested(self) -> bool:
        """True once a signal arrived."""
        return self.signum is not None

    def check(self) -> None:
        """Raise :class:`Stopped` if a signal arrived (its own exception may have been swallowed)."""
        if self.signum is not None:
            raise Stopped(signal.Signals(self.signum).name)

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
        self.check()

    def __enter__(self) -> StopSignals:
        """Install the handlers."""
        for signum in (signal.SIGINT, signal.SIGTERM):
            self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *_: Any) -> None:
        """Restore the previous handlers."""
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)


def write_interrupted(run_dir: Path, stop: StopSignals) -> int:
    """Write the INTERRUPTED marker, say how to resume; the exit status is 128 + the signal number."""
    from agents.rl import latest_checkpoint  # SB3 is loaded once a run has started

    checkpoint = latest_checkpoint(run_dir)
    name = signal.Signals(stop.signum).name if stop.signum else "interrupt"
    if (run_dir / TRAINING_FILE).exists():
        state = "training had finished; resuming runs the evaluation"
    else:
        state = f"last checkpoint {checkpoint}" if checkpoint else "no checkpoint yet; resuming starts training over"
    message = f"{name}: stopped, {state}\nresume with: {PROG} --resume {run_dir}\n"
    write_text(run_dir / INTERRUPTED_FILE, time.strftime("%Y-%m-%dT%H:%M:%S ") + message)
    print(f"\n{message}", end="", file=sys.stderr)
    return 128 + (stop.signum or signal.SIGINT)


def run_folder_of(args: Any) -> Path:
    """The folder a run writes into: the unfinished run ``--resume`` continues in place, else ``--out``."""
    if args.resume is not None and is_unfinished_run(args.resume):
        return Path(args.resume)
    return Path(args.out)


_NOT_WRITABLE = (errno.EROFS, errno.EACCES, errno.EPERM)


def write_failed(exc: OSError, run_dir: Path) -> int:
    """A file could not be written (e.g. a full disk): it is not there, never half-written; exit status 1.

    The remedy follows the cause: space for a full disk, a writable copy for a read-only folder.
    """
    print(f"{PROG}: error: could not write {exc.filename or 'output'}: {exc.strerror or exc}", file=sys.stderr)
    if exc.errno in (errno.ENOSPC, errno.EDQUOT):
        remedy = f"free space, then {PROG} --resume {run_dir}"
    elif exc.errno in _NOT_WRITABLE:
        remedy = f"it is not writable here: copy it to a writable place (cp -a), then {PROG} --resume THE_COPY"
    else:
        remedy = f"fix the cause above, then {PROG} --resume {run_dir}"
    print(f"{run_dir} keeps what was complete; {remedy}", file=sys.stderr)
    return 1


def clean_leftovers(run_dir: Path) -> None:
    """Before resuming: drop any temporary file a killed process left behind.

    The ``INTERRUPTED`` marker stays until the run writes what replaces it (a new marker, or
    ``COMPLETE``): a resume that fails leaves the folder saying how it stopped.
    """
    for leftover in list(run_dir.rglob(f"*{TEMP_MARKER}*")):
        if leftover.is_dir():
            shutil.rmtree(leftover, ignore_errors=True)
        else:
            leftover.unlink(missing_ok=True)


def remove_checkpoints(run_dir: Path) -> None:
    """Training is over: its checkpoints have served their purpose."""
    shutil.rmtree(run_dir / CHECKPOINTS_DIR, ignore_errors=True)
