"""CleanRL-style single-file PPO on coop_gym's natively batched vector env (gymnasium 1.x).

Read top to bottom: arguments -> vector env -> agent -> rollout -> GAE -> update -> log. The
arguments are a typed dataclass parsed by tyro, as in CleanRL (field docs are the ``--help``).
Needs only gymnasium, numpy, torch, tensorboard and tyro (``pip install -e ".[train]"``)::

    python examples/ppo_coop_gym.py          # the default hard level, CoopGym/SitToStandHard-v2
    tensorboard --logdir runs/

The defaults are ``train.py``'s PPO settings for that level (``agents/hyperparams.py``:
8 envs x 512 steps, 10 epochs of 8 minibatches, ``gamma`` 0.995, entropy bonus 0.02, the wider
training persona set, 1M steps); ``--env-id CoopGym/SitToStand-v0 --total-timesteps 300000``
trains the paper's model.

What differs from CleanRL's ``ppo.py`` (written for gym 0.2x's same-step autoreset):

* The env is ``gymnasium.make_vec(id, num_envs, vectorization_mode="vector_entry_point")``:
  coop_gym's own batched env, with Gymnasium 1.x's default ``NEXT_STEP`` autoreset. The
  step that ends an episode returns that episode's final observation and info; the *next*
  step resets the env (reward 0, action ignored). So (i) a truncated episode is
  bootstrapped from the observation returned with it, with no ``final_obs`` lookup, and
  (ii) the reset transitions are not experience: they are masked out of the PPO loss.
* Episode statistics come from ``gymnasium.wrappers.vector.RecordEpisodeStatistics``,
  which knows ``NEXT_STEP`` (it reads ``metadata["autoreset_mode"]``): on the step an
  episode ends, ``infos["episode"]["r"][i]`` holds its return where ``infos["_episode"][i]``.
  The outcome (``success``/``unsafe``/``premature``/``timeout``) is ``infos["outcome"][i]``
  of that same step -- one step later env ``i`` has been reset.
* MultiDiscrete actions (push, verbal cue, lift): one categorical head per component.
"""

from __future__ import annotations

import random
import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import tyro
from torch import nn
from torch.distributions import Categorical

import coop_gym  # noqa: F401  (registers the ids)


@dataclass
class Args:
    """Command-line arguments (``--field-name value``); each field's docstring is its ``--help``."""

    env_id: str = "CoopGym/SitToStandHard-v2"
    """the coop_gym env id"""
    seed: int = 1
    """seed of the envs, the network and the sampling"""
    total_timesteps: int = 1_000_000
    """env steps to train for"""
    num_envs: int = 8
    """envs stepped side by side in the batched env"""
    num_steps: int = 512
    """steps per env in one rollout"""
    learning_rate: float = 3e-4
    """Adam's learning rate"""
    anneal_lr: bool = True
    """decay the learning rate linearly to 0"""
    gamma: float = 0.995
    """discount factor"""
    gae_lambda: float = 0.95
    """lambda of generalised advantage estimation"""
    num_minibatches: int = 8
    """minibatches per epoch"""
    update_epochs: int = 10
    """passes over each rollout"""
    clip_coef: float = 0.2
    """PPO's clipping range of the probability ratio"""
    ent_coef: float = 0.02
    """entropy bonus coefficient"""
    vf_coef: float = 0.5
    """value loss coefficient"""
    max_grad_norm: float = 0.5
    """gradient norm clip"""
    personas: str = "train_wide"
    """persona set trained on (never the held-out "test")"""
    torch_threads: int = 1
    """torch CPU threads"""
    track: bool = True
    """write TensorBoard events under runs/"""


def parse_args(argv: list[str] | None = None) -> Args:
    """Every field of :class:`Args` as ``--field-name`` (tyro)."""
    return tyro.cli(Args, args=argv, description=(__doc__ or "").split("\n\n")[0])


