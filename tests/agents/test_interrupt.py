"""train.py never loses a run: Ctrl-C and SIGKILL mid-training, then ``--resume`` to completion."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[2]
# PPO with one env: 512-step rollouts, so a checkpoint boundary every 512 steps.
TINY = [
    "--timesteps", "1536", "--n-envs", "1", "--checkpoint-every", "512", "--eval-episodes", "4",
    "--eval-points", "0", "--select-episodes", "64", "--baselines", "", "--no-progress", "--threads", "1",
]  # fmt: skip


def _start(out: Path) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, str(ROOT / "train.py"), *TINY, "--out", str(out)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=out,
    )


def _wait_for_checkpoint(out: Path, proc: subprocess.Popen[str], timeout_s: float = 120) -> Path:
    """The run folder, once its first checkpoint exists (training is under way)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        found = [p for p in out.glob("*/checkpoints/step_*") if (p / "state.pkl").exists()]
        if found:
            return found[0].parents[1]
        if proc.poll() is not None:
            pytest.fail(f"train.py ended before its first checkpoint: {proc.communicate()[1][-2000:]}")
        time.sleep(0.05)
    proc.kill()
    pytest.fail("no checkpoint appeared")


def _policy_weights(run: Path) -> dict[str, torch.Tensor]:
    from agents.rl import load_model

    model, _ = load_model(run / "model.zip")
    return model.policy.state_dict()


def _interrupt(out: Path, signum: int) -> Path:
    """Start a tiny train.py run, send ``signum`` once its first checkpoint exists; the run folder."""
    proc = _start(out)
    run = _wait_for_checkpoint(out, proc)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    expected = -signal.SIGKILL if signum == signal.SIGKILL else 128 + signum
    assert proc.returncode == expected, err[-2000:]
    assert not (run / "COMPLETE").exists()
    if signum != signal.SIGKILL:
        assert (run / "INTERRUPTED").exists() and "Traceback" not in err
        assert f"python train.py --resume {run}" in err and f"--resume {run}" in (run / "INTERRUPTED").read_text()
    return run


def _resume_to_completion(run: Path, capsys: pytest.CaptureFixture[str]) -> str:
    """Resume in-process with no other flag (the run's own settings); the printed output."""
    import train

    assert train.main(["--resume", str(run), "--no-progress"]) == 0
    assert [p.name for p in run.parent.iterdir()] == [run.name]  # in its own folder: no orphan
    assert (run / "COMPLETE").exists() and not (run / "INTERRUPTED").exists()
    assert not (run / "checkpoints").exists() and not [p for p in run.rglob("*") if ".tmp-" in p.name]
    results = json.loads((run / "results.json").read_text())
    assert results["training"]["total_timesteps"] == 1536 and results["learning_curve"] == []  # --eval-points 0
    return capsys.readouterr().out


def test_ctrl_c_stops_cleanly_and_resume_completes(tmp_path, capsys):
    out = tmp_path / "runs"
    out.mkdir()
    run = _interrupt(out, signal.SIGINT)
    assert "continuing from" in _resume_to_completion(run, capsys)


def test_sigkill_then_resume_continues_from_the_last_checkpoint(tmp_path, capsys):
    out = tmp_path / "runs"
    out.mkdir()
    run = _interrupt(out, signal.SIGKILL)
    assert not (run / "INTERRUPTED").exists()
    (run / "checkpoints" / ".step_000000009999.tmp-dead").mkdir()  # as if killed while writing one
    (run / ".eval.tmp-dead.json").write_text("{")
    printed = _resume_to_completion(run, capsys)
    assert "continuing from" in printed and "step_000000000512" in printed


@pytest.mark.slow
def test_sigterm_at_a_boundary_then_resume_reaches_the_weights_of_an_unbroken_run(tmp_path, capsys):
    """End to end through train.py; tests/agents/test_checkpoint.py shows the same for each algorithm in-process."""
    import train

    out = tmp_path / "runs"
    out.mkdir()
    run = _interrupt(out, signal.SIGTERM)
    _resume_to_completion(run, capsys)
    straight = tmp_path / "straight"
    assert train.main([*TINY, "--out", str(straight)]) == 0
    (unbroken,) = straight.iterdir()
    a, b = _policy_weights(run), _policy_weights(unbroken)
    assert all(torch.equal(a[k], b[k]) for k in a)
    # The validation scores continue across the interruption: the same policy is selected.
    selected = [json.loads((r / "training.json").read_text())["training"]["selected"] for r in (run, unbroken)]
    assert selected[0] == selected[1] and len(selected[0]["scores"]) == 2  # at 1024 steps, then the final policy


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--seed", "3"], r"--seed 3 \(the run has 0\)"),
        (["--algo", "dqn", "--timesteps", "64"], r"--algo 'dqn' \(the run has 'ppo'\); --timesteps 64"),
    ],
)
def test_resume_flags_that_contradict_the_run_are_named(tmp_path, argv, message, capsys):
    import re

    import train

    run = tmp_path / "run"
    run.mkdir()
    settings = {"algo": "ppo", "env": "CoopGym/SitToStand-v0", "seed": 0, "timesteps": 2560, "n_envs": 1}
    (run / "args.json").write_text(json.dumps(settings))
    with pytest.raises(SystemExit) as exc:
        train.parse_args(["--resume", str(run), *argv])
    assert exc.value.code == 2
    assert re.search(message, capsys.readouterr().err)
    args = train.parse_args(["--resume", str(run), "--seed", "0"])  # agreeing flags are fine
    assert (args.algo, args.seed, args.timesteps, args.n_envs) == ("ppo", 0, 2560, 1)


def test_resume_without_a_checkpoint_starts_over_and_after_training_only_evaluates(tmp_path, capsys):
    """Killed before the first checkpoint: training starts over in the same folder. Killed while
    evaluating: the finished training is kept and only the evaluation runs again."""
    import dataclasses

    import train

    run = tmp_path / "runs" / "killed_early"
    run.mkdir(parents=True)
    args = train.Args(timesteps=64, n_envs=1, eval_episodes=2, eval_points=0, baselines="", progress=False)
    (run / "args.json").write_text(json.dumps(dataclasses.asdict(args)))  # older style: env etc. left None
    assert train.main(["--resume", str(run)]) == 0
    assert [p.name for p in run.parent.iterdir()] == [run.name] and (run / "COMPLETE").exists()
    trained = json.loads((run / "results.json").read_text())["training"]
    assert trained["total_timesteps"] == 512  # one rollout of the default n_steps

    for name in ("COMPLETE", "results.json", "eval.json"):  # as if killed during the evaluation
        (run / name).unlink()
    capsys.readouterr()
    assert train.main(["--resume", str(run)]) == 0
    assert "trained" not in capsys.readouterr().out  # no training this time
    assert json.loads((run / "results.json").read_text())["training"] == trained


def test_an_interrupted_eval_only_run_is_not_resumed_as_training(tmp_path, capsys):
    import train

    run = tmp_path / "run"
    run.mkdir()
    (run / "args.json").write_text(json.dumps({"algo": "ppo", "eval_only": True, "model": "runs/x/model.zip"}))
    with pytest.raises(SystemExit) as exc:
        train.parse_args(["--resume", str(run)])
    assert exc.value.code == 2
    assert "was an --eval-only run; run it again: --eval-only --model runs/x/model.zip" in capsys.readouterr().err
