"""The compiled steps of a small scene (nscd.compiled_step) equal the general step, bit for bit.

A single run of a scene of a few bodies takes its plain steps in one compiled call
(several steps per call in ``simulate``); every other step (an impact located inside the step,
a problem the compiled Newton leaves, a body turning fast) goes through the general step,
``nscd.stepper.step``. Both compose the same compiled stages in the same order, so a run
must not depend on which path took its steps: the reference here is the same run with the
compiled path switched off, and the comparisons are exact (tolerance 0: a difference of one
unit in the last place grows along a rocking run and would hide a stage composed
differently). The engine's physics is validated against theory elsewhere
(tests/test_engine2d.py, tests/test_engine3d.py) on runs that now take this path.
"""
from __future__ import annotations

import numpy as np
import pytest

import nscd
from nscd import compiled_step
from nscd.motion import OneSine
from nscd.result import driven_work
from nscd.solver import small
from nscd.stepper import Settings, Simulator


def rocking_block() -> nscd.Scene:
    """The 0.5 x 1.5 m block released at half its slenderness angle (Housner's free rocking)."""
    scene, _ = nscd.tilted_block(0.5, 1.5, 0.5 * np.arctan(0.5 / 1.5))
    return scene


def blocks_3d() -> nscd.Scene:
    """3D: a 0.2 x 0.3 x 0.8 m block standing on a base and a 0.3 m cube dropped from 2 mm
    beside it (it lands inside a step), turning slowly."""
    scene = nscd.Scene(dim=3)
    scene.add_base(nscd.box(2.0, 2.0, 0.1), position=(0.0, 0.0, -0.05))
    scene.add_block(nscd.box(0.2, 0.3, 0.8), position=(-0.4, 0.0, 0.4), orientation=(1.0, 0.0, 0.0, 0.0))
    scene.add_block(nscd.box(0.3, 0.3, 0.3), position=(0.4, 0.0, 0.152), orientation=(1.0, 0.0, 0.0, 0.0),
                    omega=(0.0, 0.3, 0.0))
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def shaken_block() -> nscd.Scene:
    """A 0.2 x 0.6 m block on a base shaken by one sine pulse strong enough to rock it (a driven
    body whose ready motion's formula poses it inside the compiled call)."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(2.0, 0.1), position=(0.0, -0.05), motion=OneSine(6.0, omega=2 * np.pi * 2.0))
    scene.add_block(nscd.box(0.2, 0.6), position=(0.0, 0.3), name="block")
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def general_only(monkeypatch) -> None:
    """Every step by the general step (the compiled path off)."""
    monkeypatch.setattr(compiled_step.CompiledSteps, "of", classmethod(lambda cls, *args: None))


def assert_same_result(compiled: nscd.Result, general: nscd.Result) -> None:
    """Exact equality: histories, energies, impacts and solver reports."""
    for name in ("time", "q", "v", "kinetic", "potential", "dissipated", "work_input"):
        np.testing.assert_array_equal(getattr(compiled, name), getattr(general, name), err_msg=name)
    assert compiled.impacts.keys() == general.impacts.keys()
    for key in general.impacts:
        np.testing.assert_array_equal(compiled.impacts[key], general.impacts[key], err_msg=f"impacts[{key!r}]")
    for name in ("iterations", "merit", "n_contacts", "n_active", "penetration", "unconverged_times"):
        np.testing.assert_array_equal(getattr(compiled.report, name), getattr(general.report, name), err_msg=name)
    assert compiled.report.statuses == general.report.statuses


def count_paths(monkeypatch) -> dict:
    """Count the steps each path takes (the compiled steps by the calls' returns)."""
    counts = {"compiled": 0, "general": 0}
    run_compiled, run_general = compiled_step.CompiledSteps.run, nscd.stepper.Run._general_step
    run_one = compiled_step.CompiledSteps.run_one

    def compiled_steps(self, data, rows, n_steps):
        taken, codes = run_compiled(self, data, rows, n_steps)
        counts["compiled"] += int(taken.sum())
        return taken, codes

    def compiled_steps_of_one(self, data, n_steps):
        taken, code = run_one(self, data, n_steps)
        counts["compiled"] += taken
        return taken, code

    def general_step(self, rows, stacklevel):
        counts["general"] += len(rows)
        return run_general(self, rows, stacklevel + 1)

    monkeypatch.setattr(compiled_step.CompiledSteps, "run", compiled_steps)
    monkeypatch.setattr(compiled_step.CompiledSteps, "run_one", compiled_steps_of_one)
    monkeypatch.setattr(nscd.stepper.Run, "_general_step", general_step)
    return counts


CASES = {
    # name: (scene, t_end s, dt s); the rocking block's impacts (the first at 0.43 s) are
    # located by the general step, the swings between them compiled
    "2D rocking block": (rocking_block, 1.0, 1e-3),
    "2D rocking block, coarse step": (rocking_block, 1.2, 1e-2),
    "2D three-block stack": (lambda: nscd.stack(3, width=0.4, height=1.0)[0], 0.1, 1e-3),
    "2D block on a shaken base": (shaken_block, 0.4, 1e-3),
    "3D blocks, one landing": (blocks_3d, 0.04, 1e-3),
    "3D LNEC trilith": (nscd.lnec.trilith, 0.02, 1e-3),
    # a few dozen bodies: 28 voussoirs and two springers shaken by a pulse, 29 joints (116
    # unknowns: the dense fast path's problems)
    "2D arch of 28 voussoirs, shaken": (lambda: nscd.arch(1.0, 0.15, 28, motion=OneSine(3.0, omega=2 * np.pi * 5.0))[0],
                                        0.1, 1e-3),
}


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
@pytest.mark.parametrize("case", list(CASES))
def test_compiled_steps_equal_the_general_step(case, scheme, monkeypatch):
    make, t_end, dt = CASES[case]
    settings = Settings(scheme=scheme)
    counts = count_paths(monkeypatch)
    compiled = nscd.simulate(make(), t_end, dt, settings=settings)
    # the comparison is not vacuous: most steps were compiled
    assert counts["compiled"] > counts["general"], counts
    with monkeypatch.context() as m:
        general_only(m)
        general = nscd.simulate(make(), t_end, dt, settings=settings)
    assert_same_result(compiled, general)
    if case.startswith("2D rocking"):
        assert len(compiled.impacts["time"]) >= 1


def test_a_single_run_backs_off_only_after_hand_backs_in_a_row():
    """A single run's compiled calls: an isolated step handed back costs no general step more;
    a call whose first step is handed back right after another such call sends the next 1, 2, 4,
    ... (at most 64) steps to the general step, and a call that takes a step ends it."""
    paths = nscd.stepper._Paths(single=True, threads=1)
    for _ in range(3):  # hand-backs each after a call that took steps: never backs off
        paths.handed_back(True)
        assert paths.compiled_next(1)
        paths.handed_back(False)
        assert paths.compiled_next(1)
    paths.handed_back(True)
    general = []
    for _ in range(9):  # then every call hands back its first step
        assert paths.compiled_next(1)
        paths.handed_back(True)
        k = 0
        while not paths.compiled_next(1):
            k += 1
        general.append(k)
        paths.general_for = 0
    assert general == [1, 2, 4, 8, 16, 32, 64, 64, 64]
    paths.handed_back(False)  # a call that took a step: no back-off any more
    paths.handed_back(True)
    assert paths.compiled_next(1)


def test_a_scene_whose_steps_all_need_the_general_step_backs_off(monkeypatch):
    """A running-bond wall of 32 blocks on a shaken base (at most ALL_PAIRS_BODIES bodies, so
    compiled steps are tried) whose contact problems are larger than the compiled fast path
    takes: every compiled call hands its first step back, and the run backs off, so that of
    120 steps a handful are tried compiled (calls at steps 1, 2, 4, 7, 12, 21, 38, 71: 8), and
    the result is the general step alone's."""
    def make():
        return nscd.wall(5, 6, 0.4, 0.2, motion=OneSine(2.0, omega=2 * np.pi * 3.0))[0]

    calls = []
    run_one = compiled_step.CompiledSteps.run_one

    def counted(self, data, n_steps):
        taken, code = run_one(self, data, n_steps)
        calls.append(taken)
        return taken, code

    with monkeypatch.context() as m:
        m.setattr(compiled_step.CompiledSteps, "run_one", counted)
        tried = nscd.simulate(make(), 0.12, 1e-3)
    assert len(tried.report.n_contacts) == 120 and max(tried.report.n_active) * 2 > 120
    assert calls and not any(calls), calls  # every call handed its first step back
    assert len(calls) == 8, calls
    general_only(monkeypatch)
    assert_same_result(tried, nscd.simulate(make(), 0.12, 1e-3))


def test_step_by_step_equals_simulate_and_outputs_equal(monkeypatch):
    """``Simulator.step`` (one compiled step per call) gives what ``simulate`` (many per call)
    does, and the last step's report and output (contacts, active set, impulses, relative
    velocities) equal the general step's."""
    settings = Settings()
    compiled = Simulator(rocking_block(), 1e-3, settings)
    reports = [compiled.step() for _ in range(300)]
    assert_same_result(compiled.result(), nscd.simulate(rocking_block(), 0.3, 1e-3, settings=settings))
    general_only(monkeypatch)
    general = Simulator(rocking_block(), 1e-3, settings)
    assert [general.step() for _ in range(300)] == reports
    out, reference = compiled.output, general.output
    assert out.report == reference.report
    for name in ("active", "impulses", "u_before", "u_after", "solved_at", "driven"):
        np.testing.assert_array_equal(getattr(out, name), getattr(reference, name), err_msg=name)
    for name in reference.contacts.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(out.contacts, name), getattr(reference.contacts, name), err_msg=name)


