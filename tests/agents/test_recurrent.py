"""agents.ppo.recurrent: the LSTM resets, determinism, checkpoints, the sb3-contrib form, refusals."""

from __future__ import annotations

import itertools
import pickle
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("flax")

import jax

import coop_gym  # noqa: F401
from agents.hyperparams import hyperparams_for
from agents.ppo import PPOConfig
from agents.ppo.recurrent import NumpyLstmPolicy, RecurrentPPO, RecurrentPPOConfig

HARD = "CoopGym/SitToStandHard-v2"
TINY = RecurrentPPOConfig(n_envs=4, n_steps=32, batch_size=64, n_epochs=2)
WIDE = {"personas": "train_wide"}
ROOT = Path(__file__).resolve().parents[2]


def _leaves(tree: object) -> list[np.ndarray]:
    return [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(tree)]


def _same(a: object, b: object) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(_leaves(a), _leaves(b), strict=True))


def test_the_lstm_state_is_zeroed_where_an_episode_starts() -> None:
    learner = RecurrentPPO(HARD, TINY, seed=0, env_kwargs=WIDE)
    policy = NumpyLstmPolicy(learner.params, learner.nvec, "tanh")
    rng = np.random.default_rng(0)
    obs = rng.normal(size=(2, 11)).astype(np.float32)
    state = tuple(rng.normal(size=(2, 64)).astype(np.float32) for _ in range(4))
    zeros = tuple(np.zeros((2, 64), np.float32) for _ in range(4))
    logits, values, after = policy.step(obs, np.array([1.0, 0.0], np.float32), state)
    fresh_logits, fresh_values, fresh_after = policy.step(obs, np.ones(2, np.float32), zeros)
    np.testing.assert_array_equal(logits[0], fresh_logits[0])  # env 0 began an episode: its state did not count
    np.testing.assert_array_equal(values[0], fresh_values[0])
    assert all(np.array_equal(a[0], b[0]) for a, b in zip(after, fresh_after, strict=True))
    assert not np.allclose(logits[1], fresh_logits[1])  # env 1 carried its state


def test_the_update_sees_the_sequences_the_rollout_played() -> None:
    """The flax network over a rollout, from the states it began with: the NumPy rollout's values and log-probs."""
    from agents.ppo.networks import log_prob_entropy

    learner = RecurrentPPO(HARD, TINY.replace(n_steps=64), seed=1, env_kwargs=WIDE)
    learner.update(learner.rollout(), 1.0)
    rollout = learner.rollout()  # from the LSTM states the first one ended in
    assert rollout.starts[1:].sum() > 0 and float(np.abs(rollout.lstm_states[0]).sum()) > 0
    logits, values, _ = learner.network.apply(learner.acting_params, rollout.obs, rollout.starts, rollout.lstm_states)
    rows = lambda x: x.reshape(-1, *x.shape[2:])  # noqa: E731
    log_prob, _ = log_prob_entropy(logits, rows(rollout.actions), learner.nvec)
    np.testing.assert_allclose(np.asarray(values), rows(rollout.values), rtol=1e-4, atol=2e-5)
    np.testing.assert_allclose(np.asarray(log_prob), rows(rollout.log_probs), rtol=1e-4, atol=2e-5)


@pytest.mark.parametrize("lag", [0, 1])
def test_a_seed_trains_the_same_weights_and_a_checkpoint_continues_exactly(lag: int) -> None:
    config, saved = TINY.replace(policy_lag=lag), {}

    def keep(learner: RecurrentPPO) -> bool:
        if learner.num_timesteps == 256:
            saved["state"] = pickle.dumps(learner.state())
        return True

    first = RecurrentPPO(HARD, config, seed=3, env_kwargs=WIDE).learn(640, keep)
    again = RecurrentPPO(HARD, config, seed=3, env_kwargs=WIDE).learn(640)
    resumed = RecurrentPPO(HARD, config, seed=3, env_kwargs=WIDE)
    resumed.restore(pickle.loads(saved["state"]))
    assert float(np.abs(resumed.lstm_state[0]).sum()) > 0  # the envs' LSTM states came back
    resumed.learn(640)
    other = RecurrentPPO(HARD, config, seed=4, env_kwargs=WIDE).learn(640)
    assert _same(first.params, again.params)
    assert _same(first.params, resumed.params)
    assert not _same(first.params, other.params)


