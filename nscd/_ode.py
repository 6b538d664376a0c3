"""Event-driven integration of the reduced models: scipy's DOP853, compiled, stepped to the first event.

The rocking models (:mod:`nscd.rocking`, :mod:`nscd.stacked`) integrate a smooth ODE
between events (an impact, an overturn, an interface opening) thousands of times per run.
:func:`fly` is the method of :func:`scipy.integrate.solve_ivp` with ``method="DOP853"``:
scipy's Dormand-Prince 8(5,3) tableau (``scipy.integrate.DOP853``'s coefficient arrays,
read from scipy), its error norm, step-size control (safety 0.9, factors in [0.2, 10]),
initial-step rule (Hairer, Norsett & Wanner) and seventh-order dense output, and its
event rule (a sign change of ``event(t, y)`` in its direction between two steps, the root
located on the step's dense output by Brent's method with ``xtol = rtol = 4 eps``:
:func:`scipy.optimize.brentq`, or its compiled transcription for a :class:`Crossing`).
The stages run in one compiled call per step on the compiled right-hand sides of
:mod:`nscd._equations`; the ground accelerations at the step's 16 stage times come from
:func:`nscd.motion.ground_accelerations` (one call per step: the ready motions' compiled
formulas, any other :class:`~nscd.motion.Motion` through its own ``acceleration``).
Every event here is terminal.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.integrate import DOP853
from scipy.optimize import brentq

from nscd._equations import rhs
from nscd._jit import njit, njit_helper

_EPS = np.finfo(float).eps
_SAFETY, _MIN_FACTOR, _MAX_FACTOR = 0.9, 0.2, 10.0          # scipy.integrate._ivp.rk
_EXPONENT = -1.0 / (DOP853.error_estimator_order + 1.0)
# The tableau (Hairer's fixed coefficients): the kernels below read it as compiled-in constants (numba
# freezes global arrays), which spares six array arguments on each call of a step.
_A, _B, _C, _E3, _E5, _D = (np.ascontiguousarray(x, dtype=float) for x in
                            (DOP853.A, DOP853.B, DOP853.C, DOP853.E3, DOP853.E5, DOP853.D))
_A_EXTRA, _C_EXTRA = np.ascontiguousarray(DOP853.A_EXTRA, dtype=float), np.ascontiguousarray(DOP853.C_EXTRA, float)
_N_STAGES = DOP853.n_stages                                  # 12
#: Stage times of a step, in units of h from its start: the 12 stages, the end (FSAL), the 3 dense-output stages.
NODES = np.concatenate([_C, [1.0], _C_EXTRA])

Event = tuple[Callable[[float, np.ndarray], float], int]
"""An event function ``g(t, y)`` and its direction: -1 fires when g goes from >= 0 to <= 0,
+1 from <= 0 to >= 0. A :class:`Crossing` is located by compiled code."""


@dataclass(frozen=True)
class Crossing:
    """The event ``g(t, y) = sign * y[index]``, and 1.0 for ``t <= after`` (a state starting on
    the crossing does not fire at once): an impact. Its root on a step is found by
    :func:`_crossing_root`, Brent's method as :func:`scipy.optimize.brentq`, compiled."""

    index: int
    sign: float
    after: float = -math.inf

    def __call__(self, t: float, y: np.ndarray) -> float:
        return self.sign * y[self.index] if t > self.after else 1.0

Ground = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]
"""``ground(t)`` -> (horizontal, vertical) ground accelerations in m/s^2 at the times ``t`` (s):
:func:`nscd.motion.ground_accelerations`."""


# --------------------------------------------------------------------------- compiled kernels
@njit_helper
def _combine(K, rows, coefficients, y, h, out):
    """out = y + h sum_r coefficients[r] K[r] over the first ``rows`` stages."""
    for j in range(len(y)):
        acc = 0.0
        for r in range(rows):
            acc += K[r, j] * coefficients[r]
        out[j] = y[j] + acc * h


