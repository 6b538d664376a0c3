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
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from itertools import product

import numpy as np
from scipy.optimize import brentq

from nscd._equations import (STACK, stack_accelerations, stack_contact_forces, stack_history, stack_lever_arms,
                              stack_positions, stack_release, stack_rest_margins, stack_terms)
from nscd._ode import Crossing, fly
from nscd.motion import STANDARD_GRAVITY, Motion, ground_accelerations
from nscd.rocking import OVERTURN_ANGLE, _acceleration_at, _scan_step

__all__ = ["StackedBlocks", "StackedResult", "PATTERNS", "classify_patterns"]

#: Pattern names by (base interface rocking, joint interface rocking) and, when both rock,
#: the sign of phi1 * phi2 (Spanos, Roussis & Politis 2001; seed 003 Fig. 9).
PATTERNS = ("rest", "pattern 1 (same way)", "pattern 2 (opposite ways)", "pattern 3 (one body)",
            "pattern 4 (top alone)")

_RTOL, _ATOL = 1e-9, 1e-12
_XTOL = 1e-14  # s, root-finding tolerance on the onset time
_ONSET_EPS = 1e-9  # release when s * acceleration exceeds this times p^2 (round-off guard)
_MAX_EVENTS = 200_000


def _check_positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} == {value}, must be a finite number > 0.")
    return value


