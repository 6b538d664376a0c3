"""Compiled equations of motion of the reduced models: the one source of their right-hand sides.

The 1-DOF Housner family (:mod:`nscd.rocking`: seed ``000_b03963299c8d30d2.txt`` eqs. 2-11,
4-9 and 4-37) and the 2-DOF stacked pair (:mod:`nscd.stacked`, derivation in its module
docstring). The models' Python methods and the compiled integrator (:mod:`nscd._ode`) both
call these kernels. Each model's constants travel in one float array ``par`` (built by
``nscd.rocking._constants`` and ``StackedBlocks._constants``); the state ``y`` and the ground
accelerations ``ag`` (horizontal) and ``av`` (vertical, up positive) are in SI units.

``par`` of the Housner block (12 entries):

== ============================================================================================
0  slenderness alpha (rad)
1  p^2 (1/s^2)
2  g (m/s^2)
3  1.0 for the linearised equation, else 0.0
4  the anchorage: 0 none, 1 elastic-brittle, 2 elasto-plastic (Bouc-Wen)
5  the restrainer's coefficient: 3 sigma sin^2(alpha) / q (elastic-brittle), 2 sigma sin(alpha) (Bouc-Wen)
6  Bouc-Wen gamma
7  Bouc-Wen beta
8  Bouc-Wen n
9  Bouc-Wen theta_y (rad)
10 the pivot side of the flight (+1 / -1)
11 1.0 while the anchorage is intact, else 0.0
== ============================================================================================

``par`` of the stacked pair (12 entries):

== ============================================================================================
0  m1, the bottom block's mass (kg)
1  m2, the top block's mass (kg)
2  I1, the bottom block's centroidal inertia (kg m^2)
3  I2, the top block's centroidal inertia (kg m^2)
4  g (m/s^2)
5  b1, the bottom block's half width (m)
6  h1, the bottom block's half height (m)
7  b2, the top block's half width (m)
8  h2, the top block's half height (m)
9  e, the top block's offset from the bottom block's axis (m)
10 k1, the base interface's pivot side of the flight (+1, -1, 0 closed)
11 k2, the joint's pivot side of the flight (+1, -1, 0 closed)
== ============================================================================================
"""
from __future__ import annotations

import math

import numpy as np

from nscd._jit import njit, njit_helper

HOUSNER, STACK = 0, 1
"""The models :func:`rhs` knows."""


# --------------------------------------------------------------------------- the Housner block
@njit
def housner_theta_ddot(par, side, theta, ag, av, z, intact):
    """theta'' in rad/s^2 on the pivot of ``side`` (000 eq. 2-11; restrainers eqs. 4-9, 4-37)."""
    alpha, p2, g, linear = par[0], par[1], par[2], par[3] != 0.0
    d = side * alpha - theta
    if linear:
        sin_d, cos_d = d, 1.0
    else:
        sin_d, cos_d = math.sin(d), math.cos(d)
    restoring = 0.0
    if intact:
        if par[4] == 1.0:      # elastic-brittle: k sin(theta) (k theta linearised)
            restoring = par[5] * (theta if linear else math.sin(theta))
        elif par[4] == 2.0:    # Bouc-Wen: 2 sigma sin(alpha) z cos(theta / 2)
            restoring = par[5] * z * (1.0 if linear else math.cos(0.5 * theta))
    return -p2 * (sin_d * (1.0 + av / g) + (ag / g) * cos_d + restoring)


@njit
def housner_theta_ddot_many(par, side, theta, ag, av, z, intact):
    """:func:`housner_theta_ddot` over arrays of equal length (side, theta, ag, av, z, intact)."""
    out = np.empty(len(theta))
    for i in range(len(theta)):
        out[i] = housner_theta_ddot(par, side[i], theta[i], ag[i], av[i], z[i], intact[i])
    return out


