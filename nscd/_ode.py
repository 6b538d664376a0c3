"""Event-driven integration of the reduced models: scipy's DOP853 stepped to the first event.

The rocking models (:mod:`nscd.rocking`, :mod:`nscd.stacked`) integrate a smooth ODE
between events (an impact, an overturn, an interface opening) thousands of times per
run, most flights a few steps long. :func:`fly` does what
:func:`scipy.integrate.solve_ivp` does for them -- the same stepper
(:class:`scipy.integrate.DOP853`, same tolerances and step control), the same event
rule (a sign change of ``event(t, y)`` in its direction between two steps, the root
located on the step's dense output by :func:`scipy.optimize.brentq` with
``xtol = rtol = 4 eps``) -- without the per-call and per-step bookkeeping of
``solve_ivp`` (event arrays, result assembly), which dominated the run time of
the reduced models. Every event here is terminal.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.integrate import DOP853, OdeSolution
from scipy.optimize import brentq

_EPS = np.finfo(float).eps

Event = tuple[Callable[[float, np.ndarray], float], int]
"""An event function ``g(t, y)`` and its direction: -1 fires when g goes from >= 0 to <= 0,
+1 from <= 0 to >= 0."""


@dataclass
class Flight:
    """One integration from ``t0`` to the first event or ``t_bound``.

    Attributes
    ----------
    t1 : float
        s, where it stopped (the event's root, or ``t_bound``).
    y1 : ndarray, shape (n,)
        State at ``t1``.
    event : int or None
        Index in ``events`` of the event that stopped it (the earliest root of the last
        step); None at ``t_bound``.
    times : list of float
        Step ends ``t0, t_1, ..., t1`` (the last one the event's root).
    dense : list
        The dense output of each step (DOP853's seventh-order interpolant).
    last_step : float or None
        s, the last full step taken (a good first step for the next flight).
    """

    t1: float
    y1: np.ndarray
    event: int | None
    times: list
    dense: list
    last_step: float | None

    def evaluate(self, t) -> np.ndarray:
        """State at the times ``t`` (s, inside [t0, t1]), shape (n, len(t)) (or (n,) for a float)."""
        if np.size(t) == 0:
            return np.zeros((len(self.y1),) + np.shape(t))
        if not self.dense:  # stopped where it started
            return np.broadcast_to(np.reshape(self.y1, (-1,) + (1,) * np.ndim(t)),
                                   (len(self.y1),) + np.shape(t)).copy()
        return OdeSolution(self.times, self.dense)(t)


def fly(rhs: Callable[[float, np.ndarray], Sequence[float]], t0: float, y0: np.ndarray, t_bound: float,
        events: Sequence[Event], rtol: float, atol: float, first_step: float | None = None) -> Flight:
    """Integrate ``y' = rhs(t, y)`` from ``(t0, y0)`` until the first event or ``t_bound``.

    Parameters
    ----------
    rhs : callable
        ``rhs(t, y)`` -> the derivative (sequence of n floats).
    t0, t_bound : float
        Start and end times in s, ``t_bound > t0``.
    y0 : ndarray, shape (n,)
    events : sequence of (function, direction)
        See :data:`Event`; every event is terminal.
    rtol, atol : float
        DOP853's tolerances.
    first_step : float, optional
        s; None lets DOP853 choose it (:func:`scipy.integrate` 's initial step rule).

    Raises
    ------
    RuntimeError
        When DOP853 fails (step size below its minimum), naming the time.
    """
    solver = DOP853(rhs, t0, np.asarray(y0, float), t_bound, rtol=rtol, atol=atol,
                    first_step=None if first_step is None else min(first_step, t_bound - t0))
    g = [event(t0, solver.y) for event, _ in events]
    times, dense, last_step = [t0], [], None
    while solver.status == "running":
        message = solver.step()
        if solver.status == "failed":
            raise RuntimeError(f"integration failed at t = {solver.t:.6g} s: {message}")
        t_old, t = solver.t_old, solver.t
        step = solver.dense_output()
        dense.append(step)
        g_new = [event(t, solver.y) for event, _ in events]
        hits = []
        for index, ((event, direction), before, after) in enumerate(zip(events, g, g_new)):
            if (before >= 0.0 >= after) if direction < 0 else (before <= 0.0 <= after):
                root = brentq(lambda s, event=event: event(s, step(s)), t_old, t, xtol=4 * _EPS, rtol=4 * _EPS)
                hits.append((root, index))
        if hits:
            root, index = min(hits)
            if root > t_old:
                times.append(root)
            else:  # the event at the step's start: the step adds nothing
                dense.pop()
            return Flight(root, step(root), index, times, dense, last_step)
        times.append(t)
        last_step = t - t_old
        g = g_new
    return Flight(solver.t, np.array(solver.y, float), None, times, dense, last_step)


def sample(flight: Flight, grid: np.ndarray) -> np.ndarray:
    """The flight's state at the increasing times ``grid`` (s, inside it), shape (len(grid), n)."""
    if len(grid) == 0:
        return np.zeros((0, len(flight.y1)))
    return np.atleast_2d(flight.evaluate(grid)).reshape(len(flight.y1), -1).T

