"""The Coulomb cone: projection, its generalised Jacobian, De Saxcé's natural map and the FCLIB merit.

All functions work on arrays of shape ``(m, dim)`` — one row per contact, ordered
``[normal, t1, (t2)]`` — with ``dim`` 2 or 3 and friction coefficients ``mu`` of shape
``(m,)``, ``mu >= 0``. The cone of contact ``c`` is

    K_mu = {x : ||x_T|| <= mu_c x_N},

its dual is ``K_mu* = {y : mu_c ||y_T|| <= y_N}``; ``mu_c == 0`` gives the frictionless
cone ``{x_N >= 0, x_T = 0}`` (dual: ``y_N >= 0``), handled by the same formulas.
"""
from __future__ import annotations

import numpy as np

def tangent_norm(x: np.ndarray) -> np.ndarray:
    """``||x_T||`` per row of ``x`` (shape (m, dim) -> (m,))."""
    if x.shape[1] == 2:
        return np.abs(x[:, 1])
    return np.hypot(x[:, 1], x[:, 2])


def project(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """Euclidean projection of each row of ``x`` onto its Coulomb cone ``K_mu``.

    Inside the cone ``x`` is kept; otherwise the projection lies on the ray through
    ``(1, mu t)``, ``t = x_T / ||x_T||``, at normal coordinate
    ``a = max(0, (x_N + mu ||x_T||) / (1 + mu^2))`` (``a = 0``: the polar cone).

    Parameters
    ----------
    x : ndarray, shape (m, dim)
        Points to project, ``[normal, tangent...]`` per row (any consistent unit).
    mu : ndarray, shape (m,)
        Friction coefficients, ``>= 0``.

    Returns
    -------
    ndarray, shape (m, dim)
        ``P_K(x)`` row by row.
    """
    xn = x[:, 0]
    rho = tangent_norm(x)
    # x_N >= 0 as well: with mu == 0 and x_T == 0, rho <= mu x_N holds for every x_N
    # (0 <= -0.0), which would keep a negative normal component (an adhesive impulse).
    inside = (rho <= mu * xn) & (xn >= 0.0)
    a = np.maximum((xn + mu * rho) / (1.0 + mu * mu), 0.0)
    # off the cone, x_T is scaled by mu a / ||x_T|| (<= 1 there, so no overflow; x_T = 0 -> 0)
    out = x * np.where(inside, 1.0, mu * a / np.where(rho > 0.0, rho, 1.0))[:, None]
    out[:, 0] = np.where(inside, xn, a)
    return out


def project_jacobian(x: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """An element of the generalised (Clarke) Jacobian of :func:`project`, per contact.

    Inside the cone it is the identity, in the polar cone zero, and on the lateral
    surface (``a = (x_N + mu ||x_T||) / (1 + mu^2)``, ``t = x_T / ||x_T||``)::

        1/(1+mu^2) [[1,    mu t^T],
                    [mu t, mu^2 t t^T + (1+mu^2) mu a / ||x_T|| (I - t t^T)]]

    Parameters
    ----------
    x : ndarray, shape (m, dim)
    mu : ndarray, shape (m,)

    Returns
    -------
    ndarray, shape (m, dim, dim)
    """
    dim = x.shape[1]
    xn = x[:, 0]
    rho = tangent_norm(x)
    inside = (rho <= mu * xn) & (xn >= 0.0)
    c = 1.0 / (1.0 + mu * mu)
    a = (xn + mu * rho) * c
    lateral = (a > 0.0) & ~inside
    safe = np.where(rho > 0.0, rho, 1.0)
    # the lateral-surface formula, zeroed off the lateral surface, plus I inside the cone
    col = np.concatenate((np.ones((x.shape[0], 1)), mu[:, None] * x[:, 1:] / safe[:, None]), axis=1)
    jac = col[:, :, None] * col[:, None, :] * (c * lateral)[:, None, None]
    if dim == 3:
        t = x[:, 1:] / safe[:, None]
        curv = mu * a / safe * lateral
        jac[:, 1:, 1:] += curv[:, None, None] * (np.eye(2) - t[:, :, None] * t[:, None, :])
    jac += inside[:, None, None] * np.eye(dim)
    return jac


def natural_map(r: np.ndarray, u: np.ndarray, mu: np.ndarray, exact: bool = True) -> np.ndarray:
    """De Saxcé's natural map ``F = r - P_K(r - (u + mu ||u_T|| e_N))`` per contact.

    ``F == 0`` exactly when ``K_mu ∋ r ⊥ u + mu ||u_T|| e_N ∈ K_mu*``. With
    ``exact=False`` the shift is dropped (the convex relaxation ``K ∋ r ⊥ u ∈ K*``).

    Parameters
    ----------
    r : ndarray, shape (m, dim)
        Impulses (reactions).
    u : ndarray, shape (m, dim)
        Relative velocities ``u = W r + q``.
    mu : ndarray, shape (m,)
    exact : bool
        Include the De Saxcé shift ``mu ||u_T||`` on the normal component.

    Returns
    -------
    ndarray, shape (m, dim)
    """
    y = r - u
    if exact:
        y[:, 0] -= mu * tangent_norm(u)
    return r - project(y, mu)


def merit(r: np.ndarray, u: np.ndarray, mu: np.ndarray, q_norm: float, exact: bool = True) -> float:
    """FCLIB's ``fclib_merit_local``: ``||F(r)||_2 / (1 + sqrt(||q||_2))``.

    Parameters
    ----------
    r, u : ndarray, shape (m, dim)
        Impulses and relative velocities ``u = W r + q``.
    mu : ndarray, shape (m,)
    q_norm : float
        ``||q||_2`` of the problem (the denominator really is ``1 + sqrt(||q||)``).
    exact : bool
        See :func:`natural_map`.

    Returns
    -------
    float
        Dimensionless merit; ``0`` at an exact solution.
    """
    f = natural_map(r, u, mu, exact).ravel()
    return float(np.sqrt(f @ f) / (1.0 + np.sqrt(q_norm)))


def merit_and_dual_violation(r: np.ndarray, u: np.ndarray, mu: np.ndarray, q_norm: float,
                             exact: bool = True) -> tuple[float, float]:
    """FCLIB :func:`merit` and the distance of ``u + mu ||u_T|| e_N`` to ``K_mu*``, same scaling.

    At an exact solution both vanish, and in exact arithmetic the second never exceeds
    the first (Moreau's decomposition); in floating point the merit loses ``u`` when
    ``||r|| >> ||u||`` (e.g. a mechanism driven to ``r ~ 1e21``), which the second
    catches. ``dist(x, K*) = ||P_K(-x)||``; both projections are done in one call.

    Parameters
    ----------
    r, u : ndarray, shape (m, dim)
    mu : ndarray, shape (m,)
    q_norm : float
    exact : bool

    Returns
    -------
    merit, dual_violation : float
    """
    m = mu.size
    x = u.copy()
    if exact:
        x[:, 0] += mu * tangent_norm(u)
    p = project(np.concatenate((r - x, -x)), np.concatenate((mu, mu)))
    e = (r - p[:m]).ravel()
    v = p[m:].ravel()
    scale = 1.0 + np.sqrt(q_norm)
    return float(np.sqrt(e @ e)) / scale, float(np.sqrt(v @ v)) / scale
