"""One sweep runner for many independent simulations, over any executor.

``run`` maps a function over a list of keyword-argument dicts; ``grid`` runs
it over the cartesian product of parameter values and writes a resumable,
deterministic CSV file. Both take any :class:`concurrent.futures.Executor`:

* ``executor=None`` (default): a local :class:`~concurrent.futures.ProcessPoolExecutor`
  over ``os.cpu_count()`` workers, created and shut down inside the call;
* :class:`SerialExecutor`: everything in the calling process, in order (debugging,
  profiling, ``--jobs 1``);
* a Dask cluster: ``dask.distributed.Client(...).get_executor()`` (optional
  extra ``distributed``).

``func`` must be picklable for process pools: a module-level function or a
bound method of a picklable object (e.g. :meth:`nscd.rigs.DoublePulseRig.run`).

Progress
--------
With ``progress=True`` a bar with the cells done and the estimated time left
goes to standard error: ``tqdm`` when it is installed (optional extra
``progress``), otherwise a plain counter, redrawn in place on a terminal and
printed every 10 % of the cells when standard error is not a terminal (log
files stay short). ``progress=False`` shows nothing.

Files written by ``grid(..., out="map.csv")``
---------------------------------------------
``map.csv``
    One row per cell. Columns: ``cell`` (index in the grid order), the
    parameters in the order given, ``status`` (``ok`` or ``failed``),
    ``error`` (``ExceptionType: message`` of a failed cell, empty otherwise),
    then the result fields, and last ``check``, the CRC-32 of the row's other
    fields. Rows are appended (one write each) and ``fsync``-ed as cells finish,
    so a killed sweep keeps every finished cell; when the sweep is complete the
    file is rewritten in cell order, so the same sweep always gives
    byte-identical files, whatever the executor or the order of completion.
    Every whole-file write is atomic (:mod:`nscd._atomic`).
``map.csv.json``
    The sweep's description: parameters, fixed arguments, function name,
    settings of the object a bound method belongs to (its ``to_dict()``, when it
    has one), nscd version, cell order. A rerun with the same description resumes:
    the cells already in the CSV (``ok`` or ``failed``) are skipped unless
    ``retry_failed=True``.
``map.csv.cells``
    Batched sweeps only, while they run: one JSON line per cell finished inside a
    batched call whose ``func`` accepts ``on_result`` (moved into the CSV as the
    sweep goes; removed at the end).

Resuming never loses or silently replaces finished rows: every row is checked
(all columns present, ``check`` matching, a valid status, the cell index and
parameter values of this grid); a row cut by a crash is dropped with a warning
and its cell computed again. A CSV with finished rows is never overwritten
without ``resume=False`` (``nscd map --restart``): not when its description
differs, and not when the ``.json`` description is missing.

Workers of a process pool end with the sweep: a worker whose parent process
dies (even by SIGKILL) exits within ``_WATCH_PERIOD`` s instead of computing on
as an orphan.
"""
from __future__ import annotations

import concurrent.futures as cf
import csv
import dataclasses
import inspect
import io
import itertools
import json
import logging
import math
import numbers
import os
import pickle
import queue
import sys
import threading
import time
import warnings
import zlib
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from nscd import _atomic

__all__ = ["SerialExecutor", "SweepMismatchError", "Table", "grid", "run"]

logger = logging.getLogger(__name__)

#: Columns written by ``grid`` before and after the parameters, and last; reserved names.
CELL, STATUS, ERROR, CHECK = "cell", "status", "error", "check"
_RESERVED = (CELL, STATUS, ERROR, CHECK)
OK, FAILED = "ok", "failed"

#: Seconds between two looks of a worker at its parent process, and of a sweep at the cells a
#: batched call has finished so far.
_WATCH_PERIOD = 0.5


class SweepMismatchError(ValueError):
    """``out`` of :func:`grid` holds another sweep than the one asked for.

    Attributes
    ----------
    path : Path
        The JSON description of the sweep in the file.
    key : str
        The first field of the description that differs (``"parameters"``, ...).
    in_file, now
        That field's value in the file and in the call.
    """

    def __init__(self, message: str, path: Path, key: str, in_file: Any, now: Any) -> None:
        super().__init__(message)
        self.path, self.key, self.in_file, self.now = path, key, in_file, now


# --------------------------------------------------------------------------- executors


class SerialExecutor(cf.Executor):
    """An executor that runs each task at once, in the calling process.

    Results are identical to a process pool's; useful for debugging (breakpoints
    and tracebacks work), for profiling and for ``--jobs 1``. Exceptions that are
    not ``Exception`` (KeyboardInterrupt, SystemExit) propagate at once.
    """

    def submit(self, fn: Callable, /, *args: Any, **kwargs: Any) -> cf.Future:
        future: cf.Future = cf.Future()
        try:
            future.set_result(fn(*args, **kwargs))
        except Exception as exc:  # handed to the caller through the future, like a pool does
            future.set_exception(exc)
        return future


