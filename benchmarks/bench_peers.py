"""nscd beside general-purpose engines (MuJoCo, PyBullet) on the free-rocking block.

The case of ``bench_engine`` part 1: a 0.5 x 1.5 m block released from rest at
alpha/2 about its corner, restitution 0, friction 0.8, 2.5 s. For dt = 1e-3 and
1e-4 s, every engine is run in this process, one after the other, and measured the
same way: restitution per impact from the rocking amplitudes (against Housner's
``1 - 1.5 sin^2 alpha``), 5th impact time against the 1-DOF Housner model, wall
and CPU seconds per simulated second. Writes ``benchmarks/results/peers.md``,
``peers.csv`` and ``peers_work_precision.png``.

An engine that is not installed (``pip install -e .[peers]``) is listed as skipped,
never replaced by anything else.

Engine settings (the block is the same rigid 0.5 x 0.5 x 1.5 m box, 2500 kg/m^3):

- MuJoCo: box geom on a plane, the body restricted to the x-z plane by two slide
  joints and a hinge (exactly planar); ``solref = "2dt 1"`` (the stiffest time
  constant MuJoCo accepts at this dt, critically damped: no bounce), ``solimp =
  "0.99 0.999 0.001"``, elliptic cone, ``impratio = 10``, ``noslip_iterations = 5``,
  Newton solver, implicit-fast integrator, friction 0.8 (condim 3), no joint damping.
- PyBullet: a 3D box on a plane (planar by symmetry), fixed time step ``dt`` (one
  substep), restitution 0, lateral friction 0.8, linear and angular damping 0,
  other solver settings PyBullet's defaults (sequential impulses, 50 iterations,
  split impulse).
- LMGC90 through its pip wrapper ``compas_lmgc90`` (Python 3.11 wheels, extra
  ``peers``): the block and a 3 x 3 x 0.2 m base as boxes from vertices and faces,
  the base a support (``set_supports(z_threshold=0)``), law ``IQS_CLB`` (Coulomb,
  friction 0.8, alert distance 1e-2 m), theta 0.5; angle from the body frame, omega
  by differences. If the block ends up below the base's top, the run stops and its
  row says so (with these settings it falls through within the first second).

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_peers.py [--quick]``
(``--quick``: nscd is run at dt = 1e-4 s for the first 1 s only, enough for its cost
but not its accuracy, which is then taken from dt = 1e-3 s only).
"""
from __future__ import annotations

import argparse
import math
import time
from importlib import metadata
from pathlib import Path
from typing import Callable

import numpy as np

import nscd

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.bench_peers
    from bench_engine import (ALPHA, ETA_HOUSNER, HEIGHT, N_IMPACTS, ROCK_T_END, THETA0, WIDTH, housner_reference,
                              rocking_accuracy, rocking_scene_2d)
    from common import RESULTS, log, markdown_table, stamp_lines, write_csv, write_text, save_figure
except ImportError:  # pragma: no cover
    from benchmarks.bench_engine import (ALPHA, ETA_HOUSNER, HEIGHT, N_IMPACTS, ROCK_T_END, THETA0, WIDTH,
                                         housner_reference, rocking_accuracy, rocking_scene_2d)
    from benchmarks.common import RESULTS, log, markdown_table, stamp_lines, write_csv, write_text, save_figure

DTS = (1e-3, 1e-4)
#: The midpoint rule reaches the peers' dt = 1e-4 accuracy at coarser steps (see BENCHMARKS.md).
MIDPOINT_DTS = (1e-2, 5e-3, 3e-3, 1e-3)
DENSITY, FRICTION, DEPTH = 2500.0, 0.8, 0.5   # kg/m^3, -, m (out-of-plane size of the 3D boxes)
#: Start of the block's centre for a tilt ``THETA0`` about the +x bottom edge (x, z), m.
CENTRE = (WIDTH / 2 - WIDTH / 2 * math.cos(THETA0) + HEIGHT / 2 * math.sin(THETA0),
          WIDTH / 2 * math.sin(THETA0) + HEIGHT / 2 * math.cos(THETA0))


