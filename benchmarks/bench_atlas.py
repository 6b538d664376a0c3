"""Stability atlas: which integrator settings survive which scenario at which time step.

A grid of scenarios x time steps (1e-2, 3e-3, 1e-3, 3e-4 s) x methods (nscd default =
Moreau's midpoint rule with impact localisation; theta 0.5 with impact localisation;
plain Moreau–Jean; theta = 1; relaxed Coulomb cone; and the event-driven 1-DOF Housner
model where it applies). Each cell is marked

- **ok**: ran, every step converged, and the scenario's error measure is within its
  tolerance (see :data:`SCENARIOS`, column "inaccurate when");
- **inaccurate**: ran, but the error measure is beyond the tolerance, or some steps
  did not converge;
- **failed**: raised an exception or produced non-finite states (message recorded).

Writes ``benchmarks/results/atlas.md`` (table per scenario), ``atlas.csv`` and
``atlas.png`` (coloured grid).

Run: ``OPENBLAS_NUM_THREADS=1 .venv/bin/python benchmarks/bench_atlas.py [--quick]``
(or through ``benchmarks/run_all.py``). ``--quick`` keeps dt = 1e-2 and 3e-3 s only and runs
the 20-block tower for 2 s instead of 100 s. The cells run on two worker processes
(nothing here is timed).
"""
from __future__ import annotations

import argparse
import math
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

import nscd
from nscd.analysis import overturning_spectrum
from nscd.motion import STANDARD_GRAVITY, OneSine
from nscd.rocking import HousnerBlock, housner_eta
from nscd.solver import SolverSettings

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.bench_atlas
    from bench_engine import _crossings, _peak, stack_scene_2d
    from common import RESULTS, log, markdown_table, stamp_lines, write_csv, write_text, save_figure
except ImportError:  # pragma: no cover
    from benchmarks.bench_engine import _crossings, _peak, stack_scene_2d
    from benchmarks.common import RESULTS, log, markdown_table, stamp_lines, write_csv, write_text, save_figure

DTS = (1e-2, 3e-3, 1e-3, 3e-4)
DTS_QUICK = DTS[:2]
HOUSNER = "1-DOF Housner (event-driven)"
METHODS = {
    "nscd default (midpoint rule, localised)": nscd.Settings(),
    "theta 0.5 (localised)": nscd.Settings(scheme="theta"),
    "plain Moreau–Jean (theta 0.5)": nscd.Settings(scheme="theta", localize_impacts=False),
    "theta 1 (localised)": nscd.Settings(scheme="theta", theta=1.0),
    "relaxed cone (theta 0.5, localised)": nscd.Settings(scheme="theta", solver=SolverSettings(coulomb="relaxed")),
}
FRICTION = 0.8
#: Tower: simulated time (s), full and --quick.
TOWER_T, TOWER_T_QUICK = 100.0, 2.0
#: Tower: at most this many steps per cell (full mode), so dt = 3e-4 does not take hours.
TOWER_MAX_STEPS = 10_000
DRIFT_TOL = 1e-6                   # m
ETA_TOL = 0.01                     # relative restitution error
REST_TOL = 0.02                    # relative error of the time to rest
OMEGA_REST = 1e-3                  # rad/s: below this the block counts as at rest
SLIDE_V0, SLIDE_MU, SLIDE_TOL, LIFT_TOL = 5.0, 0.5, 0.01, 1e-3
THRESHOLD_WP_OVER_P, THRESHOLD_FACTORS, THRESHOLD_T = 3.0, (0.99, 1.01), 4.0


@dataclass(frozen=True)
class Cell:
    """Outcome of one scenario x method x dt: status, measured value (text), detail."""

    status: str        # "ok", "inaccurate", "failed" or "n/a"
    value: str
    detail: str = ""


# --------------------------------------------------------------------------- scenes
def trilith() -> nscd.Scene:
    """2D trilith: posts 0.2 x 1.0 m (density 2.7), lintel 1.2 x 0.3 m 1000 times heavier than a post."""
    post_mass = 0.2 * 1.0 * 2.7
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1))
    for x in (-0.4, 0.4):
        scene.add_block(nscd.box(0.2, 1.0), position=(x, 0.5), density=2.7)
    scene.add_block(nscd.box(1.2, 0.3), position=(0.0, 1.15), density=1000 * post_mass / (1.2 * 0.3))
    scene.set_contact(friction=FRICTION, restitution=0.0)
    return scene


# --------------------------------------------------------------------------- measures
class MeasureError(RuntimeError):
    """The run finished but its history does not show what the measure needs (an inaccurate cell)."""


