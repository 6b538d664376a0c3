"""3D builders: drums, walls with a depth, columns and colonnades: geometry, contact, rest."""
from __future__ import annotations

import math

import numpy as np
import pytest

import nscd
from nscd.contact.detect import detect
from nscd.model import Model
from nscd.stepper import initial_state


@pytest.mark.parametrize("n_sides", [3, 4, 16, 64])
def test_drum_volume_is_the_inscribed_polygon_prism(n_sides):
    radius, height, density = 0.4, 0.7, 2500.0
    shape = nscd.drum(radius, height, n_sides)
    # A regular n-gon inscribed in a circle of radius r: n triangles of area r^2 sin(2 pi / n) / 2.
    polygon_area = 0.5 * n_sides * radius**2 * math.sin(2 * math.pi / n_sides)
    assert shape.mass(density) == pytest.approx(density * polygon_area * height, rel=1e-12)
    # Against the cylinder pi r^2 h: short by exactly 1 - sin(2 pi/n) / (2 pi/n) (2.6 % at 16 sides).
    cylinder = density * math.pi * radius**2 * height
    deficit = 1.0 - math.sin(2 * math.pi / n_sides) / (2 * math.pi / n_sides)
    assert 1.0 - shape.mass(density) / cylinder == pytest.approx(deficit, rel=1e-9)
    np.testing.assert_allclose(np.linalg.norm(shape.vertices[:, :2], axis=1), radius, rtol=1e-12)
    np.testing.assert_allclose(np.ptp(shape.vertices[:, 2]), height, rtol=1e-12)


@pytest.mark.parametrize("kwargs, message", [
    (dict(radius=0.0), "radius == 0.0"), (dict(height=-1.0), "height == -1.0"),
    (dict(n_sides=2), "n_sides == 2"),
])
def test_drum_bad_input(kwargs, message):
    with pytest.raises(ValueError, match=message):
        nscd.drum(**(dict(radius=0.3, height=0.5, n_sides=8) | kwargs))


def _closed_pairs(scene) -> tuple[set, np.ndarray]:
    model = Model.from_scene(scene)
    contacts = detect(model, initial_state(scene).q, margin=1e-3)
    return {(int(a), int(b)) for a, b in zip(contacts.body_a, contacts.body_b)}, contacts.gap


def test_wall_with_depth_is_the_running_bond_in_3d():
    scene2, courses2 = nscd.wall(3, 3, 0.4, 0.3)
    scene, courses = nscd.wall(3, 3, 0.4, 0.3, depth=0.2)
    assert scene.dim == 3 and scene2.dim == 2
    assert [len(c) for c in courses] == [len(c) for c in courses2]
    for body3, body2 in zip((b for c in courses for b in c), (b for c in courses2 for b in c)):
        # same x and height as the 2D wall, centred on y = 0, boxes 0.2 m deep
        np.testing.assert_allclose(body3.q0[[0, 2]], body2.q0[:2], atol=1e-12)
        assert body3.q0[1] == 0.0
        assert np.ptp(body3.shape.vertices[:, 1]) == pytest.approx(0.2, rel=1e-12)
        assert body3.mass == pytest.approx(0.2 * body2.mass, rel=1e-12)  # 2D: unit depth
    pairs, gaps = _closed_pairs(scene)
    pairs2, _ = _closed_pairs(scene2)
    assert pairs == pairs2  # the same joints (bed and head) as in 2D
    assert np.all(np.abs(gaps) <= 1e-12)  # placed exactly in contact (round-off only)


def test_wall_depth_bad_input():
    with pytest.raises(ValueError, match="depth == 0.0"):
        nscd.wall(2, 2, 0.4, 0.2, depth=0.0)


def test_colonnade_is_built_in_contact():
    scene, columns, architrave = nscd.colonnade(3, 1.0, 2, radius=0.2, drum_height=0.5, n_sides=8,
                                                architrave_height=0.3)
    assert [len(c) for c in columns] == [2, 2, 2] and len(architrave) == 2
    pairs, gaps = _closed_pairs(scene)
    base = scene.bodies[0].index
    expected = set()
    for column in columns:
        expected.add((base, column[0].index))
        expected.add((column[0].index, column[1].index))
    # architrave block i rests on columns i and i + 1 and touches block i + 1 over column i + 1
    for i, block in enumerate(architrave):
        expected |= {(columns[i][-1].index, block.index), (columns[i + 1][-1].index, block.index)}
    expected.add((architrave[0].index, architrave[1].index))
    assert pairs == expected
    assert np.all(np.abs(gaps) <= 1e-12)
    np.testing.assert_allclose([c[0].q0[0] for c in columns], [-1.0, 0.0, 1.0])


def test_colonnade_bad_spacing():
    with pytest.raises(ValueError, match=r"spacing == 0.3, must be > 2 radius"):
        nscd.colonnade(2, 0.3, 1, radius=0.2, drum_height=0.5)


def _drift(result, bodies) -> np.ndarray:
    idx = [b.index for b in bodies]
    return result.q[:, idx] - result.q[0, idx]


@pytest.mark.parametrize("build, n_bed_joints", [
    (lambda: (lambda s, c: (s, [b for row in c for b in row]))(*nscd.wall(3, 3, 0.4, 0.2, depth=0.2)), 3),
    (lambda: nscd.column(3, 0.25, 0.6, n_sides=12), 3),
    (lambda: (lambda s, c, a: (s, [b for col in c for b in col] + a))(
        *nscd.colonnade(2, 0.8, 1, radius=0.2, drum_height=0.5, n_sides=8)), 2),
], ids=["wall", "column", "colonnade"])
def test_3d_assemblies_rest_without_creep(build, n_bed_joints):
    # In equilibrium under vertical weights the exact motion is none. As for the 2D wall
    # (tests/test_builders.py): each closed bed joint may settle by up to the stepper's
    # gap tolerance g dt^2, so the top sinks by at most n_bed_joints g dt^2; sideways
    # and in rotation nothing drives the blocks, so 1e-6 m (and 1e-6 in the quaternion)
    # bounds the solver residual (merit 1e-8) accumulated over the run.
    dt = 1e-3
    scene, bodies = build()
    result = nscd.simulate(scene, 0.1, dt)
    assert result.success
    drift = _drift(result, bodies)
    assert np.max(np.abs(drift[..., :2])) < 1e-6
    assert np.max(np.abs(drift[..., 4:])) < 1e-6
    assert np.max(np.abs(drift[..., 2])) <= n_bed_joints * scene.gravity * dt**2
