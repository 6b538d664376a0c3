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

The compiled store: installing nscd (``pip install``, the build step of ``setup.py``) runs
:mod:`nscd.precompile`, which compiles the main job's kernels ahead of time into the
package's own folder ``nscd/_compiled`` (numba's cache format: machine code for this
machine's processor). Every kernel looks there first, then in numba's cache (``__pycache__``
beside the sources, or ``NUMBA_CACHE_DIR``), and compiles only what neither holds. Both are
stamped with the contents of every source file of the package (and numba's version, which
numba's index records): an edited source or another numba version leaves them unused, and the
kernels compile at first call as without them. numba's own stamp is the modification time and
size of the kernel's own file alone; but a kernel's machine code holds that of every compiled
function it calls, from any module, so an edit of a callee's module (``state.py``, say) would
leave its callers in other modules (``stepper.py``, ``compiled_step.py``) running the callee's
old code from the cache, or failing in numba's runtime where their types no longer agree. With
the package's stamp nothing stale is ever run; the price is that any edit of the package
recompiles every kernel at its next call.
"""
from __future__ import annotations

import functools
import hashlib
import sys
from pathlib import Path
from typing import Callable, TypeVar

import numba as _numba
from numba.core import config as _config
from numba.core.caching import FunctionCache as _FunctionCache
from numba.core.caching import IndexDataCacheFile as _IndexDataCacheFile
from numba.core.registry import CPUDispatcher as _CPUDispatcher

F = TypeVar("F", bound=Callable)

#: Options of every compiled function (see the module docstring).
_OPTIONS = {"fastmath": False, "no_cfunc_wrapper": True}

#: The package's compiled store, written when nscd is installed (see the module docstring).
STORE = Path(__file__).resolve().parent / "_compiled"

#: True while :mod:`nscd.precompile` builds the store: every kernel compiled afresh (neither
#: store nor cache read) and written into the store, not into numba's cache.
_building_store = False


def build_store() -> None:
    """From now on in this process, compile every kernel afresh into :data:`STORE` (the
    install's step, :mod:`nscd.precompile`)."""
    global _building_store
    _building_store = True


@functools.cache
def package_stamp() -> str:
    """The SHA-256 of every source file of the package (its path and contents): the stamp of
    the compiled store, which holds each kernel with its compiled callees from any module."""
    root = Path(__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(root.rglob("*.py")):
        digest.update(str(source.relative_to(root)).encode())
        digest.update(source.read_bytes())
    return digest.hexdigest()


class _KernelCache(_FunctionCache):
    """numba's cache of one kernel, behind the package's compiled store: a compiled
    specialisation is looked up in :data:`STORE` first, then in numba's own cache (both
    stamped by :func:`package_stamp`); it is saved in numba's cache, or in the store while
    the store is built."""

    def __init__(self, py_func: Callable) -> None:
        super().__init__(py_func)
        # numba's cache stamped as the store is: by every source of the package, not the kernel's own file alone
        self._cache_file = _IndexDataCacheFile(cache_path=self._cache_path, filename_base=self._impl.filename_base,
                                               source_stamp=package_stamp())
        name = f"{py_func.__module__}.{py_func.__qualname__}".replace("<", "").replace(">", "")
        self._store = _IndexDataCacheFile(cache_path=str(STORE), source_stamp=package_stamp(),
                                          filename_base=f"{name}.py{sys.version_info[0]}{sys.version_info[1]}")

    def _load_overload(self, sig, target_context):
        if not self._enabled or _building_store:
            return None
        key = self._index_key(sig, target_context.codegen())
        data = self._store.load(key)
        if data is None:
            data = self._cache_file.load(key)
        return None if data is None else self._impl.rebuild(target_context, data)

    def _save_overload(self, sig, data) -> None:
        if not _building_store:
            super()._save_overload(sig, data)
        elif self._enabled and self._impl.check_cachable(data):
            STORE.mkdir(exist_ok=True)
            self._store.save(self._index_key(sig, data.codegen), self._impl.reduce(data))


def _cached(dispatcher):
    """``dispatcher`` with its compiled code kept by :class:`_KernelCache`."""
    dispatcher._cache = _KernelCache(dispatcher.py_func)
    return dispatcher


def njit(function: F | None = None, *, nogil: bool = False) -> F:
    """``numba.njit(cache=True, fastmath=False)``, without the C entry nothing calls, its
    compiled code kept by the store and numba's cache (:class:`_KernelCache`);
    ``@njit(nogil=True)``: the kernel releases the GIL (threads may run it side by side)."""
    if function is None:
        return lambda f: njit(f, nogil=nogil)
    if _config.DISABLE_JIT:
        return function
    return _cached(_numba.njit(nogil=nogil, **_OPTIONS)(function))


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
    optimised and generated twice, alone and again inside its caller; and for a small one
    called in a hot loop with arrays, whose calls cost as much as their work (each array
    passed as a structure, a reference to it taken and dropped)."""
    if function is None:
        return lambda f: njit_helper(f, inline=inline)
    if _config.DISABLE_JIT:
        return function
    options = {**_OPTIONS, "nopython": True, "no_cpython_wrapper": True}
    if inline:
        options["inline"] = "always"
    return _cached(_HelperDispatcher(py_func=function, locals={}, targetoptions=options))
