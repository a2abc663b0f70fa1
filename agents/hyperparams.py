r"""Default training hyperparameters, per algorithm and env id -- the one place they live.

``train.py`` and :mod:`agents.rl` read :data:`HYPERPARAMS`; the RL Zoo files in
``agents/zoo/*.yml`` are generated from it (:func:`zoo_yaml`, checked by a test), so::

    python -m rl_zoo3.train --algo ppo --env CoopGym/SitToStand-v0 --gym-packages coop_gym \\
        -conf agents/zoo/ppo.yml --num-threads 1

trains with the same settings (one torch thread, as ``train.py --threads`` defaults to).
Nothing here imports torch or SB3.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from coop_gym.cli import SEED_LIMIT
from coop_gym.io import write_text
from coop_gym.model.personas import TEST_PERSONAS, resolve_personas
from coop_gym.registration import HARD_ENV_ID
from estimator.validate import check_integer

__all__ = [
    "ALGORITHMS",
    "DEFAULT_ENV_IDS",
    "FRAMEWORKS",
    "HYPERPARAMS",
    "JAX_ALGORITHMS",
    "JAX_POLICY_LAG",
    "JAX_SIZING",
    "ZOO_ALGO_NAMES",
    "TrainingConfig",
    "hyperparams_for",
    "write_zoo_files",
    "zoo_yaml",
]

ALGORITHMS: tuple[str, ...] = ("ppo", "recurrent_ppo", "dqn")
"""Algorithms ``train.py`` offers: SB3 PPO, sb3-contrib RecurrentPPO, SB3 DQN."""

FRAMEWORKS: tuple[str, ...] = ("sb3", "jax")
"""Learners that train in this process: SB3 itself, or JAX (PPO: :class:`agents.ppo.PPO`; RecurrentPPO:
:class:`agents.ppo.recurrent.RecurrentPPO`)."""

JAX_ALGORITHMS: tuple[str, ...] = ("ppo", "recurrent_ppo")
"""Algorithms ``framework="jax"`` trains."""

DEFAULT_ENV_IDS: dict[str, str] = {
    # The hard level: where reading the mind decides the outcome (coop_gym/model/difficulty.py).
    "ppo": HARD_ENV_ID,
    # Measurements only: the policy must remember the cue responses itself (an LSTM).
    "recurrent_ppo": "CoopGym/SitToStandRaw-v0",
    # DQN needs a flat Discrete action space.
    "dqn": "CoopGym/SitToStandDiscrete-v0",
}
"""The env each algorithm is meant for."""

ZOO_ALGO_NAMES: dict[str, str] = {"ppo": "ppo", "recurrent_ppo": "ppo_lstm", "dqn": "dqn"}
"""RL Zoo's ``--algo`` name of each algorithm."""


@dataclass(frozen=True)
class TrainingConfig:
    """Everything needed to build and train one agent.

    Attributes:
        algo: One of :data:`ALGORITHMS`.
        env_id: Registered env id the settings were tuned for.
        n_envs: Parallel training envs.
        total_timesteps: Default training budget [env steps].
        policy: SB3 policy name.
        normalize: Normalise observations with ``VecNormalize`` (running mean/std; rewards
            are left alone -- they are already O(1)). Saved and loaded with the model.
        personas: Persona set trained on: ``"train"`` or ``"train_wide"`` (the same personas,
            wider person-to-person variation); the held-out ``"test"`` set is never trained on.
        algo_kwargs: Keyword arguments of the SB3 algorithm's constructor.
        policy_kwargs: The policy's ``policy_kwargs`` (network sizes).
        framework: ``"sb3"`` (SB3's own class) or ``"jax"`` (``ppo``: :class:`agents.ppo.PPO`;
            ``recurrent_ppo``: :class:`agents.ppo.recurrent.RecurrentPPO`; flax networks, optax,
            the update compiled by JAX).
    """

    algo: str
    env_id: str
    n_envs: int
    total_timesteps: int
    policy: str
    normalize: bool
    personas: str = "train"
    algo_kwargs: Mapping[str, Any] = field(default_factory=dict)
    policy_kwargs: Mapping[str, Any] = field(default_factory=dict)
    framework: str = "sb3"

    def __post_init__(self) -> None:
        """Validate ranges."""
        if self.algo not in ALGORITHMS:
            raise ValueError(f"TrainingConfig.algo must be one of {list(ALGORITHMS)}, got {self.algo!r}")
        if self.framework not in FRAMEWORKS or (self.framework == "jax" and self.algo not in JAX_ALGORITHMS):
            raise ValueError(
                f"TrainingConfig.framework must be one of {list(FRAMEWORKS)} ('jax' for {', '.join(JAX_ALGORITHMS)}), "
                f"got {self.framework!r} for {self.algo!r}"
            )
        if self.framework != "jax" and "policy_lag" in self.algo_kwargs:
            raise ValueError(
                "TrainingConfig.algo_kwargs: policy_lag is agents.ppo's (framework='jax'); "
                f"framework={self.framework!r} has no such setting (drop it from algo_kwargs)"
            )
        check_integer("TrainingConfig.n_envs", self.n_envs, 1, SEED_LIMIT)  # envs seeded seed .. seed + n_envs - 1
        check_integer("TrainingConfig.total_timesteps", self.total_timesteps, 1, sys.maxsize)
        held_out = {p.name for p in resolve_personas(self.personas)} & set(TEST_PERSONAS)
        if held_out:
            raise ValueError(f"TrainingConfig.personas must not include held-out personas, got {sorted(held_out)}")

    def replace(self, **changes: Any) -> TrainingConfig:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    def model_kwargs(self) -> dict[str, Any]:
        """Keyword arguments for the SB3 constructor (``policy_kwargs`` included)."""
        kwargs = dict(self.algo_kwargs)
        if self.policy_kwargs:
            kwargs["policy_kwargs"] = dict(self.policy_kwargs)
        return kwargs


