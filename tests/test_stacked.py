"""The 2-DOF stacked rocking model against theory and against the 2D engine (LNEC stacked pair)."""
import math

import numpy as np
import pytest
from scipy.integrate import quad

import nscd
from nscd import lnec
from nscd.motion import Harmonic, Record
from nscd.rocking import HousnerBlock
from nscd.stacked import StackedBlocks, classify_patterns, dominant_pattern

G = nscd.motion.STANDARD_GRAVITY


def lnec_stack() -> StackedBlocks:
    """The LNEC pair with the stones' masses (003 Table 2 dimensions, granite)."""
    b, t = lnec.SPECIMENS["stacked_bottom"], lnec.SPECIMENS["stacked_top"]
    return StackedBlocks((b.width, b.height), (t.width, t.height),
                         bottom_mass=lnec.GRANITE_DENSITY * b.width * b.height * b.thickness,
                         top_mass=lnec.GRANITE_DENSITY * t.width * t.height * t.thickness)


def test_single_block_limits_reduce_to_housner():
    """Top alone on a held bottom block: the top is Housner's block (Housner's eta, its flights)."""
    stack = StackedBlocks((0.4, 1.0), (0.2, 0.8), bottom_mass=1e6, top_mass=1.0)  # bottom too heavy to lift
    top = HousnerBlock(0.2, 0.8)
    r = stack.simulate(None, 3.0, phi0=(0.0, 0.15))
    h = top.simulate(None, 3.0, theta0=-0.15)  # nscd.rocking counts the angle the other way
    assert r.pattern == "pattern 4 (top alone)"
    # event times to 1e-6 s: both are event-driven at rtol <= 1e-9 on the same equation
    n = min(len(h.impacts), 5)
    assert np.allclose(r.impacts["time"][:n], h.impacts.time[:n], atol=1e-6)
    ratio = r.impacts["after"][0, 1] / r.impacts["before"][0, 1]
    assert ratio == pytest.approx(1.0 - 1.5 * math.sin(top.alpha) ** 2, rel=1e-9)


def test_stack_released_as_one_body_is_a_compound_block():
    """Pattern 3 from a tilt: first impact time from energy (quadrature) and eta = 1 - 2 M b^2 / I_O.

    A stocky top (b2/h2 = 1) never reaches its rocking condition, so the stack is one rigid
    body rocking about a base corner until the first impact and after it.
    """
    w1, h1, w2, h2, m1, m2 = 0.3, 1.2, 0.3, 0.3, 3.0, 1.0
    stack = StackedBlocks((w1, h1), (w2, h2), bottom_mass=m1, top_mass=m2)
    M, b = m1 + m2, w1 / 2
    yc = (m1 * h1 / 2 + m2 * (h1 + h2 / 2)) / M
    i_g = stack.bottom_inertia + stack.top_inertia + m1 * (yc - h1 / 2) ** 2 + m2 * (h1 + h2 / 2 - yc) ** 2
    i_o = i_g + M * (b * b + yc * yc)
    d, alpha_c = math.hypot(b, yc), math.atan2(b, yc)
    phi0 = 0.6 * alpha_c
    r = stack.simulate(None, 2.0, phi0=(phi0, phi0))
    first = r.time < r.impacts["time"][0]
    assert np.all(r.sides[first, 1] == 0), "the top must ride as one body"

    def integrand(u):  # dt/du with phi = phi0 - u^2 (removes the endpoint singularity of dt/dphi)
        # cos(alpha_c - phi) - cos(alpha_c - phi0) written without cancellation
        drop = 2.0 * math.sin(alpha_c - phi0 + 0.5 * u * u) * math.sin(0.5 * u * u)
        return 2.0 * u / math.sqrt(2.0 * M * G * d * drop / i_o)
    t_impact = quad(integrand, 0.0, math.sqrt(phi0), epsabs=1e-13, epsrel=1e-11)[0]
    assert r.impacts["time"][0] == pytest.approx(t_impact, rel=1e-7)  # quadrature and event location ~1e-9
    eta = r.impacts["after"][0, 0] / r.impacts["before"][0, 0]
    assert eta == pytest.approx(1.0 - 2.0 * M * b * b / i_o, rel=1e-9)
    assert r.impacts["after"][0, 1] == pytest.approx(r.impacts["after"][0, 0], rel=1e-12)  # still one body


def test_impacts_never_create_energy():
    """Plastic impacts about the new pivots dissipate: kinetic energy after <= before at every impact."""
    stack = lnec_stack()
    r = stack.simulate(Harmonic.from_displacement(0.002, frequency=6.5, cycles=6, ramp_cycles=1), 2.5)
    assert len(r.impacts["time"]) > 10
    for t, before, after in zip(r.impacts["time"], r.impacts["before"], r.impacts["after"]):
        i = np.searchsorted(r.time, t)
        phi1, phi2 = r.phi[i]
        k_before, k_after = r.sides[i - 1], r.sides[min(i + 1, len(r.time) - 1)]
        e0 = stack.kinetic_energy(phi1, phi2, *before, *k_before)
        e1 = stack.kinetic_energy(phi1, phi2, *after, *k_after)
        assert e1 <= e0 * (1 + 1e-9) + 1e-15


