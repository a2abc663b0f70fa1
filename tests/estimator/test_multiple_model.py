"""Multiple-model estimators: exactness against the paper filter, robustness, decisions, calibration."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from estimator.identification.nominal_trials import simulate_nominal, simulate_nominal_trials
from estimator.kalman import FastKalmanFilter, PaperKalmanFilter, nominal_row
from estimator.metrics import accuracy, brier_score, expected_calibration_error, log_loss
from estimator.multiple_model import (
    MODE_VALUES,
    IMMEstimator,
    MultipleModelEstimator,
    confident_judgment,
    map_judgment,
    sequential_judgment,
    switching_transition_matrix,
)
from estimator.nominal import NominalModel

# A noisier model than the default, so posteriors stay away from 0/1 for a while and
# the comparison below tests more than saturated probabilities.
NOISY = NominalModel(position_noise_std_m=0.02, intention_process_std_m=0.004)


def _posterior_from_paper_filter(
    means: np.ndarray, covariances: np.ndarray, s0: float, mode_prior: np.ndarray
) -> np.ndarray:
    """Discrete posterior over xi from the 4-state filter's Gaussian xi marginal (Q_xi = 0).

    Divide out the N(0, s0^2) prior: 1/vL = 1/v - 1/s0^2, mL/vL = m/v; then
    log p(k) = log pi_k - k^2 / (2 vL) + k mL / vL + const.
    """
    m, v = means[..., 3], covariances[..., 3, 3]
    precision = 1.0 / v - 1.0 / s0**2
    shift = m / v
    k = MODE_VALUES.astype(float)
    logp = np.log(mode_prior) - 0.5 * precision[..., None] * k**2 + shift[..., None] * k
    logp -= logp.max(axis=-1, keepdims=True)
    p = np.exp(logp)
    return p / p.sum(axis=-1, keepdims=True)


def _cues(rng: np.random.Generator, n: int, t: int) -> tuple[np.ndarray, np.ndarray]:
    cp = np.where(rng.random((n, t)) < 0.3, rng.choice([10.0, 30.0], (n, t)), 0.0)
    cv = rng.integers(-1, 2, (n, t)).astype(float)
    return cp, cv


@pytest.mark.parametrize("mode_prior", [None, [0.2, 0.3, 0.5]])
def test_mmae_equals_paper_filter_posterior_batched(mode_prior: list[float] | None) -> None:
    rng = np.random.default_rng(0)
    s0 = 1.5
    models = [
        NOISY.replace(cooperativeness_process_std=0.0, initial_cooperativeness_std=s0),
        NOISY.replace(
            cooperativeness_process_std=0.0,
            initial_cooperativeness_std=s0,
            verbal_gain_m_per_s=0.05,
            damping_rate_per_s=4.0,
            position_noise_std_m=0.01,
        ),
        NOISY.replace(cooperativeness_process_std=0.0, initial_cooperativeness_std=s0, push_gain_m_per_s_n=0.002),
    ]
    n, t = len(models), 250
    rows = np.array([nominal_row(m) for m in models])
    cp = np.zeros((n, t))
    cv = np.zeros((n, t))
    y = np.empty((n, t))
    for i, model in enumerate(models):
        cp[i, 60:110] = 10.0 * (i + 1)
        cv[i, 150:200] = 1.0 if i != 1 else -1.0
        y[i], _ = simulate_nominal(model, cp[i], cv[i], xi=i - 1, rng=rng)
    kf = FastKalmanFilter(rows, y[:, 0], prior=models[0])
    means, covs, _ = kf.run(cp[:, 1:], cv[:, 1:], y[:, 1:])
    prior = np.full(3, 1 / 3) if mode_prior is None else np.asarray(mode_prior)
    expected = _posterior_from_paper_filter(means, covs, s0, prior)

    mm = MultipleModelEstimator(rows, y[:, 0], prior=models[0], mode_prior=mode_prior, probability_floor=0.0)
    probs = mm.run(cp[:, 1:], cv[:, 1:], y[:, 1:])
    np.testing.assert_allclose(probs, expected, rtol=0, atol=1e-10)
    # Not a trivial agreement: the posteriors move and are not all saturated.
    assert np.ptp(probs[..., 2]) > 0.5
    assert np.any((probs > 0.05) & (probs < 0.95))


def test_mmae_equals_filterpy_reference() -> None:
    s0 = 1.0
    model = NOISY.replace(cooperativeness_process_std=0.0, initial_cooperativeness_std=s0)
    rng = np.random.default_rng(1)
    cp = np.zeros(150)
    cv = np.zeros(150)
    cp[30:80] = 10.0
    cv[70:120] = 1.0
    y, _ = simulate_nominal(model, cp, cv, xi=1, rng=rng)
    kf = PaperKalmanFilter(model, first_position_m=y[0])
    mm = MultipleModelEstimator.from_model(model, y[:1], probability_floor=0.0)
    for t in range(1, len(y)):
        mean = kf.step(cp[t], cv[t], y[t])
        probs = mm.step(cp[t : t + 1], cv[t : t + 1], y[t : t + 1])
        expected = _posterior_from_paper_filter(mean, kf.covariance, s0, np.full(3, 1 / 3))
        np.testing.assert_allclose(probs[0], expected, rtol=0, atol=1e-10)
        # Each mode's mean is the 4-state posterior conditioned on xi = k:
        # m[:3] + P[:3, 3] / P[3, 3] * (k - m[3]).
        cov = kf.covariance
        conditional = mean[:3] + np.outer(MODE_VALUES - mean[3], cov[:3, 3] / cov[3, 3])
        np.testing.assert_allclose(mm.means[0], conditional, rtol=0, atol=1e-11)
    np.testing.assert_allclose(mm.mean[0], probs[0] @ conditional, rtol=0, atol=1e-11)


@pytest.mark.parametrize("cls", [MultipleModelEstimator, IMMEstimator])
def test_step_equals_run_and_reset(cls: type) -> None:
    rng = np.random.default_rng(2)
    n, t = 5, 80
    cp, cv = _cues(rng, n, t)
    y = rng.normal(0.0, 0.01, (n, t))
    a = cls.from_model(NominalModel(), y[:, 0])
    b = cls.from_model(NominalModel(), y[:, 0])
    stepped = np.stack([a.step(cp[:, k], cv[:, k], y[:, k]) for k in range(t)], axis=1)
    ran = b.run(cp, cv, y)
    np.testing.assert_array_equal(stepped, ran)
    np.testing.assert_array_equal(a.mean, b.mean)
    np.testing.assert_allclose(a.expected_xi, ran[:, -1, 2] - ran[:, -1, 0])
    # Reset two envs (mask and index forms): they restart, the others are untouched.
    before = a.probabilities
    a.reset(np.array([1, 3]), np.array([0.1, -0.2]))
    after = a.probabilities
    np.testing.assert_array_equal(after[[0, 2, 4]], before[[0, 2, 4]])
    np.testing.assert_allclose(after[[1, 3]], 1 / 3)
    np.testing.assert_allclose(a.mean[[1, 3]], [[0.1, 0.0, 0.1], [-0.2, 0.0, -0.2]])
    mask = np.zeros(n, dtype=bool)
    mask[0] = True
    a.reset(mask, 0.0)
    np.testing.assert_allclose(a.probabilities[0], 1 / 3)


def test_imm_without_switching_reduces_to_mmae() -> None:
    # p_ij = identity: mixing weights are the identity, so IMM is exactly MMAE.
    rng = np.random.default_rng(3)
    n, t = 4, 200
    cp, cv = _cues(rng, n, t)
    y = np.cumsum(rng.normal(0.0, 0.003, (n, t)), axis=1)
    mm = MultipleModelEstimator.from_model(NOISY, y[:, 0], probability_floor=0.0)
    imm = IMMEstimator.from_model(NOISY, y[:, 0], probability_floor=0.0, switching_rate_per_s=0.0)
    np.testing.assert_allclose(imm.run(cp, cv, y), mm.run(cp, cv, y), rtol=0, atol=1e-12)
    np.testing.assert_allclose(imm.covariance, mm.covariance, rtol=1e-10, atol=1e-18)


def _reference_imm(
    model: NominalModel, trans: np.ndarray, y: np.ndarray, cp: np.ndarray, cv: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Textbook IMM (Bar-Shalom) in plain NumPy, linear-space probabilities, dense matrices."""
    dt = model.dt_s
    a4 = model.transition_matrix(0.0, 0.0)
    F = a4[:3, :3]
    Q = model.process_covariance[:3, :3]
    R = model.measurement_variance
    H = np.array([[1.0, 0.0, 0.0]])
    means = [np.array([y[0], 0.0, y[0]]) for _ in range(3)]
    P0 = np.diag([R, model.initial_velocity_std_m_per_s**2, model.initial_intention_std_m**2])
    covs = [P0.copy() for _ in range(3)]
    mu = np.full(3, 1 / 3)
    out = []
    for t in range(1, len(y)):
        cbar = trans.T @ mu
        w = trans * mu[:, None] / cbar[None, :]  # w[i, j] = mu_{i|j}
        mixed_m = [sum(w[i, j] * means[i] for i in range(3)) for j in range(3)]
        mixed_P = [
            sum(w[i, j] * (covs[i] + np.outer(means[i] - mixed_m[j], means[i] - mixed_m[j])) for i in range(3))
            for j in range(3)
        ]
        lik = np.empty(3)
        for j, xi in enumerate((-1.0, 0.0, 1.0)):
            B = np.array([[0.0, 0.0], [model.push_compliance_m_per_s2_n * dt, 0.0], [0.0, 0.0]])
            B[2] = [xi * model.push_gain_m_per_s_n * dt, xi * model.verbal_gain_m_per_s * dt]
            m = F @ mixed_m[j] + B @ np.array([cp[t], cv[t]])
            P = F @ mixed_P[j] @ F.T + Q
            S = float((H @ P @ H.T)[0, 0]) + R
            K = (P @ H.T / S).ravel()
            e = y[t] - m[0]
            means[j] = m + K * e
            IKH = np.eye(3) - np.outer(K, H)
            covs[j] = IKH @ P @ IKH.T + R * np.outer(K, K)
            lik[j] = np.exp(-0.5 * e * e / S) / np.sqrt(2 * np.pi * S)
        mu = lik * cbar / np.sum(lik * cbar)
        out.append(mu)
    return np.array(out), np.array(means)


