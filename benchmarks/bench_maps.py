"""End-to-end time of double-pulse maps: 20 x 20 cells, scale 1, at most 1 s simulated per cell.

Runs ``DoublePulseRig(...).map`` over gap 0.005–0.05 m and v_peak 0.1–1.5 m/s on a local
process pool over all cores, with the rig's defaults (midpoint rule, dt = 5e-4 s, the
simulations' high block friction), for the single block and the three-block stack: cell by
cell (the default) and batched (``map(..., batch=True)``: one batch of cells per worker,
advanced together by ``nscd.batch``), both stopping each cell once its outcome is decided
(the rig's terminal event); then, as the reference those early stops are checked against,
the batched map with every cell run to 1 s (``run_batch`` with ``stop_early=False``;
batched runs equal single runs bit for bit, ``tests/test_batch.py``). Writes
``benchmarks/results/maps.md`` with the wall time, CPU seconds per cell, the count of each
mode, the cells with a step the contact solver left above its tolerance, the number of cells
whose mode differs from the cell-by-cell map and from the
full-length map (target 0 for both), and the 1-minute load average before and after each
run (the machine is shared: a load above the core count inflates wall times).

Run:  .venv/bin/python benchmarks/bench_maps.py [--n 20] [--quick]
"""
from __future__ import annotations

import argparse
import collections
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

from common import markdown_table, stamp, stamp_lines, write_text
from nscd import sweep
from nscd.rigs import DoublePulseRig


def children_cpu() -> float:
    """CPU seconds used so far by this process's finished children (the pool workers)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def load() -> float:
    """1-minute load average (nan where unavailable)."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def timed_map(rig: DoublePulseRig, gaps: np.ndarray, v_peaks: np.ndarray, run: str) -> dict:
    """One map on the default pool (``run``: "cell by cell", "batched" or "batched, full length"):
    its table, wall and children's CPU seconds, load before/after."""
    with tempfile.TemporaryDirectory() as folder:
        out = str(Path(folder) / "map.csv")
        before = load()
        cpu0, wall0 = children_cpu(), time.perf_counter()
        if run == "batched, full length":
            table = sweep.grid(rig.run_batch, {"gap": gaps.tolist(), "v_peak": v_peaks.tolist()}, out=out,
                               fixed={"t_end": 1.0, "stop_early": False}, progress=False, batch=True)
        else:
            table = rig.map(gaps, v_peaks, out=out, progress=False, batch=run == "batched")
        wall = time.perf_counter() - wall0
        cpu = children_cpu() - cpu0
    return {"table": table, "wall": wall, "cpu": cpu, "load": (before, load())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=20, help="cells per axis")
    parser.add_argument("--quick", action="store_true", help="6 x 6 cells instead of --n")
    parser.add_argument("--no-reference", action="store_true", help="skip the full-length reference map")
    parser.add_argument("--no-cells", action="store_true",
                        help="skip the cell-by-cell map (batched cells equal their single runs bit for bit: "
                             "tests/test_batch.py)")
    args = parser.parse_args()
    if args.quick:
        args.n = 6
    info = stamp()
    gaps = np.linspace(0.005, 0.05, args.n)
    v_peaks = np.linspace(0.1, 1.5, args.n)
    rows = []
    for specimen in ("stack3", "single"):
        # the rig's defaults: the midpoint rule, the simulations' high block friction
        rig = DoublePulseRig(specimen=specimen, scale=1, base="kinematic")
        rig.run_batch([{"v_peak": 0.5, "gap": 0.02, "t_end": 0.01}])  # compile or load the kernels
        names = ([] if args.no_cells else ["cell by cell"]) + ["batched"] + \
            ([] if args.no_reference else ["batched, full length"])
        runs = {name: timed_map(rig, gaps, v_peaks, name) for name in names}
        cells = None if args.no_cells else runs["cell by cell"]["table"]["mode"]
        full = None if args.no_reference else runs["batched, full length"]["table"]["mode"]
        for name, run in runs.items():
            table = run["table"]
            modes = collections.Counter(str(m) for m in table["mode"])
            failed = int(np.sum(np.asarray(table["status"]) != "ok"))
            unconverged = np.asarray(table["unconverged_steps"], dtype=float)
            rows.append([specimen, name, f"{args.n} x {args.n}", f"{rig.dt:g}", f"{run['wall']:.1f}",
                         f"{run['cpu'] / args.n ** 2:.3f}", f"{np.mean(table['t_stop']):.3f}", failed,
                         f"{int(np.sum(unconverged > 0))} ({int(np.sum(unconverged))})",
                         "-" if cells is None else int(np.sum(table["mode"] != cells)),
                         "-" if full is None else int(np.sum(table["mode"] != full)),
                         ", ".join(f"{k} {v}" for k, v in sorted(modes.items())),
                         f"{run['load'][0]:.1f} / {run['load'][1]:.1f}"])
    lines = ["# Double-pulse maps: end-to-end time", "", *stamp_lines(info), "",
             "Scale 1, kinematic base, gap 0.005–0.05 m x v_peak 0.1–1.5 m/s, t_end 1 s per cell, local "
             "process pool over all cores, the rig's defaults (midpoint rule, dt 5e-4 s, block friction "
             f"{DoublePulseRig().friction:g}). `cell by cell`: one engine run per cell (`map(...)`); `batched`: "
             "one batch of cells per worker advanced together (`map(..., batch=True)`, `nscd.batch`). Both "
             "stop a cell once its outcome is decided (the rig's terminal event: everything at rest, the "
             "energy below the lowest rocking barrier with the base at rest, or a single block lying on its "
             "side; `nscd.rigs._Watch`); `batched, full length` runs every cell to 1 s, the reference of the "
             "early stops. `mean t_stop`: simulated seconds per cell. `cells with unconverged steps`: cells "
             "with a step the contact solver left above its tolerance (counted and warned), and those steps "
             "in all. `differing from cells` / `from full "
             "length`: cells whose mode differs from the cell-by-cell map / the full-length map (target 0). "
             "The numba-compiled kernels are warmed up in this process first; each pool worker still loads "
             "them from the cache. Aim: the batched stack map within 5 s wall on 2 cores.", "",
             *markdown_table(["specimen", "run", "cells", "dt (s)", "wall (s)", "CPU s per cell", "mean t_stop (s)",
                              "failed cells", "cells with unconverged steps (steps)", "differing from cells",
                              "from full length", "modes",
                              "load before / after"], rows), ""]
    path = write_text("maps.md", lines)
    print("\n".join(lines))
    print(f"written to {path}")


if __name__ == "__main__":
    main()
