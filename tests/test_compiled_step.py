"""The compiled steps of a small scene (nscd.compiled_step) equal the general step, bit for bit.

A single run of a scene of a few bodies takes its plain steps in one compiled call
(several steps per call in ``simulate``); every other step (an impact located inside the step,
a problem the compiled Newton leaves, a body turning fast) goes through the general step,
``nscd.stepper.step``. Both compose the same compiled stages in the same order, so a run
must not depend on which path took its steps: the reference here is the same run with the
compiled path switched off, and the comparisons are exact (tolerance 0: a difference of one
unit in the last place grows along a rocking run and would hide a stage composed
differently). The engine's physics is validated against theory elsewhere
(tests/test_engine2d.py, tests/test_engine3d.py) on runs that now take this path.
"""
from __future__ import annotations

import numpy as np
import pytest

import nscd
from nscd import compiled_step
from nscd.motion import OneSine
from nscd.result import driven_work
from nscd.stepper import Settings, Simulator


def rocking_block() -> nscd.Scene:
    """The 0.5 x 1.5 m block released at half its slenderness angle (Housner's free rocking)."""
    scene, _ = nscd.tilted_block(0.5, 1.5, 0.5 * np.arctan(0.5 / 1.5))
    return scene


def blocks_3d() -> nscd.Scene:
    """3D: a 0.2 x 0.3 x 0.8 m block standing on a base and a 0.3 m cube dropped from 2 mm
    beside it (it lands inside a step), turning slowly."""
    scene = nscd.Scene(dim=3)
    scene.add_base(nscd.box(2.0, 2.0, 0.1), position=(0.0, 0.0, -0.05))
    scene.add_block(nscd.box(0.2, 0.3, 0.8), position=(-0.4, 0.0, 0.4), orientation=(1.0, 0.0, 0.0, 0.0))
    scene.add_block(nscd.box(0.3, 0.3, 0.3), position=(0.4, 0.0, 0.152), orientation=(1.0, 0.0, 0.0, 0.0),
                    omega=(0.0, 0.3, 0.0))
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def shaken_block() -> nscd.Scene:
    """A 0.2 x 0.6 m block on a base shaken by one sine pulse strong enough to rock it (a driven
    body: its motion evaluated in Python before the compiled steps)."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(2.0, 0.1), position=(0.0, -0.05), motion=OneSine(6.0, omega=2 * np.pi * 2.0))
    scene.add_block(nscd.box(0.2, 0.6), position=(0.0, 0.3), name="block")
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def general_only(monkeypatch) -> None:
    """Every step by the general step (the compiled path off)."""
    monkeypatch.setattr(compiled_step.CompiledSteps, "of", classmethod(lambda cls, k, builder: None))


def assert_same_result(compiled: nscd.Result, general: nscd.Result) -> None:
    """Exact equality: histories, energies, impacts and solver reports."""
    for name in ("time", "q", "v", "kinetic", "potential", "dissipated", "work_input"):
        np.testing.assert_array_equal(getattr(compiled, name), getattr(general, name), err_msg=name)
    assert compiled.impacts.keys() == general.impacts.keys()
    for key in general.impacts:
        np.testing.assert_array_equal(compiled.impacts[key], general.impacts[key], err_msg=f"impacts[{key!r}]")
    for name in ("iterations", "merit", "n_contacts", "n_active", "penetration", "unconverged_times"):
        np.testing.assert_array_equal(getattr(compiled.report, name), getattr(general.report, name), err_msg=name)
    assert compiled.report.statuses == general.report.statuses


def count_paths(monkeypatch) -> dict:
    """Count the steps each path takes (the compiled steps by the calls' returns)."""
    counts = {"compiled": 0, "general": 0}
    run_compiled, run_general = nscd.stepper.Run._compiled_steps, nscd.stepper.Run._general_step

    def compiled_steps(self, n_steps, stacklevel):
        done, code = run_compiled(self, n_steps, stacklevel + 1)
        counts["compiled"] += done
        return done, code

    def general_step(self, stacklevel):
        counts["general"] += 1
        return run_general(self, stacklevel + 1)

    monkeypatch.setattr(nscd.stepper.Run, "_compiled_steps", compiled_steps)
    monkeypatch.setattr(nscd.stepper.Run, "_general_step", general_step)
    return counts


CASES = {
    # name: (scene, t_end s, dt s); the rocking block's impacts (the first at 0.43 s) are
    # located by the general step, the swings between them compiled
    "2D rocking block": (rocking_block, 1.0, 1e-3),
    "2D rocking block, coarse step": (rocking_block, 1.2, 1e-2),
    "2D three-block stack": (lambda: nscd.stack(3, width=0.4, height=1.0)[0], 0.1, 1e-3),
    "2D block on a shaken base": (shaken_block, 0.4, 1e-3),
    "3D blocks, one landing": (blocks_3d, 0.04, 1e-3),
    "3D LNEC trilith": (nscd.lnec.trilith, 0.02, 1e-3),
}


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
@pytest.mark.parametrize("case", list(CASES))
def test_compiled_steps_equal_the_general_step(case, scheme, monkeypatch):
    make, t_end, dt = CASES[case]
    settings = Settings(scheme=scheme)
    counts = count_paths(monkeypatch)
    compiled = nscd.simulate(make(), t_end, dt, settings=settings)
    # the comparison is not vacuous: most steps were compiled
    assert counts["compiled"] > counts["general"], counts
    with monkeypatch.context() as m:
        general_only(m)
        general = nscd.simulate(make(), t_end, dt, settings=settings)
    assert_same_result(compiled, general)
    if case.startswith("2D rocking"):
        assert len(compiled.impacts["time"]) >= 1


def test_step_by_step_equals_simulate_and_outputs_equal(monkeypatch):
    """``Simulator.step`` (one compiled step per call) gives what ``simulate`` (many per call)
    does, and the last step's report and output (contacts, active set, impulses, relative
    velocities) equal the general step's."""
    settings = Settings()
    compiled = Simulator(rocking_block(), 1e-3, settings)
    reports = [compiled.step() for _ in range(300)]
    assert_same_result(compiled.result(), nscd.simulate(rocking_block(), 0.3, 1e-3, settings=settings))
    general_only(monkeypatch)
    general = Simulator(rocking_block(), 1e-3, settings)
    assert [general.step() for _ in range(300)] == reports
    out, reference = compiled.output, general.output
    assert out.report == reference.report
    for name in ("active", "impulses", "u_before", "u_after", "solved_at", "driven"):
        np.testing.assert_array_equal(getattr(out, name), getattr(reference, name), err_msg=name)
    for name in reference.contacts.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(out.contacts, name), getattr(reference.contacts, name), err_msg=name)


