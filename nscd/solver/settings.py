"""Options and outcome codes of the frictional contact solver."""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np

from nscd.solver.regimes import MAX_CONTACTS


class Status(str, Enum):
    """What happened in a solve (compares equal to its string value).

    Members
    -------
    CONVERGED
        ``"converged"``: merit <= ``tol`` reached by the fast Newton path, the
        Gauss–Seidel sweeps of large problems, the proximal-point iterations of small ones
        or the interior-point fixed point alone.
    POLISHED
        ``"converged after polish"``: the interior-point fixed point (or, for a large
        problem, the Gauss–Seidel sweeps; for a small one, the proximal-point iterations)
        stalled or cycled above ``tol``; the semismooth Newton polish took it below ``tol``.
    STALLED
        ``"stalled"``: merit stayed above ``tol`` (the message gives the value).
    CYCLING
        ``"cycling"``: the fixed point on the De Saxcé shift did not settle and the
        polish could not rescue it.
    NUMERICAL_FAILURE
        ``"numerical failure"``: the conic solver failed and no iterate reached ``tol``.
    """

    CONVERGED = "converged"
    POLISHED = "converged after polish"
    STALLED = "stalled"
    CYCLING = "cycling"
    NUMERICAL_FAILURE = "numerical failure"

    def __str__(self) -> str:
        return self.value


_COULOMB = ("exact", "relaxed")


