"""Where a benchmark's figures live: one JSON file per measurement under ``bench/results/``.

Every bench script takes ``--save [PATH]``: without it the script only prints; with it the
script also writes its report to ``PATH`` (default ``bench/results/<name>.json``, the file
``python bench/report.py`` renders ``docs/BENCHMARKS.md`` from). A results file holds

- ``benchmark``: the script's name (``run``, ``cold_start``, ...);
- ``command``: the command line that produced it, to rerun it;
- ``date``: when it finished (UTC);
- ``machine``: core count, load average at the end, and the versions of Python, NumPy, numba,
  Gymnasium, coop_gym (and of torch, SB3 and JAX when the run used them);
- ``results``: the script's own report.

The figures quoted in ``docs/BENCHMARKS.md`` come only from these files. What the trainers share
(``bench/learners.py``, ``bench/time_to_quality.py``, ``bench/library_defaults.py``, ``bench/cleanrl_defaults.py``,
``bench/ensembles.py``: the held-out scores, the IQM over runs, the run folders, a config's sizing) follows the
files' handling; the formatting the sections of the page share (``bench/report.py``) is at the end of this module.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import shlex
import statistics
import sys
from collections.abc import Callable, Sequence
from importlib import metadata
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
RESULTS = BENCH / "results"
if str(ROOT) not in sys.path:  # run as a script from a checkout: import coop_gym and agents from it
    sys.path.insert(0, str(ROOT))


def add_save_argument(parser: argparse.ArgumentParser, default: str) -> None:
    """``--save [PATH]``: also write the report as JSON (``default`` under ``bench/results/``)."""
    parser.add_argument(
        "--save",
        nargs="?",
        const=str(RESULTS / default),
        metavar="PATH",
        help=f"also write the report as JSON to PATH (default without PATH: bench/results/{default}, "
        "what docs/BENCHMARKS.md is rendered from)",
    )


def summary(values: Sequence[float]) -> dict[str, Any]:
    """Median and min..max of repeated measurements, with the values themselves."""
    return {"median": statistics.median(values), "min": min(values), "max": max(values), "values": list(values)}


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def cpu(cpuinfo: Path = Path("/proc/cpuinfo")) -> str | None:
    """The CPU's model name and its widest vector extension (``"... (avx512f)"``), from ``cpuinfo``.

    The vector extension decides which kernels NumPy's BLAS, MKL and XLA run, so a training
    seed's weights (docs/agents.md, "Reproducibility"); None where ``cpuinfo`` is missing.
    """
    try:
        text = cpuinfo.read_text(encoding="utf-8")
    except OSError:
        return None
    fields = dict(
        (key.strip(), value.strip())
        for key, _, value in (line.partition(":") for line in text.splitlines())
        if key.strip() in ("model name", "flags")
    )
    flags = set(fields.get("flags", "").split())
    widest = next((flag for flag in ("avx512f", "avx2", "avx", "sse4_2") if flag in flags), None)
    name = fields.get("model name") or platform.processor() or None
    return None if name is None else f"{name} ({widest})" if widest else name


def machine() -> dict[str, Any]:
    """What the figures were measured on: cores, CPU, load and the versions that set the speed."""
    info: dict[str, Any] = {
        "cpu_count": os.cpu_count(),
        "cpu": cpu(),
        "load_average_1min": os.getloadavg()[0],
        "platform": f"{platform.system()} {platform.machine()}",
        "python": platform.python_version(),
    }
    for package in ("numpy", "numba", "gymnasium", "coop_gym"):
        info[package] = _version(package)
    # torch, SB3 and JAX only where the run imported them (their version changes learning speed).
    for module, package in (("torch", "torch"), ("stable_baselines3", "stable_baselines3"), ("jax", "jax")):
        if module in sys.modules:
            info[package] = _version(package)
    return info


def command_line(script: str, argv: Sequence[str] | None) -> str:
    """The command that reruns this measurement (``argv``: the flags; None = ``sys.argv[1:]``)."""
    flags = list(sys.argv[1:] if argv is None else argv)
    return shlex.join(["python", f"bench/{script}.py", *flags])


def save(path: str | Path, benchmark: str, argv: Sequence[str] | None, results: dict[str, Any]) -> Path:
    """Write ``results`` with the command, the date and the machine to ``path``; returns it."""
    from coop_gym.io import write_json

    record = {
        "benchmark": benchmark,
        "command": command_line(benchmark, argv),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": machine(),
        "results": results,
    }
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    write_json(target, record)
    print(f"wrote {target}", file=sys.stderr)
    return target


def load_all(folder: Path = RESULTS) -> dict[str, dict[str, Any]]:
    """Every results file in ``folder``, by file stem."""
    return {path.stem: json.loads(path.read_text(encoding="utf-8")) for path in sorted(folder.glob("*.json"))}


# --- what the trainers share ---------------------------------------------------------------------

# Scores of a trained learner on the held-out personas, beside the handbook caregiver's (library_defaults.py,
# cleanrl_defaults.py): every agent plays the same seeded episodes of the held-out personas; the handbook plays
# them on CoopGym/SitToStand-v0 (the same model and people as the unit-scaled ids; the observation it reads).
REFERENCE_ENV_ID = "CoopGym/SitToStand-v0"


def held_out_report(
    run: dict[str, Any], agents: dict[str, tuple[Any, bool]], env_id: str, episodes: int
) -> dict[str, Any]:
    """``run`` with the scores of ``agents`` (label: (agent, deterministic)) and the handbook's."""
    from agents.evaluate import evaluate

    scores = {"handbook": evaluate("handbook", REFERENCE_ENV_ID, "test", episodes, 0).summary()}
    for label, (agent, deterministic) in agents.items():
        scores[label] = evaluate(agent, env_id, "test", episodes, 0, deterministic=deterministic).summary()
    for label, score in scores.items():
        print(f"{label:>12}: success {score['success_rate']:.3f}, unsafe {score['unsafe_rate']:.3f}")
    return {**run, "env_id": env_id, "episodes": episodes, "reference_env_id": REFERENCE_ENV_ID, "scores": scores}


