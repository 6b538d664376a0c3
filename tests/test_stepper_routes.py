"""The stepper sends each contact problem down the route ``SolverSettings`` documents.

``fast_path_unknowns`` bounds the problems the compiled semismooth Newton takes; above it
(up to ``large_problem_unknowns``) the dense problem goes to the conic fixed point by
:func:`nscd.solver.core.solve` (``nscd/solver/settings.py``, ``docs/guide/solver.md``).
"""
from __future__ import annotations

import numpy as np
import pytest

import nscd
from nscd.solver import core


def resting_block():
    scene = nscd.Scene()
    scene.add_base(nscd.box(4.0, 0.2), position=(0.0, -0.1))
    block = scene.add_block(nscd.box(0.4, 0.2), position=(0.0, 0.1), density=2000.0)
    scene.set_contact(friction=0.5, restitution=0.0)
    return scene, block


@pytest.mark.parametrize("fast_path_unknowns, conic", [(120, False), (0, True)])
def test_fast_path_unknowns_chooses_the_route(monkeypatch, fast_path_unknowns, conic):
    calls = []
    solve = core.solve

    def counting_solve(*args, **kwargs):
        calls.append(args[1].size)
        return solve(*args, **kwargs)

    monkeypatch.setattr(core, "solve", counting_solve)
    scene, block = resting_block()
    settings = nscd.Settings(solver=nscd.SolverSettings(fast_path_unknowns=fast_path_unknowns))
    sim = nscd.Simulator(scene, dt=1e-3, settings=settings)
    for _ in range(50):
        report = sim.step()
        assert report.converged, report
    # a block resting on two corners: 4 unknowns every step. The compiled Newton accepts
    # them all (never core.solve); with the fast path off every step's problem is the conic one's
    assert calls == ([4] * 50 if conic else [])
    # either route solves the same problem to tol: the block stays at rest (to the
    # gap tolerance's scale, 1 um, over 50 steps)
    assert np.max(np.abs(sim.state.q[sim.model.dynamic_index] - [0.0, 0.1, 0.0])) < 1e-6


def test_falling_block_without_spin_predicts_its_end_overlap():
    # The end-of-step overlap is predicted from the contacts' relative velocities, exact for
    # translation; only a turn (|omega| > 0) bounds the error and may ask for a fresh
    # detection in the end configuration. A block falling fast without turning needs none,
    # whatever its vertical speed (the y velocity is not an angular component).
    from nscd.stepper import _predicted_overlaps
    first = np.array([0, 1])
    v = np.zeros((1, 2, 3))
    v[0, 1, 1] = -20.0  # m/s, falling
    v_end = v.copy()
    gap = np.array([1e-3])  # m, still open at the end of the step
    def check(v_end):
        return _predicted_overlaps(gap, np.array([0]), np.array([1]), first, v, v_end, np.ones(1),
                                   np.array([0.25, 0.25]), np.array([False]), 1e-5)

    overlap, checked = check(v_end)
    assert not checked[0] and overlap[0] == 0.0
    v_end[0, 1, 2] = 1.0  # rad/s: the same block turning, span 1 s, R = 0.25 m: bound 0.125 m >= 1e-5 m
    assert check(v_end)[1][0]