def _history(step: Callable[[], tuple[float, float]], n_steps: int, dt: float):
    """Run ``step`` (advances one step, returns (angle rad, angular velocity rad/s)) ``n_steps`` times.

    Returns time (s), angle, omega (arrays of n_steps + 1, the initial state first),
    wall and CPU seconds of the loop.
    """
    t = np.arange(n_steps + 1) * dt
    angle, omega = np.empty(n_steps + 1), np.empty(n_steps + 1)
    angle[0], omega[0] = THETA0, 0.0
    cpu0, wall0 = time.process_time(), time.perf_counter()
    for k in range(1, n_steps + 1):
        angle[k], omega[k] = step()
    return t, angle, omega, time.perf_counter() - wall0, time.process_time() - cpu0


def mujoco_block(dt: float):
    """MuJoCo's model and data of the rocking box (settings in the module docstring), released
    at ``THETA0``: ``(mujoco module, model, data)``."""
    import mujoco

    half = (WIDTH / 2, DEPTH / 2, HEIGHT / 2)
    xml = f"""
<mujoco>
  <option timestep="{dt}" gravity="0 0 -9.80665" cone="elliptic" impratio="10" noslip_iterations="5"
          solver="Newton" integrator="implicitfast"/>
  <default><geom friction="{FRICTION} 0.005 0.0001" condim="3" solref="{2 * dt} 1"
                 solimp="0.99 0.999 0.001"/></default>
  <worldbody>
    <geom type="plane" size="5 5 0.1"/>
    <body name="block" pos="0 0 0">
      <joint name="x" type="slide" axis="1 0 0"/>
      <joint name="z" type="slide" axis="0 0 1"/>
      <joint name="pitch" type="hinge" axis="0 1 0"/>
      <geom type="box" size="{half[0]} {half[1]} {half[2]}" density="{DENSITY}"/>
    </body>
  </worldbody>
</mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    data.qpos[:] = (CENTRE[0], CENTRE[1], THETA0)   # hinge about +y: positive pitch lowers the +x side
    mujoco.mj_forward(model, data)
    return mujoco, model, data


def mujoco_run(dt: float, n_steps: int):
    """Free rocking in MuJoCo (settings in the module docstring); see :func:`_history`."""
    mujoco, model, data = mujoco_block(dt)

    def step():
        mujoco.mj_step(model, data)
        return float(data.qpos[2]), float(data.qvel[2])

    return _history(step, n_steps, dt)


def pybullet_run(dt: float, n_steps: int):
    """Free rocking in PyBullet (settings in the module docstring); see :func:`_history`."""
    import pybullet as pb

    client = pb.connect(pb.DIRECT)
    try:
        pb.setGravity(0, 0, -9.80665, physicsClientId=client)
        pb.setPhysicsEngineParameter(fixedTimeStep=dt, numSubSteps=0, physicsClientId=client)
        plane = pb.createMultiBody(0, pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=client),
                                   physicsClientId=client)
        half = (WIDTH / 2, DEPTH / 2, HEIGHT / 2)
        box = pb.createMultiBody(DENSITY * 8 * half[0] * half[1] * half[2],
                                 pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=client),
                                 basePosition=(CENTRE[0], 0.0, CENTRE[1]),
                                 baseOrientation=(0.0, math.sin(THETA0 / 2), 0.0, math.cos(THETA0 / 2)),
                                 physicsClientId=client)
        for body in (plane, box):
            pb.changeDynamics(body, -1, lateralFriction=FRICTION, restitution=0.0, linearDamping=0.0,
                              angularDamping=0.0, physicsClientId=client)

        def step():
            pb.stepSimulation(physicsClientId=client)
            _, (x, y, z, w) = pb.getBasePositionAndOrientation(box, physicsClientId=client)
            _, angular = pb.getBaseVelocity(box, physicsClientId=client)
            pitch = math.atan2(2 * (w * y - z * x), 1 - 2 * (x * x + y * y))   # rotation about y
            return pitch, float(angular[1])

        return _history(step, n_steps, dt)
    finally:
        pb.disconnect(physicsClientId=client)


def nscd_run(dt: float, n_steps: int, scheme: str = "theta"):
    """Free rocking in the nscd 2D engine (impacts localised, theta 0.5 or the midpoint rule),
    run as a user runs it (:meth:`nscd.Simulator.run`: many compiled steps per call, as
    :func:`nscd.simulate`); see :func:`_history`."""
    scene, block = rocking_scene_2d()
    sim = nscd.Simulator(scene, dt, nscd.Settings(scheme=scheme))
    cpu, wall = time.process_time(), time.perf_counter()
    sim.run(n_steps * dt)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    res = sim.result()
    if res.time.size != n_steps + 1:
        raise RuntimeError(f"nscd took {res.time.size - 1} steps, not {n_steps}")
    return res.time, res.angle(block), res.omega(block), wall, cpu


def nscd_midpoint_run(dt: float, n_steps: int):
    """:func:`nscd_run` with Moreau's midpoint rule (``Settings(scheme="midpoint")``)."""
    return nscd_run(dt, n_steps, scheme="midpoint")


