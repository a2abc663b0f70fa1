"""CleanRL's ``ppo.py``, unmodified and on its defaults, scored on the held-out personas.

CleanRL's scripts are single files that train and exit; they do not save the agent. This
runs one as a user would (``python ppo.py --env-id ... --total-timesteps N``, through
:func:`runpy.run_path` with that command line), then takes the trained ``agent`` from the
script's globals and scores it with the common evaluation path
(:func:`agents.evaluate.evaluate`) on the held-out personas: greedy (argmax of the policy's
logits, what SB3's ``deterministic=True`` means) and sampled (how the script acts while it
trains). The script is not part of coop_gym; fetch it from CleanRL (``cleanrl/ppo.py``;
the tyro it needs comes with coop_gym)::

    python bench/cleanrl_defaults.py --script ppo.py --env-id CoopGym/SitToStandDiscreteUnit-v0 \\
        --total-timesteps 1000000 --out runs/cleanrl

The id is handed to the script as ``coop_gym:<id>``, so ``gym.make`` imports coop_gym (and so
registers the ids) before it makes the env. The JSON written to ``--out`` holds the command,
the wall time, both evaluations and the handbook caregiver's on the same episodes
(``bench/result_files.py``). ``--save`` also writes it to
``bench/results/cleanrl_defaults_<script>_<env>_<timesteps>.json`` (``bench/result_files.py``).
"""

from __future__ import annotations

import argparse
import hashlib
import runpy
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
import gymnasium as gym
import numpy as np
import torch
from numpy.typing import NDArray
from result_files import add_save_argument, held_out_report, save

import coop_gym
from coop_gym.io import save_with, write_json


class ScriptAgent:
    """A CleanRL ``Agent`` (``actor`` logits over a Discrete action) behind SB3's ``predict``."""

    def __init__(self, module: torch.nn.Module, name: str) -> None:
        self.module = module
        self.name = name

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> tuple[NDArray[np.int64], Any]:
        """SB3's protocol (``agents.base.Agent``); the script's agent keeps no state."""
        with torch.no_grad():
            logits = self.module.actor(torch.as_tensor(np.asarray(observation), dtype=torch.float32))
            if deterministic:
                actions = logits.argmax(dim=-1)
            else:
                actions = torch.distributions.Categorical(logits=logits).sample()
        return actions.numpy().astype(np.int64), state


def run_script(
    script: Path, env_arg: str, total_timesteps: int, seed: int, extra: tuple[str, ...] = ()
) -> tuple[ScriptAgent, dict[str, Any]]:
    """Run ``script`` as ``python SCRIPT --env-id ENV_ARG --total-timesteps N --seed S [EXTRA]``; its agent and the run.

    ``env_arg`` is what ``gym.make`` gets, ``module:id`` (``coop_gym:CoopGym/...``) so that the
    module that registers the id is imported first.
    """
    torch.set_num_threads(1)
    command = [
        str(script), "--env-id", env_arg, "--total-timesteps", str(total_timesteps),
        "--seed", str(seed), *extra,
    ]  # fmt: skip
    saved_argv = sys.argv
    sys.argv = command
    started = time.perf_counter()
    try:
        namespace = runpy.run_path(str(script), run_name="__main__")
    finally:
        sys.argv = saved_argv
    wall = time.perf_counter() - started
    if "agent" not in namespace:
        raise SystemExit(f"{script} defined no `agent` to evaluate")
    agent = ScriptAgent(namespace["agent"].cpu().eval(), f"cleanrl_{script.stem}_{total_timesteps}")
    run = {"script_command": ["python", *command], "timesteps": total_timesteps, "seed": seed}
    run["script_sha256"] = hashlib.sha256(script.read_bytes()).hexdigest()  # which version of the script
    run["wall_time_s"] = wall
    return agent, run


# --- hard-v2 with a timeout priced as a failed assistance ---------------------------------

