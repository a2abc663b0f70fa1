"""Learner x observation on the hard level: one budget, the same held-out episodes, several seeds.

    python bench/learners.py [--rows ppo-kalman,ppo-raw,...] [--seeds 0,1,2,3,4] [--timesteps 1000000]
                             [--episodes 2000] [--runs DIR] [--people] [--save [PATH]]

Does the paper's estimator help a learner, and can memory replace it? Each row is a learner
and the observation it gets (:data:`ROWS`):

- ``ppo-kalman``: SB3's PPO (MLP) on the default observation, the paper's Kalman estimate of ``xi`` beside
  the measurements (``python train.py --framework sb3``); ``ppo-switching``: + the switching filter's
  ``P(xi)`` (:data:`SWITCHING`); ``ppo-raw``: the measurements alone; ``recurrent-raw`` / ``recurrent-kalman``:
  sb3-contrib's RecurrentPPO (an LSTM: memory) on the measurements alone / on the default observation;
- ``jax-kalman`` / ``jax-switching`` / ``jax-raw``: the same PPO trained by ``train.py``'s learner,
  :class:`agents.ppo.PPO`, on its sizing with ``policy_lag=0`` (``python train.py --policy-lag 0``);
  ``jax-lstm-raw`` / ``jax-lstm-kalman`` / ``jax-lstm-population`` (across bodies): the recurrent rows trained
  by :class:`agents.ppo.recurrent.RecurrentPPO` (PPO's settings, an LSTM before the heads); ``ROW@N``
  (a ``jax-*`` row on ``N`` envs, ``n_steps`` scaled so an update still takes the same
  samples) and ``ROW@N-eE`` (the same with ``E`` epochs per update) compare sizings;
  ``jax-unit``, ``jax-kalman-lag`` (``train.py``'s default), ``jax-kalman-lag-population`` (trained across
  bodies), ``jax-switching-*``, ``jax-discreteunit``: variations of ``jax-kalman``, each row's ``what``;
  records saved before these rows moved to ``agents.ppo`` hold ``jax-*`` rows trained by ``JaxPPO`` and
  ``JaxRecurrentPPO`` (each record's ``what`` names its learner);
- ``cleanrl-*``: CleanRL's public ``ppo.py`` as its user runs it (``--cleanrl-script PATH``; the script is
  not part of coop_gym, see ``bench/cleanrl_defaults.py``), given :data:`CLEANRL_ENV_ID`, its final policy
  greedy: ``cleanrl-ppo`` unmodified on its defaults (the library-defaults row), the others with the flags,
  people or reward wrapper their ``what`` names (:data:`TRAINPY_FLAGS`: all of ``train.py``'s PPO settings);
- ``ROW-stackK`` (e.g. ``ppo-raw-stack16``): an SB3 row with its last ``K`` observations stacked
  into one (SB3's ``VecFrameStack``): memory of a fixed window of ``K`` x 0.1 s.

Every run follows ``train.py``'s protocol on ``CoopGym/SitToStandHard-v2``: the algorithm's settings from
:mod:`agents.hyperparams` with the budget ``--timesteps`` and the wider training personas (or the row's), the
best-validated policy of the last half kept (:class:`agents.rl.SelectionCallback`, training personas only),
then ``--episodes`` held-out episodes (test personas, seeds ``0..N-1``: the episodes of ``bench/levels.py``),
which the scripted oracle, best blind, prober and belief caregiver play too. Each row reports, over its
training seeds, the interquartile mean of the held-out success rate and of the mind-reading score
``(success - blind) / (oracle - blind)`` with a stratified bootstrap 95 % interval (rliable's method,
:func:`agents.evaluate.headroom.iqm_across_runs`) and the training wall time.

Each finished (row, seed) is written to ``--runs DIR/<row>__<seed>.json`` (with the kept model beside
it) as soon as it is done; a rerun with the same ``--runs`` skips what is there, so an interrupted sweep
loses only the run in progress. Each run's file also holds its kept policy's score on the validation
people, ``validation_people``: what a choice of settings is made on, never the held-out score.
``--no-train`` reports the runs there and trains none (rows may then have different seeds). ``--save``
writes the report to ``bench/results/learners.json`` (``bench/result_files.py``). ``--people`` has every
scored policy also play the validation people and the held-out episodes: each row's ``people`` says how
well each selecting set predicts the held-out people (``bench/results/selection_people.json``).
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import statistics
import sys
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import (
    CLEANRL_ENV_ID,
    add_save_argument,
    import_learners,
    iqm_ci,
    kept_json,
    rates,
    resized,
    save,
    sizing,
)

from coop_gym.cli import positive_int, seed_list
from coop_gym.registration import HARD_ENV_ID

ENV_ID = HARD_ENV_ID
SCRIPTED = ("oracle", "blind", "prober", "belief")
"""The reference caregivers played on the same episodes (``blind`` is the widened blind family's best)."""


@dataclass(frozen=True)
class Row:
    """A learner and the observation it trains on."""

    algo: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)
    what: str = ""
    framework: str = "sb3"
    frame_stack: int = 1
    env_id: str = ENV_ID
    train_env: str = ""
    """What CleanRL's script gets as ``--env-id`` (``module:id``); empty: ``coop_gym:`` + ``env_id``."""
    script_args: tuple[str, ...] = ()
    """Flags CleanRL's script gets beyond its defaults (e.g. ``("--ent-coef", "0.02")``)."""
    normalize: bool = True
    """Whether observations pass through ``VecNormalize``, as ``train.py``'s do (not CleanRL's script's)."""
    algo_kwargs: dict[str, Any] = field(default_factory=dict)
    """The learner's settings beyond ``train.py``'s (e.g. ``{"policy_lag": 1}``). A ``jax`` PPO row without
    ``policy_lag`` here runs ``policy_lag=0``, whatever ``train.py``'s default."""
    personas: str = "train_wide"
    """The people trained on (``train.py``'s wider training personas, or ``"train_population"``)."""


