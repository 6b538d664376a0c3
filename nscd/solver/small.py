"""Compiled semismooth Newton for small dense contact problems, many at once.

One numba kernel (:func:`solve_dense`) solves ``B`` independent problems
``u = W r + q`` with exact (De Saxcé) or relaxed Coulomb friction, each on its own
leading ``n_b x n_b`` block of padded arrays, in one compiled call. It is the fast
path of :func:`nscd.solver.core.solve` (``B = 1``) and the engine of
:func:`nscd.solver.core.solve_batch`; problems it does not accept go to the proximal
point (:func:`nscd.solver.proximal.solve_dense`, compiled, whose inner problems and polish
are solved by this kernel; both in one compiled call, :func:`nscd.solver.proximal.fast_path`),
then to the conic fixed point there.

It is :mod:`.newton` compiled, in the scaled units of :class:`nscd.solver.core._Scaled`:

- **Scaling.** ``d_c = 1 / sqrt(max(W_NN,c, floor))`` per contact
  (``floor = 1e-14 max(1, max_c W_NN,c)``), ``sigma = ||D q||_inf``,
  ``r = sigma D r'``, ``u = sigma D^-1 u'``; ``sigma == 0`` is the trivial solution
  ``r = 0, u = q``.
- **Newton.** ``F(r') = r' - P_K(r' - (u' + mu ||u'_T|| e_N))`` from the warm start
  and, if that fails, once more from ``r = 0`` (on the fast path only when the warm start
  was junk: ``||F||`` not halved from it, :data:`JUNK_START`); on the fast path a run also
  ends when ``||F||`` has not halved in :data:`FAST_PATIENCE` iterations (a stall test:
  the problems of a stack whose joint slides slowly at the friction limit crawl along the
  near null space of ``W``, and the proximal point solves them for a fraction of the cost,
  ``docs/solver.md``); steps from the
  proximally regularised Jacobian ``I - D + D (I + E) (W' + ||F|| I)`` with an Armijo
  line search on ``||F||``, then Levenberg–Marquardt directions with
  ``lambda = (1, 1e2, 1e4) ||F||``, then at most three watchdog steps; the iterate of
  smallest ``||F||`` is kept (see :mod:`.newton` for why each piece is there).
- **Acceptance**, exactly as :meth:`nscd.solver.core._Scaled.stop`: the unscaled FCLIB
  merit ``||r - P_K(r - (u + mu ||u_T|| e_N))|| / (1 + sqrt(||q||))`` and the unscaled
  distance of ``u + mu ||u_T|| e_N`` to the dual cone both ``<= tol``
  (:func:`nscd.solver.cone.merit_and_dual_violation`). As in ``_Scaled.newton``, they
  are evaluated only once the scaled ``||F||`` times a lower bound of the unscaled/scaled
  ratio is below ``tol``.

Memory: a call allocates one work array, laid out anew for each problem by its size (the
Newton's vectors and matrices, the Jacobian's blocks, the acceptance test's vectors), so that
its problems and their iterations allocate nothing: the problems of a step of a few blocks
are small enough that allocating and freeing their arrays was a sizeable share of solving them.

Determinism: all arithmetic is written as explicit loops over the problem's own
``n_b`` unknowns (no BLAS, whose blocking depends on the array sizes; numba's default
``fastmath=False`` forbids reassociation), so a problem gives bitwise the same answer
alone or inside a padded batch. Linear systems are solved by Gaussian elimination with
partial pivoting (Newton) and Cholesky (Levenberg–Marquardt), written out here for the
same reason.
"""
from __future__ import annotations

import math

import numpy as np

from nscd._jit import njit, njit_helper
from nscd.solver.newton import _ARMIJO, _LM_FACTORS, _MIN_STEP, _WATCHDOG

#: Outcome codes of :func:`solve_dense` (and of :func:`nscd.solver.proximal.solve_dense`:
#: accepted by the proximal point, or by the polish after it), one per problem.
NOT_ACCEPTED, ACCEPTED, TRIVIAL, PROXIMAL, PROXIMAL_POLISHED = 0, 1, 2, 3, 4

