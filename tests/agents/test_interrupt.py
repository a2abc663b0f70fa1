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
# PPO with one env: 256-step rollouts, so a checkpoint boundary every 512 steps (every second rollout).
TINY = [
    "--seeds", "1", "--timesteps", "1536", "--n-envs", "1", "--checkpoint-every", "512", "--eval-episodes", "4",
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
    from agents.hyperparams import hyperparams_for

    # One rollout of the default learner's n_steps (PPO's default framework: jax).
    assert trained["total_timesteps"] == hyperparams_for("ppo", None, "jax").algo_kwargs["n_steps"]

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


# --- a hostile user's run folders: each is named in one line, and the folder is left as it was ---------


def _usage_error(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one error line of ``train.main(argv)``, which must exit with status 2 and no traceback."""
    import train

    with pytest.raises(SystemExit) as exc:
        train.main(argv)
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "Traceback" not in err, err
    (line,) = [line for line in err.splitlines() if "error" in line]
    assert line.startswith("python train.py: error: ")
    return line


def _settings(**changes: object) -> str:
    """A tiny run's args.json, as train.py writes it, with ``changes``."""
    import dataclasses

    import train

    args = train.Args(seeds=1, timesteps=64, n_envs=1, eval_episodes=2, eval_points=0, baselines="handbook")
    return json.dumps(dataclasses.asdict(args) | changes)


def test_resume_of_an_args_json_without_settings_names_what_is_missing(tmp_path, capsys):
    run = tmp_path / "run"
    run.mkdir()
    (run / "args.json").write_text("{}")
    line = _usage_error(["--resume", str(run)], capsys)
    assert f"{run / 'args.json'} does not record the run's settings: algo, env, seed, timesteps, n_envs missing" in line
    assert [p.name for p in run.iterdir()] == ["args.json"]  # no default run started inside it


@pytest.mark.parametrize(
    ("settings", "message"),
    [
        ('{"seed": "banana"}', r"args.json: seed must be int, got 'banana'"),
        (_settings(seed="banana"), r"args.json: seed must be int, got 'banana'"),
        (_settings(timesteps=True), r"args.json: timesteps must be int or None, got True"),
        (_settings(algo="sac"), r"args.json: algo must be one of 'ppo', 'recurrent_ppo', 'dqn', got 'sac'"),
        (_settings(n_envs=0), r"args.json: --n-envs must be >= 1, got 0"),
        (_settings(eval_personas="nobody"), r"args.json: --eval-personas: unknown persona 'nobody'"),
    ],
)
def test_resume_reads_args_json_back_through_the_typed_args(tmp_path, settings, message, capsys):
    import re

    run = tmp_path / "run"
    run.mkdir()
    (run / "args.json").write_text(settings)
    assert re.search(message, _usage_error(["--resume", str(run)], capsys))


@pytest.fixture
def stopped_while_evaluating(tmp_path: Path) -> Path:
    """A run folder stopped during its final evaluation: its settings, the saved agent, training.json."""
    from agents.hyperparams import hyperparams_for
    from agents.rl import make_model, make_train_env, save_agent

    torch.set_num_threads(1)
    run = tmp_path / "runs" / "run"
    run.mkdir(parents=True)
    (run / "args.json").write_text(_settings())
    config = hyperparams_for("ppo")
    env = make_train_env(config.env_id, 1, 0, normalize=True, backend="dummy")
    save_agent(make_model(config, env, 0), run, algo="ppo", env_id=config.env_id)
    env.close()
    (run / "training.json").write_text(json.dumps({"training": {}, "learning_curve": [], "start_steps": 0}))
    (run / "INTERRUPTED").write_text(f"SIGINT: stopped\nresume with: python train.py --resume {run}\n")
    return run


def test_a_truncated_training_json_is_named_and_the_marker_kept(stopped_while_evaluating, capsys):
    run = stopped_while_evaluating
    (run / "training.json").write_text((run / "training.json").read_text()[:20])
    line = _usage_error(["--resume", str(run)], capsys)
    assert f"--resume: {run / 'training.json'} is unreadable" in line and "remove it to train this run again" in line
    assert (run / "INTERRUPTED").exists() and not (run / "COMPLETE").exists()


def test_a_signal_whose_exception_is_swallowed_during_evaluation_still_stops_the_run(
    stopped_while_evaluating, monkeypatch, capsys
):
    """As when the signal lands inside numba's ctypes callback: the handler's exception is lost, the signal is not."""
    import agents.trainer.run_report
    import train
    from agents.trainer.training_run import Stopped

    evaluate = agents.trainer.run_report.evaluate

    def evaluate_and_get_a_signal(*args, **kwargs):
        try:
            signal.raise_signal(signal.SIGINT)  # the handler runs here and raises Stopped ...
        except Stopped:
            pass  # ... which a ctypes callback would print as "Exception ignored" and drop
        return evaluate(*args, **kwargs)

    run = stopped_while_evaluating
    monkeypatch.setattr(agents.trainer.run_report, "evaluate", evaluate_and_get_a_signal)
    assert train.main(["--resume", str(run)]) == 128 + signal.SIGINT
    assert "training had finished" in (run / "INTERRUPTED").read_text()
    assert not (run / "COMPLETE").exists() and not (run / "results.json").exists()
    monkeypatch.setattr(agents.trainer.run_report, "evaluate", evaluate)
    assert train.main(["--resume", str(run)]) == 0
    assert (run / "COMPLETE").exists() and not (run / "INTERRUPTED").exists()


# --- a run that cannot continue: exit status 1, one line naming the folder and the cause, the marker kept ---


def _cannot_continue(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """The one error line of ``train.main(argv)``, which must exit with status 1 and no traceback."""
    import train

    try:
        code = train.main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err, err
    (line,) = [line for line in err.splitlines() if "error" in line]
    assert line.startswith("python train.py: error: ")
    return line


def test_a_run_whose_model_is_gone_after_training_says_so_and_keeps_its_marker(stopped_while_evaluating, capsys):
    run = stopped_while_evaluating
    (run / "model.zip").unlink()
    line = _cannot_continue(["--resume", str(run)], capsys)
    assert f"--resume {run}: training finished (training.json) but its model.zip is missing" in line, line
    assert "free space" not in line and (run / "INTERRUPTED").exists()


def test_a_foreign_model_in_a_checkpoint_is_named_before_training(tmp_path, capsys):
    """An SB3 run's model.zip (1 env) copied into a JAX run's checkpoint (2 envs) at another step count."""
    from agents.hyperparams import hyperparams_for
    from agents.ppo import PPO, PPOConfig
    from agents.rl import make_model, make_train_env, save_agent
    from agents.rl.ppo_run import save_learner

    run = tmp_path / "runs" / "run"
    run.mkdir(parents=True)
    (run / "args.json").write_text(_settings(n_envs=2, timesteps=4096, framework="jax"))
    (run / "INTERRUPTED").write_text(f"SIGINT: stopped\nresume with: python train.py --resume {run}\n")
    config = hyperparams_for("ppo", None, "jax")
    own = PPO(config.env_id, PPOConfig.from_training(config.replace(n_envs=2)), 0, {"personas": config.personas})
    own.num_timesteps = 2048
    checkpoint = save_learner(own, run, algo="ppo", env_id=config.env_id, extra={"start_steps": 0})
    own.env.close()
    foreign = tmp_path / "foreign"
    sb3 = make_model(hyperparams_for("ppo", None, "sb3"), make_train_env(config.env_id, 1, 0, backend="dummy"), 0)
    save_agent(sb3, foreign, algo="ppo", env_id=config.env_id)
    (checkpoint / "model.zip").write_bytes((foreign / "model.zip").read_bytes())
    line = _cannot_continue(["--resume", str(run), "--no-progress"], capsys)
    assert f"--resume {run}: {checkpoint / 'model.zip'} holds a model of num_timesteps 0" in line, line
    assert "but its checkpoint's state.pkl has 2048" in line and f"remove {checkpoint}" in line
    assert (run / "INTERRUPTED").exists() and not (run / "COMPLETE").exists()


def test_a_read_only_run_folder_is_named_before_any_work(stopped_while_evaluating, monkeypatch, capsys):
    """What a read-only mount gives (root writes through permission bits, so access is faked)."""
    import os

    run = stopped_while_evaluating
    before = sorted(p.name for p in run.iterdir())
    monkeypatch.setattr(os, "access", lambda path, mode: Path(path) != run)
    line = _cannot_continue(["--resume", str(run)], capsys)
    assert f"--resume {run}: the run folder is not writable; copy it to a writable place (cp -a {run} COPY)" in line
    assert "free space" not in line and "--resume runs" not in line
    assert sorted(p.name for p in run.iterdir()) == before


@pytest.mark.parametrize(
    ("errno_name", "remedy"),
    [("ENOSPC", "free space, then python train.py --resume RUN"), ("EROFS", "copy it to a writable place")],
)
def test_a_failed_write_names_the_folder_and_the_remedy_for_its_cause(errno_name, remedy, capsys):
    import errno
    import os

    from agents.trainer.training_run import write_failed

    code = errno.__dict__[errno_name]
    assert write_failed(OSError(code, os.strerror(code), "RUN/eval.json"), Path("RUN")) == 1
    err = capsys.readouterr().err
    assert f"could not write RUN/eval.json: {os.strerror(code)}" in err and remedy in err, err
    assert err.count("free space") == (errno_name == "ENOSPC")


def test_envs_the_learners_minibatches_cannot_divide_are_named_before_any_folder(tmp_path, capsys):
    """3 envs x 256 steps cannot be cut into minibatches of 512: one line, and no run folder."""
    import train

    assert train.main(["--n-envs", "3", "--seeds", "1", "--out", str(tmp_path / "runs"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "python train.py: error: --n-envs 3:" in err, err
    assert "multiple of batch_size (512)" in err
    assert not (tmp_path / "runs").exists()
