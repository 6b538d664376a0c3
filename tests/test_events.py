"""Events of a run, in the style of scipy.integrate.solve_ivp: functions of the state whose
zeros are located within the step; terminal events stop the run (or, in a batch, the scene).

Oracles: free fall (exact parabola: the height crosses a level at t = sqrt(2 d / g)), and
the one definition of overturned (nscd.result.OVERTURN_ANGLE) on a block released beyond
its slenderness angle.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import nscd
from nscd.batch import simulate_batch
from nscd.motion import STANDARD_GRAVITY as G
from nscd.motion import OneSine
from nscd.result import OVERTURN_ANGLE
from nscd.events import overturning

DT = 1e-3


def dropped_block(height: float) -> nscd.Scene:
    scene = nscd.Scene()
    scene.add_base(nscd.box(2.0, 0.2), position=(0.0, -0.1))
    scene.add_block(nscd.box(0.2, 0.4), position=(0.0, 0.2 + height), name="block")
    scene.set_contact(friction=0.6, restitution=0.0)
    return scene


def shaken_block(amplitude: float) -> nscd.Scene:
    """A 0.3 x 0.9 m block (alpha = 0.32 rad) on a base shaken by one sine pulse of 1.5 Hz (m/s^2)."""
    scene = nscd.Scene()
    scene.add_base(nscd.box(4.0, 0.2), position=(0.0, -0.1), motion=OneSine(amplitude, omega=2 * math.pi * 1.5))
    scene.add_block(nscd.box(0.3, 0.9), position=(0.0, 0.45), name="block")
    scene.set_contact(friction=0.8, restitution=0.0)
    return scene


class Level:
    """Height of the block's centre above ``level`` (m); falling zeros only."""

    direction = -1.0
    terminal = False

    def __init__(self, level: float) -> None:
        self.level = level

    def __call__(self, state: nscd.State) -> float:
        return float(state.q[1, 1]) - self.level


@pytest.mark.parametrize("scheme", ["midpoint", "theta"])
def test_event_located_within_the_step_in_free_fall(scheme):
    """A block dropped from 0.1 m passes 0.0533 m below its start at t = sqrt(2 d / g)."""
    start, drop = 0.3, 0.0533
    event = Level(start - drop)
    result = nscd.simulate(dropped_block(0.1), 0.2, DT, settings=nscd.Settings(scheme=scheme), events=[event])
    (times,) = result.t_events
    assert len(times) == 1
    # Linear interpolation of the exact parabola over one step errs in height by at most
    # g dt^2 / 8, i.e. by g dt^2 / (8 |v|) = 1.2e-6 s in time at |v| = 1.0 m/s; the event time
    # falls strictly inside a step (not at its end: 53.3 ms is not a multiple of 1 ms... nearly)
    assert times[0] == pytest.approx(math.sqrt(2 * drop / G), abs=2e-6)
    assert result.status == "finished"  # not terminal


def test_direction_selects_the_crossings():
    rising = Level(0.25)
    rising.direction = 1.0  # the falling block never crosses upwards
    result = nscd.simulate(dropped_block(0.1), 0.2, DT, events=[rising, Level(0.25)])
    assert len(result.t_events[0]) == 0 and len(result.t_events[1]) == 1


def test_terminal_overturning_event_stops_the_run():
    """A pulse of 12 m/s^2 (3.7 g tan(alpha)) overturns the block; the run stops there."""
    scene = shaken_block(12.0)
    result = nscd.simulate(scene, 3.0, DT, events=[overturning(scene, "block")])
    assert result.status == "event"
    (times,) = result.t_events
    assert len(times) == 1
    assert result.overturned("block")
    assert result.time[-1] < 3.0  # stopped early, at the end of the step of the event
    rotation = np.abs(result.rotation("block"))
    # the event lies in the last step, where the rotation passes OVERTURN_ANGLE
    assert rotation[-2] < OVERTURN_ANGLE <= rotation[-1]
    assert result.time[-2] < times[0] <= result.time[-1]


