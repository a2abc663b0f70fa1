"""CleanRL-style single-file PPO on coop_gym's natively batched vector env (gymnasium 1.x).

Read top to bottom: arguments -> vector env -> agent -> rollout -> GAE -> update -> log.
Needs only gymnasium, numpy, torch and tensorboard (``pip install -e ".[train]"``)::

    python examples/ppo_coop_gym.py --total-timesteps 300000
    tensorboard --logdir runs/

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

import argparse
import dataclasses
import random
import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from torch import nn
from torch.distributions import Categorical

import coop_gym  # noqa: F401  (registers the ids)


@dataclass
class Args:
    """Command-line arguments (``--name value``)."""

    env_id: str = "CoopGym/SitToStand-v0"
    seed: int = 1
    total_timesteps: int = 300_000
    num_envs: int = 8
    num_steps: int = 512
    learning_rate: float = 3e-4
    anneal_lr: bool = True
    gamma: float = 0.995
    gae_lambda: float = 0.95
    num_minibatches: int = 8
    update_epochs: int = 10
    clip_coef: float = 0.2
    ent_coef: float = 0.01
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    personas: str = "train"
    torch_threads: int = 1
    track: bool = True  # write TensorBoard events under runs/


def parse_args(argv: list[str] | None = None) -> Args:
    """Every field of :class:`Args` as ``--field-name``."""
    parser = argparse.ArgumentParser(description=(__doc__ or "").split("\n\n")[0])
    for f in dataclasses.fields(Args):
        flag = "--" + f.name.replace("_", "-")
        if f.type in ("bool", bool):
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=f.default)
        else:
            parser.add_argument(flag, type=type(f.default), default=f.default)
    return Args(**vars(parser.parse_args(argv)))


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


def main(argv: list[str] | None = None) -> None:
    """Train PPO, logging as CleanRL does."""
    args = parse_args(argv)
    batch_size = args.num_envs * args.num_steps
    minibatch_size = batch_size // args.num_minibatches
    num_iterations = max(1, args.total_timesteps // batch_size)
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
    nvec = [int(n) for n in space.nvec] if isinstance(space, gym.spaces.MultiDiscrete) else [int(space.n)]
    obs_dim = int(np.prod(envs.single_observation_space.shape))
    agent = Agent(obs_dim, nvec)
    optimizer = torch.optim.Adam(agent.parameters(), lr=args.learning_rate, eps=1e-5)

    obs = torch.zeros((args.num_steps, args.num_envs, obs_dim))
    actions = torch.zeros((args.num_steps, args.num_envs, len(nvec)), dtype=torch.long)
    logprobs = torch.zeros((args.num_steps, args.num_envs))
    rewards = torch.zeros((args.num_steps, args.num_envs))
    terminated = torch.zeros((args.num_steps, args.num_envs))
    dones = torch.zeros((args.num_steps, args.num_envs))
    valid = torch.zeros((args.num_steps, args.num_envs), dtype=torch.bool)
    values = torch.zeros((args.num_steps, args.num_envs))

    global_step = 0
    start_time = time.time()
    next_obs_np, _ = envs.reset(seed=args.seed)
    next_obs = torch.as_tensor(next_obs_np, dtype=torch.float32)
    # NEXT_STEP: an env whose episode ended on the previous step is reset by the coming step.
    autoreset = np.zeros(args.num_envs, dtype=bool)
    outcomes: list[str] = []

    for iteration in range(1, num_iterations + 1):
        if args.anneal_lr:
            optimizer.param_groups[0]["lr"] = (1.0 - (iteration - 1.0) / num_iterations) * args.learning_rate

        for step in range(args.num_steps):
            obs[step] = next_obs
            valid[step] = torch.as_tensor(~autoreset)
            with torch.no_grad():
                action, logprob, _, value = agent.get_action_and_value(next_obs)
            values[step] = value.flatten()
            actions[step] = action
            logprobs[step] = logprob

            env_action = action.numpy() if len(nvec) > 1 else action[:, 0].numpy()
            next_obs_np, reward, term, trunc, infos = envs.step(env_action)
            global_step += int((~autoreset).sum())  # reset steps are not env steps of an episode
            autoreset = np.logical_or(term, trunc)
            rewards[step] = torch.as_tensor(reward, dtype=torch.float32)
            terminated[step] = torch.as_tensor(term, dtype=torch.float32)
            dones[step] = torch.as_tensor(autoreset, dtype=torch.float32)
            next_obs = torch.as_tensor(next_obs_np, dtype=torch.float32)

            for episode_return, length, outcome in finished_episodes(infos):
                outcomes.append(outcome)
                print(f"global_step={global_step}, episodic_return={episode_return:.3f}, outcome={outcome}")
                if writer is not None:
                    writer.add_scalar("charts/episodic_return", episode_return, global_step)
                    writer.add_scalar("charts/episodic_length", length, global_step)
        if outcomes and writer is not None:
            recent = outcomes[-200:]
            writer.add_scalar("charts/success_rate", recent.count("success") / len(recent), global_step)
            writer.add_scalar("charts/unsafe_rate", recent.count("unsafe") / len(recent), global_step)

        # GAE. values[t + 1] is V of the observation that step t returned: after a
        # truncation that is the final observation (NEXT_STEP), so time-outs bootstrap.
        with torch.no_grad():
            next_value = agent.get_value(next_obs).reshape(1, -1)
            advantages = torch.zeros_like(rewards)
            lastgaelam = torch.zeros(args.num_envs)
            for t in reversed(range(args.num_steps)):
                following = next_value[0] if t == args.num_steps - 1 else values[t + 1]
                delta = rewards[t] + args.gamma * following * (1.0 - terminated[t]) - values[t]
                # An ended episode stops the recursion; the reset step after it is masked out below.
                lastgaelam = delta + args.gamma * args.gae_lambda * (1.0 - dones[t]) * lastgaelam
                advantages[t] = lastgaelam
            returns = advantages + values

        # Flatten the batch, keeping only real transitions (not the NEXT_STEP reset steps).
        keep = valid.reshape(-1)
        b_obs = obs.reshape(-1, obs_dim)[keep]
        b_logprobs = logprobs.reshape(-1)[keep]
        b_actions = actions.reshape(-1, len(nvec))[keep]
        b_advantages = advantages.reshape(-1)[keep]
        b_returns = returns.reshape(-1)[keep]
        b_values = values.reshape(-1)[keep]
        n = int(keep.sum())

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

        y_pred, y_true = b_values.numpy(), b_returns.numpy()
        var_y = np.var(y_true)
        explained_var = np.nan if var_y == 0 else 1 - np.var(y_true - y_pred) / var_y
        sps = int(global_step / (time.time() - start_time))
        recent = outcomes[-200:]
        success = recent.count("success") / len(recent) if recent else float("nan")
        print(f"iteration {iteration}/{num_iterations}: SPS {sps}, success rate (last {len(recent)}) {success:.3f}")
        if writer is not None:
            writer.add_scalar("charts/learning_rate", optimizer.param_groups[0]["lr"], global_step)
            writer.add_scalar("losses/value_loss", v_loss.item(), global_step)
            writer.add_scalar("losses/policy_loss", pg_loss.item(), global_step)
            writer.add_scalar("losses/entropy", entropy_loss.item(), global_step)
            writer.add_scalar("losses/approx_kl", approx_kl.item(), global_step)
            writer.add_scalar("losses/clipfrac", np.mean(clipfracs), global_step)
            writer.add_scalar("losses/explained_variance", explained_var, global_step)
            writer.add_scalar("charts/SPS", sps, global_step)

    envs.close()
    if writer is not None:
        writer.close()


if __name__ == "__main__":
    main()
