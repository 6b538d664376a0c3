"""Scaling of the 2D step with the scene size: a running-bond wall on a shaking base.

Walls of N = 10 ... 2000 blocks (``nscd.builders.wall``, 0.4 x 0.2 m blocks, about
twice as many courses as blocks per course) stand on a base driven by a 2 Hz sine of
0.5 m/s^2 (raised-cosine ramp of one cycle, so the wall is carried without an impact).
For each wall the script times steps of an :class:`nscd.Simulator` (dt = 1 ms) after a
few warm-up steps and splits the time between the stages of a step: contact detection,
the Jacobian, the condensation (the dense ``H``, ``W = H M^-1 H^T`` and ``q`` of small
problems; for large ones ``W`` kept factored, with the recovery of ``v``), the contact solve
(the compiled Newton of small problems, :func:`nscd.solver.core.solve` for large ones:
two-level NSGS) and the rest (stepper, result), then fits ``time per step ~ contacts^p`` by
least squares in log-log. Every row states the accuracy it was bought at: the largest
FCLIB merit of the timed solves, the solver path, and the drift of the wall relative to
the base (the base acceleration is below ``mu g``: the wall should move with it rigidly).

Targets: p <= 1.2 up to 2000 blocks, under 50 ms per step at 1000. The
wall of about 1000 blocks is also timed with one-level NSGS (no body-space correction),
for comparison.

Walls are measured in increasing size; a wall whose predicted measuring time (from the
last one's per-step time and the exponent so far) exceeds ``--budget`` seconds is not
run, and neither are larger ones: the table says so instead of giving a number.

Writes ``benchmarks/results/scaling.md``, ``scaling.csv`` and ``scaling.png``.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_scaling.py [--quick] [--budget S]``
"""
from __future__ import annotations

import argparse
import math
import os
import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

import nscd
import nscd.compiled_step  # noqa: F401 - binds the stepper's compiled stages before StageTimer wraps them
import nscd.solver.core
import nscd.stepper
from nscd.solver import SolverSettings
from nscd.builders import wall
from nscd.motion import Harmonic
from nscd.solver.small import NOT_ACCEPTED

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.bench_scaling
    from common import RESULTS, log, markdown_table, stamp_lines, write_csv, write_text, save_figure
except ImportError:  # pragma: no cover
    from benchmarks.common import RESULTS, log, markdown_table, stamp_lines, write_csv, write_text, save_figure

SIZES = (10, 20, 50, 100, 200, 500, 1000, 2000)
SIZES_QUICK = SIZES[:5]
BLOCK = (0.4, 0.2)            # block width, height, m
DT = 1e-3                     # s
WARMUP, STEPS = 3, 20         # steps before timing, timed steps
BASE_MOTION = dict(amplitude=0.5, frequency=2.0, ramp_cycles=1.0)   # m/s^2, Hz, cycles


def wall_shape(n_blocks: int) -> tuple[int, int]:
    """Courses and blocks per course of a wall of about ``n_blocks`` blocks, twice as many courses."""
    per_course = max(2, round(math.sqrt(n_blocks / 2.0)))
    courses = max(1, round((n_blocks + 0.5) / (per_course + 0.5)))
    return courses, per_course


#: Wrapped callables: (module, name, stage), the names the step calls each stage by (called from
#: Python; the compiled ones are timed as a whole). ``_assemble`` forms the Jacobian, the active
#: set and the small problems' dense operators; ``core.newton_batch`` solves the small problems
#: (the compiled Newton); a small problem it does not accept goes on to ``core.solve``. Large
#: ones: ``solve_velocity_unchecked`` includes ``core.solve``; their condensation is the difference.
_WRAPPED = ((nscd.stepper, "detect_batch", "detect"), (nscd.stepper, "_assemble", "jacobian"),
            (nscd.solver.core, "newton_batch", "small solve"),
            (nscd.stepper, "solve_velocity_unchecked", "velocity form"), (nscd.solver.core, "solve", "solve"))
STAGES = ("detect", "jacobian", "condense", "solve", "rest")