def test_terminal_event_stops_only_its_scene_in_a_batch():
    scenes = [shaken_block(12.0), shaken_block(2.0)]  # overturns; stays at rest (below g tan(alpha))
    events = [overturning(scenes[0], "block")]
    batched = simulate_batch(scenes, 1.5, DT, events=events)
    assert batched[0].status == "event" and batched[1].status == "finished"
    assert len(batched[1].time) == 1501 and len(batched[0].time) < 1501
    for scene, result in zip(scenes, batched):
        single = nscd.simulate(scene, 1.5, DT, events=events)
        np.testing.assert_array_equal(result.q, single.q)
        np.testing.assert_array_equal(result.t_events[0], single.t_events[0])


def test_events_scene_by_scene_in_a_batch():
    """One list of events per scene: a terminal event stops only the scene it was given to."""
    scenes = [dropped_block(0.1), dropped_block(0.1)]
    stop_low = Level(0.3 - 0.0533)
    stop_low.terminal = True
    batched = simulate_batch(scenes, 0.2, DT, events=[[], [stop_low]])
    assert batched[0].status == "finished" and len(batched[0].time) == 201
    assert batched[1].status == "event" and batched[1].time[-1] < 0.2
    single = nscd.simulate(scenes[1], 0.2, DT, events=[stop_low])
    np.testing.assert_array_equal(batched[1].q, single.q)
    np.testing.assert_array_equal(batched[1].t_events[0], single.t_events[0])
    with pytest.raises(ValueError, match="events has 1 lists, must be one list of events per scene"):
        simulate_batch(scenes, 0.01, DT, events=[[stop_low]])
    with pytest.raises(TypeError, match=r"events\[1\]\[0\] is a int, must be a callable"):
        simulate_batch(scenes, 0.01, DT, events=[[], [3]])


def test_bad_events_raise():
    scene = dropped_block(0.1)
    with pytest.raises(TypeError, match=r"events\[0\] is a int, must be a callable"):
        nscd.simulate(scene, 0.01, DT, events=[3])
    bad = Level(0.0)
    bad.direction = "down"
    with pytest.raises(ValueError, match=r"events\[0\].direction == 'down', must be a finite number"):
        nscd.simulate(scene, 0.01, DT, events=[bad])
    with pytest.raises(ValueError, match=r"angle == 4.0, must be in \(0, pi\]"):
        overturning(scene, "block", angle=4.0)


class Heights:
    """Vectorized: the heights of the block's centre above ``level`` (m) in every scene at once."""

    vectorized = True
    terminal = True
    direction = -1.0

    def __init__(self, level: float) -> None:
        self.level = level
        self.calls = 0

    def __call__(self, states: nscd.state.States) -> np.ndarray:
        self.calls += 1
        return states.q[:, 1, 1] - self.level


def test_vectorized_event_is_evaluated_once_per_step_for_all_scenes():
    """A vectorized event sees all the scenes of a step in one call and locates each scene's zero
    as the plain event does: a block dropped from 0.1 m passes 0.2467 m at t = sqrt(2 d / g)."""
    scenes = [dropped_block(0.1), dropped_block(0.04)]
    level = 0.3 - 0.0533
    vectorized = Heights(level)
    batched = simulate_batch(scenes, 0.2, DT, events=[vectorized])
    assert vectorized.calls == 201  # the initial states, then one call per step, both scenes together
    plain = Level(level)
    plain.terminal = True
    for scene, result in zip(scenes, batched):
        single = nscd.simulate(scene, 0.2, DT, events=[plain])
        np.testing.assert_array_equal(result.q, single.q)
        np.testing.assert_array_equal(result.t_events[0], single.t_events[0])
    # the first falls 0.0533 m (t = sqrt(2 d / g), located within 2e-6 s as above); the second
    # starts below the level (its centre at 0.24 m): no falling zero, it runs to the end
    assert batched[0].status == "event"
    assert batched[0].t_events[0][0] == pytest.approx(math.sqrt(2 * 0.0533 / G), abs=2e-6)
    assert batched[1].status == "finished" and len(batched[1].t_events[0]) == 0


def test_bad_vectorized_events_raise():
    scene = dropped_block(0.1)

    class Scalar(Heights):
        def __call__(self, states):
            return 1.0

    with pytest.raises(ValueError, match=r"returned shape \(\) for 1 scenes, must return one value per scene"):
        nscd.simulate(scene, 0.01, DT, events=[Scalar(0.0)])
    bad = Heights(0.0)
    bad.vectorized = "yes"
    with pytest.raises(TypeError, match=r"events\[0\].vectorized == 'yes', must be True or False"):
        nscd.simulate(scene, 0.01, DT, events=[bad])
