"""Ground-motion intensity measures of an accelerogram.

The measures are those Sorrentino, Masiani & Decanini correlate with the
overturning of rocking blocks (seed 001, lines 150-227): PGA, PGV, PGD, Arias
intensity, Araya-Saragoni destructiveness potential, significant durations,
RMS acceleration, characteristic and Fajfar intensities, maximum incremental
velocity and predominant period. Duration-based quantities follow 001 in using
the 10-90 % significant duration Delta t_80 (001 line 184, eqs 7-9).

All integrals are exact for the record's piecewise-linear acceleration
(see :class:`nscd.motion.Record`).
"""
from __future__ import annotations

import numpy as np

from nscd.motion import STANDARD_GRAVITY, Record

__all__ = ["UNITS", "intensity_measures"]

UNITS = {
    "PGA": "m/s^2", "PGV": "m/s", "PGD": "m", "arias": "m/s", "D5_95": "s", "D10_90": "s",
    "a_rms": "m/s^2", "Ic": "m^1.5/s^2.5", "If": "m/s^0.75", "nu0": "1/s", "PD": "m s",
    "IV_max": "m/s", "Tp": "s",
}
"""Unit of each key returned by :func:`intensity_measures`."""


def _husid_times(record: Record, fractions: tuple[float, ...]) -> np.ndarray:
    """Times (s) at which the cumulative integral of a^2 reaches the given fractions.

    The cumulative integral is exact at the samples (Simpson-like rule
    dt/3 (a_k^2 + a_k a_{k+1} + a_{k+1}^2), exact for a piecewise-linear a) and
    linearly interpolated between them.
    """
    a, dt = record.samples_mps2, record.dt
    steps = dt / 3.0 * (a[:-1] ** 2 + a[:-1] * a[1:] + a[1:] ** 2)
    husid = np.concatenate(([0.0], np.cumsum(steps)))
    return np.interp(np.asarray(fractions) * husid[-1], husid, record.time)


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


def intensity_measures(record: Record, *, baseline_order: int | None = 2) -> dict[str, float]:
    """Intensity measures of an accelerogram (units in :data:`UNITS`).

    Parameters
    ----------
    record : Record
        The accelerogram (piecewise-linear acceleration).
    baseline_order : {1, 2} or None
        Order of the least-squares velocity-trend removal
        (:meth:`Record.baseline_corrected`) applied before computing PGV, PGD
        and If; ``None`` integrates the record as it is.

    Returns
    -------
    dict
        ``"PGA"``
            max |a| at the samples, m/s^2.
        ``"PGV"``, ``"PGD"``
            max |v|, max |d| at the samples of the (baseline-corrected) record
            integrated exactly from rest, m/s and m.
        ``"arias"``
            Arias intensity I_A = pi / (2 g) int a^2 dt (001 eq 6), m/s, with
            g = 9.80665 m/s^2.
        ``"D5_95"``, ``"D10_90"``
            Significant durations t_95 - t_5 and t_90 - t_10 (Trifunac & Brady;
            001 line 184) from the Husid plot (cumulative int a^2 dt), s.
        ``"a_rms"``
            RMS acceleration over [t_10, t_90], sqrt(int a^2 dt / Delta t_80)
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
            acceleration, m/s.
        ``"Tp"``
            Predominant period, 1 / (frequency of the peak of the Fourier
            amplitude spectrum of the samples) (Ojeda & Escallon; 001 line 196),
            with the record zero-padded to at least 4 times its length (period
            resolution Tp^2 / (4 duration)), s.
    """
    if not isinstance(record, Record):
        raise TypeError(f"record is a {type(record).__name__}, must be an nscd.motion.Record.")
    if record.pga == 0.0:
        raise ValueError(f"record {record.name!r} is identically zero: no intensity measures.")
    if baseline_order is None:
        corrected = record
    else:
        corrected = record.baseline_corrected(baseline_order)
    a, dt, t = record.samples_mps2, record.dt, record.time

    integral_a2 = float(np.sum(dt / 3.0 * (a[:-1] ** 2 + a[:-1] * a[1:] + a[1:] ** 2)))
    t5, t10, t90, t95 = _husid_times(record, (0.05, 0.10, 0.90, 0.95))
    d80 = float(t90 - t10)
    a_rms = float(np.sqrt(0.8 * integral_a2 / d80))
    pgv = float(np.max(np.abs(corrected.velocity(t))))

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
        "PGD": float(np.max(np.abs(corrected.displacement(t)))),
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
