"""The learners' sections of docs/BENCHMARKS.md: learner x observation, across CPUs, budgets, selection.

Each renders one results file of ``bench/learners.py`` (``bench/result_files.py`` finds them); the
other quality sections are ``bench/report_quality.py``'s.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))  # bench/result_files.py, however this runs
from result_files import (
    Results,
    _ci,
    _count,
    _from_results,
    _pct,
    _provenance,
    _table,
    _two_decimals,
)


def _except_cleanrl(report: dict[str, Any]) -> str:
    """The learners page's exception: CleanRL's script keeps its own protocol."""
    if not any(name.startswith("cleanrl-") for name in report["rows"]):
        return ""
    return (
        " but the `cleanrl-*` ones (CleanRL's `ppo.py` as its user runs it: its settings or the flags"
        " and id the row names, its personas unless the row says otherwise, its final policy)"
    )


@_from_results("learners", "### Learners and observations on the hard level", "python bench/learners.py")
def learners(report: dict[str, Any], record: dict[str, Any]) -> str:
    """Learner x observation on the hard level (``bench/learners.py``)."""
    rows = []
    for name, row in report["rows"].items():
        per_seed = ", ".join(f"{100 * run['success_rate']:.1f}" for run in row["per_seed"])
        rows.append(_learner_row(f"`{name}`: {row['what']}", row, per_seed))
    for name, row in report["scripted"].items():
        rows.append([f"{name} (scripted)", "", _pct(row["success_rate"]), "", "", _pct(row["unsafe_rate"]), ""])
    header = [
        "learner: observation",
        "seeds",
        "success, IQM [95 % CI]",
        "mind-reading score, IQM [95 % CI]",
        "success per seed (%)",
        "unsafe (mean)",
        "training (median)",
    ]
    return f"""Each row{_except_cleanrl(report)} trains with `train.py`'s protocol on `{report["env_id"]}`
({report["timesteps"]:,} steps, the wider training personas, the best-validated policy of the last
half kept; the observation, action and normalisation the row names) once per training seed,
and plays the same {report["episodes"]} held-out episodes as the scripted caregivers below
(seeds 0..{report["episodes"] - 1}, the test personas). The interquartile mean over seeds and
its stratified bootstrap interval follow rliable; the mind-reading score is
`(success - blind) / (oracle - blind)` per seed. Training seconds were measured with other runs
on the machine.

{_table(header, rows)}
"""


def _seeds_at(runs: list[dict[str, Any]], level: float | None) -> str:
    return "—" if level is None else f"{sum(run['success_rate'] >= level for run in runs)}/{len(runs)}"


def _moved(changes: list[float]) -> str:
    """The median and the largest of per-seed changes of a rate, in points."""
    return "—" if not changes else f"{100 * statistics.median(changes):.1f} / {100 * max(changes):.1f}"


def _cpu_row(name: str, record: dict[str, Any], first: dict[int, float], is_reference: bool) -> list[str]:
    """Row ``name`` of one machine's ``learners*.json`` ``record``; ``first``: each seed's success on the first."""
    report = record["results"]
    row = report["rows"][name]
    runs = row["per_seed"]
    moved = [abs(run["success_rate"] - first[run["training_seed"]]) for run in runs if run["training_seed"] in first]
    return [
        f"`{name}`",
        record["machine"].get("cpu") or "not recorded",
        *_seed_cells(row, report["scripted"]),
        "(reference)" if is_reference else _moved(moved),
    ]


_SEED_COLUMNS = [
    "seeds",
    "validation: mean",
    "validation: lowest",
    "held-out success, IQM [95 % CI]",
    "held-out: lowest seed",
    "seeds ≥ belief",
    "seeds ≥ prober",
]
"""The columns of :func:`_seed_cells`."""


def _seed_cells(row: dict[str, Any], scripted: dict[str, Any]) -> list[str]:
    """A ``learners.json`` row over its seeds: validation, held-out, and the seeds at the scripted levels."""
    runs = row["per_seed"]
    validation = [run["validation_success_rate"] for run in runs if "validation_success_rate" in run]
    return [
        str(len(runs)),
        _pct(statistics.mean(validation)) if validation else "—",
        _pct(min(validation)) if validation else "—",
        f"{_pct(row['success']['iqm'])} {_ci(row['success']['ci95'])}",
        _pct(min(run["success_rate"] for run in runs)),
        _seeds_at(runs, scripted.get("belief", {}).get("success_rate")),
        _seeds_at(runs, scripted.get("prober", {}).get("success_rate")),
    ]


OTHER_SECTIONS_RECORDS = ("learners_ppo", "learners_bodies", "learners_recurrent", "learners_lstm")
"""``bench/learners.py``'s results files that hold other sections' rows (another learner, other people), not the
rows of ``learners.json`` trained on another CPU."""


def _cpu_record(stem: str) -> bool:
    """Whether ``stem`` is ``learners.json``'s rows on some CPU: ``learners`` or ``learners_<cpu>``."""
    others = stem.startswith(BUDGET_PREFIX) or stem in OTHER_SECTIONS_RECORDS
    return stem == "learners" or (stem.startswith("learners_") and not others)


