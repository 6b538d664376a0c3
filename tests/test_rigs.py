"""Tests of the double-pulse rig of 002 (nscd.rigs), its maps and the ``nscd map`` command."""
from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import quad

from nscd import rigs
from nscd.motion import STANDARD_GRAVITY as G
from nscd.result import OVERTURN_ANGLE
from nscd.rigs import DoublePulse, DoublePulseRig, classify
from nscd.state import States

# ----------------------------------------------------------------- DoublePulse, closed form


@pytest.mark.parametrize(("v_peak", "gap", "e_s"), [(0.6, 0.03, 0.5), (1.5, 0.005, 0.0), (0.3, 0.05, 1.0)])
def test_double_pulse_is_exactly_integrable(v_peak, gap, e_s):
    motion = DoublePulse(v_peak, gap, stopper_restitution=e_s)
    breaks = [0.0, motion.rise_time, motion.t_impact, motion.t_impact + motion.rise_time, motion.duration]
    breaks = [b for b in breaks if math.isfinite(b)]
    for t in np.linspace(0.0, 1.3 * motion.duration, 23):
        inside = [b for b in breaks if b < t]
        v_int = quad(motion.acceleration, 0.0, t, points=inside or None, limit=200, epsabs=1e-13)[0]
        d_int = quad(motion.velocity, 0.0, t, points=inside or None, limit=200, epsabs=1e-13)[0]
        # 1e-9: quadrature of a piecewise polynomial with its breakpoints given is exact to round-off
        assert abs(v_int - motion.velocity(t)) < 1e-9
        assert abs(d_int - motion.displacement(t)) < 1e-9


def test_double_pulse_phases_match_the_hand_derivation():
    v, gap, mu, e, t_r = 0.8, 0.03, 0.26, 0.5, 0.005
    motion = DoublePulse(v, gap, rise_time=t_r, base_friction=mu, stopper_restitution=e)
    # launch: uniform acceleration to v_peak in t_r, travelling v t_r / 2
    assert motion.acceleration(0.5 * t_r) == pytest.approx(v / t_r, rel=1e-12)
    assert motion.velocity(t_r) == pytest.approx(v, rel=1e-12)
    assert motion.displacement(t_r) == pytest.approx(0.5 * v * t_r, rel=1e-12)
    # free sliding: -mu g; reaches the gap at v_impact^2 = v^2 - 2 mu g (gap - v t_r / 2)
    assert motion.acceleration(t_r + 1e-3) == pytest.approx(-mu * G, rel=1e-12)
    v_impact = math.sqrt(v * v - 2 * mu * G * (gap - 0.5 * v * t_r))
    assert motion.v_impact == pytest.approx(v_impact, rel=1e-12)
    assert motion.t_impact == pytest.approx(t_r + (v - v_impact) / (mu * G), rel=1e-12)
    assert motion.displacement(motion.t_impact) == pytest.approx(gap, rel=1e-12)
    # reverse impulse over t_r to -e v_impact, then back to rest under friction
    assert motion.velocity(motion.t_impact + t_r) == pytest.approx(-e * v_impact, rel=1e-12)
    assert motion.acceleration(motion.t_impact + t_r + 1e-3) == pytest.approx(mu * G, rel=1e-12)
    assert motion.duration == pytest.approx(motion.t_impact + t_r + e * v_impact / (mu * G), rel=1e-12)
    assert motion.velocity(motion.duration + 1.0) == 0.0 and motion.acceleration(motion.duration + 1.0) == 0.0
    assert motion.velocity(-1.0) == 0.0 and motion.displacement(-1.0) == 0.0