@njit
def housner_contact_forces(par, half_width, half_height, mass, theta, theta_dot, ag, av):
    """The base's force on a free-standing block over a history: Newton ``F = m (c'' - g_eff)``.

    Arrays (n samples) of the model's rotation ``theta`` (rad), rate ``theta'`` (rad/s) and ground
    accelerations ``ag``, ``av`` (m/s^2); ``half_width``, ``half_height`` in m, ``mass`` in kg.
    Written in the 2D engine's frame (x right, y up), where the block's angle is ``phi = -theta``
    and it pivots on the corner of side ``sgn(phi)`` (``sgn(phi')`` at ``phi = 0``; none at rest):
    the centroid is ``R(phi) (side b, h)`` from the pivot, ``g_eff = (-a_g, -(g + a_v))``.

    Returns
    -------
    fx, fy : ndarray, shape (n,)
        Tangential and normal force on the block, N.
    height : ndarray, shape (n,)
        The centroid's height above the pivot, m.
    """
    n = len(theta)
    fx, fy, height = np.empty(n), np.empty(n), np.empty(n)
    g = par[2]
    for i in range(n):
        phi, dphi = -theta[i], -theta_dot[i]
        if phi > 0.0 or (phi == 0.0 and dphi > 0.0):
            side = 1.0
        elif phi < 0.0 or (phi == 0.0 and dphi < 0.0):
            side = -1.0
        else:
            side = 0.0
        # the model's pivot side is sgn(theta) = -side
        ddphi = 0.0 if side == 0.0 else -housner_theta_ddot(par, -side, -phi, ag[i], av[i], 0.0, False)
        ux, uy = side * half_width, half_height
        c, s = math.cos(phi), math.sin(phi)
        rx, ry = c * ux - s * uy, s * ux + c * uy
        ax, ay = -ry * ddphi - rx * (dphi * dphi), rx * ddphi - ry * (dphi * dphi)
        fx[i], fy[i], height[i] = mass * (ax + ag[i]), mass * (ay + g + av[i]), ry
    return fx, fy, height


@njit_helper
def housner_rhs(par, y, ag, av, out):
    """(theta, theta'[, z]) -> derivatives on the pivot ``par[10]``; z is Bouc-Wen's hysteretic variable."""
    intact = par[11] != 0.0
    bouc = intact and par[4] == 2.0
    z = y[2] if bouc else 0.0
    out[0] = y[1]
    out[1] = housner_theta_ddot(par, par[10], y[0], ag, av, z, intact)
    if bouc:
        zabs = abs(z)
        gamma, beta, n = par[6], par[7], par[8]
        out[2] = (y[1] - gamma * abs(y[1]) * zabs ** (n - 1.0) * z - beta * y[1] * zabs ** n) / par[9]


# --------------------------------------------------------------------------- the stacked pair
@njit_helper
def stack_lever_arms(par, k1, k2):
    """u1, w, u2 in body coordinates (``nscd.stacked`` docstring) for pivot sides k1, k2 (0 -> +1)."""
    b1, h1, b2, h2, e = par[5], par[6], par[7], par[8], par[9]
    s1 = 1.0 if k1 == 0 else float(k1)
    s2 = 1.0 if k2 == 0 else float(k2)
    return s1 * b1, h1, e - s2 * b2 + s1 * b1, 2.0 * h1, s2 * b2, h2


@njit_helper
def _rotated_arms(par, phi1, phi2, k1, k2):
    """The lever arms of :func:`stack_lever_arms` turned into the base frame: R(phi1) u1, R(phi1) w, R(phi2) u2 (m)."""
    u1x, u1y, wx, wy, u2x, u2y = stack_lever_arms(par, k1, k2)
    c, s = math.cos(phi1), math.sin(phi1)
    cc, ss = math.cos(phi2), math.sin(phi2)
    return (c * u1x - s * u1y, s * u1x + c * u1y,
            c * wx - s * wy, s * wx + c * wy,
            cc * u2x - ss * u2y, ss * u2x + cc * u2y)


@njit_helper
def _in_bottom_axes(phi1, x, y):
    """A vector (x, y) of the base frame in the bottom block's axes (tangential, normal to its top face)."""
    c, s = math.cos(phi1), math.sin(phi1)
    return c * x + s * y, -s * x + c * y


@njit_helper
def _base_pivot(par, k1):
    """x (m, base frame) of the bottom block's pivot ``o1 = (-k1 b1, 0)``; the right corner (k1 -> +1) when closed."""
    return -(1.0 if k1 == 0 else float(k1)) * par[5]


