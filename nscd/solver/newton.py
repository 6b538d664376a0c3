"""Semismooth Newton on De Saxcé's natural map: the polish after the sweeps or the interior point.

The small-problem fast path runs the same method compiled on a dense ``W``
(:mod:`.small`, which takes its constants from here); this module works on the sparse
(or dense) ``W`` of problems too large for that kernel, with scipy's factorisations.

Solves ``F(r) = r - P_K(r - (u + mu ||u_T|| e_N)) = 0`` with ``u = W r + q`` (the
vector whose norm is the FCLIB merit) by generalised Newton steps with an Armijo
line search on ``||F||``. With ``D`` the Jacobian of the cone projection at
``y = r - u - s e_N`` and ``E`` the derivative of the shift ``s = mu ||u_T||``
(``E[N, T] = mu u_T^T / ||u_T||``), one element of the generalised Jacobian is

    J = I - D + D (I + E) W.

On degenerate problems (stacks: W only semidefinite, rank 78 of 156 in FCLIB's
BoxesStack1; contacts with r and u both at the cone tip) ``J`` is singular or
nearly so and plain Newton steps blow up along the null space of ``W``. The step
therefore uses the proximally regularised Jacobian

    J_eps = I - D + D (I + E) (W + eps I),   eps = ||F||   (scaled units, diag W = 1),

the Jacobian of the natural map of the proximal problem ``u = W r + q + eps (r - r_k)``:
an inexact Newton step whose perturbation vanishes like ``||F||`` (so convergence
stays superlinear) and that damps the null-space components (on the 23 FCLIB problems
it is what takes BoxesStack1, Capsules-i101 and spheres-in-a-box below 1e-8; eps = 0
or ``||F||^2`` stall at 1e-7..1e-5). When the line search rejects that step,
Levenberg–Marquardt steps ``(J^T J + lambda I) d = -J^T F`` with growing ``lambda``
are tried; when none decreases ``||F||`` (a kink of the merit), up to three full
Newton steps are taken regardless (a watchdog) and the best iterate is returned.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.linalg import lapack

from nscd.solver import cone

# Armijo constant and smallest step length of the line search on ||F||.
_ARMIJO = 1e-4
_MIN_STEP = 2.0**-30
# Directions tried in turn until the line search accepts one: the (regularised) Newton
# step, then Levenberg–Marquardt with lambda = factor * ||F|| (larger lambda: shorter,
# more gradient-like steps).
_LM_FACTORS = (0.0, 1.0, 1e2, 1e4)
# Consecutive non-monotone (watchdog) steps allowed when no direction decreases ||F||.
_WATCHDOG = 3


@dataclass
class NewtonResult:
    """Outcome of :func:`solve`.

    Attributes
    ----------
    r : ndarray, shape (m * dim,)
        Last accepted iterate.
    merit : float
        The caller's merit of ``r``.
    converged : bool
        ``stop`` reported success.
    iterations : int
        Newton iterations taken.
    """

    r: np.ndarray
    merit: float
    converged: bool
    iterations: int


def _jacobian(W, r: np.ndarray, u: np.ndarray, mu: np.ndarray, dim: int, exact: bool, eps: float):
    """Regularised generalised Jacobian ``I - D + D (I + E) (W + eps I)`` (dense or sparse like ``W``)."""
    m = mu.size
    ut = u[:, 1:]
    y = r - u
    if exact:
        norm_t = cone.tangent_norm(u)
        y[:, 0] -= mu * norm_t
    D = cone.project_jacobian(y, mu)
    G = D.copy()
    if exact:
        dir_t = ut / np.where(norm_t > 0.0, norm_t, 1.0)[:, None]
        G[:, :, 1:] += D[:, :, :1] * (mu[:, None] * dir_t)[:, None, :]
    n = m * dim
    if sp.issparse(W):
        idx = np.arange(m + 1)
        Db = sp.bsr_matrix((D, idx[:-1], idx), shape=(n, n))
        Gb = sp.bsr_matrix((G, idx[:-1], idx), shape=(n, n))
        return (sp.identity(n, format="csr") - Db.tocsr() + Gb.tocsr() @ W + eps * Gb.tocsr()).tocsc()
    J = np.matmul(G, W.reshape(m, dim, n)).reshape(n, n)
    contacts = np.arange(m)
    J.reshape(m, dim, m, dim)[contacts, :, contacts, :] += eps * G - D + np.eye(dim)
    return J


def _newton_direction(J, f: np.ndarray) -> np.ndarray | None:
    """Plain Newton direction ``J d = -f``; None when ``J`` is numerically singular."""
    if sp.issparse(J):
        try:
            d = spla.splu(J).solve(-f)
        except RuntimeError:
            return None
    else:
        # LAPACK directly: numpy.linalg.solve costs ~15 us of Python overhead per call.
        _, _, d, info = lapack.dgesv(J, -f)
        if info != 0:
            return None
    return d if np.isfinite(d).all() else None


def _lm_direction(J, f: np.ndarray, lam: float) -> np.ndarray | None:
    """Levenberg–Marquardt direction ``(J^T J + lam I) d = -J^T f``."""
    g = J.T @ f
    if sp.issparse(J):
        try:
            d = spla.splu((J.T @ J + lam * sp.identity(f.size)).tocsc()).solve(-g)
        except RuntimeError:
            return None
    else:
        A = J.T @ J
        A[np.diag_indices(f.size)] += lam
        _, d, info = lapack.dposv(A, -g)
        if info != 0:
            return None
    return d if np.isfinite(d).all() else None


def solve(
    W,
    q: np.ndarray,
    mu: np.ndarray,
    dim: int,
    r0: np.ndarray,
    exact: bool,
    max_iter: int,
    stop: Callable[[np.ndarray, np.ndarray, float], tuple[float | None, bool]],
    merit: Callable[[np.ndarray, np.ndarray], float],
    stall: int | None = None,
) -> NewtonResult:
    """Semismooth Newton with line search on ``F(r) = 0``.

    Parameters
    ----------
    W : ndarray or scipy.sparse matrix, shape (n, n)
        Delassus matrix (scaled units), ``n = m * dim``.
    q : ndarray, shape (n,)
        Free velocity (scaled units).
    mu : ndarray, shape (m,)
        Friction coefficients.
    dim : int
        2 or 3.
    r0 : ndarray, shape (n,)
        Starting impulses.
    exact : bool
        Exact Coulomb (De Saxcé shift) or the relaxed map.
    max_iter : int
        Iteration limit.
    stop : callable
        ``stop(r, u, norm_f) -> (merit or None, done)``: whether ``r`` (with
        ``u = W r + q`` and residual norm ``norm_f``) meets the caller's criterion, and
        the caller's merit if it was evaluated.
    merit : callable
        ``merit(r, u) -> float``: the caller's merit, for the result when ``stop`` did
        not evaluate it.
    stall : int, optional
        Also stop when ``stall`` iterations in a row have not halved the smallest ``||F||``:
        where the generalised Jacobian switches with the contacts' regimes (a wall at the
        friction limit) Newton creeps at a few per cent per iteration, each iteration a sparse
        factorisation. None: only ``max_iter``.

    Returns
    -------
    NewtonResult
        The iterate of smallest ``||F||`` (the last one unless watchdog steps were taken).
    """
    m = mu.size
    shape = (m, dim)

    def residual(r_: np.ndarray, u_: np.ndarray) -> tuple[np.ndarray, float]:
        f_ = cone.natural_map(r_.reshape(shape), u_.reshape(shape), mu, exact).ravel()
        return f_, float(np.sqrt(f_ @ f_))

    r = r0
    u = W @ r + q
    f, norm_f = residual(r, u)
    value, done = stop(r, u, norm_f)
    best = (norm_f, r, u, value)
    k = watchdog = 0
    halved_at, halved_norm = 0, norm_f  # last iteration that halved the smallest ||F||
    while not done and k < max_iter and (stall is None or k - halved_at < stall):
        k += 1
        J = _jacobian(W, r.reshape(shape), u.reshape(shape), mu, dim, exact, norm_f)
        accepted = False
        for lam in _LM_FACTORS:
            d = _newton_direction(J, f) if lam == 0.0 else _lm_direction(J, f, lam * norm_f)
            step = 1.0
            while d is not None and step >= _MIN_STEP:
                r_try = r + step * d
                u_try = W @ r_try + q
                f_try, norm_try = residual(r_try, u_try)
                if norm_try <= (1.0 - _ARMIJO * step) * norm_f:
                    accepted = True
                    break
                step *= 0.5
            if accepted:
                break
        if not accepted:
            # Stuck at a kink of ||F||: take the full regularised Newton step anyway (a
            # watchdog: at most _WATCHDOG in a row), keeping the best iterate to return.
            d = _newton_direction(J, f)
            watchdog += 1
            if d is None or watchdog > _WATCHDOG:
                break
            r_try = r + d
            u_try = W @ r_try + q
            f_try, norm_try = residual(r_try, u_try)
        else:
            watchdog = 0
        r, u, f, norm_f = r_try, u_try, f_try, norm_try
        value, done = stop(r, u, norm_f)
        if done or norm_f < best[0]:
            best = (norm_f, r, u, value)
        if norm_f <= 0.5 * halved_norm:
            halved_at, halved_norm = k, norm_f
    _, r, u, value = best
    return NewtonResult(r, merit(r, u) if value is None else value, done, k)
