"""Proximal-point outer loop for contact problems at the friction limit.

When a problem ``u = W r + q`` is degenerate — contacts sliding at the friction limit
everywhere, redundant contact points (two per joint in 2D) so that ``W`` is singular —
the impulses are not unique and the De Saxcé shift ``mu ||u_T||`` switches contacts
between sticking and sliding from one iterate to the next: the semismooth Newton
(:mod:`.small`, :mod:`.newton`) and the Gauss–Seidel sweeps stall (``docs/solver.md``).
The proximal-point method (Rockafellar 1976; Siconos' ``FC3D_PROX``, Acary & Brogliato,
*Numerical Methods for Nonsmooth Dynamical Systems*, 2008) solves instead a sequence of
problems of the same kind, each well posed (``W + alpha I`` is positive definite):

    r_{k+1} solves  K ∋ r ⊥ u + alpha (r - r_k) + mu ||u_T|| e_N ∈ K*,  u = W r + q,

that is the exact-Coulomb problem with ``W + alpha I`` and ``q - alpha r_k``, in the
solver's scaled units (:class:`nscd.solver.core._Scaled`: ``diag W = 1`` on normal rows,
so ``alpha`` is dimensionless; in physical units the regularisation is ``alpha W_NN`` per
contact). A fixed point ``r_{k+1} = r_k`` solves the original problem exactly: the
regularisation is removed by the outer loop, exact Coulomb is kept, and each iterate is
tested on the *original* problem's merit. Each inner problem is solved warm, from
``r_k``, by the semismooth Newton.

Two entries: :func:`solve_dense`, compiled, for dense problems (the small problems the
compiled Newton of the fast path does not accept, and dense large ones after the sweeps): the
whole loop, its inner Newton (:mod:`.small`) and the polish after it in one compiled call over
a batch; :func:`solve` for a sparse ``W`` (large problems after the sweeps), the inner problems
by :mod:`.newton` with scipy's factorisations. :func:`fast_path` is the solver's compiled fast
path of small problems, the Newton and then :func:`solve_dense` on those it does not accept,
in one compiled call: the one source of :func:`nscd.solver.core.newton_batch` (the general
step's stage 9, :func:`nscd.solver.core.solve_batch`) and of the compiled steps
(:mod:`nscd.compiled_step`).

``alpha`` follows Siconos' adaptive rule: ``alpha = sigma e`` with ``e`` the relative
merit of the current iterate and ``sigma = 5`` (large steps of a strongly regularised
problem far from a solution, nearly the original problem close to one), multiplied by 10
when an inner solve fails (its best iterate is taken only if it lowers the original
merit); the next success keeps that ``alpha`` rather than lowering it at once. The inner
tolerance is a tenth of the current natural-map norm of the original problem (Siconos'
adaptive internal tolerance; at ``r_k`` both problems have the same velocities, hence
the same natural map).

The loop ends at the caller's acceptance test, after ``max_outer`` inner solves, when
``alpha`` has grown beyond ``1e6`` (every inner solve fails), or when it has stalled (its best
merit, above 100 ``tol``, fell by less than 10 % over the last 30 inner solves). The best iterate (smallest
merit) is returned; :func:`solve_dense` then polishes it (the Newton on the original problem)
when it is not accepted.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from nscd._jit import njit, njit_helper
from nscd.solver import cone, newton, small

# Siconos' defaults (fc3d_proximal_set_default): alpha = sigma * error ** nu with sigma = 5,
# nu = 1, multiplied by 10 after a failed inner solve; inner tolerance = error / 10.
_SIGMA = 5.0
_GROWTH = 10.0
_INNER_RATIO = 10.0
# An alpha this large means the inner problems fail however regularised: give up.
_MAX_ALPHA = 1e6
# Give up too when the loop has stalled: its best merit, still above 100 tol, fell by less than
# 10 % (a factor 0.9) over the last 30 inner problems. On the three-block stack's double-pulse
# map (7 600 problems the Newton leaves to the proximal point, docs/solver.md) the 104 problems
# the loop never accepts sit at their first few iterates' merit (median 1e-3) and would spend
# the whole ``max_outer`` (120 inner problems, about 1 350 Newton iterations each) for nothing;
# of the 7 492 it accepts, one lowered its best merit by less than that over 30 inner problems
# before its acceptance. Near the tolerance a flat best merit may still end in a jump (the 4 x 3
# wall of tests/test_wall_breakup.py: 7.2e-8 for 46 inner problems, then converged), so the
# test leaves a loop alone below 100 tol.
_STALL_WINDOW = 30
_STALL_GAIN = 0.9
_STALL_FLOOR = 100.0


@dataclass
class ProximalResult:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    r : ndarray, shape (n,)
        Best iterate (smallest merit of the original problem), unit of ``r0``.
    merit : float
        The caller's merit of ``r``.
    converged : bool
        The caller's acceptance test passed.
    outer : int
        Inner problems solved (outer iterations).
    inner : int
        Newton iterations of all inner solves.
    """

    r: np.ndarray
    merit: float
    converged: bool
    outer: int
    inner: int


