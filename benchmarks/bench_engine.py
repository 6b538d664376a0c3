"""Speed of the nscd engine step, always beside the accuracy reached.

Five measurements, written to ``benchmarks/results/`` (``engine.md``, CSV tables,
``work_precision.png``):

1. free rocking of a 0.5 x 1.5 m block released at theta0 = alpha/2: per-impact
   restitution (from the rocking amplitudes, by energy) against Housner's
   ``1 - 1.5 sin^2 alpha`` and the 5th impact time against the 1-DOF Housner model,
   for several time steps and integrator settings, with a work–precision chart;
2. per-step time of a resting block and of 3- and 10-block stacks (2D);
3. per-step time of 3D scenes (rocking box, LNEC stacked pair, trilith) and a
   cProfile breakdown of the 3D step;
4. a block sliding to rest: stopping distance against ``v0^2 / (2 mu g)`` and
   lift-off, exact against relaxed Coulomb cone;
5. a cProfile breakdown of the 2D single-block step.

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_engine.py [--quick]``
(or through ``benchmarks/run_all.py``). ``--quick`` drops the two smallest time
steps of part 1 and shortens the timing runs.
"""
from __future__ import annotations

import argparse
import cProfile
import math
import pstats
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

import nscd
from nscd import lnec, stepper
from nscd.motion import STANDARD_GRAVITY
from nscd.rocking import HousnerBlock
from nscd.shapes3d import box3
from nscd.solver import SolverSettings

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.bench_engine
    from common import RESULTS, log, markdown_table, stamp_lines, timed_steps, write_csv, write_text, save_figure
except ImportError:  # pragma: no cover
    from benchmarks.common import RESULTS, log, markdown_table, stamp_lines, timed_steps, write_csv, write_text, save_figure

# -- the rocking block of part 1 (and the 2D profile) -------------------------------------
WIDTH, HEIGHT = 0.5, 1.5          # m
B, H = WIDTH / 2, HEIGHT / 2      # half width, half height, m
ALPHA = math.atan2(B, H)          # slenderness angle, rad
THETA0 = ALPHA / 2                # release angle, rad
ETA_HOUSNER = 1.0 - 1.5 * math.sin(ALPHA) ** 2
N_IMPACTS = 5
ROCK_T_END = 2.5                  # s: 5 impacts (5th at 2.25 s) and the peak after the 5th (~2.39 s)
DTS = (1e-2, 5e-3, 3e-3, 1e-3, 3e-4, 1e-4)
DTS_QUICK = DTS[:3]
METHODS = {
    "midpoint, localised": nscd.Settings(scheme="midpoint", localize_impacts=True),
    "midpoint, plain": nscd.Settings(scheme="midpoint", localize_impacts=False),
    "theta 0.5, localised": nscd.Settings(scheme="theta", theta=0.5, localize_impacts=True),
    "theta 0.5, plain": nscd.Settings(scheme="theta", theta=0.5, localize_impacts=False),
    "theta 1, localised": nscd.Settings(scheme="theta", theta=1.0, localize_impacts=True),
    "theta 1, plain": nscd.Settings(scheme="theta", theta=1.0, localize_impacts=False),
    "theta 0.5, localised, relaxed cone": nscd.Settings(
        scheme="theta", theta=0.5, localize_impacts=True, solver=SolverSettings(coulomb="relaxed")),
}
#: Targets for the median step (s): one 2D block, the 2D 3-block stack, the LNEC trilith in 3D
#: (the compiled step's aims, about 6x MuJoCo's step of a 3D box for the block).
TARGET_SINGLE, TARGET_STACK3, TARGET_TRILITH = 25e-6, 50e-6, 150e-6
#: Target for free rocking at MuJoCo's dt = 1e-4 accuracy: this fraction of MuJoCo's CPU time.
TARGET_FREE_ROCKING_VS_MUJOCO = 0.1

# -- the other scenes ---------------------------------------------------------------------
STACK_BLOCK = (0.4, 0.3)          # m, width x height of the stacked blocks of part 2
SLIDE_V0, SLIDE_MU, SLIDE_BLOCK = 1.0, 0.3, (0.4, 0.2)
DT = 1e-3                         # s, step of parts 2-5

