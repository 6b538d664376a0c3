"""Property-based tests (Hypothesis) over random small 2D scenes.

A scene is a fixed base and one to three blocks (boxes or regular polygons) stacked above it
with random gaps, densities, friction and restitution coefficients, start velocities up to
50 m/s and spins, run for a few dozen steps of dt up to 1e-2 s. What must hold whatever the
scene:

* the run finishes, every step is reported (solver statuses add up to the steps) and every
  unconverged step is also warned about;
* no NaN or infinity in positions, velocities or energies;
* no step raises the mechanical energy K + P (computed from the positions and velocities
  alone, not from the impulses) beyond round-off: the base is fixed and the contacts are
  dissipative (restitution < 1). With the theta = 0.5 position update a free flight
  conserves K + P exactly (Delta K = -m g h (v_k + v_k+1)/2 = -Delta P), so any rise is
  work done by the contact impulses. This one fails today, under both schemes: a scene
  Hypothesis found (two triangles standing on a corner, the upper one thrown down,
  frictionless, e = 0, dt = 1/128 s) is kept as a strict xfail, which fails once the step
  cannot create energy; the property over random scenes (``check_no_step_creates_energy``)
  is then to run again. The time step, not the data, has to change for it to pass.

* no step ends in an overlap deeper than ``PENETRATION_TOLERANCE`` without a warning
  saying so (speculative contacts find every contact that can close in a step);
* the energy balance computed independently (dissipation and driven work from the impulses,
  K and P from the states) holds: ``result.report.energy_residual`` is round-off.

Few examples by default (the suite stays fast); ``-m slow`` runs many more.
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import nscd
from nscd.stepper import PENETRATION_TOLERANCE


@st.composite
def scenes(draw):
    """A scene, its time step (s) and number of steps."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(40.0, 0.2), position=(0.0, -0.1))  # top face at y = 0
    height = 0.0
    for _ in range(draw(st.integers(1, 3))):
        if draw(st.booleans()):
            shape = nscd.box(draw(st.floats(0.05, 1.0)), draw(st.floats(0.05, 1.5)))
        else:
            shape = nscd.regular_polygon(draw(st.integers(3, 8)), draw(st.floats(0.05, 0.6)))
        below, above = -float(shape.vertices[:, 1].min()), float(shape.vertices[:, 1].max())
        gap = draw(st.floats(0.0, 0.1))
        scene.add_block(
            shape, position=(draw(st.floats(-0.2, 0.2)), height + gap + below),
            density=draw(st.floats(100.0, 1e4)),
            velocity=(draw(st.floats(-50.0, 50.0)), draw(st.floats(-50.0, 50.0))),
            omega=draw(st.floats(-20.0, 20.0)),
        )
        height += gap + below + above
    scene.set_contact(friction=draw(st.floats(0.0, 1.0)), restitution=draw(st.floats(0.0, 0.9)))
    return scene, draw(st.floats(1e-4, 1e-2)), draw(st.integers(10, 40))


def run(case, kind: str = "did not converge", settings: nscd.Settings | None = None):
    """The result of a case (default settings unless given) and the warnings whose message contains ``kind``."""
    scene, dt, n_steps = case
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = nscd.simulate(scene, t_end=n_steps * dt, dt=dt, settings=settings)
    return result, [w for w in caught if kind in str(w.message)]


FEW = settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow])
MANY = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def check_reported_and_finite(case):
    result, unconverged_warnings = run(case)
    assert result.status == "finished"
    report = result.report
    assert report.n_steps == len(result.time) - 1 == sum(report.statuses.values())
    assert len(unconverged_warnings) == report.n_unconverged == len(report.unconverged_times)
    for name in ("q", "v", "kinetic", "potential", "dissipated"):
        assert np.all(np.isfinite(getattr(result, name))), name


def check_no_step_creates_energy(case, settings: nscd.Settings | None = None):
    result, _ = run(case, settings=settings)
    energy = result.kinetic + result.potential
    # Round-off of K + P: 1e-9 of the largest energy term of the run (a sum of a few products,
    # each exact to 1e-16 relative; 1e-9 leaves room for the solver's 1e-8 merit on impulses
    # that are small against the momentum).
    tolerance = 1e-9 * float(np.max(np.abs(result.kinetic) + np.abs(result.potential)))
    rise = np.diff(energy)
    worst = int(np.argmax(rise))
    assert rise[worst] <= tolerance, (
        f"K + P rose by {rise[worst]:.3g} J at t = {result.time[worst + 1]:.4g} s (tolerance {tolerance:.3g} J)")


def check_overlaps_said_and_energy_balanced(case):
    result, overlap_warnings = run(case, "overlap by")
    scene = case[0]
    smallest = min(b.shape.radius for b in scene.bodies if b.kind.value == "dynamic")
    deep = result.report.penetration > PENETRATION_TOLERANCE * smallest
    assert len(overlap_warnings) == int(np.sum(deep))  # every deep overlap warned, no other
    # The step's kinetic-energy identity is exact for theta = 1/2 in 2D: what is left is
    # round-off, 1e-9 of the largest energy term (as above) or of the energy dissipated.
    scale = float(np.max(np.abs(result.kinetic) + np.abs(result.potential) + np.abs(result.dissipated)))
    assert result.report.energy_residual <= 1e-9 * scale


@FEW
@given(scenes())
def test_overlaps_are_said_and_the_energy_balance_holds(case):
    check_overlaps_said_and_energy_balanced(case)


@pytest.mark.slow
@MANY
@given(scenes())
def test_overlaps_are_said_and_the_energy_balance_holds_many(case):
    check_overlaps_said_and_energy_balanced(case)


@FEW
@given(scenes())
def test_every_step_is_reported_and_finite(case):
    check_reported_and_finite(case)


@pytest.mark.slow
@MANY
@given(scenes())
def test_every_step_is_reported_and_finite_many(case):
    check_reported_and_finite(case)


def triangles_on_corners():
    """A counter-example Hypothesis found (shrunk): on the fixed base, a triangle of circumradius
    0.5 m standing on a corner under one of 0.25 m thrown down at 2 m/s, 100 kg/m^3, frictionless,
    e = 0, 10 steps of 1/128 s."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(40.0, 0.2), position=(0.0, -0.1))
    height = 0.0
    for radius, velocity in ((0.5, 0.0), (0.25, -2.0)):
        shape = nscd.regular_polygon(3, radius)
        below = -float(shape.vertices[:, 1].min())
        scene.add_block(shape, position=(0.0, height + below), density=100.0, velocity=(0.0, velocity))
        height += below + float(shape.vertices[:, 1].max())
    scene.set_contact(friction=0.0, restitution=0.0)
    return scene, 1.0 / 128.0, 10


# Strict: the day no step of this scene creates energy, the mark fails and is to be removed,
# with check_no_step_creates_energy run over random scenes (scenes()) again.
@pytest.mark.xfail(reason="contact impulses can do positive work in a step today (frictionless, e = 0); "
                          "an energy-consistent step belongs to the time step's redesign", strict=True)
@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
def test_no_step_creates_energy_on_triangles_standing_on_corners(scheme):
    check_no_step_creates_energy(triangles_on_corners(), nscd.Settings(scheme=scheme))
