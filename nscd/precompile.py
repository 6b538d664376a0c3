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
2D, its impacts located inside it), the solver's Newton. A run that uses other
kernels (3D scenes, the theta scheme, large problems, ground motions) compiles those at its
first call, as before.

``python -m nscd.precompile`` alone compiles into numba's cache (after an edit of the
sources, say, which leaves the store unused); running it again is cheap: what is cached is
loaded, not compiled. ``--all`` also runs, briefly, the engine's other families of kernels,
which otherwise compile at their first call: a driven base (a single-sine pulse), a stack of
three blocks at the friction limit in a batch of two (the rig's and the maps' path, with the
proximal point), a 2D wall's large problems (Gauss–Seidel and the coarse level) and the LNEC
trilith in 3D.
"""
from __future__ import annotations

import argparse
import math
import time

import numpy as np

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


def precompile_others() -> float:
    """Run the engine's other families of kernels once, briefly (see the module docstring).
    Returns the wall time it took, s."""
    import nscd
    from nscd import lnec
    from nscd.motion import Harmonic, OneSine
    from nscd.solver import SolverSettings

    start = time.perf_counter()
    two_hertz = 4.0 * math.pi  # rad/s
    block, _ = nscd.stack(1, WIDTH, HEIGHT, motion=OneSine(4.0, two_hertz))  # 4 m/s^2 lifts the main job's block
    nscd.simulate(block, t_end=0.6, dt=1e-3)
    stacks = [nscd.stack(3, 0.2, 0.6, friction=0.3, motion=OneSine(a, two_hertz))[0] for a in (3.0, 5.0)]
    nscd.simulate_batch(stacks, t_end=0.5, dt=5e-4)
    wall, _ = nscd.wall(6, 8, 0.4, 0.2, motion=Harmonic(amplitude=8.0, frequency=2.0))
    large = nscd.Settings(solver=SolverSettings(tol_relative=1e-4, max_conic_unknowns=0))
    nscd.simulate(wall, t_end=0.05, dt=1e-3, settings=large)
    table = Harmonic.from_displacement(5e-3, frequency=4.0, cycles=2.0, ramp_cycles=1.0)
    table.displacement(np.linspace(0.0, 0.5, 3))  # a motion at many times at once (a record's post-processing)
    trilith = lnec.trilith(motion=table)
    nscd.simulate(trilith, t_end=0.2, dt=1e-3)
    stepped = nscd.Simulator(trilith, dt=1e-3)  # step by step: the motions evaluated a step at a time
    for _ in range(10):
        stepped.step()
    return time.perf_counter() - start


def main() -> None:
    """``python -m nscd.precompile [--store]``: compile, and say how long it took."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--store", action="store_true",
                        help="compile every kernel afresh into the package's compiled store (the install's step)")
    parser.add_argument("--all", action="store_true",
                        help="also the other families of kernels: driven bases, batches, walls, 3D")
    args = parser.parse_args()
    store = args.store
    from nscd import _jit

    if store:
        _jit.build_store()
    where = f"the compiled store {_jit.STORE}" if store else "numba's cache"
    print(f"nscd: compiling the engine's kernels ahead of time into {where} ...", flush=True)
    seconds = precompile() + (precompile_others() if args.all else 0.0)
    print(f"nscd: done in {seconds:.0f} s")


if __name__ == "__main__":
    main()
