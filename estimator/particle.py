"""A particle filter of a switching person: ``P(xi = k)`` where the mind changes and the body is bent.

The paper's filter (:mod:`estimator.kalman`) and the multiple-model filters
(:mod:`estimator.multiple_model`) model a person whose intention moves only voluntarily
(``eta`` changes by ``xi * (k3 c_p + k4 c_v)``) and whose mind does not change within a
trial. The hard level's person is neither (``coop_gym/model/difficulty.py``): a push bends an
unresponsive person who then stays bent (passive follow), an idle unresponsive person leans
forward on their own (spontaneous lean), and willingness is recruited by a guided push, lapses,
wears down under pushing and turns into refusals. Read with the linear filters, each of those
leans looks like cooperation.

This filter carries that person. Each particle ``i`` is one hypothesis of the whole person
state ``s_i`` (shoulder ``x``, velocity ``xdot``, intention ``eta``, mode ``xi`` and the
person's memory of the cues) and is moved by the person's own transition -- the simulator's
one-step function, passed in, so the estimator's process model and the simulated person are
one definition -- on NOMINAL parameters (a caregiver does not know this person's true ones).
The cues are known to the caregiver, so every particle hears the same cues: the mode switches
depend on them exactly as the person's chain does (recruiting by a guided push, lapses, lapses
under pushing, refusals). With a scalar position reading ``y`` (std ``r``):

* predict: ``s_i <- f(s_i, u_t, w_i)``, ``w_i`` the process noises (standard normals);
* weight: ``log w_i += -0.5 (y_t - x_i)^2 / r^2``; normalised with log-sum-exp;
* estimate: ``P(xi = k | y_1..t) = sum_i w_i [xi_i = k]``; posterior means of ``x, xdot, eta``;
* resample (systematic, one uniform) when the effective sample size
  ``1 / sum_i w_i^2`` falls below ``resample_fraction * M``.

Model mismatch (a frail person's push compliance is four times the nominal one) is absorbed
by two robustness knobs chosen on the training personas (``agents/caregivers/belief.py``): the reading
std ``r`` is inflated above the camera's, and ``mode_jitter_per_s`` re-draws a particle's mode
uniformly at that rate so no mode is ever locked out.

Randomness: every particle draw comes from each env's own ``numpy.random.Generator`` (through
:mod:`estimator.compiled.rng`, so the kernel's numbers are the ``Generator``'s), drawn in a fixed order
(per step: particles in order, ``n_noises`` normals each, then one uniform for the jitter of each
particle when the jitter is on, then one uniform if resampling) -- the reference
implementation :func:`reference_run` in plain Python draws the same numbers and is held equal
to the kernel in ``tests/estimator/test_particle.py``.

Shapes: ``N`` envs, ``M`` particles, ``S`` state columns, ``C`` parameter columns, ``T`` steps.
Modes are ordered ``xi = -1, 0, +1`` in every ``(..., 3)`` array, as in
:mod:`estimator.multiple_model`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import ArrayLike, NDArray

from estimator.compiled.cache import guard_kernel_cache
from estimator.compiled.rng import bit_generator_row, random, standard_normal
from estimator.validate import check_integer, check_number

__all__ = ["SwitchingParticleFilter", "reference_run"]

N_MODES = 3


@njit(cache=True, error_model="numpy")
def _normalise(log_w: NDArray[np.float64], w: NDArray[np.float64]) -> float:
    """``w = exp(log_w)`` normalised (log-sum-exp); ``log_w`` shifted to log ``w``. Returns the ESS."""
    top = -math.inf
    for i in range(log_w.shape[0]):
        top = max(top, log_w[i])
    if not math.isfinite(top):  # every particle impossible: start the weights afresh
        for i in range(log_w.shape[0]):
            log_w[i] = 0.0
        top = 0.0
    total = 0.0
    for i in range(log_w.shape[0]):
        w[i] = math.exp(log_w[i] - top)
        total += w[i]
    log_total = math.log(total) + top
    squares = 0.0
    for i in range(log_w.shape[0]):
        w[i] /= total
        log_w[i] -= log_total
        squares += w[i] * w[i]
    return 1.0 / squares


@njit(cache=True, error_model="numpy")
def _resample(
    particles: NDArray[np.float64],
    log_w: NDArray[np.float64],
    w: NDArray[np.float64],
    scratch: NDArray[np.float64],
    uniform: float,
) -> None:
    """Systematic resampling: particle ``i`` copied ``floor`` or ``ceil`` of ``M w_i`` times; weights equal."""
    m = particles.shape[0]
    cumulative = w[0]
    source = 0
    for i in range(m):
        target = (i + uniform) / m
        while cumulative < target and source < m - 1:
            source += 1
            cumulative += w[source]
        for j in range(particles.shape[1]):
            scratch[i, j] = particles[source, j]
    for i in range(m):
        for j in range(particles.shape[1]):
            particles[i, j] = scratch[i, j]
        log_w[i] = -math.log(m)
        w[i] = 1.0 / m


@njit(cache=True, error_model="numpy")
def _summarise(
    particles: NDArray[np.float64],
    w: NDArray[np.float64],
    xi_column: int,
    position_column: int,
    probs: NDArray[np.float64],
    mean: NDArray[np.float64],
) -> None:
    """Mode probabilities and the posterior mean of the three continuous columns from ``position_column``."""
    for k in range(N_MODES):
        probs[k] = 0.0
    for k in range(mean.shape[0]):
        mean[k] = 0.0
    for i in range(particles.shape[0]):
        mode = int(particles[i, xi_column] + 1.5)  # -1, 0, +1 -> 0, 1, 2
        probs[mode] += w[i]
        for k in range(mean.shape[0]):
            mean[k] += w[i] * particles[i, position_column + k]


# Not cached on disk: ``transition`` is a first-class function, whose Numba type is keyed by the
# dispatcher object, so no other process would find the cached copy (each added one more to the
# index, which grew without bound). It compiles once per process, in the calling process: one
# call filters a whole sequence, far longer as Python than its compile takes.
@njit(error_model="numpy")
def _filter(
    transition: Any,
    particles: NDArray[np.float64],
    log_w: NDArray[np.float64],
    params: NDArray[np.float64],
    delay_push: NDArray[np.float64],
    delay_verbal: NDArray[np.float64],
    generators: NDArray[np.uint64],
    push_force_n: NDArray[np.float64],
    verbal_cue: NDArray[np.float64],
    y: NDArray[np.float64],
    settings: NDArray[np.float64],
    probs_out: NDArray[np.float64],
    probs: NDArray[np.float64],
    mean: NDArray[np.float64],
) -> int:
    """Run every env's particles over its (T,) inputs; returns -1, or the first env with a non-finite input.

    ``settings``: ``[n_noises, xi_column, position_column, reading_var, resample_fraction, jitter_p]``.
    """
    n_envs, m, width = particles.shape
    person = width - 1  # the last column is the particle's parameter hypothesis
    n_noises = int(settings[0])
    xi_column = int(settings[1])
    position_column = int(settings[2])
    reading_var = settings[3]
    resample_below = settings[4] * m
    jitter_p = settings[5]
    for e in range(n_envs):
        for t in range(y.shape[1]):
            if not (math.isfinite(push_force_n[e, t]) and math.isfinite(verbal_cue[e, t]) and math.isfinite(y[e, t])):
                return e
    z = np.empty(max(n_noises, 1))
    w = np.empty(m)
    scratch = np.empty((m, width))
    for e in range(n_envs):
        g = generators[e]
        for t in range(y.shape[1]):
            for i in range(m):
                for j in range(n_noises):
                    z[j] = standard_normal(g)
                h = int(particles[e, i, person])
                transition(particles[e, i, :person], params[e, h], delay_push[e], delay_verbal[e],
                           push_force_n[e, t], verbal_cue[e, t], z)  # fmt: skip
                if jitter_p > 0.0 and random(g) < jitter_p:
                    # Robustness: now and then a particle forgets its mode (none is locked out).
                    particles[e, i, xi_column] = float(int(random(g) * 3.0) - 1)
                error = y[e, t] - particles[e, i, position_column]
                log_w[e, i] += -0.5 * error * error / reading_var
            ess = _normalise(log_w[e], w)
            _summarise(particles[e], w, xi_column, position_column, probs[e], mean[e])
            for k in range(N_MODES):
                probs_out[e, t, k] = probs[e, k]
            if ess < resample_below:
                _resample(particles[e], log_w[e], w, scratch, random(g))
    return -1


def _checked_arrays(
    params: ArrayLike, initial_state: ArrayLike, rngs: Sequence[np.random.Generator], mode_prior: ArrayLike
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """:class:`SwitchingParticleFilter`'s (N, K, C) hypotheses, state template and mode prior, checked."""
    rows = np.asarray(params, dtype=np.float64)
    if rows.ndim == 2:
        rows = rows[:, None, :]
    rows = np.ascontiguousarray(rows)
    if rows.ndim != 3 or not np.all(np.isfinite(rows)):
        raise ValueError(f"params must be a finite (N, K, C) or (N, C) array, got shape {np.shape(params)}")
    n = rows.shape[0]
    if len(rngs) != n or not all(isinstance(r, np.random.Generator) for r in rngs):
        raise ValueError(f"rngs must be {n} numpy.random.Generator objects, one per env")
    template = np.asarray(initial_state, dtype=np.float64)
    if template.ndim != 1 or not np.all(np.isfinite(template)):
        raise ValueError("initial_state must be a finite 1-D state row")
    prior = np.asarray(mode_prior, dtype=np.float64)
    if prior.shape != (N_MODES,) or np.any(prior < 0) or not math.isclose(prior.sum(), 1.0, abs_tol=1e-9):
        raise ValueError(f"mode_prior must be 3 non-negative probabilities summing to 1, got {mode_prior!r}")
    return rows, template, prior / prior.sum()


