"""The single-degree-of-freedom Housner family: a rigid block rocking on a rigid base.

A rectangular block of full width ``2b`` and full height ``2h`` on a base that cannot
let it slide rocks about one bottom corner at a time. Its rotation ``theta`` (rad,
counter-clockwise positive) obeys (seed 000, eq. 2-11, Makris & Zhang)

    theta'' = -p^2 [ sin(s alpha - theta) (1 + a_v/g) + (a_g/g) cos(s alpha - theta) ],

with ``s = sgn(theta)`` the side of the pivot, ``alpha = atan(b/h)`` the slenderness,
``R = sqrt(b^2 + h^2)`` the half diagonal and ``p = sqrt(3 g / (4 R))`` the frequency
parameter; ``a_g`` is the horizontal and ``a_v`` the vertical ground acceleration
(m/s^2, up positive). A positive ``a_g`` starts a negative rotation from rest, once
``|a_g| > g tan(alpha) (1 + a_v/g)``. The linearised model (``linear=True``, 000 eq.
2-44) replaces ``sin x`` by ``x`` and ``cos x`` by 1. Each time ``theta`` crosses zero
the block lands on the other corner and its angular velocity is multiplied by the
velocity ratio ``eta`` (Housner: ``1 - 1.5 sin^2 alpha``, 000 eq. 2-14; the kinetic
energy ratio is ``eta^2``). The block overturns when ``|theta|`` reaches
:data:`nscd.result.OVERTURN_ANGLE` (pi/2 - 0.02: within a degree of lying on its side).

Integration is event driven: scipy's DOP853 method (rtol 1e-10, atol 1e-12), compiled, on
the compiled equation of :mod:`nscd._equations`, stepped from event to event by
:func:`nscd._ode.fly` (impact, overturning, fracture of a restrainer, end of the
excitation); the linearised free-standing block under a pulse of the sine family or
no excitation uses its exact closed form (hyperbolic functions plus the particular
solution of the pulse) and finds the impact times by root finding on it.

Outcome: overturned when |theta| reaches OVERTURN_ANGLE (both formulations), or, once the
excitation is over, when free rocking must take the block over (energy above the
unstable equilibrium theta = alpha and moving away from it, possibly after one more
impact) -- the exact criterion behind the paper's "overturns at infinite time"
(000 eq. 2-26). Blocks at rest stay put until the ground lifts a corner; a Zeno
sequence of ever smaller bounces ends at rest (``rest_tol``).

Anchored blocks (000 chapter 4) carry restrainers: :class:`ElasticBrittle` (eq. 4-9)
or :class:`ElastoPlastic` (Bouc-Wen, eqs. 4-37 and 4-38).
"""
from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from scipy.optimize import brentq

from nscd._equations import HOUSNER, housner_contact_forces, housner_theta_ddot, housner_theta_ddot_many
from nscd._ode import Crossing, fly, inner_output_times
from nscd.motion import STANDARD_GRAVITY, Motion, ground_accelerations
from nscd.result import OVERTURN_ANGLE  # the one definition of overturned (re-exported)

__all__ = [
    "HousnerBlock", "ElasticBrittle", "ElastoPlastic", "RockingResult", "Impacts",
    "housner_eta", "required_friction", "OVERTURN_ANGLE", "PeakResponses", "linear_record_peaks",
]


_RTOL, _ATOL = 1e-10, 1e-12
_XTOL = 1e-15  # s, root-finding tolerance on event times
_ETA_SLACK = 1e-3  # eta printed to three digits (e.g. 0.825 at 20 deg, Housner 0.8246) does not warn
_MAX_PASSES = 200  # events (onsets, impacts) per record interval in linear_record_peaks
_ONSET_EPS = 1e-10  # rocking starts when side * theta'' at rest exceeds this times p^2 (round-off guard)


def housner_eta(alpha: float) -> float:
    """Housner's velocity ratio ``1 - 1.5 sin^2(alpha)`` (seed 000 eq. 2-14).

    Angular momentum about the landing corner is conserved at impact; the ratio of
    angular velocities after/before is this value (the energy ratio is its square).
    It is the largest ratio under which a rectangular block keeps rocking.
    """
    _check_alpha(alpha)
    return 1.0 - 1.5 * math.sin(alpha) ** 2


def required_friction(alpha: float, onset_acceleration: float, g: float = STANDARD_GRAVITY) -> float:
    """Static friction coefficient needed to enter pure rocking without sliding.

    Shenton's criterion (seed 000 eq. 2-7; eq. 2-45 for a one-cosine pulse, where the
    ground acceleration at onset is the amplitude). With ``a`` the ground acceleration
    at the instant rocking starts (>= g tan(alpha)),

        mu >= [a - 3/4 cos^2(alpha) (a - g tan alpha)] / [g + 3/4 sin(alpha) cos(alpha) (a - g tan alpha)],

    which is ``tan(alpha)`` for pulses that build up gradually (eq. 2-8).

    Parameters
    ----------
    alpha : float
        Slenderness in rad, in (0, pi/2).
    onset_acceleration : float
        |Ground acceleration| in m/s^2 at the onset of rocking.
    g : float
        Gravity in m/s^2.
    """
    _check_alpha(alpha)
    a = abs(float(onset_acceleration))
    excess = a - g * math.tan(alpha)
    c, s = math.cos(alpha), math.sin(alpha)
    return (a - 0.75 * c * c * excess) / (g + 0.75 * s * c * excess)


def _check_alpha(alpha: float) -> None:
    if not (0.0 < alpha < 0.5 * math.pi):
        raise ValueError(f"alpha == {alpha}, must be in (0, pi/2).")


# --------------------------------------------------------------------------- anchorages
@dataclass(frozen=True)
class ElasticBrittle:
    """Elastic-brittle restrainers (seed 000 section 4.1, eq. 4-9).

    Linear elastic until the rotation reaches ``theta_y``, then the anchorage
    fractures for good (the paper's single fracture function f(theta): after the
    first fracture the block rocks as a free-standing one).

    Parameters
    ----------
    strength : float
        sigma = F_u / W, restrainer strength over block weight, > 0.
    influence : float
        q = u_y p^2 / g, the influence factor (dimensionless), > 0.
    """

    strength: float
    influence: float

    def __post_init__(self):
        _check_positive("strength", self.strength)
        _check_positive("influence", self.influence)

    def theta_y(self, alpha: float) -> float:
        """Yield (and here fracture) rotation theta_y = 2 q / (3 sin alpha) in rad.

        From theta_y = F_u/(2 K b) = u_y/(2 b) (eq. 4-6) and q = u_y p^2/g with
        p^2 = 3 g/(4 R), b = R sin(alpha).
        """
        return 2.0 * self.influence / (3.0 * math.sin(alpha))

    def theta_fracture(self, alpha: float) -> float:
        """Rotation in rad at which the restrainers fracture (= theta_y)."""
        return self.theta_y(alpha)

    def static_overturning_acceleration(self, alpha: float, g: float = STANDARD_GRAVITY) -> float:
        """Constant ground acceleration (m/s^2) that overturns the anchored block (zero-frequency limit).

        Moment balance at theta_y just before fracture (eq. 4-9 at rest):
        a = g [tan(alpha - theta_y) + 3 sigma sin^2(alpha) / q sin(theta_y) / cos(alpha - theta_y)].
        """
        ty = self.theta_y(alpha)
        k = 3.0 * self.strength * math.sin(alpha) ** 2 / self.influence
        return g * (math.tan(alpha - ty) + k * math.sin(ty) / math.cos(alpha - ty))


