"""Ground motions: the horizontal (or vertical) base excitation of a scene.

Every motion is a :class:`Motion`, a scalar function of time along one axis with
``acceleration(t)`` (m/s^2), ``velocity(t)`` (m/s) and ``displacement(t)`` (m),
vectorised over ``t`` (a float in, a float out; an array in, an array of the same
shape out), and a ``duration`` (s) after which the motion is over (``inf`` if
never). Velocity is the exact time derivative of displacement and acceleration
the exact derivative of velocity, for every class here. Every motion is zero for
``t < 0`` and starts from rest at ``t = 0`` unless its class documents otherwise
(only :class:`Harmonic` and :class:`Sweep` without a ramp do).

Amplitudes are in m/s^2 unless ``unit="g"`` says otherwise (``g`` is the standard
gravity :data:`STANDARD_GRAVITY`); displacements in m.

Sign convention (``docs/architecture.md``): a positive horizontal ground
acceleration starts a clockwise (negative) rotation of a block at rest.

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
from collections.abc import Callable
from importlib import resources
from pathlib import Path

import numpy as np
from scipy.optimize import brentq

__all__ = [
    "STANDARD_GRAVITY", "Motion", "OneSine", "OneCosine", "TypeCn", "Harmonic",
    "HanningSine", "Sweep", "Prescribed", "Record", "elcentro",
]

STANDARD_GRAVITY = 9.80665
"""Standard gravity in m/s^2, used to convert amplitudes given in ``g``."""

_UNITS = {"m/s^2": 1.0, "g": STANDARD_GRAVITY}

TimeLike = float | np.ndarray


# --------------------------------------------------------------------------- checks
def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{name} == {value}, must be finite.")
    return value


def _positive(name: str, value: float) -> float:
    value = float(value)
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


# --------------------------------------------------------------------------- base
class Motion(abc.ABC):
    """A ground motion along one axis: a(t) in m/s^2, v(t) in m/s, d(t) in m.

    Subclasses implement ``_kinematics(t)`` on a 1-D float array and return the
    triple (displacement, velocity, acceleration); the public methods handle
    scalars and shapes.

    Attributes
    ----------
    duration : float
        Time in s after which the motion is over (acceleration zero for good);
        ``inf`` if it never ends.
    """

    duration: float

    @abc.abstractmethod
    def _kinematics(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (d, v, a) at the times ``t`` (1-D array, s)."""

    def _evaluate(self, t: TimeLike, which: int) -> TimeLike:
        t_arr = np.asarray(t, dtype=float)
        out = self._kinematics(np.atleast_1d(t_arr).ravel())[which].reshape(t_arr.shape)
        return float(out) if t_arr.ndim == 0 else out

    def displacement(self, t: TimeLike) -> TimeLike:
        """Ground displacement in m at time(s) ``t`` (s); same shape as ``t``."""
        return self._evaluate(t, 0)

    def velocity(self, t: TimeLike) -> TimeLike:
        """Ground velocity in m/s at time(s) ``t`` (s); d/dt of :meth:`displacement`."""
        return self._evaluate(t, 1)

    def acceleration(self, t: TimeLike) -> TimeLike:
        """Ground acceleration in m/s^2 at time(s) ``t`` (s); d/dt of :meth:`velocity`."""
        return self._evaluate(t, 2)


