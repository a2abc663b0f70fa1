"""agents.ppo: the learner's pieces against references, its determinism, its checkpoints, its SB3 form."""

from __future__ import annotations

import pickle
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("jax")
pytest.importorskip("flax")

import itertools

import jax

import coop_gym  # noqa: F401
from agents.ppo import PPO, PPOConfig
from agents.ppo.ppo import NumpyPolicy, ObsNormalizer, Rollout, advantages

HARD = "CoopGym/SitToStandHard-v2"
TINY = PPOConfig(n_envs=4, n_steps=64, batch_size=128, n_epochs=2)
WIDE = {"personas": "train_wide"}


def _leaves(tree: object) -> list[np.ndarray]:
    return [np.asarray(leaf) for leaf in jax.tree_util.tree_leaves(tree)]


def _same(a: object, b: object) -> bool:
    return all(np.array_equal(x, y) for x, y in zip(_leaves(a), _leaves(b), strict=True))


def test_the_advantages_are_sb3s_gae() -> None:
    from gymnasium import spaces
    from stable_baselines3.common.buffers import RolloutBuffer

    rng = np.random.default_rng(0)
    n_steps, n_envs, gamma, lam = 16, 3, 0.99, 0.9
    rollout = Rollout(
        obs=np.zeros((n_steps, n_envs, 1), np.float32),
        actions=np.zeros((n_steps, n_envs, 1), np.int64),
        log_probs=np.zeros((n_steps, n_envs), np.float32),
        values=rng.normal(size=(n_steps, n_envs)).astype(np.float32),
        rewards=rng.normal(size=(n_steps, n_envs)).astype(np.float32),
        starts=(rng.random((n_steps, n_envs)) < 0.2).astype(np.float32),
        last_values=rng.normal(size=n_envs).astype(np.float32),
        last_starts=np.array([1.0, 0.0, 0.0], np.float32),
    )
    import torch

    space = spaces.Box(-1, 1, (1,))
    buffer = RolloutBuffer(n_steps, space, spaces.Discrete(2), "cpu", gae_lambda=lam, gamma=gamma, n_envs=n_envs)
    for t in range(n_steps):
        values = torch.from_numpy(rollout.values[t])
        buffer.add(rollout.obs[t], np.zeros((n_envs, 1)), rollout.rewards[t], rollout.starts[t], values, values * 0)
    buffer.compute_returns_and_advantage(torch.from_numpy(rollout.last_values), rollout.last_starts)
    adv, returns = advantages(rollout, gamma, lam)
    np.testing.assert_allclose(adv, buffer.advantages, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(returns, buffer.returns, rtol=1e-5, atol=1e-5)


def test_the_normalizer_is_sb3s_running_mean_std() -> None:
    from stable_baselines3.common.running_mean_std import RunningMeanStd

    rng = np.random.default_rng(1)
    ours, theirs = ObsNormalizer((3,)), RunningMeanStd(shape=(3,))
    for _ in range(50):
        batch = (rng.normal(size=(16, 3)) * [1.0, 50.0, 0.01] + [0.0, 100.0, -3.0]).astype(np.float32)
        ours.update(batch)
        theirs.update(batch)
    np.testing.assert_allclose(ours.mean, theirs.mean, rtol=1e-5)  # SB3 takes a float32 batch mean
    np.testing.assert_allclose(ours.var, theirs.var, rtol=1e-5)
    obs = rng.normal(size=(5, 3)).astype(np.float32) * 100
    expected = np.clip((obs - theirs.mean) / np.sqrt(theirs.var + 1e-8), -10, 10)
    np.testing.assert_allclose(ours(obs), expected, rtol=1e-5, atol=1e-6)


def test_the_numpy_policy_samples_the_networks_distribution() -> None:
    learner = PPO(HARD, TINY, seed=0, env_kwargs=WIDE)
    obs = np.random.default_rng(2).normal(size=(1, 11)).astype(np.float32)
    logits, value = learner.network.apply(learner.params, obs)
    bounds = np.cumsum([0, *learner.nvec])
    probs = [np.asarray(jax.nn.softmax(logits[0, lo:hi])) for lo, hi in itertools.pairwise(bounds)]
    policy, rng = NumpyPolicy(learner.params, learner.nvec, "tanh"), np.random.default_rng(3)
    draws = np.stack([policy.act(np.repeat(obs, 4000, axis=0), rng)[0] for _ in range(5)]).reshape(-1, 3)
    for head, p in enumerate(probs):
        frequencies = np.bincount(draws[:, head], minlength=len(p)) / len(draws)
        np.testing.assert_allclose(frequencies, p, atol=0.01)
    actions, log_prob, values = policy.act(obs, rng)
    expected = sum(np.log(p[a]) for p, a in zip(probs, actions[0], strict=True))
    np.testing.assert_allclose(log_prob[0], expected, rtol=1e-5)
    np.testing.assert_allclose(values, np.asarray(value), rtol=1e-5)


@pytest.mark.parametrize("lag", [0, 1])
def test_a_seed_trains_the_same_weights_and_a_checkpoint_continues_exactly(lag: int) -> None:
    config, saved = TINY.replace(policy_lag=lag), {}

    def keep(learner: PPO) -> bool:
        if learner.num_timesteps == 512:
            saved["state"] = pickle.dumps(learner.state())
        return True

    first = PPO(HARD, config, seed=3, env_kwargs=WIDE).learn(1280, keep)
    again = PPO(HARD, config, seed=3, env_kwargs=WIDE).learn(1280)
    resumed = PPO(HARD, config, seed=3, env_kwargs=WIDE)
    resumed.restore(pickle.loads(saved["state"]))
    resumed.learn(1280)
    other = PPO(HARD, config, seed=4, env_kwargs=WIDE).learn(1280)
    assert _same(first.params, again.params)
    assert _same(first.params, resumed.params)
    assert not _same(first.params, other.params)


@pytest.mark.parametrize("recurrent", [False, True], ids=["ppo", "recurrent"])
def test_a_seed_trains_the_same_weights_in_another_process_at_another_thread_count(recurrent: bool) -> None:
    import hashlib
    import os

    from agents.ppo.recurrent import RecurrentPPO, RecurrentPPOConfig

    if recurrent:
        cls, config, steps = RecurrentPPO, RecurrentPPOConfig(n_envs=4, n_steps=32, batch_size=64, n_epochs=2), 384
    else:
        cls, config, steps = PPO, TINY, 768
    code = (
        "import hashlib, numpy as np, jax, coop_gym\n"
        "from agents.ppo import PPO, PPOConfig\n"
        "from agents.ppo.recurrent import RecurrentPPO, RecurrentPPOConfig\n"
        f"l = {cls.__name__}('{HARD}', {config!r}, seed=5, env_kwargs={WIDE!r}).learn({steps})\n"
        "leaves = [np.asarray(x) for x in jax.tree_util.tree_leaves(l.params)]\n"
        "print(hashlib.sha256(b''.join(x.tobytes() for x in leaves)).hexdigest())\n"
    )
    here = cls(HARD, config, seed=5, env_kwargs=WIDE).learn(steps)
    mine = hashlib.sha256(b"".join(x.tobytes() for x in _leaves(here.params))).hexdigest()
    for threads in ("1", "2"):
        env = {**os.environ, "OMP_NUM_THREADS": threads}
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, check=True, env=env, text=True)
        assert out.stdout.split()[-1] == mine


