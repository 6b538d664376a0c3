"""Figures of the 1-DOF rocking toolkit (matplotlib, imported inside the functions).

* :func:`time_history` -- ground acceleration, theta/alpha and theta_dot/p (seed 000 figs. 6-7, 12-13);
* :func:`overturning_spectrum` -- overturn / safe regions shaded, boundaries marked by mode
  (seed 000 figs. 5, 8, 11);
* :func:`rocking_curves` -- normalised peak responses against alpha, one line per R, overturned
  blocks circled (seed 001 figs. 4-5);
* :func:`rocking_spectrum` -- peak rotation and angular velocity against p (seed 000 figs. 23-24).

Each function draws on ``ax`` (or new axes) and returns the matplotlib ``Figure``.
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["time_history", "overturning_spectrum", "rocking_curves", "rocking_spectrum"]

#: Marker shape and colour of each overturning mode (seed 000: mode 1 without impact,
#: mode 2 after one impact; later modes grouped).
_MODE_MARKERS = {"mode 1": ("o", "tab:blue"), "mode 2": ("s", "tab:red"), "2+ impacts": ("^", "tab:green")}
_MODE_TEXT = {"mode 1": "mode 1: no impact", "mode 2": "mode 2: after one impact",
              "2+ impacts": "after two or more impacts"}
#: Fill of the marker for each kind of boundary along the amplitude (one encoding per meaning):
#: full where overturning starts, empty where it stops, half where the mode changes.
_KIND_FILL = {"overturn": {"fillstyle": "full"}, "safe": {"fillstyle": "none"},
              "mode": {"fillstyle": "bottom"}}
_KIND_TEXT = {"overturn": "overturning starts", "safe": "safe again above", "mode": "mode changes to"}


def _axes(ax, nrows: int = 1, **fig_kw):
    import matplotlib.pyplot as plt
    if ax is not None:
        return ax.figure, ax
    fig, ax = plt.subplots(nrows, 1, **fig_kw)
    return fig, ax


def time_history(result, motion=None, *, axes=None, title: str | None = None):
    """Ground acceleration (g), theta/alpha and theta_dot/p against time, stacked.

    Parameters
    ----------
    result : nscd.rocking.RockingResult
    motion : nscd.motion.Motion, optional
        The horizontal ground motion (top panel; omitted when None).
    axes : sequence of 3 Axes, optional
    title : str, optional
    """
    import matplotlib.pyplot as plt
    blk = result.block
    n = 3 if motion is not None else 2
    if axes is None:
        fig, axes = plt.subplots(n, 1, sharex=True, figsize=(6, 1.9 * n), constrained_layout=True)
    else:
        fig = axes[0].figure
    axes = list(np.atleast_1d(axes))
    t = result.time
    if motion is not None:
        tt = np.linspace(0.0, t[-1] if len(t) else 1.0, 2000)
        axes[0].plot(tt, np.asarray(motion.acceleration(tt)) / blk.g, color="0.3", lw=1)
        axes[0].set_ylabel(r"$\ddot u_g$ (g)")
    axes[-2].plot(t, result.theta / blk.alpha, color="tab:blue", lw=1)
    axes[-2].set_ylabel(r"$\theta/\alpha$")
    axes[-1].plot(t, result.theta_dot / blk.p, color="tab:orange", lw=1)
    axes[-1].set_ylabel(r"$\dot\theta/p$")
    axes[-1].set_xlabel("time (s)")
    for ax in axes:
        ax.axhline(0.0, color="0.8", lw=0.5)
    if len(result.impacts):
        axes[-2].plot(result.impacts.time, np.zeros(len(result.impacts)), "k|", ms=8, label="impact")
        axes[-2].legend(fontsize=7, loc="best", frameon=False)
    status = f"overturned ({result.mode})" if result.overturned else "no overturning"
    axes[0].set_title(title or status, fontsize=10)
    return fig


def overturning_spectrum(spec, *, ax=None, units: str = "alpha g", x: str = "wp/p", shade: bool = True,
                         label: str | None = None, marker_size: float = 9):
    """Overturning acceleration spectrum: overturn regions shaded, boundaries marked by mode.

    Parameters
    ----------
    spec : nscd.analysis.OverturningSpectrum
    ax : Axes, optional
    units : {"alpha g", "g"}
        Amplitude axis: a_p / (alpha g) (figs. 5, 11) or a_p / g (fig. 8).
    x : {"wp/p", "f"}
        Abscissa: omega_p / p, or the pulse frequency in Hz (fig. 8).
    shade : bool
        Shade the overturning region (grey) under the safe background.
    label : str, optional
        Legend prefix for the boundary markers (e.g. "linear").
    """
    if units not in ("alpha g", "g"):
        raise ValueError(f"units == {units!r}, must be 'alpha g' or 'g'.")
    if x not in ("wp/p", "f"):
        raise ValueError(f"x == {x!r}, must be 'wp/p' or 'f'.")
    fig, ax = _axes(ax, figsize=(6, 4.5), constrained_layout=True)
    blk = spec.block
    yscale = blk.alpha if units == "g" else 1.0
    xs = spec.wp_over_p * (blk.p / (2 * math.pi) if x == "f" else 1.0)
    if shade:  # one bar per wp/p and overturning interval, as wide as the spacing of the columns
        edges = np.concatenate(([xs[0]], 0.5 * (xs[1:] + xs[:-1]), [xs[-1]])) if len(xs) > 1 else np.array(
            [xs[0] * 0.95, xs[0] * 1.05])
        for i in range(len(xs)):
            for lo, hi in spec.overturn_intervals(i):
                ax.bar(0.5 * (edges[i] + edges[i + 1]), (hi - lo) * yscale, width=edges[i + 1] - edges[i],
                       bottom=lo * yscale, color="0.85", lw=0, zorder=0)
    drawn: dict[tuple[str, str], Any] = {}
    for xi, col in zip(xs, spec.boundaries):
        for b in col:
            mode = b.mode if b.mode in _MODE_MARKERS else "2+ impacts"
            marker, colour = _MODE_MARKERS[mode]
            handle = ax.plot(xi, b.value * yscale, marker, color=colour, mec=colour, ls="none",
                             ms=marker_size * 0.6, **_KIND_FILL[b.kind])[0]
            drawn.setdefault((b.kind, mode), handle)
    # one legend order for every panel: kind of boundary, then mode
    order = sorted(drawn, key=lambda key: (list(_KIND_FILL).index(key[0]), list(_MODE_MARKERS).index(key[1])))
    prefix = f"{label}: " if label else ""
    ax.legend([drawn[key] for key in order],
              [f"{prefix}{_KIND_TEXT[kind]} ({_MODE_TEXT[mode]})" for kind, mode in order],
              fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.13), ncol=2, frameon=False)
    ax.set_xlabel(r"$\omega_p/p$" if x == "wp/p" else "f (Hz)")
    ax.set_ylabel(r"$a_p/(\alpha g)$" if units == "alpha g" else r"$a_p$ (g)")
    ax.set_ylim(0.0, spec.amplitude_max * yscale)
    ax.set_xlim(0.0, xs.max())
    ax.text(0.03, 0.93, "Overturning area shaded", transform=ax.transAxes, fontsize=8, color="0.35")
    ax.set_title(rf"{spec.pulse} pulse, $\alpha$ = {blk.alpha:.3g} rad, $p$ = {blk.p:.3g} rad/s, "
                 rf"$\eta$ = {blk.eta:.3g}", fontsize=9)
    return fig


_QUANTITIES = {
    "theta": r"max $|\theta|/\alpha$",
    "theta_dot": r"max $|\dot\theta|/\dot\theta_r$",
    "energy": r"max $E/V_r$",
    "dissipated": r"$E_D/V_r$",
}


def rocking_curves(curves, quantity: str = "theta", *, ax=None, R_values=None, **line_kw: Any):
    """Rocking curves of seed 001: a normalised peak response against alpha, one line per R.

    Overturned blocks are drawn at their value (capped at the top of the axis) and circled.

    Parameters
    ----------
    curves : nscd.analysis.RockingCurves
    quantity : {"theta", "theta_dot", "energy", "dissipated"}
    R_values : sequence of float, optional
        Subset of R to draw (default all).
    """
    if quantity not in _QUANTITIES:
        raise ValueError(f"quantity == {quantity!r}, must be one of {sorted(_QUANTITIES)}.")
    fig, ax = _axes(ax, figsize=(6, 4), constrained_layout=True)
    values = getattr(curves, quantity)
    top = 3.0 if quantity != "dissipated" else max(1.0, float(np.nanmax(np.where(curves.overturned, 0, values))) * 1.1)
    for i, R in enumerate(curves.R):
        if R_values is not None and not np.any(np.isclose(R, R_values)):
            continue
        y = np.minimum(values[i], top)
        (line,) = ax.plot(curves.alpha, y, label=f"R = {R:g} m", **line_kw)
        o = curves.overturned[i]
        ax.plot(curves.alpha[o], y[o], "o", mfc="none", mec=line.get_color(), ms=8)
    ax.axhline(1.0, color="0.6", lw=0.7, ls="--")
    ax.set_xlabel(r"$\alpha$ (rad)")
    ax.set_ylabel(_QUANTITIES[quantity])
    ax.set_ylim(0.0, top * 1.02)
    ax.legend(fontsize=7, ncol=2)
    return fig


def rocking_spectrum(spec, *, axes=None):
    """Peak rotation and angular velocity against p (two stacked panels)."""
    import matplotlib.pyplot as plt
    if axes is None:
        fig, axes = plt.subplots(2, 1, sharex=True, figsize=(6, 4.5), constrained_layout=True)
    else:
        fig = axes[0].figure
    over = spec.overturned
    for ax, y, lab in ((axes[0], spec.theta_max, r"max $|\theta|/\alpha$"),
                       (axes[1], spec.theta_dot_max, r"max $|\dot\theta|/p$")):
        ax.plot(spec.p[~over], y[~over], ".-", lw=1)
        ax.plot(spec.p[over], np.full(over.sum(), ax.get_ylim()[1] if not (~over).any() else np.max(y[~over]) * 1.1),
                "x", color="tab:red", label="overturned (no peak; drawn above the curve)")
        ax.set_ylabel(lab)
    axes[1].set_xlabel("p (rad/s)")
    if over.any():
        axes[0].legend(fontsize=7)
    axes[0].set_title(rf"$\alpha$ = {spec.alpha:.3g} rad", fontsize=9)
    return fig
