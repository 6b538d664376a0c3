"""A bounded cost per large contact problem: ``SolverSettings.max_conic_unknowns``.

A large problem that the Gauss–Seidel sweeps (and the polish) leave above the tolerance
is not handed to the interior point when it has more unknowns than
``max_conic_unknowns``: its best iterate comes back ``STALLED``, and a time step that
meets such a problem is reported unconverged and warned, never silent. Oracles: the
FCLIB merit written out in ``tests/test_solver_fclib.py`` (no solver code), the weight
a resting column carries, and the stepper's own report and warning.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import nscd
from nscd.motion import Harmonic
from nscd.solver import SolverSettings, Status, solve_local
from test_solver_fclib import reference_merit
from test_solver_relative import _chain_problem

# Two sweeps cannot carry 200 stacked bodies' weight down a column (Gauss–Seidel moves
# the load one contact per half sweep): the sweeps certainly end above 1e-8.
STARVED = dict(max_sweeps=2, sweeps_per_check=1, polish=False)


def test_bounded_large_problem_returns_its_best_sweep_as_stalled():
    H, q, mu = _chain_problem(200)   # 400 unknowns, above large_problem_unknowns
    W = (H @ H.T).toarray()
    sol = solve_local(W, q, mu, dim=2, settings=SolverSettings(max_conic_unknowns=399, **STARVED))
    assert sol.status == Status.STALLED and not sol.converged
    assert sol.path == "nsgs" and sol.sweeps == 2
    assert sol.interior_point_iterations == 0 and sol.fixed_point_iterations == 0
    assert "max_conic_unknowns" in sol.message and any("no interior point" in note for note in sol.notes)
    # the reported merit is the FCLIB merit of the returned impulses (independent formula;
    # the two differ only by the order of the floating-point sums)
    assert sol.merit == pytest.approx(reference_merit(W, q, mu, sol.r.ravel(), 2), rel=1e-9)
    assert sol.merit > 1e-8


def test_problem_at_or_below_the_bound_still_goes_to_the_interior_point():
    """The same problem with the bound at its size (or no bound): the interior point solves it."""
    H, q, mu = _chain_problem(200)
    W = (H @ H.T).toarray()
    for bound in (400, None):
        sol = solve_local(W, q, mu, dim=2, settings=SolverSettings(max_conic_unknowns=bound, **STARVED))
        assert sol.converged and sol.fixed_point_iterations >= 1
        assert reference_merit(W, q, mu, sol.r.ravel(), 2) <= 1e-8
        # the ground contact carries the 200 bodies' weight over the step (g dt each)
        assert sol.r.ravel()[0] == pytest.approx(200 * 9.81e-3, rel=1e-6)


@pytest.mark.parametrize("value", [-1, 2.5, "100"])
def test_max_conic_unknowns_out_of_range(value):
    with pytest.raises(ValueError, match="max_conic_unknowns"):
        SolverSettings(max_conic_unknowns=value)


def test_bounded_step_is_reported_and_warned():
    """A wall whose contact problems get two sweeps and no interior point: every such step
    is counted unconverged in its report, with the merit it reached, and warned."""
    scene, _ = nscd.wall(6, 4, 0.4, 0.2, motion=Harmonic(0.5, frequency=2.0, ramp_cycles=1.0))
    solver = SolverSettings(max_conic_unknowns=0, max_sweeps=2, large_problem_unknowns=0, fast_path_unknowns=0)
    sim = nscd.Simulator(scene, dt=1e-3, settings=nscd.Settings(solver=solver))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        reports = [sim.step() for _ in range(3)]
    unconverged = [r for r in reports if not r.converged]
    assert unconverged and all(r.merit > solver.tol for r in unconverged)
    assert sum(issubclass(w.category, RuntimeWarning) for w in caught) >= len(unconverged)
    assert np.all(np.isfinite(sim.state.q))


@pytest.mark.parametrize("tol_relative", [None, 1e-4])
def test_a_run_whose_large_problems_miss_the_absolute_merit_names_the_collapse_setting(tol_relative):
    """The same starved wall run to its end: its result says how many steps did not converge
    and, only when no relative tolerance was set, the collapse setting (the relative merit,
    the bounded interior point) and where it is documented."""
    scene, _ = nscd.wall(6, 4, 0.4, 0.2, motion=Harmonic(0.5, frequency=2.0, ramp_cycles=1.0))
    solver = SolverSettings(max_conic_unknowns=0, max_sweeps=2, large_problem_unknowns=0, fast_path_unknowns=0,
                            tol_relative=tol_relative)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        result = nscd.simulate(scene, t_end=0.003, dt=1e-3, settings=nscd.Settings(solver=solver))
    assert result.report.n_unconverged > 0
    assert "did not converge" in result.message
    hinted = "tol_relative=1e-4, max_conic_unknowns=0" in result.message and "docs/guide/solver.md" in result.message
    assert hinted == (tol_relative is None)
