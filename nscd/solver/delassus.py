"""The Delassus operator ``W = H M^-1 H^T`` of a large assembly, kept as its two factors.

For a wall of a thousand blocks ``W`` has about 20 nonzero ``dim x dim`` blocks per
contact row (every contact that shares a body), ``H`` two or three (the contact's two
bodies). Forming ``W`` costs a sparse product per step, and a Gauss–Seidel sweep over
its rows reads all of those blocks. Kept factored, the sweep works in the body
velocities, as LMGC90's and Bullet's solvers do: contact ``c`` reads its relative
velocity ``u_c = H_c y + q_c`` from the bodies' impulse velocities ``y = M^-1 H^T r``
and, once its impulse changes by ``dr_c``, pushes ``y += (M^-1 H^T)_c dr_c`` back to
them — the same Gauss–Seidel iterates (the same arithmetic up to rounding) for a
fraction of the memory traffic. ``W`` is formed only if a stage needs it as a matrix
(:meth:`Delassus.tocsr`: the Newton polish and the interior point).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from nscd._jit import njit


@njit
def _diagonal_blocks(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, g_ptr: np.ndarray,
                     g_ind: np.ndarray, g_dat: np.ndarray, n: int, dim: int) -> np.ndarray:
    """``W_cc = H_c (M^-1 H^T)_c`` (m, dim, dim) from the CSR rows of ``H`` and of ``G = H M^-1``."""
    m = (h_ptr.size - 1) // dim
    blocks = np.zeros((m, dim, dim))
    scratch = np.zeros(n)
    for c in range(m):
        for j in range(dim):
            row = c * dim + j
            for e in range(g_ptr[row], g_ptr[row + 1]):
                scratch[g_ind[e]] += g_dat[e]
            for i in range(dim):
                acc = 0.0
                hr = c * dim + i
                for e in range(h_ptr[hr], h_ptr[hr + 1]):
                    acc += h_dat[e] * scratch[h_ind[e]]
                blocks[c, i, j] = acc
            for e in range(g_ptr[row], g_ptr[row + 1]):
                scratch[g_ind[e]] = 0.0
    return blocks


# Velocities per body in 3D (a translation and a rotation), the width of a body's block of columns.
_VELOCITIES_3D = 6


@njit
def _contact_rows(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, g_ptr: np.ndarray, g_ind: np.ndarray,
                  g_dat: np.ndarray) -> tuple:
    """The 3D rows of ``H`` and ``G`` of each contact laid out by body: ``(bodies, h, g)``.

    ``bodies`` (m, 2): first velocity index of the contact's two bodies (ascending; -1 where the
    contact touches one body or none); ``h``, ``g`` (m, 3, 12): the contact's rows over those
    bodies' six velocities each, zeros where the CSR rows have no entry.
    """
    m = (h_ptr.size - 1) // 3
    bodies = np.full((m, 2), -1, dtype=np.int64)
    h = np.zeros((m, 3, 2 * _VELOCITIES_3D))
    g = np.zeros((m, 3, 2 * _VELOCITIES_3D))
    for c in range(m):
        low, high = _contact_bodies(h_ptr, h_ind, c, -1, -1)
        low, high = _contact_bodies(g_ptr, g_ind, c, low, high)
        bodies[c, 0], bodies[c, 1] = low, high
        _place_rows(h_ptr, h_ind, h_dat, c, low, h)
        _place_rows(g_ptr, g_ind, g_dat, c, low, g)
    return bodies, h, g


@njit
def _contact_bodies(ptr: np.ndarray, ind: np.ndarray, c: int, low: int, high: int) -> tuple:
    """The first velocity indices ``low < high`` of the bodies that contact ``c``'s three CSR rows touch,
    added to those found so far (-1: none yet)."""
    for e in range(ptr[3 * c], ptr[3 * c + 3]):
        start = (ind[e] // _VELOCITIES_3D) * _VELOCITIES_3D
        if low < 0 or start == low:
            low = start
        elif start < low:
            if high >= 0:
                raise ValueError("a contact's rows touch more than two bodies")
            low, high = start, low
        elif high < 0 or start == high:
            high = start
        else:
            raise ValueError("a contact's rows touch more than two bodies")
    return low, high


@njit
def _place_rows(ptr: np.ndarray, ind: np.ndarray, dat: np.ndarray, c: int, low: int, out: np.ndarray) -> None:
    """Contact ``c``'s three CSR rows into ``out[c]`` (3, 12): the body at ``low`` first, the other second."""
    for i in range(3):
        for e in range(ptr[3 * c + i], ptr[3 * c + i + 1]):
            column = ind[e] - low
            if column < 0 or column >= _VELOCITIES_3D:
                column = _VELOCITIES_3D + ind[e] % _VELOCITIES_3D
            out[c, i, column] = dat[e]


