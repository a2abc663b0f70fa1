"""System identification: the maximum-likelihood fit of a nominal model to trials, and trials to fit.

The trials are simulated from a known nominal model (:mod:`estimator.identification.nominal_trials`):
data whose true model is known, to test the fit and the filters on.
"""