SWITCHING: dict[str, Any] = {"estimator": "switching", "estimator_options": {"n_particles": 256, "hypotheses": 32}}
"""The switching rows' filter: the light one ``hard-ppo-switching`` trains and plays with. A filter step's
work grows with its particles, so the default filter (1024 particles, 128 hypotheses, what the belief
caregiver reads) would make each run several times longer (the rows' training time: ``train_wall_s`` in
``bench/results/learners.json``)."""
_TRUE_PERSON = {"n_particles": 256, "hypotheses": 1, "true_person": True}
SWITCHING_TRUE: dict[str, Any] = {"estimator": "switching", "estimator_options": _TRUE_PERSON}
"""The switching filter given each episode's true person: what a caregiver that had identified the person reads."""

TRAINPY_FLAGS = (
    "--num-envs", "16", "--num-steps", "256", "--num-minibatches", "8", "--update-epochs", "10",
    "--learning-rate", "3e-4", "--gamma", "0.995", "--ent-coef", "0.02", "--no-clip-vloss",
)  # fmt: skip
"""CleanRL ``ppo.py``'s flags for ``train.py``'s PPO settings on the hard level
(:func:`agents.hyperparams.hyperparams_for` with ``JAX_SIZING``): the same rollout,
minibatch, epochs, learning rate (both decay linearly), discount, entropy bonus and no value
clipping. What stays the script's: its personas, no observation normalisation, its final policy."""

WIDE_TRAIN_ENV = "cleanrl_defaults:WidePersonas/SitToStandHardDiscreteUnit-v2"
"""What CleanRL's script trains on for the wider personas (``bench/cleanrl_defaults.py``'s ``WIDE_ENV_ID``)."""

DISCRETE_UNIT: dict[str, Any] = {"action_type": "discrete", "observation_scale": "unit"}
"""The keywords that make :data:`ENV_ID` into :data:`CLEANRL_ENV_ID`."""
_NO_NORM = "SitToStandHardDiscreteUnit-v2's 18 joint actions and unit-scaled observations, no observation normaliser"

