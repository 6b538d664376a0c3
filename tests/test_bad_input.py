"""Bad input is met by a ValueError that names the body or parameter and the allowed range."""
from __future__ import annotations

import math
import warnings

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


# ----------------------------------------------------------------------------------------
# Every real number type is a number: numpy scalars are accepted wherever a float is.

def test_numpy_scalars_are_accepted_as_numbers():
    scene = block_scene(density=np.float32(2500.0))
    assert scene.bodies[1].density == 2500.0
    assert block_scene(density=np.int64(2500)).bodies[1].mass == scene.bodies[1].mass
    scene.set_contact(friction=np.float64(0.5), restitution=np.float32(0.25))
    assert scene.default_contact.friction == 0.5 and scene.default_contact.restitution == 0.25
    result = nscd.simulate(block_scene(), t_end=np.float64(0.004), dt=np.float32(1e-3))
    assert result.status == "finished" and len(result.time) == 5
    assert nscd.Settings(theta=np.float32(0.5)).theta == 0.5


# ----------------------------------------------------------------------------------------
# Refused inputs: each raises a clear error naming the parameter, its value and what is allowed.

def at2_file(tmp_path, header4, values="0.1 0.2 0.3", binary=None):
    path = tmp_path / "record.AT2"
    if binary is not None:
        path.write_bytes(binary)
    else:
        path.write_text(f"PEER NGA\nrecord\nACCELERATION TIME SERIES IN UNITS OF G\n{header4}\n{values}\n")
    return path


def two_block_batch():
    return nscd.BatchSimulator([block_scene(), block_scene()], dt=1e-3)


def saved_result(tmp_path):
    return nscd.simulate(block_scene(), t_end=0.003, dt=1e-3).save(tmp_path / "run.npz")


def cell(x):
    return {"y": 2 * x}


def solve(W):
    from nscd.solver import solve_local

    return solve_local(np.asarray(W, float), np.array([-1.0, 0.5, 0.0]), [0.5], dim=3)


REFUSED = {
    # name: (make, exception, message)
    "friction given as a word": (lambda tmp: block_scene().set_contact(friction="high"),
                                 TypeError, r"friction == 'high' \(str\), must be a real number"),
    "between with three names": (lambda tmp: block_scene().set_contact(0.5, between=("a", "b", "c")),
                                 TypeError, r"between == \('a', 'b', 'c'\), must be a pair"),
    "a string for the scene": (lambda tmp: nscd.simulate("scene", t_end=0.1, dt=1e-3),
                               TypeError, r"scene == 'scene', must be an nscd.Scene"),
    "solver settings as a dict": (lambda tmp: nscd.Settings(solver={"tol": 1e-3}),
                                  TypeError, r"solver == \{'tol': 0.001\}, must be an nscd.SolverSettings"),
    "a string for a trimesh": (lambda tmp: nscd.Polyhedron.from_trimesh("cube"),
                               TypeError, r"mesh == 'cube' \(str\), must be a trimesh.Trimesh"),
    "words for record samples": (lambda tmp: nscd.motion.Record(["a", "b"], dt=0.01, unit="g"),
                                 TypeError, r"samples must be real numbers"),
    "a record read at t = nan": (lambda tmp: nscd.motion.Record([0.0, 1.0, 0.0], dt=0.01, unit="g").acceleration(math.nan),
                                 ValueError, r"t == nan contains NaN"),
    "a binary file as .AT2": (lambda tmp: nscd.motion.Record.from_at2(at2_file(tmp, "", binary=bytes(range(256)) * 2)),
                              ValueError, r"record.AT2: not a text file"),
    "DT= . in an .AT2 header": (lambda tmp: nscd.motion.Record.from_at2(at2_file(tmp, "NPTS= 3, DT= . SEC")),
                                ValueError, r"header line 4 must give 'NPTS= N, DT= X SEC' .*got 'NPTS= 3, DT= \. SEC'"),
    "NPTS=0 in an .AT2 header": (lambda tmp: nscd.motion.Record.from_at2(at2_file(tmp, "NPTS= 0, DT= .01 SEC")),
                                 ValueError, r"NPTS == 0 on header line 4, must be a whole number >= 2"),
    "DT=1e308 in an .AT2 header": (lambda tmp: nscd.motion.Record.from_at2(at2_file(tmp, "NPTS= 3, DT= 1e308 SEC")),
                                   ValueError, r"dt == 1e\+308 s with 3 samples"),
    "random bytes as a result": (lambda tmp: (tmp / "r.npz").write_bytes(bytes(range(256)) * 4) and nscd.load(tmp / "r.npz"),
                                 ValueError, r"r.npz is not a NumPy .npz archive \(ValueError: This file contains pickled"),
    "a truncated result": (lambda tmp: nscd.load(truncated(saved_result(tmp))),
                           ValueError, r"cut.npz is not a NumPy .npz archive \(BadZipFile"),
    "another program's .npz": (lambda tmp: np.savez(tmp / "foreign.npz", a=np.arange(3)) or nscd.load(tmp / "foreign.npz"),
                               ValueError, r"foreign.npz is not an nscd result \(no 'meta', 'time', 'q'... entry\)"),
    "a result whose times are all NaN": (lambda tmp: nscd.load(nan_times(tmp)),
                                         ValueError, r"time\[0\] == nan \(4 of 4 times not finite\)"),
    "a sweep written to a missing folder": (
        lambda tmp: nscd.sweep.grid(cell, {"x": [1, 2]}, out=tmp / "missing" / "map.csv", progress=False,
                                    executor=nscd.sweep.SerialExecutor()),
        ValueError, r"out == '.*missing/map.csv': the folder '.*missing' does not exist"),
    "a sweep grid with NaN": (lambda tmp: nscd.sweep.grid(cell, {"x": [1.0, math.nan]}, progress=False,
                                                          executor=nscd.sweep.SerialExecutor()),
                              ValueError, r"parameter 'x': value 1 is nan"),
    "a sweep grid with a repeated value": (lambda tmp: nscd.sweep.grid(cell, {"x": [1, 2, 1]}, progress=False,
                                                                       executor=nscd.sweep.SerialExecutor()),
                                           ValueError, r"parameter 'x': value 1 is given twice \(at 0 and 2\)"),
    "an indefinite Delassus matrix": (lambda tmp: solve(np.diag([1.0, -1.0, 1.0])),
                                      ValueError, r"W\[1, 1\] == -1.0: W is indefinite"),
    "an indefinite W with a positive diagonal": (lambda tmp: solve([[1, 0, 3], [0, 1, 0], [3, 0, 1]]),
                                                 ValueError, r"W is indefinite \(smallest eigenvalue .* -2"),
    "a zero Delassus matrix": (lambda tmp: solve(np.zeros((3, 3))),
                               ValueError, r"W\[0, 0\] == 0.0 \(normal row of contact 0\), must be > 0"),
    "stopping scene 99 of 2": (lambda tmp: two_block_batch().stop(99),
                               ValueError, r"k == 99: index 99 is outside \[0, 2\)"),
    "running until nan": (lambda tmp: nscd.Simulator(block_scene(), dt=1e-3).run(until=math.nan),
                          ValueError, r"until == nan, must be a finite time"),
    "a start velocity of 1e200 m/s": (lambda tmp: block_scene(velocity=(1e200, 0.0)),
                                      ValueError, r"body 'block1': velocity == \[1e\+200, 0.0\] m/s, its norm must "
                                                  r"be below the speed of light"),
    "localize_impacts='no'": (lambda tmp: nscd.Settings(localize_impacts="no"),
                              TypeError, r"localize_impacts == 'no', must be True or False"),
    "checkpoint_every=-1": (lambda tmp: nscd.simulate(block_scene(), t_end=0.002, dt=1e-3, checkpoint=tmp / "c.npz",
                                                      checkpoint_every=-1),
                            ValueError, r"checkpoint_every == -1.0, must be > 0 s"),
    "a checkpoint under a regular file": (
        lambda tmp: (tmp / "file").write_text("x") and nscd.simulate(block_scene(), t_end=0.002, dt=1e-3,
                                                                     checkpoint=tmp / "file" / "c.npz"),
        ValueError, r"checkpoint == '.*file/c.npz' cannot be written"),
}


