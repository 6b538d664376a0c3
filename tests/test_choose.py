"""choose_model and run: the smallest adequate model, with reasons, run and checked after the run."""
import math

import numpy as np
import pytest

import nscd
from nscd import lnec
from nscd.choose import AssumptionWarning, choose_model, run
from nscd.motion import OneSine, STANDARD_GRAVITY as G

WIDTH, HEIGHT = 0.5, 1.5                  # the README's block: tan(alpha) = 1/3
ONSET = G * WIDTH / HEIGHT                # Housner's static onset g tan(alpha), m/s^2


def block_scene(friction=0.8, motion=None, vertical=None, restitution=0.0):
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), motion=motion, vertical=vertical, name="base")
    scene.add_block(nscd.box(WIDTH, HEIGHT), position=(0.0, HEIGHT / 2), density=2500.0, name="block")
    scene.set_contact(friction=friction, restitution=restitution)
    return scene


def test_single_block_with_enough_friction_is_housner():
    pulse = OneSine(1.2 * ONSET, omega=6.1)
    choice = choose_model(block_scene(0.8, pulse))
    assert choice.kind == "housner"
    assert any("0.3333" in r and "Shenton" in r for r in choice.reasons)  # needed mu at a gradual onset: tan(alpha)
    assert any("mu g = 7.845" in x for x in choice.limits)                # Shenton's sliding threshold, 0.8 g


def test_friction_below_onset_requirement_gets_the_engine():
    choice = choose_model(block_scene(0.2, OneSine(1.2 * ONSET, omega=6.1)))
    assert choice.kind == "2d"
    assert "friction 0.2 < 0.3333" in choice.reasons[0] and "Shenton" in choice.reasons[0]


def test_pulse_lifting_the_block_off_gets_the_engine():
    lift = OneSine(-1.3 * G, omega=20.0)  # base falls faster than g during the first half cycle
    choice = choose_model(block_scene(0.8, OneSine(0.5 * ONSET, omega=6.1), vertical=lift))
    assert choice.kind == "2d"
    assert "lift off" in choice.reasons[0] and "-12.75" in choice.reasons[0]


def test_wall_gets_the_2d_engine():
    scene, _ = nscd.wall(n_courses=3, n_per_course=2, block_width=0.4, block_height=0.2, friction=0.7)
    choice = choose_model(scene)
    assert choice.kind == "2d"
    assert "not reducible" in choice.reasons[0]


def test_stacked_pair_and_3d_scenes():
    assert choose_model(lnec.stacked_pair_2d(OneSine(3.0, omega=30.0))).kind == "stacked"
    assert choose_model(lnec.trilith()).kind == "3d"
    # the 3D single specimen driven along its width reduces to its section
    assert choose_model(lnec.single(2, motion=OneSine(3.0, omega=20.0))).kind == "housner"


def test_bad_model_names_and_forced_models():
    scene = block_scene(0.8, OneSine(1.2 * ONSET, omega=6.1))
    with pytest.raises(ValueError, match="model == 'foo'"):
        run(scene, 1.0, 1e-3, model="foo")
    with pytest.raises(ValueError, match="model == 'foo'"):
        nscd.simulate(scene, 1.0, 1e-3, model="foo")
    wall, _ = nscd.wall(n_courses=3, n_per_course=2, block_width=0.4, block_height=0.2, friction=0.7)
    with pytest.raises(ValueError, match="model == 'housner' cannot represent this scene: not reducible"):
        run(wall, 1.0, 1e-3, model="housner")
    with pytest.raises(ValueError, match="model == 'stacked' cannot represent"):
        run(scene, 1.0, 1e-3, model="stacked")
    with pytest.raises(ValueError, match="model == '2d' cannot represent a 3D scene"):
        run(lnec.single(2), 1.0, 1e-3, model="2d")
    with pytest.raises(ValueError, match="give its time step dt"):
        run(scene, 1.0, None, model="2d")


