"""Tests of nscd.sweep: order, determinism, resume, failures, executors."""
from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import json
import math
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest

from nscd import sweep
from nscd.sweep import SerialExecutor, Table


# ----------------------------------------------------------------- module-level (picklable) cell functions


@dataclasses.dataclass
class Cell:
    product: float
    label: str


def product(a, b, scale=1.0):
    """A cell with a known closed-form answer."""
    return Cell(product=a * b * scale, label=f"{a}x{b}")


def counted(a, b, log):
    """Append one line per call to ``log``; raise SystemExit (a 'kill') once the log has more
    lines than the environment variable NSCD_TEST_DIE_AFTER says (in-process executors only)."""
    with open(log, "a") as handle:
        handle.write(f"{a},{b}\n")
    die_after = os.environ.get("NSCD_TEST_DIE_AFTER")
    if die_after is not None and len(Path(log).read_text().splitlines()) > int(die_after):
        raise SystemExit("simulated kill")
    return {"sum": a + b, "root": math.sqrt(a + b)}


def sometimes_fails(x):
    if x == 2:
        raise ZeroDivisionError("cell two is broken")
    return {"inverse": 1.0 / x}


def slow_square(x, delay=0.0):
    time.sleep(delay)
    return {"square": x * x}


class RefusingExecutor(cf.Executor):
    def submit(self, fn, /, *args, **kwargs):
        raise OSError("queue full")


# ----------------------------------------------------------------- run


def test_run_orders_results_like_cases_under_a_process_pool():
    # delays reversed so later cases finish first: the result order must still follow the cases
    cases = [{"x": x, "delay": 0.05 * (4 - x)} for x in range(5)]
    results = sweep.run(slow_square, cases, executor=cf.ProcessPoolExecutor(2), progress=False)
    assert [r["square"] for r in results] == [x * x for x in range(5)]


def test_run_default_pool_and_failure_names_the_case():
    assert sweep.run(slow_square, [{"x": 3}], progress=False) == [{"square": 9}]
    with pytest.raises(RuntimeError, match=r"case 1 \(\{'x': 2\}\).*ZeroDivisionError"):
        sweep.run(sometimes_fails, [{"x": 1}, {"x": 2}, {"x": 4}], executor=SerialExecutor(), progress=False)


def test_unpicklable_function_is_refused_for_process_pools():
    with pytest.raises(TypeError, match="cannot be pickled"):
        sweep.run(lambda x: x, [{"x": 1}], progress=False)


def test_executor_refusing_tasks_gives_a_clear_error(tmp_path):
    with pytest.raises(RuntimeError, match="RefusingExecutor refused case 0.*OSError: queue full"):
        sweep.grid(product, {"a": [1], "b": [2]}, out=tmp_path / "m.csv", executor=RefusingExecutor(),
                   progress=False)


# ----------------------------------------------------------------- grid: order, files, determinism


def test_grid_order_is_nested_loops_first_parameter_slowest(tmp_path):
    table = sweep.grid(product, {"a": [1, 2, 3], "b": [10, 20]}, out=tmp_path / "m.csv",
                       executor=SerialExecutor(), fixed={"scale": 0.5}, progress=False)
    assert table["cell"].tolist() == list(range(6))
    assert table["a"].tolist() == [1, 1, 2, 2, 3, 3]
    assert table["b"].tolist() == [10, 20, 10, 20, 10, 20]
    np.testing.assert_array_equal(table["product"], 0.5 * table["a"] * table["b"])  # exact: small ints * 0.5
    assert set(table["status"]) == {"ok"}
    assert table.names == ["cell", "a", "b", "status", "error", "product", "label", "check"]
    side = json.loads((tmp_path / "m.csv.json").read_text())
    assert side["parameters"] == {"a": [1, 2, 3], "b": [10, 20]}
    assert side["fixed"] == {"scale": 0.5}
    assert side["function"] == f"{__name__}.product"
    assert side["cells"] == 6
    # the returned table is what is on disk
    assert Table.from_csv(tmp_path / "m.csv").rows == table.rows


def test_same_sweep_twice_gives_byte_identical_files_serial_vs_pool(tmp_path):
    params = {"x": [3.0, 0.1, 1 / 3, 2.5e-9], "delay": [0.03, 0.0]}
    sweep.grid(slow_square, params, out=tmp_path / "a.csv", executor=SerialExecutor(), progress=False)
    with cf.ProcessPoolExecutor(2) as pool:
        sweep.grid(slow_square, params, out=tmp_path / "b.csv", executor=pool, progress=False)
    for suffix in ("", ".json"):
        assert (tmp_path / f"a.csv{suffix}").read_bytes() == (tmp_path / f"b.csv{suffix}").read_bytes()
    table = Table.from_csv(tmp_path / "a.csv")
    # floats written with repr round-trip exactly
    assert table["square"].tolist() == [x * x for x in params["x"] for _ in params["delay"]]


