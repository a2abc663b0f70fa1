"""Seeds played as one: what ``train.py --seeds N`` keeps, as an ensemble and as the best of its N seeds.

    python bench/ensembles.py --runs DIR [--row jax-kalman-lag] [--runs-of 16] [--sizes 2,4]
                              [--episodes 2000] [--validation-episodes 1000] [--save [PATH]]

Reads the runs ``bench/learners.py --rows ROW --seeds 0,1,... --runs DIR`` trained: each seed's kept
model and its record (held-out success, and its score on the validation people). ``train.py --seed s
--seeds N`` trains the seeds ``s .. s + N - 1`` exactly as those runs did, so for each size ``N`` and
each ``s`` below ``--runs-of`` it keeps

- ``--keep ensemble``: the N seeds' models played as one (:class:`agents.rl.ensemble.EnsembleAgent`),
  scored here on the validation people and on the held-out episodes (the test people) that every
  row of ``bench/learners.py`` plays;
- ``--keep best``: the seed best on the validation people (ties to the lower seed), from the records.

``N = 1`` is the seed alone. Per size: each run's held-out success, the interquartile mean over runs
with its stratified bootstrap interval, the lowest run, the runs at or above the belief caregiver, and
how the validation people's success predicts the held-out success over runs (Pearson ``r`` with its
95 % interval). The runs of consecutive ``s`` share seeds, as ``train.py --seed s`` runs do. Each
ensemble's scores are kept in ``DIR/ensemble__<row>__<s>+<N>.json`` as soon as they are measured, so
an interrupted run loses only the ensemble being scored. Nothing is chosen on the held-out scores.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from learners import ENV_ID
from result_files import add_save_argument, kept_json, rates, save

from coop_gym.cli import positive_int, seed_list


def _record(folder: Path, row: str, seed: int, timesteps: int) -> dict[str, Any]:
    """``bench/learners.py``'s record of one (row, seed) run; SystemExit naming the command where it is missing."""
    path = folder / f"{row}__{seed}__{timesteps}.json"
    if not path.is_file():
        raise SystemExit(f"no run {path}: python bench/learners.py --rows {row} --seeds ... --runs {folder}")
    record = dict(json.loads(path.read_text(encoding="utf-8")))
    if "validation_people" not in record:
        raise SystemExit(f"{path} has no score on the validation people: train it again with bench/learners.py")
    return record


def _ensemble(folder: Path, row: str, members: list[int], args: argparse.Namespace) -> dict[str, Any]:
    """The ensemble of ``members`` scored on the held-out episodes and the validation people (kept in ``folder``)."""
    from agents.evaluate import evaluate
    from agents.rl.callbacks import VALIDATION_SEED
    from agents.rl.ensemble import load_ensemble

    def measure() -> dict[str, Any]:
        agent = load_ensemble([folder / f"{row}__{s}__{args.timesteps}" for s in members])
        test = evaluate(agent, ENV_ID, "test", args.episodes, 0)
        people = evaluate(agent, ENV_ID, "validation", args.validation_episodes, VALIDATION_SEED).summary()
        found = {**rates(test.summary()), "members": members, "by_persona": test.persona_rates()}
        print(
            f"ensemble {members}: held-out {found['success_rate']:.3f}, validation people {people['success_rate']:.3f}"
        )
        return {**found, "validation_people": rates(people)}

    return dict(kept_json(folder / f"ensemble__{row}__{members[0]}+{len(members)}.json", measure))


def _size(records: dict[int, dict[str, Any]], size: int, args: argparse.Namespace) -> dict[str, Any]:
    """Each run ``s`` of ``--seeds size``: the ensemble (``size > 1``) and the best seed, with the summary over runs."""
    runs: dict[str, list[dict[str, Any]]] = {"ensemble": [], "best": []}
    for start in range(args.runs_of):
        members = list(range(start, start + size))
        best = max(members, key=lambda s: (records[s]["validation_people"]["success_rate"], -s))
        runs["best"].append({**rates(records[best]), "members": members, "kept_seed": best})
        runs["best"][-1].update({key: records[best][key] for key in ("validation_people", "by_persona")})
        if size > 1:
            runs["ensemble"].append(_ensemble(args.runs, args.row, members, args))
    return {keep: {"runs": found, **_over_runs(found)} for keep, found in runs.items() if found}


def _over_runs(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """IQM of held-out success with its interval, and how the validation people's success predicts it."""
    from scipy import stats

    from agents.evaluate.headroom import iqm_across_runs

    held_out = [r["success_rate"] for r in runs]
    validation = [r["validation_people"]["success_rate"] for r in runs]
    iqm = iqm_across_runs({ENV_ID: held_out})
    constant = len(set(held_out)) < 2 or len(set(validation)) < 2
    pearson = None if constant or len(runs) < 3 else stats.pearsonr(validation, held_out)
    return {
        "success_iqm": iqm.iqm,
        "success_ci95": list(iqm.ci95),
        "success_mean": statistics.mean(held_out),
        "success_lowest": min(held_out),
        "unsafe_mean": statistics.mean(r["unsafe_rate"] for r in runs),
        "pearson_r": None if pearson is None else float(pearson.statistic),
        "pearson_r_ci95": None if pearson is None else list(pearson.confidence_interval()),
    }


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python bench/ensembles.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=Path, required=True, help="bench/learners.py's folder of finished runs")
    parser.add_argument("--row", default="jax-kalman-lag", help="the learners row whose seeds are played")
    parser.add_argument("--runs-of", type=positive_int, default=16, help="train.py --seed s for s below this")
    parser.add_argument("--sizes", type=seed_list, default=[2, 4], help="--seeds N of each run, joined by ','")
    parser.add_argument("--timesteps", type=positive_int, default=1_000_000, help="the runs' training budget")
    parser.add_argument("--episodes", type=positive_int, default=2000, help="held-out episodes per agent")
    parser.add_argument("--validation-episodes", type=positive_int, default=1000, help="validation people's")
    add_save_argument(parser, "ensembles.json")
    return parser


def main(argv: list[str] | None = None) -> int:
    """Score every size's runs; print them, and with ``--save`` write the report."""
    args = _parser().parse_args(argv)
    if 0 in args.sizes:
        raise SystemExit("--sizes: each N must be >= 1")
    seeds = range(args.runs_of + max(args.sizes) - 1)
    records = {s: _record(args.runs, args.row, s, args.timesteps) for s in seeds}
    scripted_file = args.runs / f"scripted__{args.episodes}.json"
    if not scripted_file.is_file():
        raise SystemExit(f"no {scripted_file}: bench/learners.py --episodes {args.episodes} writes it")
    report: dict[str, Any] = {
        "env_id": ENV_ID,
        "row": args.row,
        "timesteps": args.timesteps,
        "episodes": args.episodes,
        "validation_episodes": args.validation_episodes,
        "scripted": json.loads(scripted_file.read_text(encoding="utf-8")),
        "sizes": {str(n): _size(records, n, args) for n in sorted({1, *args.sizes})},
    }
    for size, kept in report["sizes"].items():
        for keep, found in kept.items():
            print(f"--seeds {size} --keep {keep}: IQM {found['success_iqm']:.3f}, lowest {found['success_lowest']:.3f}")
    if args.save:
        save(args.save, "ensembles", argv, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
