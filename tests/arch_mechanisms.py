"""Reference for the arch tests: the kinematic (upper-bound) theorem of limit analysis over
four-hinge mechanisms of a voussoir arch, written independently of nscd.

Heyman's rigid, no-tension, no-sliding masonry: a mechanism is a chain
support - A - B - C - support of rigid segments joined by four hinges, each at the intrados
or the extrados end of a joint. Segment A turns about hinge 1, C about hinge 4, and B's
motion follows from the pins at hinges 2 and 3. It is kinematically admissible when every
hinge opens the joint on its other side (the other end of the joint face separates). The
horizontal load is a body force ``-lambda g`` along x on every voussoir (supports
accelerating toward +x); by virtual work the mechanism's load factor is
``lambda = (sum m v_y) / (-sum m v_x)`` at the centroids, and the collapse load factor is
the smallest over all admissible mechanisms in which the load does positive work. Hinges
are restricted to the joints (the arch is made of voussoirs), so this is the exact limit
load of the discrete arch, not an approximation of a continuous one.

The geometry is rebuilt here from its definition (centreline radius R, thickness t,
embrace, n equal voussoirs with radial joints, chord intrados and extrados).
"""
from __future__ import annotations

import itertools
import math

import numpy as np


def arch_joints(radius: float, thickness: float, n: int, angle: float = math.pi):
    """Intrados and extrados ends (n + 1, 2) of the joints, from the left springing, and their polar angles."""
    phi = 0.5 * math.pi + 0.5 * angle - angle * np.arange(n + 1) / n
    unit = np.column_stack([np.cos(phi), np.sin(phi)])
    return (radius - thickness / 2) * unit, (radius + thickness / 2) * unit, phi


def _area_centroid(poly: np.ndarray) -> tuple[float, np.ndarray]:
    x, y = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = 0.5 * cross.sum()
    centroid = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6 * area)
    return abs(area), centroid


def _cross_k(omega: float, r: np.ndarray) -> np.ndarray:
    """omega e_z x r."""
    return omega * np.array([-r[1], r[0]])


def collapse_load_factor(radius: float, thickness: float, n: int, angle: float = math.pi):
    """(lambda, hinges): smallest load factor over admissible four-hinge mechanisms.

    ``hinges`` is a tuple of four ``(joint index, "i" or "e")``.
    """
    intra, extra, phi = arch_joints(radius, thickness, n, angle)
    mass, first = [], []
    for k in range(n):
        a, c = _area_centroid(np.array([intra[k], extra[k], extra[k + 1], intra[k + 1]]))
        mass.append(a)
        first.append(a * c)
    # prefix sums: segment [j, k) has mass M[k] - M[j], first moment S[k] - S[j]
    M = np.concatenate([[0.0], np.cumsum(mass)])
    S = np.vstack([[0.0, 0.0], np.cumsum(first, axis=0)])
    # joint normal pointing from voussoir k-1 to voussoir k (toward decreasing phi)
    normal = np.column_stack([np.sin(phi), -np.cos(phi)])
    ends = {"i": intra, "e": extra}
    other = {"i": extra, "e": intra}
    best = (math.inf, None)
    for joints in itertools.combinations(range(n + 1), 4):
        for sides in itertools.product("ie", repeat=4):
            P = [ends[s][j] for s, j in zip(sides, joints)]
            Q = [other[s][j] for s, j in zip(sides, joints)]
            # omega_A = 1: omega_A k x (P2 - P1) + omega_B k x (P3 - P2) = omega_C k x (P3 - P4)
            lhs = np.column_stack([_cross_k(1.0, P[2] - P[1]), -_cross_k(1.0, P[2] - P[3])])
            if abs(np.linalg.det(lhs)) < 1e-12 * radius**2:
                continue
            w_b, w_c = np.linalg.solve(lhs, -_cross_k(1.0, P[1] - P[0]))
            for sign in (1.0, -1.0):
                w = [0.0, sign, sign * w_b, sign * w_c, 0.0]  # support, A, B, C, support
                ok = all(np.dot(_cross_k(w[h + 1] - w[h], Q[h] - P[h]), normal[joints[h]]) > 0.0
                         for h in range(4))
                if not ok:
                    continue
                j1, j2, j3, j4 = joints
                v2 = _cross_k(w[1], P[1] - P[0])
                momentum = (_cross_k(w[1], (S[j2] - S[j1]) - (M[j2] - M[j1]) * P[0])
                            + (M[j3] - M[j2]) * v2 + _cross_k(w[2], (S[j3] - S[j2]) - (M[j3] - M[j2]) * P[1])
                            + _cross_k(w[3], (S[j4] - S[j3]) - (M[j4] - M[j3]) * P[3]))
                if momentum[0] >= 0.0:
                    continue  # the load -lambda g x does no positive work
                lam = momentum[1] / -momentum[0]
                if lam < best[0]:
                    best = (lam, tuple(zip(joints, sides)))
    return best
