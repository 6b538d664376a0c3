"""The ``nscd`` command: one subcommand per task.

    nscd map --specimen stack3 --scale 1 --gap 0.005:0.05:20 --v-peak 0.1:1.5:20 -o map.csv --plot map.png
    nscd map --specimen stack3 --gap 0.005:0.05:20 --v-peak 0.1:1.5:20 -o map.csv --batch   # cells batched
    nscd export run.npz -o out/run.pvd --every 10
    nscd animate run.npz -o run.gif

Adding a subcommand is one function ``_<name>_command(subparsers)`` that adds its
parser and sets ``handler`` (a function of the parsed arguments returning an exit
code), listed in :data:`COMMANDS`. A handler checks every input and output path
before it starts the work, and may set ``args.on_interrupt`` (what to tell a user who
stops it).

Errors and signals
------------------
A user error (bad value, missing or unreadable file, output folder that does not
exist, unknown format) prints one line ``nscd <command>: error: ...`` on standard
error and exits with code 2; a failure during the work (an executor that broke)
exits with 1. Ctrl-C prints one line and exits with 130, SIGTERM with 143; both end
the worker processes of ``nscd map`` (the finished cells stay in the CSV and a rerun
resumes). ``--debug`` shows the Python traceback instead.
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import logging
import os
import _thread
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Collection, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["main", "parse_values"]

EXIT_USAGE, EXIT_FAILURE, EXIT_INTERRUPTED, EXIT_TERMINATED = 2, 1, 130, 143
"""Exit codes: bad input (argparse's convention), failure during the work, 128 + SIGINT, 128 + SIGTERM."""


class Terminated(BaseException):
    """Raised in the main thread when the process receives SIGTERM (not an ``Exception``,
    so that no cell-level handler swallows it)."""


def parse_values(text: str, name: str) -> list[float]:
    """Values of a sweep axis from the command line.

    ``"start:stop:n"`` gives ``n`` evenly spaced values from ``start`` to ``stop``
    (both included; ``start < stop``, ``n >= 2``); ``"a,b,c"`` (or one number)
    gives the listed values.

    Raises
    ------
    ValueError
        Naming ``name`` and the text, for an empty, reversed or malformed range.
    """
    try:
        if ":" in text:
            start, stop, count = text.split(":")
            start, stop, n = float(start), float(stop), int(count)
            if n < 2:
                raise ValueError(f"{name} == {text!r}: n == {n}, must be >= 2 (or give one value).")
            if not start < stop:
                raise ValueError(f"{name} == {text!r}: start == {start} must be < stop == {stop}.")
            return np.linspace(start, stop, n).tolist()
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError as exc:
        if str(exc).startswith(name):
            raise
        raise ValueError(f"{name} == {text!r}, must be start:stop:n or a comma-separated list of numbers.") from exc
    if not values:
        raise ValueError(f"{name} == {text!r} gives no values.")
    return values


# --------------------------------------------------------------------------- paths, checked first


def _input_file(text: str) -> Path:
    """An existing, readable file."""
    path = Path(text)
    if not path.exists():
        raise ValueError(f"{text}: no such file.")
    if path.is_dir():
        raise ValueError(f"{text} is a folder, must be a file.")
    if not os.access(path, os.R_OK):
        raise ValueError(f"{text}: permission denied.")
    return path


def _output_file(text: str, option: str, suffixes: Collection[str], create_folder: bool = False) -> Path:
    """An output path with one of ``suffixes`` in an existing (or, with ``create_folder``,
    newly created) writable folder."""
    path = Path(text)
    if path.suffix.lower() not in suffixes:
        raise ValueError(f"{option} {text}: unknown format {path.suffix or '(no suffix)'!r}, "
                         f"must end with one of {', '.join(sorted(suffixes))}.")
    folder = path.parent
    if create_folder:
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ValueError(f"{option} {text}: cannot create folder {str(folder)!r} ({exc.strerror}).") from exc
    if not folder.is_dir():
        raise ValueError(f"{option} {text}: folder {str(folder)!r} does not exist.")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"{option} {text}: folder {str(folder)!r} is not writable.")
    if path.is_dir():
        raise ValueError(f"{option} {text} is a folder, must be a file name.")
    return path


