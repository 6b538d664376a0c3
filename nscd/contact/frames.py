"""Contact frames and the sparse contact Jacobian, shared by 2D and 3D.

For contact ``c`` between bodies ``a`` and ``b`` at point ``x_c`` with unit normal
``n_c`` (from a to b), the relative velocity of b with respect to a at the point,

    u_c = (v_b + omega_b x r_b) - (v_a + omega_a x r_a),   r_i = x_c - x_i,

expressed in the frame ``[n, t1 (, t2)]``, is ``u = H v + w``: ``H`` acts on the
velocities of the dynamic bodies, ``w`` holds the part due to fixed and driven bodies.
Rows are ordered per contact: normal first, then the tangents.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from nscd._jit import HAVE_NUMBA, njit


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


def tangent_frames(normal: np.ndarray) -> np.ndarray:
    """Orthonormal frames ``[n, t1 (, t2)]`` for unit normals of shape (m, dim).

    2D: ``t1 = (-n_y, n_x)`` (the normal turned 90 deg counter-clockwise).
    3D: ``t1`` is perpendicular to n and to the world axis least aligned with n,
    ``t2 = n x t1`` (a right-handed frame).
    """
    m, dim = normal.shape
    frame = np.empty((m, dim, dim))
    frame[:, 0] = normal
    if dim == 2:
        frame[:, 1, 0] = -normal[:, 1]
        frame[:, 1, 1] = normal[:, 0]
        return frame
    axis = np.zeros_like(normal)
    axis[np.arange(m), np.argmin(np.abs(normal), axis=1)] = 1.0
    t1 = _cross(normal, axis)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    frame[:, 1] = t1
    frame[:, 2] = _cross(normal, t1)
    return frame


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a x b`` over the last axis (length 3) of broadcastable arrays.

    The arithmetic of ``np.cross`` (bit-identical results) without its axis handling,
    which costs several times the products on the small arrays of a step.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    out = np.empty(np.broadcast(a0, b0).shape + (3,))
    np.subtract(a1 * b2, a2 * b1, out=out[..., 0])
    np.subtract(a2 * b0, a0 * b2, out=out[..., 1])
    np.subtract(a0 * b1, a1 * b0, out=out[..., 2])
    return out


def _lever_rows(frame: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Angular part of the Jacobian rows: (m, dim, n_rot) for lever arms r (m, dim).

    2D: d(e . (omega x r))/d omega = r_x e_y - r_y e_x;  3D: r x e.
    """
    if frame.shape[1] == 2:
        return (r[:, None, 0] * frame[:, :, 1] - r[:, None, 1] * frame[:, :, 0])[:, :, None]
    return _cross(r[:, None, :], frame)


def jacobian(
    contacts: Contacts,
    centres: np.ndarray,
    velocities: np.ndarray,
    dof_of_body: np.ndarray,
    n_dofs: int,
    dense: bool = False,
) -> tuple[sp.csr_array | np.ndarray, np.ndarray]:
    """Sparse Jacobian ``H`` and offset ``w`` with ``u = H v + w`` (see module docstring).

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
    dense : bool
        Return ``H`` as a dense array (cheaper for a few bodies) instead of CSR.

    Returns
    -------
    H : csr_array or ndarray, shape (m * dim, n_dofs)
    w : ndarray, shape (n_sets, m * dim)
    """
    m = len(contacts)
    dim = centres.shape[1]
    n_sets, _, nv = velocities.shape
    frame = contacts.frame
    if dim == 2 and HAVE_NUMBA:
        # one compiled pass instead of ~30 small numpy calls (a third of a small scene's step)
        rows, cols, data, w = _jacobian_2d(contacts.body_a, contacts.body_b, contacts.point, frame,
                                           np.ascontiguousarray(centres, dtype=np.float64), dof_of_body,
                                           np.ascontiguousarray(velocities, dtype=np.float64))
        if dense:
            H = np.zeros((m * dim, n_dofs))
            H[rows, cols] = data
        else:
            H = sp.csr_array((data, (rows, cols)), shape=(m * dim, n_dofs))
        return H, w.reshape(n_sets, m * dim)
    w = np.zeros((n_sets, m, dim))
    sides = []
    for body, sign in ((contacts.body_b, 1.0), (contacts.body_a, -1.0)):
        r = contacts.point - centres[body]
        block = np.concatenate([frame, _lever_rows(frame, r)], axis=2) * sign  # (m, dim, nv)
        dof = dof_of_body[body]
        dyn = dof >= 0
        sides.append((np.flatnonzero(dyn), dof[dyn], block[dyn]))
        if not dyn.all():
            fixed = ~dyn
            w[:, fixed] += np.einsum("mkj,smj->smk", block[fixed], velocities[:, body[fixed]])
    H = _dense_jacobian(sides, m, dim, n_dofs) if dense else _sparse_jacobian(sides, m, dim, n_dofs)
    return H, w.reshape(n_sets, m * dim)