def learners_across_cpus(results: Results) -> str:
    """The same rows and seeds of ``bench/learners.py`` trained on several CPUs (``learners*.json``)."""
    head = "### The same seeds on another CPU\n"
    records = {stem: record for stem, record in results.items() if _cpu_record(stem)}
    if "learners" not in records or len(records) < 2:
        return (
            f"{head}\nNo second machine yet: on a CPU other than `bench/results/learners.json`'s, `python"
            " bench/learners.py --rows jax-kalman --seeds 0,1,2,3,4,5,6,7 --save bench/results/learners_<cpu>.json`,"
            " then `python bench/report.py`.\n"
        )
    reference = records["learners"]["results"]["rows"]
    ordered = ["learners", *sorted(stem for stem in records if stem != "learners")]
    rows: list[list[str]] = []
    for name in reference:
        holders = [stem for stem in ordered if name in records[stem]["results"]["rows"]]
        if len(holders) < 2:  # a row on the first machine only
            continue
        first = {run["training_seed"]: run["success_rate"] for run in reference[name]["per_seed"]}
        rows.extend(_cpu_row(name, records[stem], first, stem == "learners") for stem in holders)
    header = [
        "row",
        "CPU (widest vector extension)",
        *_SEED_COLUMNS,
        "held-out change per seed: median / largest (points)",
    ]
    provenance = "\n\n".join(_provenance(records[stem]) for stem in ordered if stem != "learners")
    return f"""{head}
{provenance}

A seed trains the same weights in every process on one machine, not on another CPU: NumPy's BLAS,
MKL and XLA pick their kernels by the CPU's vector extensions and add in another order
(docs/agents.md, "Reproducibility"). Each row here is trained by `bench/learners.py` on the
same seeds on each machine and scored on the same held-out episodes; the first machine's rows
are those of the table above (`bench/results/learners.json`), and the last column compares each
seed's held-out success with that seed's there.

{_table(header, rows)}
"""


BUDGET_PREFIX = "learners_budget_"
"""``bench/results/learners_budget_<steps>.json``: the default learner on another budget (:func:`training_budget`)."""


