"""Contact frames and the sparse contact Jacobian, shared by 2D and 3D.

For contact ``c`` between bodies ``a`` and ``b`` at point ``x_c`` with unit normal
``n_c`` (from a to b), the relative velocity of b with respect to a at the point,

    u_c = (v_b + omega_b x r_b) - (v_a + omega_a x r_a),   r_i = x_c - x_i,

expressed in the frame ``[n, t1 (, t2)]``, is ``u = H v + w``: ``H`` acts on the
velocities of the dynamic bodies, ``w`` holds the part due to fixed and driven bodies.
Rows are ordered per contact: normal first, then the tangents.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from nscd._jit import njit

# The 3D tangent frame is built on the first world axis whose component of the normal is
# below this in magnitude: above 1/sqrt(3), so that every unit normal has one; far from 0
# and 1, so that a normal near a world axis never crosses it (see tangent_frames).
_FRAME_AXIS_LIMIT = 0.6



@dataclass(frozen=True)
class Contacts:
    """Contact points of one configuration, as arrays over contacts.

    Attributes
    ----------
    body_a, body_b : ndarray of int, shape (m,)
        Scene indices of the two bodies; the normal points from a to b.
    point : ndarray, shape (m, dim)
        Contact point in the world frame, m (midpoint of the two surface points).
    frame : ndarray, shape (m, dim, dim)
        Rows ``[n, t1 (, t2)]``: unit normal from a to b, then unit tangents.
    gap : ndarray, shape (m,)
        Signed normal distance in m; negative when penetrating.
    friction, restitution : ndarray, shape (m,)
        Contact law of each point (mu >= 0, e in [0, 1]).
    ids : ndarray of int, shape (m, 3)
        ``(body_a, body_b, feature id)``: stable while the same features touch.
    """

    body_a: np.ndarray
    body_b: np.ndarray
    point: np.ndarray
    frame: np.ndarray
    gap: np.ndarray
    friction: np.ndarray
    restitution: np.ndarray
    ids: np.ndarray

    def __len__(self) -> int:
        return len(self.gap)

    def subset(self, mask: np.ndarray) -> "Contacts":
        """The contacts selected by a boolean or index ``mask``."""
        return Contacts(*(getattr(self, f)[mask] for f in self.__dataclass_fields__))

    @staticmethod
    def empty(dim: int) -> "Contacts":
        z = np.zeros(0)
        zi = np.zeros(0, dtype=int)
        return Contacts(zi, zi, np.zeros((0, dim)), np.zeros((0, dim, dim)), z, z, z,
                        np.zeros((0, 3), dtype=int))


@njit
def tangent_frames(normal: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``[n, t1 (, t2)]`` for unit normals of shape (m, dim).

    2D: ``t1 = (-n_y, n_x)`` (the normal turned 90 deg counter-clockwise).
    3D: ``t1`` is perpendicular to n and to the first world axis (x, y, z) whose component
    of n is below ``_FRAME_AXIS_LIMIT`` in magnitude, ``t2 = n x t1`` (a right-handed
    frame). The frame thus turns continuously with a normal that stays near a world axis
    (a bed joint's normal near z: ``t1`` near y whatever the sign and order of its tiny x
    and y components), so that tangential impulses carried in the frame from one step to
    the next (the warm start) keep their direction; it jumps only where a component
    crosses the limit, at least 36 degrees away from every world axis.
    """
    m, dim = normal.shape
    frame = np.empty((m, dim, dim))
    for c in range(m):
        for d in range(dim):
            frame[c, 0, d] = normal[c, d]
        if dim == 2:
            frame[c, 1, 0], frame[c, 1, 1] = -normal[c, 1], normal[c, 0]
            continue
        nx, ny, nz = normal[c, 0], normal[c, 1], normal[c, 2]
        axis = 0
        while abs(normal[c, axis]) >= _FRAME_AXIS_LIMIT:
            axis += 1
        ax, ay, az = (1.0 if axis == 0 else 0.0), (1.0 if axis == 1 else 0.0), (1.0 if axis == 2 else 0.0)
        tx, ty, tz = ny * az - nz * ay, nz * ax - nx * az, nx * ay - ny * ax
        length = math.sqrt(tx * tx + ty * ty + tz * tz)
        tx, ty, tz = tx / length, ty / length, tz / length
        frame[c, 1, 0], frame[c, 1, 1], frame[c, 1, 2] = tx, ty, tz
        frame[c, 2, 0], frame[c, 2, 1], frame[c, 2, 2] = ny * tz - nz * ty, nz * tx - nx * tz, nx * ty - ny * tx
    return frame