class StageTimer:
    """Wall time per stage of the step, and the solver's merit and path of each solve.

    Wraps the names the stepper and the solver API call (restored by :meth:`close`);
    the wrappers add two ``perf_counter`` calls per use, negligible against any stage.
    """

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self.merits: list[float] = []
        self.paths: list[str] = []
        self.sweeps: list[int] = []
        self._saved = [(module, name, getattr(module, name)) for module, name, _ in _WRAPPED]
        for (module, name, stage), (_, _, func) in zip(_WRAPPED, self._saved):
            setattr(module, name, self._wrap(func, stage))
        self.reset()

    def _wrap(self, func: Callable, key: str) -> Callable:
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                result = func(*args, **kwargs)
            finally:
                self.seconds[key] += time.perf_counter() - start
            if key == "solve":
                self.merits.append(result.merit)
                self.paths.append(result.path)
                self.sweeps.append(result.sweeps)
            elif key == "small solve":  # (impulses, velocities, merits, (outcome code, iterations) per problem)
                _, _, merits, info = result
                for merit, code in zip(merits.tolist(), info[:, 0].tolist()):
                    if code != NOT_ACCEPTED:  # the others are solved again by core.solve
                        self.merits.append(merit)
                        self.paths.append("newton (fast path)")
                        self.sweeps.append(0)
            return result
        return timed

    def reset(self) -> None:
        self.seconds = {stage: 0.0 for _, _, stage in _WRAPPED}
        self.merits, self.paths, self.sweeps = [], [], []

    def shares(self, total: float) -> dict[str, float]:
        """Fraction of ``total`` seconds per stage of :data:`STAGES`."""
        s = self.seconds
        stages = {"detect": s["detect"], "jacobian": s["jacobian"],
                  "condense": s["velocity form"] - s["solve"],
                  "solve": s["small solve"] + s["solve"]}
        stages["rest"] = total - sum(stages.values())
        return {k: v / total for k, v in stages.items()}

    def close(self) -> None:
        for module, name, func in self._saved:
            setattr(module, name, func)


@dataclass
class Row:
    blocks: int
    courses: int
    per_course: int
    contacts: float          # mean over the timed steps
    active: float
    ms_per_step: float       # median wall time
    cpu_ms_per_step: float   # process CPU time / steps
    detect_share: float
    jacobian_share: float
    condense_share: float
    solver_share: float
    rest_share: float
    unconverged: int
    max_merit: float         # largest FCLIB merit of the timed solves
    paths: str               # solver paths of the timed solves
    sweeps: float            # mean Gauss-Seidel sweeps per solve
    drift_mm: float          # largest block displacement relative to the base over the timed steps, mm


def measure(n_blocks: int, timer: StageTimer, two_level: bool = True) -> Row:
    """Time the steps of a wall of about ``n_blocks`` blocks; ``two_level=False``: without the
    body-space correction of the Gauss-Seidel sweeps (one-level NSGS, for comparison)."""
    courses, per_course = wall_shape(n_blocks)
    scene, rows = wall(courses, per_course, *BLOCK, motion=Harmonic(**BASE_MOTION))
    sim = nscd.Simulator(scene, DT)
    if not two_level:
        sim.data.coarse[0] = None  # the scene's body-space correction (nscd.state.Data.coarse)
    for _ in range(WARMUP):
        sim.step()
    timer.reset()
    wall_times, reports = [], []
    dyn, base = sim.model.dynamic_index, np.flatnonzero(~sim.model.dynamic)[0]
    start_q = sim.state.q.copy()
    cpu = time.process_time()
    for _ in range(STEPS):
        start = time.perf_counter()
        reports.append(sim.step())
        wall_times.append(time.perf_counter() - start)
    cpu = time.process_time() - cpu
    total = float(np.sum(wall_times))
    moved = sim.state.q[dyn, :2] - start_q[dyn, :2] - (sim.state.q[base, :2] - start_q[base, :2])
    # a scene of at most ALL_PAIRS_BODIES bodies takes its steps in one compiled call
    # (nscd.compiled_step): no stage of it passes the timer, so no shares and no paths
    compiled = not timer.merits
    shares = dict.fromkeys(STAGES, float("nan")) if compiled else timer.shares(total)
    paths = sorted(set(timer.paths))
    return Row(
        blocks=sum(map(len, rows)), courses=courses, per_course=per_course,
        contacts=float(np.mean([r.n_contacts for r in reports])),
        active=float(np.mean([r.n_active for r in reports])),
        ms_per_step=1e3 * float(np.median(wall_times)), cpu_ms_per_step=1e3 * cpu / STEPS,
        detect_share=shares["detect"], jacobian_share=shares["jacobian"], condense_share=shares["condense"],
        solver_share=shares["solve"], rest_share=shares["rest"],
        unconverged=sum(not r.converged for r in reports), max_merit=float(max(r.merit for r in reports)),
        paths="compiled steps" if compiled else " / ".join(f"{p} x{timer.paths.count(p)}" for p in paths),
        sweeps=float(np.mean(timer.sweeps)) if timer.sweeps else 0.0,
        drift_mm=1e3 * float(np.abs(moved).max()),
    )


