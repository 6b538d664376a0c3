"""Tests of nscd.intensity against closed forms for a sampled cosine, and El Centro sanity."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from nscd.intensity import UNITS, intensity_measures
from nscd.motion import STANDARD_GRAVITY, Record, elcentro

A, F, CYCLES, DT = 2.0, 1.25, 10, 0.001   # a = A cos(2 pi F t) over 10 whole cycles
W = 2 * math.pi * F
T_END = CYCLES / F


@pytest.fixture(scope="module")
def cosine():
    t = np.arange(round(T_END / DT) + 1) * DT
    rec = Record(A * np.cos(W * t), DT, "m/s^2")
    return intensity_measures(rec, baseline_order=None)


def husid_time(fraction):
    """t with int_0^t cos^2 = fraction * int_0^T cos^2, closed form."""
    cumulative = lambda t: t / 2 + math.sin(2 * W * t) / (4 * W)
    return brentq(lambda t: cumulative(t) - fraction * cumulative(T_END), 0.0, T_END, xtol=1e-14)


# piecewise-linear interpolation of the cosine changes the integrals by O((W DT)^2 / 12)
# ~ 6e-6 relative; the Husid times are interpolated linearly between samples (error << DT)
RTOL_INTEGRAL = 2e-5


def test_keys_and_units(cosine):
    assert set(cosine) == set(UNITS)


def test_peaks(cosine):
    assert cosine["PGA"] == pytest.approx(A, rel=1e-15)
    # v = A/W sin(W t), d = A/W^2 (1 - cos(W t)); the peaks fall on samples (T/4 = 200 DT)
    assert cosine["PGV"] == pytest.approx(A / W, rel=RTOL_INTEGRAL)
    assert cosine["PGD"] == pytest.approx(2 * A / W**2, rel=RTOL_INTEGRAL)


def test_arias_and_durations(cosine):
    arias = math.pi / (2 * STANDARD_GRAVITY) * A**2 * T_END / 2
    assert cosine["arias"] == pytest.approx(arias, rel=RTOL_INTEGRAL)
    d80 = husid_time(0.9) - husid_time(0.1)
    assert cosine["D5_95"] == pytest.approx(husid_time(0.95) - husid_time(0.05), abs=DT / 10)
    assert cosine["D10_90"] == pytest.approx(d80, abs=DT / 10)
    a_rms = math.sqrt(0.8 * A**2 * T_END / 2 / d80)          # 001 eq 7
    assert cosine["a_rms"] == pytest.approx(a_rms, rel=1e-4)  # DT / 10 on d80 ~ 1e-5 relative
    assert cosine["Ic"] == pytest.approx(a_rms**1.5 * d80**0.5, rel=2e-4)     # 001 eq 8
    assert cosine["If"] == pytest.approx(A / W * d80**0.25, rel=1e-4)         # 001 eq 9


def test_zero_crossings_destructiveness_and_incremental_velocity(cosine):
    # a cosine crosses zero twice per cycle, at (k + 1/2) pi / W: 2 CYCLES crossings
    assert cosine["nu0"] == pytest.approx(2 * CYCLES / T_END, rel=1e-12)
    arias = math.pi / (2 * STANDARD_GRAVITY) * A**2 * T_END / 2
    assert cosine["PD"] == pytest.approx(arias / (2 * F) ** 2, rel=RTOL_INTEGRAL)  # 001 eq 5
    # largest area under one pulse: a full half cycle, int |A cos| = 2 A / W
    assert cosine["IV_max"] == pytest.approx(2 * A / W, rel=RTOL_INTEGRAL)


def test_predominant_period(cosine):
    n_fft = 2 ** math.ceil(math.log2(4 * (round(T_END / DT) + 1)))
    df = 1 / (n_fft * DT)
    # the Fourier peak is found on the padded grid: within half a bin of F
    assert cosine["Tp"] == pytest.approx(1 / F, abs=0.5 * df / F**2 * 1.01)


def test_scaling_and_polarity_laws():
    rec = elcentro()
    base = intensity_measures(rec)
    doubled = intensity_measures(rec.scaled(2.0))
    flipped = intensity_measures(rec.reversed())
    exponents = {"PGA": 1, "PGV": 1, "PGD": 1, "arias": 2, "D5_95": 0, "D10_90": 0, "a_rms": 1,
                 "Ic": 1.5, "If": 1, "nu0": 0, "PD": 2, "IV_max": 1, "Tp": 0}
    for key, power in exponents.items():
        # every measure is homogeneous in the amplitude and even in the polarity
        assert doubled[key] == pytest.approx(2.0**power * base[key], rel=1e-12), key
        assert flipped[key] == pytest.approx(base[key], rel=1e-12), key


def test_el_centro_sanity():
    im = intensity_measures(elcentro())
    assert im["PGA"] / STANDARD_GRAVITY == pytest.approx(0.319, abs=5e-4)  # record README
    # broad bands from the literature on this record (PGV ~ 0.3-0.4 m/s, D5-95 ~ 24 s,
    # Arias ~ 1.7-1.8 m/s, dominant periods 0.2-0.6 s); a sanity check, not a validation
    assert 0.30 < im["PGV"] < 0.40
    assert 0.05 < im["PGD"] < 0.30
    assert 1.4 < im["arias"] < 2.0
    assert 20.0 < im["D5_95"] < 28.0 and im["D10_90"] < im["D5_95"]
    assert 0.1 < im["Tp"] < 1.0
    with pytest.raises(TypeError, match="must be an nscd.motion.Record"):
        intensity_measures(np.zeros(10))


# Expected values for the shipped El Centro 1940 N-S record computed WITHOUT nscd by
# tests/reference/elcentro_intensity.py: its own AT2 parsing, numpy / scipy
# cumulative_trapezoid over the samples (the convention of PEER, gmprocess, eqsig,
# SeismoSignal), and eqsig 1.2 (eqsig.im.calc_arias_intensity 1.800357936 m/s with
# g = 9.81, i.e. 1.800972947 with g = 9.80665; eqsig PGV 0.3614152598 m/s and PGD
# 0.2134335585 m equal the by-hand trapezoid values to 10 digits). Printed to 10
# significant digits: rel 1e-9 is that print precision.
EL_CENTRO_SAMPLES = {
    "PGA": 3.126556153, "PGV": 0.3614152598, "PGD": 0.2134335585, "arias": 1.800972947,
    "D5_95": 23.8433624, "D10_90": 20.07081633, "a_rms": 0.6694474152, "Ic": 2.453902041,
}
# eqsig's significant duration picks whole samples (first / last sample strictly inside
# the 5-95 % band): 23.82 s; each end may sit up to one step (0.02 s) from the interpolated
# Husid time, so the durations agree within two steps
EQSIG_D5_95, EL_CENTRO_DT = 23.82, 0.02
# Arias of the piecewise-linear interpolant, brute force by the same script (1000
# sub-samples per step, trapezoid: relative error ~ 1e-6 / 12, printed to 10 digits)
EL_CENTRO_INTERPOLANT_ARIAS = 1.723569032


def test_el_centro_defaults_match_the_fields_convention():
    im = intensity_measures(elcentro())
    for key, expected in EL_CENTRO_SAMPLES.items():
        assert im[key] == pytest.approx(expected, rel=1e-9), key
    assert im["D5_95"] == pytest.approx(EQSIG_D5_95, abs=2 * EL_CENTRO_DT)


def test_el_centro_exact_interpolant_is_one_keyword_away():
    exact = intensity_measures(elcentro(), integration="interpolant")
    # 1e-7: the brute-force refinement's own error (~1e-7 relative) plus the print precision
    assert exact["arias"] == pytest.approx(EL_CENTRO_INTERPOLANT_ARIAS, rel=1e-7)
    # the interpolant's a^2 is smaller than the trapezoid of the samples' a^2 on every step:
    # the 4.3 % gap on this record at 50 Hz
    assert exact["arias"] / EL_CENTRO_SAMPLES["arias"] == pytest.approx(0.957, abs=1e-3)
    # the velocity is the same in both conventions (trapezoid of a = exact for linear a)
    assert exact["PGV"] == pytest.approx(EL_CENTRO_SAMPLES["PGV"], rel=1e-9)
    with pytest.raises(ValueError, match="integration == 'simpson', must be one of"):
        intensity_measures(elcentro(), integration="simpson")


def test_baseline_correction_only_when_asked():
    rec = elcentro()
    raw, corrected = intensity_measures(rec), intensity_measures(rec, baseline_order=2)
    assert raw["PGV"] == pytest.approx(EL_CENTRO_SAMPLES["PGV"], rel=1e-9)
    # removing the velocity trend changes PGV and PGD (not the acceleration measures)
    assert corrected["PGV"] != pytest.approx(raw["PGV"], rel=1e-4)
    assert corrected["arias"] == raw["arias"]


def test_zero_record_is_rejected():
    with pytest.raises(ValueError, match="identically zero"):
        intensity_measures(Record(np.zeros(10), 0.01, "g"))
