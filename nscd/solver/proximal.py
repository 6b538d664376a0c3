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
``r_k``: a dense ``W`` by the compiled Newton, a sparse one by :mod:`.newton`.

``alpha`` follows Siconos' adaptive rule: ``alpha = sigma e`` with ``e`` the relative
merit of the current iterate and ``sigma = 5`` (large steps of a strongly regularised
problem far from a solution, nearly the original problem close to one), multiplied by 10
when an inner solve fails (its best iterate is taken only if it lowers the original
merit); the next success keeps that ``alpha`` rather than lowering it at once. The inner
tolerance is a tenth of the current natural-map norm of the original problem (Siconos'
adaptive internal tolerance; at ``r_k`` both problems have the same velocities, hence
the same natural map).

The loop ends at the caller's acceptance test, after ``max_outer`` inner solves, or when
``alpha`` has grown beyond ``1e6`` (every inner solve fails). The best iterate (smallest
merit) is returned.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from nscd.solver import cone, newton, small

# Siconos' defaults (fc3d_proximal_set_default): alpha = sigma * error ** nu with sigma = 5,
# nu = 1, multiplied by 10 after a failed inner solve; inner tolerance = error / 10.
_SIGMA = 5.0
_GROWTH = 10.0
_INNER_RATIO = 10.0
# An alpha this large means the inner problems fail however regularised: give up.
_MAX_ALPHA = 1e6


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


def _inner_dense(W: np.ndarray, alpha: float, q: np.ndarray, mu: np.ndarray, dim: int, r0: np.ndarray,
                 exact: bool, target: float, max_iter: int) -> tuple[np.ndarray, bool, int]:
    """The inner problem ``W + alpha I``, ``q`` by the compiled Newton (:func:`.small.solve_dense`),
    from ``r0``, to a natural-map norm of ``target``: returns ``(r, accepted, iterations)``."""
    n = q.size
    W_inner = W[None].copy()
    W_inner[0].flat[::n + 1] += alpha
    r, u = np.empty((1, n)), np.empty((1, n))
    merit, info = np.empty(1), np.empty((1, 2), dtype=np.int64)
    # the kernel's acceptance is FCLIB's merit, the natural-map norm over 1 + sqrt(||q||)
    tol = target / (1.0 + math.sqrt(float(np.linalg.norm(q))))
    small.solve_dense(W_inner, q[None], np.ascontiguousarray(mu, dtype=float)[None], np.array([n]), dim,
                      r0[None], tol, exact, max_iter, r, u, merit, info)
    return r[0], bool(info[0, 0] == small.ACCEPTED), int(info[0, 1])


def _inner_sparse(W, alpha: float, q: np.ndarray, mu: np.ndarray, dim: int, r0: np.ndarray, exact: bool,
                  target: float, max_iter: int) -> tuple[np.ndarray, bool, int]:
    """The inner problem ``W + alpha I``, ``q`` (sparse ``W``) by :func:`.newton.solve` (scipy's
    factorisations), from ``r0``, to a natural-map norm of ``target``: ``(r, accepted, iterations)``."""
    W_inner = sp.csr_matrix(W + alpha * sp.identity(q.size, format="csr"))
    res = newton.solve(W_inner, q, mu, dim, r0, exact, max_iter, lambda r, u, norm_f: (None, norm_f <= target),
                       lambda r, u: math.nan)
    return res.r, res.converged, res.iterations


def solve(W, q: np.ndarray, mu: np.ndarray, dim: int, r0: np.ndarray, exact: bool, max_outer: int,
          max_inner: int, measure: Callable[[np.ndarray, np.ndarray], tuple[float, float, bool]]) -> ProximalResult:
    """Proximal-point iterations on the scaled problem ``u = W r + q`` from ``r0``.

    Parameters
    ----------
    W : ndarray or scipy.sparse matrix, shape (n, n)
        Delassus matrix in the solver's scaled units (unit normal diagonal, rows per contact
        ``[N, T1, (T2)]``): a dense C-contiguous float array is solved by the compiled
        Newton, a sparse one by :mod:`.newton`.
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

    Returns
    -------
    ProximalResult
    """
    inner_solve = _inner_dense if isinstance(W, np.ndarray) else _inner_sparse
    r = np.ascontiguousarray(r0, dtype=float).copy()
    u = W @ r + q
    merit, relative, done = measure(r, u)
    best = ProximalResult(r.copy(), merit, done, 0, 0)
    alpha = _SIGMA * relative
    recovering = False
    while not best.converged and best.outer < max_outer and alpha <= _MAX_ALPHA:
        best.outer += 1
        # at r_k the inner problem's velocity equals the original one's, so is its natural map
        target = float(np.linalg.norm(cone.natural_map(r.reshape(-1, dim), u.reshape(-1, dim), mu, exact)))
        trial, accepted, iterations = inner_solve(W, alpha, q - alpha * r, mu, dim, r, exact, target / _INNER_RATIO,
                                                  max_inner)
        best.inner += iterations
        trial_u = W @ trial + q
        trial_merit, trial_relative, done = measure(trial, trial_u)
        if accepted or trial_merit < merit:
            r, u, merit, relative = trial, trial_u, trial_merit, trial_relative
            if done or merit < best.merit:
                best.r, best.merit, best.converged = r.copy(), merit, done
        if accepted:
            # the first success after a failure keeps its alpha (lowering it at once would fail
            # again: the cycle fail, x10, success, lower costs a failed solve every other step)
            alpha = max(_SIGMA * relative, alpha) if recovering else _SIGMA * relative
            recovering = False
        else:  # too weakly regularised for the inner Newton: regularise more
            alpha *= _GROWTH
            recovering = True
    return best
