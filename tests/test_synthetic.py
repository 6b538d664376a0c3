"""Tests of nscd.synthetic: SDOF closed forms, EC8 formulas, spectrum-compatible records."""
from __future__ import annotations

import math

import numpy as np
import pytest

from nscd.motion import STANDARD_GRAVITY, Record, elcentro
from nscd.synthetic import (ec8_spectrum, response_spectrum, sdof_response,
                            spectrum_compatible_records)


def step_response(a0, period, zeta, t):
    """u(t) from rest under a_g = a0 (constant from t = 0): u'' + 2 z w u' + w^2 u = -a0."""
    w = 2 * math.pi / period
    wd = w * math.sqrt(1 - zeta**2)
    decay = np.exp(-zeta * w * t)
    u = -a0 / w**2 * (1 - decay * (np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t)))
    v = -a0 / w**2 * decay * (w**2 / wd) * np.sin(wd * t)
    return u, v


def harmonic_response(A, Omega, period, zeta, t):
    """u(t) from rest under a_g = A sin(Omega t): steady state plus the free transient."""
    w = 2 * math.pi / period
    wd = w * math.sqrt(1 - zeta**2)
    # particular solution C sin + D cos of u'' + 2 z w u' + w^2 u = -A sin(Omega t)
    C, D = np.linalg.solve([[w**2 - Omega**2, -2 * zeta * w * Omega],
                            [2 * zeta * w * Omega, w**2 - Omega**2]], [-A, 0.0])
    E = -D                                   # u(0) = 0
    F = (zeta * w * E - C * Omega) / wd      # u'(0) = 0
    return (C * np.sin(Omega * t) + D * np.cos(Omega * t)
            + np.exp(-zeta * w * t) * (E * np.cos(wd * t) + F * np.sin(wd * t)))


@pytest.mark.parametrize("zeta", [0.0, 0.05, 0.3])
@pytest.mark.parametrize("substeps", [1, 3])
def test_step_input_is_integrated_exactly(zeta, substeps):
    # a constant record is a step at t = 0, exactly piecewise linear: the recurrence
    # must reproduce the closed form to round-off, which accumulates over the up to
    # 3000 steps of the undamped filter to ~1e-11 of the peak
    a0, dt, period = 2.0, 0.01, 0.7
    t, u, v = sdof_response((np.full(1001, a0), dt), period, zeta, substeps=substeps)
    u_exact, v_exact = step_response(a0, period, zeta, t)
    np.testing.assert_allclose(u, u_exact, rtol=0, atol=1e-10 * np.max(np.abs(u_exact)))
    np.testing.assert_allclose(v, v_exact, rtol=0, atol=1e-10 * np.max(np.abs(v_exact)))


def test_harmonic_input_matches_transient_plus_steady_state_at_second_order():
    A, Omega, period, zeta, T = 1.5, 2 * math.pi * 1.3, 0.5, 0.05, 8.0
    errors = []
    for dt in (0.004, 0.002):
        t = np.arange(round(T / dt) + 1) * dt
        _, u, _ = sdof_response((A * np.sin(Omega * t), dt), period, zeta)
        exact = harmonic_response(A, Omega, period, zeta, t)
        errors.append(np.max(np.abs(u - exact)) / np.max(np.abs(exact)))
    # the only error is the linear interpolation of the sine input, O((Omega dt)^2 / 8)
    # ~ 1e-4 relative at dt = 0.004; halving dt must divide it by ~4
    assert errors[0] < 2e-4
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.05)


def test_spectrum_relations_and_limits():
    dt = 0.002
    t = np.arange(1001) * dt
    acc = 3.0 * np.sin(2 * math.pi * 1.0 * t) * np.sin(math.pi * t / t[-1])  # smooth, <= 1.5 Hz
    spec = response_spectrum((acc, dt), [0.005, 0.5, 1.0], 0.05)
    w = 2 * math.pi / spec.periods
    np.testing.assert_allclose(spec.Sv, w * spec.Sd, rtol=1e-15)
    np.testing.assert_allclose(spec.Sa, w**2 * spec.Sd, rtol=1e-15)
    # rigid limit: for T = 0.005 s << 1/1.5 Hz, Sa -> PGA with a quasi-static error
    # of order (f / f_n)^2 = (1.5 * 0.005)^2 < 1e-4 plus the 2 zeta f / f_n damping lag ~ 1e-3
    assert spec.Sa[0] == pytest.approx(np.max(np.abs(acc)), rel=2e-3)


def test_el_centro_spectrum_against_published_values():
    # Chopra, Dynamics of Structures, Fig. 6.4.1 (El Centro 1940 N-S, zeta = 2 %):
    # D = 5.97 in at Tn = 1 s and 7.47 in at Tn = 2 s (3 significant digits)
    spec = response_spectrum(elcentro(), [1.0, 2.0], 0.02, min_samples_per_period=200)
    np.testing.assert_allclose(spec.Sd / 0.0254, [5.97, 7.47], rtol=3e-3)


