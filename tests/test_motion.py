"""Tests of nscd.motion against closed forms (seed 000 pulses, seed 003 table motions)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

import nscd
from nscd.motion import (STANDARD_GRAVITY, ConstantAccelerationPhases, HanningSine, Harmonic, OneCosine,
                         OneSine, Prescribed, Record, Sweep, TypeCn, elcentro)

G = STANDARD_GRAVITY

ANALYTIC = {
    "one-sine": lambda: OneSine(2.0, 3.0),
    "one-cosine": lambda: OneCosine(0.3, 5.0, unit="g"),
    "type-C1": lambda: TypeCn(1.5, 2.0, 1),
    "type-C2": lambda: TypeCn(-1.5, 4.0, 2),
    "harmonic": lambda: Harmonic(1.0, frequency=2.0, cycles=5),
    "harmonic-ramped": lambda: Harmonic.from_displacement(0.006, frequency=3.3, cycles=10,
                                                          ramp_cycles=2),
    "hanning": lambda: HanningSine(0.007, frequency=3.3, cycles=8),
    "sweep-linear-down": lambda: Sweep(0.003, 5.0, 0.5, 6.0),
    "sweep-log-up": lambda: Sweep(0.006, 0.5, 5.0, 6.0, law="log", ramp=1.0),
    "acceleration phases": lambda: ConstantAccelerationPhases([0.0, 0.2, 0.5], [3.0, -1.0, -2.0], 0.9),
}


@pytest.mark.parametrize("name", ANALYTIC)
def test_velocity_and_acceleration_are_exact_derivatives(name):
    motion = ANALYTIC[name]()
    t = np.random.default_rng(1).uniform(0.0, 1.3 * motion.duration, 200)
    h = 1e-5
    for lower, upper in ((motion.displacement, motion.velocity),
                         (motion.velocity, motion.acceleration)):
        fd = (lower(t + h) - lower(t - h)) / (2.0 * h)
        exact = upper(t)
        scale = np.max(np.abs(exact))
        # central difference: truncation h^2 |f'''| / 6 <= 1e-10 * (2 pi 5 Hz)^2 * scale
        # ~ 1e-7 scale, round-off 1e-16 |f| / h ~ 1e-11 scale; 1e-6 leaves a margin
        # (the 200 seeded times avoid the few kinks by more than h)
        np.testing.assert_allclose(fd, exact, rtol=0, atol=1e-6 * scale)


@pytest.mark.parametrize("name", ANALYTIC)
def test_kinematics_are_integrals_of_acceleration_from_rest(name):
    motion = ANALYTIC[name]()
    assert motion.displacement(-0.5) == motion.velocity(-0.5) == motion.acceleration(-0.5) == 0.0
    grid = np.linspace(0.0, motion.duration, 2001)
    peak_v, peak_d = np.max(np.abs(motion.velocity(grid))), np.max(np.abs(motion.displacement(grid)))
    # the start value v(0+) is the integration constant (a velocity jump at t = 0 for
    # un-ramped Harmonic and Sweep); after the end, table motions stop (v = 0) and
    # hold their displacement, pulses keep their final velocity
    v0 = motion.velocity(1e-14)
    for t in (0.37 * motion.duration, motion.duration, 1.5 * motion.duration):
        v_int, _ = quad(motion.acceleration, 0.0, t, limit=500, epsabs=1e-13, epsrel=1e-11)
        d_int, _ = quad(motion.velocity, 0.0, t, limit=500, epsabs=1e-13, epsrel=1e-11)
        # adaptive quadrature is accurate to ~1e-11 relative to the peak values
        assert motion.velocity(min(t, motion.duration)) == pytest.approx(v0 + v_int,
                                                                         abs=1e-9 * peak_v)
        assert motion.displacement(t) == pytest.approx(d_int, abs=1e-9 * peak_d)


def test_scalar_in_float_out_and_shapes_preserved():
    motion = OneSine(1.0, 2.0)
    assert isinstance(motion.acceleration(0.3), float)
    t = np.linspace(0, 4, 12).reshape(3, 4)
    assert motion.displacement(t).shape == (3, 4)


def test_one_sine_closed_form_and_residual_displacement():
    A, w = 2.0, 3.0
    pulse = OneSine(A, w)
    T = 2 * math.pi / w
    assert pulse.duration == pytest.approx(T, rel=1e-15)
    t = np.linspace(0, T, 50)
    np.testing.assert_allclose(pulse.acceleration(t), A * np.sin(w * t), atol=1e-14)
    np.testing.assert_allclose(pulse.velocity(t), A / w * (1 - np.cos(w * t)), atol=1e-14)
    # the exact integral from rest: no residual velocity, a permanent forward
    # displacement 2 pi A / w^2 (000 line 1236: "results to a forward ground displacement")
    assert pulse.velocity(3 * T) == pytest.approx(0.0, abs=1e-14)
    assert pulse.displacement(3 * T) == pytest.approx(2 * math.pi * A / w**2, rel=1e-14)
    assert pulse.acceleration(1.5 * T) == 0.0
    assert OneSine(0.5, 3.0, unit="g").acceleration(T / 4) == pytest.approx(0.5 * G, rel=1e-15)


def test_one_cosine_returns_to_rest_at_origin():
    A, w = 1.2, 4.0
    pulse = OneCosine(A, w)
    T = 2 * math.pi / w
    assert pulse.acceleration(0.0) == A  # peak at the initiation of motion (000 Fig. 3)
    assert pulse.displacement(T / 2) == pytest.approx(2 * A / w**2, rel=1e-14)
    assert pulse.velocity(2 * T) == pytest.approx(0.0, abs=1e-14)
    assert pulse.displacement(2 * T) == pytest.approx(0.0, abs=1e-14)


@pytest.mark.parametrize("n, phi_over_pi", [(1, 0.0697), (2, 0.0410)])
def test_type_cn_phase_and_rest_at_both_ends(n, phi_over_pi):
    A, w = 1.5, 2.0
    pulse = TypeCn(A, w, n)
    # phase quoted to 3 significant digits in the literature (Makris & Roussos 2000)
    assert pulse.phi / math.pi == pytest.approx(phi_over_pi, abs=6e-5)
    assert pulse.duration == pytest.approx((n + 0.5 - pulse.phi / math.pi) * 2 * math.pi / w,
                                           rel=1e-14)
    # finite at t = 0 but smaller than the peak (000 lines 489-490)
    assert pulse.acceleration(0.0) == pytest.approx(A * math.cos(pulse.phi), rel=1e-14)
    t = np.linspace(0, pulse.duration, 20001)
    assert np.max(np.abs(pulse.acceleration(t))) == pytest.approx(A, rel=1e-6)  # grid resolution
    assert pulse.velocity(pulse.duration) == pytest.approx(0.0, abs=1e-14)
    assert pulse.displacement(pulse.duration) == pytest.approx(0.0, abs=1e-13)
    assert pulse.displacement(5 * pulse.duration) == pytest.approx(0.0, abs=1e-12)


def test_harmonic_from_acceleration_and_from_displacement():
    f, D = 3.3, 0.006
    w = 2 * math.pi * f
    table = Harmonic.from_displacement(D, frequency=f, cycles=10)
    t = np.linspace(0, table.duration, 333)
    np.testing.assert_allclose(table.displacement(t), D * np.sin(w * t), atol=1e-15)
    np.testing.assert_allclose(table.acceleration(t), -D * w**2 * np.sin(w * t), atol=1e-12)
    assert table.amplitude == pytest.approx(-D * w**2, rel=1e-15)
    # no ramp: documented velocity jump to D w at t = 0
    assert table.velocity(0.0) == pytest.approx(D * w, rel=1e-14)
    by_acc = Harmonic(0.2, omega=w, unit="g", cycles=10)
    np.testing.assert_allclose(by_acc.acceleration(t), 0.2 * G * np.sin(w * t), atol=1e-12)
    assert by_acc.displacement_amplitude == pytest.approx(-0.2 * G / w**2, rel=1e-15)
    assert math.isinf(Harmonic(1.0, 2.0).duration)


def test_harmonic_ramp_starts_and_stops_at_rest():
    D, f = 0.005, 2.0
    table = Harmonic.from_displacement(D, frequency=f, cycles=6, ramp_cycles=1.5)
    for t in (0.0, table.duration, table.duration + 1.0):
        assert table.velocity(t) == pytest.approx(0.0, abs=1e-15)
        assert table.displacement(t) == pytest.approx(0.0, abs=1e-15)
    mid = np.linspace(1.5 / f, table.duration - 1.5 / f, 101)
    np.testing.assert_allclose(table.displacement(mid), D * np.sin(2 * math.pi * f * mid),
                               atol=1e-15)


def test_hanning_sine_window():
    D, f, n = 0.007, 3.3, 8
    motion = HanningSine(D, frequency=f, cycles=n)
    assert motion.duration == pytest.approx(n / f, rel=1e-15)
    for t in (0.0, motion.duration):
        assert motion.displacement(t) == pytest.approx(0.0, abs=1e-15)
        assert motion.velocity(t) == pytest.approx(0.0, abs=1e-15)
        assert motion.acceleration(t) == pytest.approx(0.0, abs=1e-12)
    t = np.linspace(0, motion.duration, 7)
    window = 0.5 * (1 - np.cos(2 * math.pi * t / motion.duration))
    np.testing.assert_allclose(motion.displacement(t), D * window * np.sin(2 * math.pi * f * t),
                               atol=1e-15)


@pytest.mark.parametrize("law", ["linear", "log"])
@pytest.mark.parametrize("f0, f1", [(0.5, 5.0), (5.0, 0.5)])
def test_sweep_phase_law_counts_zero_crossings(law, f0, f1):
    T = 10.0
    motion = Sweep(0.003, f0, f1, T, law=law)
    if law == "linear":
        total_phase = math.pi * (f0 + f1) * T
    else:
        total_phase = 2 * math.pi * T * (f1 - f0) / math.log(f1 / f0)
    t = np.linspace(1e-9, T - 1e-9, 400001)
    d = motion.displacement(t)
    crossings = np.count_nonzero(np.sign(d[1:]) != np.sign(d[:-1]))
    # d = D sin(theta): one zero crossing each time theta passes a multiple of pi
    assert crossings == math.floor(total_phase / math.pi)
    assert np.max(np.abs(d)) == pytest.approx(0.003, rel=1e-4)  # grid resolution


@pytest.mark.parametrize("build, message", [
    (lambda: OneSine(1.0, -2.0), "omega == -2.0"),
    (lambda: OneSine(float("nan"), 2.0), "amplitude == nan"),
    (lambda: OneCosine(1.0, 2.0, unit="gal"), "unit == 'gal'"),
    (lambda: TypeCn(1.0, 2.0, 0), "n == 0"),
    (lambda: Harmonic(1.0), "give exactly one"),
    (lambda: Harmonic(1.0, 2.0, frequency=1.0), "give exactly one"),
    (lambda: Harmonic(1.0, 2.0, cycles=2, ramp_cycles=1.5), "ramp_cycles == 1.5"),
    (lambda: Harmonic.from_displacement(0.01, frequency=0.0), "frequency == 0.0"),
    (lambda: HanningSine(0.01, frequency=2.0, cycles=-1), "cycles == -1.0"),
    (lambda: Sweep(0.01, 1.0, 1.0, 10.0), "f_end == 1.0"),
    (lambda: Sweep(0.01, 1.0, 2.0, 10.0, law="cubic"), "law == 'cubic'"),
    (lambda: Sweep(0.01, 1.0, 2.0, 10.0, ramp=6.0), "ramp == 6.0"),
    (lambda: ConstantAccelerationPhases([0.0, 0.3, 0.2], [1.0, 0.0, -1.0], 1.0), r"starts == \[0.0, 0.3, 0.2\]"),
    (lambda: ConstantAccelerationPhases([0.0, 0.3], [1.0], 1.0), r"accelerations == \[1.0\] m/s\^2"),
    (lambda: ConstantAccelerationPhases([0.0, 0.3], [1.0, float("nan")], 1.0), r"accelerations == \[1.0, nan\] m/s\^2"),
    (lambda: ConstantAccelerationPhases([0.0, 0.3], [1.0, -1.0], 0.2), "duration == 0.2"),
])
def test_constructors_name_parameter_and_value(build, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        build()


def test_acceleration_phases_closed_form_and_at_rest_after():
    """Phases of constant acceleration: 3 m/s^2 for 0.2 s, then -1 m/s^2 for 0.3 s, then
    -1.5 m/s^2 to 0.8 s: v = 0.6, 0.3, -0.15 m/s and d = 0.06, 0.195, 0.217 5 m at the phase
    ends (by hand: v0 t + a t^2 / 2 phase by phase); after the end the velocity stays, or is
    exactly 0 with ``at_rest_after``."""
    moving = ConstantAccelerationPhases([0.0, 0.2, 0.5], [3.0, -1.0, -1.5], 0.8)
    resting = ConstantAccelerationPhases([0.0, 0.2], [3.0, -3.0], 0.4, at_rest_after=True)
    d, v, a = moving.kinematics(np.array([0.2, 0.5, 0.8, 1.0]))
    # rounding of the phase sums: a few ulps of values of order 0.1-1
    np.testing.assert_allclose(v, [0.6, 0.3, -0.15, -0.15], rtol=0, atol=1e-15)
    np.testing.assert_allclose(d, [0.06, 0.195, 0.2175, 0.2175 - 0.03], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(a, [-1.0, -1.5, 0.0, 0.0])
    assert resting.velocity(0.4) == 0.0 and resting.velocity(2.0) == 0.0
    assert resting.displacement(2.0) == pytest.approx(0.12, abs=1e-15)  # 2 x (3 x 0.2^2 / 2)


def test_prescribed_functions():
    motion = Prescribed(np.sin, np.cos, lambda t: -np.sin(t), duration=10.0)
    assert motion.acceleration(1.0) == pytest.approx(-math.sin(1.0), rel=1e-15)
    constant = Prescribed(lambda t: 0.0, lambda t: 0.0, lambda t: 0.0)
    assert constant.velocity(np.zeros(3)).shape == (3,)
    with pytest.raises(ValueError, match="velocity"):
        Prescribed(np.sin, 3.0, np.cos)
    with pytest.raises(ValueError, match=r"acceleration\(0.0\) == nan"):
        Prescribed(np.sin, np.cos, lambda t: np.full_like(t, np.nan))
    with pytest.raises(ValueError, match="vectorised"):
        Prescribed(np.sin, np.cos, lambda t: np.zeros(2))
    with pytest.warns(UserWarning, match="acceleration does not match"):
        Prescribed(np.sin, np.cos, np.sin)


# ------------------------------------------------------------------ records
def test_record_integrates_piecewise_linear_acceleration_exactly():
    # a linear acceleration is reproduced exactly by the interpolation, so v and d
    # must equal their closed forms everywhere (round-off only)
    c0, c1, dt, n = 0.7, -0.3, 0.05, 81
    rec = Record(c0 + c1 * np.arange(n) * dt, dt, "m/s^2")
    T = rec.duration
    t = np.random.default_rng(0).uniform(0, T, 50)
    np.testing.assert_allclose(rec.acceleration(t), c0 + c1 * t, atol=1e-14)
    np.testing.assert_allclose(rec.velocity(t), c0 * t + c1 * t**2 / 2, atol=1e-13)
    np.testing.assert_allclose(rec.displacement(t), c0 * t**2 / 2 + c1 * t**3 / 6, atol=1e-13)
    vT, dT = c0 * T + c1 * T**2 / 2, c0 * T**2 / 2 + c1 * T**3 / 6
    assert rec.acceleration(T + 1.0) == 0.0 and rec.acceleration(-0.1) == 0.0
    assert rec.velocity(T + 1.0) == pytest.approx(vT, rel=1e-13)
    assert rec.displacement(T + 1.0) == pytest.approx(dT + vT, rel=1e-13)


def test_record_converges_at_second_order_to_a_sampled_sine():
    A, w, T = 1.0, 2 * math.pi, 3.0
    errors = []
    for dt in (0.02, 0.01):
        t = np.arange(round(T / dt) + 1) * dt
        rec = Record(A * np.sin(w * t), dt, "m/s^2")
        probe = np.linspace(0, T, 77)
        errors.append(np.max(np.abs(rec.displacement(probe)
                                    - A / w * (probe - np.sin(w * probe) / w))))
    # linear interpolation error O(dt^2): halving dt divides the error by ~4
    assert errors[0] / errors[1] == pytest.approx(4.0, rel=0.05)


def test_record_validation():
    with pytest.raises(ValueError, match="unit == None"):
        Record([0.0, 1.0], 0.01, None)
    with pytest.raises(ValueError, match="unit == 'cm/s^2'".replace("^", r"\^")):
        Record([0.0, 1.0], 0.01, "cm/s^2")
    with pytest.raises(ValueError, match=r"samples\[2\] == nan"):
        Record([0.0, 1.0, float("nan"), 2.0], 0.01, "g")
    with pytest.raises(ValueError, match=r"samples\[1\] == inf"):
        Record([0.0, float("inf")], 0.01, "g")
    with pytest.raises(ValueError, match="dt == 0.0"):
        Record([0.0, 1.0], 0.0, "g")
    with pytest.raises(ValueError, match="at least 2"):
        Record([1.0], 0.01, "g")


def test_record_scaling_and_polarity():
    rec = Record([0.0, 0.1, -0.25, 0.05], 0.01, "g")
    assert rec.pga == pytest.approx(0.25 * G, rel=1e-15)
    assert rec.scaled(2.0).pga == pytest.approx(0.5 * G, rel=1e-15)
    assert rec.scaled_to_pga(0.4, "g").pga == pytest.approx(0.4 * G, rel=1e-15)
    assert rec.scaled_to_pga(3.0, "m/s^2").pga == pytest.approx(3.0, rel=1e-15)
    rev = rec.reversed()
    np.testing.assert_array_equal(rev.samples_mps2, -rec.samples_mps2)
    assert rev.displacement(0.1) == -rec.displacement(0.1)
    with pytest.raises(ValueError, match="pga == -1.0"):
        rec.scaled_to_pga(-1.0, "g")
    with pytest.raises(ValueError, match="identically zero"):
        Record(np.zeros(5), 0.01, "g").scaled_to_pga(0.1, "g")


@pytest.mark.parametrize("order", [1, 2])
def test_baseline_correction_removes_polynomial_velocity_trends(order):
    rng = np.random.default_rng(3)
    dt, n = 0.01, 1500
    t = np.arange(n) * dt
    base = Record(rng.standard_normal(n), dt, "m/s^2")
    # an acceleration offset/drift adds a velocity trend in the fitted span
    drift = 0.05 + (0.01 * t if order == 2 else 0.0)
    drifted = Record(base.samples_mps2 + drift, dt, "m/s^2")
    a, b = base.baseline_corrected(order), drifted.baseline_corrected(order)
    # least squares is invariant to adding an element of the fitted span
    np.testing.assert_allclose(a.samples_mps2, b.samples_mps2, atol=1e-9)
    # normal equations: the corrected velocity is orthogonal to t^j, j = 1..order
    v = a.velocity(t)
    for j in range(1, order + 1):
        assert abs(np.dot(v, t**j)) <= 1e-9 * np.linalg.norm(v) * np.linalg.norm(t**j)
    assert a.velocity(0.0) == 0.0 and a.displacement(0.0) == 0.0
    with pytest.raises(ValueError, match="order == 3"):
        base.baseline_corrected(3)


def test_shipped_el_centro_record_matches_its_readme():
    rec = elcentro()
    assert len(rec) == 1559 and rec.dt == 0.02  # header NPTS, DT; padding zero ignored
    # README: peak |a| 0.319 g at 2.02 s (3 significant digits)
    assert rec.pga / G == pytest.approx(0.319, abs=5e-4)
    assert rec.time[np.argmax(np.abs(rec.samples_mps2))] == pytest.approx(2.02, abs=1e-12)
    assert rec.samples_mps2[0] == pytest.approx(0.00630 * G, rel=1e-12)  # first value of the file
    assert Record.example("elcentro_1940_ns").pga == rec.pga
    with pytest.raises(ValueError, match="name == 'kobe'"):
        Record.example("kobe")


AT2 = """PEER NGA STRONG MOTION DATABASE RECORD
TEST 1999, STATION, 000
ACCELERATION TIME SERIES IN UNITS OF {unit}
npts=5 ,  dt=.0050 SEC
 1.0 2.0 3.0
 4.0 {last}