def training_budget(results: Results) -> str:
    """``train.py``'s learner on several budgets, the same seeds on one CPU (``learners_budget_*.json``)."""
    head = "### Training budget\n"
    budgets = [record for stem, record in sorted(results.items()) if stem.startswith(BUDGET_PREFIX)]
    command = (
        "`python bench/learners.py --rows jax-kalman-lag --seeds 0,1,...,15 --timesteps T --save "
        "bench/results/learners_budget_T.json`"
    )
    if not budgets:
        return f"{head}\nNo results file yet: {command}, then `python bench/report.py`.\n"
    from agents.hyperparams import hyperparams_for

    train_steps = hyperparams_for("ppo").total_timesteps
    cpu = budgets[0]["machine"].get("cpu")
    same_cpu = [
        record
        for stem, record in sorted(results.items())
        if (_cpu_record(stem) or stem.startswith(BUDGET_PREFIX)) and record["machine"].get("cpu") == cpu
    ]
    rows = []
    for record in sorted(same_cpu, key=lambda r: r["results"]["timesteps"]):
        report = record["results"]
        row = report["rows"].get("jax-kalman-lag")
        if row is None:
            continue
        steps = report["timesteps"]
        budget = f"**{_count(steps)}**" if steps == train_steps else _count(steps)
        rows.append([budget, *_seed_cells(row, report["scripted"])])
    header = ["budget (env steps)", *_SEED_COLUMNS]
    provenance = "\n\n".join(_provenance(record) for record in budgets)
    return f"""{head}
{provenance}

`train.py`'s settings (`jax-kalman-lag`, trained by `JaxPPO` in these records) on other budgets, its learning
rate decaying to 0 over each, the same sixteen seeds on one CPU ({cpu or "not recorded"}), each run keeping its
best-validated policy of the last half and scored on the held-out episodes of [Learners and
observations](#learners-and-observations-on-the-hard-level); the {_count(train_steps)}-step row is
that section's on this CPU ([The same seeds on another CPU](#the-same-seeds-on-another-cpu)).
Trained by {command}.

{_table(header, rows)}
"""


_PEOPLE_COMMAND = "python bench/learners.py --rows jax-kalman-lag --seeds 0,1,...,15 --people --runs runs/people"


def _corr(value: float | None) -> str:
    """A correlation to two decimals; "—" where it is undefined (a constant input)."""
    return "—" if value is None else f"{value:.2f}"


_SELECTING = {"train": "training personas' validation episodes", "validation": "validation people"}


@_from_results("selection_people", "### Selecting on the validation people", _PEOPLE_COMMAND)
def selection_people(report: dict[str, Any], record: dict[str, Any]) -> str:
    """How well each selecting set predicts the held-out people across seeds (``bench/learners.py --people``)."""
    belief = report["scripted"]["belief"]["success_rate"]
    tables = []
    for name, row in report["rows"].items():
        if (study := row.get("people")) is None:  # a row without --people's scores, or under 3 seeds
            continue
        cells = []
        for rule, label in _SELECTING.items():
            found = study[rule]
            kept, pairs = found["kept_target_success"], found["best_of_pairs_target_success"]
            r, (low, high) = _corr(found["pearson_r"]), (_corr(c) for c in found["pearson_r_ci95"])
            cells.append([label, f"{r} [{low}, {high}]", _corr(found["spearman_rho"])])
            cells[-1] += [_corr(found["candidates_pearson_r"]), f"{_pct(statistics.mean(kept))} / {_pct(min(kept))}"]
            cells[-1] += [f"{sum(k >= belief for k in kept)} of {len(kept)}"]
            cells[-1] += [f"{_pct(statistics.mean(pairs))} / {_pct(min(pairs))}"]
        header = [f"`{name}`, selected on", "r: kept policy's score vs held-out success [95 % CI]", "Spearman rho"]
        header += ["r over every scored policy", "held-out success of the kept: mean / lowest"]
        header += [f"seeds ≥ belief ({_pct(belief)})", "better-scored of seeds s, s + n/2: held-out mean / lowest"]
        tables.append(f"{study['runs']} seeds of `{name}`:\n\n{_table(header, cells)}")
    return f"""Each seed trains as `train.py` does ({report["timesteps"]:,} steps on `{report["env_id"]}`); every policy
the selection scores (8 in the last half and the final one) plays three sets: 1000 validation episodes of the training
personas (today's selection), 1000 of the validation people (`personas="validation"`: 64 persons no training episode
shows, `coop_gym.model.personas.validation_people`) and the {report["episodes"]} held-out episodes of the test
people. Per selecting set: the policy each seed keeps (its best there, ties to the later), how its score there
correlates with its held-out success over seeds (Pearson r with its Fisher interval, Spearman rho) and over every
scored policy, what it scores held-out, and what keeping the better-scored of two seeds gives. The held-out scores
are recorded only to report; nothing is chosen on them.

{chr(10).join(tables)}
"""