@njit_helper
def _trial_step(model, par, y, f, h, ag, av, rtol, atol, K):
    """One DOP853 step of size h (scipy's ``rk_step`` and ``_estimate_error_norm``): error norm, y_new, f_new."""
    n = len(y)
    for j in range(n):  # element by element: no compiled shape-mismatch message
        K[0, j] = f[j]
    state = np.empty(n)
    for s in range(1, _N_STAGES):
        _combine(K, s, _A[s], y, h, state)
        rhs(model, par, state, ag[s], av[s], K[s])
    y_new = np.empty(n)
    _combine(K, _B.shape[0], _B, y, h, y_new)  # the _N_STAGES weights (a variable: one specialisation)
    f_new = np.empty(n)
    rhs(model, par, y_new, ag[_N_STAGES], av[_N_STAGES], f_new)
    for j in range(n):
        K[_N_STAGES, j] = f_new[j]
    err5, err3 = 0.0, 0.0
    for j in range(n):
        scale = atol + max(abs(y[j]), abs(y_new[j])) * rtol
        e5, e3 = 0.0, 0.0
        for r in range(_N_STAGES + 1):
            e5 += K[r, j] * _E5[r]
            e3 += K[r, j] * _E3[r]
        err5 += (e5 / scale) ** 2
        err3 += (e3 / scale) ** 2
    if err5 == 0.0 and err3 == 0.0:
        return 0.0, y_new, f_new
    return abs(h) * err5 / math.sqrt((err5 + 0.01 * err3) * n), y_new, f_new


@njit
def _attempt(model, par, y, f, h, ag, av, rtol, atol, K):
    """:func:`_trial_step`, and when its error norm is below 1 (the step is accepted) the step's
    interpolant (:func:`_dense_coefficients`; an empty (7, 0) array otherwise): error, y_new, f_new, F."""
    error, y_new, f_new = _trial_step(model, par, y, f, h, ag, av, rtol, atol, K)
    if error < 1.0:
        return error, y_new, f_new, _dense_coefficients(model, par, y, y_new, f_new, h, ag, av, K)
    return error, y_new, f_new, np.empty((7, 0))


@njit_helper
def _dense_coefficients(model, par, y, y_new, f_new, h, ag, av, K):
    """F (7, n): the seventh-order interpolant of the step (scipy's ``DOP853._dense_output_impl``)."""
    n = len(y)
    state = np.empty(n)
    for e in range(3):
        s = _N_STAGES + 1 + e
        _combine(K, s, _A_EXTRA[e], y, h, state)
        rhs(model, par, state, ag[s], av[s], K[s])
    F = np.empty((7, n))
    for j in range(n):
        dy = y_new[j] - y[j]
        F[0, j] = dy
        F[1, j] = h * K[0, j] - dy
        F[2, j] = 2.0 * dy - h * (f_new[j] + K[0, j])
        for i in range(4):
            acc = 0.0
            for r in range(K.shape[0]):
                acc += _D[i, r] * K[r, j]
            F[3 + i, j] = h * acc
    return F


@njit
def _interpolate(t_old, h, y_old, F, t, out):
    """The dense output of one step at time t (scipy's ``Dop853DenseOutput``)."""
    x = (t - t_old) / h
    for j in range(len(y_old)):
        acc = 0.0
        for i in range(7):
            acc += F[6 - i, j]
            acc *= x if i % 2 == 0 else 1.0 - x
        out[j] = acc + y_old[j]


@njit_helper
def _crossing_value(t_old, h, y_old, F, index, sign, after, t):
    """:class:`Crossing`'s g at time t on one step's dense output (the arithmetic of :func:`_interpolate`)."""
    if t <= after:
        return 1.0
    x = (t - t_old) / h
    acc = 0.0
    for i in range(7):
        acc += F[6 - i, index]
        acc *= x if i % 2 == 0 else 1.0 - x
    return sign * (acc + y_old[index])


@njit
def _crossing_root(t_old, h, y_old, F, index, sign, after, xa, xb, xtol, rtol):
    """Root of a :class:`Crossing` in [xa, xb] (a sign change): Brent's method, the algorithm of
    scipy's ``brentq`` (scipy/optimize/Zeros/brentq.c), 100 iterations at most."""
    xpre, xcur = xa, xb
    xblk, fblk, spre, scur = 0.0, 0.0, 0.0, 0.0
    fpre = _crossing_value(t_old, h, y_old, F, index, sign, after, xpre)
    fcur = _crossing_value(t_old, h, y_old, F, index, sign, after, xcur)
    if fpre == 0.0:
        return xpre
    if fcur == 0.0:
        return xcur
    for _ in range(100):
        if fpre != 0.0 and fcur != 0.0 and (fpre < 0.0) != (fcur < 0.0):
            xblk, fblk = xpre, fpre
            spre = scur = xcur - xpre
        if abs(fblk) < abs(fcur):
            xpre, xcur, xblk = xcur, xblk, xcur
            fpre, fcur, fblk = fcur, fblk, fcur
        delta = 0.5 * (xtol + rtol * abs(xcur))
        sbis = 0.5 * (xblk - xcur)
        if fcur == 0.0 or abs(sbis) < delta:
            return xcur
        if abs(spre) > delta and abs(fcur) < abs(fpre):
            if xpre == xblk:  # interpolate
                stry = -fcur * (xcur - xpre) / (fcur - fpre)
            else:  # extrapolate
                dpre = (fpre - fcur) / (xpre - xcur)
                dblk = (fblk - fcur) / (xblk - xcur)
                stry = -fcur * (fblk * dblk - fpre * dpre) / (dblk * dpre * (fblk - fpre))
            if 2.0 * abs(stry) < min(abs(spre), 3.0 * abs(sbis) - delta):  # good short step
                spre, scur = scur, stry
            else:
                spre, scur = sbis, sbis
        else:
            spre, scur = sbis, sbis
        xpre, fpre = xcur, fcur
        xcur += scur if abs(scur) > delta else (delta if sbis > 0.0 else -delta)
        fcur = _crossing_value(t_old, h, y_old, F, index, sign, after, xcur)
    return xcur