@dataclass(frozen=True)
class ElastoPlastic:
    """Elasto-plastic (Bouc-Wen) restrainers (seed 000 section 4.2, eqs. 4-37, 4-38).

    Restoring term ``3 sigma sin^2(alpha)/q theta_y Z cos(theta/2)`` with the
    hysteretic variable Z: ``theta_y Z' = theta' - gamma |theta'| |Z|^(n-1) Z -
    beta theta' |Z|^n``; fracture when ``|theta|`` reaches ``ductility * theta_y``.
    One hysteretic element acts on both sides, as in the paper.

    Parameters
    ----------
    strength : float
        sigma = F_u / W, > 0.
    influence : float
        q = u_y p^2 / g, > 0.
    ductility : float
        mu = theta_f / theta_y, >= 1.
    beta, gamma : float
        Bouc-Wen shape parameters (beta + gamma = 1 keeps |Z| <= 1).
    n : float
        Bouc-Wen sharpness (large n: bilinear elasto-plastic), >= 1.
    """

    strength: float
    influence: float
    ductility: float = 1.0
    beta: float = 0.5
    gamma: float = 0.5
    n: float = 10.0

    def __post_init__(self):
        _check_positive("strength", self.strength)
        _check_positive("influence", self.influence)
        if not self.ductility >= 1.0:
            raise ValueError(f"ductility == {self.ductility}, must be >= 1.")
        if not self.n >= 1.0:
            raise ValueError(f"n == {self.n}, must be >= 1.")

    def theta_y(self, alpha: float) -> float:
        """Yield rotation theta_y = 2 q / (3 sin alpha) in rad (see ElasticBrittle)."""
        return 2.0 * self.influence / (3.0 * math.sin(alpha))

    def theta_fracture(self, alpha: float) -> float:
        """Fracture rotation mu theta_y in rad."""
        return self.ductility * self.theta_y(alpha)

    def static_overturning_acceleration(self, alpha: float, g: float = STANDARD_GRAVITY) -> float:
        """Constant ground acceleration (m/s^2) that overturns the anchored block (seed 000 eq. 4-45).

        Moment balance when the restrainers reach their strength (Z = 1) at theta_y:
        m a R cos(alpha - theta_y) = m g R sin(alpha - theta_y) + F_u 2 b cos(theta_y / 2), so

            a = g [tan(alpha - theta_y) + 2 sigma sin(alpha) cos(theta_y / 2) / cos(alpha - theta_y)]

        (b / R = sin(alpha); this is the restoring term of eq. 4-37 at Z = 1. The scan of
        eq. 4-45 prints tan(alpha) where the derivation gives sin(alpha).)
        """
        ty = self.theta_y(alpha)
        return g * (math.tan(alpha - ty) + 2.0 * self.strength * math.sin(alpha) * math.cos(0.5 * ty)
                    / math.cos(alpha - ty))


Anchorage = ElasticBrittle | ElastoPlastic


def _check_positive(name: str, value: float) -> None:
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} == {value}, must be > 0.")


# --------------------------------------------------------------------------- results
@dataclass(frozen=True)
class Impacts:
    """Impacts of a rocking history (landing on the other corner).

    Attributes
    ----------
    time : ndarray, shape (n_impacts,)
        Times in s.
    theta_dot_before, theta_dot_after : ndarray, shape (n_impacts,)
        Angular velocity in rad/s just before and just after; after = eta * before.
    """

    time: np.ndarray
    theta_dot_before: np.ndarray
    theta_dot_after: np.ndarray

    def __len__(self) -> int:
        return len(self.time)


@dataclass(frozen=True)
class RockingResult:
    """History and outcome of :meth:`HousnerBlock.simulate`.

    Attributes
    ----------
    time : ndarray, shape (n,)
        Sample times in s (increasing; an impact time appears twice, before and
        after the jump of the velocity).
    theta : ndarray, shape (n,)
        Rotation in rad, counter-clockwise positive.
    theta_dot : ndarray, shape (n,)
        Angular velocity in rad/s.
    impacts : Impacts
        Every impact.
    overturned : bool
        True if |theta| reached OVERTURN_ANGLE, or if after the end of the excitation the
        block, rocking freely, is certain to overturn (energy above the unstable
        equilibrium, moving away from it); the history then runs on past ``t_end``
        until OVERTURN_ANGLE unless the simulation stopped once decided.
    overturn_time : float
        Time in s when |theta| reaches OVERTURN_ANGLE (nan if not overturned or not computed).
    mode : str, int or None
        For an overturned block: "mode 2" (no impact before overturning), "mode 1"
        (one impact, seed 000) or the number of impacts; None otherwise.
    uplifted : bool
        True if the block ever left its rest position.
    dissipated_energy : float
        Energy lost in impacts, in units of m g R (sum of (1 - eta^2) theta_dot^2/(2 p^2)).
    block : HousnerBlock
        The block simulated.
    fractured_at : float
        Time in s at which the anchorage fractured (nan if never or free-standing).
    """

    time: np.ndarray
    theta: np.ndarray
    theta_dot: np.ndarray
    impacts: Impacts
    overturned: bool
    overturn_time: float
    mode: str | int | None
    uplifted: bool
    dissipated_energy: float
    block: "HousnerBlock"
    fractured_at: float = math.nan

    @property
    def max_abs_theta(self) -> float:
        """max |theta| over the history, rad."""
        return float(np.max(np.abs(self.theta))) if len(self.theta) else 0.0

    @property
    def max_abs_theta_dot(self) -> float:
        """max |theta_dot| over the history, rad/s."""
        return float(np.max(np.abs(self.theta_dot))) if len(self.theta_dot) else 0.0