def _kept_of_seeds(row: dict[str, Any]) -> dict[int, tuple[float, float, float]]:
    """Per training seed: (its kept policy's validation-people success, held-out success, held-out unsafe rate).

    Empty where the runs' scored policies carry no validation-people score (``bench/learners.py`` without ``--people``).
    """
    kept = {}
    for run in row["per_seed"]:
        scored = [c for c in run.get("candidates", []) if c["timesteps"] == run["kept_step"] and "validation" in c]
        if not scored:
            return {}
        kept[run["training_seed"]] = (scored[0]["validation"]["success_rate"], run["success_rate"], run["unsafe_rate"])
    return kept


def _best_of(kept: dict[int, tuple[float, float, float]], subsets: list[tuple[int, ...]]) -> list[tuple[float, float]]:
    """Held-out (success, unsafe) of the seed each subset keeps: best on the validation people, ties to the lower."""
    chosen = [max(subset, key=lambda seed: (kept[seed][0], -seed)) for subset in subsets]
    return [kept[seed][1:] for seed in chosen]


def _iqm_cell(success: list[float], report: dict[str, Any]) -> str:
    """IQM of runs' held-out success with its interval, and the mind-reading score of that IQM."""
    from agents.evaluate.headroom import iqm_across_runs

    if len(success) < 2:
        return "—"
    found = iqm_across_runs({report["env_id"]: success})
    blind, oracle = (report["scripted"][name]["success_rate"] for name in ("blind", "oracle"))
    score = f"{(found.iqm - blind) / (oracle - blind):.2f}" if oracle > blind else "—"
    return f"{_pct(found.iqm)} {_ci(found.ci95)}; {score}"


@_from_results("selection_people", "### Best of N seeds: `train.py --seeds N`", _PEOPLE_COMMAND)
def best_of_seeds(report: dict[str, Any], record: dict[str, Any]) -> str:
    """What ``train.py --seeds N`` keeps, from the per-seed records of ``bench/learners.py --people``."""
    import itertools

    belief, prober = (report["scripted"][name]["success_rate"] for name in ("belief", "prober"))
    row_name = "jax-kalman-lag"
    kept = _kept_of_seeds(report["rows"].get(row_name, {"per_seed": []}))
    if not kept:
        return f"The record has no `{row_name}` row with validation-people scores (`{_PEOPLE_COMMAND} --save`).\n"
    seeds = sorted(kept)
    rows = []
    for n in range(1, min(4, len(seeds)) + 1):
        every = _best_of(kept, list(itertools.combinations(seeds, n)))
        runs = _best_of(kept, [tuple(seeds[i : i + n]) for i in range(0, len(seeds) - n + 1, n)])
        success = sorted(s for s, _ in every)
        rows.append(
            [
                str(n),
                f"{_pct(statistics.mean(success))} / {_pct(success[len(success) // 10])} / {_pct(success[0])}",
                f"{_pct(sum(s < belief for s in success) / len(success))}",
                f"{_pct(sum(s < prober for s in success) / len(success))}",
                f"{_pct(statistics.mean(u for _, u in every))}",
                ", ".join(_pct(s) for s, _ in runs),
                _iqm_cell([s for s, _ in runs], report),
            ]
        )
    header = ["N", "held-out success: mean / 10th percentile / lowest", f"below belief ({_pct(belief)})"]
    header += [f"below prober ({_pct(prober)})", "unsafe (mean)", "`--seed 0, N, 2N, ...`: held-out success"]
    header += ["their IQM [95 % CI]; mind-reading score"]
    return f"""`train.py --seeds N --keep best` trains seeds `--seed` .. `--seed + N - 1`, each as `train.py --seed S`
does (its own selection on the training personas' validation episodes), scores each kept policy on 1000 episodes of the
validation people and keeps the best (PPO's default keeps them all as one: [Seeds played as
one](#seeds-played-as-one-trainpy-seeds-n-keep-ensemble)). Since a seed trains the same policy alone or in a `--seeds`
run, what `--seeds N --keep best` keeps
follows from the {len(seeds)} seeds of `{row_name}` above: every set of N of them (the first three columns), and
the runs `--seed 0`, `--seed N`, ... (the last). Held-out success on the {report["episodes"]} test episodes, recorded
only to report; nothing is chosen on them.

{_table(header, rows)}
"""