def test_double_pulse_that_stops_short_of_the_stopper():
    v, mu = 0.3, 0.26
    motion = DoublePulse(v, 0.05, base_friction=mu)
    assert math.isnan(motion.t_impact)
    stop = 0.5 * v * motion.rise_time + v * v / (2 * mu * G)  # launch travel + v^2 / (2 mu g) < 0.05 m
    assert motion.displacement(10.0) == pytest.approx(stop, rel=1e-12)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"v_peak": 0.0, "gap": 0.03}, r"v_peak == 0.0, must be in \(0.0"),
        ({"v_peak": -1.0, "gap": 0.03}, "v_peak == -1.0"),
        ({"v_peak": 0.5, "gap": -0.01}, "gap == -0.01"),
        ({"v_peak": 2.0, "gap": 0.004}, "gap == 0.004 m, must be > v_peak"),
        ({"v_peak": 0.5, "gap": 0.03, "stopper_restitution": 1.5}, "stopper_restitution == 1.5"),
    ],
)
def test_double_pulse_rejects_bad_input(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DoublePulse(**kwargs)


# ----------------------------------------------------------------- geometry and scaling (002)


def test_specimens_and_scaling_follow_002():
    single1, single2 = DoublePulseRig("single", 1), DoublePulseRig("single", 2)
    assert single1.block_size == pytest.approx((0.010, 0.045)) and single2.block_size == pytest.approx((0.020, 0.090))
    assert DoublePulseRig("stack3", 2).block_size == pytest.approx((0.020, 0.030))
    # 002 line 179: p2 / p1 = 0.707 (three decimals)
    assert single2.p / single1.p == pytest.approx(0.707, abs=5e-4)
    # p = sqrt(3 g / 4R), R the half diagonal: the stack's outline is the single block's (10 x 45 mm)
    assert DoublePulseRig("stack3", 1).p == pytest.approx(math.sqrt(3 * G / (4 * math.hypot(0.005, 0.0225))))
    # geometric mass ratio 2^3 = 8 (002 measured 6.83 on the real blocks, line 179)
    assert single2.mass / single1.mass == pytest.approx(8.0)
    assert single1.mass == pytest.approx(2700 * 0.010 * 0.045 * 0.010)
    # T_d: rise time plus frictionless free travel (gap - v t_r / 2) / v
    assert single1.excitation_period(0.5, 0.03) == pytest.approx(0.005 + (0.03 - 0.00125) / 0.5)
    p_td, energy = single2.scaled(0.5, 0.03)
    assert p_td == pytest.approx(single2.p * single2.excitation_period(0.5, 0.03))
    assert energy == pytest.approx(0.5 * single2.mass * 0.25)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"specimen": "stack4"}, "specimen == 'stack4'"),
        ({"base": "moving"}, "base == 'moving'"),
        ({"scale": -1.0}, "scale == -1.0"),
        ({"friction": -0.1}, "friction == -0.1"),
        ({"dt": 0.01}, r"dt == 0.01, must be in \(0.0, 0.005\]"),
    ],
)
def test_rig_rejects_bad_settings(kwargs, match):
    with pytest.raises(ValueError, match=match):
        DoublePulseRig(**kwargs)


@pytest.mark.parametrize(
    ("gaps", "v_peaks", "match"),
    [
        ([], [0.5], "gaps has shape"),
        ([0.03, 0.01], [0.5], "gaps == .* strictly increasing"),
        ([-0.01, 0.02], [0.5], "every value must be finite and > 0"),
        ([0.02], [-0.5, 0.5], "v_peaks == .* > 0"),
        ([0.003, 0.02], [0.5, 1.5], "reach the stopper during the launch"),
    ],
)
def test_map_rejects_bad_grids(gaps, v_peaks, match):
    with pytest.raises(ValueError, match=match):
        DoublePulseRig().map(gaps, v_peaks, progress=False)


# ----------------------------------------------------------------- classification (synthetic)


@pytest.mark.parametrize(
    ("angles", "mode"),
    [
        ([0.01], "A"),
        ([1.57], "B_L"),          # CCW, fallen toward -x
        ([-1.6], "B_R"),
        ([0.0, 0.02, -0.01], "A"),
        ([0.0, 0.01, 1.4], "B_L"),   # top block only
        ([0.02, -1.5, -1.6], "C_R"),  # two upper blocks
        ([1.5, 1.6, 1.4], "D_L"),     # whole stack
        ([-1.5, 0.1, 1.6], "D_R"),    # lowest overturned block decides
    ],
)
def test_classify(angles, mode):
    assert classify(angles) == mode


def test_classify_rejects_other_stacks():
    with pytest.raises(ValueError, match=r"shape \(2,\)"):
        classify([0.0, 0.1])


def _state(t, angles, omegas, base_v=0.0, base_x=0.0, heights=0.0):
    """The 2D state of one cell (row 0 of the watch) with the base in row 0 and blocks in rows 1..
    (q: x, y, angle; v: vx, vy, omega), as a vectorized event is given it."""
    n = len(angles)
    q = np.zeros((n + 1, 3))
    v = np.zeros((n + 1, 3))
    q[0, 0], v[0, 0] = base_x, base_v
    q[1:, 1], q[1:, 2], v[1:, 2] = heights, angles, omegas
    return States(np.array([t]), q[None], v[None], np.array([0]))