# The numpy Newton's line-search constants (Armijo constant, smallest step, watchdog
# steps) and its Levenberg-Marquardt factors after the plain Newton direction (factor 0).
_LM_ONLY = _LM_FACTORS[1:]
# Stall test of the fast path (``patience``): a run whose ||F|| has not halved over that many
# iterations is crawling along a kink or a valley of ||F|| (on a stack's singular W, line-search
# steps of 2^-20 and less), each iteration costing up to four line searches.
_STALL = 0.5
#: ``patience`` of the fast path and of the proximal point's inner problems (their fallbacks are
#: robust); the polishes run without a stall test.
FAST_PATIENCE = 5
#: ``restart_above`` of the fast path: a warm start is junk (and the Newton runs again from
#: ``r = 0``) when the Newton could not halve ``||F||`` from it; one it took closer but not to
#: ``tol`` (a slowly sliding joint on a singular ``W``, :mod:`.proximal`) goes on to the
#: proximal point from there. The polish restarts always (0), the proximal point's inner
#: problems never (their warm start is the outer iterate).
JUNK_START = _STALL


# The cone's small helpers take and return numbers, or are compiled inside their callers
# (inline=True): a compiled callee that is given arrays takes and drops a reference to each
# (an atomic update of a counter) at every call, several times the cost of projecting one
# contact (``docs/solver.md``, fourteenth round).
@njit_helper(inline=True)
def _norm_t(x1, x2, dim):
    """``||x_T||`` of the tangential part ``x1`` (2D; ``x2`` not read) or ``(x1, x2)`` (3D)."""
    return abs(x1) if dim == 2 else math.hypot(x1, x2)


@njit_helper(inline=True)
def _tangent_norm(x, i, dim):
    """``||x_T||`` of the contact whose normal row is ``i``."""
    return _norm_t(x[i + 1], x[i + 2] if dim == 3 else 0.0, dim)


@njit_helper
def _cone_point(xn, x1, x2, mu, dim):
    """``P_K`` of the point ``(xn, x1)`` (2D; ``x2`` not read, 0.0 returned for it) or
    ``(xn, x1, x2)`` (3D) on the cone ``||x_T|| <= mu x_N`` (as :func:`cone.project`)."""
    rho = _norm_t(x1, x2, dim)
    if rho <= mu * xn and xn >= 0.0:
        return xn, x1, x2
    a = max((xn + mu * rho) / (1.0 + mu * mu), 0.0)
    scale = mu * a / rho if rho > 0.0 else 0.0
    return a, x1 * scale, x2 * scale


@njit_helper(inline=True)
def _project(x, i, mu, dim, out):
    """``out[i:i+dim] = P_K(x[i:i+dim])`` on the cone ``||x_T|| <= mu x_N`` (:func:`_cone_point`)."""
    a, b, c = _cone_point(x[i], x[i + 1], x[i + 2] if dim == 3 else 0.0, mu, dim)
    out[i] = a
    out[i + 1] = b
    if dim == 3:
        out[i + 2] = c