"""


def test_from_at2_units_counts_and_padding(tmp_path):
    path = tmp_path / "a.AT2"
    path.write_text(AT2.format(unit="CM/S/S", last="5.0 0.0 0.0"))
    rec = Record.from_at2(path)
    assert len(rec) == 5 and rec.dt == 0.005
    np.testing.assert_allclose(rec.samples_mps2, [0.01, 0.02, 0.03, 0.04, 0.05], rtol=1e-15)
    path.write_text(AT2.format(unit="G", last=""))
    with pytest.raises(ValueError, match=r"a\.AT2: NPTS == 5 but only 4 value"):
        Record.from_at2(path)
    path.write_text(AT2.format(unit="FURLONGS", last="5.0"))
    with pytest.raises(ValueError, match="a.AT2: no acceleration unit"):
        Record.from_at2(path)
    path.write_text(AT2.format(unit="G", last="5.0").replace("npts=5", "N=5"))
    with pytest.raises(ValueError, match="header line 4"):
        Record.from_at2(path)


OLD_PEER_HEADER = """PACIFIC ENGINEERING AND ANALYSIS STRONG-MOTION DATA
 IMPERIAL VALLEY 05/19/40 0439, EL CENTRO ARRAY #9, 180
ACCELERATION TIME HISTORY IN UNITS OF G
{line4}
"""


@pytest.mark.parametrize("line4", [
    "NPTS=  1559, DT= .02000 SEC",     # NGA database (the shipped file's layout)
    "1559    0.0200    NPTS, DT",      # older PEER strong-motion database
    "  1559   .02000   NPTS, DT",
    "DT= 0.02 SEC, NPTS= 1559",
])
def test_from_at2_reads_both_peer_header_layouts(tmp_path, line4):
    shipped = (Path(nscd.__file__).parent / "data" / "elcentro_1940_ns.AT2").read_text().splitlines()
    path = tmp_path / "elc.AT2"
    path.write_text(OLD_PEER_HEADER.format(line4=line4) + "\n".join(shipped[4:]) + "\n")
    rec = Record.from_at2(path)
    # the shipped file's NPTS and DT, whichever way line 4 spells them
    assert len(rec) == 1559 and rec.dt == 0.02
    np.testing.assert_array_equal(rec.samples_mps2, elcentro().samples_mps2)


@pytest.mark.parametrize("line4", ["1559    0.0200", "1559.5 0.02 NPTS, DT", "NPTS, DT 1559 0.02"])
def test_from_at2_rejects_ambiguous_line_4(tmp_path, line4):
    path = tmp_path / "bad.AT2"
    path.write_text(OLD_PEER_HEADER.format(line4=line4) + "1.0 2.0\n")
    with pytest.raises(ValueError, match=r"bad\.AT2: (header line 4|NPTS == 1559.5)"):
        Record.from_at2(path)


def test_from_text_checks_uniform_step(tmp_path):
    path = tmp_path / "rec.txt"
    t = 1.0 + np.arange(6) * 0.01
    np.savetxt(path, np.column_stack([t, np.arange(6.0)]), header="time acc", fmt="%.6f")
    rec = Record.from_text(path, "g", skiprows=1)
    assert rec.dt == pytest.approx(0.01, rel=1e-12) and rec.time[0] == 0.0
    assert rec.pga == pytest.approx(5 * G, rel=1e-15)
    with pytest.raises(ValueError, match="unit == None"):
        Record.from_text(path, None, skiprows=1)
    t[3] += 0.004
    np.savetxt(path, np.column_stack([t, np.arange(6.0)]))
    with pytest.raises(ValueError, match="must be uniform"):
        Record.from_text(path, "g")


def test_kinematics_returns_the_three_quantities():
    motion = TypeCn(1.0, 3.0, 1)
    d, v, a = motion.kinematics(0.4)
    assert (d, v, a) == (motion.displacement(0.4), motion.velocity(0.4), motion.acceleration(0.4))
    t = np.linspace(0, 3, 6).reshape(2, 3)
    assert all(x.shape == (2, 3) for x in motion.kinematics(t))
    # the attributes the 1-DOF rocking model reads: a = amplitude sin(omega t + phase)
    assert motion.acceleration(0.4) == pytest.approx(
        motion.amplitude * math.sin(motion.omega * 0.4 + motion.phase), rel=1e-14)


def test_harmonic_length_by_cycles_or_duration():
    by_cycles = Harmonic.from_displacement(0.004, frequency=2.5, cycles=5)
    by_duration = Harmonic.from_displacement(0.004, frequency=2.5, duration=2.0)
    assert by_cycles.duration == pytest.approx(by_duration.duration, rel=1e-15)
    with pytest.raises(ValueError, match="give at most one"):
        Harmonic(1.0, 2.0, cycles=3, duration=2.0)
    with pytest.raises(ValueError, match="duration == -2.0"):
        Harmonic(1.0, 2.0, duration=-2.0)
