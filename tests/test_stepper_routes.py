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