@njit
def stack_terms(par, phi1, phi2, dphi1, dphi2, k1, k2, ag, av):
    """M11, M12, M22, C1, C2, Q1, Q2 of the 2-DOF equations ``M q'' + C = Q`` in pattern (k1, k2)."""
    m1, m2, i1, i2, g = par[0], par[1], par[2], par[3], par[4]
    u1x, u1y, wx, wy, u2x, u2y = stack_lever_arms(par, k1, k2)
    d = phi2 - phi1
    cd, sd = math.cos(d), math.sin(d)
    rux, ruy = cd * u2x - sd * u2y, sd * u2x + cd * u2y  # R(delta) u2
    m11 = i1 + m1 * (u1x * u1x + u1y * u1y) + m2 * (wx * wx + wy * wy)
    m22 = i2 + m2 * (u2x * u2x + u2y * u2y)
    m12 = m2 * (wx * rux + wy * ruy)
    x = wx * ruy - wy * rux
    c1_, c2_ = -m2 * dphi2 * dphi2 * x, m2 * dphi1 * dphi1 * x
    gx, gy = -ag, -(g + av)
    r1x, r1y, rwx, rwy, r2x, r2y = _rotated_arms(par, phi1, phi2, k1, k2)
    q1 = m1 * (r1x * gy - r1y * gx) + m2 * (rwx * gy - rwy * gx)
    q2 = m2 * (r2x * gy - r2y * gx)
    return m11, m12, m22, c1_, c2_, q1, q2


@njit
def stack_accelerations(par, phi1, phi2, dphi1, dphi2, k1, k2, ag, av):
    """(phi1'', phi2'') in rad/s^2 in pattern (k1, k2); a closed interface holds (``nscd.stacked``)."""
    m11, m12, m22, c1, c2, q1, q2 = stack_terms(par, phi1, phi2, dphi1, dphi2, k1, k2, ag, av)
    if k1 != 0 and k2 != 0:
        det = m11 * m22 - m12 * m12
        r1, r2 = q1 - c1, q2 - c2
        return (m22 * r1 - m12 * r2) / det, (m11 * r2 - m12 * r1) / det
    if k1 != 0:  # one body: S = (1, 1)
        a = (q1 + q2 - c1 - c2) / (m11 + 2.0 * m12 + m22)
        return a, a
    if k2 != 0:  # top alone: S = (0, 1)
        return 0.0, (q2 - c2) / m22
    return 0.0, 0.0


@njit_helper
def stack_rhs(par, y, ag, av, out):
    """(phi1, delta, phi1', delta') -> derivatives in the pattern (par[10], par[11])."""
    k1, k2 = int(par[10]), int(par[11])
    a1, a2 = stack_accelerations(par, y[0], y[0] + y[1], y[2], y[2] + y[3], k1, k2, ag, av)
    out[0] = y[2]
    out[1] = y[3]
    out[2] = a1
    out[3] = a2 - a1


@njit
def rhs(model, par, y, ag, av, out):
    """The right-hand side of ``model`` (:data:`HOUSNER` or :data:`STACK`) into ``out``."""
    if model == HOUSNER:
        housner_rhs(par, y, ag, av, out)
    else:
        stack_rhs(par, y, ag, av, out)


@njit
def stack_positions(par, phi1, phi2, k1, k2):
    """Centroids (c1x, c1y, c2x, c2y) in m in the base frame for angles (rad) and pivot sides.

    ``c1 = o1 + R(phi1) u1`` and ``c2 = j + R(phi2) u2``, ``j`` the top block's pivot (:func:`_joint_pivot`).
    Each coordinate is summed term by term from the origin (``(o1x + cos u1x) - sin u1y``), not as the
    origin plus :func:`_rotated_arms`: the impacts' momenta are taken about these points, and a
    different rounding here would move every later impact of a chaotic history.
    """
    u1x, u1y, _, _, u2x, u2y = stack_lever_arms(par, k1, k2)
    ox = _base_pivot(par, k1)
    c, s = math.cos(phi1), math.sin(phi1)
    cc, ss = math.cos(phi2), math.sin(phi2)
    jx, jy = _joint_pivot(par, phi1, k1, k2)
    return ox + c * u1x - s * u1y, s * u1x + c * u1y, jx + cc * u2x - ss * u2y, jy + ss * u2x + cc * u2y


@njit_helper
def _joint_pivot(par, phi1, k1, k2):
    """The top block's pivot on the bottom one, ``o1 + R(phi1) w`` (m, base frame), in pattern (k1, k2)."""
    _, _, wx, wy, _, _ = stack_lever_arms(par, k1, k2)
    c, s = math.cos(phi1), math.sin(phi1)
    return _base_pivot(par, k1) + c * wx - s * wy, s * wx + c * wy