def _box(centre, half, rotation) -> dict:
    """A box as LMGC90's wrapper takes it: 8 vertices (m) and 6 outward quadrilateral faces."""
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], float)
    vertices = (signs * np.asarray(half)) @ np.asarray(rotation).T + np.asarray(centre)
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return {"vertices": vertices.tolist(), "faces": faces}


def lmgc90_run(dt: float, n_steps: int):
    """Free rocking in LMGC90 (``compas_lmgc90``; settings in the module docstring); see :func:`_history`."""
    from compas_lmgc90.solver import Solver

    c, s = math.cos(THETA0), math.sin(THETA0)
    tilt = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    solver = Solver(dt=dt, theta=0.5, density=DENSITY)
    solver.geometry_from_v_f([_box((0.0, 0.0, -0.1), (1.5, 1.5, 0.1), np.eye(3)),
                              _box((CENTRE[0], 0.0, CENTRE[1]), (WIDTH / 2, DEPTH / 2, HEIGHT / 2), tilt)])
    solver.set_supports(z_threshold=0.0)
    solver.contact_law("IQS_CLB", FRICTION, alert=1e-2)
    solver.preprocess()
    # the frame may be stored as R or R^T: the sign is fixed by the first step (the tilt is positive)
    state = {"angle": THETA0, "sign": 0.0}

    def step():
        out = solver.lmgc90.compute_one_step()
        z = float(out.bodies[1][2])
        if z < 0.0:
            raise RuntimeError(f"the block fell through the base (centre at z = {z:.3f} m)")
        frame = np.array(out.body_frames[1]).reshape(3, 3)
        raw = math.atan2(frame[0, 2], frame[0, 0])
        state["sign"] = state["sign"] or math.copysign(1.0, raw)
        angle = state["sign"] * raw
        omega = (angle - state["angle"]) / dt
        state["angle"] = angle
        return angle, omega

    return _history(step, n_steps, dt)


#: engine label -> (package, runner, time steps in s)
ENGINES = {"nscd (theta 0.5)": ("nscd", nscd_run, DTS),
           "nscd (midpoint)": ("nscd", nscd_midpoint_run, MIDPOINT_DTS),
           "MuJoCo": ("mujoco", mujoco_run, DTS), "PyBullet": ("pybullet", pybullet_run, DTS),
           "LMGC90": ("compas_lmgc90", lmgc90_run, DTS)}


def _version(package: str) -> str | None:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return None