def _check(res) -> None:
    """Raise if the run stopped early or produced non-finite states."""
    if res.status != "finished":
        raise RuntimeError(f"status {res.status}: {res.message}")
    if not np.all(np.isfinite(res.q)):
        raise RuntimeError("non-finite positions")


def _judge(bad: bool, value: str, res=None, detail: str = "") -> Cell:
    unconverged = res.report.n_unconverged if res is not None else 0
    if unconverged:
        detail = f"{unconverged} unconverged steps; {detail}".rstrip("; ")
    return Cell("inaccurate" if bad or unconverged else "ok", value, detail)


def _dynamic(res) -> list:
    return [n for n, kind in zip(res.body_names, res.body_kinds) if kind == "dynamic"]


def _drift_cell(res) -> Cell:
    drift = max(float(np.max(np.linalg.norm(res.position(b) - res.position(b)[0], axis=1))) for b in _dynamic(res))
    return _judge(drift > DRIFT_TOL, f"{drift:.1e} m", res)


def _restitutions(t, angle, omega, alpha: float, theta0: float, n: int) -> np.ndarray:
    """Velocity ratios of the first ``n`` impacts from the rocking amplitudes (as in bench_engine)."""
    impacts = _crossings(t, angle, omega)[:n + 1]
    if len(impacts) < n + 1:
        raise MeasureError(f"only {len(impacts)} zero crossings, {n + 1} needed")
    peaks = np.array([theta0, *(_peak(t, angle, impacts[k], impacts[k + 1]) for k in range(n))])
    energy = np.cos(alpha - np.abs(peaks)) - math.cos(alpha)
    return np.sqrt(energy[1:] / energy[:-1])


# --------------------------------------------------------------------------- scenarios
@dataclass(frozen=True)
class Scenario:
    """A row block of the atlas.

    ``nscd(settings, dt, quick) -> Cell`` runs the engine; ``housner(dt) -> Cell`` the
    1-DOF model (None where it does not apply).
    """

    name: str
    what: str
    criterion: str
    nscd: Callable
    housner: Callable | None = None


def _rest_reference() -> tuple[float, int]:
    """Time to rest (s, last impact) and impact count of the 1-DOF model of the rocking-to-rest case."""
    res = HousnerBlock(width=0.5, height=1.5).simulate(None, t_end=20.0, theta0=-math.atan2(0.25, 0.75) / 2)
    if res.theta[-1] != 0.0 or res.theta_dot[-1] != 0.0:
        raise RuntimeError(f"1-DOF model not at rest at 20 s: theta {res.theta[-1]:.1e} rad")
    return float(res.impacts.time[-1]), len(res.impacts)


def rest_nscd(settings, dt, quick) -> Cell:
    t_ref, _ = _rest_reference()
    scene, block = nscd.tilted_block(0.5, 1.5, math.atan2(0.25, 0.75) / 2, friction=FRICTION)
    res = nscd.simulate(scene, t_ref + 1.0, dt, settings=settings)
    _check(res)
    moving = np.flatnonzero(np.abs(res.omega(block)) > OMEGA_REST)
    if len(moving) and moving[-1] == len(res.time) - 1:
        return Cell("failed", "no rest", f"still rocking at the end ({res.time[-1]:.2f} s; |omega| > {OMEGA_REST} rad/s)")
    t_rest = float(res.time[moving[-1] + 1]) if len(moving) else 0.0
    final = abs(float(res.angle(block)[-1]))
    error = abs(t_rest - t_ref) / t_ref
    return _judge(error > REST_TOL or final > 1e-4, f"{100 * error:.1f} %", res,
                  f"rest at {t_rest:.3f} s, final angle {final:.1e} rad")


def rest_housner(dt) -> Cell:
    t_ref, n = _rest_reference()
    return Cell("ok", f"rest {t_ref:.3f} s", f"{n} impacts, theta = theta_dot = 0 exactly after")


def trilith_nscd(settings, dt, quick) -> Cell:
    res = nscd.simulate(trilith(), 2.0, dt, settings=settings)
    _check(res)
    return _drift_cell(res)


def tower_time(dt: float, quick: bool) -> float:
    """Simulated time (s) of the tower cell: TOWER_T, capped at TOWER_MAX_STEPS steps; 2 s with --quick."""
    return TOWER_T_QUICK if quick else min(TOWER_T, TOWER_MAX_STEPS * dt)