def test_failed_cell_is_recorded_and_the_sweep_carries_on(tmp_path):
    with pytest.warns(RuntimeWarning, match="1 of 4 cells failed.*cell two is broken"):
        table = sweep.grid(sometimes_fails, {"x": [1, 2, 4, 5]}, out=tmp_path / "m.csv",
                           executor=SerialExecutor(), progress=False)
    assert table["status"].tolist() == ["ok", "failed", "ok", "ok"]
    assert table["error"][1] == "ZeroDivisionError: cell two is broken"
    inverse = table["inverse"]
    assert np.isnan(inverse[1]) and inverse[[0, 2, 3]].tolist() == [1.0, 0.25, 0.2]


# ----------------------------------------------------------------- resume


def test_resume_after_kill_computes_only_missing_cells(tmp_path, monkeypatch):
    out, log = tmp_path / "m.csv", tmp_path / "calls.log"
    params = {"a": [1, 2, 3], "b": [4, 5, 6, 7]}
    monkeypatch.setenv("NSCD_TEST_DIE_AFTER", "5")
    with pytest.raises(SystemExit):
        sweep.grid(counted, params, out=out, executor=SerialExecutor(), progress=False,
                   fixed={"log": str(log)})
    monkeypatch.delenv("NSCD_TEST_DIE_AFTER")
    assert len(out.read_text().splitlines()) == 1 + 5  # header + the 5 cells finished before the kill
    with open(out, "a") as handle:  # a row cut in the middle of writing by the kill
        handle.write("5,2,5,o")
    log.unlink()
    # the same description (fixed arguments included) is needed to resume
    with pytest.raises(ValueError, match="'fixed'"):
        sweep.grid(counted, params, out=out, executor=SerialExecutor(), progress=False,
                   fixed={"log": str(tmp_path / "other.log")})
    sweep.grid(counted, params, out=out, executor=SerialExecutor(), progress=False,
               fixed={"log": str(log)})
    # only the 7 missing cells ran (the cut row 5 among them), in cell order
    assert log.read_text().splitlines() == ["2,5", "2,6", "2,7", "3,4", "3,5", "3,6", "3,7"]
    # identical to an uninterrupted sweep
    fresh = tmp_path / "fresh.csv"
    sweep.grid(counted, params, out=fresh, executor=SerialExecutor(), progress=False,
               fixed={"log": str(tmp_path / "calls2.log")})
    assert fresh.read_bytes() == out.read_bytes()
    # a complete sweep resumes with nothing to do
    log.unlink()
    sweep.grid(counted, params, out=out, executor=SerialExecutor(), progress=False,
               fixed={"log": str(log)})
    assert not log.exists()


def test_resume_with_other_parameters_is_refused(tmp_path):
    out = tmp_path / "m.csv"
    sweep.grid(product, {"a": [1, 2], "b": [3]}, out=out, executor=SerialExecutor(), progress=False)
    with pytest.raises(ValueError, match="describes another sweep: 'parameters'"):
        sweep.grid(product, {"a": [1, 2, 3], "b": [3]}, out=out, executor=SerialExecutor(), progress=False)


def test_retry_failed_reruns_only_failed_cells(tmp_path):
    out = tmp_path / "m.csv"
    with pytest.warns(RuntimeWarning):
        sweep.grid(sometimes_fails, {"x": [1, 2]}, out=out, executor=SerialExecutor(), progress=False)
    with pytest.warns(RuntimeWarning):  # kept, not rerun
        table = sweep.grid(sometimes_fails, {"x": [1, 2]}, out=out, executor=SerialExecutor(), progress=False)
    assert table["status"].tolist() == ["ok", "failed"]
    with pytest.warns(RuntimeWarning, match="1 of 2 cells failed"):
        sweep.grid(sometimes_fails, {"x": [1, 2]}, out=out, executor=SerialExecutor(), progress=False,
                   retry_failed=True)


KILL_SCRIPT = textwrap.dedent(
    """
    import sys, concurrent.futures as cf
    sys.path.insert(0, {tests!r})
    from nscd import sweep
    from test_sweep import slow_square
    sweep.grid(slow_square, {{"x": list(range(12))}}, out={out!r}, fixed={{"delay": 0.15}},
               executor=cf.ProcessPoolExecutor(2), progress=False)
    """
)


