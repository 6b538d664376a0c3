"""Compilation with numba (a required dependency): one switch for every compiled kernel.

``njit`` compiles a function with numba (``cache=True``: the compiled code is kept in
``__pycache__``, so only the first run of a fresh install compiles; ``fastmath=False``:
IEEE arithmetic, the same bits as the uncompiled code). There is one source per kernel
and no numpy twin. To run the kernels as plain Python (to step through them in a
debugger), set the environment variable ``NUMBA_DISABLE_JIT=1`` before importing nscd.
"""
from __future__ import annotations

from typing import Callable, TypeVar

import numba as _numba

F = TypeVar("F", bound=Callable)

def njit(function: F) -> F:
    """``numba.njit(cache=True, fastmath=False)``."""
    return _numba.njit(cache=True, fastmath=False)(function)