def _image_formats() -> set[str]:
    """Suffixes matplotlib can save a figure to (``.png``, ``.pdf``, ``.svg``, ...)."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise ValueError("--plot needs matplotlib: pip install 'nscd[plot]'.") from exc
    return {f".{ext}" for ext in FigureCanvasAgg(Figure()).get_supported_filetypes()}


# --------------------------------------------------------------------------- worker processes


def _ignore_interrupt() -> None:
    """Pool-worker initializer: Ctrl-C reaches the whole process group; only the parent handles it.
    SIGTERM (the parent ending its workers) ends a worker at once, whatever it is doing."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)   # also discards a SIGINT pending since the fork
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})   # blocked by _process_pool
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    sys.unraisablehook = sys.__unraisablehook__


def _process_pool(workers: int) -> cf.ProcessPoolExecutor:
    """A process pool of ``workers`` processes, started now, that Ctrl-C never interrupts.

    A worker forked with Python's Ctrl-C handler and signalled before its initializer runs
    would print a ``KeyboardInterrupt`` traceback. So SIGINT is blocked in this process while
    the workers start (a forked child inherits the mask; :func:`_ignore_interrupt` ignores
    SIGINT, which discards one pending, then unblocks it) and unblocked after, which delivers
    a Ctrl-C of that moment to this process alone.
    """
    pool = cf.ProcessPoolExecutor(max_workers=workers, initializer=_ignore_interrupt)
    if not hasattr(signal, "pthread_sigmask"):
        return pool
    before = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        pool.submit(int).result()   # starts the workers (all of them with the fork start method)
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, before)
    return pool


def _executor(jobs: int | None, scheduler: str | None) -> cf.Executor:
    """The executor for ``--jobs`` / ``--scheduler``: a Dask client's, in-process, or a process pool."""
    from nscd.sweep import SerialExecutor

    if scheduler is not None:
        from dask.distributed import Client  # optional extra "distributed"

        return Client(scheduler).get_executor()
    if jobs is not None and jobs < 1:
        raise ValueError(f"--jobs == {jobs}, must be >= 1.")
    if jobs == 1:
        return SerialExecutor()
    return _process_pool(jobs or os.cpu_count() or 1)


def _end_workers(executor: cf.Executor) -> None:
    """Stop a process pool at once: terminate its workers, drop queued cells.

    ``ProcessPoolExecutor`` has no public call for this before Python 3.14
    (``terminate_workers``); its ``_processes`` holds the worker processes.
    """
    for process in list((getattr(executor, "_processes", None) or {}).values()):
        process.terminate()
    executor.shutdown(wait=True, cancel_futures=True)


def _workers(executor: cf.Executor) -> int:
    """Worker count of an executor (1 for in-process, os.cpu_count() when unknown)."""
    from nscd.sweep import SerialExecutor

    if isinstance(executor, SerialExecutor):
        return 1
    return getattr(executor, "_max_workers", None) or os.cpu_count() or 1


class _StderrLines(logging.Handler):
    """Log records of nscd.sweep (e.g. "resuming map.csv: 12 of 400 cells already done") as
    ``nscd <command>: ...`` lines on standard error."""

    def __init__(self, command: str) -> None:
        super().__init__(logging.INFO)
        self.command = command

    def emit(self, record: logging.LogRecord) -> None:
        print(f"nscd {self.command}: {record.getMessage()}", file=sys.stderr)


# --------------------------------------------------------------------------- nscd map