@njit
def _body_velocities(g_ptr: np.ndarray, g_ind: np.ndarray, g_dat: np.ndarray, x: np.ndarray, y: np.ndarray) -> None:
    """``y = G^T x`` from the CSR rows of ``G`` (the bodies' impulse velocities ``M^-1 H^T x``; with the rows
    of ``H``, ``H^T x``): each row's products added in the order of the rows."""
    for i in range(y.size):
        y[i] = 0.0
    for row in range(x.size):
        if x[row] != 0.0:
            for e in range(g_ptr[row], g_ptr[row + 1]):
                y[g_ind[e]] += g_dat[e] * x[row]


@njit
def _contact_velocities(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, y: np.ndarray, q: np.ndarray,
                        u: np.ndarray) -> None:
    """``u = H y + q`` from the CSR rows of ``H``."""
    for row in range(u.size):
        acc = q[row]
        for e in range(h_ptr[row], h_ptr[row + 1]):
            acc += h_dat[e] * y[h_ind[e]]
        u[row] = acc


class Delassus:
    """``W = H M^-1 H^T`` as ``H`` (CSR) and ``M^-1 H^T``, with what the solver asks of ``W``.

    Parameters
    ----------
    H : scipy.sparse.csr_matrix, shape (m * dim, n)
        Contact Jacobian, rows per contact ``[N, T1, (T2)]``.
    MinvHT : scipy.sparse matrix (CSR or CSC), shape (n, m * dim)
        ``M^-1 H^T`` (``M`` the block-diagonal mass matrix of the ``n`` velocities).
    dim : int
        2 or 3.

    Notes
    -----
    Supports ``W @ r``, :meth:`diagonal`, :meth:`scaled` (``D W D`` for a diagonal
    ``D``, again factored), :meth:`tocsr` and, for the body-velocity sweeps of
    :mod:`.nsgs`, :meth:`sweep_data`.
    """

    def __init__(self, H: sp.csr_matrix, MinvHT: sp.csr_matrix, dim: int) -> None:
        self.H, self.MinvHT, self.dim = H, MinvHT, dim
        self.shape = (H.shape[0], H.shape[0])
        self._sweep_data: tuple | None = None
        self._contact_rows: tuple | None = None

    def __matmul__(self, r: np.ndarray) -> np.ndarray:
        return self.H @ (self.MinvHT @ r)

    def diagonal(self) -> np.ndarray:
        """The diagonal of ``W`` (length ``m * dim``)."""
        return self.blocks().diagonal(axis1=1, axis2=2).ravel().copy()

    def blocks(self) -> np.ndarray:
        """The diagonal blocks ``W_cc``, shape (m, dim, dim)."""
        return self.sweep_data()[6]

    def sweep_data(self) -> tuple:
        """CSR arrays of ``H`` and of ``G = (M^-1 H^T)^T`` (int64 / float64) and the blocks ``W_cc``.

        Returns ``(h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks)``, computed once.
        """
        if self._sweep_data is None:
            G = self.MinvHT.T.tocsr()
            arrays = []
            for A in (self.H, G):
                A.sort_indices()
                arrays += [A.indptr.astype(np.int64), A.indices.astype(np.int64),
                           np.ascontiguousarray(A.data, dtype=np.float64)]
            blocks = _diagonal_blocks(*arrays, self.H.shape[1], self.dim)
            self._sweep_data = (*arrays, blocks)
        return self._sweep_data

    def contact_rows(self) -> tuple:
        """3D: ``(bodies, h, g)`` of :func:`_contact_rows` (six velocities per body), computed once.

        The 3D sweeps read a contact's three rows of ``H`` and write its three rows of ``G`` over
        the twelve velocities of its two bodies: laid out contact by contact, one gather of
        ``y`` serves the three rows and no column index is read per entry.
        """
        if self._contact_rows is None:
            self._contact_rows = _contact_rows(*self.sweep_data()[:6])
        return self._contact_rows

    def scaled(self, d: np.ndarray) -> Delassus:
        """``D W D`` for ``D = diag(d)``, as the factors ``D H`` and ``M^-1 H^T D`` (sweep data rescaled, not recomputed)."""
        h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, blocks = self.sweep_data()
        h_scaled = h_dat * d[np.repeat(np.arange(h_ptr.size - 1), np.diff(h_ptr))]
        g_scaled = g_dat * d[np.repeat(np.arange(g_ptr.size - 1), np.diff(g_ptr))]
        H = sp.csr_matrix((h_scaled, h_ind, h_ptr), shape=self.H.shape)
        MinvHT = sp.csr_matrix((g_scaled, g_ind, g_ptr), shape=self.H.shape).T  # CSC: no conversion
        out = Delassus(H, MinvHT, self.dim)
        dc = d.reshape(-1, self.dim)
        out._sweep_data = (h_ptr, h_ind, h_scaled, g_ptr, g_ind, g_scaled, blocks * dc[:, :, None] * dc[:, None, :])
        if self._contact_rows is not None:
            bodies, h, g = self._contact_rows
            out._contact_rows = (bodies, h * dc[:, :, None], g * dc[:, :, None])
        return out

    def tocsr(self) -> sp.csr_matrix:
        """``W`` formed as a CSR matrix (one sparse product)."""
        return sp.csr_matrix(self.H @ self.MinvHT)