@njit
def stack_contact_forces(par, phi1, phi2, dphi1, dphi2, ddphi1, ddphi2, k1, k2, ag, av):
    """(t_base, n_base, t_joint, n_joint) in N: Newton ``F = m (c'' - g_eff)`` for each block (``nscd.stacked``)."""
    m1, m2, g = par[0], par[1], par[4]
    r1x, r1y, rwx, rwy, r2x, r2y = _rotated_arms(par, phi1, phi2, k1, k2)
    a1x, a1y = -r1y * ddphi1 - r1x * dphi1 * dphi1, r1x * ddphi1 - r1y * dphi1 * dphi1
    awx, awy = -rwy * ddphi1 - rwx * dphi1 * dphi1, rwx * ddphi1 - rwy * dphi1 * dphi1
    a2x, a2y = -r2y * ddphi2 - r2x * dphi2 * dphi2, r2x * ddphi2 - r2y * dphi2 * dphi2
    gx, gy = -ag, -(g + av)
    f2x, f2y = m2 * (awx + a2x - gx), m2 * (awy + a2y - gy)
    f1x, f1y = m1 * (a1x - gx) + f2x, m1 * (a1y - gy) + f2y
    t_joint, n_joint = _in_bottom_axes(phi1, f2x, f2y)
    return f1x, f1y, t_joint, n_joint


@njit
def stack_history(par, phi, phi_dot, sides, ag, av):
    """Over a history (n samples): angular accelerations (n, 2), contact forces (n, 4), centroids (n, 4)."""
    n = phi.shape[0]
    acc, forces, centroids = np.empty((n, 2)), np.empty((n, 4)), np.empty((n, 4))
    for i in range(n):
        k1, k2 = sides[i, 0], sides[i, 1]
        a1, a2 = stack_accelerations(par, phi[i, 0], phi[i, 1], phi_dot[i, 0], phi_dot[i, 1], k1, k2, ag[i], av[i])
        acc[i, 0], acc[i, 1] = a1, a2
        forces[i, :] = stack_contact_forces(par, phi[i, 0], phi[i, 1], phi_dot[i, 0], phi_dot[i, 1], a1, a2,
                                            k1, k2, ag[i], av[i])
        centroids[i, :] = stack_positions(par, phi[i, 0], phi[i, 1], k1, k2)
    return acc, forces, centroids


@njit
def stack_release(par, phi1, phi2, dphi1, dphi2, k1, k2, ag, av, out):
    """Release tests of the closed interfaces of pattern (k1, k2) into ``out`` (rows of (interface, side,
    margin)); returns the number of rows. ``margin = side * (the interface's angular acceleration if
    freed about ``side``)`` in rad/s^2: > 0 means it would pull at the opposite corner, so it opens."""
    n = 0
    if k1 == 0:
        for s in (1, -1):
            a1, _ = stack_accelerations(par, phi1, phi2, 0.0, dphi2, s, k2, ag, av)
            out[n, 0], out[n, 1], out[n, 2] = 0.0, s, s * a1
            n += 1
    if k2 == 0:
        for s in (1, -1):
            a1, a2 = stack_accelerations(par, phi1, phi2, dphi1, dphi1, k1, s, ag, av)
            out[n, 0], out[n, 1], out[n, 2] = 1.0, s, s * (a2 - a1)
            n += 1
    return n


@njit
def stack_release_margin(par, phi1, phi2, dphi1, dphi2, k1, k2, ag, av):
    """The largest release margin (rad/s^2) of :func:`stack_release`; -inf when no interface is closed."""
    tests = np.empty((4, 3))
    n = stack_release(par, phi1, phi2, dphi1, dphi2, k1, k2, ag, av, tests)
    best = -math.inf
    for i in range(n):
        best = max(best, tests[i, 2])
    return best


@njit
def stack_rest_margins(par, ag, av):
    """The largest release margin (rad/s^2) of the stack at rest (pattern (0, 0)) under each (ag, av)."""
    out = np.empty(len(ag))
    for i in range(len(ag)):
        out[i] = stack_release_margin(par, 0.0, 0.0, 0.0, 0.0, 0, 0, ag[i], av[i])
    return out


@njit_helper
def _stack_unit_velocities(par, phi1, phi2, k1, k2):
    """Centroid velocities (m/s) per unit rate in pattern (k1, k2): bottom per phi1', top per phi1' and per phi2'.

    ``R(phi) E u = E R(phi) u = (-(R u)_y, (R u)_x)`` for each lever arm of :func:`_rotated_arms`.
    """
    r1x, r1y, rwx, rwy, r2x, r2y = _rotated_arms(par, phi1, phi2, k1, k2)
    return -r1y, r1x, -rwy, rwx, -r2y, r2x


