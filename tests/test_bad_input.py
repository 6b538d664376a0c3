"""Bad input is met by a ValueError that names the body or parameter and the allowed range."""
from __future__ import annotations

import math

import numpy as np
import pytest

import nscd


def block_scene(**block_kwargs):
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1))
    kwargs = dict(position=(0.0, 0.75), density=2500.0)
    kwargs.update(block_kwargs)
    scene.add_block(nscd.box(0.5, 1.5), **kwargs)
    return scene


@pytest.mark.parametrize("vertices, message", [
    ([(0, 0), (2, 0), (1, 0.5), (2, 2), (0, 2)], "non-convex"),
    ([(0, 0), (1, 1), (1, 0), (0, 1)], "self-intersecting"),
    ([(0, 0), (1, 0)], "at least 3 vertices"),
    ([(0, 0), (1, 0), (2, 0)], "zero area"),
    ([(0, 0), (1, 0), (1, 0), (0, 1)], "repeated"),
    ([(0, 0), (1, 0), (np.nan, 1)], "NaN"),
])
def test_bad_polygons(vertices, message):
    with pytest.raises(ValueError, match=message):
        nscd.polygon(vertices)


def test_polygon_accepts_clockwise_order():
    cw = nscd.polygon([(0, 0), (0, 1), (1, 1), (1, 0)])
    assert cw.area == pytest.approx(1.0)


@pytest.mark.parametrize("density", [0.0, -1.0, math.nan])
def test_density_must_be_positive(density):
    with pytest.raises(ValueError, match=r"body 'block1': density == .*must be > 0"):
        block_scene(density=density)


def test_overlapping_bodies_at_start_name_both():
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), name="floor")
    scene.add_block(nscd.box(0.5, 1.5), position=(0.0, 0.70), density=2500.0, name="pier")
    with pytest.raises(ValueError, match="'floor' and 'pier' overlap by 0.05"):
        nscd.simulate(scene, t_end=0.1, dt=1e-3)


@pytest.mark.parametrize("friction, restitution, message", [
    (-0.1, 0.0, r"friction == -0.1, must be a finite number >= 0"),
    (0.5, 1.5, r"restitution == 1.5, must be in \[0, 1\]"),
    (0.5, -0.2, r"restitution == -0.2, must be in \[0, 1\]"),
    (math.inf, 0.0, "friction == inf"),
])
def test_contact_law_ranges(friction, restitution, message):
    scene = block_scene()
    with pytest.raises(ValueError, match=message):
        scene.set_contact(friction=friction, restitution=restitution)


@pytest.mark.parametrize("t_end, dt, message", [
    (1.0, 0.0, r"dt == 0.0, must be a finite number > 0"),
    (1.0, -1e-3, r"dt == -0.001"),
    (-1.0, 1e-3, r"t_end == -1.0, must be a finite number >= 0"),
    (1.0, 2.0, r"dt == 2.0, must be in \(0, t_end\]"),
    (1.0, math.nan, "dt == nan"),
])
def test_time_step_and_end(t_end, dt, message):
    with pytest.raises(ValueError, match=message):
        nscd.simulate(block_scene(), t_end=t_end, dt=dt)


@pytest.mark.parametrize("make", [
    lambda: nscd.motion.OneSine(amplitude=math.nan, omega=6.0),
    lambda: nscd.motion.OneSine(amplitude=1.0, omega=math.inf),
    lambda: nscd.motion.OneCosine(amplitude=1.0, omega=0.0),
    lambda: nscd.motion.Record([0.0, 0.1, math.nan, 0.0], dt=0.01, unit="g"),
    lambda: nscd.motion.Record([0.0, 0.1, math.inf], dt=0.01, unit="m/s^2"),
    lambda: nscd.motion.Record([0.0, 0.1, 0.2], dt=0.01, unit=None),
    lambda: nscd.motion.Record([0.0, 0.1, 0.2], dt=0.0, unit="g"),
])
def test_motions_reject_nan_inf_and_missing_units(make):
    with pytest.raises(ValueError):
        make()


def test_record_error_names_the_bad_sample():
    with pytest.raises(ValueError, match="2"):
        nscd.motion.Record([0.0, 0.1, math.nan, 0.0], dt=0.01, unit="g")


def test_shape_dimension_must_match_scene():
    scene3 = nscd.Scene(dim=3)
    with pytest.raises(ValueError, match="shape is 2D but the scene is 3D"):
        scene3.add_block(nscd.box(0.5, 1.5), position=(0, 0, 1), density=2500.0)
    scene2 = nscd.Scene()
    with pytest.raises(ValueError, match="shape is 3D but the scene is 2D"):
        scene2.add_block(nscd.box(0.5, 0.5, 1.5), position=(0, 1), density=2500.0)


def test_zero_quaternion_is_rejected():
    scene = nscd.Scene(dim=3)
    with pytest.raises(ValueError, match="zero norm"):
        scene.add_block(nscd.box(0.5, 0.5, 1.5), position=(0, 0, 1), orientation=(0, 0, 0, 0), density=2500.0)


def test_scene_without_dynamic_body():
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1))
    with pytest.raises(ValueError, match="no dynamic body"):
        nscd.simulate(scene, t_end=0.1, dt=1e-3)


def test_motion_must_be_a_motion():
    scene = nscd.Scene()
    with pytest.raises(TypeError, match="motion must be an nscd.motion.Motion"):
        scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), motion=lambda t: 0.0)


def test_settings_ranges():
    with pytest.raises(ValueError, match=r"theta == 0.2, must be in \[0.5, 1\]"):
        nscd.Settings(theta=0.2)
    with pytest.raises(ValueError, match="on_failure"):
        nscd.Settings(on_failure="ignore")
