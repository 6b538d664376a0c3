"""Two stacked rigid blocks rocking on a rigid base: the 2-DOF model of Spanos, Roussis & Politis.

A bottom block (full width ``2 b1``, height ``2 h1``) stands on a horizontally (and
optionally vertically) shaken base; a top block (``2 b2`` x ``2 h2``, ``b2 + |e| <= b1``)
stands on it, its centre offset by ``e`` from the bottom block's axis. Friction is
taken high enough that nothing slides and impacts are plastic (no bounce): each
interface is either *closed* (flat on the face below) or *rocking* about one corner.
The four rocking patterns of Spanos, Roussis & Politis (2001), by which seed
``003_e23e844b706a29bc.txt`` (Fig. 9) classifies its stacked-block tests, are the
states of the two interfaces:

==========  =================  ==================  =========================================
pattern     base interface     joint interface     motion
==========  =================  ==================  =========================================
1           rocking            rocking             both blocks rock, absolute angles same sign
2           rocking            rocking             both blocks rock, absolute angles opposite
3           rocking            closed              the stack rocks as one body
4           closed             rocking             the top block rocks alone
rest        closed             closed
==========  =================  ==================  =========================================

The derivation, with its sign conventions and impact maps:

Coordinates and signs. The engine's: x right, y up, angles counter-clockwise
positive. ``phi1`` is the absolute rotation of the bottom block, ``phi2`` that of the
top block, ``delta = phi2 - phi1`` the top block's rotation relative to the bottom.
A block with a positive angle pivots about its *left* corner (a positive base
acceleration a_g, +x, tips the blocks to positive angles). ``k1 = sgn(phi1)`` and
``k2 = sgn(delta)`` are the pivot sides, 0 for a closed interface. In the base frame
(origin at the base surface under the bottom block's axis) the bodies feel gravity
plus the inertial force of the base, ``g_eff = (-a_g, -(g + a_v))`` per unit mass.

Kinematics. With ``R(phi)`` the rotation and, in body coordinates,
``u1 = (k1 b1, h1)`` (pivot -> bottom centroid), ``w = (e - k2 b2 + k1 b1, 2 h1)``
(bottom pivot -> top pivot) and ``u2 = (k2 b2, h2)`` (top pivot -> top centroid)::

    c1 = o1 + R(phi1) u1,    c2 = o1 + R(phi1) w + R(phi2) u2,    o1 = (-k1 b1, 0).

Equations of motion (virtual work, ``sum m_i J_i^T (c_i'' - g_eff) + I q'' = 0``),
``M q'' + C = Q`` with, writing ``a x b = a_x b_y - a_y b_x``,
``X = w x R(delta) u2``::

    M11 = I1 + m1 |u1|^2 + m2 |w|^2,   M22 = I2 + m2 |u2|^2,   M12 = m2 w . R(delta) u2,
    C1 = -m2 phi2'^2 X,                C2 = m2 phi1'^2 X,
    Q1 = (R(phi1) u1) x m1 g_eff + (R(phi1) w) x m2 g_eff,     Q2 = (R(phi2) u2) x m2 g_eff.

A closed interface is the constraint ``phi1 = 0`` (pattern 4) or ``delta = 0``
(pattern 3), imposed by reducing ``q = S x``. It opens on the side ``s`` when the
corner opposite the pivot ``s`` would have to pull: equivalently, when freeing that
interface about ``s`` gives ``s * (its angular acceleration) > 0`` (the release test,
the stacked form of Housner's uplift condition ``|a_g| > g tan(alpha)``).

Impacts (an interface closing, its angle reaching 0): the impacting corner becomes
the new pivot, the old pivot lifts, and angular momentum is conserved about the
points through which all impulses on a sub-system pass:

* the whole stack about the base pivot (when the base interface rocks after impact),
* the top block about its pivot on the bottom block (when the joint rocks after impact).

Both are linear in the velocities: ``L_post S x+ = L_pre q'-``. An interface whose
new pivot gets a velocity of the wrong sign (it would close again at once) closes
(``k = 0``); a closed interface that the impulse would open (impulsive release test)
opens. For a single rectangular block this map is Housner's ``1 - 1.5 sin^2 alpha``.

Integration is event driven like :mod:`nscd.rocking`: scipy's DOP853 method, compiled, on the
compiled equations of :mod:`nscd._equations` (:func:`nscd._ode.fly`), between events (an
impact, a closed interface opening, an overturn); a
stack at rest waits until the release test of some interface is met (found by a scan
and root finding), then enters the one consistent pattern.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from itertools import product

import numpy as np
from scipy.optimize import brentq

from nscd._equations import (STACK, stack_accelerations, stack_contact_forces, stack_history, stack_impact,
                              stack_impulses, stack_positions, stack_release, stack_release_margin, stack_rest_margins,
                              stack_terms)
from nscd._ode import Crossing, Flight, fly, inner_output_times
from nscd.motion import STANDARD_GRAVITY, Motion, ground_accelerations
from nscd.rocking import OVERTURN_ANGLE, _acceleration_at, _scan_step

__all__ = ["StackedBlocks", "StackedResult", "PATTERNS", "classify_patterns"]

#: Pattern names by (base interface rocking, joint interface rocking) and, when both rock,
#: the sign of phi1 * phi2 (Spanos, Roussis & Politis 2001; seed 003 Fig. 9).
PATTERNS = ("rest", "pattern 1 (same way)", "pattern 2 (opposite ways)", "pattern 3 (one body)",
            "pattern 4 (top alone)")

#: The patterns a state of pattern (k1, k2) may enter, fewest openings of closed interfaces first
#: (``_StackSimulation._choose``).
_CANDIDATES = {(k1, k2): sorted(product((0, 1, -1) if k1 == 0 else (k1,), (0, 1, -1) if k2 == 0 else (k2,)),
                                key=lambda c, k1=k1, k2=k2: (c[0] != k1) + (c[1] != k2))
               for k1, k2 in product((-1, 0, 1), repeat=2)}

_REST = (0.0, 0.0, 0.0, 0.0)  # (phi1, phi2, phi1', phi2') of the stack at rest
_RTOL, _ATOL = 1e-9, 1e-12
_XTOL = 1e-14  # s, root-finding tolerance on the onset time
_ONSET_EPS = 1e-9  # release when s * acceleration exceeds this times p^2 (round-off guard)
_MAX_EVENTS = 200_000


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} == {value}, must be a finite number > 0.")
    return value


@dataclass(frozen=True)
class StackedBlocks:
    """Two rectangular rigid blocks, one on the other, on a rigid base (2D, unit depth or real masses).

    Parameters
    ----------
    bottom, top : (width, height)
        Full sides in m of the bottom and top block, > 0; the top's base must lie on
        the bottom's top face: ``top width / 2 + |offset| <= bottom width / 2``.
    bottom_mass, top_mass : float
        Masses in kg (> 0). Only their ratio and the inertias matter for the motion.
    bottom_inertia, top_inertia : float or None
        Centroidal moments of inertia in kg m^2; None: uniform rectangle ``m (w^2 + h^2) / 12``.
    offset : float
        Horizontal offset in m of the top block's axis from the bottom block's (+x right).
    g : float
        Gravity in m/s^2.
    """

    bottom: tuple[float, float]
    top: tuple[float, float]
    bottom_mass: float = 1.0
    top_mass: float = 1.0
    bottom_inertia: float | None = None
    top_inertia: float | None = None
    offset: float = 0.0
    g: float = STANDARD_GRAVITY

    def __post_init__(self):
        (w1, h1), (w2, h2) = self.bottom, self.top
        for name, value in (("bottom width", w1), ("bottom height", h1), ("top width", w2),
                            ("top height", h2), ("bottom_mass", self.bottom_mass),
                            ("top_mass", self.top_mass), ("g", self.g)):
            _check_positive(name, value)
        if not math.isfinite(self.offset) or w2 / 2 + abs(self.offset) > w1 / 2 * (1 + 1e-12):
            raise ValueError(f"offset == {self.offset} with top width {w2}: the top block's base must lie on "
                             f"the bottom block's top face (|offset| + {w2 / 2:g} <= {w1 / 2:g} m).")
        for name, inertia, m, (w, h) in (("bottom_inertia", self.bottom_inertia, self.bottom_mass, self.bottom),
                                          ("top_inertia", self.top_inertia, self.top_mass, self.top)):
            if inertia is None:
                object.__setattr__(self, name, m * (w * w + h * h) / 12.0)
            else:
                _check_positive(name, inertia)

    # ------------------------------------------------------------------ geometry
    @property
    def b1(self) -> float:
        """Half width of the bottom block, m."""
        return 0.5 * self.bottom[0]

    @property
    def h1(self) -> float:
        """Half height of the bottom block, m."""
        return 0.5 * self.bottom[1]

    @property
    def b2(self) -> float:
        """Half width of the top block, m."""
        return 0.5 * self.top[0]

    @property
    def h2(self) -> float:
        """Half height of the top block, m."""
        return 0.5 * self.top[1]

    @property
    def p(self) -> float:
        """Frequency parameter of the stack rocking as one body, rad/s: sqrt(M g d / I_O).

        ``d`` is the distance from a base corner to the stack's centre of mass and
        ``I_O`` the stack's moment of inertia about that corner (pivot on the +x side
        for an offset top block). Sets the scale of the rest tolerance.
        """
        m1, m2 = self.bottom_mass, self.top_mass
        xc = m2 * self.offset / (m1 + m2)
        yc = (m1 * self.h1 + m2 * (2 * self.h1 + self.h2)) / (m1 + m2)
        i_o = (self.bottom_inertia + self.top_inertia + m1 * (self.b1 ** 2 + self.h1 ** 2)
               + m2 * ((self.b1 - self.offset) ** 2 + (2 * self.h1 + self.h2) ** 2))
        return math.sqrt((m1 + m2) * self.g * math.hypot(self.b1 - xc, yc) / i_o)

    def onset_accelerations(self) -> dict[str, tuple[float, float]]:
        """Static onset accelerations (m/s^2) of the patterns that can start from rest.

        From statics (the base moving with constant acceleration a_g, no vertical):

        * one body (pattern 3) about the left (a_g > 0) or right (a_g < 0) base corner:
          ``|a_g| = g x_lever / y_G`` with ``x_lever`` the horizontal distance from the corner
          to the stack's centre of mass and ``y_G`` its height;
        * top alone (pattern 4) about a corner of the joint: ``|a_g| = g b2 / h2``.

        The stack at rest under a slowly growing acceleration enters the pattern whose
        onset is the lowest (patterns 1 and 2 cannot start from rest quasi-statically).

        Returns
        -------
        dict
            ``{"one body": (a_plus, a_minus), "top alone": (a_plus, a_minus)}``: the
            positive acceleration that tips toward positive angles and the (negative) one
            that tips toward negative angles.
        """
        m1, m2, g, e = self.bottom_mass, self.top_mass, self.g, self.offset
        y_g = m1 * self.h1 + m2 * (2 * self.h1 + self.h2)
        plus = g * (m1 * self.b1 + m2 * (self.b1 + e)) / y_g
        minus = -g * (m1 * self.b1 + m2 * (self.b1 - e)) / y_g
        top = g * self.b2 / self.h2
        return {"one body": (plus, minus), "top alone": (top, -top)}

    # ------------------------------------------------------------------ mechanics
    @cached_property
    def _constants(self) -> np.ndarray:
        """The stack's ``par`` of :mod:`nscd._equations` (layout in that module's docstring), pattern (0, 0)."""
        return np.array([self.bottom_mass, self.top_mass, self.bottom_inertia, self.top_inertia, self.g,
                         self.b1, self.h1, self.b2, self.h2, self.offset, 0.0, 0.0])

    def _pattern_constants(self, k1: int, k2: int) -> np.ndarray:
        """``par`` of pattern (k1, k2): one array per pattern, kept (not to be written)."""
        return self._patterns[k1, k2]

    @cached_property
    def _patterns(self) -> dict[tuple[int, int], np.ndarray]:
        patterns = {}
        for k1, k2 in product((-1, 0, 1), repeat=2):
            par = self._constants.copy()
            par[10], par[11] = k1, k2  # the pivot sides' entries of the layout
            patterns[k1, k2] = par
        return patterns

    def positions(self, phi1: float, phi2: float, k1: int, k2: int) -> tuple[tuple, tuple]:
        """Centroids c1, c2 in m in the base frame for angles (rad) and pivot sides."""
        c1x, c1y, c2x, c2y = stack_positions(self._constants, float(phi1), float(phi2), int(k1), int(k2))
        return (c1x, c1y), (c2x, c2y)

    def _full(self, phi1, phi2, dphi1, dphi2, k1, k2, ag, av):
        """M (3 entries), C, Q of the 2-DOF equations for pivot sides k1, k2 (module docstring)."""
        return stack_terms(self._constants, float(phi1), float(phi2), float(dphi1), float(dphi2), int(k1), int(k2),
                           float(ag), float(av))

    def accelerations(self, phi1, phi2, dphi1, dphi2, k1, k2, ag, av=0.0) -> tuple[float, float]:
        """Angular accelerations (phi1'', phi2'') in rad/s^2 in the pattern (k1, k2).

        ``k1 = 0`` holds the bottom block on the base (phi1'' = 0); ``k2 = 0`` holds the top
        block on the bottom one (phi2'' = phi1''). ``ag``, ``av``: base accelerations, m/s^2.
        The compiled :func:`nscd._equations.stack_accelerations`.
        """
        return stack_accelerations(self._constants, float(phi1), float(phi2), float(dphi1), float(dphi2),
                                   int(k1), int(k2), float(ag), float(av))

    def release(self, phi1, phi2, dphi1, dphi2, k1, k2, ag, av=0.0) -> list[tuple[int, int, float]]:
        """Release tests of the closed interfaces of pattern (k1, k2).

        Returns
        -------
        list of (interface, side, margin)
            ``interface`` 0 (base) or 1 (joint), ``side`` +1/-1 the pivot it would open
            about, ``margin = side * (its angular acceleration if freed)`` in rad/s^2:
            > 0 means the closed interface would have to pull at the opposite corner, so it opens.
        """
        tests = np.empty((4, 3))
        n = stack_release(self._constants, float(phi1), float(phi2), float(dphi1), float(dphi2), int(k1), int(k2),
                          float(ag), float(av), tests)
        return [(int(i), int(side), float(margin)) for i, side, margin in tests[:n]]

    def kinetic_energy(self, phi1, phi2, dphi1, dphi2, k1, k2) -> float:
        """Kinetic energy in J (relative to the base) of the stack in pattern (k1, k2)."""
        m11, m12, m22, *_ = self._full(phi1, phi2, dphi1, dphi2, k1, k2, 0.0, 0.0)
        return 0.5 * (m11 * dphi1 ** 2 + 2.0 * m12 * dphi1 * dphi2 + m22 * dphi2 ** 2)

    def impact(self, phi1, phi2, dphi1, dphi2, pre: tuple[int, int], post: tuple[int, int]) -> tuple[float, float]:
        """Velocities (phi1'+, phi2'+) in rad/s just after an impact from pattern ``pre`` into ``post``.

        Angular momentum is conserved about the post-impact pivots (module docstring):
        the stack about the base pivot if the base interface rocks after the impact, the
        top block about its pivot if the joint rocks. Pattern (0, 0) stops the stack.
        The compiled :func:`nscd._equations.stack_impact`.
        """
        return stack_impact(self._constants, float(phi1), float(phi2), float(dphi1), float(dphi2),
                            int(pre[0]), int(pre[1]), int(post[0]), int(post[1]))

    def contact_forces(self, phi1, phi2, dphi1, dphi2, ddphi1, ddphi2, k1, k2, ag, av=0.0):
        """Contact forces (N) from the motion: on the bottom block from the base, on the top from the bottom.

        Returns
        -------
        (t_base, n_base, t_joint, n_joint) : floats
            Tangential and normal components; the base's frame is (x, y), the joint's
            the bottom block's own axes (its top face). Newton for each body:
            ``F = m (c'' - g_eff)`` (relative accelerations, ``g_eff = (-a_g, -(g + a_v))``).
        """
        return stack_contact_forces(self._constants, float(phi1), float(phi2), float(dphi1), float(dphi2),
                                    float(ddphi1), float(ddphi2), int(k1), int(k2), float(ag), float(av))

    # ------------------------------------------------------------------ simulation
    def simulate(self, motion: Motion | None = None, t_end: float = 10.0, *, vertical: Motion | None = None,
                 phi0: tuple[float, float] = (0.0, 0.0), phi_dot0: tuple[float, float] = (0.0, 0.0),
                 dt_out: float | None = None, min_flight: float = 1e-3) -> "StackedResult":
        """Rocking history of the stack under a base motion (or free, from an initial state).

        Parameters
        ----------
        motion : Motion or None
            Horizontal base acceleration along +x (m/s^2). None: free rocking.
        t_end : float
            End time in s, > 0.
        vertical : Motion, optional
            Vertical base acceleration (up positive); must stay above -g.
        phi0, phi_dot0 : (float, float)
            Initial absolute angles (rad, CCW positive) and angular velocities (rad/s)
            of the bottom and top block. An interface with zero relative angle and
            rate starts closed.
        dt_out : float, optional
            Output sampling step in s (default t_end / 2000); event times always included.
        min_flight : float
            s. A bounce (an interface reopening on its other corner after an impact, or
            kicked open by the impulse) whose flight would end within this time is
            absorbed: the interface stays closed and opens again only by its release
            test, from zero relative velocity. Ends Zeno sequences; the default 1 ms is
            the time step at which the engine is run against this model.

        Returns
        -------
        StackedResult
        """
        _check_positive("t_end", t_end)
        if not (math.isfinite(min_flight) and min_flight >= 0.0):
            raise ValueError(f"min_flight == {min_flight}, must be >= 0 s.")
        if dt_out is not None:
            _check_positive("dt_out", dt_out)
        phi1, phi2 = (float(x) for x in phi0)
        d1, d2 = (float(x) for x in phi_dot0)
        if abs(phi1) >= OVERTURN_ANGLE or abs(phi2 - phi1) >= OVERTURN_ANGLE:
            raise ValueError(f"phi0 == {phi0}: |phi1| and |phi2 - phi1| must be below pi/2.")
        if vertical is not None:
            ts = np.linspace(0.0, min(t_end, vertical.duration), 4001)
            if np.any(np.asarray(vertical.acceleration(ts)) <= -self.g):
                raise ValueError("vertical acceleration reaches -g: the stack would lift off the base.")
        return _StackSimulation(self, motion, vertical, float(t_end), dt_out or t_end / 2000.0,
                                min_flight).run(phi1, phi2, d1, d2)


# --------------------------------------------------------------------------- results
@dataclass(frozen=True)
class StackedResult:
    """History and outcome of :meth:`StackedBlocks.simulate`.

    Attributes
    ----------
    time : ndarray, shape (n,)
        s; an event time appears twice (before and after the jump).
    phi : ndarray, shape (n, 2)
        Absolute angles of the bottom and top block, rad, CCW positive.
    phi_dot : ndarray, shape (n, 2)
        Angular velocities, rad/s.
    sides : ndarray of int, shape (n, 2)
        Pivot sides (k1, k2) of the base and joint interfaces: +1 left corner, -1 right, 0 closed.
    impacts : dict of ndarray
        ``time`` (s), ``interface`` (0 base, 1 joint), ``before``/``after`` ((k, 2) rad/s),
        ``impulse_base``/``impulse_joint`` ((k, 2) N s: tangential, normal, in each
        interface's frame, on the upper body).
    overturned : bool
        A block reached pi/2 (bottom: ``|phi1|``; top: ``|phi2 - phi1|`` or ``|phi2|``).
    overturn_time : float
        s (nan if not overturned).
    stack : StackedBlocks
    """

    time: np.ndarray
    phi: np.ndarray
    phi_dot: np.ndarray
    sides: np.ndarray
    impacts: dict
    overturned: bool
    overturn_time: float
    stack: StackedBlocks
    ground: tuple = field(default=(None, None), repr=False)

    @property
    def max_abs_phi(self) -> np.ndarray:
        """``max |phi|`` of each block over the history, rad, shape (2,)."""
        return np.max(np.abs(self.phi), axis=0) if len(self.time) else np.zeros(2)

    def pattern_times(self) -> dict[str, float]:
        """Time in s spent in each pattern of :data:`PATTERNS` (from the pivot sides)."""
        return _pattern_times(self.time, self.sides[:, 0] != 0, self.sides[:, 1] != 0, self.phi)

    @property
    def pattern(self) -> str:
        """The pattern the stack spent the most time in other than rest ("rest" if it never moved)."""
        return _dominant(self.pattern_times())

    @cached_property
    def _history(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Accelerations, contact forces and centroids at the samples, computed once (the methods return copies)."""
        motion, vertical = self.ground
        ag = np.zeros(len(self.time)) if motion is None else np.asarray(motion.acceleration(self.time), float)
        av = np.zeros(len(self.time)) if vertical is None else np.asarray(vertical.acceleration(self.time), float)
        return stack_history(self.stack._constants, np.ascontiguousarray(self.phi), np.ascontiguousarray(self.phi_dot),
                             np.ascontiguousarray(self.sides, dtype=np.int64), ag, av)

    def accelerations(self) -> np.ndarray:
        """Angular accelerations (n, 2) in rad/s^2 at the samples, from the equations of motion."""
        return self._history[0].copy()

    def contact_forces(self) -> np.ndarray:
        """Contact forces (n, 4) in N at the samples: base (tangential, normal), joint (tangential, normal).

        See :meth:`StackedBlocks.contact_forces`; per unit depth if the masses are.
        """
        return self._history[1].copy()

    def centroids(self) -> np.ndarray:
        """Centroids (n, 4) in m in the base frame at the samples: bottom (x, y), top (x, y)."""
        return self._history[2].copy()


def _pattern_times(time, base_rocks, joint_rocks, phi) -> dict[str, float]:
    dt = np.diff(time)
    both = base_rocks[:-1] & joint_rocks[:-1]
    same = (phi[:-1, 0] * phi[:-1, 1]) >= 0.0
    masks = {
        "rest": ~base_rocks[:-1] & ~joint_rocks[:-1],
        PATTERNS[1]: both & same,
        PATTERNS[2]: both & ~same,
        PATTERNS[3]: base_rocks[:-1] & ~joint_rocks[:-1],
        PATTERNS[4]: ~base_rocks[:-1] & joint_rocks[:-1],
    }
    return {name: float(np.sum(dt[mask])) for name, mask in masks.items()}


def _dominant(times: dict[str, float]) -> str:
    moving = {k: v for k, v in times.items() if k != "rest"}
    best = max(moving, key=moving.get)
    return best if moving[best] > 0.0 else "rest"


def classify_patterns(time: np.ndarray, phi_bottom: np.ndarray, phi_top: np.ndarray,
                      tol: float = 1e-3) -> dict[str, float]:
    """Time in s spent in each pattern of :data:`PATTERNS`, from sampled angle histories.

    The same reading for any model (the engine's histories, measurements): an
    interface rocks where its relative angle exceeds ``tol`` (rad): the base where
    ``|phi_bottom| > tol``, the joint where ``|phi_top - phi_bottom| > tol``.
    """
    phi_bottom, phi_top = np.asarray(phi_bottom, float), np.asarray(phi_top, float)
    phi = np.column_stack([phi_bottom, phi_top])
    return _pattern_times(np.asarray(time, float), np.abs(phi_bottom) > tol,
                          np.abs(phi_top - phi_bottom) > tol, phi)


def dominant_pattern(times: dict[str, float]) -> str:
    """The pattern with the most time other than rest ("rest" if none)."""
    return _dominant(times)


# --------------------------------------------------------------------------- the event loop
def _relative(y):
    """(phi1, phi2, phi1', phi2') -> (phi1, delta, phi1', delta'), along axis 0."""
    y = np.asarray(y, float)
    return np.array([y[0], y[1] - y[0], y[2], y[3] - y[2]])


def _absolute(z):
    """(phi1, delta, phi1', delta') -> (phi1, phi2, phi1', phi2'), along axis 0."""
    z = np.asarray(z, float)
    return np.array([z[0], z[0] + z[1], z[2], z[2] + z[3]])


class _StackSimulation:
    """Rest, onsets, flights, releases, impacts and overturning of one run."""

    def __init__(self, stack: StackedBlocks, motion, vertical, t_end, dt_out, min_flight):
        self.stack, self.motion, self.vertical = stack, motion, vertical
        self.t_end, self.dt_out, self.min_flight = t_end, dt_out, float(min_flight)
        self.acc_h, self.acc_v = _acceleration_at(motion), _acceleration_at(vertical)
        self.ground = ground_accelerations(motion, vertical)
        self.eps = _ONSET_EPS * stack.p ** 2
        self.first_step = None  # s, the last full step of the previous flight
        # the output, piece by piece (_record): its first and last times and states, pivot sides, whether the last
        # sample closes it, and whether its inside is a flight; the steps of all flights, in time order
        self.pieces = []
        self.flights = Flight(0.0, np.zeros(4), None, [], [], [], [], None)  # all flights' steps, one after another
        self.impacts = {"time": [], "interface": [], "before": [], "after": [],
                        "impulse_base": [], "impulse_joint": []}

    # -- pattern choice ------------------------------------------------------
    def _choose(self, t, y, k1, k2) -> tuple[int, int]:
        """The consistent pattern for a state whose closed interfaces may open (enumeration).

        A pattern is consistent when each interface it opens turns the way of its pivot
        (``s * acceleration >= eps / 2``) and no interface it keeps closed fails its release
        test (margin <= eps / 2; the release event fires at eps). Fewest openings first; if none is consistent (round-off at a
        switching instant), the one opening the interface with the largest release margin.
        """
        par = self.stack._constants
        ag, av = self.acc_h(t), self.acc_v(t)
        phi1, phi2, d1, d2 = map(float, y)
        half = 0.5 * self.eps
        for c1, c2 in _CANDIDATES[k1, k2]:
            a1, a2 = stack_accelerations(par, phi1, phi2, d1, d2, c1, c2, ag, av)
            if k1 == 0 and c1 and c1 * a1 < half:
                continue
            if k2 == 0 and c2 and c2 * (a2 - a1) < half:
                continue
            if stack_release_margin(par, phi1, phi2, d1, d2, c1, c2, ag, av) <= half:
                return c1, c2
        tests = self.stack.release(phi1, phi2, d1, d2, k1, k2, ag, av)
        interface, side, margin = max(tests, key=lambda x: x[2])
        return (side, k2) if interface == 0 else (k1, side)

    def _release_margin(self, t, y, k1, k2) -> float:
        """The largest release margin (rad/s^2) of pattern (k1, k2) at (t, y) less the threshold eps: > 0 opens.

        The release event of a flight and the onset search at rest.
        """
        return stack_release_margin(self.stack._constants, float(y[0]), float(y[1]), float(y[2]), float(y[3]),
                                    k1, k2, self.acc_h(t), self.acc_v(t)) - self.eps

    # -- rest ----------------------------------------------------------------
    def _next_onset(self, t0: float) -> float | None:
        """The first time >= t0 (s) at which the stack at rest passes a release test, or None.

        The rest margins (:func:`nscd._equations.stack_rest_margins`) are scanned on the samples
        ``linspace(t0, t_last, n)`` (spacing at most the scan step), in compiled windows that grow
        from t0 (an onset is usually near); the instant is located by Brent's method between the
        last sample below the threshold and the first above it.
        """
        motion, vertical = self.motion, self.vertical
        ends = [m.duration for m in (motion, vertical) if m is not None]
        if not ends:
            return None
        t_last = min(self.t_end, max(ends) + 1e-9)
        if t_last <= t0:
            return None
        n = max(2, int(math.ceil((t_last - t0) / _scan_step(motion, vertical))) + 1)
        spacing = (t_last - t0) / (n - 1)

        def sample(k: int) -> float:  # np.linspace(t0, t_last, n)[k]
            return t_last if k == n - 1 else k * spacing + t0
        start, size = 0, 64
        while start < n:
            stop = min(n, start + size)
            window = np.arange(start, stop) * spacing + t0
            if stop == n:
                window[-1] = t_last
            opens = np.flatnonzero(stack_rest_margins(self.stack._constants, *self.ground(window)) - self.eps > 0.0)
            if len(opens):
                k = start + int(opens[0])
                if k == 0:
                    return t0
                return brentq(lambda t: self._release_margin(t, _REST, 0, 0), sample(k - 1), sample(k), xtol=_XTOL,
                              rtol=4 * np.finfo(float).eps)
            start, size = stop, 2 * size
        return None

    # -- output --------------------------------------------------------------
    def _record(self, a, b, y_a, y_b, k1, k2, closes=True, flight=None):
        """A piece of the output in pattern (k1, k2): time ``a`` (s) with state ``y_a``, the output grid strictly
        inside (a, b), and time ``b`` with ``y_b`` if ``closes``. Inside: the flight's dense output, or rest."""
        self.pieces.append((a, b, y_a, y_b, k1, k2, closes, flight is not None))
        if flight is not None:
            self.flights.extend(flight)

    def _samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Times (n,), states (n, 4) and pivot sides (n, 2) of the pieces, in one pass over all of them."""
        if not self.pieces:
            return np.zeros(0), np.zeros((0, 4)), np.zeros((0, 2), dtype=int)
        a, b, y_a, y_b, k1, k2, closes, flies = (np.array(x) for x in zip(*self.pieces))
        grid, piece = inner_output_times(a, b, self.dt_out)  # the inner samples and the piece of each
        n_inside = np.bincount(piece, minlength=len(a))
        rows = 1 + n_inside + closes  # per piece: a, its inner samples, b if it closes
        start = np.cumsum(rows) - rows
        times, states = np.empty(rows.sum()), np.zeros((rows.sum(), 4))
        times[start], states[start] = a, y_a
        end = (start + rows - 1)[closes]
        times[end], states[end] = b[closes], y_b[closes]
        # an inner sample's row: its piece's first row + 1 + its rank among the piece's inner samples
        row = start[piece] + 1 + np.arange(len(grid)) - (np.cumsum(n_inside) - n_inside)[piece]
        times[row] = grid
        flying = flies[piece]
        if np.any(flying):  # each of these times inside a step of its flight
            states[row[flying]] = _absolute(self.flights.evaluate(grid[flying])).T
        sides = np.repeat(np.column_stack([k1, k2]), rows, axis=0)
        return times, states, sides

    # -- flights -------------------------------------------------------------
    def _fly(self, t0, y0, k1, k2):
        """Integrate pattern (k1, k2) from (t0, y0) to the next event; y = (phi1, phi2, phi1', phi2').

        The integrated state is (phi1, delta, phi1', delta'), so a closed joint stays exactly
        closed and an opening one starts from an exact zero.
        """
        events, names = [], []
        if k1:
            # an interface that just closed starts at zero angle: its impact test is off at t0 itself
            events.append((Crossing(0, float(k1), t0), -1))
            names.append("impact base")
            events.append((lambda t, z: abs(z[0]) - OVERTURN_ANGLE, 1))
            names.append("overturn")
        if k2:
            events.append((Crossing(1, float(k2), t0), -1))
            names.append("impact joint")
            events.append((lambda t, z: max(abs(z[1]), abs(z[0] + z[1])) - OVERTURN_ANGLE, 1))
            names.append("overturn")
        if k1 == 0 or k2 == 0:
            events.append((lambda t, z: self._release_margin(t, (z[0], z[0] + z[1], z[2], z[2] + z[3]), k1, k2), 1))
            names.append("release")
        try:
            flight = fly(STACK, self.stack._pattern_constants(k1, k2), self.ground, t0, _relative(y0), self.t_end,
                         events, _RTOL, _ATOL, self.first_step)
        except RuntimeError as err:
            raise RuntimeError(f"stacked rocking: {err}") from None
        self.first_step = flight.last_step or self.first_step
        t1, z1 = flight.t1, flight.y1
        event = "end" if flight.event is None else names[flight.event]
        y1 = _absolute(z1)
        self._record(t0, t1, np.array(y0, float), y1.copy(), k1, k2, flight=flight)
        return t1, y1, event

    # -- impacts -------------------------------------------------------------
    def _impact(self, t, y, k1, k2, interface):
        stack = self.stack
        before = (y[2], y[3])
        n1, n2 = (-k1, k2) if interface == 0 else (k1, -k2)
        if interface == 0:
            y[0] = 0.0
        else:
            y[1] = y[0]
        after = stack.impact(y[0], y[1], y[2], y[3], (k1, k2), (n1, n2))
        # the new pivot turns the wrong way, or the bounce is too short to matter: the interface closes
        if self._bounce_ends(t, y, after, (n1, n2), interface):
            closed = (0, n2) if interface == 0 else (n1, 0)
            n1, n2, after = closed[0], closed[1], stack.impact(y[0], y[1], y[2], y[3], (k1, k2), closed)
        # a closed interface kicked open by the impulse
        for other in (0, 1):
            if (n1, n2)[other] != 0 or other == interface:
                continue
            for s in (1, -1):
                trial = (s, n2) if other == 0 else (n1, s)
                v = stack.impact(y[0], y[1], y[2], y[3], (k1, k2), trial)
                if not self._bounce_ends(t, y, v, trial, other):
                    n1, n2, after = trial[0], trial[1], v
                    break
        self._log_impact(t, y, before, after, (k1, k2), (n1, n2), interface)
        y[2], y[3] = after
        return n1, n2

    def _bounce_ends(self, t, y, rates, sides, interface) -> bool:
        """Whether interface ``interface``, opening at relative rate from ``rates`` in pattern ``sides``, stays shut.

        It does when the rate turns the wrong way for its pivot, or when the flight it
        starts would close again within ``min_flight`` (s): ``2 |rate| / |restoring
        acceleration|`` at the start of the flight. Such bounces carry rotations of order
        ``rate * min_flight / 4`` and end Zeno sequences of ever shorter bounces (the
        stacked analogue of the Zeno collapse of :func:`nscd.rocking.linear_record_peaks`).
        """
        rate = rates[0] if interface == 0 else rates[1] - rates[0]
        side = sides[interface]
        if side * rate <= 0.0:
            return True
        a1, a2 = self.stack.accelerations(y[0], y[1], rates[0], rates[1], sides[0], sides[1],
                                          self.acc_h(t), self.acc_v(t))
        restoring = -side * (a1 if interface == 0 else a2 - a1)
        return restoring > 0.0 and 2.0 * abs(rate) < self.min_flight * restoring

    def _log_impact(self, t, y, before, after, pre, post, interface):
        pbx, pby, pjt, pjn = stack_impulses(self.stack._constants, float(y[0]), float(y[1]), float(before[0]),
                                            float(before[1]), int(pre[0]), int(pre[1]), float(after[0]),
                                            float(after[1]), int(post[0]), int(post[1]))
        imp = self.impacts
        imp["time"].append(t)
        imp["interface"].append(interface)
        imp["before"].append(before)
        imp["after"].append(after)
        imp["impulse_base"].append((pbx, pby))
        imp["impulse_joint"].append((pjt, pjn))

    # -- the loop ------------------------------------------------------------
    def run(self, phi1, phi2, d1, d2) -> StackedResult:
        y = np.array([phi1, phi2, d1, d2], float)
        k1 = int(np.sign(phi1)) if phi1 else int(np.sign(d1))
        delta, ddelta = phi2 - phi1, d2 - d1
        k2 = int(np.sign(delta)) if delta else int(np.sign(ddelta))
        t, overturned, overturn_time = 0.0, False, math.nan
        if k1 == 0 or k2 == 0:
            k1, k2 = self._choose(t, y, k1, k2)
        n_events = 0
        while t < self.t_end:
            n_events += 1
            if n_events > _MAX_EVENTS:
                raise RuntimeError(f"stacked rocking: more than {_MAX_EVENTS} events before t = {t:.6g} s.")
            if k1 == 0 and k2 == 0:
                onset = self._next_onset(t)
                t_next = self.t_end if onset is None else onset
                # at rest, sampled like a flight (the checks read the ground's demand)
                self._record(t, t_next, np.zeros(4), np.zeros(4), 0, 0, closes=t_next > t)
                if onset is None:
                    break
                t, y = onset, np.zeros(4)
                k1, k2 = self._choose(t, y, 0, 0)
                if (k1, k2) == (0, 0):  # the margin touched zero only: look again a scan step later
                    t = min(self.t_end, t + _scan_step(self.motion, self.vertical))
                continue
            t, y, event = self._fly(t, y, k1, k2)
            if event == "end":
                break
            if event == "overturn":
                overturned, overturn_time = True, t
                break
            if event == "release":
                k1, k2 = self._choose(t, y, k1, k2)
                continue
            interface = 0 if event == "impact base" else 1
            k1, k2 = self._impact(t, y, k1, k2, interface)
            if k1 == 0:
                y[0], y[2] = 0.0, 0.0
            if k2 == 0:
                y[1], y[3] = y[0], y[2]
            if k1 == 0 or k2 == 0:
                k1, k2 = self._choose(t, y, k1, k2)
            after = y.copy()
            self._record(t, t, after, after, k1, k2, closes=False)
        times, states, sides = self._samples()
        imp = {k: np.array(v, dtype=int if k == "interface" else float) for k, v in self.impacts.items()}
        for k in ("before", "after", "impulse_base", "impulse_joint"):
            imp[k] = imp[k].reshape(-1, 2)
        return StackedResult(times, states[:, :2], states[:, 2:], sides,
                             imp, overturned, overturn_time, self.stack, (self.motion, self.vertical))
