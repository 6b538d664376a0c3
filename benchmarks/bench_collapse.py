"""Walls that break up on a shaking base: cost per step, convergence, energy and overlap; MuJoCo beside.

Scenes (``nscd.wall``, blocks 0.4 x 0.2 m, density 2500 kg/m^3, friction 0.7, restitution 0),
base shaken horizontally by ``Harmonic(8 m/s^2, 2 Hz, one-cycle ramp)``: 8 m/s^2 is above
``mu g = 6.87 m/s^2``, so the wall slides on its base and breaks up. dt = 1 ms,
:class:`nscd.Settings` with the schemes of ``--schemes`` (default: the midpoint rule, the
default scheme) and the shipped solver (target FCLIB merit 1e-8; ``--tol-relative`` and
``--max-conic-unknowns`` as :class:`nscd.solver.SolverSettings`).

- the README's wall, 13 courses x 7 blocks (97 bodies), for ``--t-end`` simulated seconds;
- the 990-block wall of ``benchmarks/bench_scaling.py`` (44 x 22), shaken the same way;
- the 97-block wall in MuJoCo in the same run: boxes 0.4 x 0.2 x 0.2 m (0.2 m deep) of the
  same density, planar joints (x, z, rotation about y), elliptic cone, friction 0.7, the
  base a box driven kinematically (its slide joint's position and velocity set to the
  same motion before every step), dt = 1 ms, the contact settings of ``bench_peers.py``.

Before each nscd run two steps of the same wall in a throwaway simulator load the compiled
kernels (from numba's cache, or compile them): a cost of the process, not of a step, as
MuJoCo's model compilation is not timed. Each nscd run stops at ``--t-end`` or when its CPU budget (``--budget`` / ``--budget-large``
seconds) is spent, and says so. Per run: steps, CPU seconds, median and worst CPU per step
(process time, so other processes' load does not count), steps over 100 ms, unconverged
steps (``StepReport.converged`` false: counted and warned by the stepper) and their worst
merit, the largest overlap between two bodies at the end of any step (``detect``'s most
negative gap), and the energy balance:

- ``E = kinetic + potential + dissipated`` from :class:`nscd.Result`;
- an estimate of the work the base does that uses none of the engine's contact quantities
  (``Result.work_input`` and ``report.energy_residual`` are computed from the impulses and
  relative velocities): the only horizontal external force
  on the blocks is the base's, so its impulse over a step is the change of the blocks'
  total horizontal momentum, and its work is that times the base velocity averaged over
  the step (first order in dt). The table gives the largest ``|E - E(0) - W_base|`` over
  the run as a share of the initial potential energy (goal: 1 %), and the most negative
  single-step increment of ``dissipated`` (energy created at the contacts).

Also reported: when the wall has broken up (the spread of the blocks' horizontal
displacements first exceeds 5 cm: it no longer moves as one body), and the median step
from the start to that moment (the 990-block wall's goal: shaken "until it has broken up",
median step <= 100 ms) beside the median over the whole run; ``--after-break-up S`` ends the
990-block wall's run S simulated seconds after its break-up.

Writes ``benchmarks/results/collapse.md`` and ``collapse.csv``.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_collapse.py [--t-end 5] [--budget 1800]``
"""
from __future__ import annotations

import argparse
import os
import time
import warnings
from dataclasses import dataclass

import numpy as np

import nscd
from nscd.contact.detect import detect
from nscd.motion import Harmonic
from nscd.solver import SolverSettings

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.bench_collapse
    from common import log, markdown_table, stamp_lines, write_csv, write_text
except ImportError:  # pragma: no cover
    from benchmarks.common import log, markdown_table, stamp_lines, write_csv, write_text

BLOCK = (0.4, 0.2)                    # width, height, m
DENSITY, FRICTION = 2500.0, 0.7       # kg/m^3, -
DEPTH = 0.2                           # m, out-of-plane size of MuJoCo's boxes
BASE_MOTION = dict(amplitude=8.0, frequency=2.0, ramp_cycles=1.0)   # m/s^2, Hz, cycles
DT = 1e-3                             # s
SMALL, LARGE = (13, 7), (44, 22)      # courses, blocks per course (97 and 990 blocks)
BROKEN_SPREAD = 0.05                  # m: spread of horizontal displacements that counts as broken up
SLOW_STEP = 0.1                       # s: the per-step goal


def _motion() -> Harmonic:
    return Harmonic(BASE_MOTION["amplitude"], frequency=BASE_MOTION["frequency"],
                    ramp_cycles=BASE_MOTION["ramp_cycles"])


