"""The paper's experiment as a harness over the human model, the envs' nominal model and the filters.

A layer above :mod:`coop_gym.envs` (docs/STYLE.md, "Layout"): it builds simulated subjects
from the model, the filters' nominal models with :func:`coop_gym.envs.core.nominal_model_for`,
and scores :mod:`estimator`'s filters on them. ``python -m coop_gym.experiment.protocol`` runs
one experiment; ``python -m coop_gym.experiment.calibrate`` the calibration report.
"""
