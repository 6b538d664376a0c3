"""Ground motions: the horizontal (or vertical) base excitation of a scene.

Every motion is a :class:`Motion`, a scalar function of time along one axis with
``acceleration(t)`` (m/s^2), ``velocity(t)`` (m/s) and ``displacement(t)`` (m),
vectorised over ``t`` (a float in, a float out; an array in, an array of the same
shape out), and a ``duration`` (s) after which the motion is over (``inf`` if
never). Velocity is the exact time derivative of displacement and acceleration
the exact derivative of velocity, for every class here. Every motion is zero for
``t < 0`` and starts from rest at ``t = 0`` unless its class documents otherwise
(:class:`Harmonic` and :class:`Sweep` without a ramp start with a velocity jump;
:class:`Prescribed` is whatever its functions say).

Amplitudes are in m/s^2 unless ``unit="g"`` says otherwise (``g`` is the standard
gravity :data:`STANDARD_GRAVITY`); displacements in m.

Sign convention (``docs/architecture.md``): a positive horizontal ground
acceleration (+x) tips a block at rest toward -x, a counter-clockwise (positive)
rotation in the engine; in the 1-DOF model (and the papers) a negative theta.

Sources: the one-sine (Type-A) and one-cosine (Type-B) pulses and the Type-Cn
pulses are those of Makris & Zhang (seed 000, lines 482-490, 707-741, 1236-1240);
the constant sine, Hanning sine and run-up / run-down sweeps are the shaking-table
inputs of the LNEC tests (seed 003, line 75 and line 182).
"""
from __future__ import annotations

import abc
import math
import re
import warnings
from collections.abc import Callable, Sequence
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

from nscd._checks import real_number
from nscd._jit import njit, njit_helper

__all__ = [
    "STANDARD_GRAVITY", "Motion", "HalfSine", "OneSine", "OneCosine", "TypeCn", "Harmonic",
    "HanningSine", "Sweep", "ConstantAccelerationPhases", "Prescribed", "Scaled", "Record", "elcentro",
]

STANDARD_GRAVITY = 9.80665
"""Standard gravity in m/s^2, used to convert amplitudes given in ``g``."""

_UNITS = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}

TimeLike = float | np.ndarray


# --------------------------------------------------------------------------- checks
def _finite(name: str, value: float) -> float:
    value = real_number(name, value)
    if not math.isfinite(value):
        raise ValueError(f"{name} == {value}, must be finite.")
    return value


def _positive(name: str, value: float) -> float:
    value = real_number(name, value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} == {value}, must be finite and > 0.")
    return value


def _unit_factor(unit: str | None, name: str = "unit") -> float:
    """Factor converting a quantity in ``unit`` to m/s^2."""
    if unit not in _UNITS:
        raise ValueError(f"{name} == {unit!r}, must be one of {sorted(_UNITS)} (stated explicitly).")
    return _UNITS[unit]


def _angular_frequency(omega: float | None, frequency: float | None) -> float:
    """Return omega (rad/s) from exactly one of omega (rad/s) or frequency (Hz)."""
    if (omega is None) == (frequency is None):
        raise ValueError(
            f"omega == {omega}, frequency == {frequency}: give exactly one of omega (rad/s) "
            "or frequency (Hz).")
    if omega is not None:
        return _positive("omega", omega)
    return 2.0 * math.pi * _positive("frequency", frequency)


# --------------------------------------------------------------------------- the formulas, compiled
# Each ready motion's kinematics is one compiled formula of one time t (s) and its constants
# ``par``: the one source of Motion.kinematics (looped over the times), Motion.acceleration_at
# and the reduced models' ground (ground_accelerations, at a step's stage times).
_ZERO, _SINE_PULSE, _ENVELOPED_SINE, _RECORD, _PHASES = 0, 1, 2, 3, 4
_NO_TABLE = np.zeros(0)  # the sample tables of a motion that has none


@njit_helper
def _sine_pulse(t, par):
    """(d, v, a) of A sin(w t + p) on [0, T] from rest, par = (A, w, p, T) (:class:`_SinePulse`)."""
    A, w, p, T = par[0], par[1], par[2], par[3]
    tc = min(max(t, 0.0), T)
    inside = 1.0 if tc == t else 0.0
    a = inside * A * math.sin(w * tc + p)
    v = A / w * (math.cos(p) - math.cos(w * tc + p))
    d = A / w * math.cos(p) * tc - A / w ** 2 * (math.sin(w * tc + p) - math.sin(p))
    return d + v * (max(t, 0.0) - tc), v, a


@njit
def _envelope(t, T, ramp, hanning):
    """(e, e', e'') of the envelope at t in [0, T]: Hanning, or raised-cosine ramps of ``ramp`` s at both ends.

    Ramps: e = (1 - cos(pi t / ramp)) / 2 on [0, ramp], 1 in the middle, mirrored at the end;
    e and e' are continuous, e'' jumps at the ramp ends (finite acceleration steps).
    """
    if hanning:
        k = 2.0 * math.pi / T
        return 0.5 * (1.0 - math.cos(k * t)), 0.5 * k * math.sin(k * t), 0.5 * k ** 2 * math.cos(k * t)
    if ramp == 0.0:
        return 1.0, 0.0, 0.0
    k = math.pi / ramp
    to_end = T - t
    sign = 1.0 if to_end >= t else -1.0          # +1 nearer the start (and midway), -1 nearer the end
    tau = min(t, to_end)                          # distance to the nearer end
    ramping = 1.0 if tau < ramp else 0.0
    x = k * min(tau, ramp)
    return 0.5 * (1.0 - math.cos(x)), ramping * sign * 0.5 * k * math.sin(x), ramping * 0.5 * k ** 2 * math.cos(x)


@njit_helper
def _phase(t, T, law, f0, f1):
    """(theta, theta', theta'') in rad, rad/s, rad/s^2: constant circular frequency f0 (law 0),
    or a sweep from f0 to f1 Hz, linear (law 1) or exponential (law 2) in time (:class:`Sweep`)."""
    if law == 0.0:
        return f0 * t, f0, 0.0
    if law == 1.0:
        rate = (f1 - f0) / T
        f = f0 + rate * t
        return 2.0 * math.pi * (f0 * t + 0.5 * rate * t ** 2), 2.0 * math.pi * f, 2.0 * math.pi * rate
    log_k = math.log(f1 / f0)
    f = f0 * math.exp(log_k * t / T)
    return (2.0 * math.pi * f0 * T * math.expm1(log_k * t / T) / log_k, 2.0 * math.pi * f,
            2.0 * math.pi * f * log_k / T)