@njit_helper
def _next_alpha(alpha, relative, accepted, recovering):
    """Siconos' rule: the next ``alpha`` after an inner solve (``accepted`` or not) from an
    iterate of relative merit ``relative``, and whether the loop is recovering from a failure."""
    if accepted:
        # the first success after a failure keeps its alpha (lowering it at once would fail
        # again: the cycle fail, x10, success, lower costs a failed solve every other step)
        return (max(_SIGMA * relative, alpha) if recovering else _SIGMA * relative), False
    return alpha * _GROWTH, True  # too weakly regularised for the inner Newton: regularise more


def _inner_sparse(W, alpha: float, q: np.ndarray, mu: np.ndarray, dim: int, r0: np.ndarray, exact: bool,
                  target: float, max_iter: int) -> tuple[np.ndarray, bool, int]:
    """The inner problem ``W + alpha I``, ``q`` (sparse ``W``) by :func:`.newton.solve` (scipy's
    factorisations), from ``r0``, to a natural-map norm of ``target``: ``(r, accepted, iterations)``."""
    W_inner = sp.csr_matrix(W + alpha * sp.identity(q.size, format="csr"))
    res = newton.solve(W_inner, q, mu, dim, r0, exact, max_iter, lambda r, u, norm_f: (None, norm_f <= target),
                       lambda r, u: math.nan)
    return res.r, res.converged, res.iterations


def solve(W, q: np.ndarray, mu: np.ndarray, dim: int, r0: np.ndarray, exact: bool, max_outer: int,
          max_inner: int, measure: Callable[[np.ndarray, np.ndarray], tuple[float, float, bool]],
          tol: float) -> ProximalResult:
    """Proximal-point iterations on the scaled sparse problem ``u = W r + q`` from ``r0``.

    Parameters
    ----------
    W : scipy.sparse matrix, shape (n, n)
        Delassus matrix in the solver's scaled units (unit normal diagonal, rows per contact
        ``[N, T1, (T2)]``); a dense problem goes to :func:`solve_dense`.
    q : ndarray, shape (n,)
        Free relative velocity (scaled).
    mu : ndarray, shape (n // dim,)
        Friction coefficients, ``>= 0``.
    dim : int
        2 or 3.
    r0 : ndarray, shape (n,)
        Starting impulses (scaled).
    exact : bool
        Exact Coulomb (De Saxcé shift) or the relaxed cone, as the caller's problem.
    max_outer : int
        Maximum inner problems, >= 1.
    max_inner : int
        Newton iterations allowed per inner problem, from its warm start.
    measure : callable
        ``measure(r, u) -> (merit, relative merit, accepted)`` of the original problem
        (``u = W r + q``), the caller's acceptance test.
    tol : float
        The caller's absolute tolerance on the merit (the stall test leaves the loop alone below
        ``_STALL_FLOOR * tol``).

    Returns
    -------
    ProximalResult
    """
    r = np.ascontiguousarray(r0, dtype=float).copy()
    u = W @ r + q
    merit, relative, done = measure(r, u)
    best = ProximalResult(r.copy(), merit, done, 0, 0)
    alpha = _SIGMA * relative
    recovering = False
    bests = np.empty(max_outer + 1)  # the best merit after each inner problem (the stall test)
    bests[0] = merit
    while (not best.converged and best.outer < max_outer and alpha <= _MAX_ALPHA
           and not _stalled(bests, best.outer, tol)):
        best.outer += 1
        # at r_k the inner problem's velocity equals the original one's, so is its natural map
        target = float(np.linalg.norm(cone.natural_map(r.reshape(-1, dim), u.reshape(-1, dim), mu, exact)))
        trial, accepted, iterations = _inner_sparse(W, alpha, q - alpha * r, mu, dim, r, exact, target / _INNER_RATIO,
                                                  max_inner)
        best.inner += iterations
        trial_u = W @ trial + q
        trial_merit, trial_relative, done = measure(trial, trial_u)
        if accepted or trial_merit < merit:
            r, u, merit, relative = trial, trial_u, trial_merit, trial_relative
            if done or merit < best.merit:
                best.r, best.merit, best.converged = r.copy(), merit, done
        alpha, recovering = _next_alpha(alpha, relative, accepted, recovering)
        bests[best.outer] = best.merit
    return best


