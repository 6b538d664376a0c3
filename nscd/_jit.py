"""Optional compilation with numba (extra ``fast``): one switch for every compiled kernel.

``njit`` compiles a function with numba (``cache=True``, so the compiled code is kept in
``__pycache__`` between runs) when numba is installed, and returns the plain Python
function otherwise. Callers that would be slow in plain Python check ``HAVE_NUMBA`` and
take their numpy path instead; kernels stay importable either way.
"""
from __future__ import annotations

from typing import Callable, TypeVar

F = TypeVar("F", bound=Callable)

try:  # pragma: no cover - exercised by whichever environment runs the tests
    import numba as _numba
except ImportError:  # pragma: no cover
    _numba = None

#: True when numba is importable (``pip install nscd[fast]``).
HAVE_NUMBA: bool = _numba is not None


def njit(function: F) -> F:
    """``numba.njit(cache=True, fastmath=False)`` if numba is installed, else ``function`` itself."""
    if _numba is None:
        return function
    return _numba.njit(cache=True, fastmath=False)(function)
