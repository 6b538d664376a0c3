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
    then the result fields. Rows are appended and flushed as cells finish (so a
    killed sweep keeps every finished cell); when the sweep is complete the file
    is rewritten in cell order, so the same sweep always gives byte-identical
    files, whatever the executor or the order of completion.
``map.csv.json``
    The sweep's description: parameters, fixed arguments, function name,
    settings of the object a bound method belongs to (its ``to_dict()``, when it
    has one), nscd version, cell order. A rerun with the same description resumes:
    the cells already in the CSV (``ok`` or ``failed``) are skipped unless
    ``retry_failed=True``. A different description raises ``ValueError``.
"""
from __future__ import annotations

import concurrent.futures as cf
import csv
import dataclasses
import io
import itertools
import json
import logging
import math
import numbers
import os
import pickle
import sys
import time
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["SerialExecutor", "SweepMismatchError", "Table", "grid", "run"]

logger = logging.getLogger(__name__)

#: Columns written by ``grid`` before and after the parameters; reserved names.
CELL, STATUS, ERROR = "cell", "status", "error"
_RESERVED = (CELL, STATUS, ERROR)
OK, FAILED = "ok", "failed"


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


def _call(func: Callable, kwargs: dict[str, Any]) -> Any:
    """Worker-side call ``func(**kwargs)`` (module level, so it pickles)."""
    return func(**kwargs)


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


def _execute(
    func: Callable,
    cases: Sequence[Mapping[str, Any]],
    executor: cf.Executor | None,
    progress: bool,
    desc: str,
    sizes: Sequence[int] | None = None,
) -> Iterator[tuple[int, cf.Future]]:
    """Submit ``func(**case)`` for every case; yield ``(index, done_future)`` as they finish.

    The progress bar counts cells: case ``i`` stands for ``sizes[i]`` cells
    (default 1 each; a batched call runs several).

    Raises ``RuntimeError`` when the executor refuses a task or breaks (a worker
    died); cell-level exceptions stay in the futures for the caller to handle.
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
    try:
        next_case = 0
        while next_case < len(cases) or pending:
            while next_case < len(cases) and len(pending) < window:
                case = cases[next_case]
                try:
                    pending[executor.submit(_call, func, dict(case))] = next_case
                except Exception as exc:
                    raise RuntimeError(
                        f"executor {type(executor).__name__} refused case {next_case} ({dict(case)!r}): "
                        f"{type(exc).__name__}: {exc}"
                    ) from exc
                next_case += 1
            done, _ = cf.wait(pending, return_when=cf.FIRST_COMPLETED)
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
    for index, future in _execute(func, cases, executor, progress, _name(func)):
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
            _atomic_write(Path(path), text)
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


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


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
        out[name] = [_scalar(v, f"parameter {name!r} value") for v in values]
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
    """The CSV being written: rows kept in memory (text), appended to the file as they come."""

    def __init__(self, path: Path, leading: list[str]) -> None:
        self.path, self.leading = path, leading
        self.rows: dict[int, dict[str, str]] = {}
        self.names: list[str] = list(leading)

    def load(self, cells: list[dict[str, Any]]) -> None:
        """Keep the complete, consistent rows of an interrupted sweep."""
        text = self.path.read_text()
        if not text.endswith("\n"):  # last line cut by a kill: drop it
            text = text[: text.rfind("\n") + 1]
        reader = csv.DictReader(io.StringIO(text))
        if reader.fieldnames is None:
            return
        names = list(reader.fieldnames)
        if names[: len(self.leading)] != self.leading:
            raise ValueError(f"{self.path} has columns {names}, expected to start with {self.leading}; "
                             "delete it or choose another out.")
        for row in reader:
            if None in row or None in row.values():  # wrong number of fields
                continue
            cell = _parse(row[CELL])
            if not isinstance(cell, int) or not 0 <= cell < len(cells):
                raise ValueError(f"{self.path}: row with cell == {row[CELL]!r}, must be in [0, {len(cells)}).")
            expected = {k: _text(v) for k, v in cells[cell].items()}
            if any(row[k] != v for k, v in expected.items()):
                raise ValueError(f"{self.path}: cell {cell} has parameters "
                                 f"{ {k: row[k] for k in expected} }, the grid has {expected}; "
                                 "delete the file or choose another out.")
            self.rows[cell] = {k: v for k, v in row.items() if v != "" or k in self.leading}
        self.names = names
        self._rewrite(sorted(self.rows))

    def add(self, cell: int, row: dict[str, str]) -> None:
        self.rows[cell] = row
        new = [k for k in row if k not in self.names]
        if new:  # header grows: rewrite the file (happens at most a few times)
            self.names += new
            self._rewrite(list(self.rows))
            return
        with open(self.path, "a", newline="") as handle:
            csv.DictWriter(handle, fieldnames=self.names, lineterminator="\n", restval="").writerow(row)
            handle.flush()
            os.fsync(handle.fileno())

    def finish(self) -> None:
        """Rewrite in cell order with columns in order of first appearance in cell order."""
        names: dict[str, None] = dict.fromkeys(self.leading)
        for cell in sorted(self.rows):
            names.update(dict.fromkeys(self.rows[cell]))
        self.names = list(names)
        self._rewrite(sorted(self.rows))

    def _rewrite(self, order: list[int]) -> None:
        _atomic_write(self.path, _csv_text(self.names, (self.rows[c] for c in order)))


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
) -> Table:
    """Run ``func`` over the cartesian product of parameter values.

    Parameters
    ----------
    func : callable
        Called as ``func(**fixed, **cell)``; returns an object with ``to_row()``,
        a dataclass, a dict or a scalar (see :func:`result_row`), whose fields
        are scalars. Must be picklable for process pools.
    params : dict of str -> list
        Parameter name -> values (list, tuple or 1-D array, non-empty). Cells are
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
    resume : bool
        Reuse the finished cells of ``out`` when its JSON description matches
        (default). ``False`` starts afresh and overwrites ``out``.
    retry_failed : bool
        On resume, run again the cells recorded as failed.
    batch : bool
        ``func`` runs many cells in one call: ``func(cases)`` with ``cases`` a list of
        keyword dicts returns the list of their results, in order (e.g.
        :meth:`nscd.rigs.DoublePulseRig.run_batch`). The cells to run are dealt out to
        ``chunks`` calls (cell ``k`` to call ``k % chunks``, so each call gets a share of
        every region of the grid), submitted to the executor like single cells. A call
        that raises marks all its cells failed.
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
        Empty ``params``, a parameter with no values or whose values are not a
        list, a reserved or fixed name, or an ``out`` whose JSON describes another sweep.
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
        out = Path(out)
        side = out.with_name(out.name + ".json")
        journal = _Journal(out, leading)
        if resume and side.exists() and out.exists():
            _check_same_sweep(side, description)
            journal.load(cells)
        else:
            _atomic_write(out, _csv_text(leading, []))
        _atomic_write(side, _json_text(description))
    rows: dict[int, dict[str, str]] = dict(journal.rows) if journal else {}

    todo = [i for i in range(len(cells))
            if i not in rows or (retry_failed and rows[i][STATUS] == FAILED)]
    if len(todo) < len(cells):
        logger.info("resuming %s: %d of %d cells already done", out, len(cells) - len(todo), len(cells))
    calls = [{**fixed, **cells[i]} for i in todo]
    groups = [[k] for k in range(len(calls))]
    if batch:
        count = _chunks(chunks, executor)
        groups = [list(range(j, len(calls), count)) for j in range(min(count, len(calls)))]
        calls = [{"cases": [calls[k] for k in group]} for group in groups]
    desc = _name(func).removeprefix(_module(func) + ".")
    for j, future in _execute(func, calls, executor, progress, desc, [len(g) for g in groups]):
        exc = future.exception()
        results = future.result() if exc is None and batch else [None if exc else future.result()]
        if exc is None and len(results) != len(groups[j]):
            exc = TypeError(f"func returned {len(results)} results for {len(groups[j])} cases.")
        for k, result in zip(groups[j], results if exc is None else [None] * len(groups[j])):
            cell = todo[k]
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
            clash = set(fields) & set(leading)
            if clash:
                raise TypeError(f"result fields {sorted(clash)} clash with the columns {leading}.")
            row.update({STATUS: OK, ERROR: "", **{f: _text(v) for f, v in fields.items()}})
        except TypeError as bad:
            exc = bad
    if exc is not None:
        message = " ".join(f"{type(exc).__name__}: {exc}".split())
        row.update({STATUS: FAILED, ERROR: message})
    return row


def _check_same_sweep(side: Path, description: dict[str, Any]) -> None:
    try:
        old = json.loads(side.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{side} is not valid JSON ({exc}); delete it and its CSV, or pass resume=False.") from exc
    first = ["function", "settings", "parameters", "fixed"]  # the most telling difference first
    for key in first + sorted((set(old) | set(description)) - set(first)):
        if key == "nscd_version":
            continue
        if old.get(key) != description.get(key):
            raise SweepMismatchError(
                f"{side} describes another sweep: {key!r} == {old.get(key)!r} in the file, "
                f"{description.get(key)!r} now; delete the files, choose another out, or pass resume=False.",
                side, key, old.get(key), description.get(key))
    if old.get("nscd_version") != description["nscd_version"]:
        warnings.warn(f"resuming {side}: written by nscd {old.get('nscd_version')}, "
                      f"this is nscd {description['nscd_version']}.", RuntimeWarning, stacklevel=3)