def tower_nscd(settings, dt, quick) -> Cell:
    t_end = tower_time(dt, quick)
    res = nscd.simulate(stack_scene_2d(20), t_end, dt, settings=settings)
    _check(res)
    cell = _drift_cell(res)
    return Cell(cell.status, cell.value, f"{t_end:g} s simulated; {cell.detail}".rstrip("; "))


def sliding_nscd(settings, dt, quick) -> Cell:
    distance = SLIDE_V0 ** 2 / (2 * SLIDE_MU * STANDARD_GRAVITY)
    scene = nscd.Scene()
    scene.add_base(nscd.box(8.0, 0.2), position=(0.0, -0.1))
    block = scene.add_block(nscd.box(0.4, 0.2), position=(-3.5, 0.1), velocity=(SLIDE_V0, 0.0), density=2500.0)
    scene.set_contact(friction=SLIDE_MU, restitution=0.0)
    res = nscd.simulate(scene, 1.3 * SLIDE_V0 / (SLIDE_MU * STANDARD_GRAVITY), dt, settings=settings)
    _check(res)
    pos = res.position(block)
    error = abs(float(pos[-1, 0] - pos[0, 0]) - distance) / distance
    lift = float(np.max(pos[:, 1] - pos[0, 1]))
    return _judge(error > SLIDE_TOL or lift > LIFT_TOL, f"{100 * error:.2g} %", res, f"lift-off {lift:.1e} m")


def _free_rocking(alpha: float, n_impacts: int, t_end: float):
    """(nscd runner, Housner runner) of a block of slenderness ``alpha`` released at alpha/2."""
    height = 1.5
    width = height * math.tan(alpha)
    eta = housner_eta(alpha)

    def measure(t, angle, omega) -> tuple[float, str]:
        etas = _restitutions(t, angle, omega, alpha, alpha / 2, n_impacts)
        error = float(np.max(np.abs(etas - eta))) / eta
        return error, f"{100 * error:.2g} %"

    def run_nscd(settings, dt, quick) -> Cell:
        scene, block = nscd.tilted_block(width, height, alpha / 2, friction=FRICTION)
        res = nscd.simulate(scene, t_end, dt, settings=settings)
        _check(res)
        angle, omega = res.angle(block), res.omega(block)
        try:
            error, text = measure(res.time, angle, omega)
        except MeasureError as exc:
            raise MeasureError(f"{exc}; at {t_end:g} s angle {angle[-1]:.2e} rad, omega {omega[-1]:.1e} rad/s "
                               f"(release {-alpha / 2:.2e} rad)") from None
        return _judge(error > ETA_TOL, text, res)

    def run_housner(dt) -> Cell:
        res = HousnerBlock(width=width, height=height).simulate(None, t_end=t_end, theta0=-alpha / 2, dt_out=dt)
        on_grid = np.abs(res.time / dt - np.round(res.time / dt)) < 1e-9   # as sampled at dt (no event samples)
        _, first = np.unique(res.time[on_grid], return_index=True)
        error, text = measure(*(x[on_grid][first] for x in (res.time, res.theta, res.theta_dot)))
        return _judge(error > ETA_TOL, text, None, "measurement on the exact history sampled at dt")

    return run_nscd, run_housner


def _threshold_setup() -> tuple[HousnerBlock, float, float]:
    """Block, pulse circular frequency (rad/s) and 1-DOF minimum overturning amplitude (m/s^2)."""
    block = HousnerBlock(width=0.5, height=1.5)
    spectrum = overturning_spectrum(block, "one-sine", [THRESHOLD_WP_OVER_P], amplitude_max=8.0, n_scan=41,
                                    rtol=1e-5, executor=None)
    low, high = spectrum.overturn_intervals(0)[0]
    if high < 1.02 * low:
        raise RuntimeError(f"first overturn interval [{low}, {high}] alpha g narrower than 2 %")
    alpha = math.atan2(0.25, 0.75)
    return block, THRESHOLD_WP_OVER_P * block.p, low * alpha * STANDARD_GRAVITY


def _threshold_cell(overturned: list[bool], res=None) -> Cell:
    text = ", ".join(f"{f:g}: {'falls' if o else 'stands'}" for f, o in zip(THRESHOLD_FACTORS, overturned))
    return _judge(overturned != [False, True], text, res)


