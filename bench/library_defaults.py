"""What a newcomer gets: SB3 with library-default hyperparameters on the registered ids.

Trains ``PPO("MlpPolicy", "CoopGym/SitToStand-v0")`` or
``DQN("MlpPolicy", "CoopGym/SitToStandDiscrete-v0")`` exactly as a user would write it
(one env, SB3's defaults, no normalisation), saves the model and scores it with the common
evaluation path (:func:`agents.evaluate.evaluate`) on ``--episodes`` held-out episodes
(seeds 0..N-1), beside the handbook caregiver on the same episodes of ``CoopGym/SitToStand-v0``
(the same model and people; the reference of every score)::

    nice python bench/library_defaults.py --algo ppo --timesteps 300000 --out runs/defaults

``--env ID`` trains on another registered id, e.g. the unit-scaled ``CoopGym/SitToStandUnit-v0``
(the model is saved as ``{algo}_{name}_{timesteps}.zip``).

``--snapshot-at 300000`` also saves (and scores) the model when training first passes 300k
steps, as ``{algo}_{name}_300000.zip``. With PPO's defaults (constant learning rate and clip
range) that model is the one a 300k-step run gives; DQN's exploration schedule spans the whole
run, so for DQN train a separate 300k run instead.

``--save`` also writes the report to ``bench/results/library_defaults_<algo>_<env>_<timesteps>.json``
(``bench/result_files.py``; ``<env>`` is the id's name after ``CoopGym/``).

``--seeds`` measures the hard level over training seeds instead, each learner as its user writes
it (:data:`LEARNERS`), on ``CoopGym/SitToStandHard-v2``::

    python bench/library_defaults.py --seeds 0,1,2,3,4 [--learners sb3-defaults,sb3-settings]
                                     [--episodes 2000] [--runs DIR] [--save [PATH]]

- ``sb3-defaults``: ``PPO("MlpPolicy", make_vec_env(id, n_envs=8, seed=seed), seed=seed)``,
  300k steps: SB3's defaults, no normalisation, the id's own personas;
- ``sb3-settings``: the package's settings as an SB3 script takes them
  (:func:`agents.rl.sb3_settings`): ``PPO(settings.policy, settings.make_env(seed), seed=seed,
  **settings.hyperparams).learn(settings.total_timesteps)``;
- ``rl-zoo``: RL Zoo's command of docs/integrations.md (:data:`ZOO_COMMAND`, ``-conf agents.zoo.ppo``:
  the shipped hyperparameters) with ``--seed``, its final model loaded by the package's loader.

``--timesteps N`` trains every learner N steps instead (a quick check of the script); ``--no-train``
scores the models already in ``--runs`` (a learner's row then holds the seeds it has).

The final policy is kept (no selection), saved as ``DIR/<learner>__<seed>.zip`` (a rerun with the
same ``--runs`` skips what is there), and all are scored in one ``python -m agents.evaluate
--compare ...,blind,prober,belief,oracle --personas test`` on the same seeded held-out episodes:
per seed the success and the never-lift rate (episodes ending in a timeout), over seeds the
interquartile mean of success with a stratified bootstrap 95 % interval
(:func:`agents.evaluate.headroom.iqm_across_runs`). ``--save`` writes
``bench/results/library_seeds_SitToStandHard-v2.json``. CleanRL's ``ppo.py`` over seeds, on its
defaults and with the documented flags: ``bench/learners.py`` (rows ``cleanrl-ppo``,
``cleanrl-ppo-trainpy``).

``--study never-lift`` asks why CleanRL's defaults settle on never lifting there, by measurement::

    python bench/library_defaults.py --study never-lift --seeds 0,1,2,3,4 --cleanrl-script ppo.py
                                     [--cells cleanrl-ppo,...] [--timesteps 300000] [--episodes 500] [--save]

Each cell of :data:`NEVER_LIFT_CELLS` (CleanRL's script on its defaults; on the id without unit
scaling; with half its training episodes begun mid-guidance; with a timeout priced as a failed
assistance; with ``train.py``'s entropy bonus, its rollout and update size, or all its PPO settings as
flags; SB3's defaults) trains once per seed with every training episode's outcome logged at its
global step (``bench/cleanrl_defaults.py``'s ``OutcomeLog``: when the first successful lift came, when
lifting stopped, how many successes came before). Its final policy (greedy) and the scripted rows play the
same ``--episodes`` episodes of the validation people and of the training personas, never the test
personas; :func:`lift_hazard_sweep` adds what a policy that cues at random and lifts with a fixed
probability meets. ``--save`` writes ``bench/results/never_lift_SitToStandHard-v2.json``.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
import numpy as np
import torch
from learners import TRAINPY_FLAGS
from numpy.typing import NDArray
from result_files import (
    CLEANRL_ENV_ID,
    RESULTS,
    ROOT,
    add_save_argument,
    held_out_report,
    iqm_ci,
    kept_json,
    rates,
    save,
)
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.callbacks import BaseCallback

import coop_gym  # registers the ids
from agents.rl import SB3Agent
from coop_gym.cli import positive_int, seed_list
from coop_gym.registration import HARD_ENV_ID

ENV_IDS = {"ppo": "CoopGym/SitToStand-v0", "dqn": "CoopGym/SitToStandDiscrete-v0"}
HARD_ID = HARD_ENV_ID
SCRIPTED = ("blind", "prober", "belief", "oracle")
DEFAULTS_TIMESTEPS = 300_000
"""The budget of the ``sb3-defaults`` learner: what an SB3 user's first ``learn`` call takes here."""