_PPO_COMMAND = (
    "python bench/learners.py --rows jax-kalman-lag --seeds 0,1,...,15 --save bench/results/learners_ppo.json"
)


def ppo_learner(results: Results) -> str:
    """``agents.ppo``'s rows beside ``JaxPPO``'s ``jax-kalman-lag`` of the learners records (the same protocol)."""
    head = "### The PPO learner `agents.ppo` against `JaxPPO`\n"
    record = results.get("learners_ppo")
    if record is None:
        return f"{head}\nNo results file yet: `{_PPO_COMMAND}`, then `python bench/report.py`.\n"
    report = record["results"]
    rows = [
        _learner_row(f"`{name}`: {row['what']}", row, _pct(row["min_success"])) for name, row in report["rows"].items()
    ]
    for stem in ("learners", "learners_avx512"):
        found = results.get(stem)
        if found is not None and "jax-kalman-lag" in found["results"]["rows"]:
            reference = found["results"]["rows"]["jax-kalman-lag"]
            label = f"`jax-kalman-lag`: `JaxPPO` (`bench/results/{stem}.json`)"
            rows.append(_learner_row(label, reference, _pct(reference["min_success"])))
    header = ["learner", "seeds", "success, IQM [95 % CI]", "mind-reading score, IQM [95 % CI]"]
    header += ["lowest seed", "unsafe (mean)", "training (median)"]
    return f"""{head}
{_provenance(record)}

{_learners_protocol(report)} The first row is
`train.py`'s learner (`agents.ppo`, policy lag 1), the `JaxPPO` rows the learner before it (policy lag 1, the same
settings) from the records named (their machines: the records' provenance). The two learners' seeds draw different
initial weights and actions.

{_table(header, rows)}
"""


_RECURRENT_COMMAND = (
    "python bench/learners.py --rows jax-lstm-kalman --seeds 0,1,...,9 --save bench/results/learners_recurrent.json"
)


@_from_results(
    "learners_recurrent",
    "### The recurrent learner `agents.ppo.recurrent` against `JaxRecurrentPPO`",
    _RECURRENT_COMMAND,
)
def recurrent_learner(report: dict[str, Any], record: dict[str, Any]) -> str:
    """``RecurrentPPO`` beside ``JaxRecurrentPPO``, the learner ``train.py --algo recurrent_ppo`` trained before it."""
    return f"""{_learners_protocol(report)} Each row's learner is
the one it names, on the same settings: `JaxRecurrentPPO` is the learner `train.py --algo recurrent_ppo --framework jax`
trained before `agents.ppo.recurrent.RecurrentPPO`, which it and the row `jax-lstm-kalman` train now
(`jax-lstm-kalman-agents-ppo` is that row under the name it had while both learners stood). Their seeds draw
different initial weights, actions and minibatch orders. {_recurrent_tables(report)}"""


_LSTM_COMMAND = (
    "python bench/learners.py --rows jax-lstm-raw,jax-lstm-population --seeds 0,1,2,3,4 "
    "--save bench/results/learners_lstm.json"
)


