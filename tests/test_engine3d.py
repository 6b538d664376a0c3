"""Validation of the engine in 3D against theory, and the LNEC scenes of 003.

Oracles: Housner's restitution eta = 1 - 1.5 sin^2(alpha) and the exact free-rocking
quarter period (quadrature of the energy equation) for a box rocking in a plane;
isotropic Coulomb sliding (straight path, stop at v0^2 / (2 mu g), no lift-off);
torsional stop time omega0 I_z / M with M = mu sum N_i r_i over the contact points;
rest of the LNEC trilith and stacked pair (no creep); Table 2 of 003.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad

import nscd
from nscd import lnec
from nscd.contact.detect3d import collide_polyhedra
from nscd.motion import STANDARD_GRAVITY as G
from nscd.shapes3d import box3


def _quat_y(angle: float) -> tuple[float, float, float, float]:
    """Unit quaternion (w, x, y, z) of a rotation by ``angle`` rad about +y."""
    return (math.cos(angle / 2), 0.0, math.sin(angle / 2), 0.0)


def _pitch(quat: np.ndarray) -> np.ndarray:
    """Signed rotation about +y (rad) of orientations (n, 4) that only pitch about y."""
    w, x, y, z = quat.T
    return np.arctan2(2 * (x * z + w * y), 1 - 2 * (x * x + y * y))


# -- Table 2 of 003 --------------------------------------------------------------------

@pytest.mark.parametrize("name", ["single1", "single2", "single3", "stacked_top", "stacked_bottom",
                                  "trilith_column", "trilith_lintel"])
def test_lnec_masses_match_table_2(name):
    stone = lnec.SPECIMENS[name]
    shape = box3(stone.width, stone.thickness, stone.height)
    # Table 2 gives masses to 3 significant figures of sawn stones: 2 %
    assert shape.mass(lnec.GRANITE_DENSITY) == pytest.approx(stone.mass, rel=0.02)


@pytest.mark.parametrize("name", ["single1", "single2", "single3", "stacked_top"])
def test_lnec_inertias_match_table_2(name):
    stone = lnec.SPECIMENS[name]
    shape = box3(stone.width, stone.thickness, stone.height)
    m = stone.mass
    inertia = shape.inertia(lnec.GRANITE_DENSITY) * m / shape.mass(lnec.GRANITE_DENSITY)
    b, h = stone.width / 2, stone.height / 2
    # I_o: about the base edge along y (parallel axes); J_o: about the vertical axis
    i_pivot = inertia[1, 1] + m * (b * b + h * h)
    # published to 2-3 significant figures: 4 %
    assert i_pivot == pytest.approx(stone.inertia_pivot, rel=0.04)
    assert inertia[2, 2] == pytest.approx(stone.inertia_torsion, rel=0.04)


@pytest.mark.parametrize("build", [lambda: lnec.single(1), lnec.stacked_pair, lnec.trilith])
def test_lnec_scenes_touch_without_gaps(build):
    scene = build()
    placed = {b.name: b.shape.place(b.q0[:3], np.eye(3)) for b in scene.bodies}
    pairs = {"base": ("block",), "bottom": ("top",), "left": ("lintel",), "right": ("lintel",)}
    pairs["base"] += ("bottom", "left", "right")
    touching = 0
    for lower, uppers in pairs.items():
        for upper in uppers:
            if lower in placed and upper in placed:
                m = collide_polyhedra(placed[lower], placed[upper], 1e-6)
                np.testing.assert_allclose(m.gaps, 0.0, atol=1e-12)
                np.testing.assert_allclose(m.normal, [0, 0, 1], atol=1e-12)
                touching += 1
    assert touching == {1: 1, 2: 2, 3: 4}[len(scene.dynamic_bodies)]


def test_lnec_rejects_bad_input():
    with pytest.raises(ValueError, match="number == 5"):
        lnec.single(5)
    with pytest.raises(ValueError, match="span == 0.1"):
        lnec.trilith(span=0.1)


# -- planar rocking of a 3D box ------------------------------------------------------------

def _rocking_scene(stone: lnec.Specimen, theta0: float):
    """The stone released from rest, pitched by theta0 about its +x bottom edge."""
    b, h = stone.width / 2, stone.height / 2
    scene = nscd.Scene(dim=3)
    scene.add_base(box3(3.0, 3.0, 0.2), position=(0.0, 0.0, -0.1))
    c, s = math.cos(theta0), math.sin(theta0)
    centre = (b - b * c + h * s, 0.0, b * s + h * c)     # pivot (b, 0, 0) + R_y (-b, 0, h)
    block = scene.add_block(box3(stone.width, stone.thickness, stone.height), position=centre,
                            orientation=_quat_y(theta0), density=lnec.GRANITE_DENSITY)
    # friction high enough that the corner never slips at impact: pure rocking
    scene.set_contact(friction=2.0, restitution=0.0)
    return scene, block


def _quarter_period(alpha: float, theta0: float, p: float) -> float:
    """Exact time from release at theta0 (rest) to the first impact, nonlinear Housner.

    theta_dot^2 = 2 p^2 (cos(alpha - theta0) - cos(alpha - theta)); with
    theta = theta0 - s^2 the endpoint singularity of dt = dtheta / |theta_dot| goes away.
    """
    def integrand(s):
        theta = theta0 - s * s
        rate2 = 2 * p * p * (math.cos(alpha - theta0) - math.cos(alpha - theta))
        if rate2 <= 0.0:
            return 2.0 / math.sqrt(2 * p * p * math.sin(alpha - theta0))
        return 2 * s / math.sqrt(rate2)
    return quad(integrand, 0.0, math.sqrt(theta0), epsabs=1e-13, epsrel=1e-12, limit=200)[0]


def _rocking_run(name: str, dt: float, n_impacts: int, scheme: str = "theta"):
    """Errors of the first impact time and of the first restitutions of a released stone.

    The restitution of each impact comes from the amplitudes on either side of it
    (energy is conserved between impacts: theta_dot^2 at theta = 0 is
    2 p^2 (cos(alpha - A) - cos alpha)) and is compared with 1 - 1.5 sin^2 alpha.
    """
    stone = lnec.SPECIMENS[name]
    b, h = stone.width / 2, stone.height / 2
    alpha, big_r = math.atan2(b, h), math.hypot(b, h)
    p = math.sqrt(3 * G / (4 * big_r))
    theta0 = 0.5 * alpha
    t_first = _quarter_period(alpha, theta0, p)
    scene, block = _rocking_scene(stone, theta0)
    res = nscd.simulate(scene, t_end=(2 * n_impacts + 0.5) * t_first, dt=dt,
                        settings=nscd.Settings(scheme=scheme))
    assert res.success, res.message
    # the motion stays in the x-z plane
    assert np.max(np.abs(res.position(block)[:, 1])) < 1e-9
    assert np.max(np.abs(res.omega(block)[:, [0, 2]])) < 1e-9
    a = np.abs(_pitch(res.orientation(block)))
    peaks = a[1:-1][(a[1:-1] > a[:-2]) & (a[1:-1] >= a[2:])]
    amps = np.concatenate([[theta0], peaks])
    assert len(amps) > n_impacts
    eta = 1 - 1.5 * math.sin(alpha) ** 2
    ratios = np.sqrt((np.cos(alpha - amps[1:]) - math.cos(alpha))
                     / (np.cos(alpha - amps[:-1]) - math.cos(alpha)))
    return res.impacts["time"][0] / t_first - 1, ratios[:n_impacts] / eta - 1


def test_planar_rocking_first_impact_matches_housner():
    time_error, eta_error = _rocking_run("single1", 1e-3, 1)
    # Moreau-Jean closes the gap within one step (1e-3 s on 0.38 s) and conserves the
    # angular momentum about the landing edge: 0.5 % on both, as asked
    assert abs(time_error) < 0.005
    assert abs(eta_error[0]) < 0.005


@pytest.mark.slow
@pytest.mark.parametrize("name", ["single1", "single2"])
def test_planar_rocking_three_impacts_converge(name):
    # Later impacts fall anywhere inside a step: at dt = 1e-3 s the second restitution
    # is off by 0.4 % (single 1) and 1.5 % (single 2); the error is first order in dt
    # at worst, so a four times smaller step brings all three within 0.5 %.
    time_error, eta_error = _rocking_run(name, 2.5e-4, 3)
    assert abs(time_error) < 0.005
    assert np.all(np.abs(eta_error) < 0.005), eta_error


@pytest.mark.parametrize("name", ["single1", "single2"])
def test_planar_rocking_midpoint_rule_three_impacts_at_dt_3e3(name):
    # Moreau's midpoint rule (second order between impacts, impacts localised): measured
    # 0.002-0.003 % on the first three restitutions and 1e-6 on the first impact time at
    # dt = 3e-3 s, where the theta scheme is off by 0.4-1.5 % at dt = 1e-3. The bound, 0.05 %,
    # is the 0.5 % accuracy target with a tenfold margin kept for the solver tolerance.
    time_error, eta_error = _rocking_run(name, 3e-3, 3, scheme="midpoint")
    assert abs(time_error) < 5e-4
    assert np.all(np.abs(eta_error) < 5e-4), eta_error


# -- isotropic Coulomb sliding -------------------------------------------------------------

@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
def test_sliding_off_the_faces_is_isotropic_and_stops_at_coulomb_distance(scheme):
    v0, mu, heading = 1.0, 0.3, math.radians(30.0)
    scene = nscd.Scene(dim=3)
    scene.add_base(box3(20.0, 20.0, 0.2), position=(0.0, 0.0, -0.1))
    block = scene.add_block(box3(0.4, 0.4, 0.2), position=(0.0, 0.0, 0.1), density=2000.0,
                            velocity=(v0 * math.cos(heading), v0 * math.sin(heading), 0.0))
    scene.set_contact(friction=mu, restitution=0.0)
    res = nscd.simulate(scene, t_end=0.5, dt=1e-3, settings=nscd.Settings(scheme=scheme))
    assert res.success, res.message
    path = res.position(block) - res.position(block)[0]
    travelled = np.linalg.norm(path[-1, :2])
    # the deceleration mu g is exact in the scheme; the stop falls within one step: 0.5 %
    assert travelled == pytest.approx(v0**2 / (2 * mu * G), rel=0.005)
    # isotropic cone: the path keeps its heading (the box's faces are along x and y)
    moving = np.linalg.norm(path[:, :2], axis=1) > 1e-3
    headings = np.arctan2(path[moving, 1], path[moving, 0])
    assert np.max(np.abs(headings - heading)) < 1e-3
    # exact Coulomb: no lift-off while sliding, no spin
    assert np.max(np.abs(path[:, 2])) < 1e-6
    assert np.max(np.abs(res.omega(block))) < 1e-6


# -- torsion -----------------------------------------------------------------------------

@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
def test_torsion_stops_at_the_friction_moment_time(scheme):
    omega0, mu = 10.0, 0.3
    w, d, hgt, rho = 0.4, 0.3, 0.2, 2000.0
    scene = nscd.Scene(dim=3)
    scene.add_base(box3(4.0, 4.0, 0.2), position=(0.0, 0.0, -0.1))
    block = scene.add_block(box3(w, d, hgt), position=(0.0, 0.0, hgt / 2), density=rho,
                            omega=(0.0, 0.0, omega0))
    scene.set_contact(friction=mu, restitution=0.0)
    dt = 1e-3
    res = nscd.simulate(scene, t_end=0.4, dt=dt, store_impulses=True, settings=nscd.Settings(scheme=scheme))
    assert res.success, res.message
    # friction moment from the engine's own contact points and normal impulses (step 1)
    first = res.contacts[0]
    centre = res.position(block)[0]
    lever = np.linalg.norm((first["point"] - centre)[:, :2], axis=1)
    moment = mu * np.sum(first["impulse"][:, 0] * lever) / dt
    # those points are the four corners, each carrying a quarter of the weight
    mass = w * d * hgt * rho
    assert moment == pytest.approx(mu * mass * G * math.hypot(w / 2, d / 2), rel=1e-6)
    i_z = mass * (w * w + d * d) / 12
    t_stop = omega0 * i_z / moment
    spin = res.omega(block)[:, 2]
    t_engine = res.time[np.argmax(spin <= 1e-9)]
    # the stop falls within one step (1e-3 s on 0.28 s): 2 % as asked
    assert abs(t_engine - t_stop) / t_stop < 0.02
    # the centre does not wander (the corner forces cancel)
    assert np.max(np.abs(res.position(block) - centre)) < 1e-6


# -- rest ----------------------------------------------------------------------------------

def _assert_at_rest(scene, t_end: float, scheme: str = "midpoint") -> None:
    res = nscd.simulate(scene, t_end=t_end, dt=1e-3, settings=nscd.Settings(scheme=scheme))
    assert res.success, res.message
    for body in scene.dynamic_bodies:
        drift = np.linalg.norm(res.position(body) - res.position(body)[0], axis=1)
        assert drift.max() < 1e-6, body.name
        assert res.rotation(body).max() < 1e-6, body.name


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
@pytest.mark.parametrize("build", [lnec.stacked_pair, lnec.trilith])
def test_lnec_assemblies_rest_1s(build, scheme):
    _assert_at_rest(build(), 1.0, scheme)


@pytest.mark.slow
@pytest.mark.parametrize("build", [lnec.stacked_pair, lnec.trilith])
def test_lnec_assemblies_rest_10s(build):
    _assert_at_rest(build(), 10.0)