@njit_helper
def _enveloped_sine(t, par):
    """(d, v, a) of d = D e(t) sin(theta(t)) on [0, T], par = (D, T, ramp, hanning, law, f0, f1)."""
    D, T = par[0], par[1]
    tc = min(max(t, 0.0), T)
    inside = 1.0 if tc == t else 0.0
    e, de, dde = _envelope(tc, T, par[2], par[3] != 0.0)
    th, dth, ddth = _phase(tc, T, par[4], par[5], par[6])
    s, c = math.sin(th), math.cos(th)
    d = (1.0 if t >= 0.0 else 0.0) * D * e * s
    v = inside * D * (de * s + e * dth * c)
    a = inside * D * (dde * s + (2.0 * de * dth + e * ddth) * c - e * dth ** 2 * s)
    return d, v, a


@njit
def _record(t, par, acc, vel, dis):
    """(d, v, a) of the piecewise-linear record, par = (dt, duration), tables at the samples (:class:`Record`)."""
    dt, T = par[0], par[1]
    tc = min(max(t, 0.0), T)
    inside = 1.0 if tc == t else 0.0
    k = min(int(tc / dt), len(acc) - 2)
    s = tc - k * dt
    slope = (acc[k + 1] - acc[k]) / dt
    a = inside * (acc[k] + slope * s)
    v = vel[k] + acc[k] * s + 0.5 * slope * s ** 2
    d = dis[k] + vel[k] * s + 0.5 * acc[k] * s ** 2 + slope * s ** 3 / 6.0
    return d + v * (max(t, 0.0) - tc), v, a


@njit_helper
def _phases(t, par):
    """(d, v, a) of phases of constant acceleration from rest (:class:`ConstantAccelerationPhases`),
    par = (n, duration, v_end, d_end, starts (n), accelerations (n), and the velocities (n) and
    displacements (n) at the starts); at constant velocity ``v_end`` after ``duration``, at rest
    before t = 0. Entries after these (padding) are not read."""
    n, end, v_end, d_end = int(par[0]), par[1], par[2], par[3]
    tc = min(max(t, 0.0), end)
    phase = 0
    for j in range(1, n):
        if par[4 + j] <= tc:
            phase = j
    tau = tc - par[4 + phase]
    ak, v0, d0 = par[4 + n + phase], par[4 + 2 * n + phase], par[4 + 3 * n + phase]
    after = t >= end
    v = v_end if after else v0 + ak * tau
    displacement = d_end if after else d0 + v0 * tau + 0.5 * ak * (tau * tau)
    d = displacement + v * (max(t, 0.0) - tc)
    a = ak if 0.0 <= t < end else 0.0
    return d, v, a


@njit
def _kinematics_at(kind, par, acc, vel, dis, t):
    """(d, v, a) of a ready motion of ``kind`` at one time t (s)."""
    if kind == _SINE_PULSE:
        return _sine_pulse(t, par)
    if kind == _ENVELOPED_SINE:
        return _enveloped_sine(t, par)
    if kind == _RECORD:
        return _record(t, par, acc, vel, dis)
    if kind == _PHASES:
        return _phases(t, par)
    return 0.0, 0.0, 0.0


@njit
def _kinematics_many(kind, par, acc, vel, dis, t):
    """(3, n): displacement, velocity, acceleration at the times t (n,)."""
    out = np.empty((3, len(t)))
    for i in range(len(t)):
        out[0, i], out[1, i], out[2, i] = _kinematics_at(kind, par, acc, vel, dis, t[i])
    return out


@njit
def _acceleration_at(kind, par, acc, vel, dis, t):
    return _kinematics_at(kind, par, acc, vel, dis, t)[2]


@njit
def _ground_accelerations(kind_h, factor_h, par_h, acc_h, vel_h, dis_h,
                          kind_v, factor_v, par_v, acc_v, vel_v, dis_v, t):
    ag, av = np.empty(len(t)), np.empty(len(t))
    for i in range(len(t)):
        ag[i] = factor_h * _kinematics_at(kind_h, par_h, acc_h, vel_h, dis_h, t[i])[2]
        av[i] = factor_v * _kinematics_at(kind_v, par_v, acc_v, vel_v, dis_v, t[i])[2]
    return ag, av


def ground_accelerations(motion: Motion | None, vertical: Motion | None
                         ) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """``evaluate(t)``: horizontal and vertical ground accelerations (m/s^2) at the times ``t`` (s, 1-D).

    None means zero. Ready motions (and :class:`Scaled` ones) in one compiled loop; any
    other motion through its :meth:`Motion.acceleration`.
    """
    if motion is None and vertical is None:  # a ground at rest: no compiled loop to build (nor compile)
        return lambda t: (np.zeros(len(t)), np.zeros(len(t)))
    specs = [(_ZERO, 1.0, _NO_TABLE, _NO_TABLE, _NO_TABLE, _NO_TABLE) if m is None else m._compiled()
             for m in (motion, vertical)]
    if specs[0] is not None and specs[1] is not None:
        arguments = (*specs[0], *specs[1])
        return lambda t: _ground_accelerations(*arguments, t)
    return lambda t: tuple(np.zeros(len(t)) if m is None else np.asarray(m.acceleration(t), dtype=float)
                           for m in (motion, vertical))