@_from_results("learners_lstm", "### The memory rows on `agents.ppo.recurrent`", _LSTM_COMMAND)
def recurrent_rows(report: dict[str, Any], record: dict[str, Any]) -> str:
    """The other ``jax-lstm-*`` rows trained by ``RecurrentPPO`` (the learners records hold ``JaxRecurrentPPO``'s)."""
    return f"""{_learners_protocol(report)} The rows are those of
[Learners and observations](#learners-and-observations-on-the-hard-level) and
[Across bodies](#across-bodies-what-the-observation-carries-to-people-not-met), trained by
`agents.ppo.recurrent.RecurrentPPO`, what they train today (those tables' records: `JaxRecurrentPPO`); `jax-lstm-kalman`
on it: the section above. {_recurrent_tables(report)}"""


def _recurrent_tables(report: dict[str, Any]) -> str:
    """The scripted caregivers' rates, the rows over their seeds, and each seed's held-out success."""
    scripted = report["scripted"]
    rows = [
        [
            f"`{name}`: {row['what']}",
            *_seed_cells(row, scripted),
            _score_cell(row["score"]),
            _pct(row["unsafe_rate_mean"]),
            f"{row['train_wall_s_median']:.0f} s",
        ]
        for name, row in report["rows"].items()
    ]
    header = ["learner", *_SEED_COLUMNS, "mind-reading score, IQM [95 % CI]", "unsafe (mean)", "training (median)"]
    on_these = ", ".join(f"{agent} {_pct(scripted[agent]['success_rate'])}" for agent in ("belief", "prober", "blind"))
    per_seed = [
        [f"`{name}`", ", ".join(f"{run['training_seed']}: {_pct(run['success_rate'])}" for run in row["per_seed"])]
        for name, row in report["rows"].items()
    ]
    return f"""On these episodes: {on_these}.

{_table(header, rows)}

{_table(["row", "held-out success of each training seed"], per_seed)}
"""


_PERSONA_COMMAND = "python bench/learners.py --rows jax-kalman-lag --seeds 0,1,...,31 --by-persona --save PATH"


@_from_results("learners_ppo", "### Where the learned caregiver loses, by held-out person", _PERSONA_COMMAND)
def by_persona(report: dict[str, Any], record: dict[str, Any]) -> str:
    """Each held-out persona's outcomes: the learned rows (mean over seeds, lowest..highest) beside the scripted."""
    scripted = report.get("scripted_by_persona")
    rows_with = {name: row for name, row in report["rows"].items() if "by_persona" in row}
    if scripted is None or not rows_with:
        return f"The record has no rates per persona: `{_PERSONA_COMMAND}`.\n"
    header = ["persona", "caregiver", "success", "unsafe", "premature", "timeout"]
    rows = []
    for persona in sorted(scripted["oracle"]):
        for name, row in rows_with.items():
            found = row["by_persona"][persona]
            low, high = found["success_rate_range"]
            label = f"`{name}`, mean of {row['runs']} seeds"
            success = f"{_pct(found['success_rate'])} ({100 * low:.1f}..{100 * high:.1f})"
            rows.append(
                [persona, label, success] + [_pct(found[f"{o}_rate"]) for o in ("unsafe", "premature", "timeout")]
            )
        for agent in ("belief", "prober", "blind", "oracle"):
            found = scripted[agent][persona]
            rows.append(
                [persona, agent] + [_pct(found[f"{o}_rate"]) for o in ("success", "unsafe", "premature", "timeout")]
            )
    episodes = {p: scripted["oracle"][p]["episodes"] for p in sorted(scripted["oracle"])}
    split = ", ".join(f"{p} {n}" for p, n in episodes.items())
    return f"""The held-out episodes of [The PPO learner](#the-ppo-learner-agentsppo-against-jaxppo) split by the
persona each person was drawn from ({split}): every seed's kept policy (success: the mean over seeds, then the
lowest and highest seed), and the scripted caregivers on the same episodes. The outcomes are the env's: success a
lift with the person cooperative and leaning forward, unsafe a lift while they resist or sit upright, premature any
other lift, timeout no lift in time.

{_table(header, rows)}
"""


