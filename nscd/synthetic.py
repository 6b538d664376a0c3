"""Response spectra, the Eurocode 8 elastic spectrum and spectrum-compatible accelerograms.

- :func:`sdof_response` / :func:`response_spectrum`: linear single-degree-of-
  freedom oscillators under a :class:`~nscd.motion.Record`, integrated with the
  exact recurrence for piecewise-linear excitation (Nigam & Jennings 1969; Chopra,
  *Dynamics of Structures*, section 5.2), so the only approximation is sampling
  the peak (see ``min_samples_per_period``).
- :func:`ec8_spectrum`: the EN 1998-1 (2004) elastic horizontal spectrum, section 3.2.2.2.
- :func:`spectrum_compatible_records`: seeded synthetic accelerograms whose 5 %
  damped spectra match a target, like the thirty EC8-compatible motions of the
  LNEC random tests (seed 003, line 77).

Sign convention: the oscillator's relative displacement u obeys
u'' + 2 zeta omega u' + omega^2 u = -a_g(t).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

from nscd.motion import Record, _positive, _unit_factor

__all__ = ["ResponseSpectrum", "sdof_response", "response_spectrum", "ec8_spectrum",
           "spectrum_compatible_records"]


def _as_record(motion: Record | tuple) -> Record:
    """A Record, or (acceleration samples in m/s^2, dt in s) made into one."""
    if isinstance(motion, Record):
        return motion
    if isinstance(motion, tuple) and len(motion) == 2:
        return Record(motion[0], motion[1], "m/s^2")
    raise TypeError(f"record is a {type(motion).__name__}, must be a Record or a tuple "
                    "(acceleration in m/s^2, dt in s).")


def _check_damping(damping: float) -> float:
    damping = float(damping)
    if not 0.0 <= damping < 1.0:
        raise ValueError(f"damping == {damping}, must be in [0, 1) (fraction of critical).")
    return damping


def _recurrence(omega: float, zeta: float, dt: float):
    """Exact step matrices for u'' + 2 zeta omega u' + omega^2 u = p(t), p linear on the step.

    Returns (A, b0, b1) with x_{k+1} = A x_k + b0 p_k + b1 p_{k+1}, x = (u, u').
    Coefficients of Chopra, Dynamics of Structures, Table 5.2.1, with k = omega^2, m = 1.
    """
    wd = omega * math.sqrt(1.0 - zeta**2)
    r = zeta / math.sqrt(1.0 - zeta**2)
    e = math.exp(-zeta * omega * dt)
    s, c = math.sin(wd * dt), math.cos(wd * dt)
    k = omega**2
    A = np.array([[e * (r * s + c), e * s / wd],
                  [-e * omega / math.sqrt(1.0 - zeta**2) * s, e * (c - r * s)]])
    b0 = np.array([
        (2 * zeta / (omega * dt) + e * (((1 - 2 * zeta**2) / (wd * dt) - r) * s
                                        - (1 + 2 * zeta / (omega * dt)) * c)) / k,
        (-1 / dt + e * ((omega / math.sqrt(1 - zeta**2) + r / dt) * s + c / dt)) / k,
    ])
    b1 = np.array([
        (1 - 2 * zeta / (omega * dt) + e * ((2 * zeta**2 - 1) / (wd * dt) * s
                                            + 2 * zeta / (omega * dt) * c)) / k,
        (1 - e * (r * s + c)) / (k * dt),
    ])
    return A, b0, b1


def _filters(period: float, zeta: float, h: float, rows: tuple[int, ...]):
    """IIR filters (num, den, zi per unit p_0) giving x[rows] of the exact recurrence.

    The recurrence x_{k+1} = A x_k + b0 p_k + b1 p_{k+1}, x_0 = 0, on steps h
    makes each component a second-order IIR filter of p (transfer function
    e_i^T (zI - A)^-1 (b0 + b1 z)), so the loop over time runs in C
    (``scipy.signal.lfilter``). With a zero initial filter state the filter
    would assume p_{-1} = 0 and start from x_0 = b1 p_0; the initial state
    ``zi = p_0 zi_unit`` instead adds the free response -A^k b1 p_0, which
    makes x_0 = 0 exactly.
    """
    A, b0, b1 = _recurrence(2.0 * math.pi / period, zeta, h)
    tr, det = A[0, 0] + A[1, 1], A[0, 0] * A[1, 1] - A[0, 1] * A[1, 0]
    den = np.array([1.0, -tr, det])
    free0, free1 = b1, A @ b1  # x_0 and x_1 of the free response per unit p_0
    out = []
    for i in rows:
        j = 1 - i  # row i of adj(zI - A) is (z - A_jj) e_i + A_ij e_j
        num = np.array([b1[i],
                        b0[i] - A[j, j] * b1[i] + A[i, j] * b1[j],
                        -A[j, j] * b0[i] + A[i, j] * b0[j]])
        # direct form II transposed: its zero-input output is zi[0], zi[1] + tr zi[0], ...
        out.append((num, den, np.array([-free0[i], -free1[i] + tr * free0[i]])))
    return out


def _run(filt, p: np.ndarray) -> np.ndarray:
    num, den, zi_unit = filt
    return lfilter(num, den, p, zi=p[0] * zi_unit)[0]


def _refined(samples: np.ndarray, substeps: int) -> np.ndarray:
    """Piecewise-linear samples on steps dt / substeps (exact: same polyline)."""
    if substeps == 1:
        return samples
    fine = np.arange((samples.size - 1) * substeps + 1) / substeps
    return np.interp(fine, np.arange(samples.size), samples)


class _OscillatorBank:
    """Peak relative displacements of oscillators at fixed periods, damping and dt.

    Built once (the filter coefficients), applied to many records of step ``dt``.
    Each record step is split so that every period has at least
    ``min_samples_per_period`` samples.
    """

    def __init__(self, periods: np.ndarray, zeta: float, dt: float, min_samples_per_period: int):
        self.items = []
        for T in periods:
            m = max(1, math.ceil(min_samples_per_period * dt / T))
            self.items.append((m, _filters(T, zeta, dt / m, rows=(0,))[0]))

    def peak_displacement(self, samples_mps2: np.ndarray) -> np.ndarray:
        p = {m: -_refined(samples_mps2, m) for m in {m for m, _ in self.items}}
        return np.array([np.max(np.abs(_run(filt, p[m]))) for m, filt in self.items])


def sdof_response(record: Record | tuple, period: float, damping: float = 0.05, *,
                  substeps: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Relative response of a linear oscillator to a ground acceleration record, from rest.

    Solves u'' + 2 zeta omega u' + omega^2 u = -a_g(t), omega = 2 pi / period, with
    a_g the record's piecewise-linear acceleration, exactly at the sample times.

    Parameters
    ----------
    record : Record or tuple (samples in m/s^2, dt in s)
    period : float
        Natural period in s, > 0.
    damping : float
        Fraction of critical damping zeta, in [0, 1).
    substeps : int
        Split each record step in this many (the excitation is piecewise
        linear, so this is exact in the input; it only samples the response more
        finely).

    Returns
    -------
    t : ndarray, shape (m,)
        Times in s, m = (n - 1) substeps + 1.
    u : ndarray, shape (m,)
        Relative displacement in m.
    v : ndarray, shape (m,)
        Relative velocity in m/s.
    """
    rec = _as_record(record)
    period = _positive("period", period)
    zeta = _check_damping(damping)
    if int(substeps) != substeps or substeps < 1:
        raise ValueError(f"substeps == {substeps!r}, must be an integer >= 1.")
    substeps = int(substeps)
    p = -_refined(rec.samples_mps2, substeps)
    u, v = (_run(f, p) for f in _filters(period, zeta, rec.dt / substeps, rows=(0, 1)))
    return np.arange(p.size) * (rec.dt / substeps), u, v


@dataclass(frozen=True)
class ResponseSpectrum:
    """Linear elastic response spectrum.

    Attributes
    ----------
    periods : ndarray, shape (k,)
        Natural periods T in s.
    damping : float
        Fraction of critical damping.
    Sd : ndarray, shape (k,)
        Spectral displacement max |u| in m.
    Sv : ndarray, shape (k,)
        Pseudo-velocity (2 pi / T) Sd in m/s.
    Sa : ndarray, shape (k,)
        Pseudo-acceleration (2 pi / T)^2 Sd in m/s^2.
    """

    periods: np.ndarray
    damping: float
    Sd: np.ndarray
    Sv: np.ndarray
    Sa: np.ndarray


def response_spectrum(record: Record | tuple, periods, damping: float = 0.05, *,
                      min_samples_per_period: int = 20) -> ResponseSpectrum:
    """Pseudo-acceleration, pseudo-velocity and displacement spectra of a record.

    Each oscillator is integrated with the exact piecewise-linear recurrence
    (:func:`sdof_response`) over the record's duration (no free-vibration tail).
    The peak is taken at the samples; each record step is split so that there
    are at least ``min_samples_per_period`` samples per oscillator period,
    which bounds the under-estimate of a near-sinusoidal peak by
    1 - cos(pi / min_samples_per_period) (1.2 % for the default 20).

    Parameters
    ----------
    record : Record or tuple (samples in m/s^2, dt in s)
    periods : array_like, shape (k,)
        Natural periods in s, all > 0.
    damping : float
        Fraction of critical damping, in [0, 1).
    min_samples_per_period : int
        See above, >= 1.

    Returns
    -------
    ResponseSpectrum
    """
    rec = _as_record(record)
    periods = np.atleast_1d(np.asarray(periods, dtype=float))
    if periods.ndim != 1 or not np.all(np.isfinite(periods) & (periods > 0.0)):
        raise ValueError(f"periods == {periods}, must be a 1-D array of finite values > 0.")
    zeta = _check_damping(damping)
    if int(min_samples_per_period) != min_samples_per_period or min_samples_per_period < 1:
        raise ValueError(f"min_samples_per_period == {min_samples_per_period!r}, "
                         "must be an integer >= 1.")
    sd = _OscillatorBank(periods, zeta, rec.dt, int(min_samples_per_period)).peak_displacement(
        rec.samples_mps2)
    w = 2.0 * math.pi / periods
    return ResponseSpectrum(periods=periods, damping=zeta, Sd=sd, Sv=w * sd, Sa=w**2 * sd)


# Table 3.2 and 3.3 of EN 1998-1: ground type -> (S, T_B, T_C, T_D) in s.
_EC8_CORNERS = {
    1: {"A": (1.0, 0.15, 0.4, 2.0), "B": (1.2, 0.15, 0.5, 2.0), "C": (1.15, 0.20, 0.6, 2.0),
        "D": (1.35, 0.20, 0.8, 2.0), "E": (1.4, 0.15, 0.5, 2.0)},
    2: {"A": (1.0, 0.05, 0.25, 1.2), "B": (1.35, 0.05, 0.25, 1.2), "C": (1.5, 0.10, 0.25, 1.2),
        "D": (1.8, 0.10, 0.30, 1.2), "E": (1.6, 0.05, 0.25, 1.2)},
}


def ec8_spectrum(periods, ag: float, *, ground_type: str = "A", spectrum_type: int = 1,
                 damping: float = 0.05, unit: str = "m/s^2", S: float | None = None,
                 TB: float | None = None, TC: float | None = None,
                 TD: float | None = None) -> np.ndarray:
    """Eurocode 8 elastic horizontal response spectrum S_e(T) (EN 1998-1, eqs 3.2-3.6).

        0 <= T <= TB:   ag S (1 + T / TB (2.5 eta - 1))
        TB <= T <= TC:  2.5 ag S eta
        TC <= T <= TD:  2.5 ag S eta TC / T
        TD <= T:        2.5 ag S eta TC TD / T^2

    with eta = sqrt(10 / (5 + 100 damping)) >= 0.55. S, TB, TC, TD come from
    Tables 3.2 (type 1) / 3.3 (type 2) for ``ground_type``, unless given
    explicitly (national annexes, or the LNEC tests of seed 003, line 77:
    plateau 0.1-0.3 s at 7 m/s^2 with PGA 2.8 m/s^2, i.e. S eta = 1 and
    ``ec8_spectrum(T, 2.8, TB=0.1, TC=0.3)``). S_e(0) = ag S is the PGA.

    Parameters
    ----------
    periods : array_like
        Periods in s, >= 0.
    ag : float
        Design ground acceleration on type A ground, > 0, in ``unit``.
    ground_type : {"A", "B", "C", "D", "E"}
    spectrum_type : {1, 2}
    damping : float
        Viscous damping ratio, >= 0 (0.05 gives eta = 1).
    unit : {"m/s^2", "g"}
        Unit of ``ag``; the result is in m/s^2.
    S, TB, TC, TD : float, optional
        Overrides of the soil factor and corner periods (s); need 0 < TB < TC < TD.

    Returns
    -------
    ndarray, same shape as ``periods``
        Spectral acceleration in m/s^2.
    """
    T = np.asarray(periods, dtype=float)
    if not np.all(np.isfinite(T) & (T >= 0.0)):
        raise ValueError(f"periods == {T}, must be finite and >= 0.")
    ag = _positive("ag", ag) * _unit_factor(unit)
    if spectrum_type not in _EC8_CORNERS:
        raise ValueError(f"spectrum_type == {spectrum_type!r}, must be 1 or 2.")
    if ground_type not in _EC8_CORNERS[spectrum_type]:
        raise ValueError(f"ground_type == {ground_type!r}, must be one of "
                         f"{sorted(_EC8_CORNERS[spectrum_type])}.")
    table = _EC8_CORNERS[spectrum_type][ground_type]
    S, TB, TC, TD = (table[i] if given is None else _positive(name, given)
                     for i, (name, given) in enumerate((("S", S), ("TB", TB), ("TC", TC), ("TD", TD))))
    if not TB < TC < TD:
        raise ValueError(f"TB, TC, TD == {TB}, {TC}, {TD}, must satisfy 0 < TB < TC < TD.")
    damping = float(damping)
    if not (math.isfinite(damping) and damping >= 0.0):
        raise ValueError(f"damping == {damping}, must be finite and >= 0.")
    eta = max(math.sqrt(10.0 / (5.0 + 100.0 * damping)), 0.55)
    plateau = 2.5 * ag * S * eta
    return np.select(
        [T <= TB, T <= TC, T <= TD],
        [ag * S * (1.0 + T / TB * (2.5 * eta - 1.0)), plateau, plateau * TC / np.maximum(T, TC)],
        plateau * TC * TD / np.maximum(T, TD) ** 2)


def _envelope(t: np.ndarray, duration: float) -> np.ndarray:
    """Jennings-type intensity envelope: (t/t1)^2 rise, plateau, exponential decay.

    Rise to t1 = 0.1 duration, strong phase to t2 = 0.5 duration, then
    exp(-c (t - t2)) with c chosen so that the envelope is 0.05 at the end.
    """
    t1, t2 = 0.1 * duration, 0.5 * duration
    c = -math.log(0.05) / (duration - t2)
    return np.where(t < t1, (t / t1) ** 2, np.where(t < t2, 1.0, np.exp(-c * (t - t2))))


def _zero_end_velocity_and_displacement(acc: np.ndarray, dt: float,
                                        shape: np.ndarray) -> np.ndarray:
    """Subtract shape(t) (c0 + c1 t / T) from acc so that v(T) = d(T) = 0 exactly.

    v(T) and d(T) of a piecewise-linear record are linear in its samples, so the
    two coefficients solve a 2 x 2 system built from the exact integrals of the
    two correction shapes (both vanish at t = 0 with ``shape``, keeping a(0)).
    """
    t = np.arange(acc.size) * dt
    basis = (shape, shape * t / t[-1])

    def end_state(a):
        rec = Record(a, dt, "m/s^2")
        return np.array([rec.velocity(rec.duration), rec.displacement(rec.duration)])

    matrix = np.column_stack([end_state(b) for b in basis])
    c = np.linalg.solve(matrix, end_state(acc))
    return acc - c[0] * basis[0] - c[1] * basis[1]


def spectrum_compatible_records(
        target: Callable[[np.ndarray], np.ndarray], n: int = 30, *, duration: float = 20.0,
        dt: float = 0.01, seed: int = 0, damping: float = 0.05, pga: float | None = None,
        period_range: tuple[float, float] = (0.04, 3.0), n_periods: int = 80,
        iterations: int = 8) -> list[Record]:
    """Seeded synthetic accelerograms whose response spectra match a target spectrum.

    For each record (as in SIMQKE-type generators):

    1. Gaussian white noise (``numpy.random.default_rng(seed)``; record i uses the
       i-th stream spawned from ``seed``) times a Jennings envelope: quadratic
       rise over the first 10 % of ``duration``, constant to 50 %, exponential
       decay to 5 % at the end.
    2. ``iterations`` times: compute the pseudo-acceleration spectrum at
       ``n_periods`` log-spaced periods in ``period_range`` (exact recurrence,
       at least 20 samples per period); multiply the Fourier amplitudes at
       frequency f = 1/T by target(T) / Sa(T) (interpolated in log f, held at
       the end values outside the range; components below 1 / (2 max period) Hz
       are removed); apply the end correction of step 3; then impose the PGA:
       scale up if the peak is below it, clip the samples that exceed it
       otherwise (the next iteration repairs the spectrum).
    3. End correction: subtract env(t) (c0 + c1 t / duration) so that the final
       velocity and displacement are exactly zero (the record starts and ends
       at rest; env(0) = 0 keeps a(0)).
    4. A last end correction and an exact scaling to ``pga`` (default
       target(0), the zero-period ordinate, i.e. the PGA of an EC8 spectrum).

    Matching quality (5 % damping, EC8 target of seed 003, 16 s records, dt =
    0.01 s, 30 records, defaults): over 0.05-2 s the mean spectrum of the set
    stays within 10 % of the target and each record within 25 %
    (``tests/test_synthetic.py``); EN 1998-1 section 3.2.3.1.2 asks that the mean
    of the set be no less than 90 % of the target.

    The returned records are identical for identical arguments.

    Parameters
    ----------
    target : callable
        target(periods in s) -> spectral pseudo-acceleration in m/s^2, e.g.
        ``lambda T: ec8_spectrum(T, 2.8, TB=0.1, TC=0.3)``.
    n : int
        Number of records, >= 1.
    duration : float
        Length of each record in s, > 0.
    dt : float
        Sampling step in s, > 0; the shortest matched period must be >= 4 dt.
    seed : int
        Seed of the random generator.
    damping : float
        Damping ratio of the matched spectrum, in [0, 1).
    pga : float, optional
        Peak ground acceleration in m/s^2 of every record; target(0) by default.
    period_range : (float, float)
        Shortest and longest matched period in s.
    n_periods : int
        Number of matched periods, >= 2.
    iterations : int
        Number of spectral-scaling iterations, >= 1.

    Returns
    -------
    list of Record, length n
        Accelerograms in m/s^2 with ``n_samples = round(duration / dt) + 1``,
        named ``"synthetic <seed>-<i>"``.
    """
    if int(n) != n or n < 1:
        raise ValueError(f"n == {n!r}, must be an integer >= 1.")
    duration, dt = _positive("duration", duration), _positive("dt", dt)
    zeta = _check_damping(damping)
    t_min, t_max = (_positive("period_range", p) for p in period_range)
    if not 4.0 * dt <= t_min < t_max:
        raise ValueError(f"period_range == {period_range}, must satisfy 4 dt = {4 * dt} <= "
                         "min < max.")
    if int(n_periods) != n_periods or n_periods < 2:
        raise ValueError(f"n_periods == {n_periods!r}, must be an integer >= 2.")
    if int(iterations) != iterations or iterations < 1:
        raise ValueError(f"iterations == {iterations!r}, must be an integer >= 1.")
    periods = np.geomspace(t_min, t_max, int(n_periods))
    goal = np.asarray(target(periods), dtype=float)
    if goal.shape != periods.shape or not np.all(np.isfinite(goal) & (goal > 0.0)):
        raise ValueError(f"target(periods) == {goal}, must be finite and > 0 at the periods "
                         f"{periods}.")
    peak = float(np.asarray(target(np.array([0.0])), dtype=float)[0]) if pga is None else pga
    peak = _positive("pga", peak)

    n_samples = int(round(duration / dt)) + 1
    t = np.arange(n_samples) * dt
    env = _envelope(t, t[-1])
    freqs = np.fft.rfftfreq(n_samples, dt)
    f_target = 1.0 / periods[::-1]  # increasing frequencies
    keep = freqs >= 0.5 / t_max
    bank = _OscillatorBank(periods, zeta, dt, 20)
    omega2 = (2.0 * math.pi / periods) ** 2

    def limit(acc: np.ndarray) -> np.ndarray:
        acc = _zero_end_velocity_and_displacement(acc, dt, env)
        largest = np.max(np.abs(acc))
        return acc * (peak / largest) if largest < peak else np.clip(acc, -peak, peak)

    records = []
    for i, stream in enumerate(np.random.default_rng(seed).spawn(int(n))):
        acc = limit(stream.standard_normal(n_samples) * env)
        for _ in range(int(iterations)):
            sa = omega2 * bank.peak_displacement(acc)
            log_ratio = np.log(goal / sa)[::-1]
            gain = np.exp(np.interp(np.log(np.maximum(freqs, f_target[0])), np.log(f_target),
                                    log_ratio)) * keep
            acc = limit(np.fft.irfft(np.fft.rfft(acc) * gain, n_samples))
        acc = _zero_end_velocity_and_displacement(acc, dt, env)
        acc *= peak / np.max(np.abs(acc))
        records.append(Record(acc, dt, "m/s^2", name=f"synthetic {seed}-{i}"))
    return records
