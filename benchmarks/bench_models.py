"""The model choice against the engine: same outcome, how much faster.

    OPENBLAS_NUM_THREADS=1 python benchmarks/bench_models.py

Writes ``benchmarks/results/models.md`` (+ ``models.csv``). Each case runs
``nscd.simulate(scene, t_end, dt, model="auto")`` (the model :func:`nscd.choose_model`
picks, its assumption checks included) and the 2D engine on the same scene
(``model="2d"``, Moreau's midpoint rule at ``DT``), and compares the outcome
(overturned or not; the peak rotation of each block; the stacked pattern) and the wall
times. Cases:

* single blocks (the README's 0.5 x 1.5 m block, friction 0.8): free rocking from a tilt;
  one-sine pulses at 0.99 and 1.01 x the 1-DOF model's own overturning amplitude
  (wp/p = 4, found by bisection on ``nscd.rocking``: the engine must land on the same side);
  LNEC specimen 2 in three harmonic cells of 003 Table 4 (the scene of
  ``bench_lnec_table4.py``); El Centro 1940 N-S scaled to PGA 0.5 g;
* the LNEC stacked pair in the plane (``nscd.lnec.stacked_pair_2d``, friction 2: no sliding)
  in three constant-sine cells of 003 Table 5.

Wall and process CPU times after one untimed warm-up run of each model: the engine's a single
run, the reduced model's the median of three (a run of tens of milliseconds is at the mercy of
the other processes of a shared machine); the stamp gives the load.
"""
from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import nscd  # noqa: E402
from nscd import lnec  # noqa: E402
from nscd.motion import Harmonic, OneSine  # noqa: E402
from nscd.rocking import HousnerBlock  # noqa: E402
from nscd.stacked import classify_patterns, dominant_pattern  # noqa: E402

from common import log, markdown_table, stamp_lines, write_csv, write_text  # noqa: E402
import bench_lnec_table4 as table4  # noqa: E402

#: Engine time step, s (midpoint rule: impacts within ~0.1 ms of the Housner model at this step, README).
DT = 1e-3
WIDTH, HEIGHT, DENSITY, FRICTION = 0.5, 1.5, 2500.0, 0.8


def block_scene(motion=None, angle=0.0) -> nscd.Scene:
    """The README's block on a 3 m base, optionally released from a tilt (rad) on its corner."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), motion=motion, name="base")
    b, h = WIDTH / 2, HEIGHT / 2
    k = 1.0 if angle >= 0 else -1.0
    c, s = math.cos(angle), math.sin(angle)
    x = -k * b + c * k * b - s * h
    y = s * k * b + c * h
    scene.add_block(nscd.box(WIDTH, HEIGHT), position=(x, y), angle=angle, density=DENSITY, name="block")
    scene.set_contact(friction=FRICTION, restitution=0.0)
    return scene


def overturning_amplitude(block: HousnerBlock, omega: float) -> float:
    """Smallest one-sine amplitude (m/s^2) that overturns the 1-DOF block, by bisection to 1e-6 relative."""
    lo, hi = block.onset_acceleration, 20.0 * block.onset_acceleration
    if not block.simulate(OneSine(hi, omega=omega), 20.0, stop_when_decided=True).overturned:
        raise RuntimeError("no overturning below 20 g tan(alpha)")
    # the first overturning amplitude above the onset (mode 1 / mode 2 boundary below the safe band)
    amps = np.linspace(lo, hi, 200)
    first = next(a for a in amps if block.simulate(OneSine(a, omega=omega), 20.0,
                                                   stop_when_decided=True).overturned)
    lo, hi = first - (amps[1] - amps[0]), first
    while hi - lo > 1e-6 * hi:
        mid = 0.5 * (lo + hi)
        if block.simulate(OneSine(mid, omega=omega), 20.0, stop_when_decided=True).overturned:
            hi = mid
        else:
            lo = mid
    return hi


def timed(func, repeats: int = 1):
    """(value, median wall time in s, median process CPU time in s) over ``repeats`` runs."""
    walls, cpus = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        value = func()
        walls.append(time.perf_counter() - start)
        cpus.append(time.process_time() - start_cpu)
    return value, float(np.median(walls)), float(np.median(cpus))


def compare(name: str, scene: nscd.Scene, t_end: float, blocks: list[str]) -> dict:
    t_end = round(t_end / DT) * DT  # a whole number of engine steps
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reduced, t_reduced, cpu_reduced = timed(lambda: nscd.simulate(scene, t_end, DT, model="auto"), repeats=3)
    engine, t_engine, cpu_engine = timed(lambda: nscd.simulate(scene, t_end, DT, model="2d",
                                                               settings=nscd.Settings(scheme="midpoint")))
    row = {"case": name, "model": reduced.model, "t_end": t_end,
           "violations": "; ".join(c.name for c in reduced.violations) or "none",
           "reduced_s": t_reduced, "engine_s": t_engine, "speedup": t_engine / t_reduced,
           "reduced_cpu_s": cpu_reduced, "engine_cpu_s": cpu_engine, "speedup_cpu": cpu_engine / cpu_reduced}
    same = True
    for body in blocks:
        peaks = [math.degrees(float(np.max(np.abs(r.angle(body))))) for r in (reduced, engine)]
        over = [r.overturned(body) for r in (reduced, engine)]
        row[f"{body}_deg"] = tuple(peaks)
        row[f"{body}_overturned"] = tuple(over)
        same = same and over[0] == over[1]
    if len(blocks) == 2:
        row["pattern"] = tuple(dominant_pattern(classify_patterns(r.time, r.angle(blocks[0]), r.angle(blocks[1])))
                               for r in (reduced, engine))
        same = same and row["pattern"][0] == row["pattern"][1]
    row["same_outcome"] = same
    log(f"{name}: {row}")
    return row


def warm_up() -> None:
    """One untimed run of each model: imports, numba kernels and caches are not counted."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for scene in (block_scene(OneSine(4.0, omega=6.1)),
                      lnec.stacked_pair_2d(Harmonic.from_displacement(0.002, frequency=6.5, cycles=2), friction=2.0)):
            for model in ("auto", "2d"):
                nscd.simulate(scene, 0.3, DT, model=model, settings=nscd.Settings(scheme="midpoint"))