def test_warm_starts_equal_the_general_steps_step_after_step(monkeypatch):
    """The warm start each step hands on (ids, impulses, their trend, and whether the linear
    prediction was clearly the better, ``WarmStart.linear``) is the general step's, step after
    step, through a pulse that rocks a block (impacts: the impulses jump, the prediction loses,
    and it wins again while the block rides the base)."""
    fields = ("ids", "impulses", "trend", "first", "trended", "linear")
    compiled = Simulator(shaken_block(), 1e-3)
    general_only(monkeypatch)
    general = Simulator(shaken_block(), 1e-3)
    seen = set()
    for k in range(700):
        compiled.step()
        general.step()
        a, b = compiled.data.warm, general.data.warm
        for name in fields:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=f"step {k}: {name}")
        seen.add(bool(a.linear[0]))
    assert seen == {True, False}, "the run never changed its choice of start: the test sees one case only"


def test_repeated_calls_go_straight_to_the_machine_code_of_their_types():
    """A kernel called again with the same argument objects skips the dispatcher's typing (a
    single run's ``Simulator.step``) and gives what the dispatcher's call gives; new objects
    go through the dispatcher again. The kernel here: the pairwise sum of the driven work,
    whose value numpy's ``np.sum`` gives bit for bit."""
    call = compiled_step._RepeatedCall(driven_work)
    impulses, driven = np.linspace(-1.0, 2.0, 14).reshape(7, 2), np.linspace(0.3, -0.2, 14).reshape(7, 2)
    expected = np.sum(impulses * driven)
    assert call(impulses, driven) == expected  # through the dispatcher
    if len(getattr(driven_work, "overloads", ())) == 1:  # compiled (not NUMBA_DISABLE_JIT), one specialisation
        assert call._entry is not driven_work
    assert [call(impulses, driven) for _ in range(3)] == [expected] * 3  # straight to the machine code
    other = 2.0 * impulses  # a new object of the same type: through the dispatcher, then kept
    assert call(other, driven) == np.sum(other * driven) and call._args[0] is other


