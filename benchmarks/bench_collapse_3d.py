"""Cost per step of the 97-block running-bond wall shaken to collapse: 3D against 2D.

The wall of ``benchmarks/bench_collapse.py``, an assembly that breaks up: ``nscd.wall(13, 7, 0.4, 0.2,
friction=0.7)`` (97 blocks, 0.4 x 0.2 m, restitution 0), its base shaken along x at
8 m/s^2 and 2 Hz with a one-cycle raised-cosine ramp (``Harmonic(8.0, frequency=2.0,
ramp_cycles=1.0)``), dt = 1e-3 s, exact Coulomb, the default settings or those given
on the command line (scheme, relative tolerance, bound on the interior point's problem
size). The same wall is built in 3D with ``depth=0.2`` (boxes 0.4 x 0.2 x 0.2 m in a
``Scene(dim=3)``, the motion in the plane of the wall) and both are stepped from t = 0 for the same number of steps. Reported per dimension: CPU and
wall-clock time per step (mean, median, worst), solver iterations, unconverged steps
and the largest FCLIB merit (the accuracy the time was bought at), and the 3D / 2D
ratio of the mean CPU time per step (goal <= 3).

Writes ``benchmarks/results/collapse_3d.md`` and ``collapse_3d.csv``, or the Markdown file given by
``--output`` and the CSV beside it (a trial run that must not replace the published table).

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_collapse_3d.py [--steps N] [--scheme theta]
[--tol-relative 1e-4] [--max-conic-unknowns 600] [--output /tmp/collapse_3d.md]``. The wall rides the
base until t ~ 0.15 s, its blocks start to rock from ~0.2 s and it breaks up from ~0.38 s: the
default 150 steps time the wall carried by the base, ``--steps 600 --tol-relative 1e-4
--max-conic-unknowns 0`` the onset of rocking and the break-up (the default tolerance, FCLIB merit
1e-8, is out of reach for most break-up problems: ``docs/solver.md``).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path
import warnings

import numpy as np

import nscd
from nscd.motion import Harmonic
from nscd.solver import SolverSettings

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.bench_collapse_3d
    from common import log, markdown_table, stamp_lines, write_csv, write_text
except ImportError:  # pragma: no cover
    from benchmarks.common import log, markdown_table, stamp_lines, write_csv, write_text

WALL = dict(n_courses=13, n_per_course=7, block_width=0.4, block_height=0.2, friction=0.7)
DEPTH = 0.2                    # m, the 3D wall's thickness
MOTION = dict(amplitude=8.0, frequency=2.0, ramp_cycles=1.0)   # m/s^2, Hz, cycles
DT = 1e-3                      # s
WARMUP = 2                     # steps before timing (the first compiles numba kernels)
GOAL_RATIO = 3.0


def measure(depth: float | None, n_steps: int, settings: nscd.Settings) -> dict:
    """Step the wall (2D if ``depth`` is None) ``n_steps`` times after a warm-up; timings and accuracy."""
    scene, courses = nscd.wall(**WALL, motion=Harmonic(**MOTION), depth=depth)
    sim = nscd.Simulator(scene, DT, settings)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # unconverged steps are counted below
        for _ in range(WARMUP):
            sim.step()
        cpu, wall, reports = np.empty(n_steps), np.empty(n_steps), []
        for k in range(n_steps):
            c0, w0 = time.process_time(), time.perf_counter()
            reports.append(sim.step())
            cpu[k], wall[k] = time.process_time() - c0, time.perf_counter() - w0
            if (k + 1) % 20 == 0:
                log(f"{'2D' if depth is None else '3D'}: {k + 1}/{n_steps} steps, "
                    f"mean {1e3 * cpu[:k + 1].mean():.1f} ms CPU per step")
    blocks = [b.index for c in courses for b in c]
    dim = scene.dim
    base = scene.bodies[0]
    # Largest displacement of a block relative to the base over the run: did the wall break up?
    base_shift = float(base.motion.displacement(sim.state.t))
    moved = sim.state.q[blocks, :dim].copy()
    moved[:, 0] -= base_shift
    start = np.array([scene.bodies[i].q0[:dim] for i in blocks])
    return {
        "dim": dim, "blocks": len(blocks), "steps": n_steps, "t_end": sim.state.t,
        "cpu_mean_ms": 1e3 * cpu.mean(), "cpu_median_ms": 1e3 * np.median(cpu),
        "cpu_max_ms": 1e3 * cpu.max(), "wall_mean_ms": 1e3 * wall.mean(),
        "iterations_mean": float(np.mean([r.iterations for r in reports])),
        "contacts_mean": float(np.mean([r.n_contacts for r in reports])),
        "over_100ms": int(np.sum(cpu > 0.1)),
        "unconverged": sum(not r.converged for r in reports),
        "max_merit": max(r.merit for r in reports),
        "max_relative_displacement_m": float(np.max(np.linalg.norm(moved - start, axis=1))),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=150, help="timed steps per wall (default 150)")
    parser.add_argument("--scheme", default=None, help="nscd.Settings scheme (default: the default)")
    parser.add_argument("--tol-relative", type=float, default=None, help="SolverSettings.tol_relative")
    parser.add_argument("--max-conic-unknowns", type=int, default=None, help="SolverSettings.max_conic_unknowns")
    parser.add_argument("--output", default=None,
                        help="Markdown file to write (the CSV beside it; default benchmarks/results/collapse_3d.md)")
    args = parser.parse_args()
    solver = SolverSettings(tol_relative=args.tol_relative, max_conic_unknowns=args.max_conic_unknowns)
    settings = nscd.Settings(solver=solver) if args.scheme is None else nscd.Settings(scheme=args.scheme, solver=solver)
    options = "".join(f" --{flag} {value}" for flag, value in (
        ("scheme", args.scheme), ("tol-relative", args.tol_relative), ("max-conic-unknowns", args.max_conic_unknowns))
        if value is not None)
    rows = [measure(None, args.steps, settings), measure(DEPTH, args.steps, settings)]
    ratio = rows[1]["cpu_mean_ms"] / rows[0]["cpu_mean_ms"]
    keys = list(rows[0])
    markdown = Path(args.output).resolve() if args.output else Path("collapse_3d.md")  # relative: in results/
    write_csv(str(markdown.with_suffix(".csv")), keys, [[r[k] for k in keys] for r in rows])
    table = markdown_table(
        ["wall", "blocks", "steps (t_end)", "CPU ms/step mean / median / worst", "steps > 100 ms", "wall-clock ms/step",
         "solver iterations", "contacts", "unconverged", "max merit", "largest block displacement vs base"],
        [[f"{r['dim']}D", r["blocks"], f"{r['steps']} ({r['t_end']:.3f} s)",
          f"{r['cpu_mean_ms']:.1f} / {r['cpu_median_ms']:.1f} / {r['cpu_max_ms']:.1f}", r["over_100ms"],
          f"{r['wall_mean_ms']:.1f}", f"{r['iterations_mean']:.1f}", f"{r['contacts_mean']:.0f}",
          r["unconverged"], f"{r['max_merit']:.2e}", f"{1e3 * r['max_relative_displacement_m']:.2f} mm"]
         for r in rows])
    verdict = "met" if ratio <= GOAL_RATIO else "not met"
    lines = ["# The 97-block wall shaken to collapse: 3D against 2D", "", *stamp_lines(), "",
             f"`nscd.wall(13, 7, 0.4, 0.2, friction=0.7[, depth={DEPTH}])`, base "
             f"`Harmonic(8.0, frequency=2.0, ramp_cycles=1.0)`, dt = {DT} s, scheme {settings.scheme}, "
             f"tol_relative {solver.tol_relative}, max_conic_unknowns {solver.max_conic_unknowns} (None: default), "
             f"{WARMUP} warm-up steps then {args.steps} timed steps from t = {WARMUP * DT} s "
             "(CPU time of this process: insensitive to the other processes' load).", "",
             *table, "",
             f"3D / 2D mean CPU per step: **{ratio:.2f}** (goal <= {GOAL_RATIO:g}: {verdict}).", "",
             "The last column says whether the wall had started to break up in the timed window: "
             "0 mm means it still rode the base rigidly (the ramp's acceleration stays below "
             "mu g = 6.9 m/s^2 until about t = 0.38 s), so the figures are the cost of a resting "
             "wall on an accelerating base; `--steps 600` reaches the break-up.", "",
             "Accuracy: a step counts as converged when the contact solver reached its tolerance "
             "(the absolute FCLIB merit, or tol_relative when given); the merit column is the largest "
             "FCLIB merit of the timed steps.",
             f"Run: `OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_collapse_3d.py --steps {args.steps}{options}`"]
    path = write_text(str(markdown), lines)
    log(f"wrote {path} and {path.with_suffix('.csv')}: 3D / 2D = {ratio:.2f}")


if __name__ == "__main__":
    main()
