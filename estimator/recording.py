"""The recording format of one sit-to-stand trial: a CSV file the estimators read offline.

One file holds one trial, sampled at a fixed rate. Comment lines (``#``) before the header
carry metadata as ``# key: value``; the header names the columns, each with its unit in its
suffix; each row is one sample:

.. code-block:: text

    # coop_gym recording v1
    # subject: s00
    # persona: typical
    # model: {"dt_s": 0.02, "damping_rate_per_s": 6.0, ...}
    time_s,shoulder_position_m,force_n,verbal_cue,cue_force_n,requested_xi,true_xi
    0.0,0.00312,0.41,0,0.0,1,1
    0.02,0.00298,-0.22,0,0.0,1,1

=======================  ========  ==========================================================
column                   required  meaning
=======================  ========  ==========================================================
``time_s``               yes       sample time [s], increasing at a fixed step (the filter's ``dt``)
``shoulder_position_m``  yes       measured forward shoulder displacement [m] (camera, motion capture)
``force_n``              yes       measured push force on the upper back [N] (the filter's ``c_p``)
``verbal_cue``           yes       verbal cue playing: -1 "lean back", 0 none, +1 "lean forward"
``cue_force_n``          no        the push the robot commanded [N]; marks the physical cue's onset
``requested_xi``         no        the cooperativeness the subject was asked to act (-1, 0, +1),
                                   the same on every row; the paper's tables need it
``true_xi``              no        the true cooperativeness per sample (-1, 0, +1; simulator only)
=======================  ========  ==========================================================

The initial cue onset is the first sample with a cue acting: ``cue_force_n > 0`` where that
column is present, else ``force_n`` above :data:`ONSET_FORCE_N`, or ``verbal_cue != 0``.
Metadata keys: ``model`` (a JSON object of :class:`~estimator.nominal.NominalModel` fields,
the filter's nominal model; default ``NominalModel()`` with ``dt_s`` from ``time_s``) and any
others (``subject``, ``persona``, ``source``), kept as text. A file that breaks a rule is
refused with a :class:`RecordingError` naming its line and column.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimator.nominal import NominalModel

__all__ = [
    "COLUMNS",
    "FORMAT_LINE",
    "ONSET_FORCE_N",
    "REQUIRED_COLUMNS",
    "Recording",
    "RecordingError",
    "format_recording",
    "parse_recording",
    "read_recording",
    "recordings_in",
]

FORMAT_LINE = "coop_gym recording v1"
"""The first comment line of every file this package writes (optional when reading)."""

REQUIRED_COLUMNS: tuple[str, ...] = ("time_s", "shoulder_position_m", "force_n", "verbal_cue")
COLUMNS: tuple[str, ...] = (*REQUIRED_COLUMNS, "cue_force_n", "requested_xi", "true_xi")
"""Every column the format knows, in the order it is written."""

ONSET_FORCE_N = 2.0
"""Without ``cue_force_n``, a measured force above this marks a push [N]: four times the
force sensor's noise std (0.5 N), so sensor noise alone does not start a judgment window."""

_XI_COLUMNS = ("verbal_cue", "requested_xi", "true_xi")
# A time step may wander by this fraction of dt (float rounding of written times), no more.
_DT_TOLERANCE = 1e-3


class RecordingError(ValueError):
    """A recording that breaks the format; the message names the file, line and column."""