def test_repeated_calls_of_a_kernel_of_several_specialisations_find_the_one_of_their_types():
    """Where a kernel has several specialisations (a process that ran 2D and 3D scenes), the
    dispatcher chooses among them at every call; calls that repeat the same objects have the
    one of exactly their types looked up once and go straight to it, with what the
    dispatcher gives. The kernel: a sum over a tuple of arrays, compiled for floats and for
    integers."""
    numba = pytest.importorskip("numba")
    if numba.config.DISABLE_JIT:
        pytest.skip("plain Python: no specialisations")

    @numba.njit
    def total(scale, arrays):
        return scale * (arrays[0].sum() + arrays[1].sum())

    as_ints = (np.arange(4), np.arange(3))
    assert total(2, as_ints) == 18
    call = compiled_step._RepeatedCall(total)
    arrays = (np.linspace(0.0, 1.0, 5), np.linspace(1.0, 3.0, 3))
    expected = 0.5 * (arrays[0].sum() + arrays[1].sum())
    results = [call(0.5, arrays) for _ in range(call.RESOLVE_AFTER)]
    assert len(total.overloads) == 2 and call._entry is total  # still the dispatcher's choice
    results += [call(0.5, arrays) for _ in range(3)]
    assert call._entry is not total  # the floats' machine code, looked up once
    assert call._entry is total.overloads[tuple(total.typeof_pyval(a) for a in (0.5, arrays))].entry_point
    assert results == [expected] * len(results)
    assert call(2, as_ints) == 18 and call._entry is total  # new objects: the dispatcher again


def test_a_shaken_scene_repeats_its_arguments_step_after_step():
    """A single run whose base a ready motion drives (posed inside the compiled call) hands
    ``plain_steps`` the same argument objects step after step, so that its calls skip the
    dispatcher's typing as a scene without driven bodies does (a new ``drive`` tuple at each
    step sent every call of a shaken scene through the dispatcher)."""
    sim = Simulator(shaken_block(), 1e-3)
    assert sim.data.drives.everywhere
    for _ in range(100):  # the history buffers double as the run grows (room for 128 steps)
        sim.step()
    before = sim._run._compiled._single._args
    for _ in range(3):
        sim.step()
    after = sim._run._compiled._single._args
    assert len(after) == len(before) and all(a is b for a, b in zip(after, before))


def test_buffers_grow_with_the_contacts(monkeypatch):
    """A column of 12 blocks (26 contacts, more than the warm start's first buffer holds) and
    a run longer than the first history buffers: grown, and the run unchanged."""
    scene = nscd.stack(12, width=0.4, height=0.3)[0]
    counts = count_paths(monkeypatch)
    compiled = nscd.simulate(scene, 0.05, 1e-3)
    assert counts["compiled"] > counts["general"] and compiled.report.n_active[-1] > 16
    general_only(monkeypatch)
    assert_same_result(compiled, nscd.simulate(scene, 0.05, 1e-3))


def test_events_stop_a_compiled_run_as_a_general_one(monkeypatch):
    """A terminal event evaluated after each compiled step stops the run at the same step."""
    def tilt(state) -> float:
        return abs(state.q[1, 2]) - 0.05  # the block's rotation passes 0.05 rad
    tilt.terminal = True
    compiled = nscd.simulate(rocking_block(), 1.0, 1e-3, events=[tilt])
    general_only(monkeypatch)
    general = nscd.simulate(rocking_block(), 1.0, 1e-3, events=[tilt])
    assert compiled.status == general.status == "event"
    assert_same_result(compiled, general)
    np.testing.assert_array_equal(compiled.t_events[0], general.t_events[0])