def _is_int(value) -> bool:
    """An integer count: a Python or numpy integer, not a bool (``True`` is an int to Python)."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


@dataclass(frozen=True)
class SolverSettings:
    """Options of :func:`nscd.solver.solve_velocity` and :func:`nscd.solver.solve_local`.

    Parameters
    ----------
    coulomb : {"exact", "relaxed"}
        ``"exact"``: De Saxcé's shift ``s = mu ||u_T||`` iterated to a fixed point
        (exact Coulomb friction). ``"relaxed"``: ``s = 0``, one convex solve; a sliding
        contact then separates at normal speed ``mu ||u_T||`` — allowed only when chosen.
    tol : float
        Target FCLIB merit (dimensionless), in (0, 1).
    tol_relative : float or None
        Also accept, on the Gauss–Seidel path of large problems (the sweeps and the Newton
        polish after them) and on the proximal-point path of small ones, a solution whose merit
        relative to the problem's own scale is at most this: the De Saxcé residual in the
        energy norm of ``W`` (each contact's impulse weighted by ``sqrt(W_NN)``, its
        velocity by ``1 / sqrt(W_NN)``) over the larger of the impulses' and the free
        velocities' norms in the same units (see ``nscd.solver.core._Scaled.relative``
        and ``docs/solver.md``). The reported ``merit`` stays the FCLIB one; a note
        records the relative merit. None: the absolute ``tol`` alone. In (0, 1).
    fixed_point_tol : float
        Stop the fixed point when ``||s_new - s||_inf <= fixed_point_tol (1 + ||s||_inf)``
        (scaled units), in (0, 1).
    max_fixed_point : int
        Maximum number of conic solves in the fixed point, >= 1.
    polish : bool
        Run the semismooth Newton polish when the conic fixed point ends above ``tol``.
    polish_below : float
        Hand over to the polish as soon as the conic fixed point reaches this merit
        (Newton converges quadratically from there; the interior point does not).
    max_polish : int
        Maximum Newton iterations of the polish, >= 1. The polish of a large problem above
        ``max_conic_unknowns`` also stops after a few iterations that do not halve its
        residual (nothing dearer follows it; ``docs/solver.md``, fifth round).
    fast_path_unknowns : int
        Problems with at most this many unknowns (contacts x dim) first try the Newton
        solve on the small dense Delassus matrix from the warm start; the conic fixed
        point is the fallback when it does not reach ``tol``. 0 disables the fast path.
    max_fast : int
        Newton iterations allowed on the fast path, >= 1.
    max_proximal : int
        A small dense problem the fast path does not accept first goes through at most
        this many proximal-point iterations (:mod:`nscd.solver.proximal`: exact-Coulomb
        problems with ``W + alpha D^-2``, each solved by the fast path's Newton, whose
        fixed point solves the original problem; fewer once stalled far from ``tol``), before
        the conic fixed point. 0
        disables them. >= 0. (120: a problem of the 4 x 3 wall sliding at the friction limit
        that needed 114 from the warm start stayed at merit 1.05e-8 after 60; ``docs/solver.md``.)
    proximal_unknowns : int
        A problem of at most this many unknowns also goes through the proximal-point
        iterations when the Gauss–Seidel sweeps and the polish of the large-problem path leave
        it above the tolerance (from the best sweep; up to ``core.DENSE_PROXIMAL_UNKNOWNS`` (240) by the
        compiled loop on ``W`` formed dense, beyond with inner problems by :mod:`nscd.solver.newton`
        on a sparse ``W``), before the conic fixed point and before ``max_conic_unknowns``
        gives up. Each inner problem costs a few sparse factorisations: raising this to cover
        a wall's problems (hundreds of unknowns) turns steps that would stall into converged
        ones at the price of slower steps (``docs/solver.md``, fourth round). >= 0.
    tol_gap_abs, tol_gap_rel, tol_feas : float
        Clarabel tolerances on the scaled conic subproblem.
    max_interior_point : int
        Clarabel iteration limit per conic solve.
    large_problem_unknowns : int
        Problems with more unknowns than this
        (contacts x dim) are solved by the nonsmooth Gauss–Seidel of :mod:`nscd.solver.nsgs`
        (cost per sweep linear in the contacts) instead of the conic fixed point; a
        problem it leaves above ``tol`` after ``max_sweeps`` goes on to the conic fixed
        point, recorded in the notes. >= 0.
    max_sweeps : int
        Cap on the (symmetric) Gauss–Seidel sweeps of that path, >= 1.
    max_conic_unknowns : int or None
        A large problem with more unknowns than this that the sweeps (and the polish) leave
        above the tolerance is *not* handed to the conic fixed point: its best iterate is
        returned with status ``STALLED`` (counted and warned by the stepper). This bounds
        the cost of a step (the interior point costs seconds on thousands of unknowns,
        and on the steps of a wall breaking up it rarely reaches ``tol`` either:
        ``docs/solver.md``). None: no bound. >= 0.
    sweeps_per_check : int
        Evaluate the merit every this many sweeps (it costs about a third of a sweep), >= 1.
    regime_contacts : int
        A 2D exact-Coulomb problem of at most this many contacts that every route above
        leaves above ``tol`` is solved exactly by choosing each contact's regime (open,
        sticking, slipping either way) and solving the linear system of each choice
        (:mod:`nscd.solver.regimes`; 4^n systems at worst). 0 disables it. In
        [0, ``regimes.MAX_CONTACTS``] (6).
    """

    coulomb: str = "exact"
    tol: float = 1e-8
    tol_relative: float | None = None
    fixed_point_tol: float = 1e-10
    max_fixed_point: int = 20
    polish: bool = True
    polish_below: float = 1e-5
    max_polish: int = 60
    fast_path_unknowns: int = 120
    max_fast: int = 25
    max_proximal: int = 120
    proximal_unknowns: int = 240
    tol_gap_abs: float = 1e-10
    tol_gap_rel: float = 1e-10
    tol_feas: float = 1e-10
    max_interior_point: int = 200
    large_problem_unknowns: int = 120
    max_sweeps: int = 1000
    max_conic_unknowns: int | None = None
    sweeps_per_check: int = 5
    regime_contacts: int = MAX_CONTACTS

    def __post_init__(self) -> None:
        if self.coulomb not in _COULOMB:
            raise ValueError(f"coulomb == {self.coulomb!r}, must be one of {_COULOMB}.")
        for name in ("tol", "fixed_point_tol", "polish_below", "tol_gap_abs", "tol_gap_rel", "tol_feas"):
            value = getattr(self, name)
            if not 0.0 < value < 1.0:
                raise ValueError(f"{name} == {value!r}, must be in (0, 1).")
        if self.tol_relative is not None and not 0.0 < self.tol_relative < 1.0:
            raise ValueError(f"tol_relative == {self.tol_relative!r}, must be in (0, 1) or None.")
        for name in ("max_fixed_point", "max_polish", "max_fast", "max_interior_point", "max_sweeps",
                     "sweeps_per_check"):
            value = getattr(self, name)
            if not (_is_int(value) and value >= 1):
                raise ValueError(f"{name} == {value!r}, must be an int >= 1.")
        for name in ("fast_path_unknowns", "large_problem_unknowns", "max_proximal", "proximal_unknowns"):
            value = getattr(self, name)
            if not (_is_int(value) and value >= 0):
                raise ValueError(f"{name} == {value!r}, must be an int >= 0.")
        if not (_is_int(self.regime_contacts) and 0 <= self.regime_contacts <= MAX_CONTACTS):
            raise ValueError(f"regime_contacts == {self.regime_contacts!r}, must be an int in [0, {MAX_CONTACTS}].")
        if self.max_conic_unknowns is not None and not (
                _is_int(self.max_conic_unknowns) and self.max_conic_unknowns >= 0):
            raise ValueError(f"max_conic_unknowns == {self.max_conic_unknowns!r}, must be an int >= 0 or None.")

    @property
    def exact(self) -> bool:
        """True for exact Coulomb friction (the De Saxcé shift is iterated)."""
        return self.coulomb == "exact"
