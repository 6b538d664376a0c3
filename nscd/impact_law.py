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

from nscd._jit import njit, njit_helper

__all__ = ["BISECTIONS", "NO_TRIAL", "bisection_next", "bisection_start", "dissipation", "restitution_factor"]

#: Bisection steps on the restitution factor: 2^-30 ~ 1e-9, below the solver's relative tolerance.
BISECTIONS = 30

#: What :func:`bisection_next` returns when no trial is left: the factor is the state's ``low``.
NO_TRIAL = -1.0


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
    state = bisection_start()
    lam, _ = bisection_next(state, False)
    best = None
    while lam != NO_TRIAL:
        trial = solve(lam)
        lost, scale = dissipation(trial[0], u_before, trial[1])
        lam, keep = bisection_next(state, lost >= -tolerance * scale)
        if keep:
            best = trial
    return float(state[1]), best


@njit_helper
def bisection_start() -> np.ndarray:
    """The state of :func:`bisection_next` before its first trial: (trials asked for, low, high)."""
    return np.array([0.0, 0.0, 1.0])


@njit
def bisection_next(state: np.ndarray, dissipates: bool) -> tuple[float, bool]:
    """One move of the bisection on a problem's restitution factor, in place on ``state``
    (:func:`bisection_start`: trials asked for, and the bracket ``low``, ``high``): told whether
    the trial last asked for dissipates (not read for the first, plastic, trial, which does by
    the law's construction), returns the factor of the next trial (:data:`NO_TRIAL` after
    ``BISECTIONS`` halvings of the bracket, the factor then ``state[1]``) and whether the trial
    last asked for is kept (the plastic one, then each that dissipates: the last kept is the
    solution). The one source of the bisection of :func:`restitution_factor` and of the time
    step's (its compiled and general paths)."""
    trials = state[0]
    keep = trials == 1.0  # the plastic trial, lam = 0
    if trials > 1.0:
        mid = 0.5 * (state[1] + state[2])  # the factor of that trial
        if dissipates:
            state[1] = mid
            keep = True
        else:
            state[2] = mid
    if trials == BISECTIONS + 1:
        return NO_TRIAL, keep
    state[0] = trials + 1.0
    return (0.0 if trials == 0.0 else 0.5 * (state[1] + state[2])), keep
