"""Ground-motion intensity measures of an accelerogram.

The measures are those Sorrentino, Masiani & Decanini correlate with the
overturning of rocking blocks (seed 001, lines 150-227): PGA, PGV, PGD, Arias
intensity, Araya-Saragoni destructiveness potential, significant durations,
RMS acceleration, characteristic and Fajfar intensities, maximum incremental
velocity and predominant period. Duration-based quantities follow 001 in using
the 10-90 % significant duration Delta t_80 (001 line 184, eqs 7-9).

Two integration conventions (``integration=``):

``"samples"`` (default)
    The field's convention: the trapezoidal rule over the samples as they are
    (cumulative int a^2 dt for Arias and the Husid plot, v = cumulative
    trapezoid of a, d = cumulative trapezoid of v). PEER flatfiles, USGS
    gmprocess, eqsig and SeismoSignal compute this way, so the numbers match the
    databases a user quotes.
``"interpolant"``
    The exact integrals of the piecewise-linear acceleration that
    :class:`nscd.motion.Record` drives a base with (int a^2 dt by the rule
    dt/3 (a_k^2 + a_k a_{k+1} + a_{k+1}^2), the exact cubic displacement). It
    gives Arias intensities a few per cent lower than the trapezoid on records
    sampled at 50-100 Hz, since a^2 of a linear segment is smaller than the
    average of its end values.

No baseline correction is applied unless ``baseline_order`` asks for one.
"""
from __future__ import annotations

import numpy as np

from nscd.motion import STANDARD_GRAVITY, Record

__all__ = ["INTEGRATIONS", "UNITS", "intensity_measures"]

UNITS = {
    "PGA": "m/s^2", "PGV": "m/s", "PGD": "m", "arias": "m/s", "D5_95": "s", "D10_90": "s",
    "a_rms": "m/s^2", "Ic": "m^1.5/s^2.5", "If": "m/s^0.75", "nu0": "1/s", "PD": "m s",
    "IV_max": "m/s", "Tp": "s",
}
"""Unit of each key returned by :func:`intensity_measures`."""


INTEGRATIONS = ("samples", "interpolant")
"""Accepted values of ``integration`` in :func:`intensity_measures`."""


def _cumulative_square(record: Record, integration: str) -> np.ndarray:
    """Cumulative int_0^{t_k} a^2 dt at the samples, (m/s^2)^2 s, shape (n,).

    ``"samples"``: trapezoid dt (a_k^2 + a_{k+1}^2) / 2; ``"interpolant"``: the
    exact integral of the square of the linear segment, dt/3 (a_k^2 + a_k a_{k+1} + a_{k+1}^2).
    """
    a, dt = record.samples_mps2, record.dt
    if integration == "samples":
        steps = 0.5 * dt * (a[:-1] ** 2 + a[1:] ** 2)
    else:
        steps = dt / 3.0 * (a[:-1] ** 2 + a[:-1] * a[1:] + a[1:] ** 2)
    return np.concatenate(([0.0], np.cumsum(steps)))


def _velocity_displacement(record: Record, integration: str) -> tuple[np.ndarray, np.ndarray]:
    """Velocity (m/s) and displacement (m) at the samples, integrated from rest.

    The velocity is the cumulative trapezoid of a in both conventions (which is
    exact for the piecewise-linear a, :class:`Record`); the displacement is the cumulative trapezoid of v
    (``"samples"``) or the exact cubic (``"interpolant"``).
    """
    t = record.time
    v = record.velocity(t)
    if integration == "interpolant":
        return v, record.displacement(t)
    return v, np.concatenate(([0.0], np.cumsum(0.5 * record.dt * (v[:-1] + v[1:]))))


def _zero_crossings(record: Record) -> np.ndarray:
    """Times (s) where the piecewise-linear acceleration changes sign.

    Between two consecutive nonzero samples of opposite sign the crossing is
    the exact root of the linear interpolant; when zero samples separate them,
    the first zero sample is taken (a is zero over the whole run, so the choice
    does not change any area). Touching zero without a sign change is no crossing.
    """
    a, t = record.samples_mps2, record.time
    nonzero = np.flatnonzero(a != 0.0)
    i, j = nonzero[:-1], nonzero[1:]
    flip = np.sign(a[i]) != np.sign(a[j])
    i, j = i[flip], j[flip]
    root = t[i] + record.dt * a[i] / (a[i] - a[j])
    return np.where(j == i + 1, root, t[np.minimum(i + 1, t.size - 1)])


