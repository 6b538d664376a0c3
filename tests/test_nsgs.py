"""The large-problem path: nonsmooth Gauss–Seidel (``nscd.solver.nsgs``) and the linear-time step.

Oracles: De Saxcé's complementarity itself (the natural map vanishes at a solution),
the interior-point path of the same solver on the same problems (a different
algorithm: Clarabel + Newton polish), FCLIB's merit recomputed independently, exact
statics of a wall at rest (the base carries the weight), and plain definitions
(``M^-1 B`` against a dense solve, dict semantics of the warm start, the scene's laws).
"""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.sparse as sp

import nscd
from nscd import fclib
from nscd.builders import wall
from nscd.model import Model
from nscd.motion import STANDARD_GRAVITY as G
from nscd.solver import SolverSettings, cone, nsgs, solve_local, solve_velocity
from nscd.solver.api import _inverse_mass_times
from nscd.stepper import Settings, Simulator, WarmStart, initial_state, warm_start_of
from nscd.state import LINEAR_PREDICTION_GAIN
from test_solver_fclib import reference_merit

NSGS = SolverSettings(large_problem_unknowns=0)          # every problem above the fast path: NSGS
INTERIOR = SolverSettings(large_problem_unknowns=10**9)  # never NSGS: the interior-point path
DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "fclib"
FCLIB = sorted(DATA.glob("*.npz")) if DATA.is_dir() else []


def natural_map_norm(W, r, b, mu):
    """max |F| of one contact's De Saxcé natural map (0 at a solution)."""
    u = W @ r + b
    return float(np.abs(cone.natural_map(r[None], u[None], np.array([mu]))).max())


@pytest.mark.parametrize("dim", [2, 3])
def test_local_solve_is_exact(dim):
    """The per-contact solve satisfies De Saxcé's complementarity to round-off, in every regime."""
    rng = np.random.default_rng(dim)
    regimes = set()
    for k in range(400):
        A = rng.normal(size=(dim, dim))
        W = A @ A.T + 0.05 * np.eye(dim)  # symmetric positive definite, like H M^-1 H^T
        b = rng.normal(size=dim)
        mu = 0.0 if k % 10 == 0 else rng.uniform(0.05, 1.5)
        r = np.zeros(dim)
        if dim == 2:
            r[:] = nsgs._local_2d(W[0, 0], W[0, 1], W[1, 0], W[1, 1], b[0], b[1], mu)
        else:
            nsgs._local_3d(W, b, mu, r)
        # exact up to round-off of O(1) data (the 3D slide root is found to the last bits)
        assert natural_map_norm(W, r, b, mu) <= 1e-12 * (1.0 + np.abs(b).max() + np.abs(r).max())
        tangent = np.linalg.norm(r[1:])
        regimes.add("separate" if r[0] == 0.0 else "stick" if tangent < mu * r[0] * (1 - 1e-9) else "slide")
    assert regimes == {"separate", "stick", "slide"}  # every branch was exercised


def random_velocity_problem(dim: int, n_bodies: int, n_contacts: int, seed: int):
    """Bodies with random masses, contacts between random pairs (or a body and the ground).

    Contact ``c`` acts on body ``c`` (its own) and, every other contact, on one more random
    body: H has full row rank, so W = H M^-1 H^T is positive definite.
    """
    rng = np.random.default_rng(seed)
    nv = 3 if dim == 2 else 6
    n = n_bodies * nv
    blocks = []
    for _ in range(n_bodies):
        A = rng.normal(size=(nv, nv))
        blocks.append(A @ A.T + nv * np.eye(nv) if dim == 3 else np.diag(rng.uniform(0.5, 2.0, nv)))
    M = sp.block_diag(blocks, format="csr")
    rows, cols, vals = [], [], []
    for c in range(n_contacts):
        others = np.delete(np.arange(n_bodies), c)
        for body in [c, rng.choice(others)][: 1 + c % 2]:
            for i in range(dim):
                rows += [c * dim + i] * nv
                cols += list(range(body * nv, body * nv + nv))
                vals += list(rng.normal(size=nv))
    H = sp.csr_matrix((vals, (rows, cols)), shape=(n_contacts * dim, n))
    v_free = rng.normal(size=n)
    offset = rng.normal(size=n_contacts * dim) * 0.5
    offset[::dim] -= 0.5  # most contacts approach
    mu = rng.uniform(0.1, 0.8, n_contacts)
    return M, v_free, H, offset, mu