class _Snapshots(BaseCallback):
    """Save the model once ``num_timesteps`` has reached each of ``steps``, after that rollout's update.

    ``learn(total_timesteps=n)`` stops after the update of the rollout that reaches ``n``, so the
    model saved at the start of the next rollout (or at the end of training) is that run's model.
    """

    def __init__(self, steps: list[int], path_for: Callable[[int], Path]) -> None:
        super().__init__()
        self.pending = sorted(steps)
        self.path_for = path_for

    def _save_reached(self) -> None:
        while self.pending and self.num_timesteps >= self.pending[0]:
            self.model.save(self.path_for(self.pending.pop(0)))

    def _on_rollout_start(self) -> None:
        self._save_reached()

    def _on_training_end(self) -> None:
        self._save_reached()

    def _on_step(self) -> bool:
        return True


def _train_defaults(seed: int, path: Path, timesteps: int | None, wrapper_class: Any = None) -> None:
    from stable_baselines3.common.env_util import make_vec_env

    env = make_vec_env(HARD_ID, n_envs=8, seed=seed, wrapper_class=wrapper_class)
    PPO("MlpPolicy", env, seed=seed, device="cpu").learn(timesteps or DEFAULTS_TIMESTEPS).save(path)


def _train_settings(seed: int, path: Path, timesteps: int | None) -> None:
    from agents.rl import find_vec_normalize, save_model_bundle, sb3_settings

    settings = sb3_settings(HARD_ID)
    env = settings.make_env(seed)
    model = PPO(settings.policy, env, seed=seed, device="cpu", **settings.hyperparams)
    model.learn(timesteps or settings.total_timesteps)
    save_model_bundle(model, path, algo="ppo", env_id=HARD_ID, vec_normalize=find_vec_normalize(env))


ZOO_COMMAND = (
    "-m", "rl_zoo3.train", "--algo", "ppo", "--env", HARD_ID, "--gym-packages", "coop_gym",
    "-conf", "agents.zoo.ppo", "--num-threads", "1",
)  # fmt: skip
"""RL Zoo's training command of docs/integrations.md (after ``python``), its seed and folder added."""


