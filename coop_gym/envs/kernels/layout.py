"""The packed rows the compiled step reads: one float row per env, one of constants, one per persona.

Each argument of a compiled call costs about as much as a whole env step's arithmetic, so the
kernels take few arrays: each env's whole state in one row of blocks (:data:`BLOCKS`), the
settings in one constants row (:data:`CONSTS`, filled by :func:`pack_consts` from the settings
dataclasses) and the personas in one table (:data:`PERSONA_BLOCKS`, :func:`pack_personas`).
Every column is named from a list (:mod:`estimator.compiled.schema`), never numbered by hand.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from coop_gym.envs.config import LiftCriteria, RewardWeights
from coop_gym.envs.kernels.report import REPORT_COLUMNS
from coop_gym.model.dynamics import DELAY_LINE_LENGTH, PARAM_COLUMNS, STATE_COLUMNS, pack_person
from coop_gym.model.params import Cues, PersonParams, Realism, Timing
from coop_gym.model.personas import VARIED_PARAMETERS, Persona
from estimator.compiled.schema import field_values, index_table, offset_table
from estimator.judgment import JUDGMENT_COLUMNS, ThresholdJudgment
from estimator.kalman import NOMINAL_COLUMNS, nominal_row
from estimator.nominal import STATE_DIM, NominalModel

__all__ = [
    "BLOCKS",
    "CONSTS",
    "CONST_COLUMNS",
    "CUES",
    "CUE_COLUMNS",
    "DRAWS",
    "DRAW_COLUMNS",
    "NO_OVERRIDE",
    "PERSONA_BLOCKS",
    "PersonaTable",
    "nominal_model_for",
    "pack_consts",
    "pack_personas",
]

CUE_COLUMNS: tuple[str, ...] = ("verbal_value", "verbal_remaining_s", "elapsed_s", "impulse_n_s")
"""Per-env bookkeeping of the cue scheduler: the utterance playing, the clock, the step's push impulse."""
CUES = index_table("CueColumns", CUE_COLUMNS)

BLOCKS = offset_table(
    "StateBlocks",
    {
        "person": len(STATE_COLUMNS),
        "cues": len(CUE_COLUMNS),
        "mean": STATE_DIM,
        "cov": STATE_DIM * STATE_DIM,
        "judge": len(JUDGMENT_COLUMNS),
        "nominal": len(NOMINAL_COLUMNS),
        "params": len(PARAM_COLUMNS),
        "delay_push": DELAY_LINE_LENGTH,
        "delay_verbal": DELAY_LINE_LENGTH,
        "report": len(REPORT_COLUMNS),
    },
)
"""Start of each block of the packed per-env state row (SitToStandCore.state); after ``end`` come
3 x substeps columns of the filter bank's inputs: measured force, verbal cue, position."""

CONST_COLUMNS: tuple[str, ...] = (
    "substeps",
    "verbal_duration_s",
    "judgment_delay_s",
    "judgment_threshold",
    "success_lean_m",
    "upright_m",
    "episode_s",
    "reward_success",
    "reward_unsafe",
    "reward_premature",
    "time_term",
    "force_per_n_s",
    "build_obs",
    "vary",
    "xdot_var",
    "eta_var",
    "xi_var",
    "xi_std",
    "n_obs",
    "n_varied",
    "obs_at",
    "varied_at",
)
"""Scalars the kernels read, packed in one float array (SitToStandCore.consts)."""
CONSTS = index_table("ConstColumns", CONST_COLUMNS)
# After the scalars come the observation spec (feature index, low, high; n_obs each) and the
# columns a reset varies.

DRAW_COLUMNS: tuple[str, ...] = ("persona", "uniform", "lean", "normals")
"""Columns of the scratch rows of a reset: the draws, then (from ``normals`` on) the variation
normals, turned into factors."""
DRAWS = index_table("DrawColumns", DRAW_COLUMNS)

PERSONA_BLOCKS = offset_table(
    "PersonaBlocks", {"params": len(PARAM_COLUMNS), "nominal": len(NOMINAL_COLUMNS), "xi_cuts": 2}
)
"""Columns of a persona-table row: the packed person, the filter's nominal row, the initial-xi cuts."""

NO_OVERRIDE = -99
""""Draw it": the persona / initial-xi override of a reset that fixes nothing."""


def nominal_model_for(person: PersonParams, timing: Timing, base: NominalModel | None = None) -> NominalModel:
    """The filter's nominal model for a persona: its typical gains, the paper's linear form.

    The filter sees the persona's *typical* parameters, not the episode's varied person,
    and none of the realism knobs -- the gap real people leave.
    """
    base = base or NominalModel()
    # The nominal model shares its gains' names with the person's fields: copy every shared one.
    person_values = {**field_values(person), "dt_s": timing.dt_s}
    shared = {f.name: person_values[f.name] for f in dataclasses.fields(NominalModel) if f.name in person_values}
    # A noiseless camera still needs R > 0 for the filter to be well posed.
    shared["position_noise_std_m"] = max(shared["position_noise_std_m"], 1e-4)
    return base.replace(**shared)