def test_imm_equals_textbook_reference() -> None:
    rng = np.random.default_rng(8)
    t = 120
    cp = np.zeros(t)
    cv = np.where((np.arange(t) // 20) % 2 == 0, 1.0, -1.0)
    cp[40:70] = 10.0
    xi = np.where(np.arange(t) < 60, 1.0, -1.0)
    model = NominalModel()
    y, _ = simulate_nominal(model, cp, cv, xi, rng)
    trans = np.array([[0.98, 0.012, 0.008], [0.01, 0.98, 0.01], [0.005, 0.015, 0.98]])
    expected, expected_means = _reference_imm(model, trans, y, cp, cv)
    imm = IMMEstimator.from_model(model, y[:1], probability_floor=0.0, transition_matrix=trans)
    probs = imm.run(cp[None, 1:], cv[None, 1:], y[None, 1:])[0]
    np.testing.assert_allclose(probs, expected, rtol=0, atol=1e-10)
    np.testing.assert_allclose(imm.means[0], expected_means, rtol=0, atol=1e-12)
    assert np.ptp(probs[:, 2]) > 0.5  # the modes actually moved


@pytest.mark.parametrize("cls", [MultipleModelEstimator, IMMEstimator])
def test_probabilities_stay_finite_on_garbage_and_recover(cls: type) -> None:
    rng = np.random.default_rng(4)
    n, t = 4, 100_000
    cp = np.where(rng.random((n, t)) < 0.5, rng.uniform(0.0, 2000.0, (n, t)), 0.0)
    cv = rng.integers(-1, 2, (n, t)).astype(float)
    y = rng.uniform(-1.0, 1.0, (n, t))  # measurement garbage up to 1 m
    y[1] = np.where(rng.random(t) < 0.001, 1.0, 0.0)  # rare 1 m spikes on a still person
    # A low-velocity-noise model, so the clean responses afterwards are decisive within seconds.
    model = NominalModel(velocity_process_std_m_per_s=0.004)
    est = cls.from_model(model, np.zeros(n))
    probs = est.run(cp, cv, y)
    assert np.all(np.isfinite(probs))
    assert np.all(probs >= 0.0)
    np.testing.assert_allclose(probs.sum(axis=-1), 1.0, atol=1e-12)
    assert np.all(np.isfinite(est.log_probabilities))
    assert np.all(np.isfinite(est.mean))
    # No lock-out: afterwards, clean cooperative responses win the estimator back within seconds.
    clean_cp = np.zeros((n, 400))
    clean_cv = np.broadcast_to(np.where((np.arange(400) // 50) % 2 == 0, 1.0, -1.0), (n, 400))
    clean = np.array([simulate_nominal(model, clean_cp[0], clean_cv[0], 1, rng)[0] for _ in range(n)])
    recovered = est.run(clean_cp, clean_cv, clean)
    assert np.all(recovered[:, -1, 2] > 0.9)


def test_floor_prevents_lock_out_but_exact_bayes_locks() -> None:
    model = NominalModel()
    rng = np.random.default_rng(5)
    t = 600
    cv = np.where((np.arange(t) // 50) % 2 == 0, 1.0, -1.0)
    cp = np.zeros(t)
    xi = np.where(np.arange(t) < 300, -1.0, 1.0)
    y, _ = simulate_nominal(model, cp, cv, xi, rng)
    floored = MultipleModelEstimator.from_model(model, y[:1], probability_floor=1e-4)
    exact = MultipleModelEstimator.from_model(model, y[:1], probability_floor=0.0)
    floored = floored.run(cp[None, 1:], cv[None, 1:], y[None, 1:])
    exact = exact.run(cp[None, 1:], cv[None, 1:], y[None, 1:])
    assert floored[0, 290, 0] > 0.99 and exact[0, 290, 0] > 0.99
    assert floored[0, -1, 2] > 0.99  # the floor lets the new mode take over
    assert exact[0, 420, 2] < 0.5  # exact Bayes for a constant xi still trusts the first half


def test_imm_tracks_a_switch_faster_than_mmae() -> None:
    model = NominalModel()
    rng = np.random.default_rng(6)
    t, switch = 1500, 750
    cv = np.where((np.arange(t) // 50) % 2 == 0, 1.0, -1.0)  # alternate "lean forward" / "lean back" each second
    cp = np.zeros(t)
    xi = np.where(np.arange(t) < switch, 1.0, -1.0)
    y, _ = simulate_nominal(model, cp, cv, xi, rng)
    imm = IMMEstimator.from_model(model, y[:1], switching_rate_per_s=0.1)
    p = imm.run(cp[None, 1:], cv[None, 1:], y[None, 1:])[0]
    judged = map_judgment(p)  # p[k] is after measurement k + 1
    before = judged[100 : switch - 1]
    after = judged[switch + 100 :]
    assert np.mean(before == 1) > 0.95
    assert np.mean(after == -1) > 0.95
    delay_imm = _first(p[switch - 1 :, 0] > 0.9)
    assert 0 < delay_imm < 100  # under 2 s
    # A floored MMAE follows too, later; exact Bayes for a constant xi does not within the trial.
    floored = MultipleModelEstimator.from_model(model, y[:1], probability_floor=1e-6)
    delay_floored = _first(floored.run(cp[None, 1:], cv[None, 1:], y[None, 1:])[0, switch - 1 :, 0] > 0.9)
    assert delay_imm <= delay_floored < t - switch
    exact = MultipleModelEstimator.from_model(model, y[:1], probability_floor=0.0)
    assert _first(exact.run(cp[None, 1:], cv[None, 1:], y[None, 1:])[0, switch - 1 :, 0] > 0.9) == t - switch


def _first(condition: np.ndarray) -> int:
    """Index of the first True, or the length if none."""
    return int(np.argmax(condition)) if condition.any() else len(condition)


def test_map_judgment_and_calibration_on_nominal_data() -> None:
    model = NominalModel(position_noise_std_m=0.01)  # noisier than default, so mistakes are possible
    rng = np.random.default_rng(7)
    trials = simulate_nominal_trials(model, 150, 300, rng)
    y = np.array([tr.measured_position_m for tr in trials])
    cp = np.array([tr.push_force_n for tr in trials])
    cv = np.array([tr.verbal_cue for tr in trials])
    xi = np.array([tr.xi for tr in trials])
    mm = MultipleModelEstimator.from_model(model, y[:, 0])
    probs = mm.run(cp[:, 1:], cv[:, 1:], y[:, 1:])
    final = probs[:, -1]
    assert np.mean(map_judgment(final) == xi) > 0.9
    assert accuracy(final, xi) > 0.9
    # The posterior is calibrated when the model matches.
    assert log_loss(final, xi) < 0.3
    assert brier_score(final, xi) < 0.15
    assert expected_calibration_error(final, xi) < 0.08
    # Paper-style judgment 0.75 s after the first cue onset: still mostly right.
    onset = np.array([np.argmax((c != 0) | (v != 0)) for c, v in zip(cp, cv, strict=True)])
    at = np.clip(onset - 1 + round(0.75 / model.dt_s), 0, probs.shape[1] - 1)
    early = probs[np.arange(len(trials)), at]
    assert np.mean(map_judgment(early) == xi) > 0.7
    # Confidence rule: fewer decisions, but more precise ones.
    judged, decided = confident_judgment(final, 0.99)
    assert decided.mean() > 0.5
    assert np.mean(judged[decided] == xi[decided]) >= np.mean(map_judgment(final) == xi)
    assert np.all(judged[~decided] == 0)
    # SPRT-style earliest decision: decided before the end in most trials, and right.
    seq, when = sequential_judgment(probs, error_rate=0.01, start_step=onset)
    done = when >= 0
    assert done.mean() > 0.8
    assert np.all(when[done] >= onset[done])
    assert np.mean(seq[done] == xi[done]) > 0.95


def test_decision_rules_on_crafted_probabilities() -> None:
    p = np.array([[0.5, 0.2, 0.3], [0.1, 0.2, 0.7], [1 / 3, 1 / 3, 1 / 3], [0.45, 0.1, 0.45], [0.0, 0.05, 0.95]])
    np.testing.assert_array_equal(map_judgment(p), [-1, 1, 0, -1, 1])
    judged, decided = confident_judgment(p, 0.7)
    np.testing.assert_array_equal(judged, [0, 1, 0, 0, 1])
    np.testing.assert_array_equal(decided, [False, True, False, False, True])
    seq = np.array([[[0.4, 0.3, 0.3], [0.1, 0.1, 0.8], [0.01, 0.01, 0.98]], [[0.9, 0.05, 0.05]] * 3])
    judgment, step = sequential_judgment(seq, error_rate=0.05)
    np.testing.assert_array_equal(judgment, [1, 0])  # (0.9/0.05 = 18 < 19: never decided)
    np.testing.assert_array_equal(step, [2, -1])
    judgment, step = sequential_judgment(seq, error_rate=0.1)
    np.testing.assert_array_equal(judgment, [1, -1])
    np.testing.assert_array_equal(step, [2, 0])
    with pytest.raises(ValueError, match="last axis"):
        map_judgment(np.ones((2, 2)))
    with pytest.raises(ValueError, match="confidence"):
        confident_judgment(p, 1.5)
    with pytest.raises(ValueError, match="error_rate"):
        sequential_judgment(seq, error_rate=0.7)


def test_metrics_reference_values() -> None:
    labels = np.array([-1, 0, 1, 1])
    perfect = np.eye(3)[labels + 1]
    uniform = np.full((4, 3), 1 / 3)
    assert log_loss(perfect, labels) == pytest.approx(0.0, abs=1e-12)
    assert log_loss(uniform, labels) == pytest.approx(np.log(3))
    assert brier_score(perfect, labels) == 0.0
    assert brier_score(uniform, labels) == pytest.approx(2 / 3)
    assert expected_calibration_error(perfect, labels) == pytest.approx(0.0)
    # Always 80% sure and right 3 times out of 4: ECE = |0.75 - 0.8|.
    p = np.array([[0.8, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.1, 0.8], [0.8, 0.1, 0.1]])
    assert expected_calibration_error(p, labels) == pytest.approx(0.05)
    assert accuracy(p, labels) == 0.75
    with pytest.raises(ValueError, match="labels"):
        log_loss(p, np.array([2, 0, 1, 1]))
    with pytest.raises(ValueError, match="summing to 1"):
        brier_score(p * 2, labels)


def test_bad_input_raises_clear_errors() -> None:
    mm = MultipleModelEstimator.from_model(NominalModel(), np.zeros(3))
    with pytest.raises(ValueError, match="shape"):
        mm.step(np.zeros(2), np.zeros(3), np.zeros(3))
    with pytest.raises(ValueError, match="finite"):
        mm.step(np.zeros(3), np.array([0.0, np.nan, 0.0]), np.zeros(3))
    np.testing.assert_allclose(mm.probabilities, 1 / 3)  # the rejected step changed nothing
    with pytest.raises(ValueError, match="finite"):
        mm.run(np.zeros((3, 4)), np.zeros((3, 4)), np.full((3, 4), np.inf))
    with pytest.raises(ValueError, match="probability_floor"):
        MultipleModelEstimator.from_model(NominalModel(), np.zeros(1), probability_floor=0.5)
    with pytest.raises(ValueError, match="mode_prior"):
        MultipleModelEstimator.from_model(NominalModel(), np.zeros(1), mode_prior=[1.0, -1.0, 1.0])
    with pytest.raises(ValueError, match="row-stochastic"):
        IMMEstimator.from_model(NominalModel(), np.zeros(1), transition_matrix=np.ones((3, 3)))
    with pytest.raises(ValueError, match="nominal_rows"):
        MultipleModelEstimator(np.zeros((2, 5)), np.zeros(2))
    # A scalar input is one value for every env.
    assert mm.step(0.0, 0.0, 0.0).shape == (3, 3)


def test_switching_transition_matrix() -> None:
    p = switching_transition_matrix(0.5, 0.02)
    np.testing.assert_allclose(p.sum(axis=1), 1.0)
    assert p[0, 0] == pytest.approx(np.exp(-0.01))
    assert p[0, 1] == p[0, 2] == pytest.approx((1 - np.exp(-0.01)) / 2)
    np.testing.assert_array_equal(switching_transition_matrix(0.0, 0.02), np.eye(3))


@settings(max_examples=30, deadline=None)
@given(
    floor=st.floats(0.0, 0.3),
    rate=st.floats(0.0, 50.0),
    prior=st.lists(st.floats(0.01, 1.0), min_size=3, max_size=3),
    seed=st.integers(0, 2**16),
    scale=st.sampled_from([1e-6, 1e-3, 1.0, 10.0]),
)
def test_property_probabilities_are_distributions(
    floor: float, rate: float, prior: list[float], seed: int, scale: float
) -> None:
    rng = np.random.default_rng(seed)
    cp, cv = _cues(rng, 2, 60)
    y = rng.normal(0.0, scale, (2, 60))
    for est in (
        MultipleModelEstimator.from_model(NominalModel(), y[:, 0], probability_floor=floor, mode_prior=prior),
        IMMEstimator.from_model(
            NominalModel(), y[:, 0], probability_floor=floor, mode_prior=prior, switching_rate_per_s=rate
        ),
    ):
        probs = est.run(cp * scale, cv, y)
        assert np.all(np.isfinite(probs)) and np.all(probs >= 0)
        np.testing.assert_allclose(probs.sum(axis=-1), 1.0, atol=1e-12)
        if floor > 0:
            # Every mode keeps at least the floor before each update, so none is locked at 0.
            assert np.all(est.log_probabilities > -np.inf)