_POP = "train_population"
ROWS: dict[str, Row] = {
    "ppo-kalman": Row("ppo", {}, "SB3's PPO (MLP), Kalman estimate + measurements (train.py --framework sb3)"),
    "ppo-switching": Row("ppo", SWITCHING, "PPO (MLP), + switching filter's P(xi) (256 particles, 32 hypotheses)"),
    "ppo-raw": Row("ppo", {"observation_mode": "raw"}, "PPO (MLP), measurements only"),
    "recurrent-raw": Row("recurrent_ppo", {"observation_mode": "raw"}, "RecurrentPPO (LSTM), measurements only"),
    "recurrent-kalman": Row("recurrent_ppo", {}, "RecurrentPPO (LSTM), Kalman estimate + measurements"),
    "jax-kalman": Row("ppo", {}, "agents.ppo, Kalman estimate + measurements (train.py --policy-lag 0)", "jax"),
    "jax-kalman-lag": Row(
        "ppo",
        {},
        "agents.ppo, policy_lag=1 (each update runs while the next rollout plays), Kalman estimate + measurements"
        " (train.py's default)",
        "jax",
        algo_kwargs={"policy_lag": 1},
    ),
    "jax-kalman-lag-population": Row(
        "ppo",
        {},
        "jax-kalman-lag trained across bodies: 512 persons of the validation people's population (train_population)",
        "jax",
        algo_kwargs={"policy_lag": 1},
        personas=_POP,
    ),
    "jax-switching-population": Row(
        "ppo",
        SWITCHING,
        "jax-kalman-lag-population + the switching filter's P(xi) (32 person hypotheses weighed in each episode)",
        "jax",
        algo_kwargs={"policy_lag": 1},
        personas=_POP,
    ),
    "jax-switching-true-population": Row(
        "ppo",
        SWITCHING_TRUE,
        "jax-switching-population with the filter given each episode's true person (the bound of identifying them)",
        "jax",
        algo_kwargs={"policy_lag": 1},
        personas=_POP,
    ),
    "jax-switching": Row(
        "ppo", SWITCHING, "agents.ppo, + switching filter's P(xi) (256 particles, 32 hypotheses)", "jax"
    ),
    "jax-raw": Row("ppo", {"observation_mode": "raw"}, "agents.ppo, measurements only", "jax"),
    "jax-lstm-raw": Row(
        "recurrent_ppo",
        {"observation_mode": "raw"},
        "agents.ppo's RecurrentPPO (LSTM: memory), measurements only",
        "jax",
    ),
    "jax-lstm-kalman": Row(
        "recurrent_ppo", {}, "agents.ppo's RecurrentPPO (LSTM), Kalman estimate + measurements", "jax"
    ),
    "jax-lstm-population": Row(
        "recurrent_ppo", {}, "jax-lstm-kalman trained across bodies (train_population)", "jax", personas=_POP
    ),
    "jax-unit": Row(
        "ppo",
        {"observation_scale": "unit"},
        "agents.ppo, unit-scaled observations (SitToStandHardUnit-v2) instead of the observation normaliser",
        "jax",
        normalize=False,
    ),
    "jax-discreteunit": Row(
        "ppo", DISCRETE_UNIT, "agents.ppo on CleanRL's interface, " + _NO_NORM, "jax", normalize=False
    ),
    "cleanrl-ppo": Row(
        "ppo",
        {},
        "CleanRL's ppo.py unmodified on its defaults (its personas, no selection), SitToStandHardDiscreteUnit-v2",
        "cleanrl",
        env_id=CLEANRL_ENV_ID,
    ),
    "cleanrl-ppo-priced": Row(
        "ppo",
        {},
        "CleanRL's ppo.py on its defaults, trained with a timeout priced as a failed assistance (-1), scored on the id",
        "cleanrl",
        env_id=CLEANRL_ENV_ID,
        train_env="cleanrl_defaults:PricedTimeout/SitToStandHardDiscreteUnit-v2",
    ),
    "cleanrl-ppo-ent02": Row(
        "ppo",
        {},
        "CleanRL's ppo.py on its defaults but train.py's entropy bonus (--ent-coef 0.02), "
        "SitToStandHardDiscreteUnit-v2",
        "cleanrl",
        env_id=CLEANRL_ENV_ID,
        script_args=("--ent-coef", "0.02"),
    ),
    "cleanrl-ppo-trainpy": Row(
        "ppo",
        {},
        "CleanRL's ppo.py with train.py's PPO settings as its flags (16 x 256 rollouts, 8 minibatches, "
        "10 epochs, lr 3e-4, gamma 0.995, entropy 0.02, no value clipping), its personas, no selection",
        "cleanrl",
        env_id=CLEANRL_ENV_ID,
        script_args=TRAINPY_FLAGS,
    ),
    "cleanrl-ppo-rollout": Row(
        "ppo",
        {},
        "CleanRL's ppo.py on its defaults but train.py's rollout and update size (16 x 256 rollouts, "
        "8 minibatches, 10 epochs), its personas, no selection",
        "cleanrl",
        env_id=CLEANRL_ENV_ID,
        script_args=TRAINPY_FLAGS[:8],
    ),
    "cleanrl-ppo-loss": Row(
        "ppo",
        {},
        "CleanRL's ppo.py on its defaults but train.py's learning rate, discount, entropy bonus and "
        "no value clipping, its personas, no selection",
        "cleanrl",
        env_id=CLEANRL_ENV_ID,
        script_args=TRAINPY_FLAGS[8:],
    ),
    "cleanrl-ppo-trainpy-wide": Row(
        "ppo",
        {},
        "CleanRL's ppo.py with train.py's PPO settings as its flags, trained on train.py's wider personas, "
        "no selection",
        "cleanrl",
        env_id=CLEANRL_ENV_ID,
        train_env=WIDE_TRAIN_ENV,
        script_args=TRAINPY_FLAGS,
    ),
    "cleanrl-ppo-wide": Row(
        "ppo",
        {},
        "CleanRL's ppo.py on its defaults, trained on train.py's wider personas, no selection",
        "cleanrl",
        env_id=CLEANRL_ENV_ID,
        train_env=WIDE_TRAIN_ENV,
    ),
}
"""The rows. ``ROW-stackK`` is SB3 row ``ROW`` on its last ``K`` observations (SB3's ``VecFrameStack``:
memory of a fixed window, 0.1 s per frame); ``ROW@N`` is a ``jax-*`` row on ``N`` envs, ``ROW@N-eE``
the same with ``E`` epochs per update."""