def test_response_spectrum_validation():
    rec = Record([0.0, 1.0, 0.0], 0.01, "m/s^2")
    with pytest.raises(ValueError, match="damping == 1.0"):
        response_spectrum(rec, [0.5], damping=1.0)
    with pytest.raises(ValueError, match="periods"):
        response_spectrum(rec, [0.5, -1.0])
    with pytest.raises(TypeError, match="record is a list"):
        response_spectrum([0.0, 1.0], [0.5])
    with pytest.raises(ValueError, match="period == 0.0"):
        sdof_response(rec, 0.0)


def test_ec8_spectrum_of_the_lnec_tests():
    # 003 line 77: plateau 0.1-0.3 s at 7 m/s^2 with PGA 2.8 m/s^2 -> S eta = 7 / (2.5 * 2.8) = 1
    T = np.array([0.0, 0.05, 0.1, 0.2, 0.3, 1.0, 2.0, 3.0])
    Se = ec8_spectrum(T, 2.8, ground_type="A", TB=0.1, TC=0.3)
    expected = [2.8, 2.8 * (1 + 0.5 * 1.5), 7.0, 7.0, 7.0, 7.0 * 0.3, 7.0 * 0.3 / 2.0,
                7.0 * 0.3 * 2.0 / 9.0]
    np.testing.assert_allclose(Se, expected, rtol=1e-14)


def test_ec8_spectrum_tables_and_damping():
    ag = 0.25
    # type 1, ground C: S = 1.15, TB = 0.2, TC = 0.6, TD = 2.0 (EN 1998-1 Table 3.2)
    Se = ec8_spectrum([0.0, 0.2, 0.6, 2.0, 4.0], ag, ground_type="C", unit="g")
    plateau = 2.5 * 1.15 * ag * STANDARD_GRAVITY
    np.testing.assert_allclose(Se, [plateau / 2.5, plateau, plateau, plateau * 0.3,
                                    plateau * 0.6 * 2.0 / 16.0], rtol=1e-14)
    # eta = sqrt(10 / (5 + xi)) with xi in %, floored at 0.55
    ratio = ec8_spectrum([0.3], 1.0, damping=0.10) / ec8_spectrum([0.3], 1.0)
    assert ratio[0] == pytest.approx(math.sqrt(10 / 15), rel=1e-14)
    assert (ec8_spectrum([0.3], 1.0, damping=0.5) / ec8_spectrum([0.3], 1.0))[0] == 0.55
    with pytest.raises(ValueError, match="ground_type == 'F'"):
        ec8_spectrum([0.3], 1.0, ground_type="F")
    with pytest.raises(ValueError, match="TB, TC, TD == 0.5, 0.3"):
        ec8_spectrum([0.3], 1.0, TB=0.5, TC=0.3)


def lnec_target(T):
    return ec8_spectrum(T, 2.8, TB=0.1, TC=0.3)


@pytest.fixture(scope="module")
def lnec_set():
    return spectrum_compatible_records(lnec_target, n=30, duration=16.0, dt=0.01, seed=7)


def test_spectrum_compatible_records_match_the_target(lnec_set):
    periods = np.geomspace(0.05, 2.0, 40)
    ratio = np.array([response_spectrum(r, periods).Sa for r in lnec_set]) / lnec_target(periods)
    # EN 1998-1 3.2.3.1.2 asks the mean of a set to be >= 90 % of the target; we also
    # bound it above by 110 % (measured: -1 % / +5 %). Single records scatter more:
    # frequency-domain scaling matches each oscillator only at the 80 matched periods and
    # the PGA constraint clips peaks (measured -19 % / +20 % for this seed), hence 25 %.
    mean = ratio.mean(axis=0)
    assert np.all((mean > 0.90) & (mean < 1.10)), mean
    assert np.all((ratio > 0.75) & (ratio < 1.25)), (ratio.min(), ratio.max())


def test_spectrum_compatible_records_are_at_rest_at_the_end_and_scaled(lnec_set):
    assert len(lnec_set) == 30
    for rec in lnec_set:
        assert len(rec) == 1601 and rec.dt == 0.01
        assert rec.pga == pytest.approx(2.8, rel=1e-14)   # target(0) of the EC8 spectrum
        pgv = np.max(np.abs(rec.velocity(rec.time)))
        pgd = np.max(np.abs(rec.displacement(rec.time)))
        # exact end correction: only round-off of the 2 x 2 solve remains
        assert abs(rec.velocity(rec.duration)) < 1e-10 * pgv
        assert abs(rec.displacement(rec.duration)) < 1e-10 * pgd
    assert len({rec.samples_mps2.tobytes() for rec in lnec_set}) == 30  # all different


def test_spectrum_compatible_records_are_reproducible():
    kwargs = dict(n=2, duration=6.0, dt=0.01, iterations=2)
    first = spectrum_compatible_records(lnec_target, seed=3, **kwargs)
    again = spectrum_compatible_records(lnec_target, seed=3, **kwargs)
    other = spectrum_compatible_records(lnec_target, seed=4, **kwargs)
    for a, b, c in zip(first, again, other):
        np.testing.assert_array_equal(a.samples_mps2, b.samples_mps2)
        assert not np.array_equal(a.samples_mps2, c.samples_mps2)
    with pytest.raises(ValueError, match="period_range"):
        spectrum_compatible_records(lnec_target, n=1, dt=0.02, period_range=(0.05, 2.0))
    with pytest.raises(ValueError, match="n == 0"):
        spectrum_compatible_records(lnec_target, n=0)
