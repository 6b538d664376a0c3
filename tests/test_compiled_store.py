"""The compiled store (``nscd._jit``): a kernel compiled into it is loaded from it by a later
dispatcher, and only while the package's sources are those it was compiled from.

The end-to-end check (the install's step, then the main job compiling nothing; an edited
source compiling again) is ``tests/test_precompile.py`` (slow); this one runs a tiny kernel
against a store in a temporary folder, numba's own cache moved to another.
"""
from __future__ import annotations

from numba.core import config as _config
from numba.core.caching import IndexDataCacheFile

from nscd import _jit


def _twice(x):
    return 2.0 * x


def _kernel_without_numbas_cache(folder):
    """``_twice`` compiled by nscd's ``njit``, numba's own cache in the empty ``folder``: only
    the store can provide its machine code."""
    folder.mkdir(exist_ok=True)
    kernel = _jit.njit(_twice)
    kernel._cache._cache_file = IndexDataCacheFile(cache_path=str(folder), filename_base="twice",
                                                   source_stamp="the test's")
    return kernel


def test_a_kernel_in_the_store_is_loaded_from_it_while_the_sources_match(tmp_path, monkeypatch):
    monkeypatch.setattr(_jit, "STORE", tmp_path / "store")
    monkeypatch.setattr(_jit, "_building_store", True)
    built = _kernel_without_numbas_cache(tmp_path / "cache")
    assert built(1.5) == 3.0
    assert list((tmp_path / "store").glob("*.nbc")), "nothing written into the store"
    assert not list((tmp_path / "cache").glob("*")), "the store's build wrote into numba's cache"

    monkeypatch.setattr(_jit, "_building_store", False)
    loaded = _kernel_without_numbas_cache(tmp_path / "cache")
    assert loaded(1.5) == 3.0
    assert sum(loaded.stats.cache_hits.values()) == 1 and not sum(loaded.stats.cache_misses.values())

    monkeypatch.setattr(_jit, "package_stamp", lambda: "the sources edited")
    edited = _kernel_without_numbas_cache(tmp_path / "cache")
    assert edited(1.5) == 3.0
    assert not sum(edited.stats.cache_hits.values()) and sum(edited.stats.cache_misses.values()) == 1


def test_numbas_cache_is_used_only_while_the_package_sources_match(tmp_path, monkeypatch):
    """numba's own cache of a kernel is stamped, as the store is, by every source of the package:
    a kernel's machine code holds that of the compiled functions it calls from other modules, so
    an edit anywhere in the package must leave every cached kernel unused (numba's stamp alone,
    the kernel's own file, would keep running a callee's old code)."""
    monkeypatch.setattr(_jit, "STORE", tmp_path / "store")  # empty: only numba's cache can hold the kernel
    monkeypatch.setattr(_config, "CACHE_DIR", str(tmp_path / "cache"))
    first = _jit.njit(_twice)
    assert first(1.5) == 3.0
    assert list((tmp_path / "cache").rglob("*.nbc")), "nothing written into numba's cache"
    again = _jit.njit(_twice)
    assert again(1.5) == 3.0
    assert sum(again.stats.cache_hits.values()) == 1 and not sum(again.stats.cache_misses.values())

    monkeypatch.setattr(_jit, "package_stamp", lambda: "another module of the package edited")
    edited = _jit.njit(_twice)
    assert edited(1.5) == 3.0
    assert not sum(edited.stats.cache_hits.values()) and sum(edited.stats.cache_misses.values()) == 1
