"""Why a shaken wall costs more under one time-stepping scheme than the other: the sub-steps
of event location, the solver's work in each kind of sub-step and the quality of its warm
starts, for the theta scheme and Moreau's midpoint rule at the same instants.

Scene: the README's running-bond wall of ``benchmarks/bench_collapse.py`` (13 courses x 7
blocks of 0.4 x 0.2 m, friction 0.7, base ``Harmonic(8 m/s^2, 2 Hz, one-cycle ramp)``),
dt = 1 ms, ``SolverSettings(tol_relative=1e-4, max_conic_unknowns=0)`` (the bounded route
of ``docs/solver.md``), or the ``--courses`` x ``--per-course`` wall.

Each step is taken as the stepper takes it: a plain sub-step, and where an impact is
located an approach (the impacting contacts deferred), corrections of the closing time
(midpoint rule), the impact (a sub-step of zero length) and the rest of the step. The
script wraps the stepper's sub-step (``nscd.stepper._advance``) and its large-problem
solve (``nscd.stepper.solve_velocity_unchecked``) to count, per kind of sub-step: how many,
their solver iterations and CPU, how many ended above the tolerance, and the median
distance of the warm start from the impulses found, ``|P0 - P| / |P|``. It runs against
whatever ``nscd`` is imported (``PYTHONPATH``), so an earlier commit can be measured with
the same script; the results file names the commit of that ``nscd``.

Writes ``benchmarks/results/<--out>`` (default ``midpoint_wall.md``).

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/study_midpoint_wall.py [--t-end 0.6]``
"""
from __future__ import annotations

import argparse
import collections
import os
import subprocess
import time
import warnings

import numpy as np

import nscd
from nscd import stepper
from nscd.motion import Harmonic
from nscd.solver import SolverSettings

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.study_midpoint_wall
    from common import log, markdown_table, stamp_lines, write_text
except ImportError:  # pragma: no cover
    from benchmarks.common import log, markdown_table, stamp_lines, write_text

KINDS = ("plain or rest", "approach", "correction", "impact")


def _kind(request) -> str:
    """The kind of a sub-step from its request (see ``nscd.stepper._Plan``)."""
    if request.dt == 0.0:
        return "impact"
    if request.defer:
        return "approach"
    return "correction" if request.watch is not None else "plain or rest"


class Probe:
    """Counts of the sub-steps and large solves of a single-scene run (see the module text)."""

    def __init__(self) -> None:
        self.count = collections.Counter()
        self.iterations = collections.Counter()
        self.cpu = collections.Counter()
        self.unconverged = collections.Counter()
        self.warm_error = collections.defaultdict(list)
        self.kind = "plain or rest"
        self.advance, self.solve = stepper._advance, stepper.solve_velocity_unchecked

    def __enter__(self) -> "Probe":
        def advance(constants, data, rows, t, q, v, warm, requests=None):
            self.kind = "plain or rest" if requests is None else _kind(requests[0])
            self.count[self.kind] += 1
            return self.advance(constants, data, rows, t, q, v, warm, requests)

        def solve(mass, v_free, H, offset, mu, dim, settings, start, coarse):
            begin = time.process_time()
            sol = self.solve(mass, v_free, H, offset, mu, dim, settings, start, coarse)
            self.cpu[self.kind] += time.process_time() - begin
            self.iterations[self.kind] += sol.iterations
            self.unconverged[self.kind] += not sol.converged
            P0 = np.zeros(sol.P.shape) if start is None else np.asarray(start).reshape(sol.P.shape)
            self.warm_error[self.kind].append(np.linalg.norm(P0 - sol.P) / max(np.linalg.norm(sol.P), 1e-300))
            return sol

        stepper._advance, stepper.solve_velocity_unchecked = advance, solve
        return self

    def __exit__(self, *exc) -> None:
        stepper._advance, stepper.solve_velocity_unchecked = self.advance, self.solve


