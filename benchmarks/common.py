"""Shared pieces of the benchmark scripts: the run stamp, table writing, step timing.

Every benchmark output starts with :func:`stamp_lines`, so a number is never read
without the machine, library versions, commit and load it was measured on.
"""
from __future__ import annotations

import csv
import datetime as _dt
import os
import platform
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path
from typing import Any, Sequence

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
_PACKAGES = ("numpy", "scipy", "clarabel", "matplotlib")


def _cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (Linux), else :func:`platform.processor`."""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8").splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "not installed"


def _git(*args: str) -> str:
    try:
        out = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=10, check=True)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip()


def stamp() -> dict[str, Any]:
    """Where and when the numbers are measured.

    Returns
    -------
    dict
        ``date`` (UTC, ISO 8601), ``cpu`` (model from /proc/cpuinfo), ``cores``
        (logical), ``load`` (1-minute load average at the time of the call; above
        ``cores`` the machine is shared and wall times are inflated), ``python``,
        one entry per package of ``numpy, scipy, clarabel, matplotlib``, ``commit``
        (short hash of HEAD) and ``dirty_engine`` (True if ``nscd/`` had uncommitted
        changes: the numbers then belong to a tree between two commits).
    """
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    info: dict[str, Any] = {
        "date": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "cpu": _cpu_model(),
        "cores": os.cpu_count(),
        "load": load,
        "python": platform.python_version(),
    }
    info.update({name: _version(name) for name in _PACKAGES})
    info["commit"] = _git("rev-parse", "--short", "HEAD")
    info["dirty_engine"] = bool(_git("status", "--porcelain", "--", "nscd"))
    return info


def stamp_lines(info: dict[str, Any] | None = None) -> list[str]:
    """The stamp as Markdown lines (a bullet list), measured now unless ``info`` is given."""
    info = info or stamp()
    shared = " — shared machine, wall times inflated" if info["load"] > info["cores"] else ""
    tree = " (with uncommitted changes in nscd/)" if info["dirty_engine"] else ""
    return [
        f"- date: {info['date']}; commit {info['commit']}{tree}",
        f"- machine: {info['cpu']}, {info['cores']} logical cores, 1-min load average "
        f"{info['load']:.1f}{shared}",
        f"- Python {info['python']}; numpy {info['numpy']}, scipy {info['scipy']}, "
        f"clarabel {info['clarabel']}, matplotlib {info['matplotlib']}; "
        f"OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS', 'unset')}",
    ]


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> list[str]:
    """Markdown table lines; cells are converted with ``str`` (format numbers before), ``|`` escaped."""
    def line(cells: Sequence[Any]) -> str:
        return "| " + " | ".join(str(cell).replace("|", "\\|") for cell in cells) + " |"

    return [line(header), "|" + "---|" * len(header), *(line(row) for row in rows)]


def write_csv(name: str, header: Sequence[str], rows: Sequence[Sequence[Any]]) -> Path:
    """Write ``rows`` to ``benchmarks/results/<name>`` (CSV) and return the path."""
    path = RESULTS / name
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        writer.writerows(rows)
    return path


def save_figure(fig: Any, name: str, dpi: int = 110) -> Path:
    """Save a matplotlib figure to ``benchmarks/results/<name>``, close it, return the path."""
    import matplotlib.pyplot as plt

    path = RESULTS / name
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def write_text(name: str, lines: Sequence[str]) -> Path:
    """Write Markdown ``lines`` to ``benchmarks/results/<name>`` and return the path."""
    path = RESULTS / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def timed_steps(sim: Any, n_steps: int) -> tuple[np.ndarray, float, list]:
    """Step ``sim`` (an :class:`nscd.Simulator`) ``n_steps`` times, timing each step.

    Returns
    -------
    wall : ndarray, shape (n_steps,)
        Wall-clock seconds of each step.
    cpu : float
        Process CPU seconds of the whole loop (insensitive to other processes'
        load, unlike ``wall``).
    reports : list of StepReport
    """
    wall = np.empty(n_steps)
    reports = []
    cpu_start = time.process_time()
    for k in range(n_steps):
        start = time.perf_counter()
        reports.append(sim.step())
        wall[k] = time.perf_counter() - start
    return wall, time.process_time() - cpu_start, reports


def log(message: str) -> None:
    """Progress line on stderr (results go to files, progress to the terminal)."""
    print(message, file=sys.stderr, flush=True)