def test_driven_work_sums_as_numpy_does():
    """The driven bodies' work of a step, ``sum P . w``, has the bits of ``np.sum(P * w)`` (numpy's
    pairwise summation), which the recording of a step by Python used: sizes across the
    pairwise blocks (8 and 128 terms) and halvings, magnitudes over 16 decades."""
    rng = np.random.default_rng(7)
    for k in list(range(0, 70)) + [150, 300, 1000, 3001]:
        for dim in (2, 3):
            impulses = rng.standard_normal((k, dim)) * 10.0 ** rng.uniform(-8.0, 8.0, (k, dim))
            driven = rng.standard_normal((k, dim))
            assert driven_work(impulses, driven) == np.sum(impulses * driven), (k, dim)


# --- impacts located inside the step, in compiled code (scenes without a driven body) ------------


def dropped_pair() -> nscd.Scene:
    """Two free 0.3 x 0.6 m blocks (no driven body): the lower one 1 mm above the base, the
    upper one 2 mm above it and turned by 0.01 rad; both land inside a step, corner first."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(2.0, 0.1), position=(0.0, -0.05))
    scene.add_block(nscd.box(0.3, 0.6), position=(0.0, 0.301), name="lower")
    scene.add_block(nscd.box(0.3, 0.6), position=(0.0, 0.903), angle=0.01, name="upper")
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def tilted_box(angle: float = 0.1) -> nscd.Scene:
    """3D: a free 0.3 x 0.3 x 0.6 m box turned by ``angle`` (rad) about y, one edge 2 cm above
    the base: it lands on that edge, then rocks onto its face (impacts inside steps)."""
    scene = nscd.Scene(dim=3)
    scene.add_base(nscd.box(2.0, 2.0, 0.1), position=(0.0, 0.0, -0.05))
    scene.add_block(nscd.box(0.3, 0.3, 0.6), position=(0.0, 0.0, 0.32),
                    orientation=(np.cos(angle / 2), 0.0, np.sin(angle / 2), 0.0))
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def run_batch(scenes: list, t_end: float, dt: float, settings: Settings) -> list:
    """The results of ``scenes`` run as one batch on two threads (many compiled steps per call)."""
    sim = nscd.BatchSimulator(scenes, dt, settings, threads=2)
    sim.run(until=t_end)
    return sim.results()


def count_plans(monkeypatch) -> dict:
    """Count the steps whose impacts the general step locates (its ``_Plan``s: event location in Python)."""
    counts = {"plans": 0}
    plan_init = nscd.stepper._Plan.__init__

    def counted(self, *args, **kwargs):
        counts["plans"] += 1
        plan_init(self, *args, **kwargs)

    monkeypatch.setattr(nscd.stepper._Plan, "__init__", counted)
    return counts


def located_inside_steps(times: np.ndarray, dt: float) -> int:
    """How many impact times fall inside a step (off the grid of whole steps, to 1e-6 dt)."""
    return int(np.sum(np.abs(times / dt - np.round(times / dt)) > 1e-6))


UNDRIVEN = {
    # name: (scene, t_end s, dt s, every step compiled): the free-rocking block's first impact
    # (0.43 s); a falling pair, some of whose steps the compiled Newton does not accept (the
    # proximal point's, handed back: not impacts); a 3D box landing on an edge and rocking
    "2D rocking block": (rocking_block, 1.0, 1e-3, True),
    "2D dropped pair": (dropped_pair, 0.15, 1e-3, False),
    "3D tilted box": (tilted_box, 0.3, 2e-3, True),
}


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
@pytest.mark.parametrize("case", list(UNDRIVEN))
def test_undriven_impacts_are_located_in_compiled_steps(case, scheme, monkeypatch):
    """A scene without a driven body takes the steps in which an impact is located (event
    location's sub-steps: approach, corrections, impact, rest) in compiled code, and its run is
    the general step's, bit for bit."""
    make, t_end, dt, every_step = UNDRIVEN[case]
    settings = Settings(scheme=scheme)
    counts, plans = count_paths(monkeypatch), count_plans(monkeypatch)
    compiled = nscd.simulate(make(), t_end, dt, settings=settings)
    assert plans["plans"] == 0, "an impact was located by the general step"
    if every_step:
        assert counts["general"] == 0, counts
    # not vacuous: impacts were located inside steps (their times are the sub-steps' ends)
    assert located_inside_steps(compiled.impacts["time"], dt) >= 1, compiled.impacts["time"]
    with monkeypatch.context() as m:
        general_only(m)
        general = nscd.simulate(make(), t_end, dt, settings=settings)
    assert_same_result(compiled, general)


def test_output_of_an_impact_step_equals_the_general_steps(monkeypatch):
    """``Simulator.output`` after a step split at an impact in compiled code: its sub-steps'
    contacts end to end, the end time of each active contact's sub-step (``solved_at``), and
    the report joined as the general step joins them (``StepOutput.joined``)."""
    settings = Settings()
    steps = 434  # the block's first impact, 0.433 s, falls inside the 434th step of 1 ms
    compiled = Simulator(rocking_block(), 1e-3, settings)
    counts = count_paths(monkeypatch)
    reports = [compiled.step() for _ in range(steps)]
    assert counts["general"] == 0
    with monkeypatch.context() as m:
        general_only(m)
        general = Simulator(rocking_block(), 1e-3, settings)
        assert [general.step() for _ in range(steps)] == reports
    out, reference = compiled.output, general.output
    assert len(set(reference.solved_at.tolist())) > 1  # not vacuous: the last step was split
    assert out.report == reference.report
    for name in ("active", "impulses", "u_before", "u_after", "solved_at", "driven"):
        np.testing.assert_array_equal(getattr(out, name), getattr(reference, name), err_msg=name)
    for name in reference.contacts.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(out.contacts, name), getattr(reference.contacts, name), err_msg=name)