def _block(index, inertia=1.0):
    """A synthetic 10 x 45 mm block of mass 1 kg standing at rest height 0.0225 m."""
    vertices = np.array([[-0.005, -0.0225], [0.005, -0.0225], [0.005, 0.0225], [-0.005, 0.0225]])
    return SimpleNamespace(index=index, mass=1.0, inertia=inertia, q0=np.array([0.0, 0.0225, 0.0]),
                           shape=SimpleNamespace(vertices=vertices))


def _rocking_history(watch, n_blocks, t_stop_motion=0.4, dt=1e-3):
    """Feed theta = 0.1 sin(10 t) (every block) until t_stop_motion, then rest; return the stop time."""
    for k in range(1, 1000):
        t = k * dt
        moving = t < t_stop_motion
        angle, omega = (0.1 * math.sin(10 * t), math.cos(10 * t)) if moving else (0.0, 0.0)
        # centres at the rest height: only the rotation carries energy
        state = _state(t, [angle] * n_blocks, [omega] * n_blocks, heights=0.0225)
        if watch.update(state)[0]:
            return t
    return None


def test_watch_records_the_rocking_phase_at_the_impact_and_rest():
    """Synthetic stack rocking theta = 0.1 sin(10 t), kinematic impact at t = 0.2 s, rest at 0.4 s."""
    dt = 1e-3
    base = SimpleNamespace(index=0, q0=np.zeros(3))
    watch = rigs._Watch([_block(1), _block(2), _block(3)], base, dt, t_impact=0.2, stopper_x=None,
                        rest_after=0.3)
    stopped = _rocking_history(watch, 3)
    # recorded at the last step before 0.2 s (within one dt)
    assert watch.theta_impact[0] == pytest.approx([0.1 * math.sin(10 * 0.2)] * 3, abs=1.0 * dt)
    assert watch.omega_impact[0] == pytest.approx([math.cos(10 * 0.2)] * 3, abs=10 * dt)
    assert watch.max_tilt[0] == pytest.approx([0.1] * 3, rel=1e-4)
    # a stack stops QUIET_TIME after everything is at rest
    assert stopped == pytest.approx(0.4 + watch.QUIET_TIME, abs=2 * dt)
    assert not watch.decided[0]


@pytest.mark.parametrize(("inertia", "stop"), [(1e-6, 0.3), (1.0, 0.4)])
def test_watch_stops_a_single_block_below_its_overturning_barrier(inertia, stop):
    # barrier m g (R - h/2) = 9.81 * (0.02305 - 0.0225) = 5.4e-3 J; rocking energy I omega^2 / 2 <= I / 2
    base = SimpleNamespace(index=0, q0=np.zeros(3))
    watch = rigs._Watch([_block(1, inertia)], base, 1e-3, t_impact=math.nan, stopper_x=None, rest_after=0.3)
    # small inertia: below the barrier as soon as the base rests (0.3 s); large: only when it stops (0.4 s)
    assert _rocking_history(watch, 1) == pytest.approx(stop, abs=2e-3)
    assert watch.decided[0]


def test_watch_detects_the_impact_of_a_dynamic_base():
    """Base at 0.5 m/s closes a 0.02 m gap at 40 ms and rebounds at -0.25 m/s; the block turns back then."""
    dt, v = 1e-3, 0.5
    base = SimpleNamespace(index=0, q0=np.zeros(3), mass=10.0)
    stopper_x = 0.1 + 0.02  # base half length 0.1 m + gap 0.02 m
    watch = rigs._Watch([_block(1)], base, dt, t_impact=math.nan, stopper_x=stopper_x, rest_after=0.0)
    for k in range(1, 100):
        t = k * dt
        before = v * t < 0.02 - 1e-12
        x = v * t if before else 0.02 - 0.25 * (t - 0.04)
        watch.update(_state(t, [0.05] if before else [0.04], [0.3] if before else [-0.3],
                            base_v=v if before else -0.25, base_x=x))
    assert watch.t_impact[0] == pytest.approx(0.02 / v, abs=dt)  # the gap closes at 40 ms
    assert watch.theta_impact[0, 0] == 0.05 and watch.omega_impact[0, 0] == 0.3  # the phase before the impact


