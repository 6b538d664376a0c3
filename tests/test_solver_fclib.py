"""The contact solver on the 23 FCLIB / Siconos problems (external test set).

The files carry no reference solution: the oracle is FCLIB's merit, recomputed here
independently of the solver (plain numpy, straight from the README's definition), so a
solver that reported a wrong merit would fail. Target: merit <= 1e-8, the level the
field calls "solved" (README); 1e-6 for the granular-flow file printed with 6 digits.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

from nscd import fclib
from nscd.solver import SolverSettings, Status, solve_local, solve_velocity

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "fclib"
FILES = sorted(DATA.glob("*.npz")) if DATA.is_dir() else []
pytestmark = pytest.mark.skipif(not FILES, reason=f"FCLIB test problems not found in {DATA} "
                                "(shared/data/fclib beside the repository)")

# Tolerances from the task: 1e-8 everywhere, 1e-6 for the file printed with 6 significant digits.
LOOSE = {"fc2d_granularflowonwall_00667_00000": 1e-6}


def reference_merit(W, q, mu, r, dim):
    """FCLIB merit written out from the README, contact by contact (no solver code)."""
    u = W @ r + q
    total = 0.0
    for c in range(mu.size):
        rc, uc = r[c * dim:(c + 1) * dim], u[c * dim:(c + 1) * dim]
        x = rc - (uc + np.r_[mu[c] * np.linalg.norm(uc[1:]), np.zeros(dim - 1)])
        xn, xt = x[0], x[1:]
        nt = np.linalg.norm(xt)
        # the polar cone first (-x in K*: the projection is 0), then the cone itself: with
        # mu = 0 and x_T = 0 the cone test 0 <= mu x_N also holds for x_N < 0, and taking it
        # first would keep x (a negative normal impulse) as its own projection
        if mu[c] * nt <= -xn:
            p = np.zeros(dim)
        elif nt <= mu[c] * xn:
            p = x
        else:
            a = (xn + mu[c] * nt) / (1 + mu[c] ** 2)
            p = np.r_[a, mu[c] * a * xt / nt]
        total += np.sum((rc - p) ** 2)
    return np.sqrt(total) / (1 + np.sqrt(np.linalg.norm(q)))


# All 23 run in the default suite: together about 10 s on the 2-core test machine.
@pytest.mark.parametrize("path", [pytest.param(f, id=f.stem) for f in FILES])
def test_fclib_problem_solved(path):
    p = fclib.load(path)
    target = LOOSE.get(p.name, 1e-8)
    sol = solve_local(p.W, p.q, p.mu, dim=p.dim, tol=target)
    assert sol.converged, f"{p.name}: {sol.status} {sol.message}"
    assert sol.status in (Status.CONVERGED, Status.POLISHED)
    assert reference_merit(p.W, p.q, p.mu, sol.r, p.dim) <= target
    # the reported merit is the same quantity (round-off of the two evaluations: 1e-12 abs)
    assert sol.merit == pytest.approx(reference_merit(p.W, p.q, p.mu, sol.r, p.dim), rel=1e-6, abs=1e-12)
    # u is W r + q (relative round-off 1e-10)
    assert np.allclose(sol.u, p.W @ sol.r + p.q, rtol=1e-10, atol=1e-10 * np.abs(p.q).max())


def test_loader_fields():
    p = fclib.load(DATA / "FrictionContact3D_1c.npz")
    assert (p.name, p.dim, p.contacts) == ("FrictionContact3D_1c", 3, 1)
    assert p.W.shape == (3, 3) and p.q.shape == (3,) and p.M_diag is None
    big = fclib.load(DATA / "Capsules-i101-404.npz")
    assert sp.issparse(big.W) and big.W.shape == (675, 675)


def test_loader_rejects_other_files(tmp_path):
    bad = tmp_path / "x.npz"
    np.savez(bad, a=np.zeros(2))
    with pytest.raises(ValueError, match="not an FCLIB problem"):
        fclib.load(bad)


@pytest.mark.parametrize("name", ["Box_Stacks-i0122-82-5", "spheres-in-a-box-98-i10000-256-10"])
def test_global_problem_in_velocity_form(name):
    # FCLIB's global form M v = H r + f, u = H^T v + w is nscd's velocity form with
    # v_free = M^-1 f, Jacobian H^T, offset w; the same merit must be reached on W, q.
    p = fclib.load(DATA / f"{name}.npz")
    sol = solve_velocity(sp.diags(p.M_diag), p.f / p.M_diag, p.H.T, p.w, p.mu, p.dim)
    assert sol.converged, sol.message
    r = sol.P.ravel()
    assert reference_merit(p.W, p.q, p.mu, r, p.dim) <= 1e-8
    # v = M^-1 (H r + f) and u = H^T v + w (round-off, relative 1e-10)
    v = (p.H @ r + p.f) / p.M_diag
    assert np.allclose(sol.v, v, rtol=1e-10, atol=1e-10 * np.abs(v).max())
    u = p.H.T @ v + p.w
    assert np.allclose(sol.u.ravel(), u, rtol=1e-10, atol=1e-10 * np.abs(u).max())


def test_status_is_honest_when_stopped_early():
    # No polish, no proximal point and a single conic solve: the stack problem cannot reach
    # 1e-8 (the plain interior point stalls near 1e-7 on its degenerate contacts).
    p = fclib.load(DATA / "BoxesStack1-i100000-32.npz")
    sol = solve_local(p.W, p.q, p.mu, dim=p.dim,
                      settings=SolverSettings(polish=False, max_fixed_point=1, fast_path_unknowns=0,
                                              max_proximal=0))
    assert not sol.converged
    assert sol.status in (Status.STALLED, Status.CYCLING)
    assert reference_merit(p.W, p.q, p.mu, sol.r, p.dim) > 1e-8
    assert "tol" in sol.message
