"""The pretrained caregivers load by name and score what their cards say."""

from __future__ import annotations

import pytest

pytest.importorskip("stable_baselines3")

from agents.evaluate import evaluate
from agents.pretrained import pretrained_card, pretrained_members, pretrained_model_path, pretrained_names
from agents.rl import load_agent
from agents.tools.evaluate_cli import main

NAMES = pretrained_names()


def test_the_hard_level_models_ship():
    assert {"hard-ppo", "hard-ppo-switching", "hard-v2-ppo", "hard-v2-ppo-ensemble"} <= set(NAMES)
    for name in NAMES:
        card = pretrained_card(name)
        files = pretrained_members(name) or (pretrained_model_path(name),)
        assert card["name"] == name and all(f.is_file() for f in files)
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


def test_a_model_the_retired_jax_learner_saved_loads_as_sb3s_ppo_naming_its_framework():
    """``hard-v2-ppo`` was saved by ``JaxPPO`` (``framework`` "jax"): it loads as SB3's own PPO, its framework kept."""
    from stable_baselines3 import PPO

    from agents.rl import load_model

    model, info = load_model(pretrained_model_path("hard-v2-ppo"))
    assert type(model) is PPO and info["framework"] == "jax" and model.framework == "jax"


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


ENSEMBLE = "hard-v2-ppo-ensemble"


def test_the_default_train_py_caregiver_ships_as_its_seeds_played_as_one(capsys):
    import train
    from agents.rl.ensemble import EnsembleAgent
    from agents.trainer.train_args import seeds_of

    default_seeds = seeds_of(train.Args())  # what `python train.py --seed 0` keeps as one
    card = pretrained_card(ENSEMBLE)
    agent = load_agent(f"pretrained:{ENSEMBLE}")
    assert isinstance(agent, EnsembleAgent) and len(agent.members) == len(card["members"]) == default_seeds
    assert [m["seed"] for m in card["training"]["members"]] == card["training"]["seeds"] == list(range(default_seeds))
    assert main(["--model", f"pretrained:{ENSEMBLE}", "--episodes", "4", "--json"]) == 0
    assert f'"pretrained:{ENSEMBLE}"' in capsys.readouterr().out
    with pytest.raises(ValueError, match=r"is an ensemble, not one model zip"):
        pretrained_model_path(ENSEMBLE)


@pytest.fixture
def shipped_ensemble(tmp_path, monkeypatch):
    """The ensemble's card and members copied to a folder that stands in for agents/pretrained."""
    import shutil

    import agents.pretrained

    shutil.copyfile(agents.pretrained._folder() / f"{ENSEMBLE}.json", tmp_path / f"{ENSEMBLE}.json")
    shutil.copytree(agents.pretrained._folder() / ENSEMBLE, tmp_path / ENSEMBLE)
    monkeypatch.setattr(agents.pretrained, "_folder", lambda: tmp_path)
    return tmp_path


def test_a_missing_member_is_named(shipped_ensemble, capsys):
    member = f"{ENSEMBLE}/seed_2.zip"
    (shipped_ensemble / member).unlink()
    assert ENSEMBLE in pretrained_names()
    with pytest.raises(ValueError, match=rf"pretrained:{ENSEMBLE}: member '{member}' is missing"):
        load_agent(f"pretrained:{ENSEMBLE}")
    with pytest.raises(SystemExit) as exc:
        main(["--model", f"pretrained:{ENSEMBLE}", "--episodes", "2"])
    assert exc.value.code == 2 and f"member '{member}' is missing" in capsys.readouterr().err


def test_a_damaged_member_is_named(shipped_ensemble):
    member = shipped_ensemble / ENSEMBLE / "seed_1.zip"
    member.write_bytes(member.read_bytes()[:1000])
    with pytest.raises(ValueError, match=rf"member '{ENSEMBLE}/seed_1.zip' does not load \(could not load"):
        load_agent(f"pretrained:{ENSEMBLE}")


@pytest.mark.parametrize(
    ("members", "problem"),
    [
        (["hard-v2-ppo-ensemble/seed_0.zip"], "not a list of two or more"),
        (["../x.zip", "../y.zip"], "member '../x.zip' lies outside"),
    ],
)
def test_a_card_naming_too_few_members_or_files_outside_is_refused(shipped_ensemble, members, problem):
    import json

    card = shipped_ensemble / f"{ENSEMBLE}.json"
    card.write_text(json.dumps(json.loads(card.read_text()) | {"members": members}))
    with pytest.raises(ValueError, match=problem):
        load_agent(f"pretrained:{ENSEMBLE}")
