"""Benchmark the contact solver on the 23 FCLIB problems and on engine-sized steps.

Writes ``benchmarks/results/fclib.md`` (two Markdown tables) and prints it:

1. every FCLIB / Siconos problem in ``shared/data/fclib`` (beside the repository):
   size, iterations per stage (fast Newton / conic fixed point / Clarabel / polish),
   final FCLIB merit, status and wall time of :func:`nscd.solver.solve_local`;
2. :func:`nscd.solver.solve_velocity` on stacks of 2D blocks sliding on the floor
   (2, 6 and 20 contacts), in microseconds per call: cold (no warm start), warm from
   the same problem's solution, and along a 200-step sliding sequence warm-started
   from the previous step; and a block pivoting on one corner (the contact frame
   turns every step, so the warm start is close but not exact: the engine's case).

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_fclib.py`` (one BLAS
thread: the solver's dense kernels are small and a shared machine otherwise
oversubscribes its cores).
"""
from __future__ import annotations

import os
import platform
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from nscd import fclib
from nscd.solver import solve_local, solve_velocity

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "fclib"
OUT = ROOT / "benchmarks" / "results" / "fclib.md"
TARGET = {"fc2d_granularflowonwall_00667_00000": 1e-6}  # printed with 6 digits (README)
G, DT = 9.81, 1e-3