def _stack_block(index, height=0.015):
    """A synthetic 10 x 15 mm block of mass 1 kg, the ``index``-th (from 1) of a column on y = 0."""
    vertices = np.array([[-0.005, -height / 2], [0.005, -height / 2], [0.005, height / 2], [-0.005, height / 2]])
    return SimpleNamespace(index=index, mass=1.0, inertia=1.0, q0=np.array([0.0, (index - 0.5) * height, 0.0]),
                           shape=SimpleNamespace(vertices=vertices))


def test_rocking_barrier_of_a_block_and_of_a_stack():
    # Housner's geometry: a rigid body rocking over a bottom corner lifts its centre by R - c
    barrier, limit = rigs._rocking_barrier([_block(1)], G)
    assert barrier == pytest.approx(G * (math.hypot(0.005, 0.0225) - 0.0225), rel=1e-12)
    assert limit == pytest.approx(math.atan(0.005 / 0.0225), rel=1e-12)
    # three 10 x 15 mm blocks of 1 kg: the top block over the middle one (1 kg, c = 7.5 mm), the
    # top two over the bottom one (2 kg, c = 15 mm), the column over the base (3 kg, c = 22.5 mm)
    lifts = [1 * (math.hypot(0.005, 0.0075) - 0.0075), 2 * (math.hypot(0.005, 0.015) - 0.015),
             3 * (math.hypot(0.005, 0.0225) - 0.0225)]
    barrier, limit = rigs._rocking_barrier([_stack_block(1), _stack_block(2), _stack_block(3)], G)
    assert barrier == pytest.approx(G * min(lifts), rel=1e-12)  # the top block alone: 1.51 mm of 1 kg
    assert limit == pytest.approx(0.5 * math.atan(0.005 / 0.0225), rel=1e-12)  # half the column's slenderness


def test_watch_stops_a_stack_below_its_barrier_and_a_single_block_lying():
    base = SimpleNamespace(index=0, q0=np.zeros(3))
    blocks = [_stack_block(1), _stack_block(2), _stack_block(3)]
    stacked = rigs._Watch(blocks, base, 1e-3, t_impact=math.nan, stopper_x=None, rest_after=0.1, stacked=True)
    heights = [b.q0[1] for b in blocks]
    state = _state(0.2, [0.02] * 3, [0.3] * 3, heights=heights)
    # kinetic energy 3 * 1 * 0.3^2 / 2 = 0.135 J, above the barrier 9.81 * 1.51e-3 = 0.0149 J
    assert not stacked.update(state)[0]
    state = _state(0.2, [0.02] * 3, [0.05] * 3, heights=heights)  # 3.75e-3 J: below, every tilt within 0.11 rad
    assert stacked(state).tolist() == [1.0] and stacked.decided[0]  # decided
    loose = rigs._Watch(blocks, base, 1e-3, t_impact=math.nan, stopper_x=None, rest_after=0.1)
    assert loose(state).tolist() == [-1.0]  # placements not nominal: the stack waits for rest
    lying = _state(0.05, [OVERTURN_ANGLE + 1e-3], [2.0], base_v=0.4)  # base still moving
    single = rigs._Watch([_block(1)], base, 1e-3, t_impact=math.nan, stopper_x=None, rest_after=0.3)
    assert not single.update(lying)[0]
    single = rigs._Watch([_block(1)], base, 1e-3, t_impact=math.nan, stopper_x=None, rest_after=0.3,
                         lying_stays=True)
    assert single.update(lying)[0] and single.decided[0]


@pytest.mark.parametrize("specimen", ["single", "stack3"])
def test_early_stops_keep_the_modes_of_full_length_runs(specimen):
    """The rig's terminal event stops a cell once its outcome is decided: the mode of every cell of
    a 3 x 3 map (every mode class of the specimen's map) equals that of a run to t_end = 1 s."""
    import warnings

    rig = DoublePulseRig(specimen)
    cases = [{"gap": gap, "v_peak": v} for gap in (0.005, 0.0275, 0.05) for v in (0.1, 0.8, 1.5)]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a few unconverged steps: counted in the outcomes
        early = rig.run_batch(cases)
        full = rig.run_batch([dict(case, stop_early=False) for case in cases])
    assert [o.mode for o in early] == [o.mode for o in full]
    assert all(o.t_stop == pytest.approx(1.0) for o in full)
    assert np.mean([o.t_stop for o in early]) < 0.4  # and the early stops do stop early
    assert len({o.mode for o in early}) >= 2