# --------------------------------------------------------------------------- base
class Motion(abc.ABC):
    """A ground motion along one axis: a(t) in m/s^2, v(t) in m/s, d(t) in m.

    Subclasses implement ``_kinematics(t)`` for ``t`` a 1-D float array or a
    numpy float scalar and return the triple (displacement, velocity,
    acceleration) broadcastable to ``t``; the public methods handle shapes.

    Attributes
    ----------
    duration : float
        Time in s after which the motion is over (acceleration zero for good);
        ``inf`` if it never ends.
    """

    duration: float

    @abc.abstractmethod
    def _kinematics(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (d, v, a) at the times ``t`` (s; 1-D array or numpy float scalar)."""

    def kinematics(self, t: TimeLike) -> tuple[TimeLike, TimeLike, TimeLike]:
        """(displacement in m, velocity in m/s, acceleration in m/s^2) at time(s) ``t`` in one call."""
        t_arr = np.asarray(t, dtype=float)
        if np.isnan(t_arr).any():
            raise ValueError(f"t == {t!r} contains NaN, must be times in s.")
        if t_arr.ndim == 0:  # scalar fast path: numpy scalars avoid small-array overhead
            return tuple(float(x) for x in self._kinematics(t_arr[()]))
        shape = t_arr.shape
        return tuple(np.broadcast_to(x, shape).reshape(shape) if np.ndim(x) == 0
                     else np.reshape(x, shape) for x in self._kinematics(t_arr.ravel()))

    def displacement(self, t: TimeLike) -> TimeLike:
        """Ground displacement in m at time(s) ``t`` (s); same shape as ``t``."""
        return self.kinematics(t)[0]

    def velocity(self, t: TimeLike) -> TimeLike:
        """Ground velocity in m/s at time(s) ``t`` (s); d/dt of :meth:`displacement`."""
        return self.kinematics(t)[1]

    def acceleration(self, t: TimeLike) -> TimeLike:
        """Ground acceleration in m/s^2 at time(s) ``t`` (s); d/dt of :meth:`velocity`."""
        return self.kinematics(t)[2]

    def acceleration_at(self, t: float) -> float:
        """Ground acceleration in m/s^2 at one time ``t`` (a float, s), without checks.

        For the reduced models' root finding and event tests (:mod:`nscd.rocking`,
        :mod:`nscd.stacked`), which call it thousands of times per run. The ready motions evaluate their one
        formula with the math module (no array overhead; equal to :meth:`acceleration`
        to rounding); any other motion goes through :meth:`acceleration`.
        """
        return float(self.acceleration(t))

    def _compiled(self) -> tuple | None:
        """(kind, factor, par, tables...) of the compiled formula, or None (evaluated in Python)."""
        return None


class _Compiled(Motion):
    """A ready motion: its kinematics one compiled formula of ``kind`` with constants ``_par``
    (and sample tables ``_tables`` for records)."""

    _kind: int
    _par: np.ndarray
    _tables: tuple = (_NO_TABLE, _NO_TABLE, _NO_TABLE)

    def _kinematics(self, t):
        if np.ndim(t) == 0:
            return _kinematics_at(self._kind, self._par, *self._tables, float(t))
        out = _kinematics_many(self._kind, self._par, *self._tables, np.asarray(t, dtype=float))
        return out[0], out[1], out[2]

    def acceleration_at(self, t: float) -> float:
        return _acceleration_at(self._kind, self._par, *self._tables, float(t))

    def _compiled(self) -> tuple:
        return (self._kind, 1.0, self._par, *self._tables)


class ConstantAccelerationPhases(_Compiled):
    """A motion from rest made of phases of constant acceleration (exact kinematics).

    Parameters
    ----------
    starts : sequence of float, shape (n,)
        Start time of each phase, s; increasing, ``starts[0] == 0``.
    accelerations : sequence of float, shape (n,)
        Acceleration of each phase, m/s^2; the last phase lasts until ``duration``,
        after which the acceleration is zero (the velocity stays constant).
    duration : float
        End of the last phase, s.
    at_rest_after : bool
        The phases bring the motion to rest at ``duration``: the velocity is then
        exactly 0 (not a rounding residue of the phase sums).
    """

    _kind = _PHASES

    def __init__(self, starts: Sequence[float], accelerations: Sequence[float], duration: float,
                 at_rest_after: bool = False) -> None:
        starts = np.asarray(starts, dtype=float)
        accelerations = np.asarray(accelerations, dtype=float)
        if starts.ndim != 1 or starts.shape != accelerations.shape or not len(starts) or starts[0] != 0.0 \
                or np.any(np.diff(starts) <= 0.0) or not np.all(np.isfinite(accelerations)):
            raise ValueError(f"starts == {starts.tolist()} s and accelerations == {accelerations.tolist()} m/s^2 "
                             "must be two sequences of one length >= 1, starts increasing from 0, accelerations "
                             "finite.")
        self.duration = float(duration)
        if not starts[-1] <= self.duration < math.inf:
            raise ValueError(f"duration == {duration} s, must be finite and >= the last start {starts[-1]} s.")
        span = np.append(starts[1:], self.duration) - starts
        velocities = np.concatenate([[0.0], np.cumsum(accelerations * span)])
        displacements = np.concatenate([[0.0], np.cumsum(velocities[:-1] * span + 0.5 * accelerations * span**2)])
        v_end = 0.0 if at_rest_after else velocities[-1]
        self._par = np.concatenate([[len(starts), self.duration, v_end, displacements[-1]], starts, accelerations,
                                    velocities[:-1], displacements[:-1]])

    def __repr__(self) -> str:
        n = int(self._par[0])
        return (f"ConstantAccelerationPhases(starts={self._par[4:4 + n].tolist()}, "
                f"accelerations={self._par[4 + n:4 + 2 * n].tolist()}, duration={self.duration!r})")


# --------------------------------------------------------------------------- pulses
class _SinePulse(_Compiled):
    """a(t) = A sin(omega t + phase) on [0, duration], zero otherwise, from rest.

    The exact integrals from rest are

        v(t) = A/omega (cos(phase) - cos(omega t + phase)),
        d(t) = A/omega cos(phase) t - A/omega^2 (sin(omega t + phase) - sin(phase)),

    continued linearly after the pulse: v(t) = v(T), d(t) = d(T) + v(T) (t - T).

    HalfSine, OneSine, OneCosine and TypeCn share these attributes; the 1-DOF rocking model
    reads them to use its closed-form flights.

    Attributes
    ----------
    amplitude : float
        A in m/s^2 (converted from ``unit``).
    omega : float
        Circular frequency in rad/s.
    phase : float
        Phase in rad (0 for OneSine, pi/2 for OneCosine, phi + pi/2 for TypeCn).
    duration : float
        Pulse length T in s.
    """

    def __init__(self, amplitude: float, omega: float, unit: str, phase: float, duration: float):
        self.amplitude = _finite("amplitude", amplitude) * _unit_factor(unit)
        self.omega = _positive("omega", omega)
        self.phase = phase
        self.duration = duration
        self._kind, self._par = _SINE_PULSE, np.array([self.amplitude, self.omega, phase, duration])

    def __repr__(self) -> str:
        return f"{type(self).__name__}(amplitude={self.amplitude!r} m/s^2, omega={self.omega!r} rad/s)"


class HalfSine(_SinePulse):
    """Half-sine acceleration pulse of seed 000 (prologue, eqs. 1-2) and 001 (eq. 11).

    a(t) = A sin(omega t) for 0 <= t <= pi / omega, zero after: one lobe of duration
    T_p / 2 with T_p = 2 pi / omega. From rest, v(t) = A/omega (1 - cos(omega t)), which
    ends at 2 A / omega and stays there (the ground keeps moving at constant velocity,
    so its acceleration, all a rocking block feels, is zero after the pulse), and
    d(t) = A/omega (t - sin(omega t)/omega). Under the linearised Housner equation the
    smallest amplitude that overturns a block is ``a_p0 = alpha g / sin(psi)``, with psi the
    root of ``(omega/p) sin(psi) - cos(psi) = exp(-(p/omega)(pi - psi))`` (000 prologue,
    eq. 2; Shi et al.); the block then topples after the pulse, in free rocking.

    Parameters
    ----------
    amplitude : float
        Peak acceleration A (may be negative for a reversed pulse), in ``unit``.
    omega : float
        Circular frequency omega_p of the sine in rad/s, > 0 (the pulse lasts pi / omega).
    unit : {"m/s^2", "g"}
        Unit of ``amplitude``.
    """

    def __init__(self, amplitude: float, omega: float, unit: str = "m/s^2"):
        omega = _positive("omega", omega)
        super().__init__(amplitude, omega, unit, phase=0.0, duration=math.pi / omega)


class OneSine(_SinePulse):
    """One-sine (Type-A) acceleration pulse of seed 000 (eq. 2-16 with psi = 0).

    a(t) = A sin(omega t) for 0 <= t <= 2 pi / omega, zero after. Starting from
    rest, v(t) = A/omega (1 - cos(omega t)) >= 0 and
    d(t) = A/omega (t - sin(omega t)/omega). The velocity returns exactly to zero
    at the end of the pulse, but the ground keeps a permanent forward displacement
    d = 2 pi A / omega^2 ("a one-sine acceleration pulse results to a forward
    ground displacement", 000 line 1236); after the pulse d stays constant.

    Parameters
    ----------
    amplitude : float
        Peak acceleration A (may be negative for a reversed pulse), in ``unit``.
    omega : float
        Circular frequency omega_p of the pulse in rad/s, > 0.
    unit : {"m/s^2", "g"}
        Unit of ``amplitude``.
    """

    def __init__(self, amplitude: float, omega: float, unit: str = "m/s^2"):
        omega = _positive("omega", omega)
        super().__init__(amplitude, omega, unit, phase=0.0, duration=2.0 * math.pi / omega)


class OneCosine(_SinePulse):
    """One-cosine (Type-B) acceleration pulse of seed 000 (section 2.4).

    a(t) = A cos(omega t) for 0 <= t <= 2 pi / omega, zero after: the acceleration
    jumps to its peak A at t = 0 (velocity and displacement stay continuous).
    From rest, v(t) = A/omega sin(omega t) and d(t) = A/omega^2 (1 - cos(omega t)):
    a forward-and-back displacement that ends, like the velocity, exactly at zero.

    Parameters
    ----------
    amplitude : float
        Peak acceleration A (may be negative), in ``unit``.
    omega : float
        Circular frequency in rad/s, > 0.
    unit : {"m/s^2", "g"}
        Unit of ``amplitude``.
    """

    def __init__(self, amplitude: float, omega: float, unit: str = "m/s^2"):
        omega = _positive("omega", omega)
        super().__init__(amplitude, omega, unit, phase=0.5 * math.pi,
                         duration=2.0 * math.pi / omega)


class TypeCn(_SinePulse):
    """Makris & Chang (1998) Type-Cn cycloidal pulse, cited in seed 000 (lines 489, 707-723).

    With v_p = A / omega and T = 2 pi / omega, the ground velocity is

        v(t) = v_p sin(omega t + phi) - v_p sin(phi),   0 <= t <= t_n = (n + 1/2 - phi/pi) T,

    so a(t) = A cos(omega t + phi): finite at t = 0 (A cos(phi)) but smaller than
    the peak A, as 000 describes. Velocity starts and ends at zero; the phase
    ``phi`` in (0, pi/2) is the root of tan(phi) ((2n + 1) pi - 2 phi) = 2, which
    makes the displacement d(t) = v_p/omega (cos(phi) - cos(omega t + phi))
    - v_p sin(phi) t return to zero at t_n as well (phi = 0.0697 pi for n = 1,
    0.0410 pi for n = 2, the values quoted in the literature). The displacement
    history has n main cycles. After t_n the motion is at rest.

    Parameters
    ----------
    amplitude : float
        Peak acceleration A = omega v_p (may be negative), in ``unit``.
    omega : float
        Circular frequency omega_p in rad/s, > 0.
    n : int
        Number of main cycles, >= 1.
    unit : {"m/s^2", "g"}
        Unit of ``amplitude``.

    Attributes
    ----------
    phi : float
        The phase phi in rad.
    """

    def __init__(self, amplitude: float, omega: float, n: int, unit: str = "m/s^2"):
        omega = _positive("omega", omega)
        if isinstance(n, bool) or int(n) != n or n < 1:
            raise ValueError(f"n == {n!r}, must be an integer >= 1.")
        self.n = int(n)
        self.phi = brentq(lambda f: math.tan(f) * ((2 * n + 1) * math.pi - 2 * f) - 2.0,
                          1e-12, 0.5 * math.pi - 1e-9, xtol=1e-15)
        t_end = (n + 0.5 - self.phi / math.pi) * 2.0 * math.pi / omega
        super().__init__(amplitude, omega, unit, phase=self.phi + 0.5 * math.pi, duration=t_end)


# --------------------------------------------------------------------------- table motions
class _EnvelopedSine(_Compiled):
    """Displacement-defined motion d(t) = D e(t) sin(theta(t)) on [0, duration].

    Velocity and acceleration are the exact derivatives (product and chain rule)

        v = D (e' sin(theta) + e theta' cos(theta)),
        a = D (e'' sin(theta) + (2 e' theta' + e theta'') cos(theta) - e theta'^2 sin(theta)).

    Before t = 0 everything is zero; after ``duration`` the displacement is held
    at its final value with zero velocity and acceleration. Subclasses choose the
    envelope (e, e', e'': ramps or Hanning, the kernel ``_envelope``) and the phase
    (theta, theta', theta'': constant frequency or a sweep, the kernel ``_phase``).
    """

    def __init__(self, displacement_amplitude: float, duration: float, ramp: float = 0.0, hanning: bool = False,
                 law: int = 0, f0: float = 0.0, f1: float = 0.0):
        """Envelope: Hanning window, or raised-cosine ramps of ``ramp`` s (``_envelope``); phase law 0:
        theta = f0 t (f0 a circular frequency, rad/s), 1 / 2: linear / exponential sweep from f0 to f1 Hz."""
        self.displacement_amplitude = displacement_amplitude
        self.duration = duration
        self._kind = _ENVELOPED_SINE
        self._par = np.array([displacement_amplitude, duration, ramp, float(hanning), float(law), f0, f1])


class Harmonic(_EnvelopedSine):
    """Constant-frequency sine, as the "constant sine" shaking-table tests of seed 003.

    Displacement-defined: d(t) = D e(t) sin(omega t) on [0, cycles 2 pi / omega],
    with e(t) = 1 except for optional raised-cosine ramps of ``ramp_cycles``
    periods at both ends (see below); v and a are its exact derivatives, so away
    from the ramps a(t) = -D omega^2 sin(omega t). Build it from the peak
    acceleration with ``Harmonic(amplitude, omega=...)`` (then
    D = -amplitude / omega^2, so that a(t) = amplitude sin(omega t)) or from the
    table's displacement amplitude with :meth:`from_displacement`.

    Start and end (the documented exception to "starts from rest"): with
    ``ramp_cycles == 0`` the ground velocity jumps from 0 to D omega at t = 0 and
    back to 0 at the end (an impulsive start and stop; the acceleration is the
    pure sine throughout). A block resting on such a base feels a velocity jump
    that a one-degree-of-freedom model driven by a(t) alone does not see, so for
    engine runs prefer ``ramp_cycles >= 1``: the raised-cosine ramp
    e = (1 - cos(pi t / t_r)) / 2, t_r = ramp_cycles 2 pi / omega, starts and stops
    the table from rest with continuous velocity (finite acceleration steps only).
    After the end the displacement is held (zero for whole cycles).

    Parameters
    ----------
    amplitude : float
        Peak acceleration of the steady part (may be negative), in ``unit``.
    omega, frequency : float
        Give exactly one: circular frequency in rad/s or frequency in Hz, > 0.
    cycles, duration : float, optional
        Give at most one: the number of periods (> 0, ``inf`` allowed) or the
        duration in s (> 0); neither gives a never-ending sine (then no end ramp).
    ramp_cycles : float
        Length of each ramp in periods, >= 0, with 2 ramp_cycles <= cycles; the
        ramps are part of the ``cycles`` (cycles - 2 ramp_cycles at full amplitude).
    unit : {"m/s^2", "g"}
        Unit of ``amplitude``.
    """

    def __init__(self, amplitude: float, omega: float | None = None, *,
                 frequency: float | None = None, cycles: float | None = None,
                 duration: float | None = None, ramp_cycles: float = 0.0, unit: str = "m/s^2"):
        w = _angular_frequency(omega, frequency)
        acc = _finite("amplitude", amplitude) * _unit_factor(unit)
        self._init(-acc / w**2, w, cycles, duration, ramp_cycles)

    @classmethod
    def from_displacement(cls, amplitude: float, omega: float | None = None, *,
                          frequency: float | None = None, cycles: float | None = None,
                          duration: float | None = None, ramp_cycles: float = 0.0) -> Harmonic:
        """Sine of displacement amplitude ``amplitude`` (m): d(t) = amplitude e(t) sin(omega t).

        Same parameters as the class, with ``amplitude`` the table displacement
        amplitude in m (e.g. 003's "3.3 Hz / 6 mm" is
        ``Harmonic.from_displacement(0.006, frequency=3.3, cycles=...)``).
        """
        self = cls.__new__(cls)
        self._init(_finite("amplitude", amplitude), _angular_frequency(omega, frequency),
                   cycles, duration, ramp_cycles)
        return self

    def _init(self, displacement_amplitude: float, omega: float, cycles: float | None,
              duration: float | None, ramp_cycles: float) -> None:
        period = 2.0 * math.pi / omega
        if cycles is not None and duration is not None:
            raise ValueError(f"cycles == {cycles}, duration == {duration}: give at most one.")
        if duration is not None:
            cycles = _positive("duration", duration) / period
        cycles = math.inf if cycles is None else float(cycles)
        if not cycles > 0.0:
            raise ValueError(f"cycles == {cycles}, must be > 0 (or inf).")
        ramp_cycles = float(ramp_cycles)
        if not (0.0 <= ramp_cycles and (math.isinf(cycles) or 2.0 * ramp_cycles <= cycles)):
            raise ValueError(f"ramp_cycles == {ramp_cycles}, must be in [0, cycles / 2] "
                             f"= [0, {cycles / 2}].")
        self.omega = omega
        self.ramp = ramp_cycles * period
        super().__init__(displacement_amplitude, cycles * period, ramp=self.ramp, f0=omega)

    @property
    def amplitude(self) -> float:
        """Peak acceleration of the steady part in m/s^2 (sign as in a = amplitude sin(omega t))."""
        return -self.displacement_amplitude * self.omega**2

    def __repr__(self) -> str:
        return (f"Harmonic(displacement_amplitude={self.displacement_amplitude!r} m, "
                f"omega={self.omega!r} rad/s, duration={self.duration!r} s, ramp={self.ramp!r} s)")


class HanningSine(_EnvelopedSine):
    """Hanning-modulated sine, the "Hanning sine" shaking-table tests of seed 003 (line 75).

    d(t) = D w(t) sin(omega t) on [0, T], T = cycles 2 pi / omega, with the Hanning
    window w(t) = (1 - cos(2 pi t / T)) / 2; v and a are its exact derivatives.
    The window and its slope vanish at both ends, so the motion starts and ends
    at rest (d = v = a = 0 at t = 0 and t = T) with continuous acceleration.

    Parameters
    ----------
    amplitude : float
        Displacement amplitude D in m (peak of the window; may be negative).
    omega, frequency : float
        Give exactly one: carrier circular frequency in rad/s or frequency in Hz, > 0.
    cycles : float
        Number of carrier periods in the window, > 0.

    Examples
    --------
    003's "Hanning sine of 3.3 Hz / 7 mm": ``HanningSine(0.007, frequency=3.3, cycles=...)``
    (the number of cycles is not given in 003).
    """

    def __init__(self, amplitude: float, omega: float | None = None, *,
                 frequency: float | None = None, cycles: float):
        self.omega = _angular_frequency(omega, frequency)
        cycles = _positive("cycles", cycles)
        super().__init__(_finite("amplitude", amplitude), cycles * 2.0 * math.pi / self.omega, hanning=True,
                         f0=self.omega)

    def __repr__(self) -> str:
        return (f"HanningSine(amplitude={self.displacement_amplitude!r} m, "
                f"omega={self.omega!r} rad/s, duration={self.duration!r} s)")


class Sweep(_EnvelopedSine):
    """Constant-amplitude frequency sweep (run-up or run-down), seed 003 (lines 75, 182).

    d(t) = D e(t) sin(theta(t)) on [0, duration], with instantaneous frequency
    f(t) = theta'(t) / (2 pi) going from ``f_start`` to ``f_end`` (Hz):

    - ``law="linear"``: f(t) = f0 + (f1 - f0) t / T, theta = 2 pi (f0 t + (f1 - f0) t^2 / (2 T));
    - ``law="log"`` (exponential): f(t) = f0 (f1/f0)^(t/T),
      theta = 2 pi f0 T ((f1/f0)^(t/T) - 1) / ln(f1/f0).

    ``f_end > f_start`` is a run-up, ``f_end < f_start`` a run-down (003 ran
    5.0 -> 0.5 Hz at 3 mm and 0.5 -> 5.0 Hz at 6 mm). v and a are the exact
    derivatives. The envelope e is 1 with optional raised-cosine ramps of
    ``ramp`` seconds at both ends, as in :class:`Harmonic`; without a ramp the
    velocity jumps to D 2 pi f_start at t = 0 (documented exception to starting
    from rest) and from its final value to 0 at the end.

    Parameters
    ----------
    amplitude : float
        Displacement amplitude D in m (may be negative).
    f_start, f_end : float
        Initial and final frequencies in Hz, > 0 and different.
    duration : float
        Sweep duration T in s, > 0.
    law : {"linear", "log"}
        Frequency law.
    ramp : float
        Ramp length in s at each end, in [0, duration / 2].
    """

    def __init__(self, amplitude: float, f_start: float, f_end: float, duration: float, *,
                 law: str = "linear", ramp: float = 0.0):
        self.f_start = _positive("f_start", f_start)
        self.f_end = _positive("f_end", f_end)
        if self.f_end == self.f_start:
            raise ValueError(f"f_end == {f_end}, must differ from f_start == {f_start} "
                             "(use Harmonic for a constant frequency).")
        if law not in ("linear", "log"):
            raise ValueError(f"law == {law!r}, must be 'linear' or 'log'.")
        self.law = law
        duration = _positive("duration", duration)
        ramp = float(ramp)
        if not 0.0 <= ramp <= 0.5 * duration:
            raise ValueError(f"ramp == {ramp}, must be in [0, duration / 2] = [0, {duration / 2}].")
        self.ramp = ramp
        super().__init__(_finite("amplitude", amplitude), duration, ramp=ramp, law=1 if law == "linear" else 2,
                         f0=self.f_start, f1=self.f_end)

    def __repr__(self) -> str:
        return (f"Sweep(amplitude={self.displacement_amplitude!r} m, f_start={self.f_start!r} Hz, "
                f"f_end={self.f_end!r} Hz, duration={self.duration!r} s, law={self.law!r}, "
                f"ramp={self.ramp!r} s)")


# --------------------------------------------------------------------------- user functions
class Prescribed(Motion):
    """A motion given by three user functions of time.

    The functions must be vectorised (a float array of times in s in, an array of
    the same shape out; a constant scalar result is broadcast) and mutually
    consistent: ``velocity`` the derivative of ``displacement``, ``acceleration``
    that of ``velocity``. At construction they are evaluated at a few times in
    [0, min(duration, 1 s)]: non-finite values raise ``ValueError``; a central
    finite difference disagreeing by more than 1 % of the signal's scale raises
    a ``UserWarning`` (a loose check: it cannot prove consistency, and kinks are
    legitimate). Values for t < 0 are whatever the functions return.

    Parameters
    ----------
    displacement, velocity, acceleration : callable
        d(t) in m, v(t) in m/s, a(t) in m/s^2.
    duration : float
        Time in s after which the motion is over, > 0 (``inf`` by default).
    """

    def __init__(self, displacement: Callable, velocity: Callable, acceleration: Callable,
                 duration: float = math.inf):
        functions = {"displacement": displacement, "velocity": velocity,
                     "acceleration": acceleration}
        for name, f in functions.items():
            if not callable(f):
                raise ValueError(f"{name} == {f!r}, must be a callable f(t).")
        duration = float(duration)
        if not duration > 0.0:
            raise ValueError(f"duration == {duration}, must be > 0.")
        self._functions = (displacement, velocity, acceleration)
        self.duration = duration
        self._check(min(duration, 1.0))

    def _call(self, index: int, t: np.ndarray) -> np.ndarray:
        out = np.asarray(self._functions[index](t), dtype=float)
        if out.shape != t.shape:
            try:
                out = np.broadcast_to(out, t.shape)
            except ValueError:
                name = ("displacement", "velocity", "acceleration")[index]
                raise ValueError(f"{name} returned shape {out.shape} for times of shape "
                                 f"{t.shape}: it must be vectorised.") from None
        return out

    def _check(self, span: float) -> None:
        t = span * np.array([0.0, 0.137, 0.391, 0.642, 0.883])
        h = 1e-5 * span
        d, v, a = (self._call(i, t) for i in range(3))
        for name, values in (("displacement", d), ("velocity", v), ("acceleration", a)):
            bad = np.flatnonzero(~np.isfinite(values))
            if bad.size:
                raise ValueError(f"{name}({t[bad[0]]}) == {values[bad[0]]}, must be finite.")
        for lower, upper, name in ((0, 1, "velocity"), (1, 2, "acceleration")):
            fd = (self._call(lower, t[1:] + h) - self._call(lower, t[1:] - h)) / (2.0 * h)
            exact = (v, a)[lower][1:]
            scale = max(np.max(np.abs(exact)), np.max(np.abs(fd)), 1e-12)
            if np.max(np.abs(fd - exact)) > 1e-2 * scale:
                warnings.warn(f"Prescribed: {name} does not match the finite-difference "
                              f"derivative of {('displacement', 'velocity')[lower]} "
                              f"(max difference {np.max(np.abs(fd - exact)):.3g}, scale "
                              f"{scale:.3g}); check the functions.", UserWarning, stacklevel=3)

    def _kinematics(self, t):
        return self._call(0, t), self._call(1, t), self._call(2, t)


class Scaled(Motion):
    """A motion multiplied by a constant factor: d, v and a all scaled (picklable).

    Keeps the attributes by which the 1-DOF model recognises a motion's structure
    (``dt``, ``omega``, ``phase``; ``amplitude`` and ``samples_mps2`` scaled): a scaled
    pulse keeps its closed-form flights and a scaled record its sample breakpoints.

    Parameters
    ----------
    motion : Motion
    factor : float
        Finite; may be negative or zero.
    """

    def __init__(self, motion: Motion, factor: float):
        if not isinstance(motion, Motion):
            raise TypeError(f"motion must be an nscd.motion.Motion, got {type(motion).__name__}.")
        self.motion, self.factor = motion, _finite("factor", factor)
        self.duration = motion.duration
        for name in ("dt", "omega", "phase"):
            if hasattr(motion, name):
                setattr(self, name, getattr(motion, name))
        for name in ("amplitude", "samples_mps2"):
            if hasattr(motion, name):
                setattr(self, name, self.factor * np.asarray(getattr(motion, name)))

    def _kinematics(self, t):
        d, v, a = self.motion._kinematics(t)
        return self.factor * d, self.factor * v, self.factor * a

    def acceleration_at(self, t: float) -> float:
        return self.factor * self.motion.acceleration_at(t)

    def _compiled(self) -> tuple | None:
        inner = self.motion._compiled()
        return None if inner is None else (inner[0], self.factor * inner[1], *inner[2:])

    def __repr__(self) -> str:
        return f"Scaled({self.motion!r}, factor={self.factor!r})"


# --------------------------------------------------------------------------- records
_AT2_UNITS = (  # (pattern on the 3rd header line, unit, factor to that unit)
    (re.compile(r"\bCM\s*/\s*S(EC)?\s*(\^?2|\*\*2|/\s*S(EC)?|2)|\bGALS?\b", re.I), "m/s^2", 0.01),
    (re.compile(r"\bM\s*/\s*S(EC)?\s*(\^?2|\*\*2|/\s*S(EC)?|2)", re.I), "m/s^2", 1.0),
    (re.compile(r"\bG\b", re.I), "g", 1.0),
)


_AT2_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eEdD][-+]?\d+)?"
_AT2_NAMED = (re.compile(rf"NPTS\s*=\s*({_AT2_NUMBER})", re.I), re.compile(rf"DT\s*=\s*({_AT2_NUMBER})", re.I))
_AT2_LISTED = re.compile(rf"^\s*({_AT2_NUMBER})[\s,]+({_AT2_NUMBER})[\s,]+(NPTS|DT)\s*,?\s*(NPTS|DT)\b", re.I)


def _at2_npts_dt(path: Path, line: str) -> tuple[int, float]:
    """Number of points and step (s) from the 4th line of a PEER ``.AT2`` header (both layouts)."""
    named = [pattern.search(line) for pattern in _AT2_NAMED]
    listed = _AT2_LISTED.match(line)
    if all(named):
        npts, dt = (match.group(1) for match in named)
    elif listed and {listed.group(3).upper(), listed.group(4).upper()} == {"NPTS", "DT"}:
        values = {listed.group(3).upper(): listed.group(1), listed.group(4).upper(): listed.group(2)}
        npts, dt = values["NPTS"], values["DT"]
    else:
        raise ValueError(f"{path}: header line 4 must give 'NPTS= N, DT= X SEC' or 'N  X  NPTS, DT', "
                         f"got {line!r}.")
    n = float(npts.replace("D", "E").replace("d", "e"))
    if n != int(n) or n < 2:
        raise ValueError(f"{path}: NPTS == {npts} on header line 4, must be a whole number >= 2.")
    return int(n), float(dt.replace("D", "E").replace("d", "e"))


class Record(_Compiled):
    """A recorded (or synthetic) accelerogram sampled at a constant step.

    The acceleration is the piecewise-linear interpolation of the samples
    a_k at t_k = k dt, k = 0 .. n - 1, and zero for t < 0 and t > (n - 1) dt
    (``duration``). Velocity and displacement are its exact integrals from rest:
    on [t_k, t_k + s], s <= dt,

        v = v_k + a_k s + (a_{k+1} - a_k) s^2 / (2 dt),
        d = d_k + v_k s + a_k s^2 / 2 + (a_{k+1} - a_k) s^3 / (6 dt),

    i.e. the trapezoidal rule for v and the exact cubic for d at the samples;
    after the end v stays at its final value and d grows linearly with it. A raw
    record's final velocity is rarely zero; see :meth:`baseline_corrected`.

    Parameters
    ----------
    samples : array_like, shape (n,)
        Accelerations in ``unit``; n >= 2, all finite.
    dt : float
        Sampling step in s, > 0.
    unit : {"m/s^2", "g"}
        Unit of ``samples``; required, never guessed.
    name : str
        Label (e.g. the file it came from).

    Attributes
    ----------
    samples_mps2 : ndarray, shape (n,)
        The samples in m/s^2 (read-only).
    dt, duration, name
    """

    def __init__(self, samples, dt: float, unit: str, *, name: str = ""):
        factor = _unit_factor(unit)
        try:
            values = np.array(samples, dtype=float)
        except (TypeError, ValueError) as err:
            raise TypeError(f"samples must be real numbers (accelerations in {unit}): {err}.") from None
        if values.ndim != 1 or values.size < 2:
            raise ValueError(f"samples has shape {values.shape}, must be 1-D with at least 2 values.")
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise ValueError(f"samples[{bad[0]}] == {values[bad[0]]}, must be finite "
                             f"({bad.size} non-finite value(s) in {name or 'the record'}).")
        self.dt = _positive("dt", dt)
        if not math.isfinite((values.size - 1) * self.dt * self.dt):
            raise ValueError(f"dt == {self.dt} s with {values.size} samples: the duration (n - 1) dt or "
                             "dt^2 overflows; dt must keep both finite.")
        self.name = str(name)
        self.samples_mps2 = values * factor
        self.samples_mps2.setflags(write=False)
        self.duration = (values.size - 1) * self.dt
        a = self.samples_mps2
        v = np.concatenate(([0.0], np.cumsum(0.5 * self.dt * (a[:-1] + a[1:]))))
        dd = v[:-1] * self.dt + self.dt**2 * (a[:-1] / 3.0 + a[1:] / 6.0)
        self._v = v
        self._d = np.concatenate(([0.0], np.cumsum(dd)))
        self._kind, self._par = _RECORD, np.array([self.dt, self.duration])
        self._tables = (np.array(a), self._v, self._d)  # writable copies: one compiled signature

    @property
    def time(self) -> np.ndarray:
        """Sample times t_k = k dt in s, shape (n,)."""
        return np.arange(self.samples_mps2.size) * self.dt

    @property
    def pga(self) -> float:
        """Peak ground acceleration max |a_k| in m/s^2."""
        return float(np.max(np.abs(self.samples_mps2)))

    def __len__(self) -> int:
        return self.samples_mps2.size

    def __repr__(self) -> str:
        return (f"Record({self.name or 'unnamed'!r}, n={len(self)}, dt={self.dt!r} s, "
                f"pga={self.pga:.4g} m/s^2)")

    # -------------------------------------------------------------- derived records
    def _with_samples(self, samples_mps2: np.ndarray, name: str) -> Record:
        return Record(samples_mps2, self.dt, "m/s^2", name=name)

    def scaled(self, factor: float) -> Record:
        """Record with every sample multiplied by ``factor`` (finite, may be negative)."""
        factor = _finite("factor", factor)
        return self._with_samples(factor * self.samples_mps2, f"{self.name} x {factor:g}")

    def scaled_to_pga(self, pga: float, unit: str) -> Record:
        """Record scaled so that its peak |a| is ``pga`` (> 0) in ``unit`` ("m/s^2" or "g")."""
        target = _positive("pga", pga) * _unit_factor(unit)
        if self.pga == 0.0:
            raise ValueError(f"record {self.name!r} is identically zero: cannot scale to a PGA.")
        return self.scaled(target / self.pga)

    def reversed(self) -> Record:
        """Record of opposite polarity (every sample negated), same time axis."""
        return self._with_samples(-self.samples_mps2, f"-{self.name}")

    def baseline_corrected(self, order: int = 2) -> Record:
        """Record with the least-squares polynomial trend of its velocity removed.

        The velocity at the samples, v_k, is fitted by least squares with
        p(t) = sum_{j=1..order} c_j t^j (no constant term, so the motion still
        starts from rest) and the derivative p'(t) is subtracted from the
        acceleration samples. p' is a polynomial of degree order - 1 <= 1, which
        the piecewise-linear interpolation represents exactly, so the corrected
        record's velocity is exactly v(t) - p(t) and the displacement its exact
        integral. ``order=1`` removes a constant acceleration offset, ``order=2``
        (the default) also a linear drift. Applied to PGV and PGD only when asked
        (``baseline_order`` of :func:`nscd.intensity.intensity_measures`).

        Parameters
        ----------
        order : {1, 2}
            Degree of the velocity trend.
        """
        if order not in (1, 2):
            raise ValueError(f"order == {order!r}, must be 1 or 2.")
        t = self.time
        basis = np.column_stack([t**j for j in range(1, order + 1)])
        coef, *_ = np.linalg.lstsq(basis, self._v, rcond=None)
        trend_slope = sum(j * coef[j - 1] * t ** (j - 1) for j in range(1, order + 1))
        return self._with_samples(self.samples_mps2 - trend_slope, f"{self.name} (baseline {order})")

    # -------------------------------------------------------------- readers
    @classmethod
    def from_at2(cls, path: str | Path) -> Record:
        """Read a PEER NGA ``.AT2`` file.

        Four header lines: the third names the unit (``G``, ``CM/S/S`` / ``GAL``
        or ``M/S/S``; cm/s^2 is converted to m/s^2), the fourth gives the
        number of points and the step in either PEER layout:
        ``NPTS=  1559, DT= .0200 SEC`` (the NGA database; order, spacing and
        case are free) or ``1559    0.0200    NPTS, DT`` (the older strong-motion
        database: the values first, then their names in the same order). Then
        at least N values, any number to a line; values beyond N (padding) are
        ignored.

        Raises
        ------
        ValueError
            Naming the file when the header cannot be parsed, a value is not a
            number, or fewer than N values follow.
        """
        path = Path(path)
        try:
            lines = path.read_text().splitlines()
        except UnicodeDecodeError as err:
            raise ValueError(f"{path}: not a text file (byte {err.start} is {err.object[err.start:err.start + 1]!r}); "
                             "a PEER .AT2 file is plain text.") from None
        if len(lines) < 4:
            raise ValueError(f"{path}: {len(lines)} line(s), a PEER .AT2 file has a 4-line header.")
        unit, factor = None, 1.0
        for pattern, unit_name, unit_factor in _AT2_UNITS:
            if pattern.search(lines[2]):
                unit, factor = unit_name, unit_factor
                break
        if unit is None:
            raise ValueError(f"{path}: no acceleration unit (G, CM/S/S, M/S/S) on header line 3: "
                             f"{lines[2]!r}.")
        n, dt = _at2_npts_dt(path, lines[3])
        tokens = " ".join(lines[4:]).replace("D", "E").replace("d", "e").split()
        if len(tokens) < n:
            raise ValueError(f"{path}: NPTS == {n} but only {len(tokens)} value(s) follow the header.")
        try:
            values = np.array([float(x) for x in tokens[:n]])
        except ValueError as err:
            raise ValueError(f"{path}: {err}.") from None
        return cls(values * factor, dt, unit, name=path.stem)

    @classmethod
    def from_text(cls, path: str | Path, unit: str, *, skiprows: int = 0,
                  delimiter: str | None = None, rtol: float = 1e-3) -> Record:
        """Read a two-column text file: time in s, acceleration in ``unit``.

        Times must be increasing with a constant step: every step must equal
        dt = (t_last - t_first) / (n - 1) within ``rtol * dt`` (default 1e-3,
        room for times printed with few digits). Times are taken relative to the
        first one (the record starts at t = 0).

        Parameters
        ----------
        path : str or Path
        unit : {"m/s^2", "g"}
            Unit of the acceleration column; required.
        skiprows : int
            Header lines to skip.
        delimiter : str, optional
            Column separator (whitespace by default).
        rtol : float
            Relative tolerance of the uniform-step check, > 0.
        """
        _unit_factor(unit)
        rtol = _positive("rtol", rtol)
        path = Path(path)
        try:
            data = np.loadtxt(path, skiprows=skiprows, delimiter=delimiter, ndmin=2)
        except ValueError as err:
            raise ValueError(f"{path}: {err}") from None
        if data.shape[1] != 2 or data.shape[0] < 2:
            raise ValueError(f"{path}: found {data.shape[0]} row(s) of {data.shape[1]} column(s), "
                             "need at least 2 rows of (time, acceleration).")
        t = data[:, 0]
        dt = (t[-1] - t[0]) / (t.size - 1)
        if not dt > 0.0:
            raise ValueError(f"{path}: times run from {t[0]} to {t[-1]} s, must increase.")
        step_error = np.abs(np.diff(t) - dt)
        worst = int(np.argmax(step_error))
        if step_error[worst] > rtol * dt:
            raise ValueError(f"{path}: time step between rows {worst + skiprows} and "
                             f"{worst + skiprows + 1} is {t[worst + 1] - t[worst]} s, the mean step "
                             f"is {dt} s: the step must be uniform (rtol={rtol}).")
        return cls(data[:, 1], dt, unit, name=path.stem)

    @classmethod
    def example(cls, name: str = "elcentro_1940_ns") -> Record:
        """A record shipped with nscd (``nscd/data/<name>.AT2``).

        Available: ``"elcentro_1940_ns"`` (Imperial Valley 1940, El Centro N-S,
        1559 samples at 0.02 s, PGA 0.319 g; public domain).
        """
        folder = resources.files("nscd").joinpath("data")
        available = sorted(p.name[:-4] for p in folder.iterdir() if p.name.endswith(".AT2"))
        if name not in available:
            raise ValueError(f"name == {name!r}, must be one of {available}.")
        with resources.as_file(folder.joinpath(f"{name}.AT2")) as path:
            return cls.from_at2(path)


def elcentro() -> Record:
    """The El Centro 1940 N-S record shipped with nscd (PGA 0.319 g at 2.02 s)."""
    return Record.example("elcentro_1940_ns")