def _train_zoo(seed: int, path: Path, timesteps: int | None) -> None:
    """:data:`ZOO_COMMAND` with ``--seed``; the model and its statistics kept in RL Zoo's layout.

    RL Zoo writes ``logs/ppo/<env>_1/<env>.zip`` and ``<env>_1/<env>/vecnormalize.pkl``; the model
    goes to ``path`` and the statistics to ``path``'s stem folder, the same layout, where the package's
    loader looks (:func:`agents.rl.load_agent`). In a subprocess: importing rl_zoo3 patches gymnasium.
    """
    import shutil

    logs = path.with_name(f"{path.stem}_logs").resolve()  # the command runs in the checkout
    command = [sys.executable, *ZOO_COMMAND, "--seed", str(seed), "-f", str(logs)]
    subprocess.run([*command, *(["-n", str(timesteps)] if timesteps else [])], cwd=ROOT, check=True)
    name = HARD_ID.replace("/", "-")
    run = logs / "ppo" / f"{name}_1"
    path.with_suffix("").mkdir(exist_ok=True)
    shutil.copyfile(run / name / "vecnormalize.pkl", path.with_suffix("") / "vecnormalize.pkl")
    shutil.copyfile(run / f"{name}.zip", path)


LEARNERS: dict[str, tuple[str, Callable[[int, Path, int | None], None]]] = {
    "sb3-defaults": ('PPO("MlpPolicy", make_vec_env(id, n_envs=8)): SB3 defaults, 300k steps', _train_defaults),
    "sb3-settings": ("PPO(**sb3_settings(id).hyperparams) on settings.make_env(): package settings", _train_settings),
    "rl-zoo": ("python -m rl_zoo3.train --algo ppo -conf agents.zoo.ppo: the shipped hyperparameters", _train_zoo),
}


def _score_seeds(learners: list[str], seeds: list[int], runs: Path, episodes: int) -> dict[str, Any]:
    """Score the saved models and the scripted rows in one ``agents.evaluate`` run; the per-seed report."""
    from agents.evaluate.headroom import iqm_across_runs

    walls = json.loads((runs / "train_wall_s.json").read_text())
    seeds_of = {name: [seed for seed in seeds if (runs / f"{name}__{seed}.zip").exists()] for name in learners}
    learners = [name for name in learners if seeds_of[name]]  # --no-train: a learner with no model has no row
    models = [str(runs / f"{name}__{seed}.zip") for name in learners for seed in seeds_of[name]]
    command = [sys.executable, "-m", "agents.evaluate", "--compare", ",".join([*models, *SCRIPTED]), "--env", HARD_ID]
    command += ["--personas", "test", "--episodes", str(episodes), "--json"]
    done = subprocess.run(command, capture_output=True, text=True, cwd=ROOT, check=True)
    scored = {r["agent"]: r for r in json.loads(done.stdout)["results"]}
    rows: dict[str, Any] = {}
    for name in learners:
        results = [scored[f"ppo:{name}__{seed}"] for seed in seeds_of[name]]
        per_seed = [
            {
                "seed": seed,
                **{f"{key}_rate": result[f"{key}_rate"] for key in ("success", "unsafe", "premature")},
                "never_lift_rate": result["timeout_rate"],
                "train_wall_s": walls.get(f"{name}__{seed}"),
            }
            for seed, result in zip(seeds_of[name], results, strict=True)
        ]
        success = iqm_across_runs({HARD_ID: [s["success_rate"] for s in per_seed]})
        rows[name] = {
            "what": LEARNERS[name][0],
            "success": {"iqm": success.iqm, "ci95": list(success.ci95)},
            "min_success": min(s["success_rate"] for s in per_seed),
            "per_seed": per_seed,
        }
    scripted = {a: {k: scored[a][k] for k in ("success_rate", "unsafe_rate", "timeout_rate")} for a in SCRIPTED}
    return {"env_id": HARD_ID, "personas": "test", "episodes": episodes, "rows": rows, "scripted": scripted}