@njit
def _interpolate_many(starts, steps, y_olds, Fs, times):
    """State (n, len(times)) at increasing ``times``, each from the step that contains it."""
    out = np.empty((y_olds.shape[1], len(times)))
    value = np.empty(y_olds.shape[1])
    k = 0
    for i in range(len(times)):
        while k + 1 < len(starts) and times[i] >= starts[k + 1]:
            k += 1
        _interpolate(starts[k], steps[k], y_olds[k], Fs[k], times[i], value)
        for j in range(value.shape[0]):  # element by element: no compiled shape-mismatch message
            out[j, i] = value[j]
    return out


@njit
def inner_output_times(t0, t1, dt_out):
    """The multiples of ``dt_out`` strictly inside each interval (t0[i], t1[i]) (s), interval after
    interval, and the index i of each: the sample times of the reduced models' histories between their
    events (:func:`nscd.rocking._output_times`, :mod:`nscd.stacked`)."""
    n = 0
    for i in range(len(t0)):
        n += max(math.ceil(t1[i] / dt_out) - (math.floor(t0[i] / dt_out) + 1), 0)
    times, index = np.empty(n), np.empty(n, dtype=np.int64)
    m = 0
    for i in range(len(t0)):
        for k in range(math.floor(t0[i] / dt_out) + 1, math.ceil(t1[i] / dt_out)):
            t = k * dt_out
            if t0[i] < t < t1[i]:
                times[m], index[m] = t, i
                m += 1
    return times[:m], index[:m]


def _initial_step(derivative, t0: float, y0: np.ndarray, f0: np.ndarray, t_bound: float, rtol: float,
                  atol: float) -> float:
    """First step in s: the rule of Hairer, Norsett & Wanner (Solving ODEs I, sec. II.4) that
    scipy's solvers use, for DOP853's error order 7."""
    interval = t_bound - t0
    if interval == 0.0:
        return 0.0
    scale = atol + np.abs(y0) * rtol
    d0, d1 = (float(np.linalg.norm(x / scale)) / math.sqrt(len(y0)) for x in (y0, f0))
    h0 = min(1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1, interval)
    f1 = derivative(t0 + h0, y0 + h0 * f0)
    d2 = float(np.linalg.norm((f1 - f0) / scale)) / math.sqrt(len(y0)) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (1.0 / (DOP853.error_estimator_order + 1))
    return min(100.0 * h0, h1, interval)