@pytest.mark.parametrize("dim", [2, 3])
def test_nsgs_matches_interior_point_on_random_sparse_problems(dim):
    """NSGS and the Clarabel path reach merit <= 1e-8 on the same problems and agree on u and v."""
    for seed in range(3):
        M, v_free, H, offset, mu = random_velocity_problem(dim, 120, 100 if dim == 2 else 60, seed)
        a = solve_velocity(M, v_free, H, offset, mu, dim, settings=NSGS)
        b = solve_velocity(M, v_free, H, offset, mu, dim, settings=INTERIOR)
        assert a.path == "nsgs" and a.sweeps > 0 and a.converged and a.merit <= 1e-8
        assert b.path.startswith("interior point") and b.converged and b.merit <= 1e-8
        # W positive definite (cond ~1e3 here): two merit-1e-8 solutions differ by at most
        # ~cond * merit * (1 + sqrt |q|) ~ 1e-5 in u; 1e-5 of the data scale.
        scale = 1.0 + np.abs(H @ v_free + offset).max()
        assert np.abs(a.u - b.u).max() <= 1e-5 * scale
        assert np.abs(a.v - b.v).max() <= 1e-5 * (1.0 + np.abs(v_free).max())


def test_local_3d_slide_is_exact_far_from_isotropy_and_at_the_ends_of_its_root():
    """The 3D sliding root (Newton's method on ``mu r_N / |r_T| - 1``, kept in its bracket) where its
    start is poor: a tangential block anisotropic by 1e4 (the Schur complement far from ``s I``), a
    slide barely past the cone (root near ``kappa = 0``), a slide a million times past it (the
    bracket's high end grown from the block's scale), friction 1e-3 to 5. Each solution satisfies
    De Saxce's law to round-off of its own data: the natural map within 1e-12 of ``|b| + |W| |r|``
    (the size of the terms whose rounding it measures), and the root does not depend on where its
    search starts (the sweeps start it from the contact's last one) beyond round-off."""
    rng = np.random.default_rng(11)
    slides = 0
    for k in range(600):
        Q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        W = Q @ np.diag([1.0, 10.0 ** rng.uniform(-2, 2), 10.0 ** rng.uniform(-2, 2)]) @ Q.T
        mu = [1e-3, 0.05, 0.7, 5.0][k % 4]
        b = np.array([-1.0, 0.0, 0.0])
        stick = -np.linalg.solve(W, b)  # the impulse that stops the contact from b = (-1, 0, 0)
        direction = rng.normal(size=2)
        direction /= np.linalg.norm(direction)
        # tangential data from a hair past the cone to a million times past it
        b[1:] = direction * 10.0 ** rng.uniform(-6, 6) * mu * max(stick[0], 1e-3)
        r = np.zeros(3)
        nsgs._local_3d(W, b, mu, r)
        size = np.abs(b).max() + np.abs(W).max() * np.abs(r).max()
        assert natural_map_norm(W, r, b, mu) <= 1e-12 * size
        slides += r[0] > 0.0 and np.linalg.norm(r[1:]) >= mu * r[0] * (1.0 - 1e-9)
        # the sweeps start a slide's root from the contact's last kappa: any start finds the same root
        kappa = nsgs._local_3d_reduced(nsgs._reduce_3d(W), b, mu, r, 0.0)
        for start in (1e-9 * kappa, 0.5 * kappa, 2.0 * kappa, 1e9 * kappa + 1.0):
            other = np.zeros(3)
            nsgs._local_3d_reduced(nsgs._reduce_3d(W), b, mu, other, start)
            assert np.abs(other - r).max() <= 1e-12 * np.abs(r).max()
    assert slides >= 300  # most of these slide


@pytest.mark.parametrize("b_t, expected", [((0.0, 0.0), (1.0, 0.0, 0.0)), ((0.3, 0.0), (1.0, -0.7, 0.0))])
def test_local_3d_with_a_singular_tangential_block(b_t, expected):
    """A contact whose tangential rows no impulse moves (``W = diag(1, 0, 0)``: a singular Schur
    complement, which the stick test cannot invert) pressed by ``b_N = -1``: without tangential data it
    sticks with ``r = (1, 0, 0)``, with ``b_T = (0.3, 0)`` it slides with ``r_T = -mu r_N`` along ``b_T``
    (``u_T = b_T`` whatever ``r``): exact answers by hand (friction 0.7), to round-off, and no
    division by zero in the compiled root search."""
    r = np.zeros(3)
    W, b = np.diag([1.0, 0.0, 0.0]), np.array([-1.0, *b_t])
    nsgs._local_3d(W, b, 0.7, r)
    assert np.abs(r - np.array(expected)).max() <= 1e-12
    assert natural_map_norm(W, r, b, 0.7) <= 1e-12


