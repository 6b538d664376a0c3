"""End-to-end time of double-pulse maps (issues 5 and 6): 20 x 20 cells, scale 1, 1 s simulated per cell.

Runs ``DoublePulseRig(...).map`` over gap 0.005–0.05 m and v_peak 0.1–1.5 m/s on a local
process pool over all cores, at the rig's default (converged) time step, for the single
block and the three-block stack, twice: cell by cell (the default) and batched
(``map(..., batch=True)``: one batch of cells per worker, advanced together by
``nscd.batch``). Writes ``benchmarks/results/maps.md`` with the wall time, CPU seconds
per cell, the count of each mode, the number of cells whose mode differs between the two
runs (the batched run must reproduce the cell-by-cell one: target 0), and the 1-minute
load average before and after each run (the machine is shared: a load above the core
count inflates wall times).

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
from nscd.rigs import DoublePulseRig


def children_cpu() -> float:
    """CPU seconds used so far by this process's finished children (the pool workers)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def load() -> float:
    """1-minute load average (nan where unavailable)."""
    return os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")


def timed_map(rig: DoublePulseRig, gaps: np.ndarray, v_peaks: np.ndarray, batch: bool) -> dict:
    """One map on the default pool: its table, wall and children's CPU seconds, load before/after."""
    with tempfile.TemporaryDirectory() as folder:
        before = load()
        cpu0, wall0 = children_cpu(), time.perf_counter()
        table = rig.map(gaps, v_peaks, out=str(Path(folder) / "map.csv"), progress=False, batch=batch)
        wall = time.perf_counter() - wall0
        cpu = children_cpu() - cpu0
    return {"table": table, "wall": wall, "cpu": cpu, "load": (before, load())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--n", type=int, default=20, help="cells per axis")
    parser.add_argument("--quick", action="store_true", help="6 x 6 cells instead of --n")
    args = parser.parse_args()
    if args.quick:
        args.n = 6
    info = stamp()
    gaps = np.linspace(0.005, 0.05, args.n)
    v_peaks = np.linspace(0.1, 1.5, args.n)
    rows = []
    for specimen in ("single", "stack3"):
        # the measured friction and the theta scheme: the rig its results in results/maps.md were measured with
        rig = DoublePulseRig(specimen=specimen, scale=1, base="kinematic", friction=0.54, scheme="theta")
        rig.run_batch([{"v_peak": 0.5, "gap": 0.02, "t_end": 0.01}])  # compile or load the kernels
        runs = {"cell by cell": timed_map(rig, gaps, v_peaks, batch=False),
                "batched": timed_map(rig, gaps, v_peaks, batch=True)}
        reference = runs["cell by cell"]["table"]["mode"]
        for name, run in runs.items():
            table = run["table"]
            modes = collections.Counter(str(m) for m in table["mode"])
            failed = int(np.sum(np.asarray(table["status"]) != "ok"))
            differ = int(np.sum(table["mode"] != reference))
            rows.append([specimen, name, f"{args.n} x {args.n}", f"{rig.dt:g}", f"{run['wall']:.1f}",
                         f"{run['cpu'] / args.n ** 2:.3f}", failed, differ,
                         ", ".join(f"{k} {v}" for k, v in sorted(modes.items())),
                         f"{run['load'][0]:.1f} / {run['load'][1]:.1f}"])
    lines = ["# Double-pulse maps: end-to-end time", "", *stamp_lines(info), "",
             "Scale 1, kinematic base, gap 0.005–0.05 m x v_peak 0.1–1.5 m/s, t_end 1 s per cell (cells "
             "stop early once everything is at rest), local process pool over all cores, the rig's "
             "default dt. `cell by cell`: one engine run per cell (`map(...)`); `batched`: one batch of "
             "cells per worker advanced together (`map(..., batch=True)`, `nscd.batch`), whose modes must "
             "equal the cell-by-cell ones (column `modes differing`). The numba-compiled kernels are "
             "warmed up in this process first; each pool worker still loads them from the cache. "
             "Issue 5 aims: under 5 min for the stack map, under 10 s for the single block; issue 6: "
             "the batched stack map under 60 s.", "",
             *markdown_table(["specimen", "run", "cells", "dt (s)", "wall (s)", "CPU s per cell", "failed cells",
                              "modes differing", "modes", "load before / after"], rows), ""]
    path = write_text("maps.md", lines)
    print("\n".join(lines))
    print(f"written to {path}")


if __name__ == "__main__":
    main()
