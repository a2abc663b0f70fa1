"""Learned agents: tiny learn() smoke runs, save/load round trips, hyperparameters and Zoo files."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

import coop_gym  # noqa: F401
from agents.evaluate import evaluate
from agents.hyperparams import (
    ALGORITHMS,
    DEFAULT_ENV_IDS,
    HYPERPARAMS,
    ZOO_ALGO_NAMES,
    TrainingConfig,
    hyperparams_for,
    zoo_yaml,
)
from agents.rl import (
    AGENT_FILE,
    MODEL_FILE,
    VECNORMALIZE_FILE,
    SB3Agent,
    algorithm_class,
    load_agent,
    make_model,
    make_train_env,
    save_agent,
)
from agents.rl.callbacks import _renamed

torch.set_num_threads(1)

# Small rollouts so learn(64) is quick; everything else is the real default config.
_TINY = {
    "ppo": {"n_steps": 32, "batch_size": 32, "n_epochs": 1},
    "recurrent_ppo": {"n_steps": 32, "batch_size": 32, "n_epochs": 1},
    "dqn": {"learning_starts": 16, "buffer_size": 1000, "batch_size": 16, "train_freq": 4},
}


def tiny_model(algo, seed=0, n_envs=2):
    config = hyperparams_for(algo)
    env = make_train_env(config.env_id, n_envs, seed, normalize=config.normalize, backend="dummy")
    return config, env, make_model(config, env, seed, overrides=_TINY[algo])


@pytest.mark.parametrize("algo", ALGORITHMS)
def test_learn_64_smoke_and_save_load_round_trip(algo, tmp_path):
    config, env, model = tiny_model(algo)
    model.learn(64)
    assert model.num_timesteps >= 64
    save_agent(model, tmp_path, algo=algo, env_id=config.env_id)
    assert (tmp_path / MODEL_FILE).exists() and (tmp_path / AGENT_FILE).exists()
    assert (tmp_path / VECNORMALIZE_FILE).exists() == config.normalize

    agent = load_agent(tmp_path)
    assert agent.algo == algo and agent.env_id == config.env_id
    live = SB3Agent(model, algo, config.env_id, agent.obs_normalizer)
    # Same observations -> identical deterministic actions, also through recurrent state.
    probe = gym.make(config.env_id)
    obs = np.stack([probe.reset(seed=s)[0] for s in range(3)])
    state_a = state_b = None
    starts = np.ones(3, dtype=bool)
    for _ in range(5):
        a, state_a = agent.predict(obs, state_a, starts, deterministic=True)
        b, state_b = live.predict(obs, state_b, starts, deterministic=True)
        assert np.array_equal(a, b)
        assert all(probe.action_space.contains(x) for x in a)
        starts = np.zeros(3, dtype=bool)
    env.close()


def test_saved_normalisation_is_applied(tmp_path):
    config, env, model = tiny_model("ppo")
    model.learn(64)
    save_agent(model, tmp_path, algo="ppo", env_id=config.env_id)
    agent = load_agent(tmp_path / MODEL_FILE)
    vec_normalize = env  # make_train_env puts VecNormalize outermost
    obs = np.stack([gym.make(config.env_id).reset(seed=s)[0] for s in range(4)])
    assert np.allclose(agent.normalize(obs), vec_normalize.normalize_obs(obs), atol=1e-6)
    assert agent.normalize(obs[0]).shape == obs[0].shape
    env.close()


def test_recurrent_agent_evaluates_with_its_lstm_state(tmp_path):
    config, env, model = tiny_model("recurrent_ppo")
    model.learn(64)
    save_agent(model, tmp_path, algo="recurrent_ppo", env_id=config.env_id)
    agent = load_agent(tmp_path)
    a = evaluate(agent, config.env_id, "test", episodes=4, seed=0, n_envs=2)
    b = evaluate(agent, config.env_id, "test", episodes=4, seed=0, n_envs=2)
    assert a.records == b.records and a.episodes == 4
    env.close()


def test_load_agent_errors(tmp_path):
    with pytest.raises(FileNotFoundError):
        load_agent(tmp_path / "nothing.zip")
    bad = tmp_path / "model.zip"
    bad.write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="could not load"):
        load_agent(bad)


def test_hyperparams_are_consistent():
    for algo in ALGORITHMS:
        config = hyperparams_for(algo)
        assert config.env_id == DEFAULT_ENV_IDS[algo] and config.env_id in gym.registry
        for env_id, cfg in HYPERPARAMS[algo].items():
            assert env_id in gym.registry and cfg.algo == algo
            assert cfg.personas in ("train", "train_wide")  # never a held-out persona
    other = hyperparams_for("ppo", "CoopGym/SitToStandMM-v0")
    assert other.env_id == "CoopGym/SitToStandMM-v0" and other.algo_kwargs == hyperparams_for("ppo").algo_kwargs
    with pytest.raises(ValueError, match="unknown algorithm"):
        hyperparams_for("a2c")
    with pytest.raises(ValueError, match="n_envs"):
        TrainingConfig("ppo", "CoopGym/SitToStand-v0", 0, 10, "MlpPolicy", False)
    with pytest.raises(ValueError, match=r"must not include held-out personas.*frail"):
        TrainingConfig("ppo", "CoopGym/SitToStand-v0", 8, 10, "MlpPolicy", False, personas=["typical", "frail"])
    lagged = hyperparams_for("ppo", "CoopGym/SitToStandHard-v2", "jax")
    assert lagged.algo_kwargs["policy_lag"] == 1
    with pytest.raises(ValueError, match=r"policy_lag is agents.ppo's \(framework='jax'\); framework='sb3'"):
        lagged.replace(framework="sb3")


def test_zoo_files_are_generated_from_hyperparams():
    import yaml

    folder = Path(__file__).resolve().parents[2] / "agents" / "zoo"
    for algo in ALGORITHMS:
        path = folder / f"{ZOO_ALGO_NAMES[algo]}.yml"
        assert path.read_text() == zoo_yaml(algo), f"{path} is stale: run agents.hyperparams.write_zoo_files()"
        loaded = yaml.safe_load(path.read_text())
        config = hyperparams_for(algo)
        entry = loaded[config.env_id]
        assert entry["n_envs"] == config.n_envs and entry["policy"] == config.policy
        assert entry["env_kwargs"] == {"personas": config.personas}
        for key, value in config.algo_kwargs.items():
            assert entry[key] == value


def test_tensorboard_keys_follow_cleanrl():
    assert _renamed("rollout/ep_rew_mean") == "charts/episodic_return"
    assert _renamed("train/value_loss") == "losses/value_loss"
    assert _renamed("time/fps") == "charts/SPS"
    assert _renamed("time/iterations") is None
    assert _renamed("eval/success_rate") == "eval/success_rate"


def test_make_train_env_validates():
    with pytest.raises(ValueError, match="n_envs"):
        make_train_env("CoopGym/SitToStand-v0", 0, 0)
    with pytest.raises(ValueError, match="backend"):
        make_train_env("CoopGym/SitToStand-v0", 1, 0, backend="subproc")


def test_algorithm_is_read_from_a_bare_zip(tmp_path):
    """Without agent.json (e.g. an RL Zoo run) the algorithm comes from the saved policy class."""
    for algo in ("recurrent_ppo", "dqn"):
        _, env, model = tiny_model(algo)
        model.save(tmp_path / f"{algo}.zip")
        agent = load_agent(tmp_path / f"{algo}.zip")
        assert agent.algo == algo and type(agent.model) is type(model) and agent.env_id is None
        env.close()


def test_selection_saves_the_best_validated_policy(tmp_path, monkeypatch):
    """The policy that scored best on validation is loaded back (weights, statistics, steps); ties go later."""
    import agents.evaluate as evaluate_module
    from agents.rl import SelectionCallback, read_bundle
    from agents.rl.callbacks import VALIDATION_PERSONAS, VALIDATION_SEED

    scores = iter([0.5, 0.9, 0.9, 0.4, 0.6])  # four points during training, then the final policy
    calls = []

    class Result:
        def __init__(self, personas, seed):
            calls.append((personas, seed))
            self.success_rate = next(scores)

    monkeypatch.setattr(
        evaluate_module, "evaluate", lambda agent, env_id, personas, n, seed, **kw: Result(personas, seed)
    )
    config, env, model = tiny_model("ppo")
    selection = SelectionCallback(tmp_path, "ppo", config.env_id, episodes=8, points=4, start=64, every=64)
    model.learn(64 * 6, callback=selection)
    assert [p["success_rate"] for p in selection.history] == [0.5, 0.9, 0.9, 0.4]
    kept = selection.history[2]  # 0.9 twice: the later one
    saved_weights = {k: v.clone() for k, v in model.policy.state_dict().items()}
    selected = selection.finish(model)
    assert calls == [(VALIDATION_PERSONAS, VALIDATION_SEED)] * 5  # the training personas, never "test"
    assert selected["timesteps"] == kept["timesteps"] < selected["final_timesteps"]
    assert model.num_timesteps == kept["timesteps"]
    _, stats = read_bundle(selection.saved_path(kept["timesteps"]))
    assert np.array_equal(env.obs_rms.mean, stats.obs_rms.mean)
    loaded = model.policy.state_dict()
    assert any(not torch.equal(loaded[k], saved_weights[k]) for k in loaded)  # the final weights were replaced
    best = algorithm_class("ppo").load(selection.saved_path(kept["timesteps"]), device="cpu").policy.state_dict()
    assert all(torch.equal(loaded[k], best[k]) for k in loaded)
    env.close()


def test_selection_on_the_validation_people_records_other_sets_without_selecting_on_them(tmp_path, monkeypatch):
    """``personas="validation"`` selects on the validation people; ``recorded`` sets are played and only recorded."""
    import agents.evaluate as evaluate_module
    from agents.rl import SelectionCallback
    from agents.rl.callbacks import VALIDATION_SEED

    rates = {"validation": iter([0.2, 0.7, 0.3]), "test": iter([0.9, 0.1, 0.95])}
    calls = []

    class Result:
        def __init__(self, personas, episodes, seed):
            calls.append((personas, episodes, seed))
            self.success_rate, self.unsafe_rate = next(rates[personas]), 0.0

    monkeypatch.setattr(
        evaluate_module, "evaluate", lambda agent, env_id, personas, n, seed, **kw: Result(personas, n, seed)
    )
    config, env, model = tiny_model("ppo")
    recorded = {"test": ("test", 4, 0)}
    selection = SelectionCallback(
        tmp_path, "ppo", config.env_id, 8, 2, 64, 64, personas="validation", recorded=recorded
    )
    model.learn(64 * 4, callback=selection)
    selected = selection.finish(model)
    assert calls == [("validation", 8, VALIDATION_SEED), ("test", 4, 0)] * 3
    assert selected["personas"] == "validation"
    assert selected["validation_success_rate"] == 0.7  # the test people's 0.95 never selects
    assert [p["test"]["success_rate"] for p in selected["scores"]] == [0.9, 0.1, 0.95]
    with pytest.raises(ValueError, match=r"SelectionCallback.personas must be one of \['train', 'validation'\]"):
        SelectionCallback(tmp_path, "ppo", config.env_id, 8, 2, 64, 64, personas="test")
    env.close()


_SAME_SEED_RUN = """
import sys, hashlib, torch
torch.set_num_threads(int(sys.argv[1]))
from stable_baselines3.common.vec_env import VecNormalize
from agents.hyperparams import hyperparams_for
from agents.rl import make_model, make_train_env
config = hyperparams_for("ppo")
env = VecNormalize(make_train_env(config.env_id, 8, 3, personas=config.personas), norm_obs=True, norm_reward=False)
model = make_model(config, env, 3, overrides={"n_steps": 64, "batch_size": 128, "n_epochs": 2})
model.learn(1024)
digest = hashlib.sha256()
for tensor in model.policy.state_dict().values():
    digest.update(tensor.numpy().tobytes())
digest.update(env.obs_rms.mean.tobytes())
print(digest.hexdigest())
"""


def test_a_seed_trains_the_same_weights_in_two_fresh_processes() -> None:
    """train.py's PPO on the hard level, 1024 steps twice in fresh processes on one torch thread: the same weights.

    One thread is train.py's default (``--threads``): torch's multi-threaded reductions add in
    another order, so another thread count trains other weights (docs/agents.md, "Reproducibility").
    """
    import subprocess
    import sys

    root = Path(__file__).resolve().parents[2]
    digests = [
        subprocess.run(
            [sys.executable, "-c", _SAME_SEED_RUN, "1"], cwd=root, capture_output=True, text=True, check=True
        ).stdout.strip()
        for _ in range(2)
    ]
    assert len(digests[0]) == 64 and digests[0] == digests[1], digests