def test_outcome_row_and_ensemble_probabilities():
    out = rigs.Outcome("C_L", 0.06, (0.01, 0.02, 0.03), (1.0, 2.0, 3.0), (0.0, 1.5, 1.6),
                       (0.1, 1.5, 1.6), 0.8, True, 0)
    row = out.to_row()
    assert row["mode"] == "C_L" and row["theta_impact_2"] == 0.03 and row["omega_impact_0"] == 1.0
    ens = rigs.EnsembleOutcome(("A", "B_L", "B_L", "A", "D_R"))
    assert ens.probabilities["B_L"] == pytest.approx(0.4) and ens.probabilities["C_R"] == 0.0
    assert ens.mode == "A"  # tie A/B_L: first in MODES
    assert sum(ens.probabilities.values()) == pytest.approx(1.0)


# ----------------------------------------------------------------- CLI and plots without the engine


def test_parse_values():
    from nscd.cli import parse_values

    assert parse_values("0.005:0.05:10", "--gap") == pytest.approx(np.linspace(0.005, 0.05, 10).tolist())
    assert parse_values("0.1,0.2", "--v-peak") == [0.1, 0.2]
    with pytest.raises(ValueError, match="--gap == '0.05:0.005:20': start == 0.05 must be < stop"):
        parse_values("0.05:0.005:20", "--gap")
    with pytest.raises(ValueError, match="n == 1, must be >= 2"):
        parse_values("0.1:0.2:1", "--gap")
    with pytest.raises(ValueError, match="must be start:stop:n or a comma-separated"):
        parse_values("a:b", "--gap")


def test_cli_reports_bad_input_with_exit_code_2(tmp_path, capsys):
    from nscd.cli import main

    code = main(["map", "--gap", "0.05:0.005:4", "--v-peak", "0.1:1:3", "-o", str(tmp_path / "m.csv")])
    assert code == 2
    assert "nscd map: error: --gap == '0.05:0.005:4'" in capsys.readouterr().err
    code = main(["map", "--gap", "0.01:0.05:4", "--v-peak=-0.5,0.5", "-o", str(tmp_path / "m.csv")])
    assert code == 2 and "v_peaks == [-0.5, 0.5]" in capsys.readouterr().err


def test_mode_map_draws_one_series_per_mode_present():
    pytest.importorskip("matplotlib")
    from nscd.plot import maps
    from nscd.sweep import Table

    table = Table([{"gap": g, "v_peak": v, "status": "ok", "mode": m}
                   for g, v, m in [(0.01, 0.2, "A"), (0.02, 0.2, "A"), (0.01, 0.8, "B_R"), (0.02, 0.8, "B_L")]]
                  + [{"gap": 0.03, "v_peak": 0.8, "status": "failed", "mode": None}])
    ax = maps.mode_map(table).axes[0]
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    # each mode code with what it means (seed 002: lowest block fallen, side)
    assert labels == ["A: none falls", "B_L: top (or only) block falls, left",
                      "B_R: top (or only) block falls, right", "failed"]
    offsets = {c.get_label(): c.get_offsets() for c in ax.collections}
    np.testing.assert_allclose(offsets["A: none falls"], [[1.0, 0.2], [2.0, 0.2]])  # gap drawn in cm
    assert ax.get_xlabel() == "stop gap BD (cm)"


# ----------------------------------------------------------------- with the engine

G_PTFE = 0.26 * G  # friction deceleration of the base, m/s^2


def test_dynamic_base_alone_decelerates_at_mu_b_g_and_reaches_the_stopper_on_time():
    from nscd.stepper import simulate

    rig = DoublePulseRig("single", base="dynamic")
    v, gap, dt = 0.6, 0.03, 5e-4
    scene, blocks, base = rig.scene(v, gap, bare=True)
    assert blocks == []
    result = simulate(scene, 0.09, dt)
    t, u = result.time, result.velocity(base)[:, 0]
    closed = DoublePulse(v, gap)  # same launch, friction and stopper, in closed form
    free = (t > 2 * rig.rise_time + 2 * dt) & (t < closed.t_impact - 2 * dt)  # pusher gone, before the stopper
    slope = np.polyfit(t[free], u[free], 1)[0]
    assert slope == pytest.approx(-G_PTFE, rel=5e-3)  # 0.5 %, the accuracy target
    # the base touches the stopper within one step of the closed-form time (first-order impact timing)
    k = np.argmax(u < 0.0)  # first state after the reverse impact
    assert t[k - 1] - dt <= closed.t_impact <= t[k] + dt
    # Newton's restitution on the stopper: rebound = -e_s * approach speed (2 % for the step's friction)
    assert u[k] == pytest.approx(-rig.stopper_restitution * closed.v_impact, rel=2e-2)