CLEANRL_ENV_ID = "CoopGym/SitToStandHardDiscreteUnit-v2"
"""The id CleanRL's ``ppo.py`` gets: hard-v2 with Discrete actions and unit-scaled observations (the same episodes)."""
RATE_KEYS = ("success_rate", "unsafe_rate", "premature_rate", "timeout_rate")
"""The outcome rates a run keeps of an evaluation summary (:meth:`agents.evaluate.results.EvaluationResult.summary`)."""


def rates(summary: dict[str, Any]) -> dict[str, Any]:
    """The :data:`RATE_KEYS` of an evaluation summary."""
    return {key: summary[key] for key in RATE_KEYS}


def iqm_ci(values: Sequence[float]) -> dict[str, Any]:
    """``{"iqm", "ci95"}`` of runs' scores: the interquartile mean and its stratified bootstrap 95 % interval
    (rliable's method, :func:`agents.evaluate.headroom.iqm_across_runs`); one run: its score, ``[None, None]``."""
    from agents.evaluate.headroom import iqm_across_runs

    if len(values) < 2:
        return {"iqm": values[0], "ci95": [None, None]}
    found = iqm_across_runs({"runs": list(values)})
    return {"iqm": found.iqm, "ci95": list(found.ci95)}


def kept_json(path: Path, make: Callable[[], Any] | None) -> Any:
    """The JSON at ``path``, written there first from ``make()`` where there is none (None: none and no ``make``).

    A sweep keeps each finished run (and its references) in its folder, so a rerun skips what is there.
    """
    from coop_gym.io import write_json

    if not path.exists():
        if make is None:
            return None
        write_json(path, make())
    return json.loads(path.read_text())


def sizing(size: str) -> tuple[int, int | None] | None:
    """``N`` or ``N-eE`` (N envs, E epochs per update) as ``(N, E or None)``; None if it is neither.

    The sizing after ``@`` in a contender of ``bench/time_to_quality.py`` and in a row of ``bench/learners.py``.
    """
    found = re.fullmatch(r"([1-9][0-9]*)(?:-e([1-9][0-9]*))?", size)
    if found is None:
        return None
    return int(found.group(1)), int(found.group(2)) if found.group(2) else None


