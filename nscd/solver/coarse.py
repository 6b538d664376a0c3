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
``dr = H_A z`` (``z`` a vector of body velocities) that best reduces the energy
``E(r) = 1/2 r^T W r + q^T r`` restricted to ``A``, ``W_AA = H_A M^-1 H_A^T``, is found
as follows. ``E(r + H_A z) - E(r) = 1/2 z^T (H_A^T W_AA H_A) z + z^T H_A^T u_A`` with
``u_A = (W r + q)_A``, and ``H_A^T W_AA H_A = G M^-1 G`` with ``G = H_A^T H_A``
(symmetric, ``n x n``). Setting the gradient to zero,

    G M^-1 G z = -H_A^T u_A   =>   z = -G^-1 M G^-1 H_A^T u_A,

one Cholesky factor of ``G`` and two solves, with the mass matrix ``M`` applied between
them. Nothing in this asks ``M`` to be diagonal: it holds for any symmetric positive
definite ``M``, so in 3D ``M`` is the block-diagonal matrix of the bodies' ``3 x 3``
translational masses and ``3 x 3`` world inertia tensors, applied by the inverses of the
diagonal blocks of the caller's ``M^-1`` (:func:`_inverse_blocks`). The weighting is
consistent: the ``M`` between the solves is the inverse of the ``M^-1`` inside ``W``,
because ``z`` minimises the energy of ``W`` itself — a diagonal stand-in for ``M`` (its
diagonal, or the reciprocal of the diagonal of ``M^-1``) would give the minimiser of another energy, and the correction
of a wrong energy fights the sweeps. Where ``G`` is regular, ``z`` is the exact
projection in the ``W_AA``-norm onto ``u_A = 0`` (``G M^-1 G`` regular gives
``H_A^T (u_A + W_AA H_A z) = 0``, and ``H_A^T`` is injective on the rows when ``G`` is
regular and ``H_A`` has full row rank; otherwise ``u_A`` is brought to its least
``W``-energy residual): applied twice it changes nothing the second time. The sweep
after it settles the contacts whose regime it got wrong. Whatever factor is used, the correction vanishes
where ``u_A = 0``: a solution of the contact problem is a fixed point of
sweep-after-correction, so a stale factor (an earlier step's, an active set that has
since changed by a few contacts) slows the iteration down but cannot move its answer.
That is what lets the factor be kept from step to step while the assembly's contacts
and geometry stay nearly the same (a wall resting or carried without a change of
contact regime; refactored as soon as the active rows or the contact list change, or
the Jacobian moves).