def _map_command(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "map", help="overturning map of the double-pulse rig (002) over stop gap and peak velocity",
        description="Run the double-pulse rig of Ceh et al. (seed 002) over a grid of stop gaps BD "
                    "and peak base velocities; write a resumable CSV (and its .json description).",
    )
    parser.add_argument("--specimen", choices=["single", "stack3"], default="single")
    parser.add_argument("--scale", type=float, default=1.0, help="specimen scale (1 or 2 in 002)")
    parser.add_argument("--base", choices=["kinematic", "dynamic"], default="kinematic",
                        help="prescribed base motion, or a base body computed with the blocks")
    parser.add_argument("--gap", required=True, help="stop gaps BD in m: start:stop:n or a,b,c")
    parser.add_argument("--v-peak", required=True, help="peak base velocities in m/s: start:stop:n or a,b,c")
    parser.add_argument("-o", "--out", required=True, help="CSV file (resumed if it exists)")
    parser.add_argument("--plot", help="also draw the map to this image file (.png, .pdf, .svg; needs matplotlib)")
    parser.add_argument("--jobs", type=int, help="worker processes (default: all cores; 1: in-process)")
    parser.add_argument("--scheduler", help="address of a Dask scheduler to run the cells on")
    parser.add_argument("--ensemble", type=int, metavar="N",
                        help="N perturbed runs per cell: a map of mode probabilities")
    parser.add_argument("--seed", type=int, default=0, help="seed of the ensembles")
    parser.add_argument("--batch", action="store_true",
                        help="advance the cells together, four batches per worker (same results, several "
                             "times faster; not with --ensemble)")
    parser.add_argument("--t-end", type=float, default=1.0, help="latest end time of a run, s")
    parser.add_argument("--dt", type=float, help="time step, s (default: the rig's converged value)")
    parser.add_argument("--scheme", choices=["midpoint", "theta"],
                        help="integration scheme (default: the rig's, midpoint; --batch needs theta)")
    parser.add_argument("--friction", type=float,
                        help="block friction (default: high, no sliding, as 002's simulations; 0.54 measured)")
    parser.add_argument("--verify-dt", action="store_true",
                        help="rerun every cell at dt/2: columns converged and changes (not with --batch, --ensemble)")
    parser.add_argument("--base-friction", type=float, help="friction of the base on PTFE (default 0.26)")
    parser.add_argument("--stopper-restitution", type=float, help="restitution on the stopper (default 0.5)")
    parser.add_argument("--restart", action="store_true", help="start afresh instead of resuming")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(handler=_run_map)


def _values_summary(value: Any) -> str:
    """Short text of a sweep description field: lists as 'n values a .. b'."""
    if isinstance(value, dict):
        return ", ".join(f"{k}: {_values_summary(v)}" for k, v in value.items())
    if isinstance(value, list) and len(value) > 3:
        return f"{len(value)} values {value[0]:g} .. {value[-1]:g}" if all(
            isinstance(v, (int, float)) for v in value) else f"{len(value)} values"
    return repr(value)


