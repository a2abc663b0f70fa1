"""The validators of the scalars a user hands in (plain Python: what counts as a number, and its range).

One place decides what counts as a number, so every validator of the project agrees:

* a number is a real number (``numbers.Real``): Python's ``int`` and ``float`` and NumPy's
  integer and floating scalars (``np.float32(0.02)``, ``np.int64(5)``) -- but never a ``bool``
  or ``np.bool_`` (``True`` is an ``int`` to Python, not a value anyone means as a rate);
* an integer is an ``int`` or a NumPy integer scalar (again not a bool);
* an array is never a scalar, not even one of size 1 (``np.array([1])`` is refused with the
  name of the argument, instead of being compared element-wise or truncated with a warning).

Accepted NumPy scalars come back as the Python number of the same value (:func:`python_scalar`),
so a frozen dataclass stores ``0.019999999552965164``, not an ``np.float32`` that would turn later
arithmetic into float32.

On the lowest layer, beside :mod:`estimator.compiled` (``tests/test_layers.py``): the person's
parameters (``coop_gym.model``) and the filters (``estimator``) both validate with it, and
neither may import the other. It imports nothing of the project.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any, TypeGuard

import numpy as np

__all__ = ["check_choice", "check_flag", "check_integer", "check_number", "is_integer", "is_number", "python_scalar"]


def is_number(value: Any) -> bool:
    """Whether ``value`` is a real scalar that is not a bool: ``int``, ``float`` or a NumPy number scalar."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def is_integer(value: Any) -> TypeGuard[int | np.integer[Any]]:
    """Whether ``value`` is an integer scalar that is not a bool: ``int`` or a NumPy integer scalar."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def python_scalar(value: Any) -> Any:
    """``value`` as a Python scalar: a NumPy scalar becomes its ``int``/``float``/``bool``, anything else is kept."""
    return value.item() if isinstance(value, np.generic) else value


def check_number(name: str, value: Any, low: float = -math.inf, high: float = math.inf) -> Any:
    """Return ``value`` (as a Python number) if it is a finite number in ``[low, high]``, else raise ``ValueError``.

    Example:
        >>> check_number("Timing.dt_s", np.float32(0.5), 0.0, 1.0)
        0.5
        >>> check_number("Timing.dt_s", True, 0.0, 1.0)
        Traceback (most recent call last):
        ...
        ValueError: Timing.dt_s must be a number, got True
    """
    if not is_number(value):
        raise ValueError(f"{name} must be a number, got {value!r}")
    if not math.isfinite(value) or not (low <= value <= high):
        raise ValueError(f"{name} must be in [{low}, {high}], got {value!r}")
    return python_scalar(value)


def check_integer(name: str, value: Any, low: int, high: int) -> int:
    """Return ``value`` as an ``int`` if it is an integer in ``[low, high]``, else raise ``ValueError``."""
    if not is_integer(value) or not low <= value <= high:
        raise ValueError(f"{name} must be an int in [{low}, {high}], got {value!r}")
    return int(value)


def check_choice(name: str, value: Any, choices: Sequence[int]) -> int:
    """Return ``value`` as an ``int`` if it is a number equal to one of ``choices``, else raise ``ValueError``.

    Example:
        >>> check_choice("initial_xi", np.int8(-1), (-1, 0, 1))
        -1
        >>> check_choice("initial_xi", np.array([1]), (-1, 0, 1))
        Traceback (most recent call last):
        ...
        ValueError: initial_xi must be -1, 0 or 1, got array([1])
    """
    if not is_number(value) or value not in choices:
        listed = ", ".join(str(c) for c in choices[:-1]) + f" or {choices[-1]}" if len(choices) > 1 else str(choices[0])
        raise ValueError(f"{name} must be {listed}, got {value!r}")
    return int(value)


def check_flag(name: str, value: Any) -> bool:
    """Return ``value`` as a ``bool`` if it is ``True``/``False`` (or ``np.True_``/``np.False_``), else raise."""
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError(f"{name} must be a bool, got {value!r}")
    return bool(value)
