"""A score never lies silently: what a saved agent says about itself is checked against what it holds,
and a command given one thing twice, a flag its learner ignores or a closed pipe says so in one line.

The run folders' own cases (a missing model after training, a foreign checkpoint, a read-only folder)
are in tests/agents/test_interrupt.py, beside the other interrupted runs.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from agents.tools.evaluate_cli import main

ROOT = Path(__file__).resolve().parents[2]


def _usage_error(call, capsys: pytest.CaptureFixture[str]) -> str:
    """The one error line of ``call()``, which must exit with status 2 and print no result."""
    with pytest.raises(SystemExit) as exc:
        call()
    out, err = capsys.readouterr()
    assert exc.value.code == 2 and out == "" and "Traceback" not in err, err
    (line,) = [line for line in err.splitlines() if "error" in line]
    return line


def _rewrite_zip(source: Path, target: Path, drop: str = "", replace: dict[str, bytes] | None = None) -> None:
    """``source`` copied to ``target`` without the member ``drop`` and with ``replace``'s members replaced."""
    with zipfile.ZipFile(source) as old, zipfile.ZipFile(target, "w") as new:
        for item in old.infolist():
            if item.filename != drop:
                new.writestr(item, (replace or {}).get(item.filename, old.read(item.filename)))


@pytest.fixture
def shipped(tmp_path: Path) -> Path:
    """A normalised model folder as train.py leaves one: model.zip (the shipped hard-v2 PPO) and its files beside."""
    from agents.pretrained import pretrained_model_path

    folder = tmp_path / "run"
    folder.mkdir()
    model = folder / "model.zip"
    shutil.copyfile(pretrained_model_path("hard-v2-ppo"), model)
    with zipfile.ZipFile(model) as archive:
        info = json.loads(archive.read("coop_gym/agent.json"))
        (folder / "vecnormalize.pkl").write_bytes(archive.read("coop_gym/vecnormalize.pkl"))
    (folder / "agent.json").write_text(json.dumps(info | {"model": "model.zip", "vecnormalize": "vecnormalize.pkl"}))
    return folder


def test_a_normalised_model_without_its_normaliser_is_refused(shipped, tmp_path, capsys):
    from agents.rl import load_agent

    assert load_agent(shipped).obs_normalizer is not None  # whole, it loads with its statistics
    bare = tmp_path / "bare"
    bare.mkdir()
    _rewrite_zip(shipped / "model.zip", bare / "model.zip", drop="coop_gym/vecnormalize.pkl")
    shutil.copyfile(shipped / "agent.json", bare / "agent.json")  # says "normalized": true, as the bundle does
    with pytest.raises(ValueError, match=r"trained on normalised observations .* neither .* holds the statistics"):
        load_agent(bare)
    line = _usage_error(lambda: main(["--model", str(bare), "--episodes", "2"]), capsys)
    assert f"--model {bare}" in line and "normalised observations" in line
    (bare / "agent.json").unlink()  # the bundle's own metadata says the same
    assert "normalised observations" in _usage_error(lambda: main(["--model", str(bare), "--episodes", "2"]), capsys)


def test_a_bundle_whose_metadata_contradicts_its_model_is_refused(shipped, tmp_path):
    from agents.rl import load_agent

    with zipfile.ZipFile(shipped / "model.zip") as archive:
        info = json.loads(archive.read("coop_gym/agent.json"))
    lying = tmp_path / "lying.zip"
    claims = json.dumps(info | {"num_timesteps": 22_343_680}).encode()
    _rewrite_zip(shipped / "model.zip", lying, replace={"coop_gym/agent.json": claims})
    with pytest.raises(ValueError, match=r"its metadata says num_timesteps 22343680, but the model it holds has \d+"):
        load_agent(lying)


def test_compare_refuses_a_run_folder_and_its_model_as_two_rows(shipped, capsys):
    line = _usage_error(lambda: main(["--compare", f"{shipped},{shipped}/model.zip,blind", "--episodes", "2"]), capsys)
    assert f"'{shipped}' and '{shipped}/model.zip' are one model" in line and "list each agent once" in line


def _scored_run(folder: Path, seed: int, score: float) -> Path:
    """A finished run folder as train.py leaves it: results.json with its training seed and score, COMPLETE."""
    folder.mkdir(parents=True)
    results = {
        "algo": "ppo",
        "framework": "jax",
        "env_id": "CoopGym/SitToStandHard-v2",
        "seed": seed,
        "evaluation": {"personas": "test", "episodes": 1000, "seed": 0, "results": [{"mind_reading_score": score}]},
    }
    (folder / "results.json").write_text(json.dumps(results))
    (folder / "COMPLETE").write_text("")
    return folder


def test_runs_refuses_copies_of_one_training_seed(tmp_path, capsys):
    copies = [_scored_run(tmp_path / "out" / name, 0, 0.59) for name in ("a", "b", "c")]
    line = _usage_error(lambda: main(["--runs", *map(str, copies)]), capsys)
    assert "are one training seed (jax:ppo seed 0 on CoopGym/SitToStandHard-v2)" in line, line
    assert all(str(run) in line for run in copies) and "give each seed once" in line
    assert "one training seed" in _usage_error(lambda: main(["--runs", str(tmp_path / "out")]), capsys)
    seeds = [_scored_run(tmp_path / "seeds" / str(seed), seed, 0.5 + seed / 10) for seed in range(3)]
    assert main(["--runs", *map(str, seeds), "--json"]) == 0  # three seeds: an IQM over three runs
    assert json.loads(capsys.readouterr().out)["jax:ppo"]["runs"] == {"CoopGym/SitToStandHard-v2": 3}


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--baselines", "blind,blind,oracle"], "--baselines: 'blind' given twice; list each agent once"),
        (["--num-env-runners", "2"], "--num-env-runners is for --framework rllib; the jax learner trains"),
        (["--address", "ray://head:10001"], "--address is for --framework rllib; the jax learner trains"),
        (["--framework", "sb3", "--address", "auto"], "--address is for --framework rllib; the sb3 learner"),
        (["--timesteps", "99999999999999999999999"], "--timesteps must be <= 9223372036854775807"),
        (["--select-on", "validation", "--select-points", "0"], "--select-on validation needs --select-points >= 1"),
    ],
)
def test_train_refuses_what_its_run_would_ignore_or_never_reach(argv, message, capsys):
    import train

    line = _usage_error(lambda: train.parse_args(argv), capsys)
    assert message in line, line


def test_a_reader_that_closes_the_pipe_early_gets_no_traceback():
    """``python -m agents.evaluate --json | head -c 300``, with the reader gone before the first write."""
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "agents.evaluate", "--agent", "blind", "--episodes", "2", "--json"],
            stdout=write_end,
            stderr=subprocess.PIPE,
            text=True,
            cwd=ROOT,
            timeout=300,
        )
    finally:
        os.close(write_end)
    assert proc.returncode == 1 and proc.stderr == "", proc.stderr[-2000:]


def test_exit_status_passes_the_status_through():
    from coop_gym.cli import exit_status

    assert exit_status(lambda: 3) == 3 and exit_status(lambda: None) == 0