@pytest.mark.parametrize("dim", [2, 3])
def test_focused_passes_change_only_their_contacts_and_keep_the_body_velocities(dim):
    """The focused passes of the plain sweeps (``nsgs._sweep_contacts`` over a subset) leave every
    other contact's impulse as it was, keep ``y = M^-1 H^T r`` (to rounding), and a contact
    swept alone ends on the exact solution of its local problem (its Coulomb cone, and a
    velocity in the dual cone of De Saxce's law): the passes are Gauss-Seidel steps, nothing else."""
    M, v_free, H, offset, mu = random_velocity_problem(dim, 40, 30, seed=7)
    MinvHT = _inverse_mass_times(M, sp.csr_matrix(H).T.tocsr())
    W = nsgs.Delassus(sp.csr_matrix(H), sp.csr_matrix(MinvHT), dim)
    q = (H @ v_free + offset).reshape(-1, dim)
    data = nsgs.sweep_arrays(W)
    r = np.random.default_rng(3).uniform(0.0, 0.1, q.shape)
    r[:, 1:] *= 0.1  # inside the cones (mu >= 0.1)
    before = r.copy()
    y = W.MinvHT @ r.ravel()
    subset = np.array([3, 11, 17, 4])
    nsgs._sweep_contacts(*data, q, mu, r, y, subset, 5)
    others = np.setdiff1d(np.arange(mu.size), subset)
    assert np.array_equal(r[others], before[others])
    # y is updated by the same products as formed afresh: equal to rounding (1e-12 of its size)
    assert np.allclose(y, W.MinvHT @ r.ravel(), rtol=0.0, atol=1e-12 * (1.0 + np.abs(y).max()))
    # one contact alone: a single local solve, exact (the merit of its own 1-contact problem
    # is rounding, 1e-12 of its impulse and velocity scale)
    c = np.array([5])
    nsgs._sweep_contacts(*data, q, mu, r, y, c, 1)
    u = (H @ (v_free + W.MinvHT @ r.ravel()) + offset).reshape(-1, dim)
    merit = cone.merit(r[c], u[c], mu[c], 0.0)
    assert merit <= 1e-12 * (1.0 + np.abs(r[c]).max() + np.abs(u[c]).max())


def test_joints_group_the_contacts_between_the_same_bodies():
    """The 3D focused passes' neighbours are the contacts of the same joint: a label shared by the
    contacts between the same two bodies (in either order of their columns), by the contacts of one
    body with a fixed one, and by no other contact."""
    # 3 bodies of 6 velocities; contacts 0 and 1 between bodies 0 and 2 (columns in both orders),
    # 2 and 5 between body 1 and a fixed body, 3 between two fixed bodies (no column), 4 between 1 and 2
    touched = {0: [*range(0, 6), *range(12, 18)], 1: [*range(12, 18), *range(0, 6)], 2: [*range(6, 12)],
               3: [], 4: [*range(6, 18)], 5: [*range(6, 12)]}
    dim = 3
    h_ptr, h_ind = [0], []
    for c, cols in touched.items():
        for row in range(dim):  # each of the contact's rows touches its bodies' velocities
            h_ind.extend(cols)
            h_ptr.append(len(h_ind))
    H = sp.csr_matrix((np.ones(len(h_ind)), h_ind, h_ptr), shape=(dim * len(touched), 18))
    bodies = nsgs.Delassus(H, H.T.tocsr(), dim).contact_rows()[0]
    label = nsgs._joint_labels(bodies)
    same = {(0, 1), (2, 5)}
    for a in range(6):
        for b in range(a + 1, 6):
            assert (label[a] == label[b]) == ((a, b) in same), (a, b, label)


