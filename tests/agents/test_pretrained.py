"""The pretrained caregivers load by name and score what their cards say."""

from __future__ import annotations

import pytest

pytest.importorskip("stable_baselines3")

from agents.evaluate import evaluate
from agents.pretrained import pretrained_card, pretrained_model_path, pretrained_names
from agents.rl import load_agent
from agents.tools.evaluate_cli import main

NAMES = pretrained_names()


def test_the_hard_level_models_ship():
    assert {"hard-ppo", "hard-ppo-switching", "hard-v2-ppo"} <= set(NAMES)
    for name in NAMES:
        card = pretrained_card(name)
        assert card["name"] == name and pretrained_model_path(name).is_file()
        assert {"command", "seed", "timesteps", "wall_time_s"} <= set(card["training"])
        assert card["evaluation"]["personas"] == "test" and len(card["evaluation"]["table"]) >= 4


@pytest.mark.parametrize("name", NAMES)
def test_a_pretrained_model_loads_by_name_and_reproduces_its_card(name):
    card = pretrained_card(name)
    agent = load_agent(f"pretrained:{name}")
    assert agent.name == f"pretrained:{name}" and agent.env_id == card["env_id"]
    assert agent.env_kwargs == card["env_kwargs"] and list(agent.features) == card["features"]
    check, evaluation = card["check"], card["evaluation"]
    result = evaluate(
        agent,
        card["env_id"],
        evaluation["personas"],
        check["episodes"],
        evaluation["seed"],
        n_envs=evaluation["n_envs"],
        env_kwargs=card["env_kwargs"],
    )
    for outcome in ("success", "unsafe", "premature", "timeout"):
        assert result.count(outcome) == check[outcome], outcome
    assert result.mean_return == pytest.approx(check["mean_return"], rel=1e-9, abs=1e-12)
    # The card's table and its check agree on those episodes.
    assert check["same_as_the_evaluations_first_episodes"]


def test_an_unknown_name_lists_the_known_ones(capsys):
    with pytest.raises(ValueError, match=r"unknown pretrained model 'nope'; known: pretrained:hard-ppo"):
        load_agent("pretrained:nope")
    with pytest.raises(SystemExit) as exc:
        main(["--model", "pretrained:nope"])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and "unknown pretrained model 'pretrained:nope'" in err and "pretrained:hard-ppo" in err


def test_train_py_scores_a_pretrained_model_by_name(tmp_path):
    import json

    import train

    code = train.main(
        ["--eval-only", "--model", "pretrained:hard-ppo", "--eval-episodes", "4", "--baselines", "handbook",
         "--out", str(tmp_path), "--no-progress"]
    )  # fmt: skip
    assert code == 0
    (run_dir,) = tmp_path.iterdir()
    results = json.loads((run_dir / "results.json").read_text())
    assert [r["agent"] for r in results["evaluation"]["results"]][:2] == ["ppo (learned)", "handbook"]


def test_the_evaluate_command_sets_the_policys_torch_threads(capsys):
    """One thread by default (as train.py): evaluations side by side contend for the cores under torch's default."""
    import torch

    before = torch.get_num_threads()
    try:
        assert main(["--model", "pretrained:hard-v2-ppo", "--episodes", "4", "--threads", "2", "--json"]) == 0
        assert torch.get_num_threads() == 2
        assert main(["--model", "pretrained:hard-v2-ppo", "--episodes", "4", "--json"]) == 0
        assert torch.get_num_threads() == 1
    finally:
        torch.set_num_threads(before)
    capsys.readouterr()