def _critical_impulse(width, height):
    """Velocity jump that just overturns a free-standing block (impulsive Housner, no friction on the base).

    Angular momentum about the pivot corner: omega0 = dV (h/2) / (4 R^2 / 3); overturning needs
    omega0^2 >= 2 p^2 (1 - cos alpha), p^2 = 3 g / (4 R), R the half diagonal.
    """
    R = math.hypot(width / 2, height / 2)
    alpha = math.atan(width / height)
    omega = math.sqrt(2 * 3 * G / (4 * R) * (1 - math.cos(alpha)))
    return omega * (4 * R * R / 3) / (height / 2)


def test_no_overturning_well_below_the_impulsive_threshold():
    rig = DoublePulseRig("single")
    v = 0.4 * _critical_impulse(*rig.block_size)  # 0.4: clear of the threshold; the ramp and friction only help
    for gap in (0.01, 0.05):
        out = rig.run(v, gap, t_end=0.4)  # the base is at rest after 0.03 s; the rocking only decays
        assert out.mode == "A", (gap, out)
        assert out.max_tilt[0] < math.atan(10 / 45)  # never near its slenderness angle


def test_reverse_pulse_at_small_gap_keeps_standing_a_block_that_falls_at_large_gap():
    rig = DoublePulseRig("single")
    v = 0.3  # 2.4 x the impulsive threshold (0.123 m/s for 10 x 45 mm)
    far = rig.run(v, 0.05)  # the base stops 17.6 mm after launch: no reverse pulse
    assert math.isnan(far.t_impact)
    assert far.mode == "B_L"  # thrown to the side opposite to the first push (002, Figure 24)
    near = rig.run(v, 0.008, t_end=0.6)  # base at rest after 0.03 s; 0.6 s is many rocking periods
    # the stopper hits while the block still leans left and turns left: the reverse push stops it
    assert near.theta_impact[0] > 0 and near.omega_impact[0] > 0
    assert near.mode == "A"


@pytest.mark.slow
def test_scale_2_needs_a_larger_peak_velocity_than_scale_1():
    # 0.2 m/s, no reverse pulse: between the thresholds of the two scales (they scale like sqrt(size))
    small, large = DoublePulseRig("single", 1).run(0.2, 0.05), DoublePulseRig("single", 2).run(0.2, 0.05)
    assert small.mode != "A" and large.mode == "A"
    assert _critical_impulse(0.02, 0.09) / _critical_impulse(0.01, 0.045) == pytest.approx(math.sqrt(2))


@pytest.mark.slow
def test_three_block_stacks_show_partial_modes():
    # 002 (Figures 17, 19, 25): partial overturning where the reverse pulse catches the bottom block
    rig = DoublePulseRig("stack3")
    modes = {rig.run(v, gap).mode for v, gap in ((0.5, 0.0114), (0.5, 0.0179), (0.7, 0.0179))}
    assert modes & {"B_L", "B_R", "C_L", "C_R"}, modes


def test_rig_run_in_a_sweep_records_the_rig_settings(tmp_path):
    import json
    import pickle

    from nscd import sweep

    rig = DoublePulseRig("single")
    pickle.dumps(rig.run)  # process pools need it
    # t_end 0.02 s: before the stopper (impact at 46 ms for 0.8 m/s, 0.035 m) and before any fall
    table = sweep.grid(rig.run, {"gap": [0.035], "v_peak": [0.05, 0.8]}, out=tmp_path / "m.csv",
                       fixed={"t_end": 0.02}, executor=sweep.SerialExecutor(), progress=False)
    assert table["mode"].tolist() == ["A", "A"]
    assert np.isnan(table["theta_impact_0"]).all()
    assert table["t_stop"] == pytest.approx([0.02, 0.02])
    # the strong launch throws the block left (CCW, angle > 0); the weak one cannot lift it past 0.02 rad
    assert table["max_tilt_0"][1] > 0.05 and table["theta_final_0"][1] > 0
    settings = json.loads((tmp_path / "m.csv.json").read_text())["settings"]["object"]
    assert settings["specimen"] == "single" and settings["base_friction"] == 0.26


