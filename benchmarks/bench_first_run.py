"""First run of the main job from an empty numba cache: wall and CPU time, and what compiles.

    python benchmarks/bench_first_run.py

Runs ``examples/single_block/free_rocking.py`` (default settings) in a fresh process with
``NUMBA_CACHE_DIR`` an empty folder, then again with that cache filled; their difference is
the compilation. Each run reports its wall time and its CPU time (user + system, of the child
process: less sensitive than wall time to a shared machine's load; the load average is given
beside each run). The cold run also records every numba compilation (numba's
``numba:compile`` events) and lists the kernels compiled from Python with the CPU seconds
each took, callees included. Then, in a second empty cache folder, the install step
``python -m nscd.precompile`` (timed on its own: it is part of installing) and the main job
after it. Writes ``benchmarks/results/first_run.md``; the target: 10 s wall for the first
run, install excluded.
"""
from __future__ import annotations

import json
import os
import resource
import runpy
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import ROOT, log, markdown_table, stamp_lines, write_text  # noqa: E402

EXAMPLE = ROOT / "examples" / "single_block" / "free_rocking.py"


#: numba's compiler passes the anatomy of a compilation names; the other passes are summed.
_PHASES = {"nopython_type_inference": "type inference", "native_lowering": "lowering"}


def _record_compilations(json_path: str, out: str) -> None:
    """In the child: run the example, recording numba's compilations, then write to ``json_path``
    the kernels compiled from Python (kernel, CPU s, callees included) and, per compiled
    function, the CPU seconds of its own compilation (its callees' excluded) by phase: type
    inference, lowering (numba building the LLVM IR, Python), LLVM (numba's calls into LLVM under
    its lock: parsing, optimisation, machine code, callees linked in included) and the other
    passes; its seconds with its callees, and its number of specialisations."""
    from collections import defaultdict

    from numba.core import event

    compiled: list[tuple[str, float]] = []
    functions: dict = defaultdict(lambda: defaultdict(float))
    stack: list[list] = []  # open events: [kind, name, start, seconds of nested events]

    def function_of(frame_kind: str = "numba:compile") -> str | None:
        return next((f[1] for f in reversed(stack) if f[0] == frame_kind), None)

    class Listener(event.Listener):
        def __init__(self, kind: str) -> None:
            self.kind = kind

        def on_start(self, ev: event.Event) -> None:
            if self.kind == "numba:compile":
                function = ev.data["dispatcher"].py_func
                name = f"{function.__module__}.{function.__qualname__}"
            elif self.kind == "numba:run_pass":
                name = _PHASES.get(ev.data["name"].split(" [")[0], "other passes")
            else:
                name = "LLVM"
            stack.append([self.kind, name, time.process_time(), 0.0])

        def on_end(self, ev: event.Event) -> None:
            kind, name, start, nested = stack.pop()
            seconds = time.process_time() - start
            if stack:
                stack[-1][3] += seconds
            if kind == "numba:compile":
                functions[name]["with callees"] += seconds
                functions[name]["specialisations"] += 1
                functions[name]["other passes"] += seconds - nested
                if not any(f[0] == kind for f in stack):  # compiled from Python, not as a callee
                    compiled.append((name, seconds))
            elif function_of() is not None:
                functions[function_of()][name] += seconds - nested

    for kind in ("numba:compile", "numba:run_pass", "numba:llvm_lock"):
        event.register(kind, Listener(kind))
    sys.argv = [str(EXAMPLE), "--out", out]
    runpy.run_path(str(EXAMPLE), run_name="__main__")
    Path(json_path).write_text(json.dumps({"compiled": compiled, "functions": functions}), encoding="utf-8")