def make_envs(args: Args) -> gym.vector.VectorEnv:
    """coop_gym's batched env, episode statistics, running observation normalisation."""
    envs = gym.make_vec(
        args.env_id, num_envs=args.num_envs, vectorization_mode="vector_entry_point", personas=args.personas
    )
    # Statistics first, so they see the env's rewards; observations are normalised on top.
    envs = gym.wrappers.vector.RecordEpisodeStatistics(envs)
    envs = gym.wrappers.vector.NormalizeObservation(envs)
    return envs


def finished_episodes(infos: dict[str, Any]) -> list[tuple[float, int, str]]:
    """(return, length, outcome) of each episode that ended on this step (NEXT_STEP autoreset)."""
    if "_episode" not in infos:
        return []
    done = np.flatnonzero(infos["_episode"])
    return [(float(infos["episode"]["r"][i]), int(infos["episode"]["l"][i]), str(infos["outcome"][i])) for i in done]


def layer_init(layer: nn.Linear, std: float = np.sqrt(2), bias_const: float = 0.0) -> nn.Linear:
    """Orthogonal weights, constant bias (as CleanRL)."""
    torch.nn.init.orthogonal_(layer.weight, std)
    torch.nn.init.constant_(layer.bias, bias_const)
    return layer


class Agent(nn.Module):
    """Separate 64-64 tanh actor and critic; one categorical per action component."""

    def __init__(self, obs_dim: int, nvec: list[int]) -> None:
        """Networks for ``obs_dim`` features and the action components' sizes ``nvec``."""
        super().__init__()
        self.nvec = nvec
        self.critic = nn.Sequential(
            layer_init(nn.Linear(obs_dim, 64)), nn.Tanh(), layer_init(nn.Linear(64, 64)), nn.Tanh(),
            layer_init(nn.Linear(64, 1), std=1.0),
        )  # fmt: skip
        self.actor = nn.Sequential(
            layer_init(nn.Linear(obs_dim, 64)), nn.Tanh(), layer_init(nn.Linear(64, 64)), nn.Tanh(),
            layer_init(nn.Linear(64, sum(nvec)), std=0.01),
        )  # fmt: skip

    def get_value(self, x: torch.Tensor) -> torch.Tensor:
        """V(x)."""
        return self.critic(x)

    def get_action_and_value(
        self, x: torch.Tensor, action: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
        """Sampled (or given) action, its log-probability, the entropy and V(x)."""
        dists = [Categorical(logits=logits) for logits in torch.split(self.actor(x), self.nvec, dim=1)]
        if action is None:
            action = torch.stack([d.sample() for d in dists], dim=1)
        log_prob = torch.stack([d.log_prob(a) for d, a in zip(dists, action.T, strict=True)]).sum(0)
        entropy = torch.stack([d.entropy() for d in dists]).sum(0)
        return action, log_prob, entropy, self.critic(x)


class Rollout:
    """One rollout's buffers, ``(num_steps, num_envs, ...)``; ``valid`` is False on NEXT_STEP reset steps."""

    def __init__(self, num_steps: int, num_envs: int, obs_dim: int, n_actions: int) -> None:
        """Zeroed buffers."""
        shape = (num_steps, num_envs)
        self.obs = torch.zeros((*shape, obs_dim))
        self.actions = torch.zeros((*shape, n_actions), dtype=torch.long)
        self.logprobs = torch.zeros(shape)
        self.rewards = torch.zeros(shape)
        self.terminated = torch.zeros(shape)
        self.dones = torch.zeros(shape)
        self.valid = torch.zeros(shape, dtype=torch.bool)
        self.values = torch.zeros(shape)


class Collector:
    """Steps the envs with the agent into a :class:`Rollout`; keeps the episode outcomes and the step count."""

    def __init__(self, envs: gym.vector.VectorEnv, args: Args, writer: Any) -> None:
        """Reset the envs (seeded) and start counting."""
        self.envs, self.writer = envs, writer
        next_obs, _ = envs.reset(seed=args.seed)
        self.next_obs = torch.as_tensor(next_obs, dtype=torch.float32)
        # NEXT_STEP: an env whose episode ended on the previous step is reset by the coming step.
        self.autoreset = np.zeros(args.num_envs, dtype=bool)
        self.global_step = 0
        self.outcomes: list[str] = []

    def collect(self, agent: Agent, rollout: Rollout) -> None:
        """Fill ``rollout`` with the next ``num_steps`` steps of every env."""
        for step in range(rollout.obs.shape[0]):
            rollout.obs[step] = self.next_obs
            rollout.valid[step] = torch.as_tensor(~self.autoreset)
            with torch.no_grad():
                action, logprob, _, value = agent.get_action_and_value(self.next_obs)
            rollout.values[step] = value.flatten()
            rollout.actions[step] = action
            rollout.logprobs[step] = logprob

            env_action = action.numpy() if len(agent.nvec) > 1 else action[:, 0].numpy()
            next_obs, reward, term, trunc, infos = self.envs.step(env_action)
            self.global_step += int((~self.autoreset).sum())  # reset steps are not env steps of an episode
            self.autoreset = np.logical_or(term, trunc)
            rollout.rewards[step] = torch.as_tensor(reward, dtype=torch.float32)
            rollout.terminated[step] = torch.as_tensor(term, dtype=torch.float32)
            rollout.dones[step] = torch.as_tensor(self.autoreset, dtype=torch.float32)
            self.next_obs = torch.as_tensor(next_obs, dtype=torch.float32)
            self._log_episodes(infos)

    def _log_episodes(self, infos: dict[str, Any]) -> None:
        for episode_return, length, outcome in finished_episodes(infos):
            self.outcomes.append(outcome)
            print(f"global_step={self.global_step}, episodic_return={episode_return:.3f}, outcome={outcome}")
            if self.writer is not None:
                self.writer.add_scalar("charts/episodic_return", episode_return, self.global_step)
                self.writer.add_scalar("charts/episodic_length", length, self.global_step)


def advantages_and_returns(
    agent: Agent, rollout: Rollout, next_obs: torch.Tensor, gamma: float, gae_lambda: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Generalised advantage estimates and returns of ``rollout``.

    ``values[t + 1]`` is V of the observation step t returned: after a truncation that is the
    final observation (NEXT_STEP), so time-outs bootstrap.
    """
    num_steps = rollout.rewards.shape[0]
    with torch.no_grad():
        next_value = agent.get_value(next_obs).reshape(1, -1)
        advantages = torch.zeros_like(rollout.rewards)
        lastgaelam = torch.zeros(rollout.rewards.shape[1])
        for t in reversed(range(num_steps)):
            following = next_value[0] if t == num_steps - 1 else rollout.values[t + 1]
            delta = rollout.rewards[t] + gamma * following * (1.0 - rollout.terminated[t]) - rollout.values[t]
            # An ended episode stops the recursion; the reset step after it is masked out of the loss.
            lastgaelam = delta + gamma * gae_lambda * (1.0 - rollout.dones[t]) * lastgaelam
            advantages[t] = lastgaelam
    return advantages, advantages + rollout.values


def ppo_update(
    agent: Agent, optimizer: torch.optim.Optimizer, rollout: Rollout, advantages: torch.Tensor, returns: torch.Tensor,
    args: Args,
) -> dict[str, float]:  # fmt: skip
    """PPO's clipped update over the real transitions of ``rollout`` (not the NEXT_STEP reset steps)."""
    keep = rollout.valid.reshape(-1)
    b_obs = rollout.obs.reshape(-1, rollout.obs.shape[-1])[keep]
    b_logprobs = rollout.logprobs.reshape(-1)[keep]
    b_actions = rollout.actions.reshape(-1, rollout.actions.shape[-1])[keep]
    b_advantages = advantages.reshape(-1)[keep]
    b_returns = returns.reshape(-1)[keep]
    n = int(keep.sum())
    minibatch_size = rollout.obs.shape[0] * rollout.obs.shape[1] // args.num_minibatches
    clipfracs = []
    for _ in range(args.update_epochs):
        b_inds = np.random.permutation(n)
        for start in range(0, n, minibatch_size):
            mb_inds = b_inds[start : start + minibatch_size]
            _, newlogprob, entropy, newvalue = agent.get_action_and_value(b_obs[mb_inds], b_actions[mb_inds])
            logratio = newlogprob - b_logprobs[mb_inds]
            ratio = logratio.exp()
            with torch.no_grad():
                approx_kl = ((ratio - 1) - logratio).mean()
                clipfracs.append(((ratio - 1.0).abs() > args.clip_coef).float().mean().item())
            mb_advantages = b_advantages[mb_inds]
            mb_advantages = (mb_advantages - mb_advantages.mean()) / (mb_advantages.std() + 1e-8)
            pg_loss = torch.max(
                -mb_advantages * ratio, -mb_advantages * torch.clamp(ratio, 1 - args.clip_coef, 1 + args.clip_coef)
            ).mean()
            v_loss = 0.5 * ((newvalue.view(-1) - b_returns[mb_inds]) ** 2).mean()
            entropy_loss = entropy.mean()
            loss = pg_loss - args.ent_coef * entropy_loss + v_loss * args.vf_coef
            optimizer.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(agent.parameters(), args.max_grad_norm)
            optimizer.step()
    y_pred, y_true = rollout.values.reshape(-1)[keep].numpy(), b_returns.numpy()
    var_y = np.var(y_true)
    return {
        "value_loss": v_loss.item(),
        "policy_loss": pg_loss.item(),
        "entropy": entropy_loss.item(),
        "approx_kl": approx_kl.item(),
        "clipfrac": float(np.mean(clipfracs)),
        "explained_variance": np.nan if var_y == 0 else float(1 - np.var(y_true - y_pred) / var_y),
    }


def main(argv: list[str] | None = None) -> None:
    """Train PPO, logging as CleanRL does."""
    args = parse_args(argv)
    num_iterations = max(1, args.total_timesteps // (args.num_envs * args.num_steps))
    run_name = f"{args.env_id.replace('/', '-')}__ppo_coop_gym__{args.seed}__{int(time.time())}"
    writer = None
    if args.track:
        from torch.utils.tensorboard import SummaryWriter

        writer = SummaryWriter(f"runs/{run_name}")

    random.seed(args.seed)
    np.random.seed(args.seed)
    torch.manual_seed(args.seed)
    torch.set_num_threads(args.torch_threads)

    envs = make_envs(args)
    space = envs.single_action_space
    assert isinstance(space, gym.spaces.MultiDiscrete | gym.spaces.Discrete), "MultiDiscrete or Discrete actions"
    nvec = [int(n) for n in space.nvec] if isinstance(space, gym.spaces.MultiDiscrete) else [int(space.n)]
    obs_dim = int(np.prod(envs.single_observation_space.shape or ()))
    agent = Agent(obs_dim, nvec)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)
    rollout = Rollout(args.num_steps, args.num_envs, obs_dim, len(nvec))
    collector = Collector(envs, args, writer)
    start_time = time.time()

    for iteration in range(1, num_iterations + 1):
        if args.anneal_lr:
            optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / num_iterations) * args.learning_rate
        collector.collect(agent, rollout)
        advantages, returns = advantages_and_returns(agent, rollout, collector.next_obs, args.gamma, args.gae_lambda)
        losses = ppo_update(agent, optimizer, rollout, advantages, returns, args)

        global_step, recent = collector.global_step, collector.outcomes[-200:]
        sps = int(global_step / (time.time() - start_time))
        success = recent.count("success") / len(recent) if recent else float("nan")
        print(f"iteration {iteration}/{num_iterations}: SPS {sps}, success rate (last {len(recent)}) {success:.3f}")
        if writer is not None:
            if recent:
                writer.add_scalar("charts/success_rate", success, global_step)
                writer.add_scalar("charts/unsafe_rate", recent.count("unsafe") / len(recent), global_step)
            writer.add_scalar("charts/learning_rate", optimizer.param_groups[0]["lr"], global_step)
            for name, value in losses.items():
                writer.add_scalar(f"losses/{name}", value, global_step)
            writer.add_scalar("charts/SPS", sps, global_step)

    envs.close()
    if writer is not None:
        writer.close()


if __name__ == "__main__":
    main()
