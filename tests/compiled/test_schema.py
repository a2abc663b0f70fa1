"""Named index tables: a packed row's columns come from one list of names."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pytest
from numba import njit

from estimator.compiled.schema import field_names, field_values, index_table, offset_table


@dataclass(frozen=True)
class _Inner:
    gain_per_s: float = 2.0
    enabled: bool = True


@dataclass(frozen=True)
class _Outer:
    step_s: float = 0.1
    inner: _Inner = _Inner()
    count: int = 3


def test_field_names_flatten_nested_dataclasses_in_order() -> None:
    assert field_names(_Outer) == ("step_s", "gain_per_s", "enabled", "count")
    assert field_values(_Outer()) == {"step_s": 0.1, "gain_per_s": 2.0, "enabled": True, "count": 3}


def test_a_new_field_propagates_to_the_table() -> None:
    # Adding a field to the dataclass is the one edit: the table grows by that name, in place.
    grown = dataclasses.make_dataclass("_Grown", [("new_rate_per_s", float, 0.5)], bases=(_Inner,), frozen=True)
    table = index_table("Grown", (*field_names(grown), "derived"))
    assert table._fields == ("gain_per_s", "enabled", "new_rate_per_s", "derived")
    assert tuple(table) == (0, 1, 2, 3)


def test_index_table_rejects_a_repeated_name() -> None:
    with pytest.raises(ValueError, match="used twice: a"):
        index_table("Bad", ("a", "b", "a"))


def test_offset_table_lays_blocks_end_to_end() -> None:
    blocks = offset_table("Blocks", {"first": 3, "second": 0, "third": 2})
    assert (blocks.first, blocks.second, blocks.third, blocks.end) == (0, 3, 3, 5)


_TABLE = index_table("Kernel", ("a", "b", "c"))


@njit
def _read(row: np.ndarray) -> float:
    return row[_TABLE.c] - row[_TABLE.a]


def test_tables_are_compile_time_constants_in_kernels() -> None:
    assert _read(np.array([1.0, 5.0, 4.0])) == 3.0
