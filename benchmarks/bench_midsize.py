"""Scenes of a few dozen bodies: compiled steps against the general step, MuJoCo beside.

Scenes of at most ``nscd.contact.detect.ALL_PAIRS_BODIES`` bodies take their plain steps in
compiled code (``nscd.compiled_step``); every step a compiled call hands back is taken by the
general step, ``nscd.stepper.step``, and a single run whose calls hand back their first step
twice in a row backs off (``nscd.stepper._Paths``). Each scene here is run twice in the same
process, with the default settings (midpoint rule, FCLIB merit 1e-8; one row below names its own), dt = 1 ms, for
``--t-end`` simulated seconds after a warm-up of 20 steps: as shipped, and with the compiled
steps off (every step by the general step, the route of a scene of more bodies). Both give the
same run bit for bit (``tests/test_compiled_step.py``); the table checks the final states.

- an arch of 20 voussoirs at rest (``nscd.arch(5.0, 0.8, 20)``: 22 bodies, 21 joints, 84
  unknowns a step);
- an arch of 28 voussoirs on a base shaken by ``Harmonic(3 m/s^2, 2 Hz, 4 cycles, one-cycle
  ramps)`` (30 bodies, 116 unknowns: the largest problems the dense fast path takes);
- a stack of 24 blocks 0.4 x 0.2 m shaken the same way (25 bodies: a slender column whose
  joints rock and stick, problems of the proximal point: ``docs/solver.md``);
- a running-bond wall of 5 courses x 6 blocks (32 blocks, 33 bodies) shaken by
  ``benchmarks/bench_collapse.py``'s motion (8 m/s^2, 2 Hz): its problems (about 80 active
  contacts) are beyond the dense fast path, so its steps are the general step's on either
  path; MuJoCo runs the same wall in the same process (``bench_collapse.run_mujoco``:
  boxes 0.2 m deep, elliptic cone); the wall again with the collapse studies' solver setting,
  ``SolverSettings(tol_relative=1e-4)`` (a step also accepted at a relative merit of 1e-4,
  ``docs/guide/solver.md``);
- a running-bond wall of 6 courses x 3 blocks (22 bodies) on a base shaken gently,
  ``Harmonic(1 m/s^2, 2 Hz)``, far below mu g: it rides the base, but a few of its problems
  (192 unknowns) are left by the sweeps to the proximal point (``docs/solver.md``, fifteenth
  round).

Per run: CPU per step (process time over the timed steps), the steps taken by the compiled
calls, unconverged steps (counted and warned by the stepper) and the largest merit.

Writes ``benchmarks/results/midsize.md`` and ``midsize.csv``.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_midsize.py [--t-end 0.5]``
"""
from __future__ import annotations

import argparse
import time
import warnings
from collections.abc import Callable

import numpy as np

import nscd
from nscd import compiled_step
from nscd.motion import Harmonic
from nscd.solver import SolverSettings

from bench_collapse import _motion, run_mujoco
from common import log, markdown_table, stamp_lines, write_csv, write_text

DT = 1e-3       # s
WARM_UP = 20    # steps before timing (the kernels loaded, the warm starts built)


def _shaking() -> Harmonic:
    return Harmonic(3.0, frequency=2.0, cycles=4, ramp_cycles=1)


SCENES: dict[str, Callable[[], nscd.Scene]] = {
    "arch of 20 voussoirs, at rest": lambda: nscd.arch(5.0, 0.8, 20)[0],
    "arch of 28 voussoirs, shaken": lambda: nscd.arch(5.0, 0.8, 28, motion=_shaking())[0],
    "stack of 24 blocks, shaken": lambda: nscd.stack(24, 0.4, 0.2, motion=_shaking())[0],
    "wall 5 x 6, shaken at 8 m/s^2": lambda: nscd.wall(5, 6, 0.4, 0.2, density=2500.0, friction=0.7,
                                                      motion=_motion())[0],
}
SCENES["wall 5 x 6, shaken at 8 m/s^2, tol_relative 1e-4"] = SCENES["wall 5 x 6, shaken at 8 m/s^2"]
SCENES["wall 6 x 3, shaken at 1 m/s^2"] = lambda: nscd.wall(6, 3, 0.4, 0.2, density=2500.0, friction=0.7,
                                                            motion=Harmonic(1.0, frequency=2.0))[0]