def fclib_table() -> list[str]:
    rows = ["| problem | dim | contacts | fast Newton | fixed point | interior point | polish | merit | status | "
            "path | time (s) |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for path in sorted(DATA.glob("*.npz")):
        p = fclib.load(path)
        tol = TARGET.get(p.name, 1e-8)
        start = time.perf_counter()
        sol = solve_local(p.W, p.q, p.mu, dim=p.dim, tol=tol)
        wall = time.perf_counter() - start
        rows.append(f"| {p.name} | {p.dim} | {p.contacts} | {sol.fast_iterations} | {sol.fixed_point_iterations} | "
                    f"{sol.interior_point_iterations} | {sol.polish_iterations} | {sol.merit:.1e} | {sol.status} | "
                    f"{sol.path} | {wall:.3f} |")
    return rows


def block_stack(blocks: int, mass: float = 100.0, b: float = 0.2, h: float = 0.5, mu: float = 0.5):
    """2D stack of ``blocks`` rigid blocks, two corner contacts per interface (ground included).

    Returns M (diagonal), H with rows [N, T] per contact (u_T = v_x + omega h at the
    bottom corners, u_N = v_y + omega x_c), and mu.
    """
    inertia = mass * ((2 * b) ** 2 + (2 * h) ** 2) / 12.0
    n = 3 * blocks
    rows = []
    for k in range(blocks):
        for x_c in (-b, b):
            normal, tangent = np.zeros(n), np.zeros(n)
            normal[3 * k:3 * k + 3] = [0.0, 1.0, x_c]
            tangent[3 * k:3 * k + 3] = [1.0, 0.0, h]
            if k > 0:  # top corners of the block below, same point
                normal[3 * (k - 1):3 * k] -= [0.0, 1.0, x_c]
                tangent[3 * (k - 1):3 * k] -= [1.0, 0.0, -h]
            rows += [normal, tangent]
    M = sp.diags(np.tile([mass, mass, inertia], blocks)).tocsr()
    return M, sp.csr_matrix(np.array(rows)), np.full(2 * blocks, mu)


def cpu_per_call(call, repeats: int = 7, number: int = 50) -> float:
    """Best-of-``repeats`` CPU time per call in microseconds."""
    best = np.inf
    for _ in range(repeats):
        start = time.process_time()
        for _ in range(number):
            call()
        best = min(best, (time.process_time() - start) / number)
    return best * 1e6


def step_table() -> list[str]:
    rows = ["| contacts | cold (µs) | warm, same problem (µs) | sliding sequence, warm (µs/step) | "
            "Newton its/step | path | worst merit |", "|---|---|---|---|---|---|---|"]
    for blocks in (1, 3, 10):
        M, H, mu = block_stack(blocks)
        n, rows_h = M.shape[0], H.shape[0]
        v0 = np.zeros(n)
        v0[0::3] = 0.8  # the whole stack slides at 0.8 m/s
        v_free = v0.copy()
        v_free[1::3] -= G * DT
        offset = np.zeros(rows_h)
        first = solve_velocity(M, v_free, H, offset, mu, 2)
        cold = cpu_per_call(lambda: solve_velocity(M, v_free, H, offset, mu, 2))
        warm = cpu_per_call(lambda: solve_velocity(M, v_free, H, offset, mu, 2, warm_start=first.P))
        # 200 steps of the sliding stack, each warm-started from the previous impulses.
        v, P, its, worst, paths = v0.copy(), None, 0, 0.0, set()
        start = time.process_time()
        for _ in range(200):
            vf = v.copy()
            vf[1::3] -= G * DT
            sol = solve_velocity(M, vf, H, offset, mu, 2, warm_start=P)
            v, P = sol.v, sol.P
            its += sol.iterations
            worst = max(worst, sol.merit)
            paths.add(sol.path)
        sequence = (time.process_time() - start) / 200 * 1e6
        rows.append(f"| {len(mu)} | {cold:.0f} | {warm:.0f} | {sequence:.0f} | {its / 200:.2f} | "
                    f"{', '.join(sorted(paths))} | {worst:.1e} |")
    per_call, its, paths, worst = pivot_sequence()
    rows += ["", "| scenario | µs/step (CPU) | Newton its/step | path | worst merit |", "|---|---|---|---|---|",
             f"| block pivoting on one corner, 300 steps, warm | {per_call:.0f} | {its:.2f} | "
             f"{', '.join(sorted(paths))} | {worst:.1e} |"]
    return rows


def pivot_sequence(steps: int = 300, mass: float = 100.0, b: float = 0.2, h: float = 0.5,
                   mu: float = 0.5) -> tuple[float, float, set[str], float]:
    """A 2D block rocking on one corner (one contact whose frame moves every step).

    Returns CPU µs per ``solve_velocity`` call, Newton iterations per call, the paths
    taken and the worst merit over ``steps`` steps of dt = 1 ms, warm-started from the
    previous impulse (the engine's case: the warm start is close but not exact).
    """
    inertia = mass * ((2 * b) ** 2 + (2 * h) ** 2) / 12.0
    M = sp.diags([mass, mass, inertia]).tocsr()
    phi = -0.05  # tilted onto its right corner (clockwise), falling back
    v = np.zeros(3)
    P, its, worst, paths, cpu = None, 0, 0.0, set(), 0.0
    for _ in range(steps):
        c, s = np.cos(phi), np.sin(phi)
        px, py = c * b + s * h, s * b - c * h  # right bottom corner relative to the centre
        H = np.array([[0.0, 1.0, px], [1.0, 0.0, -py]])  # [N, T] rows: v + omega x p
        v_free = v + np.array([0.0, -G * DT, 0.0])
        start = time.process_time()
        sol = solve_velocity(M, v_free, H, np.zeros(2), [mu], 2, warm_start=P)
        cpu += time.process_time() - start
        v, P = sol.v, sol.P
        its += sol.iterations
        worst = max(worst, sol.merit)
        paths.add(sol.path)
        phi += DT * v[2]  # only the angle changes the contact frame
    return cpu / steps * 1e6, its / steps, paths, worst


def main() -> None:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    lines = ["# Contact solver benchmark", "",
             f"Machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
             f"load average {load:.1f} at start; numpy {np.__version__}; "
             f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}.", ""]
    if DATA.is_dir():
        lines += ["## FCLIB / Siconos problems (`solve_local`, target merit 1e-8; 1e-6 for the granular flow)", ""]
        lines += fclib_table()
    else:
        lines += [f"FCLIB problems not found in {DATA}: table skipped."]
    lines += ["", "## Engine-sized steps (`solve_velocity`, 2D block stacks sliding on the floor, CPU time)", ""]
    lines += step_table()
    text = "\n".join(lines) + "\n"
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(text, encoding="utf-8")
    print(text)


if __name__ == "__main__":
    main()
