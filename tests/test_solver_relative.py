"""The tolerance relative to a contact problem's own scale (``SolverSettings.tol_relative``).

The relative merit is the De Saxcé residual in the energy norm of ``W`` over the larger
of the impulses' and the free velocities' norms (``nscd.solver.core._Scaled.relative``).
Checked against a closed form, for its independence of units, and on the large-problem
path of the solver, where it is the acceptance test that ``tol_relative`` adds.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from nscd.solver import SolverSettings, Status, core, solve_local, solve_velocity


def _relative(W: np.ndarray, q: np.ndarray, mu: np.ndarray, r: np.ndarray, dim: int) -> float:
    P = core._Scaled(W, q, mu, dim, SolverSettings())
    r_s = r / (P.sigma * P.d)
    return P.relative(r_s, P.W @ r_s + P.q)


@pytest.mark.parametrize("w, v", [(1.0, 1.0), (0.03, 0.2), (2e4, 3e-3)])
@pytest.mark.parametrize("eps", [1e-6, 1e-3, 0.1])
def test_relative_merit_of_an_overloaded_contact(w, v, eps):
    """One contact approaching at ``v`` (mobility ``w``): the impulse ``(1 + eps) v / w`` that
    stops it and bounces it back at ``eps v`` has natural map ``eps`` in the scaled units,
    in which the impulse is ``1 + eps`` and the free velocity 1: relative merit
    ``eps / (1 + eps)``, whatever the units of ``w`` and ``v``."""
    W = np.diag([w, 1.7 * w])
    q = np.array([-v, 0.0])
    r = np.array([(1.0 + eps) * v / w, 0.0])
    # rounding of the scaled products only: 1e-12 relative
    assert _relative(W, q, np.array([0.5]), r, 2) == pytest.approx(eps / (1.0 + eps), rel=1e-9)


def test_relative_merit_is_unit_free():
    """Changing the unit of impulse (and so of W) and of velocity leaves it unchanged."""
    rng = np.random.default_rng(3)
    A = rng.standard_normal((12, 9))
    W = A @ A.T + 0.1 * np.eye(12)
    q = rng.standard_normal(12)
    mu = np.full(4, 0.6)
    r = np.abs(rng.standard_normal(12))
    base = _relative(W, q, mu, r, 3)
    a, b = 1e3, 1e-2   # impulse unit x a (W / a), velocity unit x b
    assert _relative(W * b / a, q * b, mu, r * a, 3) == pytest.approx(base, rel=1e-9)
    assert base > 0.0


def _chain_problem(n: int) -> tuple[sp.csr_matrix, np.ndarray, np.ndarray]:
    """A column of ``n`` unit masses resting on each other under gravity, one 2D contact per interface.

    Contact ``c`` lies below body ``c`` (contact 0 on the ground); rows ``[N, T]``.
    ``W = H M^-1 H^T`` couples neighbouring contacts; ``q`` is the free velocity of one
    step of gravity (``-g dt`` closing each interface of the falling column by 0 except
    the ground one), plus a slight tangential drift to exercise friction.
    """
    rows, cols, vals = [], [], []
    for c in range(n):
        for k in range(2):       # normal: body y velocity, tangential: body x velocity
            rows.append(2 * c + k); cols.append(2 * c + (1 - k)); vals.append(1.0)
            if c > 0:
                rows.append(2 * c + k); cols.append(2 * (c - 1) + (1 - k)); vals.append(-1.0)
    H = sp.csr_matrix((vals, (rows, cols)), shape=(2 * n, 2 * n))
    v_free = np.zeros(2 * n)
    v_free[1::2] = -9.81e-3                       # one 1 ms step of gravity on every body
    v_free[0::2] = 1e-3 * np.linspace(0.0, 1.0, n)  # a shear drift
    return H, H @ v_free, np.full(n, 0.3)


def test_large_problem_accepted_at_the_relative_tolerance():
    """On the Gauss–Seidel path a large problem stops at ``tol_relative`` (noted), its answer
    meets that bound, and the same problem without it goes on to the absolute merit."""
    H, q, mu = _chain_problem(200)   # 400 unknowns > large_problem_unknowns
    W = (H @ H.T).toarray()
    loose = SolverSettings(tol_relative=1e-3, sweeps_per_check=1)
    sol = solve_local(W, q, mu, dim=2, settings=loose)
    assert sol.status == Status.CONVERGED and sol.path == "nsgs"
    assert _relative(W, q, mu, sol.r, 2) <= 1e-3
    strict = solve_local(W, q, mu, dim=2, settings=SolverSettings(sweeps_per_check=1))
    assert strict.converged and strict.merit <= 1e-8
    assert strict.sweeps >= sol.sweeps
    if sol.merit > 1e-8:
        assert any("tol_relative" in note for note in sol.notes)
    # the column carries its weight: the ground contact holds all 200 bodies (g dt each)
    assert strict.r[0] == pytest.approx(200 * 9.81e-3, rel=1e-6)


@pytest.mark.parametrize("value", [0.0, 1.0, -1e-4, 2.0])
def test_tol_relative_out_of_range(value):
    with pytest.raises(ValueError, match="tol_relative"):
        SolverSettings(tol_relative=value)


def test_polish_after_the_sweeps_stops_at_the_relative_tolerance():
    """The Newton polish of a large problem the sweeps leave unsolved accepts at ``tol_relative``
    as the sweeps do: its answer meets that bound (checked here on the answer itself), in fewer
    Newton iterations than the same polish taken to the absolute merit."""
    from test_nsgs import random_velocity_problem

    M, v_free, H, offset, mu = random_velocity_problem(2, 120, 100, 0)   # 200 unknowns, W positive definite
    starved = dict(large_problem_unknowns=0, max_sweeps=2, sweeps_per_check=1, polish_below=0.5, max_proximal=0)
    loose = solve_velocity(M, v_free, H, offset, mu, 2, settings=SolverSettings(tol_relative=1e-3, **starved))
    strict = solve_velocity(M, v_free, H, offset, mu, 2, settings=SolverSettings(**starved))
    assert loose.path == strict.path == "nsgs + polish"
    assert loose.status == strict.status == Status.POLISHED
    assert strict.merit <= 1e-8
    W = (H @ spla.spsolve(sp.csc_matrix(M), sp.csc_matrix(H.T))).toarray()
    q = H @ v_free + offset
    assert _relative(W, q, mu, loose.P.ravel(), 2) <= 1e-3
    assert loose.polish_iterations < strict.polish_iterations
    if loose.merit > 1e-8:
        assert any("tol_relative" in note for note in loose.notes)