def test_the_sb3_model_plays_the_learners_weights_and_saves_as_a_bundle(tmp_path: object) -> None:
    import torch

    from agents.evaluate import evaluate
    from agents.ppo.sb3_format import to_sb3
    from agents.rl import load_agent, save_agent

    learner = PPO(HARD, TINY, seed=0, env_kwargs=WIDE).learn(512)
    model = to_sb3(learner)
    obs = np.random.default_rng(4).normal(size=(6, 11)).astype(np.float32)
    logits, value = learner.network.apply(learner.params, obs)
    with torch.no_grad():
        distribution = model.policy.get_distribution(torch.from_numpy(obs))
        theirs = torch.cat([d.logits for d in distribution.distribution], 1).numpy()
        values = model.policy.predict_values(torch.from_numpy(obs)).numpy()[:, 0]
    bounds = np.cumsum([0, *learner.nvec])
    ours = np.concatenate(
        [np.asarray(jax.nn.log_softmax(logits[:, lo:hi])) for lo, hi in itertools.pairwise(bounds)], 1
    )
    np.testing.assert_allclose(ours, theirs, atol=1e-5)
    np.testing.assert_allclose(np.asarray(value), values, atol=1e-5)
    assert model.num_timesteps == learner.num_timesteps
    stats = model.get_env()
    np.testing.assert_array_equal(stats.obs_rms.mean, learner.normalizer.mean)
    agent = load_agent(save_agent(model, tmp_path, algo="ppo", env_id=HARD))
    np.testing.assert_array_equal(agent.obs_normalizer(obs), learner.normalizer(obs))
    assert evaluate(agent, HARD, "test", 8, 0).episodes == 8