@pytest.mark.skipif(not FCLIB, reason=f"FCLIB problems not found in {DATA}")
@pytest.mark.parametrize("path", [pytest.param(f, id=f.stem) for f in FCLIB])
def test_fclib_with_nsgs(path):
    """Every FCLIB problem is solved with NSGS first; what NSGS leaves is handed over, and says so."""
    p = fclib.load(path)
    target = 1e-6 if p.name == "fc2d_granularflowonwall_00667_00000" else 1e-8  # as test_solver_fclib
    sol = solve_local(p.W, p.q, p.mu, dim=p.dim, tol=target, settings=NSGS)
    assert sol.converged, f"{p.name}: {sol.status} {sol.message} {sol.notes}"
    assert reference_merit(p.W, p.q, p.mu, sol.r, p.dim) <= target
    if sol.path == "nsgs":
        assert sol.sweeps >= 1
    elif p.q.size > NSGS.fast_path_unknowns or not sol.path.startswith(("newton (fast path)", "proximal point")):
        # a small problem is the compiled fast path's (the Newton, then the proximal point)
        # and never reaches NSGS; anything else went through NSGS first
        assert any(note.startswith("NSGS left merit") for note in sol.notes)


def test_unconverged_nsgs_is_handed_over_and_reported():
    """With one sweep allowed NSGS cannot reach 1e-8: the interior point finishes, the notes say why
    (the proximal point, which would come first for these 200 unknowns, is off)."""
    M, v_free, H, offset, mu = random_velocity_problem(2, 120, 100, seed=7)
    settings = SolverSettings(large_problem_unknowns=0, max_sweeps=1, sweeps_per_check=1, max_proximal=0)
    sol = solve_velocity(M, v_free, H, offset, mu, 2, settings=settings)
    assert sol.sweeps == 1
    assert sol.path.startswith("interior point")
    assert any("NSGS left merit" in note and "handed to the interior point" in note for note in sol.notes)
    assert sol.converged and sol.merit <= 1e-8


@pytest.mark.parametrize("field, value", [("large_problem_unknowns", -1), ("max_sweeps", 0),
                                          ("sweeps_per_check", 0), ("max_sweeps", 2.5)])
def test_settings_reject_bad_values(field, value):
    with pytest.raises(ValueError, match=f"{field} == {value!r}, must be an int >= "):
        SolverSettings(**{field: value})


def wall_at_rest(courses: int, per_course: int):
    scene, rows = wall(courses, per_course, 0.4, 0.2)  # fixed base
    return scene, initial_state(scene), sum(map(len, rows))


def run_at_rest(scene, dt: float, n_steps: int):
    """Steps of the wall by the Simulator; yields (model, state, step output).

    Every step must reach merit 5e-8 and at least 95 % of them the default 1e-8: a
    hyperstatic wall has a few degenerate steps where the gap terms of redundant contacts
    disagree at the 1e-8 m/s level; on such a step (t = 0.58 s at dt = 10 ms, saved and
    re-solved) the interior-point path stalls too, at 1.6e-8, from a warm or a cold start.
    The step reports it (status "stalled"), never silently.
    """
    sim = Simulator(scene, dt, Settings())
    converged = 0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # counted below
        for _ in range(n_steps):
            report = sim.step()
            assert report.merit <= 5e-8
            assert report.converged == (report.merit <= 1e-8)
            converged += report.converged
            yield sim.model, sim.state, sim.output
    assert converged >= 0.95 * n_steps


def base_impulse(model, out) -> np.ndarray:
    """World impulse (N s) of the base on the blocks over one step (normal from base to block)."""
    contacts = out.contacts.subset(out.active)
    on_base = ~model.dynamic[contacts.body_a]
    world = np.einsum("ck,ckj->cj", out.impulses[on_base], contacts.frame[on_base])
    return world.sum(axis=0)


