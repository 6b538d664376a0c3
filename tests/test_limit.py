"""Collapse load factor on a quasi-static tilting table, against limit analysis."""
from __future__ import annotations

import math

import numpy as np
import pytest

import nscd
from nscd.analysis import collapse_load_factor
from nscd.motion import Harmonic

from arch_mechanisms import collapse_load_factor as kinematic_load_factor


@pytest.mark.parametrize("width, direction", [(0.2, 1), (0.33, -1), (0.5, 1)])
def test_block_tips_at_tan_alpha(width, direction):
    # A rigid block of width b and height h on a base with enough friction (mu = 1 > b/h)
    # starts to rock when the base acceleration reaches g b / h = g tan(alpha) (statics
    # of the block about its edge: the resultant of weight and inertia force passes
    # through the edge). 1 %: the onset is read within sqrt(2e-6 s T) ~ 1e-4 of the
    # load factor (module docstring of nscd.limit), the stepper's first-order error on
    # a body at rest is zero.
    height = 1.0
    scene, (block,) = nscd.stack(1, width=width, height=height, friction=1.0)
    tan_alpha = width / height
    collapse = collapse_load_factor(scene, direction=direction, start=0.9 * tan_alpha)
    assert collapse.collapsed and collapse.result.success
    assert collapse.load_factor == pytest.approx(tan_alpha, rel=1e-2)
    # The mechanism: one hinge between the base and the block, about the edge on the side
    # the inertial load points to (-x when the base accelerates toward +x).
    (hinge,) = collapse.joints
    assert hinge.kind == "hinge" and {hinge.body_a, hinge.body_b} == {0, block.index}
    np.testing.assert_allclose(hinge.points[0], [-direction * width / 2, 0.0], atol=1e-6)


def test_column_of_blocks_tips_as_one_about_its_base():
    # Three identical blocks b x h stacked: the top k blocks tip about their own bottom edge
    # at lambda = b / (k h), so the whole column goes first, at b / (3 h), as a monolith:
    # one hinge, on the base joint; the joints between blocks stay closed. 1 %: as above.
    width, height = 0.3, 0.5
    scene, blocks = nscd.stack(3, width=width, height=height, friction=1.0)
    exact = width / (3 * height)
    collapse = collapse_load_factor(scene, start=0.9 * exact)
    assert collapse.load_factor == pytest.approx(exact, rel=1e-2)
    (hinge,) = collapse.joints
    assert hinge.kind == "hinge" and {hinge.body_a, hinge.body_b} == {0, blocks[0].index}


def test_drum_tips_about_its_edge_in_3d():
    # A 12-sided drum (circumradius r, a side face normal to x) on a base with mu = 1 tips
    # about the bottom edge of that face, at distance r cos(pi / 12) from the axis: the
    # static limit is lambda = 2 r cos(pi / n) / h. 1 %: as for the 2D block.
    radius, height, n = 0.2, 1.0, 12
    scene, (drum,) = nscd.column(1, radius, height, n_sides=n, friction=1.0)
    exact = 2 * radius * math.cos(math.pi / n) / height
    collapse = collapse_load_factor(scene, start=0.95 * exact)
    assert collapse.load_factor == pytest.approx(exact, rel=1e-2)
    (hinge,) = collapse.joints
    assert hinge.kind == "hinge"
    np.testing.assert_allclose(hinge.points[:, 0], -radius * math.cos(math.pi / n), atol=1e-6)


def test_block_with_low_friction_slides_at_mu_g():
    # mu = 0.25 < b/h = 0.33: the base can only transmit mu m g sideways, so the block
    # slides (without rocking) when the acceleration reaches mu g. 1 %: as above.
    scene, (block,) = nscd.stack(1, width=0.33, height=1.0, friction=0.25)
    collapse = collapse_load_factor(scene, start=0.22)
    assert collapse.load_factor == pytest.approx(0.25, rel=1e-2)
    assert [j.kind for j in collapse.joints] == ["slip"] and not collapse.hinges


def test_semicircular_arch_against_kinematic_limit_analysis():
    # No verifiable published number was found for this geometry, so the reference is
    # an independent upper-bound (kinematic) limit analysis of the same discrete arch:
    # the smallest virtual-work load factor over all admissible four-hinge mechanisms
    # with hinges at the joints (tests/arch_mechanisms.py; lambda = 0.14997 with hinges at
    # joints 0 extrados, 4 intrados, 9 extrados, 14 intrados for t/R = 0.15, 16 voussoirs).
    # Friction 0.8 keeps every joint from sliding (the reference assumes no sliding).
    # 2 %: the onset reading (~1e-4) plus the hinges' finite rotation before the mechanism
    # is recognised; the mechanism must be the same four hinges.
    radius, thickness, n = 1.0, 0.15, 16
    reference, hinges = kinematic_load_factor(radius, thickness, n)
    scene, voussoirs = nscd.arch(radius, thickness, n, friction=0.8)
    collapse = collapse_load_factor(scene, start=0.9 * reference)
    assert collapse.result.success
    assert collapse.load_factor == pytest.approx(reference, rel=2e-2)
    found = []
    for joint in collapse.hinges:
        (pivot,) = joint.points
        k = int(round((math.pi - math.acos(pivot[0] / np.linalg.norm(pivot))) / (math.pi / n)))
        found.append((k, "e" if np.linalg.norm(pivot) > radius else "i"))
    assert sorted(found) == sorted(hinges)


