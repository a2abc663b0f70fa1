"""Where the person model and the switching particle filter meet: the filter's process model is the person.

:class:`estimator.particle.SwitchingParticleFilter` is generic over its transition; here it is
given the simulator's own person step (:func:`coop_gym.model.dynamics.person_substep`) and
NOMINAL people -- what a caregiver may assume of someone they have not met: by default 128
hypotheses drawn around the training personas at the env's difficulty level, each with its push
compliance scaled over a wide range (:class:`SwitchingOptions`), which the particles share out
and the readings weigh; ``hypotheses=1`` is the ``typical`` persona alone. With
``true_person=True`` the filter is given each episode's TRUE person instead: the bound a
caregiver who knew the person could reach. :class:`SwitchingEstimator` is the filter as the env
core's estimator (``estimator="switching"``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from coop_gym.model.difficulty import Difficulty, get_difficulty
from coop_gym.model.dynamics import (
    DELAY_LINE_LENGTH,
    STATE,
    initial_state_row,
    pack_person,
    person_substep,
)
from coop_gym.model.params import PersonParams, Realism, Timing
from coop_gym.model.personas import PERSONAS, TRAIN_PERSONAS, get_persona, sample_person
from estimator.kalman import NOMINAL_COLUMNS
from estimator.particle import SwitchingParticleFilter
from estimator.validate import check_flag, check_integer, check_number

__all__ = [
    "NOISES_PER_PARTICLE",
    "SwitchingEstimator",
    "SwitchingOptions",
    "hypothesis_people",
    "level_filter",
    "nominal_person",
    "pack_at_level",
    "switching_filter",
]

NOISES_PER_PARTICLE = 3
"""Normals :func:`person_substep` reads: acceleration, intention and the chain's uniform (no sensor noise)."""


@dataclass(frozen=True)
class SwitchingOptions:
    """Settings of the switching particle filter (``estimator_options`` of ``estimator="switching"``).

    The defaults were compared on the training personas through the belief caregiver
    (``agents/caregivers/belief.py``; 250 episodes each): 1024 particles over 128 hypotheses with a
    compliance range of 8 read them best of the settings tried. The reading std, mode jitter and
    compliance range sit on a flat top: nearby values move the caregiver's leave-one-out success
    by less than the noise (docs/HARD_LEVEL.md, "The belief caregiver"). The filter costs about
    ``n_particles`` person steps per env step (``python bench/run.py`` times the env); a
    lighter filter (256 particles, 32 hypotheses) suits training many envs. See
    :class:`estimator.particle.SwitchingParticleFilter` for what each does.

    Attributes:
        n_particles: Particles per env.
        reading_std_m: The std of a position reading the weights assume [m] (above the camera's
            4 mm: it absorbs the gap between the nominal and the real person).
        mode_jitter_per_s: Rate [1/s] at which a particle's mode is re-drawn.
        resample_fraction: Resample below this effective sample size over ``n_particles``.
        lean_std_m: Std of the initial lean around the first reading [m].
        hypotheses: Parameter hypotheses the particles share out: 1 is the nominal (``typical``)
            person; more are people drawn from the training personas with
            ``hypothesis_spread`` variation (a caregiver who has not met the person is unsure of
            how compliant, strong and persuadable they are).
        hypothesis_spread: Std of the log of each varied parameter of a drawn hypothesis.
        personas: The personas the hypotheses are drawn around (names; default the training
            personas): a caregiver's idea of the people it will meet. Leaving one out and
            scoring on it (``python -m agents.tune.belief``) measures what meeting an unknown
            kind of person costs.
        compliance_range: A drawn hypothesis's effective push compliance (``k2`` times the
            stiffness factor of its mode) is further scaled by a factor log-uniform in
            ``[1 / compliance_range, compliance_range]``: how far a push moves a person who does
            not resist varies most of all between older adults (a frail person is moved several
            times as far), and a pushed lean read with too stiff a body looks like cooperation.
        true_person: Give the filter each episode's true person instead (the bound of a
            caregiver who knew the person).
        difficulty: The level the nominal people are at (the env sets its own).
    """

    n_particles: int = 1024
    reading_std_m: float = 0.01
    mode_jitter_per_s: float = 0.05
    resample_fraction: float = 0.5
    lean_std_m: float = 0.01
    hypotheses: int = 128
    hypothesis_spread: float = 0.7
    compliance_range: float = 8.0
    personas: tuple[str, ...] = TRAIN_PERSONAS
    true_person: bool = False
    difficulty: str | Difficulty | None = None

    def __post_init__(self) -> None:
        """Validate ranges."""
        check_integer("SwitchingOptions.n_particles", self.n_particles, 1, 100_000)
        check_number("SwitchingOptions.reading_std_m", self.reading_std_m, 1e-5, 1.0)
        check_number("SwitchingOptions.mode_jitter_per_s", self.mode_jitter_per_s, 0.0, 100.0)
        check_number("SwitchingOptions.resample_fraction", self.resample_fraction, 0.0, 1.0)
        check_number("SwitchingOptions.lean_std_m", self.lean_std_m, 0.0, 1.0)
        check_integer("SwitchingOptions.hypotheses", self.hypotheses, 1, self.n_particles)
        check_number("SwitchingOptions.hypothesis_spread", self.hypothesis_spread, 0.0, 2.0)
        check_number("SwitchingOptions.compliance_range", self.compliance_range, 1.0, 100.0)
        check_flag("SwitchingOptions.true_person", self.true_person)
        if isinstance(self.personas, str) or not self.personas:
            raise ValueError(f"SwitchingOptions.personas must be a non-empty sequence of names, got {self.personas!r}")
        for name in self.personas:
            get_persona(name)
        object.__setattr__(self, "personas", tuple(self.personas))