def test_wall_at_rest_base_carries_the_weight_and_does_not_drift(monkeypatch):
    """A 97-block running-bond wall on a fixed base, 1 s at dt = 2 ms (500 steps, all by NSGS).

    Exact statics: the blocks stay at rest, so over each step the base gives the impulse
    ``sum(m) g dt`` upward and none sideways; no block moves by more than 1e-6 m in 1 s.
    """
    calls = {"nsgs": 0}
    solve = nsgs.solve

    def counting(*args, **kwargs):
        calls["nsgs"] += 1
        return solve(*args, **kwargs)

    monkeypatch.setattr(nsgs, "solve", counting)
    scene, start, n_blocks = wall_at_rest(13, 7)
    assert n_blocks == 97
    dt, n_steps = 0.002, 500
    state = start
    for k, (model, state, out) in enumerate(run_at_rest(scene, dt, n_steps)):
        weight = model.mass[model.dynamic].sum() * G
        assert out.report.n_active * 2 > SolverSettings().large_problem_unknowns
        if k % 50 == 0:
            impulse = base_impulse(model, out)
            # v stays ~0 to the solver's merit (u ~ 1e-8 m/s per contact), so the balance
            # sum(m) g dt holds to ~sum(m) * 1e-8 m/s: relative 1e-6 is a wide margin.
            assert impulse[1] == pytest.approx(weight * dt, rel=1e-6)
            assert abs(impulse[0]) <= 1e-6 * weight * dt
    assert calls["nsgs"] == n_steps
    dyn = model.dynamic_index
    drift = np.abs(state.q[dyn, :2] - start.q[dyn, :2]).max()
    assert drift < 1e-6  # no creep over 1 s
    # rotations: 1e-6 m over the 0.2 m half-diagonal of a block
    assert np.abs(state.q[dyn, 2] - start.q[dyn, 2]).max() < 1e-6 / 0.2


@pytest.mark.slow
def test_wall_at_rest_fine_step():
    """Same wall, 1 s at dt = 1 ms (1000 steps): no block moves by more than 1e-6 m."""
    scene, start, _ = wall_at_rest(13, 7)
    state = start
    for model, state, _ in run_at_rest(scene, 1e-3, 1000):
        pass
    dyn = model.dynamic_index
    assert np.abs(state.q[dyn, :2] - start.q[dyn, :2]).max() < 1e-6


@pytest.mark.parametrize("block", [1, 3, 6])
def test_inverse_mass_times_block_diagonal(block):
    """Per-block inverse of a block-diagonal M equals a dense solve (sparse and dense B)."""
    rng = np.random.default_rng(block)
    blocks = []
    for _ in range(40):
        A = rng.normal(size=(block, block))
        blocks.append(A @ A.T + block * np.eye(block))
    M = sp.block_diag(blocks, format="csc")
    B = sp.random(M.shape[0], 25, density=0.2, random_state=1, format="csr")
    expected = np.linalg.solve(M.toarray(), B.toarray())
    # dense LU against per-block inverses: round-off of well-conditioned 6 x 6 blocks
    assert np.allclose(_inverse_mass_times(M, B).toarray(), expected, rtol=1e-12, atol=1e-12)
    assert np.allclose(_inverse_mass_times(M.toarray(), B.toarray()), expected, rtol=1e-12, atol=1e-12)


def test_inverse_mass_times_rejects_indefinite_block():
    indefinite = np.eye(6)
    indefinite[4:, 4:] = [[1.0, 2.0], [2.0, 1.0]]  # eigenvalues 3 and -1
    M = sp.block_diag([np.eye(6), indefinite], format="csc")
    with pytest.raises(ValueError, match="not positive definite"):
        _inverse_mass_times(M, sp.identity(12, format="csr"))


def test_warm_start_lookup_matches_dict_semantics():
    """Vectorised lookup = a dict built in order (a repeated id keeps its last impulse; unknown: 0)."""
    rng = np.random.default_rng(3)
    ids = rng.integers(0, 30, size=(400, 3))
    impulses = rng.normal(size=(400, 2))
    as_dict = {}
    for key, value in zip(map(tuple, ids.tolist()), impulses):
        as_dict[key] = value
    wanted = rng.integers(0, 30, size=(500, 3))
    wanted[:250] = ids[rng.integers(0, 400, 250)]
    expected = np.array([as_dict.get(key, np.zeros(2)) for key in map(tuple, wanted.tolist())])
    assert np.array_equal(WarmStart(ids, impulses).lookup(wanted), expected)
    assert np.array_equal(WarmStart.of(as_dict, 2).lookup(wanted), expected)


