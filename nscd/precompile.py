"""Compile the main job's kernels ahead of time: a step of installing nscd.

numba compiles each kernel at its first call with new argument types and keeps the machine
code in its cache (``__pycache__`` beside the sources, or the folder ``NUMBA_CACHE_DIR``
names); every later process loads it from there. Without more, a fresh install would compile
in its first run: tens of seconds (``benchmarks/results/first_run.md``). Installing nscd
(``pip install``: ``setup.py``'s build step) runs ``python -m nscd.precompile --store``,
which compiles them into the package's compiled store ``nscd/_compiled`` instead
(:mod:`nscd._jit`), by running what the main job
(``examples/single_block/free_rocking.py``) runs, briefly: the 2D engine with default
settings on a block released from a tilt, through its first impacts, and Housner's
rocking model beside it: the compiled steps of a small scene (``nscd.compiled_step.plain_steps``,
2D), the general step's stages at the impacts, the solver's Newton. A run that uses other
kernels (3D scenes, the theta scheme, large problems, ground motions) compiles those at its
first call, as before.

``python -m nscd.precompile`` alone compiles into numba's cache (after an edit of the
sources, say, which leaves the store unused); running it again is cheap: what is cached is
loaded, not compiled.
"""
from __future__ import annotations

import argparse
import time

WIDTH, HEIGHT = 0.5, 1.5  # m, the main job's block
T_END = 1.0  # s: past the block's first two impacts (0.43 s and 0.80 s), so the impact stages compile


def precompile() -> float:
    """Run the main job's stages once (a short free rocking of the engine and of Housner's
    model), compiling and caching their kernels. Returns the wall time it took, s."""
    import nscd

    start = time.perf_counter()
    housner = nscd.HousnerBlock(width=WIDTH, height=HEIGHT, eta=None)
    theta0 = housner.alpha / 2
    scene, _ = nscd.tilted_block(WIDTH, HEIGHT, theta0)
    nscd.simulate(scene, t_end=T_END, dt=1e-3)
    housner.simulate(None, t_end=T_END, theta0=-theta0)
    return time.perf_counter() - start


def main() -> None:
    """``python -m nscd.precompile [--store]``: compile, and say how long it took."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--store", action="store_true",
                        help="compile every kernel afresh into the package's compiled store (the install's step)")
    store = parser.parse_args().store
    from nscd import _jit

    if store:
        _jit.build_store()
    where = f"the compiled store {_jit.STORE}" if store else "numba's cache"
    print(f"nscd: compiling the engine's kernels ahead of time into {where} ...", flush=True)
    print(f"nscd: done in {precompile():.0f} s")


if __name__ == "__main__":
    main()