def test_resume_after_sigkill_of_a_real_process(tmp_path):
    out = tmp_path / "m.csv"
    script = KILL_SCRIPT.format(tests=str(Path(__file__).parent), out=str(out))
    proc = subprocess.Popen([sys.executable, "-c", script], start_new_session=True)
    try:
        deadline = time.monotonic() + 30  # generous: interpreter start-up on a loaded 2-core machine
        while time.monotonic() < deadline:
            if out.exists() and len(out.read_text().splitlines()) >= 4:
                break
            time.sleep(0.02)
        else:
            pytest.fail("the sweep did not write 3 cells in 30 s")
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the whole group: the sweep and its workers
        proc.wait()
    kept = Table.from_csv(out)
    assert 3 <= len(kept) < 12
    # the resumed sweep must use the same description (delay 0.15): only missing cells are computed
    table = sweep.grid(slow_square, {"x": list(range(12))}, out=out, fixed={"delay": 0.15},
                       executor=cf.ProcessPoolExecutor(2), progress=False)
    assert table["square"].tolist() == [x * x for x in range(12)]
    assert table["cell"].tolist() == list(range(12))


# ----------------------------------------------------------------- bad input


@pytest.mark.parametrize(
    ("params", "match"),
    [
        ({}, "params == {}"),
        ({"a": []}, "parameter 'a' has no values"),
        ({"a": 3}, "parameter 'a' == 3, must be a list"),
        ({"a": "abc"}, "parameter 'a' == 'abc', must be a list"),
        ({"a": np.zeros((2, 2))}, r"parameter 'a': values have shape \(2, 2\)"),
        ({"status": [1]}, "reserved"),
    ],
)
def test_bad_grids_name_the_parameter(params, match):
    with pytest.raises(ValueError, match=match):
        sweep.grid(product, params, executor=SerialExecutor(), progress=False)


def test_swept_and_fixed_at_once_is_refused():
    with pytest.raises(ValueError, match="'a' is both swept and in fixed"):
        sweep.grid(product, {"a": [1]}, fixed={"a": 2, "b": 1}, executor=SerialExecutor(), progress=False)


# ----------------------------------------------------------------- Table


def test_table_columns_and_pivot():
    table = Table([{"x": 1, "y": 0.5, "mode": "A"}, {"x": 2, "y": 0.5, "mode": "B_L"},
                   {"x": 1, "y": 1.5, "mode": "D_R"}])
    assert table["x"].dtype == np.int64 and table["y"].dtype == float and table["mode"].dtype == object
    xs, ys, modes = table.pivot("mode", x="x", y="y")
    assert xs.tolist() == [1, 2] and ys.tolist() == [0.5, 1.5]
    assert modes.tolist() == [["A", "B_L"], ["D_R", None]]
    assert len(table.where(mode="A")) == 1


# ----------------------------------------------------------------- Dask