@pytest.mark.parametrize("n", [1, 2, 3, 100, 1025, 6000])
def test_warm_start_lookup_matches_dict_semantics_at_any_size(n):
    """The same at the sizes of a lone block to a 990-block wall (the ids sorted by hash in
    buckets of the hash's top bits, about one per id): repeats keep their last impulse, unknown
    ids get 0, ids of realistic shape (body pairs of a large scene, features -1..7)."""
    rng = np.random.default_rng(n)
    ids = np.stack([rng.integers(0, 1000, n), rng.integers(0, 1000, n), rng.integers(-1, 8, n)], axis=1)
    ids[rng.integers(0, n, n // 10)] = ids[rng.integers(0, n, n // 10)]  # repeated ids
    impulses = rng.normal(size=(n, 2))
    as_dict = {}
    for key, value in zip(map(tuple, ids.tolist()), impulses):
        as_dict[key] = value
    wanted = np.concatenate([ids[rng.permutation(n)], rng.integers(0, 1000, size=(n, 3))])
    expected = np.array([as_dict.get(key, np.zeros(2)) for key in map(tuple, wanted.tolist())])
    assert np.array_equal(WarmStart(ids, impulses).lookup(wanted), expected)


def test_contact_laws_vectorised_match_scene_rules():
    """Model.contact_laws gives, pair by pair, the law the scene's rules give."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(4.0, 0.2), position=(0.0, -0.1), material="steel")
    for k in range(6):
        scene.add_block(nscd.box(0.4, 0.2), position=(-1.5 + 0.5 * k, 0.1), material="stone" if k % 2 else "wood")
    scene.set_contact(friction=0.5, restitution=0.0)
    scene.set_contact(friction=0.3, restitution=0.1, between=("steel", "wood"))
    scene.set_contact(friction=0.9, restitution=0.2, between=(scene.bodies[2], scene.bodies[3]))
    model = Model.from_scene(scene)
    i, j = np.triu_indices(len(scene.bodies), k=1)
    for _ in range(2):  # first call fills the table, second reads it
        friction, restitution = model.contact_laws(i, j)
        expected = [scene.contact_law(scene.bodies[a], scene.bodies[b]) for a, b in zip(i, j)]
        assert friction.tolist() == [law.friction for law in expected]
        assert restitution.tolist() == [law.restitution for law in expected]


def test_warm_start_trend_extrapolates_linearly():
    """A step's warm start followed from the step before's stores the change since it; extrapolate adds it."""
    from nscd.contact.frames import Contacts
    from nscd.result import StepReport
    from nscd.stepper import StepOutput

    ids = np.array([[1, 2, 7], [1, 3, 8], [2, 3, 9]])
    contacts = Contacts(ids[:, 0], ids[:, 1], np.zeros((3, 2)), np.zeros((3, 2, 2)), np.zeros(3),
                        np.full(3, 0.5), np.zeros(3), ids)
    report = StepReport(t=0.0, n_contacts=3, n_active=3, status="converged", converged=True, iterations=1,
                        merit=0.0)
    impulses = np.array([[3.0, 0.5], [2.0, -0.1], [1.0, 0.0]])
    out = StepOutput(report, contacts, np.arange(3), impulses, np.zeros((3, 2)), np.zeros((3, 2)), np.zeros(3))
    previous = WarmStart(ids[:2], np.array([[2.5, 0.25], [2.0, 0.1]]))  # contact (2, 3, 9) is new
    warm = previous.followed_by(out.contacts.ids[out.active], out.impulses)
    expected_trend = np.array([[0.5, 0.25], [0.0, -0.2], [0.0, 0.0]])
    assert np.allclose(warm.trend, expected_trend, rtol=0, atol=1e-15)  # exact differences of binary fractions
    assert np.array_equal(warm.lookup(ids), impulses)
    assert np.allclose(warm.lookup(ids, extrapolate=True), impulses + expected_trend, rtol=0, atol=1e-15)
    assert warm_start_of(out).trend is None


def test_warm_start_keeps_the_linear_prediction_only_where_it_predicted_better():
    """A step's warm start is extrapolated (impulses + trend) only if the step before's linear
    prediction came clearly closer to this step's impulses than the plain impulses did (summed
    squared error at most LINEAR_PREDICTION_GAIN times): so it is while the impulses change
    smoothly (a wall riding a shaking base), not after a jump (an assembly breaking up: impacts,
    contacts opening) nor where it predicts no better, where the plain impulses are the better
    start. Binary fractions: exact."""
    ids = np.array([[1, 2, 7]])
    # the impulse grew by (0.5, 0.25) and grows by as much again: the prediction was exact
    smooth = WarmStart(ids, np.array([[2.0, 0.5]]), np.array([[0.5, 0.25]])).followed_by(ids, np.array([[2.5, 0.75]]))
    assert smooth.linear
    assert np.array_equal(smooth.lookup(ids, extrapolate=True), [[3.0, 1.0]])
    # it jumped up by 3 (a percussion) and falls back: the prediction (7.0, 0.75) misses by more
    # than the plain impulses (4.0, 0.5) do
    jump = WarmStart(ids, np.array([[4.0, 0.5]]), np.array([[3.0, 0.25]])).followed_by(ids, np.array([[1.0, 0.5]]))
    assert not jump.linear
    assert np.array_equal(jump.trend, [[-3.0, 0.0]])  # kept for the next step's comparison
    assert np.array_equal(jump.lookup(ids, extrapolate=True), [[1.0, 0.5]])
    # each step tells again: at rest after the jump, the plain impulses are exact...
    rest = jump.followed_by(ids, np.array([[1.0, 0.5]]))
    assert not rest.linear
    # ...as the prediction of zero trend is when they start to change: no better, not kept...
    start = rest.followed_by(ids, np.array([[1.25, 0.625]]))
    assert not start.linear
    # ...until they change as they did: exact again
    assert start.followed_by(ids, np.array([[1.5, 0.75]])).linear
    # the prediction a little better than the plain impulses (squared error 0.5625 of theirs): not kept
    near = WarmStart(ids, np.array([[2.0, 0.5]]), np.array([[0.25, 0.0]])).followed_by(ids, np.array([[3.0, 0.5]]))
    assert LINEAR_PREDICTION_GAIN < 0.5625
    assert not near.linear
    # no step before to tell: the linear prediction (of zero trend, the plain impulses)
    assert WarmStart(ids, np.array([[1.0, 0.5]])).followed_by(ids, np.array([[1.5, 0.5]])).linear


def test_warm_start_in_3d_is_not_extrapolated():
    """3D impulses (four points per face: not unique) warm-start the next step as they are."""
    ids = np.array([[1, 2, 7], [1, 3, 8]])
    impulses = np.array([[3.0, 0.5, -0.25], [2.0, -0.1, 0.0]])
    warm = WarmStart(ids, impulses, np.array([[0.5, 0.25, 0.125], [0.0, -0.2, 0.5]]))
    assert np.array_equal(warm.lookup(ids, extrapolate=True), impulses)


def test_inverse_mass_of_a_3d_scene_is_its_block_diagonal():
    """The stepper's ``M^-1`` of a 3D scene (built from its 6 x 6 blocks' entries) is the block-diagonal
    matrix of those blocks, entry for entry (a copy: exact)."""
    from nscd.stepper import _inverse_mass
    blocks = np.random.default_rng(4).normal(size=(7, 6, 6))
    blocks[2, 0, 1] = 0.0  # a zero entry stays a (stored) zero
    Minv = _inverse_mass(blocks)
    assert sp.issparse(Minv) and Minv.shape == (42, 42)
    assert np.array_equal(Minv.toarray(), sp.block_diag(list(blocks)).toarray())


def test_anderson_gram_kept_row_by_row_is_the_gram_of_the_history():
    """The Gram matrix ``dF dF^T`` that the sweeps keep as rows are pushed into their ring buffer
    (``nsgs._gram_row``: one row recomputed per push) equals the one formed afresh, and the mix
    ``g - (dX + dF)^T gamma`` is Anderson's type-II step: ``gamma`` the least-squares fit of ``f`` by the
    rows of ``dF`` (Walker & Ni 2011), here by numpy's ``lstsq``."""
    rng = np.random.default_rng(8)
    depth, n = nsgs._DEPTH, 200
    dX, dF = np.zeros((depth, n)), np.zeros((depth, n))
    gram = np.zeros((depth, depth))
    for push in range(2 * depth + 2):  # wraps around the ring buffer twice
        row = push % depth
        dX[row], dF[row] = rng.normal(size=n), rng.normal(size=n)
        used = min(push + 1, depth)
        nsgs._gram_row(dF, row, used, gram)
        # sums of n products in another order: rounding, 1e-12 of their size
        assert np.abs(gram[:used, :used] - dF[:used] @ dF[:used].T).max() <= 1e-12 * n
    g, f, out = rng.normal(size=n), rng.normal(size=n), np.empty(n)
    nsgs._anderson_mix(dX, dF, depth, gram, g, f, out)
    gamma = np.linalg.lstsq(dF.T, f, rcond=None)[0]
    # random rows are well conditioned (cond ~ 1): the ridge 1e-12 trace moves gamma by ~1e-12 relative
    assert np.abs(out - (g - (dX + dF).T @ gamma)).max() <= 1e-9 * (1.0 + np.abs(g).max())
