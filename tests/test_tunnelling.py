"""Fast bodies do not pass through each other: speculative contacts find every contact that
can close within a step (the midpoint rule sees a fast scene at the start of the step, not
half a step ahead), and the deepest end-of-step overlap is reported (and warns).

A 20 m/s block meets a resting one of equal mass, frictionless, restitution 0: a plastic
impact, after which both move at 10 m/s (momentum conservation, m v = 2 m v'); or a row of
two (every impact of the step localised). A plank spinning fast lands on the base (a step in
which a body turns fast is taken in pieces); a step that ends overlapping reports the overlap
of its end configuration.
"""
import warnings

import numpy as np
import pytest

import nscd
from nscd.stepper import PENETRATION_TOLERANCE


def _two_blocks(dim: int, width: float) -> nscd.Scene:
    s = nscd.Scene(dim=dim)
    if dim == 2:
        s.add_base(nscd.box(60, .2), position=(0, -.1))
        s.add_block(nscd.box(width, .2), position=(-.5211, .1), velocity=(20, 0), name="A")
        s.add_block(nscd.box(width, .2), position=(width / 2, .1), name="B")
    else:
        s.add_base(nscd.box(60, 2, .2), position=(0, 0, -.1))
        s.add_block(nscd.box(width, .2, .2), position=(-.5211, 0, .1), velocity=(20, 0, 0), name="A")
        s.add_block(nscd.box(width, .2, .2), position=(width / 2, 0, .1), name="B")
    s.set_contact(0)
    return s


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("width", [.02, .2])
@pytest.mark.parametrize("dt", [1e-3, 5e-3, 1e-2])
@pytest.mark.parametrize("scheme", ["theta", "midpoint"])
def test_fast_block_hits_instead_of_tunnelling(scheme, dim, width, dt):
    scene = _two_blocks(dim, width)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overlap warning, no solver failure
        r = nscd.simulate(scene, t_end=.2, dt=dt, settings=nscd.Settings(scheme=scheme))
    # the impact is recorded, between A and B
    hits = (r.impacts["body_a"] + r.impacts["body_b"]) == 3  # bodies 1 and 2
    assert hits.any()
    # plastic impact of equal masses: both at 10 m/s (solver tolerance 1e-8 relative)
    np.testing.assert_allclose(r.velocity("A")[-1][0], 10.0, rtol=1e-6)
    np.testing.assert_allclose(r.velocity("B")[-1][0], 10.0, rtol=1e-6)
    # B stays ahead of A: they never swapped
    assert r.position("B")[-1][0] > r.position("A")[-1][0]
    # overlap reported at every step and within the tolerance: 0.01 m is a tenth of the smallest
    # block's bounding radius (>= 0.1 m), so this is ten times stricter than the warning
    assert r.report.max_penetration <= PENETRATION_TOLERANCE * .01


def test_deep_overlap_is_reported_and_warns():
    """A step that ends in a deep overlap says so: a block pushed 5 mm into the base by
    hand (the step does not push bodies apart, it only stops their approach) ends its
    step overlapping by 5 mm, which is reported and warns."""
    s = nscd.Scene()
    s.add_base(nscd.box(4, .2), position=(0, -.1))
    s.add_block(nscd.box(.2, .2), position=(0, .1))
    sim = nscd.Simulator(s, dt=1e-3)
    # push the block 5 mm into the base by hand: the first step ends overlapping
    sim.data.q[0, 1, 1] -= 5e-3
    with pytest.warns(RuntimeWarning, match="overlap by"):
        sim.step()
    # 1 %: within the step the block, held by the contact, moves by far less than 50 um (gravity
    # alone would move it by g dt^2 = 1e-5 m)
    np.testing.assert_allclose(sim.output.report.penetration, 5e-3, rtol=1e-2)


def _plank_overlap(q: np.ndarray, width: float, height: float) -> np.ndarray:
    """Overlap (m) of a ``width`` x ``height`` plank of poses ``q`` (..., 3) with the base's
    top face y = 0, from the pose alone: the depth of its lowest corner (0 if above)."""
    y, angle = q[..., 1], q[..., 2]
    corners = 0.5 * np.array([[width, height], [-width, height], [-width, -height], [width, -height]])
    lowest = (y[..., None] + np.sin(angle)[..., None] * corners[:, 0]
              + np.cos(angle)[..., None] * corners[:, 1]).min(axis=-1)
    return np.maximum(-lowest, 0.0)