def cases() -> list[dict]:
    warm_up()
    rows = []
    housner = HousnerBlock(WIDTH, HEIGHT)
    rows.append(compare("free rocking from 0.6 alpha", block_scene(angle=0.6 * housner.alpha), 4.0, ["block"]))
    omega = 4.0 * housner.p
    a_star = overturning_amplitude(housner, omega)
    for factor in (0.99, 1.01):
        rows.append(compare(f"one-sine wp/p = 4 at {factor} x overturning ({a_star:.4f} m/s^2)",
                            block_scene(OneSine(factor * a_star, omega=omega)), 6.0, ["block"]))
    for frequency, amplitude in ((3.3, 6), (2.5, 10), (2.0, 12)):
        shake = table4.motion(frequency, amplitude)
        rows.append(compare(f"LNEC #2 {frequency} Hz {amplitude} mm", table4.scene(shake),
                            table4.CYCLES / frequency + table4.FREE_TIME, ["block"]))
    record = nscd.motion.elcentro().scaled_to_pga(0.5, "g")
    rows.append(compare("El Centro N-S at PGA 0.5 g", block_scene(record), record.duration + 2.0, ["block"]))
    for frequency, amplitude in ((6.5, 2.0), (4.0, 4.0), (5.0, 2.0)):
        shake = Harmonic.from_displacement(amplitude * 1e-3, frequency=frequency, cycles=10, ramp_cycles=1)
        rows.append(compare(f"LNEC stacked {frequency} Hz {amplitude} mm", lnec.stacked_pair_2d(shake, friction=2.0),
                            10 / frequency + 2.0, ["bottom", "top"]))
    return rows


def report(rows: list[dict]) -> list[str]:
    table = []
    for r in rows:
        peaks = "; ".join(f"{b}: {r[f'{b}_deg'][0]:.3f} / {r[f'{b}_deg'][1]:.3f}"
                          + (" (over)" if any(r[f"{b}_overturned"]) else "")
                          for b in ("block", "bottom", "top") if f"{b}_deg" in r)
        table.append([r["case"], r["model"], peaks, " / ".join(r.get("pattern", ("", ""))) or "-",
                      "yes" if r["same_outcome"] else "NO", r["violations"],
                      f"{r['reduced_s']:.3f}", f"{r['engine_s']:.2f}", f"{r['speedup']:.0f}x",
                      f"{r['speedup_cpu']:.0f}x ({r['reduced_cpu_s']:.3f} / {r['engine_cpu_s']:.2f})"])
    return [
        "# Model choice: reduced model (model='auto') against the 2D engine", "", *stamp_lines(), "",
        f"Engine: Moreau's midpoint rule, dt = {DT:g} s, one run. Reduced: the model `nscd.choose_model` picks, "
        "event-driven (compiled DOP853, rtol 1e-9..1e-10), its choice and assumption checks included in its time, "
        "median of three runs. Peak rotation in deg, reduced / engine; outcome = overturned or not for every block "
        "(and the dominant pattern for the stack). Times are wall-clock; the last column gives the speed-up in "
        "process CPU time (reduced / engine CPU s in parentheses), the figure least affected by other jobs on a "
        "shared machine.",
        "",
        *markdown_table(["case", "model", "peak rotation (deg) reduced / engine", "pattern reduced / engine",
                         "same outcome", "violated checks", "reduced (s)", "engine (s)", "speed-up",
                         "speed-up in CPU time"], table),
        "",
    ]


def main() -> None:
    rows = cases()
    keys = ["case", "model", "same_outcome", "reduced_s", "engine_s", "speedup", "reduced_cpu_s", "engine_cpu_s",
            "speedup_cpu", "violations"]
    write_csv("models.csv", keys + ["peaks_deg"],
              [[r[k] for k in keys] + [str({b: r[f"{b}_deg"] for b in ("block", "bottom", "top") if f"{b}_deg" in r})]
               for r in rows])
    path = write_text("models.md", report(rows))
    print(path.read_text())


if __name__ == "__main__":
    main()