# --------------------------------------------------------------------------- the block
@dataclass(frozen=True)
class HousnerBlock:
    """A rectangular rigid block rocking on a rigid base (Housner 1963; seed 000).

    Parameters
    ----------
    width, height : float
        Full width 2b and full height 2h in m, > 0.
    eta : float or None
        Velocity ratio at impact (after/before) in (0, 1]; None: Housner's
        ``1 - 1.5 sin^2(alpha)``. A value above Housner's warns (the block would
        gain angular momentum at impact).
    linear : bool
        Use the linearised equation (slender blocks, seed 000 eq. 2-44).
    anchorage : ElasticBrittle, ElastoPlastic or None
        Restrainers at the base (seed 000 chapter 4); None: free-standing.
    g : float
        Gravity in m/s^2.

    Examples
    --------
    >>> import nscd
    >>> blk = nscd.rocking.HousnerBlock(width=0.5, height=1.5)
    >>> r = blk.simulate(nscd.motion.OneSine(amplitude=4.0, omega=6.1), t_end=4.0)
    >>> r.overturned, r.mode, len(r.impacts)
    (False, None, 5)
    >>> blk.simulate(nscd.motion.OneSine(amplitude=8.0, omega=6.1), t_end=4.0).mode
    'mode 2'
    """

    width: float
    height: float
    eta: float | None = None
    linear: bool = False
    anchorage: Anchorage | None = None
    g: float = STANDARD_GRAVITY

    def __post_init__(self):
        _check_positive("width", self.width)
        _check_positive("height", self.height)
        _check_positive("g", self.g)
        if self.anchorage is not None and not isinstance(self.anchorage, (ElasticBrittle, ElastoPlastic)):
            raise TypeError(f"anchorage == {self.anchorage!r}, must be ElasticBrittle, ElastoPlastic or None.")
        housner = housner_eta(self.alpha)
        if self.eta is None:
            object.__setattr__(self, "eta", housner)
        else:
            eta = float(self.eta)
            if not (0.0 < eta <= 1.0):
                raise ValueError(f"eta == {eta}, must be in (0, 1].")
            if eta > housner + _ETA_SLACK:
                warnings.warn(f"eta == {eta} exceeds Housner's value {housner:.6g} for alpha == "
                              f"{self.alpha:.6g}: the impact would create angular momentum.",
                              stacklevel=3)
            object.__setattr__(self, "eta", eta)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_alpha_R(cls, alpha: float, R: float, eta: float | None = None, linear: bool = False,
                     anchorage: Anchorage | None = None, g: float = STANDARD_GRAVITY) -> "HousnerBlock":
        """Block of slenderness ``alpha`` (rad, in (0, pi/2)) and half diagonal ``R`` (m, > 0)."""
        _check_alpha(alpha)
        _check_positive("R", R)
        return cls(2.0 * R * math.sin(alpha), 2.0 * R * math.cos(alpha), eta, linear, anchorage, g)

    @classmethod
    def from_alpha_p(cls, alpha: float, p: float, eta: float | None = None, linear: bool = False,
                     anchorage: Anchorage | None = None, g: float = STANDARD_GRAVITY) -> "HousnerBlock":
        """Block of slenderness ``alpha`` (rad) and frequency parameter ``p`` (rad/s, > 0).

        R = 3 g / (4 p^2) for a rectangular block.
        """
        _check_positive("p", p)
        return cls.from_alpha_R(alpha, 0.75 * g / p**2, eta, linear, anchorage, g)

    # ------------------------------------------------------------------ geometry
    @property
    def b(self) -> float:
        """Half width in m."""
        return 0.5 * self.width

    @property
    def h(self) -> float:
        """Half height in m."""
        return 0.5 * self.height

    @cached_property
    def alpha(self) -> float:
        """Slenderness atan(b/h) in rad."""
        return math.atan2(self.width, self.height)

    @cached_property
    def R(self) -> float:
        """Half diagonal sqrt(b^2 + h^2) in m (corner to centroid)."""
        return math.hypot(self.b, self.h)

    @cached_property
    def p(self) -> float:
        """Frequency parameter sqrt(3 g / (4 R)) in rad/s."""
        return math.sqrt(0.75 * self.g / self.R)

    @property
    def onset_acceleration(self) -> float:
        """|Horizontal ground acceleration| in m/s^2 above which rocking starts (no vertical).

        g tan(alpha); g alpha for the linearised model.
        """
        return self.g * (self.alpha if self.linear else math.tan(self.alpha))

    @property
    def theta_dot_r(self) -> float:
        """Angular velocity in rad/s that brings the block from rest to theta = alpha.

        sqrt(3/2 g/R (1 - cos alpha)) (seed 001 eq. 2).
        """
        return self.p * math.sqrt(2.0 * (1.0 - math.cos(self.alpha)))

    # ------------------------------------------------------------------ checks
    def check_sliding(self, mu: float, motion: Motion, t_end: float | None = None) -> float:
        """Check Shenton's no-sliding condition at the onset of rocking (000 eqs. 2-7, 2-45).

        Parameters
        ----------
        mu : float
            Static friction coefficient of the base, >= 0.
        motion : Motion
            Horizontal ground motion.
        t_end : float, optional
            Search horizon in s for the onset (default: the motion's duration, or 60 s).

        Returns
        -------
        float
            The friction coefficient needed (nan if the motion never starts rocking).
            Warns (``UserWarning``) when ``mu`` is below it: the block would slide or
            slide-rock and this model does not apply.
        """
        if not (mu >= 0.0):
            raise ValueError(f"mu == {mu}, must be >= 0.")
        horizon = t_end if t_end is not None else (motion.duration if math.isfinite(motion.duration) else 60.0)
        onset = _next_onset(self, motion, None, 0.0, horizon, None)
        if onset is None:
            return math.nan
        needed = required_friction(self.alpha, float(motion.acceleration(onset[0])), self.g)
        if mu < needed:
            warnings.warn(f"mu == {mu} < {needed:.4g} needed for pure rocking at onset (t = {onset[0]:.4g} s): "
                          "the block slides; the rocking model does not apply.", stacklevel=2)
        return needed

    # ------------------------------------------------------------------ energies
    def potential(self, theta: np.ndarray | float) -> np.ndarray | float:
        """Potential energy in units of m g R: cos(alpha - |theta|) (centroid height / R).

        Quadratic expansion 1 - (alpha - |theta|)^2 / 2 for the linearised model.
        """
        d = self.alpha - np.abs(theta)
        return 1.0 - 0.5 * d * d if self.linear else np.cos(d)

    def energy(self, theta, theta_dot):
        """Mechanical energy in units of m g R: theta_dot^2/(2 p^2) + potential(theta)."""
        return 0.5 * (np.asarray(theta_dot) / self.p) ** 2 + self.potential(theta)

    # ------------------------------------------------------------------ simulation
    def contact_forces(self, mass: float, theta, theta_dot, ag, av) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The base's force on the free-standing block over a history, from Newton's law for the block.

        Parameters
        ----------
        mass : float
            kg.
        theta, theta_dot : array_like, shape (n,)
            Rotation (rad) and rate (rad/s), as :attr:`RockingResult.theta` and ``theta_dot``.
        ag, av : array_like, shape (n,)
            Horizontal and vertical (up positive) ground accelerations at the samples, m/s^2.

        Returns
        -------
        fx, fy : ndarray, shape (n,)
            Tangential and normal force on the block (N) in the 2D engine's frame, whose angle is
            ``-theta``: a negative ``fy`` is a base that would have to pull.
        height : ndarray, shape (n,)
            The centroid's height above the pivot, m.

        The compiled :func:`nscd._equations.housner_contact_forces`.
        """
        arrays = (np.ascontiguousarray(x, dtype=float) for x in (theta, theta_dot, ag, av))
        return housner_contact_forces(_constants(self), self.b, self.h, float(mass), *arrays)

    def simulate(self, motion: Motion | None = None, t_end: float = 10.0, *, vertical: Motion | None = None,
                 theta0: float = 0.0, theta_dot0: float = 0.0, dt_out: float | None = None,
                 stop_when_decided: bool = False, rest_tol: float = 1e-7) -> RockingResult:
        """Rocking history under a horizontal (and optional vertical) ground motion.

        Parameters
        ----------
        motion : Motion or None
            Horizontal ground acceleration (positive starts a negative rotation).
            None: free rocking from (theta0, theta_dot0).
        t_end : float
            End time in s, > 0.
        vertical : Motion, optional
            Vertical ground acceleration (up positive); must stay above -g.
        theta0, theta_dot0 : float
            Initial rotation (rad, |theta0| < pi/2) and angular velocity (rad/s).
            Both zero: the block rests until the ground lifts a corner.
        dt_out : float, optional
            Sampling step of the output history in s (default t_end / 2000); event
            times are always included.
        stop_when_decided : bool
            Stop as soon as the outcome is known for good: overturned, or the
            excitation is over and the freely rocking block can no longer overturn
            (energy criterion). An anchored block whose restrainers still hold when
            the excitation ends is only decided at rest or at ``t_end``.
        rest_tol : float
            The block comes to rest after an impact when |theta_dot| / p falls below
            this and the ground cannot lift the new corner (ends a Zeno sequence).

        Returns
        -------
        RockingResult
        """
        _check_positive("t_end", t_end)
        if abs(theta0) >= OVERTURN_ANGLE:
            raise ValueError(f"theta0 == {theta0}, must be in (-pi/2, pi/2).")
        if dt_out is not None:
            _check_positive("dt_out", dt_out)
        return _Simulation(self, motion, vertical, t_end, dt_out or t_end / 2000.0,
                           stop_when_decided, rest_tol).run(theta0, theta_dot0)


# --------------------------------------------------------------------------- dynamics
def _constants(block: HousnerBlock, side: int = 1, intact: bool = False) -> np.ndarray:
    """The block's ``par`` of :mod:`nscd._equations` (layout in that module's docstring)."""
    anc, alpha = block.anchorage, block.alpha
    kind, restrainer, gamma, beta, n, theta_y = 0.0, 0.0, 0.0, 0.0, 1.0, 1.0
    if isinstance(anc, ElasticBrittle):
        kind, restrainer = 1.0, 3.0 * anc.strength * math.sin(alpha) ** 2 / anc.influence
    elif isinstance(anc, ElastoPlastic):
        kind, restrainer = 2.0, 2.0 * anc.strength * math.sin(alpha)
        gamma, beta, n, theta_y = anc.gamma, anc.beta, anc.n, anc.theta_y(alpha)
    return np.array([alpha, block.p ** 2, block.g, float(block.linear), kind, restrainer, gamma, beta, n, theta_y,
                     float(side), float(intact)])


def _theta_ddot(block: HousnerBlock, side, theta, ag, av, z=0.0, intact=False):
    """Angular acceleration (rad/s^2) on the pivot of ``side`` (seed 000 eq. 2-11/4-9/4-37).

    Floats or arrays (broadcast); the compiled :func:`nscd._equations.housner_theta_ddot`.
    """
    par = _constants(block)
    if all(np.ndim(x) == 0 for x in (side, theta, ag, av, z, intact)):
        return housner_theta_ddot(par, float(side), float(theta), float(ag), float(av), float(z), bool(intact))
    arrays = np.broadcast_arrays(*(np.asarray(x, dtype=float) for x in (side, theta, ag, av, z, intact)))
    shape = arrays[0].shape
    side, theta, ag, av, z, intact = (np.ascontiguousarray(a).ravel() for a in arrays)
    return housner_theta_ddot_many(par, side, theta, ag, av, z, intact != 0.0).reshape(shape)


def _zero_acceleration(t: float) -> float:
    return 0.0


def _acceleration_at(motion: Motion | None) -> Callable[[float], float]:
    """The scalar a(t) (m/s^2) of onset and release tests: :meth:`Motion.acceleration_at`, 0 for None."""
    return _zero_acceleration if motion is None else motion.acceleration_at


def _excitation_end(motion: Motion | None, vertical: Motion | None) -> float:
    ends = [m.duration for m in (motion, vertical) if m is not None]
    return max(ends) if ends else 0.0


def _scan_step(motion: Motion | None, vertical: Motion | None) -> float:
    """A time step (s) fine enough to bracket sign changes of the ground acceleration."""
    steps = [1e-3]
    for m in (motion, vertical):
        if m is None:
            continue
        if hasattr(m, "dt"):
            steps.append(float(m.dt))
        if hasattr(m, "omega") and m.omega:
            steps.append(2.0 * math.pi / float(m.omega) / 256.0)
    return min(steps)


def _uplift_margin(block, side, t, motion, vertical, z, intact):
    """side * theta'' at theta = 0, theta' = 0: > 0 when the ground lifts the ``side`` corner."""
    ag, av = _acceleration_at(motion)(t), _acceleration_at(vertical)(t)
    return side * _theta_ddot(block, side, 0.0, ag, av, z, intact)