def run(scheme: str, courses: int, per_course: int, t_end: float) -> tuple[list, list]:
    """One run; returns the row of the summary table and the rows of the per-kind table."""
    motion = Harmonic(8.0, frequency=2.0, ramp_cycles=1.0)
    scene, _ = nscd.wall(n_courses=courses, n_per_course=per_course, block_width=0.4, block_height=0.2,
                         density=2500.0, friction=0.7, motion=motion)
    settings = nscd.Settings(scheme=scheme, solver=SolverSettings(tol_relative=1e-4, max_conic_unknowns=0))
    sim = nscd.Simulator(scene, dt=1e-3, settings=settings)
    sim.step()  # compiles what the run needs; not counted
    n = int(round(t_end / 1e-3)) - 1
    cpu = np.empty(n)
    unconverged = 0
    with warnings.catch_warnings(), Probe() as probe:
        warnings.simplefilter("ignore", RuntimeWarning)  # unconverged steps: counted below
        for k in range(n):
            begin = time.process_time()
            report = sim.step()
            cpu[k] = time.process_time() - begin
            unconverged += not report.converged
    subs = sum(probe.count.values())
    summary = [scheme, f"{sim.state.t:.3f}", f"{cpu.sum():.1f}", f"{1e3 * np.median(cpu):.1f}",
               f"{1e3 * cpu.max():.0f}", int((cpu > 0.1).sum()), unconverged, f"{subs / n:.2f}",
               f"{sum(probe.iterations.values()) / n:.0f}"]
    kinds = [[scheme, kind, probe.count[kind], f"{probe.cpu[kind]:.1f}",
              f"{probe.iterations[kind] / max(probe.count[kind], 1):.0f}", probe.unconverged[kind],
              f"{np.median(probe.warm_error[kind]):.2g}" if probe.warm_error[kind] else "–"]
             for kind in KINDS if probe.count[kind]]
    return summary, kinds


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=0.6, help="simulated seconds (s)")
    parser.add_argument("--courses", type=int, default=13)
    parser.add_argument("--per-course", type=int, default=7)
    parser.add_argument("--schemes", default="theta,midpoint")
    parser.add_argument("--out", default="midpoint_wall.md", help="results file in benchmarks/results/")
    args = parser.parse_args()
    source = os.path.dirname(nscd.__file__)
    commit = subprocess.run(["git", "-C", source, "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip() or "unknown"
    load = os.getloadavg()[0]
    summaries, kinds = [], []
    for scheme in args.schemes.split(","):
        log(f"{args.courses} x {args.per_course} wall, {scheme}, {args.t_end:g} s")
        summary, per_kind = run(scheme, args.courses, args.per_course, args.t_end)
        summaries.append(summary)
        kinds.extend(per_kind)
    lines = ["# A shaken wall under the two schemes: sub-steps, solver work, warm starts", "",
             *stamp_lines(), f"- nscd measured: commit {commit} ({source})",
             f"- 1-min load average at start: {load:.1f}, at the end: {os.getloadavg()[0]:.1f}", "",
             f"{args.courses} x {args.per_course} running-bond wall, base Harmonic(8 m/s^2, 2 Hz, one-cycle ramp), "
             "dt = 1 ms, `SolverSettings(tol_relative=1e-4, max_conic_unknowns=0)`; the first step (compiling) "
             "not counted. CPU is process time, one core.", "",
             *markdown_table(("scheme", "t reached (s)", "CPU (s)", "median step (ms)", "worst step (ms)",
                              "steps > 100 ms", "unconverged steps", "sub-steps per step",
                              "solver iterations per step"), summaries), "",
             "Per kind of sub-step (large problems: Gauss–Seidel route); warm-start error: median "
             "`|P0 - P| / |P|` of the warm start `P0` against the impulses found `P`.", "",
             *markdown_table(("scheme", "sub-step", "count", "solver CPU (s)", "iterations each", "unconverged",
                              "warm-start error"), kinds), "",
             f"Run: `OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/study_midpoint_wall.py --t-end {args.t_end:g} "
             f"--courses {args.courses} --per-course {args.per_course} --schemes {args.schemes} --out {args.out}`"]
    log(f"wrote {write_text(args.out, lines)}")


if __name__ == "__main__":
    main()
