"""train.py end to end with a tiny budget: run folder, loadable model, resume, eval-only, usage errors."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
TINY = [
    "--seeds", "1", "--timesteps", "256", "--n-envs", "2", "--eval-episodes", "8", "--eval-points", "1",
    "--select-episodes", "64", "--no-progress",
]  # fmt: skip


def run_train(*argv: str, cwd: Path, timeout_s: float = 1200) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, str(ROOT / "train.py"), *argv],
        capture_output=True,
        text=True,
        timeout=timeout_s,
        cwd=cwd,
    )


@pytest.fixture(scope="module")
def first_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("runs")
    proc = run_train(*TINY, "--out", str(out), cwd=out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (run_dir,) = out.iterdir()
    return run_dir


def test_run_folder_is_complete_and_the_model_loads(first_run):
    assert first_run.name.startswith("CoopGym-SitToStandHard-v2__ppo__0__")  # the default: the hard level
    for name in ("COMPLETE", "results.json", "model.zip", "vecnormalize.pkl", "agent.json", "eval.json", "eval.csv"):
        assert (first_run / name).exists(), name
    for name in ("learning_curve.png", "outcome_rates.png"):
        assert (first_run / name).read_bytes()[:4] == b"\x89PNG"
    assert any((first_run / "tb").iterdir())  # TensorBoard events
    results = json.loads((first_run / "results.json").read_text())
    agents = [r["agent"] for r in results["evaluation"]["results"]]
    assert agents == [
        "ppo (learned)",
        "random",
        "lift_at_once",
        "push_then_lift",
        "handbook",
        "blind",
        "prober",
        "belief",
        "oracle",
    ]
    # The report says what the benchmark measures: oracle - best blind, best non-oracle - best blind.
    room = results["headroom"]
    assert room["value_of_reading_the_mind"] == pytest.approx(room["oracle"] - room["best_blind"])
    assert room["achieved_insight"] == pytest.approx(room["best_reader"] - room["best_blind"])
    # ... and the mind-reading score of every agent, the learned one first, beside its rates.
    learned = results["evaluation"]["results"][0]
    assert "mind_reading_score" in learned and set(room["mind_reading_score"]) >= {"ppo (learned)", "blind", "oracle"}
    # The oracle scores 1 by definition -- where the score is defined: on these 8 episodes the widened blind
    # policy may succeed as often as the oracle, and then no score is made up.
    if room["oracle"] > room["best_blind"]:
        assert room["mind_reading_score"]["oracle"]["score"] == pytest.approx(1.0)
    else:
        assert room["mind_reading_score"]["oracle"]["score"] is None
    assert all(r["episodes"] == 8 and r["personas"] == ["frail", "forgetful"] for r in results["evaluation"]["results"])
    assert set(results["verdict"]) >= {"higher_success_than_handbook", "no_more_unsafe_than_handbook"}
    assert results["training"]["timesteps"] >= 256
    # 256 steps learn nothing: where the score is defined, the report says the seed reads no mind.
    learned_score = room["mind_reading_score"]["ppo (learned)"]["score"]
    expected = None if learned_score is None else learned_score <= 0
    assert results["reads_no_better_than_blind"] is expected
    # The saved policy is the best-validated one, on the training personas (here only the final one is scored).
    selected = results["training"]["selected"]
    assert selected["personas"] == "train" and selected["episodes"] == 64
    assert selected["timesteps"] == selected["final_timesteps"] == results["training"]["total_timesteps"]

    from agents.rl import load_agent

    agent = load_agent(first_run)
    again = load_agent(first_run / "model.zip")
    obs = np.zeros((3, 11), dtype=np.float32)
    assert np.array_equal(agent.predict(obs)[0], again.predict(obs)[0])


def test_resume_continues_the_step_count(first_run, tmp_path):
    import train

    before = json.loads((first_run / "agent.json").read_text())["num_timesteps"]
    assert train.main([*TINY, "--resume", str(first_run), "--baselines", "", "--out", str(tmp_path)]) == 0
    (run_dir,) = tmp_path.iterdir()
    info = json.loads((run_dir / "agent.json").read_text())
    results = json.loads((run_dir / "results.json").read_text())
    assert info["num_timesteps"] == before + results["training"]["timesteps"]
    assert results["training"]["timesteps"] >= 256 and results["training"]["resumed_from"] == str(first_run)
    assert (run_dir / "vecnormalize.pkl").exists()  # the statistics travel with the resumed model


def test_eval_only_in_process(first_run, tmp_path, capsys):
    import train

    model = str(first_run / "model.zip")
    code = train.main(
        ["--eval-only", "--model", model, "--eval-episodes", "4", "--baselines", "handbook", "--out", str(tmp_path)]
    )
    assert code == 0
    (run_dir,) = tmp_path.iterdir()
    results = json.loads((run_dir / "results.json").read_text())
    assert [r["agent"] for r in results["evaluation"]["results"]] == ["ppo (learned)", "handbook"]
    assert (run_dir / "COMPLETE").exists() and not (run_dir / "model.zip").exists()
    assert "handbook" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv",
    [
        ["--algo", "sac"],
        ["--eval-only"],
        ["--timesteps", "0"],
        ["--eval-episodes", "0"],
        ["--env", "CoopGym/Nope-v0"],
        ["--eval-personas", "grumpy"],
        ["--select-on", "test"],
        ["--baselines", "handbook,nurse"],
        ["--resume", "/no/such/run"],
        ["--model", "x.zip"],
        ["--timesteps", "lots"],
    ],
)
def test_usage_errors_exit_2(argv, capsys):
    import train

    with pytest.raises(SystemExit) as exc:
        train.parse_args(argv)
    assert exc.value.code == 2
    assert "error" in capsys.readouterr().err


def test_bad_flag_subprocess_exits_2_and_help_shows_field_docs(tmp_path):
    bad = run_train("--algo", "sac", cwd=tmp_path)
    assert bad.returncode == 2 and "--algo" in bad.stderr
    assert not any(tmp_path.iterdir())  # nothing written for a usage error
    shown = run_train("--help", cwd=tmp_path)
    assert shown.returncode == 0
    help_text = " ".join(shown.stdout.replace("│", " ").split())  # tyro's help: a box, lines wrapped
    assert "from its last checkpoint" in help_text and "--eval-episodes" in help_text
    assert "--no-progress" in help_text


def test_unwritable_out_exits_2(tmp_path, capsys):
    import train

    blocker = tmp_path / "a_file"
    blocker.write_text("not a folder")
    with pytest.raises(SystemExit) as exc:
        train.parse_args(["--out", str(blocker / "runs")])
    assert exc.value.code == 2 and "a_file is not a folder" in capsys.readouterr().err


@pytest.mark.slow
def test_default_run_beats_the_handbook_on_held_out_personas(tmp_path):
    """The quality bar (SPEC): `python train.py` on defaults beats the handbook on 1000 held-out episodes.

    Quality only: how long it takes is a measurement (docs/BENCHMARKS.md, "Time to a good caregiver", from
    bench/results/time_to_quality_*.json), not an assertion, since other jobs on the machine move it. The
    timeout only guards against a hang."""
    import time

    started = time.perf_counter()
    proc = run_train("--out", str(tmp_path), "--no-progress", cwd=tmp_path, timeout_s=2 * 3600)
    print(f"default train.py run: {time.perf_counter() - started:.0f} s wall")
    assert proc.returncode == 0, proc.stderr[-3000:]
    (run_dir,) = tmp_path.iterdir()
    results = json.loads((run_dir / "results.json").read_text())
    assert results["evaluation"]["episodes"] >= 1000 and results["evaluation"]["personas"] == "test"
    verdict = results["verdict"]
    assert verdict["higher_success_than_handbook"], verdict
    assert verdict["no_more_unsafe_than_handbook"], verdict


def test_the_report_warns_when_the_learned_agent_reads_no_mind(capsys):
    from types import SimpleNamespace

    from agents.trainer.run_report import warn_if_blind

    def room(score):
        return SimpleNamespace(score_of=lambda agent: SimpleNamespace(agent=agent, score=score))

    assert warn_if_blind("ppo (learned)", room(-0.02)) is True
    assert "does no better than the best blind policy" in capsys.readouterr().out
    assert warn_if_blind("ppo (learned)", room(0.62)) is False
    assert warn_if_blind("ppo (learned)", room(float("nan"))) is None
    assert warn_if_blind("ppo (learned)", None) is None
    assert capsys.readouterr().out == ""


def test_the_algo_choices_are_the_algorithms_with_defaults():
    """``Args.algo``'s Literal is what tyro offers; it must name exactly agents.hyperparams.ALGORITHMS."""
    import typing

    import train
    from agents.hyperparams import ALGORITHMS

    assert typing.get_args(typing.get_type_hints(train.Args)["algo"]) == ALGORITHMS