_PPO = TrainingConfig(
    algo="ppo",
    env_id="CoopGym/SitToStand-v0",
    n_envs=8,
    total_timesteps=300_000,
    policy="MlpPolicy",
    normalize=True,
    algo_kwargs={
        # 4096 steps per update in minibatches of 512 (held-out success over seeds:
        # python train.py --env CoopGym/SitToStand-v0 --seed S).
        "n_steps": 512,
        "batch_size": 512,
        "n_epochs": 10,
        # Decaying to 0 settles the final policy.
        "learning_rate": "lin_3e-4",
        # A long horizon favours gentle pushes: a firm push moves a frail person whatever
        # they think, and reads as cooperation.
        "gamma": 0.995,
        "gae_lambda": 0.95,
        "clip_range": 0.2,
        "ent_coef": 0.01,
        "vf_coef": 0.5,
        "max_grad_norm": 0.5,
    },
    policy_kwargs={"net_arch": [64, 64]},
)
"""PPO's settings (tuned on the ``-v0`` ids)."""


_HARD_IDS = ("CoopGym/SitToStandHard-v1", "CoopGym/SitToStandHard-v2")
_PPO_HARD = _PPO.replace(
    env_id=HARD_ENV_ID,
    total_timesteps=1_000_000,
    personas="train_wide",
    algo_kwargs={**_PPO.algo_kwargs, "ent_coef": 0.02},
)
"""PPO's settings on the hard level (see the comment in :data:`HYPERPARAMS`)."""

HYPERPARAMS: dict[str, dict[str, TrainingConfig]] = {
    "ppo": {
        # Sized for time to quality: 4096 samples per update from 64 envs x 64 steps
        # (python bench/time_to_quality.py; bench/results/time_to_quality_CoopGym-SitToStand-v0.json).
        "CoopGym/SitToStand-v0": _PPO.replace(n_envs=64, algo_kwargs={**_PPO.algo_kwargs, "n_steps": 64}),
        # The hard level (-v1 and -v2 alike): 8 x 512, more samples (the policy must learn to
        # stop pushing, ask, and read the answer), a wider spread of people (docs/agents.md,
        # "Why the wider spread") and an entropy bonus of 0.02, which keeps seeds from settling
        # on never lifting; chosen on the training personas' validation episodes
        # (python bench/time_to_quality.py; python bench/learners.py --rows ppo-kalman).
        **{env_id: _PPO_HARD.replace(env_id=env_id) for env_id in _HARD_IDS},
    },
    "recurrent_ppo": {
        "CoopGym/SitToStandRaw-v0": TrainingConfig(
            algo="recurrent_ppo",
            env_id="CoopGym/SitToStandRaw-v0",
            n_envs=8,
            # The LSTM learns -v0 from the measurements alone in 300k steps (held-out score:
            # docs/agents.md, "Other algorithms").
            total_timesteps=300_000,
            policy="MlpLstmPolicy",
            normalize=True,
            algo_kwargs={
                "n_steps": 128,
                "batch_size": 256,
                "n_epochs": 10,
                "learning_rate": 3e-4,
                "gamma": 0.99,
                "gae_lambda": 0.95,
                "clip_range": 0.2,
                "ent_coef": 0.01,
            },
            policy_kwargs={"lstm_hidden_size": 64, "net_arch": [64]},
        ),
        # The hard level: PPO's hard-level settings, an LSTM of 64 before the heads of 64: the
        # memory rows of python bench/learners.py differ from the MLP rows in the network alone.
        **{
            env_id: _PPO_HARD.replace(
                algo="recurrent_ppo",
                env_id=env_id,
                policy="MlpLstmPolicy",
                policy_kwargs={"lstm_hidden_size": 64, "net_arch": [64]},
            )
            for env_id in _HARD_IDS
        },
    },
    "dqn": {
        "CoopGym/SitToStandDiscrete-v0": TrainingConfig(
            algo="dqn",
            env_id="CoopGym/SitToStandDiscrete-v0",
            n_envs=4,
            # Held-out score of this budget: docs/agents.md, "Other algorithms".
            total_timesteps=500_000,
            policy="MlpPolicy",
            normalize=True,
            algo_kwargs={
                "learning_rate": 5e-4,
                "buffer_size": 100_000,
                "learning_starts": 5_000,
                "batch_size": 128,
                "gamma": 0.995,
                # 5-step returns carry the lift's reward back through the ~20-step guiding phase.
                "n_steps": 5,
                "train_freq": 4,
                "gradient_steps": 1,
                "target_update_interval": 2_000,
                "exploration_fraction": 0.3,
                "exploration_final_eps": 0.02,
            },
            policy_kwargs={"net_arch": [128, 128]},
        ),
    },
}
"""Default hyperparameters: ``HYPERPARAMS[algo][env_id]``."""


