"""Self-contained model bundles: a lone model.zip carries its normaliser and metadata; damaged files fail clearly."""

from __future__ import annotations

import json
import shutil
import zipfile

import numpy as np
import pytest
import torch

import coop_gym
from agents.evaluate import evaluate
from agents.hyperparams import hyperparams_for
from agents.rl import (
    AGENT_FILE,
    BUNDLE_INFO,
    BUNDLE_VECNORMALIZE,
    MODEL_FILE,
    VECNORMALIZE_FILE,
    load_agent,
    make_model,
    make_train_env,
    save_agent,
)

torch.set_num_threads(1)


@pytest.fixture(scope="module")
def saved(tmp_path_factory):
    """A tiny PPO run folder (normalised observations), saved the current way."""
    folder = tmp_path_factory.mktemp("agent")
    config = hyperparams_for("ppo", "CoopGym/SitToStand-v0")
    env = make_train_env(config.env_id, 2, 0, normalize=True, backend="dummy")
    model = make_model(config, env, 0, overrides={"n_steps": 32, "batch_size": 32, "n_epochs": 1})
    model.learn(64)
    save_agent(model, folder, algo="ppo", env_id=config.env_id)
    env.close()
    return folder


def test_the_zip_holds_metadata_and_normaliser(saved):
    with zipfile.ZipFile(saved / MODEL_FILE) as archive:
        info = json.loads(archive.read(BUNDLE_INFO))
        assert BUNDLE_VECNORMALIZE in archive.namelist()
    assert info["algo"] == "ppo" and info["env_id"] == "CoopGym/SitToStand-v0"
    assert info["coop_gym_version"] == coop_gym.__version__ and info["normalized"] is True
    assert len(info["features"]) == 11 and all(isinstance(f, str) for f in info["features"])
    assert not [p.name for p in saved.iterdir() if ".tmp-" in p.name]


def test_a_lone_copy_of_model_zip_loads_and_scores_the_same(saved, tmp_path):
    lone = tmp_path / "copied.zip"
    shutil.copy(saved / MODEL_FILE, lone)  # no agent.json, no vecnormalize.pkl beside it
    original, copy = load_agent(saved), load_agent(lone)
    assert copy.algo == "ppo" and copy.env_id == "CoopGym/SitToStand-v0" and copy.features == original.features
    assert copy.obs_normalizer is not None
    np.testing.assert_array_equal(copy.obs_normalizer.mean, original.obs_normalizer.mean)
    a = evaluate(original, "CoopGym/SitToStand-v0", "test", 6, 3, n_envs=6)
    b = evaluate(copy, "CoopGym/SitToStand-v0", "test", 6, 3, n_envs=6)
    assert [r.outcome for r in a.records] == [r.outcome for r in b.records]
    assert a.mean_return == b.mean_return


def test_an_old_run_folder_still_loads(saved, tmp_path):
    """Before bundles: a plain SB3 zip with vecnormalize.pkl and agent.json beside it."""
    old = tmp_path / "old_run"
    old.mkdir()
    with zipfile.ZipFile(saved / MODEL_FILE) as src, zipfile.ZipFile(old / MODEL_FILE, "w") as dst:
        for item in src.infolist():
            if not item.filename.startswith("coop_gym/"):
                dst.writestr(item, src.read(item.filename))
    shutil.copy(saved / VECNORMALIZE_FILE, old / VECNORMALIZE_FILE)
    info = json.loads((saved / AGENT_FILE).read_text())
    old_info = {k: info[k] for k in ("algo", "env_id", "num_timesteps")} | {
        "model": MODEL_FILE,
        "vecnormalize": VECNORMALIZE_FILE,
    }
    (old / AGENT_FILE).write_text(json.dumps(old_info))
    agent, current = load_agent(old), load_agent(saved)
    assert agent.algo == "ppo" and agent.features is None and agent.obs_normalizer is not None
    np.testing.assert_array_equal(agent.obs_normalizer.scale, current.obs_normalizer.scale)


def test_another_env_is_refused_naming_the_features(saved):
    agent = load_agent(saved)
    with pytest.raises(
        ValueError,
        match=r"11 observation features differ from CoopGym/SitToStandOracle-v0's 12: .* extra \['true_xi'\]",
    ):
        evaluate(agent, "CoopGym/SitToStandOracle-v0", "test", 2, 0)


@pytest.mark.parametrize(
    ("damage", "match"),
    [
        ("empty", r"model.zip: the file is empty"),
        ("truncated", r"model.zip: not a complete zip archive"),
        ("text", r"not a complete zip archive"),
        ("agent_json", r"agent.json: not valid JSON"),
        ("vecnormalize", r"vecnormalize.pkl: not a readable VecNormalize pickle"),
    ],
)
def test_damaged_files_raise_value_error_naming_the_file(saved, tmp_path, damage, match):
    folder = tmp_path / "run"
    shutil.copytree(saved, folder)
    model = folder / MODEL_FILE
    if damage in ("agent_json", "vecnormalize"):  # an old-style folder, whose side files are read
        with zipfile.ZipFile(saved / MODEL_FILE) as src, zipfile.ZipFile(model, "w") as dst:
            for item in src.infolist():
                if not item.filename.startswith("coop_gym/"):
                    dst.writestr(item, src.read(item.filename))
    if damage == "empty":
        model.write_bytes(b"")
    elif damage == "truncated":
        model.write_bytes((saved / MODEL_FILE).read_bytes()[:2000])
    elif damage == "text":
        model.write_text("hello")
    elif damage == "agent_json":
        (folder / AGENT_FILE).write_text("{not json")
    else:
        (folder / VECNORMALIZE_FILE).write_bytes(b"\x80\x04garbage")
    with pytest.raises(ValueError, match=match):
        load_agent(folder)