def _seeds(args: argparse.Namespace, argv: list[str] | None) -> None:
    """``--seeds``: each learner of ``--learners`` trained once per seed, then all scored together."""
    learners = args.learners.split(",")
    runs = Path(args.runs)
    runs.mkdir(parents=True, exist_ok=True)
    walls_path = runs / "train_wall_s.json"
    for name in learners:
        for seed in args.seeds:
            path = runs / f"{name}__{seed}.zip"
            if not path.exists() and not args.no_train:
                started = time.perf_counter()
                LEARNERS[name][1](seed, path, args.timesteps)
                # Read again: another process may train other seeds into the same --runs.
                walls = json.loads(walls_path.read_text()) if walls_path.exists() else {}
                walls[path.stem] = time.perf_counter() - started
                walls_path.write_text(json.dumps(walls, indent=2) + "\n")
                print(f"{path.stem}: trained in {walls[path.stem]:.0f} s", flush=True)
    report = _score_seeds(learners, args.seeds, runs, args.episodes)
    for name, row in report["rows"].items():
        cells = ", ".join(f"{s['success_rate']:.3f} (never lifts {s['never_lift_rate']:.3f})" for s in row["per_seed"])
        print(f"{name}: IQM {row['success']['iqm']:.3f} {row['success']['ci95']}; per seed {cells}")
    print("scripted:", {a: s["success_rate"] for a, s in report["scripted"].items()})
    _save_to(args, argv, "library_seeds_SitToStandHard-v2.json", report)


_SAVE_DEFAULT = "library_defaults_<algo>_<env>_<timesteps>.json"
"""``--save``'s file of one run (``<algo>_<env>_<timesteps>`` filled in); ``--seeds`` and ``--study`` name theirs."""


def _save_to(args: argparse.Namespace, argv: list[str] | None, name: str, report: dict[str, Any]) -> None:
    """With ``--save``: ``report`` to its ``PATH``, or without one to ``bench/results/<name>``."""
    if args.save:
        target = RESULTS / name if args.save == str(RESULTS / _SAVE_DEFAULT) else args.save
        save(target, "library_defaults", argv, report)


# --- the never-lift study: why a library's defaults settle on never lifting ---------------------


@dataclass(frozen=True)
class Cell:
    """A cell of the never-lift study: what is trained, on what, with which flags, scored on which id."""

    what: str
    train_env: str | None
    """CleanRL's ``--env-id``: a measurement aid of ``bench/cleanrl_defaults.py`` that logs each episode's
    outcome (``cleanrl_defaults:<id>``); None: SB3's defaults, the same log as ``make_vec_env``'s ``wrapper_class``."""
    scored_on: str
    """The id the final policy is scored on: its starts seated, its reward the id's own."""
    flags: tuple[str, ...] = ()
    """CleanRL's flags beyond its defaults."""
    sb3_curriculum: bool = False
    """SB3's defaults' envs each in :class:`cleanrl_defaults.Curriculum` (the paper's level first)."""