def test_auto_runs_housner_with_the_engine_outcome():
    """The README's pulse: the 1-DOF model and the 2D engine agree on the outcome and the peak."""
    scene = block_scene(0.8, OneSine(4.0, omega=6.1))
    reduced = run(scene, 4.0, model="auto")
    engine = nscd.simulate(scene, 4.0, 1e-2, settings=nscd.Settings(scheme="midpoint"), model="2d")
    assert reduced.model == "housner" and engine.model == "2d"
    assert reduced.overturned("block") == engine.overturned("block") is False
    peak_r, peak_e = (np.max(np.abs(r.angle("block"))) for r in (reduced, engine))
    assert peak_r == pytest.approx(peak_e, rel=0.02)  # midpoint rule at dt = 1e-2: impacts within 0.6 ms (README)
    assert not reduced.violations
    # the centre of mass where the angle puts it: on the circle of radius R about the pivot
    x, y = reduced.position("block").T
    r_half = math.hypot(WIDTH / 2, HEIGHT / 2)
    pivot_x = np.asarray(scene.body("base").motion.displacement(reduced.time)) - np.sign(reduced.angle("block")) * WIDTH / 2
    moving = reduced.angle("block") != 0
    assert np.allclose(np.hypot(x - pivot_x, y)[moving], r_half, rtol=1e-12)


def test_violated_friction_is_flagged_with_time_and_margin():
    """mu = 0.34 passes Shenton's onset test (0.3333) but not the demand while rocking (0.35 at t = 0.25 s)."""
    scene = block_scene(0.34, OneSine(4.0, omega=6.1))
    assert choose_model(scene).kind == "housner"
    with pytest.warns(AssumptionWarning, match="largest friction demand at the base"):
        result = run(scene, 4.0)
    (bad,) = result.violations
    assert bad.name == "no sliding at the base"
    assert bad.margin < 0 and 0.0 < bad.worst_time < 2 * math.pi / 6.1   # during the pulse
    # the demand from statics at the instant of the onset: a / g on the resting block, here tan(alpha)
    assert 0.34 - bad.margin >= WIDTH / HEIGHT


@pytest.mark.filterwarnings("ignore:housner model:nscd.choose.AssumptionWarning")
def test_forcing_housner_on_a_sliding_block_warns():
    scene = block_scene(0.2, OneSine(1.2 * ONSET, omega=6.1))
    with pytest.warns(AssumptionWarning, match="forced"):
        result = run(scene, 2.0, model="housner")
    assert result.model == "housner" and result.violations


def test_verify_reports_the_engine_outcome():
    scene = block_scene(0.8, OneSine(4.0, omega=6.1))
    result = run(scene, 3.0, 1e-2, verify=True, settings=nscd.Settings(scheme="midpoint"))
    v = result.report["verification"]
    assert v["models"] == ("housner", "2d") and v["same_outcome"]
    assert v["blocks"]["block"]["relative_difference"] < 0.02


def test_2d_scene_runs_extruded_in_3d():
    scene = block_scene(0.8, OneSine(4.0, omega=6.1))
    result = run(scene, 0.3, 1e-3, model="3d")
    assert result.model == "3d" and result.dim == 3
    assert result.success


def test_free_rocking_from_a_tilt_is_housner_with_the_engine_impacts():
    """A block released on its corner: Housner's first impact time (closed by energy) in both models."""
    b, h, tilt = WIDTH / 2, HEIGHT / 2, 0.15
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), name="base")
    # on the left corner (-b, 0): centroid = corner + R(tilt) (b, h)
    scene.add_block(nscd.box(WIDTH, HEIGHT), angle=tilt, density=2500.0, name="block",
                    position=(-b + math.cos(tilt) * b - math.sin(tilt) * h, math.sin(tilt) * b + math.cos(tilt) * h))
    scene.set_contact(friction=0.8)
    result = run(scene, 1.0)
    assert result.model == "housner"
    assert result.angle("block")[0] == pytest.approx(tilt) and np.allclose(result.position("block")[0],
                                                                            scene.body("block").q0[:2])
    alpha, p = math.atan2(b, h), math.sqrt(0.75 * G / math.hypot(b, h))
    # nonlinear free rocking: t = int_0^tilt dphi / sqrt(2 p^2 (cos(alpha - phi) - cos(alpha - tilt)))
    from scipy.integrate import quad
    t1 = quad(lambda u: 2 * u / math.sqrt(4 * p * p * math.sin(alpha - tilt + u * u / 2) * math.sin(u * u / 2)),
              0.0, math.sqrt(tilt), epsabs=1e-12)[0]
    assert result.impacts["time"][0] == pytest.approx(t1, rel=1e-7)


