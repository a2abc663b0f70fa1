"""The quality sections of ``docs/BENCHMARKS.md``.

The levels, ``train.py``, the learners (and the same seeds on another CPU), library defaults (and
outside learners over seeds), RLlib, the paper's experiment.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/report_format.py, however this runs
from report_format import (
    TIMES,
    Results,
    _ci,
    _count,
    _from_results,
    _missing,
    _pct,
    _points,
    _provenance,
    _rate,
    _table,
)


def test_command(results: Results) -> str:
    return """\
## The test command

The README's test command is `.ci/run`: a fresh virtual environment, the CPU build of torch,
`python -m pytest` (the default suite), then the `[rllib]` install and the lowest supported
Gymnasium, each in its own environment (`scripts/test_other_installs.sh`). The slow suite is
`python -m pytest -m slow`. No bench script times them, so this page quotes no duration.
"""


def _level_agents(levels: dict[str, Any]) -> list[str]:
    names: list[str] = []
    for level in levels.values():
        names += [row["agent"] for row in level["results"] if row["agent"] not in names]
    return names


@_from_results("levels", "## Quality\n\n### The levels", "python bench/levels.py")
def the_levels(report: dict[str, Any], record: dict[str, Any]) -> str:
    levels = report["levels"]
    ids = ", ".join(f"`{level['env_id']}`" for level in levels.values())
    rows = []
    for name in _level_agents(levels):
        cells = []
        for level in levels.values():
            row = _row(level, name)
            cells.append("" if row is None else f"{_rate(row, 'success')}, unsafe {_rate(row, 'unsafe', False)}")
        rows.append([f"`{name}`", *cells])
    success = _table(["agent", *levels], rows)
    room_rows = []
    for lv, level in levels.items():
        room = level["headroom"]
        room_rows.append(
            [
                lv,
                _pct(room["oracle"]),
                f"{_pct(room['best_blind'])} (`{room['best_blind_agent']}`)",
                f"{_pct(room['best_reader'])} (`{room['best_reader_agent']}`)",
                _points(room["value_of_reading_the_mind"], room["value_of_reading_the_mind_ci95"]),
                _points(room["achieved_insight"], room["achieved_insight_ci95"]),
            ]
        )
    room_table = _table(
        ["level", "oracle", "best blind", "best reader", "value of reading the mind", "achieved insight"], room_rows
    )
    personas = ", ".join(next(iter(levels.values()))["results"][0]["personas"])
    first, last = report["seed"], report["seed"] + report["episodes"] - 1
    return f"""Held-out personas ({personas}), {report["episodes"]} seeded episodes per agent (seeds
{first}..{last}, the same episodes for every agent) on each level ({ids}), played through `agents.evaluate` as
`python -m agents.evaluate --env ID --compare AGENTS --personas test --episodes N` does. The
`oracle` sees the person's true cooperativeness (`xi`): the ceiling every row is read against.
`blind` is the mental-state-blind family's winner for the level (a schedule of cue phases with a
lift rule on the lean and the clock, chosen on the training personas; [The hard level](HARD_LEVEL.md));
`prober` asks with words alone and lifts on the answer; `belief` is the belief caregiver
([The hard level](HARD_LEVEL.md#the-belief-caregiver)); `handbook` is the paper's thresholded
Kalman judgment; `push_then_lift` pushes and lifts without a judgment. The `pretrained:` rows
are the models shipped in `agents/pretrained` (see [`train.py` on the hard level](#trainpy-on-the-hard-level)).

Success [95 % interval] and unsafe lifts:

{success}

The value of reading the mind is the oracle's success minus the best blind caregiver's; the
achieved insight is the best reader's (the best agent that is neither blind nor the oracle)
minus the best blind caregiver's; both with paired bootstrap 95 % intervals over the same
episodes (`agents.evaluate.headroom`):

{room_table}
"""


def _row(level: dict[str, Any], name: str) -> dict[str, Any] | None:
    return next((row for row in level["results"] if row["agent"] == name), None)


def train_py(results: Results) -> str:
    from agents.hyperparams import DEFAULT_ENV_IDS

    head = "### `train.py` on the hard level\n"
    record = results.get("levels")
    levels = {} if record is None else record["results"]["levels"]
    # The level of train.py's default env (hard-v2): its pretrained rows beside its baselines.
    hard = next((level for level in levels.values() if level["env_id"] == DEFAULT_ENV_IDS["ppo"]), None)
    if hard is None:
        return head + "\n" + _missing("python bench/levels.py --levels hard-v2") + "\n"
    names = [row["agent"] for row in hard["results"] if row["agent"].startswith("pretrained:")]
    names += ["prober", "belief", "blind", "handbook", "oracle"]
    scores = hard["headroom"].get("mind_reading_score", {})
    rows = []
    for name in names:
        row = _row(hard, name)
        if row is None:
            continue
        score = scores.get(name)
        rows.append(
            [
                f"`{name}`",
                _rate(row, "success"),
                _rate(row, "unsafe"),
                _rate(row, "premature", False),
                _rate(row, "timeout", False),
                _score(score),
            ]
        )
    header = ["agent", "success [95 % CI]", "unsafe [95 % CI]", "premature", "timeout", "mind-reading score"]
    table = _table(header, rows)
    return f"""{head}
{_provenance(record)}

`python train.py` on its defaults trains PPO on `{hard["env_id"]}` ([Agents and
training](agents.md#trainpy)). The models shipped in `agents/pretrained` are such runs (their
cards, `agents/pretrained/*.json`, record the settings and the training run); `bench/levels.py`
scores them on the hard level's held-out episodes beside the baselines of the same run. The
mind-reading score puts an agent's success on the scale from the best blind caregiver (0) to the
oracle (1), paired over the same episodes:

{table}

Only the shipped seeds are scored here; a spread over training seeds needs `python train.py
--seed S` per seed and `python -m agents.evaluate --runs RUN...`. The models trained on the
`-v1` hard level (train.py's default before `-v2`) are scored in the levels table above.
"""


def _score(score: dict[str, Any] | None) -> str:
    """A mind-reading score with its interval (blank where it is not defined)."""
    if score is None or score.get("score") is None:
        return ""
    interval = score.get("ci95") or (None, None)
    if None in interval:
        return f"{score['score']:.2f}"
    return f"{score['score']:.2f} [{interval[0]:.2f}, {interval[1]:.2f}]"


def library_defaults(results: Results) -> str:
    head = "### Library defaults\n"
    records = [r for stem, r in results.items() if stem.startswith(("library_defaults_", "cleanrl_defaults_"))]
    intro = """
What a user gets from a generic learner with its library's default settings, one training seed
each, scored greedy on held-out episodes beside the handbook caregiver on the same episodes
(`bench/result_files.py`; the handbook plays `CoopGym/SitToStand-v0`, the same model and people as
the unit-scaled ids, whose every observation feature is about [-1, 1]).
`bench/library_defaults.py` trains SB3's `PPO("MlpPolicy", id)` or `DQN("MlpPolicy", id)` as a
user writes it; `bench/cleanrl_defaults.py` runs CleanRL's `ppo.py` unmodified (fetched
separately; its tyro comes with coop_gym) and scores its agent both greedy and sampled.
"""
    if not records:
        return head + intro + "\n" + _missing("python bench/library_defaults.py --algo ppo") + "\n"
    sections = [head + intro]
    for record in sorted(records, key=lambda r: r["command"]):
        report = record["results"]
        learner = (
            f"CleanRL `{Path(report['script_command'][1]).name}`"
            if record["benchmark"] == "cleanrl_defaults"
            else f'SB3 `{report["algo"].upper()}("MlpPolicy", id)`'
        )
        rows = []
        for label, row in report["scores"].items():
            if label == "handbook":
                name = "handbook caregiver (reference)"
            else:
                name = f"{learner}, {int(label):,} steps" if label.isdigit() else f"{learner}, {label}"
            env_id = report["reference_env_id"] if label == "handbook" else report["env_id"]
            rows.append(
                [
                    name,
                    f"`{env_id}`",
                    _rate(row, "success"),
                    _rate(row, "unsafe", False),
                    _rate(row, "premature", False),
                    _rate(row, "timeout", False),
                ]
            )
        table = _table(["agent", "id", "success [95 % CI]", "unsafe", "premature", "timeout"], rows)
        sections.append(
            f"""{_provenance(record)}

{learner} on `{report["env_id"]}`, {_count(report["timesteps"])} training steps (seed {report["seed"]}, \
{report["wall_time_s"]:.0f} s of training), {report["episodes"]} held-out episodes:

{table}
"""
        )
    return "\n".join(sections)


def _seeds_row(name: str, per_seed: list[dict[str, Any]], success: dict[str, Any]) -> list[str]:
    cells = [
        f"{100 * r['success_rate']:.1f} / {100 * r.get('never_lift_rate', r.get('timeout_rate')):.1f}" for r in per_seed
    ]
    return [name, str(len(per_seed)), f"{_pct(success['iqm'])} {_ci(success['ci95'])}", "; ".join(cells)]


CLEANRL_SEEDS = "cleanrl_seeds_SitToStandHard-v2"
"""CleanRL's ``ppo.py`` over seeds on the hard level, its rows alone: ``bench/learners.py --rows cleanrl-...
--save bench/results/cleanrl_seeds_SitToStandHard-v2.json`` (another budget: ``..._<steps>.json``). Without
one the section takes ``learners.json``'s ``cleanrl-ppo`` and ``cleanrl-ppo-trainpy``."""


def _cleanrl_records(results: Results) -> list[tuple[dict[str, Any], list[tuple[str, dict[str, Any]]]]]:
    """Each record the CleanRL rows come from, with its rows: every row of the :data:`CLEANRL_SEEDS` files (the
    budgets in order), else two of learners'."""
    stems = sorted((s for s in results if s == CLEANRL_SEEDS or s.startswith(CLEANRL_SEEDS + "_")), key=len)
    records = [results[stem] for stem in stems]
    if records:
        return [(record, list(record["results"]["rows"].items())) for record in records]
    record = results.get("learners")
    if record is None:
        return []
    rows = record["results"]["rows"]
    return [(record, [(name, rows[name]) for name in ("cleanrl-ppo", "cleanrl-ppo-trainpy") if name in rows])]


def outside_learners(results: Results) -> str:
    """SB3 and CleanRL over training seeds on the hard level, as their users run them."""
    head = "### Outside learners over seeds on the hard level\n"
    record = results.get("library_seeds_SitToStandHard-v2")
    if record is None:
        return head + "\n" + _missing("python bench/library_defaults.py --seeds 0,1,2,3,4") + "\n"
    report = record["results"]
    rows = [_seeds_row(f"SB3 `{n}`: {r['what']}", r["per_seed"], r["success"]) for n, r in report["rows"].items()]
    cleanrl_line = ""
    for cleanrl, cleanrl_rows in _cleanrl_records(results):
        steps = f"{_count(cleanrl['results']['timesteps'])} steps"
        rows += [_seeds_row(f"`{n}`: {r['what']}, {steps}", r["per_seed"], r["success"]) for n, r in cleanrl_rows]
        cleanrl_line += f"\n\nThe `cleanrl-*` rows of {steps}: {_provenance(cleanrl)}"
    rows += [[f"{a} (scripted)", "", _pct(r["success_rate"]), ""] for a, r in report["scripted"].items()]
    header = ["learner, as its user runs it", "seeds", "success, IQM [95 % CI]", "per seed: success / never lifts (%)"]
    return f"""{head}
{_provenance(record)}{cleanrl_line}

What a user of SB3 or CleanRL gets on `{report["env_id"]}`: each learner trained once per seed,
its final policy scored greedy on the same {report["episodes"]} held-out episodes as the scripted
caregivers (`python -m agents.evaluate`, the test personas). *Never lifts* is the share of episodes
that end in a timeout. The SB3 rows are `bench/library_defaults.py --seeds` (SB3's defaults; the
package's settings from `agents.rl.sb3_settings`; RL Zoo's command of docs/integrations.md, its
final model loaded by the package's loader); the CleanRL rows are `bench/learners.py`'s
(CleanRL's `ppo.py` unmodified: its defaults; the flags of docs/integrations.md). The interquartile
mean over seeds and its stratified bootstrap interval follow rliable.

{_table(header, rows)}
"""


def rllib(results: Results) -> str:
    return """\
### RLlib

`python train.py --framework rllib` trains the same envs with Ray RLlib
([Integrations](integrations.md#ray-rllib)). No bench script measures its sampling speed or its
learning, so this page quotes no RLlib figure; score a run with
`python -m agents.evaluate --model RUN --personas test --episodes 1000`.
"""


def _kalman_table(estimators: dict[str, Any], labels: Sequence[str]) -> list[str]:
    """The paper's filter's P(judged | requested) beside the paper's."""
    sections: list[str] = []
    kalman = estimators.get("kalman")
    if kalman is not None:
        paper = kalman["paper"]["confusion"]
        rows = []
        for i, requested in enumerate(labels):
            total = sum(paper[i])
            cells = [
                f"{100 * kalman['p_estimated_given_requested_mean'][i][j]:.1f} ± "
                f"{100 * kalman['p_estimated_given_requested_std'][i][j]:.1f} % (paper {100 * paper[i][j] / total:.1f})"
                for j in range(3)
            ]
            rows.append([f"requested {requested}", *cells])
        table = _table(["P(judged \\| requested)", *(f"judged {label}" for label in labels)], rows)
        sections.append(
            f"""The paper's thresholded Kalman filter:

{table}

Accuracy {100 * kalman["accuracy"]:.1f} ± {100 * kalman["accuracy_std"]:.1f} % (paper \
{100 * kalman["paper"]["accuracy"]:.0f} %), balanced accuracy {100 * kalman["balanced_accuracy"]:.1f} ± \
{100 * kalman["balanced_accuracy_std"]:.1f} % (paper {100 * kalman["paper"]["balanced_accuracy"]:.1f} %).
"""
        )
    return sections


def _estimators_table(estimators: dict[str, Any], delay_s: float, cap: str) -> list[str]:
    """Every estimator on the same trials."""
    sections: list[str] = []
    names = {
        "kalman": "paper's thresholded KF",
        "multiple_model": "MMAE (plain nominal model)",
        "imm": "IMM (plain nominal model)",
        "delay_aware": "MMAE aware of the reaction delay",
        "persona_bank": "per-state filter bank (persona's delay, stiffness, noise)",
        "calibrated": "bank recalibrated on the subject's history",
        "switching": "switching particle filter (hypotheses around the training personas)",
        "oracle": "bound: the subject's true parameters",
    }
    rows = [
        [
            names.get(name, name),
            f"{100 * run['balanced_accuracy']:.1f} ± {100 * run['balanced_accuracy_std']:.1f}",
            f"{run['log_loss']:.2f}",
            f"{run['brier']:.2f}",
            f"{run['ece']:.2f}",
        ]
        for name, run in estimators.items()
    ]
    table = _table(["estimator", "balanced accuracy [%]", "log loss", "Brier", "ECE"], rows)
    sections.append(
        f"""Estimators on the same trials (judgment at {delay_s} s):

{table}

{cap}"""
    )
    return sections


def _levels_lines(report: dict[str, Any]) -> list[str]:
    """The paper's filter and the switching filter on each level's subjects."""
    sections: list[str] = []
    if report["difficulties"]:
        levels = ", ".join(
            f"{level} {100 * run['balanced_accuracy']:.1f} ± {100 * run['balanced_accuracy_std']:.1f} %"
            for level, run in report["difficulties"].items()
        )
        paper_ba = 100 * next(iter(report["difficulties"].values()))["paper"]["balanced_accuracy"]
        sections.append(
            f"""The paper's filter on the subjects of each level (`-v1`, and the hard `-v2`; `--difficulty LEVEL`),
balanced accuracy: {levels} (paper {paper_ba:.1f} %).
"""
        )
    if report.get("difficulties_switching"):
        levels = ", ".join(
            f"{level} {100 * run['balanced_accuracy']:.1f} ± {100 * run['balanced_accuracy_std']:.1f} %"
            for level, run in report["difficulties_switching"].items()
        )
        sections.append(
            f"""The switching particle filter on the same subjects, modelling each level's person
(`--difficulty LEVEL --estimator switching`), balanced accuracy: {levels}. It hedges over bodies
drawn around the training personas where the paper's filter is given each subject's persona
model, and 0.75 s after one cue the answer is within what that spread explains: it is built for
a level's long interactions ([Estimators](estimators.md#reading-the-mind-on-a-level)).
"""
        )
    return sections


def papers_experiment(results: Results) -> str:
    from coop_gym.model.params import Intention
    from estimator.judgment import ThresholdJudgment

    head = "### The paper's experiment\n"
    delay_s = ThresholdJudgment().delay_s
    reaction_s = Intention().reaction_delay_s
    cap = f"""At the paper's {delay_s} s the person has answered the cue for only ~{delay_s - reaction_s:.2f} s
({reaction_s} s reaction delay), which caps every estimator, the bound included.
"""
    record = results.get("papers_experiment")
    if record is None:
        return head + "\n" + _missing("python bench/papers_experiment.py") + "\n\n" + cap
    report = record["results"]
    estimators = report["estimators"]
    labels = ("uncooperative", "unresponsive", "cooperative")
    sections = [f"{head}\n{_provenance(record)}\n"]
    sections.append(
        f"""`python -m coop_gym.experiment.protocol --seeds {report["seeds"]} --estimator NAME --json`, run by
`bench/papers_experiment.py` for each estimator ([Estimators](estimators.md#the-papers-experiment)):
Bell & Asada's protocol (4 simulated subjects {TIMES} 25 trials, each asked to be uncooperative,
unresponsive or cooperative), judged at the paper's {delay_s} s, mean ± std over seeds
0..{report["seeds"] - 1}, beside the paper's table on real people.
"""
    )
    sections += _kalman_table(estimators, labels)
    sections += _estimators_table(estimators, delay_s, cap)
    sections += _levels_lines(report)
    return "\n".join(sections)