# The natural map, the product W x + q and the line search's trial are compiled inside their
# callers (inline=True): called on their own, each call passes every array it is given as a
# structure and takes and drops a reference to it, as dear as the work of a trial on a
# problem of a few contacts (``docs/solver.md``, thirteenth round).
@njit_helper(inline=True)
def _natural_map(r, u, mu, dim, exact, y, f):
    """``f = r - P_K(r - (u + mu ||u_T|| e_N))`` (``y``: work array); returns ``||f||_2``."""
    n = r.size
    for i in range(n):
        y[i] = r[i] - u[i]
    if exact:
        for c in range(n // dim):
            y[c * dim] -= mu[c] * _tangent_norm(u, c * dim, dim)
    for c in range(n // dim):
        _project(y, c * dim, mu[c], dim, f)
    total = 0.0
    for i in range(n):
        f[i] = r[i] - f[i]
        total += f[i] * f[i]
    return math.sqrt(total)


@njit_helper(inline=True)
def _affine(W, x, q, out):
    """``out = W x + q`` (row by row, fixed summation order)."""
    n = x.size
    for i in range(n):
        total = 0.0
        for j in range(n):
            total += W[i, j] * x[j]
        out[i] = total + q[i]


@njit_helper(inline=True)
def _trial(W, q, mu, dim, exact, r, direction, step, r_try, u_try, y, f_try):
    """Trial point ``r_try = r + step direction``, ``u_try = W r_try + q``; returns ``||F(r_try)||``."""
    for i in range(r.size):
        r_try[i] = r[i] + step * direction[i]
    _affine(W, r_try, q, u_try)
    return _natural_map(r_try, u_try, mu, dim, exact, y, f_try)


@njit_helper(inline=True)
def _vector(work, k, n):
    """The ``k``-th of the vectors of ``n`` entries laid end to end in ``work`` (a view)."""
    return work[k * n:(k + 1) * n]


#: Work vectors of ``n`` entries of :func:`_unscaled_test` (its unscaled pair, the shifted
#: velocity, the two points projected and their projections), laid end to end in its ``work``.
TEST_VECTORS = 7


@njit_helper
def _unscaled_test(r_s, u_s, d, sigma, mu, dim, exact, q_norm, work):
    """Unscaled FCLIB merit and dual-cone violation of the scaled pair (``cone.merit_and_dual_violation``);
    ``work``: at least :data:`TEST_VECTORS` ``* n`` entries, written over."""
    n = r_s.size
    r, u, x, e = _vector(work, 0, n), _vector(work, 1, n), _vector(work, 2, n), _vector(work, 3, n)
    minus_x, p, v = _vector(work, 4, n), _vector(work, 5, n), _vector(work, 6, n)
    for i in range(n):
        r[i] = sigma * d[i] * r_s[i]
        u[i] = sigma * u_s[i] / d[i]
        x[i] = u[i]
    if exact:
        for c in range(n // dim):
            x[c * dim] += mu[c] * _tangent_norm(u, c * dim, dim)
    for i in range(n):
        e[i] = r[i] - x[i]
        minus_x[i] = -x[i]
    for c in range(n // dim):
        _project(e, c * dim, mu[c], dim, p)
        _project(minus_x, c * dim, mu[c], dim, v)
    merit = 0.0
    violation = 0.0
    for i in range(n):
        merit += (r[i] - p[i]) ** 2
        violation += v[i] * v[i]
    scale = 1.0 + math.sqrt(q_norm)
    return math.sqrt(merit) / scale, math.sqrt(violation) / scale


#: Work entries of :func:`_jacobian`: ``2 dim^2 + 2 dim`` (each contact's ``D``, ``G`` and two
#: vectors) for contacts of at most 3 rows.
JACOBIAN_WORK = 24


@njit
def _jacobian(W, r, u, mu, dim, exact, eps, J, work):
    """``J = I - D + G (W + eps I)``, ``G = D (I + E)`` (see :func:`newton._jacobian`), dense ``(n, n)``;
    ``work``: at least ``2 dim^2 + 2 dim`` entries (each contact's ``D``, ``G`` (row-major, ``D[k dim + l]``)
    and two vectors), written over."""
    n = r.size
    D = work[0:dim * dim]
    G = work[dim * dim:2 * dim * dim]
    y = work[2 * dim * dim:2 * dim * dim + dim]
    col = work[2 * dim * dim + dim:2 * dim * dim + 2 * dim]
    for c in range(n // dim):
        i = c * dim
        norm_t = _tangent_norm(u, i, dim) if exact else 0.0
        for k in range(dim):
            y[k] = r[i + k] - u[i + k]
        y[0] -= mu[c] * norm_t
        # D: generalised Jacobian of the projection at y (cone.project_jacobian)
        rho = _tangent_norm(y, np.int64(0), dim)  # not a literal 0 (_jit)
        for k in range(dim * dim):
            D[k] = 0.0
        if rho <= mu[c] * y[0] and y[0] >= 0.0:
            for k in range(dim):
                D[k * dim + k] = 1.0
        else:
            s = 1.0 / (1.0 + mu[c] * mu[c])
            a = (y[0] + mu[c] * rho) * s
            if a > 0.0:
                safe = rho if rho > 0.0 else 1.0
                col[0] = 1.0
                for k in range(1, dim):
                    col[k] = mu[c] * y[k] / safe
                for k in range(dim):
                    for l in range(dim):
                        D[k * dim + l] = col[k] * col[l] * s
                if dim == 3:
                    curv = mu[c] * a / safe
                    for k in range(1, 3):
                        for l in range(1, 3):
                            D[k * dim + l] += curv * ((1.0 if k == l else 0.0) - y[k] * y[l] / (safe * safe))
        # G = D (I + E), E[N, T] = mu u_T / ||u_T||
        for k in range(dim * dim):
            G[k] = D[k]
        if exact and norm_t > 0.0:
            for k in range(dim):
                for l in range(1, dim):
                    G[k * dim + l] += D[k * dim] * mu[c] * u[i + l] / norm_t
        for k in range(dim):
            for j in range(n):
                total = 0.0
                for l in range(dim):
                    total += G[k * dim + l] * W[i + l, j]
                J[i + k, j] = total
            for l in range(dim):
                J[i + k, i + l] += eps * G[k * dim + l] - D[k * dim + l] + (1.0 if k == l else 0.0)


@njit_helper
def _lu_solve(A, b, x):
    """Solve ``A x = b`` by Gaussian elimination with partial pivoting (``A`` overwritten).

    Returns False when a pivot is exactly zero or ``x`` is not finite (as LAPACK ``dgesv``'s
    ``info > 0`` and the finiteness check of :func:`newton._newton_direction`).
    """
    n = b.size
    for i in range(n):
        x[i] = b[i]
    for k in range(n):
        p = k
        big = abs(A[k, k])
        for i in range(k + 1, n):
            if abs(A[i, k]) > big:
                big = abs(A[i, k])
                p = i
        if big == 0.0:
            return False
        if p != k:
            for j in range(n):
                A[k, j], A[p, j] = A[p, j], A[k, j]
            x[k], x[p] = x[p], x[k]
        # the pivot row's last nonzero column: the rows below change before it only (an entry
        # past it would change by factor * 0), so a band of width b, as the problems of a chain
        # of joints have (a stack's, an arch's), takes about n b^2 multiply-adds, not n^3 / 3
        end = n
        while end > k + 1 and A[k, end - 1] == 0.0:
            end -= 1
        for i in range(k + 1, n):
            factor = A[i, k] / A[k, k]
            if factor != 0.0:
                for j in range(k + 1, end):
                    A[i, j] -= factor * A[k, j]
                x[i] -= factor * x[k]
    for k in range(n - 1, -1, -1):
        total = x[k]
        for j in range(k + 1, n):
            total -= A[k, j] * x[j]
        x[k] = total / A[k, k]
    return _all_finite(x)


@njit_helper(inline=True)
def _copy(source, target):
    """``target[:] = source`` for vectors of one length, as an explicit loop (a slice
    assignment compiles numpy's broadcasting and its error messages: seconds of compilation)."""
    for i in range(target.size):
        target[i] = source[i]


@njit_helper
def _all_finite(x):
    """Whether every entry of the vector ``x`` is finite."""
    for k in range(x.size):
        if not math.isfinite(x[k]):
            return False
    return True


@njit_helper
def _lm_solve(J, f, lam, A, x):
    """Levenberg–Marquardt direction ``(J^T J + lam I) x = -J^T f`` by Cholesky (``A``: work).

    Returns False when the matrix is not numerically positive definite or ``x`` is not finite.
    """
    n = f.size
    for i in range(n):
        for j in range(i + 1):
            total = 0.0
            for k in range(n):
                total += J[k, i] * J[k, j]
            A[i, j] = total
        A[i, i] += lam
        total = 0.0
        for k in range(n):
            total += J[k, i] * f[k]
        x[i] = -total
    # A = L L^T in the lower triangle
    for j in range(n):
        total = A[j, j]
        for k in range(j):
            total -= A[j, k] * A[j, k]
        if not total > 0.0:
            return False
        A[j, j] = math.sqrt(total)
        for i in range(j + 1, n):
            total = A[i, j]
            for k in range(j):
                total -= A[i, k] * A[j, k]
            A[i, j] = total / A[j, j]
    for i in range(n):
        total = x[i]
        for k in range(i):
            total -= A[i, k] * x[k]
        x[i] = total / A[i, i]
    for i in range(n - 1, -1, -1):
        total = x[i]
        for k in range(i + 1, n):
            total -= A[k, i] * x[k]
        x[i] = total / A[i, i]
    return _all_finite(x)


#: Work vectors of ``n`` entries of :func:`solve_dense`'s problem (d, the scaled q, the scaled
#: start, the best and the run's r and u), before its scaled ``W`` and the Newton's work.
_SOLVE_VECTORS = 7
#: Work vectors of ``n`` entries of :func:`_newton` (y, u, f, the direction, the Newton step,
#: -f, the trial r, u and f), then its two ``n x n`` matrices (J and the factored one).
_NEWTON_VECTORS, _NEWTON_MATRICES = 9, 2


@njit_helper
def _newton_work(n, max_iter):
    """Entries of :func:`_newton`'s ``work`` for ``n`` unknowns and ``max_iter`` iterations."""
    return (_NEWTON_VECTORS + TEST_VECTORS) * n + _NEWTON_MATRICES * n * n + max_iter + 1 + JACOBIAN_WORK


@njit_helper
def _newton(Ws, qs, mu, dim, exact, max_iter, patience, tol, r, scaling, best_r, best_u, work):
    """Semismooth Newton of :func:`nscd.solver.newton.solve` on the scaled problem, from ``r``.

    ``scaling = (d, sigma, q_norm, lower)`` gives the unscaled acceptance test; ``patience``
    (> 0) ends the run once ``||F||`` has not fallen below :data:`_STALL` times its value
    ``patience`` iterations before (0: only ``max_iter`` ends it). Writes the
    iterate of smallest ``||F||`` (or the accepted one) to ``best_r``, ``best_u``; returns
    ``(accepted, unscaled merit or NaN if not evaluated, iterations, smallest ||F||, ||F|| at r)``.
    ``work``: at least :func:`_newton_work` entries, written over (the run's vectors, matrices,
    history of ``||F||``, and the work of the Jacobian and of the acceptance test), so that a
    run allocates nothing.
    """
    d, sigma, q_norm, lower = scaling
    n = qs.size
    y, u, f = _vector(work, 0, n), _vector(work, 1, n), _vector(work, 2, n)
    direction, newton_step, minus_f = _vector(work, 3, n), _vector(work, 4, n), _vector(work, 5, n)
    r_try, u_try, f_try = _vector(work, 6, n), _vector(work, 7, n), _vector(work, 8, n)
    at = _NEWTON_VECTORS * n
    test_work = work[at:at + TEST_VECTORS * n]
    at += TEST_VECTORS * n
    J = work[at:at + n * n].reshape((n, n))
    A = work[at + n * n:at + 2 * n * n].reshape((n, n))
    at += _NEWTON_MATRICES * n * n
    history = work[at:at + max_iter + 1]
    jacobian_work = work[at + max_iter + 1:at + max_iter + 1 + JACOBIAN_WORK]
    _affine(Ws, r, qs, u)
    norm_f = _natural_map(r, u, mu, dim, exact, y, f)
    first_norm = norm_f
    value = math.nan
    done = False
    if lower * norm_f <= tol:
        value, gap = _unscaled_test(r, u, d, sigma, mu, dim, exact, q_norm, test_work)
        done = value <= tol and gap <= tol
    best_norm, best_value = norm_f, value
    _copy(r, best_r)
    _copy(u, best_u)
    k = 0
    watchdog = 0
    history[0] = norm_f
    while not done and k < max_iter:
        if patience > 0 and k >= patience and norm_f > _STALL * history[k - patience]:
            break
        k += 1
        _jacobian(Ws, r, u, mu, dim, exact, norm_f, J, jacobian_work)
        for i in range(n):
            for j in range(n):
                A[i, j] = J[i, j]
        for i in range(n):
            minus_f[i] = -f[i]
        newton_ok = _lu_solve(A, minus_f, newton_step)
        accepted = False
        norm_try = math.inf
        for attempt in range(1 + len(_LM_ONLY)):
            if attempt == 0:
                ok = newton_ok
                _copy(newton_step, direction)
            else:
                ok = _lm_solve(J, f, _LM_ONLY[attempt - 1] * norm_f, A, direction)
            step = 1.0
            while ok and step >= _MIN_STEP:
                norm_try = _trial(Ws, qs, mu, dim, exact, r, direction, step, r_try, u_try, y, f_try)
                if norm_try <= (1.0 - _ARMIJO * step) * norm_f:
                    accepted = True
                    break
                step *= 0.5
            if accepted:
                break
        if not accepted:
            # stuck at a kink of ||F||: a full regularised Newton step anyway (watchdog)
            watchdog += 1
            if not newton_ok or watchdog > _WATCHDOG:
                break
            norm_try = _trial(Ws, qs, mu, dim, exact, r, newton_step, 1.0, r_try, u_try, y, f_try)
        else:
            watchdog = 0
        _copy(r_try, r)
        _copy(u_try, u)
        _copy(f_try, f)
        norm_f = norm_try
        history[k] = norm_f
        value = math.nan
        if lower * norm_f <= tol:
            value, gap = _unscaled_test(r, u, d, sigma, mu, dim, exact, q_norm, test_work)
            done = value <= tol and gap <= tol
        if done or norm_f < best_norm:
            best_norm, best_value = norm_f, value
            _copy(r, best_r)
            _copy(u, best_u)
    return done, best_value, k, best_norm, first_norm


@njit_helper
def scale_factors(W, q, dim, d):
    """Scaling of the problem ``(W, q)`` (:class:`nscd.solver.core._Scaled`): writes the per-row
    factors ``d`` (``d_c = 1 / sqrt(max(W_NN,c, floor))`` on each of contact ``c``'s rows) and
    returns ``(sigma, ||q||_2)`` with ``sigma = ||D q||_inf`` (0: the trivial problem ``q = 0``)."""
    n = q.size
    diag_max = 0.0
    for c in range(n // dim):
        diag_max = max(diag_max, W[c * dim, c * dim])
    floor = max(diag_max, 1.0) * 1e-14
    for c in range(n // dim):
        dc = max(W[c * dim, c * dim], floor) ** -0.5
        for k in range(dim):
            d[c * dim + k] = dc
    sigma = 0.0
    q_norm = 0.0
    for i in range(n):
        sigma = max(sigma, abs(d[i] * q[i]))
        q_norm += q[i] * q[i]
    return sigma, math.sqrt(q_norm)


@njit
def solve_dense(W, q, mu, sizes, dim, r0, tol, exact, max_iter, patience, restart_above, r, u, merit, info):
    """Solve ``B`` padded small problems ``u = W r + q`` by compiled semismooth Newton.

    Results go to caller-allocated arrays (returning new arrays from a compiled
    function costs ~1 us each in boxing, as much as solving a 2-contact problem).

    Parameters
    ----------
    W : ndarray, shape (B, n_max, n_max), float64, C-contiguous
        Delassus matrices; problem ``b`` uses ``W[b, :sizes[b], :sizes[b]]`` only.
    q : ndarray, shape (B, n_max)
        Free relative velocities (unit of ``u``), rows per contact ``[N, T1, (T2)]``.
    mu : ndarray, shape (B, n_max // dim)
        Friction coefficients, ``>= 0``.
    sizes : ndarray of int64, shape (B,)
        Unknowns of each problem, multiples of ``dim``, ``<= n_max``.
    dim : int
        2 or 3.
    r0 : ndarray, shape (B, n_max)
        Starting impulses (zeros for a cold start).
    tol : float
        Acceptance level of the unscaled merit and dual-cone violation.
    exact : bool
        Exact Coulomb (De Saxcé shift) or the relaxed cone.
    max_iter : int
        Newton iterations per start (warm, then cold if the warm start fails).
    patience : int
        Stall test of each start: it ends when ``||F||`` has not fallen below
        :data:`_STALL` times its value ``patience`` iterations before; 0: no stall test.
    restart_above : float
        A warm start the Newton does not take to ``tol`` is followed by a run from ``r = 0``
        when that run's smallest ``||F||`` stayed above ``restart_above`` times ``||F||`` at
        the warm start (0: always; :data:`JUNK_START`: only a warm start it could not even
        halve ``||F||`` from; ``inf``: never).
    r, u : ndarray, shape (B, n_max), output
        Best iterate (unit of ``r0``) and ``u = W r + q`` (computed in scaled units);
        entries beyond ``sizes[b]`` are left untouched.
    merit : ndarray, shape (B,), output
        Unscaled FCLIB merit of that iterate.
    info : ndarray of int64, shape (B, 2), output
        Per problem the outcome (:data:`ACCEPTED`, :data:`NOT_ACCEPTED` or :data:`TRIVIAL`
        for ``q = 0``) and the Newton iterations taken.
    """
    # each problem scaled, solved by :func:`_newton` (again from zero if a warm start fails)
    # and unscaled, in this one function: a compiled callee is optimised again inside each
    # caller, so one level less of calls is seconds less of the first run's compilation
    # one work array for every problem of the call, laid out for each problem by its own size
    n_max = q.shape[1]
    work = np.empty(_SOLVE_VECTORS * n_max + n_max * n_max + _newton_work(n_max, max_iter))
    for b in range(q.shape[0]):
        n = sizes[b]
        W_b, q_b, mu_b, r0_b = W[b, :n, :n], q[b, :n], mu[b, :n // dim], r0[b, :n]
        r_out, u_out = r[b, :n], u[b, :n]
        m = n // dim
        d = _vector(work, 0, n)
        sigma, q_norm = scale_factors(W_b, q_b, dim, d)
        if sigma == 0.0:
            for i in range(n):
                r_out[i] = 0.0
                u_out[i] = q_b[i]
            info[b, 0], merit[b], info[b, 1] = TRIVIAL, 0.0, 0
            continue
        qs, r_scaled = _vector(work, 1, n), _vector(work, 2, n)
        best_r, best_u = _vector(work, 3, n), _vector(work, 4, n)
        run_r, run_u = _vector(work, 5, n), _vector(work, 6, n)
        at = _SOLVE_VECTORS * n
        Ws = work[at:at + n * n].reshape((n, n))
        newton_work = work[at + n * n:at + n * n + _newton_work(n, max_iter)]
        warm = False
        for i in range(n):
            for j in range(n):
                Ws[i, j] = W_b[i, j] * d[i] * d[j]
            qs[i] = q_b[i] * d[i] / sigma
            r_scaled[i] = r0_b[i] / (sigma * d[i])
            warm = warm or r_scaled[i] != 0.0
        # lower bound of (unscaled merit) / (scaled ||F||) (core._Scaled.newton)
        lower = math.inf
        for c in range(m):
            dc = d[c * dim]
            lower = min(lower, dc * min(1.0, 1.0 / (dc * dc)))
        lower *= sigma / (1.0 + math.sqrt(q_norm))
        scaling = (d, sigma, q_norm, lower)

        done, value, iterations, norm_f = False, math.nan, 0, math.inf
        # From the warm start, then (warm start only) from zero: a warm start far from this
        # problem's solution can trap Newton at a kink of ||F|| or in a slow region.
        for start in range(2 if warm else 1):
            if start == 1:
                r_scaled[:] = 0.0
            run_done, run_value, run_iterations, run_norm, first_norm = _newton(
                Ws, qs, mu_b, dim, exact, max_iter, patience, tol, r_scaled, scaling, run_r, run_u, newton_work)
            iterations += run_iterations
            if start == 0 or run_done or run_norm < norm_f:
                done, value, norm_f = run_done, run_value, run_norm
                _copy(run_r, best_r)
                _copy(run_u, best_u)
            if done or run_norm <= restart_above * first_norm:
                break
        if math.isnan(value):
            value = _unscaled_test(best_r, best_u, d, sigma, mu_b, dim, exact, q_norm, newton_work)[0]
        for i in range(n):
            r_out[i] = sigma * d[i] * best_r[i]
            u_out[i] = sigma * best_u[i] / d[i]
        info[b, 0], merit[b], info[b, 1] = (ACCEPTED if done else NOT_ACCEPTED), value, iterations