def _seed_list(seeds: ArrayLike, n: int) -> list[int]:
    """``seeds`` as ``n`` non-negative Python ints, element by element.

    ``np.asarray`` of Python ints above 2**63 beside smaller ones makes float64 and rounds them,
    so an env's particles would depend on the other envs' seeds.
    """
    values: list[Any]
    if isinstance(seeds, np.ndarray):
        if seeds.dtype.kind not in "iu":
            raise ValueError(f"seeds must be {n} non-negative ints, got an array of {seeds.dtype}")
        values = seeds.reshape(-1).tolist()
    else:
        values = list(seeds) if isinstance(seeds, (list, tuple)) else [seeds]
    seed_list = [int(v) for v in values]
    if len(seed_list) != n or min(seed_list, default=0) < 0:
        raise ValueError(f"seeds must be {n} non-negative ints")
    return seed_list


class SwitchingParticleFilter:
    """``P(xi = -1, 0, +1)`` of ``N`` people, each tracked by ``M`` particles of its whole state.

    Args:
        params: (N, K, C) each env's ``K`` parameter hypotheses for ``transition`` (a (N, C) array
            is one hypothesis each: the nominal person). Each particle carries one hypothesis,
            drawn uniformly at a reset and kept through resampling, so the filter weighs the
            hypotheses by how well they explain the readings (model uncertainty).
        initial_state: (S,) the state row a person starts in (the mode and the lean are drawn).
        transition: A compiled ``f(state_row, params_row, delay_push, delay_verbal,
            push_force_n, verbal_cue, noises)`` advancing one particle by one step in place
            (the simulator's person step); ``delay_push``/``delay_verbal`` are the env's
            delay lines of the known cues, shared by its particles.
        delay_length: Slots of each delay line.
        n_noises: Standard normals one ``transition`` call reads.
        position_column: Column of the shoulder position ``x`` [m] in a state row; the next two
            columns are ``xdot`` [m/s] and ``eta`` [m] (reported as :attr:`mean`).
        xi_column: Column of the mode ``xi``; ``intention_column`` of ``eta`` is ``position_column + 2``.
        rngs: One ``numpy.random.Generator`` per env (the particles' draws).
        n_particles: ``M``.
        mode_prior: ``P(xi = -1, 0, +1)`` at the start of an episode.
        lean_std_m: Std of the initial lean around the first reading [m].
        reading_std_m: ``r``, the std of a position reading the weights assume [m].
        resample_fraction: Resample when the effective sample size is below this times ``M``.
        mode_jitter_per_s: Rate [1/s] at which a particle's mode is re-drawn uniformly.
        dt_s: The step [s] (turns the jitter rate into a probability per step).
    """

    def __init__(  # noqa: D107  (the class docstring gives the arguments)
        self,
        params: ArrayLike,
        initial_state: ArrayLike,
        transition: Callable[..., None],
        *,
        delay_length: int,
        n_noises: int,
        position_column: int,
        xi_column: int,
        rngs: Sequence[np.random.Generator],
        n_particles: int = 256,
        mode_prior: ArrayLike = (0.3, 0.6, 0.1),
        lean_std_m: float = 0.01,
        reading_std_m: float = 0.004,
        resample_fraction: float = 0.5,
        mode_jitter_per_s: float = 0.0,
        dt_s: float = 0.02,
    ) -> None:
        rows, template, prior = _checked_arrays(params, initial_state, rngs, mode_prior)
        self.n_envs = n = rows.shape[0]
        self.n_particles = m = check_integer("n_particles", n_particles, 1, 1_000_000)
        self.mode_prior = prior
        self.lean_std_m = check_number("lean_std_m", lean_std_m, 0.0, 1.0)
        self.reading_std_m = check_number("reading_std_m", reading_std_m, 1e-6, 1.0)
        self.resample_fraction = check_number("resample_fraction", resample_fraction, 0.0, 1.0)
        self.mode_jitter_per_s = check_number("mode_jitter_per_s", mode_jitter_per_s, 0.0, 1000.0)
        dt_s = check_number("dt_s", dt_s, 1e-6, 10.0)
        for name, column in (("position_column", position_column), ("xi_column", xi_column)):
            check_integer(name, column, 0, template.shape[0] - 1)
        if position_column + 2 >= template.shape[0]:
            raise ValueError("position_column + 2 (eta) must be a column of initial_state")
        self.params = rows
        self.transition = transition
        self.template = template
        self.position_column = position_column
        self.xi_column = xi_column
        self.rngs = list(rngs)
        self.generators = np.stack([bit_generator_row(r) for r in self.rngs])
        self.settings = np.array([
            n_noises, xi_column, position_column, self.reading_std_m**2, self.resample_fraction,
            -math.expm1(-self.mode_jitter_per_s * dt_s),
        ], dtype=np.float64)  # fmt: skip
        # Each particle: the person's state row, then the index of its parameter hypothesis.
        self.particles = np.zeros((n, m, template.shape[0] + 1))
        self.log_w = np.zeros((n, m))
        self.delay_push = np.zeros((n, delay_length))
        self.delay_verbal = np.zeros((n, delay_length))
        self._probs = np.tile(self.mode_prior, (n, 1))
        self._mean = np.zeros((n, 3))

    @property
    def probabilities(self) -> NDArray[np.float64]:
        """(N, 3) ``P(xi = -1), P(xi = 0), P(xi = +1)`` after the last step (a copy)."""
        return self._probs.copy()

    @property
    def mean(self) -> NDArray[np.float64]:
        """(N, 3) posterior mean of ``[x, xdot, eta]`` after the last step."""
        return self._mean.copy()

    def hypothesis_posterior(self) -> NDArray[np.float64]:
        """(N, K) the weight each parameter hypothesis holds now: its particles' weights summed."""
        w = np.exp(self.log_w - self.log_w.max(axis=1, keepdims=True))
        w /= w.sum(axis=1, keepdims=True)
        k = self.params.shape[1]
        labels = self.particles[:, :, -1].astype(np.int64)
        return np.stack([np.bincount(labels[e], weights=w[e], minlength=k) for e in range(self.n_envs)])

    def reset(
        self,
        indices: ArrayLike,
        first_position_m: ArrayLike,
        params: ArrayLike | None = None,
        seeds: ArrayLike | None = None,
    ) -> None:
        """Start new episodes: particles at the first reading, modes drawn from the prior.

        Args:
            indices: Envs to reset (int array).
            first_position_m: First measured position [m] of each (or one value for all).
            params: (len(indices), K, C) or (len(indices), C) new hypotheses (default: keep each env's).
            seeds: (len(indices),) non-negative ints: re-seed each env's generator in place first
                (the kernel keeps drawing from the same generator objects).
        """
        idx = np.arange(self.n_envs)[np.asarray(indices, dtype=np.int64)]
        first = np.broadcast_to(np.asarray(first_position_m, dtype=np.float64), idx.shape)
        if not np.all(np.isfinite(first)):
            raise ValueError("first_position_m must be finite")
        if params is not None:
            rows = np.asarray(params, dtype=np.float64)
            if rows.ndim == 2:
                rows = rows[:, None, :]
            k, c = self.params.shape[1:]
            fits = rows.shape[0] == idx.shape[0] and rows.shape[2] == c and k % rows.shape[1] == 0
            if not fits or not np.all(np.isfinite(rows)):
                raise ValueError(f"params must be a finite ({idx.shape[0]}, {k}, {c}) or ({idx.shape[0]}, {c}) array")
            self.params[idx] = np.repeat(rows, k // rows.shape[1], axis=1)
        if seeds is not None:
            for e, seed in zip(idx, _seed_list(seeds, idx.shape[0]), strict=True):
                bits = self.rngs[e].bit_generator
                bits.state = type(bits)(seed).state
        m = self.n_particles
        for r, e in enumerate(idx):
            rng = self.rngs[e]
            lean = first[r] + self.lean_std_m * rng.standard_normal(m)
            modes = rng.choice(np.array([-1.0, 0.0, 1.0]), size=m, p=self.mode_prior)
            block = self.particles[e]
            block[:, :-1] = self.template
            block[:, -1] = np.arange(m) % self.params.shape[1]
            block[:, self.position_column] = lean
            block[:, self.position_column + 2] = lean
            block[:, self.xi_column] = modes
            self.log_w[e] = -math.log(m)
            self.delay_push[e] = 0.0
            self.delay_verbal[e] = 0.0
            self._probs[e] = [np.mean(modes == k) for k in (-1.0, 0.0, 1.0)]
            self._mean[e] = [lean.mean(), 0.0, lean.mean()]

    def run(
        self, push_force_n: ArrayLike, verbal_cue: ArrayLike, measured_position_m: ArrayLike
    ) -> NDArray[np.float64]:
        """Filter (N, T) steps of known cues and readings.

        Args:
            push_force_n: (N, T) push force acting in each step [N] (the robot's command).
            verbal_cue: (N, T) verbal cue heard in each step, in {-1, 0, +1}.
            measured_position_m: (N, T) shoulder reading at the end of each step [m].

        Returns:
            (N, T, 3) mode probabilities after each step.
        """
        y = np.asarray(measured_position_m, dtype=np.float64)
        if y.ndim != 2 or y.shape[0] != self.n_envs:
            raise ValueError(f"measured_position_m must have shape (N={self.n_envs}, T), got {y.shape}")
        inputs = []
        for name, value in (("push_force_n", push_force_n), ("verbal_cue", verbal_cue), ("measured_position_m", y)):
            arr = np.empty(y.shape)
            try:
                arr[...] = np.asarray(value, dtype=np.float64)
            except ValueError:
                raise ValueError(f"{name} must broadcast to shape {y.shape}, got {np.shape(value)}") from None
            inputs.append(arr)
        out = np.empty((*y.shape, N_MODES))
        failed = _filter(
            self.transition, self.particles, self.log_w, self.params, self.delay_push, self.delay_verbal,
            self.generators, inputs[0], inputs[1], inputs[2], self.settings, out, self._probs, self._mean,
        )  # fmt: skip
        if failed >= 0:
            raise ValueError(f"push_force_n, verbal_cue and measured_position_m of env {failed} must be finite")
        return out


def reference_run(
    pf: SwitchingParticleFilter,
    transition: Callable[..., None],
    push_force_n: NDArray[np.float64],
    verbal_cue: NDArray[np.float64],
    measured_position_m: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The filter written out in NumPy, drawing the same numbers: the reference the kernel is tested against.

    Advances ``pf`` in place exactly as :meth:`SwitchingParticleFilter.run` would (``transition``
    is the Python form of ``pf.transition``, e.g. its ``.py_func``).
    """
    n_noises, xi_col, pos_col = int(pf.settings[0]), int(pf.settings[1]), int(pf.settings[2])
    reading_var, jitter_p = pf.settings[3], pf.settings[5]
    m = pf.n_particles
    out = np.empty((*measured_position_m.shape, N_MODES))
    for e in range(pf.n_envs):
        rng = pf.rngs[e]
        for t in range(measured_position_m.shape[1]):
            for i in range(m):
                z = np.array([rng.standard_normal() for _ in range(n_noises)])
                h = int(pf.particles[e, i, -1])
                transition(pf.particles[e, i, :-1], pf.params[e, h], pf.delay_push[e], pf.delay_verbal[e],
                           push_force_n[e, t], verbal_cue[e, t], z)  # fmt: skip
                if jitter_p > 0.0 and rng.random() < jitter_p:
                    pf.particles[e, i, xi_col] = float(int(rng.random() * 3.0) - 1)
                error = measured_position_m[e, t] - pf.particles[e, i, pos_col]
                pf.log_w[e, i] += -0.5 * error * error / reading_var
            top = pf.log_w[e].max()
            w = np.exp(pf.log_w[e] - top)
            total = w.sum()
            pf.log_w[e] -= math.log(total) + top
            w /= total
            modes = pf.particles[e, :, xi_col]
            pf._probs[e] = [w[modes == k].sum() for k in (-1.0, 0.0, 1.0)]
            pf._mean[e] = w @ pf.particles[e, :, pos_col : pos_col + 3]
            out[e, t] = pf._probs[e]
            if 1.0 / np.sum(w * w) < pf.resample_fraction * m:
                positions = (np.arange(m) + rng.random()) / m
                source = np.minimum(np.searchsorted(np.cumsum(w), positions, side="left"), m - 1)
                pf.particles[e] = pf.particles[e, source]
                pf.log_w[e] = -math.log(m)
    return out


guard_kernel_cache(__name__)