def intensity_measures(record: Record, *, integration: str = "samples",
                       baseline_order: int | None = None) -> dict[str, float]:
    """Intensity measures of an accelerogram (units in :data:`UNITS`).

    Parameters
    ----------
    record : Record
        The accelerogram.
    integration : {"samples", "interpolant"}
        ``"samples"`` (default): trapezoidal rule over the samples, the
        convention of PEER, gmprocess, eqsig and SeismoSignal; ``"interpolant"``:
        exact integrals of the piecewise-linear acceleration nscd drives bases
        with (see the module docstring).
    baseline_order : {1, 2} or None
        ``None`` (default) takes the record as it is, like the databases do.
        1 or 2: remove the least-squares velocity trend of that order
        (:meth:`Record.baseline_corrected`) before computing PGV, PGD and If.

    Returns
    -------
    dict
        ``"PGA"``
            max |a| at the samples, m/s^2.
        ``"PGV"``, ``"PGD"``
            max |v|, max |d| at the samples, integrated from rest, m/s and m.
        ``"arias"``
            Arias intensity I_A = pi / (2 g) int a^2 dt (001 eq 6), m/s, with
            g = 9.80665 m/s^2 (eqsig uses 9.81: 0.03 % lower).
        ``"D5_95"``, ``"D10_90"``
            Significant durations t_95 - t_5 and t_90 - t_10 (Trifunac & Brady;
            001 line 184) from the Husid plot (cumulative int a^2 dt at the
            samples, linearly interpolated between them), s.
        ``"a_rms"``
            RMS acceleration over [t_10, t_90], sqrt(0.8 int a^2 dt / Delta t_80)
            (Housner & Jennings, 001 eq 7), m/s^2.
        ``"Ic"``
            Characteristic intensity a_rms^1.5 Delta t_80^0.5 (Park et al., 001 eq 8).
        ``"If"``
            Fajfar intensity PGV Delta t_80^0.25 (001 eq 9).
        ``"nu0"``
            Zero crossings of the acceleration per second over the whole record,
            1/s (001 line 178).
        ``"PD"``
            Destructiveness potential I_A / nu0^2 (Araya & Saragoni, 001 eq 5), m s;
            ``inf`` when the acceleration never changes sign.
        ``"IV_max"``
            Maximum incremental velocity (Anderson & Bertero, 001 line 209): the
            largest |int a dt| between consecutive zero crossings (and the record
            ends) of the uncorrected record, exact for the piecewise-linear
            acceleration (the trapezoid of the samples between crossings), m/s.
        ``"Tp"``
            Predominant period, 1 / (frequency of the peak of the Fourier
            amplitude spectrum of the samples) (Ojeda & Escallon; 001 line 196),
            with the record zero-padded to at least 4 times its length (period
            resolution Tp^2 / (4 duration)), s.
    """
    if not isinstance(record, Record):
        raise TypeError(f"record is a {type(record).__name__}, must be an nscd.motion.Record.")
    if integration not in INTEGRATIONS:
        raise ValueError(f"integration == {integration!r}, must be one of {INTEGRATIONS}.")
    if record.pga == 0.0:
        raise ValueError(f"record {record.name!r} is identically zero: no intensity measures.")
    corrected = record if baseline_order is None else record.baseline_corrected(baseline_order)
    a, dt, t = record.samples_mps2, record.dt, record.time

    husid = _cumulative_square(record, integration)
    integral_a2 = float(husid[-1])
    t5, t10, t90, t95 = np.interp(np.array([0.05, 0.10, 0.90, 0.95]) * integral_a2, husid, t)
    d80 = float(t90 - t10)
    a_rms = float(np.sqrt(0.8 * integral_a2 / d80))
    velocity, displacement = _velocity_displacement(corrected, integration)
    pgv = float(np.max(np.abs(velocity)))

    crossings = _zero_crossings(record)
    nu0 = crossings.size / record.duration
    arias = np.pi / (2.0 * STANDARD_GRAVITY) * integral_a2
    bounds = np.concatenate(([0.0], crossings, [record.duration]))
    iv_max = float(np.max(np.abs(np.diff(record.velocity(bounds)))))

    n_fft = int(2 ** np.ceil(np.log2(4 * a.size)))
    amplitude = np.abs(np.fft.rfft(a, n_fft))
    freqs = np.fft.rfftfreq(n_fft, dt)
    f_peak = freqs[1 + int(np.argmax(amplitude[1:]))]

    return {
        "PGA": record.pga,
        "PGV": pgv,
        "PGD": float(np.max(np.abs(displacement))),
        "arias": float(arias),
        "D5_95": float(t95 - t5),
        "D10_90": d80,
        "a_rms": a_rms,
        "Ic": a_rms**1.5 * d80**0.5,
        "If": pgv * d80**0.25,
        "nu0": float(nu0),
        "PD": float(arias / nu0**2) if nu0 > 0.0 else float("inf"),
        "IV_max": iv_max,
        "Tp": float(1.0 / f_peak),
    }