def fit_exponent(rows: list[Row], cpu: bool = False) -> float:
    """Least-squares slope of log(time per step) against log(contacts): wall time, or CPU time if ``cpu``."""
    if len(rows) < 2:
        return float("nan")
    times = [r.cpu_ms_per_step if cpu else r.ms_per_step for r in rows]
    return float(np.polyfit(np.log([r.contacts for r in rows]), np.log(times), 1)[0])


def plot(rows: list[Row], exponent: float, cpu_exponent: float) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    contacts = np.array([r.contacts for r in rows])
    total = np.array([r.ms_per_step for r in rows])
    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    ax.loglog(contacts, total, "o-", label="whole step, wall time")
    ax.loglog(contacts, [r.cpu_ms_per_step for r in rows], "o:", label="whole step, CPU time")
    ax.loglog(contacts, total * [r.solver_share for r in rows], "s--", label="contact solve")
    ax.loglog(contacts, total * [r.detect_share for r in rows], "^--", label="contact detection")
    ax.loglog(contacts, total * [r.condense_share for r in rows], "v--", label="condensation (H, M^-1 H^T)")
    ax.loglog(contacts, total * [r.jacobian_share for r in rows], "d--", label="Jacobian")
    ref = contacts / contacts[0]
    ax.loglog(contacts, total[0] * ref ** 1.2, ":", color="grey", label="slope 1.2 (target)")
    ax.axhline(50.0, color="red", lw=0.8, label="50 ms (target at 1000 blocks)")
    for r in rows:
        ax.annotate(f"{r.blocks}", (r.contacts, r.ms_per_step), textcoords="offset points", xytext=(4, -10),
                    fontsize=7)
    ax.set_xlabel("contact points")
    ax.set_ylabel("time per step, ms (stages: wall time)")
    ax.set_title(f"Running-bond wall on a shaking base: fitted exponent {exponent:.2f} (wall), "
                 f"{cpu_exponent:.2f} (CPU)", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, "scaling.png", dpi=130)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help=f"walls up to {SIZES_QUICK[-1]} blocks only")
    parser.add_argument("--budget", type=float, default=300.0,
                        help="skip a wall whose predicted measuring time exceeds this many seconds")
    args = parser.parse_args()
    lines = ["# Scaling: running-bond wall on a shaking base", "", *stamp_lines(), ""]
    timer = StageTimer()
    rows: list[Row] = []
    skipped: list[int] = []
    try:
        for n in SIZES_QUICK if args.quick else SIZES:
            if skipped:
                skipped.append(n)
                continue
            if rows:
                slope = max(fit_exponent(rows), 1.0) if len(rows) >= 2 else 1.0
                predicted = rows[-1].ms_per_step * 1e-3 * (n / rows[-1].blocks) ** slope * (WARMUP + STEPS)
                if predicted > args.budget:
                    log(f"{n} blocks: predicted {predicted:.0f} s > budget {args.budget:.0f} s, not run")
                    skipped.append(n)
                    continue
            row = measure(n, timer)
            rows.append(row)
            log(f"{row.blocks} blocks, {row.contacts:.0f} contacts: {row.ms_per_step:.1f} ms/step "
                f"(solve {100 * row.solver_share:.0f} %, detection {100 * row.detect_share:.0f} %), "
                f"merit <= {row.max_merit:.1e}, {row.paths}")
        one_level = measure(1000, timer, two_level=False) if any(abs(r.blocks - 1000) <= 100 for r in rows) else None
    finally:
        timer.close()
    exponent, cpu_exponent = fit_exponent(rows), fit_exponent(rows, cpu=True)
    large = [r for r in rows if r.blocks >= 100]
    exponent_large, cpu_exponent_large = fit_exponent(large), fit_exponent(large, cpu=True)
    header = ["blocks", "courses x per course", "contacts", "active", "ms/step (median)", "CPU ms/step",
              "detect", "Jacobian", "condense", "solve", "rest", "unconverged steps", "max merit",
              "drift vs base, mm", "sweeps per solve", "solver path (solves)"]
    table = [[r.blocks, f"{r.courses} x {r.per_course}", f"{r.contacts:.0f}", f"{r.active:.0f}",
              f"{r.ms_per_step:.1f}", f"{r.cpu_ms_per_step:.1f}",
              *(f"{100 * getattr(r, f'{stage}_share'):.0f} %"
                for stage in ("detect", "jacobian", "condense", "solver", "rest")),
              f"{r.unconverged}/{STEPS}", f"{r.max_merit:.1e}", f"{r.drift_mm:.1e}", f"{r.sweeps:.1f}", r.paths]
             for r in rows]
    table += [[n, "%d x %d" % wall_shape(n), "—", "—", "not run (over budget)", *["—"] * 11]
              for n in skipped]
    at_1000 = min(rows, key=lambda r: abs(r.blocks - 1000)) if rows else None
    if at_1000 is not None and abs(at_1000.blocks - 1000) > 100:
        at_1000 = None
    lines += [
        f"Wall of 0.4 x 0.2 m blocks, base driven by a {BASE_MOTION['frequency']} Hz sine of "
        f"{BASE_MOTION['amplitude']} m/s^2 (ramped over one cycle); dt = {DT * 1e3:g} ms, "
        f"{WARMUP} warm-up steps then {STEPS} timed steps per wall; default settings "
        f"(exact Coulomb, merit tol 1e-8; problems "
        f"above {SolverSettings().large_problem_unknowns} unknowns go to the two-level Gauss-Seidel of "
        "nscd.solver.coarse, smaller ones to the compiled Newton). Stage columns: share of the wall time of the "
        "timed steps (condense: the dense H, W and q of small problems, the factored Delassus operator H, "
        "M^-1 H^T, q and the recovery of v of large ones; solve: the compiled Newton, or the sweeps, body-space "
        "corrections and their banded Cholesky factor; rest: stepper and result bookkeeping). Accuracy: the largest FCLIB merit of the timed solves, and the largest "
        "displacement of a block relative to the base over the timed steps.", "",
        *markdown_table(header, table), "",
        "- fitted exponent p of time per step ~ contacts^p (target p <= 1.2 up to 2000 blocks): "
        f"all measured walls **p = {exponent:.2f}** (wall time), **{cpu_exponent:.2f}** (CPU time); "
        f"walls of >= 100 blocks p = {exponent_large:.2f} (wall), {cpu_exponent_large:.2f} (CPU). "
        "CPU time is the steadier measure on a loaded machine.",
        "- about 1000 blocks: " + (f"{at_1000.blocks} blocks, {at_1000.ms_per_step:.0f} ms per step wall, "
                                   f"{at_1000.cpu_ms_per_step:.0f} ms CPU (target < 50 ms)" if at_1000
                                   else "not measured within the budget (target < 50 ms)"),
        *([f"- the same wall with one-level NSGS (no body-space correction; the solver of the previous "
           f"release): {one_level.ms_per_step:.0f} ms per step wall, {one_level.cpu_ms_per_step:.0f} ms CPU, "
           f"{one_level.sweeps:.0f} sweeps per solve (two-level: {at_1000.sweeps:.1f}), max merit "
           f"{one_level.max_merit:.1e}, drift {one_level.drift_mm:.1e} mm"] if one_level and at_1000 else []),
        f"- measuring budget per wall: {args.budget:.0f} s; 1-min load average at the end of the run "
        f"{os.getloadavg()[0]:.1f} (at the start: see the header)", "",
        "![time per step against contacts](scaling.png)",
    ]
    write_text("scaling.md", lines)
    write_csv("scaling.csv", [f.name for f in Row.__dataclass_fields__.values()],
              [[getattr(r, f) for f in Row.__dataclass_fields__] for r in rows])
    if rows:
        plot(rows, exponent, cpu_exponent)
    log(f"exponent {exponent:.2f} wall, {cpu_exponent:.2f} CPU (>= 100 blocks: {exponent_large:.2f}, "
        f"{cpu_exponent_large:.2f}); written {RESULTS / 'scaling.md'}")


if __name__ == "__main__":
    main()