_LOGGED = "Logged/SitToStandHardDiscreteUnit-v2"
NEVER_LIFT_CELLS: dict[str, Cell] = {
    "cleanrl-ppo": Cell("CleanRL's ppo.py on its defaults", _LOGGED, CLEANRL_ENV_ID),
    "cleanrl-ppo-nounit": Cell(
        "the same on the id without unit scaling (SitToStandHardDiscrete-v2)",
        "Logged/SitToStandHardDiscrete-v2",
        "CoopGym/SitToStandHardDiscrete-v2",
    ),
    "cleanrl-ppo-midguidance": Cell(
        "the same, half the training episodes started mid-guidance (cleanrl_defaults.MidGuidance)",
        "LoggedMidGuidance/SitToStandHardDiscreteUnit-v2",
        CLEANRL_ENV_ID,
    ),
    "cleanrl-ppo-curriculum": Cell(
        "the same, its first 100,000 steps on the paper's level (SitToStandDiscreteUnit-v0), then hard-v2's "
        "(cleanrl_defaults.Curriculum)",
        "LoggedCurriculum/SitToStandHardDiscreteUnit-v2",
        CLEANRL_ENV_ID,
    ),
    "cleanrl-ppo-population": Cell(
        "the same, trained across bodies: 512 persons of the validation people's population (personas "
        "train_population)",
        "LoggedPopulation/SitToStandHardDiscreteUnit-v2",
        CLEANRL_ENV_ID,
    ),
    "cleanrl-ppo-priced": Cell(
        "the same, trained with a timeout priced as a failed assistance (cleanrl_defaults.PricedTimeout, -1)",
        "LoggedPriced/SitToStandHardDiscreteUnit-v2",
        CLEANRL_ENV_ID,
    ),
    "cleanrl-ppo-ent02": Cell(
        "the same with --ent-coef 0.02 (train.py's entropy bonus)", _LOGGED, CLEANRL_ENV_ID, ("--ent-coef", "0.02")
    ),
    "cleanrl-ppo-trainpy": Cell(
        "the same with train.py's PPO settings as flags (bench/learners.py's TRAINPY_FLAGS)",
        _LOGGED,
        CLEANRL_ENV_ID,
        TRAINPY_FLAGS,
    ),
    "cleanrl-ppo-rollout": Cell(
        "the same with train.py's rollout and update size as flags (16 x 256 steps, 8 minibatches, 10 epochs)",
        _LOGGED,
        CLEANRL_ENV_ID,
        TRAINPY_FLAGS[:8],
    ),
    "sb3-defaults": Cell('PPO("MlpPolicy", make_vec_env(id, n_envs=8)): SB3 defaults', None, HARD_ID),
    "sb3-defaults-curriculum": Cell(
        "SB3's defaults, their first 100,000 steps on the paper's level (SitToStand-v0), then hard-v2's "
        "(cleanrl_defaults.Curriculum)",
        None,
        HARD_ID,
        sb3_curriculum=True,
    ),
}
"""The study's cells (:class:`Cell`)."""
STUDY_SETS = ("validation", "train")
"""Who the study scores on: the validation people and the training personas, never the test personas."""
LIFT_HAZARDS = (0.5, 0.1, 0.03, 0.01, 0.003, 0.0)
"""Per-step lift probabilities of :class:`LiftHazard`; 0.5 is a fresh Discrete(18) policy's (half its actions lift)."""
COLLAPSE_SHARE = 0.9
"""A training run has stopped lifting from the first log bin whose episodes are at least this share timeouts."""


class LiftHazard:
    """Uniform over the 9 cue pairs of the Discrete(18) action, lifting with probability ``hazard`` each step.

    A fresh policy network acts uniformly (``hazard`` 0.5); training lowers the lift's probability. What
    this policy meets at each hazard is what a learner meets on its way to never lifting.
    """

    def __init__(self, hazard: float, seed: int = 0) -> None:
        self.hazard = hazard
        self.name = f"lift-hazard-{hazard}"
        self.rng = np.random.default_rng(seed)

    def predict(
        self, observation: Any, state: Any = None, episode_start: Any = None, deterministic: bool = True
    ) -> Any:
        """SB3's protocol; the flat index of ``(push, verbal, lift)`` over ``(3, 3, 2)`` is ``2 * cues + lift``."""
        rows = np.atleast_2d(np.asarray(observation)).shape[0]
        lifts = self.rng.random(rows) < self.hazard
        actions: NDArray[np.int64] = np.asarray(2 * self.rng.integers(9, size=rows) + lifts, dtype=np.int64)
        return (actions if np.ndim(observation) == 2 else actions[0]), state


def lift_hazard_sweep(episodes: int) -> list[dict[str, Any]]:
    """Outcome rates and mean return of :class:`LiftHazard` at each :data:`LIFT_HAZARDS`, on the training personas."""
    from agents.evaluate import evaluate
    from agents.rl.callbacks import VALIDATION_SEED

    rows = []
    for hazard in LIFT_HAZARDS:
        score = evaluate(LiftHazard(hazard), CLEANRL_ENV_ID, "train", episodes, VALIDATION_SEED).summary()
        rows.append({"lift_hazard": hazard, **rates(score), "mean_return": score["mean_return"]})
    return rows