def first_run() -> dict:
    """Wall and CPU seconds of the main job with an empty numba cache, then with it filled,
    then of the install step ``python -m nscd.precompile`` in another empty cache and of the
    main job after it; the load average around each run and the compilations of the main job's runs."""
    runs = {}
    with tempfile.TemporaryDirectory() as folder:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(folder) / "cache"), "PYTHONPATH": str(ROOT),
               "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
        record = Path(folder) / "compiled.json"
        for name in ("empty cache", "cache filled"):
            load_before = os.getloadavg()[0]
            cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            subprocess.run([sys.executable, __file__, "--child", str(record), str(Path(folder) / "out")],
                           env=env, check=True, capture_output=True)
            wall = time.perf_counter() - start
            cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = cpu1.ru_utime - cpu0.ru_utime + cpu1.ru_stime - cpu0.ru_stime
            runs[name] = {"wall": wall, "cpu": cpu, "load": (load_before, os.getloadavg()[0]),
                          **json.loads(record.read_text(encoding="utf-8"))}
            log(f"main job, {name}: {wall:.1f} s wall, {cpu:.1f} s CPU")
    with tempfile.TemporaryDirectory() as folder:
        env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(folder) / "cache"), "PYTHONPATH": str(ROOT),
               "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
        record = Path(folder) / "compiled.json"
        for name, command in (("install step (python -m nscd.precompile)", [sys.executable, "-m", "nscd.precompile"]),
                              ("after the install step", [sys.executable, __file__, "--child", str(record),
                                                          str(Path(folder) / "out")])):
            load_before = os.getloadavg()[0]
            cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
            start = time.perf_counter()
            subprocess.run(command, env=env, check=True, capture_output=True)
            wall = time.perf_counter() - start
            cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
            cpu = cpu1.ru_utime - cpu0.ru_utime + cpu1.ru_stime - cpu0.ru_stime
            recorded = json.loads(record.read_text(encoding="utf-8")) if record.exists() else {"compiled": None}
            runs[name] = {"wall": wall, "cpu": cpu, "load": (load_before, os.getloadavg()[0]), **recorded}
            log(f"{name}: {wall:.1f} s wall, {cpu:.1f} s CPU")
    return runs


#: Phases of a function's own compilation, in the order of the anatomy's columns.
_COLUMNS = ("type inference", "lowering", "LLVM", "other passes")

#: Functions listed in the anatomy (the slowest to compile; the totals cover all).
_LISTED = 25


def _anatomy_lines(functions: dict) -> list[str]:
    """The anatomy of the cold run's compilation: CPU seconds by phase over every function
    compiled, and the functions whose own compilation took longest."""
    own = {name: sum(phases.get(c, 0.0) for c in _COLUMNS) for name, phases in functions.items()}
    totals = [sum(phases.get(c, 0.0) for phases in functions.values()) for c in _COLUMNS]
    slowest = sorted(functions, key=lambda name: -own[name])[:_LISTED]
    rows = [(name, f"{own[name]:.2f}", *(f"{functions[name].get(c, 0.0):.2f}" for c in _COLUMNS),
             f"{functions[name]['with callees']:.2f}", int(functions[name]["specialisations"])) for name in slowest]
    return ["## Where the compilation goes (cold run, CPU s)", "",
            f"{len(functions)} functions, {sum(int(p['specialisations']) for p in functions.values())} "
            f"specialisations compiled; {sum(own.values()):.1f} s: "
            + ", ".join(f"{c} {t:.1f} s" for c, t in zip(_COLUMNS, totals)) + ". Per function its own "
            "compilation (its compiled callees' excluded): type inference; lowering (numba building the LLVM "
            "IR, in Python); LLVM (parsing, optimising and generating machine code, for the function and "
            "every compiled callee linked into it: numba links and optimises each callee again inside "
            "each caller); numba's other passes.", "",
            *markdown_table(["function", "own", *_COLUMNS, "with callees", "specialisations"], rows), ""]


def main() -> None:
    if len(sys.argv) == 4 and sys.argv[1] == "--child":
        _record_compilations(sys.argv[2], sys.argv[3])
        return
    runs = first_run()
    cold, warm = runs["empty cache"], runs["cache filled"]
    kernels = sorted(cold["compiled"], key=lambda item: -item[1])
    lines = ["# First run of the main job (bench_first_run.py)", "", *stamp_lines(), "",
             "`examples/single_block/free_rocking.py` with default settings (4 s of free rocking at "
             "dt = 1 ms), in a fresh process; compilation = empty cache minus cache filled.", "",
             *markdown_table(["numba cache", "wall (s)", "CPU s (user + system)", "kernels compiled",
                              "load before / after"],
                             [(name, f"{run['wall']:.1f}", f"{run['cpu']:.1f}",
                               "-" if run["compiled"] is None else len(run["compiled"]),
                               f"{run['load'][0]:.1f} / {run['load'][1]:.1f}") for name, run in runs.items()]),
             "", "The install step is part of installing (README's main command runs it after `pip install`); "
             "the first run of the main job after it is the row \"after the install step\".",
             "", f"Compilation: {cold['wall'] - warm['wall']:.1f} s wall, {cold['cpu'] - warm['cpu']:.1f} s CPU.", "",
             "## Kernels compiled in the cold run (CPU s each, its callees included)", "",
             *markdown_table(["kernel", "CPU s"], [(name, f"{seconds:.2f}") for name, seconds in kernels]), "",
             *_anatomy_lines(cold["functions"])]
    write_text("first_run.md", lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
