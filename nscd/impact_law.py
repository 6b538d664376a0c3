"""An impact law that cannot create energy: Newton's restitution capped per impact.

Newton's law ``u_n+ = -e u_n-`` with Coulomb friction is not energetically consistent:
with ``e > 0`` and friction, the impulse that reverses the normal velocity can also
reverse a sliding velocity and leave more kinetic energy than before (Kane's example;
Glocker, "Energetic consistency conditions for standard impacts, Part I", Multibody
System Dynamics 29, 2013; Acary & Brogliato, *Numerical Methods for Nonsmooth Dynamical
Systems*, Springer 2008, on Newton's law with friction). nscd keeps Newton's law and
Coulomb, and scales the restitution of every contact of a scene's contact problem by one
factor ``lambda`` in [0, 1], the largest for which the contacts dissipate:

    D(lambda) = -sum_c P_c . (u_c- + u_c+) / 2 >= 0,

with ``P`` the impulses and ``u-``, ``u+`` the relative velocities before and after
(``D`` is the energy the contacts take from the dynamic bodies, see
:class:`nscd.result.ResultBuilder`). At ``lambda = 0`` the impact is plastic and
dissipates (``P . u+ <= 0`` by the normal complementarity and Coulomb's maximal
dissipation, and ``K+ - K- = P . u+ - |v+ - v-|_M^2 / 2``); ``lambda`` is found by
bisection. With ``mu = 0`` Newton's law dissipates ``(1 - e^2)``-wise on its own and
``lambda = 1``: nothing changes (``e = 1`` then conserves energy exactly).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from nscd._jit import njit

__all__ = ["BISECTIONS", "dissipation", "restitution_factor"]

#: Bisection steps on the restitution factor: 2^-30 ~ 1e-9, below the solver's relative tolerance.
BISECTIONS = 30


@njit
def dissipation(impulses: np.ndarray, u_before: np.ndarray, u_after: np.ndarray) -> tuple[float, float]:
    """Energy the contacts take from the bodies (J) and the size of the terms it sums (J).

    The energy is ``-sum P·(u- + u+)/2``; its scale ``sum |P| (|u-| + |u+|)/2`` (for round-off tests).

    ``impulses`` (N s), ``u_before``, ``u_after`` (m/s): (m, dim) in the contact frames.
    """
    lost = 0.0
    scale = 0.0
    for c in range(impulses.shape[0]):
        for d in range(impulses.shape[1]):
            p = impulses[c, d]
            lost += p * (0.5 * (u_before[c, d] + u_after[c, d]))
            scale += abs(p) * (abs(u_before[c, d]) + abs(u_after[c, d]))
    return -lost, 0.5 * scale


def restitution_factor(solve: Callable[[float], tuple], u_before: np.ndarray,
                       tolerance: float) -> tuple[float, tuple]:
    """The largest factor ``lambda`` in [0, 1) on the restitution of one contact problem
    whose solution dissipates, and that solution (called when ``lambda = 1`` does not).

    Parameters
    ----------
    solve : callable
        ``solve(lam)`` returns a tuple starting ``(impulses, u_after, ...)`` ((m, dim) each)
        for the problem with every restitution multiplied by ``lam``.
    u_before : ndarray, shape (m, dim)
        Relative velocities before, m/s.
    tolerance : float
        Relative round-off allowed: ``D >= -tolerance * scale`` counts as dissipative.

    Returns
    -------
    lam : float
        The factor, to ``2^-BISECTIONS``; its solution dissipates (0.0: plastic impact).
    solution : tuple
        What ``solve(lam)`` returned.
    """
    def dissipates(solution) -> bool:
        lost, scale = dissipation(solution[0], u_before, solution[1])
        return lost >= -tolerance * scale

    low, high = 0.0, 1.0
    best = solve(0.0)
    for _ in range(BISECTIONS):
        mid = 0.5 * (low + high)
        trial = solve(mid)
        if dissipates(trial):
            low, best = mid, trial
        else:
            high = mid
    return low, best