@pytest.mark.parametrize("recurrent", [False, True], ids=["ppo", "recurrent"])
def test_scoring_the_policy_between_rollouts_leaves_the_training_unchanged(recurrent: bool) -> None:
    """A run's work at its rollout ends (the policy as SB3's model, scored on episodes) changes no draw of training."""
    from agents.evaluate import evaluate
    from agents.ppo import PPO
    from agents.ppo.sb3_format import to_sb3
    from agents.rl.callbacks import _current_policy

    config = TINY if recurrent else PPOConfig(n_envs=4, n_steps=32, batch_size=64, n_epochs=2, policy_lag=0)
    cls = RecurrentPPO if recurrent else PPO
    scored = []

    def score(learner: PPO) -> bool:
        agent = _current_policy(to_sb3(learner, learner.acting_params), config.ALGO, HARD)
        scored.append(evaluate(agent, HARD, "train", 8, 2_000_000, n_envs=8).success_rate)
        return True

    hooked = cls(HARD, config, seed=6, env_kwargs=WIDE).learn(512, score)
    bare = cls(HARD, config, seed=6, env_kwargs=WIDE).learn(512)
    assert len(scored) == 4
    assert _same(hooked.params, bare.params)
    ours, theirs = hooked.take_episodes(), bare.take_episodes()
    assert len(ours["r"]) > 0 and all(np.array_equal(ours[k], theirs[k]) for k in ("r", "l", "outcome"))


def test_it_saves_as_sb3_contribs_recurrent_ppo_which_plays_its_weights(tmp_path: Path) -> None:
    import torch
    from sb3_contrib import RecurrentPPO as SB3RecurrentPPO

    from agents.evaluate import evaluate
    from agents.ppo.sb3_format import from_sb3, to_sb3
    from agents.rl import load_agent, load_model, save_agent

    learner = RecurrentPPO(HARD, TINY, seed=0, env_kwargs=WIDE).learn(256)
    path = save_agent(to_sb3(learner), tmp_path / "run", algo="recurrent_ppo", env_id=HARD)
    model, info = load_model(path)
    assert isinstance(model, SB3RecurrentPPO) and info["framework"] == "jax"
    obs = np.random.default_rng(4).normal(size=(12, 1, 11)).astype(np.float32)
    starts = np.zeros((12, 1), np.float32)
    starts[[0, 7]] = 1.0  # a second episode inside the sequence
    zeros = tuple(np.zeros((1, 64), np.float32) for _ in range(4))
    logits, values, _ = learner.network.apply(learner.params, obs, starts, zeros)
    state = (torch.zeros(1, 1, 64), torch.zeros(1, 1, 64))
    with torch.no_grad():
        seq, ep = torch.from_numpy(obs[:, 0]), torch.from_numpy(starts[:, 0])
        distribution, _ = model.policy.get_distribution(seq, state, ep)
        theirs = torch.cat([d.logits for d in distribution.distribution], 1).numpy()
        their_values = model.policy.predict_values(seq, state, ep).numpy()[:, 0]
    bounds = np.cumsum([0, *learner.nvec])
    ours = np.concatenate([np.asarray(jax.nn.log_softmax(logits[:, a:b])) for a, b in itertools.pairwise(bounds)], 1)
    np.testing.assert_allclose(ours, theirs, atol=1e-5)
    np.testing.assert_allclose(np.asarray(values), their_values, atol=1e-5)
    agent = load_agent(path)
    np.testing.assert_array_equal(agent.obs_normalizer(obs[:, 0]), learner.normalizer(obs[:, 0]))
    assert evaluate(agent, HARD, "test", 8, 0).episodes == 8
    back = RecurrentPPO(HARD, TINY, seed=9, env_kwargs=WIDE)
    from_sb3(back, model)
    assert _same(back.params, learner.params)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"n_steps": 32, "batch_size": 48, "n_envs": 3}, "batch_size \\(48\\) must be a multiple of n_steps \\(32\\)"),
        ({"lstm_hidden_size": 0}, "lstm_hidden_size must be a positive integer"),
        ({"batch_size": 100}, "RecurrentPPOConfig: n_envs \\* n_steps"),
        ({"policy_lag": 2}, "RecurrentPPOConfig.policy_lag"),
    ],
)
def test_settings_it_cannot_run_are_refused(changes: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        RecurrentPPOConfig(**changes)  # type: ignore[arg-type]


def test_the_settings_of_train_py_convert_and_others_are_refused_by_name() -> None:
    config = hyperparams_for("recurrent_ppo", HARD, "jax")
    ours = RecurrentPPOConfig.from_training(config)
    assert (ours.n_envs, ours.n_steps, ours.batch_size, ours.hidden, ours.lstm_hidden_size) == (16, 256, 512, (64,), 64)
    assert (ours.learning_rate, ours.anneal_lr, ours.ent_coef, ours.gamma, ours.policy_lag) == (3e-4, True, 0.02,
                                                                                               0.995, 0)  # fmt: skip
    shared = config.replace(policy_kwargs={**config.policy_kwargs, "shared_lstm": True})
    with pytest.raises(ValueError, match="shared_lstm"):
        RecurrentPPOConfig.from_training(shared)
    with pytest.raises(ValueError, match="target_kl"):
        RecurrentPPOConfig.from_training(config.replace(algo_kwargs={**config.algo_kwargs, "target_kl": 0.01}))
    with pytest.raises(ValueError, match="'ppo' settings"):
        RecurrentPPOConfig.from_training(hyperparams_for("ppo", HARD, "jax"))
    with pytest.raises(ValueError, match="needs a RecurrentPPOConfig"):
        RecurrentPPO(HARD, PPOConfig(), seed=0)  # type: ignore[arg-type]