def _row(name: str) -> tuple[Row, str]:
    """The row of a name (``ROW``, ``ROW-stackK``, ``ROW@N``, ``ROW@N-eE``) and its sizing (``""``: the row's own)."""
    base, _, size = name.partition("@")
    stacked = re.fullmatch(r"(.+)-stack([1-9][0-9]*)", base)
    key = stacked.group(1) if stacked else base
    if key not in ROWS or ((size or stacked) and ROWS[key].framework == "cleanrl"):
        raise KeyError(name)
    if stacked and ROWS[key].framework == "jax":  # agents.ppo stacks no frames
        raise KeyError(name)
    if size and (sizing(size) is None or ROWS[key].framework != "jax"):
        raise KeyError(name)
    row = ROWS[key]
    if stacked:
        k = int(stacked.group(2))
        row = dataclasses.replace(row, frame_stack=k, what=f"{row.what}, last {k} observations stacked")
    return row, size


def _rows(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = []
    for n in names:
        try:
            _row(n)
        except KeyError:
            unknown.append(n)
    if unknown or not names:
        known = f"{', '.join(ROWS)} (also ROW-stackK of an SB3 row; jax-* rows: ROW@N, ROW@N-eE)"
        raise argparse.ArgumentTypeError(f"unknown row(s) {unknown}; known: {known}")
    return names


def train_cleanrl(
    name: str, script: Path, seed: int, timesteps: int, episodes: int, folder: Path, validation: int
) -> dict[str, Any]:
    """Run CleanRL's script on its defaults with ``seed``, save its agent, score it (greedy) held-out."""
    import torch
    from cleanrl_defaults import run_script

    from agents.evaluate import evaluate
    from agents.rl.callbacks import VALIDATION_PERSONAS, VALIDATION_SEED
    from coop_gym.io import save_with

    row, _ = _row(name)
    agent, run = run_script(script, row.train_env or f"coop_gym:{row.env_id}", timesteps, seed, row.script_args)
    state = agent.module.state_dict()
    save_with(folder / f"{name}__{seed}__{timesteps}.pt", lambda temp: torch.save(state, temp))
    checked = evaluate(agent, row.env_id, VALIDATION_PERSONAS, validation, VALIDATION_SEED)
    # The validation people, not the training personas' episodes: what a choice of flags is made on.
    people = evaluate(agent, row.env_id, "validation", validation, VALIDATION_SEED).summary()
    result = evaluate(agent, row.env_id, "test", episodes, 0, name=f"{name}:{seed}")
    return {
        **result.summary(),
        "row": name,
        "training_seed": seed,
        "timesteps": timesteps,
        "train_wall_s": run["wall_time_s"],
        "kept_step": timesteps,
        "validation_success_rate": checked.success_rate,
        "validation_people": rates(people),
        "script_command": run["script_command"],
        "script_sha256": run["script_sha256"],
    }


def train_one(
    name: str, seed: int, timesteps: int, episodes: int, folder: Path, validation: int, people: bool = False
) -> dict[str, Any]:
    """Train row ``name`` as ``train.py`` does, keep the best-validated policy, score it held-out (``people``: see
    :func:`people_report`; every scored policy also plays the validation people and the held-out episodes)."""
    import torch

    from agents.evaluate import evaluate
    from agents.hyperparams import hyperparams_for
    from agents.rl import SelectionCallback, load_agent, save_agent
    from agents.rl.callbacks import VALIDATION_SEED

    torch.set_num_threads(1)  # as train.py --threads
    row, size = _row(name)
    config = hyperparams_for(row.algo, ENV_ID, row.framework)
    sequential = {"policy_lag": 0} if row.algo == "ppo" and row.framework == "jax" else {}
    config = config.replace(
        total_timesteps=timesteps,
        personas=row.personas,
        normalize=config.normalize and row.normalize,
        algo_kwargs={**config.algo_kwargs, **sequential, **row.algo_kwargs},
    )
    if size:  # the same samples per update on N envs (and E epochs)
        try:
            config = resized(config, size)
        except ValueError as error:
            raise ValueError(f"{name}: {error}") from None
    half = timesteps // 2
    every = max(1, (timesteps - half) // 8)
    checkpoints = folder / f"{name}__{seed}__{timesteps}_checkpoints"
    recorded = {"validation": ("validation", validation, VALIDATION_SEED), "test": ("test", episodes, 0)}
    selection = SelectionCallback(
        checkpoints, row.algo, ENV_ID, validation, 8, half, every, row.env_kwargs, recorded=recorded if people else None
    )
    started = time.perf_counter()
    model, selected = _learn(row, config, seed, timesteps, selection)
    wall_s = time.perf_counter() - started
    saved = save_agent(model, folder / f"{name}__{seed}__{timesteps}", algo=row.algo, env_id=ENV_ID)
    agent = load_agent(saved)  # what a user loads, not the object in memory
    result = evaluate(agent, ENV_ID, "test", episodes, 0, env_kwargs=row.env_kwargs, name=f"{name}:{seed}")
    on_people = evaluate(agent, ENV_ID, "validation", validation, VALIDATION_SEED, env_kwargs=row.env_kwargs).summary()
    return {
        **result.summary(),  # its "seed" is the first held-out episode's
        "by_persona": result.persona_rates(),
        "row": name,
        "training_seed": seed,
        "timesteps": timesteps,
        "train_wall_s": wall_s,
        "kept_step": selected["timesteps"],
        "validation_success_rate": selected["validation_success_rate"],
        "validation_people": rates(on_people),
        **({"candidates": selected["scores"]} if people else {}),
    }


def _learn(row: Row, config: Any, seed: int, timesteps: int, selection: Any) -> tuple[Any, dict[str, Any]]:
    """``(model, selected)``: row ``row`` trained (a ``jax`` row by ``agents.ppo`` on coop_gym's vector env, the
    others by SB3 on SB3's), the policy kept."""
    if row.framework == "jax":
        from agents.rl.ppo_run import learn_selected, make_learner

        learner = make_learner(config, ENV_ID, seed, row.env_kwargs)
        trained, selected = learn_selected(learner, timesteps, selection)
        learner.env.close()
        return trained, selected  # type: ignore[return-value]
    from stable_baselines3.common.vec_env import VecFrameStack

    from agents.rl import make_model, make_train_env

    env = make_train_env(
        ENV_ID, config.n_envs, seed, personas=config.personas, normalize=config.normalize, env_kwargs=row.env_kwargs
    )
    if row.frame_stack > 1:  # normalised frames stacked (what the saved agent rebuilds when it plays)
        env = VecFrameStack(env, row.frame_stack)
    model = make_model(config, env, seed)
    model.learn(timesteps, callback=selection)
    env.close()
    return model, selection.finish(model)


def people_report(runs: list[dict[str, Any]]) -> dict[str, Any] | None:
    """Over a row's runs with ``candidates``: how well the training personas' validation episodes
    (``train``, today's selection) and the validation people (``validation``) predict the held-out
    people, and what each keeps (:func:`agents.evaluate.headroom.selection_study`); None without them."""
    from agents.evaluate.headroom import selection_study

    if len(runs) < 3 or not all("candidates" in run for run in runs):
        return None
    scored = [[{**p, "train": {"success_rate": p["success_rate"]}} for p in run["candidates"]] for run in runs]
    return selection_study(scored, ("train", "validation"))


def scripted(episodes: int) -> dict[str, dict[str, Any]]:
    """The reference caregivers on the held-out episodes (each with its rates per persona, ``by_persona``)."""
    from agents.evaluate import evaluate

    results = {name: evaluate(name, ENV_ID, "test", episodes, 0) for name in SCRIPTED}
    return {name: {**result.summary(), "by_persona": result.persona_rates()} for name, result in results.items()}


def rescore_by_persona(name: str, run: dict[str, Any], folder: Path, timesteps: int) -> dict[str, Any]:
    """``run`` with the per-persona rates of its saved model replayed on the same held-out episodes.

    Raises:
        ValueError: the replay does not reproduce the run's recorded success (another model, or other episodes).
    """
    from agents.evaluate import evaluate
    from agents.rl import load_agent

    seed = run["training_seed"]
    agent = load_agent(folder / f"{name}__{seed}__{timesteps}")
    result = evaluate(agent, ENV_ID, "test", run["episodes"], 0, env_kwargs=_row(name)[0].env_kwargs)
    if result.success_rate != run["success_rate"]:
        raise ValueError(f"{name} seed {seed}: replayed success {result.success_rate} != {run['success_rate']}")
    return {**run, "by_persona": result.persona_rates()}


def aggregate(runs: list[dict[str, Any]], blind: float, oracle: float) -> dict[str, Any]:
    """IQM of success and of the mind-reading score over a row's runs, with stratified bootstrap intervals."""
    success = [r["success_rate"] for r in runs]
    # The score is undefined where the oracle does not beat the best blind policy (nothing to read).
    scores = [(s - blind) / (oracle - blind) for s in success] if oracle > blind else []
    out: dict[str, Any] = {"runs": len(runs), "training_seeds": [r["training_seed"] for r in runs]}
    out["score"] = {"iqm": None, "ci95": [None, None]}
    for key, values in (("success", success), ("score", scores)):
        if values:
            out[key] = iqm_ci(values)
    out["min_success"] = min(success)
    out["unsafe_rate_mean"] = statistics.fmean(r["unsafe_rate"] for r in runs)
    out["train_wall_s_median"] = statistics.median(r["train_wall_s"] for r in runs)
    return out


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python bench/learners.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", type=_rows, default=list(ROWS), help=f"comma-separated, of {', '.join(ROWS)}")
    parser.add_argument("--seeds", type=seed_list, default=[0, 1, 2, 3, 4], help="training seeds, joined by ','")
    parser.add_argument("--timesteps", type=positive_int, default=1_000_000, help="training budget per run")
    parser.add_argument("--episodes", type=positive_int, default=2000, help="held-out episodes per agent")
    parser.add_argument("--validation-episodes", type=positive_int, default=1000, help="per selection score")
    parser.add_argument("--runs", type=Path, default=Path("runs/learners"), help="folder of finished runs")
    parser.add_argument(
        "--no-train", action="store_true", help="report the (row, seed) runs already in --runs; train none"
    )
    parser.add_argument(
        "--cleanrl-script", type=Path, default=None, help="CleanRL's ppo.py, to train the cleanrl-* rows"
    )
    parser.add_argument(
        "--people",
        action="store_true",
        help="score every candidate policy on the validation people and the held-out episodes too: how well "
        "each selecting set predicts the held-out people (the report's 'people' of each row)",
    )
    parser.add_argument(
        "--by-persona",
        action="store_true",
        help="replay the saved model of each run without a per-persona record on its held-out episodes, and "
        "report each row's rates per test persona beside the scripted caregivers'",
    )
    add_save_argument(parser, "learners.json")
    return parser


def _row_runs(name: str, args: argparse.Namespace, parser: argparse.ArgumentParser) -> list[dict[str, Any]]:
    """Row ``name``'s finished runs over ``--seeds``, each trained first unless in ``--runs`` (or ``--no-train``)."""
    from coop_gym.io import write_json

    runs = []
    for seed in args.seeds:
        path = args.runs / f"{name}__{seed}__{args.timesteps}.json"
        found = kept_json(path, None if args.no_train else partial(_train, name, seed, args))
        if found is None:
            continue
        run = {**found, "training_seed": seed}  # the file's name holds the seed
        if run["episodes"] != args.episodes:
            parser.error(f"{path} was scored on {run['episodes']} episodes, not --episodes {args.episodes}")
        if args.by_persona and "by_persona" not in run and _row(name)[0].framework != "cleanrl":
            run = rescore_by_persona(name, run, args.runs, args.timesteps)
            write_json(path, run)  # the file's own keys (its training_seed too) and the rates per persona
        runs.append(run)
        print(f"{name:>17} seed {seed}: success {run['success_rate']:.3f}", file=sys.stderr)
    if not runs:
        parser.error(f"--no-train: no run of {name} in {args.runs} for --seeds {args.seeds}")
    return runs


def _train(name: str, seed: int, args: argparse.Namespace) -> dict[str, Any]:
    """One (row, seed) run of ``name``: CleanRL's script for a ``cleanrl-*`` row, else :func:`train_one`."""
    timesteps, episodes, validation = args.timesteps, args.episodes, args.validation_episodes
    if _row(name)[0].framework == "cleanrl":
        return train_cleanrl(name, args.cleanrl_script, seed, timesteps, episodes, args.runs, validation)
    return train_one(name, seed, timesteps, episodes, args.runs, validation, args.people)


def _what(name: str) -> str:
    """Row ``name``'s description, with its sizing if it has one."""
    row, size = _row(name)
    found = sizing(size) if size else None
    if found is None:
        return row.what
    return row.what + f", {found[0]} envs" + (f", {found[1]} epochs" if found[1] is not None else "")


def main(argv: list[str] | None = None) -> int:
    """Train and score every (row, seed) not yet in ``--runs``; print the table (and save it)."""
    parser = _parser()
    args = parser.parse_args(argv)
    from agents.evaluate.results import persona_rates_over_runs
    from coop_gym.cli import output_path_problem
    from coop_gym.io import write_json

    problem = output_path_problem(str(args.runs), folder=True)
    if problem:
        parser.error(f"--runs: {problem}")
    to_run = [
        name
        for name in args.rows
        for seed in args.seeds
        if not (args.runs / f"{name}__{seed}__{args.timesteps}.json").exists()
    ]
    needs_script = not args.no_train and any(_row(name)[0].framework == "cleanrl" for name in to_run)
    if needs_script and (args.cleanrl_script is None or not args.cleanrl_script.is_file()):
        parser.error(f"--cleanrl-script: the cleanrl-* rows need CleanRL's ppo.py, got {args.cleanrl_script}")

    args.runs.mkdir(parents=True, exist_ok=True)
    reference_file = args.runs / f"scripted__{args.episodes}.json"
    reference = kept_json(reference_file, lambda: scripted(args.episodes))
    if args.by_persona and "by_persona" not in reference["oracle"]:  # kept by a run without --by-persona
        reference = scripted(args.episodes)
        write_json(reference_file, reference)
    blind, oracle = reference["blind"]["success_rate"], reference["oracle"]["success_rate"]
    table: dict[str, Any] = {}
    for name in args.rows:
        runs = _row_runs(name, args, parser)
        table[name] = {"what": _what(name), **aggregate(runs, blind, oracle), "per_seed": runs}
        if (people := people_report(runs)) is not None:
            table[name]["people"] = people
        if all("by_persona" in run for run in runs):
            table[name]["by_persona"] = persona_rates_over_runs([run["by_persona"] for run in runs])
    for name, row in table.items():
        s, c = row["success"], row["score"]
        print(f"{name:>17}: success IQM {s['iqm']:.3f} {s['ci95']}, score IQM {c['iqm']} {c['ci95']}")
    report = {
        "env_id": ENV_ID,
        "timesteps": args.timesteps,
        "episodes": args.episodes,
        "rows": table,
        "scripted": {k: {m: v[m] for m in ("success_rate", "unsafe_rate")} for k, v in reference.items()},
    }
    if all("by_persona" in v for v in reference.values()):
        report["scripted_by_persona"] = {k: v["by_persona"] for k, v in reference.items()}
    if args.save:
        import_learners(jax=any(_row(name)[0].framework == "jax" for name in args.rows))
        save(args.save, "learners", argv, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