UNDRIVEN_BATCHES = {
    "2D rocking blocks": (lambda: [nscd.tilted_block(0.5, 1.5, a)[0] for a in (0.06, 0.1, 0.16)], 1.0, 1e-3),
    "3D tilted boxes": (lambda: [tilted_box(a) for a in (0.06, 0.1)], 0.3, 2e-3),
}


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
@pytest.mark.parametrize("case", list(UNDRIVEN_BATCHES))
def test_undriven_batches_locate_impacts_in_compiled_steps(case, scheme, monkeypatch):
    """A batch of scenes without a driven body (two threads) takes its impact steps in compiled
    code, none by the general step, and each scene's run is its single run's by the general
    step alone, bit for bit."""
    make, t_end, dt = UNDRIVEN_BATCHES[case]
    settings = Settings(scheme=scheme)
    counts = count_paths(monkeypatch)
    batched = run_batch(make(), t_end, dt, settings)
    assert counts["general"] == 0, counts
    assert all(located_inside_steps(r.impacts["time"], dt) >= 1 for r in batched)
    with monkeypatch.context() as m:
        general_only(m)
        for scene, result in zip(make(), batched):
            assert_same_result(result, nscd.simulate(scene, t_end, dt, settings=settings))


def test_summed_impulses_are_numpys_unique_and_add_at():
    """The next step's warm start of a step split at impacts (each contact's impulse summed
    over the sub-steps, :func:`nscd.state.summed_impulses`) has the ids of
    ``np.unique(ids, axis=0)`` in its order and the bits of ``np.add.at`` (the sum in the
    order of the rows): ids with repeats, negative features, impulses over 16 decades."""
    from nscd.state import summed_impulses
    rng = np.random.default_rng(3)
    for k in (0, 1, 2, 5, 17, 64, 300):
        for dim in (2, 3):
            ids = rng.integers(-2, 4, size=(k, 3)).astype(np.int64)
            impulses = rng.standard_normal((k, dim)) * 10.0 ** rng.uniform(-8.0, 8.0, (k, dim))
            unique, inverse = np.unique(ids, axis=0, return_inverse=True)
            total = np.zeros((len(unique), dim))
            np.add.at(total, inverse.ravel(), impulses)
            got_ids, got_total = summed_impulses(ids, impulses)
            np.testing.assert_array_equal(got_ids, unique)
            assert got_total.tobytes() == total.tobytes(), (k, dim)


# --- batches: each scene's plain steps compiled, as in its single run ----------------------------


def in_python(motion: nscd.motion.Motion) -> nscd.motion.Motion:
    """The same motion as a :class:`~nscd.motion.Prescribed` one (three Python functions, the
    ready motion's own evaluation): posed in Python, not by the compiled formulas."""
    return nscd.motion.Prescribed(motion.displacement, motion.velocity, motion.acceleration, motion.duration)


def rocking_blocks(amplitude: float, height: float = 0.0, angle: float = 0.0, python: bool = False) -> nscd.Scene:
    """:func:`shaken_block` with the pulse's amplitude (m/s^2), optionally dropped from ``height``
    (m) turned by ``angle`` (rad): it lands inside a step; with ``python``, its base's motion
    posed in Python (:func:`in_python`)."""
    scene = nscd.Scene()
    motion = OneSine(amplitude, omega=2 * np.pi * 2.0)
    scene.add_base(nscd.box(2.0, 0.1), position=(0.0, -0.05), motion=in_python(motion) if python else motion)
    scene.add_block(nscd.box(0.2, 0.6), position=(0.0, 0.3 + height), angle=angle, name="block")
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def landing_3d(amplitude: float, height: float, python: bool = False) -> nscd.Scene:
    """3D: a 0.2 x 0.3 x 0.8 m block dropped from ``height`` (m) onto a base shaken along x
    (with ``python``, its motion posed in Python)."""
    scene = nscd.Scene(dim=3)
    motion = OneSine(amplitude, omega=4 * np.pi)
    scene.add_base(nscd.box(2.0, 2.0, 0.1), position=(0.0, 0.0, -0.05), motion=in_python(motion) if python else motion)
    scene.add_block(nscd.box(0.2, 0.3, 0.8), position=(0.0, 0.0, 0.4 + height), orientation=(1.0, 0.0, 0.0, 0.0))
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


