"""Overturning maps of the double-pulse rig (002, Figures 9-21), with matplotlib.

* :func:`mode_map`: one marker per cell, shaped and coloured by mode, over the
  stop gap BD (cm) and the peak base velocity (m/s), as 002's Figures 9-12, 16-19;
* :func:`scaled_map`: several maps (scales 1 and 2) on the scaled axes of 002's
  Figures 13, 14, 20, 21: excitation period times Housner's p, and input kinetic
  energy; red where something overturned, blue where all stood; filled markers for
  the first map, empty for the next;
* :func:`probability_map`: an ensemble map (``DoublePulseRig.ensemble`` cells),
  shaded by the probability of overturning, with the most likely mode's marker.

Each takes a :class:`nscd.sweep.Table` (as returned by :func:`nscd.sweep.grid` or
read by ``Table.from_csv``), draws on ``ax`` (or on new axes of a new figure, made
without pyplot so it works headless) and returns the matplotlib ``Figure``, as the
rest of :mod:`nscd.plot`; save with ``fig.savefig("map.png")``. matplotlib is
imported only when a function is called.
"""
from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from nscd.rigs import MODES
from nscd.sweep import Table

__all__ = ["MODE_STYLE", "MODE_TEXT", "mode_map", "scaled_map", "probability_map"]

#: marker and colour of each mode: colour by what fell (B top, C two upper, D all),
#: marker by the side (< left, > right).
MODE_STYLE: dict[str, dict[str, str]] = {
    "A": {"marker": "o", "color": "tab:blue"},
    "B_L": {"marker": "<", "color": "tab:orange"},
    "B_R": {"marker": ">", "color": "tab:orange"},
    "C_L": {"marker": "<", "color": "tab:green"},
    "C_R": {"marker": ">", "color": "tab:green"},
    "D_L": {"marker": "<", "color": "tab:red"},
    "D_R": {"marker": ">", "color": "tab:red"},
}
_FAILED_STYLE = {"marker": "x", "color": "black"}
#: ring drawn around a cell whose outcome changed at dt/2 (``converged`` column False)
_UNCONVERGED_STYLE = {"marker": "s", "facecolors": "none", "edgecolors": "black", "linewidths": 1.5}

#: What each mode code means (seed 002; :func:`nscd.rigs.classify`): the letter names the
#: lowest block that fell, the suffix the side (L: toward -x, where the first impulse throws it).
MODE_TEXT: dict[str, str] = {
    "A": "A: none falls",
    "B_L": "B_L: top (or only) block falls, left", "B_R": "B_R: top (or only) block falls, right",
    "C_L": "C_L: upper two fall, left", "C_R": "C_R: upper two fall, right",
    "D_L": "D_L: all fall, left", "D_R": "D_R: all fall, right",
}


def _axes(ax: Any) -> Any:
    if ax is not None:
        return ax
    from matplotlib.figure import Figure

    return Figure(figsize=(7.5, 4.5), layout="constrained").add_subplot()


def _ok(table: Table) -> tuple[Table, Table]:
    """Rows that finished, rows that failed (``status`` column of a sweep; all ok without it)."""
    if "status" not in table.names:
        return table, Table([])
    return table.where(status="ok"), table.where(status="failed")


def mode_map(table: Table, *, ax: Any = None, x: str = "gap", y: str = "v_peak", mode: str = "mode",
             title: str | None = None, markersize: float = 40.0) -> Any:
    """Markers per mode over stop gap (cm) and peak base velocity (m/s).

    Parameters
    ----------
    table : Table
        Columns ``x`` (stop gap, m), ``y`` (peak velocity, m/s) and ``mode``
        (one of :data:`nscd.rigs.MODES`); failed cells (``status == "failed"``)
        are drawn as black crosses. With a ``converged`` column (a map run with
        ``verify_dt=True``, :func:`nscd.convergence.verify_time_step`), cells whose
        outcome changed at dt/2 get a black square ring, labelled "unconverged".
    ax : matplotlib Axes, optional
    x, y, mode : str
        Column names.
    title : str, optional
    markersize : float
        Marker area, points^2.

    Returns
    -------
    matplotlib Figure
    """
    ax = _axes(ax)
    done, failed = _ok(table)
    for name in MODES:
        cells = done.where(**{mode: name})
        if len(cells):
            ax.scatter(100.0 * cells[x], cells[y], s=markersize, label=MODE_TEXT[name], **MODE_STYLE[name])
    unknown = sorted(set(done[mode].tolist()) - set(MODES)) if len(done) else []
    if unknown:
        raise ValueError(f"column {mode!r} holds {unknown}, not modes of nscd.rigs.MODES {MODES}.")
    if len(failed):
        ax.scatter(100.0 * failed[x], failed[y], s=markersize, label="failed", **_FAILED_STYLE)
    if "converged" in done.names:
        unconverged = done.where(converged=False)
        if len(unconverged):
            ax.scatter(100.0 * unconverged[x], unconverged[y], s=3.0 * markersize, label="unconverged",
                       **_UNCONVERGED_STYLE)
    ax.set_xlabel("stop gap BD (cm)")
    ax.set_ylabel("peak base velocity $v_{peak}$ (m/s)")
    if title:
        ax.set_title(title)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), title="mode", frameon=False)
    return ax.figure