def _onset_from_pieces(block, pieces, t0, t1) -> tuple[float, int] | None:
    """Onset for the linear free-standing block under A sin(w t + phi) pieces, without Motion calls.

    The corner of side s lifts when -s a(t) > g (alpha + eps) (eq. 2-44 at rest).
    """
    thr = block.g * (block.alpha + _ONSET_EPS)
    for (ta, tb, A, w, ph) in pieces:
        lo, hi = max(t0, ta), min(t1, tb)
        if hi <= lo or abs(A) <= thr:
            continue
        n = max(3, int(math.ceil((hi - lo) * w / (2.0 * math.pi) * 256)) + 1)
        ts = np.linspace(lo, hi, n)
        a = A * np.sin(w * ts + ph)
        up = np.nonzero(np.abs(a) > thr)[0]
        if len(up) == 0:
            continue
        k = up[0]
        side = -1 if a[k] > 0 else 1
        if k == 0:
            return lo, side
        f = lambda t: -side * A * math.sin(w * t + ph) - thr  # noqa: E731
        return brentq(f, ts[k - 1], ts[k], xtol=_XTOL, rtol=4 * np.finfo(float).eps), side
    return None


def _next_onset(block, motion, vertical, t0, t1, state) -> tuple[float, int] | None:
    """First time in [t0, t1] at which the ground lifts a corner of the resting block, with its side."""
    if motion is None and vertical is None:
        return None
    z, intact = (0.0, False) if state is None else state
    t_last = min(t1, _excitation_end(motion, vertical) + 1e-9)
    if t_last <= t0:
        return None
    step = _scan_step(motion, vertical)
    n = max(2, int(math.ceil((t_last - t0) / step)) + 1)
    ts = np.linspace(t0, t_last, n)
    ag = np.zeros(n) if motion is None else np.asarray(motion.acceleration(ts), dtype=float)
    av = np.zeros(n) if vertical is None else np.asarray(vertical.acceleration(ts), dtype=float)
    margins = {side: side * _theta_ddot(block, side, 0.0, ag, av, z, intact) for side in (-1, 1)}
    eps = _ONSET_EPS * block.p**2
    best = None
    for side, margin in margins.items():
        up = np.nonzero(margin > eps)[0]
        if len(up) == 0:
            continue
        k = up[0]
        if k == 0:
            t_on = t0
        else:
            f = lambda t, side=side: _uplift_margin(block, side, t, motion, vertical, z, intact) - eps  # noqa: E731
            t_on = brentq(f, ts[k - 1], ts[k], xtol=_XTOL, rtol=4 * np.finfo(float).eps)
        if best is None or t_on < best[0]:
            best = (t_on, side)
    return best