READY_DRIVEN_BATCHES = {
    # name: (scenes, t_end s, dt s): bases driven by ready motions (posed in compiled code at
    # every sub-step), blocks that rock, land inside a step and rest
    "2D shaken and dropped blocks": (lambda: [rocking_blocks(6.0), rocking_blocks(3.0, 0.03, 0.01),
                                              rocking_blocks(0.5), rocking_blocks(4.0, 0.01)], 0.3, 1e-3),
    "3D shaken and dropped blocks": (lambda: [landing_3d(8.0, 0.0), landing_3d(2.0, 0.02)], 0.12, 2e-3),
}


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
@pytest.mark.parametrize("case", list(READY_DRIVEN_BATCHES))
def test_ready_driven_batches_locate_impacts_in_compiled_steps(case, scheme, monkeypatch):
    """A batch whose bases are driven by ready motions (two threads) takes its impact steps in
    compiled code, none by the general step, the base posed at every sub-step's end (and
    midpoint) by the motions' compiled formulas; each scene's run is its single run's by the
    general step alone, bit for bit."""
    make, t_end, dt = READY_DRIVEN_BATCHES[case]
    settings = Settings(scheme=scheme)
    counts = count_paths(monkeypatch)
    batched = run_batch(make(), t_end, dt, settings)
    assert counts["general"] == 0, counts
    assert sum(located_inside_steps(r.impacts["time"], dt) for r in batched) >= 1
    with monkeypatch.context() as m:
        general_only(m)
        for scene, result in zip(make(), batched):
            assert_same_result(result, nscd.simulate(scene, t_end, dt, settings=settings))


BATCHES = {
    # name: (scenes, t_end s, dt s): driven bases, blocks that rock, land inside a step (an
    # impact located by the general step: one base of each batch of shaken blocks is driven in
    # Python, so none of the batch's impacts is located in compiled code) and rest, with
    # different contact counts per scene
    "2D shaken and dropped blocks": (lambda: [rocking_blocks(6.0), rocking_blocks(3.0, 0.03, 0.01),
                                              rocking_blocks(0.5), rocking_blocks(4.0, 0.01, python=True)], 0.3,
                                     1e-3),
    "2D double-pulse stacks": (lambda: [nscd.rigs.DoublePulseRig(specimen="stack3").scene(v, g)[0]
                                        for v, g in ((0.3, 0.04), (0.8, 0.02), (1.2, 0.01))], 0.12, 5e-4),
    "2D twelve-block columns": (lambda: [nscd.stack(12, width=0.4, height=0.3, motion=OneSine(a, omega=4 * np.pi))[0]
                                         for a in (1.0, 3.0)], 0.05, 1e-3),
    "3D shaken and dropped blocks": (lambda: [landing_3d(8.0, 0.0), landing_3d(2.0, 0.02, python=True)], 0.12,
                                     2e-3),
    "2D arches of 28 voussoirs": (lambda: [nscd.arch(1.0, 0.15, 28, motion=OneSine(a, omega=2 * np.pi * 5.0))[0]
                                           for a in (2.0, 4.0)], 0.04, 1e-3),
}
#: Batches whose steps are all compiled (their problems, those the Newton leaves included), with
#: more contacts than the first buffers hold
ALL_COMPILED = ("2D twelve-block columns", "2D arches of 28 voussoirs")


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
@pytest.mark.parametrize("case", list(BATCHES))
def test_batches_take_compiled_steps_as_single_runs_do(case, scheme, monkeypatch):
    """A batch (on two threads, many compiled steps per call) gives each scene the run the
    general step alone gives it, bit for bit: compiled steps where its plain step can be
    compiled, the general step (with other scenes, or every scene in lock step after a
    call in which some scene needed it) elsewhere."""
    make, t_end, dt = BATCHES[case]
    settings = Settings(scheme=scheme)
    counts = count_paths(monkeypatch)
    batched = run_batch(make(), t_end, dt, settings)
    assert counts["compiled"] > 0, counts
    if case not in ALL_COMPILED:  # both paths taken
        assert counts["general"] > 0, counts
    with monkeypatch.context() as m:
        general_only(m)
        for scene, result in zip(make(), batched):
            assert_same_result(result, nscd.simulate(scene, t_end, dt, settings=settings))
    if case in ALL_COMPILED:  # more contacts than the first buffers hold: grown
        assert max(r.report.n_active.max() for r in batched) > 16
    else:  # impacts inside a step, located by the general step
        assert any(len(r.impacts["time"]) for r in batched)


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
def test_batches_stepped_with_events_equal_single_runs(scheme, monkeypatch):
    """Lock steps (``BatchSimulator.step``) with a terminal event per scene, the histories not
    recorded (the compiled steps record into the batch's own arrays), then recorded: the
    events stop each scene at the step its single run stops, at the same states."""
    def tilt(state) -> float:
        return abs(state.q[1, 2]) - 0.02  # the block's rotation passes 0.02 rad
    tilt.terminal = True
    scenes = BATCHES["2D shaken and dropped blocks"][0]
    settings = Settings(scheme=scheme)
    counts = count_paths(monkeypatch)
    states = {}
    for record in (False, True):
        sim = nscd.BatchSimulator(scenes(), 1e-3, settings, record=record, events=[tilt], threads=2)
        for _ in range(300):
            sim.step()
        states[record] = [sim.state(k) for k in range(len(sim))]
    assert counts["compiled"] > 0 and counts["general"] > 0, counts
    general_only(monkeypatch)
    singles = [nscd.simulate(scene, 0.3, 1e-3, settings=settings, events=[tilt]) for scene in scenes()]
    assert {r.status for r in singles} == {"event", "finished"}  # some scenes stop, some do not
    for k, single in enumerate(singles):
        for record in (False, True):
            assert states[record][k].t == single.time[-1]
            np.testing.assert_array_equal(states[record][k].q, single.q[-1])
            np.testing.assert_array_equal(states[record][k].v, single.v[-1])
    assert_same_result(sim.results()[0], singles[0])