PRICED_BASE_ENV_ID = "CoopGym/SitToStandHardDiscreteUnit-v2"
PRICED_ENV_ID = "PricedTimeout/SitToStandHardDiscreteUnit-v2"
"""A measurement aid, not an env version: :data:`PRICED_BASE_ENV_ID` whose reward also subtracts
:data:`TIMEOUT_PENALTY` when an episode ends in a timeout. On every coop_gym id a timeout costs
only the time that passed (30 s x 0.01 = 0.3), less than a premature lift (0.5), so a learner that
has not yet found the person's mind can settle on never lifting. Dynamics, observations and
outcomes are the id's own, so a policy trained on it is scored on the id itself. Importing this
module registers it: CleanRL's script takes ``--env-id cleanrl_defaults:PricedTimeout/...``
(``bench/learners.py``'s ``cleanrl-ppo-priced`` row)."""
TIMEOUT_PENALTY = 1.0
"""Subtracted from the last reward of an episode that ends in a timeout: a failed assistance."""


class PricedTimeout(gym.Wrapper[Any, Any, Any, Any]):
    """Subtracts ``penalty`` from the reward of the step whose outcome is ``timeout``."""

    def __init__(self, env: gym.Env[Any, Any], penalty: float = TIMEOUT_PENALTY) -> None:
        super().__init__(env)
        self.penalty = float(penalty)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        if info.get("outcome") == "timeout":
            reward = float(reward) - self.penalty
        return observation, float(reward), terminated, truncated, info


def make_priced(**kwargs: Any) -> gym.Env[Any, Any]:
    """:data:`PRICED_BASE_ENV_ID` made as registered (its time limit included), in :class:`PricedTimeout`."""
    return PricedTimeout(gym.make(PRICED_BASE_ENV_ID, **kwargs))


if PRICED_ENV_ID not in gym.registry:
    gym.register(PRICED_ENV_ID, entry_point=make_priced)


# --- hard-v2 on train.py's wider training personas -----------------------------------------

WIDE_ENV_ID = "WidePersonas/SitToStandHardDiscreteUnit-v2"
"""A measurement aid, not an env version: :data:`PRICED_BASE_ENV_ID` made with
``personas="train_wide"``, the persona set ``train.py`` trains on, where the id's own default is
``"train"``. CleanRL's ``gym.make(env_id)`` passes no keyword, so the set goes into the
registration (``bench/learners.py``'s ``cleanrl-ppo-wide`` row)."""


def make_wide(**kwargs: Any) -> gym.Env[Any, Any]:
    """:data:`PRICED_BASE_ENV_ID` made as registered, on the ``"train_wide"`` personas."""
    return gym.make(PRICED_BASE_ENV_ID, **{"personas": "train_wide", **kwargs})


if WIDE_ENV_ID not in gym.registry:
    gym.register(WIDE_ENV_ID, entry_point=make_wide)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--script", required=True, help="path of CleanRL's ppo.py (or another script defining `agent`)")
    parser.add_argument("--env-id", default="CoopGym/SitToStandDiscreteUnit-v0", choices=sorted(coop_gym.ENV_IDS))
    parser.add_argument("--total-timesteps", type=int, default=1_000_000)
    parser.add_argument("--seed", type=int, default=1, help="the script's --seed (CleanRL's default is 1)")
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--out", default="runs/cleanrl")
    add_save_argument(parser, "cleanrl_defaults_<script>_<env>_<timesteps>.json")
    args = parser.parse_args(argv)
    script = Path(args.script)
    if not script.is_file():
        parser.error(f"--script: no such file {str(script)!r}")
    if args.total_timesteps < 1:
        parser.error(f"--total-timesteps: must be a positive integer, got {args.total_timesteps}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)

    agent, run = run_script(script, f"coop_gym:{args.env_id}", args.total_timesteps, args.seed)
    name = agent.name
    # Greedy (argmax, SB3's deterministic=True) and sampled (how the script acts while it trains).
    agents = {"greedy": (agent, True), "sampled": (agent, False)}
    report = held_out_report(run, agents, args.env_id, args.episodes)
    path = out / f"{name}_{args.env_id.split('/')[-1]}_seed{args.seed}.json"
    write_json(path, report)
    save_with(path.with_suffix(".pt"), lambda temp: torch.save(agent.module.state_dict(), temp))
    print(f"wrote {path}")
    if args.save:
        stem = f"{script.stem}_{args.env_id.split('/')[-1]}_{args.total_timesteps}"
        save(args.save.replace("<script>_<env>_<timesteps>", stem), "cleanrl_defaults", argv, report)


if __name__ == "__main__":
    main()