#: The settings of a scene's runs where not the defaults
SETTINGS = {"wall 5 x 6, shaken at 8 m/s^2, tol_relative 1e-4": nscd.Settings(solver=SolverSettings(tol_relative=1e-4))}


def run(make: Callable[[], nscd.Scene], t_end: float, compiled: bool, settings: nscd.Settings) -> dict:
    """One run of ``make()``'s scene with ``settings`` (see the module text); ``compiled``: as
    shipped, else every step by the general step."""
    taken = [0]
    run_one, of = compiled_step.CompiledSteps.run_one, compiled_step.CompiledSteps.of

    def counted(self, data, n_steps):
        steps, code = run_one(self, data, n_steps)
        taken[0] += steps
        return steps, code

    compiled_step.CompiledSteps.run_one = counted
    if not compiled:
        compiled_step.CompiledSteps.of = classmethod(lambda cls, *args: None)
    try:
        scene = make()
        sim = nscd.Simulator(scene, DT, settings)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # unconverged steps: counted below
            sim.run(WARM_UP * DT)
            taken[0] = 0
            n_steps = int(round(t_end / DT))
            cpu = time.process_time()
            sim.run((WARM_UP + n_steps) * DT)
            cpu = time.process_time() - cpu
    finally:
        compiled_step.CompiledSteps.run_one, compiled_step.CompiledSteps.of = run_one, of
    report = sim.result().report
    return {"bodies": len(scene.bodies), "steps": n_steps, "cpu": cpu, "compiled": taken[0],
            "unconverged": int(report.n_unconverged), "merit": float(np.max(report.merit)),
            "q": sim.state.q.copy()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--t-end", type=float, default=0.5, help="simulated seconds timed per run")
    args = parser.parse_args()
    header = ["scene", "bodies", "path", "steps", "steps compiled", "CPU ms/step", "general / shipped",
              "unconverged", "max merit", "same final state"]
    rows = []
    for name, make in SCENES.items():
        log(f"{name}: shipped, then the general step alone")
        settings = SETTINGS.get(name, nscd.Settings())
        shipped, general = run(make, args.t_end, True, settings), run(make, args.t_end, False, settings)
        same = bool(np.array_equal(shipped["q"], general["q"]))
        for path, r in (("shipped", shipped), ("general step alone", general)):
            ratio = general["cpu"] / shipped["cpu"]
            rows.append([name, r["bodies"], path, r["steps"], r["compiled"], f"{1e3 * r['cpu'] / r['steps']:.3f}",
                         f"{ratio:.2f}" if path == "shipped" else "", r["unconverged"], f"{r['merit']:.1e}",
                         "yes" if same else "NO"])
    log("wall 5 x 6 in MuJoCo")
    mujoco = run_mujoco(5, 6, args.t_end)
    rows.append(["wall 5 x 6, shaken at 8 m/s^2", mujoco.bodies, "MuJoCo", mujoco.steps, "–",
                 f"{1e3 * mujoco.cpu / mujoco.steps:.3f}", "", "–", "–", "–"])
    write_csv("midsize.csv", header, rows)
    lines = ["# Scenes of a few dozen bodies: compiled steps against the general step", "",
             f"dt = {DT:g} s, default settings (midpoint rule, FCLIB merit 1e-8) unless the scene names its "
             f"solver setting, {args.t_end:g} s simulated "
             f"after {WARM_UP} steps; CPU time (`time.process_time`). \"general / shipped\": the same run with every "
             "step by the general step, over the shipped run's CPU, in the same process.", "",
             *markdown_table(header, rows), "", *stamp_lines()]
    path = write_text("midsize.md", lines)
    print("\n".join(lines))
    log(f"wrote {path}")


if __name__ == "__main__":
    main()
