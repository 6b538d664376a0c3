"""Tests of the 1-DOF Housner model (nscd.rocking) against theory and seed 000 / 003."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp

from nscd.motion import OneCosine, OneSine
from nscd.rocking import OVERTURN_ANGLE, ElasticBrittle, ElastoPlastic, HousnerBlock, housner_eta, required_friction


# --------------------------------------------------------------------------- construction
def test_geometry_of_a_block_from_width_and_height():
    blk = HousnerBlock(width=0.5, height=1.5)
    b, h = 0.25, 0.75
    assert blk.alpha == pytest.approx(math.atan(b / h), rel=1e-15)
    assert blk.R == pytest.approx(math.hypot(b, h), rel=1e-15)
    assert blk.p == pytest.approx(math.sqrt(3 * blk.g / (4 * blk.R)), rel=1e-15)
    assert blk.eta == pytest.approx(1 - 1.5 * math.sin(blk.alpha) ** 2, rel=1e-15)


def test_constructors_round_trip():
    a = HousnerBlock.from_alpha_p(alpha=0.25, p=2.14, eta=0.9, linear=True)
    assert (a.alpha, a.p, a.eta, a.linear) == (pytest.approx(0.25, rel=1e-14), pytest.approx(2.14, rel=1e-14), 0.9, True)
    b = HousnerBlock.from_alpha_R(alpha=0.2, R=3.0)
    assert (b.alpha, b.R) == (pytest.approx(0.2, rel=1e-14), pytest.approx(3.0, rel=1e-14))


@pytest.mark.parametrize("degrees, printed", [(15, 0.90), (20, 0.825), (25, 0.732)])
def test_housner_eta_max(degrees, printed):
    # seed 000 quotes eta = r_max = 0.90, 0.825 (fig. 9) and 0.732: agreement to the printed digits
    digits = len(str(printed).split(".")[1])
    assert round(housner_eta(math.radians(degrees)), digits) == printed


@pytest.mark.parametrize("kwargs", [dict(eta=0.0), dict(eta=1.2), dict(eta=-0.5), dict(width=0.0), dict(height=-1.0)])
def test_bad_block_raises(kwargs):
    args = dict(width=0.5, height=1.5) | kwargs
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        HousnerBlock(**args)


@pytest.mark.parametrize("alpha", [0.0, -0.1, math.pi / 2, 2.0])
def test_bad_alpha_raises(alpha):
    with pytest.raises(ValueError, match="alpha"):
        HousnerBlock.from_alpha_p(alpha=alpha, p=2.0)


def test_eta_above_housner_warns():
    with pytest.warns(UserWarning, match="Housner"):
        HousnerBlock(width=0.5, height=1.5, eta=0.95)


# --------------------------------------------------------------------------- free rocking
@pytest.mark.parametrize("linear", [True, False])
def test_restitution_and_energy_per_impact(linear):
    """Each impact multiplies theta_dot by eta; between impacts energy is conserved,
    so the amplitudes follow V(theta_n) - V(0) = eta^2 (V(theta_{n-1}) - V(0))."""
    blk = HousnerBlock.from_alpha_p(alpha=0.2, p=2.0, eta=0.85, linear=linear)
    r = blk.simulate(None, t_end=6.0, theta0=0.15)
    imp = r.impacts
    assert len(imp) >= 4
    np.testing.assert_allclose(imp.theta_dot_after / imp.theta_dot_before, 0.85, rtol=1e-14)
    # |theta_dot| before impact n+1 equals |theta_dot| after impact n (energy conserved in flight);
    # 1e-8: integrator tolerance rtol 1e-10 accumulated over a flight
    np.testing.assert_allclose(np.abs(imp.theta_dot_before[1:]), np.abs(imp.theta_dot_after[:-1]), rtol=1e-8)
    # velocity at the first impact from energy: theta_dot^2 / (2 p^2) = V(theta0) - V(0)
    v0 = math.sqrt(2 * blk.p**2 * (blk.potential(0.15) - blk.potential(0.0)))
    assert abs(imp.theta_dot_before[0]) == pytest.approx(v0, rel=1e-8)


def test_time_to_first_impact_linear_closed_form():
    # Housner: released from theta0 the linear block lands at (1/p) arccosh(1/(1 - theta0/alpha));
    # 1e-6: the closed-form flight is exact up to root finding at 1e-15 s
    for alpha, p, theta0 in [(0.25, 2.14, 0.1), (0.1, 4.0, 0.09), (0.3, 1.5, 0.01)]:
        blk = HousnerBlock.from_alpha_p(alpha=alpha, p=p, eta=0.85, linear=True)
        r = blk.simulate(None, t_end=5.0, theta0=theta0)
        expected = math.acosh(1.0 / (1.0 - theta0 / alpha)) / p
        assert r.impacts.time[0] == pytest.approx(expected, rel=1e-6)


def test_time_to_first_impact_nonlinear_quadrature():
    # energy conservation (cf. seed 003 eq. 3.6): released from theta0 the block lands after
    # t = 1/(p sqrt 2) int_0^theta0 dx / sqrt(cos(alpha - theta0) - cos(alpha - x));
    # with x = theta0 - u^2 the integrand is smooth. 1e-6: solve_ivp at rtol 1e-10, quadrature to 1e-12
    alpha, p, theta0 = 0.25, 2.14, 0.15
    blk = HousnerBlock.from_alpha_p(alpha=alpha, p=p, eta=0.9)
    r = blk.simulate(None, t_end=5.0, theta0=theta0)
    c0 = math.cos(alpha - theta0)
    integral, _ = quad(lambda u: 2 * u / math.sqrt(c0 - math.cos(alpha - theta0 + u * u)) if u > 0
                       else 2 / math.sqrt(math.sin(alpha - theta0)), 0.0, math.sqrt(theta0),
                       epsabs=1e-13, epsrel=1e-12, limit=200)
    assert r.impacts.time[0] == pytest.approx(integral / (p * math.sqrt(2.0)), rel=1e-6)


def test_nonlinear_close_to_linear_for_small_alpha():
    # For alpha = 0.02 the linearisation errors are O(alpha^2) ~ 4e-4: 2e-3 relative
    alpha, p, theta0 = 0.02, 3.0, 0.01
    lin = HousnerBlock.from_alpha_p(alpha, p, eta=0.9, linear=True).simulate(None, 2.0, theta0=theta0)
    non = HousnerBlock.from_alpha_p(alpha, p, eta=0.9).simulate(None, 2.0, theta0=theta0)
    assert non.impacts.time[0] == pytest.approx(lin.impacts.time[0], rel=2e-3)


def test_free_rocking_comes_to_rest():
    blk = HousnerBlock.from_alpha_p(alpha=0.2, p=2.0, eta=0.7)
    r = blk.simulate(None, t_end=30.0, theta0=0.1)
    assert not r.overturned and r.mode is None
    assert r.theta[-1] == 0.0 and r.theta_dot[-1] == 0.0


def test_free_overturning_beyond_alpha():
    blk = HousnerBlock.from_alpha_p(alpha=0.2, p=2.0)
    r = blk.simulate(None, t_end=5.0, theta0=0.21)
    assert r.overturned and r.mode == "mode 2"
    assert abs(r.theta[-1]) == pytest.approx(OVERTURN_ANGLE, rel=1e-9)  # the history ends at overturning


# --------------------------------------------------------------------------- onset
@pytest.mark.parametrize("linear", [True, False])
def test_onset_threshold_and_direction(linear):
    blk = HousnerBlock.from_alpha_p(alpha=0.2, p=2.0, linear=linear)
    w = 10.0
    below = blk.simulate(OneSine(0.999 * blk.onset_acceleration, w), t_end=2.0)
    assert not below.uplifted and np.all(below.theta == 0.0)
    above = blk.simulate(OneSine(1.2 * blk.onset_acceleration, w), t_end=2.0)
    assert above.uplifted
    moving = above.theta[np.abs(above.theta) > 0]
    assert moving[0] < 0.0  # a positive ground acceleration starts a negative rotation
    # onset time: a(t) = A sin(w t) reaches the threshold at asin(1/1.2)/w
    first = above.time[np.nonzero(above.theta)[0][0] - 1]
    assert first == pytest.approx(math.asin(1 / 1.2) / w, rel=1e-6)  # 1e-6: brentq on the scan grid


def test_vertical_acceleration_raises_the_threshold():
    blk = HousnerBlock.from_alpha_p(alpha=0.2, p=2.0)
    w = 10.0
    a = 1.1 * blk.onset_acceleration
    # upward ground acceleration of 0.2 g during the pulse: threshold 1.2 g tan(alpha) > a
    up = OneCosine(0.2 * blk.g, w / 4.0)  # stays >= 0 over the first quarter period of the sine
    r = blk.simulate(OneSine(a, w), t_end=math.pi / (2 * w), vertical=up)
    assert not r.uplifted
    assert blk.simulate(OneSine(a, w), t_end=math.pi / (2 * w)).uplifted


# --------------------------------------------------------------------------- closed form vs integration
def test_linear_closed_form_matches_direct_integration():
    """The exact flights of the linear model against solve_ivp on eq. 2-44 written here."""
    blk = HousnerBlock.from_alpha_p(alpha=0.25, p=2.14, eta=0.9, linear=True)
    A, w = 1.5 * 0.25 * blk.g, 3.0 * 2.14  # lands during the pulse (t = 0.69 s < 0.98 s)
    r = blk.simulate(OneSine(A, w), t_end=3.0)
    t_on = math.asin(0.25 * blk.g / A) / w
    p, alpha, g = blk.p, blk.alpha, blk.g

    def rhs(t, y, side):
        ag = A * math.sin(w * t) if t <= 2 * math.pi / w else 0.0
        return [y[1], p**2 * (y[0] - side * alpha - ag / g)]

    def land(t, y, side):
        return side * y[0]
    land.terminal, land.direction = True, -1
    sol = solve_ivp(rhs, (t_on, 2 * math.pi / w), [0.0, 0.0], args=(-1,), events=land,
                    rtol=1e-12, atol=1e-14, method="DOP853")
    # first impact time and velocity: 1e-6 relative (both solutions accurate to ~1e-10)
    assert r.impacts.time[0] == pytest.approx(sol.t_events[0][0], rel=1e-6)
    assert r.impacts.theta_dot_before[0] == pytest.approx(sol.y_events[0][0][1], rel=1e-6)


# --------------------------------------------------------------------------- friction
def test_required_friction_reduces_to_tan_alpha():
    # seed 000 eq. 2-8: a pulse building up gradually needs mu >= tan(alpha)
    assert required_friction(0.25, 9.81 * math.tan(0.25), g=9.81) == pytest.approx(math.tan(0.25), rel=1e-14)


def test_required_friction_one_cosine_slender_limit():
    # seed 000 eq. 2-46 (slender approximation of 2-45): alpha (3/4 + x/4) / (1 + 3/4 alpha^2 (x - 1));
    # at alpha = 0.02 the approximation errors are O(alpha^2): 1e-3 relative
    alpha, x = 0.02, 6.0
    approx = alpha * (0.75 + 0.25 * x) / (1 + 0.75 * alpha**2 * (x - 1))
    assert required_friction(alpha, x * alpha * 9.81, g=9.81) == pytest.approx(approx, rel=1e-3)


def test_figure_10_magnification_two_for_alpha_025():
    # seed 000 fig. 10 text: alpha = 0.25, one-cosine a_p/(alpha g) ~ 6 needs mu about 2 tan(alpha); 10 %: read off a figure
    mu = required_friction(0.25, 6 * 0.25 * 9.81, g=9.81)
    assert mu / math.tan(0.25) == pytest.approx(2.0, rel=0.1)


def test_check_sliding_warns():
    blk = HousnerBlock.from_alpha_p(alpha=0.25, p=2.14)
    pulse = OneCosine(6 * 0.25 * blk.g, 3 * 2.14)
    with pytest.warns(UserWarning, match="slides"):
        needed = blk.check_sliding(0.3, pulse)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert blk.check_sliding(needed * 1.01, pulse) == pytest.approx(needed)


# --------------------------------------------------------------------------- anchorages
def test_anchorage_validation():
    with pytest.raises(ValueError, match="strength"):
        ElasticBrittle(strength=0.0, influence=1e-3)
    with pytest.raises(ValueError, match="ductility"):
        ElastoPlastic(strength=0.4, influence=1e-3, ductility=0.5)


@pytest.mark.parametrize("q, alpha_deg, printed", [
    (6.4e-4, 18.43, 1.33e-3), (3.2e-4, 34.61, 3.82e-4), (4.1e-4, 23.12, 6.97e-4), (4.9e-4, 32.91, 6.02e-4),
])
def test_theta_y_from_table_2(q, alpha_deg, printed):
    # seed 000 Table 2: theta_y = 2 q / (3 sin alpha); 2 %: q is printed with two digits
    # (the first row of the table, q = 1.8e-4 at 23.2 deg, is not consistent with its theta_y and is left out)
    assert ElasticBrittle(0.4, q).theta_y(math.radians(alpha_deg)) == pytest.approx(printed, rel=0.02)


# --------------------------------------------------------------------------- contact force
def test_contact_force_at_rest_is_the_weight_and_inertia():
    """At rest the base carries F = m (a_g, g + a_v) (static balance); the centroid stands h above it."""
    blk, m = HousnerBlock(0.5, 1.5), 300.0
    ag, av = np.array([1.5, -2.0]), np.array([0.5, -1.0])
    fx, fy, height = blk.contact_forces(m, np.zeros(2), np.zeros(2), ag, av)
    # three roundings of a sum of O(1) terms: 1e-14 relative
    np.testing.assert_allclose(fx, m * ag, rtol=1e-14)
    np.testing.assert_allclose(fy, m * (blk.g + av), rtol=1e-14)
    np.testing.assert_allclose(height, blk.h, rtol=1e-14)


@pytest.mark.parametrize("theta, theta_dot, ag, av", [(0.1, -0.3, 2.0, 0.5), (-0.05, 0.4, -1.0, 0.0),
                                                      (0.0, 0.7, 3.0, -1.5), (-0.2, -0.1, 0.0, 2.0)])
def test_contact_force_turns_the_block_about_its_centroid(theta, theta_dot, ag, av):
    """The force from Newton's law for the centroid, applied at the pivot, gives Euler's law about the centroid.

    ``(pivot - c) x F = I_G phi''`` with ``I_G = m (b^2 + h^2) / 3`` (a rectangle) and ``phi = -theta``,
    ``theta''`` from 000 eq. 2-11 written out here (the pivot side is sgn(theta), sgn(theta') at 0):
    the translational and rotational equations of one rigid body agree.
    """
    blk, m = HousnerBlock(0.5, 1.5), 300.0
    b, h, g, alpha = blk.b, blk.h, blk.g, blk.alpha
    side = math.copysign(1.0, theta if theta != 0.0 else theta_dot)
    p2 = 3.0 * g / (4.0 * math.hypot(b, h))
    theta_ddot = -p2 * (math.sin(side * alpha - theta) * (1.0 + av / g) + ag / g * math.cos(side * alpha - theta))
    fx, fy, height = (float(v[0]) for v in blk.contact_forces(m, [theta], [theta_dot], [ag], [av]))
    phi, k = -theta, -side                                   # the engine's angle and pivot side
    cx = math.cos(phi) * k * b - math.sin(phi) * h            # centroid from the pivot
    cy = math.sin(phi) * k * b + math.cos(phi) * h
    moment = -cx * fy + cy * fx                               # (pivot - centroid) x F
    # forces of order m g = 3e3 N on arms of 1 m: 1e-9 relative to the moment m g R
    assert moment == pytest.approx(m * (b * b + h * h) / 3.0 * -theta_ddot, abs=1e-9 * m * g * math.hypot(b, h))
    assert height == pytest.approx(cy, rel=1e-14)
