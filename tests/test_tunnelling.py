"""Fast bodies do not pass through each other: speculative contacts find every contact that
can close within a step (the midpoint rule sees a fast scene at the start of the step, not
half a step ahead), and the deepest end-of-step overlap is reported (and warns).

A 20 m/s block meets a resting one of equal mass, frictionless, restitution 0: a plastic
impact, after which both move at 10 m/s (momentum conservation, m v = 2 m v'). A plank
spinning fast lands on the base: a step that ends overlapping reports the overlap of its end
configuration.
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
    # overlap reported at every step and within the tolerance
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
    np.testing.assert_allclose(sim.output.report.penetration, 5e-3, rtol=1e-2)


def _plank_overlap(result, width: float, height: float) -> np.ndarray:
    """Overlap (m) of a ``width`` x ``height`` plank (body 1) with the base's top face y = 0
    at the end of each step, from the plank's pose alone: the depth of its lowest corner."""
    x, y, angle = result.q[1:, 1, 0], result.q[1:, 1, 1], result.q[1:, 1, 2]
    corners = 0.5 * np.array([[width, height], [-width, height], [-width, -height], [width, -height]])
    lowest = (y[:, None] + np.sin(angle)[:, None] * corners[:, 0] + np.cos(angle)[:, None] * corners[:, 1]).min(axis=1)
    return np.maximum(-lowest, 0.0)


@pytest.mark.parametrize("scheme", ["theta", "midpoint"])
@pytest.mark.parametrize("omega, dt", [(50.0, 1e-2), (100.0, 1e-2), (30.0, 2e-2)])
def test_deep_end_overlaps_are_detected_in_the_end_configuration(scheme, omega, dt):
    """A plank spinning at 0.5-1 rad per step lands on the base: its corners come round
    within a step, the first-order prediction of the end gaps errs by centimetres, and steps
    can end overlapping. Every step whose end configuration overlaps beyond the warning
    threshold reports that overlap (the depth of the lowest corner, computed here from the
    pose) and warns; no other step warns."""
    width, height = .4, .1
    s = nscd.Scene()
    s.add_base(nscd.box(40, .2), position=(0, -.1))
    s.add_block(nscd.box(width, height), position=(0, .3), velocity=(0, -2), omega=omega)
    s.set_contact(friction=.5)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = nscd.simulate(s, t_end=1.0, dt=dt, settings=nscd.Settings(scheme=scheme))
    overlap = _plank_overlap(r, width, height)
    deep = overlap > PENETRATION_TOLERANCE * np.hypot(width, height) / 2
    # detected in the same configuration: equal to round-off (1e-12 m on positions of order 1 m)
    np.testing.assert_allclose(r.report.penetration[deep], overlap[deep], rtol=0, atol=1e-12)
    assert sum("overlap by" in str(w.message) for w in caught) == deep.sum()

