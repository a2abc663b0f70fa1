"""A trained :class:`~agents.ppo.ppo.PPO` as Stable-Baselines3's PPO, through SB3's public API.

:func:`to_sb3` builds SB3's ``PPO("MlpPolicy", ...)`` with the learner's settings and network
(a :class:`~agents.ppo.recurrent.RecurrentPPO`: sb3-contrib's ``RecurrentPPO("MlpLstmPolicy", ...)``),
loads the flax weights into its torch policy (``policy.load_state_dict``) and its observation
statistics into a ``VecNormalize``; the package's bundle (:func:`agents.rl.save_model_bundle`)
then saves the two as any SB3 model, so a learner's ``model.zip`` loads, plays and scores
without JAX. :func:`from_sb3` reads the weights back into a learner.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import torch
from sb3_contrib import RecurrentPPO as SB3RecurrentPPO
from stable_baselines3 import PPO as SB3PPO
from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

from agents.ppo.ppo import PPO
from agents.ppo.recurrent import RecurrentPPO

__all__ = ["from_sb3", "sb3_class", "sb3_state_dict", "to_sb3"]

_NETS = {"pi": ("mlp_extractor.policy_net", "action_net"), "vf": ("mlp_extractor.value_net", "value_net")}
_LSTMS = {"lstm_pi": "lstm_actor", "lstm_vf": "lstm_critic"}
"""sb3-contrib's name of each LSTM; its one layer's weights are ``<name>.<weight>_l0``, as flax's."""


def _layer_names(net: dict[str, Any]) -> list[str]:
    return sorted(net, key=lambda name: int(name.split("_")[1]))


def sb3_state_dict(params: Any) -> dict[str, torch.Tensor]:
    """The flax weights as SB3's ``MlpPolicy`` state dict (``Linear`` weights are ``W^T``), or ``MlpLstmPolicy``'s."""
    state = {}
    for net, name in _LSTMS.items():
        for weight, value in params["params"].get(net, {}).items():
            state[f"{name}.{weight}_l0"] = torch.from_numpy(np.array(value).copy())
    for net, (hidden, head) in _NETS.items():
        layers = params["params"][net]
        names = _layer_names(layers)
        targets = [f"{hidden}.{2 * i}" for i in range(len(names) - 1)] + [head]
        for name, target in zip(names, targets, strict=True):
            state[f"{target}.weight"] = torch.from_numpy(np.array(layers[name]["kernel"]).T.copy())
            state[f"{target}.bias"] = torch.from_numpy(np.array(layers[name]["bias"]).copy())
    return state


def sb3_class(learner: PPO) -> type[SB3PPO] | type[SB3RecurrentPPO]:
    """The SB3 class a learner saves as: SB3's PPO, or sb3-contrib's RecurrentPPO for a recurrent one."""
    return SB3RecurrentPPO if isinstance(learner, RecurrentPPO) else SB3PPO


def to_sb3(learner: PPO, params: Any = None) -> Any:
    """SB3's PPO (or RecurrentPPO) playing the learner's weights (or ``params``), with its observation statistics.

    The model's env is ``n_envs`` envs of the learner's id and kwargs, inside a ``VecNormalize``
    holding the learner's statistics (not updating them) when it normalises observations;
    ``num_timesteps`` is the learner's. The model logs nowhere; its ``framework`` is ``"jax"``, the
    ``train.py --framework`` that trains this learner (what a saved ``agent.json`` records).
    """
    from stable_baselines3.common.logger import Logger

    cfg = learner.config
    env: Any = DummyVecEnv([lambda: gym.make(learner.env_id, **learner.env_kwargs)] * cfg.n_envs)
    if learner.normalizer is not None:
        env = VecNormalize(env, training=False, norm_obs=True, norm_reward=False, clip_obs=learner.normalizer.clip)
        env.obs_rms.mean = learner.normalizer.mean.copy()
        env.obs_rms.var = learner.normalizer.var.copy()
        env.obs_rms.count = float(learner.normalizer.count)
    activation = {"tanh": torch.nn.Tanh, "relu": torch.nn.ReLU}[cfg.activation]
    policy_kwargs: dict[str, Any] = {"net_arch": list(cfg.hidden), "activation_fn": activation}
    if isinstance(learner, RecurrentPPO):
        policy_kwargs["lstm_hidden_size"] = learner.config.lstm_hidden_size
    model = sb3_class(learner)(
        "MlpLstmPolicy" if isinstance(learner, RecurrentPPO) else "MlpPolicy",
        env,
        n_steps=cfg.n_steps,
        batch_size=cfg.batch_size,
        n_epochs=cfg.n_epochs,
        learning_rate=cfg.learning_rate,
        gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda,
        clip_range=cfg.clip_range,
        ent_coef=cfg.ent_coef,
        vf_coef=cfg.vf_coef,
        max_grad_norm=cfg.max_grad_norm,
        policy_kwargs=policy_kwargs,
        seed=learner.seed,
        device="cpu",
    )
    model.policy.load_state_dict(sb3_state_dict(learner.params if params is None else params), strict=True)
    model.num_timesteps = learner.num_timesteps
    model.set_logger(Logger(None, []))
    model.framework = "jax"  # type: ignore[union-attr]  # what agent.json records: train.py --framework jax
    return model


def from_sb3(learner: PPO, model: Any) -> None:
    """Load an SB3 PPO's (a recurrent learner: RecurrentPPO's) weights, same network, into ``learner``'s params."""
    import jax

    state = model.policy.state_dict()
    params = jax.tree_util.tree_map(np.asarray, learner.params)
    for net, (hidden, head) in _NETS.items():
        layers = params["params"][net]
        names = _layer_names(layers)
        targets = [f"{hidden}.{2 * i}" for i in range(len(names) - 1)] + [head]
        for name, target in zip(names, targets, strict=True):
            layers[name]["kernel"] = state[f"{target}.weight"].numpy().T.copy()
            layers[name]["bias"] = state[f"{target}.bias"].numpy().copy()
    for net, name in _LSTMS.items():
        for weight in params["params"].get(net, {}):
            params["params"][net][weight] = state[f"{name}.{weight}_l0"].numpy().copy()
    learner.set_params(params)