@pytest.mark.parametrize("pattern, geometry", [
    ("pattern 4 (top alone)", ((0.4, 0.6), (0.15, 0.6))),   # slender top: b2/h2 = 0.25 < stack's 0.32
    ("pattern 3 (one body)", ((0.2, 0.6), (0.2, 0.3))),     # stocky top: b2/h2 = 0.67 > stack's 0.24
])
def test_static_onset_from_statics(pattern, geometry):
    """Under a slowly growing base acceleration the stack leaves rest at the statics' lowest onset."""
    bottom, top = geometry
    stack = StackedBlocks(bottom, top, bottom_mass=2.0, top_mass=1.0)
    onsets = stack.onset_accelerations()
    # statics by hand: stack about a base corner, lever b1 over the centre-of-mass height
    b1, h1, b2, h2 = bottom[0] / 2, bottom[1] / 2, top[0] / 2, top[1] / 2
    one_body = G * b1 * 3.0 / (2.0 * h1 + 1.0 * (2 * h1 + h2))
    assert onsets["one body"][0] == pytest.approx(one_body, rel=1e-12)
    assert onsets["top alone"][0] == pytest.approx(G * b2 / h2, rel=1e-12)
    slope = 0.5  # m/s^3: quasi-static (the dynamic overshoot at the onset instant is zero by construction)
    ramp = Record(slope * np.arange(0.0, 12.0, 0.01), dt=0.01, unit="m/s^2")
    r = stack.simulate(ramp, 11.0)
    start = np.argmax(np.any(r.sides != 0, axis=1))
    expected = min(onsets["one body"][0], onsets["top alone"][0])
    assert r.time[start] * slope == pytest.approx(expected, rel=1e-6)  # root found to 1e-14 s
    first = {(1, 0): "pattern 3 (one body)", (0, 1): "pattern 4 (top alone)"}[tuple(r.sides[start])]
    assert first == pattern


def test_bad_geometry_raises():
    with pytest.raises(ValueError, match="offset"):
        StackedBlocks((0.2, 0.6), (0.3, 0.6))
    with pytest.raises(ValueError, match="top height"):
        StackedBlocks((0.2, 0.6), (0.1, -1.0))
    with pytest.raises(ValueError, match="min_flight"):
        lnec_stack().simulate(None, 1.0, min_flight=-1.0)


def _engine_and_model(frequency, amplitude_mm, free=2.0, dt=1e-3):
    shake = Harmonic.from_displacement(amplitude_mm * 1e-3, frequency=frequency, cycles=10, ramp_cycles=1)
    t_end = round((10 / frequency + free) / dt) * dt  # a whole number of engine steps
    # friction 2: no sliding anywhere (the model's assumption), so the comparison isolates rocking
    engine = nscd.simulate(lnec.stacked_pair_2d(shake, friction=2.0), t_end, dt,
                           settings=nscd.Settings(scheme="midpoint"))
    model = lnec_stack().simulate(shake, t_end)
    e1, e2 = engine.angle("bottom"), engine.angle("top")
    return (classify_patterns(engine.time, e1, e2), np.abs([e1, e2]).max(axis=1),
            classify_patterns(model.time, model.phi[:, 0], model.phi[:, 1]), model.max_abs_phi)


def _check_agreement(frequency, amplitude_mm, free=2.0):
    pe, peak_e, pm, peak_m = _engine_and_model(frequency, amplitude_mm, free)
    assert dominant_pattern(pe) == dominant_pattern(pm)
    rocking = peak_e > math.radians(0.05)  # "no rocking" below 0.05 deg, as the LNEC benchmark
    assert np.array_equal(rocking, peak_m > math.radians(0.05))
    # "within a few %": 5 %, the engine's midpoint rule at dt = 1 ms puts impacts within
    # ~0.6 ms (README), which moves a chaotic rocking history's peak by a few %
    assert np.allclose(peak_m[rocking], peak_e[rocking], rtol=0.05)


def test_lnec_stacked_pair_agrees_with_engine_one_cell():
    """6.5 Hz, 2 mm (a cell of 003 Table 5): both blocks rock, pattern 2, as measured."""
    _check_agreement(6.5, 2.0, free=0.5)


@pytest.mark.slow
@pytest.mark.parametrize("frequency, amplitude_mm", [(3.0, 3.0), (3.3, 4.0), (4.0, 3.0), (4.0, 4.0),
                                                     (5.0, 2.0), (5.0, 4.0), (6.5, 1.0), (6.5, 2.0)])
def test_lnec_stacked_pair_agrees_with_engine_grid(frequency, amplitude_mm):
    """The constant-sine cells of 003 Table 5 (2D, friction high enough to rule out sliding)."""
    _check_agreement(frequency, amplitude_mm)