# --------------------------------------------------------------------------- flights
@dataclass
class _Flight:
    """One rocking segment on one pivot, from t0 until an event or t_stop."""

    t1: float
    theta1: float
    theta_dot1: float
    z1: float
    event: str  # "impact", "overturn", "fracture", "stop"
    evaluate: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def _fly_numeric(block, motion, vertical, t0, theta0, thd0, z0, intact, side, t_stop) -> _Flight:
    anc = block.anchorage
    bouc = isinstance(anc, ElastoPlastic) and intact
    par = _constants(block, side, intact)
    names = ["impact", "overturn"]
    events = [(Crossing(0, float(side)), -1), (lambda t, y: abs(y[0]) - OVERTURN_ANGLE, 1)]
    if anc is not None and intact:
        th_f = anc.theta_fracture(block.alpha)
        names.append("fracture")
        events.append((lambda t, y: abs(y[0]) - th_f, 1))
    shaking = ground_accelerations(motion, vertical)
    y = np.array([theta0, thd0] + ([z0] if bouc else []), dtype=float)
    # integrate between the kinks of sampled records (piecewise-linear acceleration):
    # each piece is smooth, so the high-order steps are not rejected at every sample
    whole, first_step = None, None
    for t_b in _breakpoints(t0, t_stop, motion, vertical):
        piece = fly(HOUSNER, par, shaking, t0 if whole is None else whole.t1, y, t_b, events, _RTOL, _ATOL,
                    first_step)
        if whole is None:
            whole = piece
        else:
            whole.extend(piece)
        y, first_step = piece.y1, whole.last_step or first_step
        if piece.event is not None:
            break
    event = "stop" if whole.event is None else names[whole.event]
    y = np.array(whole.y1, dtype=float)
    if event == "impact":
        y[0] = 0.0

    def evaluate(t):
        state = whole.evaluate(np.asarray(t, dtype=float))
        return state[0], state[1]
    return _Flight(whole.t1, float(y[0]), float(y[1]), float(y[2]) if bouc else z0, event, evaluate)


def _output_times(t0: float, t1: float, dt_out: float) -> np.ndarray:
    """Sample times (s) of a history from ``t0`` to ``t1``: ``t0``, the multiples of ``dt_out``
    strictly inside (t0, t1) (:func:`nscd._ode.inner_output_times`), then ``t1``; just ``t0`` when
    ``t1 <= t0``."""
    if t1 <= t0:
        return np.array([t0])
    return np.concatenate(([t0], inner_output_times(np.array([t0]), np.array([t1]), dt_out)[0], [t1]))


def _breakpoints(t0: float, t1: float, *motions: Motion | None) -> list[float]:
    """Ends of the smooth pieces of [t0, t1]: sample times of records inside, then t1."""
    points = []
    for m in motions:
        dt = getattr(m, "dt", None) if getattr(m, "samples_mps2", None) is not None else None
        if dt:
            k0, k1 = math.floor(t0 / dt) + 1, math.ceil(min(t1, m.duration) / dt)
            grid = np.arange(k0, k1 + 1) * dt
            points.extend(grid[(grid > t0) & (grid < t1)].tolist())
    return sorted(set(points)) + [t1]


def _sine_pieces(motion: Motion | None) -> list[tuple[float, float, float, float, float]] | None:
    """Describe the motion as A sin(omega t + phase) on [0, duration] (zero after), if it is one.

    Returns [(t_start, t_end, A, omega, phase)] or None when the motion is not of this
    family (checked numerically, so any Motion subclass with these attributes works).
    """
    if motion is None:
        return []
    try:
        A, w, ph, T = (float(motion.amplitude), float(motion.omega), float(motion.phase), float(motion.duration))
    except (AttributeError, TypeError):
        return None
    if not (math.isfinite(T) and w > 0):
        return None
    ts = np.array([0.0, 0.13, 0.37, 0.61, 0.89]) * T
    expected = A * np.sin(w * ts + ph)
    if not np.allclose(np.asarray(motion.acceleration(ts)), expected, rtol=1e-12, atol=1e-12 * abs(A)):
        return None
    return [(0.0, T, A, w, ph)]


def _fly_closed(block, pieces, t0, theta0, thd0, side, t_stop) -> _Flight:
    """Exact flight of the linearised free-standing block (seed 000 eqs. 2-19..2-25).

    On each piece theta = s alpha + P(t) + C1 cosh(p tau) + C2 sinh(p tau), with the
    particular solution P = (A/g) sin(w t + phi) / (1 + w^2/p^2) of the pulse.
    """
    p, g, s_alpha = block.p, block.g, side * block.alpha
    segments = []  # (ta, tb, C1, C2, K, w, ph)
    t, th, thd = t0, theta0, thd0
    bounds = sorted({t0, t_stop} | {x for pc in pieces for x in pc[:2] if t0 < x < t_stop})
    for ta, tb in zip(bounds[:-1], bounds[1:]):
        K, w, ph = 0.0, 0.0, 0.0
        for (pa, pb, A, wp, php) in pieces:
            if pa <= ta and tb <= pb:
                K, w, ph = (A / g) / (1.0 + (wp / p) ** 2), wp, php
        C1 = th - s_alpha - K * math.sin(w * ta + ph)
        C2 = (thd - K * w * math.cos(w * ta + ph)) / p
        seg = (ta, tb, C1, C2, K, w, ph)

        def theta_of(tt, seg=seg):
            a, _, c1, c2, k, ww, pp = seg
            tau = p * (np.asarray(tt) - a)
            return s_alpha + k * np.sin(ww * np.asarray(tt) + pp) + c1 * np.cosh(tau) + c2 * np.sinh(tau)

        def theta_dot_of(tt, seg=seg):
            a, _, c1, c2, k, ww, pp = seg
            tau = p * (np.asarray(tt) - a)
            return k * ww * np.cos(ww * np.asarray(tt) + pp) + p * (c1 * np.sinh(tau) + c2 * np.cosh(tau))

        # scan for the first crossing of theta = 0 (impact) or |theta| = pi/2 (overturn)
        h = 0.1 / max(p, w)
        n = max(3, int(math.ceil((tb - ta) / h)) + 1)
        ts = np.linspace(ta, tb, n)
        vals = side * theta_of(ts)
        hit = None
        bad = np.nonzero((vals[1:] < 0.0) | (vals[1:] >= OVERTURN_ANGLE))[0]
        if len(bad):
            k = bad[0] + 1
            if vals[k] < 0.0:
                f, event = (lambda tt: side * theta_of(tt)), "impact"
            else:
                f, event = (lambda tt: side * theta_of(tt) - OVERTURN_ANGLE), "overturn"
            lo = ts[k - 1]
            if f(lo) * f(ts[k]) >= 0.0:  # only at the start, on theta = 0 itself: lands at once
                hit = (lo, event)
            else:
                hit = (brentq(f, lo, ts[k], xtol=_XTOL, rtol=4 * np.finfo(float).eps), event)
        segments.append((ta, hit[0] if hit else tb, theta_of, theta_dot_of))
        if hit:
            t1, event = hit
            th1 = 0.0 if event == "impact" else side * OVERTURN_ANGLE
            return _Flight(t1, th1, float(theta_dot_of(t1)), 0.0, event, _piecewise(segments))
        t, th, thd = tb, float(theta_of(tb)), float(theta_dot_of(tb))
    return _Flight(t, th, thd, 0.0, "stop", _piecewise(segments))