#: Parts of the step for the profile breakdown. A small scene's step runs in one compiled call
#: (``compiled_step.plain_steps``: detection, assembly, solve, integration and the recording), which
#: cProfile sees as one leaf; a step handed back (an impact located within the step, a problem left to
#: the solver's other routes) is the general step ``stepper.step``; the rest is the Python around
#: the compiled call (its arguments, the report, the recording room, the run loop).
COMPILED, GENERAL, AROUND = ("compiled step (detection to integration, recording)",
                             "general step in Python (impacts within the step, other solver routes)",
                             "Python around the compiled call (arguments, report, loop)")


def _part_of(filename: str, line: int, function: str) -> str | None:
    """The part of :data:`COMPILED`, :data:`GENERAL` a profiled function stands for, else None."""
    if "plain_steps" in function:
        return COMPILED
    code = stepper.step.__code__
    if filename == code.co_filename and line == code.co_firstlineno and function == code.co_name:
        return GENERAL
    return None


@dataclass
class Summary:
    """Headline numbers of a run, for BENCHMARKS.md (filled by the parts of :func:`run`)."""

    quick: bool
    rocking: list = field(default_factory=list)      # rows of part 1 (dicts)
    housner_cpu: float = math.nan                    # s, CPU of the 1-DOF model over ROCK_T_END
    steps: list = field(default_factory=list)        # rows of parts 2 and 3 (dicts)
    sliding: list = field(default_factory=list)      # rows of part 4 (dicts)
    profile_2d: dict = field(default_factory=dict)   # stage -> share of the step
    profile_3d: dict = field(default_factory=dict)
    top_2d: list = field(default_factory=list)       # (function, tottime share)
    calls_2d: float = math.nan                       # function calls per 2D step (cProfile)
    png: Path | None = None


# --------------------------------------------------------------------------- scenes
def rocking_scene_2d(theta0: float = THETA0) -> tuple[nscd.Scene, object]:
    """The 0.5 x 1.5 m block tilted clockwise by ``theta0`` (rad) on its right bottom corner."""
    c, s = math.cos(-theta0), math.sin(-theta0)
    # centre = pivot (b, 0) + R(-theta0) (-b, h)
    centre = (B + c * -B - s * H, s * -B + c * H)
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), motion=None)
    block = scene.add_block(nscd.box(WIDTH, HEIGHT), position=centre, angle=-theta0, density=2500.0)
    scene.set_contact(friction=0.8, restitution=0.0)
    return scene, block


def stack_scene_2d(n_blocks: int) -> nscd.Scene:
    """``n_blocks`` blocks of 0.4 x 0.3 m stacked at rest on a fixed base (n_blocks = 1: one block)."""
    width, height = STACK_BLOCK
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), motion=None)
    for k in range(n_blocks):
        scene.add_block(nscd.box(width, height), position=(0.0, height * (k + 0.5)), density=2500.0)
    scene.set_contact(friction=0.8, restitution=0.0)
    return scene


def rocking_scene_3d(theta0: float = THETA0) -> tuple[nscd.Scene, object]:
    """A 0.5 x 0.5 x 1.5 m box pitched by ``theta0`` about its +x bottom edge (planar rocking)."""
    c, s = math.cos(theta0), math.sin(theta0)
    scene = nscd.Scene(dim=3)
    scene.add_base(box3(3.0, 3.0, 0.2), position=(0.0, 0.0, -0.1))
    block = scene.add_block(box3(WIDTH, WIDTH, HEIGHT), position=(B - B * c + H * s, 0.0, B * s + H * c),
                            orientation=(math.cos(theta0 / 2), 0.0, math.sin(theta0 / 2), 0.0), density=2500.0)
    scene.set_contact(friction=0.8, restitution=0.0)
    return scene, block


def sliding_scene(coulomb: str) -> tuple[nscd.Scene, object, nscd.Settings]:
    """The 0.4 x 0.2 m block launched at 1 m/s along a 4 m fixed base, mu = 0.3."""
    width, height = SLIDE_BLOCK
    scene = nscd.Scene()
    scene.add_base(nscd.box(4.0, 0.2), position=(0.0, -0.1), motion=None)
    block = scene.add_block(nscd.box(width, height), position=(-1.0, height / 2), velocity=(SLIDE_V0, 0.0),
                            density=2500.0)
    scene.set_contact(friction=SLIDE_MU, restitution=0.0)
    return scene, block, nscd.Settings(solver=SolverSettings(coulomb=coulomb))


