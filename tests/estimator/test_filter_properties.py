"""Property-based robustness of the filters over their parameter space and arbitrary data.

* The paper's filter (:class:`FastKalmanFilter`, :func:`kalman_step`): means, covariances and
  log-likelihoods finite; every covariance symmetric positive semi-definite; the compiled
  filter agrees with the filterpy reference.
* The multiple-model estimators (MMAE and IMM): the mode probabilities stay a distribution
  (finite, in [0, 1], summing to 1, log-probabilities finite) even on data the model does not
  explain (where linear-space implementations underflow to 0/0); their covariances stay
  symmetric PSD.

Models are drawn over the ranges the env can hand the filter (``nominal_model_for`` of any
valid persona and timing) and beyond for the noise levels. Run ``pytest -s`` to see how many
examples each property ran.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from estimator import multiple_model as mm
from estimator.kalman import FastKalmanFilter, PaperKalmanFilter, kalman_step, nominal_row
from estimator.nominal import NominalModel

EXAMPLES: Counter[str] = Counter()
COMMON = settings(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


def _number(low: float, high: float) -> st.SearchStrategy[float]:
    return st.one_of(st.sampled_from([low, high]), st.floats(low, high, allow_nan=False, allow_infinity=False))


# NominalModel field -> range drawn. The gains and dt span what the env can produce from a valid
# persona and timing (coop_gym.model.params ranges); noise levels go from near zero to large.
MODEL_RANGES: dict[str, tuple[float, float]] = {
    "dt_s": (1e-4, 0.1),
    "damping_rate_per_s": (0.01, 100.0),
    "voluntary_gain_per_s2": (0.01, 1000.0),
    "push_compliance_m_per_s2_n": (0.0, 1.0),
    "push_gain_m_per_s_n": (0.0, 1.0),
    "verbal_gain_m_per_s": (0.0, 10.0),
    "position_noise_std_m": (1e-6, 1.0),
    "velocity_process_std_m_per_s": (0.0, 1.0),
    "intention_process_std_m": (0.0, 1.0),
    "cooperativeness_process_std": (0.0, 1.0),
    "position_process_std_m": (0.0, 1.0),
    "initial_velocity_std_m_per_s": (0.0, 10.0),
    "initial_intention_std_m": (0.0, 10.0),
    "initial_cooperativeness_std": (0.0, 10.0),
}


def test_model_ranges_name_every_field() -> None:
    import dataclasses

    assert set(MODEL_RANGES) == {f.name for f in dataclasses.fields(NominalModel)}


def euler_stable(model: NominalModel) -> bool:
    """Whether the filter's Euler step of eq. 1, ``[[1, dt], [-k1 dt, 1 - lambda1 dt]]``, is stable.

    With ``a = k1 dt^2`` and ``b = lambda1 dt`` (Jury): ``max(0, 2b - 4) < a < b``. The true
    dynamics is always stable; the Euler model of a stiff person is not (``k1 dt > lambda1``:
    k1 = 1000 /s^2 at the env's 20 ms is already outside).
    """
    a = model.voluntary_gain_per_s2 * model.dt_s**2
    b = model.damping_rate_per_s * model.dt_s
    return max(0.0, 2.0 * b - 4.0) < a < b


@st.composite
def models(draw: st.DrawFn) -> NominalModel:
    """Any NominalModel over MODEL_RANGES (process noise down to zero) whose Euler model is stable."""
    values = {name: draw(_number(lo, hi)) for name, (lo, hi) in MODEL_RANGES.items()}
    # Place k1 inside the stable band for the drawn dt and lambda1 (see euler_stable).
    dt, damping = values["dt_s"], values["damping_rate_per_s"]
    b = damping * dt
    low, high = max(0.0, 2.0 * b - 4.0), b
    fraction = draw(st.floats(0.01, 0.99))
    values["voluntary_gain_per_s2"] = min(max((low + fraction * (high - low)) / dt**2, 0.01), 1000.0)
    model = NominalModel(**values)
    assume(euler_stable(model))
    return model


@st.composite
def env_models(draw: st.DrawFn) -> NominalModel:
    """What ``nominal_model_for`` can build: any gains and dt (Euler-unstable ones too), the
    default process noise and prior, a camera noise of at least 0.1 mm."""
    names = ("dt_s", "damping_rate_per_s", "voluntary_gain_per_s2", "push_compliance_m_per_s2_n",
             "push_gain_m_per_s_n", "verbal_gain_m_per_s")  # fmt: skip
    values = {name: draw(_number(*MODEL_RANGES[name])) for name in names}
    return NominalModel(**values, position_noise_std_m=draw(_number(1e-4, 1.0)))


@st.composite
def raw_models(draw: st.DrawFn) -> NominalModel:
    """Any NominalModel over MODEL_RANGES, Euler-unstable and noise-free ones included."""
    return NominalModel(**{name: draw(_number(lo, hi)) for name, (lo, hi) in MODEL_RANGES.items()})


def any_model() -> st.SearchStrategy[NominalModel]:
    return st.one_of(models(), env_models())


@st.composite
def sequences(draw: st.DrawFn, n_envs: int = 1, max_steps: int = 300) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(push_force_n, verbal_cue, measured_position_m), each (n_envs, T): arbitrary cues and data."""
    steps = draw(st.integers(1, max_steps))
    shape = (n_envs, steps)
    push = draw(hnp.arrays(np.float64, shape, elements=_number(0.0, 200.0)))
    verbal = draw(hnp.arrays(np.float64, shape, elements=st.sampled_from([-1.0, 0.0, 1.0])))
    scale = draw(st.sampled_from([0.01, 1.0, 100.0]))  # 100 m: data no model explains
    y = draw(hnp.arrays(np.float64, shape, elements=_number(-1.0, 1.0))) * scale
    return push, verbal, y


def assert_symmetric_psd(P: np.ndarray, where: str) -> None:
    """Every trailing (k, k) matrix of ``P`` is finite, symmetric and PSD (to rounding)."""
    assert np.all(np.isfinite(P)), f"{where}: non-finite covariance"
    scale = np.maximum(1.0, np.max(np.abs(P), axis=(-1, -2)))[..., None, None]
    asym = np.abs(P - np.swapaxes(P, -1, -2)) / scale
    assert asym.max() <= 1e-12, f"{where}: asymmetry {asym.max()}"
    eig = np.linalg.eigvalsh(0.5 * (P + np.swapaxes(P, -1, -2)))
    worst = (eig / scale[..., 0]).min()
    assert worst >= -1e-10, f"{where}: covariance not PSD (smallest eigenvalue / scale = {worst})"


# --------------------------------------------------------------------------- paper filter


def _check_fast_run(model: NominalModel, data: tuple[np.ndarray, np.ndarray, np.ndarray]) -> tuple[Any, ...]:
    push, verbal, y = data
    kf = FastKalmanFilter.from_model(model, y[:, 0])
    means, covs, loglik = kf.run(push, verbal, y)
    assert np.all(np.isfinite(means)), "non-finite mean"
    assert np.all(np.isfinite(loglik)), "non-finite log-likelihood"
    assert_symmetric_psd(covs, "FastKalmanFilter.run")
    assert_symmetric_psd(kf.P, "FastKalmanFilter.P")
    return means, covs


@settings(COMMON, max_examples=100)
@given(model=any_model(), data=sequences(n_envs=3))
def test_fast_filter_stays_finite_and_psd(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    EXAMPLES["fast_filter_stays_finite_and_psd"] += 1
    _check_fast_run(model, data)


@pytest.mark.slow
@settings(COMMON, max_examples=3000)
@given(model=any_model(), data=sequences(n_envs=3, max_steps=3000))
def test_fast_filter_stays_finite_and_psd_long(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    EXAMPLES["fast_filter_stays_finite_and_psd_long"] += 1
    _check_fast_run(model, data)


@settings(COMMON, max_examples=50)
@given(model=any_model(), data=sequences(max_steps=100))
def test_kalman_step_in_place_stays_finite_and_psd(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    """The kernel the env calls, one step at a time on its own arrays."""
    EXAMPLES["kalman_step_in_place_stays_finite_and_psd"] += 1
    push, verbal, y = (a[0] for a in data)
    m = model.initial_state(float(y[0]))
    P = model.initial_covariance()
    row = nominal_row(model)
    for t in range(y.shape[0]):
        innovation, S = kalman_step(m, P, row, float(push[t]), float(verbal[t]), float(y[t]))
        assert np.isfinite(innovation) and np.isfinite(S) and S > 0, (t, innovation, S)
        assert np.all(np.isfinite(m)), t
        assert_symmetric_psd(P, f"kalman_step {t}")


def long_double_filter(
    model: NominalModel, push: np.ndarray, verbal: np.ndarray, y: np.ndarray, store_as_double: bool = False
) -> tuple[np.ndarray, np.ndarray]:
    """The paper filter's equations in extended precision: the "exact" answer to judge rounding by.

    With ``store_as_double`` the state is rounded to float64 wherever a predict/update filter
    keeps it (the prior after the predict, the posterior after the update), as the paper's
    filter, filterpy and the compiled one all do: every operation exact, only the stored states
    rounded. Its distance from the exact answer is the error floor of such a filter in double
    precision on this problem -- what the problem's own conditioning makes of half an ulp.
    """
    L = np.longdouble
    x = model.initial_state(float(y[0])).astype(L)
    P = model.initial_covariance().astype(L)
    Q, B, R = model.process_covariance.astype(L), model.input_vector.astype(L), L(model.measurement_variance)
    means, covs = [], []
    for t in range(y.shape[0]):
        A = model.transition_matrix(float(push[t]), float(verbal[t])).astype(L)
        x = A @ x + B * L(push[t])
        P = A @ P @ A.T + Q
        if store_as_double:
            x, P = x.astype(np.float64).astype(L), P.astype(np.float64).astype(L)
        K = P[:, 0] / (P[0, 0] + R)
        x = x + K * (L(y[t]) - x[0])
        IKH = np.eye(4, dtype=L) - np.outer(K, np.array([1, 0, 0, 0], dtype=L))
        P = IKH @ P @ IKH.T + np.outer(K, K) * R
        if store_as_double:
            x, P = x.astype(np.float64).astype(L), P.astype(np.float64).astype(L)
        means.append(x.astype(np.float64))
        covs.append(P.astype(np.float64))
    return np.array(means), np.array(covs)


@st.composite
def well_conditioned_models(draw: st.DrawFn) -> NominalModel:
    """Euler-stable models whose updates stay well conditioned: camera noise >= 0.1 mm (the env's
    floor), process noise >= 1e-4 per step, prior stds at most 1000 camera stds (variance ratio
    <= 1e6; the env's is ~6e4)."""
    model = draw(models())
    camera = draw(_number(1e-4, 1.0))
    noise = {
        "position_noise_std_m": camera,
        **{name: draw(_number(1e-4, 1.0)) for name in MODEL_RANGES if name.endswith("process_std_m")},
        "velocity_process_std_m_per_s": draw(_number(1e-4, 1.0)),
        "cooperativeness_process_std": draw(_number(1e-4, 1.0)),
        **{
            name: draw(_number(1e-3, min(10.0, 1000.0 * camera)))
            for name in MODEL_RANGES
            if name.startswith("initial_")
        },
    }
    return model.replace(**noise)


STRICT, EDGE = 1e-9, 1e-6
"""Accuracy bounds relative to each quantity's scale: well-conditioned problems, edge models."""

FLOOR_FRACTION = 0.1
"""A problem is well conditioned for the strict bound when double precision itself allows it
with room to spare: the exact filter with its prior and posterior stored in doubles (the error
floor of a predict/update filter in double precision) stays within ``FLOOR_FRACTION * STRICT``
of the exact answer."""


def _scaled_errors(
    model: NominalModel, data: tuple[np.ndarray, ...], means: np.ndarray, covs: np.ndarray
) -> dict[str, np.ndarray]:
    """Per step, each filter's distance from the extended-precision answer, relative to each
    quantity's scale: ``(T, 2)`` arrays of (mean, covariance) errors for "fast", "filterpy" and
    "floor" (the exact filter with its state stored in doubles, see :func:`long_double_filter`)."""
    push, verbal, y = (a[0] for a in data)
    ref = PaperKalmanFilter(model, first_position_m=float(y[0]))
    exact_m, exact_p = long_double_filter(model, push, verbal, y)
    floor_m, floor_p = long_double_filter(model, push, verbal, y, store_as_double=True)
    errors = {name: np.zeros((y.shape[0], 2)) for name in ("fast", "filterpy", "floor")}
    p_scale = float(np.max(np.abs(ref.covariance)))
    for t in range(y.shape[0]):
        mean = ref.step(float(push[t]), float(verbal[t]), float(y[t]))
        cov = ref.covariance
        m_scale = max(1.0, float(np.max(np.abs(mean))))
        # Rounding is relative to the largest covariance met so far: updates with a tiny R cancel
        # it down by many orders (e.g. 100 -> 1e-11), leaving the filters ~1e-16 * that apart.
        p_scale = max(p_scale, 1e-300, float(np.max(np.abs(ref.kf.P_prior))), float(np.max(np.abs(cov))))
        for name, (got_m, got_p) in (
            ("fast", (means[0, t], covs[0, t])), ("filterpy", (mean, cov)), ("floor", (floor_m[t], floor_p[t]))
        ):  # fmt: skip
            errors[name][t] = np.max(np.abs(got_m - exact_m[t])) / m_scale, np.max(np.abs(got_p - exact_p[t])) / p_scale
    return errors


def _compare_with_filterpy(model: NominalModel, data: tuple[np.ndarray, ...], strict: bool) -> float:
    """Both filters (the compiled one and filterpy) within a tolerance of the extended-precision
    answer, relative to each quantity's scale: ``strict`` 1e-9 where the problem is well
    conditioned (see :data:`FLOOR_FRACTION`); otherwise 1e-6 (edge models, where rounding is
    amplified: a stiff Euler model at dt 0.1 s swings the covariance through 1e6 within a step;
    a camera noise of 1 um against a prior of 10 m).

    Each filter is held to the exact answer, not to the other: two rounded answers differ by the
    sum of their errors. The long run found a model (a 200 N push at dt 0.1 s, covariance
    condition ~1.6e9) where the compiled filter was 7.7e-10 and filterpy 2.4e-10 from the exact
    mean, so 1.007e-9 apart -- both accurate to 1e-9, neither to the other within it.

    Whether the strict bound applies is measured, not guessed from the model's noise levels:
    where even the exact filter with its state stored in doubles is more than
    ``FLOOR_FRACTION * 1e-9`` off (pushes of 200 N on a compliance of 1 m/s^2/N drove the
    covariance's condition to 3.5e11 and that floor to 5.1e-10), 1e-9 asks of a double-precision
    filter what double precision cannot promise, and the edge bound applies. Returns the
    tolerance applied.
    """
    means, covs = _check_fast_run(model, data)
    errors = _scaled_errors(model, data, means, covs)
    floor = float(errors["floor"].max())
    tolerance = STRICT if strict and floor <= FLOOR_FRACTION * STRICT else EDGE
    for name in ("fast", "filterpy"):
        worst = errors[name].max(axis=0)
        step = int(np.argmax(errors[name].max(axis=1)))
        assert worst.max() <= tolerance, (
            f"{name} is {worst[0]:.3g} (mean) / {worst[1]:.3g} (covariance) from the exact answer at step {step}, "
            f"tolerance {tolerance:g}, double-precision floor {floor:.3g}"
        )
    return tolerance


# The default run's accuracy properties draw a fixed set of examples (derandomize): their 1e-9
# bound is at the edge of double precision on the strongest pushes, and the long runs below
# (random, thousands of examples) found models past it (see the found models below). A CI run must
# not pass or fail by the luck of the draw; the exploration is the long runs' job.
@settings(COMMON, max_examples=40, derandomize=True)
@given(model=well_conditioned_models(), data=sequences(max_steps=150))
def test_fast_filter_matches_filterpy_everywhere(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    """Both filters within 1e-9 of the extended-precision answer wherever the problem is well conditioned."""
    EXAMPLES["fast_filter_matches_filterpy_everywhere"] += 1
    if _compare_with_filterpy(model, data, strict=True) == STRICT:
        EXAMPLES["fast_filter_matches_filterpy_everywhere (held to 1e-9)"] += 1


@settings(COMMON, max_examples=20, derandomize=True)
@given(model=any_model(), data=sequences(max_steps=150))
def test_fast_filter_and_filterpy_accurate_at_the_edges(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    EXAMPLES["fast_filter_and_filterpy_accurate_at_the_edges"] += 1
    _compare_with_filterpy(model, data, strict=False)


@pytest.mark.slow
@settings(COMMON, max_examples=1000)
@given(model=well_conditioned_models(), data=sequences(max_steps=1000))
def test_fast_filter_matches_filterpy_everywhere_long(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    EXAMPLES["fast_filter_matches_filterpy_everywhere_long"] += 1
    if _compare_with_filterpy(model, data, strict=True) == STRICT:
        EXAMPLES["fast_filter_matches_filterpy_everywhere_long (held to 1e-9)"] += 1


@pytest.mark.slow
@settings(COMMON, max_examples=500)
@given(model=any_model(), data=sequences(max_steps=1000))
def test_fast_filter_and_filterpy_accurate_at_the_edges_long(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    EXAMPLES["fast_filter_and_filterpy_accurate_at_the_edges_long"] += 1
    _compare_with_filterpy(model, data, strict=False)


def test_euler_unstable_model_without_process_noise_stays_psd() -> None:
    """Found by the long property run: with Q = 0, a stiff person's Euler model (|z| ~ 3.3 per
    step at dt 0.1 s) grows the covariance until the update's cancellation breaks it: P lost
    PSD and S went negative (NaN log-likelihood) within ~17 steps. kalman_step now projects an
    indefinite P back onto the PSD cone (a guard the env's models never reach)."""
    model = NominalModel(
        dt_s=0.1, damping_rate_per_s=0.01, voluntary_gain_per_s2=986.0, position_noise_std_m=1.0,
        velocity_process_std_m_per_s=0.0, intention_process_std_m=0.0, cooperativeness_process_std=0.0,
        position_process_std_m=0.0, initial_velocity_std_m_per_s=0.0, initial_intention_std_m=0.0,
        initial_cooperativeness_std=0.0,
    )  # fmt: skip
    assert not euler_stable(model)
    n = 40
    _check_fast_run(model, (np.zeros((1, n)), np.full((1, n), -1.0), np.full((1, n), -0.01)))


def test_edge_model_from_the_long_run_stays_finite_and_psd() -> None:
    """Found by the long property run: no process noise, a 1 um camera against a prior xi std of
    10, pushes of 200 N at dt 0.1 s. The update's cancellation (P_00 / R ~ 1e16) left P with an
    eigenvalue of -1e-10 of its scale and the next S negative: a NaN log-likelihood where filterpy
    gave 12.64. (The problem is beyond double precision -- condition ~1e17, the extended-precision
    filter loses PSD too -- so only finiteness and PSD are asked.)"""
    model = NominalModel(
        dt_s=0.1, damping_rate_per_s=6.0, voluntary_gain_per_s2=9.0, push_compliance_m_per_s2_n=1.0,
        push_gain_m_per_s_n=1.0, verbal_gain_m_per_s=0.0, position_noise_std_m=1e-6,
        velocity_process_std_m_per_s=0.0, intention_process_std_m=0.0, cooperativeness_process_std=0.0,
        position_process_std_m=0.0, initial_velocity_std_m_per_s=0.1, initial_intention_std_m=0.0,
        initial_cooperativeness_std=10.0,
    )  # fmt: skip
    rng = np.random.default_rng(18)
    n = 200
    data = (np.full((3, n), 200.0), rng.choice([-1.0, 0.0, 1.0], (3, n)), rng.uniform(-1.0, 1.0, (3, n)))
    _check_fast_run(model, data)


def _pushed_model(**changes: float) -> NominalModel:
    """The long strict property's found push models: damping 1 /s, push gain 1, no verbal gain, a
    0.1 mm camera, process noise 1e-4 (cooperativeness 1) and a 1e-3 prior; ``changes`` set the
    step, the voluntary gain and the push compliance."""
    base = NominalModel(
        damping_rate_per_s=1.0, push_gain_m_per_s_n=1.0, verbal_gain_m_per_s=0.0, position_noise_std_m=1e-4,
        velocity_process_std_m_per_s=1e-4, intention_process_std_m=1e-4, cooperativeness_process_std=1.0,
        position_process_std_m=1e-4, initial_velocity_std_m_per_s=1e-3, initial_intention_std_m=1e-3,
        initial_cooperativeness_std=1e-3,
    )  # fmt: skip
    return base.replace(**changes)


def test_both_filters_accurate_where_they_disagree_by_their_summed_rounding() -> None:
    """Found by the long strict property: after a 200 N push at dt 0.1 s (condition ~1.6e9) the
    compiled filter and filterpy were 1.007e-9 apart on the velocity mean, each within 1e-9 of
    the extended-precision answer (7.7e-10 and 2.4e-10). Its double-precision floor is 1.6e-10
    (past FLOOR_FRACTION, so the property now holds it at the edge bound); held here to 1e-9."""
    model = _pushed_model(dt_s=0.1, voluntary_gain_per_s2=4.999999999999999, push_compliance_m_per_s2_n=0.0)
    push = np.zeros((1, 16))
    push[0, 6] = 200.0
    data = (push, np.full((1, 16), -1.0), np.array([[-0.01] + [0.01] * 15]))
    means, covs = _check_fast_run(model, data)
    errors = _scaled_errors(model, data, means, covs)
    assert 1e-10 < errors["floor"].max() < 2e-10, errors["floor"].max()
    for name in ("fast", "filterpy"):
        assert errors[name].max() <= STRICT, (name, errors[name].max())


def test_repeated_200n_pushes_are_past_the_double_precision_floor() -> None:
    """Found by the long strict property (the models the env can build: compliance up to 1, pushes
    up to 200 N): the compiled filter's mean was 1.09e-9 (relative) from the extended-precision
    answer, past the strict 1e-9; filterpy's 2.4e-10. No repair is involved. The problem itself
    is the cause: the covariance's condition reaches 3.5e11, and a filter doing every operation
    exactly but storing its prior and posterior in doubles is 5.1e-10 off -- half the strict
    bound. So the strict bound does not apply (FLOOR_FRACTION); both filters stay within a few
    times that floor (compiled 2.2x, filterpy 0.5x)."""
    model = _pushed_model(dt_s=0.09375, voluntary_gain_per_s2=5.333333333333333, push_compliance_m_per_s2_n=1.0)
    data = (np.array([[200.0, 200.0, 0.0, 200.0, 200.0]]), np.full((1, 5), -1.0), np.full((1, 5), -0.01))
    means, covs = _check_fast_run(model, data)
    errors = _scaled_errors(model, data, means, covs)
    floor = errors["floor"].max()
    assert 4e-10 < floor < 6e-10, floor
    for name in ("fast", "filterpy"):
        assert errors[name].max() <= 4.0 * floor, (name, errors[name].max(), floor)
    assert _compare_with_filterpy(model, data, strict=True) == EDGE


def test_repair_keeps_small_variances_accurate() -> None:
    """Found by the long accuracy property: a 1 um camera against a prior intention std of 10 and
    no process noise. The Joseph update leaves P a hair indefinite (rounding), and projecting it
    back in P's own scale moved the 5e-13 position variance by eps * 100 = 1e-14 (1.6 %), which
    grew to 0.35 % on P[2, 2] within 4 steps. The projection now works in P's diagonal scale."""
    model = NominalModel(
        dt_s=1e-4, damping_rate_per_s=0.01, voluntary_gain_per_s2=3.1250000000000004, push_compliance_m_per_s2_n=0.0,
        push_gain_m_per_s_n=0.0, verbal_gain_m_per_s=0.0, position_noise_std_m=1e-6,
        velocity_process_std_m_per_s=0.0, intention_process_std_m=0.0, cooperativeness_process_std=0.0,
        position_process_std_m=0.0, initial_velocity_std_m_per_s=0.0, initial_intention_std_m=10.0,
        initial_cooperativeness_std=0.0,
    )  # fmt: skip
    data = (np.zeros((1, 4)), np.full((1, 4), -1.0), np.full((1, 4), -0.01))
    _, covs = _check_fast_run(model, data)
    exact = long_double_filter(model, *(a[0] for a in data))[1]
    # Each entry within 1e-12 of its own scale sqrt(P_ii P_jj) (the old repair: 1.6e-2 at step 2).
    d = np.sqrt(np.einsum("tii->ti", exact))
    assert np.all(np.abs(covs[0] - exact) <= 1e-12 * d[:, :, None] * d[:, None, :])
    _compare_with_filterpy(model, data, strict=False)


def test_repair_ignores_variances_below_rounding() -> None:
    """Found by the long edge property: no intention noise or prior, a 1 um camera, opposite verbal
    cues. After 4 steps the intention variance is ~5e-41 (known exactly, up to rounding) beside
    off-diagonal rounding of ~1e-18, and P fails the PSD test. Scaling the repair by that variance
    made the scaled entries ~1e4 and the repaired P[1, 1] 2.3e9 (exact: 1.04). The repair's scale
    now ignores variances below eps * the largest; the filter is within 1e-6 of the exact answer."""
    model = NominalModel(
        dt_s=0.046875, damping_rate_per_s=2.5, voluntary_gain_per_s2=26.666666666666668, push_compliance_m_per_s2_n=0.0,
        push_gain_m_per_s_n=0.0, verbal_gain_m_per_s=3.9940423778111542, position_noise_std_m=1e-06,
        velocity_process_std_m_per_s=1.0, intention_process_std_m=0.0, cooperativeness_process_std=0.0,
        position_process_std_m=0.0, initial_velocity_std_m_per_s=0.0, initial_intention_std_m=0.0,
        initial_cooperativeness_std=1.0,
    )  # fmt: skip
    data = (np.zeros((1, 4)), np.array([[-1.0, -1.0, 1.0, 1.0]]), np.full((1, 4), -0.01))
    assert _compare_with_filterpy(model, data, strict=False) == EDGE


@settings(COMMON, max_examples=30)
@given(model=raw_models(), data=sequences(n_envs=2, max_steps=300))
def test_fast_filter_stays_finite_and_psd_on_any_model(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    """The paper filter on every model of MODEL_RANGES, Euler-unstable and noise-free ones included."""
    EXAMPLES["fast_filter_stays_finite_and_psd_on_any_model"] += 1
    _check_fast_run(model, data)


@pytest.mark.slow
@settings(COMMON, max_examples=300)
@given(model=raw_models(), data=sequences(n_envs=2, max_steps=3000))
def test_fast_filter_stays_finite_and_psd_on_any_model_long(model: NominalModel, data: tuple[np.ndarray, ...]) -> None:
    EXAMPLES["fast_filter_stays_finite_and_psd_on_any_model_long"] += 1
    _check_fast_run(model, data)


# --------------------------------------------------------------------------- multiple model


@st.composite
def mode_priors(draw: st.DrawFn) -> np.ndarray | None:
    weights = draw(st.one_of(st.none(), hnp.arrays(np.float64, 3, elements=_number(0.0, 1.0))))
    if weights is not None and weights.sum() <= 0:
        weights[1] = 1.0
    return weights


def assert_distribution(probs: np.ndarray, log_probs: np.ndarray | None, where: str) -> None:
    assert np.all(np.isfinite(probs)), f"{where}: non-finite probabilities {probs}"
    assert np.all(probs >= 0.0) and np.all(probs <= 1.0 + 1e-12), f"{where}: probabilities outside [0, 1]"
    np.testing.assert_allclose(probs.sum(axis=-1), 1.0, rtol=0, atol=1e-12, err_msg=where)
    if log_probs is not None:
        assert np.all(np.isfinite(log_probs)) or np.all(log_probs[np.isinf(log_probs)] < 0), where
        assert np.all(log_probs <= 1e-12), f"{where}: log-probability above 0"


def _estimator(kind: str, model: NominalModel, first: np.ndarray, prior: Any, floor: float, rate: float) -> Any:
    if kind == "mmae":
        return mm.MultipleModelEstimator.from_model(model, first, mode_prior=prior, probability_floor=floor)
    return mm.IMMEstimator.from_model(
        model, first, mode_prior=prior, probability_floor=floor, switching_rate_per_s=rate
    )


MM_ARGUMENTS = {
    "kind": st.sampled_from(["mmae", "imm"]),
    "model": st.one_of(raw_models(), env_models()),  # the MMAE/IMM Riccati step holds even here
    "data": sequences(n_envs=2),
    "prior": mode_priors(),
    "floor": st.one_of(st.just(0.0), st.just(1e-6), _number(0.0, 0.33)),
    "rate": _number(0.0, 100.0),
    "stepwise": st.booleans(),
}


@settings(COMMON, max_examples=100)
@given(**MM_ARGUMENTS)
def test_mode_probabilities_stay_a_distribution(**arguments: Any) -> None:
    EXAMPLES["mode_probabilities_stay_a_distribution"] += 1
    _check_multiple_model(**arguments)


@pytest.mark.slow
@settings(COMMON, max_examples=3000)
@given(**MM_ARGUMENTS)
def test_mode_probabilities_stay_a_distribution_long(**arguments: Any) -> None:
    EXAMPLES["mode_probabilities_stay_a_distribution_long"] += 1
    _check_multiple_model(**arguments)


def _check_multiple_model(
    kind: str,
    model: NominalModel,
    data: tuple[np.ndarray, ...],
    prior: np.ndarray | None,
    floor: float,
    rate: float,
    stepwise: bool,
) -> None:
    push, verbal, y = data
    est = _estimator(kind, model, y[:, 0], prior, floor, rate)
    assert_distribution(est.probabilities, est.log_probabilities, "prior")
    if stepwise:
        for t in range(y.shape[1]):
            probs = est.step(push[:, t], verbal[:, t], y[:, t])
            assert_distribution(probs, est.log_probabilities, f"{kind} step {t}")
    else:
        seq = est.run(push, verbal, y)
        assert seq.shape == (*y.shape, 3)
        assert_distribution(seq, None, f"{kind} run")
    assert_distribution(est.probabilities, est.log_probabilities, f"{kind} final")
    assert np.all(np.isfinite(est.mean)), f"{kind}: non-finite mean"
    assert_symmetric_psd(est.P, f"{kind} P")
    assert_symmetric_psd(est.covariance, f"{kind} mixture covariance")


def teardown_module() -> None:
    for name, count in sorted(EXAMPLES.items()):
        print(f"hypothesis examples run: {name}: {count}")
