"""End-to-end time of double-pulse maps (issue 5): 20 x 20 cells, scale 1, 1 s simulated per cell.

Runs ``DoublePulseRig(...).map`` over gap 0.005–0.05 m and v_peak 0.1–1.5 m/s on a local
process pool over all cores, at the rig's default (converged) time step, for the single
block and the three-block stack, and writes ``benchmarks/results/maps.md`` with the
wall time, CPU seconds per cell and the count of each mode.

Run:  .venv/bin/python benchmarks/bench_maps.py [--n 20]
"""
from __future__ import annotations

import argparse
import collections
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
        rig = DoublePulseRig(specimen=specimen, scale=1, base="kinematic")
        with tempfile.TemporaryDirectory() as folder:
            cpu0, wall0 = children_cpu(), time.perf_counter()
            table = rig.map(gaps, v_peaks, out=str(Path(folder) / "map.csv"), progress=False)
            wall = time.perf_counter() - wall0
            cpu = children_cpu() - cpu0
        modes = collections.Counter(str(m) for m in table["mode"])
        failed = int(np.sum(np.asarray(table["status"]) != "ok"))
        rows.append([specimen, f"{args.n} x {args.n}", f"{rig.dt:g}", f"{wall:.0f}",
                     f"{cpu / args.n ** 2:.2f}", failed,
                     ", ".join(f"{k} {v}" for k, v in sorted(modes.items()))])
    lines = ["# Double-pulse maps: end-to-end time", "", *stamp_lines(info), "",
             "Scale 1, kinematic base, gap 0.005–0.05 m x v_peak 0.1–1.5 m/s, t_end 1 s per cell (cells "
             "stop early once everything is at rest), local process pool over all cores, the rig's "
             "default dt. Issue 5 aims: under 5 min for the stack map, under 10 s for the single block.", "",
             *markdown_table(["specimen", "cells", "dt (s)", "wall (s)", "CPU s per cell", "failed cells",
                              "modes"], rows), ""]
    path = write_text("maps.md", lines)
    print("\n".join(lines))
    print(f"written to {path}")


if __name__ == "__main__":
    main()