@pytest.mark.slow
@pytest.mark.parametrize("angle, thickness", [(2 * math.pi / 3, 0.1), (1.2 * math.pi, 0.3)])
def test_shallow_and_horseshoe_arches_against_kinematic_limit_analysis(angle, thickness):
    # As above for a shallow (120 degree, reference lambda = 0.593) and a horseshoe (216
    # degree, lambda = 0.175; a horseshoe needs a thicker ring to stand at all) arch of 12
    # voussoirs. Hinge positions in polar angle from the left springing.
    radius, n = 1.0, 12
    reference, hinges = kinematic_load_factor(radius, thickness, n, angle)
    scene, _ = nscd.arch(radius, thickness, n, friction=0.8, angle=angle)
    collapse = collapse_load_factor(scene, start=0.9 * reference)
    assert collapse.result.success
    assert collapse.load_factor == pytest.approx(reference, rel=2e-2)
    found = []
    left = 0.5 * math.pi + 0.5 * angle
    for joint in collapse.hinges:
        (pivot,) = joint.points
        lowest = 0.5 * math.pi - 0.5 * angle - 1e-6  # polar angle of the right springing
        polar = lowest + (math.atan2(pivot[1], pivot[0]) - lowest) % (2 * math.pi)
        found.append((int(round((left - polar) / (angle / n))), "e" if np.linalg.norm(pivot) > radius else "i"))
    assert sorted(found) == sorted(hinges)


@pytest.mark.slow
def test_block_from_rest_ramp():
    # The whole ramp from lambda = 0 (no start offset): same answer, tan(alpha) within 1 %.
    scene, _ = nscd.stack(1, width=0.25, height=1.0, friction=1.0)
    assert collapse_load_factor(scene).load_factor == pytest.approx(0.25, rel=1e-2)


def test_no_collapse_below_max_load_factor():
    scene, _ = nscd.stack(1, width=0.5, height=1.0, friction=1.0)
    collapse = collapse_load_factor(scene, start=0.3, max_load_factor=0.32)
    assert not collapse.collapsed and math.isnan(collapse.load_factor)
    assert collapse.load[-1] == pytest.approx(0.32, abs=1e-3)
    assert collapse.displacement.max() < 1e-6  # at rest on the accelerating base


def test_too_fast_ramp_is_refused_with_the_ramp_it_needs():
    scene, _ = nscd.stack(1, width=0.3, height=1.0, friction=1.0)
    # T = sqrt(1 m / g) = 0.319 s: at most 0.01 per T, rate <= 0.0313 1/s.
    bound = 0.01 / math.sqrt(1.0 / scene.gravity)
    with pytest.raises(ValueError, match=r"rate == 0\.1 1/s is too fast to be quasi-static") as info:
        collapse_load_factor(scene, rate=0.1)
    assert f"{bound:.6g}" in str(info.value)


@pytest.mark.parametrize("kwargs, message", [
    (dict(direction=0), "direction == 0"),
    (dict(rate=-1.0), "rate == -1.0"),
    (dict(start=-0.1), "start == -0.1"),
    (dict(max_load_factor=0.0), "max_load_factor == 0.0"),
    (dict(detect=0.5), "detect == 0.5"),
])
def test_collapse_load_factor_bad_input(kwargs, message):
    scene, _ = nscd.stack(1, width=0.3, height=1.0)
    with pytest.raises(ValueError, match=message):
        collapse_load_factor(scene, **kwargs)


def test_driven_supports_are_refused():
    scene, _ = nscd.stack(1, width=0.3, height=1.0, motion=Harmonic(1.0, frequency=1.0))
    with pytest.raises(ValueError, match="body 'base' already has a motion"):
        collapse_load_factor(scene)


def test_start_above_the_collapse_load_is_refused():
    scene, _ = nscd.stack(1, width=0.3, height=1.0, friction=1.0)
    with pytest.raises(ValueError, match="start == 0.5: the assembly moved from the first step"):
        collapse_load_factor(scene, start=0.5)
