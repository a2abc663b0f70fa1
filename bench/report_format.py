"""Formatting shared by the sections of ``docs/BENCHMARKS.md`` (``bench/report.py``)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

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
    return f"No results file yet: `{command} --save`, then `python bench/report.py`."


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
