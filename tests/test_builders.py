"""Scene builders: geometry of stacks and running-bond walls, rest, bad input."""
from __future__ import annotations

import numpy as np
import pytest

import nscd
from nscd.builders import stack, wall
from nscd.contact.detect import detect
from nscd.model import Model
from nscd.stepper import initial_state


def _extent(body) -> tuple[np.ndarray, np.ndarray]:
    """Lower-left and upper-right corners of a block at its initial pose (unrotated)."""
    vertices = body.shape.vertices + body.q0[:2]
    return vertices.min(axis=0), vertices.max(axis=0)


def test_wall_is_a_running_bond():
    n_courses, n_per_course, bw, bh = 5, 4, 0.4, 0.2
    scene, courses = wall(n_courses, n_per_course, bw, bh)
    assert [len(c) for c in courses] == [4, 5, 4, 5, 4]
    assert len(scene.dynamic_bodies) == n_courses * n_per_course + n_courses // 2
    for row, course in enumerate(courses):
        corners = [_extent(b) for b in course]
        # Exact arithmetic on multiples of bw / 4 and bh / 2 (binary fractions of the
        # inputs): 1e-12 m only absorbs the round-off of the vertex sums.
        lower = np.array([c[0] for c in corners])
        upper = np.array([c[1] for c in corners])
        np.testing.assert_allclose(lower[:, 1], row * bh, atol=1e-12)
        np.testing.assert_allclose(upper[:, 1], (row + 1) * bh, atol=1e-12)
        np.testing.assert_allclose(lower[1:, 0], upper[:-1, 0], atol=1e-12)  # no gap, no overlap
        np.testing.assert_allclose([lower[0, 0], upper[-1, 0]], [-0.8, 0.8], atol=1e-12)  # flush ends
        joints = upper[:-1, 0]
        expected = -0.8 + bw * (np.arange(1, len(joints) + 1) - 0.5 * (row % 2))
        np.testing.assert_allclose(joints, expected, atol=1e-12)  # joints offset by half a block
        widths = upper[:, 0] - lower[:, 0]
        if row % 2:
            np.testing.assert_allclose(widths[[0, -1]], bw / 2, atol=1e-12)


def test_wall_contacts_are_closed_at_the_start():
    # Every joint touches: contact points with zero gap, and none overlapping.
    scene, _ = wall(3, 3, 0.4, 0.3)
    model = Model.from_scene(scene)
    contacts = detect(model, initial_state(scene).q, margin=1e-3)
    # Bed joints: 3 + 4 + 3 blocks on the course below (2 corners per touching pair);
    # head joints: 2 + 3 + 2. Points: base-course 0: 3 pairs; course 0-1: 6 pairs;
    # course 1-2: 6 pairs; head joints 7 pairs; 2 points each.
    assert len(contacts) == 2 * (3 + 6 + 6 + 7)
    assert np.all(np.abs(contacts.gap) <= 1e-12)  # placed exactly in contact (round-off only)


def test_stack_positions():
    scene, blocks = stack(3, width=0.4, height=1.0)
    np.testing.assert_allclose([b.q0[1] for b in blocks], [0.5, 1.5, 2.5])
    assert scene.bodies[0].name == "base" and not scene.bodies[0].is_dynamic


def test_wall_rests_without_drift():
    # A wall on a fixed base is in static equilibrium (vertical weights only): the exact
    # motion is none. A velocity-level step may settle each closed contact by up to the
    # stepper's gap tolerance g dt^2 (about 1e-5 m at dt = 1e-3 s), so over 4 bed joints
    # the top may sink by at most 4 g dt^2; sideways and in rotation nothing drives it,
    # so 1e-6 m (and rad) bounds the solver's residual (merit 1e-8) accumulated over the run.
    dt = 1e-3
    scene, courses = wall(4, 4, 0.4, 0.2)
    assert sum(map(len, courses)) == 18
    result = nscd.simulate(scene, 0.5, dt)
    q = result.q
    dyn = [b.index for c in courses for b in c]
    drift = q[:, dyn] - q[0, dyn]
    assert np.max(np.abs(drift[..., 0])) < 1e-6
    assert np.max(np.abs(drift[..., 2])) < 1e-6
    assert np.max(np.abs(drift[..., 1])) <= 4 * scene.gravity * dt**2


@pytest.mark.parametrize("kwargs, message", [
    (dict(n_courses=0), "n_courses == 0"),
    (dict(n_courses=2.5), "n_courses == 2.5"),
    (dict(n_per_course=True), "n_per_course == True"),
    (dict(block_width=-0.4), "block_width == -0.4"),
    (dict(block_height=float("nan")), "block_height == nan"),
    (dict(friction=-0.1), "friction == -0.1"),
    (dict(base_height=0.0), "base_height == 0.0"),
    (dict(density=0.0), "density == 0.0"),
])
def test_wall_bad_input(kwargs, message):
    args = dict(n_courses=2, n_per_course=3, block_width=0.4, block_height=0.2) | kwargs
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        wall(**args)


@pytest.mark.parametrize("kwargs, message", [
    (dict(n=0), "n == 0"),
    (dict(width=0.0), "width == 0.0"),
    (dict(height="1"), "height == '1'"),
])
def test_stack_bad_input(kwargs, message):
    args = dict(n=2, width=0.4, height=1.0) | kwargs
    with pytest.raises(ValueError, match=message):
        stack(**args)


@pytest.mark.parametrize("width, height, theta0", [(0.5, 1.5, 0.16), (0.4, 0.4, 0.3), (1.0, 2.0, 0.0)])
def test_tilted_block_rests_on_its_right_corner(width, height, theta0):
    # Housner's release: the block turned by -theta0 with its corner (b, 0) on the base's top
    # face; the corner's world position follows from the pose alone (x = c + R(-theta0) r).
    scene, block = nscd.tilted_block(width, height, theta0)
    x, y, angle = block.q0
    b, h = width / 2, height / 2
    c, s = np.cos(angle), np.sin(angle)
    corner = np.array([x + c * b - s * (-h), y + s * b + c * (-h)])
    assert angle == pytest.approx(-theta0, abs=1e-15)
    assert corner == pytest.approx([b, 0.0], abs=1e-12)  # round-off of a few products of O(1) m
    # the other bottom corner is lifted by width sin(theta0)
    other = np.array([x + c * -b - s * (-h), y + s * -b + c * (-h)])
    assert other[1] == pytest.approx(width * np.sin(theta0), abs=1e-12)


@pytest.mark.parametrize("kwargs, word", [({"theta0": -0.1}, "theta0"), ({"theta0": float("nan")}, "theta0"),
                                          ({"width": 0.0}, "width"), ({"friction": -1.0}, "friction")])
def test_tilted_block_refuses_bad_input(kwargs, word):
    args = {"width": 0.5, "height": 1.5, "theta0": 0.1} | kwargs
    with pytest.raises(ValueError, match=word):
        nscd.tilted_block(**args)