def threshold_nscd(settings, dt, quick) -> Cell:
    _, omega, amplitude = _threshold_setup()
    outcomes, unconverged, last = [], 0, None
    for factor in THRESHOLD_FACTORS:
        scene = nscd.Scene()
        scene.add_base(nscd.box(6.0, 0.2), position=(0.0, -0.1), motion=OneSine(factor * amplitude, omega))
        block = scene.add_block(nscd.box(0.5, 1.5), position=(0.0, 0.75), density=2500.0)
        scene.set_contact(friction=FRICTION, restitution=0.0)
        last = nscd.simulate(scene, THRESHOLD_T, dt, settings=settings)
        _check(last)
        unconverged += last.report.n_unconverged
        outcomes.append(last.overturned(block))
    cell = _threshold_cell(outcomes)
    detail = f"{unconverged} unconverged steps" if unconverged else ""
    return Cell("inaccurate" if cell.status != "ok" or unconverged else "ok", cell.value, detail)


def threshold_housner(dt) -> Cell:
    block, omega, amplitude = _threshold_setup()
    outcomes = [block.simulate(OneSine(f * amplitude, omega), t_end=THRESHOLD_T, stop_when_decided=True).overturned
                for f in THRESHOLD_FACTORS]
    return _threshold_cell(outcomes)


_SLENDER = _free_rocking(0.05, 5, 5.0)
_SQUAT = _free_rocking(0.7, 2, 1.5)

SCENARIOS = (
    Scenario("rocking to rest", "0.5 x 1.5 m block released at alpha/2, free rocking until rest (Zeno sequence of "
             "impacts); value: |time to rest - 1-DOF| / 1-DOF (rest: |omega| < 1e-3 rad/s for good)",
             f"error > {100 * REST_TOL:g} % or final |angle| > 1e-4 rad", rest_nscd, rest_housner),
    Scenario("trilith, lintel 1000x a post", "posts 0.2 x 1.0 m (density 2.7), lintel 1.2 x 0.3 m of 1000x a "
             "post's mass, at rest 2 s; value: max drift of any block", f"drift > {DRIFT_TOL:g} m", trilith_nscd),
    Scenario("20-block tower at rest", "20 blocks 0.4 x 0.3 m stacked, at rest; value: max drift of any block",
             f"drift > {DRIFT_TOL:g} m", tower_nscd),
    Scenario("sliding at 5 m/s", f"0.4 x 0.2 m block launched at {SLIDE_V0:g} m/s, mu = {SLIDE_MU}; value: "
             "|stopping distance - v0^2/(2 mu g)| / v0^2/(2 mu g)",
             f"error > {100 * SLIDE_TOL:g} % or lift-off > {LIFT_TOL:g} m", sliding_nscd),
    Scenario("slender block, alpha = 0.05", "1.5 m tall, free rocking from alpha/2; value: max relative "
             "restitution error over 5 impacts (Housner 1 - 1.5 sin^2 alpha = 0.996)",
             f"error > {100 * ETA_TOL:g} %", *_SLENDER),
    Scenario("squat block, alpha = 0.7", "1.5 m tall, free rocking from alpha/2; value: max relative "
             "restitution error over 2 impacts (Housner eta = 0.378; the 3rd and 4th impacts are 0.036 s apart, too close for the amplitude measure)", f"error > {100 * ETA_TOL:g} %", *_SQUAT),
    Scenario("overturning threshold", f"0.5 x 1.5 m block, one-sine pulse at wp/p = {THRESHOLD_WP_OVER_P:g}, "
             "amplitude 0.99 and 1.01 x the 1-DOF minimum overturning amplitude (nscd.analysis."
             f"overturning_spectrum, rtol 1e-5), {THRESHOLD_T:g} s; value: outcome per factor",
             "0.99 does not stand or 1.01 does not fall", threshold_nscd, threshold_housner),
)


# --------------------------------------------------------------------------- driver
def run_cell(scenario_index: int, method: str, dt: float, quick: bool) -> Cell:
    """One cell of the atlas; any exception becomes a "failed" cell with its message."""
    scenario = SCENARIOS[scenario_index]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")   # unconverged steps are counted from the report instead
            if method == HOUSNER:
                return scenario.housner(dt) if scenario.housner else Cell("n/a", "—")
            return scenario.nscd(METHODS[method], dt, quick)
    except MeasureError as exc:
        return Cell("inaccurate", "not measurable", str(exc))
    except Exception as exc:  # noqa: BLE001 - a failed cell is a result of the atlas
        return Cell("failed", type(exc).__name__, str(exc)[:160])


COLOURS = {"ok": "#4caf50", "inaccurate": "#ffb300", "failed": "#e53935", "n/a": "#d0d0d0"}


