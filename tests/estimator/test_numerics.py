"""Numerical care at the edges of the valid parameter space, over long runs.

* :class:`FastKalmanFilter` for 10^5 filter steps (2000 s at 50 Hz) on extreme but valid
  models -- very stiff (Euler factor ``1 - lambda1*dt`` down to -9), very compliant,
  near-zero noise, large noise: every covariance finite, symmetric and PSD, and within the
  bounds the maths guarantees (the Joseph-form update keeps ``P[0, 0] <= R``; ``xi`` is a
  random walk seen only through the cues, so ``P[3, 3] <= P0[3, 3] + t * q_xi``).
* The env for 10^4 steps with extreme personas: observations finite and in the space, the
  in-env filter's covariance symmetric PSD with the same bounds.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from coop_gym.envs.sit_to_stand import SitToStandEnv
from coop_gym.model.params import Biomechanics, Intention, PersonParams, Realism, Sensors, Timing
from coop_gym.model.personas import Persona
from estimator.kalman import FastKalmanFilter, kalman_step, nominal_row
from estimator.nominal import NominalModel

FILTER_STEPS = 100_000
CHUNK = 10_000  # covariances are checked chunk by chunk to keep memory small


def _noise_levels(camera: float, process: float, prior: float) -> NominalModel:
    """The default model with every noise at one level per kind: the camera's std, the four
    process stds and the three prior stds (the position's prior is the camera's own)."""
    process_stds = (
        "velocity_process_std_m_per_s",
        "intention_process_std_m",
        "cooperativeness_process_std",
        "position_process_std_m",
    )
    prior_stds = ("initial_velocity_std_m_per_s", "initial_intention_std_m", "initial_cooperativeness_std")
    return NominalModel(
        position_noise_std_m=camera, **dict.fromkeys(process_stds, process), **dict.fromkeys(prior_stds, prior)
    )


EXTREME_MODELS: dict[str, NominalModel] = {
    "default": NominalModel(),
    "stiff, dt 20 ms": NominalModel(damping_rate_per_s=100.0, voluntary_gain_per_s2=1000.0),
    "stiff, dt 100 ms": NominalModel(dt_s=0.1, damping_rate_per_s=100.0, voluntary_gain_per_s2=1000.0),
    "compliant": NominalModel(
        damping_rate_per_s=0.01,
        voluntary_gain_per_s2=0.01,
        push_compliance_m_per_s2_n=1.0,
        push_gain_m_per_s_n=1.0,
        verbal_gain_m_per_s=10.0,
    ),
    "near-zero noise": _noise_levels(camera=1e-6, process=0.0, prior=1e-6),
    "tiny R, large prior": NominalModel(position_noise_std_m=1e-6, initial_velocity_std_m_per_s=10.0),
    "large noise": _noise_levels(camera=1.0, process=1.0, prior=10.0),
}


def held_cues(rng: np.random.Generator, n_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Cues held over random stretches (1..200 steps), long quiet spells included."""
    push = np.empty(n_steps)
    verbal = np.empty(n_steps)
    t = 0
    while t < n_steps:
        length = int(rng.integers(1, 200))
        push[t : t + length] = rng.choice([0.0, 0.0, 10.0, 30.0, 200.0])
        verbal[t : t + length] = rng.choice([0.0, 0.0, -1.0, 1.0])
        t += length
    return push, verbal


def assert_covariances_sane(
    P: np.ndarray, model_row: np.ndarray, p0_xi: float, steps_done: np.ndarray, where: str
) -> None:
    """(..., 4, 4) covariances: finite, symmetric, PSD, ``P00 <= R``, ``P33 <= P0_33 + t q_xi``."""
    assert np.all(np.isfinite(P)), f"{where}: non-finite covariance"
    scale = np.maximum(1.0, np.max(np.abs(P), axis=(-1, -2)))
    asym = np.max(np.abs(P - np.swapaxes(P, -1, -2)), axis=(-1, -2)) / scale
    assert asym.max() <= 1e-12, f"{where}: asymmetry {asym.max()}"
    eig = np.linalg.eigvalsh(P)
    assert (eig[..., 0] / scale).min() >= -1e-10, f"{where}: not PSD, smallest eigenvalue {eig[..., 0].min()}"
    r, q_xi = model_row[10], model_row[9]
    assert np.all(P[..., 0, 0] <= r * (1 + 1e-9)), f"{where}: P00 {P[..., 0, 0].max()} above R {r}"
    bound = p0_xi + steps_done * q_xi
    assert np.all(P[..., 3, 3] <= bound * (1 + 1e-9) + 1e-300), f"{where}: P33 above the random-walk bound"