# --------------------------------------------------------------------------- measures
def _crossings(t: np.ndarray, angle: np.ndarray, omega: np.ndarray, min_gap: float = 0.05) -> np.ndarray:
    """Times (s) at which the angle changes sign (zero counts as positive), extrapolated from the sample before.

    The angle is linear in time before the impact (the kink is at the impact), so
    ``t_k - angle_k / omega_k`` is second-order accurate. Crossings closer than
    ``min_gap`` s to the previous one (round-off chatter around zero) are dropped.
    """
    negative = angle < 0.0
    k = np.flatnonzero(negative[:-1] != negative[1:])
    times: list[float] = []
    for i in k:
        tc = t[i] - angle[i] / omega[i] if omega[i] != 0.0 else t[i]
        tc = min(max(tc, t[i]), t[i + 1])
        if not times or tc - times[-1] > min_gap:
            times.append(tc)
    return np.array(times)


def _peak(t: np.ndarray, values: np.ndarray, t0: float, t1: float) -> float:
    """max |values| on [t0, t1], refined by a parabola through the largest sample and its neighbours.

    Returns nan when the maximum sits on the window's edge (the peak was not reached).
    """
    idx = np.flatnonzero((t >= t0) & (t <= t1))
    a = np.abs(values[idx])
    j = int(np.argmax(a))
    if j == 0 or j == len(a) - 1:
        return math.nan
    y0, y1, y2 = a[j - 1], a[j], a[j + 1]
    denom = y0 - 2 * y1 + y2
    return float(y1 - 0.125 * (y0 - y2) ** 2 / denom) if denom < 0 else float(y1)


def restitution_from_amplitudes(amplitudes: np.ndarray, alpha: float = ALPHA) -> np.ndarray:
    """Per-impact velocity ratio from successive rocking amplitudes (rad), by energy.

    ``eta_k = sqrt((cos(alpha - a_k) - cos alpha) / (cos(alpha - a_(k-1)) - cos alpha))``:
    the energy above rest is ``m g R (cos(alpha - |a|) - cos alpha)`` at a peak and all
    kinetic at the impact, where the velocity ratio squared scales it.
    """
    energy = np.cos(alpha - np.abs(amplitudes)) - math.cos(alpha)
    return np.sqrt(energy[1:] / energy[:-1])


