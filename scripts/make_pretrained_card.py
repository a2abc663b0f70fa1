r"""Ship a trained model as a pretrained caregiver: copy it into ``agents/pretrained/`` and write its card.

The card (``agents/pretrained/NAME.json``) holds what a user needs to trust the model: the env
it plays (id and kwargs), how it was trained, and its held-out table -- the model beside the
best blind policy, the prober, the belief caregiver and the oracle on the same ``--episodes``
seeded episodes of the ``test`` personas, each with success, unsafe, premature and timeout
rates (95 % Wilson intervals) and the mind-reading score -- exactly what ::

    python -m agents.evaluate --model pretrained:NAME --compare blind,push_then_lift,prober,belief,oracle \
        --personas test --episodes 1000 --seed 0

prints. ``check`` holds the outcome counts and mean return of the model alone on the first
``--check-episodes`` of those episodes, which ``tests/agents/test_pretrained.py`` reproduces
exactly (the evaluation is deterministic: the same seeds, a deterministic policy)::

    python scripts/make_pretrained_card.py hard-ppo --model /tmp/pre/RUN/model.zip \
        --command "python train.py --out /tmp/pre" --training-json /tmp/pre/RUN/training.json

A run folder kept as an ensemble (``train.py``'s default, its ``ensemble.json``) ships as one: give
the folder as ``--model``, and its members' ``model.zip`` files go to ``agents/pretrained/NAME/``
(``seed_K.zip``), which the card's ``members`` names; its training section lists each member's
seed, steps, wall time and selection and the ensemble's score on the validation people::

    python scripts/make_pretrained_card.py hard-v2-ppo-ensemble --model /tmp/pre/runs/RUN \
        --command "python train.py --seed 0 --out /tmp/pre/runs" --training-json /tmp/pre/runs/RUN/training.json
"""

from __future__ import annotations

import json
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import tyro

from agents.run_folder import ENSEMBLE_FILE, MODEL_FILE, TRAINING_FILE

BASELINES = ("blind", "push_then_lift", "prober", "belief", "oracle")
"""The agents beside the model: the blind family's two best, the two readers (the prober's
displacement rule, the belief caregiver's estimator) and the oracle."""
PRETRAINED = Path(__file__).resolve().parents[1] / "agents" / "pretrained"


@dataclass
class Args:
    """Command-line arguments; each field's docstring is its ``--help``."""

    name: tyro.conf.Positional[str]
    """the pretrained model's name (hard-ppo: loaded as pretrained:hard-ppo)"""
    model: str
    """the trained model.zip (agents.rl.save_agent's bundle), or a run folder kept as an ensemble (ensemble.json)"""
    command: str
    """the command that trained it (recorded in the card)"""
    training_json: str
    """the training summary (train.py's training.json or the script's): steps, wall time, seed"""
    env_kwargs: str = "{}"
    """env kwargs the model plays with, as JSON (the switching filter's estimate: {"estimator": "switching", ...})"""
    notes: list[str] = field(default_factory=list)
    """sentences for the card's notes"""
    episodes: int = 1000
    """held-out evaluation episodes (seeds seed .. seed + episodes - 1)"""
    check_episodes: int = 200
    """the first episodes the test replays"""
    seed: int = 0
    """seed of evaluation episode 0"""
    n_envs: int = 64
    """episodes played side by side (python -m agents.evaluate's default)"""


def _row(result: Any, score: Any) -> dict[str, Any]:
    """One row of the card's table."""
    row: dict[str, Any] = {"agent": result.agent, "episodes": result.episodes}
    for outcome in ("success", "unsafe", "premature", "timeout"):
        row[outcome] = result.rate(outcome)
        row[f"{outcome}_ci95"] = list(result.interval(outcome))
    row["mind_reading_score"] = score.score if score is not None else None
    row["mind_reading_score_ci95"] = list(score.ci95) if score is not None else None
    row["mean_return"] = result.mean_return
    return row


def _counts(result: Any) -> dict[str, Any]:
    """What the test compares: the outcome counts and the mean return."""
    counts: dict[str, Any] = {o: result.count(o) for o in ("success", "unsafe", "premature", "timeout")}
    return {
        "episodes": result.episodes,
        **counts,
        "success_rate": result.success_rate,
        "mean_return": result.mean_return,
    }


def _training(args: Args, training: dict[str, Any], env_id: str, model_zip: Path) -> dict[str, Any]:
    """The card's training section, from the training summary (train.py's or the script's).

    A card's own training section is a summary too: carding a model again keeps its
    ``defaults`` line (the settings in words), which no training summary writes.
    """
    from agents.rl.bundle import read_bundle

    framework = read_bundle(model_zip)[0].get("framework", "sb3")
    sizing = " with JAX_SIZING" if framework == "jax" else ""
    section = {
        "command": args.command,
        "framework": framework,
        "seed": training.get("seed", 0),
        "timesteps": training["timesteps"],
        "n_envs": training.get("n_envs"),
        "personas": training.get("personas"),
        "wall_time_s": round(float(training["wall_time_s"]), 1),
        "hyperparams": f"agents/hyperparams.py: HYPERPARAMS['ppo']['{env_id}']{sizing}",
    }
    if "selected" in training:  # train.py kept the best-validated policy, not the final one
        section["selected"] = _selected(training["selected"])
    if "defaults" in training:
        section["defaults"] = training["defaults"]
    return section


def _selected(selected: dict[str, Any]) -> dict[str, Any]:
    """What the card says of the best-validated policy train.py kept."""
    return {k: selected[k] for k in ("timesteps", "validation_success_rate", "personas", "episodes")}


def _members(run: Path) -> list[str]:
    """The member folders a run folder kept as an ensemble names (relative to it)."""
    members: list[str] = json.loads((run / ENSEMBLE_FILE).read_text())["members"]
    return members