def test_ensemble_members_are_reproducible_and_perturbed():
    rig = DoublePulseRig("stack3")
    a, b, c = (rig.run(0.5, 0.03, t_end=0.01, seed=s) for s in (7, 7, 8))
    assert a.theta_final == b.theta_final  # same seed, same draws, same deterministic run
    assert a.theta_final != c.theta_final
    ensemble = rig.ensemble(0.05, 0.03, n=2, t_end=0.01)
    assert ensemble.modes == ("A", "A") and ensemble.probabilities["A"] == 1.0


def test_scaled_and_probability_maps_place_cells_on_002_axes():
    pytest.importorskip("matplotlib")
    from nscd.plot import maps
    from nscd.sweep import Table

    rig1, rig2 = DoublePulseRig("single", 1), DoublePulseRig("single", 2)
    table = Table([{"gap": 0.02, "v_peak": 0.5, "status": "ok", "mode": "B_L"},
                   {"gap": 0.04, "v_peak": 0.2, "status": "ok", "mode": "A"}])
    ax = maps.scaled_map([table, table], [rig1, rig2]).axes[0]
    points = {c.get_label(): c.get_offsets() for c in ax.collections}
    np.testing.assert_allclose(points["scale 1: overturning"], [rig1.scaled(0.5, 0.02)])
    np.testing.assert_allclose(points["scale 2: no overturning"], [rig2.scaled(0.2, 0.04)])
    ensemble = Table([{"gap": g, "v_peak": v, "status": "ok", "mode": "A", "p_A": 1.0 - 0.25 * k}
                      for k, (g, v) in enumerate([(0.01, 0.2), (0.02, 0.2), (0.01, 0.4), (0.02, 0.4)])])
    ax = maps.probability_map(ensemble).axes[0]
    shading = ax.collections[0].get_array()
    np.testing.assert_allclose(np.ravel(shading), [0.0, 0.25, 0.5, 0.75])  # 1 - p_A, row by v_peak
    with pytest.raises(ValueError, match="no column 'p_A'"):
        maps.probability_map(table)


@pytest.mark.parametrize("base", ["kinematic", "dynamic"])
def test_stopper_inside_the_base_or_the_launch_is_refused(base):
    rig = DoublePulseRig(base=base)
    with pytest.raises(ValueError, match="gap == -0.01, must be in"):
        rig.scene(0.5, -0.01)
    with pytest.raises(ValueError, match="gap == 0.001 m, must be > v_peak"):
        rig.run(0.5, 0.001)


def test_watch_does_not_call_a_block_past_its_slenderness_safe():
    # tilted 0.3 rad > alpha = atan(10/45) = 0.219 rad: falling even with little energy
    base = SimpleNamespace(index=0, q0=np.zeros(3))
    watch = rigs._Watch([_block(1)], base, 1e-3, t_impact=math.nan, stopper_x=None, rest_after=0.0)
    state = _state(0.5, [0.3], [0.1], heights=0.0225)  # energy ~ 0, far below the barrier
    assert not watch.update(state)[0] and not watch.decided[0]


# ----------------------------------------------------------------- friction, mass ratio, convergence (002)


def _pivot_slip(rig: DoublePulseRig, v_peak: float, gap: float) -> float:
    """Path (m) slid along the base by the block corners while they touch it, up to the reverse impact."""
    out = rig.run(v_peak, gap, t_end=1.0, keep_result=True)
    res = out.result
    t, centre, angle = res.time, res.position("block0"), res.angle("block0")
    base_x = res.position("base")[:, 0]
    width, height = rig.block_size
    slid = 0.0
    for side in (-1.0, 1.0):
        x = centre[:, 0] + side * width / 2 * np.cos(angle) + height / 2 * np.sin(angle) - base_x
        y = centre[:, 1] + side * width / 2 * np.sin(angle) - height / 2 * np.cos(angle)
        touching = (y < 1e-6) & (t <= out.t_impact)  # base top at y = 0; 1 um: the solver's gaps are far smaller
        both = touching[1:] & touching[:-1]
        slid += float(np.sum(np.abs(np.diff(x))[both]))
    return slid