def _call(func: Callable, kwargs: dict[str, Any], parent: int) -> Any:
    """Worker-side call ``func(**kwargs)`` (module level, so it pickles).

    ``parent`` is the process id of the sweep; in another process (a pool's worker) the
    worker first arranges to end with its parent (:func:`_end_with_parent`), and its batches
    step in one thread (``NSCD_THREADS``, :func:`nscd.batch.default_threads`) unless set.
    """
    if os.getpid() != parent:
        _end_with_parent()
        # the pool spreads the calls over the cores: a batch in a worker steps in one thread
        os.environ.setdefault("NSCD_THREADS", "1")
    return func(**kwargs)


_watching = threading.Event()


def _end_with_parent() -> None:
    """Exit this worker process as soon as its parent process dies (idempotent).

    A process pool's workers otherwise outlive a sweep killed by SIGKILL (its shutdown code
    never runs) and go on computing for nobody. A daemon thread polls ``os.getppid()`` every
    ``_WATCH_PERIOD`` s: when the parent dies the worker is re-parented (the id changes) and
    exits at once. Portable, unlike Linux's ``PR_SET_PDEATHSIG``, which also fires when the
    parent *thread* that started the worker ends.
    """
    if _watching.is_set():
        return
    _watching.set()
    threading.Thread(target=_exit_when_orphaned, args=(os.getppid(),), name="nscd-parent-watch",
                     daemon=True).start()


def _exit_when_orphaned(parent: int) -> None:
    while os.getppid() == parent:
        time.sleep(_WATCH_PERIOD)
    os._exit(1)  # no clean-up: the parent that would use this worker's results is gone


def _check_picklable(func: Callable) -> None:
    try:
        pickle.dumps(func)
    except Exception as exc:  # pickle raises several types (PicklingError, AttributeError, TypeError)
        raise TypeError(
            f"func {func!r} cannot be pickled for a process pool ({exc}); use a module-level "
            "function or a bound method of a picklable object, or executor=SerialExecutor()."
        ) from exc


# --------------------------------------------------------------------------- progress


class _LineProgress:
    """Plain progress counter on stderr when tqdm is not installed."""

    def __init__(self, total: int, desc: str) -> None:
        self.total, self.desc, self.done = total, desc, 0
        self.start = time.monotonic()
        self.tty = sys.stderr.isatty()
        self._last_decile = -1

    def update(self, n: int = 1) -> None:
        self.done += n
        elapsed = time.monotonic() - self.start
        left = elapsed / self.done * (self.total - self.done)
        line = f"{self.desc}: {self.done}/{self.total} cells, {_hms(elapsed)} elapsed, {_hms(left)} left"
        if self.tty:
            sys.stderr.write("\r" + line)
        else:
            decile = 10 * self.done // self.total
            if decile == self._last_decile:
                return
            self._last_decile = decile
            sys.stderr.write(line + "\n")
        sys.stderr.flush()

    def close(self) -> None:
        if self.tty and self.done:
            sys.stderr.write("\n")
            sys.stderr.flush()


class _NoProgress:
    def update(self, n: int = 1) -> None:
        pass

    def close(self) -> None:
        pass


def _hms(seconds: float) -> str:
    seconds = int(round(seconds))
    return f"{seconds // 3600:d}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


def _progress_bar(progress: bool, total: int, desc: str):
    if not progress or total == 0:
        return _NoProgress()
    try:
        from tqdm.auto import tqdm
    except ImportError:
        return _LineProgress(total, desc)
    return tqdm(total=total, desc=desc, unit="cell", file=sys.stderr)


# --------------------------------------------------------------------------- execution core


def _finished_futures(finished: queue.SimpleQueue, timeout: float | None) -> list[cf.Future]:
    """The futures put on ``finished`` so far, after waiting up to ``timeout`` s (None: for ever)
    for the first one; an empty list when none finished in time."""
    try:
        done = [finished.get(timeout=timeout)]
    except queue.Empty:
        return []
    while True:
        try:
            done.append(finished.get_nowait())
        except queue.Empty:
            return done