def resized(config: Any, size: str) -> Any:
    """``config`` on ``N`` envs with the same samples per update (``n_envs * n_steps``), and ``E`` epochs if given."""
    found = sizing(size)
    assert found is not None, size
    n_envs, epochs = found
    batch = config.n_envs * config.algo_kwargs["n_steps"]
    if batch % n_envs:
        raise ValueError(f"N must divide the {batch}-step rollout of its config, got {n_envs}")
    kwargs = {**config.algo_kwargs, "n_steps": batch // n_envs}
    if epochs is not None:
        kwargs["n_epochs"] = epochs
    return config.replace(n_envs=n_envs, algo_kwargs=kwargs)


def import_learners(jax: bool) -> None:
    """Import torch and SB3 (and JAX): :func:`machine` then records the versions the runs trained with.

    A run may have trained in a worker process, or from a record, so the saving process imports them itself.
    """
    import stable_baselines3  # noqa: F401
    import torch  # noqa: F401

    if jax:
        import jax as _jax  # noqa: F401


# --- the formatting shared by the sections of docs/BENCHMARKS.md (bench/report.py) ---------------

Results = dict[str, dict[str, Any]]
TIMES = "\N{MULTIPLICATION SIGN}"


def _pct(rate: float | None) -> str:
    return "—" if rate is None else f"{100 * rate:.1f} %"


def _ci(interval: Sequence[float] | None) -> str:
    if interval is None or None in interval:  # no interval (one run)
        return ""
    return f"[{100 * interval[0]:.1f}, {100 * interval[1]:.1f}]"


def _rate(row: dict[str, Any], outcome: str, interval: bool = True) -> str:
    """``76.0 % [74.1, 77.8]``: an outcome rate of an evaluation summary with its 95 % interval."""
    text = _pct(row[f"{outcome}_rate"])
    return f"{text} {_ci(row[f'{outcome}_rate_ci95'])}" if interval else text


def _points(value: float, interval: Sequence[float] | None = None) -> str:
    """A difference of rates in percentage points: ``+24.0 [+22.2, +25.8]``."""
    text = f"{100 * value:+.1f}"
    return text if interval is None else f"{text} [{100 * interval[0]:+.1f}, {100 * interval[1]:+.1f}]"


def _two_decimals(value: float, interval: Sequence[float | None] | None = None) -> str:
    """A score to two decimals with its 95 % interval where it has one: ``0.42 [0.31, 0.55]``."""
    text = f"{value:.2f}"
    return text if interval is None or None in interval else f"{text} [{interval[0]:.2f}, {interval[1]:.2f}]"


def _spread(summary: dict[str, Any], digits: int = 2, unit: str = TIMES) -> str:
    """Median and min..max of repeats: ``0.78x (0.74..0.86)`` (with a multiplication sign)."""
    return f"{summary['median']:.{digits}f}{unit} ({summary['min']:.{digits}f}..{summary['max']:.{digits}f})"


def _kwargs(settings: dict[str, Any]) -> str:
    return ", ".join(f"`{key}={value}`" for key, value in settings.items())


def _mb(value: float | None) -> str:
    return "—" if value is None else f"{value:.0f} MB"


def _count(value: float) -> str:
    return f"{value:,.0f}"


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def _provenance(record: dict[str, Any]) -> str:
    """The command, date and machine of a results file, as one line under a section's heading."""
    m = record["machine"]
    versions = ", ".join(
        f"{name} {m[key]}"
        for name, key in (
            ("Python", "python"),
            ("NumPy", "numpy"),
            ("numba", "numba"),
            ("torch", "torch"),
            ("SB3", "stable_baselines3"),
            ("JAX", "jax"),
        )
        if m.get(key)
    )
    return (
        f"*Measured by* `{record['command']}` · {record['date']} · {m['cpu_count']} cores"
        f"{' (' + m['cpu'] + ')' if m.get('cpu') else ''}, "
        f"load average {m['load_average_1min']:.1f} at the end · {versions}"
    )


def _missing(command: str) -> str:
    saving = command if re.search(r"(^| )--save( |$)", command) else f"{command} --save"
    return f"No results file yet: `{saving}`, then `python bench/report.py`."


def _from_results(
    stem: str, heading: str, command: str
) -> Callable[[Callable[[dict[str, Any], dict[str, Any]], str]], Callable[[Results], str]]:
    """A section drawn from one results file: ``heading``, the file's provenance, then the body.

    The decorated function gets the file's report and the whole record and returns the body;
    without the file the section names ``command``, which makes it.
    """

    def wrap(body: Callable[[dict[str, Any], dict[str, Any]], str]) -> Callable[[Results], str]:
        def section(results: Results) -> str:
            record = results.get(stem)
            if record is None:
                return f"{heading}\n\n{_missing(command)}\n"
            return f"{heading}\n\n{_provenance(record)}\n\n{body(record['results'], record)}"

        section.__name__ = body.__name__
        return section

    return wrap