def test_stack_whose_joint_cannot_hold_gets_the_engine():
    scene = lnec.stacked_pair_2d(OneSine(3.0, omega=30.0))
    scene.set_contact(0.1, between=(scene.body("bottom"), scene.body("top")))
    choice = choose_model(scene)
    assert choice.kind == "2d" and "'bottom' and 'top' < 0.1954" in choice.reasons[0]


# -- the base shaking out of the plane ------------------------------------------------------------
# A one-sine pulse at 30 deg out of the plane, its in-plane component A cos(beta) = 1.73 m/s^2 below the
# onset g tan(alpha) = 3.27 m/s^2: the block stands still in the plane, so its normal force is m g
# and its centroid stays at h = HEIGHT / 2 above the base. The out-of-plane overturning demand is
# then Housner's static ratio |a_z| h / (g b_z) (seed 000 lines 492-495 across the plane) and the
# friction demand that of the resultant horizontal acceleration, |a| / g.
A_OOP, BETA, OMEGA_OOP = 2.0, math.radians(30.0), 6.1


def out_of_plane_scene(depth):
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), motion=OneSine(A_OOP, omega=OMEGA_OOP),
                   out_of_plane_angle=BETA, name="base")
    scene.add_block(nscd.box(WIDTH, HEIGHT), position=(0.0, HEIGHT / 2), density=2500.0, name="block",
                    depth=depth)
    scene.set_contact(friction=0.8)
    return scene


def test_block_thin_in_depth_is_flagged_out_of_plane():
    scene = out_of_plane_scene(depth=0.1)           # tips across the plane at g 0.05 / 0.75 = 0.654 m/s^2
    choice = choose_model(scene)
    assert choice.kind == "3d" and "rock out of plane" in choice.reasons[0] and "0.6538" in choice.reasons[0]
    with pytest.warns(AssumptionWarning):
        result = run(scene, 2.0, model="housner")
    assert float(np.max(np.abs(result.angle("block")))) == 0.0   # no rocking in the plane
    bad = {c.name: c for c in result.violations}
    assert set(bad) == {"no rocking out of the plane at the base"}
    demand = A_OOP * math.sin(BETA) * (HEIGHT / 2) / (G * 0.05)      # 1.53 at the pulse's peaks
    # sampled every 1 ms: the sampled peak of |sin| is within (omega 0.5 ms)^2 / 2 = 5e-6 of 1
    assert 1.0 - bad["no rocking out of the plane at the base"].margin == pytest.approx(demand, rel=1e-5)
    t_worst = bad["no rocking out of the plane at the base"].worst_time
    assert min(abs(t_worst - k * math.pi / (2 * OMEGA_OOP)) for k in (1, 3)) <= 1e-3
    friction = next(c for c in result.checks if c.name == "no sliding at the base")
    assert friction.ok and 0.8 - friction.margin == pytest.approx(A_OOP / G, rel=1e-5)  # resultant |a| / g


def test_block_deep_in_depth_stays_planar():
    scene = out_of_plane_scene(depth=1.0)           # tips across the plane only at 6.54 m/s^2
    choice = choose_model(scene)
    assert choice.kind == "housner" and any("out-of-plane" in r for r in choice.reasons)
    result = run(scene, 2.0)
    assert not result.violations
    oop = next(c for c in result.checks if c.name == "no rocking out of the plane at the base")
    assert oop.margin == pytest.approx(1.0 - A_OOP * math.sin(BETA) * (HEIGHT / 2) / (G * 0.5), rel=1e-5)


def test_out_of_plane_motion_without_depth_gets_the_3d_engine():
    choice = choose_model(out_of_plane_scene(depth=None))
    assert choice.kind == "3d" and "has no depth" in choice.reasons[0]
    with pytest.warns(AssumptionWarning, match="not simulated"):
        run(out_of_plane_scene(depth=1.0), 0.01, 1e-3, model="2d")


