"""The paper's filter: the compiled filter against filterpy, and the thresholded judgment."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from coop_gym.envs.core import nominal_model_for
from coop_gym.model.dynamics import simulate
from coop_gym.model.params import PersonParams, Timing
from estimator.compiled.schema import field_values
from estimator.judgment import ThresholdJudgment, judgment_substep, threshold_judgment
from estimator.kalman import (
    NOMINAL,
    NOMINAL_COLUMNS,
    NOMINAL_DERIVED_COLUMNS,
    NOMINAL_FIELDS,
    FastKalmanFilter,
    PaperKalmanFilter,
    nominal_row,
)
from estimator.nominal import NominalModel


def _random_cues(rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
    # Piecewise-constant cues with random holds, like an agent's actions.
    holds = rng.integers(5, 60, size=n)
    cp = np.repeat(rng.choice([0.0, 10.0, 30.0], size=n), holds)[:n] + rng.normal(0, 0.5, n)
    cv = np.repeat(rng.choice([-1.0, 0.0, 1.0], size=n), holds)[:n]
    return cp, cv


@pytest.mark.parametrize("seed", [0, 1])
def test_fast_filter_matches_filterpy_on_long_random_cue_sequences(seed: int) -> None:
    rng = np.random.default_rng(seed)
    n = 5000
    cp, cv = _random_cues(rng, n)
    model = nominal_model_for(PersonParams(), Timing())
    traj = simulate(PersonParams(), cp, cv, rng, initial_xi=int(rng.integers(-1, 2)))
    y = traj.measured_position_m
    ref = PaperKalmanFilter(model, first_position_m=y[0])
    ref_means = np.empty((n, 4))
    ref_covs = np.empty((n, 4, 4))
    for t in range(n):
        ref_means[t] = ref.step(cp[t], cv[t], y[t])
        ref_covs[t] = ref.covariance
    fast = FastKalmanFilter.from_model(model, y[:1])
    means, covs, loglik = fast.run(cp[None], cv[None], y[None])
    assert np.max(np.abs(means[0] - ref_means)) < 1e-9
    assert np.max(np.abs(covs[0] - ref_covs)) < 1e-9
    assert np.all(np.isfinite(loglik))


def test_batched_filters_are_independent() -> None:
    rng = np.random.default_rng(3)
    cp, cv = _random_cues(rng, 400)
    y = rng.normal(0, 0.01, (3, 400))
    models = [NominalModel(), NominalModel(voluntary_gain_per_s2=5.0), NominalModel(push_gain_m_per_s_n=0.01)]
    batch = FastKalmanFilter(np.stack([nominal_row(m) for m in models]), y[:, 0])
    means, _, _ = batch.run(np.tile(cp, (3, 1)), np.tile(cv, (3, 1)), y)
    for k, model in enumerate(models):
        alone = FastKalmanFilter.from_model(model, y[k : k + 1, 0])
        m_alone, _, _ = alone.run(cp[None], cv[None], y[k : k + 1])
        assert np.array_equal(means[k], m_alone[0])


def test_filter_recovers_the_sign_of_xi_from_a_noise_free_nominal_response() -> None:
    model = NominalModel()
    n = 200
    cv = np.zeros(n)
    cv[10:60] = 1.0
    for xi in (-1.0, 1.0):
        # Generate from the filter's own model so the answer is known exactly.
        s = np.zeros(4)
        s[3] = xi
        ys = np.empty(n)
        for t in range(n):
            s = model.transition_matrix(0.0, cv[t]) @ s
            ys[t] = s[0]
        kf = FastKalmanFilter.from_model(model, ys[:1])
        means, _, _ = kf.run(np.zeros((1, n)), cv[None], ys[None])
        assert np.sign(means[0, -1, 3]) == xi
        assert abs(means[0, -1, 3] - xi) < 0.3


def test_nominal_model_validates_fields() -> None:
    with pytest.raises(ValueError, match=r"NominalModel\.dt_s"):
        NominalModel(dt_s=0.0)
    with pytest.raises(ValueError, match="unknown NominalModel field"):
        NominalModel.from_dict({"k9": 1.0})


def test_threshold_judgment_bands() -> None:
    judged = threshold_judgment(np.array([-1.0, -0.3, -0.29, 0.0, 0.29, 0.3, 2.0]), 0.3)
    assert judged.tolist() == [-1, -1, 0, 0, 0, 1, 1]
    assert ThresholdJudgment().judge(0.5).tolist() == 1
    with pytest.raises(ValueError, match="threshold"):
        ThresholdJudgment(threshold=0.0)


def test_judgment_is_sampled_a_fixed_delay_after_the_initial_onset() -> None:
    row = np.zeros(4)
    dt, delay = 0.02, 0.75
    made_at = []
    # Cue from step 10 to 100 (one onset), estimate rising linearly.
    for t in range(200):
        active = 10 <= t < 100
        if judgment_substep(row, active, t / 100.0, delay, 0.3, dt):
            made_at.append(t)
    # One judgment, 37 steps (0.74 s of slack-rounded 0.75 s) after the onset step.
    assert made_at == [10 + 37]
    assert row[2] == 1.0  # 0.47 >= 0.3


def test_nominal_row_is_named_by_the_model_fields_then_the_derived_variances() -> None:
    # One schema: the packed row's direct columns are NominalModel fields, by name.
    fields = {f.name for f in dataclasses.fields(NominalModel)}
    assert set(NOMINAL_FIELDS) <= fields
    assert NOMINAL_COLUMNS == NOMINAL_FIELDS + NOMINAL_DERIVED_COLUMNS
    assert NOMINAL._fields == NOMINAL_COLUMNS and tuple(NOMINAL) == tuple(range(len(NOMINAL_COLUMNS)))
    model = NominalModel(push_gain_m_per_s_n=0.01, position_noise_std_m=0.003)
    row = nominal_row(model)
    for name in NOMINAL_FIELDS:
        assert row[getattr(NOMINAL, name)] == getattr(model, name), name
    assert row[NOMINAL.r_position] == model.measurement_variance
    np.testing.assert_array_equal(
        row[NOMINAL.q_position : NOMINAL.q_cooperativeness + 1], np.diag(model.process_covariance)
    )


def test_nominal_defaults_are_the_typical_persons_gains() -> None:
    # The filter's default model is the default person's (estimator/ may not import the model,
    # so the defaults are written twice; this keeps them equal), and nominal_model_for copies
    # every field the two share by name.
    assert nominal_model_for(PersonParams(), Timing()) == NominalModel()
    shared = {f.name for f in dataclasses.fields(NominalModel)} & set(field_values(PersonParams()))
    assert shared == {*NOMINAL_FIELDS, "position_noise_std_m"} - {"dt_s"}
