"""Compilation with numba (a required dependency): one switch for every compiled kernel.

``njit`` compiles a function with numba (``cache=True``: the compiled code is kept in
``__pycache__``, so only the first run of a fresh install compiles; ``fastmath=False``:
IEEE arithmetic, the same bits as the uncompiled code). There is one source per kernel
and no numpy twin. To run the kernels as plain Python (to step through them in a
debugger), set the environment variable ``NUMBA_DISABLE_JIT=1`` before importing nscd.

What keeps the compilation of a fresh install short (``benchmarks/bench_first_run.py``
lists what compiles, and for how long; ``python -m nscd.precompile`` compiles the main
job's kernels as a step of installing):

- pass C-contiguous arrays: a strided view (a column, ``a[:, 0]``) compiles a second
  specialisation of the kernel and of every compiled function it calls;
- copy into an array element by element: a slice assignment from an array
  (``a[i, :] = b``) compiles numba's shape-mismatch message, seconds of string formatting;
- keep chains of compiled calls short: a compiled callee is optimised and code-generated
  again inside each compiled caller, so every level of calls compiles its callees once more.
"""
from __future__ import annotations

from typing import Callable, TypeVar

import numba as _numba

F = TypeVar("F", bound=Callable)

def njit(function: F) -> F:
    """``numba.njit(cache=True, fastmath=False)``."""
    return _numba.njit(cache=True, fastmath=False)(function)