def _learners_protocol(report: dict[str, Any]) -> str:
    """The sentence that says a ``learners*.json`` record's rows were trained and scored as ``learners.json``'s."""
    return f"""The rows train as those of [Learners and observations](#learners-and-observations-on-the-hard-level)
do ({report["timesteps"]:,} steps, the wider training personas, the best policy of the last half on the training
personas' validation episodes kept) and play the same {report["episodes"]} held-out episodes."""


def _score_cell(score: dict[str, Any]) -> str:
    """A row's mind-reading score, IQM [95 % CI], or a dash where it has none."""
    return "—" if score["iqm"] is None else _two_decimals(score["iqm"], score["ci95"])


def _learner_row(label: str, row: dict[str, Any], seeds: str) -> list[str]:
    """A ``learners*.json`` row's cells: seeds, success and mind-reading score (IQM [95 % CI]), ``seeds``, unsafe,
    training time."""
    success, score = row["success"], row["score"]
    return [
        label,
        str(row["runs"]),
        f"{_pct(success['iqm'])} {_ci(success['ci95'])}".rstrip(),
        _score_cell(score),
        seeds,
        _pct(row["unsafe_rate_mean"]),
        f"{row['train_wall_s_median']:.0f} s",
    ]


_BODIES_COMMAND = (
    "python bench/learners.py --rows jax-kalman-lag,jax-kalman-lag-population,jax-switching-population,"
    "jax-switching-true-population,jax-lstm-population --seeds 0,1,2,3 --save bench/results/learners_bodies.json"
)


def _bodies_cells(label: str, pairs: list[tuple[float, float]], frail: list[float], report: Any) -> list[str]:
    """One row of :func:`across_bodies`: ``pairs`` of (validation people's, held-out success) per seed."""
    validation, held_out = [v for v, _ in pairs], [h for _, h in pairs]
    gap = statistics.mean(v - h for v, h in pairs)
    belief = report["scripted"]["belief"]["success_rate"]
    return [
        label,
        str(len(pairs)),
        _pct(statistics.mean(validation)),
        _iqm_cell(held_out, report),
        f"{100 * gap:+.1f}",
        _pct(min(held_out)),
        _pct(statistics.mean(frail)) if frail else "—",
        f"{sum(h >= belief for h in held_out)} of {len(held_out)}",
    ]


def across_bodies(results: Results) -> str:
    """Training across bodies with and without the switching filter's ``P(xi)``: validation people against test."""
    head = "### Across bodies: what the observation carries to people not met\n"
    record = results.get("learners_bodies")
    if record is None:
        return f"{head}\nNo results file yet: `{_BODIES_COMMAND}`, then `python bench/report.py`.\n"
    report, rows = record["results"], []
    for name, row in report["rows"].items():
        pairs = [(run["validation_people"]["success_rate"], run["success_rate"]) for run in row["per_seed"]]
        frail = [run["by_persona"]["frail"]["success_rate"] for run in row["per_seed"] if "by_persona" in run]
        rows.append(_bodies_cells(f"`{name}`: {row['what']}", pairs, frail, report))
    header = ["learner: observation", "seeds", "validation people: mean", "held-out success, IQM [95 % CI]; score"]
    header += ["validation minus held-out (points, mean)", "held-out: lowest seed", "frail: mean", "seeds ≥ belief"]
    scripted = ", ".join(f"{name} {_pct(report['scripted'][name]['success_rate'])}" for name in report["scripted"])
    return f"""{head}
{_provenance(record)}

Each row trains as [Learners and observations](#learners-and-observations-on-the-hard-level) does
({report["timesteps"]:,} steps, the best policy of the last half on the training personas' validation episodes
kept; `agents.ppo` with policy lag 1, `train.py`'s learner, or for the `lstm` row the LSTM learner of
`train.py --algo recurrent_ppo`), the `-population` rows on 512 persons of the validation people's population
(`train_population`) instead of the wider training personas. Each seed's kept policy plays 1000
episodes of the validation people (the set every choice is made on) and the same {report["episodes"]} held-out
episodes of the test people ({scripted}); the gap column is the mean over seeds of the first minus the second.
The `switching` rows observe the switching filter's `P(xi)` beside the Kalman estimate: its person hypotheses
are weighed by the readings within each episode, and the `true` row's filter is given each episode's true
person instead (what a caregiver that had identified the person would read).

{_table(header, rows)}
"""