@dataclass
class Run:
    """Outcome of one simulation (see the module text)."""

    name: str
    engine: str
    bodies: int
    steps: int
    t_reached: float
    cpu: float
    step_cpu: np.ndarray
    unconverged: int = 0
    worst_merit: float = 0.0
    max_overlap: float = float("nan")
    energy_drift: float = float("nan")       # max |E - E0 - W_base| / P0
    created: float = float("nan")            # most negative dissipated increment, J
    broken_at: float = float("nan")
    broken_step: int = 0                     # steps taken when the wall counted as broken up (0: not)
    stopped: str = ""


def run_nscd(name: str, courses: int, per_course: int, t_end: float, budget: float,
             tol_relative: float | None, max_conic_unknowns: int | None = None, scheme: str = "midpoint",
             overlap_every: int = 1, after_break_up: float | None = None) -> Run:
    """Simulate a wall (see the module text) until ``t_end``, ``budget`` CPU seconds or, if
    ``after_break_up`` is given, that many simulated seconds after it has broken up.

    ``tol_relative``, ``max_conic_unknowns``: those of :class:`nscd.solver.SolverSettings`
    (None: the defaults, absolute FCLIB merit 1e-8 alone, no bound on a problem's work);
    ``scheme``: :class:`nscd.Settings` ``scheme``.
    """
    motion = _motion()
    scene, _ = nscd.wall(n_courses=courses, n_per_course=per_course, block_width=BLOCK[0],
                         block_height=BLOCK[1], density=DENSITY, friction=FRICTION, motion=motion)
    settings = nscd.Settings(scheme=scheme, solver=SolverSettings(tol_relative=tol_relative,
                                                                  max_conic_unknowns=max_conic_unknowns))
    # the compiled kernels loaded (from numba's cache, or compiled) by two steps of the same wall
    # in a throwaway simulator: a cost of the process, not of a step (as MuJoCo's model
    # compilation is not timed)
    warm_up = nscd.Simulator(scene, dt=DT, settings=settings)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        warm_up.step()
        warm_up.step()
    sim = nscd.Simulator(scene, dt=DT, settings=settings)
    model = sim.model
    dyn = model.dynamic_index
    mass = model.mass[dyn]
    x0 = sim.state.q[dyn, 0].copy()
    n_steps = int(round(t_end / DT))
    step_cpu = np.empty(n_steps)
    momentum = [float(mass @ sim.state.v[dyn, 0])]
    work = [0.0]
    overlap, broken_at, broken_step, unconverged, worst = 0.0, float("nan"), 0, 0, 0.0
    stopped = ""
    cpu_start = time.process_time()
    k = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)   # counted below
        for k in range(n_steps):
            t0 = sim.state.t
            start = time.process_time()
            report = sim.step()
            step_cpu[k] = time.process_time() - start
            if not report.converged:
                unconverged += 1
                worst = max(worst, report.merit)
            p_x = float(mass @ sim.state.v[dyn, 0])
            v_base = 0.5 * (float(motion.velocity(t0)) + float(motion.velocity(sim.state.t)))
            work.append(work[-1] + v_base * (p_x - momentum[-1]))
            momentum.append(p_x)
            if k % overlap_every == 0:
                contacts = detect(model, sim.state.q, sim.margin)
                if len(contacts):
                    overlap = max(overlap, float(-contacts.gap.min()))
            if np.isnan(broken_at):
                spread = np.ptp(sim.state.q[dyn, 0] - x0)
                if spread > BROKEN_SPREAD:
                    broken_at, broken_step = sim.state.t, k + 1
            elif after_break_up is not None and sim.state.t >= broken_at + after_break_up - 0.5 * DT:
                stopped = f"{after_break_up:g} s after the break-up"
                k += 1
                break
            if time.process_time() - cpu_start > budget:
                stopped = f"CPU budget {budget:g} s spent at t = {sim.state.t:.3f} s"
                k += 1
                break
        else:
            k = n_steps
    cpu = time.process_time() - cpu_start
    result = sim.result()
    energy = result.kinetic + result.potential + result.dissipated
    drift = np.abs(energy - energy[0] - np.array(work[:energy.size]))
    p0 = float(result.potential[0])
    engine = ", ".join(["nscd", scheme] + ([] if tol_relative is None else [f"tol_relative {tol_relative:g}"])
                       + ([] if max_conic_unknowns is None else [f"max_conic_unknowns {max_conic_unknowns}"]))
    return Run(name, engine, len(dyn), k, sim.state.t, cpu, step_cpu[:k], unconverged, worst, overlap,
               float(drift.max() / p0), float(np.diff(result.dissipated).min(initial=0.0)), broken_at, broken_step,
               stopped)


