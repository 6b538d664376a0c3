"""Rocking onset of LNEC specimen 2 (003, Table 4 set-up) against rigid-block theory.

A rigid rectangular block on a rigid base, under a horizontal base acceleration a(t),
stays at rest while |a| < g tan(alpha) = g b / h (moment balance about the base edge;
Housner 1963, eq. 3.1 of 003) and no sliding is possible while |a| < mu g (here
tan(alpha) = 0.17 < mu = 0.577). Above that onset it rocks, and with Newton
restitution 0 the engine's impact is Housner's angular-momentum impact, so the
rocking follows the 1-DOF Housner equation (nscd.rocking.HousnerBlock).
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import nscd
from nscd import lnec
from nscd.motion import STANDARD_GRAVITY, Harmonic
from nscd.rocking import HousnerBlock

STONE = lnec.SPECIMENS["single2"]
B, H = STONE.width / 2, STONE.height / 2
FREQUENCY = 5.0  # Hz, the highest frequency of Table 4
CYCLES = 2       # ramp up and ramp down (raised cosine, one cycle each): the shortest Harmonic
FREE_TIME = 0.2  # s of free rocking after the motion


def _shake(onset_factor: float) -> Harmonic:
    """Table-4-like motion whose sampled peak acceleration is ``onset_factor * g tan(alpha)``."""
    unit = Harmonic.from_displacement(1.0, frequency=FREQUENCY, cycles=CYCLES, ramp_cycles=1)
    t = np.linspace(0.0, unit.duration, 20001)
    peak_per_metre = float(np.max(np.abs(unit.acceleration(t))))
    amplitude = onset_factor * STANDARD_GRAVITY * (B / H) / peak_per_metre
    return Harmonic.from_displacement(amplitude, frequency=FREQUENCY, cycles=CYCLES, ramp_cycles=1)


def _max_tilt_deg(shake: Harmonic) -> float:
    result = nscd.simulate(lnec.single(2, motion=shake, restitution=0.0), shake.duration + FREE_TIME, dt=1e-3)
    assert not result.overturned("block")
    return math.degrees(float(np.max(np.abs(result.rotation("block")))))


def test_specimen2_rests_below_the_rocking_onset():
    tilt = _max_tilt_deg(_shake(0.9))
    # Below the onset theory gives no tilt at all; 1e-4 deg (corner lift 0.15 um on the
    # 0.17 m base) only allows for round-off, far below the 0.05 deg "no rocking"
    # threshold of benchmarks/bench_lnec_table4.py.
    assert tilt < 1e-4


def test_specimen2_rocks_above_the_onset_as_the_housner_equation():
    shake = _shake(1.5)
    tilt = _max_tilt_deg(shake)
    housner = HousnerBlock.from_alpha_R(math.atan2(B, H), math.hypot(B, H)).simulate(
        shake, shake.duration + FREE_TIME)
    expected = math.degrees(housner.max_abs_theta)
    assert expected > 0.05  # the theory itself predicts rocking here
    # 5 %: Moreau-Jean is first order in dt; at dt = 1 ms against the 5 Hz forcing
    # (dt * 2 pi f = 3 %) and the rocking time scale 1/p = 0.26 s the expected error is
    # a few percent.
    assert tilt == pytest.approx(expected, rel=0.05)


def test_harmonic_cell_near_the_onset_rocks_at_default_settings():
    """Table 4 of 003, 3 Hz / 5 mm (10 cycles): measured 1.85 deg of rocking.

    The cell lies just above the rocking onset (peak table acceleration about 1.1 g tan(alpha)),
    where the outcome is a bifurcation: the 1-DOF Housner model gives 1.85 to 2.02 deg for
    D = 4.9 to 5.1 mm, and the theta scheme at dt = 1 ms misses the onset (0.014 deg: no
    rocking). The default scheme (Moreau's midpoint rule, second order between impacts) at the
    default settings and dt = 1 ms must rock by about 2 deg.
    """
    assert nscd.Settings().scheme == "midpoint"
    shake = Harmonic.from_displacement(5e-3, frequency=3.0, cycles=10, ramp_cycles=1)
    result = nscd.simulate(lnec.single_in_plane(2, motion=shake), shake.duration + 0.5, dt=1e-3)
    tilt = math.degrees(float(np.max(np.abs(result.rotation("block")))))
    # within 20 % of the measured 1.85 deg: the spread of the rigid-body (Housner) model over
    # +-2 % of the amplitude near this onset (1.85 to 2.02 deg) plus the test's own scatter
    assert tilt == pytest.approx(1.85, rel=0.2)
    assert not result.overturned("block")
