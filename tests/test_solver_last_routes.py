"""The last routes of a small problem that the compiled Newton, the proximal point and the conic
fixed point leave above the tolerance (``nscd.solver.core.solve_rejected``): in 2D the contacts'
regimes (``nscd.solver.regimes``), in 3D the proximal point once more with patient inner solves.

Each answer is checked against the regimes of an exact-Coulomb contact, written out here
independently of the solver: open (``r = 0``, ``u_N >= 0``), sticking (``u = 0``,
``|r_T| <= mu r_N``) and slipping (``u_N = 0``, ``r_T = -mu r_N u_T / |u_T|``)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from nscd.rigs import DoublePulseRig
from nscd.solver import SolverSettings, regimes, solve_local


def _regime_violation(W: np.ndarray, q: np.ndarray, mu: np.ndarray, r: np.ndarray) -> float:
    """The largest violation, over the contacts, of the conditions of the regime that fits each
    contact best (0 for an exact solution), in the units of ``r`` and ``u = W r + q``."""
    u = W @ r + q
    worst = 0.0
    for c in range(mu.size):
        rn, rt, un, ut = r[2 * c], r[2 * c + 1], u[2 * c], u[2 * c + 1]
        open_ = max(abs(rn), abs(rt), -un, 0.0)
        stick = max(abs(un), abs(ut), abs(rt) - mu[c] * rn, -rn, 0.0)
        slip = max(abs(un), abs(rt + mu[c] * rn * np.sign(ut)), -rn, 0.0)
        worst = max(worst, min(open_, stick, slip))
    return worst


#: Captured from the three-block stack of the double-pulse rig (v_peak 1.279 m/s, gap 5 mm,
#: t = 0.1285 s): two blocks, each on one corner, so W is block diagonal; the first corner's
#: free velocity is 0.34 m/s, the second's 1e-6 m/s. The semismooth Newton, the proximal point
#: and the conic fixed point all stalled at merit ~1e-7 (tolerance 1e-8) on the second contact,
#: whose impulse sits at the apex of its cone. Rows [N, T] per contact, m/s and kg^-1.
APEX_W = np.array([[4.6338060498343765, -3.3688411509690703, 0.0, 0.0],
                   [-3.3688411509690708, 7.712008574558243, 0.0, 0.0],
                   [0.0, 0.0, 4.359624172931155, 3.2294988441498953],
                   [0.0, 0.0, 3.2294988441498953, 7.986050345464495]])
APEX_Q = np.array([-3.3509146866215278e-01, 5.6652176648422370e-02, -4.2638943719558453e-07,
                   9.6739513988364223e-07])
APEX_MU = np.array([2.0, 2.0])


def test_two_sticking_contacts_six_orders_apart_are_solved_to_round_off():
    W, q, mu = APEX_W, APEX_Q, APEX_MU
    # By hand: each contact alone sticks if the impulse that stops it, -W_c^-1 q_c, lies in its
    # cone; both do here (|r_T| / r_N = 0.36 and 0.86 < mu = 2).
    expected = np.concatenate([-np.linalg.solve(W[:2, :2], q[:2]), -np.linalg.solve(W[2:, 2:], q[2:])])
    for c in range(2):
        assert abs(expected[2 * c + 1]) < mu[c] * expected[2 * c]
    sol = solve_local(W, q, mu, dim=2)
    assert sol.converged and sol.merit <= SolverSettings().tol
    # exact up to the round-off of 2 x 2 solves (W's blocks have condition numbers below 4), to
    # each impulse's own scale: the smaller is 1e-6 of the larger, so a merit-sized error (1e-8)
    # in it would fail this
    np.testing.assert_allclose(sol.r, expected, rtol=1e-12, atol=0.0)


def _random_problem(rng: np.random.Generator, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A 2D problem of ``m`` contacts on rigid bodies: ``W = H M^-1 H^T`` from random contact
    rows of two bodies (3 velocities each, unit masses), so ``W`` is semidefinite (rank <= 6) as
    an assembly's is; random free velocities and friction coefficients in [0.1, 2]."""
    H = rng.standard_normal((2 * m, 6))
    return H @ H.T + 1e-3 * np.eye(2 * m), rng.standard_normal(2 * m), rng.uniform(0.1, 2.0, m)


@pytest.mark.parametrize("m", [1, 2, 3, 4])
def test_every_answer_satisfies_its_regimes_and_the_acceptance_test(m):
    rng = np.random.default_rng(20261126 + m)
    for _ in range(25):
        W, q, mu = _random_problem(rng, m)
        found = regimes.solve(W, q, mu, np.zeros(2 * m), 1e-10)
        assert found is not None
        r, u, merit, trials = found
        np.testing.assert_allclose(u, W @ r + q, rtol=0, atol=1e-14)
        assert merit <= 1e-10 and 1 <= trials <= 4 ** m
        # round-off of a linear solve of at most 8 unknowns with W's condition up to ~1e4
        assert _regime_violation(W, q, mu, r) <= 1e-9 * (1.0 + np.abs(r).max() + np.abs(q).max())