def run_mujoco(courses: int, per_course: int, t_end: float) -> Run:
    """The same wall in MuJoCo (see the module text)."""
    import mujoco

    motion = _motion()
    scene, _ = nscd.wall(n_courses=courses, n_per_course=per_course, block_width=BLOCK[0],
                         block_height=BLOCK[1], density=DENSITY, friction=FRICTION, motion=motion)
    bodies = [b for b in scene.bodies if b.mass != float("inf")]
    base = next(b for b in scene.bodies if b.name == "base")
    base_half = 0.5 * np.ptp(base.shape.vertices, axis=0)
    blocks = []
    for i, b in enumerate(bodies):
        half = 0.5 * np.ptp(b.shape.vertices, axis=0)
        x, y = b.q0[0], b.q0[1]
        blocks.append(f"""
    <body name="b{i}" pos="{x} 0 {y}">
      <joint type="slide" axis="1 0 0"/><joint type="slide" axis="0 0 1"/><joint type="hinge" axis="0 1 0"/>
      <geom type="box" size="{half[0]} {DEPTH / 2} {half[1]}" density="{DENSITY}"/>
    </body>""")
    xml = f"""
<mujoco>
  <option timestep="{DT}" gravity="0 0 -9.80665" cone="elliptic" impratio="10" noslip_iterations="5"
          solver="Newton" integrator="implicitfast"/>
  <default><geom friction="{FRICTION} 0.005 0.0001" condim="3" solref="{2 * DT} 1" solimp="0.99 0.999 0.001"/></default>
  <worldbody>
    <body name="base" pos="0 0 {base.q0[1]}">
      <joint name="drive" type="slide" axis="1 0 0"/>
      <geom type="box" size="{base_half[0]} {DEPTH} {base_half[1]}" density="1e6"/>
    </body>{''.join(blocks)}
  </worldbody>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    n_steps = int(round(t_end / DT))
    step_cpu = np.empty(n_steps)
    cpu_start = time.process_time()
    for k in range(n_steps):
        t = k * DT
        start = time.process_time()
        data.qpos[0] = float(motion.displacement(t))
        data.qvel[0] = float(motion.velocity(t))
        mujoco.mj_step(model, data)
        step_cpu[k] = time.process_time() - start
    return Run("97-block wall", "MuJoCo", len(bodies), n_steps, n_steps * DT, time.process_time() - cpu_start,
               step_cpu)


def _row(run: Run) -> tuple:
    ms = 1e3 * run.step_cpu
    return (run.name, run.engine, run.bodies, run.steps, f"{run.t_reached:.3f}", f"{run.cpu:.1f}",
            f"{np.median(ms):.2f}", f"{np.median(ms[:run.broken_step]):.2f}" if run.broken_step else "–",
            f"{ms.max():.1f}", int((run.step_cpu > SLOW_STEP).sum()),
            run.unconverged if run.engine.startswith("nscd") else "–",
            f"{run.worst_merit:.1e}" if run.unconverged else "–",
            "–" if np.isnan(run.max_overlap) else f"{run.max_overlap:.1e}",
            "–" if np.isnan(run.energy_drift) else f"{100 * run.energy_drift:.2f} %",
            "–" if np.isnan(run.created) else f"{run.created:.3g}",
            "–" if np.isnan(run.broken_at) else f"{run.broken_at:.3f}",
            run.stopped or ("finished" if run.engine.startswith("nscd") else "–"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--t-end", type=float, default=5.0, help="simulated seconds of the 97-block wall")
    parser.add_argument("--t-end-mujoco", type=float, default=None,
                        help="simulated seconds of the MuJoCo run (default: --t-end)")
    parser.add_argument("--t-end-large", type=float, default=1.0, help="simulated seconds of the 990-block wall")
    parser.add_argument("--budget", type=float, default=1800.0, help="CPU seconds per 97-block nscd run")
    parser.add_argument("--budget-default", type=float, default=None,
                        help="CPU seconds of the 97-block run with the default tolerance (default: --budget)")
    parser.add_argument("--tol-relative", type=float, default=1e-4, help="SolverSettings.tol_relative of the "
                        "second 97-block run and of the 990-block run")
    parser.add_argument("--budget-large", type=float, default=900.0, help="CPU seconds for the 990-block wall")
    parser.add_argument("--after-break-up", type=float, default=None, help="simulated seconds the 990-block wall "
                        "goes on after it has broken up (default: to --t-end-large)")
    parser.add_argument("--skip-large", action="store_true", help="no 990-block wall")
    parser.add_argument("--max-conic-unknowns", type=int, default=None, help="SolverSettings.max_conic_unknowns "
                        "of every nscd run (default: none, the shipped default)")
    parser.add_argument("--schemes", default="midpoint", help="comma-separated nscd.Settings schemes; the two "
                        "97-block runs are made with each")
    args = parser.parse_args()
    schemes = args.schemes.split(",")
    load = os.getloadavg()[0]
    runs = []
    log("MuJoCo, 97-block wall")
    runs.append(run_mujoco(*SMALL, args.t_end_mujoco or args.t_end))
    bound = args.max_conic_unknowns
    for scheme in schemes:
        log(f"nscd, 97-block wall, {scheme}, default tolerance")
        runs.append(run_nscd("97-block wall", *SMALL, args.t_end, args.budget_default or args.budget, None, bound,
                             scheme))
        log(f"nscd, 97-block wall, {scheme}, tol_relative {args.tol_relative:g}")
        runs.append(run_nscd("97-block wall", *SMALL, args.t_end, args.budget, args.tol_relative, bound, scheme))
    small_runs = len(runs) - 1
    if not args.skip_large:
        log(f"nscd, 990-block wall, {schemes[0]}, tol_relative {args.tol_relative:g}")
        runs.append(run_nscd("990-block wall", *LARGE, args.t_end_large, args.budget_large, args.tol_relative,
                             bound, schemes[0], overlap_every=10, after_break_up=args.after_break_up))
    header = ("scene", "engine", "bodies", "steps", "t reached (s)", "CPU (s)", "median step (ms)",
              "median step to the break-up (ms)", "worst step (ms)", "steps > 100 ms", "unconverged", "worst unconverged merit", "max overlap (m)",
              "energy drift / P0", "energy created in a step (J)", "broken up at (s)", "run")
    rows = [_row(r) for r in runs]
    write_csv("collapse.csv", header, rows)
    mujoco = runs[0]
    per_step = mujoco.cpu / mujoco.steps
    ratios = ", ".join(f"{r.engine}: **{(r.cpu / max(r.steps, 1)) / per_step:.0f}x**" for r in runs[1:1 + small_runs])
    lines = ["# Walls breaking up on a shaking base", "", *stamp_lines(), f"- 1-min load average at start: {load:.1f}",
             "",
             f"Base: Harmonic({BASE_MOTION['amplitude']} m/s^2, {BASE_MOTION['frequency']} Hz, ramp "
             f"{BASE_MOTION['ramp_cycles']} cycle), above mu g = {FRICTION * 9.80665:.2f} m/s^2; dt = {DT * 1e3:g} ms; "
             "nscd: target FCLIB merit 1e-8 (and the relative merit where stated), the settings named in the "
             "engine column, the rest default. CPU is process time, one core.", "",
             *markdown_table(header, rows), "",
             f"nscd / MuJoCo, mean CPU per step on the 97-block wall over the steps each run took: {ratios} "
             "(MuJoCo: soft, regularised contacts; nscd: exact Coulomb friction, every step solved to its "
             "tolerance or counted). A run stopped by its CPU budget covers the start of the break-up only.", "",
             "Energy drift: E = kinetic + potential + dissipated from the result, against the base's work "
             "estimated from the blocks' horizontal momentum alone (first order in dt), independently of the "
             "contact impulses that `Result.work_input` is computed from.", "",
             f"Run: `OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_collapse.py --t-end {args.t_end:g} "
             f"--t-end-mujoco {args.t_end_mujoco or args.t_end:g} --t-end-large {args.t_end_large:g} --budget {args.budget:g} "
             f"--budget-default {args.budget_default or args.budget:g} --tol-relative {args.tol_relative:g} "
             f"--budget-large {args.budget_large:g} --schemes {args.schemes}"
             + ("" if args.after_break_up is None else f" --after-break-up {args.after_break_up:g}")
             + ("" if bound is None else f" --max-conic-unknowns {bound}") + "`"]
    path = write_text("collapse.md", lines)
    log(f"wrote {path}")


if __name__ == "__main__":
    main()
