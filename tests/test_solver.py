"""Contact solver against closed-form single-contact and rigid-block results.

Every expected value below is derived by hand in the comment next to it (Coulomb's
law, momentum balance over one step); none is a recorded output of the solver.
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from nscd.solver import SolverSettings, Status, fclib_merit, solve_local, solve_velocity
from nscd.solver import cone

G = 9.81  # m/s^2
DT = 1e-3  # s
# Analytic checks solve to merit 1e-12: the natural-map residual is then <= 1e-12 (1 + sqrt||q||),
# and impulse errors are bounded by that times ||W^-1|| (<= 1e3 here: masses <= 100 kg,
# lever arms <= 0.5 m), i.e. < 1e-8 N s, velocity errors by that / m < 1e-9 m/s.
TIGHT = SolverSettings(tol=1e-12)


# ---------------------------------------------------------------- helpers

def block_2d(mass=100.0, b=0.2, h=0.5):
    """Rigid 2D block (half width b, half height h) on the floor, contacts at both bottom corners.

    Velocities (vx, vy, omega); contact point (x_c, -h) relative to the centre moves at
    (vx + omega h, vy + omega x_c): rows [N, T] = [0, 1, x_c], [1, 0, h].
    """
    inertia = mass * ((2 * b) ** 2 + (2 * h) ** 2) / 12.0
    M = sp.diags([mass, mass, inertia]).tocsr()
    H = sp.csr_matrix(np.array([[0, 1, -b], [1, 0, h], [0, 1, b], [1, 0, h]], dtype=float))
    return M, H


def point_mass(mass=2.0, dim=3):
    """A particle on the floor z = 0 (or y = 0): rows [N, T1, (T2)] = [z, x, (y)]."""
    M = sp.identity(dim, format="csr") * mass
    perm = [dim - 1] + list(range(dim - 1))
    H = sp.csr_matrix(np.eye(dim)[perm])
    return M, H


# ---------------------------------------------------------------- cone and merit

@pytest.mark.parametrize("dim", [2, 3])
def test_projection_is_the_euclidean_projection(dim):
    rng = np.random.default_rng(1)
    x = rng.normal(size=(500, dim))
    mu = rng.uniform(0.0, 2.0, 500)
    mu[:50] = 0.0
    p = cone.project(x, mu)
    d = x - p
    # Moreau decomposition: p in K, x - p in the polar cone -K*, p orthogonal to x - p
    # (round-off of O(1) data: 1e-12).
    assert np.all(cone.tangent_norm(p) <= mu * p[:, 0] + 1e-12)
    assert np.all(mu * cone.tangent_norm(d) <= -d[:, 0] + 1e-12)
    assert np.allclose(np.einsum("ij,ij->i", p, d), 0.0, atol=1e-12)


def test_merit_hand_computed():
    # W = I, q = (-1, 0, 0): r = 0 gives u = q; r - (u + 0) = (1, 0, 0) lies in K, so
    # e = r - P_K(...) = (-1, 0, 0) and merit = 1 / (1 + sqrt(||q||)) = 1/2.
    W, q = np.eye(3), np.array([-1.0, 0.0, 0.0])
    assert fclib_merit(W, q, [0.3], np.zeros(3), 3) == pytest.approx(0.5, rel=1e-15)
    # r = (1, 0, 0) gives u = 0: an exact solution, merit 0.
    assert fclib_merit(W, q, [0.3], np.array([1.0, 0.0, 0.0]), 3) == 0.0


@pytest.mark.parametrize("dim", [2, 3])
def test_single_sliding_contact_reaction_form(dim):
    # W = I, q = (-1, 2, 0), mu = 0.5: sliding along +t1 with u_N = 0 needs r_N = 1,
    # r_T = -mu r_N e1 = (-0.5, 0); then u_T = (2 - 0.5, 0) = (1.5, 0) keeps sliding.
    q = np.array([-1.0, 2.0, 0.0][:dim])
    sol = solve_local(np.eye(dim), q, [0.5], dim=dim)
    assert sol.converged and sol.status in (Status.CONVERGED, Status.POLISHED)
    # merit 1e-8 bounds the natural-map residual, hence the error of r for W = I.
    assert np.allclose(sol.r, [1.0, -0.5, 0.0][:dim], atol=1e-7)
    assert np.allclose(sol.u, [0.0, 1.5, 0.0][:dim], atol=1e-7)


# ---------------------------------------------------------------- velocity form, analytic

@pytest.mark.parametrize("dim", [2, 3])
def test_particle_sliding_one_step(dim):
    # v0 = 1 m/s along x, mu g dt << v0: one step of Coulomb sliding removes mu g dt,
    # the normal impulse cancels gravity: P_N = m g dt, P_T = -mu m g dt along x.
    mass, mu = 2.0, 0.3
    M, H = point_mass(mass, dim)
    v_free = np.zeros(dim)
    v_free[0], v_free[-1] = 1.0, -G * DT
    sol = solve_velocity(M, v_free, H, np.zeros(dim), [mu], dim, settings=TIGHT)
    assert sol.converged and sol.merit <= TIGHT.tol
    expected_P = np.zeros(dim)
    expected_P[0], expected_P[1] = mass * G * DT, -mu * mass * G * DT
    # impulses are O(1e-2) N s; merit 1e-8 bounds their error well below 1e-9.
    assert np.allclose(sol.P[0], expected_P, atol=1e-9)
    assert sol.v[0] == pytest.approx(1.0 - mu * G * DT, abs=1e-9)
    assert abs(sol.v[-1]) < 1e-9  # no lift-off with exact Coulomb


def test_block_sliding_one_step_impulses():
    # Rigid block sliding at v0 on both corners: momentum gives P_N1 + P_N2 = m g dt and
    # P_T,i = -mu P_N,i; no rotation requires the angular impulse about the centre,
    # b (P_N2 - P_N1) + h (P_T1 + P_T2) = 0, so P_N2 - P_N1 = mu (h/b) m g dt
    # (the leading corner, x = +b, carries more).
    mass, mu, b, h = 100.0, 0.3, 0.2, 0.5
    M, H = block_2d(mass, b, h)
    v0 = 0.5
    sol = solve_velocity(M, np.array([v0, -G * DT, 0.0]), H, np.zeros(4), [mu, mu], 2, settings=TIGHT)
    assert sol.converged and sol.merit <= TIGHT.tol
    total = mass * G * DT
    diff = mu * h / b * total
    expected = np.array([[(total - diff) / 2, -mu * (total - diff) / 2],
                         [(total + diff) / 2, -mu * (total + diff) / 2]])
    assert np.allclose(sol.P, expected, atol=1e-8)  # see TIGHT
    assert np.allclose(sol.v, [v0 - mu * G * DT, 0.0, 0.0], atol=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_sticking_below_mu(dim):
    # Tangential push F = 0.5 mu m g: the friction impulse cancels it, the particle stays.
    mass, mu = 2.0, 0.4
    M, H = point_mass(mass, dim)
    F = 0.5 * mu * mass * G
    direction = np.array([0.6, 0.8])[: dim - 1]
    v_free = np.zeros(dim)
    v_free[: dim - 1] = F * DT / mass * direction
    v_free[-1] = -G * DT
    sol = solve_velocity(M, v_free, H, np.zeros(dim), [mu], dim, settings=TIGHT)
    assert sol.converged
    assert np.allclose(sol.v, 0.0, atol=1e-9)  # see TIGHT
    assert sol.P[0, 0] == pytest.approx(mass * G * DT, rel=1e-7)
    assert np.allclose(sol.P[0, 1:], -F * DT * direction, atol=1e-9)
    assert np.linalg.norm(sol.P[0, 1:]) < mu * sol.P[0, 0]  # strictly inside the cone


@pytest.mark.parametrize("dim", [2, 3])
def test_frictionless_contact(dim):
    # mu = 0: the normal impulse stops the fall, tangential motion is untouched, P_T = 0.
    mass = 2.0
    M, H = point_mass(mass, dim)
    v_free = np.zeros(dim)
    v_free[0], v_free[-1] = 1.5, -G * DT
    sol = solve_velocity(M, v_free, H, np.zeros(dim), [0.0], dim, settings=TIGHT)
    assert sol.converged
    assert sol.P[0, 0] == pytest.approx(mass * G * DT, rel=1e-7)
    assert np.allclose(sol.P[0, 1:], 0.0, atol=1e-12)  # the cone {r_T = 0}: exact up to round-off
    assert sol.v[0] == pytest.approx(1.5, abs=1e-9)


def test_frictionless_through_the_conic_path():
    # Same as above with the fast path off: exercises the nonnegative and zero cones.
    mass = 2.0
    M, H = point_mass(mass, 3)
    sol = solve_velocity(M, np.array([1.5, 0.0, -G * DT]), H, np.zeros(3), [0.0], 3,
                         settings=SolverSettings(tol=TIGHT.tol, fast_path_unknowns=0))
    assert sol.converged and sol.fixed_point_iterations >= 1
    assert sol.P[0, 0] == pytest.approx(mass * G * DT, rel=1e-7)
    assert np.allclose(sol.P[0, 1:], 0.0, atol=1e-10)  # see TIGHT


def test_separating_contact_has_no_impulse():
    # Moving away (u_N > 0 without any impulse): P = 0 exactly solves the problem.
    M, H = point_mass(2.0, 3)
    sol = solve_velocity(M, np.array([0.3, 0.0, 0.5]), H, np.zeros(3), [0.5], 3)
    assert sol.converged
    assert np.allclose(sol.P, 0.0, atol=1e-12)


def test_newton_restitution_offset():
    # offset = e u_N^k on the normal row (Newton impact): the particle arriving at
    # u_N^k = -2 m/s leaves at +e * 2 m/s (frictionless, no gravity within the impact).
    e, mass = 0.5, 2.0
    M, H = point_mass(mass, 3)
    u_before = -2.0
    sol = solve_velocity(M, np.array([0.0, 0.0, u_before]), H, np.array([e * u_before, 0.0, 0.0]), [0.0], 3,
                         settings=TIGHT)
    assert sol.converged
    assert sol.v[2] == pytest.approx(-e * u_before, abs=1e-8)
    assert sol.u[0, 0] == pytest.approx(0.0, abs=1e-8)  # u~_N = u_N + e u_N^k = 0


@pytest.mark.parametrize("path", ["fast", "conic"])
def test_exact_vs_relaxed_lift_off(path):
    # Sliding particle, relaxed cone (s = 0): the solution satisfies u ∈ K* with
    # u_N = mu |u_T| > 0 — it lifts off. Exact Coulomb keeps u_N = 0.
    mass, mu = 2.0, 0.5
    M, H = point_mass(mass, 3)
    v_free = np.array([1.0, 0.0, -G * DT])
    fast = 0 if path == "conic" else 120
    exact = solve_velocity(M, v_free, H, np.zeros(3), [mu], 3, settings=SolverSettings(fast_path_unknowns=fast))
    relaxed = solve_velocity(M, v_free, H, np.zeros(3), [mu], 3,
                             settings=SolverSettings(coulomb="relaxed", fast_path_unknowns=fast))
    assert exact.converged and relaxed.converged
    assert abs(exact.u[0, 0]) < 1e-8
    u_t = np.linalg.norm(relaxed.u[0, 1:])
    assert relaxed.u[0, 0] > 0.1  # a clear lift-off, not round-off
    assert relaxed.u[0, 0] == pytest.approx(mu * u_t, rel=1e-6)  # on the boundary of K*


def test_velocity_and_reaction_forms_agree():
    # Random well-posed problem: 4 contacts on 2 rigid 3D bodies (12 dofs >= 12 rows,
    # H of full rank, so W = H M^-1 H^T is positive definite and r is unique).
    rng = np.random.default_rng(7)
    n, m, dim = 12, 4, 3
    blocks = []
    for _ in range(2):
        A = rng.normal(size=(3, 3))
        blocks += [np.eye(3) * rng.uniform(1, 5), A @ A.T + np.eye(3)]
    M = sp.block_diag(blocks).tocsr()
    H = rng.normal(size=(m * dim, n))
    v_free = rng.normal(size=n)
    offset = rng.normal(size=m * dim) * 0.1
    mu = rng.uniform(0.2, 0.8, m)
    vel = solve_velocity(M, v_free, sp.csr_matrix(H), offset, mu, dim)
    Minv = np.linalg.inv(M.toarray())
    W = H @ Minv @ H.T
    q = H @ v_free + offset
    loc = solve_local(W, q, mu, dim=dim)
    assert vel.converged and loc.converged
    scale = np.linalg.norm(loc.r)
    # both at merit <= 1e-8 on a PD problem of condition < 1e4: impulses agree to 1e-5 relative
    assert np.allclose(vel.P.ravel(), loc.r, atol=1e-5 * scale)
    assert np.allclose(vel.v, v_free + Minv @ H.T @ loc.r, atol=1e-5 * np.linalg.norm(vel.v))
    assert vel.merit == pytest.approx(fclib_merit(W, q, mu, vel.P.ravel(), dim), rel=1e-6)


def test_fast_path_and_conic_path_agree():
    # Same random PD problem, fast Newton path versus Clarabel fixed point (+ polish).
    rng = np.random.default_rng(3)
    A = rng.normal(size=(9, 9))
    W = A @ A.T + np.eye(9)
    q = rng.normal(size=9)
    mu = [0.3, 0.6, 0.9]
    fast = solve_local(W, q, mu, dim=3)
    conic = solve_local(W, q, mu, dim=3, settings=SolverSettings(fast_path_unknowns=0))
    assert fast.path == "newton (fast path)" and conic.path.startswith("interior point")
    assert fast.converged and conic.converged
    assert np.allclose(fast.r, conic.r, atol=1e-6 * np.linalg.norm(fast.r))  # merit 1e-8, cond(W) < 1e3


def test_warm_start_from_solution_takes_no_iteration():
    M, H = block_2d()
    v_free = np.array([0.5, -G * DT, 0.0])
    first = solve_velocity(M, v_free, H, np.zeros(4), [0.3, 0.3], 2)
    again = solve_velocity(M, v_free, H, np.zeros(4), [0.3, 0.3], 2, warm_start=first.P)
    assert again.converged and again.iterations == 0
    assert np.array_equal(again.P, first.P)


def test_no_contact():
    M, _ = point_mass(2.0, 3)
    sol = solve_velocity(M, np.ones(3), sp.csr_matrix((0, 3)), np.zeros(0), np.zeros(0), 3)
    assert sol.converged and sol.P.shape == (0, 3) and np.array_equal(sol.v, np.ones(3))


def test_unsolvable_problem_is_refused_not_hidden():
    # W = 0 and an approaching q: no impulse can stop the approach (infeasible). Solved, the
    # impulses ran to ~1e21 where the FCLIB merit rounds to 0.0 (r - u == r); the zero normal
    # entry of W is refused up front instead.
    with pytest.raises(ValueError, match=r"W\[0, 0\] == 0.0 \(normal row of contact 0\), must be > 0"):
        solve_local(np.zeros((3, 3)), np.array([-1.0, 0.0, 0.0]), [0.5], dim=3)


# ---------------------------------------------------------------- bad input

@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(W=np.eye(3)[:, :2]), "W has shape"),
        (dict(q=np.zeros(4)), "q has 4 entries"),
        (dict(q=np.zeros(6)), "W has shape"),
        (dict(mu=[-0.1]), r"mu\[0\] == -0.1, must be >= 0"),
        (dict(mu=[0.1, 0.2]), "mu has shape"),
        (dict(dim=4), "dim == 4, must be 2 or 3"),
        (dict(W=np.full((3, 3), np.nan)), "W contains NaN"),
        (dict(q=np.array([np.nan, 0.0, 0.0])), "q contains NaN"),
        (dict(mu=[np.nan]), "mu contains NaN"),
    ],
)
def test_bad_input_local(kwargs, match):
    args = dict(W=np.eye(3), q=np.array([-1.0, 0.0, 0.0]), mu=[0.3], dim=3)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        solve_local(args["W"], args["q"], args["mu"], dim=args["dim"])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        (dict(M=sp.identity(2)), "M has shape"),
        (dict(H=sp.csr_matrix(np.eye(3)[:, :2])), "H has shape"),
        (dict(offset=np.zeros(4)), "offset has 4 entries"),
        (dict(v_free=np.array([np.nan, 0, 0])), "v_free contains NaN"),
        (dict(M=sp.diags([1.0, -1.0, 1.0])), "must be > 0"),
        (dict(M=np.array([[2.0, 1.0, 0.0], [1.0, -2.0, 0.0], [0.0, 0.0, 1.0]])), "not positive definite"),
        (dict(M=np.array([[2.0, 1.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 1.0]])), "not symmetric"),
        (dict(mu=[-1.0]), r"mu\[0\] == -1.0"),
        (dict(warm_start=np.zeros(3)), "warm_start has shape"),
        (dict(dim=1), "dim == 1"),
    ],
)
def test_bad_input_velocity(kwargs, match):
    M, H = point_mass(2.0, 3)
    args = dict(M=M, v_free=np.zeros(3), H=H, offset=np.zeros(3), mu=[0.3], dim=3, warm_start=None)
    args.update(kwargs)
    with pytest.raises(ValueError, match=match):
        solve_velocity(args["M"], args["v_free"], args["H"], args["offset"], args["mu"], args["dim"],
                       warm_start=args["warm_start"])


def test_settings_validation():
    with pytest.raises(ValueError, match="coulomb == 'approx'"):
        SolverSettings(coulomb="approx")
    with pytest.raises(ValueError, match="tol == 0.0"):
        SolverSettings(tol=0.0)
    with pytest.raises(ValueError, match="max_polish == 0"):
        SolverSettings(max_polish=0)
    with pytest.raises(ValueError, match="max_sweeps == True"):  # a bool is not a count
        SolverSettings(max_sweeps=True)
    with pytest.raises(ValueError, match="regime_contacts == False"):
        SolverSettings(regime_contacts=False)
    assert SolverSettings(max_sweeps=np.int64(50)).max_sweeps == 50  # numpy integers are counts


@pytest.mark.parametrize("dim", [2, 3])
def test_projection_jacobian_matches_finite_differences(dim):
    rng = np.random.default_rng(5)
    x = rng.normal(size=(400, dim))
    mu = rng.uniform(0.0, 1.5, 400)
    mu[:40] = 0.0
    J = cone.project_jacobian(x, mu)
    h = 1e-7
    for k in range(dim):
        e = np.zeros(dim)
        e[k] = h
        fd = (cone.project(x + e, mu) - cone.project(x - e, mu)) / (2 * h)
        # central differences: truncation O(h^2 * curvature) plus round-off 1e-16 / h ~ 1e-9;
        # random points are almost surely away from the kinks of the projection.
        assert np.allclose(fd, J[:, :, k], atol=1e-6)


def test_conic_duals_are_the_shifted_velocities():
    # Derivation (nscd/solver/conic.py): with z = (mu r_N, r_T) in SOC and A = -diag(mu, 1, 1),
    # KKT gives W r + q + s e_N = (mu y_N, y_T), i.e. y = ((u_N + s) / mu, u_T) with u = W r + q.
    from nscd.solver.conic import ConicSubproblem

    rng = np.random.default_rng(11)
    A = rng.normal(size=(6, 6))
    W = A @ A.T + 0.1 * np.eye(6)
    q = rng.normal(size=6)
    mu = np.array([0.4, 0.7])
    shift = np.array([0.3, 0.0, 0.0, 0.1, 0.0, 0.0])  # s on the normal rows
    res = ConicSubproblem(W, mu, 3, 1e-10, 1e-10, 1e-10, 100).solve(q + shift)
    assert res.ok
    v = (W @ res.r + q + shift).reshape(2, 3)
    expected = np.column_stack([v[:, 0] / mu, v[:, 1:]]).ravel()
    # interior-point tolerances 1e-10 on O(1) data
    assert np.allclose(res.y, expected, atol=1e-7)
    # and the impulses lie in the Coulomb cones
    r = res.r.reshape(2, 3)
    assert np.all(np.linalg.norm(r[:, 1:], axis=1) <= mu * r[:, 0] + 1e-9)


@pytest.mark.parametrize("fast", [120, 0], ids=["fast path", "conic path"])
def test_cube_sliding_on_four_corners_3d(fast):
    # Rigid cube (side 2a) sliding diagonally on 4 bottom corners: W is 12 x 12 of rank 6
    # (statically indeterminate), yet velocities are unique: every corner slides with the
    # cube, so the friction impulses add up to -mu (m g dt) along the sliding direction,
    # the normal impulses to m g dt, and the cube neither lifts nor spins:
    # v = v0 - mu g dt e, omega = 0.
    mass, a, mu = 50.0, 0.25, 0.4
    inertia = mass * (2 * a) ** 2 / 6.0
    M = sp.diags([mass] * 3 + [inertia] * 3).tocsr()
    rows = []
    for x, y in [(-a, -a), (a, -a), (a, a), (-a, a)]:
        p = np.array([x, y, -a])  # corner relative to the centre
        for direction in (np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])):
            # velocity of the corner along `direction`: d . (v + omega x p) = d . v + (p x d) . omega
            rows.append(np.concatenate([direction, np.cross(p, direction)]))
    H = sp.csr_matrix(np.array(rows))
    e = np.array([0.6, 0.8, 0.0])
    v0 = 0.7
    v_free = np.concatenate([v0 * e + [0.0, 0.0, -G * DT], np.zeros(3)])
    settings = SolverSettings(tol=TIGHT.tol, fast_path_unknowns=fast)
    sol = solve_velocity(M, v_free, H, np.zeros(12), np.full(4, mu), 3, settings=settings)
    assert sol.converged
    expected = np.concatenate([(v0 - mu * G * DT) * e, np.zeros(3)])
    assert np.allclose(sol.v, expected, atol=1e-9)  # see TIGHT
    assert sol.P[:, 0].sum() == pytest.approx(mass * G * DT, rel=1e-8)
    assert np.allclose(sol.P[:, 1:].sum(axis=0), -mu * mass * G * DT * e[:2], atol=1e-8)
