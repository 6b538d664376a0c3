"""The ``nscd`` command: one subcommand per task.

    nscd map --specimen stack3 --scale 1 --gap 0.005:0.05:20 --v-peak 0.1:1.5:20 -o map.csv --plot map.png
    nscd map --specimen stack3 --gap 0.005:0.05:20 --v-peak 0.1:1.5:20 -o map.csv --batch   # cells batched

Adding a subcommand is one function ``_<name>_command(subparsers)`` that adds its
parser and sets ``handler`` (a function of the parsed arguments returning an exit
code), listed in :data:`COMMANDS`. Bad input exits with code 2 and a one-line
``nscd <command>: error: ...`` message on standard error.
"""
from __future__ import annotations

import argparse
import concurrent.futures as cf
import sys
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

__all__ = ["main", "parse_values"]


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


def _executor(jobs: int | None, scheduler: str | None) -> cf.Executor | None:
    """The executor for ``--jobs`` / ``--scheduler`` (None: nscd.sweep's default pool)."""
    from nscd.sweep import SerialExecutor

    if scheduler is not None:
        from dask.distributed import Client  # optional extra "distributed"

        return Client(scheduler).get_executor()
    if jobs is None:
        return None
    if jobs < 1:
        raise ValueError(f"--jobs == {jobs}, must be >= 1.")
    return SerialExecutor() if jobs == 1 else cf.ProcessPoolExecutor(max_workers=jobs)


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
    parser.add_argument("--plot", help="also draw the map to this image file (needs matplotlib)")
    parser.add_argument("--jobs", type=int, help="worker processes (default: all cores; 1: in-process)")
    parser.add_argument("--scheduler", help="address of a Dask scheduler to run the cells on")
    parser.add_argument("--ensemble", type=int, metavar="N",
                        help="N perturbed runs per cell: a map of mode probabilities")
    parser.add_argument("--seed", type=int, default=0, help="seed of the ensembles")
    parser.add_argument("--batch", action="store_true",
                        help="advance the cells together, one batch per worker (same results, several "
                             "times faster; not with --ensemble)")
    parser.add_argument("--t-end", type=float, default=1.0, help="latest end time of a run, s")
    parser.add_argument("--dt", type=float, help="time step, s (default: the rig's converged value)")
    parser.add_argument("--base-friction", type=float, help="friction of the base on PTFE (default 0.26)")
    parser.add_argument("--stopper-restitution", type=float, help="restitution on the stopper (default 0.5)")
    parser.add_argument("--restart", action="store_true", help="start afresh instead of resuming")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    parser.set_defaults(handler=_run_map)


def _run_map(args: argparse.Namespace) -> int:
    from nscd.rigs import DoublePulseRig

    options = {"specimen": args.specimen, "scale": args.scale, "base": args.base}
    for key in ("dt", "base_friction", "stopper_restitution"):
        if getattr(args, key) is not None:
            options[key] = getattr(args, key)
    rig = DoublePulseRig(**options)
    gaps, v_peaks = parse_values(args.gap, "--gap"), parse_values(args.v_peak, "--v-peak")
    if args.ensemble is not None and args.ensemble < 1:
        raise ValueError(f"--ensemble == {args.ensemble}, must be >= 1.")
    executor = _executor(args.jobs, args.scheduler)
    try:
        table = rig.map(gaps, v_peaks, out=args.out, executor=executor, ensemble=args.ensemble,
                        seed=args.seed, t_end=args.t_end, progress=not args.quiet, resume=not args.restart,
                        batch=args.batch)
    finally:
        if executor is not None:
            executor.shutdown()
    if args.plot:
        from nscd.plot import maps

        title = f"{args.specimen}, scale {args.scale:g}, {args.base} base"
        draw = maps.mode_map if args.ensemble is None else maps.probability_map
        draw(table, title=title).savefig(args.plot, dpi=150)
    counts = {mode: int(np.sum(table["mode"] == mode)) for mode in sorted(set(table["mode"].tolist()) - {None})}
    failed = int(np.sum(table["status"] == "failed"))
    summary = ", ".join(f"{mode}: {n}" for mode, n in counts.items())
    print(f"{len(table)} cells -> {args.out} ({summary}{f'; {failed} failed' if failed else ''})")
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

    written = load(args.result).to_paraview(args.out, every=args.every, depth=args.depth)
    print(f"{args.result} -> {', '.join(str(p) for p in written)}")
    return 0


# --------------------------------------------------------------------------- entry point

#: Functions that each add one subcommand.
COMMANDS: list[Callable[[Any], None]] = [_map_command, _export_command]


def build_parser() -> argparse.ArgumentParser:
    """The ``nscd`` argument parser with every subcommand of :data:`COMMANDS`."""
    from nscd import __version__

    parser = argparse.ArgumentParser(prog="nscd", description="Non-smooth contact dynamics of rigid blocks.")
    parser.add_argument("--version", action="version", version=f"nscd {__version__}")
    subparsers = parser.add_subparsers(title="commands", metavar="COMMAND", required=True)
    for add in COMMANDS:
        add(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``nscd`` command; returns the exit code (2 for bad input)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except ValueError as exc:
        command = " ".join(a for a in (argv if argv is not None else sys.argv[1:])[:1])
        print(f"nscd {command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