# --------------------------------------------------------------------------- flights
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
    starts, steps : list of float
        Start time and size (s) of each step.
    y_olds, coefficients : list of ndarray
        State at each step's start, shape (n,), and its interpolant, shape (7, n).
    last_step : float or None
        s, the last full step taken (a good first step for the next flight).
    """

    t1: float
    y1: np.ndarray
    event: int | None
    starts: list
    steps: list
    y_olds: list
    coefficients: list
    last_step: float | None

    def extend(self, other: Flight) -> None:
        """Append the steps of the flight that continues this one (from its ``t1``, or later: the
        times between two flights are then outside every step)."""
        self.starts += other.starts
        self.steps += other.steps
        self.y_olds += other.y_olds
        self.coefficients += other.coefficients
        self.t1, self.y1, self.event = other.t1, other.y1, other.event
        self.last_step = other.last_step or self.last_step

    def evaluate(self, t) -> np.ndarray:
        """State at the increasing times ``t`` (s, inside the flight's steps), shape (n, len(t)) (or (n,) for
        a float)."""
        times = np.atleast_1d(np.asarray(t, dtype=float))
        if not self.starts:  # stopped where it started
            out = np.repeat(np.asarray(self.y1, float)[:, None], len(times), axis=1)
        else:
            out = _interpolate_many(np.array(self.starts), np.array(self.steps), np.array(self.y_olds),
                                    np.array(self.coefficients), times)
        return out[:, 0] if np.ndim(t) == 0 else out


def fly(model: int, par: np.ndarray, ground: Ground, t0: float, y0: np.ndarray, t_bound: float,
        events: Sequence[Event], rtol: float, atol: float, first_step: float | None = None) -> Flight:
    """Integrate ``model``'s equations (:func:`nscd._equations.rhs`) from ``(t0, y0)`` to the first event or ``t_bound``.

    Parameters
    ----------
    model : int
        :data:`nscd._equations.HOUSNER` or :data:`nscd._equations.STACK`.
    par : ndarray
        The model's constants (:mod:`nscd._equations`).
    ground : Ground
        The ground accelerations, called once per step at its 16 stage times.
    t0, t_bound : float
        Start and end times in s, ``t_bound > t0``.
    y0 : ndarray, shape (n,)
    events : sequence of (function, direction)
        See :data:`Event`; every event is terminal.
    rtol, atol : float
        DOP853's tolerances.
    first_step : float, optional
        s; None: the initial-step rule of :func:`_initial_step`.

    Raises
    ------
    RuntimeError
        When the step size falls below its minimum (10 ulp of t), naming the time.
    """
    par = np.ascontiguousarray(par, dtype=float)
    y = np.array(y0, dtype=float)
    n = len(y)
    K = np.empty((len(NODES), n))

    def derivative(t: float, state: np.ndarray) -> np.ndarray:
        ag, av = ground(np.array([t]))
        out = np.empty(n)
        rhs(model, par, np.asarray(state, dtype=float), ag[0], av[0], out)
        return out

    t = float(t0)
    f = derivative(t, y)
    if first_step is None:
        h_abs = _initial_step(derivative, t, y, f, t_bound, rtol, atol)
    else:
        h_abs = min(float(first_step), t_bound - t)
    g = [event(t, y) for event, _ in events]
    flight = Flight(t, y, None, [], [], [], [], None)
    value = np.empty(n)
    while t < t_bound:
        min_step = 10.0 * abs(math.nextafter(t, math.inf) - t)
        h_abs = max(h_abs, min_step)
        rejected = False
        while True:
            if h_abs < min_step:
                raise RuntimeError(f"integration failed at t = {t:.6g} s: the step size fell below its minimum.")
            t_new = min(t + h_abs, t_bound)
            h = t_new - t
            h_abs = abs(h)
            ag, av = ground(t + NODES * h)
            error, y_new, f_new, F = _attempt(model, par, y, f, h, ag, av, rtol, atol, K)
            if error < 1.0:
                factor = _MAX_FACTOR if error == 0.0 else min(_MAX_FACTOR, _SAFETY * error ** _EXPONENT)
                h_abs *= min(1.0, factor) if rejected else factor
                break
            h_abs *= max(_MIN_FACTOR, _SAFETY * error ** _EXPONENT)
            rejected = True
        flight.starts.append(t)
        flight.steps.append(h)
        flight.y_olds.append(y)
        flight.coefficients.append(F)
        g_new = [event(t_new, y_new) for event, _ in events]
        hits = []
        for index, ((event, direction), before, after) in enumerate(zip(events, g, g_new)):
            if (before >= 0.0 >= after) if direction < 0 else (before <= 0.0 <= after):
                if isinstance(event, Crossing):
                    root = _crossing_root(t, h, y, F, event.index, event.sign, event.after, t, t_new,
                                          4 * _EPS, 4 * _EPS)
                else:
                    def on_dense(s, event=event, t_old=t, h=h, y_old=y, F=F):
                        _interpolate(t_old, h, y_old, F, s, value)
                        return event(s, value)
                    root = brentq(on_dense, t, t_new, xtol=4 * _EPS, rtol=4 * _EPS)
                hits.append((root, index))
        if hits:
            root, index = min(hits)
            y1 = np.empty(n)
            _interpolate(t, h, y, F, root, y1)
            if root <= t:  # the event at the step's start: the step adds nothing
                for field in (flight.starts, flight.steps, flight.y_olds, flight.coefficients):
                    field.pop()
            flight.t1, flight.y1, flight.event = root, y1, index
            return flight
        if t_new < t_bound:
            flight.last_step = h
        t, y, f, g = t_new, y_new, f_new, g_new
    flight.t1, flight.y1 = t, y
    return flight
