"""Compilation with numba (a required dependency): one switch for every compiled kernel.

``njit`` compiles a function with numba (``cache=True``: the compiled code is kept in
``__pycache__``, so only the first run of a fresh install compiles; ``fastmath=False``:
IEEE arithmetic, the same bits as the uncompiled code). ``njit_helper`` compiles a
function that only other compiled functions call: the same machine code, without the
entry from Python (called from Python, it runs as plain Python). There is one source per
kernel and no numpy twin. To run the kernels as plain Python (to step through them in a
debugger), set the environment variable ``NUMBA_DISABLE_JIT=1`` before importing nscd.

What keeps the compilation of a fresh install short (``benchmarks/bench_first_run.py``
lists what compiles, and for how long; ``python -m nscd.precompile`` compiles the main
job's kernels as a step of installing):

- no wrapper that nothing calls: numba lowers beside each compiled function an entry for
  C callers (a ``cfunc`` wrapper: never used here, not built) and one for Python callers
  (unboxing every argument: about 60 ms of compilation for ten array arguments, not built
  for ``njit_helper`` functions);
- pass C-contiguous arrays: a strided view (a column, ``a[:, 0]``) compiles a second
  specialisation of the kernel and of every compiled function it calls;
- pass a compiled callee variables, not constants: a literal argument (``f(x, 0)``,
  ``f(x, True)``) compiles a specialisation of ``f`` for that value, beside the one for
  the argument's type (a variable assigned a constant is typed as that literal too;
  ``np.int64(0)`` is not);
- copy into an array element by element: a slice assignment from an array
  (``a[i, :] = b``) compiles numba's shape-mismatch message, seconds of string formatting;
- keep chains of compiled calls short: a compiled callee is optimised and code-generated
  again inside each compiled caller, so every level of calls compiles its callees once more;
  a large function with a single call site (a loop over scenes around one scene's steps) is
  ``njit_helper(inline=True)``: compiled inside its caller only. Not every helper: numba's
  inlining pass is slow, and a helper called from several places is compiled at each.
"""
from __future__ import annotations

from typing import Callable, TypeVar

import numba as _numba
from numba.core import config as _config
from numba.core.registry import CPUDispatcher as _CPUDispatcher

F = TypeVar("F", bound=Callable)

#: Options of every compiled function (see the module docstring).
_OPTIONS = {"fastmath": False, "no_cfunc_wrapper": True}


def njit(function: F | None = None, *, nogil: bool = False) -> F:
    """``numba.njit(cache=True, fastmath=False)``, without the C entry nothing calls;
    ``@njit(nogil=True)``: the kernel releases the GIL (threads may run it side by side)."""
    if function is None:
        return lambda f: njit(f, nogil=nogil)
    return _numba.njit(cache=True, nogil=nogil, **_OPTIONS)(function)


class _HelperDispatcher(_CPUDispatcher):
    """A numba dispatcher compiled without its entry from Python: compiled code calls its
    machine code; a call from Python (a kernel's ``py_func`` stepped in a debugger) runs the
    plain Python function."""

    def __call__(self, *args, **kwargs):
        return self.py_func(*args, **kwargs)


def njit_helper(function: F | None = None, *, inline: bool = False) -> F:
    """Compile ``function`` as :func:`njit` does, for compiled callers: numba builds no entry
    from Python (unboxing its arguments), which cuts its compilation; a call from Python runs
    the plain Python function. With ``NUMBA_DISABLE_JIT=1``, the plain Python function.

    ``@njit_helper(inline=True)``: numba compiles no machine code of the function's own; its
    body is compiled inside each compiled caller (numba's ``inline="always"``, typed there).
    For a large function that one caller calls once: compiled on its own, it would be
    optimised and generated twice, alone and again inside its caller."""
    if function is None:
        return lambda f: njit_helper(f, inline=inline)
    if _config.DISABLE_JIT:
        return function
    options = {**_OPTIONS, "nopython": True, "no_cpython_wrapper": True}
    if inline:
        options["inline"] = "always"
    dispatcher = _HelperDispatcher(py_func=function, locals={}, targetoptions=options)
    dispatcher.enable_caching()
    return dispatcher
