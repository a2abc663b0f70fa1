"""The quality sections of ``docs/BENCHMARKS.md``.

The levels, ``train.py``, the learners (and the same seeds on another CPU), library defaults (and
outside learners over seeds), RLlib, the paper's experiment.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import (
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
    _two_decimals,
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
    if record is None or hard is None:
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
    return _two_decimals(score["score"], score.get("ci95"))


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
    never = [r["never_lift_rate"] if "never_lift_rate" in r else r["timeout_rate"] for r in per_seed]
    cells = [f"{100 * r['success_rate']:.1f} / {100 * n:.1f}" for r, n in zip(per_seed, never, strict=True)]
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


NEVER_LIFT = "never_lift_SitToStandHard-v2"
"""``bench/library_defaults.py --study never-lift --save``: why a library's defaults settle on never lifting."""
_OUTCOMES = ("success", "unsafe", "premature", "timeout")


def _first_steps_shares(per_seed: list[dict[str, Any]], chunk: int, chunks: int) -> list[str]:
    """Pooled over seeds, the share of training episodes ending in each outcome per ``chunk`` steps (the first
    ``chunks``): ``success / unsafe / premature / timeout`` in %."""
    cells = []
    for k in range(chunks):
        totals = dict.fromkeys(_OUTCOMES, 0)
        for run in per_seed:
            for b in run["training_bins"]:
                if k * chunk < b["to_step"] <= (k + 1) * chunk:
                    totals = {o: totals[o] + b[o] for o in _OUTCOMES}
        n = sum(totals.values())
        cells.append(" / ".join(f"{100 * totals[o] / n:.0f}" for o in _OUTCOMES) if n else "—")
    return cells


def _never_lift_tables(report: dict[str, Any]) -> tuple[str, str, str]:
    """The scores per cell and scripted row, the training episodes' outcomes, and the lift-hazard sweep."""
    scores, mechanism = [], []
    for name, row in report["rows"].items():
        cells = [f"`{name}`: {row['what']}", str(len(row["per_seed"]))]
        for people in ("validation", "train"):
            cells.append(f"{_pct(row[people]['success_iqm'])} {_ci(row[people]['success_ci95'])}")
            seeds = [s[people] for s in row["per_seed"]]
            cells.append("; ".join(f"{100 * s['success_rate']:.0f} / {100 * s['never_lift_rate']:.0f}" for s in seeds))
        scores.append(cells)
        runs = [s["training"] for s in row["per_seed"]]
        first = [_count(r["first_success_step"]) if r["first_success_step"] else "never" for r in runs]
        collapse = [_count(r["collapse_step"]) if r["collapse_step"] else "—" for r in runs]
        before = [str(r["successes_before_collapse"]) for r in runs]
        shares = _first_steps_shares(row["per_seed"], 50_000, 4)
        mechanism.append([f"`{name}`", "; ".join(first), "; ".join(collapse), "; ".join(before), *shares])
    for agent in report["scripted"]["validation"]:
        scripted = [report["scripted"][people][agent] for people in ("validation", "train")]
        scores.append(
            [f"{agent} (scripted)", "", _pct(scripted[0]["success_rate"]), "", _pct(scripted[1]["success_rate"]), ""]
        )
    header = [
        "trained",
        "seeds",
        "validation people: success, IQM [95 % CI]",
        "per seed: success / never lifts (%)",
        "training personas: success, IQM [95 % CI]",
        "per seed: success / never lifts (%)",
    ]
    shares = [f"steps {k * 50}k to {(k + 1) * 50}k: S / U / P / T (%)" for k in range(4)]
    mech_header = ["cell", "first successful lift (step), per seed", "stops lifting (step)", "successes by then"]
    hazard = [
        [f"{h['lift_hazard']:g}", *(_pct(h[f"{o}_rate"]) for o in _OUTCOMES), f"{h['mean_return']:+.2f}"]
        for h in report["lift_hazard"]
    ]
    hazard_header = ["lift probability per step", "success", "unsafe", "premature", "timeout", "mean return"]
    return _table(header, scores), _table(mech_header + shares, mechanism), _table(hazard_header, hazard)


@_from_results(
    NEVER_LIFT,
    "### Never lifting on the hard level: the measured why",
    "python bench/library_defaults.py --study never-lift --seeds 0,1,2,3,4",
)
def never_lift(report: dict[str, Any], record: dict[str, Any]) -> str:
    """Why CleanRL's defaults never lift on the hard level, measured on the validation people and training personas."""
    scores, mechanism, hazard = _never_lift_tables(report)
    return f"""Each cell is trained {_count(report["timesteps"])} steps once per seed, every training episode's outcome
logged with its step (`bench/cleanrl_defaults.py`'s `OutcomeLog`); its final policy is scored greedy on
{report["episodes"]} episodes (seeds from {report["episode_seed"]}) of the validation people and of the
training personas, never the test personas, the scripted caregivers on the same episodes. *Never lifts*:
the share of episodes ending in a timeout. The cells: CleanRL's `ppo.py` unmodified, on its defaults, on
`CoopGym/SitToStandHardDiscreteUnit-v2` (`cleanrl-ppo`), on the same id without unit scaling
(`-nounit`), with half its training episodes begun mid-guidance by the scripted oracle, handed over
before it would lift (`-midguidance`, `MidGuidance`), with a timeout priced as a failed assistance
(`-priced`, `PricedTimeout`), with `train.py`'s entropy bonus (`-ent02`), its rollout and update size
(`-rollout`) or all its PPO settings as flags (`-trainpy`); and SB3's
`PPO("MlpPolicy", make_vec_env(id, n_envs=8))` on `{report["env_id"]}`. Every policy is scored on an id
as registered (seated starts, the id's reward). The same script at 1M steps, on its defaults and with
`train.py`'s flags, is in the outside learners' table above.

{scores}

The training episodes: when each seed first lifted successfully, when it stopped lifting (the first
{_count(report["bin_steps"])}-step bin with at least 90 % timeouts), how many successful lifts it had
met by then, and, over all seeds, the share of episodes ending in success / unsafe / premature / timeout
(`-midguidance`'s include the episodes begun mid-guidance).

{mechanism}

What a policy that cues at random and lifts with a fixed probability per step meets (the training
personas): a fresh `Discrete(18)` network lifts with probability 0.5, and training lowers it.

{hazard}
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