# --------------------------------------------------------------------------- pulses
class _SinePulse(Motion):
    """a(t) = A sin(omega t + phase) on [0, duration], zero otherwise, from rest.

    The exact integrals from rest are

        v(t) = A/omega (cos(phase) - cos(omega t + phase)),
        d(t) = A/omega cos(phase) t - A/omega^2 (sin(omega t + phase) - sin(phase)),

    continued linearly after the pulse: v(t) = v(T), d(t) = d(T) + v(T) (t - T).
    """

    def __init__(self, amplitude: float, omega: float, unit: str, phase: float, duration: float):
        self.amplitude = _finite("amplitude", amplitude) * _unit_factor(unit)
        self.omega = _positive("omega", omega)
        self.phase = phase
        self.duration = duration

    def _kinematics(self, t):
        A, w, p = self.amplitude, self.omega, self.phase
        tc = np.clip(t, 0.0, self.duration)
        a = np.where((t >= 0.0) & (t <= self.duration), A * np.sin(w * tc + p), 0.0)
        v = A / w * (math.cos(p) - np.cos(w * tc + p))
        d = A / w * math.cos(p) * tc - A / w**2 * (np.sin(w * tc + p) - math.sin(p))
        d = d + v * (np.maximum(t, 0.0) - tc)
        return d, v, a

    def __repr__(self) -> str:
        return f"{type(self).__name__}(amplitude={self.amplitude!r} m/s^2, omega={self.omega!r} rad/s)"


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
class _EnvelopedSine(Motion):
    """Displacement-defined motion d(t) = D e(t) sin(theta(t)) on [0, duration].

    Velocity and acceleration are the exact derivatives (product and chain rule)

        v = D (e' sin(theta) + e theta' cos(theta)),
        a = D (e'' sin(theta) + (2 e' theta' + e theta'') cos(theta) - e theta'^2 sin(theta)).

    Before t = 0 everything is zero; after ``duration`` the displacement is held
    at its final value with zero velocity and acceleration. Subclasses give the
    envelope (e, e', e'') and the phase (theta, theta', theta'').
    """

    def __init__(self, displacement_amplitude: float, duration: float):
        self.displacement_amplitude = displacement_amplitude
        self.duration = duration

    @abc.abstractmethod
    def _envelope(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(e, de/dt, d2e/dt2) for t in [0, duration]."""

    @abc.abstractmethod
    def _phase(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(theta, dtheta/dt, d2theta/dt2) in rad, rad/s, rad/s^2 for t in [0, duration]."""

    def _kinematics(self, t):
        D = self.displacement_amplitude
        tc = np.clip(t, 0.0, self.duration)
        e, de, dde = self._envelope(tc)
        th, dth, ddth = self._phase(tc)
        s, c = np.sin(th), np.cos(th)
        inside = (t >= 0.0) & (t <= self.duration)
        d = np.where(t >= 0.0, D * e * s, 0.0)
        v = np.where(inside, D * (de * s + e * dth * c), 0.0)
        a = np.where(inside, D * (dde * s + (2.0 * de * dth + e * ddth) * c - e * dth**2 * s), 0.0)
        return d, v, a


def _raised_cosine_ramps(t: np.ndarray, duration: float, ramp: float):
    """Envelope 1 with raised-cosine ramps of length ``ramp`` (s) at both ends.

    e = (1 - cos(pi t / ramp)) / 2 on [0, ramp], 1 in the middle, mirrored on
    [duration - ramp, duration]; e and e' are continuous, e'' jumps at the ramp
    ends (finite acceleration steps). ``ramp == 0`` gives e = 1 throughout.
    """
    e, de, dde = np.ones_like(t), np.zeros_like(t), np.zeros_like(t)
    if ramp == 0.0:
        return e, de, dde
    k = math.pi / ramp
    for tau, sign in ((t, 1.0), (duration - t, -1.0)):
        m = tau < ramp
        e[m] = 0.5 * (1.0 - np.cos(k * tau[m]))
        de[m] = sign * 0.5 * k * np.sin(k * tau[m])
        dde[m] = 0.5 * k**2 * np.cos(k * tau[m])
    return e, de, dde


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
    cycles : float
        Number of periods, > 0, or ``inf`` for a never-ending sine (then no end ramp).
    ramp_cycles : float
        Length of each ramp in periods, >= 0, with 2 ramp_cycles <= cycles.
    unit : {"m/s^2", "g"}
        Unit of ``amplitude``.
    """

    def __init__(self, amplitude: float, omega: float | None = None, *,
                 frequency: float | None = None, cycles: float = math.inf,
                 ramp_cycles: float = 0.0, unit: str = "m/s^2"):
        w = _angular_frequency(omega, frequency)
        acc = _finite("amplitude", amplitude) * _unit_factor(unit)
        self._init(-acc / w**2, w, cycles, ramp_cycles)

    @classmethod
    def from_displacement(cls, amplitude: float, omega: float | None = None, *,
                          frequency: float | None = None, cycles: float = math.inf,
                          ramp_cycles: float = 0.0) -> Harmonic:
        """Sine of displacement amplitude ``amplitude`` (m): d(t) = amplitude e(t) sin(omega t).

        Same parameters as the class, with ``amplitude`` the table displacement
        amplitude in m (e.g. 003's "3.3 Hz / 6 mm" is
        ``Harmonic.from_displacement(0.006, frequency=3.3, cycles=...)``).
        """
        self = cls.__new__(cls)
        self._init(_finite("amplitude", amplitude), _angular_frequency(omega, frequency),
                   cycles, ramp_cycles)
        return self

    def _init(self, displacement_amplitude: float, omega: float, cycles: float,
              ramp_cycles: float) -> None:
        cycles = float(cycles)
        if not cycles > 0.0:
            raise ValueError(f"cycles == {cycles}, must be > 0 (or inf).")
        ramp_cycles = float(ramp_cycles)
        if not (0.0 <= ramp_cycles and (math.isinf(cycles) or 2.0 * ramp_cycles <= cycles)):
            raise ValueError(f"ramp_cycles == {ramp_cycles}, must be in [0, cycles / 2] "
                             f"= [0, {cycles / 2}].")
        self.omega = omega
        period = 2.0 * math.pi / omega
        self.ramp = ramp_cycles * period
        super().__init__(displacement_amplitude, cycles * period)

    @property
    def amplitude(self) -> float:
        """Peak acceleration of the steady part in m/s^2 (sign as in a = amplitude sin(omega t))."""
        return -self.displacement_amplitude * self.omega**2

    def _envelope(self, t):
        return _raised_cosine_ramps(t, self.duration, self.ramp)

    def _phase(self, t):
        return self.omega * t, np.full_like(t, self.omega), np.zeros_like(t)

    def __repr__(self) -> str:
        return (f"Harmonic(displacement_amplitude={self.displacement_amplitude!r} m, "
                f"omega={self.omega!r} rad/s, duration={self.duration!r} s, ramp={self.ramp!r} s)")


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
