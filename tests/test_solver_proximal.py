"""The proximal-point outer loop (``nscd.solver.proximal``): its answer solves the original
exact-Coulomb problem (no regularisation left), checked against momentum balance on a
degenerate problem whose impulses are not unique, and it is the route a small problem
the fast path does not accept takes first."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from nscd.solver import SolverSettings, core, proximal, small
from nscd.solver.settings import Status
from nscd.solver.cone import merit_and_dual_violation

G = 9.80665


def _block_on_two_points(vx: float, vy: float, mu: float, dt: float = 1e-3):
    """A 2D block (0.4 x 0.2 m, 16 kg) landing on a fixed base on its two bottom corners,
    with free velocity (vx, vy - g dt): ``W = H M^-1 H^T`` (4 x 4, rank 3: the two
    tangential impulses can trade against each other, ``H^T (0, t, 0, -t) = 0``) and
    ``q = H v_free``. Rows per contact ``[N, T]``, normal +y, tangent +x."""
    b, h, m = 0.2, 0.1, 16.0
    inertia = m * (0.4 ** 2 + 0.2 ** 2) / 12.0
    H = np.array([[0.0, 1.0, -b], [1.0, 0.0, h],  # corner (-b, -h): v + omega x p
                  [0.0, 1.0, b], [1.0, 0.0, h]])
    Minv = np.diag([1 / m, 1 / m, 1 / inertia])
    v_free = np.array([vx, vy - G * dt, 0.0])
    return H @ Minv @ H.T, H @ v_free, np.full(2, mu), m, v_free


def _proximal_point(W, q, mu, tol):
    """The compiled proximal-point loop alone (no polish after it) from r = 0, accepted at FCLIB
    merit and dual-cone violation <= tol: ``(r, merit, converged)``."""
    n = q.size
    r, u, merit, info = np.empty((1, n)), np.empty((1, n)), np.empty(1), np.empty((1, 4), dtype=np.int64)
    proximal.solve_dense(W[None].copy(), q[None].copy(), mu[None].copy(), np.array([n]), 2, np.zeros((1, n)), tol,
                         0.0, True, 60, 25, 0, r, u, merit, info)
    return r[0], float(merit[0]), info[0, 0] == small.PROXIMAL


def test_degenerate_sticking_landing_stops_the_block_with_exact_coulomb():
    # Landing at 0.1 m/s while moving sideways at 0.02 m/s, mu = 0.5: the impulse that stops
    # it, m (0.02, 0.1 + g dt), lies inside the cone (0.02 < 0.5 x 0.11), so the block sticks:
    # the total impulse is fixed by momentum, its split between the corners is not.
    W, q, mu, m, v_free = _block_on_two_points(0.02, -0.1, 0.5)
    assert np.linalg.matrix_rank(W) == 3
    tol = 1e-10
    r, merit, converged = _proximal_point(W, q, mu, tol)
    assert converged and merit <= tol
    u = (W @ r + q).reshape(2, 2)
    r = r.reshape(2, 2)
    # the original problem's answer, not the regularised one: both corners at rest
    assert np.max(np.abs(u)) < 1e-9
    # momentum balance: the impulses take the block's free momentum to zero (the merit 1e-10,
    # over 1 + sqrt ||q|| = 1.4, bounds each impulse's error to ~1.4e-10 / W_NN = 7e-10 N s)
    np.testing.assert_allclose(r.sum(axis=0), [-m * v_free[1], -m * v_free[0]], rtol=0, atol=1e-8)
    # each corner inside its own cone, pushing (exact Coulomb per contact)
    assert np.all(r[:, 0] > 0) and np.all(np.abs(r[:, 1]) <= mu * r[:, 0] + 1e-12)


def test_sliding_landing_takes_the_coulomb_impulse():
    # Sideways at 1 m/s, mu = 0.3: stopping would need 16 N s > 0.3 x 1.76 N s, so the block
    # slides: both corners at the cone's edge, the total tangential impulse -mu times the
    # normal one, and the normal one stops the fall (u_N = 0).
    W, q, mu, m, v_free = _block_on_two_points(1.0, -0.1, 0.3)
    tol = 1e-10
    r, merit, converged = _proximal_point(W, q, mu, tol)
    assert converged
    u = (W @ r + q).reshape(2, 2)
    r = r.reshape(2, 2)
    # the merit 1e-10 (over 1 + sqrt ||q|| = 2.2) bounds the natural map, so each impulse's
    # error to ~2e-10 / W_NN (W_NN = 0.21 /kg): 1e-9 N s per corner; 1e-8 for the sum
    np.testing.assert_allclose(r[:, 0].sum(), -m * v_free[1], rtol=0, atol=1e-8)
    np.testing.assert_allclose(r[:, 1], -0.3 * r[:, 0], rtol=0, atol=1e-8)
    assert np.all(u[:, 1] > 0) and np.max(np.abs(u[:, 0])) < 1e-9


def test_the_sparse_loop_takes_the_coulomb_impulse_too():
    # The loop of large problems (a sparse W, inner problems by scipy's factorisations) on the
    # sliding landing above: the same Coulomb impulse (same error bounds).
    W, q, mu, m, v_free = _block_on_two_points(1.0, -0.1, 0.3)
    tol = 1e-10

    def measure(r, u):
        value = max(merit_and_dual_violation(r.reshape(-1, 2), u.reshape(-1, 2), mu, float(np.linalg.norm(q))))
        return value, value, value <= tol

    out = proximal.solve(sp.csr_matrix(W), q, mu, 2, np.zeros(4), True, 60, 25, measure, tol)
    assert out.converged and out.merit <= tol
    r = out.r.reshape(2, 2)
    np.testing.assert_allclose(r[:, 0].sum(), -m * v_free[1], rtol=0, atol=1e-8)
    np.testing.assert_allclose(r[:, 1], -0.3 * r[:, 0], rtol=0, atol=1e-8)


def test_a_problem_the_fast_path_does_not_accept_goes_through_the_proximal_point():
    # max_fast = 2: two Newton iterations from zero do not solve this problem, so the fast
    # path hands it on; the proximal point's inner problems (regularised, warm) need only
    # that many, and the answer meets the shipped tolerance on the original problem.
    W, q, mu, *_ = _block_on_two_points(1.0, -0.1, 0.3)
    settings = SolverSettings(max_fast=2)
    res = core.solve(W, q, mu, 2, settings)
    assert res.path.startswith("proximal point"), res.path
    assert res.proximal_iterations > 0 and res.iterations >= res.proximal_iterations
    value = max(merit_and_dual_violation(res.r.reshape(-1, 2), (W @ res.r + q).reshape(-1, 2), mu,
                                         float(np.linalg.norm(q))))
    assert value <= settings.tol


def _one_contact_coulomb(W, q, mu):
    """Coulomb's solution of one 2D contact ``u = W r + q`` (rows [N, T]) in closed form: the
    one of separation, sticking and sliding (``r_T = -s mu r_N``, ``u_N = 0``, ``u_T`` of sign
    ``s``) whose conditions hold."""
    if q[0] >= 0.0:
        return np.zeros(2)
    stick = -np.linalg.solve(W, q)
    if stick[0] >= 0.0 and abs(stick[1]) <= mu * stick[0]:
        return stick
    for s in (1.0, -1.0):
        r_n = -q[0] / (W[0, 0] - s * mu * W[0, 1])
        r = np.array([r_n, -s * mu * r_n])
        if r_n >= 0.0 and s * (W[1] @ r + q[1]) > 0.0:
            return r
    raise AssertionError("no Coulomb solution")


# One contact (mu = 2) of the three-block stack's double-pulse map, captured with its warm start:
# the Newton and the proximal point leave it at a stationary point of ||F|| (docs/solver.md), the
# conic fixed point solves it.
_STUCK_W = np.array([[2.8525764942867724, -1.6411023488698715], [-1.6411023488698715, 9.492951941281804]])
_STUCK_Q = np.array([-0.0043288290497071336, -0.11363578223478454])
_STUCK_R0 = np.array([0.0032337361893267744, 0.004182540903506859])


def test_a_stalled_proximal_point_hands_its_problem_on_early_and_the_chain_solves_it():
    mu, settings = np.array([2.0]), SolverSettings()
    r, u, merit, info = core.newton_batch(_STUCK_W[None], _STUCK_Q[None], mu[None], np.array([2]), 2, settings,
                                          _STUCK_R0[None])
    code, _, outer, _, _ = info[0].tolist()
    # the loop gave up once its best merit stopped falling, far from the tolerance, not after
    # max_proximal inner problems
    assert code == small.NOT_ACCEPTED and merit[0] > proximal._STALL_FLOOR * settings.tol
    assert proximal._STALL_WINDOW <= outer < settings.max_proximal
    res = core.solve(_STUCK_W, _STUCK_Q, mu, 2, settings, _STUCK_R0)
    assert res.status in (Status.CONVERGED, Status.POLISHED) and res.merit <= settings.tol
    exact = _one_contact_coulomb(_STUCK_W, _STUCK_Q, 2.0)
    # the FCLIB merit 1e-8 bounds the impulses' error to about 1e-8 of their scale (|q| / W_NN) times
    # the condition number of W (4.0 here): 1e-7 of the largest impulse leaves a factor 2.5 more
    np.testing.assert_allclose(res.r, exact, rtol=0, atol=1e-7 * np.abs(exact).max())


def test_the_sparse_loop_gives_up_when_stalled_far_from_the_tolerance_only():
    # The stall test of the sparse loop (the same as the compiled dense one's): a best merit that
    # does not fall ends the loop after _STALL_WINDOW inner problems when it is above
    # _STALL_FLOOR tol, and never below it (a flat merit near the tolerance may still jump).
    W, q, mu, *_ = _block_on_two_points(1.0, -0.1, 0.3)
    tol = 1e-8
    for flat, expected in ((1e3 * tol, proximal._STALL_WINDOW), (10.0 * tol, 60)):
        out = proximal.solve(sp.csr_matrix(W), q, mu, 2, np.zeros(4), True, 60, 25,
                             lambda r, u: (flat, flat, False), tol)
        assert not out.converged and out.outer == expected


@pytest.mark.parametrize("name", ["max_proximal", "proximal_unknowns"])
@pytest.mark.parametrize("value", [-1, 1.5, "3"])
def test_proximal_settings_must_be_non_negative_ints(name, value):
    with pytest.raises(ValueError, match=name):
        SolverSettings(**{name: value})


def test_a_problem_just_above_the_dense_limit_gets_the_proximal_point_after_the_sweeps():
    # 31 independent sliding blocks (124 unknowns > large_problem_unknowns = 120): the
    # Gauss-Seidel path; one sweep (max_sweeps = 1) leaves it unsolved and, with the polish
    # threshold out of reach, the proximal point (at most proximal_unknowns = 240) finishes
    # it before the interior point: each block takes its own Coulomb impulse.
    W1, q1, mu1, m, v_free = _block_on_two_points(1.0, -0.1, 0.3)
    copies = 31
    W = np.kron(np.eye(copies), W1)
    q, mu = np.tile(q1, copies), np.tile(mu1, copies)
    settings = SolverSettings(max_sweeps=1, sweeps_per_check=1, polish_below=1e-12)
    assert settings.large_problem_unknowns < q.size <= settings.proximal_unknowns
    res = core.solve(W, q, mu, 2, settings)
    assert res.path.startswith("nsgs + proximal point"), (res.path, res.notes)
    assert res.merit <= settings.tol and res.sweeps == 1
    r = res.r.reshape(copies, 2, 2)
    # per block, as the sliding test above: the normal impulses stop the fall, the tangential
    # ones are -mu times them (same error bound: 1e-8 N s)
    np.testing.assert_allclose(r[:, :, 0].sum(axis=1), -m * v_free[1], rtol=0, atol=1e-8)
    np.testing.assert_allclose(r[:, :, 1], -0.3 * r[:, :, 0], rtol=0, atol=1e-8)


def _chain_problem(n_contacts: int, seed: int):
    """A 2D problem of ``n_contacts`` contacts, each on one or two of a chain of bodies (W = H M^-1 H^T, sparse)."""
    rng = np.random.default_rng(seed)
    n_bodies = (n_contacts + 1) // 2 + 1
    rows, cols, vals = [], [], []
    for c in range(n_contacts):
        for body, sign in ((c // 2, 1.0), (c // 2 + 1, -1.0)):
            for row in (2 * c, 2 * c + 1):
                for dof in range(3):
                    rows.append(row)
                    cols.append(3 * body + dof)
                    vals.append(sign * rng.normal())
    H = sp.csr_matrix((vals, (rows, cols)), shape=(2 * n_contacts, 3 * n_bodies))
    Minv = sp.diags(rng.uniform(0.5, 2.0, 3 * n_bodies))
    q = rng.normal(size=2 * n_contacts)
    q[::2] -= 1.0
    return sp.csr_matrix(H @ Minv @ H.T), q, np.full(n_contacts, 0.6)


def test_a_sparse_mid_size_problem_takes_the_compiled_proximal_point_on_its_w_formed_dense():
    """Up to DENSE_PROXIMAL_UNKNOWNS the proximal point forms a sparse W dense and runs its compiled
    loop: the same answer, bit for bit, as the problem given dense; beyond, W stays sparse."""
    settings = SolverSettings()
    W, q, mu = _chain_problem(core.DENSE_PROXIMAL_UNKNOWNS // 2, seed=3)
    sparse = core._Scaled(W, q, mu, 2, settings)
    dense = core._Scaled(W.toarray(), q, mu, 2, settings)
    assert np.array_equal(sparse.original[0], W.toarray())
    a, b = core._proximal(sparse, settings, None), core._proximal(dense, settings, None)
    assert a.status in (Status.CONVERGED, Status.POLISHED) and a.merit <= settings.tol
    assert np.array_equal(a.r, b.r) and a.merit == b.merit
    W, q, mu = _chain_problem(core.DENSE_PROXIMAL_UNKNOWNS // 2 + 1, seed=3)
    assert core._Scaled(W, q, mu, 2, settings).original is None
