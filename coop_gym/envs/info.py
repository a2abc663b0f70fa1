"""The ``info`` of a step, single or batched, built from the report rows the step kernel writes."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from coop_gym.envs.arguments import SitToStandConfig
from coop_gym.envs.config import (
    Outcome,
)
from coop_gym.envs.kernels.report import REPORT, REPORT_COLUMNS, REWARD_TERMS
from coop_gym.envs.kernels.step import select_and_clip
from coop_gym.envs.observation import PROBABILITY_FEATURES
from estimator.compiled.cache import guard_kernel_cache

__all__ = [
    "NUMERIC_INFO_KEYS",
    "InfoBuilder",
    "report_info",
]


# --- info -------------------------------------------------------------------------

_OUTCOME_LABELS: tuple[str, ...] = tuple(o.label for o in Outcome)
_OUTCOME_LABEL_ARRAY = np.array(_OUTCOME_LABELS, dtype=object)

_INFO_ENTRIES: tuple[tuple[str, int, str], ...] = (
    ("true_x_m", REPORT.true_x_m, "float"),
    ("true_xdot_m_per_s", REPORT.true_xdot_m_per_s, "float"),
    ("true_eta_m", REPORT.true_eta_m, "float"),
    ("true_xi", REPORT.info_true_xi, "int"),
    ("persona", REPORT.persona_index, "label"),
    ("outcome", REPORT.outcome, "label"),
    ("judgment", REPORT.judgment, "int"),
    ("xi_estimate", REPORT.xi_hat, "float"),
    ("push_force_n", REPORT.push_force_n, "float"),
    ("verbal_cue", REPORT.verbal_cue, "int"),
    ("elapsed_s", REPORT.elapsed_s, "float"),
)
"""The one list of the info's keys, in order: (key, report column, kind). A ``"label"`` is a name
looked up by the column's integer (the persona's, the outcome's); its number is the key of
:data:`_CODE_KEYS` in the numeric info and beside the label in the vector info. Every info adds
the reward terms (:data:`~coop_gym.envs.kernels.report.REWARD_TERMS`) and, with a multiple-model
estimator, the mode probabilities."""

_CODE_KEYS = {"persona": "persona_index", "outcome": "outcome_code"}


def report_info(r: list[float], persona_names: Sequence[str], probabilities: bool) -> dict[str, Any]:
    """The single env's ``info`` dict from one row of ``SitToStandCore.report`` (as a list).

    Args:
        r: ``core.report[i].tolist()`` (one ``tolist()`` reads every value at once).
        persona_names: Names of the env's personas, by index.
        probabilities: Add ``xi_probabilities`` (a multiple-model estimator runs).
    """
    # Unpacked by position (checked against _INFO_ENTRIES at import): one bytecode
    # instead of ~25 indexed look-ups on the hot path.
    (_pos, _force, verbal, _since, _x_hat, _xdot_hat, _eta_hat, xi_hat, _xi_std, judgment, elapsed,
     p_uncoop, p_unresp, p_coop, _true_xi_feature,
     success, unsafe, premature, time_term, force_term, _reward, outcome,
     push, true_x, true_xdot, true_eta, true_xi, persona) = r  # fmt: skip
    info: dict[str, Any] = {
        "true_x_m": true_x,
        "true_xdot_m_per_s": true_xdot,
        "true_eta_m": true_eta,
        "true_xi": int(true_xi),
        "persona": persona_names[int(persona)],
        "outcome": _OUTCOME_LABELS[int(outcome)],
        "judgment": int(judgment),
        "xi_estimate": xi_hat,
        "push_force_n": push,
        "verbal_cue": int(verbal),
        "elapsed_s": elapsed,
    }
    if probabilities:
        info["xi_probabilities"] = np.array([p_uncoop, p_unresp, p_coop])
    info["reward_terms"] = {
        "success": success,
        "unsafe": unsafe,
        "premature": premature,
        "time": time_term,
        "force": force_term,
    }
    return info


def _check_report_info() -> None:
    """Raise unless :func:`report_info` reads each key from the column :data:`_INFO_ENTRIES` names.

    report_info unpacks the row by position, for speed; this reads a row whose every value tells
    its column apart (an explicit check, not an assert: it must hold under python -O too).
    """
    row = [float(100 + column) for column in range(len(REPORT_COLUMNS))]
    row[REPORT.outcome] = float(len(_OUTCOME_LABELS) - 1)
    names = [f"column {column}" for column in range(200 + len(REPORT_COLUMNS))]
    labels = {"persona": names, "outcome": _OUTCOME_LABELS}
    try:
        expected: dict[str, Any] = {
            key: labels[key][int(row[column])]
            if kind == "label"
            else int(row[column])
            if kind == "int"
            else row[column]
            for key, column, kind in _INFO_ENTRIES
        }
        expected["xi_probabilities"] = [row[REPORT.p_uncooperative + k] for k in range(len(PROBABILITY_FEATURES))]
        expected["reward_terms"] = {name: row[REPORT.reward_success + k] for k, name in enumerate(REWARD_TERMS)}
        info = report_info(row, names, True)
        info["xi_probabilities"] = info["xi_probabilities"].tolist()
        matches = list(info.items()) == list(expected.items())
    except (IndexError, ValueError):  # a column outside the row, a label read from a column that holds no code
        matches = False
    if not matches:
        raise RuntimeError("report_info reads other columns or keys than _INFO_ENTRIES: update report_info")


_check_report_info()


# The vector info's keys in order: (key, report column, as int) or a label (column None), each
# label followed by its code's key; report_info gives the same keys bar the codes
# (tests/coop_gym/test_contract.py holds the two equal).
_INFO_COLUMNS: tuple[tuple[str, int | None, bool], ...] = tuple(
    entry
    for key, column, kind in _INFO_ENTRIES
    for entry in (
        [(key, None, False), (_CODE_KEYS[key], None, False)] if kind == "label" else [(key, column, kind == "int")]
    )
)


# (key, report column, as int): the numeric info, one entry per key, scalars in the single env.
_NUMERIC_INFO: tuple[tuple[str, int, bool], ...] = (
    *((_CODE_KEYS.get(key, key), column, kind != "float") for key, column, kind in _INFO_ENTRIES),
    *((f"reward_{name}", REPORT.reward_success + k, False) for k, name in enumerate(REWARD_TERMS)),
)
_NUMERIC_PROBABILITIES: tuple[tuple[str, int, bool], ...] = tuple(
    (name, REPORT.p_uncooperative + k, False) for k, name in enumerate(PROBABILITY_FEATURES)
)
if [column for _, column, _ in _NUMERIC_PROBABILITIES] != [REPORT.p_uncooperative, REPORT.p_unresponsive,
                                                           REPORT.p_cooperative]:  # fmt: skip
    raise RuntimeError("the multiple-model probabilities must be consecutive report columns")

NUMERIC_INFO_KEYS: tuple[str, ...] = tuple(key for key, _, _ in _NUMERIC_INFO)
"""Keys of every ``info_mode="numeric"`` info, in order: the default info's numbers with the
persona as ``persona_index`` (into the env's ``personas``), the outcome as ``outcome_code`` (an
:class:`~coop_gym.envs.config.Outcome` value) and the reward terms as ``reward_<term>``. A
multiple-model estimator adds ``p_uncooperative``, ``p_unresponsive``, ``p_cooperative`` (the
default info's ``xi_probabilities``); ``observation_scale="unit"`` adds ``unscaled_obs``."""


@njit(cache=True, error_model="numpy")
def _gather_info_columns(
    report: NDArray[np.float64],
    float_columns: NDArray[np.int64],
    floats: NDArray[np.float64],
    int_columns: NDArray[np.int64],
    ints: NDArray[np.int64],
) -> None:
    # floats[k, i] = report[i, float_columns[k]] and ints[k, i] = int(report[i, int_columns[k]])
    # (truncation, as astype(np.int64)), in one call. Column by column: filling the blocks row by
    # row writes to addresses 8 KiB apart, which alias the loads 4 KiB apart and stall them.
    for k in range(float_columns.shape[0]):
        column = float_columns[k]
        for i in range(report.shape[0]):
            floats[k, i] = report[i, column]
    for k in range(int_columns.shape[0]):
        column = int_columns[k]
        for i in range(report.shape[0]):
            ints[k, i] = int(report[i, column])


@njit(cache=True, error_model="numpy")
def _unscaled_rows(
    report: NDArray[np.float64],
    columns: NDArray[np.float64],
    low: NDArray[np.float64],
    high: NDArray[np.float64],
    obs: NDArray[np.float32],
) -> None:
    # The physical observation of each report row, selected and clipped as the step selects it.
    for i in range(report.shape[0]):
        select_and_clip(report[i], columns, low, high, obs[i])


class InfoBuilder:
    """The info of an env of ``config``, single (:meth:`single`) or batched (:meth:`batched`), from report rows.

    ``info_mode="default"`` gives :func:`report_info` (single) and the same keys as arrays (batched);
    ``"numeric"`` gives :data:`NUMERIC_INFO_KEYS` (NumPy int64 and float64 scalars in the single
    env, arrays of them with Gymnasium's ``_key`` masks in the vector env). Under
    ``observation_scale="unit"`` either adds ``unscaled_obs``: the observation in its units,
    float32, as the ``"none"`` scale gives it (the unit observation is it over the scales, clipped).

    Args:
        config: The env's settings.
    """

    def __init__(self, config: SitToStandConfig) -> None:
        """Tables of the info's keys and of the physical observation's columns and bounds."""
        self.persona_names = tuple(p.name for p in config.personas)
        self._persona_array = np.array(self.persona_names, dtype=object)
        self.probabilities = config.estimator != "kalman"
        self.numeric = config.info_mode == "numeric"
        self.unscaled = config.observation_scale == "unit"
        self._entries = _NUMERIC_INFO + (_NUMERIC_PROBABILITIES if self.probabilities else ())
        # The physical observation rebuilt from a report row by the step's own selection.
        self._obs_columns = np.array([REPORT_COLUMNS.index(f) for f in config.physical_features], dtype=np.float64)
        physical = config.physical_observation_space()
        self._obs_low = physical.low.astype(np.float64)
        self._obs_high = physical.high.astype(np.float64)
        self._plan_all_envs()

    def _plan_all_envs(self) -> None:
        """Where each key of an all-envs info comes from: a row of the float or the int block the kernel fills.

        ``_top``: (key, source, block row) in the info's key order, source ``"f"`` / ``"i"`` (that block),
        ``"persona"`` / ``"outcome"`` (the label of the int block's row); ``_terms``: the reward terms'.
        """
        float_columns: list[int] = []
        int_columns: list[int] = []

        def slot(column: int, as_int: bool) -> tuple[str, int]:
            # A row of its own per key: no two info arrays share memory.
            columns = int_columns if as_int else float_columns
            columns.append(column)
            return ("i" if as_int else "f"), len(columns) - 1

        def label_of(key: str) -> int:  # the int row a label is looked up from (its key comes next)
            column = REPORT.persona_index if key == "persona" else REPORT.outcome
            return len(int_columns) if column not in int_columns else int_columns.index(column)

        top: list[tuple[str, str, int]] = []
        terms: list[tuple[str, str, int]] = []
        if self.numeric:
            top = [(key, *slot(column, as_int)) for key, column, as_int in self._entries]
        else:
            # The keys of _INFO_COLUMNS, in its order.
            for key, column, as_int in _INFO_COLUMNS:
                if key in ("persona", "outcome"):
                    top.append((key, key, label_of(key)))
                elif key == "persona_index":
                    top.append((key, *slot(REPORT.persona_index, True)))
                elif key == "outcome_code":
                    top.append((key, *slot(REPORT.outcome, True)))
                elif column is not None:
                    top.append((key, *slot(column, as_int)))
                else:
                    raise RuntimeError(f"the info's {key!r} has no report column: update _plan_all_envs")
            terms = [(name, *slot(REPORT.reward_success + k, False)) for k, name in enumerate(REWARD_TERMS)]
        for key, source, at in top:
            if source in ("persona", "outcome") and int_columns[at] != (
                REPORT.persona_index if source == "persona" else REPORT.outcome
            ):
                raise RuntimeError(f"the info's {key!r} must come right before its int key: update _INFO_COLUMNS")
        self._top = tuple(top)
        self._terms = tuple(terms)
        self._float_columns = np.array(float_columns, dtype=np.int64)
        self._int_columns = np.array(int_columns, dtype=np.int64)
        self._mask_count = len(top) + len(terms) + (0 if self.numeric else 1 + self.probabilities) + self.unscaled

    def unscaled_observation(self, rows: NDArray[np.float64]) -> NDArray[np.float32]:
        """The physical observation of report rows (one row or a batch)."""
        batch = np.atleast_2d(rows)
        obs = np.empty((batch.shape[0], self._obs_columns.shape[0]), dtype=np.float32)
        _unscaled_rows(batch, self._obs_columns, self._obs_low, self._obs_high, obs)
        return obs if rows.ndim == 2 else obs[0]

    def single(self, r: list[float]) -> dict[str, Any]:
        """The single env's info from one report row (``core.report[i].tolist()``)."""
        if self.numeric:
            # NumPy scalars, not Python numbers: TorchRL's info reader asks each value for its dtype.
            info: dict[str, Any] = {
                key: np.int64(r[column]) if as_int else np.float64(r[column]) for key, column, as_int in self._entries
            }
        else:
            info = report_info(r, self.persona_names, self.probabilities)
        if self.unscaled:
            info["unscaled_obs"] = self.unscaled_observation(np.array(r))
        return info

    def batched(self, report: NDArray[np.float64], mask: NDArray[np.bool_] | None) -> dict[str, Any]:
        """The vector env's infos (arrays with Gymnasium's ``_key`` masks) from its report rows.

        The single env's keys plus ``persona_index`` and ``outcome_code`` (:class:`~coop_gym.envs.config.Outcome`
        ints) under ``info_mode="default"``. Entries of envs outside ``mask`` (default all) are
        zero (``None`` for labels), as Gymnasium's ``_add_info`` leaves them.
        """
        infos = self._all_envs(report)
        if mask is not None:
            _apply_mask(infos, mask, ~mask if not mask.all() else None)
        return infos

    def _all_envs(self, report: NDArray[np.float64]) -> dict[str, Any]:
        """:meth:`batched` of every env (each step's infos), the same keys, values and dtypes, built faster.

        One compiled pass copies the report's info columns into two fresh blocks (float64 and
        int64) whose rows are the info's arrays, and the ``_key`` masks are the rows of one fresh
        all-True block: every array is new on every call and owns no memory another one uses.
        """
        n = report.shape[0]
        floats = np.empty((self._float_columns.shape[0], n))
        ints = np.empty((self._int_columns.shape[0], n), dtype=np.int64)
        _gather_info_columns(report, self._float_columns, floats, self._int_columns, ints)
        masks = iter(np.ones((self._mask_count, n), dtype=bool))
        infos: dict[str, Any] = {}
        for key, source, at in self._top:
            if source == "f":
                infos[key] = floats[at]
            elif source == "i":
                infos[key] = ints[at]
            else:
                labels = self._persona_array if source == "persona" else _OUTCOME_LABEL_ARRAY
                infos[key] = labels[ints[at]]
            infos[f"_{key}"] = next(masks)
        if self.probabilities and not self.numeric:
            infos["xi_probabilities"] = report[:, REPORT.p_uncooperative : REPORT.p_cooperative + 1].copy()
            infos["_xi_probabilities"] = next(masks)
        if not self.numeric:
            reward_terms: dict[str, Any] = {}
            for key, _, at in self._terms:
                reward_terms[key] = floats[at]
                reward_terms[f"_{key}"] = next(masks)
            infos["reward_terms"] = reward_terms
            infos["_reward_terms"] = next(masks)
        if self.unscaled:
            infos["unscaled_obs"] = self.unscaled_observation(report)
            infos["_unscaled_obs"] = next(masks)
        return infos


def _apply_mask(infos: dict[str, Any], mask: NDArray[np.bool_], outside: NDArray[np.bool_] | None) -> None:
    # Every ``_key`` becomes a copy of the mask; values of envs ``outside`` it are zeroed (None for labels).
    for key, value in infos.items():
        if key.startswith("_"):
            infos[key] = mask.copy()
        elif isinstance(value, dict):
            _apply_mask(value, mask, outside)
        elif outside is not None:
            value[outside] = None if value.dtype == object else 0


guard_kernel_cache(__name__)