def _execute(
    func: Callable,
    cases: Sequence[Mapping[str, Any]],
    executor: cf.Executor | None,
    progress: bool,
    desc: str,
    sizes: Sequence[int] | None = None,
    poll: Callable[[], None] | None = None,
) -> Iterator[tuple[int, cf.Future]]:
    """Submit ``func(**case)`` for every case; yield ``(index, done_future)`` as they finish.

    The progress bar counts cells: case ``i`` stands for ``sizes[i]`` cells
    (default 1 each; a batched call runs several). ``poll()``, when given, is called
    every ``_WATCH_PERIOD`` s while the cases run.

    Raises ``RuntimeError`` when the executor refuses a task or breaks (a worker
    died); cell-level exceptions stay in the futures for the caller to handle.

    Finished futures reach this thread through a queue their done-callbacks feed, not
    through ``concurrent.futures.wait``: ``wait`` takes the lock of every pending future
    one after the other, and a Ctrl-C landing between two of those acquisitions leaves
    the first ones held by this thread for good, so the pool's manager thread blocks
    setting a result and the pool's shutdown never ends. Waiting on a queue holds no
    lock when the interrupt arrives.
    """
    if not cases:
        return
    own = executor is None
    if own:
        _check_picklable(func)
        executor = cf.ProcessPoolExecutor(max_workers=max(1, min(os.cpu_count() or 1, len(cases))))
    elif isinstance(executor, cf.ProcessPoolExecutor):
        _check_picklable(func)
    # SerialExecutor computes inside submit: submit one cell at a time so each is
    # yielded (and written) as soon as it is done; other executors get every cell at once.
    window = 1 if isinstance(executor, SerialExecutor) else max(1, len(cases))
    sizes = [1] * len(cases) if sizes is None else list(sizes)
    bar = _progress_bar(progress, sum(sizes), desc)
    pending: dict[cf.Future, int] = {}
    finished: queue.SimpleQueue[cf.Future] = queue.SimpleQueue()
    try:
        next_case = 0
        while next_case < len(cases) or pending:
            while next_case < len(cases) and len(pending) < window:
                case = cases[next_case]
                try:
                    future = executor.submit(_call, func, dict(case), os.getpid())
                except Exception as exc:
                    raise RuntimeError(
                        f"executor {type(executor).__name__} refused case {next_case} ({dict(case)!r}): "
                        f"{type(exc).__name__}: {exc}"
                    ) from exc
                pending[future] = next_case
                future.add_done_callback(finished.put)
                next_case += 1
            done = _finished_futures(finished, None if poll is None else _WATCH_PERIOD)
            if poll is not None:
                poll()
            for future in sorted(done, key=pending.__getitem__):
                index = pending.pop(future)
                exc = cf.CancelledError("cancelled by the executor") if future.cancelled() else future.exception()
                if isinstance(exc, (cf.BrokenExecutor, cf.CancelledError)):
                    raise RuntimeError(
                        f"executor {type(executor).__name__} broke while running case {index} "
                        f"({type(exc).__name__}: {exc}); finished cells are kept, rerun to resume."
                    ) from exc
                bar.update(sizes[index])
                yield index, future
    finally:
        bar.close()
        for future in pending:
            future.cancel()
        if own:
            executor.shutdown(wait=True, cancel_futures=True)


def run(
    func: Callable[..., Any],
    cases: Sequence[Mapping[str, Any]],
    executor: cf.Executor | None = None,
    progress: bool = True,
    desc: str | None = None,
) -> list[Any]:
    """Call ``func(**case)`` for every case, in parallel.

    Parameters
    ----------
    func : callable
        Picklable for process pools (module-level function, or bound method of
        a picklable object).
    cases : sequence of dict
        Keyword arguments of each call.
    executor : concurrent.futures.Executor, optional
        Default: a local process pool over ``os.cpu_count()`` workers, created
        and shut down inside. See the module docstring.
    progress : bool
        Progress bar on standard error.
    desc : str, optional
        Label of the progress bar (default: the function's name).

    Returns
    -------
    list
        ``func(**cases[i])`` at index ``i``.

    Raises
    ------
    RuntimeError
        If a call raised (the first failing case in case order is named; the
        original exception is chained), or the executor refused a task.
    """
    cases = list(cases)
    for index, case in enumerate(cases):
        if not isinstance(case, Mapping):
            raise TypeError(f"cases[{index}] == {case!r}, must be a dict of keyword arguments.")
    results: list[Any] = [None] * len(cases)
    errors: dict[int, BaseException] = {}
    for index, future in _execute(func, cases, executor, progress, desc or _name(func)):
        exc = future.exception()
        if exc is None:
            results[index] = future.result()
        else:
            errors[index] = exc
    if errors:
        first = min(errors)
        raise RuntimeError(
            f"{len(errors)} of {len(cases)} cases failed; first: case {first} ({dict(cases[first])!r}): "
            f"{type(errors[first]).__name__}: {errors[first]}"
        ) from errors[first]
    return results


# --------------------------------------------------------------------------- values <-> CSV text


def _scalar(value: Any, where: str) -> Any:
    """A Python scalar (None, bool, int, float, str) for ``value``, or TypeError."""
    if isinstance(value, np.generic):
        value = value.item()
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        return float(value)
    raise TypeError(f"{where} == {value!r} is not a scalar (None, bool, int, float or str).")


def _text(value: Any) -> str:
    """CSV text of a scalar: repr for floats (round-trips exactly), '' for None."""
    if value is None:
        return ""
    if isinstance(value, float):
        return repr(value)
    return str(value)