def _spinning_plank(omega: float, vy: float, width: float = .4, height: float = .1) -> nscd.Scene:
    s = nscd.Scene()
    s.add_base(nscd.box(40, .2), position=(0, -.1))
    s.add_block(nscd.box(width, height), position=(0, .3), velocity=(0, vy), omega=omega)
    s.set_contact(friction=.5)
    return s


@pytest.mark.parametrize("scheme", ["theta", "midpoint"])
@pytest.mark.parametrize("omega, vy, dt", [(50.0, -2.0, 1e-2), (80.0, -5.0, 1e-2), (100.0, 0.0, 1e-2),
                                           (30.0, -1.0, 2e-2)])
def test_spinning_plank_lands_without_deep_overlap(scheme, omega, vy, dt):
    """A plank spinning by 0.5-1 rad per step lands on the base. A step's contacts are
    linearised about its start, so a corner that comes round within a large turn is not seen
    coming (whole steps ended centimetres deep); the step is taken in pieces of at most
    0.04 rad of turn, which bounds that error by 0.04^2 R / 2 = 8e-4 R: no step ends deeper
    than the warning threshold (1e-3 R), checked here on the plank's pose at every step."""
    width, height = .4, .1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overlap warning, no solver failure
        r = nscd.simulate(_spinning_plank(omega, vy, width, height), t_end=1.0, dt=dt,
                          settings=nscd.Settings(scheme=scheme))
    assert _plank_overlap(r.q[:, 1], width, height).max() <= PENETRATION_TOLERANCE * np.hypot(width, height) / 2


@pytest.mark.parametrize("scheme", ["theta", "midpoint"])
def test_deep_end_overlap_is_detected_in_the_end_configuration(scheme):
    """A spinning plank pushed 5 mm into the base by hand ends its step overlapping (the step
    stops approaches, it does not push bodies apart). The first-order prediction of that
    overlap errs by the plank's turning (up to (omega span)^2 R / 2); the reported overlap is the depth
    of the lowest corner of the end pose, computed here from the pose, to round-off."""
    width, height = .4, .1
    s = nscd.Scene()
    s.add_base(nscd.box(40, .2), position=(0, -.1))
    s.add_block(nscd.box(width, height), position=(0, height / 2), omega=20.0)
    sim = nscd.Simulator(s, dt=1e-2, settings=nscd.Settings(scheme=scheme))
    sim.data.q[0, 1, 1] -= 5e-3
    with pytest.warns(RuntimeWarning, match="overlap by"):
        sim.step()
    # detected in the same configuration: equal to round-off (1e-12 m on positions of order 1 m)
    np.testing.assert_allclose(sim.output.report.penetration, _plank_overlap(sim.state.q[1], width, height),
                               rtol=0, atol=1e-12)


def test_fast_block_hits_a_row_of_thin_blocks():
    """Newton's cradle with plastic impacts: a 2 cm block at 20 m/s hits two resting 2 cm
    blocks 5 mm apart (both gaps close within one step of 1e-2 s); momentum conservation
    leaves the three at 20/3 m/s, in their order, with no overlap."""
    s = nscd.Scene()
    s.add_base(nscd.box(60, .2), position=(0, -.1))
    names = ["A", "B", "C"]
    for name, x, vx in zip(names, (-.5211, .01, .035), (20, 0, 0)):
        s.add_block(nscd.box(.02, .2), position=(x, .1), velocity=(vx, 0), name=name)
    s.set_contact(0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overlap warning, no solver failure
        r = nscd.simulate(s, t_end=.2, dt=1e-2)
    for name in names:  # solver tolerance 1e-8 relative
        np.testing.assert_allclose(r.velocity(name)[-1][0], 20 / 3, rtol=1e-6)
    x = [r.position(name)[-1][0] for name in names]
    assert x[0] < x[1] < x[2]
    # a tenth of the warning threshold of the blocks (bounding radius 0.1 m), as above
    assert r.report.max_penetration <= PENETRATION_TOLERANCE * .01
