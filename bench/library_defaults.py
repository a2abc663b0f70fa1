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
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
import torch
from result_files import RESULTS, ROOT, add_save_argument, held_out_report, save
from stable_baselines3 import DQN, PPO
from stable_baselines3.common.callbacks import BaseCallback

import coop_gym  # registers the ids
from agents.rl import SB3Agent
from coop_gym.cli import positive_int, seed_list

ENV_IDS = {"ppo": "CoopGym/SitToStand-v0", "dqn": "CoopGym/SitToStandDiscrete-v0"}
HARD_ID = "CoopGym/SitToStandHard-v2"
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


def _train_defaults(seed: int, path: Path, timesteps: int | None) -> None:
    from stable_baselines3.common.env_util import make_vec_env

    env = make_vec_env(HARD_ID, n_envs=8, seed=seed)
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
    if args.save:
        default = str(RESULTS / "library_defaults_<algo>_<env>_<timesteps>.json")
        target = RESULTS / "library_seeds_SitToStandHard-v2.json" if args.save == default else args.save
        save(target, "library_defaults", argv, report)


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
    add_save_argument(parser, "library_defaults_<algo>_<env>_<timesteps>.json")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
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