def _run_map(args: argparse.Namespace) -> int:
    from nscd.rigs import DoublePulseRig
    from nscd.sweep import SweepMismatchError

    out = _output_file(args.out, "-o", {".csv"})
    plot = _output_file(args.plot, "--plot", _image_formats()) if args.plot else None
    options = {"specimen": args.specimen, "scale": args.scale, "base": args.base}
    for key in ("dt", "scheme", "friction", "base_friction", "stopper_restitution"):
        if getattr(args, key) is not None:
            options[key] = getattr(args, key)
    rig = DoublePulseRig(**options)
    gaps, v_peaks = parse_values(args.gap, "--gap"), parse_values(args.v_peak, "--v-peak")
    if args.ensemble is not None and args.ensemble < 1:
        raise ValueError(f"--ensemble == {args.ensemble}, must be >= 1.")

    executor = _executor(args.jobs, args.scheduler)
    args.on_interrupt = f"the finished cells are in {out}: run the same command again to resume"
    resumed = _StderrLines("map")
    sweep_log = logging.getLogger("nscd.sweep")
    sweep_log.addHandler(resumed)
    sweep_log.setLevel(logging.INFO)
    finished = False
    try:
        # four batches per worker: the progress bar (which counts cells) moves as each finishes
        chunks = 4 * _workers(executor) if args.batch else None
        table = rig.map(gaps, v_peaks, out=out, executor=executor, ensemble=args.ensemble,
                        seed=args.seed, t_end=args.t_end, progress=not args.quiet, resume=not args.restart,
                        batch=args.batch, chunks=chunks, verify_dt=args.verify_dt)
        finished = True
    except SweepMismatchError as exc:
        raise ValueError(f"{out} holds another sweep ({exc.key}: {_values_summary(exc.in_file)} in the file, "
                         f"{_values_summary(exc.now)} now); pass --restart to overwrite it, "
                         "or choose another -o.") from exc
    finally:
        sweep_log.removeHandler(resumed)
        if finished:
            executor.shutdown()
        else:
            _end_workers(executor)
    written = [str(out)]
    if plot is not None:
        from nscd.plot import maps

        title = f"{args.specimen}, scale {args.scale:g}, {args.base} base"
        draw = maps.mode_map if args.ensemble is None else maps.probability_map
        draw(table, title=title).savefig(plot, dpi=150)
        written.append(str(plot))
    counts = {mode: int(np.sum(table["mode"] == mode)) for mode in sorted(set(table["mode"].tolist()) - {None})}
    failed = int(np.sum(table["status"] == "failed"))
    summary = ", ".join(f"{mode}: {n}" for mode, n in counts.items())
    print(f"{len(table)} cells -> {', '.join(written)} ({summary}{f'; {failed} failed' if failed else ''})")
    return 0


# --------------------------------------------------------------------------- nscd export


def _export_command(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "export", help="ParaView time series (.pvd or .xdmf) of a saved result",
        description="Write the block surfaces of a result saved with Result.save as a ParaView time "
                    "series (see nscd.io.to_paraview).",
    )
    parser.add_argument("result", help="result file (.npz)")
    parser.add_argument("-o", "--out", required=True, help="output file: .pvd (VTU series) or .xdmf")
    parser.add_argument("--every", type=int, default=1, help="write every N-th stored time (the last always)")
    parser.add_argument("--depth", type=float, help="2D extrusion depth along z, m (default: 0.2 x largest block)")
    parser.set_defaults(handler=_run_export)


def _run_export(args: argparse.Namespace) -> int:
    from nscd.result import load

    source = _input_file(args.result)
    out = _output_file(args.out, "-o", {".pvd", ".xdmf"}, create_folder=True)   # as to_paraview does
    written = load(source).to_paraview(out, every=args.every, depth=args.depth)
    print(f"{source} -> {', '.join(str(p) for p in written)}")
    return 0


# --------------------------------------------------------------------------- nscd animate


def _animate_command(subparsers: Any) -> None:
    parser = subparsers.add_parser(
        "animate", help="a GIF or MP4 of a saved result (matplotlib; no ParaView needed)",
        description="Draw the blocks of a result saved with Result.save, frame by frame (2D outlines, "
                    "3D projected outlines), with the time and the base acceleration "
                    "(see nscd.plot.animate).",
    )
    parser.add_argument("result", help="result file (.npz)")
    parser.add_argument("-o", "--out", required=True, help="output file: .gif (Pillow) or .mp4 (needs ffmpeg)")
    parser.add_argument("--fps", type=float, default=25.0, help="frames per second of the film")
    parser.add_argument("--speed", type=float, default=1.0,
                        help="simulated seconds per second of film (0.25: four times slower)")
    parser.add_argument("--view", choices=["xz", "yz"], default="xz", help="3D: the plane the blocks are projected on")
    parser.set_defaults(handler=_run_animate)