def test_default_friction_prevents_sliding_as_in_002s_simulations():
    """002 line 106: the SOLFEC simulations used a high friction "to prevent inter block sliding".

    Figure 23's run (single block, scale 1, v_peak 0.59 m/s, BD 2.0 cm): the launch accelerates
    the base at v_peak / 5 ms = 12 g, far beyond what the measured friction 0.54 can transmit to a
    block that is not yet rocking, so at 0.54 the pivot slides by millimetres; the default must not.
    """
    assert DoublePulseRig().friction == rigs.SIMULATED_FRICTION
    # 1 um: a thousandth of the block's 10 mm width, far above the solver's residual slip
    assert _pivot_slip(DoublePulseRig("single"), 0.59, 0.02) < 1e-6
    # 1 mm: a tenth of the block width, a sliding that changes the rocking (measured: 7.7 mm)
    assert _pivot_slip(DoublePulseRig("single", friction=rigs.MEASURED_FRICTION), 0.59, 0.02) > 1e-3


def test_measured_mass_ratio_of_002():
    """002 line 179: m2/m1 = 6.83 measured for the two scales (8 for geometric similarity)."""
    for specimen in ("single", "stack3"):
        small = DoublePulseRig(specimen, 1.0)
        assert DoublePulseRig(specimen, 2.0).mass / small.mass == pytest.approx(8.0, rel=1e-12)
        measured = DoublePulseRig(specimen, 2.0, mass_ratio="measured")
        assert measured.mass / small.mass == pytest.approx(6.83, rel=1e-12)
        assert DoublePulseRig(specimen, 1.0, mass_ratio="measured").mass == small.mass
        # the energy axis of the scaled maps (002 Figs. 13-14, 20-21) carries the mass
        assert measured.scaled(0.6, 0.03)[1] / DoublePulseRig(specimen, 2.0).scaled(0.6, 0.03)[1] == \
            pytest.approx(6.83 / 8.0, rel=1e-12)
    with pytest.raises(ValueError, match="mass_ratio == 'weighed'"):
        DoublePulseRig(mass_ratio="weighed")
    with pytest.raises(ValueError, match="scale == 3.0 with mass_ratio == 'measured'"):
        DoublePulseRig(scale=3.0, mass_ratio="measured")
    with pytest.raises(ValueError, match="scheme == 'rk4'"):
        DoublePulseRig(scheme="rk4")


@pytest.mark.parametrize(("specimen", "v_peak", "gap", "mode"), [
    ("single", 0.56, 0.030, "B_L"),   # 002 Figure 24: rocks left, turns back at the reverse impact, falls left
    ("stack3", 0.54, 0.030, "D_L"),   # 002 Figure 26: the reverse impact comes late, the whole stack falls left
])
def test_figures_24_and_26_of_002_converged(specimen, v_peak, gap, mode):
    """The experiments of 002 Figs. 24 and 26, with the rig as 002 simulated it (high friction).

    Figs. 23 and 25 (B_R, C_L) are not matched by the rigid model; the benchmark
    benchmarks/bench_double_pulse.py reports all four and why.
    """
    check = DoublePulseRig(specimen).run_verified(v_peak, gap)
    assert check.converged, check.changes
    assert check.outcome["mode"] == mode


def test_map_with_verify_dt_marks_each_cell():
    from nscd.sweep import SerialExecutor

    rig = DoublePulseRig("single")
    table = rig.map([0.03], [0.1, 0.56], executor=SerialExecutor(), progress=False, verify_dt=True, t_end=0.6)
    # 0.1 m/s: far below the impulsive threshold; 0.56 m/s at BD 3.0 cm: the experiment of 002 Fig. 24
    assert list(table["mode"]) == ["A", "B_L"]
    assert {"converged", "changes"} <= set(table.names)
    assert all(isinstance(c, (bool, np.bool_)) for c in table["converged"])
    assert table["converged"][1]  # as test_figures_24_and_26_of_002_converged finds at t_end = 1 s
    with pytest.raises(ValueError, match="verify_dt == True with batch == True"):
        rig.map([0.02], [0.5], progress=False, verify_dt=True, batch=True)


def test_mode_map_rings_unconverged_cells():
    pytest.importorskip("matplotlib")
    from nscd.plot import maps
    from nscd.sweep import Table

    table = Table([{"gap": 0.01, "v_peak": 0.2, "status": "ok", "mode": "A", "converged": True},
                   {"gap": 0.02, "v_peak": 0.8, "status": "ok", "mode": "B_L", "converged": False}])
    ax = maps.mode_map(table).axes[0]
    offsets = {c.get_label(): c.get_offsets() for c in ax.collections}
    np.testing.assert_allclose(offsets["unconverged"], [[2.0, 0.8]])
    assert "unconverged" in [t.get_text() for t in ax.get_legend().get_texts()]
