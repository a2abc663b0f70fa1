"""The estimators' arguments: NumPy scalars are numbers (issue #13), bools, strings and arrays are not."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from estimator.identification.identify import Trial
from estimator.judgment import ThresholdJudgment
from estimator.multiple_model import (
    IMMEstimator,
    MultipleModelEstimator,
    confident_judgment,
    sequential_judgment,
    switching_transition_matrix,
)
from estimator.nominal import NominalModel


def test_numpy_scalars_are_numbers() -> None:
    judgment = ThresholdJudgment(delay_s=np.float32(0.75), threshold=np.float64(0.3))
    assert type(judgment.delay_s) is float and type(judgment.threshold) is float
    assert judgment == ThresholdJudgment(delay_s=float(np.float32(0.75)), threshold=0.3)
    trial = Trial(np.zeros(3), np.zeros(3), np.zeros(3), xi=np.int64(-1), dt_s=np.float32(0.02))
    assert type(trial.xi) is int and trial.xi == -1 and type(trial.dt_s) is float
    np.testing.assert_array_equal(switching_transition_matrix(np.float32(0.5), np.float64(0.02)),
                                  switching_transition_matrix(0.5, 0.02))  # fmt: skip
    model = NominalModel()
    estimator = MultipleModelEstimator.from_model(model, np.zeros(2), probability_floor=np.float32(1e-6))
    assert estimator.probability_floor == float(np.float32(1e-6))
    IMMEstimator.from_model(model, np.zeros(2), switching_rate_per_s=np.int64(1))
    probs = np.full((1, 4, 3), 1.0 / 3.0)
    confident_judgment(probs, confidence=np.float32(0.9))
    sequential_judgment(probs, error_rate=np.float64(0.05))


def test_nominal_model_takes_numpy_scalars() -> None:
    assert NominalModel(dt_s=np.float32(0.02)).dt_s == float(np.float32(0.02))


BAD: list[tuple[str, Any, str]] = [
    ("judgment delay bool", lambda: ThresholdJudgment(delay_s=True), r"ThresholdJudgment\.delay_s must be in"),
    ("judgment threshold np.bool_", lambda: ThresholdJudgment(threshold=np.True_), r"ThresholdJudgment\.threshold"),
    ("judgment threshold array", lambda: ThresholdJudgment(threshold=np.array([0.3])), r"threshold must be > 0"),
    ("trial xi array", lambda: Trial(np.zeros(3), np.zeros(3), np.zeros(3), xi=np.array([1])), r"Trial\.xi must be"),
    ("trial xi np.bool_", lambda: Trial(np.zeros(3), np.zeros(3), np.zeros(3), xi=np.True_), r"Trial\.xi must be"),
    ("trial dt bool", lambda: Trial(np.zeros(3), np.zeros(3), np.zeros(3), dt_s=True), r"Trial\.dt_s must be"),
    (
        "floor a string",
        lambda: MultipleModelEstimator.from_model(NominalModel(), np.zeros(1), probability_floor="0.1"),
        r"probability_floor must be in \[0, 1/3\), got '0\.1'",
    ),
    (
        "floor np.bool_",
        lambda: MultipleModelEstimator.from_model(NominalModel(), np.zeros(1), probability_floor=np.False_),
        r"probability_floor must be in \[0, 1/3\), got np\.False_",
    ),
    ("switching rate bool", lambda: switching_transition_matrix(True, 0.02), r"switching_rate_per_s must be finite"),
    ("switching dt array", lambda: switching_transition_matrix(1.0, np.array([0.02])), r"dt_s must be finite"),
    ("confidence str", lambda: confident_judgment(np.full((2, 3), 1 / 3), confidence="0.9"), r"confidence must be"),
    ("error rate array", lambda: sequential_judgment(np.ones((1, 2, 3)) / 3, np.array([0.1])), r"error_rate must be"),
]


@pytest.mark.parametrize(("make", "match"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_values_are_refused_by_name(make: Any, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        make()