def _as_options(options: SwitchingOptions | dict[str, Any] | None) -> SwitchingOptions:
    if options is None:
        return SwitchingOptions()
    if isinstance(options, SwitchingOptions):
        return options
    try:
        return SwitchingOptions(**options)
    except TypeError as exc:  # an unknown option name
        raise ValueError(f"estimator_options for 'switching': {exc}") from None


def nominal_person(difficulty: Difficulty | None, realism: Realism) -> PersonParams:
    """The person a caregiver assumes: the ``typical`` persona at ``difficulty``, with ``realism``."""
    return _at_level(PERSONAS["typical"].params, difficulty, realism)


def _at_level(person: PersonParams, difficulty: Difficulty | None, realism: Realism) -> PersonParams:
    """``person`` with ``difficulty``'s knobs and ``realism``."""
    if difficulty is not None:
        person = difficulty.apply(person)
    return person.with_realism(realism)


def mode_prior(personas: Sequence[str] = TRAIN_PERSONAS) -> tuple[float, float, float]:
    """``P(xi = -1, 0, +1)`` at an episode's start, averaged over ``personas`` (names)."""
    coop = [PERSONAS[name].params.cooperativeness for name in personas]
    p_unc = float(np.mean([c.initial_p_uncooperative for c in coop]))
    p_coop = float(np.mean([c.initial_p_cooperative for c in coop]))
    return (p_unc, 1.0 - p_unc - p_coop, p_coop)


def switching_filter(
    person_rows: NDArray[np.float64],
    timing: Timing,
    rngs: Sequence[np.random.Generator],
    options: SwitchingOptions | dict[str, Any] | None = None,
) -> SwitchingParticleFilter:
    """A switching particle filter of ``len(rngs)`` envs over packed person rows.

    Args:
        person_rows: (N, C) packed person rows (:func:`pack_person`) the particles move by.
        timing: The time base (``dt``).
        rngs: One generator per env for the particles' draws.
        options: :class:`SwitchingOptions` or a dict of its fields.
    """
    options = _as_options(options)
    return SwitchingParticleFilter(
        person_rows,
        initial_state_row(0, 0.0),
        person_substep,
        delay_length=DELAY_LINE_LENGTH,
        n_noises=NOISES_PER_PARTICLE,
        position_column=STATE.x_m,
        xi_column=STATE.xi,
        rngs=rngs,
        n_particles=options.n_particles,
        mode_prior=mode_prior(options.personas),
        lean_std_m=options.lean_std_m,
        reading_std_m=options.reading_std_m,
        resample_fraction=options.resample_fraction,
        mode_jitter_per_s=options.mode_jitter_per_s,
        dt_s=timing.dt_s,
    )


HYPOTHESES_SEED = 20_220_523
"""Seed of the draw of parameter hypotheses: one fixed bank, the same for every env and run."""


def hypothesis_people(options: SwitchingOptions) -> list[PersonParams]:
    """The ``options.hypotheses`` people drawn around ``options.personas``, before a level's knobs.

    Each is drawn with ``hypothesis_spread`` variation, its push compliance then scaled
    log-uniformly in ``[1 / compliance_range, compliance_range]``; one fixed draw
    (:data:`HYPOTHESES_SEED`), the same for every env and run.
    """
    rng = np.random.default_rng(HYPOTHESES_SEED)
    people = []
    for k in range(options.hypotheses):
        persona = PERSONAS[options.personas[k % len(options.personas)]]
        person = sample_person(dataclasses.replace(persona, variation_relative_std=options.hypothesis_spread), rng)
        scale = math.exp(rng.uniform(-1.0, 1.0) * math.log(options.compliance_range))
        bio = person.biomechanics
        bio = dataclasses.replace(bio, push_compliance_m_per_s2_n=bio.push_compliance_m_per_s2_n * scale)
        people.append(dataclasses.replace(person, biomechanics=bio))
    return people


