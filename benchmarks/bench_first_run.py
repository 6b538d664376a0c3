"""First run of the main job after a fresh install, from an empty numba cache: wall and CPU
time, and what compiles.

    python benchmarks/bench_first_run.py

Runs ``examples/single_block/free_rocking.py`` (default settings) in a fresh process:

* on the package's sources alone (copied without the compiled store ``nscd/_compiled``),
  with ``NUMBA_CACHE_DIR`` an empty folder, then again with that cache filled: their
  difference is what the first run would compile without the install's ahead-of-time step.
  This cold run records every numba compilation (numba's ``numba:compile`` events) and lists
  the kernels compiled from Python with the CPU seconds each took, callees included, and
  where the compilation goes;
* after a fresh install as the README's main command makes it (a clone of the commit, a new
  virtual environment, ``pip install -e '.[plot]'``, which compiles the main job's kernels
  into the store: timed whole), with ``NUMBA_CACHE_DIR`` an empty folder.

Each run reports its wall time and its CPU time (user + system, of the child process: less
sensitive than wall time to a shared machine's load; the load average is given beside each
run). Writes ``benchmarks/results/first_run.md``; the target: 10 s wall for the first run
after a fresh install, with an empty compilation cache, install excluded. Needs git and the
package registry (or pip's cache) for the install.
"""
from __future__ import annotations

import json
import os
import resource
import runpy
import shutil
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


def _timed(command: list[str], env: dict, cwd: Path | None = None) -> dict:
    """Wall and CPU seconds (user + system, of the child) of ``command``, and the load average
    before and after."""
    load_before = os.getloadavg()[0]
    cpu0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    subprocess.run(command, env=env, cwd=cwd, check=True, capture_output=True)
    wall = time.perf_counter() - start
    cpu1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = cpu1.ru_utime - cpu0.ru_utime + cpu1.ru_stime - cpu0.ru_stime
    return {"wall": wall, "cpu": cpu, "load": (load_before, os.getloadavg()[0])}


def _child_env(cache: Path, package_root: Path | None) -> dict:
    """The environment of a run: numba's cache in ``cache``, nscd from ``package_root`` (None:
    the interpreter's installed nscd), one BLAS thread, no display."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    env.pop("NUMBA_DISABLE_JIT", None)
    env.pop("PYTHONPATH", None)
    if package_root is not None:
        env["PYTHONPATH"] = str(package_root)
    return env


#: The rows of the table: the main job without the compiled store, from an empty numba cache
#: (everything compiled in the run) and with that cache filled; the install (a clone of the
#: commit into a fresh virtual environment, as the README's main command installs it); the
#: main job after it, from an empty numba cache.
COLD, WARM, INSTALL, AFTER = ("empty cache, no compiled store", "cache filled, no compiled store",
                              "install (pip install -e '.[plot]' of a clone, fresh venv)",
                              "first run after the install, empty cache")


def first_run() -> dict:
    """Wall and CPU seconds of the main job without the compiled store from an empty numba
    cache, then with it filled; of a fresh install (which compiles the main job's kernels
    ahead of time) and of the main job after it from an empty numba cache; the load average
    around each run and the compilations of the main job's runs."""
    runs = {}
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        package = folder / "package"  # the sources alone, without a compiled store
        shutil.copytree(ROOT / "nscd", package / "nscd", ignore=shutil.ignore_patterns("__pycache__", "_compiled"))
        record = folder / "compiled.json"
        for name in (COLD, WARM):
            runs[name] = {**_timed([sys.executable, __file__, "--child", str(record), str(folder / "out")],
                                   _child_env(folder / "cache", package)),
                          **json.loads(record.read_text(encoding="utf-8"))}
            log(f"main job, {name}: {runs[name]['wall']:.1f} s wall, {runs[name]['cpu']:.1f} s CPU")
        clone = folder / "clone"
        subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
        python = clone / ".venv" / "bin" / "python"
        env = _child_env(folder / "unused", None)
        subprocess.run([sys.executable, "-m", "venv", str(clone / ".venv")], check=True)
        runs[INSTALL] = {**_timed([str(python), "-m", "pip", "install", "-q", "-e", ".[plot]"], env, cwd=clone),
                         "compiled": None}
        log(f"{INSTALL}: {runs[INSTALL]['wall']:.1f} s wall, {runs[INSTALL]['cpu']:.1f} s CPU")
        record.unlink()
        runs[AFTER] = {**_timed([str(python), __file__, "--child", str(record), str(folder / "out")],
                                _child_env(folder / "cache2", None), cwd=clone),
                       **json.loads(record.read_text(encoding="utf-8"))}
        log(f"{AFTER}: {runs[AFTER]['wall']:.1f} s wall, {runs[AFTER]['cpu']:.1f} s CPU")
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
    cold, warm = runs[COLD], runs[WARM]
    kernels = sorted(cold["compiled"], key=lambda item: -item[1])
    lines = ["# First run of the main job (bench_first_run.py)", "", *stamp_lines(), "",
             "`examples/single_block/free_rocking.py` with default settings (4 s of free rocking at "
             "dt = 1 ms), in a fresh process. Without the compiled store (the sources alone) its first "
             "run compiles every kernel it calls: compilation = empty cache minus cache filled. "
             "Installing (`pip install`: `setup.py` runs `python -m nscd.precompile --store`) compiles "
             "them ahead of time into the package's store `nscd/_compiled`; the install is timed whole "
             "(the virtual environment's packages, the build's own and the compilation) and the main "
             "job run after it with an empty numba cache.", "",
             *markdown_table(["run", "wall (s)", "CPU s (user + system)", "kernels compiled",
                              "load before / after"],
                             [(name, f"{run['wall']:.1f}", f"{run['cpu']:.1f}",
                               "-" if run["compiled"] is None else len(run["compiled"]),
                               f"{run['load'][0]:.1f} / {run['load'][1]:.1f}") for name, run in runs.items()]),
             "", f"Compilation: {cold['wall'] - warm['wall']:.1f} s wall, {cold['cpu'] - warm['cpu']:.1f} s CPU.", "",
             "## Kernels compiled in the cold run (CPU s each, its callees included)", "",
             *markdown_table(["kernel", "CPU s"], [(name, f"{seconds:.2f}") for name, seconds in kernels]), "",
             *_anatomy_lines(cold["functions"])]
    write_text("first_run.md", lines)
    print("\n".join(lines))


if __name__ == "__main__":
    main()