def truncated(path):
    data = path.read_bytes()
    cut = path.with_name("cut.npz")
    cut.write_bytes(data[: len(data) // 2])
    return cut


def nan_times(tmp_path):
    result = nscd.simulate(block_scene(), t_end=0.003, dt=1e-3)
    result.time[:] = math.nan
    return result.save(tmp_path / "nan.npz")


@pytest.mark.parametrize("name", list(REFUSED))
def test_refused(name, tmp_path):
    make, exception, message = REFUSED[name]
    with pytest.raises(exception, match=message):
        make(tmp_path)


# ----------------------------------------------------------------------------------------
# Borderline inputs with a documented rule.

def test_start_overlap_equal_to_the_tolerance_is_accepted_and_deeper_refused():
    from nscd.scene import OVERLAP_TOLERANCE

    # the base's top face is at y = 0 and the block's half height 0.75 m
    result = nscd.simulate(block_scene(position=(0.0, 0.75 - OVERLAP_TOLERANCE)), t_end=0.002, dt=1e-3)
    assert result.status == "finished"
    with pytest.raises(ValueError, match=r"overlap by 1.01e-06 m at the start; penetration must be <= 1e-06 m"):
        nscd.simulate(block_scene(position=(0.0, 0.75 - 1.01 * OVERLAP_TOLERANCE)), t_end=0.002, dt=1e-3)


def test_a_block_sized_in_millimetres_warns_and_one_in_metres_does_not():
    scene = nscd.Scene()
    with pytest.warns(UserWarning, match=r"body 'block0': its bounding radius is 790.6 m, .* millimetres"):
        scene.add_block(nscd.box(500.0, 1500.0), position=(0.0, 750.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene.add_block(nscd.box(0.5, 1.5), position=(5.0, 0.75))


def test_t_end_between_whole_steps_takes_the_nearest_whole_step_and_says_so():
    with pytest.warns(RuntimeWarning, match=r"t_end == 0.0015 s is not a whole number of steps .* 2 steps, "
                                            r"and ends at t = 0.002 s"):
        result = nscd.simulate(block_scene(), t_end=0.0015, dt=1e-3)
    assert len(result.time) == 3 and result.time[-1] == pytest.approx(0.002, rel=1e-12)
    with pytest.warns(RuntimeWarning, match=r"1 steps, and ends at t = 0.001 s"):
        nscd.simulate(block_scene(), t_end=0.0014, dt=1e-3)
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a whole number of steps (up to round-off of 0.003 / 1e-3): silent
        assert len(nscd.simulate(block_scene(), t_end=0.003, dt=1e-3).time) == 4