def pack_at_level(
    person: PersonParams, difficulty: Difficulty | None, realism: Realism, timing: Timing
) -> NDArray[np.float64]:
    """``person`` with ``difficulty``'s knobs and ``realism``, packed into a parameter row (:func:`pack_person`)."""
    return pack_person(_at_level(person, difficulty, realism), timing)


def hypothesis_rows(
    options: SwitchingOptions, difficulty: Difficulty | None, realism: Realism, timing: Timing
) -> NDArray[np.float64]:
    """(K, C) packed parameter hypotheses: the nominal person, or :func:`hypothesis_people` at the level."""
    if options.hypotheses == 1:
        return pack_person(nominal_person(difficulty, realism), timing)[None]
    return np.stack([pack_at_level(person, difficulty, realism, timing) for person in hypothesis_people(options)])


def hypothesis_bank(
    n_envs: int,
    difficulty: Difficulty | None,
    realism: Realism,
    timing: Timing,
    options: SwitchingOptions | None = None,
) -> NDArray[np.float64]:
    """(N, K, C) every env's parameter hypotheses (:func:`hypothesis_rows`): one bank, shared by every env."""
    bank = hypothesis_rows(options or SwitchingOptions(), difficulty, realism, timing)
    # A copy (never the broadcast view): resets write each env's true person into its rows.
    return np.array(np.broadcast_to(bank, (n_envs, *bank.shape)))


def _seed_of(rng: np.random.Generator) -> int:
    """A seed for the particles' draws from ``rng``'s state, without drawing from it.

    The person's random stream stays the same whichever estimator watches (an env with
    ``estimator="switching"`` plays the same people as one with ``"kalman"``), and the
    particles still differ from episode to episode and follow the env's seed.
    """
    text = repr(rng.bit_generator.state).encode()
    return int.from_bytes(hashlib.blake2b(text, digest_size=8).digest(), "little")


def level_filter(
    timing: Timing,
    realism: Realism,
    rngs: Sequence[np.random.Generator],
    options: SwitchingOptions | dict[str, Any] | None = None,
) -> SwitchingParticleFilter:
    """A switching particle filter of ``len(rngs)`` envs on the hypotheses of ``options.difficulty``'s level.

    :func:`switching_filter` over :func:`hypothesis_bank`: what the envs' ``estimator="switching"``
    runs, and what ``coop_gym.experiment``'s ``switching`` estimator runs on the paper's trials.
    """
    options = _as_options(options)
    difficulty = None if options.difficulty is None else get_difficulty(options.difficulty)
    rows = hypothesis_bank(len(rngs), difficulty, realism, timing, options)
    return switching_filter(rows, timing, rngs, options)


class SwitchingEstimator:
    """The switching particle filter as an env core's multiple-model estimator.

    It takes what the core gives its multiple-model estimators each step (the substeps'
    measured push force, verbal cue and shoulder reading) and returns ``P(xi = -1, 0, +1)``.
    At a reset the particles are re-seeded from the env's generator state (see
    :func:`_seed_of`); with ``true_person`` they are given the episode's true person.

    Args:
        n_envs: Envs of the core.
        timing: The core's time base.
        realism: The core's realism switches (the nominal person is built with them).
        true_people: (N, C) view of the core's packed person of each env (read at resets).
        rngs: The core's list of env generators (read at resets).
        options: :class:`SwitchingOptions` or a dict of its fields.
    """

    def __init__(  # noqa: D107  (the class docstring gives the arguments)
        self,
        n_envs: int,
        timing: Timing,
        realism: Realism,
        true_people: NDArray[np.float64],
        rngs: Sequence[np.random.Generator | None],
        options: SwitchingOptions | dict[str, Any] | None = None,
    ) -> None:
        self.options = _as_options(options)
        own = [np.random.default_rng(i) for i in range(n_envs)]
        self.filter = level_filter(timing, realism, own, self.options)
        self._true_people = true_people
        self._rngs = rngs
        # The multiple-model interface's Kalman rows (written by the core at resets): not read here.
        self.nominal = np.zeros((n_envs, len(NOMINAL_COLUMNS)))

    @property
    def probabilities(self) -> NDArray[np.float64]:
        """(N, 3) ``P(xi = -1), P(xi = 0), P(xi = +1)``."""
        return self.filter.probabilities

    def reset(self, indices: NDArray[np.int64], first_position_m: NDArray[np.float64]) -> None:
        """Start the particles of new episodes at their first reading."""
        seeds = []
        for i in indices:
            rng = self._rngs[int(i)]
            seeds.append(0 if rng is None else _seed_of(rng))
        people = self._true_people[indices] if self.options.true_person else None
        self.filter.reset(indices, first_position_m, params=people, seeds=seeds)

    def run(
        self, push_force_n: NDArray[np.float64], verbal_cue: NDArray[np.float64], y: NDArray[np.float64]
    ) -> NDArray[np.float64]:
        """(N, T, 3) mode probabilities over the (N, T) substeps just simulated."""
        return self.filter.run(push_force_n, verbal_cue, y)