def _parse(text: str) -> Any:
    """Inverse of :func:`_text` (ints, floats, bools, None, else str)."""
    if text == "":
        return None
    if text in ("True", "False"):
        return text == "True"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def result_row(result: Any) -> dict[str, Any]:
    """The CSV fields of one cell's result.

    * an object with ``to_row()`` -> that dict;
    * a dataclass instance -> its fields;
    * a mapping -> its items;
    * a scalar -> ``{"value": result}``.

    Every field value must be a scalar (None, bool, int, float, str or a numpy
    scalar); ``TypeError`` names the first one that is not.
    """
    if hasattr(result, "to_row"):
        row = dict(result.to_row())
    elif dataclasses.is_dataclass(result) and not isinstance(result, type):
        row = {f.name: getattr(result, f.name) for f in dataclasses.fields(result)}
    elif isinstance(result, Mapping):
        row = dict(result)
    else:
        row = {"value": result}
    return {str(key): _scalar(value, f"result field {key!r}") for key, value in row.items()}


# --------------------------------------------------------------------------- Table


class Table:
    """Columns of a sweep's results, without pandas.

    Parameters
    ----------
    rows : iterable of dict
        One dict per row; missing fields become None.

    Attributes
    ----------
    rows : list of dict
        The rows, in order.
    names : list of str
        Column names, in order of first appearance.

    Notes
    -----
    ``table["v_peak"]`` is a numpy array: ``int64`` when every value is an int,
    ``float64`` (None -> nan) when every value is a number, ``object`` otherwise
    (strings, or mixed). ``table.pivot("mode", x="gap", y="v_peak")`` gives a 2D
    array ready for ``pcolormesh``/``scatter``.
    """

    def __init__(self, rows: Iterable[Mapping[str, Any]]) -> None:
        self.rows: list[dict[str, Any]] = [dict(row) for row in rows]
        names: dict[str, None] = {}
        for row in self.rows:
            names.update(dict.fromkeys(row))
        self.names: list[str] = list(names)

    def __len__(self) -> int:
        return len(self.rows)

    def __repr__(self) -> str:
        return f"Table({len(self)} rows, columns={self.names})"

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self.names:
            raise KeyError(f"no column {name!r}; columns are {self.names}")
        values = [row.get(name) for row in self.rows]
        present = [v for v in values if v is not None]
        numeric = all(isinstance(v, numbers.Real) and not isinstance(v, bool) for v in present)
        if present and numeric and len(present) == len(values) and all(isinstance(v, int) for v in values):
            return np.array(values, dtype=np.int64)
        if present and numeric:
            return np.array([np.nan if v is None else v for v in values], dtype=float)
        out = np.empty(len(values), dtype=object)
        out[:] = values
        return out

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """All columns as ``{name: array}``."""
        return {name: self[name] for name in self.names}

    def where(self, **equal: Any) -> "Table":
        """The rows whose columns equal the given values, e.g. ``table.where(status="ok")``."""
        return Table(row for row in self.rows if all(row.get(k) == v for k, v in equal.items()))

    def pivot(self, value: str, x: str, y: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Arrange a column over two parameters.

        Returns
        -------
        xs : ndarray, shape (nx,)
            Sorted distinct values of column ``x``.
        ys : ndarray, shape (ny,)
            Sorted distinct values of column ``y``.
        z : ndarray, shape (ny, nx)
            ``z[j, i]`` is ``value`` at ``(xs[i], ys[j])`` (None/nan where absent).
        """
        xs, ys, zs = self[x], self[y], self[value]
        ux, uy = np.unique(xs), np.unique(ys)
        out = np.full((uy.size, ux.size), np.nan if zs.dtype.kind in "fi" else None,
                      dtype=float if zs.dtype.kind in "fi" else object)
        out[np.searchsorted(uy, ys), np.searchsorted(ux, xs)] = zs
        return ux, uy, out

    def to_csv(self, path: str | os.PathLike | None = None) -> str:
        """Write the table as CSV (floats in round-trip precision); return the text."""
        text = _csv_text(self.names, [{k: _text(v) for k, v in row.items()} for row in self.rows])
        if path is not None:
            _atomic.write_text(path, text)
        return text

    @classmethod
    def from_csv(cls, path: str | os.PathLike) -> "Table":
        """Read a CSV written by :meth:`to_csv` or :func:`grid` (empty field -> None)."""
        with open(path, newline="") as handle:
            return cls({k: _parse(v) for k, v in row.items()} for row in csv.DictReader(handle))


def _csv_text(names: Sequence[str], rows: Iterable[Mapping[str, str]]) -> str:
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(names), lineterminator="\n", restval="")
    writer.writeheader()
    writer.writerows(rows)
    return buffer.getvalue()


def _csv_line(names: Sequence[str], row: Mapping[str, str]) -> str:
    """One CSV row (with its newline) under the columns ``names``."""
    buffer = io.StringIO()
    csv.DictWriter(buffer, fieldnames=list(names), lineterminator="\n", restval="").writerow(row)
    return buffer.getvalue()


def _checksum(row: Mapping[str, str]) -> str:
    """CRC-32 of a row's non-empty fields other than ``check``, as text ("0x" and 8 hex digits).

    Written as the last column, so a row cut anywhere by a crash (even inside its last
    value, then ended by a newline) fails it on resume and is computed again.
    """
    fields = sorted((k, v) for k, v in row.items() if k != CHECK and v not in ("", None))
    return f"0x{zlib.crc32(json.dumps(fields).encode()):08x}"


# --------------------------------------------------------------------------- grid


def _module(func: Callable) -> str:
    target = getattr(func, "func", func)  # functools.partial
    return getattr(target, "__module__", type(target).__module__)


def _name(func: Callable) -> str:
    target = getattr(func, "func", func)  # functools.partial
    module = getattr(target, "__module__", type(target).__module__)
    qualname = getattr(target, "__qualname__", type(target).__qualname__)
    return f"{module}.{qualname}"


def _settings(func: Callable) -> Any:
    owner = getattr(func, "__self__", None)
    settings = {}
    if owner is not None and callable(getattr(owner, "to_dict", None)):
        settings["object"] = owner.to_dict()
    if hasattr(func, "keywords"):  # functools.partial
        settings["partial_args"] = list(getattr(func, "args", ()))
        settings["partial_keywords"] = dict(func.keywords)
    return settings


def _validate_params(params: Mapping[str, Any], fixed: Mapping[str, Any]) -> dict[str, list]:
    if not isinstance(params, Mapping) or not params:
        raise ValueError(f"params == {params!r}, must be a non-empty dict of parameter name -> list of values.")
    out = {}
    for name, values in params.items():
        if not isinstance(name, str) or not name.isidentifier():
            raise ValueError(f"parameter name {name!r} must be a Python identifier (a keyword of func).")
        if name in _RESERVED:
            raise ValueError(f"parameter name {name!r} is reserved for a column; reserved: {_RESERVED}.")
        if name in fixed:
            raise ValueError(f"parameter {name!r} is both swept and in fixed.")
        if isinstance(values, np.ndarray):
            if values.ndim != 1:
                raise ValueError(f"parameter {name!r}: values have shape {values.shape}, must be 1-D.")
            values = values.tolist()
        if not isinstance(values, (list, tuple)):
            raise ValueError(f"parameter {name!r} == {values!r}, must be a list of values (not a {type(values).__name__}).")
        if len(values) == 0:
            raise ValueError(f"parameter {name!r} has no values; give at least one.")
        values = [_scalar(v, f"parameter {name!r} value") for v in values]
        for i, value in enumerate(values):
            if isinstance(value, float) and math.isnan(value):
                raise ValueError(f"parameter {name!r}: value {i} is nan; values must be numbers (not NaN), "
                                 "strings, booleans or None.")
            if value in values[:i]:
                raise ValueError(f"parameter {name!r}: value {value!r} is given twice (at {values.index(value)} "
                                 f"and {i}); give each value once.")
        out[name] = values
    return out


def _description(func: Callable, params: dict[str, list], fixed: dict[str, Any]) -> dict[str, Any]:
    from nscd import __version__

    description = {
        "function": _name(func),
        "settings": _settings(func),
        "parameters": params,
        "fixed": fixed,
        "order": "cartesian product, the first parameter varies slowest and the last fastest",
        "cells": math.prod(len(v) for v in params.values()),
        "nscd_version": __version__,
    }
    # normalise through JSON so a description compares equal to its file (tuples, reprs)
    return json.loads(json.dumps(description, default=repr))


def _json_text(description: Mapping[str, Any]) -> str:
    return json.dumps(description, indent=2, sort_keys=True) + "\n"


class _Journal:
    """The CSV being written: rows kept in memory (text), appended to the file as they come.

    Columns: ``leading`` (cell, parameters, status, error), the result fields in order of
    first appearance, ``check`` last.
    """

    def __init__(self, path: Path, leading: list[str]) -> None:
        self.path, self.leading = path, leading
        self.rows: dict[int, dict[str, str]] = {}
        self.names: list[str] = [*leading, CHECK]
        self.cell_log = path.with_name(path.name + ".cells")

    def start(self) -> None:
        """Begin a new sweep: a CSV with the header only, no cell log."""
        self._rewrite([])
        self.cell_log.unlink(missing_ok=True)

    def load(self, cells: list[dict[str, Any]]) -> None:
        """Keep the whole, consistent rows of an interrupted sweep (CSV and cell log).

        A row that is not whole (cut by a crash: missing fields, a wrong check, an
        impossible status) is dropped with a warning and its cell computed again. A whole
        row of another grid (cell index out of range, other parameter values) raises.
        """
        text = self.path.read_text(encoding="utf-8")
        if not text.endswith("\n"):  # last line cut by a kill: drop it (its cell is computed again)
            text = text[: text.rfind("\n") + 1]
        reader = csv.DictReader(io.StringIO(text))
        if reader.fieldnames is None:
            return
        names = list(reader.fieldnames)
        if names[: len(self.leading)] != self.leading or names[-1] != CHECK:
            raise ValueError(f"{self.path} has columns {names}, not {self.leading} first and {CHECK!r} last "
                             "(another program's file or an older nscd's); pass resume=False "
                             "(CLI: --restart) to overwrite it.")
        damaged = 0
        for row in itertools.chain(reader, self._logged()):
            whole = self._whole(row, cells)
            if whole is None:
                damaged += 1
            else:
                self.rows[whole[0]] = whole[1]
        if damaged:
            warnings.warn(f"{self.path}: {damaged} damaged row(s) (cut by a crash or edited) dropped; "
                          "their cells are computed again.", RuntimeWarning, stacklevel=3)
        found = dict.fromkeys(names[:-1])
        for cell in sorted(self.rows):  # result fields of rows only in the cell log
            found.update(dict.fromkeys(k for k in self.rows[cell] if k != CHECK))
        self.names = [*found, CHECK]
        self._rewrite(sorted(self.rows))
        self.cell_log.unlink(missing_ok=True)  # its rows are in the CSV now

    def _logged(self) -> Iterator[dict]:
        """Rows of the cell log (cells finished inside batched calls), whole lines only."""
        if not self.cell_log.exists():
            return
        for line in self.cell_log.read_text(encoding="utf-8").splitlines(keepends=True):
            try:
                row = json.loads(line) if line.endswith("\n") else None
            except json.JSONDecodeError:
                row = None
            yield row if isinstance(row, dict) else {None: line}

    def _whole(self, row: Mapping, cells: list[dict[str, Any]]) -> tuple[int, dict[str, str]] | None:
        """``(cell, row)`` of a whole row, None for a damaged one; ValueError for another grid's."""
        if not isinstance(row, Mapping) or None in row or any(not isinstance(v, str) for v in row.values()):
            return None  # wrong number of fields, or a log line that is not a row
        fields = {k: v for k, v in row.items() if v != "" or k in self.leading}
        if (any(k not in fields for k in self.leading) or fields.get(CHECK) != _checksum(fields)
                or fields[STATUS] not in (OK, FAILED) or (fields[STATUS] == FAILED) != (fields[ERROR] != "")):
            return None
        cell = _parse(fields[CELL])
        if not isinstance(cell, int) or not 0 <= cell < len(cells):
            raise ValueError(f"{self.path}: row with cell == {fields[CELL]!r}, must be in [0, {len(cells)}); "
                             "pass resume=False (CLI: --restart) to overwrite the file.")
        expected = {k: _text(v) for k, v in cells[cell].items()}
        if any(fields[k] != v for k, v in expected.items()):
            raise ValueError(f"{self.path}: cell {cell} has other parameter values than this grid's; "
                             "choose another out, or pass resume=False (CLI: --restart) to overwrite it.")
        return cell, fields

    def add(self, cell: int, row: dict[str, str]) -> None:
        """Record a finished cell and append its row to the file (fsync-ed)."""
        if self.rows.get(cell, {}).get(CHECK) == row[CHECK]:  # already there (a batched cell from the cell log)
            return
        self.rows[cell] = row
        new = [k for k in row if k not in self.names]
        if new:  # header grows: rewrite the file (happens at most a few times)
            self.names[-1:-1] = new
            self._rewrite(list(self.rows))
            return
        _atomic.append_line(self.path, _csv_line(self.names, row))

    def finish(self) -> None:
        """Rewrite in cell order with columns in order of first appearance in cell order."""
        names: dict[str, None] = dict.fromkeys(self.leading)
        for cell in sorted(self.rows):
            names.update(dict.fromkeys(self.rows[cell]))
        names.pop(CHECK, None)
        self.names = [*names, CHECK]
        self._rewrite(sorted(self.rows))
        self.cell_log.unlink(missing_ok=True)

    def _rewrite(self, order: list[int]) -> None:
        _atomic.write_text(self.path, _csv_text(self.names, (self.rows[c] for c in order)))


class _CellLog:
    """Given to a batched ``func`` as ``on_result``: appends each finished cell's row to the
    cell log (``out + ".cells"``, one JSON line per cell) from inside the worker, so a kill
    loses no finished cell. Best effort: a log that cannot be written (a remote worker
    without the folder) leaves the cells to the call's return value.
    """

    def __init__(self, path: Path, cell_ids: list[int], values: list[dict[str, Any]], leading: list[str]) -> None:
        self.path, self.cell_ids, self.values, self.leading = path, cell_ids, values, leading

    def __call__(self, k: int, result: Any) -> None:
        row = _row(self.cell_ids[k], self.values[k], result, None, self.leading)
        try:
            _atomic.append_line(self.path, json.dumps(row) + "\n")
        except OSError as exc:
            logger.warning("cell log %s not written (%s); cell %d is saved when its batch returns",
                           self.path, exc, self.cell_ids[k])


def _accepts_on_result(func: Callable) -> bool:
    try:
        return "on_result" in inspect.signature(func).parameters
    except (TypeError, ValueError):  # builtins without a signature
        return False


def grid(
    func: Callable[..., Any],
    params: Mapping[str, Sequence[Any]],
    out: str | os.PathLike | None = None,
    executor: cf.Executor | None = None,
    fixed: Mapping[str, Any] | None = None,
    progress: bool = True,
    resume: bool = True,
    retry_failed: bool = False,
    batch: bool = False,
    chunks: int | None = None,
    desc: str | None = None,
) -> Table:
    """Run ``func`` over the cartesian product of parameter values.

    Parameters
    ----------
    func : callable
        Called as ``func(**fixed, **cell)``; returns an object with ``to_row()``,
        a dataclass, a dict or a scalar (see :func:`result_row`), whose fields
        are scalars. Must be picklable for process pools.
    params : dict of str -> list
        Parameter name -> values (list, tuple or 1-D array, non-empty, no NaN, each
        value once). Cells are
        ordered as nested loops in the order given: the first parameter varies
        slowest, the last fastest (``itertools.product``).
    out : path, optional
        CSV file (and ``out + ".json"``); see the module docstring. Without it
        nothing is written and nothing can resume.
    executor : concurrent.futures.Executor, optional
        Default: a local process pool over all cores.
    fixed : dict, optional
        Keyword arguments passed unchanged to every call (recorded in the JSON).
    progress : bool
        Progress bar on standard error.
    desc : str, optional
        Label of the progress bar (default: the function's name).
    resume : bool
        Reuse the finished cells of ``out`` when its JSON description matches
        (default); a CSV with finished rows whose description differs or is
        missing raises ValueError. ``False`` starts afresh and overwrites ``out``.
    retry_failed : bool
        On resume, run again the cells recorded as failed.
    batch : bool
        ``func`` runs many cells in one call: ``func(cases)`` with ``cases`` a list of
        keyword dicts returns the list of their results, in order (e.g.
        :meth:`nscd.rigs.DoublePulseRig.run_batch`). The cells to run are dealt out to
        ``chunks`` calls (cell ``k`` to call ``k % chunks``, so each call gets a share of
        every region of the grid), submitted to the executor like single cells. A call
        that raises marks its unfinished cells failed. When ``func`` accepts an
        ``on_result`` keyword, it is given a callable ``on_result(k, result)`` to call as
        soon as case ``k`` is done: that cell is saved then, not when the call returns.
    chunks : int, optional
        Calls of a batched sweep (>= 1); default: one per worker (``os.cpu_count()`` for
        the default pool or another executor, the worker count of a
        ``ProcessPoolExecutor``, 1 for a :class:`SerialExecutor`).

    Returns
    -------
    Table
        One row per cell, in cell order, with the columns of the CSV (values as
        read back from CSV text, so a resumed sweep returns the same table).

    Raises
    ------
    ValueError
        Empty ``params``, a parameter with no values, NaN or repeated values, or whose
        values are not a list, a reserved or fixed name, an ``out`` in a missing folder,
        or an ``out`` with finished rows whose JSON describes another sweep or is missing.
    RuntimeError
        The executor refused a task or broke (finished cells are kept in ``out``).

    Notes
    -----
    A cell whose call raises is recorded with ``status == "failed"`` and the
    exception in ``error``; the sweep carries on and warns at the end.
    """
    fixed = dict(fixed or {})
    params = _validate_params(params, fixed)
    names = list(params)
    cells = [dict(zip(names, values)) for values in itertools.product(*params.values())]
    leading = [CELL, *names, STATUS, ERROR]
    description = _description(func, params, fixed)

    journal = None
    if out is not None:
        out = _atomic.check_writable(out, "out", create_folder=False)
        side = out.with_name(out.name + ".json")
        journal = _Journal(out, leading)
        if resume and out.exists():
            if side.exists():
                _check_same_sweep(side, description)
            elif _has_rows(out):
                raise ValueError(f"{out} holds finished rows but {side.name} (the sweep's description) is "
                                 "missing, so they cannot be checked against this sweep; restore it, or pass "
                                 "resume=False (CLI: --restart) to overwrite them.")
        if resume and side.exists() and out.exists():
            journal.load(cells)
        else:
            journal.start()
        _atomic.write_text(side, _json_text(description))
    rows: dict[int, dict[str, str]] = dict(journal.rows) if journal else {}

    todo = [i for i in range(len(cells))
            if i not in rows or (retry_failed and rows[i][STATUS] == FAILED)]
    if len(todo) < len(cells):
        logger.info("resuming %s: %d of %d cells already done", out, len(cells) - len(todo), len(cells))
    calls = [{**fixed, **cells[i]} for i in todo]
    groups = [[k] for k in range(len(calls))]
    follower = None
    if batch:
        count = _chunks(chunks, executor)
        groups = [list(range(j, len(calls), count)) for j in range(min(count, len(calls)))]
        calls = [{"cases": [calls[k] for k in group]} for group in groups]
        if journal is not None and _accepts_on_result(func):
            for call, group in zip(calls, groups):
                call["on_result"] = _CellLog(journal.cell_log, [todo[k] for k in group],
                                             [cells[todo[k]] for k in group], leading)
            follower = _LogFollower(journal, cells, rows)
    desc = desc or _name(func).removeprefix(_module(func) + ".")
    for j, future in _execute(func, calls, executor, progress, desc, [len(g) for g in groups],
                              follower and follower.poll):
        exc = future.exception()
        results = future.result() if exc is None and batch else [None if exc else future.result()]
        if exc is None and len(results) != len(groups[j]):
            exc = TypeError(f"func returned {len(results)} results for {len(groups[j])} cases.")
        for k, result in zip(groups[j], results if exc is None else [None] * len(groups[j])):
            cell = todo[k]
            if exc is not None and follower is not None and cell in follower.seen:
                continue  # finished before its batched call failed: its row is kept
            rows[cell] = row = _row(cell, cells[cell], result, exc, leading)
            if journal is not None:
                journal.add(cell, row)
    if journal is not None:
        journal.finish()

    failed = [c for c in sorted(rows) if rows[c][STATUS] == FAILED]
    if failed:
        warnings.warn(f"{len(failed)} of {len(cells)} cells failed (first: cell {failed[0]}: "
                      f"{rows[failed[0]][ERROR]}); see the status and error columns.",
                      RuntimeWarning, stacklevel=2)
    return Table({k: _parse(v) for k, v in rows[c].items()} for c in sorted(rows))


def _has_rows(path: Path) -> bool:
    """Whether a CSV file has anything after its header line."""
    with open(path, encoding="utf-8", errors="replace") as handle:
        handle.readline()
        return handle.read(1) != ""


class _LogFollower:
    """Moves the cells that batched calls have finished so far from the cell log into the CSV."""

    def __init__(self, journal: _Journal, cells: list[dict[str, Any]], rows: dict[int, dict[str, str]]) -> None:
        self.journal, self.cells, self.rows = journal, cells, rows
        self.offset = 0
        self.seen: set[int] = set()  # cells read from the log

    def poll(self) -> None:
        try:
            with open(self.journal.cell_log, "rb") as handle:
                handle.seek(self.offset)
                data = handle.read()
        except FileNotFoundError:
            return
        data = data[: data.rfind(b"\n") + 1]  # whole lines only; the rest is read next time
        self.offset += len(data)
        for line in data.decode("utf-8", errors="replace").splitlines():
            try:
                whole = self.journal._whole(json.loads(line), self.cells)
            except json.JSONDecodeError:
                whole = None
            if whole is not None:
                self.rows[whole[0]] = whole[1]
                self.seen.add(whole[0])
                self.journal.add(*whole)


def _chunks(chunks: int | None, executor: cf.Executor | None) -> int:
    """Number of calls of a batched sweep (see :func:`grid`)."""
    if chunks is None:
        if isinstance(executor, SerialExecutor):
            return 1
        if isinstance(executor, cf.ProcessPoolExecutor):
            return getattr(executor, "_max_workers", None) or os.cpu_count() or 1
        return os.cpu_count() or 1
    if isinstance(chunks, bool) or not isinstance(chunks, int) or chunks < 1:
        raise ValueError(f"chunks == {chunks!r}, must be an int >= 1.")
    return chunks


def _row(cell: int, values: Mapping[str, Any], result: Any, exc: BaseException | None,
         leading: list[str]) -> dict[str, str]:
    """The CSV row (text) of one cell: its parameters, status, error and result fields."""
    row = {CELL: str(cell), **{n: _text(v) for n, v in values.items()}}
    if exc is None:
        try:
            fields = result_row(result)
            clash = set(fields) & {*leading, CHECK}
            if clash:
                raise TypeError(f"result fields {sorted(clash)} clash with the columns {[*leading, CHECK]}.")
            row.update({STATUS: OK, ERROR: "", **{f: _text(v) for f, v in fields.items()}})
        except TypeError as bad:
            exc = bad
    if exc is not None:
        message = " ".join(f"{type(exc).__name__}: {exc}".split())
        row.update({STATUS: FAILED, ERROR: message})
    row[CHECK] = _checksum(row)
    return row


def _check_same_sweep(side: Path, description: dict[str, Any]) -> None:
    try:
        old = json.loads(side.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{side} is not valid JSON ({exc}); restore it, or pass resume=False "
                         "(CLI: --restart) to overwrite the sweep.") from exc
    first = ["function", "settings", "parameters", "fixed"]  # the most telling difference first
    for key in first + sorted((set(old) | set(description)) - set(first)):
        if key == "nscd_version":
            continue
        if old.get(key) != description.get(key):
            raise SweepMismatchError(
                f"{side} describes another sweep: {key!r} differs; choose another out, or pass resume=False "
                "(CLI: --restart) to overwrite its finished rows.", side, key, old.get(key), description.get(key))
    if old.get("nscd_version") != description["nscd_version"]:
        warnings.warn(f"resuming {side}: written by nscd {old.get('nscd_version')}, "
                      f"this is nscd {description['nscd_version']}.", RuntimeWarning, stacklevel=3)