@njit_helper
def _stalled(bests, outer, tol):
    """Whether the loop has stalled after ``outer`` inner problems (``bests`` (>= outer + 1,): the
    best merit after each, ``bests[0]`` the start's): its best merit, still above
    ``_STALL_FLOOR * tol``, fell by less than a factor ``_STALL_GAIN`` over the last
    ``_STALL_WINDOW`` inner problems. The one test of the dense (compiled) and the sparse loop."""
    return (outer >= _STALL_WINDOW and bests[outer] > _STALL_FLOOR * tol
            and bests[outer] > _STALL_GAIN * bests[outer - _STALL_WINDOW])


#: Work vectors of ``n`` entries of :func:`_measure`: the acceptance test's, then unit factors.
MEASURE_VECTORS = small.TEST_VECTORS + 1


@njit_helper
def _measure(r, u, q, d, sigma, mu, dim, exact, q_norm, tol, tol_relative, work):
    """The acceptance test of :meth:`nscd.solver.core._Scaled.stop_relative` on the scaled pair
    ``(r, u)`` of a problem scaled by ``d``, ``sigma`` (unscaled ``||q||_2 = q_norm``; ``q`` the
    scaled one): ``(unscaled merit, relative merit, accepted)`` (``tol_relative <= 0``: the
    absolute test alone). ``work``: at least :data:`MEASURE_VECTORS` ``* n`` entries, written over."""
    n = r.size
    test_work = work[0:small.TEST_VECTORS * n]
    ones = small._vector(work, small.TEST_VECTORS, n)
    value, gap = small._unscaled_test(r, u, d, sigma, mu, dim, exact, q_norm, test_work)
    for i in range(n):
        ones[i] = 1.0
    scaled_value, scaled_gap = small._unscaled_test(r, u, ones, 1.0, mu, dim, exact, 0.0, test_work)
    size = 0.0
    q_size = 0.0
    for i in range(r.size):
        size += r[i] * r[i]
        q_size += q[i] * q[i]
    relative = max(scaled_value, scaled_gap) / max(math.sqrt(size), math.sqrt(q_size))
    done = (value <= tol and gap <= tol) or (tol_relative > 0.0 and relative <= tol_relative)
    return value, relative, done


