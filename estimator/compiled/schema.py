"""Packed rows with named columns: one name per quantity from the dataclass down to the kernel.

The kernels work on flat float rows (a person's parameters, the filter's nominal model,
the env's scalars, its state and its report). Each row's column order is *derived* here
from one list of names -- a dataclass's fields (nested dataclasses flattened) plus the
derived columns declared beside it -- never numbered by hand:

>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Spring:
...     stiffness_n_per_m: float = 2.0
...     damping_n_s_per_m: float = 0.5
>>> SPRING = index_table("Spring", field_names(Spring) + ("period_s",))
>>> SPRING.damping_n_s_per_m, SPRING.period_s, len(SPRING)
(1, 2, 3)

A table is a ``namedtuple`` instance of ints. Numba freezes a global tuple into the
machine code, so ``p[SPRING.stiffness_n_per_m]`` inside ``@njit`` compiles to the same
constant index as a literal ``0`` (the bench checks it stays as fast), and
:mod:`estimator.compiled.cache` re-keys the disk cache when the list changes.
"""

from __future__ import annotations

import dataclasses
from collections import namedtuple
from collections.abc import Iterable, Mapping
from typing import Any

__all__ = ["field_names", "field_values", "index_table", "offset_table"]


def _nested(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def field_names(cls: type) -> tuple[str, ...]:
    """The fields of dataclass ``cls`` in order; a field whose default is a dataclass is flattened in place."""
    names: list[str] = []
    for field in dataclasses.fields(cls):
        default = field.default
        if _nested(default):
            names.extend(field_names(type(default)))
        else:
            names.append(field.name)
    return tuple(names)


def field_values(obj: Any) -> dict[str, Any]:
    """``{name: value}`` of dataclass instance ``obj``, flattened like :func:`field_names`."""
    values: dict[str, Any] = {}
    for field in dataclasses.fields(obj):
        value = getattr(obj, field.name)
        if _nested(value):
            values.update(field_values(value))
        else:
            values[field.name] = value
    return values


def index_table(typename: str, columns: Iterable[str]) -> Any:
    """A namedtuple instance mapping each column name to its index 0, 1, ...; a repeated name raises."""
    columns = tuple(columns)
    repeated = sorted({name for name in columns if columns.count(name) > 1})
    if repeated:
        raise ValueError(f"{typename}: column name(s) used twice: {', '.join(repeated)}")
    return namedtuple(typename, columns)(*range(len(columns)))


def offset_table(typename: str, widths: Mapping[str, int]) -> Any:
    """A namedtuple instance of the start of each block laid end to end, plus ``end`` (the total width)."""
    starts = [0]
    for width in widths.values():
        starts.append(starts[-1] + int(width))
    return namedtuple(typename, (*widths, "end"))(*starts)  # type: ignore[arg-type]