@dataclass(frozen=True, eq=False)
class Recording:
    """One trial's samples (arrays of length ``T``), as read from or written to a file.

    Attributes:
        time_s: Sample times [s].
        shoulder_position_m: Measured shoulder position [m].
        force_n: Measured push force [N].
        verbal_cue: Verbal cue per sample, in {-1, 0, +1}.
        cue_force_n: Commanded push force [N], or ``None``.
        requested_xi: Requested cooperativeness per sample, or ``None``.
        true_xi: True cooperativeness per sample, or ``None``.
        model: The filter's nominal model, or ``None`` for ``NominalModel(dt_s=dt)``.
        meta: Other metadata (``subject``, ``persona``, ``source``...).
        name: Where it came from (a path), for messages.
    """

    time_s: NDArray[np.float64]
    shoulder_position_m: NDArray[np.float64]
    force_n: NDArray[np.float64]
    verbal_cue: NDArray[np.float64]
    cue_force_n: NDArray[np.float64] | None = None
    requested_xi: NDArray[np.float64] | None = None
    true_xi: NDArray[np.float64] | None = None
    model: NominalModel | None = None
    meta: Mapping[str, str] = field(default_factory=dict)
    name: str = "<recording>"

    @property
    def dt_s(self) -> float:
        """The sampling step [s] (the first interval; the reader checks the rest agree)."""
        return float(self.time_s[1] - self.time_s[0])

    @property
    def nominal_model(self) -> NominalModel:
        """The model the filter runs on: the recorded one, else the defaults at this recording's step."""
        return self.model if self.model is not None else NominalModel(dt_s=self.dt_s)

    @property
    def requested(self) -> int | None:
        """The trial's requested ``xi`` (``None`` if not recorded)."""
        return None if self.requested_xi is None else int(self.requested_xi[0])

    @property
    def cue_active(self) -> NDArray[np.bool_]:
        """(T,) whether a cue acts at each sample (see the module docstring for the onset rule)."""
        push = self.cue_force_n > 0.0 if self.cue_force_n is not None else self.force_n > ONSET_FORCE_N
        return np.asarray(push | (self.verbal_cue != 0.0), dtype=bool)


def format_recording(recording: Recording) -> str:
    """The CSV text of ``recording`` (every float written exactly, as Python's ``repr``)."""
    out = io.StringIO()
    out.write(f"# {FORMAT_LINE}\n")
    for key, value in recording.meta.items():
        out.write(f"# {key}: {value}\n")
    if recording.model is not None:
        out.write(f"# model: {json.dumps(dataclasses.asdict(recording.model))}\n")
    columns = [c for c in COLUMNS if getattr(recording, c) is not None]
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(columns)
    arrays = [getattr(recording, c) for c in columns]
    for values in zip(*arrays, strict=True):
        writer.writerow([_cell(c, v) for c, v in zip(columns, values, strict=True)])
    return out.getvalue()


def _cell(column: str, value: float) -> str:
    return str(int(value)) if column in _XI_COLUMNS else repr(float(value))


