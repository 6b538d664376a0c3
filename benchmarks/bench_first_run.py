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


def _record_compilations(json_path: str, out: str) -> None:
    """In the child: run the example, then write each top-level compilation (kernel, CPU s) to ``json_path``."""
    from numba.core import event

    compiled: list[tuple[str, float]] = []

    class Listener(event.Listener):
        def __init__(self) -> None:
            self.started: list[float] = []

        def on_start(self, ev: event.Event) -> None:
            self.started.append(time.process_time())

        def on_end(self, ev: event.Event) -> None:
            seconds = time.process_time() - self.started.pop()
            if not self.started:  # compiled from Python, not as a callee of another kernel
                function = ev.data["dispatcher"].py_func
                compiled.append((f"{function.__module__}.{function.__qualname__}", seconds))

    event.register("numba:compile", Listener())
    sys.argv = [str(EXAMPLE), "--out", out]
    runpy.run_path(str(EXAMPLE), run_name="__main__")
    Path(json_path).write_text(json.dumps(compiled), encoding="utf-8")


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
                          "compiled": json.loads(record.read_text(encoding="utf-8"))}
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
            compiled = json.loads(record.read_text(encoding="utf-8")) if record.exists() else None
            runs[name] = {"wall": wall, "cpu": cpu, "load": (load_before, os.getloadavg()[0]), "compiled": compiled}
            log(f"{name}: {wall:.1f} s wall, {cpu:.1f} s CPU")
    return runs


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
             *markdown_table(["kernel", "CPU s"], [(name, f"{seconds:.2f}") for name, seconds in kernels]), ""]
    write_text("first_run.md", lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
