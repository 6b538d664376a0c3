"""Small 2D contact problems solved exactly by their contacts' regimes.

In 2D the Coulomb cone ``K_mu = {|r_T| <= mu r_N}`` of a contact is a wedge, so the problem
``K_mu ∋ r ⊥ W r + q + mu |u_T| e_N ∈ K_mu*`` (exact Coulomb, De Saxcé's form) is
piecewise linear: each contact ``c`` is in one of four regimes,

* open: ``r_c = 0`` (and ``u_N >= 0``),
* sticking: ``u_c = 0`` (and ``|r_T| <= mu r_N``),
* slipping forward / backward (``s = +1 / -1``): ``u_N = 0`` and ``r_T = -s mu r_N``
  (and ``r_N >= 0``, ``s u_T >= 0``),

and once every contact's regime is chosen the impulses solve one linear system of ``2m``
equations. Enumerating the ``4^m`` choices is a finite, exact method (the 2D frictional
problem is a linear complementarity problem); it is what is left when the iterative routes
stall just above the tolerance on a problem of a few contacts, typically one whose impulses
differ by many orders of magnitude (a contact carrying ``1e-7`` of its neighbour's impulse,
near the apex of its cone, where the natural map's pieces meet). The choices are tried in order
of how many contacts differ from the regimes of the best iterate the other routes reached, and
each candidate is accepted by the solver's own test (the FCLIB merit and the dual-cone
violation, :func:`nscd.solver.cone.merit_and_dual_violation`), which is the complementarity
check itself. Units are those of ``W`` and ``q`` (any consistent set); rows per contact are
``[normal, tangent]``.

Not for 3D (a slipping contact's direction is then an unknown of a nonlinear system) nor for
the relaxed cone (a convex problem the conic route solves).
"""
from __future__ import annotations

import itertools

import numpy as np

from .cone import merit_and_dual_violation, project, tangent_norm

#: The most contacts whose regimes are enumerated (4^6 = 4096 linear systems of 12 unknowns at worst).
MAX_CONTACTS = 6

OPEN, STICK, SLIP_FORWARD, SLIP_BACKWARD = 0, 1, 2, 3


def guess(W: np.ndarray, q: np.ndarray, mu: np.ndarray, r: np.ndarray) -> tuple[int, ...]:
    """The regime of each contact read from the impulses ``r`` (2m,): the piece of the cone's
    projection (:func:`nscd.solver.cone.project`) that the natural map's argument
    ``r - rho (u + mu |u_T| e_N)`` (``rho = 1 / W_NN`` of the contact, ``u = W r + q``) falls in:
    kept (inside the cone): sticking; sent to the apex (its polar cone): open; else onto the
    cone's edge, slipping against the tangential impulse's sign."""
    m = mu.size
    R, U = r.reshape(m, 2), (W @ r + q).reshape(m, 2)
    diagonal = W.diagonal()[::2]
    rho = 1.0 / np.where(diagonal > 0.0, diagonal, 1.0)
    y = R - rho[:, None] * U
    y[:, 0] -= rho * mu * tangent_norm(U)
    p = project(y, mu)
    kept = np.all(p == y, axis=1)
    return tuple(STICK if k else OPEN if pn == 0.0 else SLIP_BACKWARD if pt > 0.0 else SLIP_FORWARD
                 for k, pn, pt in zip(kept.tolist(), p[:, 0].tolist(), p[:, 1].tolist()))


def impulses(W: np.ndarray, q: np.ndarray, mu: np.ndarray, regimes: tuple[int, ...]) -> np.ndarray | None:
    """The impulses (2m,) of the linear system of ``regimes`` (one per contact); None where the
    system has no solution (a singular system whose least-squares solution misses it)."""
    n = q.size
    A, b = np.zeros((n, n)), np.zeros(n)
    for c, regime in enumerate(regimes):
        rn, rt = 2 * c, 2 * c + 1
        if regime == OPEN:
            A[rn, rn] = A[rt, rt] = 1.0
        elif regime == STICK:
            A[rn], b[rn], A[rt], b[rt] = W[rn], -q[rn], W[rt], -q[rt]
        else:
            A[rn], b[rn] = W[rn], -q[rn]
            A[rt, rt], A[rt, rn] = 1.0, (mu[c] if regime == SLIP_FORWARD else -mu[c])
    try:
        return np.linalg.solve(A, b)
    except np.linalg.LinAlgError:  # redundant contacts: a singular system, consistent or not
        r = np.linalg.lstsq(A, b, rcond=None)[0]
        return r if np.allclose(A @ r, b, rtol=1e-12, atol=1e-12 * (1.0 + np.abs(b).max())) else None


def solve(W: np.ndarray, q: np.ndarray, mu: np.ndarray, start: np.ndarray, tol: float
          ) -> tuple[np.ndarray, np.ndarray, float, int] | None:
    """The first choice of regimes, in order of the contacts that differ from ``guess(start)``,
    whose impulses pass the acceptance test at ``tol``.

    Parameters
    ----------
    W : ndarray, shape (2m, 2m)
        Delassus matrix, rows ``[N, T]`` per contact, ``m <= MAX_CONTACTS``.
    q : ndarray, shape (2m,)
        Free relative velocity.
    mu : ndarray, shape (m,)
        Friction coefficients, ``>= 0``.
    start : ndarray, shape (2m,)
        The best impulses reached by another route.
    tol : float
        FCLIB merit (and dual-cone violation) to reach.

    Returns
    -------
    (r, u, merit, trials) or None
        Impulses, relative velocities ``u = W r + q``, their merit and the linear systems
        solved; None if no choice of regimes passes (e.g. redundant contacts whose
        least-squares impulses leave their cones).
    """
    m = mu.size
    if m > MAX_CONTACTS:
        raise ValueError(f"{m} contacts; the regimes are enumerated for at most {MAX_CONTACTS}.")
    first = guess(W, q, mu, start)
    q_norm = float(np.sqrt(q @ q))
    order = sorted(itertools.product(range(4), repeat=m), key=lambda rs: sum(a != b for a, b in zip(rs, first)))
    for trials, regimes in enumerate(order, start=1):
        r = impulses(W, q, mu, regimes)
        if r is None or not np.all(np.isfinite(r)):
            continue
        u = W @ r + q
        merit, violation = merit_and_dual_violation(r.reshape(m, 2), u.reshape(m, 2), mu, q_norm, True)
        if merit <= tol and violation <= tol:
            return r, u, merit, trials
    return None