def _ensemble_training(section: dict[str, Any], training: dict[str, Any], run: Path) -> None:
    """Turn the kept seed's training section into the ensemble's: every member's seed, steps, wall time, selection.

    ``wall_time_s`` becomes the members' training times added up (they train one after another);
    ``validation`` is the ensemble's score on the validation people (``train.py``'s ``--keep ensemble``).
    """
    members = _members(run)
    summaries = [json.loads((run / m / TRAINING_FILE).read_text())["training"] for m in members]
    seeds = [score["seed"] for score in training["seeds"]]
    if len(seeds) != len(members) or len({s["timesteps"] for s in summaries}) != 1:
        raise ValueError(f"{run}: the training summary's seeds do not match ensemble.json's members")
    section.pop("selected", None)  # the kept seed's; each member's is below
    section |= {"seed": seeds[0], "seeds": seeds, "wall_time_s": round(sum(s["wall_time_s"] for s in summaries), 1)}
    section["members"] = [
        {
            "seed": seed,
            "timesteps": summary["timesteps"],
            "wall_time_s": round(float(summary["wall_time_s"]), 1),
            "validation_people_success_rate": score["success_rate"],
            **({"selected": _selected(summary["selected"])} if "selected" in summary else {}),
        }
        for seed, summary, score in zip(seeds, summaries, training["seeds"], strict=True)
    ]
    section["validation"] = training["ensemble"]


def _evaluation(args: Args, label: str, results: list[Any]) -> dict[str, Any]:
    """The card's held-out table: the model and :data:`BASELINES` on the same episodes."""
    from agents.evaluate import headroom

    room = headroom(results)
    if room is None:
        raise ValueError("the held-out table needs the oracle and a non-oracle agent")
    return {
        "command": (
            f"python -m agents.evaluate --model {label} --compare {','.join(BASELINES)} "
            f"--personas test --episodes {args.episodes} --seed {args.seed}"
        ),
        "personas": "test",
        "episodes": args.episodes,
        "seed": args.seed,
        "n_envs": args.n_envs,
        "best_blind_agent": room.best_blind_agent,
        "table": [_row(r, room.score_of(r.agent)) for r in results],
    }


def _check(args: Args, model_result: Any, check: Any) -> dict[str, Any]:
    """The card's check section: the model alone on the evaluation's first ``check_episodes``."""
    first = model_result.records[: args.check_episodes]
    same = [(r.outcome, r.episode_return) for r in first] == [(r.outcome, r.episode_return) for r in check.records]
    return {
        "what": f"the model alone on the first {args.check_episodes} episodes of the evaluation "
        "(tests/agents/test_pretrained.py reproduces these exactly)",
        **_counts(check),
        "same_as_the_evaluations_first_episodes": same,
    }


def _ship(args: Args) -> tuple[dict[str, Any], list[Path]]:
    """Copy the model (or the ensemble's members) into ``agents/pretrained``: the card's files and the zips.

    A single model becomes ``NAME.zip`` (the card's ``model``); an ensemble's members become
    ``NAME/seed_K.zip`` (the card's ``members``, relative to ``agents/pretrained``).
    """
    source = Path(args.model)
    if not (source / ENSEMBLE_FILE).is_file():
        target = PRETRAINED / f"{args.name}.zip"
        shutil.copyfile(source, target)
        return {"model": target.name}, [target]
    folder = PRETRAINED / args.name
    folder.mkdir(exist_ok=True)
    targets = []
    for member in _members(source):
        targets.append(folder / f"{Path(member).name}.zip")
        shutil.copyfile(source / member / MODEL_FILE, targets[-1])
    return {"members": [t.relative_to(PRETRAINED).as_posix() for t in targets]}, targets


def main() -> None:
    """Copy the model, evaluate it and the baselines, write the card."""
    args = tyro.cli(Args)
    from agents.evaluate import evaluate, print_table
    from agents.rl import load_agent
    from agents.rl.ensemble import load_ensemble

    env_kwargs = json.loads(args.env_kwargs)
    training = json.loads(Path(args.training_json).read_text())
    training = training.get("training", training)
    files, zips = _ship(args)
    label = f"pretrained:{args.name}"
    agent = load_agent(zips[0]) if len(zips) == 1 else load_ensemble(zips, name=label)
    if agent.env_id is None:
        raise ValueError(f"{args.model} does not record the env it was trained on")
    env_id = agent.env_id
    common: dict[str, Any] = {"personas": "test", "seed": args.seed, "n_envs": args.n_envs}

    model_result = evaluate(agent, env_id, episodes=args.episodes, env_kwargs=env_kwargs, name=label, **common)
    results = [model_result] + [evaluate(b, env_id, episodes=args.episodes, **common) for b in BASELINES]
    evaluation = _evaluation(args, label, results)
    print_table(results)
    check = evaluate(agent, env_id, episodes=args.check_episodes, env_kwargs=env_kwargs, name=label, **common)

    section = _training(args, training, env_id, zips[0])
    if "members" in files:
        _ensemble_training(section, training, Path(args.model))
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False)
    card = {
        "name": args.name,
        **files,
        "algo": agent.algo,
        "env_id": env_id,
        "env_kwargs": env_kwargs,
        "features": list(agent.features or ()),
        "training": section,
        "evaluation": evaluation,
        "check": _check(args, model_result, check),
        "carded_at_commit": commit.stdout.strip(),
        "notes": args.notes,
    }
    (PRETRAINED / f"{args.name}.json").write_text(json.dumps(card, indent=2) + "\n")
    print(f"wrote {', '.join(map(str, zips))} and {PRETRAINED / args.name}.json")


if __name__ == "__main__":
    main()
