"""Proximal-point outer loop for small dense contact problems at the friction limit.

When a small problem ``u = W r + q`` is degenerate — contacts sliding at the friction
limit everywhere, redundant contact points (two per joint in 2D) so that ``W`` is
singular — the impulses are not unique and the De Saxcé shift ``mu ||u_T||`` switches
contacts between sticking and sliding from one iterate to the next: the compiled
semismooth Newton (:mod:`.small`) stalls (``docs/solver.md``). The proximal-point method
(Rockafellar 1976; Siconos' ``FC3D_PROX``, Acary & Brogliato, *Numerical Methods for
Nonsmooth Dynamical Systems*, 2008) solves instead a sequence of problems of the same
kind, each well posed (``W + alpha D^-2`` is positive definite):

    r_{k+1} solves  K ∋ r ⊥ u + alpha D^-2 (r - r_k) + mu ||u_T|| e_N ∈ K*,  u = W r + q,

that is the exact-Coulomb problem with ``W + alpha D^-2`` and ``q - alpha D^-2 r_k``
(``D^-2`` = each contact's ``W_NN``: ``alpha`` is dimensionless, the regularisation
``alpha I`` in the solver's scaled units where ``diag W = 1``). A fixed point
``r_{k+1} = r_k`` solves the original problem exactly: the regularisation is removed by
the outer loop, exact Coulomb is kept, and each iterate is tested on the *original*
problem's merit. Each inner problem is solved warm, from ``r_k``, by the compiled Newton.

``alpha`` follows Siconos' adaptive rule: ``alpha = sigma e`` with ``e`` the relative
merit of the current iterate and ``sigma = 5`` (large steps of a strongly regularised
problem far from a solution, nearly the original problem close to one), multiplied by 10
when an inner solve fails (its best iterate is taken only if it lowers the original
merit); the next success keeps that ``alpha`` rather than lowering it at once. The inner tolerance is a tenth of
the current outer merit (Siconos' adaptive internal tolerance), never below the outer
tolerance's tenth.

The loop ends at the caller's acceptance test, after ``max_outer`` inner solves, or when
``alpha`` has grown beyond ``1e6`` (every inner solve fails). The best iterate (smallest
merit) is returned.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from nscd.solver import small

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


def solve(W: np.ndarray, q: np.ndarray, mu: np.ndarray, dim: int, r0: np.ndarray, exact: bool, tol: float,
          max_outer: int, max_inner: int,
          measure: Callable[[np.ndarray, np.ndarray], tuple[float, float, bool]]) -> ProximalResult:
    """Proximal-point iterations on the dense problem ``u = W r + q`` from ``r0``.

    Parameters
    ----------
    W : ndarray, shape (n, n)
        Dense Delassus matrix (C-contiguous float), rows per contact ``[N, T1, (T2)]``.
    q : ndarray, shape (n,)
        Free relative velocity.
    mu : ndarray, shape (n // dim,)
        Friction coefficients, ``>= 0``.
    dim : int
        2 or 3.
    r0 : ndarray, shape (n,)
        Starting impulses.
    exact : bool
        Exact Coulomb (De Saxcé shift) or the relaxed cone, as the caller's problem.
    tol : float
        The caller's target FCLIB merit: the inner tolerances are a tenth of the current
        merit, never below a tenth of this.
    max_outer : int
        Maximum inner problems, >= 1.
    max_inner : int
        Newton iterations allowed per inner problem (from its warm start; the compiled
        kernel tries once more from zero if that fails).
    measure : callable
        ``measure(r, u) -> (merit, relative merit, accepted)`` of the original problem
        (unscaled ``r`` and ``u = W r + q``).

    Returns
    -------
    ProximalResult
    """
    n = q.size
    diag = W.diagonal()[::dim]
    weight = np.repeat(np.maximum(diag, max(diag.max(), 1.0) * 1e-14), dim)  # D^-2, as small.py's scaling
    q_scale = 1.0 + math.sqrt(float(np.linalg.norm(q)))
    r = np.ascontiguousarray(r0, dtype=float).copy()
    merit, relative, done = measure(r, W @ r + q)
    best = ProximalResult(r.copy(), merit, done, 0, 0)
    alpha = _SIGMA * relative
    sizes = np.array([n])
    mu_b = np.ascontiguousarray(mu, dtype=float)[None]
    W_inner = np.empty((1, n, n))
    q_inner, r_inner, u_inner = np.empty((1, n)), np.empty((1, n)), np.empty((1, n))
    inner_merit, info = np.empty(1), np.empty((1, 2), dtype=np.int64)
    recovering = False
    while not best.converged and best.outer < max_outer and alpha <= _MAX_ALPHA:
        best.outer += 1
        W_inner[0] = W
        W_inner[0].flat[::n + 1] += alpha * weight
        q_inner[0] = q - alpha * weight * r
        # the inner merit's denominator is 1 + sqrt(||q_inner||): the same natural-map
        # norm as merit / _INNER_RATIO of the original problem
        inner_tol = max(merit, tol) / _INNER_RATIO * q_scale / (1.0 + math.sqrt(float(np.linalg.norm(q_inner[0]))))
        small.solve_dense(W_inner, q_inner, mu_b, sizes, dim, r[None], inner_tol, exact, max_inner, r_inner,
                          u_inner, inner_merit, info)
        best.inner += int(info[0, 1])
        trial = r_inner[0].copy()
        trial_merit, trial_relative, done = measure(trial, W @ trial + q)
        if info[0, 0] == small.ACCEPTED or trial_merit < merit:
            r, merit, relative = trial, trial_merit, trial_relative
            if done or merit < best.merit:
                best.r, best.merit, best.converged = r.copy(), merit, done
        if info[0, 0] == small.ACCEPTED:
            # the first success after a failure keeps its alpha (lowering it at once would fail
            # again: the cycle fail, x10, success, lower costs a failed solve every other step)
            alpha = max(_SIGMA * relative, alpha) if recovering else _SIGMA * relative
            recovering = False
        else:  # too weakly regularised for the inner Newton: regularise more
            alpha *= _GROWTH
            recovering = True
    return best