@njit
def solve_dense(W, q, mu, sizes, dim, r0, tol, tol_relative, exact, max_outer, max_inner, max_polish, r, u, merit,
                info):
    """Proximal-point iterations, then the polish, on ``B`` padded dense problems, compiled.

    Each problem is scaled as :class:`nscd.solver.core._Scaled` scales it and iterated from
    ``r0`` in those units; each inner problem ``W' + alpha I``, ``q' - alpha r_k`` is solved
    by :func:`nscd.solver.small.solve_dense` from ``r_k`` (no restart from zero: ``r_k`` is the
    natural start; no stall test) to a tenth of the current natural-map norm. A best iterate
    the loop does not accept is polished by :func:`nscd.solver.small.solve_dense` on the
    original problem (``max_polish`` Newton iterations from it, then from zero; 0: no polish).

    Parameters
    ----------
    W, q, mu, sizes, dim, r0, tol, exact
        As :func:`nscd.solver.small.solve_dense` (``r0``: the starting impulses).
    tol_relative : float
        Also accept a relative merit (:meth:`nscd.solver.core._Scaled.relative`) at most this;
        ``<= 0``: the absolute ``tol`` alone.
    max_outer : int
        Inner problems at most (>= 1).
    max_inner : int
        Newton iterations per inner problem and start.
    max_polish : int
        Newton iterations of the polish per start.
    r, u, merit : ndarray, output
        As :func:`nscd.solver.small.solve_dense`: the accepted (or best) iterate, its
        velocities and unscaled merit.
    info : ndarray of int64, shape (B, 4), output
        Per problem the outcome (:data:`~nscd.solver.small.PROXIMAL`,
        :data:`~nscd.solver.small.PROXIMAL_POLISHED`, :data:`~nscd.solver.small.NOT_ACCEPTED`
        or :data:`~nscd.solver.small.TRIVIAL`), the inner problems solved, their Newton
        iterations and the polish's Newton iterations.
    """
    for b in range(q.shape[0]):
        n = sizes[b]
        m = n // dim
        W_b, q_b, r0_b = W[b, :n, :n], q[b, :n], r0[b, :n]
        mu_b = np.empty((1, m))
        for c in range(m):
            mu_b[0, c] = mu[b, c]
        d = np.empty(n)
        sigma, q_norm = small.scale_factors(W_b, q_b, dim, d)
        info[b, 1], info[b, 2], info[b, 3] = 0, 0, 0
        if sigma == 0.0:
            for i in range(n):
                r[b, i] = 0.0
                u[b, i] = q_b[i]
            info[b, 0], merit[b] = small.TRIVIAL, 0.0
            continue
        # the scaled problem (W' = D W D, q' = D q / sigma) and the start in its units
        W_inner = np.empty((1, n, n))
        Ws = np.empty((n, n))
        qs = np.empty(n)
        x = np.empty(n)
        for i in range(n):
            for j in range(n):
                Ws[i, j] = W_b[i, j] * d[i] * d[j]
            qs[i] = q_b[i] * d[i] / sigma
            x[i] = r0_b[i] / (sigma * d[i])
        xu = np.empty(n)
        small._affine(Ws, x, qs, xu)
        measure_work = np.empty(MEASURE_VECTORS * n)
        value, relative, done = _measure(x, xu, qs, d, sigma, mu_b[0], dim, exact, q_norm, tol, tol_relative,
                                         measure_work)
        best = x.copy()
        best_value, converged = value, done
        alpha = _SIGMA * relative
        recovering = False
        outer, inner = 0, 0
        y, f = np.empty(n), np.empty(n)
        q_inner = np.empty((1, n))
        start = np.empty((1, n))
        trial, trial_u = np.empty((1, n)), np.empty((1, n))
        inner_merit, inner_info = np.empty(1), np.empty((1, 2), dtype=np.int64)
        one = np.full(1, n)
        # no stall test: a patience of 0, not a literal 0 (a literal compiles small.solve_dense
        # once more for that value, nscd._jit)
        no_stall = np.int64(0)
        bests = np.empty(max_outer + 1)  # the best merit after each inner problem (the stall test)
        bests[0] = best_value
        while not converged and outer < max_outer and alpha <= _MAX_ALPHA and not _stalled(bests, outer, tol):
            outer += 1
            # at r_k the inner problem's velocity equals the original one's, so is its natural map
            target = small._natural_map(x, xu, mu_b[0], dim, exact, y, f) / _INNER_RATIO
            inner_norm = 0.0
            for i in range(n):
                for j in range(n):
                    W_inner[0, i, j] = Ws[i, j]
                W_inner[0, i, i] += alpha
                q_inner[0, i] = qs[i] - alpha * x[i]
                start[0, i] = x[i]
                inner_norm += q_inner[0, i] * q_inner[0, i]
            # the kernel's acceptance is FCLIB's merit, the natural-map norm over 1 + sqrt(||q||)
            inner_tol = target / (1.0 + math.sqrt(math.sqrt(inner_norm)))
            # no stall test (the inner problems of a wall sliding at the friction limit crawl and
            # then converge), no restart from zero (r_k is the start)
            small.solve_dense(W_inner, q_inner, mu_b, one, dim, start, inner_tol, exact, max_inner, no_stall, math.inf,
                              trial, trial_u, inner_merit, inner_info)
            inner += inner_info[0, 1]
            accepted = inner_info[0, 0] != small.NOT_ACCEPTED
            small._affine(Ws, trial[0], qs, y)
            trial_value, trial_relative, done = _measure(trial[0], y, qs, d, sigma, mu_b[0], dim, exact, q_norm,
                                                         tol, tol_relative, measure_work)
            if accepted or trial_value < value:
                small._copy(trial[0], x)
                small._copy(y, xu)
                value, relative = trial_value, trial_relative
                if done or value < best_value:
                    small._copy(x, best)
                    best_value, converged = value, done
            alpha, recovering = _next_alpha(alpha, relative, accepted, recovering)
            bests[outer] = best_value
        info[b, 1], info[b, 2] = outer, inner
        code = small.PROXIMAL if converged else small.NOT_ACCEPTED
        for i in range(n):
            start[0, i] = sigma * d[i] * best[i]
        if not converged and max_polish > 0:
            # the Newton on the original problem from the best iterate
            small.solve_dense(W[b:b + 1], q[b:b + 1], mu_b, one, dim, start, tol, exact, max_polish, no_stall, 0.0,
                              trial, trial_u, inner_merit, inner_info)
            info[b, 3] = inner_info[0, 1]
            if inner_info[0, 0] == small.ACCEPTED or inner_merit[0] < best_value:
                code = small.PROXIMAL_POLISHED if inner_info[0, 0] == small.ACCEPTED else code
                best_value = inner_merit[0]
                for i in range(n):
                    r[b, i] = trial[0, i]
                    u[b, i] = trial_u[0, i]
                info[b, 0], merit[b] = code, best_value
                continue
        small._affine(Ws, best, qs, xu)
        for i in range(n):
            r[b, i] = start[0, i]
            u[b, i] = sigma * xu[i] / d[i]
        info[b, 0], merit[b] = code, best_value