**Rows the correction pushes out of their cones (3D).** The correction is a bilateral one:
on its rows it lets an impulse take any sign. In a 3D wall 0.2 m deep that is not a detail: the
head joints (vertical faces between the blocks of a course) carry small normal impulses, and
the bilateral correction of the base's new load — the whole wall's inertia, passed up course by
course — put a third of them in tension (``docs/solver.md``, "3D": 94 of 336 head-joint points
with a negative normal impulse after one correction, the iterate's relative merit 1e-4 -> 1e-3,
and the sweeps' guard dropped the correction in every solve). So in 3D the correction is
recomputed without the rows it pushes out of their cones: a contact whose corrected normal
impulse is negative leaves the active set with all its rows (it will open or unload), one whose
corrected friction impulse leaves the cone ``|r_T| <= mu r_N`` keeps its normal row alone (it
will slide); refactored and corrected again, up to ``_CONE_ROUNDS`` times, until no active row
leaves its cone. This is the primal active-set method of a bound-constrained quadratic
program applied to the coarse space: each round only removes rows, so it ends; the rows left
are those whose bilateral answer the cones accept. The rows dropped stay out while the
contacts stay the same (same Jacobian pattern), whatever the set read from the impulses of
later solves (:meth:`CoarseCorrection.prepare`): a factor is kept while that set, less them,
does not change. Only the first correction after a factorization refactors in its rounds; a later
one drops the rows it pushes out of their cones from itself alone and recomputes with the same
factor (the masked residual keeps the fixed point, as for the rows read inactive). Through the
rocking of the 97-block wall 0.2 m deep each correction had refactored about once, and a
factorization costs three corrections (``docs/solver.md``, "3D, eighth round"). In 2D the plain
correction converges in a few sweeps on the walls measured (a joint's two corners carry its force
and moment alone) and is left as it was.

The ridge that keeps ``G`` regular (see ``_RIDGE``) is ``eps diag(w)`` with ``w`` the
reciprocal of the diagonal of ``M^-1``: the masses and moments of inertia themselves in
2D, a diagonal bounded above by ``diag(M)`` in 3D; it only regularises.

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
from nscd.solver.delassus import Delassus, _body_velocities, _contact_velocities

# Relative ridge eps M added to G = H_A^T H_A (eps relative to trace(G) / trace(M)): keeps
# the factor regular for a body that its active rows do not hold in every direction
# (a block on one corner); 1e-8 leaves a regular G unchanged to solver precision.
_RIDGE = 1e-8
# Refactor when the Jacobian's entries moved by more than this fraction of its largest
# entry (or the active rows, the contacts or the masses changed at all): on a wall of
# many courses the factor of an earlier step's active set costs several times the sweeps
# of a fresh one, far more than the fresh factor itself.
_JACOBIAN_CHANGE = 1e-2
# At most this many rounds of dropping the rows that the correction pushes out of their cones
# and refactoring (3D, see the module text): on the 3D wall of docs/solver.md 1-3 rounds
# leave no such row; each round costs one banded factorization.
_CONE_ROUNDS = 8
# No correction for assemblies whose banded Cholesky would cost more flops than this
# (n * bandwidth^2): it keeps one factorization cheap beside the sweeps of a step.
_MAX_BAND_FLOPS = 1e8


class CoarseCorrection:
    """The body-space correction of :mod:`.nsgs` (see the module text), with its factor kept between solves.

    One instance per simulation (the stepper keeps it next to the warm start); it is
    used with a factored :class:`~.delassus.Delassus` operator, in 2D (diagonal ``M``)
    and 3D (block-diagonal ``M``, full inertia tensors).

    Attributes
    ----------
    factorizations : int
        Banded Cholesky factorizations so far.
    corrections : int
        Corrections applied so far.
    disabled : str
        Why the last :meth:`prepare` turned the correction off ("" when on).
    resting : int
        Solves left in which the sweeps go without the correction, set by :func:`nscd.solver.nsgs.solve`
        after the correction spoiled the iterate of its first check (a wall breaking up: it does
        so solve after solve).
    """

    def __init__(self) -> None:
        self.factorizations = 0
        self.corrections = 0
        self.disabled = ""
        self.resting = 0
        self._mass: np.ndarray | None = None   # the weights of the factor's ridge (kg, kg m^2)
        self._mass_blocks: tuple = ()           # M's diagonal blocks: (first velocity of each, offsets, entries)
        self._h_pattern: tuple = ()             # (indptr, indices) of the factored Jacobian
        self._h_data: np.ndarray | None = None
        self._prepared: np.ndarray | None = None  # active rows read from the impulses by prepare
        self._active: np.ndarray | None = None  # active rows of the factor (3D: fewer, see _CONE_ROUNDS)
        self._perm: np.ndarray | None = None
        self._band: np.ndarray | None = None   # upper banded Cholesky factor of G (permuted)
        self._mu: np.ndarray | None = None     # friction coefficients of this solve
        self._first = False                    # no correction yet since prepare factored (3D: its rounds refactor)

    def prepare(self, W: Delassus, mass: np.ndarray | sp.spmatrix, mu: np.ndarray, r: np.ndarray) -> bool:
        """Set the active rows from the impulses ``r`` and refactor ``G`` if needed; True if usable.

        Parameters
        ----------
        W : Delassus
            The (scaled) factored operator of this solve.
        mass : ndarray, shape (n,), or scipy.sparse matrix, shape (n, n)
            A 1-D array is the diagonal of a diagonal ``M`` (kg, kg m^2; 2D bodies); a
            matrix is ``M^-1`` (1/kg, 1/(kg m^2)), block diagonal and symmetric positive
            definite (3D bodies: world inertia tensors), the same ``M^-1`` as in ``W``.
        mu : ndarray, shape (m,)
            Friction coefficients.
        r : ndarray, shape (m * dim,)
            The (scaled) impulses after a first sweep.
        """
        active = _active_rows(r, W.dim, mu)
        H = W.H
        if np.ndim(mass) == 1:
            weights = np.ascontiguousarray(mass, dtype=np.float64)
            size = np.arange(weights.size + 1, dtype=np.int64)
            self._mass_blocks = (size, size, weights)
        else:  # M^-1 of 3D bodies: M applied by the inverses of its diagonal blocks
            weights = 1.0 / mass.diagonal()
            inverse = sp.csr_matrix(mass)
            inverse.sort_indices()
            self._mass_blocks = _inverse_blocks(inverse.indptr.astype(np.int64), inverse.indices.astype(np.int64),
                                                np.ascontiguousarray(inverse.data, dtype=np.float64))
        same_contacts = (self._h_data is not None and self._h_data.shape == H.data.shape
                         and np.array_equal(self._h_pattern[0], H.indptr)
                         and np.array_equal(self._h_pattern[1], H.indices))
        # 3D: rows dropped for leaving their cones stay out while the contacts are the same ones,
        # so a step whose impulses read a slightly different set does not redo the rounds
        target = active
        if same_contacts and self._prepared is not None and self._prepared.shape == active.shape:
            target = active & ~(self._prepared & ~self._active)
        fresh = (self._band is None or not same_contacts or not np.array_equal(target, self._active)
                 or self._mass is None or self._mass.shape != weights.shape)
        if not fresh:
            # the ridge's weights (3D: the world inertia turns with the bodies) and the
            # Jacobian are allowed to drift a little: a stale factor keeps the fixed point
            fresh = (np.abs(H.data - self._h_data).max(initial=0.0) > _JACOBIAN_CHANGE * np.abs(H.data).max(initial=0.0)
                     or np.abs(weights - self._mass).max() > _JACOBIAN_CHANGE * np.abs(weights).max())
        self._mu = mu
        self._prepared = active
        self._first = fresh
        if fresh:
            self._factor(H, weights, target)
            self._h_pattern, self._h_data, self._mass = (H.indptr.copy(), H.indices.copy()), H.data.copy(), weights.copy()
            self._active = target.copy()  # the rounds shrink it in place; _prepared keeps what was read
        return not self.disabled

    @property
    def factored_rows(self) -> np.ndarray | None:
        """Boolean mask (m * dim,) of the rows the factor targets: those read from the impulses by
        :meth:`prepare`, less, in 3D, the rows dropped for leaving their cones (None before the first)."""
        return None if self._active is None else self._active.copy()

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
        """``G^-1 b`` by the banded factor (LAPACK's ``dpbtrs``, in the factor's order)."""
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
        it still vanishes at a solution). In 3D, rows that the correction pushes out of
        their cones leave the factor's active set, which is refactored, and the correction
        is computed again (the module text, ``_CONE_ROUNDS``) — in the first correction after
        a factorization; a later one drops them from itself alone, on the same factor. The products
        with ``H``, ``G`` and ``M`` and the cone tests are compiled, the banded solves LAPACK's.
        """
        h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat = W.sweep_data()[:6]
        rows = _active_rows(x, W.dim, self._mu) & self._active
        u = np.empty(x.size)
        _masked_velocity(h_ptr, h_ind, h_dat, g_ptr, g_ind, g_dat, q, x, rows, np.empty(W.H.shape[1]), u)
        change, b, w = np.empty(x.size), np.empty(W.H.shape[1]), np.empty(W.H.shape[1])
        rounds = _CONE_ROUNDS if W.dim == 3 else 0
        for round_ in range(rounds + 1):
            _body_velocities(h_ptr, h_ind, h_dat, u, b)  # H^T u
            _apply_blocks(*self._mass_blocks, self._solve(-b), w)
            _masked_product(h_ptr, h_ind, h_dat, self._solve(w), rows, change)
            if round_ == rounds:
                break
            leaving = _leaving_cones(x + change, rows, W.dim, self._mu)
            if not leaving.any():
                break
            rows &= ~leaving
            u[~rows] = 0.0
            if not self._first:
                continue  # the rows leave this correction only, the factor is kept (the module text)
            self._active &= ~leaving
            self._factor(W.H, self._mass, self._active)
            if self.disabled:
                return x
        self.corrections += 1
        self._first = False
        return x + change


@njit
def _leaving_cones(r: np.ndarray, rows: np.ndarray, dim: int, mu: np.ndarray) -> np.ndarray:
    """Active ``rows`` to drop because the impulses ``r`` leave their cones there: every row of a
    contact whose normal impulse is negative, the tangential rows of one whose friction impulse
    is outside ``|r_T| <= mu r_N``."""
    out = np.zeros(rows.size, dtype=np.bool_)
    for c in range(mu.size):
        at = c * dim
        if rows[at] and r[at] < 0.0:
            for i in range(dim):
                out[at + i] = rows[at + i]
        elif rows[at + 1] and _tangential_norm(r, at, dim) > mu[c] * r[at]:
            for i in range(1, dim):
                out[at + i] = rows[at + i]
    return out


@njit
def _active_rows(r: np.ndarray, dim: int, mu: np.ndarray) -> np.ndarray:
    """Rows with ``u = 0`` at a solution near ``r``: normal rows of loaded contacts, tangential rows of sticking ones."""
    rows = np.empty(r.size, dtype=np.bool_)
    for c in range(r.size // dim):
        at = c * dim
        loaded = r[at] > 0.0
        stick = loaded and _tangential_norm(r, at, dim) < mu[c] * r[at] * (1.0 - 1e-9)
        rows[at] = loaded
        for i in range(1, dim):
            rows[at + i] = stick
    return rows


@njit
def _tangential_norm(r: np.ndarray, at: int, dim: int) -> float:
    """``|r_T|`` of the contact whose rows start at ``at``."""
    if dim == 2:
        return abs(r[at + 1])
    return np.sqrt(r[at + 1] * r[at + 1] + r[at + 2] * r[at + 2])


@njit
def _masked_velocity(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, g_ptr: np.ndarray, g_ind: np.ndarray,
                     g_dat: np.ndarray, q: np.ndarray, x: np.ndarray, rows: np.ndarray, y: np.ndarray,
                     u: np.ndarray) -> None:
    """``u = W x + q`` on ``rows``, 0 elsewhere, from the CSR rows of ``H`` and ``G`` (``W = H G^T``; ``y`` work
    space for the body velocities ``G^T x``); ``H y`` summed before ``q`` is added, as ``H @ y + q``."""
    _body_velocities(g_ptr, g_ind, g_dat, x, y)
    for row in range(u.size):
        if rows[row]:
            acc = 0.0
            for e in range(h_ptr[row], h_ptr[row + 1]):
                acc += h_dat[e] * y[h_ind[e]]
            u[row] = acc + q[row]
        else:
            u[row] = 0.0


@njit
def _masked_product(h_ptr: np.ndarray, h_ind: np.ndarray, h_dat: np.ndarray, z: np.ndarray, rows: np.ndarray,
                    out: np.ndarray) -> None:
    """``out = H z`` on ``rows``, 0 elsewhere, from the CSR rows of ``H``."""
    for row in range(out.size):
        acc = 0.0
        if rows[row]:
            for e in range(h_ptr[row], h_ptr[row + 1]):
                acc += h_dat[e] * z[h_ind[e]]
        out[row] = acc


@njit
def _inverse_blocks(ptr: np.ndarray, ind: np.ndarray, dat: np.ndarray) -> tuple:
    """``M``'s diagonal blocks from the CSR arrays (indices sorted) of a block-diagonal ``M^-1``: ``(first,
    offsets, entries)``, block ``k`` the velocities ``first[k]:first[k + 1]``, its inverse row by row in
    ``entries[offsets[k]:offsets[k + 1]]``. A block is the smallest run of rows closed under their columns
    (two blocks coupled by an entry make one); raises ValueError where a row reaches back before its block
    (a pattern that is not symmetric: ``M^-1`` is symmetric)."""
    n = ptr.size - 1
    first = [0]
    start = 0
    while start < n:
        stop = start + 1
        row = start
        while row < stop:
            for e in range(ptr[row], ptr[row + 1]):
                if ind[e] < start:
                    raise ValueError("mass: M^-1 is not block diagonal")
                stop = max(stop, ind[e] + 1)
            row += 1
        first.append(stop)
        start = stop
    bounds = np.array(first, dtype=np.int64)
    offsets = np.zeros(bounds.size, dtype=np.int64)
    for k in range(bounds.size - 1):
        size = bounds[k + 1] - bounds[k]
        offsets[k + 1] = offsets[k] + size * size
    entries = np.empty(offsets[-1])
    for k in range(bounds.size - 1):
        low, size = bounds[k], bounds[k + 1] - bounds[k]
        block = np.zeros((size, size))
        for row in range(low, low + size):
            for e in range(ptr[row], ptr[row + 1]):
                block[row - low, ind[e] - low] = dat[e]
        inverse = np.linalg.inv(block)
        for i in range(size):
            for j in range(size):
                entries[offsets[k] + i * size + j] = inverse[i, j]
    return bounds, offsets, entries


@njit
def _apply_blocks(first: np.ndarray, offsets: np.ndarray, entries: np.ndarray, w: np.ndarray, out: np.ndarray) -> None:
    """``out = M w`` for ``M`` given by its diagonal blocks (:func:`_inverse_blocks`)."""
    for k in range(first.size - 1):
        low, size = first[k], first[k + 1] - first[k]
        for i in range(size):
            acc = 0.0
            for j in range(size):
                acc += entries[offsets[k] + i * size + j] * w[low + j]
            out[low + i] = acc


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
    """``H_A^T H_A`` in LAPACK's upper band storage (``width + 1`` rows), velocity ``j`` at ``order[j]``.

    Accumulated column by column of the band (``by_column[j, width + i - j]``: a row's products for one
    column ``j`` are contiguous) from each row's places looked up once, then laid out as LAPACK's rows;
    every entry sums its products in the order of the rows of ``H``."""
    by_column = np.zeros((n, width + 1))
    places = np.empty(ind.size, dtype=np.int64)
    for row in range(ptr.size - 1):
        if not active[row]:
            continue
        start, stop = ptr[row], ptr[row + 1]
        for e in range(start, stop):
            places[e] = order[ind[e]]
        for f in range(start, stop):
            j = places[f]
            value = dat[f]
            for e in range(start, stop):
                i = places[e]
                if i <= j:
                    by_column[j, width + i - j] += dat[e] * value
    band = np.empty((width + 1, n))
    for j in range(n):
        for k in range(width + 1):
            band[k, j] = by_column[j, k]
    return band
