"""Analyses built on the 1-DOF Housner model: spectra, rocking curves, identification.

* :func:`overturning_spectrum` -- the whole overturn / safe structure along the
  amplitude axis of a pulse family over omega_p / p, every boundary labelled with the
  mode of overturning (seed 000, figs. 5, 8, 11: mode 1 = one impact, mode 2 = none,
  and the safe region between them).
* :func:`minimum_overturning_scale` -- smallest scale factor of a record that overturns
  a block (the outcome is not monotone in the scale: scan + bisection).
* :func:`rocking_spectrum` -- max |theta|/alpha and max |theta_dot|/p against p.
* :func:`rocking_curves`, :func:`overturning_index`, :func:`overturning_correlation` --
  the rocking curves and the overturning index I_over of seed 001 (Sorrentino et al.).
* :func:`identify_free_rocking` -- alpha, p and restitution from a free-rocking record
  (seed 003 eqs. 3.6-3.8).
* :func:`verify_time_step` (from :mod:`nscd.convergence`) -- rerun an engine result at
  dt/2 (and with the other scheme) and say whether its outcome changed.

Every sweep takes ``executor=`` (see :mod:`nscd.sweep`); each case is a deterministic
module-level function, so serial and parallel runs give identical numbers.
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.integrate import quad
from scipy.optimize import least_squares
from scipy.stats import pearsonr, spearmanr

from nscd import sweep
from nscd.convergence import TimeStepCheck, verify_time_step
from nscd.intensity import intensity_measures
from nscd.limit import Collapse, Joint, collapse_load_factor, mechanism  # noqa: F401  (re-exported: limit analysis by simulation)
from nscd.motion import HalfSine, Motion, OneCosine, OneSine, Record, Scaled
from nscd.rocking import HousnerBlock, RockingResult, linear_record_peaks

__all__ = [
    "Boundary", "OverturningSpectrum", "overturning_spectrum", "ScaleSearch", "minimum_overturning_scale",
    "RockingSpectrum", "rocking_spectrum", "RockingCurves", "rocking_curves", "overturning_index",
    "overturning_correlation", "Identification", "identify_free_rocking", "intensity_measures",
    "TimeStepCheck", "verify_time_step",
]

_PULSES = {"half-sine": HalfSine, "one-sine": OneSine, "one-cosine": OneCosine}


# --------------------------------------------------------------------------- outcome search
def _outcome(result: RockingResult) -> str | int | None:
    """None when safe, else the mode ("mode 1", "mode 2" or the number of impacts)."""
    return result.mode if result.overturned else None


@dataclass(frozen=True)
class Boundary:
    """A change of outcome along the amplitude (or scale) axis.

    Attributes
    ----------
    value : float
        Where the outcome changes (midpoint of the final bracket): amplitude in units
        of alpha g for spectra, scale factor for records.
    below, above : str, int or None
        Outcome just below and just above: None (safe) or the mode of overturning
        ("mode 1", "mode 2", or the number of impacts).
    """

    value: float
    below: str | int | None
    above: str | int | None

    @property
    def kind(self) -> str:
        """"overturn" when overturning starts above, "safe" when it stops, "mode" when the mode changes."""
        if self.below is None:
            return "overturn"
        return "safe" if self.above is None else "mode"

    @property
    def mode(self) -> str | int | None:
        """The mode of the overturning side of the boundary (above for "overturn" and "mode")."""
        return self.below if self.above is None else self.above


def _class(outcome):
    """Search class of an outcome: safe (None), "mode 1", "mode 2", or "impacts" (two or more)."""
    return outcome if outcome in (None, "mode 1", "mode 2") else "impacts"


def _search(classify, lo: float, hi: float, n_scan: int, rtol: float) -> tuple[list[Boundary], list]:
    """Scan [lo, hi] on n_scan points, bisect every change of outcome class to rtol.

    Classes are safe / mode 1 / mode 2 / two or more impacts (changes in the number of
    impacts beyond one are not boundaries). A third class met inside a bracket splits
    it: both changes are kept.
    """
    xs = [float(x) for x in np.linspace(lo, hi, n_scan)]
    outs = [classify(x) for x in xs]
    boundaries = []

    def bisect(a, b, oa, ob):
        while b - a > rtol * abs(b):
            mid = 0.5 * (a + b)
            om = classify(mid)
            if _class(om) == _class(oa):
                a, oa = mid, om
            elif _class(om) == _class(ob):
                b, ob = mid, om
            else:  # a third class inside: two changes
                bisect(a, mid, oa, om)
                a, oa = mid, om
        boundaries.append(Boundary(0.5 * (a + b), oa, ob))

    for i in range(n_scan - 1):
        if _class(outs[i]) != _class(outs[i + 1]):
            bisect(xs[i], xs[i + 1], outs[i], outs[i + 1])
    boundaries.sort(key=lambda b: b.value)
    return boundaries, outs


def _check_rtol(rtol: float) -> None:
    if not (0.0 < rtol < 0.1):
        raise ValueError(f"rtol == {rtol}, must be in (0, 0.1).")


# --------------------------------------------------------------------------- overturning spectrum
@dataclass(frozen=True)
class OverturningSpectrum:
    """Overturning acceleration spectrum of a block under a pulse family.

    Attributes
    ----------
    block : HousnerBlock
    pulse : str
        "one-sine" or "one-cosine".
    wp_over_p : ndarray, shape (n,)
        Pulse frequency over the block's frequency parameter.
    boundaries : list of list of Boundary
        Per wp/p, the amplitudes (units of alpha g, increasing) where the outcome
        changes, each with the outcome below and above (mode 1 / mode 2 ...).
    amplitude_max : float
        Top of the amplitude range searched (alpha g).
    """

    block: HousnerBlock
    pulse: str
    wp_over_p: np.ndarray
    boundaries: list
    amplitude_max: float

    @property
    def minimum(self) -> np.ndarray:
        """Minimum overturning amplitude a_p0 / (alpha g) per wp/p, shape (n,); nan if none below amplitude_max."""
        return np.array([next((b.value for b in col if b.kind == "overturn"), np.nan) for col in self.boundaries])

    @property
    def minimum_mode(self) -> list:
        """Mode of overturning at the minimum amplitude, per wp/p (None if none)."""
        return [next((b.mode for b in col if b.kind == "overturn"), None) for col in self.boundaries]

    def overturn_intervals(self, wp_over_p_index: int) -> list[tuple[float, float]]:
        """Amplitude intervals (alpha g) that overturn at the wp/p of this index, up to amplitude_max."""
        intervals, start = [], None
        for b in self.boundaries[wp_over_p_index]:
            if b.below is None and b.above is not None:
                start = b.value
            elif b.below is not None and b.above is None and start is not None:
                intervals.append((start, b.value))
                start = None
        if start is not None:
            intervals.append((start, self.amplitude_max))
        return intervals

    def overturns(self, wp_over_p_index: int, amplitude: float) -> bool:
        """Whether ``amplitude`` (alpha g) overturns at the wp/p of this index, from the boundaries."""
        col = self.boundaries[wp_over_p_index]
        state = None
        for b in col:
            if amplitude >= b.value:
                state = b.above
        return state is not None


def _spectrum_column(block: HousnerBlock, pulse: str, ratio: float, amplitude_max: float,
                     n_scan: int, rtol: float) -> list[Boundary]:
    """All boundaries along the amplitude for one wp/p (module level: picklable)."""
    omega = ratio * block.p
    cls = _PULSES[pulse]
    unit = block.alpha * block.g
    t_end = cls(1.0, omega).duration + 200.0 / block.p

    def classify(x: float):
        r = block.simulate(cls(x * unit, omega), t_end=t_end, stop_when_decided=True, dt_out=t_end)
        return _outcome(r)
    lo = block.onset_acceleration / unit * (1.0 + 1e-9)
    if lo >= amplitude_max:
        return []
    boundaries, _ = _search(classify, lo, amplitude_max, n_scan, rtol)
    return boundaries


def overturning_spectrum(block: HousnerBlock, pulse: str = "one-sine", wp_over_p: Sequence[float] = (),
                         amplitude_max: float = 16.0, *, n_scan: int = 61, rtol: float = 1e-3,
                         executor=None, progress: bool = False) -> OverturningSpectrum:
    """Overturning acceleration spectrum: every overturn / safe boundary along the amplitude.

    For each wp/p the amplitude axis from the onset of rocking to ``amplitude_max``
    (units of alpha g) is scanned on ``n_scan`` points and every change of outcome
    (safe, overturn with mode 1 / mode 2 / n impacts) is bisected to ``rtol``.
    Features narrower than the scan step can be missed: raise ``n_scan`` near
    cusps (e.g. the tip of the mode-1 "bay").

    Parameters
    ----------
    block : HousnerBlock
        The block (its ``linear`` flag picks the formulation).
    pulse : {"one-sine", "one-cosine", "half-sine"}
        Pulse family (seed 000 Type-A / Type-B; the half-sine of 000's prologue and 001 eq. 11).
    wp_over_p : sequence of float
        Pulse frequencies over p, each > 0.
    amplitude_max : float
        Top of the amplitude range, units of alpha g (> onset).
    n_scan : int
        Scan points per wp/p, >= 2.
    rtol : float
        Relative width of the final bracket of each boundary.
    executor : concurrent.futures.Executor, optional
        See :func:`nscd.sweep.run`; None: local process pool.
    progress : bool
        Progress bar on standard error.

    Returns
    -------
    OverturningSpectrum
    """
    if pulse not in _PULSES:
        raise ValueError(f"pulse == {pulse!r}, must be one of {sorted(_PULSES)}.")
    ratios = np.asarray(wp_over_p, dtype=float).ravel()
    if ratios.size == 0:
        raise ValueError("wp_over_p is empty, must hold at least one value > 0.")
    bad = np.flatnonzero(~(ratios > 0) | ~np.isfinite(ratios))
    if bad.size:
        raise ValueError(f"wp_over_p[{bad[0]}] == {ratios[bad[0]]}, must be finite and > 0.")
    if not (amplitude_max > 0 and math.isfinite(amplitude_max)):
        raise ValueError(f"amplitude_max == {amplitude_max}, must be finite and > 0.")
    if n_scan < 2:
        raise ValueError(f"n_scan == {n_scan}, must be >= 2.")
    _check_rtol(rtol)
    cases = [dict(block=block, pulse=pulse, ratio=float(r), amplitude_max=float(amplitude_max),
                  n_scan=int(n_scan), rtol=float(rtol)) for r in ratios]
    columns = sweep.run(_spectrum_column, cases, executor=executor, progress=progress,
                        desc=f"overturning spectrum, {pulse} ({'linear' if block.linear else 'nonlinear'})")
    return OverturningSpectrum(block, pulse, ratios, columns, float(amplitude_max))


# --------------------------------------------------------------------------- records
@dataclass(frozen=True)
class ScaleSearch:
    """Outcome of :func:`minimum_overturning_scale`.

    Attributes
    ----------
    minimum : float
        Smallest scale factor that overturns (nan if none up to ``scale_max``).
    boundaries : list of Boundary
        Every change of outcome along the scale axis.
    """

    minimum: float
    boundaries: list


def _scaled_outcome(block: HousnerBlock, record: Motion, scale: float, vertical: Motion | None, t_end: float):
    motion = Scaled(record, scale)
    vert = None if vertical is None else Scaled(vertical, scale)
    return _outcome(block.simulate(motion, t_end=t_end, vertical=vert, stop_when_decided=True, dt_out=t_end))


def minimum_overturning_scale(block: HousnerBlock, record: Motion, scale_max: float = 5.0, *,
                              vertical: Motion | None = None, n_scan: int = 50, rtol: float = 1e-3,
                              t_end: float | None = None) -> ScaleSearch:
    """Smallest factor by which ``record`` must be scaled to overturn ``block``.

    Scale factors in (0, scale_max] are scanned on ``n_scan`` points, each change of
    outcome bisected to ``rtol`` (overturning is not monotone in the scale: seed 000
    Table 1 and the safe region above mode 1).

    Parameters
    ----------
    block : HousnerBlock
    record : Motion
        Horizontal ground motion (vertical, if given, is scaled alike).
    scale_max : float
        Largest factor tried, > 0.
    t_end : float, optional
        End of each simulation in s (default: the excitation's duration + 200/p).
    """
    if not (scale_max > 0):
        raise ValueError(f"scale_max == {scale_max}, must be > 0.")
    _check_rtol(rtol)
    t_end = t_end or (max(record.duration, 0 if vertical is None else vertical.duration) + 200.0 / block.p)
    boundaries, outs = _search(lambda s: _scaled_outcome(block, record, s, vertical, t_end),
                               scale_max / n_scan, scale_max, n_scan, rtol)
    if outs[0] is not None:
        boundaries.insert(0, Boundary(scale_max / n_scan, None, outs[0]))
    minimum = next((b.value for b in boundaries if b.kind == "overturn"), math.nan)
    return ScaleSearch(minimum, boundaries)


@dataclass(frozen=True)
class _Response:
    max_theta: float
    max_theta_dot: float
    max_energy: float
    dissipated: float
    overturned: bool


def _response(block: HousnerBlock, motion: Motion, t_end: float) -> _Response:
    """Peak response of one block (module level: picklable)."""
    r = block.simulate(motion, t_end=t_end, dt_out=min(0.005, 0.05 / block.p))
    energy = block.energy(r.theta, r.theta_dot)
    return _Response(r.max_abs_theta, r.max_abs_theta_dot, float(np.max(energy)) if len(energy) else 0.0,
                     r.dissipated_energy, r.overturned)


@dataclass(frozen=True)
class RockingSpectrum:
    """Rocking response spectrum: peak response against p for given alpha, eta.

    Attributes
    ----------
    p : ndarray, shape (n,)
        Frequency parameters in rad/s.
    theta_max : ndarray, shape (n,)
        max |theta| / alpha (>= pi/(2 alpha) when overturned).
    theta_dot_max : ndarray, shape (n,)
        max |theta_dot| / p.
    overturned : ndarray of bool, shape (n,)
    """

    alpha: float
    eta: float | None
    p: np.ndarray
    theta_max: np.ndarray
    theta_dot_max: np.ndarray
    overturned: np.ndarray


def rocking_spectrum(record: Motion, alpha: float, p: Sequence[float], eta: float | None = None, *,
                     linear: bool = False, t_end: float | None = None, executor=None,
                     progress: bool = False) -> RockingSpectrum:
    """Peak rotation and angular velocity of blocks of slenderness ``alpha`` against p (seed 000 figs. 23-24).

    Parameters
    ----------
    record : Motion
        Horizontal ground motion.
    alpha : float
        Slenderness in rad, in (0, pi/2).
    p : sequence of float
        Frequency parameters in rad/s, each > 0.
    eta : float, optional
        Velocity ratio at impact (None: Housner's value).
    t_end : float, optional
        End time in s (default: the motion's duration + 10 s).
    """
    ps = np.asarray(p, dtype=float).ravel()
    bad = np.flatnonzero(~(ps > 0))
    if bad.size:
        raise ValueError(f"p[{bad[0]}] == {ps[bad[0]]}, must be > 0.")
    t_end = t_end or record.duration + 10.0
    blocks = [HousnerBlock.from_alpha_p(alpha, float(x), eta, linear) for x in ps]
    out = sweep.run(_response, [dict(block=b, motion=record, t_end=t_end) for b in blocks],
                    executor=executor, progress=progress, desc="rocking spectrum (blocks)")
    return RockingSpectrum(alpha, eta, ps, np.array([o.max_theta for o in out]) / alpha,
                           np.array([o.max_theta_dot for o in out]) / ps, np.array([o.overturned for o in out]))


# --------------------------------------------------------------------------- rocking curves (seed 001)
@dataclass(frozen=True)
class RockingCurves:
    """Rocking curves of seed 001 over a grid of (R, alpha) under one record.

    Arrays have shape (n_R, n_alpha). Normalisations (001 section 4): rotation by
    alpha, angular velocity by theta_dot_r = sqrt(3/2 g/R (1 - cos alpha)), energies
    by V_r = m g R (1 - cos alpha) (mechanical energy measured from rest).

    Attributes
    ----------
    alpha : ndarray, shape (n_alpha,)
        Slenderness in rad.
    R : ndarray, shape (n_R,)
        Half diagonals in m.
    theta : ndarray
        max |theta| / alpha.
    theta_dot : ndarray
        max |theta_dot| / theta_dot_r.
    energy : ndarray
        max mechanical energy / V_r.
    dissipated : ndarray
        Energy dissipated in impacts / V_r.
    overturned : ndarray of bool
    """

    alpha: np.ndarray
    R: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    energy: np.ndarray
    dissipated: np.ndarray
    overturned: np.ndarray


def rocking_curves(record: Motion, alpha: Sequence[float] | None = None, R: Sequence[float] | None = None,
                   eta: float | None = None, *, linear: bool = False, t_end: float | None = None,
                   executor=None, progress: bool = False) -> RockingCurves:
    """Rocking curves (seed 001): peak normalised responses over a grid of blocks.

    Parameters
    ----------
    record : Motion
        Horizontal ground motion.
    alpha : sequence of float, optional
        Slenderness values in rad (default 0.01, 0.02 ... 0.30 as in 001).
    R : sequence of float, optional
        Half diagonals in m (default 1.5, 2.0 ... 5.0 as in 001).
    eta : float, optional
        Velocity ratio (None: Housner's value for each alpha, as in 001).
    linear : bool
        Linearised model (001 uses the nonlinear one). Under a sampled record the
        linear blocks are integrated together by :func:`nscd.rocking.linear_record_peaks`
        (exact flights, vectorised over the blocks) instead of one run per block.
    t_end : float, optional
        End time in s (default: the record's duration + 5 s).
    """
    alphas = np.round(np.arange(1, 31) * 0.01, 10) if alpha is None else np.asarray(alpha, dtype=float).ravel()
    Rs = np.arange(1.5, 5.01, 0.5) if R is None else np.asarray(R, dtype=float).ravel()
    bad = np.flatnonzero(~((alphas > 0) & (alphas < 0.5 * math.pi)))
    if bad.size:
        raise ValueError(f"alpha[{bad[0]}] == {alphas[bad[0]]}, must be in (0, pi/2).")
    bad = np.flatnonzero(~(Rs > 0))
    if bad.size:
        raise ValueError(f"R[{bad[0]}] == {Rs[bad[0]]}, must be > 0.")
    t_end = t_end or record.duration + 5.0
    blocks = [HousnerBlock.from_alpha_R(float(a), float(r), eta, linear) for r in Rs for a in alphas]
    if linear and hasattr(record, "samples_mps2"):
        # exact vectorised flights, in fixed chunks (the same numbers whatever the executor)
        chunks = [blocks[i:i + _CHUNK] for i in range(0, len(blocks), _CHUNK)]
        parts = sweep.run(_linear_chunk, [dict(blocks=c, record=record, t_end=t_end) for c in chunks],
                          executor=executor, progress=progress, desc=f"rocking curves ({_CHUNK} blocks a cell)")
        out = [resp for part in parts for resp in part]
    else:
        out = sweep.run(_response, [dict(block=b, motion=record, t_end=t_end) for b in blocks],
                        executor=executor, progress=progress, desc="rocking curves (blocks)")
    shape = (Rs.size, alphas.size)
    v0 = np.array([b.potential(0.0) for b in blocks[:alphas.size]])[None, :]  # cos(alpha), or 1 - alpha^2/2
    p = np.sqrt(0.75 * blocks[0].g / Rs)[:, None]
    thdr = p * np.sqrt(2.0 * (1.0 - np.cos(alphas)))[None, :]
    field = lambda name: np.array([getattr(o, name) for o in out]).reshape(shape)  # noqa: E731
    return RockingCurves(
        alpha=alphas, R=Rs, theta=field("max_theta") / alphas[None, :], theta_dot=field("max_theta_dot") / thdr,
        energy=(field("max_energy") - v0) / (1.0 - v0), dissipated=field("dissipated") / (1.0 - v0),
        overturned=field("overturned").astype(bool))


_CHUNK = 512  # blocks per task of the vectorised integrator: its cost is per time step, nearly
# independent of the number of blocks, so big chunks win; fixed, so results do not depend on the executor


def _linear_chunk(blocks: list[HousnerBlock], record: Motion, t_end: float) -> list[_Response]:
    """Peak responses of linear blocks under a record, vectorised (module level: picklable)."""
    peaks = linear_record_peaks([b.alpha for b in blocks], [b.p for b in blocks], [b.eta for b in blocks],
                                record, t_end, g=blocks[0].g)
    v0 = np.array([b.potential(0.0) for b in blocks])
    return [_Response(float(peaks.max_theta[i]), float(peaks.max_theta_dot[i]), float(peaks.max_energy[i] + v0[i]),
                      float(peaks.dissipated[i]), bool(peaks.overturned[i])) for i in range(len(blocks))]


def overturning_index(curves: RockingCurves) -> np.ndarray:
    """Overturning index I_over(R) = n_over / n_tot per R (seed 001 eq. 4), shape (n_R,)."""
    return curves.overturned.mean(axis=1)


def overturning_correlation(records: Sequence[Record], measures: Sequence[str] | None = None, *,
                            alpha: Sequence[float] | None = None, R_mean: float = 3.0, R_std: float = 0.05,
                            n_R: int = 8, seed: int = 0, linear: bool = False, executor=None,
                            progress: bool = False, integration: str = "samples") -> dict:
    """Correlation of the overturning index with each intensity measure over records (seed 001 sec. 5).

    For each record, I_over is computed for ``n_R`` values of R drawn from a normal
    distribution (mean ``R_mean``, std ``R_std`` m, fixed ``seed``) times the alpha grid;
    its mean and interquartile range are kept. ``integration`` is passed to
    :func:`nscd.intensity.intensity_measures` (``"samples"``: the field's trapezoid
    over the samples; ``"interpolant"``: exact for the piecewise-linear record).

    Returns
    -------
    dict
        ``"I_over"`` (n_records,) mean index, ``"I_over_iqr"`` (n_records, 2) quartiles,
        ``"measures"`` {name: (n_records,) values}, ``"pearson"`` {name: r},
        ``"spearman"`` {name: rho}.
    """
    if len(records) < 3:
        raise ValueError(f"len(records) == {len(records)}, must be >= 3 for a correlation.")
    Rs = np.random.default_rng(seed).normal(R_mean, R_std, n_R)
    if np.any(Rs <= 0):
        raise ValueError(f"R_mean == {R_mean} and R_std == {R_std} give R <= 0.")
    index, quartiles = [], []
    for rec in records:
        ix = overturning_index(rocking_curves(rec, alpha, Rs, linear=linear, executor=executor, progress=progress))
        index.append(ix.mean())
        quartiles.append(np.percentile(ix, [25, 75]))
    ims = [intensity_measures(rec, integration=integration) for rec in records]
    names = list(measures) if measures is not None else [k for k, v in ims[0].items() if np.isscalar(v)]
    values = {k: np.array([im[k] for im in ims], dtype=float) for k in names}
    index = np.array(index)
    pear, spear = {}, {}
    for k, v in values.items():
        ok = np.isfinite(v)
        const = np.ptp(v[ok]) == 0 or np.ptp(index[ok]) == 0 if ok.sum() > 1 else True
        pear[k] = math.nan if const else float(pearsonr(v[ok], index[ok])[0])
        spear[k] = math.nan if const else float(spearmanr(v[ok], index[ok])[0])
    return {"I_over": index, "I_over_iqr": np.array(quartiles), "measures": values,
            "pearson": pear, "spearman": spear}


# --------------------------------------------------------------------------- identification (seed 003)
@dataclass(frozen=True)
class Identification:
    """Parameters identified from a free-rocking record (seed 003 eqs. 3.6-3.8).

    Attributes
    ----------
    alpha : float
        Slenderness in rad.
    p : float
        Frequency parameter in rad/s.
    eta : float
        Velocity ratio fitted with alpha and p to the impact times.
    eta_per_impact : ndarray, shape (n,)
        mu_n of eq. 3.8 (from the measured amplitudes and the fitted alpha), n = 1 ..
    eta_mean : float
        Mean of eta_per_impact (the paper's final value).
    impact_times : ndarray
        Measured impact times (s).
    amplitudes : ndarray
        Measured amplitudes r_0, r_1, ... (rad) of the half cycles.
    """

    alpha: float
    p: float
    eta: float
    eta_per_impact: np.ndarray
    eta_mean: float
    impact_times: np.ndarray
    amplitudes: np.ndarray


def _quarter_time(r: float, alpha: float) -> float:
    """p * time from amplitude r (at rest) down to theta = 0, nonlinear model (energy conservation)."""
    c0 = math.cos(alpha - r)

    def f(u):
        if u == 0.0:
            return 2.0 / math.sqrt(math.sin(alpha - r))
        return 2.0 * u / math.sqrt(max(c0 - math.cos(alpha - r + u * u), 1e-300))
    val, _ = quad(f, 0.0, math.sqrt(r), epsabs=1e-12, epsrel=1e-10, limit=100)
    return val / math.sqrt(2.0)


def _simulated_history(t: np.ndarray, alpha: float, p: float, eta: float, r0: float, t0: float) -> np.ndarray:
    """theta at the times t of a block released from rest at r0 at time t0 (held before)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # eta may exceed Housner's value while fitting
        blk = HousnerBlock.from_alpha_p(alpha, p, eta)
    span = max(float(t[-1] - t0), 1e-9)
    r = blk.simulate(None, t_end=span, theta0=r0, dt_out=float(np.min(np.diff(t))))
    keep = np.concatenate(([True], np.diff(r.time) > 0))
    return np.where(t < t0, r0, np.interp(t - t0, r.time[keep], r.theta[keep]))


def _refine_on_history(t, th, alpha, p, eta, r0, t0):
    """Least squares of the whole simulated history against the record, from the impact-time fit."""
    x0 = np.array([alpha, p, eta, r0, t0])
    lo = [abs(r0) * 1.0001, 1e-6, 1e-3, -0.5 * math.pi, -np.inf]
    hi = [0.5 * math.pi - 1e-6, np.inf, 1.0, 0.5 * math.pi, np.inf]
    x0 = np.clip(x0, np.array(lo) + 1e-12, np.array(hi) - 1e-12)
    fit = least_squares(lambda x: _simulated_history(t, *x) - th, x0, bounds=(lo, hi),
                        x_scale=[0.01 * alpha, 0.01 * p, 0.01, 0.01 * abs(r0), 0.01 / p], diff_step=1e-7,
                        xtol=1e-10, ftol=1e-10)
    return float(fit.x[0]), float(fit.x[1]), float(fit.x[2])


def identify_free_rocking(time: np.ndarray, theta: np.ndarray, *, window: float = 0.5,
                          refine: bool = True) -> Identification:
    """Identify alpha, p and the restitution from a free-rocking record (seed 003 sec. 3.2).

    Impacts are the zero crossings of theta, each located by quadratic fits to the
    samples with |theta| < ``window`` times the amplitude on either side (the
    velocity jumps at impact); amplitudes r_n are parabolas fitted around each
    extremum. alpha, p (and eta, and the release time) minimise
    sum (t_n - t_n*)^2 over the impact times (eq. 3.7), the model times chaining the
    nonlinear half-cycle time at amplitude r (eq. 3.6, by energy conservation) from
    the measured release amplitude r_0, with amplitudes after each impact from
    E_n = eta^(2n) E_0. Predicting the amplitudes, rather than inserting the noisy
    measured ones, keeps the fit well conditioned (at small r/alpha the half-cycle
    time depends on p sqrt(alpha) only). The restitution of each impact then
    follows eq. 3.8 from the measured amplitudes and the fitted alpha:
    ((cos(alpha - r_n) - cos alpha) / (cos(alpha - r_0) - cos alpha))^(1/(2n)).

    Parameters
    ----------
    time : ndarray, shape (n,)
        Sample times in s, non-decreasing. Samples at a repeated time (an event-driven
        history such as :class:`nscd.rocking.RockingResult` records each impact twice, before
        and after the velocity jump) keep the first: the rotation is continuous at an impact.
    theta : ndarray, shape (n,)
        Rotation in rad, released from rest (r_0 the first extremum).
    window : float
        Fraction of the amplitude defining the samples used near a crossing.
    refine : bool
        Then refine alpha, p, eta (with the release amplitude and time) by least
        squares of the whole simulated history against the record: every sample
        counts, which the impact times alone cannot match under noise (their fit
        is ill conditioned in alpha). False: the paper's impact-time fit only.
    """
    t = np.asarray(time, dtype=float)
    th = np.asarray(theta, dtype=float)
    if t.shape != th.shape or t.ndim != 1 or t.size < 10:
        raise ValueError(f"time and theta have shapes {t.shape} and {th.shape}, must be equal 1-D with >= 10 samples.")
    steps = np.diff(t)
    if np.any(steps < 0.0) or not np.all(np.isfinite(t)):
        k = int(np.argmax(~(steps >= 0.0)))
        raise ValueError(f"time must be finite and non-decreasing; time[{k + 1}] == {t[k + 1]} s follows "
                         f"time[{k}] == {t[k]} s.")
    distinct = np.concatenate(([True], steps > 0.0))
    t, th = t[distinct], th[distinct]
    # half cycles: runs of constant sign of a smoothed theta
    scale = np.max(np.abs(th))
    sign = np.sign(th)
    # ignore noise-level samples when splitting into half cycles
    strong = np.abs(th) > 0.2 * scale
    idx = np.flatnonzero(strong)
    runs, start = [], idx[0]
    for a, b in zip(idx[:-1], idx[1:]):
        if sign[a] != sign[b]:
            runs.append((start, a))
            start = b
    runs.append((start, idx[-1]))
    if runs and runs[-1][1] >= t.size - 3:
        runs.pop()  # the last half cycle is cut by the end of the record
    amplitudes, peak_idx = [], []
    for a, b in runs:
        seg = slice(a, b + 1)
        k = a + int(np.argmax(np.abs(th[seg])))
        amp = abs(th[k])
        near = np.flatnonzero(np.abs(th[seg]) > 0.9 * amp) + a
        if near.size >= 3:
            c = np.polyfit(t[near] - t[k], np.abs(th[near]), 2)
            amp = c[2] - c[1] ** 2 / (4 * c[0]) if c[0] < 0 else amp
        amplitudes.append(amp)
        peak_idx.append(k)
    amplitudes = np.array(amplitudes)
    peaks = np.array(peak_idx)
    # impact times: quadratic fits on either side of each crossing, extrapolated to theta = 0
    crossings = []
    for n in range(len(runs) - 1):
        s = sign[runs[n][0]]
        seg = np.arange(peaks[n], peaks[n + 1] + 1)
        c = seg[np.argmax(s * th[seg] < 0.0)]  # first sample past zero (rough)
        roots = []
        for side, idx, amp in ((s, seg[seg < c], amplitudes[n]), (-s, seg[seg >= c], amplitudes[n + 1])):
            idx = idx[(side * th[idx] < window * amp)]
            if idx.size >= 3:
                coef = np.polyfit(t[idx] - t[c], th[idx], 2)
                r = np.roots(coef)
                r = r[np.isreal(r)].real
                if r.size:
                    roots.append(t[c] + r[np.argmin(np.abs(r))])
        if roots:
            crossings.append(float(np.mean(roots)))
    crossings = np.array(crossings)
    if crossings.size < 2:
        raise ValueError(f"{crossings.size} impact(s) found in the record, need >= 2.")
    r0 = float(amplitudes[0])
    t_peak0 = float(t[peaks[0]])

    n_amp = min(amplitudes.size - 1, crossings.size)

    def residuals(x):
        alpha, p, eta, t0 = x
        e0 = math.cos(alpha - r0) - math.cos(alpha)
        times, amps, tn = [], [], t0 + _quarter_time(r0, alpha) / p
        for n in range(crossings.size):
            times.append(tn)
            # amplitude after impact n + 1: energy above rest scaled by eta^(2(n+1))
            rn = alpha - math.acos(min(1.0, math.cos(alpha) + eta ** (2 * (n + 1)) * e0))
            amps.append(rn)
            tn += 2.0 * _quarter_time(rn, alpha) / p
        return np.concatenate(((np.array(times) - crossings) / first,
                               (np.array(amps[:n_amp]) - amplitudes[1:1 + n_amp]) / r0))

    first = crossings[1] - crossings[0]
    x0 = [min(1.5 * r0, 0.5 * (r0 + 0.5 * math.pi)), 2.0 * _quarter_time(float(amplitudes[1]), 1.5 * r0) / first,
          0.9, t_peak0]
    fit = least_squares(residuals, x0,
                        bounds=([r0 * (1 + 1e-9), 1e-6, 1e-3, -np.inf], [0.5 * math.pi - 1e-9, np.inf, 1.0, np.inf]),
                        x_scale=[r0, x0[1], 0.1, first], xtol=1e-12, ftol=1e-12)
    alpha, p, eta_fit, t_release = (float(v) for v in fit.x)
    if refine:
        alpha, p, eta_fit = _refine_on_history(t, th, alpha, p, eta_fit, float(th[peaks[0]]), t_release)
    n = np.arange(1, amplitudes.size)
    e = (np.cos(alpha - amplitudes[1:]) - math.cos(alpha)) / (math.cos(alpha - amplitudes[0]) - math.cos(alpha))
    eta_n = e ** (1.0 / (2.0 * n))
    return Identification(alpha, p, eta_fit, eta_n, float(np.mean(eta_n)), crossings, amplitudes)
