"""Regenerate every benchmark table and figure, and the summary ``BENCHMARKS.md``.

Run from the repository root::

    .venv/bin/python benchmarks/run_all.py            # full (tens of minutes on a shared 2-core machine)
    .venv/bin/python benchmarks/run_all.py --quick    # a few minutes: fewer time steps, shorter runs

Runs, one after the other (never in parallel: they time themselves):

- ``benchmarks/bench_engine.py`` (in process): engine step cost beside its accuracy,
  ``benchmarks/results/engine.md``, CSV tables, ``work_precision.png``;
- ``benchmarks/bench_fclib.py``: contact solver on the FCLIB problems, ``results/fclib.md``;
- ``benchmarks/bench_rocking.py`` when present: 1-DOF model spectra and curves
  (passed ``--quick`` if it accepts it), printed table saved to ``results/rocking_toolkit.md``;
- ``benchmarks/bench_atlas.py``: stability atlas (scenarios x dt x methods),
  ``results/atlas.md``, ``atlas.png``;
- ``benchmarks/bench_peers.py``: free rocking in MuJoCo and PyBullet beside nscd,
  ``results/peers.md``, ``peers_work_precision.png``;
- ``benchmarks/bench_scaling.py`` when present;
- ``benchmarks/bench_collapse_3d.py``: the 97-block wall in 3D against 2D, ``results/collapse_3d.md``;
- ``benchmarks/bench_midsize.py``: scenes of a few dozen bodies (arches, a tall stack, a small wall),
  compiled steps against the general step, MuJoCo beside for the wall, ``results/midsize.md``;
- ``benchmarks/bench_models.py``: the model choice (Housner, stacked) against the 2D engine, ``results/models.md``;
- ``benchmarks/bench_step.py``: one step beside MuJoCo's in the same run, free rocking at
  default settings against MuJoCo at dt = 1e-4, first-run compile time, ``results/step.md``;
- ``benchmarks/bench_first_run.py``: the main job's first run after a fresh install from an empty
  numba cache, and without the install's compiled store, wall and CPU, and the kernels it
  compiles, ``results/first_run.md``;
- ``benchmarks/bench_maps.py``, ``bench_lnec_table4.py``, ``bench_double_pulse.py``,
  ``bench_lnec_stacked.py``: double-pulse map cost, and the comparisons with the experiments of
  002 and 003 (summarised in the "Experiments" section; ``--experiments-only`` rewrites just that
  section from the results files);

then writes ``BENCHMARKS.md`` at the repository root from the measured numbers.
BLAS is limited to one thread (``OPENBLAS_NUM_THREADS=1`` and friends) for all of
them: the engine's dense kernels are tiny and extra threads only contend.
"""
from __future__ import annotations

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # before numpy is imported, here and in the subprocesses

import argparse  # noqa: E402
import csv  # noqa: E402
import math  # noqa: E402
import re  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from collections.abc import Callable  # noqa: E402
from pathlib import Path  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_engine  # noqa: E402
from common import ROOT, RESULTS, log, markdown_table, stamp, stamp_lines, write_text  # noqa: E402

OUT = ROOT / "BENCHMARKS.md"


#: The other benchmark scripts -> results file where their printed output is saved
#: (None: the script writes its own file).
SCRIPTS = {"bench_fclib.py": None, "bench_rocking.py": "rocking_toolkit.md", "bench_atlas.py": None,
           "bench_peers.py": None, "bench_scaling.py": None, "bench_maps.py": None,
           "bench_collapse_3d.py": None, "bench_models.py": None, "bench_step.py": None, "bench_first_run.py": None,
           "bench_lnec_table4.py": None, "bench_double_pulse.py": None, "bench_lnec_stacked.py": None,
           "bench_midsize.py": None}


