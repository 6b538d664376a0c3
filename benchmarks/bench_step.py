"""Cost of one time step, side by side with MuJoCo in the same run, and the first-run compile time.

    python benchmarks/bench_step.py [--quick]

Writes ``benchmarks/results/step.md`` and ``step.csv``. Measured in one process, CPU time
(``time.process_time``, insensitive to other processes' load; the load average is in the
stamp):

* median CPU time of one step: a 2D block (0.5 x 1.5 m) at rest and rocking freely
  (released at alpha/2), MuJoCo's step of the same block as a 3D box rocking in its plane
  (``bench_peers.mujoco_run``'s model), the three-block stack of the double-pulse rig at
  rest, and the LNEC trilith in 3D at rest; all at dt = 1 ms and default settings; each
  taken two ways: one ``Simulator.step()`` call per step (the median call: the step and the
  Python and argument passing of a call) and the steps of ``Simulator.run`` (many steps per
  compiled call, as ``simulate``, spectra and maps take them: the median over blocks of
  ``RUN_CHUNK`` steps of the CPU time per step);
* the same call of the block at rest and rocking and MuJoCo's ``mj_step`` of its box, timed
  call by call in turn in ``ROUNDS`` alternated rounds, and nscd's over MuJoCo's per round
  (this machine's speed changes within a run: alternated, the three see the same changes);
* free rocking of the block for 2.5 s (5 impacts) with **default settings** at dt = 1e-2
  against MuJoCo at dt = 1e-4 (nscd's run once before, untimed, as its steps above are):
  CPU seconds of each, with the accuracy each reaches
  (largest restitution error against Housner's eta, error of the 5th impact time, by the
  measurement of ``bench_engine.rocking_accuracy``);
* wall time of the first run of the main job (``examples/single_block/free_rocking.py``)
  after a fresh install with an empty numba cache, and without the install's compiled store
  with an empty and a filled cache: their difference is the compilation the install saves
  (measured by ``bench_first_run.first_run``, which also lists what compiles).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

import nscd  # noqa: E402
from bench_first_run import AFTER, COLD, WARM, first_run  # noqa: E402
from bench_engine import ETA_HOUSNER, housner_reference, rocking_accuracy, rocking_scene_2d  # noqa: E402
from bench_peers import mujoco_block, mujoco_run  # noqa: E402
from common import log, markdown_table, stamp_lines, write_csv, write_text  # noqa: E402

DT = 1e-3
ROCK_T_END = 2.5
RUN_CHUNK = 100  # steps per timed call of Simulator.run
ROUNDS = 5  # alternated rounds of nscd's and MuJoCo's calls (alternated_calls)


def _median_call_us(step, n_steps: int) -> float:
    """Median CPU time (us) of a call of ``step()`` over ``n_steps`` calls."""
    times = np.empty(n_steps)
    for k in range(n_steps):
        start = time.process_time()
        step()
        times[k] = time.process_time() - start
    return float(np.median(times) * 1e6)


def alternated_calls(n_steps: int) -> list[tuple[float, float, float]]:
    """Per round of ``ROUNDS``: the median CPU time (us) of a ``Simulator.step()`` call of the
    2D block at rest, of one rocking, and of a call of MuJoCo's ``mj_step`` of the rocking box,
    ``n_steps // ROUNDS`` calls each, the three in turn in every round (so that a change of
    this machine's speed during the run affects them alike)."""
    at_rest, rocking = nscd.Simulator(_block_at_rest(), DT), nscd.Simulator(rocking_scene_2d()[0], DT)
    mujoco, model, data = mujoco_block(DT)

    def mujoco_step() -> None:
        mujoco.mj_step(model, data)
    for step in (at_rest.step, rocking.step, mujoco_step):  # first calls, warm starts
        for _ in range(20):
            step()
    calls = n_steps // ROUNDS
    return [tuple(_median_call_us(step, calls) for step in (at_rest.step, rocking.step, mujoco_step))
            for _ in range(ROUNDS)]