def scaled_map(tables: Sequence[Table], rigs: Sequence[Any], labels: Sequence[str] | None = None, *,
               ax: Any = None, title: str | None = None, markersize: float = 40.0) -> Any:
    """Maps of several scales on the scaled axes of 002 (Figures 13, 14, 20, 21).

    x: ``p * T_d`` (Housner's p of the specimen's outline times the excitation
    period, :meth:`DoublePulseRig.scaled`); y: input kinetic energy ``m v_peak^2 / 2``
    (J). Red: some block overturned; blue: all stood. Filled markers for the first
    table, empty markers for the others (as 002: scale 1 filled, scale 2 empty),
    with a different marker shape per table.

    Parameters
    ----------
    tables : sequence of Table
        Map tables with ``gap``, ``v_peak`` and ``mode`` columns.
    rigs : sequence of DoublePulseRig
        The rig of each table (its scale, specimen, rise time give the axes).
    labels : sequence of str, optional
        Legend label per table; default ``"scale <s>"``.
    """
    if len(tables) != len(rigs) or not tables:
        raise ValueError(f"tables and rigs have lengths {len(tables)} and {len(rigs)}; "
                         "give one rig per table, at least one.")
    labels = list(labels) if labels is not None else [f"scale {rig.scale:g}" for rig in rigs]
    ax = _axes(ax)
    shapes = "os^Dv"
    for k, (table, rig, label) in enumerate(zip(tables, rigs, labels)):
        done, _ = _ok(table)
        if not len(done):
            continue
        coords = np.array([rig.scaled(v, g) for g, v in zip(done["gap"], done["v_peak"])])
        fell = done["mode"] != "A"
        for mask, colour, what in ((fell, "tab:red", "overturning"), (~fell, "tab:blue", "no overturning")):
            if not mask.any():
                continue
            face = colour if k == 0 else "none"
            ax.scatter(coords[mask, 0], coords[mask, 1], s=markersize, marker=shapes[k % len(shapes)],
                       facecolors=face, edgecolors=colour, label=f"{label}: {what}")
    ax.set_xlabel("scaled excitation period $p\\,T_d$ (-)")
    ax.set_ylabel("input kinetic energy $m v_{peak}^2/2$ (J)")
    ax.set_yscale("log")
    if title:
        ax.set_title(title)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)
    return ax.figure


def probability_map(table: Table, *, ax: Any = None, x: str = "gap", y: str = "v_peak",
                    title: str | None = None, markersize: float = 40.0) -> Any:
    """Ensemble map: shading by the probability of overturning, marker of the likeliest mode.

    Parameters
    ----------
    table : Table
        Columns ``x`` (m), ``y`` (m/s), ``mode`` (the likeliest mode) and ``p_A``
        (share of members where everything stood), as written by a sweep of
        :meth:`DoublePulseRig.ensemble`.
    """
    ax = _axes(ax)
    done, failed = _ok(table)
    if "p_A" not in done.names:
        raise ValueError("table has no column 'p_A': sweep DoublePulseRig.ensemble, not run.")
    xs, ys, p_stand = done.pivot("p_A", x=x, y=y)
    mesh = ax.pcolormesh(100.0 * _edges(xs), _edges(ys), 1.0 - p_stand, cmap="Greys", vmin=0.0, vmax=1.0,
                         alpha=0.6, shading="flat")
    ax.figure.colorbar(mesh, ax=ax, label="probability of overturning")
    mode_map(Table(done.rows + failed.rows), ax=ax, x=x, y=y, markersize=markersize)
    if title:
        ax.set_title(title)
    return ax.figure


def _edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges around sorted cell centres (midpoints; half a spacing beyond the ends)."""
    centres = np.asarray(centres, dtype=float)
    if centres.size == 1:
        return centres + np.array([-0.5, 0.5]) * max(abs(centres[0]) * 0.1, 1e-3)
    mid = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([[2 * centres[0] - mid[0]], mid, [2 * centres[-1] - mid[-1]]])