def test_stack_shaken_out_of_plane_checks_both_interfaces():
    """Two blocks standing still in the plane: base demand |a_z| sum(m y) / (M g b_z1), joint |a_z| h2 / (g b_zc)."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1), motion=OneSine(A_OOP, omega=OMEGA_OOP),
                   out_of_plane_angle=BETA, name="base")
    scene.add_block(nscd.box(0.6, 1.0), position=(0.0, 0.5), density=2500.0, name="bottom", depth=0.8)
    scene.add_block(nscd.box(0.3, 0.6), position=(0.0, 1.3), density=2500.0, name="top", depth=0.3)
    scene.set_contact(friction=0.8)
    assert choose_model(scene).kind == "stacked"
    result = run(scene, 1.5)
    assert np.max(np.abs(result.angle("bottom"))) == 0.0 == np.max(np.abs(result.angle("top")))
    checks = {c.name: c for c in result.checks}
    az = A_OOP * math.sin(BETA)
    m1, m2 = 0.6 * 1.0 * 2500.0, 0.3 * 0.6 * 2500.0      # per unit depth: only ratios matter
    base = az * (m1 * 0.5 + m2 * 1.3) / ((m1 + m2) * G * 0.4)
    joint = az * 0.3 / (G * 0.15)                        # the contact is the top block's depth, 0.3 m
    assert 1.0 - checks["no rocking out of the plane at the base"].margin == pytest.approx(base, rel=1e-5)
    assert 1.0 - checks["no rocking out of the plane at the joint"].margin == pytest.approx(joint, rel=1e-5)


def test_out_of_plane_scene_input_and_extrusion():
    scene = out_of_plane_scene(depth=0.1)
    with pytest.raises(ValueError, match="out_of_plane_angle == 2.0, must be in"):
        nscd.Scene().add_base(nscd.box(1.0, 0.2), (0.0, 0.0), motion=OneSine(1.0, omega=1.0), out_of_plane_angle=2.0)
    with pytest.raises(ValueError, match="without a motion"):
        nscd.Scene().add_base(nscd.box(1.0, 0.2), (0.0, 0.0), out_of_plane_angle=0.3)
    with pytest.raises(ValueError, match="is for 2D scenes"):
        nscd.Scene(dim=3).add_base(nscd.box(1.0, 1.0, 0.2), (0.0, 0.0, 0.0), motion=OneSine(1.0, omega=1.0),
                                   out_of_plane_angle=0.3)
    with pytest.raises(ValueError, match="depth == -1.0, must be > 0 m"):
        nscd.Scene().add_block(nscd.box(1.0, 1.0), (0.0, 0.5), depth=-1.0)
    solid = nscd.choose.extrude(scene)
    base, block = solid.body("base"), solid.body("block")
    np.testing.assert_allclose(base.direction, (math.cos(BETA), math.sin(BETA), 0.0), rtol=1e-15)
    np.testing.assert_allclose(np.ptp(block.shape.vertices, axis=0), (WIDTH, 0.1, HEIGHT), rtol=1e-12)


def test_3d_engine_rocks_the_thin_block_out_of_plane_and_not_the_deep_one():
    """What the check flags, the extruded scene shows: the thin block lifts an edge across the plane after
    the instant the out-of-plane acceleration passes g b_z / h (Housner's onset across the plane), the
    deep one never tilts."""
    t_star = math.asin(G * 0.05 / (HEIGHT / 2) / (A_OOP * math.sin(BETA))) / OMEGA_OOP   # 0.117 s
    tilts = {}
    for depth in (0.1, 1.0):
        result = run(out_of_plane_scene(depth), 0.4, 1e-3, model="3d", settings=nscd.Settings(scheme="midpoint"))
        assert result.model == "3d" and result.success
        tilts[depth] = (result.time, result.rotation("block"))
    time, thin = tilts[0.1]
    assert np.max(thin[time < t_star]) < 1e-6                 # resting until the onset (solver tolerance)
    assert np.max(thin) > 5e-3                                  # 0.3 deg by 0.4 s: rocking across the plane
    assert np.max(tilts[1.0][1]) < 1e-6
