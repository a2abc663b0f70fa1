"""Outcomes are the Outcome enum end to end: the kernel's codes come from it, checks survive ``python -O``."""

from __future__ import annotations

import ast
import inspect
import subprocess
import sys
from enum import IntEnum
from pathlib import Path

import numpy as np
import pytest

from coop_gym.envs import contract, core
from coop_gym.envs.config import LiftCriteria, Outcome, RewardWeights
from coop_gym.envs.kernels import report as report_module
from coop_gym.envs.kernels import step as step_module
from coop_gym.model.dynamics import STATE
from coop_gym.model.params import Cues, Realism, Timing
from coop_gym.model.personas import PERSONAS
from estimator.judgment import ThresholdJudgment

ROOT = Path(__file__).resolve().parents[2]


def test_the_core_has_no_assert_and_its_kernel_no_outcome_literal() -> None:
    for module in (core, step_module):
        tree = ast.parse(Path(module.__file__).read_text())
        asserts = [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Assert)]
        assert not asserts, f"asserts vanish under python -O; raise instead ({module.__name__} lines {asserts})"
    kernel = ast.parse(inspect.getsource(step_module.step_env.py_func))
    literals = [
        node.lineno
        for node in ast.walk(kernel)
        if isinstance(node, (ast.Assign, ast.Compare))
        and any(isinstance(n, ast.Name) and n.id == "outcome" for n in ast.walk(node))
        and any(isinstance(n, ast.Constant) and n.value in (1, 2, 3, 4) for n in ast.walk(node))
    ]
    assert not literals, f"outcome literals in step_env (lines {literals}): use the enum's codes"


def test_the_kernel_codes_are_the_enums() -> None:
    codes = (step_module._NONE, step_module._SUCCESS, step_module._UNSAFE, step_module._PREMATURE)
    assert codes == tuple(Outcome)[:-1] and report_module._TIMEOUT == Outcome.TIMEOUT
    lifts = [o in (Outcome.SUCCESS, Outcome.UNSAFE, Outcome.PREMATURE) for o in Outcome]
    assert contract.TERMINATES.tolist() == lifts and [o.terminates for o in Outcome] == lifts
    assert contract.TRUNCATES.tolist() == [o is Outcome.TIMEOUT for o in Outcome]


def test_outcome_codes_that_are_not_consecutive_are_refused() -> None:
    class Gapped(IntEnum):
        NONE = 0
        SUCCESS = 2

    with pytest.raises(ValueError, match=r"Gapped values must be 0 \.\. 1"):
        contract.check_outcome_codes(Gapped)
    contract.check_outcome_codes(Outcome)


def test_the_package_imports_and_checks_under_python_optimize() -> None:
    code = (
        "import coop_gym.envs.kernels.step as c, coop_gym.envs.kernels.report as k; "
        "k.check_outcome_codes(k.Outcome); print(c._SUCCESS)"
    )
    out = subprocess.run([sys.executable, "-O", "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == str(int(Outcome.SUCCESS))


@pytest.mark.parametrize(
    ("xi", "lean_m", "expected"),
    [(1, 0.2, Outcome.SUCCESS), (-1, 0.2, Outcome.UNSAFE), (1, 0.0, Outcome.UNSAFE), (0, 0.1, Outcome.PREMATURE)],
)
def test_a_lift_ends_with_the_enums_outcome(xi: int, lean_m: float, expected: Outcome) -> None:
    lift = LiftCriteria()
    person = (PERSONAS["typical"],)
    c = core.SitToStandCore(1, person, Timing(), Cues(), Realism(), lift, RewardWeights(), ThresholdJudgment())
    c.reset_env(0, np.random.default_rng(0), initial_xi=xi)
    c.person[0, STATE.x_m] = lean_m  # place the shoulder
    c.cmd[0, contract.CMD.lift] = 1.0
    c.step_commands(c.cmd)
    outcome = int(c.report[0, contract.REPORT.outcome])
    assert Outcome(outcome) is expected
    assert bool(contract.TERMINATES[outcome])
    rewards = c.report[0, contract.REPORT.reward_success : contract.REPORT.reward].tolist()
    terms = dict(zip(core.REWARD_TERMS, rewards, strict=True))
    assert terms[expected.label] != 0.0