def test_the_episodes_are_kept_with_their_outcomes() -> None:
    learner = PPO(HARD, TINY, seed=0, env_kwargs=WIDE).learn(512)
    episodes = learner.take_episodes()
    assert len(episodes["r"]) > 0 and set(episodes) == {"r", "l", "t", "outcome"}
    assert set(episodes["outcome"].tolist()) <= {1, 2, 3, 4}  # success, unsafe, premature, timeout
    assert (episodes["l"] >= 1).all()
    assert learner.take_episodes()["r"].size == 0  # taken once


def test_it_learns_a_gymnasium_env_without_a_native_vector_env() -> None:
    config = PPOConfig(n_envs=8, n_steps=128, batch_size=256, n_epochs=4, gamma=0.99, ent_coef=0.0,
                       learning_rate=1e-3, policy_lag=0)  # fmt: skip
    learner = PPO("CartPole-v1", config, seed=0).learn(1024)
    before = learner.take_episodes()["l"].mean()
    learner.learn(30720)
    after = learner.take_episodes()["l"][-20:].mean()
    assert before < 40 and after > 100, (before, after)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"batch_size": 100}, "multiple of batch_size"),
        ({"policy_lag": 2}, "policy_lag"),
        ({"activation": "gelu"}, "activation"),
        ({"n_envs": 0}, "n_envs must be a positive integer"),
        ({"batch_size": 0}, "batch_size must be a positive integer"),
        ({"hidden": ()}, "hidden must be positive layer widths"),
        ({"hidden": (64, -1)}, "hidden must be positive layer widths"),
    ],
)
def test_settings_it_cannot_run_are_refused(changes: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PPOConfig(**changes)  # type: ignore[arg-type]


def test_the_settings_of_train_py_convert_and_others_are_refused() -> None:
    from agents.hyperparams import hyperparams_for

    config = hyperparams_for("ppo", HARD, "jax")
    ours = PPOConfig.from_training(config)
    assert (ours.n_envs, ours.n_steps, ours.batch_size, ours.learning_rate, ours.anneal_lr) == (
        16,
        256,
        512,
        3e-4,
        True,
    )
    assert (ours.ent_coef, ours.gamma, ours.policy_lag, ours.hidden) == (0.02, 0.995, 1, (64, 64))
    with pytest.raises(ValueError, match="target_kl"):
        PPOConfig.from_training(config.replace(algo_kwargs={**config.algo_kwargs, "target_kl": 0.01}))
