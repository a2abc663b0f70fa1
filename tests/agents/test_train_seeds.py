"""``train.py --seeds N``: each seed trained as its own run, the best on the validation people kept, resumable."""

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
# PPO with one env: 256-step rollouts, a checkpoint every 512 steps.
# --select-points 1 scores the final policy on the validation people.
TINY = [
    "--timesteps", "1536", "--n-envs", "1", "--checkpoint-every", "512", "--eval-episodes", "4",
    "--eval-points", "0", "--select-points", "1", "--select-episodes", "32", "--baselines", "",
    "--no-progress", "--threads", "1",
]  # fmt: skip


def _weights(model_zip: Path) -> dict[str, torch.Tensor]:
    from agents.rl import load_model

    model, _ = load_model(model_zip)
    return model.policy.state_dict()


def _same(a: Path, b: Path) -> bool:
    wa, wb = _weights(a), _weights(b)
    return wa.keys() == wb.keys() and all(torch.equal(wa[k], wb[k]) for k in wa)


def _only_run(out: Path) -> Path:
    (run,) = out.iterdir()
    return run


def test_each_seed_is_the_run_of_that_seed_and_the_best_on_validation_people_is_kept(tmp_path):
    import train

    assert train.main([*TINY, "--seeds", "2", "--seed", "5", "--out", str(tmp_path / "two")]) == 0
    run = _only_run(tmp_path / "two")
    training = json.loads((run / "training.json").read_text())["training"]
    scores = training["seeds"]
    assert [s["seed"] for s in scores] == [5, 6] and all(s["personas"] == "validation" for s in scores)
    best = max(scores, key=lambda s: s["success_rate"])["seed"]  # the first of equals
    assert training["kept_seed"] == best
    kept = run / "seeds" / f"seed_{best}"
    assert (run / "model.zip").read_bytes() == (kept / "model.zip").read_bytes()
    assert (run / "monitor.csv").read_bytes() == (kept / "monitor.csv").read_bytes()
    results = json.loads((run / "results.json").read_text())
    assert results["training"]["kept_seed"] == best and (run / "COMPLETE").exists()
    # A seed of a --seeds run trains what that seed trains alone.
    assert train.main([*TINY, "--seed", "6", "--out", str(tmp_path / "alone")]) == 0
    assert _same(run / "seeds" / "seed_6" / "model.zip", _only_run(tmp_path / "alone") / "model.zip")
    # Its score is the validation people's: what the evaluation path gives on those episodes.
    from agents.evaluate import evaluate
    from agents.rl import load_agent
    from agents.rl.callbacks import VALIDATION_SEED

    again = evaluate(load_agent(run / "seeds" / "seed_6"), results["env_id"], "validation", 32, VALIDATION_SEED)
    assert again.success_rate == scores[1]["success_rate"]
    # PPO's seeds are kept as one: the folder loads as their ensemble, and that is what the run scored.
    from agents.rl.ensemble import EnsembleAgent

    assert training["keep"] == "ensemble"
    assert json.loads((run / "ensemble.json").read_text()) == {"members": ["seeds/seed_5", "seeds/seed_6"]}
    ensemble = load_agent(run)
    assert isinstance(ensemble, EnsembleAgent) and len(ensemble.members) == 2 and results["model"] == str(run)
    both = evaluate(ensemble, results["env_id"], "validation", 32, VALIDATION_SEED)
    assert both.success_rate == training["ensemble"]["success_rate"]


def test_keep_best_keeps_one_seed_and_a_damaged_ensemble_file_is_named(tmp_path):
    import train
    from agents.rl import load_agent

    assert train.main([*TINY, "--seeds", "2", "--keep", "best", "--out", str(tmp_path / "best")]) == 0
    run = _only_run(tmp_path / "best")
    results = json.loads((run / "results.json").read_text())
    assert not (run / "ensemble.json").exists() and results["model"] == str(run / "model.zip")
    assert results["training"]["keep"] == "best" and "ensemble" not in results["training"]
    (run / "ensemble.json").write_text('{"members": ["seeds/seed_0", "../elsewhere"]}')
    with pytest.raises(ValueError, match=r"member '../elsewhere' is not a saved agent inside"):
        load_agent(run)
    (run / "ensemble.json").write_text("{")
    with pytest.raises(ValueError, match=r"ensemble.json is unreadable"):
        load_agent(run)


def test_ctrl_c_in_the_second_seed_resumes_it_and_keeps_the_first(tmp_path, capsys):
    import train

    out = tmp_path / "runs"
    out.mkdir()
    argv = [sys.executable, str(ROOT / "train.py"), *TINY, "--seeds", "2", "--out", str(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=out)
    deadline = time.monotonic() + 180
    while not list(out.glob("*/seeds/seed_1/checkpoints/step_*/state.pkl")):
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"no checkpoint of the second seed: {proc.communicate()[1][-2000:]}")
        time.sleep(0.05)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 128 + signal.SIGINT, err[-2000:]
    run = _only_run(out)
    assert (run / "INTERRUPTED").exists() and not (run / "model.zip").exists()
    first = (run / "seeds" / "seed_0" / "model.zip").read_bytes()
    assert (run / "seeds" / "seed_0" / "training.json").exists()
    assert train.main(["--resume", str(run), "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "continuing from" in printed and "training seed 0" not in printed  # the finished seed is kept
    assert (run / "seeds" / "seed_0" / "model.zip").read_bytes() == first
    assert (run / "COMPLETE").exists() and not (run / "INTERRUPTED").exists()
    # The resumed seed reaches the weights of an unbroken run of that seed.
    assert train.main([*TINY, "--seed", "1", "--out", str(tmp_path / "alone")]) == 0
    assert _same(run / "seeds" / "seed_1" / "model.zip", _only_run(tmp_path / "alone") / "model.zip")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--seeds", "0"], "--seeds must be >= 1, got 0"),
        (["--seeds", "2", "--eval-only", "--model", "x"], "--seeds 2 trains several seeds; not with --eval-only"),
        (["--seed", str(2**32 - 8), "--seeds", "2"], "must be below 2**32"),
        (["--algo", "dqn", "--seeds", "2", "--keep", "ensemble"], "--keep ensemble plays PPO's MLP policies"),
    ],
)
def test_seeds_out_of_reach_are_refused(argv, message, capsys):
    import train

    with pytest.raises(SystemExit) as exc:
        train.parse_args(argv)
    assert exc.value.code == 2
    assert message in capsys.readouterr().err