def test_framework_jax_trains_and_reports_and_its_model_continues_with_jax(tmp_path):
    """train.py --framework jax: the same run folder and report; the model loads as SB3's PPO and --resume keeps JAX.

    With ``--policy-lag 1``, which the run's settings keep. That the learner's checkpoint
    continues exactly, lagged or not: tests/agents/test_ppo.py.
    """
    import train
    from agents.rl import load_model

    tiny = [*TINY, "--timesteps", "512", "--checkpoint-every", "128", "--framework", "jax", "--policy-lag", "1"]
    proc = run_train(*tiny, "--out", str(tmp_path), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (run_dir,) = tmp_path.iterdir()
    settings = json.loads((run_dir / "args.json").read_text())
    assert settings["framework"] == "jax" and settings["policy_lag"] == 1
    model, info = load_model(run_dir / "model.zip")
    from stable_baselines3 import PPO

    assert isinstance(model, PPO) and info["framework"] == "jax"
    results = json.loads((run_dir / "results.json").read_text())
    assert results["training"]["timesteps"] >= 512
    assert results["evaluation"]["results"][0]["agent"] == "ppo (learned)" and results["framework"] == "jax"
    assert train.parse_args(["--resume", str(run_dir), "--out", str(tmp_path)]).framework == "jax"


def test_recurrent_ppo_on_jax_trains_agents_ppos_lstm_learner_and_saves_sb3_contribs_class(tmp_path):
    """train.py --algo recurrent_ppo --framework jax: agents.ppo.recurrent.RecurrentPPO, saved as sb3-contrib's class.

    The model loads and plays without JAX, the report names the framework, and the saved model
    holds the learner's LSTM. That its checkpoint continues exactly: tests/agents/test_recurrent.py.
    """
    from sb3_contrib import RecurrentPPO

    from agents.rl import load_model

    tiny = [*TINY, "--algo", "recurrent_ppo", "--framework", "jax", "--timesteps", "1024", "--checkpoint-every", "512"]
    proc = run_train(*tiny, "--baselines", "blind", "--out", str(tmp_path), cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    (run_dir,) = tmp_path.iterdir()
    model, info = load_model(run_dir / "model.zip")
    assert isinstance(model, RecurrentPPO) and info["framework"] == "jax" and info["algo"] == "recurrent_ppo"
    assert model.policy.lstm_actor.hidden_size == 64 and model.n_steps == 256  # the JAX sizing's rollout per env
    results = json.loads((run_dir / "results.json").read_text())
    assert results["framework"] == "jax" and results["training"]["timesteps"] >= 1024
    assert results["evaluation"]["results"][0]["agent"] == "recurrent_ppo (learned)"
    assert not (run_dir / "checkpoints").exists()  # a finished run keeps its model, not its checkpoints
