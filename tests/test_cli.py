"""The ``nscd`` command as a user runs it: exit codes and one-line messages, in a subprocess."""
from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
SMALL_MAP = ["--gap", "0.01,0.03", "--v-peak", "0.3,0.6"]  # 4 cells of the single-block rig, ~1 s each


def nscd(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    return subprocess.run([sys.executable, "-m", "nscd.cli", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)


def one_line_error(run: subprocess.CompletedProcess, command: str) -> str:
    """The error line of a failed call: exit 2, one line on stderr, no traceback."""
    assert run.returncode == 2, run.stderr
    assert "Traceback" not in run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"nscd {command}: error: "), run.stderr
    return lines[0]


def test_export_of_missing_or_foreign_files(tmp_path):
    (tmp_path / "bad.txt").write_text("not a result\n")
    assert "nonexist.npz: no such file" in one_line_error(
        nscd("export", "nonexist.npz", "-o", "x.pvd", cwd=tmp_path), "export")
    assert "bad.txt is not a NumPy .npz archive" in one_line_error(
        nscd("export", "bad.txt", "-o", "x.pvd", cwd=tmp_path), "export")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    assert "other.npz is not an nscd result" in one_line_error(
        nscd("export", "other.npz", "-o", "x.pvd", cwd=tmp_path), "export")
    assert "unknown format '.vtk'" in one_line_error(
        nscd("export", "other.npz", "-o", "x.vtk", cwd=tmp_path), "export")
    # --debug shows the traceback instead
    debug = nscd("--debug", "export", "nonexist.npz", "-o", "x.pvd", cwd=tmp_path)
    assert debug.returncode != 0 and "Traceback" in debug.stderr


@pytest.mark.parametrize("outputs, message", [
    (["-o", "m.csv", "--plot", "p.xyz"], "--plot p.xyz: unknown format '.xyz'"),
    (["-o", "m.csv", "--plot", "/nonexistent/x.png"], "--plot /nonexistent/x.png: folder '/nonexistent' does not exist"),
    (["-o", "/nonexistent/x.csv"], "-o /nonexistent/x.csv: folder '/nonexistent' does not exist"),
    (["-o", "m.txt"], "-o m.txt: unknown format '.txt'"),
])
def test_map_checks_its_outputs_before_any_cell_runs(tmp_path, outputs, message):
    run = nscd("map", *SMALL_MAP, *outputs, "--jobs", "1", cwd=tmp_path)
    assert message in one_line_error(run, "map")
    assert not (tmp_path / "m.csv").exists()      # no cell ran, nothing was written
    assert "cell" not in run.stderr                # no progress bar started


def test_map_summary_resume_and_another_grid(tmp_path):
    first = nscd("map", *SMALL_MAP, "-o", "m.csv", "--plot", "m.png", "--jobs", "1", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    assert first.stdout.startswith("4 cells -> m.csv, m.png (")   # the summary names every file
    assert (tmp_path / "m.png").stat().st_size > 0
    with open(tmp_path / "m.csv") as handle:
        assert len(list(csv.DictReader(handle))) == 4
    again = nscd("map", *SMALL_MAP, "-o", "m.csv", "--jobs", "1", cwd=tmp_path)
    assert again.returncode == 0
    assert "nscd map: resuming m.csv: 4 of 4 cells already done" in again.stderr
    other = nscd("map", "--gap", "0.01:0.03:5", "--v-peak", "0.3,0.6", "-o", "m.csv", cwd=tmp_path)
    line = one_line_error(other, "map")
    assert "m.csv holds another sweep" in line and "pass --restart" in line
    assert "resume=False" not in line
    assert "5 values 0.01 .. 0.03" in line and "0.015" not in line   # long lists summarised
    restarted = nscd("map", "--gap", "0.01,0.02,0.03", "--v-peak", "0.3", "-o", "m.csv", "--restart",
                     "--jobs", "1", "--quiet", cwd=tmp_path)
    assert restarted.returncode == 0 and restarted.stdout.startswith("3 cells -> m.csv (")


def test_batch_progress_counts_cells(tmp_path):
    run = nscd("map", "--gap", "0.01,0.02,0.03", "--v-peak", "0.3,0.6", "-o", "b.csv", "--batch",
               "--jobs", "2", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    # six cells in 4 x 2 = 8 batches (at most 6 non-empty): the bar counts cells, not batches
    assert "6/6" in run.stderr and "cell" in run.stderr


def map_in_background(tmp_path: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    # 1600 cells: still running when the signal comes, however fast the cells are
    process = subprocess.Popen(
        [sys.executable, "-m", "nscd.cli", "map", "--gap", "0.005:0.05:40", "--v-peak", "0.2:1.5:40",
         "-o", "s.csv", "--jobs", "2"],
        cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,   # its own session: the signal reaches only it and its workers
        # Ctrl-C's default action, as in a terminal: a test run started in the background (`cmd &`,
        # nohup) ignores SIGINT, and an ignored signal stays ignored across exec
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while not (tmp_path / "s.csv").exists() and time.monotonic() < deadline:
        time.sleep(0.1)
    time.sleep(2.0)   # the workers are busy with cells
    return process


def session_processes(session: int) -> list[int]:
    """Live processes of a session (/proc/<pid>/stat field 6), zombies excluded."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                fields = Path(f"/proc/{entry}/stat").read_text().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[3] == str(session) and fields[0] != "Z":
                found.append(int(entry))
    return found


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc to find the worker processes")
@pytest.mark.parametrize("sig, to_group, code, word", [
    (signal.SIGINT, True, 130, "interrupted"),     # Ctrl-C: the terminal signals the whole group
    (signal.SIGTERM, False, 143, "terminated"),    # kill <pid>: only the parent is signalled
])
def test_signals_end_the_workers_with_one_line(tmp_path, sig, to_group, code, word):
    process = map_in_background(tmp_path)
    (os.killpg if to_group else os.kill)(process.pid, sig)
    _, err = process.communicate(timeout=120)
    assert process.returncode == code
    assert "Traceback" not in err and "KeyboardInterrupt" not in err
    last = err.strip().splitlines()[-1]
    assert last == f"nscd map: {word}; the finished cells are in s.csv: run the same command again to resume."
    deadline = time.monotonic() + 10
    while session_processes(process.pid) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert session_processes(process.pid) == []    # no orphan pool worker


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the workers' signal masks in /proc")
def test_pool_workers_ignore_ctrl_c_from_their_start():
    """Every worker of a map's pool exists when the pool is handed over, and SIGINT is ignored
    in it (or still blocked, before its initializer has run): no moment where a Ctrl-C to the
    process group finds a worker with Python's handler."""
    from nscd.cli import _process_pool

    pool = _process_pool(2)
    try:
        workers = list(pool._processes.values())
        assert len(workers) == 2
        for worker in workers:
            status = Path(f"/proc/{worker.pid}/status").read_text()
            ignored = int(next(line for line in status.splitlines() if line.startswith("SigIgn:")).split()[1], 16)
            blocked = int(next(line for line in status.splitlines() if line.startswith("SigBlk:")).split()[1], 16)
            sigint = 1 << (signal.SIGINT - 1)
            assert ignored & sigint or blocked & sigint
    finally:
        pool.shutdown()
    assert not signal.pthread_sigmask(signal.SIG_BLOCK, set()) & {signal.SIGINT}   # the parent's mask restored
