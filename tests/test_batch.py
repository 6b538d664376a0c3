"""The batched sweep mode (nscd.batch): scenes advanced together equal the same scenes run one by one.

The reference is the single-scene engine itself (``nscd.simulate`` / ``Simulator`` /
``DoublePulseRig.run``), whose physics the engine tests validate against theory. The
batch must reproduce it, not approximate it: every per-scene quantity is computed by the
same floating-point operations (see the module docstring of nscd.batch), so the
comparisons below are exact (tolerance 0). A looser tolerance would hide a real
difference: on the rocking stacks of the double-pulse rig, a difference of one unit in
the last place grows to 1e-10 rad within a few hundred steps and may flip a mode near a
boundary of the map.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import replace

import numpy as np
import pytest

import nscd
from nscd.batch import BatchSimulator, check_same_structure, simulate_batch
from nscd.motion import OneSine
from nscd.result import SolverFailure
from nscd.rigs import DoublePulse, DoublePulseRig
from nscd.scene import Scene
from nscd.shapes import box
from nscd.solver import SolverSettings
from nscd.model import Model
from nscd.state import Drives, WarmStart, WarmStarts
from nscd.stepper import Settings
from nscd.sweep import SerialExecutor, grid

STACK = DoublePulseRig(specimen="stack3", scale=1)
DT = STACK.dt


def stack_scene(v_peak: float, gap: float) -> Scene:
    return STACK.scene(v_peak, gap)[0]


def rocking_scene(amplitude: float, height: float = 0.0, angle: float = 0.0) -> Scene:
    """A 0.2 x 0.6 m block on a base shaken by one sine pulse (no batched kinematics:
    the scene-by-scene path of the prescribed motions), optionally dropped from ``height``."""
    scene = Scene()
    scene.add_base(box(2.0, 0.1), position=(0.0, -0.05), motion=OneSine(amplitude, omega=2 * math.pi * 2.0))
    scene.add_block(box(0.2, 0.6), position=(0.0, 0.3 + height), angle=angle, name="block")
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def assert_same_result(batched: nscd.Result, single: nscd.Result) -> None:
    """Exact equality (same arithmetic): histories, impacts and solver reports."""
    np.testing.assert_array_equal(batched.time, single.time)
    np.testing.assert_array_equal(batched.q, single.q)
    np.testing.assert_array_equal(batched.v, single.v)
    np.testing.assert_array_equal(batched.dissipated, single.dissipated)
    assert batched.impacts.keys() == single.impacts.keys()
    for key in single.impacts:
        np.testing.assert_array_equal(batched.impacts[key], single.impacts[key], err_msg=f"impacts[{key!r}]")
    for name in ("iterations", "merit", "n_contacts", "n_active", "unconverged_times"):
        np.testing.assert_array_equal(getattr(batched.report, name), getattr(single.report, name), err_msg=name)
    assert batched.report.statuses == single.report.statuses


def test_stack_scenes_equal_single_runs():
    """Three-block stacks under different double pulses: rocking, impacts split at their own
    closing times (a different instant in each scene), stacks falling apart."""
    cells = [(0.3, 0.04), (0.8, 0.02), (1.2, 0.01)]
    t_end = 0.12
    scenes = [stack_scene(v, g) for v, g in cells]
    batched = simulate_batch(scenes, t_end, DT)
    for (v, g), scene, result in zip(cells, scenes, batched):
        single = nscd.simulate(scene, t_end, DT)
        assert_same_result(result, single)
    # the comparison is not vacuous: the scenes differ, and the stacks do rock and land
    assert not np.array_equal(batched[0].q[-1], batched[1].q[-1])
    assert all(len(r.impacts["time"]) > 0 for r in batched[1:])


def test_different_contact_counts_and_scene_by_scene_motions():
    """One block resting, one rocking, one dropped from 30 mm (beyond the detection margin) (no contact, then an impact):
    scenes with different numbers of contacts in one step, and motions without batched kinematics."""
    scenes = [rocking_scene(0.5), rocking_scene(6.0), rocking_scene(3.0, height=0.03, angle=0.01)]
    t_end = 0.25
    batched = simulate_batch(scenes, t_end, 1e-3)
    for scene, result in zip(scenes, batched):
        assert_same_result(result, nscd.simulate(scene, t_end, 1e-3))
    counts = np.array([r.report.n_contacts for r in batched])
    assert (counts[2, :10] == 0).all() and (counts[0, :10] > 0).all()  # the dropped block starts in the air
    assert len(batched[2].impacts["time"]) >= 1  # ...and lands
    assert np.max(np.abs(batched[1].angle("block"))) > 0.01  # the strong pulse rocks the block


def test_unconverged_steps_reported_per_scene_as_in_single_runs():
    """A starved solver (one Newton iteration, one conic solve, no proximal point, no polish, no
    regimes) fails on some steps: the same steps of the same scenes as in single runs, warned or
    raised naming the scene."""
    starved = Settings(solver=SolverSettings(max_fast=1, max_fixed_point=1, max_proximal=0, polish=False,
                                             regime_contacts=0))
    scenes = [stack_scene(0.3, 0.04), stack_scene(1.2, 0.01)]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        batched = simulate_batch(scenes, 0.03, DT, settings=starved)
        single = [nscd.simulate(scene, 0.03, DT, settings=starved) for scene in scenes]
    for result, reference in zip(batched, single):
        assert_same_result(result, reference)
    assert sum(r.report.n_unconverged for r in batched) > 0  # the solver was starved indeed
    messages = [str(w.message) for w in caught]
    failing = [k for k, r in enumerate(batched) if r.report.n_unconverged]
    assert any(m.startswith(f"scene {failing[0]}: contact solver did not converge") for m in messages)
    sim = BatchSimulator(scenes, DT, replace(starved, on_failure="raise"))
    with pytest.raises(SolverFailure, match=r"scene \d: contact solver did not converge"):
        sim.run(until=0.03)


def test_scene_stopped_early_costs_nothing_and_keeps_its_state():
    scenes = [stack_scene(0.8, 0.02), stack_scene(0.5, 0.03)]
    sim = BatchSimulator(scenes, DT)
    for _ in range(40):
        sim.step()
    sim.stop(1)
    frozen = sim.state(1)
    for _ in range(40):
        stepped = sim.step()
        assert stepped.tolist() == [0]
    np.testing.assert_array_equal(sim.q[1], frozen.q)
    assert sim.t[1] == frozen.t
    results = sim.results()
    assert len(results[0].time) == 81 and len(results[1].time) == 41
    single = [nscd.Simulator(scene, DT) for scene in scenes]
    single[0].run(until=80 * DT)
    single[1].run(until=40 * DT)
    for result, reference in zip(results, single):
        assert_same_result(result, reference.result())
    sim.stop(0)
    assert sim.step().size == 0


def test_small_double_pulse_map_same_modes_and_outcomes():
    """A 2 x 3 map (0.25 s per cell): every Outcome field equal to the cell-by-cell map."""
    gaps, v_peaks = [0.005, 0.04], [0.4, 0.9, 1.4]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # unconverged steps are compared below
        single = STACK.map(gaps, v_peaks, t_end=0.25, executor=SerialExecutor(), progress=False)
        batched = STACK.map(gaps, v_peaks, t_end=0.25, executor=SerialExecutor(), progress=False, batch=True)
    assert batched.names == single.names
    for row_b, row_s in zip(batched.rows, single.rows):
        assert str(row_b) == str(row_s)  # str: nan fields compare equal
    modes = set(batched["mode"].tolist())
    assert len(modes) >= 2, modes  # the map is not trivially uniform


def test_run_batch_stops_each_cell_like_run():
    """Cells with different t_end and an early stop at rest: same t_stop as run()."""
    cases = [dict(v_peak=0.1 + 1.4 / 3, gap=0.035, t_end=0.3), dict(v_peak=1.0, gap=0.01, t_end=0.05)]
    decided = []  # on_result: each cell once, as soon as it is decided, the outcome it ends with
    outcomes = STACK.run_batch(cases, on_result=lambda k, outcome: decided.append((k, outcome)))
    assert [k for k, _ in decided] == [1, 0]  # the short cell first
    for k, outcome in decided:
        assert str(outcome.to_row()) == str(outcomes[k].to_row())
    for case, outcome in zip(cases, outcomes):
        assert str(outcome.to_row()) == str(STACK.run(**case).to_row())
    assert outcomes[0].settled and outcomes[0].t_stop < 0.29  # stopped early: the stack fell and came to rest
    assert outcomes[1].t_stop == pytest.approx(0.05, abs=DT / 2)  # ran to its own t_end
    assert STACK.run_batch([]) == []
    with pytest.raises(ValueError, match=r"cases\[0\] has keys"):
        STACK.run_batch([dict(v_peak=0.5)])
    with pytest.raises(ValueError, match="base == 'dynamic': run_batch needs base == 'kinematic'"):
        DoublePulseRig(base="dynamic").run_batch([dict(v_peak=0.5, gap=0.02)])


def test_scenes_of_different_structure_raise():
    base = rocking_scene(1.0)
    heavier = Scene()
    heavier.add_base(box(2.0, 0.1), position=(0.0, -0.05), motion=OneSine(1.0, omega=4.0))
    heavier.add_block(box(0.2, 0.6), position=(0.0, 0.3), density=3000.0, name="block")
    heavier.set_contact(friction=0.6, restitution=0.0)
    with pytest.raises(ValueError, match=r"scenes\[1\] differs from scenes\[0\]: body 1 \('block'\) mass"):
        check_same_structure([base, heavier])
    slippery = rocking_scene(1.0)
    slippery.set_contact(friction=0.3, restitution=0.0)
    with pytest.raises(ValueError, match=r"scenes\[2\] differs .* contact law .* bodies 0 and 1"):
        BatchSimulator([base, rocking_scene(2.0), slippery], 1e-3)
    with pytest.raises(ValueError, match=r"scenes\[1\] differs .* 4 bodies, scenes\[0\] has 2"):
        check_same_structure([base, stack_scene(0.5, 0.02)])
    with pytest.raises(ValueError, match="scenes is empty"):
        check_same_structure([])
    with pytest.raises(ValueError, match="dt == 0"):
        BatchSimulator([base], 0.0)
    with pytest.raises(ValueError, match="record == False"):
        BatchSimulator([base], 1e-3, record=False).results()


@pytest.mark.parametrize("family", ["double pulse", "one-sine", "harmonic", "record", "scaled, vertical"])
def test_driven_poses_equal_each_bodys_prescribed_pose(family):
    """The compiled posing of driven bodies over a batch (``Drives.write``: the double-pulse base,
    the ready pulses, harmonics and records, scaled, with a vertical motion) equals each body's
    own ``Body.prescribed`` (its motion's scalar evaluation), bit for bit."""
    record = nscd.Record.example()
    motions = {
        "double pulse": [DoublePulse(v, g) for v in (0.2, 0.7, 1.5) for g in (0.005, 0.02, 0.05)],
        "one-sine": [OneSine(a, omega=w) for a in (0.5, 2.0, 9.0) for w in (3.0, 12.0, 40.0)],
        "harmonic": [nscd.Harmonic(a, frequency=f, cycles=3) for a in (0.5, 2.0, 9.0) for f in (1.0, 2.5, 7.0)],
        "record": [record.scaled(f) for f in (0.5, 1.0, 2.0)] + [record.reversed()],
        "scaled, vertical": [nscd.motion.Scaled(OneSine(a, omega=7.0), 0.3) for a in (1.0, 4.0)],
    }[family]
    scenes = []
    for m in motions:
        scene = Scene()
        scene.add_base(box(4.0, 0.2), (0.0, -0.1), motion=m,
                       vertical=OneSine(1.5, omega=20.0) if family == "scaled, vertical" else None)
        scene.add_block(box(0.4, 1.0), (0.1, 0.5))
        scenes.append(scene)
    model = Model.from_scene(scenes[0])
    drives = Drives(model, scenes)
    assert drives.everywhere
    rows = np.array([len(motions) - 1, 0, 1, 1])  # any subset, in any order, repeats allowed
    for t in np.cumsum(np.full(1200, DT))[::3]:
        q, v = np.zeros((len(rows), 2, 3)), np.zeros((len(rows), 2, 3))
        drives.write(rows, np.full(len(rows), t), q, v)
        for k, row in enumerate(rows.tolist()):
            expected = scenes[row].bodies[0].prescribed(t)
            np.testing.assert_array_equal(q[k, 0], expected[0])
            np.testing.assert_array_equal(v[k, 0], expected[1])


def _warm_start(rng, n: int, trend: bool) -> WarmStart:
    """n contacts with distinct ids (body_a, body_b, feature) and random impulses (N s, 2D)."""
    ids = np.array([[0, 1 + k // 4, k % 4] for k in range(n)], dtype=np.int64).reshape(-1, 3)
    impulses = rng.standard_normal((n, 2))
    return WarmStart(ids, impulses, rng.standard_normal((n, 2)) if trend else None, bool(rng.integers(2)))


def test_warm_starts_of_a_batch_as_arrays_equal_each_scene_s():
    """The warm starts of B scenes laid end to end give each scene the WarmStart it would hold alone:
    selected, replaced and followed by a next step, scene by scene against WarmStart's own methods."""
    rng = np.random.default_rng(3)
    scenes = [_warm_start(rng, n, trend) for n, trend in ((3, True), (0, False), (5, False), (2, True), (4, True))]
    warm = WarmStarts.stack(scenes, 2)

    def same(a: WarmStart, b: WarmStart) -> None:
        np.testing.assert_array_equal(a.ids, b.ids)
        np.testing.assert_array_equal(a.impulses, b.impulses)
        assert (a.trend is None) == (b.trend is None)
        assert a.linear == b.linear
        if a.trend is not None:
            np.testing.assert_array_equal(a.trend, b.trend)

    for k, scene in enumerate(scenes):
        same(warm[k], scene)
    picked = np.array([4, 1, 0])
    selected = warm.rows(picked)
    for j, k in enumerate(picked):
        same(selected[j], scenes[k])
    # the next step of scenes 0, 1 and 4: a contact kept (its trend: the change), one new (trend 0), one gone
    kept = [scenes[0].ids[1], scenes[0].ids[2]], [], [scenes[4].ids[0]]
    nxt = [np.array(ids + [[7, 8, 1]], dtype=np.int64).reshape(-1, 3) for ids in kept]
    impulses = [rng.standard_normal((len(ids), 2)) for ids in nxt]
    bounds = np.cumsum([0] + [len(ids) for ids in nxt])
    stepped = np.array([0, 1, 4])
    followed = warm.rows(stepped).followed_by(np.concatenate(nxt), np.concatenate(impulses), bounds)
    updated = warm.updated(stepped, followed)
    for k, scene in enumerate(scenes):
        if k in stepped:
            j = list(stepped).index(k)
            # alone: a scene without impulses before has no trend (WarmStart(ids, impulses))
            expected = scene.followed_by(nxt[j], impulses[j]) if len(scene) else WarmStart(nxt[j], impulses[j])
            same(updated[k], expected)
        else:
            same(updated[k], scene)
    assert updated[0].trend[0].tolist() == (impulses[0][0] - scenes[0].impulses[1]).tolist()
    assert updated[0].trend[2].tolist() == [0.0, 0.0]  # the new contact


@pytest.mark.parametrize("n_known, n_wanted", [(6, 5), (40, 30)])  # compared directly; hashed (> 256 pairs)
def test_warm_start_finds_each_id_s_last_row(n_known, n_wanted):
    """WarmStart.find returns, for each wanted id, the last row of the known ids holding it (a contact
    seen twice in a step split at impacts keeps its latest impulse), and whether there is one."""
    rng = np.random.default_rng(11)
    known = rng.integers(0, 2, size=(n_known, 3)).astype(np.int64)  # 8 distinct ids at most: repeats
    # known ids, and two never known (body 9), in random order
    wanted = rng.permutation(np.vstack([known[rng.integers(0, n_known, n_wanted - 2)], [[9, 1, 0], [0, 9, 2]]]))
    found, hit = WarmStart(known, np.zeros((n_known, 2))).find(wanted)
    for k, row in enumerate(wanted.tolist()):
        rows = [j for j, id_ in enumerate(known.tolist()) if id_ == row]
        assert hit[k] == bool(rows)
        if rows:
            assert found[k] == rows[-1]
    assert hit.any() and not hit.all()  # both cases met...
    assert len(np.unique(known, axis=0)) < n_known  # ...and ids known twice


# -- the batched grid of nscd.sweep -------------------------------------------------------


def _square(x: float) -> dict:
    if x < 0:
        raise ValueError(f"x == {x}, must be >= 0.")
    return {"y": x * x}


def _squares(cases: list[dict]) -> list[dict]:
    return [_square(**case) for case in cases]


def test_grid_batch_equals_cell_by_cell(tmp_path):
    params = {"x": [0.5, 1.0, 2.0, 3.0, 4.0]}
    single = grid(_square, params, executor=SerialExecutor(), progress=False)
    batched = grid(_squares, params, out=tmp_path / "b.csv", executor=SerialExecutor(), progress=False,
                   batch=True, chunks=2)
    assert batched.rows == single.rows
    again = grid(_squares, params, out=tmp_path / "b.csv", executor=SerialExecutor(), progress=False,
                 batch=True, chunks=2)  # resumed: nothing left to run
    assert again.rows == single.rows


def test_grid_batch_failure_marks_every_cell_of_the_call():
    with pytest.warns(RuntimeWarning, match="cells failed"):
        table = grid(_squares, {"x": [1.0, -1.0, 2.0, 3.0]}, executor=SerialExecutor(), progress=False,
                     batch=True, chunks=2)
    # chunk 0 holds cells 0 and 2 (fine), chunk 1 cells 1 and 3 (cell 1 raises)
    assert table["status"].tolist() == ["ok", "failed", "ok", "failed"]
    assert "x == -1.0, must be >= 0." in table.rows[3]["error"]
    with pytest.raises(ValueError, match="chunks == 0"):
        grid(_squares, {"x": [1.0]}, executor=SerialExecutor(), progress=False, batch=True, chunks=0)


def test_cli_map_batch_writes_the_same_csv(tmp_path, capsys):
    from nscd.cli import main

    common = ["map", "--specimen", "single", "--gap", "0.02", "--v-peak", "0.3,1.2", "--t-end", "0.1",
              "--jobs", "1", "--quiet"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        assert main(common + ["-o", str(tmp_path / "one.csv")]) == 0
        assert main(common + ["-o", str(tmp_path / "batch.csv"), "--batch"]) == 0
    assert (tmp_path / "batch.csv").read_text() == (tmp_path / "one.csv").read_text()
    assert main(common + ["-o", str(tmp_path / "e.csv"), "--batch", "--ensemble", "2"]) == 2
    assert "batch == True" in capsys.readouterr().err


# --- one step for single and batched runs: both schemes, 2D and 3D, large problems ------------


@pytest.mark.parametrize("scheme", ["theta", "midpoint"])
def test_batched_runs_equal_single_runs_for_both_schemes(scheme):
    """Rocking blocks and a dropped block under both schemes: impacts localised inside the
    step (split at each scene's own closing time), bit for bit as single runs."""
    settings = Settings(scheme=scheme)
    scenes = [rocking_scene(6.0), rocking_scene(3.0, height=0.03, angle=0.01), rocking_scene(0.5)]
    batched = simulate_batch(scenes, 0.25, 1e-3, settings=settings)
    for scene, result in zip(scenes, batched):
        assert_same_result(result, nscd.simulate(scene, 0.25, 1e-3, settings=settings))
    assert len(batched[1].impacts["time"]) >= 1  # the dropped block lands inside a step
    assert np.max(np.abs(batched[0].angle("block"))) > 0.01  # the strong pulse rocks the block


def block_3d(amplitude: float, height: float = 0.0) -> Scene:
    """A 0.2 x 0.3 x 0.8 m block on a base shaken by one sine pulse along x (3D), optionally dropped."""
    scene = Scene(dim=3)
    scene.add_base(box(2.0, 2.0, 0.1), position=(0.0, 0.0, -0.05),
                   motion=OneSine(amplitude, omega=2 * math.pi * 2.0))
    scene.add_block(box(0.2, 0.3, 0.8), position=(0.0, 0.0, 0.4 + height), orientation=(1.0, 0.0, 0.0, 0.0),
                    name="block")
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


@pytest.mark.parametrize("scheme", ["theta", "midpoint"])
def test_batched_3d_runs_equal_single_runs(scheme):
    """3D: a block rocked by a pulse and a block dropped onto the base, batched and alone."""
    settings = Settings(scheme=scheme)
    scenes = [block_3d(8.0), block_3d(2.0, height=0.02)]
    batched = simulate_batch(scenes, 0.12, 2e-3, settings=settings)
    for scene, result in zip(scenes, batched):
        assert_same_result(result, nscd.simulate(scene, 0.12, 2e-3, settings=settings))
    assert len(batched[1].impacts["time"]) >= 1  # the dropped block lands inside a step
    assert not np.array_equal(batched[0].q[-1], batched[1].q[-1])


def test_batched_large_problems_equal_single_runs():
    """A 4 x 5 running-bond wall shaken at 8 m/s^2 (more than 120 contact unknowns: the
    Gauss-Seidel path with each scene's own coarse correction), batched and alone."""
    from nscd.builders import wall
    from nscd.motion import Harmonic

    scenes = [wall(4, 5, 0.4, 0.2, motion=Harmonic(amplitude=a, frequency=4.0, ramp_cycles=1.0))[0]
              for a in (8.0, 6.0)]
    batched = simulate_batch(scenes, 0.1, 1e-3)
    for scene, result in zip(scenes, batched):
        assert_same_result(result, nscd.simulate(scene, 0.1, 1e-3))
    assert batched[0].report.n_active.max() * 2 > SolverSettings().large_problem_unknowns