def _run_animate(args: argparse.Namespace) -> int:
    from nscd.plot.animate import frame_steps, movie_writer
    from nscd.result import load

    source = _input_file(args.result)
    out = _output_file(args.out, "-o", {".gif", ".mp4"})
    movie_writer(out, 25.0)   # an .mp4 without ffmpeg fails here, before the result is read
    result = load(source)
    result.animate(out, fps=args.fps, speed=args.speed, view=args.view)
    print(f"{source} -> {out} ({len(frame_steps(result.time, args.fps, args.speed))} frames)")
    return 0


# --------------------------------------------------------------------------- entry point

#: Functions that each add one subcommand.
COMMANDS: list[Callable[[Any], None]] = [_map_command, _export_command, _animate_command]


def build_parser() -> argparse.ArgumentParser:
    """The ``nscd`` argument parser with every subcommand of :data:`COMMANDS`."""
    from nscd import __version__

    parser = argparse.ArgumentParser(prog="nscd", description="Non-smooth contact dynamics of rigid blocks.")
    parser.add_argument("--version", action="version", version=f"nscd {__version__}")
    parser.add_argument("--debug", action="store_true", help="show Python tracebacks of errors")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND", dest="command", required=True)
    for add in COMMANDS:
        add(subparsers)
    for sub in subparsers.choices.values():  # also after the command: nscd map ... --debug
        sub.add_argument("--debug", action="store_true", default=argparse.SUPPRESS,
                         help="show Python tracebacks of errors")
    return parser


def _one_line(exc: BaseException) -> str:
    """The message of an exception on one line (file errors as 'path: reason')."""
    if isinstance(exc, OSError) and exc.strerror:
        text = f"{exc.filename}: {exc.strerror}" if exc.filename else exc.strerror
    else:
        text = str(exc) or type(exc).__name__
    return " ".join(text.split())


def _terminate(signum: int, frame: Any) -> None:
    raise Terminated()


def _quiet_stop(unraisable: Any) -> None:
    """sys.unraisablehook: a Ctrl-C or SIGTERM that lands inside a callback Python cannot raise
    from (e.g. numba's compiler cache while kernels compile) is the user's stop: the signal is
    delivered to the main thread again (dropped, the run would go on) and ends the run with one
    line; other unraisable exceptions as usual."""
    stop = unraisable.exc_value
    if isinstance(stop, (KeyboardInterrupt, Terminated)):
        # from another thread: the main thread takes the signal once this hook has returned
        signum = signal.SIGINT if isinstance(stop, KeyboardInterrupt) else signal.SIGTERM
        threading.Thread(target=_thread.interrupt_main, args=(signum,), daemon=True).start()
    else:
        sys.__unraisablehook__(unraisable)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``nscd`` command; returns the exit code (see the module docstring)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    command = args.command
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main_thread else None
    hook = sys.unraisablehook
    if not args.debug:
        sys.unraisablehook = _quiet_stop
    try:
        with warnings.catch_warnings():
            if not args.debug:
                warnings.showwarning = lambda message, category, *rest: print(
                    f"nscd {command}: warning: {' '.join(str(message).split())}", file=sys.stderr)
            return args.handler(args)
    except (KeyboardInterrupt, Terminated, ValueError, TypeError, OSError, ImportError, RuntimeError) as exc:
        if args.debug:
            raise
        if isinstance(exc, (KeyboardInterrupt, Terminated)):
            hint = getattr(args, "on_interrupt", None)
            what = "interrupted" if isinstance(exc, KeyboardInterrupt) else "terminated"
            print(f"nscd {command}: {what}{f'; {hint}' if hint else ''}.", file=sys.stderr)
            return EXIT_INTERRUPTED if isinstance(exc, KeyboardInterrupt) else EXIT_TERMINATED
        if isinstance(exc, RuntimeError):
            print(f"nscd {command}: failed: {_one_line(exc)}", file=sys.stderr)
            return EXIT_FAILURE
        print(f"nscd {command}: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USAGE
    finally:
        sys.unraisablehook = hook
        if in_main_thread:
            signal.signal(signal.SIGTERM, previous)

if __name__ == "__main__":
    sys.exit(main())