@njit_helper
def _stack_momentum(par, phi1, phi2, k1, k2, px, py, whole):
    """Angular momentum about the point (px, py) (m, base frame) per unit phi1' and per unit phi2', the
    velocities in pattern (k1, k2): of the whole stack (``whole``) or of the top block alone, kg m^2/s."""
    m1, m2, i1, i2 = par[0], par[1], par[2], par[3]
    c1x, c1y, c2x, c2y = stack_positions(par, phi1, phi2, k1, k2)
    v1x, v1y, vax, vay, vbx, vby = _stack_unit_velocities(par, phi1, phi2, k1, k2)
    top1 = m2 * ((c2x - px) * vay - (c2y - py) * vax)
    top2 = m2 * ((c2x - px) * vby - (c2y - py) * vbx) + i2
    if whole:
        return i1 + m1 * ((c1x - px) * v1y - (c1y - py) * v1x) + top1, top2
    return top1, top2


@njit
def stack_impact(par, phi1, phi2, dphi1, dphi2, pre1, pre2, k1, k2):
    """Velocities (phi1'+, phi2'+) in rad/s after an impact from pattern (pre1, pre2) into (k1, k2).

    Angular momentum is conserved (``nscd.stacked``) about the points all impulses on a
    sub-system pass through: the whole stack about the base pivot when the base rocks after
    the impact (k1 != 0), the top block about its pivot on the bottom one when the joint
    rocks (k2 != 0). Pattern (0, 0) stops the stack.
    """
    if k1 == 0 and k2 == 0:
        return 0.0, 0.0
    base_x = _base_pivot(par, k1)  # the base pivot, (base_x, 0)
    top_x, top_y = 0.0, 0.0  # the top block's pivot
    if k2 != 0:
        top_x, top_y = _joint_pivot(par, phi1, k1, k2)
    if k1 != 0 and k2 != 0:
        a11, a12 = _stack_momentum(par, phi1, phi2, k1, k2, base_x, 0.0, True)
        a21, a22 = _stack_momentum(par, phi1, phi2, k1, k2, top_x, top_y, False)
        b11, b12 = _stack_momentum(par, phi1, phi2, pre1, pre2, base_x, 0.0, True)
        b21, b22 = _stack_momentum(par, phi1, phi2, pre1, pre2, top_x, top_y, False)
        r1, r2 = b11 * dphi1 + b12 * dphi2, b21 * dphi1 + b22 * dphi2
        det = a11 * a22 - a12 * a21
        return (a22 * r1 - a12 * r2) / det, (a11 * r2 - a21 * r1) / det
    if k1 != 0:  # one body: phi1' = phi2'
        a1, a2 = _stack_momentum(par, phi1, phi2, k1, k2, base_x, 0.0, True)
        b1, b2 = _stack_momentum(par, phi1, phi2, pre1, pre2, base_x, 0.0, True)
        x = (b1 * dphi1 + b2 * dphi2) / (a1 + a2)
        return x, x
    a1, a2 = _stack_momentum(par, phi1, phi2, k1, k2, top_x, top_y, False)  # top alone: phi1' = 0
    b1, b2 = _stack_momentum(par, phi1, phi2, pre1, pre2, top_x, top_y, False)
    return 0.0, (b1 * dphi1 + b2 * dphi2) / a2


@njit
def stack_impulses(par, phi1, phi2, before1, before2, pre1, pre2, after1, after2, k1, k2):
    """Impulses (N s) of an impact on the upper body of each interface, from the jump of the momenta.

    Rates (before1, before2) in pattern (pre1, pre2) jump to (after1, after2) in (k1, k2).
    Returns the base's impulse on the bottom block (x, y) and the joint's on the top block
    (tangential, normal in the bottom block's axes).
    """
    m1, m2 = par[0], par[1]
    v1x, v1y, vax, vay, vbx, vby = _stack_unit_velocities(par, phi1, phi2, pre1, pre2)
    w1x, w1y, wax, way, wbx, wby = _stack_unit_velocities(par, phi1, phi2, k1, k2)
    pjx = m2 * ((wax * after1 + wbx * after2) - (vax * before1 + vbx * before2))
    pjy = m2 * ((way * after1 + wby * after2) - (vay * before1 + vby * before2))
    pbx = m1 * (w1x * after1 - v1x * before1) + pjx
    pby = m1 * (w1y * after1 - v1y * before1) + pjy
    t_joint, n_joint = _in_bottom_axes(phi1, pjx, pjy)
    return pbx, pby, t_joint, n_joint