JAX_SIZING: dict[str, Any] = {
    "n_envs": 16,
    "n_steps": 256,
}
"""How the JAX learners size PPO (``framework="jax"``: :class:`agents.ppo.PPO` and its recurrent learner), over
the settings above.

With the update compiled, what is left per env step is Python's work per ``VecEnv`` step,
which more envs per step spread thinner; but shorter rollouts per env learn less per step.
16 envs x 256 steps keeps the 4096 samples per update, the minibatches and the epochs of
the SB3 settings, and scored highest of 8 x 512, 16 x 256 and 64 x 64 on the training
personas' validation episodes (python bench/learners.py --rows jax-kalman@8,jax-kalman,jax-kalman@64;
docs/agents.md, "The JAX learners' sizing")."""


JAX_POLICY_LAG: dict[str, int] = {"CoopGym/SitToStandHard-v2": 1}
"""PPO's ``policy_lag`` on the JAX learner, by env id (0 on the others): 1 runs each update on a second core
while the next rollout plays (:meth:`agents.ppo.PPO.update`). Chosen on the
training personas' validation episodes, 16 seeds on each of two CPUs (docs/agents.md, "Policy lag")."""


def hyperparams_for(algo: str, env_id: str | None = None, framework: str = "sb3") -> TrainingConfig:
    """The defaults of ``algo`` for ``env_id`` (its own env when None), for the learner ``framework``.

    An env id without tuned settings gets the algorithm's default settings, pointed at
    that env. ``framework="jax"`` takes :data:`JAX_SIZING` over them, and PPO :data:`JAX_POLICY_LAG`.

    Raises:
        ValueError: unknown algorithm, or a framework that cannot train it.
    """
    if algo not in HYPERPARAMS:
        raise ValueError(f"unknown algorithm {algo!r}; known: {', '.join(ALGORITHMS)}")
    env_id = env_id or DEFAULT_ENV_IDS[algo]
    table = HYPERPARAMS[algo]
    config = table[env_id] if env_id in table else table[DEFAULT_ENV_IDS[algo]].replace(env_id=env_id)
    if framework == "sb3":
        return config
    sizing = {k: v for k, v in JAX_SIZING.items() if k != "n_envs"}
    if algo == "ppo" and JAX_POLICY_LAG.get(env_id, 0):
        sizing["policy_lag"] = JAX_POLICY_LAG[env_id]
    return config.replace(
        framework=framework,
        n_envs=JAX_SIZING["n_envs"],
        algo_kwargs={**config.algo_kwargs, **sizing},
    )


def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return f"!!float {value:g}" if ("e" in f"{value:g}") else repr(value)
    if isinstance(value, int):
        return str(value)
    return f"'{value}'"


def zoo_yaml(algo: str) -> str:
    """RL Zoo hyperparameter file (``-conf``) text for ``algo``, generated from :data:`HYPERPARAMS`."""
    lines = [
        "# Generated by agents.hyperparams.write_zoo_files() from agents/hyperparams.py; edit that file, not this one.",
        f"# python -m rl_zoo3.train --algo {ZOO_ALGO_NAMES[algo]} --env {DEFAULT_ENV_IDS[algo]} "
        f"--gym-packages coop_gym -conf agents/zoo/{ZOO_ALGO_NAMES[algo]}.yml --num-threads 1",
    ]
    for env_id, config in HYPERPARAMS[algo].items():
        lines.append(f"{env_id}:")
        lines.append(f"  n_envs: {config.n_envs}")
        lines.append(f"  n_timesteps: {_yaml_value(float(config.total_timesteps))}")
        lines.append(f"  policy: '{config.policy}'")
        if config.normalize:
            lines.append('  normalize: "dict(norm_obs=True, norm_reward=False)"')
        lines.append("  env_kwargs:")
        lines.append(f"    personas: '{config.personas}'")
        for key, value in config.algo_kwargs.items():
            lines.append(f"  {key}: {_yaml_value(value)}")
        if config.policy_kwargs:
            inner = ", ".join(f"{k}={v!r}" for k, v in config.policy_kwargs.items())
            lines.append(f'  policy_kwargs: "dict({inner})"')
    return "\n".join(lines) + "\n"


def write_zoo_files(folder: str | Path | None = None) -> list[Path]:
    """(Re)write ``agents/zoo/{ppo,ppo_lstm,dqn}.yml`` from :data:`HYPERPARAMS`."""
    folder = Path(folder) if folder is not None else Path(__file__).parents[1] / "zoo"
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for algo in ALGORITHMS:
        path = folder / f"{ZOO_ALGO_NAMES[algo]}.yml"
        write_text(path, zoo_yaml(algo))
        paths.append(path)
    return paths