def _piecewise(segments):
    def evaluate(t):
        t = np.asarray(t, dtype=float)
        th, thd = np.empty_like(t), np.empty_like(t)
        for i, (ta, tb, f, df) in enumerate(segments):
            mask = (t >= ta) & ((t <= tb) if i == len(segments) - 1 else (t < tb))
            th[mask], thd[mask] = f(t[mask]), df(t[mask])
        return th, thd
    return evaluate


# --------------------------------------------------------------------------- the event loop
def _free_outcome(block: HousnerBlock, theta: float, theta_dot: float, side: int) -> tuple[bool, int]:
    """Outcome of free rocking (no excitation) from a state: (overturns, impacts before).

    Energy E = theta_dot^2/(2 p^2) + V(theta) (units m g R) is conserved between
    impacts; the barrier is V(alpha) = 1. An impact at theta = 0 keeps
    V(0) + eta^2 (E - V(0)).
    """
    E = float(block.energy(theta, theta_dot))
    outward = side * theta_dot > 0.0 or (theta_dot == 0.0 and abs(theta) > block.alpha)
    if abs(theta) > block.alpha and (outward or E < 1.0):
        return True, 0  # beyond the top: falls outward (or cannot climb back over it)
    if outward:
        return E > 1.0, 0
    v0 = float(block.potential(0.0))
    E_after = v0 + block.eta**2 * (E - v0)
    return E_after > 1.0, 1


class _Simulation:
    """The event loop of one simulation: rest, onset, flights, impacts, decisions."""

    def __init__(self, block, motion, vertical, t_end, dt_out, stop_when_decided, rest_tol):
        self.block, self.motion, self.vertical = block, motion, vertical
        self.t_end, self.dt_out = float(t_end), float(dt_out)
        self.stop_when_decided, self.rest_tol = stop_when_decided, rest_tol
        self.t_free = _excitation_end(motion, vertical)
        if vertical is not None:
            ts = np.linspace(0.0, min(t_end, vertical.duration), 4001)
            if np.any(np.asarray(vertical.acceleration(ts)) <= -block.g):
                raise ValueError("vertical acceleration reaches -g: the block would lift off the base.")
        pieces = None
        if block.linear and block.anchorage is None and vertical is None:
            pieces = _sine_pieces(motion)
        self.pieces = pieces
        self.times, self.thetas, self.thetadots = [], [], []
        self.imp_t, self.imp_before, self.imp_after = [], [], []

    def _fly(self, t, th, thd, z, intact, side, t_stop):
        if self.pieces is not None:
            return _fly_closed(self.block, self.pieces, t, th, thd, side, t_stop)
        return _fly_numeric(self.block, self.motion, self.vertical, t, th, thd, z, intact, side, t_stop)

    def _sample(self, t0, t1, evaluate):
        ts = _output_times(t0, t1, self.dt_out) if t1 > t0 else np.array([t0, t1])
        th, thd = evaluate(ts)
        self.times.append(ts)
        self.thetas.append(np.asarray(th, dtype=float))
        self.thetadots.append(np.asarray(thd, dtype=float))

    def _rest(self, t0, t1):
        """At rest on the base from t0 to t1, sampled like a flight (the checks read the ground's demand)."""
        ts = _output_times(t0, t1, self.dt_out)
        self.times.append(ts)
        self.thetas.append(np.zeros_like(ts))
        self.thetadots.append(np.zeros_like(ts))

    def run(self, theta0: float, theta_dot0: float) -> RockingResult:
        block = self.block
        t, th, thd, z = 0.0, float(theta0), float(theta_dot0), 0.0
        intact = block.anchorage is not None
        fractured_at = math.nan
        resting = th == 0.0 and thd == 0.0
        side = int(np.sign(th)) if th != 0.0 else int(np.sign(thd)) if thd != 0.0 else -1
        overturned, decided_overturn, overturn_time, uplifted = False, False, math.nan, not resting
        extra_impacts, stalled, settled_energy = 0, False, 0.0
        t_limit = self.t_end
        while t < t_limit:
            if resting:
                # after a flight of zero length (the ground lifted a corner for an instant only),
                # look for the next onset one scan step later, not at the same instant again
                t_search = t + _scan_step(self.motion, self.vertical) if stalled else t
                if self.pieces is not None:
                    onset = _onset_from_pieces(block, self.pieces, t_search, t_limit)
                else:
                    onset = _next_onset(block, self.motion, self.vertical, t_search, t_limit, (z, intact))
                if onset is None:
                    self._rest(t, t_limit)
                    t = t_limit
                    break
                self._rest(t, onset[0])
                t, side, th, thd, resting, uplifted = onset[0], onset[1], 0.0, 0.0, False, True
            t_stop = self.t_free if t < self.t_free < t_limit else t_limit
            flight = self._fly(t, th, thd, z, intact, side, t_stop)
            stalled = flight.t1 <= t
            self._sample(t, flight.t1, flight.evaluate)
            t, th, thd, z = flight.t1, flight.theta1, flight.theta_dot1, flight.z1
            if flight.event == "overturn":
                overturned, overturn_time = True, t
                break
            if flight.event == "fracture":
                intact, fractured_at = False, t
                continue
            if flight.event == "impact":
                after = block.eta * thd
                self.imp_t.append(t)
                self.imp_before.append(thd)
                self.imp_after.append(after)
                self.times.append(np.array([t]))
                self.thetas.append(np.array([0.0]))
                self.thetadots.append(np.array([after]))
                side, thd = -side, after
                if abs(after) < self.rest_tol * block.p and \
                        _uplift_margin(block, side, t, self.motion, self.vertical, z, intact) <= 0.0:
                    settled_energy += 0.5 * (after / block.p) ** 2  # the last bounce's energy is lost too
                    resting, thd = True, 0.0
            # decide once the excitation is over (free-standing or fractured anchorage)
            if t >= self.t_free and not decided_overturn and not (block.anchorage is not None and intact):
                if resting:
                    outcome = (False, 0)
                else:
                    outcome = _free_outcome(block, th, thd, side)
                if outcome[0]:
                    decided_overturn, extra_impacts = True, outcome[1]
                    if self.stop_when_decided:
                        overturned = True
                        break
                    t_limit = t + 100.0 / block.p  # run on until |theta| = pi/2 (escape takes < 40/p)
                elif self.stop_when_decided:
                    break
        n_imp = len(self.imp_t)
        overturned = overturned or decided_overturn
        if overturned:
            total = n_imp + (extra_impacts if math.isnan(overturn_time) else 0)
            mode = {0: "mode 2", 1: "mode 1"}.get(total, total)
        else:
            mode = None
        before = np.array(self.imp_before)
        dissipated = float(np.sum((1.0 - block.eta**2) * before**2) / (2.0 * block.p**2)) + settled_energy
        return RockingResult(
            time=np.concatenate(self.times) if self.times else np.zeros(0),
            theta=np.concatenate(self.thetas) if self.thetas else np.zeros(0),
            theta_dot=np.concatenate(self.thetadots) if self.thetadots else np.zeros(0),
            impacts=Impacts(np.array(self.imp_t), before, np.array(self.imp_after)),
            overturned=overturned, overturn_time=overturn_time, mode=mode, uplifted=uplifted,
            dissipated_energy=dissipated, block=block, fractured_at=fractured_at)