def chart(cells: dict, dts: tuple, methods: list) -> Path:
    """Coloured grid: one row per scenario x method, one column per dt, the value written in."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch, Rectangle

    rows = [(i, m) for i in range(len(SCENARIOS)) for m in methods]
    fig, ax = plt.subplots(figsize=(4 + 2.1 * len(dts), 0.32 * len(rows) + 1.6), constrained_layout=True)
    for r, (i, m) in enumerate(rows):
        for c, dt in enumerate(dts):
            cell = cells[i, m, dt]
            ax.add_patch(Rectangle((c, r), 1, 1, facecolor=COLOURS[cell.status], edgecolor="white"))
            ax.text(c + 0.5, r + 0.5, cell.value, ha="center", va="center", fontsize=6.5)
        if m == methods[0]:
            ax.axhline(r, color="k", lw=1.2)
    ax.set_xlim(0, len(dts))
    ax.set_ylim(len(rows), 0)
    ax.set_xticks(np.arange(len(dts)) + 0.5, [f"dt = {dt:g} s" for dt in dts])
    ax.xaxis.tick_top()
    ax.set_yticks(np.arange(len(rows)) + 0.5, [f"{SCENARIOS[i].name} | {m}" for i, m in rows], fontsize=7)
    fig.legend(handles=[Patch(color=c, label=s) for s, c in COLOURS.items()], loc="outside lower center", ncol=4)
    return save_figure(fig, "atlas.png")


def run(quick: bool = False, workers: int = 2) -> list[str]:
    """Run the atlas, write ``atlas.md``, ``atlas.csv``, ``atlas.png``; return the Markdown lines."""
    dts = DTS_QUICK if quick else DTS
    methods = [*METHODS, HOUSNER]
    keys = [(i, m, dt) for i in range(len(SCENARIOS)) for m in methods for dt in dts]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {key: pool.submit(run_cell, *key, quick) for key in keys}
        cells = {}
        for key, future in futures.items():
            cells[key] = future.result()
            log(f"  atlas: {SCENARIOS[key[0]].name} | {key[1]} | dt {key[2]:g}: {cells[key].status} {cells[key].value}")
    write_csv("atlas.csv", ["scenario", "method", "dt", "status", "value", "detail"],
              [[SCENARIOS[i].name, m, dt, c.status, c.value, c.detail] for (i, m, dt), c in cells.items()])
    png = chart(cells, dts, methods)
    tower = (f"{TOWER_T_QUICK:g} s (--quick; not the 100 s of the full run)" if quick else
             "100 s where that is at most " + f"{TOWER_MAX_STEPS} steps, else {TOWER_MAX_STEPS} steps: " +
             ", ".join(f"{tower_time(dt, quick):g} s at dt {dt:g}" for dt in dts))
    lines = ["# Stability atlas", "", *stamp_lines(), f"- mode: {'--quick' if quick else 'full'}", "",
             "Cells: **ok** (ran, all steps converged, error within the tolerance), **inaccurate** (error beyond "
             "the tolerance, or unconverged steps), **failed** (exception or non-finite state; message given), "
             "n/a (the 1-DOF model does not apply). Contact: e = 0, mu = 0.8 unless said. The 1-DOF Housner model "
             "is event-driven: dt only sets its output sampling, from which the same measure is taken.",
             f"Tower duration: {tower}.", "", f"![atlas](./{png.name})", ""]
    summary = []
    for i, scenario in enumerate(SCENARIOS):
        lines += [f"## {scenario.name}", "", f"{scenario.what}. **Inaccurate when** {scenario.criterion}.", ""]
        rows = []
        for m in methods:
            row = [m]
            for dt in dts:
                c = cells[i, m, dt]
                row.append(f"{c.status}: {c.value}" + (f" ({c.detail})" if c.detail else ""))
            rows.append(row)
        lines += [*markdown_table(["method", *[f"dt = {dt:g} s" for dt in dts]], rows), ""]
        summary.append([scenario.name, *[" / ".join(cells[i, m, dt].status for dt in dts) for m in methods]])
    lines[lines.index(f"![atlas](./{png.name})") + 2:lines.index(f"![atlas](./{png.name})") + 2] = [
        "## Summary (status per dt, largest dt first)", "", *markdown_table(["scenario", *methods], summary), ""]
    write_text("atlas.md", lines)
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="dt = 1e-2 and 3e-3 s only, 2 s tower")
    args = parser.parse_args()
    run(quick=args.quick)
    print((RESULTS / "atlas.md").read_text(encoding="utf-8"))


if __name__ == "__main__":
    main()