@pytest.mark.parametrize("name", EXTREME_MODELS)
def test_fast_filter_long_run_on_extreme_models(name: str) -> None:
    model = EXTREME_MODELS[name]
    rng = np.random.default_rng(0)
    push, verbal = held_cues(rng, FILTER_STEPS)
    # A person leaning within the anatomical range, seen through the model's camera noise.
    lean = np.clip(np.cumsum(rng.normal(0.0, 0.002, FILTER_STEPS)), -0.1, 0.35)
    y = lean + rng.normal(0.0, model.position_noise_std_m, FILTER_STEPS)
    kf = FastKalmanFilter.from_model(model, y[:1])
    row = nominal_row(model)
    p0_xi = model.initial_cooperativeness_std**2
    for start in range(0, FILTER_STEPS, CHUNK):
        sl = slice(start, start + CHUNK)
        means, covs, loglik = kf.run(push[None, sl], verbal[None, sl], y[None, sl])
        where = f"{name}, steps {start}..{start + CHUNK}"
        assert np.all(np.isfinite(means)), f"{where}: non-finite mean"
        assert np.all(np.isfinite(loglik)), f"{where}: non-finite log-likelihood"
        assert_covariances_sane(covs[0], row, p0_xi, np.arange(start + 1, start + CHUNK + 1), where)
    # The position estimate still tracks the data (not merely finite) -- unless the model has
    # no process noise at all: then the filter rightly stops listening once it is certain.
    if model.velocity_process_std_m_per_s > 0:
        assert abs(means[0, -1, 0] - y[-1]) < 10 * model.position_noise_std_m + 0.01


def test_kalman_step_agrees_with_the_batched_run_over_a_long_run() -> None:
    """The env's per-step kernel and the batched run are the same arithmetic (bit for bit)."""
    model = EXTREME_MODELS["stiff, dt 100 ms"]
    rng = np.random.default_rng(1)
    push, verbal = held_cues(rng, 20_000)
    y = rng.normal(0.0, 0.01, 20_000)
    kf = FastKalmanFilter.from_model(model, y[:1])
    means, covs, _ = kf.run(push[None], verbal[None], y[None])
    m = kf.m[0].copy()
    m[:] = [y[0], 0.0, y[0], 0.0]
    P = FastKalmanFilter.from_model(model, y[:1]).P[0].copy()
    row = nominal_row(model)
    for t in range(20_000):
        kalman_step(m, P, row, push[t], verbal[t], y[t])
    np.testing.assert_array_equal(m, means[0, -1])
    np.testing.assert_array_equal(P, covs[0, -1])


def test_joseph_form_keeps_a_near_singular_update_psd() -> None:
    """R twelve orders below the prior variance: the Joseph form is what keeps ``P`` sane.

    Here the short form ``P = (I - K H) P`` (checked with NumPy) drifts to ``P00 = 1.02 R`` and
    an asymmetry of 6e-10 of ``|P|``, failing both checks below; the Joseph form
    ``(I - K H) P (I - K H)^T + K R K^T`` with symmetrisation stays at ``P00 <= R``, symmetric.
    """
    model = NominalModel(position_noise_std_m=1e-6, initial_velocity_std_m_per_s=1e3, initial_intention_std_m=1e3)
    row = nominal_row(model)
    m = model.initial_state(0.0)
    P = model.initial_covariance()
    for t in range(2_000):
        kalman_step(m, P, row, 30.0 if t % 100 < 50 else 0.0, 1.0 if t % 300 < 50 else 0.0, 1e-3 * np.sin(t))
        assert_covariances_sane(P, row, model.initial_cooperativeness_std**2, np.array(t + 1), f"step {t}")


# --------------------------------------------------------------------------- env

ENV_STEPS = 10_000


def _persona(name: str, **levels: Any) -> Persona:
    return Persona(name, name, PersonParams(**levels), 0.15)


def _noisy_persona(name: str, body: float, intention: float, camera: float, force: float) -> Persona:
    """A persona with every noise of the person set: the body's acceleration noise, the intention's
    diffusion, and the camera's and force sensor's stds."""
    return _persona(
        name,
        biomechanics=Biomechanics(accel_noise_std_m_per_s2=body),
        intention=Intention(noise_std_m_per_sqrt_s=intention),
        sensors=Sensors(position_noise_std_m=camera, force_noise_std_n=force),
    )