@njit
def _jacobian_2d(body_a: np.ndarray, body_b: np.ndarray, point: np.ndarray, frame: np.ndarray,
                 centres: np.ndarray, dof_of_body: np.ndarray, velocities: np.ndarray) -> tuple:
    """The 2D ``H`` (as COO triplets, rows ``2 c + k``) and ``w`` (n_sets, m, 2) of :func:`jacobian`.

    The same arithmetic as the numpy path, contact by contact: for side ``(body, sign)``
    the row of frame vector ``e`` is ``sign [e_x, e_y, r_x e_y - r_y e_x]``,
    ``r = point - centre``; a non-dynamic body adds that row times its velocity to ``w``.
    Side b is written first, as in the numpy path (``H`` is bitwise the same; ``w`` sums
    the three products in another order than ``einsum``: equal to rounding).
    """
    m = point.shape[0]
    n_sets = velocities.shape[0]
    rows = np.empty(12 * m, dtype=np.int64)
    cols = np.empty(12 * m, dtype=np.int64)
    data = np.empty(12 * m)
    w = np.zeros((n_sets, m, 2))
    count = 0
    for side in range(2):
        sign = 1.0 if side == 0 else -1.0
        for c in range(m):
            body = body_b[c] if side == 0 else body_a[c]
            rx = point[c, 0] - centres[body, 0]
            ry = point[c, 1] - centres[body, 1]
            dof = dof_of_body[body]
            for k in range(2):
                ex, ey = frame[c, k, 0], frame[c, k, 1]
                b0, b1, b2 = ex * sign, ey * sign, (rx * ey - ry * ex) * sign
                if dof >= 0:
                    for j, value in ((0, b0), (1, b1), (2, b2)):
                        rows[count] = 2 * c + k
                        cols[count] = dof + j
                        data[count] = value
                        count += 1
                else:
                    for s in range(n_sets):
                        w[s, c, k] += (b0 * velocities[s, body, 0] + b1 * velocities[s, body, 1]
                                       + b2 * velocities[s, body, 2])
    return rows[:count], cols[:count], data[:count], w


def _dense_jacobian(sides: list, m: int, dim: int, n_dofs: int) -> np.ndarray:
    """H (m * dim, n_dofs) from per-side ``(contacts, first dofs, blocks (k, dim, nv))``.

    The two bodies of a contact differ, so every entry is written by one side only.
    """
    H = np.zeros((m, dim, n_dofs))
    for contact, dof, block in sides:
        cols = dof[:, None, None] + np.arange(block.shape[2])
        H[contact[:, None, None], np.arange(dim)[:, None], cols] = block
    return H.reshape(m * dim, n_dofs)


def _sparse_jacobian(sides: list, m: int, dim: int, n_dofs: int) -> sp.csr_array:
    """CSR form of :func:`_dense_jacobian`."""
    rows = np.arange(m * dim).reshape(m, dim)
    data, row_idx, col_idx = [], [], []
    for contact, dof, block in sides:
        nv = block.shape[2]
        cols = dof[:, None, None] + np.arange(nv)[None, None, :]
        data.append(block.ravel())
        row_idx.append(np.broadcast_to(rows[contact][:, :, None], block.shape).ravel())
        col_idx.append(np.broadcast_to(cols, block.shape).ravel())
    return sp.csr_array(
        (np.concatenate(data), (np.concatenate(row_idx), np.concatenate(col_idx))),
        shape=(m * dim, n_dofs),
    )


def centripetal_acceleration(contacts: Contacts, centres: np.ndarray, velocities: np.ndarray) -> np.ndarray:
    """Relative acceleration of the contact points due to rotation alone, in the contact frame, m/s^2.

    ``frame . (omega_b x (omega_b x r_b) - omega_a x (omega_a x r_a))``, shape (m, dim),
    rows ``[n, t1 (, t2)]``: the curvature of the points' paths that a velocity-level step
    misses. Over a step h a pivot drifts by about ``h^2 omega^2 |r| / 2``: open along the
    normal, and along the surface towards the centre of mass (a stuck pivot creeps).
    """
    dim = centres.shape[1]
    acc = np.zeros((len(contacts), dim))
    for body, sign in ((contacts.body_b, 1.0), (contacts.body_a, -1.0)):
        r = contacts.point - centres[body]
        if dim == 2:
            acc -= sign * velocities[body, 2:3] ** 2 * r
        else:
            w = velocities[body, 3:]
            acc += sign * _cross(w, _cross(w, r))
    return np.einsum("mij,mj->mi", contacts.frame, acc)


def centripetal_normal(contacts: Contacts, centres: np.ndarray, velocities: np.ndarray) -> np.ndarray:
    """Normal relative acceleration of the contact points due to rotation alone, m/s^2.

    ``n . (omega_b x (omega_b x r_b) - omega_a x (omega_a x r_a))``: the curvature of
    the points' paths that a velocity-level step misses (it makes a pivot drift open
    by about ``dt^2 omega^2 |r| / 2`` per step). Shape (m,).
    """
    dim = centres.shape[1]
    normal = contacts.frame[:, 0]
    out = np.zeros(len(contacts))
    for body, sign in ((contacts.body_b, 1.0), (contacts.body_a, -1.0)):
        r = contacts.point - centres[body]
        if dim == 2:
            w2 = velocities[body, 2] ** 2
            out += sign * (-w2 * np.einsum("mi,mi->m", r, normal))
        else:
            w = velocities[body, 3:]
            out += sign * np.einsum("mi,mi->m", _cross(w, _cross(w, r)), normal)
    return out
