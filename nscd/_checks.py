"""Argument checks shared by the public entry points: every refusal names the parameter,
its value and what is allowed.

Any real number type is a number here (Python ``int``/``float``, numpy scalars such as
``np.float32`` and ``np.int64``, ``fractions.Fraction``...): they are tested with
:class:`numbers.Real` and numpy dtypes, never with ``isinstance(x, (int, float))``.
``bool`` is refused where a quantity is expected (``True`` is an ``int`` to Python, but
``density=True`` is a mistake).
"""
from __future__ import annotations

import numbers
from typing import Any

import numpy as np

__all__ = ["flag", "real_number", "selection"]


def real_number(name: str, value: Any) -> float:
    """``value`` as a Python float, or TypeError naming ``name`` when it is not a real number.

    Accepts every :class:`numbers.Real` (numpy scalars included) and 0-d numeric arrays;
    NaN and infinities pass (range checks are the caller's).
    """
    if isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf":
        value = value.item()
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} == {value!r} ({type(value).__name__}), must be a real number.")
    return float(value)


def flag(name: str, value: Any) -> bool:
    """``value`` as a bool: only ``True``/``False`` (and numpy bools), never a truthy string."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} == {value!r}, must be True or False.")
    return bool(value)


def selection(name: str, value: Any, size: int) -> np.ndarray:
    """Indices of ``size`` entries chosen by an index, a sequence of indices or a boolean mask.

    Raises
    ------
    TypeError
        ``value`` is neither integers nor booleans.
    ValueError
        An index outside ``[0, size)`` or a mask whose length is not ``size``.
    """
    chosen = np.asarray(value)
    if chosen.dtype == bool:
        if chosen.shape != (size,):
            raise ValueError(f"{name} is a boolean mask of shape {chosen.shape}, must have shape ({size},).")
        return np.flatnonzero(chosen)
    if chosen.dtype.kind not in "iu" and chosen.size:
        raise TypeError(f"{name} == {value!r}, must be an index, indices or a boolean mask of {size} entries.")
    chosen = chosen.astype(np.intp).reshape(-1)
    outside = chosen[(chosen < 0) | (chosen >= size)]
    if outside.size:
        raise ValueError(f"{name} == {value!r}: index {int(outside[0])} is outside [0, {size}) ({size} entries).")
    return chosen