# --------------------------------------------------------------------------- many linear blocks at once
@dataclass(frozen=True)
class PeakResponses:
    """Peak responses of many blocks under one record (:func:`linear_record_peaks`).

    Every attribute is an array of shape (n_blocks,).

    Attributes
    ----------
    max_theta : ndarray
        max |theta| in rad (turning points located on the exact solution).
    max_theta_dot : ndarray
        max |theta_dot| in rad/s (extrema inside flights in closed form).
    max_energy : ndarray
        max mechanical energy above rest, units m g R.
    dissipated : ndarray
        Energy lost in impacts, units m g R.
    overturned : ndarray of bool
        Whether the block overturned.
    """

    max_theta: np.ndarray
    max_theta_dot: np.ndarray
    max_energy: np.ndarray
    dissipated: np.ndarray
    overturned: np.ndarray


def _impact_times(s, alpha, p, t0, c1, c2, a0, slope, g, dt):
    """Roots in (t0, dt) of s theta(tau) (positive at t0, negative at dt) for the linear closed form.

    Newton steps safeguarded by bisection (the bracket always shrinks), to 1e-13 s.
    """
    lo, hi = t0.copy(), np.full(t0.shape, dt)
    f_lo = s * (s * alpha + (a0 + slope * lo) / g + c1)
    f_hi = s * (s * alpha + (a0 + slope * hi) / g + c1 * np.cosh(p * (hi - t0)) + c2 * np.sinh(p * (hi - t0)))
    # regula falsi start; from theta = 0 (just after an impact) the quadratic estimate of the return
    x = np.where(f_lo > 0.0, lo + (hi - lo) * f_lo / (f_lo - f_hi), 0.5 * (lo + hi))
    v0 = s * (slope / g + p * c2)
    acc0 = s * p**2 * (c1 + 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        quad_guess = lo - 2.0 * v0 / acc0
    x = np.where((f_lo <= 0.0) & (quad_guess > lo) & (quad_guess < hi), quad_guess, x)
    for _ in range(60):
        arg = p * (x - t0)
        ch, sh = np.cosh(arg), np.sinh(arg)
        f = s * (s * alpha + (a0 + slope * x) / g + c1 * ch + c2 * sh)
        df = s * (slope / g + p * (c1 * sh + c2 * ch))
        pos = f >= 0.0
        lo, hi = np.where(pos, x, lo), np.where(pos, hi, x)
        with np.errstate(divide="ignore", invalid="ignore"):
            newton = x - f / df
        inside = np.isfinite(newton) & (newton > lo) & (newton < hi)
        x_new = np.where(inside, newton, 0.5 * (lo + hi))
        if np.all((np.abs(x_new - x) <= 1e-13) | (hi - lo <= 1e-13)):
            return x_new
        x = x_new
    return x


def linear_record_peaks(alpha, p, eta, record: Motion, t_end: float, g: float = STANDARD_GRAVITY,
                        rest_tol: float = 1e-7) -> PeakResponses:
    """Peak responses of many linearised free-standing blocks under a sampled record, vectorised.

    Exact between events: on each sample interval the record's acceleration is linear,
    a = a_k + m tau, and eq. 2-44 has the solution theta = s alpha + a/g + C1 cosh(p tau)
    + C2 sinh(p tau); impacts are located by bisection on it (to 1e-14 s), onsets
    exactly (|a| = g alpha, linear in tau). All blocks advance together, one interval
    at a time (numpy over the blocks). After the record the blocks rock freely up to
    ``t_end``; a block still rocking then is overturned if free rocking must take it
    over (same energy criterion as :meth:`HousnerBlock.simulate`). Two crossings of
    theta = 0 inside one sample interval count as none (intervals with p dt << 1).

    Parameters
    ----------
    alpha, p, eta : array_like, shape (n,)
        Slenderness (rad), frequency parameter (rad/s), velocity ratio per block.
    record : Motion
        A sampled record (``samples_mps2`` and ``dt``, e.g. :class:`nscd.motion.Record`).
    t_end : float
        End time in s (>= the record's duration to include the free rocking after it).
    """
    alpha, p, eta = (np.asarray(x, dtype=float).ravel() for x in np.broadcast_arrays(alpha, p, eta))
    if np.any(~((alpha > 0) & (alpha < 0.5 * math.pi))):
        raise ValueError(f"alpha == {alpha[~((alpha > 0) & (alpha < 0.5 * math.pi))][0]}, must be in (0, pi/2).")
    samples = getattr(record, "samples_mps2", None)
    if samples is None:
        raise TypeError(f"record == {record!r}, must be a sampled record (samples_mps2, dt).")
    dt = float(record.dt)
    n_int = int(math.ceil(t_end / dt))
    acc = np.zeros(n_int + 1)
    m = min(len(samples), n_int + 1)
    acc[:m] = samples[:m]
    n = alpha.size
    th, thd = np.zeros(n), np.zeros(n)
    side = -np.ones(n)
    resting, over = np.ones(n, bool), np.zeros(n, bool)
    max_th, max_thd, max_e, diss = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    thr = g * (alpha + _ONSET_EPS)
    v0 = 1.0 - 0.5 * alpha**2

    for k in range(n_int):
        if np.all(resting | over) and k * dt >= record.duration:
            break
        a0, slope = acc[k], (acc[k + 1] - acc[k]) / dt
        tau0 = np.zeros(n)
        active = ~over
        for _ in range(_MAX_PASSES):  # passes: onsets and impacts inside this interval
            rest = np.flatnonzero(active & resting)
            if rest.size:  # exact onset: |a| = g alpha on a linear piece
                a_start, a_end, th_r = a0 + slope * tau0[rest], a0 + slope * dt, thr[rest]
                t_on, s_on = np.full(rest.size, np.inf), np.zeros(rest.size)
                for sgn in (1.0, -1.0):  # sgn * a > thr lifts the corner of side -sgn
                    now = sgn * a_start > th_r
                    later = ~now & (sgn * a_end > th_r) & (sgn * slope > 0)
                    cand = np.where(now, tau0[rest], np.inf)
                    if later.any():
                        cand[later] = (sgn * th_r[later] - a0) / slope
                    better = cand < t_on
                    t_on[better], s_on[better] = cand[better], -sgn
                lift = np.isfinite(t_on)
                up = rest[lift]
                resting[up], side[up], tau0[up], th[up], thd[up] = False, s_on[lift], t_on[lift], 0.0, 0.0
                active[rest[~lift]] = False
            fi = np.flatnonzero(active & ~resting)
            if fi.size == 0:
                break
            s, al, pp, t0 = side[fi], alpha[fi], p[fi], tau0[fi]
            c1 = th[fi] - s * al - (a0 + slope * t0) / g
            c2 = (thd[fi] - slope / g) / pp

            def theta_of(tau):
                x = pp * (tau - t0)
                return s * al + (a0 + slope * tau) / g + c1 * np.cosh(x) + c2 * np.sinh(x)

            def theta_dot_of(tau):
                x = pp * (tau - t0)
                return slope / g + pp * (c1 * np.sinh(x) + c2 * np.cosh(x))
            end = theta_of(np.full(fi.size, dt))
            cross = s * end < 0.0
            stop = np.full(fi.size, dt)
            if cross.any():
                stop[cross] = _impact_times(s[cross], al[cross], pp[cross], t0[cross], c1[cross], c2[cross],
                                            a0, slope, g, dt)
            v_start, v_stop = theta_dot_of(t0), theta_dot_of(stop)
            # extremum of theta_dot inside the flight: theta'' = p^2 (c1 cosh x + c2 sinh x) = 0
            with np.errstate(divide="ignore", invalid="ignore"):
                x_star = np.arctanh(-c1 / c2)
            inner = np.isfinite(x_star) & (x_star > 0.0) & (x_star < pp * (stop - t0))
            if inner.any():
                xs = np.where(inner, x_star, 0.0)
                v_star = slope / g + pp * (c1 * np.sinh(xs) + c2 * np.cosh(xs))
                max_thd[fi] = np.maximum(max_thd[fi], np.where(inner, np.abs(v_star), 0.0))
            turn = v_start * v_stop < 0.0
            if turn.any():  # turning point: theta_dot = 0 is a quadratic in y = e^x (x = p tau)
                qa, qb, qc = c1[turn] + c2[turn], 2.0 * slope / (g * pp[turn]), c2[turn] - c1[turn]
                with np.errstate(divide="ignore", invalid="ignore"):
                    disc = np.sqrt(np.maximum(qb * qb - 4.0 * qa * qc, 0.0))
                    roots = np.stack([(-qb + disc) / (2.0 * qa), (-qb - disc) / (2.0 * qa),
                                      np.where(qb != 0, -qc / qb, np.nan)])  # last: qa == 0
                    xr = np.log(roots)
                span = pp[turn] * (stop[turn] - t0[turn])
                ok = np.isfinite(xr) & (xr >= 0.0) & (xr <= span)
                xt = np.where(ok, xr, np.inf).min(axis=0)
                xt = np.where(np.isfinite(xt), xt, 0.0)
                peak = np.abs(theta_of(t0))
                peak[turn] = np.abs(s[turn] * al[turn] + (a0 + slope * (t0[turn] + xt / pp[turn])) / g
                                    + c1[turn] * np.cosh(xt) + c2[turn] * np.sinh(xt))
                max_th[fi] = np.maximum(max_th[fi], peak)
            stay = fi[~cross]
            th[stay], thd[stay] = end[~cross], theta_dot_of(stop)[~cross]
            active[stay] = False
            if not cross.any():
                break
            ci = fi[cross]
            t_imp = stop[cross]
            v_before = theta_dot_of(stop)[cross]
            kinetic = 0.5 * (v_before / p[ci]) ** 2
            max_thd[ci] = np.maximum(max_thd[ci], np.abs(v_before))
            max_e[ci] = np.maximum(max_e[ci], kinetic)
            diss[ci] += (1.0 - eta[ci] ** 2) * kinetic
            v_after = eta[ci] * v_before
            new_side = -side[ci]
            # the ground pushes the new corner down: |theta''| at rest on the new side
            push = p[ci] ** 2 * (alpha[ci] + new_side * (a0 + slope * t_imp) / g)
            # Zeno chain of bounces of total duration 2 |v| / (push (1 - eta)): collapse it to rest
            # when it ends inside this interval, dissipating the remaining kinetic energy
            t_zeno = np.where(push > 0, 2.0 * np.abs(v_after) / np.where(push > 0, push, 1.0) / (1.0 - eta[ci] + 1e-300),
                              np.inf)
            settle = (push > 0) & ((t_imp + t_zeno <= dt) | (np.abs(v_after) < rest_tol * p[ci]))
            diss[ci] += np.where(settle, 0.5 * (v_after / p[ci]) ** 2, 0.0)
            th[ci], thd[ci] = 0.0, np.where(settle, 0.0, v_after)
            side[ci] = new_side
            resting[ci] = resting[ci] | settle
            tau0[ci] = np.where(settle, np.minimum(t_imp + t_zeno, dt), t_imp)
        else:  # passes exhausted (never seen): the remaining bouncers are at rest
            bouncing = active & ~resting
            resting[bouncing], th[bouncing], thd[bouncing] = True, 0.0, 0.0
        live = ~over & ~resting
        max_th = np.where(live, np.maximum(max_th, np.abs(th)), max_th)
        max_thd = np.where(live, np.maximum(max_thd, np.abs(thd)), max_thd)
        energy = 0.5 * (thd / p) ** 2 + 1.0 - 0.5 * (alpha - np.abs(th)) ** 2 - v0
        max_e = np.where(live, np.maximum(max_e, energy), max_e)
        over = over | (live & (np.abs(th) >= OVERTURN_ANGLE))
    # decision for the blocks still rocking when the simulation ends (free rocking after the record)
    if t_end >= record.duration:
        live = ~over & ~resting
        E = 0.5 * (thd / p) ** 2 + 1.0 - 0.5 * (alpha - np.abs(th)) ** 2
        outward = (side * thd > 0.0) | ((thd == 0.0) & (np.abs(th) > alpha))
        beyond = np.abs(th) > alpha
        e_after = v0 + eta**2 * (E - v0)
        falls = np.where(beyond, outward | (E < 1.0), np.where(outward, E > 1.0, e_after > 1.0))
        over = over | (live & falls)
    return PeakResponses(max_th, max_thd, max_e, diss, over)
