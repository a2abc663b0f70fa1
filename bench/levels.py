"""The levels: every baseline caregiver on the same held-out episodes of each level.

    python bench/levels.py [--episodes 2000] [--levels hard-v2,hard,medium,easy,v0] [--save [PATH]]

For each level id, the scripted caregivers (:data:`AGENTS`) and, on the hard level, the
models shipped in ``agents/pretrained`` play the same ``--episodes`` seeded episodes (seeds
0..N-1) of the held-out personas through :func:`agents.evaluate.evaluate` -- what
``python -m agents.evaluate --env ID --compare ... --personas test --episodes N`` does -- and
the report holds each agent's outcome rates with their 95 % intervals and the level's
headroom (:func:`agents.evaluate.headroom.headroom`): the oracle's success, the best blind
caregiver's, the value of reading the mind (oracle - best blind) and the achieved insight
(best reader - best blind), with paired bootstrap intervals. The oracle sees the person's
true cooperativeness: it is the reference every other row is read against.

``--save`` also writes the report to ``bench/results/levels.json`` (``bench/result_files.py``).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import add_save_argument, save

from coop_gym.cli import positive_int
from coop_gym.registration import LEVEL_ENV_IDS

LEVELS = dict(reversed(LEVEL_ENV_IDS.items()))
"""Each level's id, the hardest first (hard-v2, hard, medium, easy, v0)."""
AGENTS = ("oracle", "blind", "prober", "belief", "handbook", "push_then_lift")
PRETRAINED = {
    "hard-v2": ("pretrained:hard-v2-ppo", "pretrained:hard-v2-ppo-ensemble"),
    "hard": ("pretrained:hard-ppo", "pretrained:hard-ppo-switching"),
}


def level_report(env_id: str, agents: tuple[str, ...], episodes: int) -> dict[str, Any]:
    """Every agent on the same held-out episodes of ``env_id``: their summaries and the headroom."""
    from agents.evaluate import evaluate
    from agents.evaluate.report import results_json
    from agents.rl import load_agent

    results = []
    for name in agents:
        agent: Any = load_agent(name) if name.startswith("pretrained:") else name
        env_kwargs = None if isinstance(agent, str) else agent.env_kwargs
        result = evaluate(agent, env_id, "test", episodes, 0, env_kwargs=env_kwargs, name=name)
        print(f"  {name:>30}: success {result.success_rate:.3f}, unsafe {result.unsafe_rate:.3f}", file=sys.stderr)
        results.append(result)
    return {"env_id": env_id, **results_json(results)}


def main(argv: list[str] | None = None) -> int:
    """Parse the flags, score every level, print the success rates (and save with ``--save``)."""
    parser = argparse.ArgumentParser(prog="python bench/levels.py", description=__doc__.split("\n\n")[0])
    parser.add_argument("--episodes", type=positive_int, default=2000, help="held-out episodes per agent")
    parser.add_argument("--levels", default=",".join(LEVELS), help=f"comma-separated, of {', '.join(LEVELS)}")
    parser.add_argument("--no-pretrained", action="store_true", help="leave out the shipped models")
    add_save_argument(parser, "levels.json")
    args = parser.parse_args(argv)
    levels = [level for level in args.levels.split(",") if level]
    unknown = [level for level in levels if level not in LEVELS]
    if unknown or not levels:
        parser.error(f"--levels: unknown or empty {unknown or args.levels!r}; known: {', '.join(LEVELS)}")
    report: dict[str, Any] = {"episodes": args.episodes, "personas": "test", "seed": 0, "levels": {}}
    for level in levels:
        print(f"{level} ({LEVELS[level]})", file=sys.stderr)
        models = () if args.no_pretrained else PRETRAINED.get(level, ())
        report["levels"][level] = level_report(LEVELS[level], (*AGENTS, *models), args.episodes)
    if args.save:
        save(args.save, "levels", argv, report)
    return 0


if __name__ == "__main__":
    sys.exit(main())