def test_dask_local_cluster_gives_the_same_files(tmp_path):
    distributed = pytest.importorskip("distributed")
    params = {"a": [1, 2, 3], "b": [0.5, 0.25]}
    sweep.grid(product, params, out=tmp_path / "serial.csv", executor=SerialExecutor(), progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        table = sweep.grid(product, params, out=tmp_path / "dask.csv", executor=client.get_executor(),
                           progress=False)
    assert table["product"].tolist() == [a * b for a in params["a"] for b in params["b"]]
    assert (tmp_path / "serial.csv").read_bytes() == (tmp_path / "dask.csv").read_bytes()


def test_progress_without_tqdm_writes_a_counter_to_stderr(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "tqdm", None)  # import tqdm -> ImportError
    monkeypatch.setitem(sys.modules, "tqdm.auto", None)
    sweep.run(slow_square, [{"x": 1}, {"x": 2}], executor=SerialExecutor(), progress=True)
    err = capsys.readouterr().err
    assert "2/2 cells" in err and "left" in err
    sweep.run(slow_square, [{"x": 1}], executor=SerialExecutor(), progress=False)
    assert capsys.readouterr().err == ""


class CancellingExecutor(cf.Executor):
    """Accepts tasks and cancels them (as a cluster shutting down would)."""

    def submit(self, fn, /, *args, **kwargs):
        future = cf.Future()
        future.cancel()
        future.set_running_or_notify_cancel()  # what a real executor does: wakes up waiters
        return future


def test_cancelled_tasks_stop_the_sweep_and_keep_finished_cells(tmp_path):
    with pytest.raises(RuntimeError, match="CancellingExecutor broke while running case 0.*CancelledError"):
        sweep.grid(product, {"a": [1, 2], "b": [3]}, out=tmp_path / "m.csv", executor=CancellingExecutor(),
                   progress=False)
    assert (tmp_path / "m.csv").read_text() == "cell,a,b,status,error,check\n"  # header only, nothing invented


# ----------------------------------------------------------------- finished rows are never lost or replaced silently


def test_missing_description_refuses_to_overwrite_finished_rows(tmp_path):
    out = tmp_path / "m.csv"
    sweep.grid(product, {"a": [1, 2], "b": [3]}, out=out, executor=SerialExecutor(), progress=False)
    finished = out.read_bytes()
    (tmp_path / "m.csv.json").unlink()
    with pytest.raises(ValueError, match=r"m.csv.json \(the sweep's description\) is missing.*"
                                         r"resume=False \(CLI: --restart\)"):
        sweep.grid(product, {"a": [5, 6], "b": [3]}, out=out, executor=SerialExecutor(), progress=False)
    assert out.read_bytes() == finished
    table = sweep.grid(product, {"a": [5, 6], "b": [3]}, out=out, executor=SerialExecutor(), progress=False,
                       resume=False)  # the explicit restart
    assert table["product"].tolist() == [15.0, 18.0]


def test_other_description_message_is_short_and_names_the_restart(tmp_path):
    out = tmp_path / "m.csv"
    sweep.grid(product, {"a": list(range(50)), "b": [3]}, out=out, executor=SerialExecutor(), progress=False)
    with pytest.raises(ValueError, match=r"describes another sweep: 'parameters' differs; .*resume=False "
                                         r"\(CLI: --restart\)") as info:
        sweep.grid(product, {"a": list(range(51)), "b": [3]}, out=out, executor=SerialExecutor(), progress=False)
    assert len(str(info.value)) < 300  # not the parameter lists


def fresh_sweep(tmp_path, name="fresh.csv"):
    out = tmp_path / name
    sweep.grid(counted, {"a": [1, 2], "b": [4, 5, 6]}, out=out, executor=SerialExecutor(), progress=False,
               fixed={"log": str(tmp_path / f"{name}.log")})
    return out


@pytest.mark.parametrize("damage", ["cut inside the check, then a newline", "cut inside the last result",
                                    "an impossible status", "a value edited by hand"])
def test_a_damaged_row_is_recomputed_on_resume(tmp_path, damage):
    out, log = fresh_sweep(tmp_path, "m.csv"), tmp_path / "m.csv.log"
    log.unlink()
    lines = out.read_text().splitlines(keepends=True)
    assert lines[0] == "cell,a,b,status,error,sum,root,check\n"
    row = lines[3]  # cell 2: a = 1, b = 6
    damaged = {
        "cut inside the check, then a newline": row[:-4] + "\n",
        "cut inside the last result": row[: row.rindex(",") - 3] + "\n",
        "an impossible status": row.replace(",ok,", ",maybe,"),
        "a value edited by hand": row.replace(",7,", ",8,"),
    }[damage]
    assert damaged != row
    out.write_text("".join(lines[:3] + [damaged] + lines[4:]))
    with pytest.warns(RuntimeWarning, match="1 damaged row"):
        sweep.grid(counted, {"a": [1, 2], "b": [4, 5, 6]}, out=out, executor=SerialExecutor(), progress=False,
                   fixed={"log": str(log)})
    assert log.read_text().splitlines() == ["1,6"]  # that cell only
    assert out.read_bytes() == fresh_sweep(tmp_path).read_bytes()


def test_a_whole_row_of_another_grid_or_a_foreign_header_is_refused(tmp_path):
    out = fresh_sweep(tmp_path, "m.csv")
    lines = out.read_text().splitlines(keepends=True)
    row = {"cell": "17", "a": "1", "b": "4", "status": "ok", "error": "", "sum": "5", "root": "2.0"}
    row["check"] = sweep._checksum(row)
    out.write_text("".join(lines) + ",".join(row.values()) + "\n")
    with pytest.raises(ValueError, match=r"row with cell == '17', must be in \[0, 6\)"):
        sweep.grid(counted, {"a": [1, 2], "b": [4, 5, 6]}, out=out, executor=SerialExecutor(), progress=False,
                   fixed={"log": str(tmp_path / "m.csv.log")})
    out.write_text("cell,a,b,status,error,sum,root\n1,1,5,ok,,6,2.449\n")
    with pytest.raises(ValueError, match=r"'check' last .* pass resume=False \(CLI: --restart\)"):
        sweep.grid(counted, {"a": [1, 2], "b": [4, 5, 6]}, out=out, executor=SerialExecutor(), progress=False,
                   fixed={"log": str(tmp_path / "m.csv.log")})


def squares_batch(cases, on_result=None):
    """A batched cell function: ``on_result(k, row)`` as each case is done; a 'kill' (SystemExit)
    after NSCD_TEST_DIE_AFTER cases (in-process executors only); one line per case in its log."""
    rows = []
    for k, case in enumerate(cases):
        with open(case["log"], "a") as handle:
            handle.write(f"{case['x']}\n")
        rows.append({"square": case["x"] ** 2})
        if on_result is not None:
            on_result(k, rows[-1])
        die_after = os.environ.get("NSCD_TEST_DIE_AFTER")
        if die_after is not None and k + 1 >= int(die_after):
            raise SystemExit("simulated kill")
    return rows


def test_batched_cells_are_saved_as_they_finish(tmp_path, monkeypatch):
    out, log = tmp_path / "m.csv", tmp_path / "calls.log"
    params = {"x": [1, 2, 3, 4, 5, 6]}
    monkeypatch.setenv("NSCD_TEST_DIE_AFTER", "4")
    with pytest.raises(SystemExit):  # killed inside the one batched call, before it returned
        sweep.grid(squares_batch, params, out=out, executor=SerialExecutor(), progress=False, batch=True,
                   fixed={"log": str(log)})
    monkeypatch.delenv("NSCD_TEST_DIE_AFTER")
    assert len((tmp_path / "m.csv.cells").read_text().splitlines()) == 4  # the 4 finished cells are on disk
    log.unlink()
    table = sweep.grid(squares_batch, params, out=out, executor=SerialExecutor(), progress=False, batch=True,
                       fixed={"log": str(log)})
    assert log.read_text().splitlines() == ["5", "6"]  # only the cells not finished before the kill
    assert table["square"].tolist() == [x * x for x in params["x"]]
    assert not (tmp_path / "m.csv.cells").exists()
    fresh = tmp_path / "fresh.csv"
    sweep.grid(squares_batch, params, out=fresh, executor=SerialExecutor(), progress=False, batch=True,
               fixed={"log": str(tmp_path / "fresh.log")})
    assert fresh.read_bytes() == out.read_bytes()


ORPHAN_SCRIPT = textwrap.dedent(
    """
    import sys, concurrent.futures as cf
    sys.path.insert(0, {tests!r})
    from nscd import sweep
    from test_sweep import slow_square
    sweep.grid(slow_square, {{"x": list(range(40))}}, out={out!r}, fixed={{"delay": 0.5}},
               executor=cf.ProcessPoolExecutor(2), progress=False)
    """
)


def _children(pid: int) -> list[int]:
    found = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
                found.append(int(entry.name))
    return found


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"  # a zombie has exited (only its exit status waits to be collected)


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads the process table in /proc")
def test_pool_workers_exit_when_the_sweep_is_killed(tmp_path):
    out = tmp_path / "m.csv"
    script = ORPHAN_SCRIPT.format(tests=str(Path(__file__).parent), out=str(out))
    proc = subprocess.Popen([sys.executable, "-c", script], start_new_session=True)
    try:
        deadline = time.monotonic() + 60  # interpreter start-up on a loaded 2-core machine
        while time.monotonic() < deadline and not (out.exists() and len(out.read_text().splitlines()) >= 2):
            time.sleep(0.05)
        workers = [pid for pid in _children(proc.pid) if _alive(pid)]
        assert workers, "the sweep started no worker process"
        os.kill(proc.pid, signal.SIGKILL)  # the sweep only: its workers must notice by themselves
        proc.wait()
        deadline = time.monotonic() + 10  # the watch looks every 0.5 s; room for a loaded machine
        while time.monotonic() < deadline and any(_alive(pid) for pid in workers):
            time.sleep(0.1)
        assert not [pid for pid in workers if _alive(pid)]
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


def test_progress_bar_carries_the_label_given(capsys):
    """The bar says what runs (a map names its rig), not only the function's name."""
    sweep.grid(product, {"a": [1, 2], "b": [3]}, executor=SerialExecutor(), desc="products of a and b")
    assert "products of a and b" in capsys.readouterr().err
    sweep.grid(product, {"a": [1, 2], "b": [3]}, executor=SerialExecutor())
    assert "product" in capsys.readouterr().err