def contact_kinematics(contacts: Contacts, centres: np.ndarray,
                       velocities: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The Jacobian of each contact on its two bodies, and relative velocities of the points.

    Parameters
    ----------
    contacts : Contacts
    centres : ndarray, shape (n_bodies, dim)
        Centres of mass, m, indexed by ``contacts.body_a`` and ``body_b``.
    velocities : ndarray, shape (n_sets, n_bodies, nv)
        Sets of body velocities (dynamic, fixed and driven bodies alike).

    Returns
    -------
    blocks : ndarray, shape (m, 2, dim, nv)
        ``blocks[c, 0]`` acts on the velocity of body b (sign +), ``blocks[c, 1]`` on that
        of body a (sign -). 2D row of frame vector ``e``: ``sign [e_x, e_y, r_x e_y - r_y e_x]``;
        3D: ``sign [e, r x e]``; ``r = point - centre``.
    u : ndarray, shape (n_sets, m, dim)
        ``u_c = blocks[c, 0] @ v[b] + blocks[c, 1] @ v[a]`` for each set, m/s.

    One compiled pass, contact by contact in a fixed order of operations: a contact's
    values do not depend on the other contacts (nor on the batch they are part of).
    """
    return _contact_kinematics(*_kernel_arguments(contacts, centres, velocities))


def _kernel_arguments(contacts: Contacts, centres: np.ndarray, velocities: np.ndarray) -> tuple:
    """Bodies, points, frames, centres and velocities as the kernels of this module take them
    (C-contiguous int64 and float64 arrays)."""
    ints = (np.ascontiguousarray(a, dtype=np.int64) for a in (contacts.body_a, contacts.body_b))
    floats = (np.ascontiguousarray(a, dtype=np.float64)
              for a in (contacts.point, contacts.frame, centres, velocities))
    return (*ints, *floats)


@njit
def _contact_kinematics(body_a, body_b, point, frame, centres, velocities):
    """Kernel of :func:`contact_kinematics`."""
    m, dim = point.shape
    n_sets, _, nv = velocities.shape
    blocks = np.empty((m, 2, dim, nv))
    u = np.zeros((n_sets, m, dim))
    for c in range(m):
        for side in range(2):
            body = body_b[c] if side == 0 else body_a[c]
            sign = 1.0 if side == 0 else -1.0
            # r = point - centre, as scalars (an array expression compiles numpy's broadcasting)
            r0, r1 = point[c, 0] - centres[body, 0], point[c, 1] - centres[body, 1]
            r2 = point[c, 2] - centres[body, 2] if dim == 3 else 0.0
            for k in range(dim):
                for j in range(dim):
                    blocks[c, side, k, j] = frame[c, k, j] * sign
                e0, e1 = frame[c, k, 0], frame[c, k, 1]
                if dim == 2:
                    blocks[c, side, k, 2] = (r0 * e1 - r1 * e0) * sign
                else:
                    e2 = frame[c, k, 2]
                    blocks[c, side, k, 3] = (r1 * e2 - r2 * e1) * sign
                    blocks[c, side, k, 4] = (r2 * e0 - r0 * e2) * sign
                    blocks[c, side, k, 5] = (r0 * e1 - r1 * e0) * sign
            # u += this side's rows times the body's velocities: the rows' sums side by side,
            # each over j in order (one chain of additions a row, none waiting for another's)
            for s in range(n_sets):
                total_0, total_1 = u[s, c, 0], u[s, c, 1]
                total_2 = u[s, c, 2] if dim == 3 else 0.0
                for j in range(nv):
                    velocity = velocities[s, body, j]
                    total_0 += blocks[c, side, 0, j] * velocity
                    total_1 += blocks[c, side, 1, j] * velocity
                    if dim == 3:
                        total_2 += blocks[c, side, 2, j] * velocity
                u[s, c, 0], u[s, c, 1] = total_0, total_1
                if dim == 3:
                    u[s, c, 2] = total_2
    return blocks, u


def jacobian(
    contacts: Contacts,
    centres: np.ndarray,
    velocities: np.ndarray,
    dof_of_body: np.ndarray,
    n_dofs: int,
) -> tuple[sp.csr_array, np.ndarray]:
    """Jacobian ``H`` and offset ``w`` with ``u = H v + w`` (see module docstring).

    Parameters
    ----------
    contacts : Contacts
    centres : ndarray, shape (n_bodies, dim)
        Centres of mass, m.
    velocities : ndarray, shape (n_sets, n_bodies, nv)
        One or more sets of body velocities (e.g. at the start and the end of a step);
        only rows of non-dynamic bodies are used (they enter ``w``).
    dof_of_body : ndarray of int, shape (n_bodies,)
        First velocity index of each dynamic body in ``v``, or -1 for fixed/driven bodies.
    n_dofs : int
        Length of ``v``.

    Returns
    -------
    H : csr_array, shape (m * dim, n_dofs)
        (the time step forms a small problem's ``H`` dense in its compiled stage,
        :func:`nscd.stepper._dense_problem`, from the same blocks)
    w : ndarray, shape (n_sets, m * dim)
    """
    fixed = np.where(dof_of_body[:, None] >= 0, 0.0, 1.0)  # zero the dynamic bodies' velocities
    blocks, w = contact_kinematics(contacts, centres, velocities * fixed)
    H = assemble_jacobian(blocks, contacts.body_a, contacts.body_b, dof_of_body, n_dofs)
    m, dim = len(contacts), centres.shape[1]
    return H, w.reshape(len(velocities), m * dim)


def assemble_jacobian(blocks: np.ndarray, body_a: np.ndarray, body_b: np.ndarray, dof_of_body: np.ndarray,
                      n_dofs: int) -> sp.csr_array:
    """``H`` (m * dim, n_dofs), CSR, from the blocks of :func:`contact_kinematics`
    (columns of fixed and driven bodies, ``dof_of_body == -1``, left out).

    The two bodies of a contact differ, so every entry is written by one side only.
    """
    rows, cols, data = _jacobian_entries(blocks, np.ascontiguousarray(body_a, dtype=np.int64),
                                         np.ascontiguousarray(body_b, dtype=np.int64), dof_of_body)
    m, _, dim, _ = blocks.shape
    return sp.csr_array((data, (rows, cols)), shape=(m * dim, n_dofs))


@njit
def _jacobian_entries(blocks, body_a, body_b, dof_of_body):
    """COO triplets (rows, columns, values) of :func:`assemble_jacobian`: side b, then side a."""
    m, _, dim, nv = blocks.shape
    rows = np.empty(2 * m * dim * nv, dtype=np.int64)
    cols = np.empty(2 * m * dim * nv, dtype=np.int64)
    data = np.empty(2 * m * dim * nv)
    count = 0
    for side in range(2):
        for c in range(m):
            dof = dof_of_body[body_b[c] if side == 0 else body_a[c]]
            if dof < 0:
                continue
            for k in range(dim):
                for j in range(nv):
                    rows[count], cols[count], data[count] = c * dim + k, dof + j, blocks[c, side, k, j]
                    count += 1
    return rows[:count], cols[:count], data[:count]


def centripetal_acceleration(contacts: Contacts, centres: np.ndarray, velocities: np.ndarray) -> np.ndarray:
    """Relative acceleration of the contact points due to rotation alone, in the contact frame, m/s^2.

    ``frame . (omega_b x (omega_b x r_b) - omega_a x (omega_a x r_a))``, shape (m, dim),
    rows ``[n, t1 (, t2)]`` (``centres`` (n_bodies, dim), m; ``velocities`` (n_bodies, nv)):
    the curvature of the points' paths that a velocity-level step misses. Over a step h a
    pivot drifts by about ``h^2 omega^2 |r| / 2``: open along the normal, and along the
    surface towards the centre of mass (a stuck pivot creeps).
    """
    return _centripetal(*_kernel_arguments(contacts, centres, velocities))


@njit
def _centripetal(body_a, body_b, point, frame, centres, velocities):
    """Kernel of :func:`centripetal_acceleration`, contact by contact."""
    m, dim = point.shape
    out = np.zeros((m, dim))
    acc = np.empty(dim)
    for c in range(m):
        for d in range(dim):
            acc[d] = 0.0
        for side in range(2):
            body = body_b[c] if side == 0 else body_a[c]
            sign = 1.0 if side == 0 else -1.0
            if dim == 2:
                w2 = velocities[body, 2] * velocities[body, 2]
                for d in range(2):
                    acc[d] -= sign * w2 * (point[c, d] - centres[body, d])
            else:
                wx, wy, wz = velocities[body, 3], velocities[body, 4], velocities[body, 5]
                rx = point[c, 0] - centres[body, 0]
                ry = point[c, 1] - centres[body, 1]
                rz = point[c, 2] - centres[body, 2]
                cx, cy, cz = wy * rz - wz * ry, wz * rx - wx * rz, wx * ry - wy * rx  # omega x r
                acc[0] += sign * (wy * cz - wz * cy)
                acc[1] += sign * (wz * cx - wx * cz)
                acc[2] += sign * (wx * cy - wy * cx)
        for k in range(dim):
            total = 0.0
            for d in range(dim):
                total += frame[c, k, d] * acc[d]
            out[c, k] = total
    return out