HARD = "CoopGym/SitToStandHard-v1"


def _tiny_model(folder, env_id):
    env = make_train_env(env_id, 2, 0, normalize=True, backend="dummy")
    small = {"n_steps": 32, "batch_size": 32, "n_epochs": 1}
    model = make_model(hyperparams_for("ppo", env_id), env, 0, overrides=small)
    model.learn(64)
    save_agent(model, folder, algo="ppo", env_id=env_id)
    env.close()
    return folder


def test_compare_without_env_plays_scripted_agents_on_the_models_env(tmp_path, capsys):
    # A hard-level model compared with the handbook: the handbook must play the hard level
    # too, not the default id (where it plays far better, which would hide the mix-up).
    from agents.tools.evaluate_cli import main

    folder = _tiny_model(tmp_path / "hard", HARD)
    assert main(["--compare", f"{folder / MODEL_FILE},handbook", "--episodes", "4", "--n-envs", "4", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    rows = rows["results"] if isinstance(rows, dict) else rows
    assert {r["env_id"] for r in rows} == {HARD}


def test_compare_of_models_of_different_envs_needs_env(saved, tmp_path, capsys):
    from agents.tools.evaluate_cli import main

    folder = _tiny_model(tmp_path / "hard", HARD)
    with pytest.raises(SystemExit) as exit_info:
        main(["--compare", f"{folder / MODEL_FILE},{saved / MODEL_FILE},handbook", "--episodes", "4"])
    assert exit_info.value.code == 2
    assert "trained on different envs" in capsys.readouterr().err


def _sb3_actions(agent, obs):
    """What SB3's own ``predict`` answers (the agent's greedy shortcut switched off)."""
    agent._greedy = (agent.model.policy, None)
    try:
        return agent.predict(obs, deterministic=True)[0]
    finally:
        agent._greedy = (None, None)


@pytest.mark.parametrize("name", ["pretrained:hard-v2-ppo", "pretrained:hard-ppo-switching", "discrete"])
def test_the_greedy_shortcut_acts_as_sb3s_predict_bit_for_bit(name, tmp_path):
    from agents.rl.bundle import GreedyActor

    if name == "discrete":  # a Discrete action space (the ids CleanRL's scripts take)
        env = make_train_env("CoopGym/SitToStandHardDiscreteUnit-v2", 2, 0)
        config = hyperparams_for("ppo", "CoopGym/SitToStandHardDiscreteUnit-v2").replace(normalize=False)
        model = make_model(config, env, 0, overrides={"n_steps": 32, "batch_size": 32, "n_epochs": 1})
        model.learn(64)
        save_agent(model, tmp_path, algo="ppo", env_id="CoopGym/SitToStandHardDiscreteUnit-v2")
        name = str(tmp_path)
    agent = load_agent(name)
    assert GreedyActor.of(agent.model.policy) is not None
    rng = np.random.default_rng(0)
    dim = agent.observation_space.shape[0]
    # Wide random observations (many near-ties between heads' logits) and one repeated row.
    obs = np.concatenate([rng.normal(0, 3, (20_000, dim)), np.ones((3, dim))]).astype(np.float32)
    fast, sb3 = agent.predict(obs, deterministic=True)[0], _sb3_actions(agent, obs)
    np.testing.assert_array_equal(fast, sb3)
    assert fast.dtype == sb3.dtype and fast.shape == sb3.shape
    # Whole evaluations: the same records.
    env_id = agent.env_id
    kwargs = agent.env_kwargs
    played = evaluate(agent, env_id, "test", 24, 5, env_kwargs=kwargs).records
    assert played == _evaluate_without_shortcut(agent, env_id, kwargs)


def _evaluate_without_shortcut(agent, env_id, kwargs):
    original = agent._greedy_actor
    agent._greedy_actor = lambda: None
    try:
        return evaluate(agent, env_id, "test", 24, 5, env_kwargs=kwargs).records
    finally:
        agent._greedy_actor = original


def test_the_greedy_shortcut_leaves_other_policies_to_sb3(saved):
    from agents.rl.bundle import GreedyActor

    env = make_train_env("CoopGym/SitToStandDiscrete-v0", 1, 0)
    dqn = make_model(hyperparams_for("dqn"), env, 0, overrides={"learning_starts": 0})
    assert GreedyActor.of(dqn.policy) is None  # a Q-network: SB3's predict
    agent = load_agent(saved)
    assert GreedyActor.of(agent.model.policy) is not None
    single = np.zeros(agent.observation_space.shape, dtype=np.float32)  # one observation: SB3's path
    assert agent.predict(single, deterministic=True)[0].shape == agent.action_space.shape