def training_outcomes(log: list[tuple[int, str]], timesteps: int, bin_steps: int) -> dict[str, Any]:
    """The outcomes of a run's training episodes per ``bin_steps`` of its global step, and when lifting stopped.

    ``collapse_step``: the end of the first bin with at least :data:`COLLAPSE_SHARE` timeouts (None: never);
    ``successes_before_collapse``: the successful lifts the learner had met by then (all of them if never).
    """
    outcomes = ("success", "unsafe", "premature", "timeout")
    last = max([timesteps, *(step for step, _ in log)])  # SB3 finishes the rollout that passes ``timesteps``
    bins = [{"to_step": end, **dict.fromkeys(outcomes, 0)} for end in range(bin_steps, last + bin_steps, bin_steps)]
    for step, outcome in log:
        bins[(step - 1) // bin_steps][outcome] += 1
    collapse = next(
        (b["to_step"] for b in bins if (n := sum(b[o] for o in outcomes)) and b["timeout"] >= COLLAPSE_SHARE * n), None
    )
    successes = [step for step, outcome in log if outcome == "success"]
    return {
        "episodes": len(log),
        "first_success_step": successes[0] if successes else None,
        "collapse_step": collapse,
        "successes_before_collapse": sum(1 for s in successes if collapse is None or s <= collapse),
        "unsafe_before_collapse": sum(1 for s, o in log if o == "unsafe" and (collapse is None or s <= collapse)),
        "bins": bins,
    }


def _train_cell(cell: str, seed: int, timesteps: int, script: Path | None, folder: Path) -> Any:
    """Train ``cell`` once with ``seed``, its outcomes logged; the trained agent (saved in ``folder``)."""
    import contextlib

    import cleanrl_defaults

    cleanrl_defaults.clear_outcome_log()
    train_env, flags = NEVER_LIFT_CELLS[cell].train_env, NEVER_LIFT_CELLS[cell].flags
    if train_env is None:
        log, curriculum = cleanrl_defaults.OutcomeLog, cleanrl_defaults.Curriculum
        easy = cleanrl_defaults.CURRICULUM_EASY_SB3_ENV_ID
        wrapper = (lambda env: log(curriculum(env, easy))) if NEVER_LIFT_CELLS[cell].sb3_curriculum else log
        _train_defaults(seed, folder / f"{cell}__{seed}.zip", timesteps, wrapper)
        return SB3Agent(PPO.load(folder / f"{cell}__{seed}.zip", device="cpu"), "ppo", HARD_ID, name=cell)
    if script is None:
        raise SystemExit(f"--cleanrl-script: the {cell} cell needs CleanRL's ppo.py")
    with contextlib.chdir(folder):  # the script writes its TensorBoard folder runs/ where it runs
        agent, _ = cleanrl_defaults.run_script(
            script.resolve(), f"cleanrl_defaults:{train_env}", timesteps, seed, flags
        )
    torch.save(agent.module.state_dict(), folder / f"{cell}__{seed}.pt")
    return agent


def _study_run(cell: str, seed: int, args: argparse.Namespace, folder: Path) -> dict[str, Any]:
    """One (cell, seed) trained in ``folder``: its training outcomes and its scores on :data:`STUDY_SETS`."""
    import cleanrl_defaults

    from agents.evaluate import evaluate
    from agents.rl.callbacks import VALIDATION_SEED

    started = time.perf_counter()
    agent = _train_cell(cell, seed, args.timesteps, args.cleanrl_script, folder)
    wall = time.perf_counter() - started
    log = list(cleanrl_defaults.OUTCOME_LOG)
    run: dict[str, Any] = {"cell": cell, "seed": seed, "timesteps": args.timesteps, "train_wall_s": wall}
    run["training"] = training_outcomes(log, args.timesteps, args.bin_steps)
    for people in STUDY_SETS:
        score = evaluate(agent, NEVER_LIFT_CELLS[cell].scored_on, people, args.episodes, VALIDATION_SEED).summary()
        run[people] = rates(score)
    print(f"{cell}__{seed}: {wall:.0f} s; validation {run['validation']}; {run['training']['collapse_step']=}")
    return run


def _study_cell(cell: str, runs: list[dict[str, Any]]) -> dict[str, Any]:
    """A cell's report: per seed, and over seeds the IQM of success (bootstrap 95 %) on each set."""
    what = NEVER_LIFT_CELLS[cell]
    row: dict[str, Any] = {"what": what.what, "scored_on": what.scored_on, "flags": list(what.flags)}
    for people in STUDY_SETS:
        success = iqm_ci([r[people]["success_rate"] for r in runs])
        row[people] = {
            "success_iqm": success["iqm"],
            "success_ci95": None if success["ci95"][0] is None else success["ci95"],  # one seed: none
            "never_lift_seeds": sum(1 for r in runs if r[people]["timeout_rate"] >= COLLAPSE_SHARE),
        }
    keep = ("episodes", "first_success_step", "collapse_step", "successes_before_collapse", "unsafe_before_collapse")
    row["per_seed"] = [
        {
            "seed": r["seed"],
            "train_wall_s": r["train_wall_s"],
            **{people: {**r[people], "never_lift_rate": r[people]["timeout_rate"]} for people in STUDY_SETS},
            "training": {key: r["training"][key] for key in keep},
            "training_bins": r["training"]["bins"],
        }
        for r in runs
    ]
    return row


def _references(folder: Path, episodes: int) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """The scripted rows on :data:`STUDY_SETS` and :func:`lift_hazard_sweep`, kept in ``folder`` for a rerun."""
    from agents.evaluate import evaluate
    from agents.rl.callbacks import VALIDATION_SEED

    def measure() -> dict[str, Any]:
        scripted = {
            people: {a: rates(evaluate(a, HARD_ID, people, episodes, VALIDATION_SEED).summary()) for a in SCRIPTED}
            for people in STUDY_SETS
        }
        return {"scripted": scripted, "lift_hazard": lift_hazard_sweep(episodes)}

    kept = kept_json(folder / f"references__{episodes}.json", measure)
    return kept["scripted"], kept["lift_hazard"]


def _study(args: argparse.Namespace, argv: list[str] | None) -> None:
    """``--study never-lift``: each of ``--cells`` over ``--seeds``, the scripted rows and the lift-hazard sweep."""
    from agents.rl.callbacks import VALIDATION_SEED

    folder = Path(args.runs)
    folder.mkdir(parents=True, exist_ok=True)
    rows = {}
    for cell in args.cells.split(","):
        train = {seed: None if args.no_train else partial(_study_run, cell, seed, args, folder) for seed in args.seeds}
        found = [kept_json(folder / f"{cell}__{seed}.json", make) for seed, make in train.items()]
        runs = [run for run in found if run is not None]
        if runs:
            rows[cell] = _study_cell(cell, runs)
    scripted, hazard = _references(folder, args.episodes)
    report = {
        "env_id": HARD_ID,
        "timesteps": args.timesteps,
        "episodes": args.episodes,
        "episode_seed": VALIDATION_SEED,
        "bin_steps": args.bin_steps,
        "rows": rows,
        "scripted": scripted,
        "lift_hazard": hazard,
    }
    for cell, row in rows.items():
        cells = ", ".join(
            f"{s['validation']['success_rate']:.2f}/{s['validation']['never_lift_rate']:.2f}" for s in row["per_seed"]
        )
        print(f"{cell}: validation success/never-lift per seed {cells}")
    print("scripted (validation):", {a: s["success_rate"] for a, s in scripted["validation"].items()})
    print(
        "lift hazard:",
        [(h["lift_hazard"], h["success_rate"], round(h["mean_return"], 2)) for h in report["lift_hazard"]],
    )
    _save_to(args, argv, "never_lift_SitToStandHard-v2.json", report)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--algo", choices=sorted(ENV_IDS))
    parser.add_argument("--timesteps", type=positive_int, help="default: 300000; with --seeds each learner's own")
    parser.add_argument("--env", choices=sorted(coop_gym.ENV_IDS), help="default: the algorithm's id in ENV_IDS")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--episodes", type=positive_int, default=1000, help="held-out episodes per score")
    parser.add_argument("--out", default="runs/defaults")
    parser.add_argument("--snapshot-at", type=int, nargs="*", default=[], help="also save at these step counts")
    parser.add_argument("--seeds", type=seed_list, help="the hard level over these training seeds (--learners)")
    parser.add_argument("--learners", default=",".join(LEARNERS), help=f"with --seeds: {', '.join(LEARNERS)}")
    parser.add_argument("--runs", default="runs/library_seeds", help="with --seeds: where the models are kept")
    parser.add_argument("--no-train", action="store_true", help="with --seeds: score the models in --runs only")
    parser.add_argument("--study", choices=["never-lift"], help="with --seeds: the never-lift study (--cells)")
    parser.add_argument(
        "--cells", default=",".join(NEVER_LIFT_CELLS), help=f"with --study: {', '.join(NEVER_LIFT_CELLS)}"
    )
    parser.add_argument("--cleanrl-script", type=Path, help="with --study: CleanRL's ppo.py, for the cleanrl-* cells")
    parser.add_argument("--bin-steps", type=positive_int, default=10_000, help="with --study: log bin [steps]")
    add_save_argument(parser, _SAVE_DEFAULT)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    if args.study is not None:
        if args.seeds is None or (unknown := sorted(set(args.cells.split(",")) - set(NEVER_LIFT_CELLS))):
            parser.error(f"--study needs --seeds and known --cells: {', '.join(NEVER_LIFT_CELLS)}")
        args.timesteps = args.timesteps or DEFAULTS_TIMESTEPS
        _study(args, argv)
        return
    if args.seeds is not None:
        if unknown := sorted(set(args.learners.split(",")) - set(LEARNERS)):
            parser.error(f"--learners: unknown {unknown}; known: {', '.join(LEARNERS)}")
        _seeds(args, argv)
        return
    if args.algo is None:
        parser.error("--algo is required without --seeds")
    args.timesteps = args.timesteps or DEFAULTS_TIMESTEPS
    if any(n < 1 or n >= args.timesteps for n in args.snapshot_at):
        parser.error(f"--snapshot-at: each must be in [1, --timesteps), got {args.snapshot_at}")
    _single(args, argv)


def _single(args: argparse.Namespace, argv: list[str] | None) -> None:
    """One training run of ``--algo`` on SB3's defaults, scored beside the handbook caregiver."""
    cls = PPO if args.algo == "ppo" else DQN
    env_id = args.env or ENV_IDS[args.algo]
    model = cls("MlpPolicy", env_id, seed=args.seed, device="cpu")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    name = "" if args.env is None else env_id.split("/")[-1] + "_"

    def path_for(steps: int) -> Path:
        return out / f"{args.algo}_{name}{steps}.zip"

    started = time.perf_counter()
    model.learn(total_timesteps=args.timesteps, callback=_Snapshots(args.snapshot_at, path_for))
    wall = time.perf_counter() - started
    path = path_for(args.timesteps)
    model.save(path)
    models = {steps: cls.load(path_for(steps), device="cpu") for steps in args.snapshot_at}
    models[args.timesteps] = model
    agents = {str(n): (SB3Agent(m, args.algo, env_id, name=f"{args.algo} {n}"), True) for n, m in models.items()}
    run = {"algo": args.algo, "timesteps": args.timesteps, "seed": args.seed, "wall_time_s": wall}
    report = held_out_report(run, agents, env_id, args.episodes)
    path.with_suffix(".json").write_text(json.dumps(report, indent=2) + "\n")
    if args.save:
        stem = f"{args.algo}_{env_id.split('/')[-1]}_{args.timesteps}"
        save(args.save.replace("<algo>_<env>_<timesteps>", stem), "library_defaults", argv, report)


if __name__ == "__main__":
    main()
