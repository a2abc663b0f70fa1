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
from result_files import CLEANRL_ENV_ID, add_save_argument, held_out_report, save

import coop_gym
from coop_gym.io import save_with, write_json


class ScriptAgent:
    """A CleanRL ``Agent`` (``actor`` logits over a Discrete action) behind SB3's ``predict``."""

    def __init__(self, module: torch.nn.Module, name: str) -> None:
        self.module: Any = module  # the script's Agent: its actor is an attribute nn.Module does not declare
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

PRICED_ENV_ID = "PricedTimeout/SitToStandHardDiscreteUnit-v2"
"""A measurement aid, not an env version: :data:`CLEANRL_ENV_ID` whose reward also subtracts
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
    """:data:`CLEANRL_ENV_ID` made as registered (its time limit included), in :class:`PricedTimeout`."""
    return PricedTimeout(gym.make(CLEANRL_ENV_ID, **kwargs))


if PRICED_ENV_ID not in gym.registry:
    gym.register(PRICED_ENV_ID, entry_point=make_priced)


# --- hard-v2 on train.py's wider training personas -----------------------------------------

WIDE_ENV_ID = "WidePersonas/SitToStandHardDiscreteUnit-v2"
"""A measurement aid, not an env version: :data:`CLEANRL_ENV_ID` made with
``personas="train_wide"``, the persona set ``train.py`` trains on, where the id's own default is
``"train"``. CleanRL's ``gym.make(env_id)`` passes no keyword, so the set goes into the
registration (``bench/learners.py``'s ``cleanrl-ppo-wide`` row)."""


def make_wide(**kwargs: Any) -> gym.Env[Any, Any]:
    """:data:`CLEANRL_ENV_ID` made as registered, on the ``"train_wide"`` personas."""
    return gym.make(CLEANRL_ENV_ID, **{"personas": "train_wide", **kwargs})


if WIDE_ENV_ID not in gym.registry:
    gym.register(WIDE_ENV_ID, entry_point=make_wide)


# --- the never-lift study's measurement aids (bench/library_defaults.py --study never-lift) ---------

OUTCOME_LOG: list[tuple[int, str]] = []
"""``(steps, outcome)`` of each episode that ended in this process under :class:`OutcomeLog`: ``steps`` the
env steps all of them had taken by then, which is a learner's global step (one process, its envs stepped in
turn, as CleanRL's ``SyncVectorEnv`` and SB3's ``DummyVecEnv`` do)."""
_STEPS_TAKEN = [0]


def clear_outcome_log() -> None:
    """Empty :data:`OUTCOME_LOG` and its step count (before a training run)."""
    OUTCOME_LOG.clear()
    _STEPS_TAKEN[0] = 0


class OutcomeLog(gym.Wrapper[Any, Any, Any, Any]):
    """Appends each episode's ``info["outcome"]`` with the global step to :data:`OUTCOME_LOG`; changes nothing."""

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        observation, reward, terminated, truncated, info = self.env.step(action)
        _STEPS_TAKEN[0] += 1
        if terminated or truncated:
            OUTCOME_LOG.append((_STEPS_TAKEN[0], str(info["outcome"])))
        return observation, reward, terminated, truncated, info


MID_GUIDANCE_SHARE = 0.5
"""The share of episodes :class:`MidGuidance` starts mid-guidance; the others start seated, as on the id."""
MID_GUIDANCE_MAX_S = 15.0
"""The longest guided prefix [s]: half the 30 s episode, so a learner always has time left to act."""


class MidGuidance(gym.Wrapper[Any, Any, Any, Any]):
    """Starts :data:`MID_GUIDANCE_SHARE` of the episodes mid-guidance instead of seated.

    At such a reset the scripted oracle (:class:`agents.caregivers.scripted.OracleAgent`, which reads the
    true ``xi`` from ``info``) guides the person for a uniform 0.1 s .. :data:`MID_GUIDANCE_MAX_S`, handing
    over at the step where it would lift: the learner meets states from which a lift succeeds, and the
    clock keeps what the guidance took. A start state of a training run, not an env version: the episode's
    dynamics, reward and end are the id's own. Its draws come from its own generator, seeded by ``reset``.
    """

    def __init__(self, env: gym.Env[Any, Any]) -> None:
        super().__init__(env)
        from agents.caregivers.scripted import make_scripted
        from coop_gym.envs.contract import observation_features

        self.guide = make_scripted("oracle", observation_features("oracle", "kalman"), "discrete")
        self.prefix_rng = np.random.default_rng()
        self.max_steps = round(MID_GUIDANCE_MAX_S / env.unwrapped.timing.action_period_s)  # type: ignore[attr-defined]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        observation, info = self.env.reset(seed=seed, options=options)
        if seed is not None:
            self.prefix_rng = np.random.default_rng(seed)
        if self.prefix_rng.random() >= MID_GUIDANCE_SHARE:
            return observation, info
        self.guide.reset()
        for _ in range(int(self.prefix_rng.integers(1, self.max_steps + 1))):
            features = np.append(info.get("unscaled_obs", observation), info["true_xi"])
            action, _ = self.guide.predict(features)
            if np.unravel_index(int(action), (3, 3, 2))[2] == 1:  # the oracle would lift: hand over here
                break
            observation, _, _, _, info = self.env.step(int(action))
        return observation, info


CURRICULUM_EASY_ENV_ID = "CoopGym/SitToStandDiscreteUnit-v0"
"""The curriculum's first level: the paper's (its personas and timing), CleanRL's interface as on the hard id."""
CURRICULUM_EASY_SB3_ENV_ID = "CoopGym/SitToStand-v0"
"""The same level on the interface SB3's defaults train on (``CoopGym/SitToStandHard-v2``'s spaces)."""
CURRICULUM_STEPS = 100_000
"""The learner's steps (all its envs: :data:`OUTCOME_LOG`'s count) after which :class:`Curriculum` plays hard."""


class Curriculum(gym.Wrapper[Any, Any, Any, Any]):
    """Episodes of ``easy_id`` (:data:`CURRICULUM_EASY_ENV_ID`) until the process has taken :data:`CURRICULUM_STEPS`
    steps, then the wrapped (hard) id's: a curriculum of levels by id inside one training run, at episode boundaries.

    Both levels have the same observations and actions, so the learner sees one env. A start of a training run,
    not an env version: each episode is one of the two ids' own. A seeded reset seeds both levels, so the hard
    episodes after the switch follow the run's seed as the easy ones before it do.
    """

    def __init__(self, env: gym.Env[Any, Any], easy_id: str = CURRICULUM_EASY_ENV_ID) -> None:
        super().__init__(env)
        self.easy = gym.make(easy_id)
        if self.easy.observation_space != env.observation_space or self.easy.action_space != env.action_space:
            raise ValueError(f"Curriculum: {easy_id} and {env.spec and env.spec.id} differ in spaces")
        self.active: gym.Env[Any, Any] = self.easy

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        self.active = self.easy if _STEPS_TAKEN[0] < CURRICULUM_STEPS else self.env
        if seed is not None:  # the level not playing now takes the seed too
            (self.env if self.active is self.easy else self.easy).reset(seed=seed)
        return self.active.reset(seed=seed, options=options)

    def step(self, action: Any) -> tuple[Any, Any, bool, bool, dict[str, Any]]:
        return self.active.step(action)  # type: ignore[return-value]

    def close(self) -> None:
        self.easy.close()
        super().close()


def make_study_env(**kwargs: Any) -> gym.Env[Any, Any]:
    """The id ``base`` made as registered (the other keywords its own), its timeout priced (:class:`PricedTimeout`)
    if ``priced``, started by :class:`MidGuidance` if ``mid_guidance``, after the easy level if ``curriculum``
    (:class:`Curriculum`), outermost in :class:`OutcomeLog`."""
    priced, mid_guidance = kwargs.pop("priced", False), kwargs.pop("mid_guidance", False)
    curriculum = kwargs.pop("curriculum", False)
    env = gym.make(kwargs.pop("base"), **kwargs)
    env = PricedTimeout(env) if priced else env
    env = MidGuidance(env) if mid_guidance else env
    return OutcomeLog(Curriculum(env) if curriculum else env)


STUDY_ENV_IDS: dict[str, dict[str, Any]] = {
    "Logged/SitToStandHardDiscreteUnit-v2": {"base": CLEANRL_ENV_ID},
    "Logged/SitToStandHardDiscrete-v2": {"base": "CoopGym/SitToStandHardDiscrete-v2"},
    "LoggedMidGuidance/SitToStandHardDiscreteUnit-v2": {"base": CLEANRL_ENV_ID, "mid_guidance": True},
    "LoggedPriced/SitToStandHardDiscreteUnit-v2": {"base": CLEANRL_ENV_ID, "priced": True},
    "LoggedCurriculum/SitToStandHardDiscreteUnit-v2": {"base": CLEANRL_ENV_ID, "curriculum": True},
    "LoggedPopulation/SitToStandHardDiscreteUnit-v2": {"base": CLEANRL_ENV_ID, "personas": "train_population"},
}
"""Measurement aids, not env versions: what CleanRL's script trains on in the never-lift study
(``--env-id cleanrl_defaults:<id>``; ``gym.make`` passes no keyword, so each id's settings are in its
registration). Each logs its outcomes; the policies are scored on the ``base`` ids."""
for _id, _settings in STUDY_ENV_IDS.items():
    if _id not in gym.registry:
        gym.register(_id, entry_point=make_study_env, kwargs=_settings)


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