def run(quick: bool = False) -> list[str]:
    """Run every installed engine at every dt, write the results and return the Markdown lines."""
    t_ref, _ = housner_reference()
    rows, notes = [], []
    for scheme in ("theta", "midpoint"):   # load nscd's compiled kernels (impacts' included): a cost of the
        nscd_run(0.01, int(round(ROCK_T_END / 0.01)), scheme)   # process, not of a run
    for name, (package, runner, dts) in ENGINES.items():
        version = _version(package)
        if version is None:
            notes.append(f"- {name}: not installed (`pip install -e .[peers]`), skipped.")
            continue
        notes.append(f"- {name} {version}")
        for dt in dts:
            t_sim = 1.0 if quick and package == "nscd" and dt < 1e-3 else ROCK_T_END
            log(f"  peers: {name}, dt = {dt:g}, {t_sim:g} s")
            try:
                t, angle, omega, wall, cpu = runner(dt, int(round(t_sim / dt)))
            except Exception as exc:  # noqa: BLE001 - an engine that fails is a result
                rows.append({"engine": name, "dt": dt, "error": f"{type(exc).__name__}: {exc}"[:200]})
                continue
            row = {"engine": name, "dt": dt, "wall_per_sim_s": wall / t_sim, "cpu_per_sim_s": cpu / t_sim,
                   "eta": [math.nan] * N_IMPACTS, "eta_error": math.nan, "t5_error": math.nan, "error": ""}
            if t_sim >= ROCK_T_END:
                impacts, eta = rocking_accuracy(t, angle, omega)
                row["eta"] = list(eta)
                row["eta_error"] = float(np.max(np.abs(eta - ETA_HOUSNER)))
                if len(impacts) >= N_IMPACTS:
                    row["t5_error"] = float(abs(impacts[N_IMPACTS - 1] - t_ref[N_IMPACTS - 1]))
                else:
                    row["error"] = f"only {len(impacts)} impacts in {ROCK_T_END} s"
            else:
                row["error"] = f"timed over {t_sim:g} s only (--quick): no accuracy figures"
            rows.append(row)
    write_csv("peers.csv", ["engine", "dt", "wall_per_sim_s", "cpu_per_sim_s", "eta_error", "t5_error",
                            *[f"eta_{k + 1}" for k in range(N_IMPACTS)], "note"],
              [[r["engine"], r["dt"], r.get("wall_per_sim_s", math.nan), r.get("cpu_per_sim_s", math.nan),
                r.get("eta_error", math.nan), r.get("t5_error", math.nan), *r.get("eta", [math.nan] * N_IMPACTS),
                r["error"]] for r in rows])
    png = chart(rows)

    def fmt(r, key, spec):
        value = r.get(key, math.nan)
        return "—" if not np.isfinite(value) else format(value, spec)

    table = [[r["engine"], f"{r['dt']:g}", fmt(r, "wall_per_sim_s", ".3g"), fmt(r, "cpu_per_sim_s", ".3g"),
              " ".join("—" if not np.isfinite(e) else f"{e:.3f}" for e in r.get("eta", [math.nan] * N_IMPACTS)),
              fmt(r, "eta_error", ".1e"), fmt(r, "t5_error", ".1e"), r["error"] or ""] for r in rows]
    return [
        "# nscd beside MuJoCo and PyBullet: free rocking", "", *stamp_lines(),
        f"- mode: {'--quick' if quick else 'full'}", "", "Engines:", "", *notes, "",
        f"0.5 x 1.5 m block (alpha = {ALPHA:.4f} rad) released from rest at alpha/2 about its corner, e = 0, "
        f"mu = {FRICTION}, {ROCK_T_END} s. Restitution per impact from the rocking amplitudes by energy (the "
        f"measure of `bench_engine`), exact {ETA_HOUSNER:.4f}; 5th impact time against the 1-DOF Housner model "
        f"(t5 = {t_ref[N_IMPACTS - 1]:.5f} s). All engines run in this process one after the other; wall and CPU "
        "time of the stepping loop only (nscd's includes its result recording; the peers' includes reading "
        "the state back each step). Settings of each engine: see the docstring of `benchmarks/bench_peers.py`.",
        "", *markdown_table(["engine", "dt (s)", "wall s / sim s", "CPU s / sim s", "eta, impacts 1-5",
                             "max |eta - 0.850|", "|t5 - t5 Housner| (s)", "note"], table), "",
        f"![peers work-precision](./{png.name})", "",
    ]


def chart(rows: list[dict]) -> Path:
    """Restitution and 5th-impact-time error against CPU s per simulated s, one curve per engine."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.5), constrained_layout=True)
    for ax, key, label in ((axes[0], "eta_error", "max |eta - 0.850| over impacts 1-5"),
                           (axes[1], "t5_error", "|t5 - t5 (Housner 1-DOF)|, s")):
        for engine in ENGINES:
            pts = [r for r in rows if r["engine"] == engine and np.isfinite(r.get(key, math.nan)) and r[key] > 0]
            if not pts:
                continue
            ax.loglog([r["cpu_per_sim_s"] for r in pts], [r[key] for r in pts], "o-", label=engine)
            for r in pts:
                ax.annotate(f"{r['dt']:g}", (r["cpu_per_sim_s"], r[key]), textcoords="offset points",
                            xytext=(4, 4), fontsize=7)
        ax.set_xlabel("CPU s per simulated s (this machine)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_title("Restitution error (labels: dt in s)")
    axes[1].set_title("5th impact time error (labels: dt in s)")
    return save_figure(fig, "peers_work_precision.png")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="nscd at dt = 1e-4 timed over 1 s only")
    args = parser.parse_args()
    lines = run(quick=args.quick)
    write_text("peers.md", lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