@dataclass(frozen=True)
class PersonaTable:
    """The personas packed for a reset kernel.

    Attributes:
        table: (n_personas, PERSONA_BLOCKS.end) packed person, nominal row and initial-xi cuts.
        nominal_rows: Each persona's nominal row (the filter's model of it).
        variation_std: A 1-element array when every persona varies by the same relative std, else None.
        persona_variation_std: (n_personas,) each persona's relative std.
        varied_columns: Columns of a packed person that a reset varies.
    """

    table: NDArray[np.float64]
    nominal_rows: list[NDArray[np.float64]]
    variation_std: NDArray[np.float64] | None
    persona_variation_std: NDArray[np.float64]
    varied_columns: list[int]


def pack_personas(personas: tuple[Persona, ...], timing: Timing, realism: Realism) -> PersonaTable:
    """Each persona packed once; a reset scales the varied gains and recomputes the zero-order hold."""
    # The filter's nominal model depends only on the persona: pack each once.
    nominal_rows = [nominal_row(nominal_model_for(p.params, timing)) for p in personas]
    table = np.zeros((len(personas), PERSONA_BLOCKS.end))
    for k, persona in enumerate(personas):
        coop = persona.params.cooperativeness
        table[k, PERSONA_BLOCKS.params : PERSONA_BLOCKS.nominal] = pack_person(
            persona.params.with_realism(realism), timing
        )
        table[k, PERSONA_BLOCKS.nominal : PERSONA_BLOCKS.xi_cuts] = nominal_rows[k]
        table[k, PERSONA_BLOCKS.xi_cuts] = coop.initial_p_uncooperative
        table[k, PERSONA_BLOCKS.xi_cuts + 1] = 1.0 - coop.initial_p_cooperative
    stds = {p.variation_relative_std for p in personas}
    return PersonaTable(
        table=table,
        nominal_rows=nominal_rows,
        # One shared std (the usual case) broadcasts from a 1-element array (cheaper for a ufunc
        # than a Python float); else each reset env takes its persona's.
        variation_std=np.array([stds.pop()]) if len(stds) == 1 else None,
        persona_variation_std=np.array([p.variation_relative_std for p in personas]),
        varied_columns=[PARAM_COLUMNS.index(name) for names in VARIED_PARAMETERS.values() for name in names],
    )


@dataclass(frozen=True)
class Settings:
    """The settings the constants row is packed from (the core's)."""

    timing: Timing
    cues: Cues
    realism: Realism
    lift: LiftCriteria
    reward: RewardWeights
    judgment: ThresholdJudgment
    prior: NominalModel


def pack_consts(
    settings: Settings,
    observation_index: tuple[int, ...],
    observation_low: NDArray[np.float64] | None,
    observation_high: NDArray[np.float64] | None,
    varied: list[int],
) -> NDArray[np.float64]:
    """The scalars the kernels read (:data:`CONST_COLUMNS`), then the observation spec and the varied columns."""
    timing, reward, prior = settings.timing, settings.reward, settings.prior
    n_obs = len(observation_index)
    obs_at = len(CONST_COLUMNS)
    varied_at = obs_at + 3 * n_obs
    scalars = {
        "substeps": timing.substeps,
        "verbal_duration_s": settings.cues.verbal_duration_s,
        "judgment_delay_s": settings.judgment.delay_s,
        "judgment_threshold": settings.judgment.threshold,
        "success_lean_m": settings.lift.success_lean_m,
        "upright_m": settings.lift.upright_m,
        "episode_s": timing.episode_s,
        "reward_success": reward.success,
        "reward_unsafe": reward.unsafe,
        "reward_premature": reward.premature,
        "time_term": -reward.time_per_s * timing.action_period_s,
        "force_per_n_s": reward.force_per_n_s,
        "build_obs": 0.0,  # set by the core once its estimator exists
        "vary": 1.0 if settings.realism.person_variation else 0.0,
        "xdot_var": prior.initial_velocity_std_m_per_s**2,
        "eta_var": prior.initial_intention_std_m**2,
        "xi_var": prior.initial_cooperativeness_std**2,
        "xi_std": prior.initial_cooperativeness_std,
        "n_obs": n_obs,
        "n_varied": len(varied),
        "obs_at": obs_at,
        "varied_at": varied_at,
    }
    consts = np.zeros(varied_at + len(varied))
    consts[:obs_at] = [scalars[name] for name in CONST_COLUMNS]
    consts[obs_at : obs_at + n_obs] = observation_index
    consts[obs_at + n_obs : obs_at + 2 * n_obs] = -np.inf if observation_low is None else observation_low
    consts[obs_at + 2 * n_obs : varied_at] = np.inf if observation_high is None else observation_high
    consts[varied_at:] = varied
    return consts