def read_recording(path: str | Path) -> Recording:
    """Read one recording file; :class:`RecordingError` names the line and column of the first problem."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise RecordingError(f"{path}: cannot read: {exc}") from exc
    return parse_recording(text, name=str(path))


def parse_recording(text: str, name: str = "<recording>") -> Recording:
    """Parse the CSV text of one recording (see the module docstring for the format)."""
    lines = text.splitlines()
    meta: dict[str, str] = {}
    model: NominalModel | None = None
    k = 0
    while k < len(lines) and (lines[k].startswith("#") or not lines[k].strip()):
        key, _, value = lines[k].lstrip("#").partition(":")
        if key.strip() == "model":
            model = _parse_model(value, name, k + 1)
        elif value and key.strip():
            meta[key.strip()] = value.strip()
        k += 1
    if k == len(lines):
        raise RecordingError(f"{name}: no header line (expected columns {', '.join(REQUIRED_COLUMNS)})")
    header = next(csv.reader([lines[k]]))
    columns = _check_header(header, name, k + 1)
    rows = list(csv.reader(lines[k + 1 :]))
    values = _parse_rows(rows, columns, name, first_line=k + 2)
    return _checked(values, columns, meta, model, name)


def _parse_model(text: str, name: str, line: int) -> NominalModel:
    try:
        return NominalModel.from_dict(json.loads(text))
    except (json.JSONDecodeError, TypeError, ValueError) as exc:
        raise RecordingError(f"{name}, line {line}: bad model: {exc}") from exc


def _check_header(header: list[str], name: str, line: int) -> list[str]:
    columns = [h.strip() for h in header]
    for col, column in enumerate(columns, start=1):
        if column not in COLUMNS:
            raise RecordingError(
                f"{name}, line {line}, column {col}: unknown column {column!r} (known: {', '.join(COLUMNS)})"
            )
        if columns.index(column) != col - 1:
            raise RecordingError(f"{name}, line {line}, column {col}: column {column!r} given twice")
    missing = [c for c in REQUIRED_COLUMNS if c not in columns]
    if missing:
        raise RecordingError(f"{name}, line {line}: missing column(s) {', '.join(missing)}")
    return columns


def _parse_rows(rows: list[list[str]], columns: list[str], name: str, first_line: int) -> NDArray[np.float64]:
    """(T, C) floats of the data rows; blank lines are skipped, anything else must be a finite number."""
    out = []
    for offset, row in enumerate(rows):
        line = first_line + offset
        if not row or all(not cell.strip() for cell in row):
            continue
        if len(row) != len(columns):
            raise RecordingError(f"{name}, line {line}: {len(row)} fields, the header has {len(columns)}")
        parsed = []
        for col, (column, cell) in enumerate(zip(columns, row, strict=True), start=1):
            try:
                value = float(cell)
            except ValueError:
                raise RecordingError(f"{name}, line {line}, column {col} ({column}): not a number: {cell!r}") from None
            if not math.isfinite(value):
                raise RecordingError(f"{name}, line {line}, column {col} ({column}): not finite: {cell!r}")
            if column in _XI_COLUMNS and value not in (-1.0, 0.0, 1.0):
                raise RecordingError(f"{name}, line {line}, column {col} ({column}): must be -1, 0 or 1, got {cell!r}")
            parsed.append(value)
        out.append((line, parsed))
    if len(out) < 2:
        raise RecordingError(f"{name}: needs at least 2 samples, got {len(out)}")
    lines = np.array([line for line, _ in out])
    data = np.array([p for _, p in out], dtype=np.float64)
    _check_times(data[:, columns.index("time_s")], lines, name, columns.index("time_s") + 1)
    if "requested_xi" in columns:
        req = data[:, columns.index("requested_xi")]
        if np.any(req != req[0]):
            bad = int(np.argmax(req != req[0]))
            raise RecordingError(
                f"{name}, line {lines[bad]}, column {columns.index('requested_xi') + 1} (requested_xi): "
                "must be the same on every row (one trial, one request)"
            )
    return data


def _check_times(time_s: NDArray[np.float64], lines: NDArray[np.int64], name: str, col: int) -> None:
    """Times must increase at one fixed step (the filter's dt)."""
    steps = np.diff(time_s)
    dt = steps[0]
    bad = np.flatnonzero((steps <= 0) | (np.abs(steps - dt) > _DT_TOLERANCE * abs(dt)))
    if bad.size:
        k = int(bad[0]) + 1
        raise RecordingError(
            f"{name}, line {lines[k]}, column {col} (time_s): samples must be evenly spaced and increasing "
            f"(step {dt:g} s, this one {steps[k - 1]:g} s)"
        )


def _checked(
    data: NDArray[np.float64],
    columns: list[str],
    meta: dict[str, str],
    model: NominalModel | None,
    name: str,
) -> Recording:
    arrays = {c: np.ascontiguousarray(data[:, j]) for j, c in enumerate(columns)}
    dt = float(arrays["time_s"][1] - arrays["time_s"][0])
    if model is not None and abs(model.dt_s - dt) > _DT_TOLERANCE * dt:
        raise RecordingError(f"{name}: the model's dt_s {model.dt_s:g} s is not the samples' step {dt:g} s")
    return Recording(**arrays, model=model, meta=meta, name=name)  # type: ignore[arg-type]


def recordings_in(paths: Iterable[str | Path]) -> list[Path]:
    """The recording files named: a file as given, a folder as its ``*.csv`` files in name order."""
    out: list[Path] = []
    for p in map(Path, paths):
        out.extend(sorted(p.glob("*.csv")) if p.is_dir() else [p])
    return out
