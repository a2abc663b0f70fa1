"""The env core's packed rows are laid out from named lists (estimator.compiled.schema), never by hand."""

from __future__ import annotations

import numpy as np

from coop_gym.envs import SitToStandEnv
from coop_gym.envs.contract import REPORT, REPORT_COLUMNS
from coop_gym.envs.kernels.layout import BLOCKS, CONST_COLUMNS, CONSTS, CUE_COLUMNS, PERSONA_BLOCKS
from coop_gym.model.dynamics import PARAM_COLUMNS, STATE_COLUMNS
from estimator.judgment import JUDGMENT_COLUMNS
from estimator.kalman import NOMINAL_COLUMNS


def test_every_report_and_const_column_has_its_own_name() -> None:
    assert REPORT._fields == REPORT_COLUMNS and tuple(REPORT) == tuple(range(len(REPORT_COLUMNS)))
    assert CONSTS._fields == CONST_COLUMNS and tuple(CONSTS) == tuple(range(len(CONST_COLUMNS)))


def test_state_blocks_follow_the_row_widths() -> None:
    widths = {
        "person": len(STATE_COLUMNS),
        "cues": len(CUE_COLUMNS),
        "judge": len(JUDGMENT_COLUMNS),
        "nominal": len(NOMINAL_COLUMNS),
        "params": len(PARAM_COLUMNS),
        "report": len(REPORT_COLUMNS),
    }
    starts = BLOCKS._asdict()
    names = list(starts)
    for name, width in widths.items():
        assert starts[names[names.index(name) + 1]] - starts[name] == width, name
    assert PERSONA_BLOCKS.end == len(PARAM_COLUMNS) + len(NOMINAL_COLUMNS) + 2


def test_the_core_state_and_consts_are_sized_from_the_tables() -> None:
    core = SitToStandEnv().core
    substeps = int(core.consts[CONSTS.substeps])
    assert core.state.shape == (1, BLOCKS.end + 3 * substeps)
    assert core.report.shape == (1, len(REPORT_COLUMNS)) and core.params.shape == (1, len(PARAM_COLUMNS))
    # The observation spec sits right after the scalars.
    assert core.consts[CONSTS.obs_at] == len(CONST_COLUMNS)
    assert np.all(np.isfinite(core.consts[: len(CONST_COLUMNS)]))