def rocking_accuracy(t: np.ndarray, angle: np.ndarray, omega: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Impact times (s) and per-impact restitutions of a free-rocking history (first N_IMPACTS)."""
    impacts = _crossings(t, angle, omega)[:N_IMPACTS + 1]
    if len(impacts) < N_IMPACTS:
        return impacts, np.full(N_IMPACTS, math.nan)
    ends = list(impacts[1:N_IMPACTS + 1]) + [t[-1]] * (N_IMPACTS + 1 - len(impacts))
    peaks = [_peak(t, angle, impacts[k], ends[k]) for k in range(N_IMPACTS)]
    return impacts[:N_IMPACTS], restitution_from_amplitudes(np.array([THETA0, *peaks]))


def _median_us(wall: np.ndarray) -> float:
    return float(np.median(wall) * 1e6)


# --------------------------------------------------------------------------- part 1
def housner_reference() -> tuple[np.ndarray, float]:
    """Impact times (s) of the 1-DOF Housner model and its CPU time (s, best of 3)."""
    block = HousnerBlock(width=WIDTH, height=HEIGHT)
    best = math.inf
    for _ in range(3):
        start = time.process_time()
        res = block.simulate(None, t_end=ROCK_T_END + 0.2, theta0=-THETA0)
        best = min(best, time.process_time() - start)
    return res.impacts.time[:N_IMPACTS], best


def measurement_floor(dt: float) -> tuple[float, float]:
    """Error of :func:`rocking_accuracy` itself on the exact 1-DOF history sampled every ``dt`` s.

    Returns the max restitution error and the 5th impact time error (s) of the
    measurement alone: the floor below which the engine's errors cannot be resolved.
    """
    res = HousnerBlock(width=WIDTH, height=HEIGHT).simulate(None, t_end=ROCK_T_END, theta0=-THETA0, dt_out=dt)
    on_grid = np.abs(res.time / dt - np.round(res.time / dt)) < 1e-9   # drop the event samples
    _, first = np.unique(res.time[on_grid], return_index=True)         # and the repeated impact times
    t, theta, theta_dot = (x[on_grid][first] for x in (res.time, res.theta, res.theta_dot))
    impacts, eta = rocking_accuracy(t, theta, theta_dot)
    return float(np.max(np.abs(eta - ETA_HOUSNER))), float(abs(impacts[-1] - res.impacts.time[N_IMPACTS - 1]))


def rocking_runs(summary: Summary) -> list[str]:
    """Part 1: accuracy and cost of free rocking over methods and time steps."""
    t_ref, summary.housner_cpu = housner_reference()
    rows = []
    for label, settings in METHODS.items():
        for dt in (DTS_QUICK if summary.quick else DTS):
            log(f"  rocking: {label}, dt = {dt:g}")
            scene, block = rocking_scene_2d()
            sim = nscd.Simulator(scene, dt, settings)
            wall, cpu, _ = timed_steps(sim, int(round(ROCK_T_END / dt)))
            res = sim.result()
            impacts, eta = rocking_accuracy(res.time, res.angle(block), res.omega(block))
            t5_error = abs(impacts[N_IMPACTS - 1] - t_ref[N_IMPACTS - 1]) if len(impacts) >= N_IMPACTS else math.nan
            rows.append({
                "method": label, "dt": dt, "steps": len(wall), "median_us": _median_us(wall),
                "wall_per_sim_s": float(wall.sum()) / ROCK_T_END, "cpu_per_sim_s": cpu / ROCK_T_END,
                "eta_min": float(np.min(eta)), "eta_max": float(np.max(eta)),
                "eta_error": float(np.max(np.abs(eta - ETA_HOUSNER))), "t5_error": t5_error,
                "unconverged": res.report.n_unconverged,
            })
    summary.rocking = rows
    header = ["method", "dt (s)", "steps", "median µs/step", "wall s / sim s", "CPU s / sim s",
              "eta range (impacts 1-5)", "max |eta - 0.850|", "|t5 - t5 Housner| (s)", "unconverged"]
    table = [[r["method"], f"{r['dt']:g}", r["steps"], f"{r['median_us']:.0f}", f"{r['wall_per_sim_s']:.3g}",
              f"{r['cpu_per_sim_s']:.3g}", f"{r['eta_min']:.4f}–{r['eta_max']:.4f}", f"{r['eta_error']:.1e}",
              f"{r['t5_error']:.1e}", r["unconverged"]] for r in rows]
    write_csv("rocking_accuracy.csv", list(rows[0]), [list(r.values()) for r in rows])
    summary.png = work_precision_chart(rows, summary.housner_cpu)
    return [
        "## 1. Free rocking: accuracy against cost", "",
        f"0.5 x 1.5 m block (alpha = {ALPHA:.4f} rad) released from rest at theta0 = alpha/2 on its corner, "
        f"fixed base, mu = 0.8, e = 0, {ROCK_T_END} s simulated. Restitution per impact from the rocking "
        f"amplitudes by energy, against Housner's 1 - 1.5 sin^2 alpha = {ETA_HOUSNER:.4f}; 5th impact time "
        f"against the 1-DOF Housner model (t5 = {t_ref[N_IMPACTS - 1]:.5f} s). 'localised': the step is split at "
        "the predicted impact (default); 'plain': textbook Moreau–Jean. Wall time includes result recording.",
        "", *markdown_table(header, table), "",
        "Measurement floor (the same impact/amplitude extraction applied to the exact 1-DOF history "
        "sampled at the same step): " + "; ".join(
            f"dt {dt:g}: eta {floor[0]:.0e}, t5 {floor[1]:.0e} s"
            for dt, floor in ((dt, measurement_floor(dt)) for dt in (DTS_QUICK if summary.quick else DTS))) + ".",
        "",
        f"The 1-DOF Housner model itself (closed-form flights, event times to 1e-15 s; its API has no "
        f"tolerance to trade) takes {summary.housner_cpu * 1e3:.1f} ms CPU for the same {ROCK_T_END} s.", "",
        f"![work-precision](./{summary.png.name})", "",
    ]


def work_precision_chart(rows: list[dict], housner_cpu: float) -> Path:
    """Error against CPU seconds per simulated second, log-log, one curve per method."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(12, 6), constrained_layout=True)
    for ax, key, label in ((axes[0], "eta_error", "max |eta - 0.850| over impacts 1-5"),
                           (axes[1], "t5_error", "|t5 - t5 (Housner 1-DOF)|, s")):
        for method in METHODS:
            pts = [r for r in rows if r["method"] == method and np.isfinite(r[key]) and r[key] > 0]
            if not pts:
                continue
            x = [r["cpu_per_sim_s"] for r in pts]
            ax.loglog(x, [r[key] for r in pts], "o-", label=method)
            for r, xi in zip(pts, x):
                ax.annotate(f"{r['dt']:g}", (xi, r[key]), textcoords="offset points", xytext=(4, 4), fontsize=7)
        ax.axvline(housner_cpu / ROCK_T_END, color="k", ls=":", lw=1,
                   label="1-DOF Housner model (event-driven, reference)")
        ax.set_xlabel("CPU s per simulated s (this machine, shared)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=3, fontsize=8)
    axes[0].set_title("Restitution error (labels: dt in s)")
    axes[1].set_title("5th impact time error (labels: dt in s)")
    return save_figure(fig, "work_precision.png")


# --------------------------------------------------------------------------- parts 2 and 3
def _max_drift(res, bodies) -> float:
    """Largest distance (m) any of ``bodies`` moved from its initial position."""
    return max(float(np.max(np.linalg.norm(res.position(b) - res.position(b)[0], axis=1))) for b in bodies)


def _time_scene(name: str, scene: nscd.Scene, n_steps: int, accuracy) -> dict:
    """Median per-step wall time of ``scene`` at DT, with contacts and an accuracy figure.

    ``accuracy(result) -> (label, value)`` says what was reached during the timed run.
    """
    sim = nscd.Simulator(scene, DT)
    wall, cpu, reports = timed_steps(sim, n_steps)
    res = sim.result()
    what, value = accuracy(res)
    return {
        "scene": name, "dim": scene.dim, "steps": n_steps, "median_us": _median_us(wall),
        "p90_us": float(np.percentile(wall, 90) * 1e6), "wall_per_sim_s": float(wall.sum()) / (n_steps * DT),
        "cpu_per_sim_s": cpu / (n_steps * DT),
        "contacts": float(np.mean([r.n_contacts for r in reports])),
        "active": float(np.mean([r.n_active for r in reports])),
        "iterations": float(np.mean([r.iterations for r in reports])),
        "accuracy": f"{what} {value:.1e}", "max_merit": res.report.max_merit,
    }


def _rest_accuracy(res):
    return "max drift (m)", _max_drift(res, [n for n, kind in zip(res.body_names, res.body_kinds) if kind == "dynamic"])


def _rocking_2d_accuracy(res, block, reference):
    return "|angle - Housner| at end (rad)", abs(abs(res.angle(block)[-1]) - abs(np.interp(res.time[-1], *reference)))


def _rocking_3d_accuracy(res, block, reference):
    w, x, y, z = res.orientation(block).T
    pitch = np.arctan2(2 * (x * z + w * y), 1 - 2 * (x * x + y * y))
    return "|pitch - Housner| at end (rad)", abs(abs(pitch[-1]) - abs(np.interp(res.time[-1], *reference)))


def step_timings(summary: Summary) -> list[str]:
    """Parts 2 and 3: per-step cost of 2D stacks and 3D scenes at rest or rocking."""
    n2d = 300 if summary.quick else 1000
    n3d = 100 if summary.quick else 200
    n_rock = 400  # 0.4 s: before the first impact (0.433 s), where the Housner angle is smooth
    housner = HousnerBlock(width=WIDTH, height=HEIGHT).simulate(None, t_end=0.5, theta0=THETA0, dt_out=1e-4)
    reference = (housner.time, np.abs(housner.theta))
    rock2d, block2d = rocking_scene_2d()
    rock3d, block3d = rocking_scene_3d()
    cases = [
        ("2D rocking block 0.5 x 1.5 (released at alpha/2)", rock2d, n_rock,
         lambda r: _rocking_2d_accuracy(r, block2d, reference)),
        ("2D block 0.4 x 0.3 at rest", stack_scene_2d(1), n2d, _rest_accuracy),
        ("2D 3-block stack at rest", stack_scene_2d(3), n2d, _rest_accuracy),
        ("2D 10-block stack at rest", stack_scene_2d(10), n2d, _rest_accuracy),
        ("3D rocking box 0.5 x 0.5 x 1.5", rock3d, n3d, lambda r: _rocking_3d_accuracy(r, block3d, reference)),
        ("3D LNEC stacked pair at rest", lnec.stacked_pair(), n3d, _rest_accuracy),
        ("3D LNEC trilith at rest", lnec.trilith(), n3d, _rest_accuracy),
    ]
    rows = []
    for name, scene, n_steps, accuracy in cases:
        log(f"  timing: {name}")
        rows.append(_time_scene(name, scene, n_steps, accuracy))
    summary.steps = rows
    keys = ["scene", "steps", "median_us", "p90_us", "wall_per_sim_s", "cpu_per_sim_s", "contacts", "active",
            "iterations", "accuracy", "max_merit"]
    write_csv("step_timings.csv", keys, [[r[k] for k in keys] for r in rows])
    header = ["scene", "steps", "median µs/step", "p90 µs/step", "wall s / sim s", "CPU s / sim s",
              "contacts/step", "active/step", "solver its/step", "accuracy reached", "max merit"]
    table = [[r["scene"], r["steps"], f"{r['median_us']:.0f}", f"{r['p90_us']:.0f}", f"{r['wall_per_sim_s']:.3g}",
              f"{r['cpu_per_sim_s']:.3g}", f"{r['contacts']:.1f}", f"{r['active']:.1f}", f"{r['iterations']:.2f}",
              r["accuracy"], f"{r['max_merit']:.1e}"] for r in rows]
    return ["## 2–3. Per-step cost (dt = 1e-3 s)", "",
            f"Median of the wall time of each `Simulator.step()` (result recording included); 2D runs "
            f"{n2d} steps, 3D runs {n3d} steps. Rocking rows: the first {n_rock * DT:g} s (2D) / {n3d * DT:g} s (3D) "
            "of the release of part 1 (no impact yet), accuracy against the 1-DOF Housner angle at the end.",
            "", *markdown_table(header, table), ""]


# --------------------------------------------------------------------------- part 4
def sliding_runs(summary: Summary) -> list[str]:
    """Part 4: stopping distance and lift-off of a sliding block, exact against relaxed cone."""
    distance = SLIDE_V0 ** 2 / (2 * SLIDE_MU * STANDARD_GRAVITY)
    t_end = 1.5 * SLIDE_V0 / (SLIDE_MU * STANDARD_GRAVITY)
    rows = []
    for coulomb in ("exact", "relaxed"):
        log(f"  sliding: {coulomb} cone")
        scene, block, settings = sliding_scene(coulomb)
        sim = nscd.Simulator(scene, DT, settings)
        wall, cpu, _ = timed_steps(sim, int(round(t_end / DT)))
        res = sim.result()
        pos = res.position(block)
        travelled = float(pos[-1, 0] - pos[0, 0])
        rows.append({"cone": coulomb, "distance": travelled, "error": abs(travelled - distance),
                     "lift": float(np.max(pos[:, 1] - pos[0, 1])), "median_us": _median_us(wall),
                     "unconverged": res.report.n_unconverged})
    summary.sliding = rows
    keys = ["cone", "distance", "error", "lift", "median_us", "unconverged"]
    write_csv("sliding.csv", keys, [[r[k] for k in keys] for r in rows])
    table = [[r["cone"], f"{r['distance']:.5f}", f"{r['error']:.1e}", f"{r['lift']:.1e}", f"{r['median_us']:.0f}",
              r["unconverged"]] for r in rows]
    return ["## 4. Sliding block: exact against relaxed Coulomb cone", "",
            f"0.4 x 0.2 m block launched at v0 = {SLIDE_V0} m/s on a fixed base, mu = {SLIDE_MU}, dt = {DT:g} s, "
            f"{t_end:.2f} s simulated; theory v0^2 / (2 mu g) = {distance:.5f} m (g = {STANDARD_GRAVITY}).", "",
            *markdown_table(["cone", "distance (m)", "|error| (m)", "max lift-off (m)", "median µs/step",
                             "unconverged"], table), ""]


# --------------------------------------------------------------------------- parts 3 and 5: profiles
def profile_step(scene: nscd.Scene, n_steps: int) -> tuple[dict, list, float]:
    """cProfile ``n_steps`` steps of ``scene`` at DT.

    Returns
    -------
    shares : dict
        Part (:data:`COMPILED`, :data:`GENERAL`, :data:`AROUND`) -> fraction of the
        profiled time.
    top : list of (str, float)
        The 12 functions with the largest own time and their fraction.
    calls : float
        Python-level function calls per step (builtins and numpy C functions included).
    """
    sim = nscd.Simulator(scene, DT)
    # the first steps outside the profile: imports, caches, and the one-time lookup of the compiled
    # step's specialisation once the same arguments repeat (when a process has compiled both 2D
    # and 3D steps, the first calls go through numba's dispatcher: compiled_step._RepeatedCall)
    for _ in range(20):
        sim.step()
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(n_steps):
        sim.step()
    profiler.disable()
    stats = pstats.Stats(profiler)
    total = stats.total_tt
    shares = {COMPILED: 0.0, GENERAL: 0.0}
    own = []
    for (filename, line, func), (_, _, tottime, cumtime, _) in stats.stats.items():
        part = _part_of(filename, line, func)
        if part is not None:
            # the compiled call is a leaf (own time); the general step holds its callees
            shares[part] += (tottime if part == COMPILED else cumtime) / total
        path = filename.replace("\\", "/")
        where = path.split("/nscd/")[-1] if "/nscd/" in path else Path(path).name
        own.append((f"{where}:{func}", tottime / total))
    shares[AROUND] = max(0.0, 1.0 - shares[COMPILED] - shares[GENERAL])
    own.sort(key=lambda item: -item[1])
    return shares, own[:12], stats.total_calls / n_steps


def profiles(summary: Summary) -> list[str]:
    """Parts 3 and 5: where the time of the 2D and 3D step goes."""
    n_steps = 300 if summary.quick else 1000
    log("  profile: 2D rocking block")
    summary.profile_2d, summary.top_2d, summary.calls_2d = profile_step(rocking_scene_2d()[0], n_steps)
    log("  profile: 3D trilith")
    summary.profile_3d, top_3d, calls_3d = profile_step(lnec.trilith(), n_steps // 5)
    lines = ["## 3 and 5. Profiles (cProfile, dt = 1e-3 s)", "",
             f"Share of the profiled step time per part of the step: 2D rocking block of part 1 ({n_steps} "
             f"steps), 3D LNEC trilith at rest ({n_steps // 5} steps). The compiled step is one call that "
             "cProfile cannot look into (its stages: `docs/time_step.md`); cProfile inflates the Python "
             "around it, so read the shares, not the times.", ""]
    lines += markdown_table(["part of the step", "2D single block", "3D trilith"],
                            [[label, f"{100 * summary.profile_2d[label]:.0f} %",
                              f"{100 * summary.profile_3d[label]:.0f} %"] for label in summary.profile_2d])
    lines += ["", f"Function calls per step: {summary.calls_2d:.0f} (2D single block), {calls_3d:.0f} (3D trilith).",
              "", "Top own-time functions:", ""]
    lines += markdown_table(["2D single block", "share", "3D trilith", "share"],
                            [[a, f"{100 * sa:.1f} %", b, f"{100 * sb:.1f} %"]
                             for (a, sa), (b, sb) in zip(summary.top_2d, top_3d)])
    write_csv("profile_stages.csv", ["part", "share_2d_single_block", "share_3d_trilith"],
              [[label, summary.profile_2d[label], summary.profile_3d[label]] for label in summary.profile_2d])
    return lines + [""]


# --------------------------------------------------------------------------- driver
def run(quick: bool = False) -> Summary:
    """Run the five parts, write ``benchmarks/results/engine.md`` and return the summary."""
    summary = Summary(quick=quick)
    lines = ["# Engine benchmark", "", *stamp_lines(), f"- mode: {'--quick' if quick else 'full'}", ""]
    for part in (rocking_runs, step_timings, sliding_runs, profiles):
        log(f"bench_engine: {part.__name__}")
        lines += part(summary)
    lines += ["Run stamp at the end:", "", *stamp_lines()]
    write_text("engine.md", lines)
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer time steps and shorter runs (~minutes)")
    args = parser.parse_args()
    run(quick=args.quick)
    print((RESULTS / "engine.md").read_text(encoding="utf-8"))


if __name__ == "__main__":
    main()