@pytest.mark.parametrize("m", [2, 3, 4])
def test_the_regimes_read_from_an_exact_solution_are_its_own(m):
    # From the exact answer, the natural map's pieces name each contact's regime, so the
    # first linear system tried is the right one (contacts strictly inside their regime only:
    # at a corner of two regimes, either may be read).
    rng = np.random.default_rng(7 + m)
    checked = 0
    for _ in range(40):
        W, q, mu = _random_problem(rng, m)
        r, u, _, _ = regimes.solve(W, q, mu, np.zeros(2 * m), 1e-10)
        R, U = r.reshape(m, 2), u.reshape(m, 2)
        strict = np.all((R[:, 0] > 1e-6) | (U[:, 0] > 1e-6)) and np.all(
            (np.abs(U[:, 1]) > 1e-6) | (np.abs(R[:, 1]) < mu * R[:, 0] - 1e-6) | (R[:, 0] < 1e-12))
        if strict:
            assert regimes.solve(W, q, mu, r, 1e-10)[3] == 1
            checked += 1
    assert checked >= 10


def test_more_contacts_than_enumerated_are_refused():
    m = regimes.MAX_CONTACTS + 1
    with pytest.raises(ValueError, match=f"{m} contacts"):
        regimes.solve(np.eye(2 * m), np.ones(2 * m), np.ones(m), np.zeros(2 * m), 1e-8)


def test_regime_contacts_switches_the_route_and_is_checked():
    off = solve_local(APEX_W, APEX_Q, APEX_MU, dim=2, settings=SolverSettings(regime_contacts=0))
    assert off.path != "regimes"
    assert solve_local(APEX_W, APEX_Q, APEX_MU, dim=2).path in ("regimes", off.path)
    for bad in (-1, regimes.MAX_CONTACTS + 1, 2.0):
        with pytest.raises(ValueError, match="regime_contacts"):
            SolverSettings(regime_contacts=bad)


def test_the_double_pulse_cell_with_a_contact_at_its_cone_apex_converges_at_every_step():
    # The cell the first test's problem comes from: every step at its tolerance.
    rig = DoublePulseRig(specimen="stack3", scale=1, base="kinematic")
    outcome = rig.run(v_peak=1.2789473684210526, gap=0.005)
    assert outcome.unconverged_steps == 0


def _coulomb_violation_3d(r: np.ndarray, u: np.ndarray, mu: np.ndarray) -> float:
    """The largest violation, over the contacts, of exact Coulomb in 3D written out: the impulse in
    its cone, and open (``r = 0``, ``u_N >= 0``), sticking (``u = 0``) or slipping (``u_N = 0``,
    ``r_T = -mu r_N u_T / |u_T|``), the regime that fits each contact best."""
    worst = 0.0
    for c in range(mu.size):
        rn, rt, un, ut = r[3 * c], r[3 * c + 1:3 * c + 3], u[3 * c], u[3 * c + 1:3 * c + 3]
        cone = max(-rn, np.linalg.norm(rt) - mu[c] * rn, 0.0)
        open_ = max(abs(rn), np.linalg.norm(rt), -un, 0.0)
        stick = max(abs(un), np.linalg.norm(ut))
        slip = max(abs(un), np.linalg.norm(rt + mu[c] * rn * ut / max(np.linalg.norm(ut), 1e-300)))
        worst = max(worst, cone, min(open_, stick, slip))
    return worst


def test_a_degenerate_3d_problem_the_proximal_point_stalled_on_is_solved():
    # Captured from the LNEC trilith of 003 in 3D shaken at 6.5 Hz / 5 mm (bench_lnec_stacked.py's
    # Fig. 10 cell, midpoint rule, dt = 1 ms): 8 contacts (four corners on each of two faces, so
    # W (24 x 24) is singular), mu = 0.577, with the step's warm start. The Newton,
    # the proximal point (its inner solves capped at max_fast = 25 iterations) and the conic fixed
    # point left it at merit 2.3e-8 (tolerance 1e-8).
    data = np.load(Path(__file__).parent / "reference" / "trilith_degenerate_problem.npz")
    W, q, mu, r0 = data["W"], data["q"], data["mu"], data["r0"]
    assert np.linalg.eigvalsh(W).min() < 1e-12 * np.linalg.eigvalsh(W).max()  # degenerate indeed
    sol = solve_local(W, q, mu, dim=3, warm_start=r0)
    assert sol.converged and sol.merit <= SolverSettings().tol
    # the merit 1e-8 over 1 + sqrt(||q||) bounds each residual to ~1e-8 (m/s, N s per kg of W)
    assert _coulomb_violation_3d(sol.r, W @ sol.r + q, mu) <= 1e-7