def test_buffers_grow_with_the_contacts(monkeypatch):
    """A column of 12 blocks (26 contacts, more than the warm start's first buffer holds) and
    a run longer than the first history buffers: grown, and the run unchanged."""
    scene = nscd.stack(12, width=0.4, height=0.3)[0]
    counts = count_paths(monkeypatch)
    compiled = nscd.simulate(scene, 0.05, 1e-3)
    assert counts["compiled"] > counts["general"] and compiled.report.n_active[-1] > 16
    general_only(monkeypatch)
    assert_same_result(compiled, nscd.simulate(scene, 0.05, 1e-3))


def test_events_stop_a_compiled_run_as_a_general_one(monkeypatch):
    """A terminal event evaluated after each compiled step stops the run at the same step."""
    def tilt(state) -> float:
        return abs(state.q[1, 2]) - 0.05  # the block's rotation passes 0.05 rad
    tilt.terminal = True
    compiled = nscd.simulate(rocking_block(), 1.0, 1e-3, events=[tilt])
    general_only(monkeypatch)
    general = nscd.simulate(rocking_block(), 1.0, 1e-3, events=[tilt])
    assert compiled.status == general.status == "event"
    assert_same_result(compiled, general)
    np.testing.assert_array_equal(compiled.t_events[0], general.t_events[0])


def test_driven_work_sums_as_numpy_does():
    """The driven bodies' work of a step, ``sum P . w``, has the bits of ``np.sum(P * w)`` (numpy's
    pairwise summation), which the recording of a step by Python used: sizes across the
    pairwise blocks (8 and 128 terms) and halvings, magnitudes over 16 decades."""
    rng = np.random.default_rng(7)
    for k in list(range(0, 70)) + [150, 300, 1000, 3001]:
        for dim in (2, 3):
            impulses = rng.standard_normal((k, dim)) * 10.0 ** rng.uniform(-8.0, 8.0, (k, dim))
            driven = rng.standard_normal((k, dim))
            assert driven_work(impulses, driven) == np.sum(impulses * driven), (k, dim)