def run_script(name: str, quick: bool, capture: str | None) -> tuple[str, float]:
    """Run ``benchmarks/<name>`` with this interpreter; return its status text and wall seconds.

    With ``capture``, its standard output is saved to ``benchmarks/results/<capture>``
    under a run stamp.
    """
    path = HERE / name
    if not path.exists():
        return "not present, skipped", 0.0
    args = [sys.executable, str(path)]
    if quick and "--quick" in path.read_text(encoding="utf-8"):
        args.append("--quick")
    start = time.perf_counter()
    done = subprocess.run(args, cwd=ROOT, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if done.returncode != 0:
        log(done.stderr[-3000:])
        return f"FAILED (exit {done.returncode}; see its stderr)", wall
    if capture:
        write_text(capture, [f"Printed by `benchmarks/{name}` (captured by `run_all.py`):", "",
                             *stamp_lines(), "", done.stdout])
        return f"ok, output in [`results/{capture}`](benchmarks/results/{capture})", wall
    return "ok", wall


def _row(rows: list[dict], **match) -> dict | None:
    for row in rows:
        if all(row[k] == v for k, v in match.items()):
            return row
    return None


def _met(value: float, target: float) -> str:
    return "met" if value <= target else f"not met ({value / target:.1f}x the target)"


def headline(summary: bench_engine.Summary) -> list[str]:
    """Headline table: speed, accuracy reached, and the targets or quoted figures."""
    steps = {r["scene"]: r for r in summary.steps}
    single = steps["2D block 0.4 x 0.3 at rest"]
    rocking = steps["2D rocking block 0.5 x 1.5 (released at alpha/2)"]
    stack3 = steps["2D 3-block stack at rest"]
    stack10 = steps["2D 10-block stack at rest"]
    rows = [
        ["2D single block at rest, median µs/step", f"{single['median_us']:.0f}",
         f"{single['contacts']:.0f} contacts; {single['accuracy']}",
         f"target ≤ {bench_engine.TARGET_SINGLE * 1e6:.0f} µs", _met(single["median_us"], bench_engine.TARGET_SINGLE * 1e6)],
        ["2D rocking block, median µs/step", f"{rocking['median_us']:.0f}",
         f"{rocking['contacts']:.1f} contacts; {rocking['accuracy']}",
         f"target ≤ {bench_engine.TARGET_SINGLE * 1e6:.0f} µs", _met(rocking["median_us"], bench_engine.TARGET_SINGLE * 1e6)],
        ["2D 3-block stack at rest, median µs/step", f"{stack3['median_us']:.0f}",
         f"{stack3['contacts']:.0f} contacts; {stack3['accuracy']}",
         f"target ≤ {bench_engine.TARGET_STACK3 * 1e6:.0f} µs", _met(stack3["median_us"], bench_engine.TARGET_STACK3 * 1e6)],
        ["2D 10-block stack at rest, median µs/step", f"{stack10['median_us']:.0f}",
         f"{stack10['contacts']:.0f} contacts; {stack10['accuracy']}", "—", "—"],
    ]
    rows.append(peers_headline())
    for name in ("3D rocking box 0.5 x 0.5 x 1.5", "3D LNEC stacked pair at rest", "3D LNEC trilith at rest"):
        r = steps[name]
        target = ([f"target ≤ {bench_engine.TARGET_TRILITH * 1e6:.0f} µs",
                   _met(r["median_us"], bench_engine.TARGET_TRILITH * 1e6)]
                  if name == "3D LNEC trilith at rest" else ["—", "—"])
        rows.append([f"{name}, median µs/step", f"{r['median_us']:.0f}",
                     f"{r['contacts']:.1f} contacts; {r['accuracy']}", *target])
    for r in summary.sliding:
        rows.append([f"sliding block, {r['cone']} cone, median µs/step", f"{r['median_us']:.0f}",
                     f"stopping distance error {r['error']:.1e} m, max lift-off {r['lift']:.1e} m", "—", "—"])
    return markdown_table(["measure", "nscd (measured here)", "accuracy reached", "target / reference", "met?"], rows)


def _stage_sentence(shares: dict) -> str:
    ordered = sorted(shares.items(), key=lambda item: -item[1])
    return "; ".join(f"{label} {100 * share:.0f} %" for label, share in ordered)


def what_dominates(summary: bench_engine.Summary) -> list[str]:
    """The profile findings as sentences (numbers from this run)."""
    top = ", ".join(f"`{name}` {100 * share:.0f} %" for name, share in summary.top_2d[:5])
    rocking_us = next(r["median_us"] for r in summary.steps if r["scene"].startswith("2D rocking block"))
    compiled = summary.profile_2d[bench_engine.COMPILED]
    return [
        f"- 2D single-block step (cProfile, shares of the step): {_stage_sentence(summary.profile_2d)}.",
        f"- Largest own-time functions of the 2D step: {top}.",
        f"- 3D trilith step: {_stage_sentence(summary.profile_3d)}.",
        f"- The 2D step makes {summary.calls_2d:.0f} Python-level function calls (numpy included) around its one "
        f"compiled call; at {rocking_us:.0f} µs per step, the compiled call (detection to integration and the "
        f"recording) is about {100 * compiled:.0f} % of the profiled time and the Python around it the rest "
        "(`docs/time_step.md`, \"One step of a single run: where its microseconds go\").",
    ]


def accuracy_table(summary: bench_engine.Summary) -> list[str]:
    """Part 1 at a glance: per method, the error reached at each time step."""
    dts = sorted({r["dt"] for r in summary.rocking}, reverse=True)
    rows = []
    for method in bench_engine.METHODS:
        cells = []
        for dt in dts:
            r = _row(summary.rocking, method=method, dt=dt)
            cells.append(f"{r['eta_error']:.0e} / {r['t5_error']:.0e} / {r['wall_per_sim_s']:.2g}" if r else "—")
        rows.append([method, *cells])
    return markdown_table(["method", *[f"dt = {dt:g}" for dt in dts]], rows)


def _csv_rows(name: str) -> list[dict]:
    """Rows of ``benchmarks/results/<name>`` as dicts (empty if the file is missing)."""
    path = RESULTS / name
    if not path.exists():
        return []
    with path.open(encoding="utf-8", newline="") as handle:
        return list(csv.DictReader(handle))


#: The accuracy target on the free-rocking block (general engines need dt = 1e-4 for it).
PEER_ETA_ERROR, PEER_T5_ERROR = 1e-3, 1e-3


def _number(value: str) -> float:
    try:
        return float(value)
    except ValueError:
        return math.nan


def peers_headline() -> list[str]:
    """Headline row: nscd's cheapest run reaching the peers' dt = 1e-4 accuracy against MuJoCo
    at dt = 1e-4, both measured in the same bench_peers run (``results/peers.csv``)."""
    label = ("free rocking at the accuracy MuJoCo needs dt = 1e-4 for "
             "(max |eta error| < 0.1 %, |t5 error| < 1 ms): CPU s per simulated s")
    rows = _csv_rows("peers.csv")
    mujoco = next((r for r in rows if r["engine"] == "MuJoCo" and _number(r["dt"]) == 1e-4), None)
    good = [r for r in rows if r["engine"].startswith("nscd")
            and _number(r["eta_error"]) / bench_engine.ETA_HOUSNER < PEER_ETA_ERROR
            and _number(r["t5_error"]) < PEER_T5_ERROR]
    if mujoco is None or not good:
        return [label, "—" if not good else "see peers table", "—",
                "MuJoCo not run" if mujoco is None else "no nscd run reached it", "—"]
    best = min(good, key=lambda r: _number(r["cpu_per_sim_s"]))
    ours, theirs = _number(best["cpu_per_sim_s"]), _number(mujoco["cpu_per_sim_s"])
    return [label, f"{ours:.3g} ({best['engine']}, dt = {best['dt']})",
            f"eta error {_number(best['eta_error']) / bench_engine.ETA_HOUSNER:.2%}, "
            f"|t5 error| {_number(best['t5_error']) * 1e3:.2f} ms",
            f"MuJoCo at dt = 1e-4 in the same run: {theirs:.3g} (eta error "
            f"{_number(mujoco['eta_error']) / bench_engine.ETA_HOUSNER:.2%}, |t5 error| "
            f"{_number(mujoco['t5_error']) * 1e3:.2f} ms); "
            f"target ≤ {bench_engine.TARGET_FREE_ROCKING_VS_MUJOCO:g}x",
            "met" if ours <= bench_engine.TARGET_FREE_ROCKING_VS_MUJOCO * theirs
            else f"not met ({ours / theirs:.2f}x MuJoCo)"]


def peers_section() -> list[str]:
    """Free rocking in nscd, MuJoCo and PyBullet (from ``results/peers.csv``), or nothing if absent."""
    rows = _csv_rows("peers.csv")
    if not rows:
        return []

    def cell(value: str, spec: str) -> str:
        try:
            number = float(value)
        except ValueError:
            return "—"
        return format(number, spec) if number == number else "—"

    table = [[r["engine"], r["dt"], cell(r["cpu_per_sim_s"], ".3g"), cell(r["wall_per_sim_s"], ".3g"),
              cell(r["eta_error"], ".1e"), cell(r["t5_error"], ".1e"), r["note"]] for r in rows]
    return ["## Free rocking beside MuJoCo and PyBullet (measured in the same run)", "",
            f"Same case and measures as above; engine settings in `benchmarks/bench_peers.py`. "
            "Full table: [`results/peers.md`](benchmarks/results/peers.md).", "",
            *markdown_table(["engine", "dt (s)", "CPU s / sim s", "wall s / sim s", "max |eta - 0.850|",
                             "|t5 error| (s)", "note"], table), "",
            "![peers work-precision](benchmarks/results/peers_work_precision.png)", ""]


def atlas_section() -> list[str]:
    """The atlas summary table (copied from ``results/atlas.md``), or nothing if absent."""
    path = RESULTS / "atlas.md"
    if not path.exists():
        return []
    lines = path.read_text(encoding="utf-8").splitlines()
    start = lines.index("## Summary (status per dt, largest dt first)")
    end = next(k for k in range(start + 2, len(lines)) if not lines[k].startswith("|"))
    return ["## Stability atlas", "",
            "Status per time step (largest first) of each scenario and method; tolerances, measured errors "
            "and failure messages in [`results/atlas.md`](benchmarks/results/atlas.md).", "",
            *lines[start + 2:end], "", "![stability atlas](benchmarks/results/atlas.png)", ""]


def _results_from(name: str, header: str) -> list[str]:
    """Lines of ``results/<name>`` from its table (first line starting with ``header``) on; [] if absent."""
    path = RESULTS / name
    if not path.exists():
        return []
    lines = path.read_text(encoding="utf-8").splitlines()
    start = next((k for k, line in enumerate(lines) if line.startswith(header)), None)
    return [] if start is None else lines[start:]



def _table_section(name: str, header: str, title: str, intro: str,
                   after: Callable[[list[str]], list[str]] = lambda lines: []) -> list[str]:
    """A section quoting the table of ``results/<name>`` (the lines from ``header`` on that start
    with "|") under ``title`` and ``intro``, followed by ``after(lines)`` of those lines; [] if
    the file or its table is absent."""
    lines = _results_from(name, header)
    if not lines:
        return []
    table = [line for line in lines if line.startswith("|")]
    return [f"## {title}", "", intro, "", *table, "", *after(lines)]

def maps_section() -> list[str]:
    """The table of ``results/maps.md`` (double-pulse maps), if it was written."""
    return _table_section("maps.md", "| specimen", "Double-pulse maps (end to end)",
                          "20 x 20 cells, scale 1, the rig's defaults, at most 1 s per cell (a cell stops once its "
                          "outcome is decided; `batched, full length`: every cell to 1 s, the reference), process "
                          "pool over all cores; details in [`results/maps.md`](benchmarks/results/maps.md).")


def first_run_section() -> list[str]:
    """The tables of ``results/first_run.md`` (the main job from an empty numba cache), if written."""
    return _quoted("first_run.md", "| run", "First run from an empty compilation cache",
                   "`examples/single_block/free_rocking.py` in a fresh process, wall and CPU time: after a fresh "
                   "install (a clone, a new virtual environment, `pip install -e '.[plot]'`, which compiles the "
                   "main job's kernels ahead of time into the package's store: timed whole) with an empty numba "
                   "cache; and on the sources alone (no compiled store) with an empty and a filled numba cache, "
                   "and the kernels that run compiles; details in "
                   "[`results/first_run.md`](benchmarks/results/first_run.md) (stamped with its own date, "
                   "commit and load).")


def _quoted(name: str, header: str, title: str, intro: str) -> list[str]:
    """A section quoting ``results/<name>`` from ``header`` on (its ``##`` headings in bold); [] if absent."""
    lines = _results_from(name, header)
    if not lines:
        return []
    body = [f"**{line[3:]}**" if line.startswith("## ") else line for line in lines]
    return [f"## {title}", "", intro, "", *body, ""]


def _commit(lines: list[str]) -> str:
    """The commit of a results file's stamp line (``- date: ...; commit abc1234``), marked when it is
    not an ancestor of the current HEAD (the results predate a rebase: rerun the script to refresh)."""
    for line in lines:
        match = re.match(r"- date: .*; commit (\S+)", line)
        if match:
            commit = match.group(1)
            ancestor = subprocess.run(["git", "merge-base", "--is-ancestor", commit, "HEAD"], cwd=ROOT,
                                      capture_output=True).returncode == 0
            return commit if ancestor else f"{commit} (not an ancestor of HEAD: predates a rebase, rerun)"
    return "?"


def _experiment_rows() -> list[list[str]]:
    """One row per table or figure compared with an experiment, read from the results files."""
    rows = []
    path = RESULTS / "lnec_table4.md"
    if path.exists():
        lines = path.read_text(encoding="utf-8").splitlines()
        for line in lines:
            match = re.match(r"- rocking / no rocking: engine agrees with the test in (\d+) of (\d+) cells "
                             r"\((\d+) of \d+ converged", line)
            if match:
                agree, n, converged = (int(g) for g in match.groups())
                rows.append(["003 Table 4: specimen 2, constant sine, rocking / no rocking", n, agree,
                             n - converged, _commit(lines), "[`results/lnec_table4.md`](benchmarks/results/lnec_table4.md)"])
    path = RESULTS / "double_pulse.md"
    if path.exists():
        lines = path.read_text(encoding="utf-8").splitlines()
        for line in lines:
            match = re.match(r"- (.*): (\d+) of (\d+) figures agree, (\d+) unconverged\.", line)
            if match:
                rows.append([f"002 Figs. 23-26, final mode ({match.group(1)})", match.group(3), match.group(2),
                             match.group(4), _commit(lines),
                             "[`results/double_pulse.md`](benchmarks/results/double_pulse.md)"])
        start = next((k for k, line in enumerate(lines) if line.startswith("| statement")), None)
        for line in (lines[start + 2:] if start is not None else []):
            if not line.startswith("|"):
                break
            cells = [c.strip() for c in line.strip("|").split("|")]
            rows.append([f"002 map region: {cells[0]}", cells[1], cells[2], cells[3], _commit(lines),
                         "[`results/double_pulse.md`](benchmarks/results/double_pulse.md)"])
    path = RESULTS / "lnec_stacked.md"
    if path.exists():
        lines = path.read_text(encoding="utf-8").splitlines()
        labels = {"Table 5a/5b constant sine": "003 Table 5a/5b: stacked pair (3D), constant sine, class of both blocks",
                  "Table 5a/5b Hanning sine": "003 Table 5a/5b: stacked pair (3D), Hanning sine, class of both blocks",
                  "Fig. 10": "003 Fig. 10: trilith (3D), final displacement pattern",
                  "Fig. 11": "003 Fig. 11: trilith (3D) at 3.3 Hz / 5 mm: pillar amplitudes, in phase, lintel residual",
                  "Table 6": "003 Table 6: dynamic critical angle above the static one (2D, synthetic EC8 records)"}
        for line in lines:
            match = re.match(r"- cells agreeing: (\d+) of (\d+) \((\d+) unconverged[^)]*\) \[(.*)\]", line)
            if match:
                rows.append([labels.get(match.group(4), f"003 {match.group(4)}"), match.group(2), match.group(1),
                             match.group(3), _commit(lines),
                             "[`results/lnec_stacked.md`](benchmarks/results/lnec_stacked.md)"])
    return rows


def experiments_section() -> list[str]:
    """Per table or figure of 002 and 003: cells compared, agreeing, unconverged, and the commit."""
    rows = _experiment_rows()
    if not rows:
        return []
    return ["## Experiments", "",
            "Each engine result compared with a published experiment, checked for time-step convergence "
            "(`nscd.analysis.verify_time_step`: rerun at dt/2; unconverged cells never count as agreeing). "
            "Regenerated from the results files by `benchmarks/run_all.py --experiments-only`; each row "
            "names the commit its results file was produced at.", "",
            *markdown_table(["experiment (seed, table / figure)", "cells compared", "agreeing", "unconverged",
                             "commit", "details"], rows), ""]


def replace_experiments_section() -> None:
    """Rewrite only the "## Experiments" section of ``BENCHMARKS.md`` (inserted before "## What dominates")."""
    lines = OUT.read_text(encoding="utf-8").splitlines()
    section = experiments_section()
    if "## Experiments" in lines:
        start = lines.index("## Experiments")
        end = next((k for k in range(start + 1, len(lines)) if lines[k].startswith("## ")), len(lines))
    else:
        start = end = next((k for k, line in enumerate(lines) if line.startswith("## What dominates")), len(lines))
    OUT.write_text("\n".join(lines[:start] + section + lines[end:]) + "\n", encoding="utf-8")


def scaling_section() -> list[str]:
    """The table and findings of ``results/scaling.md`` (walls of 10-2000 blocks), if it was written."""
    return _table_section("scaling.md", "| blocks", "Scaling: running-bond walls on a shaking base",
                          "dt = 1 ms; details and the stage shares in [`results/scaling.md`](benchmarks/results/"
                          "scaling.md) (stamped with its own date, commit and load).",
                          lambda lines: [line for line in lines if line.startswith("- ")]
                          + ["", "![time per step against contacts](benchmarks/results/scaling.png)", ""])


def midsize_section() -> list[str]:
    """The table of ``results/midsize.md`` (scenes of a few dozen bodies), if it was written."""
    return _table_section("midsize.md", "| scene",
                          "Scenes of a few dozen bodies: compiled steps against the general step",
                          "dt = 1 ms, default settings (one row of the 5 x 6 wall: the collapse setting, tol_relative "
                          "1e-4), each scene run as shipped and with every step by the general step in the same process "
                          "(the same run bit for bit), MuJoCo beside for the 5 x 6 wall; details in "
                          "[`results/midsize.md`](benchmarks/results/midsize.md) (stamped with its own date, commit "
                          "and load).")


def collapse_3d_section() -> list[str]:
    """The table and ratio of ``results/collapse_3d.md`` (the 97-block wall, 3D against 2D), if it was written."""
    return _table_section("collapse_3d.md", "| wall", "The 97-block wall shaken to collapse: 3D against 2D",
                          "8 m/s^2, 2 Hz, one-cycle ramp, dt = 1 ms, the same steps from t = 0 in both; details in "
                          "[`results/collapse_3d.md`](benchmarks/results/collapse_3d.md) (stamped with its own "
                          "date, commit and load).",
                          lambda lines: [line for line in lines if line.startswith("3D / 2D")] + [""])


def models_section() -> list[str]:
    """The table of ``results/models.md`` (the model choice against the 2D engine), if it was written."""
    path = RESULTS / "models.md"
    stamp = path.read_text(encoding="utf-8").splitlines() if path.exists() else []
    load = next((m.group(1) for m in map(re.compile(r"- machine: .*1-min load average (\S+)").match, stamp) if m),
                "?")
    return _table_section("models.md", "| case", "Model choice: the reduced models against the engine",
                          "`nscd.simulate(scene, t_end, dt, model=\"auto\")` (Housner or the stacked pair, "
                          "assumption checks included) beside the 2D engine (midpoint rule, dt = 1 ms) on the same "
                          f"scene, measured at commit {_commit(stamp)} at a 1-min load average of {load} on the 2 "
                          "cores; details in [`results/models.md`](benchmarks/results/models.md).")


def step_section() -> list[str]:
    """The tables of ``results/step.md`` (one step beside MuJoCo's, first-run compile time), if written."""
    return _quoted("step.md", "## Median CPU time", "One step beside MuJoCo's (measured in the same run)",
                   "CPU time per step at dt = 1 ms and default settings, free rocking at default settings "
                   "against MuJoCo at dt = 1e-4, and the first run of the main job with an empty numba cache; "
                   "details in [`results/step.md`](benchmarks/results/step.md) (stamped with its own date, "
                   "commit and load).")


def collapse_section() -> list[str]:
    """The table and ratios of ``results/collapse.md`` (walls breaking up, beside MuJoCo), if it was written.

    ``bench_collapse.py`` is not among :data:`SCRIPTS` (a 5 s break-up takes far longer than
    the rest): it is run on its own and its stamped results are quoted here.
    """
    return _table_section("collapse.md", "| scene", "Walls breaking up on a shaking base (beside MuJoCo)",
                          "Run on its own (`benchmarks/bench_collapse.py`); stamped details in "
                          "[`results/collapse.md`](benchmarks/results/collapse.md); why the solver stops where it "
                          "does: [`docs/solver.md`](docs/solver.md).",
                          lambda lines: [line for line in lines if line and not line.startswith("|")] + [""])


def write_summary(summary: bench_engine.Summary, info: dict, scripts: dict, elapsed: float,
                  reused: list[str] | None = None) -> None:
    mode = "--quick" if summary.quick else "full"
    reused = reused or []
    provenance = ("every number below was measured by that run" if not reused else
                  "the engine tables (headline rows per step, free rocking, profiles) were measured by that run; the "
                  f"sections of {', '.join(f'`{name}`' for name in reused)} come from those scripts' own runs, "
                  "stamped in their results files (date, commit, load)")
    lines = [
        "# nscd benchmarks", "",
        "Generated by `.venv/bin/python benchmarks/run_all.py"
        f"{' --quick' if summary.quick else ''}{' --reuse ' + ' '.join(reused) if reused else ''}` (mode: {mode}, "
        f"{elapsed / 60:.1f} min); {provenance}. Rerun `benchmarks/run_all.py` without `--reuse` to regenerate "
        "this file and `benchmarks/results/` in one go.", "",
        *stamp_lines(info), "",
        "Read wall times with the load average above: on a shared machine a preempted step takes "
        "several times longer, so totals (wall s per simulated s) are inflated, the median step much "
        "less so; the process CPU time (in parentheses, and in `results/engine.md`) is the figure "
        "least affected by other jobs.",
        "", "## Headline", "", *headline(summary), "",
        "## Free rocking: error against cost", "",
        f"0.5 x 1.5 m block released at alpha/2; cells: max |eta - {bench_engine.ETA_HOUSNER:.3f}| over the "
        "first 5 impacts / |5th impact time - Housner 1-DOF| (s) / wall s per simulated s. "
        "Full table: [`results/engine.md`](benchmarks/results/engine.md).", "",
        *accuracy_table(summary), "",
        "![work-precision chart](benchmarks/results/work_precision.png)", "",
        *peers_section(), *step_section(), *first_run_section(), *atlas_section(), *maps_section(), *scaling_section(),
        *midsize_section(), *collapse_3d_section(), *models_section(), *experiments_section(), *collapse_section(),
        "## What dominates the step", "", *what_dominates(summary), "",
        "## Detailed results", "",
        "- [`benchmarks/results/engine.md`](benchmarks/results/engine.md): all engine tables (parts 1–5); "
        "CSV: `rocking_accuracy.csv`, `step_timings.csv`, `sliding.csv`, `profile_stages.csv`",
    ]
    for name, status in scripts.items():
        lines.append(f"- `benchmarks/{name}`: {status}")
    for name, what in (("fclib.md", "contact solver on FCLIB"), ("atlas.md", "stability atlas"),
                       ("peers.md", "free rocking beside MuJoCo and PyBullet"),
                       ("scaling.md", "step cost against scene size"),
                       ("midsize.md", "scenes of a few dozen bodies, compiled steps against the general step"),
                       ("collapse_3d.md", "the 97-block wall in 3D against 2D"),
                       ("models.md", "the model choice against the 2D engine"),
                       ("collapse.md", "walls breaking up, beside MuJoCo")):
        if (RESULTS / name).exists():
            lines.append(f"- [`benchmarks/results/{name}`](benchmarks/results/{name}): {what}")
    OUT.write_text("\n".join(lines) + "\n", encoding="utf-8")


def main() -> None:
    parser = argparse.ArgumentParser(description="Regenerate benchmarks/results/ and BENCHMARKS.md.")
    parser.add_argument("--quick", action="store_true", help="fewer time steps and shorter runs (a few minutes)")
    parser.add_argument("--reuse", nargs="*", default=[], metavar="SCRIPT", choices=sorted(SCRIPTS),
                        help="keep these scripts' existing results (each carries its own date and commit)")
    parser.add_argument("--experiments-only", action="store_true",
                        help="only rewrite the Experiments section of BENCHMARKS.md from the results files")
    args = parser.parse_args()
    if args.experiments_only:
        replace_experiments_section()
        log(f"run_all: rewrote the Experiments section of {OUT}")
        return
    start = time.perf_counter()
    info = stamp()
    log("run_all: bench_engine")
    summary = bench_engine.run(quick=args.quick)
    scripts = {}
    for name, capture in SCRIPTS.items():
        if name in args.reuse:
            scripts[name] = "reused: not re-run by this command; its results file carries its own date and commit"
            continue
        log(f"run_all: {name}")
        status, wall = run_script(name, args.quick, capture)
        scripts[name] = f"{status} ({wall:.0f} s)" if wall else status
    write_summary(summary, info, scripts, time.perf_counter() - start, args.reuse)
    log(f"run_all: wrote {OUT} in {(time.perf_counter() - start) / 60:.1f} min")


if __name__ == "__main__":
    main()