@njit
def fast_path(W, q, mu, sizes, dim, r0, tol, tol_relative, exact, max_fast, max_proximal, max_polish,
              proximal_unknowns, r, u, merit, info):
    """The compiled fast path of ``B`` padded dense problems: the semismooth Newton, then the
    proximal point and its polish on the problems it does not accept, in one compiled call.

    The Newton is :func:`nscd.solver.small.solve_dense` with the fast path's stall test and
    restart (:data:`~nscd.solver.small.FAST_PATIENCE`, :data:`~nscd.solver.small.JUNK_START`);
    a problem it does not accept, of at most ``proximal_unknowns`` unknowns, goes through
    :func:`solve_dense` from the Newton's best iterate (unless ``max_proximal == 0``). Each
    problem gives bitwise the same result alone or in a batch. The one source of
    :func:`nscd.solver.core.newton_batch` and of the compiled steps' stage 9
    (:mod:`nscd.compiled_step`).

    Parameters
    ----------
    W, q, mu, sizes, dim, r0, tol, exact
        As :func:`nscd.solver.small.solve_dense` (``r0``: the warm start).
    tol_relative, max_polish
        As :func:`solve_dense` (``tol_relative <= 0``: the absolute ``tol`` alone;
        ``max_polish == 0``: no polish).
    max_fast : int
        Newton iterations per start, of the fast path and of each inner problem.
    max_proximal : int
        Inner problems of the proximal point at most (0: no proximal point).
    proximal_unknowns : int
        Largest problem (unknowns) given the proximal point.
    r, u, merit : ndarray, output
        As :func:`nscd.solver.small.solve_dense`.
    info : ndarray of int64, shape (B, 5), output
        Per problem the outcome (:data:`~nscd.solver.small.ACCEPTED`,
        :data:`~nscd.solver.small.TRIVIAL`, :data:`~nscd.solver.small.PROXIMAL`,
        :data:`~nscd.solver.small.PROXIMAL_POLISHED` or :data:`~nscd.solver.small.NOT_ACCEPTED`:
        ``r`` its best iterate), the Newton iterations, the inner problems of the proximal
        point, their Newton iterations and the polish's (0 where not run).
    """
    batch = q.shape[0]
    newton_info = np.empty((batch, 2), dtype=np.int64)
    # the patience as a variable, not the global's literal: the one specialisation of the Newton
    # that solve_dense's inner problems and polish call too (nscd._jit)
    small.solve_dense(W, q, mu, sizes, dim, r0, tol, exact, max_fast, np.int64(small.FAST_PATIENCE),
                      small.JUNK_START, r, u, merit, newton_info)
    start = np.empty((1, q.shape[1]))
    proximal_info = np.empty((1, 4), dtype=np.int64)
    for b in range(batch):
        info[b, 0], info[b, 1], info[b, 2], info[b, 3], info[b, 4] = newton_info[b, 0], newton_info[b, 1], 0, 0, 0
        if newton_info[b, 0] != small.NOT_ACCEPTED or sizes[b] > proximal_unknowns or max_proximal <= 0:
            continue
        # from the Newton's best iterate, written over by the proximal point's outcome
        for i in range(sizes[b]):
            start[0, i] = r[b, i]
        solve_dense(W[b:b + 1], q[b:b + 1], mu[b:b + 1], sizes[b:b + 1], dim, start, tol, tol_relative, exact,
                    max_proximal, max_fast, max_polish, r[b:b + 1], u[b:b + 1], merit[b:b + 1], proximal_info)
        info[b, 0], info[b, 2], info[b, 3], info[b, 4] = (proximal_info[0, 0], proximal_info[0, 1],
                                                          proximal_info[0, 2], proximal_info[0, 3])