def test_threads_deal_out_the_scenes_and_change_nothing(monkeypatch):
    """Sixteen double-pulse stacks on two threads (the compiled steps of half the scenes in
    another thread) end as on one, bit for bit, and as the general step alone gives them."""
    rig = nscd.rigs.DoublePulseRig(specimen="stack3")
    cells = [(0.3 + 0.06 * k, 0.005 + 0.003 * k) for k in range(16)]
    submitted = []
    pool = compiled_step._thread_pool

    def counting_pool(workers):
        executor = pool(workers)
        submitted.append(workers)
        return executor

    monkeypatch.setattr(compiled_step, "_thread_pool", counting_pool)
    runs = {}
    for threads in (1, 2):
        sim = nscd.BatchSimulator([rig.scene(v, g)[0] for v, g in cells], rig.dt, threads=threads)
        sim.run(until=0.06)
        runs[threads] = sim.results()
    assert submitted  # the second thread took scenes
    for one, two in zip(runs[1], runs[2]):
        assert_same_result(two, one)
    general_only(monkeypatch)
    for k in (0, 7, 15):
        assert_same_result(runs[2][k], nscd.simulate(rig.scene(*cells[k])[0], 0.06, rig.dt))



def count_fresh_overlaps(monkeypatch) -> dict:
    """Count the general step's sub-steps whose end-of-step overlap is detected afresh in the
    end configuration (``nscd.stepper._end_overlaps``)."""
    counts = {"overlap": 0}
    end_overlaps = nscd.stepper._end_overlaps

    def end_overlaps_counted(model, q_end, overlap, check):
        counts["overlap"] += int(np.sum(check))
        return end_overlaps(model, q_end, overlap, check)

    monkeypatch.setattr(nscd.stepper, "_end_overlaps", end_overlaps_counted)
    return counts


@pytest.mark.parametrize("scheme, v_peak, gap", [("midpoint", 1.2, 0.01), ("theta", 0.5, 0.03)])
def test_fresh_overlaps_stay_in_compiled_steps(scheme, v_peak, gap, monkeypatch):
    """A double-pulse stack whose predicted end-of-step overlaps are sometimes not trusted
    (detected again in the end configuration): its compiled steps detect them themselves
    instead of handing the step back, and the run equals, bit for bit, the same run through
    the general step alone."""
    def scene() -> nscd.Scene:
        return nscd.rigs.DoublePulseRig(specimen="stack3").scene(v_peak, gap)[0]

    settings = Settings(scheme=scheme)
    with monkeypatch.context() as m:
        general_only(m)
        everything = count_fresh_overlaps(m)
        general = nscd.simulate(scene(), 0.2, 5e-4, settings=settings)
    handed_back = count_fresh_overlaps(monkeypatch)
    compiled = nscd.simulate(scene(), 0.2, 5e-4, settings=settings)
    # the general step still detects those of the steps it takes (impacts inside a step); the
    # plain steps' are detected in compiled code
    assert handed_back["overlap"] < everything["overlap"], (handed_back, everything)
    assert_same_result(compiled, general)


def count_fast_path_outcomes(monkeypatch) -> dict:
    """Count, by outcome, the problems the general step's compiled fast path
    (``nscd.solver.core.newton_batch``) solves: accepted by the proximal point, by its polish,
    or not accepted (left to the conic fixed point)."""
    counts = {"proximal": 0, "polished": 0, "not accepted": 0}
    newton_batch = nscd.solver.core.newton_batch

    def counted(*args):
        r, u, merit, info = newton_batch(*args)
        counts["proximal"] += int(np.sum(info[:, 0] == small.PROXIMAL))
        counts["polished"] += int(np.sum(info[:, 0] == small.PROXIMAL_POLISHED))
        counts["not accepted"] += int(np.sum(info[:, 0] == small.NOT_ACCEPTED))
        return r, u, merit, info

    monkeypatch.setattr(nscd.solver.core, "newton_batch", counted)
    return counts