_ENSEMBLES_COMMAND = "python bench/ensembles.py --runs DIR --sizes 2,4 --save (DIR: bench/learners.py --runs DIR)"


@_from_results("ensembles", "### Seeds played as one: `train.py --seeds N --keep ensemble`", _ENSEMBLES_COMMAND)
def ensembles(report: dict[str, Any], record: dict[str, Any]) -> str:
    """What ``train.py --seeds N`` keeps as an ensemble and as the best seed, over runs ``--seed s``."""
    scripted = report["scripted"]
    belief, last = scripted["belief"]["success_rate"], len(report["sizes"]["1"]["best"]["runs"]) - 1
    rows = []
    for size, kept in report["sizes"].items():
        for keep, found in kept.items():
            runs = found["runs"]
            held_out = [r["success_rate"] for r in runs]
            r, interval = found["pearson_r"], found["pearson_r_ci95"] or [None, None]
            frail = [r["by_persona"]["frail"]["success_rate"] for r in runs if "by_persona" in r]
            rows.append(
                [
                    f"`--seeds {size}`" + ("" if size == "1" else f" `--keep {keep}`"),
                    str(len(runs)),
                    _pct(statistics.mean(r["validation_people"]["success_rate"] for r in runs)),
                    _iqm_cell(held_out, report),
                    f"{_pct(statistics.mean(held_out))} / {_pct(min(held_out))}",
                    f"{sum(h >= belief for h in held_out)} of {len(runs)}",
                    f"{_pct(found['unsafe_mean'])} / {_pct(max(r['unsafe_rate'] for r in runs))}",
                    _pct(statistics.mean(frail)) if frail else "—",
                    f"{_corr(r)} [{_corr(interval[0])}, {_corr(interval[1])}]",
                ]
            )
    header = ["kept", "runs", "validation people: mean", "held-out success, IQM [95 % CI]; score", "mean / lowest"]
    header += [f"runs ≥ belief ({_pct(belief)})", "unsafe: mean / highest", "frail: mean"]
    header += ["r: validation people vs held-out [95 % CI]"]
    references = ", ".join(f"{name} {_pct(scripted[name]['success_rate'])}" for name in scripted)
    unsafe = _pct(scripted["prober"]["unsafe_rate"])
    return f"""The runs `python train.py --seed s --seeds N` for s = 0..{last}, from the seeds of `{report["row"]}`
that `bench/learners.py` trained ({report["timesteps"]:,} steps each, as `train.py` trains a seed):
`--keep ensemble` plays the N seeds as one (`agents.rl.ensemble`: per action head, the action of highest
mean probability), `--keep best` keeps the seed best on {report["validation_episodes"]} episodes of the
validation people. Runs of consecutive s share seeds, as those commands do. Every caregiver plays the same
{report["episodes"]} held-out episodes of the test people ({references}; the prober's unsafe rate
{unsafe}); the last column is how each run's success on the validation people predicts its held-out
success over the runs. Nothing is chosen on the held-out scores: the keep and N are read from the validation
people's column (where `--keep best` is scored on the episodes it was picked on).

{_table(header, rows)}
"""