def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


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
    def _vectors(self, k1: int, k2: int) -> tuple[float, float, float, float, float, float]:
        """u1, w, u2 (body coordinates, see module docstring) for pivot sides k1, k2 (0 -> +1)."""
        return self._lever_arms[k1, k2]

    @cached_property
    def _lever_arms(self) -> dict[tuple[int, int], tuple[float, ...]]:
        return {(k1, k2): stack_lever_arms(self._constants, k1, k2) for k1, k2 in product((-1, 0, 1), repeat=2)}

    @cached_property
    def _constants(self) -> np.ndarray:
        """The stack's ``par`` of :mod:`nscd._equations` (layout :data:`nscd._equations.STACK_PAR`), pattern (0, 0)."""
        return np.array([self.bottom_mass, self.top_mass, self.bottom_inertia, self.top_inertia, self.g,
                         self.b1, self.h1, self.b2, self.h2, self.offset, 0.0, 0.0])

    def _pattern_constants(self, k1: int, k2: int) -> np.ndarray:
        par = self._constants.copy()
        par[10], par[11] = k1, k2
        return par

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

    def _momentum_rows(self, phi1, phi2, k1, k2, rows):
        """Angular momentum coefficients (of phi1', phi2') about the rows' points, velocities in pattern (k1, k2).

        ``rows``: list of (point (x, y), bodies) with bodies "stack" or "top".
        """
        m1, m2 = self.bottom_mass, self.top_mass
        u1x, u1y, wx, wy, u2x, u2y = self._vectors(k1, k2)
        (c1x, c1y), (c2x, c2y) = self.positions(phi1, phi2, k1, k2)
        c, s = math.cos(phi1), math.sin(phi1)
        cc, ss = math.cos(phi2), math.sin(phi2)
        # velocity of each centroid per unit phi1' and phi2': R E u = E R u = (-(R u)_y, (R u)_x)
        v1 = (-(s * u1x + c * u1y), c * u1x - s * u1y)
        v2a = (-(s * wx + c * wy), c * wx - s * wy)
        v2b = (-(ss * u2x + cc * u2y), cc * u2x - ss * u2y)
        out = []
        for (px, py), bodies in rows:
            top1 = m2 * _cross(c2x - px, c2y - py, *v2a)
            top2 = m2 * _cross(c2x - px, c2y - py, *v2b) + self.top_inertia
            if bodies == "stack":
                out.append((self.bottom_inertia + m1 * _cross(c1x - px, c1y - py, *v1) + top1, top2))
            else:
                out.append((top1, top2))
        return out

    def _impact_rows(self, phi1, phi2, k1, k2):
        """Conservation laws of the impact for post-impact pattern (k1, k2): (point, bodies) per free DOF."""
        rows = []
        if k1:
            rows.append(((-k1 * self.b1, 0.0), "stack"))
        if k2:
            u1x, u1y, wx, wy, *_ = self._vectors(k1, k2)
            c, s = math.cos(phi1), math.sin(phi1)
            ox = -(k1 or 1) * self.b1
            rows.append(((ox + c * wx - s * wy, s * wx + c * wy), "top"))
        return rows

    def impact(self, phi1, phi2, dphi1, dphi2, pre: tuple[int, int], post: tuple[int, int]) -> tuple[float, float]:
        """Velocities (phi1'+, phi2'+) in rad/s just after an impact from pattern ``pre`` into ``post``.

        Angular momentum is conserved about the post-impact pivots (module docstring):
        the stack about the base pivot if the base interface rocks after the impact, the
        top block about its pivot if the joint rocks. Pattern (0, 0) stops the stack.
        """
        k1, k2 = post
        rows = self._impact_rows(phi1, phi2, k1, k2)
        if not rows:
            return 0.0, 0.0
        after = self._momentum_rows(phi1, phi2, k1, k2, rows)
        before = self._momentum_rows(phi1, phi2, pre[0], pre[1], rows)
        rhs = [a * dphi1 + b * dphi2 for a, b in before]
        if k1 and k2:
            (a11, a12), (a21, a22) = after
            det = a11 * a22 - a12 * a21
            x1 = (a22 * rhs[0] - a12 * rhs[1]) / det
            x2 = (a11 * rhs[1] - a21 * rhs[0]) / det
            return x1, x2
        (a1, a2), = after
        if k1:
            x = rhs[0] / (a1 + a2)
            return x, x
        return 0.0, rhs[0] / a2

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

    def _history(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        motion, vertical = self.ground
        ag = np.zeros(len(self.time)) if motion is None else np.asarray(motion.acceleration(self.time), float)
        av = np.zeros(len(self.time)) if vertical is None else np.asarray(vertical.acceleration(self.time), float)
        return stack_history(self.stack._constants, np.ascontiguousarray(self.phi), np.ascontiguousarray(self.phi_dot),
                             np.ascontiguousarray(self.sides, dtype=np.int64), ag, av)

    def accelerations(self) -> np.ndarray:
        """Angular accelerations (n, 2) in rad/s^2 at the samples, from the equations of motion."""
        return self._history()[0]

    def contact_forces(self) -> np.ndarray:
        """Contact forces (n, 4) in N at the samples: base (tangential, normal), joint (tangential, normal).

        See :meth:`StackedBlocks.contact_forces`; per unit depth if the masses are.
        """
        return self._history()[1]

    def centroids(self) -> np.ndarray:
        """Centroids (n, 4) in m in the base frame at the samples: bottom (x, y), top (x, y)."""
        return self._history()[2]


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
        self.tests = np.empty((4, 3))  # rows of release tests (nscd._equations.stack_release)
        self.times, self.states, self.sides = [], [], []
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
        stack = self.stack
        ag, av = self.acc_h(t), self.acc_v(t)
        open1 = (0, 1, -1) if k1 == 0 else (k1,)
        open2 = (0, 1, -1) if k2 == 0 else (k2,)
        d1, d2 = y[2], y[3]
        for c1, c2 in sorted(product(open1, open2), key=lambda c: (c[0] != k1) + (c[1] != k2)):
            a1, a2 = stack.accelerations(y[0], y[1], d1, d2, c1, c2, ag, av)
            ok = not (k1 == 0 and c1 and c1 * a1 < 0.5 * self.eps)
            ok = ok and not (k2 == 0 and c2 and c2 * (a2 - a1) < 0.5 * self.eps)
            ok = ok and all(m <= 0.5 * self.eps for _, _, m in stack.release(y[0], y[1], d1, d2, c1, c2, ag, av))
            if ok:
                return c1, c2
        tests = stack.release(y[0], y[1], d1, d2, k1, k2, ag, av)
        interface, side, margin = max(tests, key=lambda x: x[2])
        return (side, k2) if interface == 0 else (k1, side)

    def _release_margin(self, t, y, k1, k2) -> float:
        if k1 and k2:
            return -math.inf
        n = stack_release(self.stack._constants, float(y[0]), float(y[1]), float(y[2]), float(y[3]), k1, k2,
                          self.acc_h(t), self.acc_v(t), self.tests)
        return float(np.max(self.tests[:n, 2])) - self.eps

    # -- rest ----------------------------------------------------------------
    def _next_onset(self, t0: float) -> float | None:
        motion, vertical = self.motion, self.vertical
        ends = [m.duration for m in (motion, vertical) if m is not None]
        if not ends:
            return None
        t_last = min(self.t_end, max(ends) + 1e-9)
        if t_last <= t0:
            return None
        step = _scan_step(motion, vertical)
        y = (0.0, 0.0, 0.0, 0.0)
        f = lambda t: self._release_margin(t, y, 0, 0)  # noqa: E731
        n = max(2, int(math.ceil((t_last - t0) / step)) + 1)
        ts = np.linspace(t0, t_last, n)
        start, size = 0, 64
        while start < n:  # scan in growing windows: an onset is usually near
            window = ts[start:start + size]
            opens = np.flatnonzero(stack_rest_margins(self.stack._constants, *self.ground(window)) - self.eps > 0.0)
            if len(opens):
                k = start + int(opens[0])
                if k == 0:
                    return t0
                return brentq(f, ts[k - 1], ts[k], xtol=_XTOL, rtol=4 * np.finfo(float).eps)
            start, size = start + size, 2 * size
        return None

    # -- output --------------------------------------------------------------
    def _record(self, ts, ys, k1, k2):
        self.times.append(ts)
        self.states.append(ys)
        self.sides.append((len(ts), k1, k2))

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
            events.append((lambda t, z: self._release_margin(t, _absolute(z), k1, k2), 1))
            names.append("release")
        try:
            flight = fly(STACK, self.stack._pattern_constants(k1, k2), self.ground, t0, _relative(y0), self.t_end,
                         events, _RTOL, _ATOL, self.first_step)
        except RuntimeError as err:
            raise RuntimeError(f"stacked rocking: {err}") from None
        self.first_step = flight.last_step or self.first_step
        t1, z1 = flight.t1, flight.y1
        event = "end" if flight.event is None else names[flight.event]
        grid = np.arange(math.floor(t0 / self.dt_out) + 1, math.ceil(t1 / self.dt_out)) * self.dt_out
        grid = grid[(grid > t0) & (grid < t1)]
        zs = flight.evaluate(grid).reshape(4, -1)
        self._record(np.concatenate(([t0], grid, [t1])),
                     np.vstack([np.asarray(y0, float)[None, :], _absolute(zs).T,
                                _absolute(np.asarray(z1, float))[None, :]]), k1, k2)
        return t1, _absolute(np.array(z1, float)), event

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
        stack = self.stack
        m1, m2 = stack.bottom_mass, stack.top_mass

        def velocities(rates, sides):
            u1x, u1y, wx, wy, u2x, u2y = stack._vectors(*sides)
            c, s = math.cos(y[0]), math.sin(y[0])
            cc, ss = math.cos(y[1]), math.sin(y[1])
            v1 = (-(s * u1x + c * u1y) * rates[0], (c * u1x - s * u1y) * rates[0])
            v2 = (-(s * wx + c * wy) * rates[0] - (ss * u2x + cc * u2y) * rates[1],
                  (c * wx - s * wy) * rates[0] + (cc * u2x - ss * u2y) * rates[1])
            return v1, v2
        (v1a, v2a), (v1b, v2b) = velocities(before, pre), velocities(after, post)
        pj = (m2 * (v2b[0] - v2a[0]), m2 * (v2b[1] - v2a[1]))
        pb = (m1 * (v1b[0] - v1a[0]) + pj[0], m1 * (v1b[1] - v1a[1]) + pj[1])
        c, s = math.cos(y[0]), math.sin(y[0])
        imp = self.impacts
        imp["time"].append(t)
        imp["interface"].append(interface)
        imp["before"].append(before)
        imp["after"].append(after)
        imp["impulse_base"].append(pb)
        imp["impulse_joint"].append((c * pj[0] + s * pj[1], -s * pj[0] + c * pj[1]))

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
                grid = np.arange(math.floor(t / self.dt_out) + 1, math.ceil(t_next / self.dt_out)) * self.dt_out
                rest = np.concatenate(([t], grid[(grid > t) & (grid < t_next)], [t_next])) if t_next > t else np.array([t])
                self._record(rest, np.zeros((len(rest), 4)), 0, 0)
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
            self._record(np.array([t]), y[None, :], k1, k2)
        times = np.concatenate(self.times) if self.times else np.zeros(0)
        states = np.vstack(self.states) if self.states else np.zeros((0, 4))
        imp = {k: np.array(v, dtype=int if k == "interface" else float) for k, v in self.impacts.items()}
        for k in ("before", "after", "impulse_base", "impulse_joint"):
            imp[k] = imp[k].reshape(-1, 2)
        sides = np.repeat(np.array([k for _, *k in self.sides], dtype=int).reshape(-1, 2),
                          [n for n, *_ in self.sides], axis=0)
        return StackedResult(times, states[:, :2], states[:, 2:], sides,
                             imp, overturned, overturn_time, self.stack, (self.motion, self.vertical))
