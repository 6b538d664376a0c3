"""Coarse correction in the body velocities: the second level of a two-level Gauss–Seidel.

Gauss–Seidel fixes each contact against its neighbours, so an error that spans the
whole assembly — a wall's courses all a little too light or too heavy, the load of
the top still on its way down — decays only as fast as it diffuses, one course per
sweep: 50–100 accelerated sweeps per step on a 44-course wall. The velocity error of a
contact problem lives in the bodies, though, not in the contacts: with ``y = M^-1 H^T r``
the contact velocities are ``u = H y + q``, a field of ``n`` body velocities seen
through ``H``. This module corrects that field globally before each sweep.

For the rows ``A`` where a solution has ``u = 0`` (normal rows of loaded contacts,
tangential rows of contacts that stick — read from the current impulses), the change
``dr = H_A z`` that best reduces the energy ``1/2 r^T W r + q^T r`` restricted to ``A``
solves the body-space system ``(G M^-1 G) z = -H_A^T u_A`` with ``G = H_A^T H_A``,
i.e. ``z = -G^-1 M G^-1 H_A^T u_A`` (one Cholesky factor of ``G``, two solves). Where ``G`` is
regular this is the exact projection onto ``u_A = 0``; the sweep after it settles the
contacts whose regime it got wrong. Whatever factor is used, the correction vanishes
where ``u_A = 0``: a solution of the contact problem is a fixed point of
sweep-after-correction, so a stale factor (an earlier step's, an active set that has
since changed by a few contacts) slows the iteration down but cannot move its answer.
That is what lets the factor be kept from step to step while the assembly's contacts
and geometry stay nearly the same (a wall resting or carried without a change of
contact regime; refactored as soon as the active rows or the contact list change, or
the Jacobian moves).

``G`` is factored as a band matrix (LAPACK's banded Cholesky) in the bodies' own order
or, if narrower, reverse Cuthill–McKee's: a running-bond wall's bandwidth is about three
velocities per block of a course. An assembly whose band would cost more than
``_MAX_BAND_FLOPS`` to factor, or whose ``G`` is not positive definite, goes without
correction (plain Gauss–Seidel, noted by :attr:`CoarseCorrection.disabled`).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
from scipy.sparse.csgraph import reverse_cuthill_mckee

from nscd._jit import njit
from nscd.solver.delassus import Delassus

# Relative ridge eps M added to G = H_A^T H_A (eps relative to trace(G) / trace(M)): keeps
# the factor regular for a body that its active rows do not hold in every direction
# (a block on one corner); 1e-8 leaves a regular G unchanged to solver precision.
_RIDGE = 1e-8
# Refactor when the Jacobian's entries moved by more than this fraction of its largest
# entry (or the active rows, the contacts or the masses changed at all: measured on a
# 44-course wall, the factor of an earlier step's active set cost 2-9 times the sweeps of
# a fresh one, far more than the ~7 ms of a factor).
_JACOBIAN_CHANGE = 1e-2
# No correction for assemblies whose banded Cholesky would cost more flops than this
# (n * bandwidth^2: ~30 ms on one core).
_MAX_BAND_FLOPS = 1e8


class CoarseCorrection:
    """The body-space correction of :mod:`.nsgs` (see the module text), with its factor kept between solves.

    One instance per simulation (the stepper keeps it next to the warm start); it is
    used only with a diagonal mass matrix (2D bodies) and a factored
    :class:`~.delassus.Delassus` operator.

    Attributes
    ----------
    factorizations : int
        Banded Cholesky factorizations so far.
    corrections : int
        Corrections applied so far.
    disabled : str
        Why the last :meth:`prepare` turned the correction off ("" when on).
    """

    def __init__(self) -> None:
        self.factorizations = 0
        self.corrections = 0
        self.disabled = ""
        self._mass: np.ndarray | None = None
        self._h_pattern: tuple = ()             # (indptr, indices) of the factored Jacobian
        self._h_data: np.ndarray | None = None
        self._active: np.ndarray | None = None  # active rows of the factor
        self._perm: np.ndarray | None = None
        self._band: np.ndarray | None = None   # upper banded Cholesky factor of G (permuted)
        self._mu: np.ndarray | None = None     # friction coefficients of this solve

    def prepare(self, W: Delassus, mass: np.ndarray, mu: np.ndarray, r: np.ndarray) -> bool:
        """Set the active rows from the impulses ``r`` and refactor ``G`` if needed; True if usable.

        ``W`` is the (scaled) factored operator of this solve, ``mass`` the diagonal of
        ``M`` (kg, kg m^2), ``mu`` the friction coefficients, ``r`` the (scaled) impulses
        after a first sweep.
        """
        active = _active_rows(r, W.dim, mu)
        H = W.H
        fresh = (self._band is None or self._active is None or not np.array_equal(active, self._active)
                 or self._h_data is None or self._h_data.shape != H.data.shape
                 or not np.array_equal(self._h_pattern[0], H.indptr) or not np.array_equal(self._h_pattern[1], H.indices)
                 or not np.array_equal(mass, self._mass))
        if not fresh:
            fresh = np.abs(H.data - self._h_data).max(initial=0.0) > _JACOBIAN_CHANGE * np.abs(H.data).max(initial=0.0)
        self._mu = mu
        if fresh:
            self._factor(H, mass, active)
            self._h_pattern, self._h_data, self._mass = (H.indptr.copy(), H.indices.copy()), H.data.copy(), mass.copy()
            self._active = active
        return not self.disabled

    def _factor(self, H: sp.csr_matrix, mass: np.ndarray, active: np.ndarray) -> None:
        self.disabled, self._band = "", None
        n = H.shape[1]
        ptr, ind, dat = H.indptr.astype(np.int64), H.indices.astype(np.int64), H.data
        order = np.arange(n)
        width = _band_width(ptr, ind, active, order)
        if width * width * n > _MAX_BAND_FLOPS:
            HA = H[active]
            order = np.empty(n, dtype=np.int64)
            order[reverse_cuthill_mckee((HA.T @ HA).tocsr(), symmetric_mode=True)] = np.arange(n)
            width = _band_width(ptr, ind, active, order)
        if width * width * n > _MAX_BAND_FLOPS:
            self.disabled = f"bandwidth {width} of {n} body velocities: banded factor too costly"
            return
        band = _gram_band(ptr, ind, dat, active, order, n, width)
        ridge = _RIDGE * band[width].sum() / mass.sum()
        band[width] += ridge * mass[np.argsort(order)]
        try:
            self._band = sla.cholesky_banded(band, lower=False, check_finite=False)
        except np.linalg.LinAlgError:
            self.disabled = "H_A^T H_A + ridge not positive definite"
            return
        self._perm = np.argsort(order)
        self.factorizations += 1

    def _solve(self, b: np.ndarray) -> np.ndarray:
        x = np.empty_like(b)
        x[self._perm] = sla.cho_solve_banded((self._band, False), b[self._perm], check_finite=False)
        return x

    def correct(self, W: Delassus, q: np.ndarray, x: np.ndarray) -> np.ndarray:
        """Impulses ``x`` corrected so that ``u_A = W x + q`` on the active rows is (nearly) zero.

        The rows targeted are the factor's active rows that are still active at ``x``
        (read every time): a contact that has started to slide or lift off since
        :meth:`prepare` drops out at once, since a row whose velocity is not zero at the
        solution would make the correction fight the sweeps, and the fixed point would
        be lost. With all the factor's rows still active the correction is the exact
        projection; with a few fewer, a close approximation (its residual is masked, so
        it still vanishes at a solution).
        """
        rows = _active_rows(x, W.dim, self._mu) & self._active
        u = W @ x + q
        u[~rows] = 0.0
        H = W.H
        z = self._solve(self._mass * self._solve(-(H.T @ u)))
        change = H @ z
        change[~rows] = 0.0
        self.corrections += 1
        return x + change


def _active_rows(r: np.ndarray, dim: int, mu: np.ndarray) -> np.ndarray:
    """Rows with ``u = 0`` at a solution near ``r``: normal rows of loaded contacts, tangential rows of sticking ones."""
    R = r.reshape(-1, dim)
    loaded = R[:, 0] > 0.0
    tangential = np.linalg.norm(R[:, 1:], axis=1)
    stick = loaded & (tangential < mu * R[:, 0] * (1.0 - 1e-9))
    rows = np.empty(R.shape, dtype=bool)
    rows[:, 0] = loaded
    rows[:, 1:] = stick[:, None]
    return rows.ravel()


@njit
def _band_width(ptr: np.ndarray, ind: np.ndarray, active: np.ndarray, order: np.ndarray) -> int:
    """Half bandwidth of ``H_A^T H_A`` with velocity ``j`` placed at ``order[j]``."""
    width = 0
    for row in range(ptr.size - 1):
        if not active[row]:
            continue
        low, high = ptr.size, -1
        for e in range(ptr[row], ptr[row + 1]):
            low, high = min(low, order[ind[e]]), max(high, order[ind[e]])
        width = max(width, high - low)
    return width


@njit
def _gram_band(ptr: np.ndarray, ind: np.ndarray, dat: np.ndarray, active: np.ndarray, order: np.ndarray,
               n: int, width: int) -> np.ndarray:
    """``H_A^T H_A`` in LAPACK's upper band storage (``width + 1`` rows), velocity ``j`` at ``order[j]``."""
    band = np.zeros((width + 1, n))
    for row in range(ptr.size - 1):
        if not active[row]:
            continue
        for e in range(ptr[row], ptr[row + 1]):
            i = order[ind[e]]
            for f in range(ptr[row], ptr[row + 1]):
                j = order[ind[f]]
                if i <= j:
                    band[width + i - j, j] += dat[e] * dat[f]
    return band
