"""``train.py``'s pieces: the learners' default settings, the typed arguments, the run folder and the report.

:mod:`agents.hyperparams` (``HYPERPARAMS``, the RL Zoo files), :mod:`agents.trainer.train_args`,
:mod:`agents.run_folder` (a run folder's files), :mod:`agents.trainer.training_run` (signals,
leftovers) and :mod:`agents.trainer.run_report` (evaluate against the baselines, write the results). The
learners themselves are :mod:`agents.rl`. This ``__init__`` loads nothing, so the light modules import
without torch or Stable-Baselines3.
"""

__all__: list[str] = []
