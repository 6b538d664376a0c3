"""A small wall at the friction limit: unconverged steps and CPU with and without the
proximal-point iterations of the small-problem path (``nscd/solver/proximal.py``).

Scene: ``nscd.wall`` of ``--courses`` x ``--per-course`` blocks (default 4 x 3, 0.4 x 0.2 m,
2500 kg/m^3, friction ``--friction`` = 0.7) on a base shaken by ``Harmonic(8 m/s^2, 2 Hz,
one-cycle ramp)``, above mu g, dt = 1 ms, to ``--t-end`` (2 s), under each scheme of
``--schemes``, with the shipped solver (FCLIB merit 1e-8) and ``max_proximal`` = the shipped
value and 0 (the path before the proximal point: the compiled Newton, then the conic fixed
point and the polish), one run after the other in the same process. Its contact problems
are small (< 120 unknowns). Per run: CPU (process time), unconverged steps (counted and
warned by the stepper) and their worst merit, how far the bottom course slid on the base,
the spread of the blocks' horizontal displacements (break-up), the largest turn of a block
times its width (a joint opening), the energy balance ``kinetic + potential + dissipated -
work input`` as a share of the initial potential energy, and the deepest overlap.

Writes ``benchmarks/results/small_wall.md``.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/study_small_wall.py [--t-end 2]``
"""
from __future__ import annotations

import argparse
import time
import warnings

import numpy as np

import nscd
from nscd.motion import Harmonic
from nscd.solver import SolverSettings

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.study_small_wall
    from common import log, markdown_table, stamp_lines, write_text
except ImportError:  # pragma: no cover
    from benchmarks.common import log, markdown_table, stamp_lines, write_text


def run(courses: int, per_course: int, friction: float, scheme: str, t_end: float, max_proximal: int,
        tol_relative: float | None = None) -> list:
    """One run; the table row (see the module text)."""
    shake = Harmonic(8.0, frequency=2.0, ramp_cycles=1.0)
    scene, rows = nscd.wall(courses, per_course, 0.4, 0.2, density=2500.0, friction=friction, motion=shake)
    blocks = [b for row in rows for b in row]
    solver = SolverSettings(max_proximal=max_proximal, tol_relative=tol_relative)
    settings = nscd.Settings(scheme=scheme, solver=solver)
    start = time.process_time()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # counted below
        r = nscd.simulate(scene, t_end=t_end, dt=1e-3, settings=settings)
    cpu = time.process_time() - start
    x = np.array([r.position(b)[:, 0] - b.q0[0] for b in blocks])
    slip = np.max(np.abs(x[:len(rows[0])] - np.asarray(shake.displacement(r.time))))
    spread = np.max(np.ptp(x, axis=0))
    opening = max(np.max(np.abs(r.angle(b))) for b in blocks) * 0.4
    balance = r.kinetic + r.potential + r.dissipated - r.work_input
    energy = np.max(np.abs(balance - balance[0])) / r.potential[0]
    rep = r.report
    worst = f"{float(np.max(rep.merit)):.1e}" if rep.n_unconverged else "–"
    return [scheme, str(max_proximal), "–" if tol_relative is None else f"{tol_relative:g}", f"{cpu:.1f}",
            f"{rep.n_unconverged} / {rep.n_steps}", worst,
            f"{slip * 1e3:.1f}", f"{spread * 1e3:.1f}", f"{opening * 1e3:.1f}", f"{energy:.1e}",
            f"{rep.max_penetration * 1e6:.1f}"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--courses", type=int, default=4)
    parser.add_argument("--per-course", type=int, default=3)
    parser.add_argument("--friction", type=float, default=0.7)
    parser.add_argument("--t-end", type=float, default=2.0)
    parser.add_argument("--schemes", default="theta,midpoint")
    parser.add_argument("--tol-relative", type=float, default=None,
                        help="also run each scheme with the shipped solver and this SolverSettings.tol_relative")
    args = parser.parse_args()
    shipped = SolverSettings().max_proximal
    table = []
    for scheme in args.schemes.split(","):
        runs = [(0, None), (shipped, None)] + ([] if args.tol_relative is None else [(shipped, args.tol_relative)])
        for max_proximal, tol_relative in runs:
            log(f"{scheme}, max_proximal = {max_proximal}, tol_relative = {tol_relative}")
            table.append(run(args.courses, args.per_course, args.friction, scheme, args.t_end, max_proximal,
                             tol_relative))
            log(" | ".join(table[-1]))
    header = ["scheme", "max_proximal", "tol_relative", "CPU (s)", "unconverged steps", "worst merit",
              "slip on base (mm)",
              "spread (mm)", "joint opening (mm)", "energy balance / PE0", "deepest overlap (um)"]
    lines = [f"# A {args.courses} x {args.per_course} wall shaken above mu g (friction {args.friction:g}), "
             f"{args.t_end:g} s", "", *stamp_lines(), "",
             *markdown_table(header, table), "",
             "max_proximal = 0: the small-problem path without the proximal point (compiled Newton, then the "
             "conic fixed point and the polish). CPU is process time. Worst merit: the largest FCLIB merit of an "
             "unconverged step (tolerance 1e-8, or the relative one where set). Energy balance: the largest change "
             "of kinetic + potential + dissipated - work input over the run.", "",
             f"Run: `OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/study_small_wall.py --courses {args.courses} "
             f"--per-course {args.per_course} --friction {args.friction:g} --t-end {args.t_end:g} "
             f"--schemes {args.schemes}"
             + ("" if args.tol_relative is None else f" --tol-relative {args.tol_relative:g}") + "`"]
    log(f"wrote {write_text('small_wall.md', lines)}")


if __name__ == "__main__":
    main()