def count_dissipative_resolves(monkeypatch) -> dict:
    """Count the problems the general step solves again because their solution reverses a
    slip or creates energy (9b, ``nscd.stepper._solve_left``), and its whole calls."""
    counts = {"9b": 0, "calls": 0}
    solve_left = nscd.stepper._solve_left

    def counted(k, data, rows, left, *args):
        counts["9b"] += int(np.count_nonzero(left == nscd.stepper._CREATES_ENERGY))
        counts["calls"] += 1
        return solve_left(k, data, rows, left, *args)

    monkeypatch.setattr(nscd.stepper, "_solve_left", counted)
    return counts


def _spinning_elastic_blocks() -> nscd.Scene:
    """Four spinning blocks dropped side by side with e = 1 and friction (Kane's example:
    Newton's restitution with Coulomb friction can give the bodies energy at an impact, and
    the restitution is scaled by bisection)."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(20.0, 0.2), position=(0.0, -0.1))
    for i, (height, omega) in enumerate(((0.5, 20.0), (0.7, -15.0), (0.9, 10.0), (1.1, -25.0))):
        scene.add_block(nscd.box(0.4, 0.2), position=(-3.0 + 2.0 * i, height), omega=omega, density=2000.0)
    scene.set_contact(friction=0.8, restitution=1.0)
    return scene


@pytest.mark.parametrize("case", ["spinning elastic blocks", "stack reversing slips"])
def test_solutions_that_create_energy_are_solved_again_in_compiled_steps(monkeypatch, case):
    """9b in compiled code: a problem whose solution reverses a slip (a three-block stack on
    the double-pulse rig's kinematic base, a cell whose joints slide and stick) or whose
    restitution gives the bodies energy (spinning blocks dropped with e = 1 and friction) is
    solved again inside the compiled steps, by the plan of ``nscd.stepper._dissipative_next``
    (reflection passes, the restitution's bisection) with the fast path, instead of handing
    the step back; the run equal bit for bit to the same run through the general step alone."""
    if case == "stack reversing slips":
        rig = nscd.rigs.DoublePulseRig(specimen="stack3", scale=1, base="kinematic")
        gap, v_peak = float(np.linspace(0.005, 0.05, 20)[14]), float(np.linspace(0.1, 1.5, 20)[4])
        scene, t_end, dt = rig.scene(v_peak, gap)[0], 0.6, rig.dt
    else:
        scene, t_end, dt = _spinning_elastic_blocks(), 1.0, 1e-3
    with monkeypatch.context() as m:
        general_only(m)
        everything = count_dissipative_resolves(m)
        general = nscd.simulate(scene, t_end, dt)
    # the case is one whose problems need 9b, in several steps
    assert everything["9b"] >= 3, everything
    counts = count_paths(monkeypatch)
    left_to_python = count_dissipative_resolves(monkeypatch)
    compiled = nscd.simulate(scene, t_end, dt)
    assert left_to_python["9b"] < everything["9b"] / 3, (left_to_python, everything)
    assert counts["general"] < counts["compiled"] / 10, counts
    assert_same_result(compiled, general)


def test_the_proximal_point_stays_in_compiled_steps(monkeypatch):
    """A three-block stack on the double-pulse rig's kinematic base, a cell whose joints slide
    at the friction limit (two contact points per joint: ``W`` near singular, problems the
    Newton does not accept): the compiled steps solve those problems by the proximal point and
    its polish themselves (one compiled call, ``nscd.solver.proximal.fast_path``) instead of
    handing the step back, and record them as the general step does (statuses, iterations,
    merits), the run equal bit for bit to the same run through the general step alone."""
    rig = nscd.rigs.DoublePulseRig(specimen="stack3", scale=1, base="kinematic")
    gap, v_peak = float(np.linspace(0.005, 0.05, 20)[3]), float(np.linspace(0.1, 1.5, 20)[4])
    with monkeypatch.context() as m:
        general_only(m)
        everything = count_fast_path_outcomes(m)
        general = nscd.simulate(rig.scene(v_peak, gap)[0], 0.3, rig.dt)
    # the cell is one that needs the proximal point, and once its polish
    assert everything["proximal"] > 50 and everything["polished"] >= 1, everything
    counts = count_paths(monkeypatch)
    left_to_python = count_fast_path_outcomes(monkeypatch)
    compiled = nscd.simulate(rig.scene(v_peak, gap)[0], 0.3, rig.dt)
    # the general step still takes the steps of located impacts (a driven base), with their
    # problems; the others' proximal points and the polish ran in the compiled steps
    assert counts["general"] < counts["compiled"] / 10, counts
    assert left_to_python["proximal"] < everything["proximal"] / 2, (left_to_python, everything)
    assert left_to_python["polished"] < everything["polished"], (left_to_python, everything)
    assert str(nscd.solver.Status.POLISHED) in compiled.report.statuses
    assert_same_result(compiled, general)