EXTREME_PERSONAS: dict[str, tuple[Persona, dict[str, Any]]] = {
    "very stiff": (
        _persona("stiff", biomechanics=Biomechanics(damping_rate_per_s=90.0, voluntary_gain_per_s2=900.0)),
        {},
    ),
    "very stiff, dt 100 ms": (
        _persona("stiff", biomechanics=Biomechanics(damping_rate_per_s=90.0, voluntary_gain_per_s2=900.0)),
        {"timing": Timing(dt_s=0.1, substeps=1)},
    ),
    "very compliant": (
        _persona(
            "compliant",
            biomechanics=Biomechanics(
                damping_rate_per_s=0.02, voluntary_gain_per_s2=0.02, push_compliance_m_per_s2_n=0.9
            ),
            intention=Intention(push_gain_m_per_s_n=0.9, verbal_gain_m_per_s=9.0, saturate=False),
        ),
        {"realism": Realism(saturation=False)},
    ),
    "no noise": (_noisy_persona("noiseless", body=0.0, intention=0.0, camera=0.0, force=0.0), {}),
    "large noise": (_noisy_persona("noisy", body=10.0, intention=1.0, camera=1.0, force=100.0), {}),
}


@pytest.mark.parametrize("name", EXTREME_PERSONAS)
def test_env_long_run_with_extreme_personas(name: str) -> None:
    persona, kwargs = EXTREME_PERSONAS[name]
    env = SitToStandEnv(personas=[persona], **kwargs)
    rng = np.random.default_rng(2)
    obs, info = env.reset(seed=3)
    row = env.core.nominal[0].copy()
    p0_xi = float(env.core.P[0, 3, 3])
    steps_in_episode = 0
    substeps = env.timing.substeps
    for t in range(ENV_STEPS):
        action = [int(rng.integers(3)), int(rng.integers(3)), int(rng.random() < 0.01)]
        obs, reward, terminated, _, info = env.step(action)
        steps_in_episode += 1
        where = f"{name}, step {t}"
        assert np.all(np.isfinite(obs)) and env.observation_space.contains(obs), f"{where}: obs {obs}"
        assert np.isfinite(reward), where
        assert np.all(np.isfinite([v for v in info.values() if isinstance(v, float)])), f"{where}: {info}"
        assert_covariances_sane(env.core.P[0], row, p0_xi, np.array(steps_in_episode * substeps), where)
        if terminated or info["outcome"] == "timeout":
            obs, info = env.reset()
            steps_in_episode = 0


def _symmetric_cases(rng: np.random.Generator) -> list[np.ndarray]:
    cases = []
    for trial in range(400):
        kind = trial % 4
        if kind == 0:  # indefinite
            m = rng.normal(size=(4, 4))
            cases.append(m + m.T)
        elif kind == 1:  # PSD with variances 24 orders apart
            m = rng.normal(size=(4, 4)) * 10.0 ** rng.uniform(-12, 3, 4)[:, None]
            cases.append(m @ m.T)
        elif kind == 2:  # already diagonal but for a denormal-scale coupling
            a = np.diag(rng.normal(size=4))
            a[0, 1] = a[1, 0] = 1e-300
            cases.append(a)
        else:  # rank one, nudged indefinite: what the repair meets
            v = rng.normal(size=(4, 1))
            a = v @ v.T
            a[3, 3] -= 1e-17
            cases.append(a)
    return cases


def test_jacobi_eigendecomposition_matches_lapack() -> None:
    """The repair's own 4x4 eigensolver (kept off LAPACK for compile time): eigenvalues as
    ``eigvalsh``'s, eigenvectors orthonormal, ``V diag(w) V^T`` the input, all to 1e-13."""
    from estimator.kalman import _symmetric_eigen

    for a in _symmetric_cases(np.random.default_rng(7)):
        c, v = a.copy(), np.empty((4, 4))
        _symmetric_eigen(c, v)
        w = np.diag(c)
        scale = max(float(np.abs(a).max()), 1e-300)
        assert np.abs(c - np.diag(w)).max() == 0.0
        assert np.abs(v @ np.diag(w) @ v.T - a).max() <= 1e-13 * scale
        assert np.abs(v.T @ v - np.eye(4)).max() <= 1e-13
        assert np.abs(np.sort(w) - np.linalg.eigvalsh(a)).max() <= 1e-13 * scale