def _block_at_rest() -> nscd.Scene:
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1))
    scene.add_block(nscd.box(0.5, 1.5), position=(0.0, 0.75), density=2500.0)
    scene.set_contact(friction=0.8, restitution=0.0)
    return scene


def _median_run_step_us(sim, start_time: float, n_steps: int, chunk: int = RUN_CHUNK) -> float:
    """Median over chunks of ``chunk`` steps of the CPU time (us) per step of ``sim.run``
    (the steps of a run: many per compiled call, no Python between them), ``n_steps`` in all
    from the simulator's time ``start_time`` (s)."""
    times = np.empty(n_steps // chunk)
    for k in range(times.size):
        until = start_time + (k + 1) * chunk * DT
        start = time.process_time()
        sim.run(until=until)
        times[k] = (time.process_time() - start) / chunk
    return float(np.median(times) * 1e6)


def step_costs(n_steps: int) -> list[tuple[str, float, float]]:
    """(scene, median CPU us of one ``Simulator.step()`` call, median CPU us per step of
    ``Simulator.run``) of the scenes of the module docstring; MuJoCo's loop in both columns."""
    rows = []
    warm = 20  # steps before timing (first calls, warm starts)
    for name, scene in (("2D block at rest", _block_at_rest()), ("2D block rocking", rocking_scene_2d()[0]),
                        ("3-block stack at rest (nscd.stack(3, 0.4, 1.0))", nscd.stack(3, width=0.4, height=1.0)[0]),
                        ("LNEC trilith 3D at rest", nscd.lnec.trilith())):
        sim = nscd.Simulator(scene, DT)
        for _ in range(warm):
            sim.step()
        called = _median_call_us(sim.step, n_steps)
        sim = nscd.Simulator(scene, DT)  # the same steps again, taken by run
        for _ in range(warm):
            sim.step()
        rows.append((name, called, _median_run_step_us(sim, warm * DT, n_steps)))
        log(f"{name}: step() {rows[-1][1]:.0f} us, run {rows[-1][2]:.0f} us per step")
    mujoco = mujoco_run(DT, n_steps + warm)  # t, angle, omega, wall, cpu of the loop
    loop = mujoco[4] / (n_steps + warm) * 1e6
    rows.insert(2, ("MuJoCo 3D box rocking (mean of the loop)", loop, loop))
    return rows


def free_rocking() -> list[tuple[str, float, float, float, float]]:
    """(method, dt, CPU s, max restitution error, 5th impact time error s) of 2.5 s of free rocking."""
    reference, _ = housner_reference()
    rows = []
    scene, block = rocking_scene_2d()
    dt = 1e-2
    # a first run, not timed, as the steps above have theirs: it loads the kernels of the
    # impacts (event location, the general step) from numba's cache (tenths of a second, a
    # cost of the first run in a process, which the first-run measurement below covers)
    nscd.Simulator(scene, dt).run(until=ROCK_T_END)
    sim = nscd.Simulator(scene, dt)  # default settings
    start = time.process_time()
    sim.run(until=ROCK_T_END)
    cpu = time.process_time() - start
    res = sim.result()
    impacts, eta = rocking_accuracy(res.time, res.angle(block), res.omega(block))
    rows.append(("nscd, default settings", dt, cpu, float(np.max(np.abs(eta / ETA_HOUSNER - 1))),
                 float(abs(impacts[-1] - reference[len(impacts) - 1]))))
    dt = 1e-4
    t, angle, omega, _, cpu = mujoco_run(dt, int(round(ROCK_T_END / dt)))
    impacts, eta = rocking_accuracy(t, angle, omega)
    rows.append(("MuJoCo", dt, cpu, float(np.max(np.abs(eta / ETA_HOUSNER - 1))),
                 float(abs(impacts[-1] - reference[len(impacts) - 1]))))
    for row in rows:
        log(f"free rocking {row[0]} dt={row[1]:g}: {row[2]:.3f} CPU s, eta {100 * row[3]:.3f} %, "
            f"5th impact {1e3 * row[4]:.2f} ms")
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer steps, no first-run measurement")
    args = parser.parse_args()
    n_steps = 200 if args.quick else 1000
    lines = ["# Cost of one step (bench_step.py)", "", *stamp_lines(), ""]
    costs = step_costs(n_steps)
    lines += ["## Median CPU time of one step (dt = 1 ms, default settings)", "",
              "`Simulator.step()`: one Python call per step (the median call). `Simulator.run`: the steps of "
              f"a run, many per compiled call (the median over blocks of {RUN_CHUNK} steps of the CPU time per "
              "step), as `simulate`, spectra and maps take them. The same scenes and steps in both columns; "
              "MuJoCo's figure is the mean of its Python loop of `mj_step`.", "",
              *markdown_table(["scene", "us per Simulator.step() call", "us per step of Simulator.run"],
                              [(name, f"{called:.0f}", f"{run:.0f}") for name, called, run in costs]), ""]
    rounds = alternated_calls(n_steps)
    ratios = np.array([(rest / mj, rock / mj) for rest, rock, mj in rounds])
    log("alternated rounds (rest, rocking, MuJoCo us): " + "; ".join(" / ".join(f"{x:.0f}" for x in r)
                                                                   for r in rounds))
    lines += ["## One call against MuJoCo's, alternated", "",
              f"The block at rest, the block rocking and MuJoCo's box, {n_steps // ROUNDS} calls each in turn, "
              f"{ROUNDS} rounds (median CPU time of a call in each round, and nscd's over MuJoCo's in that round; "
              "MuJoCo's `mj_step` timed call by call as nscd's `Simulator.step()` is).", "",
              *markdown_table(["round", "2D block at rest (us)", "2D block rocking (us)", "MuJoCo box (us)",
                               "at rest / MuJoCo", "rocking / MuJoCo"],
                              [(k + 1, f"{rest:.0f}", f"{rock:.0f}", f"{mj:.1f}", f"{a:.1f}", f"{b:.1f}")
                               for k, ((rest, rock, mj), (a, b)) in enumerate(zip(rounds, ratios))]), "",
              f"Median over the rounds: at rest {np.median(ratios[:, 0]):.1f}x MuJoCo's call, rocking "
              f"{np.median(ratios[:, 1]):.1f}x (target: a 2D block's step at most about 6x MuJoCo's step of a "
              "3D box).", ""]
    rocking = free_rocking()
    lines += ["## Free rocking, 2.5 s (5 impacts)", "",
              *markdown_table(["method", "dt (s)", "CPU s", "restitution error", "5th impact time error"],
                              [(m, f"{dt:g}", f"{cpu:.3f}", f"{100 * e:.3f} %", f"{1e3 * ti:.2f} ms")
                               for m, dt, cpu, e, ti in rocking]),
              "", f"nscd / MuJoCo CPU time: {rocking[0][2] / rocking[1][2]:.2f}", ""]
    rows = [("step", name, called) for name, called, _ in costs] + \
        [("step of a run", name, run) for name, _, run in costs] + [("rocking", m, cpu) for m, _, cpu, _, _ in rocking]
    rows += [(f"alternated round {k + 1}", name, us) for k, r in enumerate(rounds)
             for name, us in zip(("2D block at rest", "2D block rocking", "MuJoCo box"), r)]
    if not args.quick:
        runs = first_run()
        cold, warm, after = runs[COLD]["wall"], runs[WARM]["wall"], runs[AFTER]["wall"]
        lines += ["## First run of the main job", "",
                  f"- after a fresh install (kernels compiled ahead of time), empty numba cache: {after:.1f} s wall",
                  f"- without the compiled store: empty numba cache {cold:.1f} s wall; cache filled: {warm:.1f} s "
                  f"wall (compilation: {cold - warm:.1f} s)", ""]
        rows += [("first run", "after the install", after), ("first run", "no store, empty cache", cold),
                 ("first run", "no store, cache filled", warm)]
    write_text("step.md", lines)
    write_csv("step.csv", ["part", "case", "value (us per step, CPU s or wall s)"], rows)


if __name__ == "__main__":
    main()
