"""Events of a run, in the style of :func:`scipy.integrate.solve_ivp`: functions of the state
whose zeros are located within the step; a terminal one stops the run (in a batch, its scene).

An event is a callable with optional attributes ``terminal`` (bool: stop at the end of the
step in which it occurs) and ``direction`` (> 0: zeros crossed from below only, < 0: from
above only, 0: both). A plain event is a function ``event(state) -> float`` of one scene's
:class:`~nscd.state.State`. An event with the attribute ``vectorized = True`` (the word
:func:`scipy.integrate.solve_ivp` uses for a function of many states) is evaluated once for
all the scenes of a step: ``event(states) -> ndarray (S,)`` of a
:class:`~nscd.state.States` (the scenes' times, positions, velocities and their rows in the
run); a single run passes it one row. Each row's value must depend on that row alone
(then a scene gives the same values stepped alone or in a batch).

After each step every event is evaluated at the step's end; a zero between the two ends
is located by linear interpolation of the function over the step (error of order dt^2).
"""
from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from nscd.result import OVERTURN_ANGLE
from nscd.rotation import tilt_angle
from nscd.scene import Scene
from nscd.state import Data, States

__all__ = ["Events", "overturning"]


class _Event:
    """One checked event function and the scenes (rows of the run) it is evaluated in."""

    def __init__(self, function: Callable, terminal: bool, direction: float, index: int, rows: np.ndarray) -> None:
        self.function, self.terminal, self.direction, self.index, self.rows = function, terminal, direction, index, rows
        self.vectorized = bool(getattr(function, "vectorized", False))

    def values(self, data: Data, rows: np.ndarray) -> np.ndarray:
        """The function's values (S,) at the current states of ``rows``."""
        if self.vectorized:
            values = np.asarray(self.function(data.states(rows)), dtype=float)
            if values.shape != rows.shape:
                raise ValueError(f"vectorized event {self.function!r} returned shape {values.shape} for "
                                 f"{len(rows)} scenes, must return one value per scene, shape ({len(rows)},).")
            return values
        return np.array([float(self.function(data.state(r))) for r in rows.tolist()])


class Events:
    """The events of B scenes of a run: their values at the last step's end, the times at
    which they occurred and the terminal event that stopped each scene.

    Parameters
    ----------
    events : sequence of callable, or one such sequence per scene, or None
        One list evaluated in every scene, or a list of ``n_scenes`` lists, scene by scene.
    data : Data
        The run's scenes at their initial state (every event is evaluated there first).

    Attributes
    ----------
    t_events : list of list of list of float
        Per scene, per event of its list, the times (s) at which the event occurred.
    stopped_by : list of tuple or None
        Per scene, ``(event index, time)`` of the terminal event that stopped it.
    """

    def __init__(self, events, data: Data) -> None:
        n_scenes = len(data)
        self._events: list[_Event] = []
        if events is not None:
            events = list(events)
            if events and all(isinstance(scene_events, (list, tuple)) for scene_events in events):
                if len(events) != n_scenes:
                    raise ValueError(f"events has {len(events)} lists, must be one list of events per scene "
                                     f"({n_scenes}) or one list of callables for every scene.")
                for k, scene_events in enumerate(events):
                    for i, checked in enumerate(check_events(scene_events, f"events[{k}]")):
                        self._events.append(_Event(*checked, i, np.array([k])))
            else:
                rows = np.arange(n_scenes)
                self._events = [_Event(*checked, i, rows) for i, checked in enumerate(check_events(events))]
        counts = np.zeros(n_scenes, dtype=int)
        for event in self._events:
            counts[event.rows] += 1
        self.t_events: list = [[[] for _ in range(n)] for n in counts.tolist()]
        self.stopped_by: list = [None] * n_scenes
        self._values = [np.full(n_scenes, math.nan) for _ in self._events]
        for event, values in zip(self._events, self._values):
            values[event.rows] = event.values(data, event.rows)

    def __bool__(self) -> bool:
        return bool(self._events)

    def locate(self, data: Data, rows: np.ndarray, t_before: np.ndarray) -> np.ndarray:
        """Evaluate every event at the end of the step just taken by scenes ``rows`` (which
        started it at ``t_before`` (S,), s), list the zeros crossed within it (in each event's
        ``direction``) at the time found by linear interpolation of the function over the
        step, and return the rows stopped by a terminal event."""
        stopped: list[int] = []
        if len(data) == 1:  # a single run: its one scene in plain numbers (a step's few microseconds)
            for event, values in zip(self._events, self._values):
                if len(event.rows):
                    g0, g1 = values.item(0), event.values(data, rows).item(0)
                    values[0] = g1
                    if _crossed(g0, g1, event.direction):
                        self._occurred(event, 0, t_before.item(0), data.t.item(0), g0, g1, stopped)
            return np.array(stopped, dtype=int)
        position = np.full(len(data), -1)
        position[rows] = np.arange(len(rows))
        for event, values in zip(self._events, self._values):
            slots = position[event.rows]
            at, start = event.rows[slots >= 0], t_before[slots[slots >= 0]]
            if not len(at):
                continue
            g0, g1 = values[at], event.values(data, at)
            values[at] = g1
            for k in np.flatnonzero(_crossed(g0, g1, event.direction)).tolist():
                r = int(at[k])
                self._occurred(event, r, float(start[k]), float(data.t[r]), float(g0[k]), float(g1[k]), stopped)
        return np.array(stopped, dtype=int)

    def _occurred(self, event: _Event, r: int, t0: float, t1: float, g0: float, g1: float,
                  stopped: list[int]) -> None:
        """``event`` crossed zero in scene ``r``'s step from ``t0`` to ``t1`` (s), its values
        ``g0`` and ``g1`` at the two ends: list the time of the zero (linear interpolation) and,
        for a terminal event, stop the scene (appended to ``stopped``)."""
        t_event = t0 + (t1 - t0) * g0 / (g0 - g1)
        self.t_events[r][event.index].append(t_event)
        if event.terminal and self.stopped_by[r] is None:
            self.stopped_by[r] = (event.index, t_event)
            stopped.append(r)


def _crossed(g0, g1, direction: float):
    """Whether an event's function crossed zero between its values ``g0`` and ``g1`` at a
    step's two ends in its ``direction`` (> 0 rising only, < 0 falling only, 0 both); numbers
    or arrays (then elementwise). A NaN (no value yet) crosses nothing."""
    return ((g0 < 0.0) & (0.0 <= g1) & (direction >= 0.0)) | ((g0 > 0.0) & (0.0 >= g1) & (direction <= 0.0))


def check_events(events, name: str = "events") -> list[tuple[Callable, bool, float]]:
    """``(function, terminal, direction)`` of each event, checked (TypeError/ValueError naming it)."""
    if events is None:
        return []
    checked = []
    for k, event in enumerate(events):
        if not callable(event):
            raise TypeError(f"{name}[{k}] is a {type(event).__name__}, must be a callable event(state) -> float.")
        terminal = getattr(event, "terminal", False)
        direction = getattr(event, "direction", 0.0)
        if not isinstance(terminal, (bool, np.bool_)):
            raise TypeError(f"{name}[{k}].terminal == {terminal!r}, must be True or False.")
        if isinstance(direction, bool) or not isinstance(direction, (int, float)) or not math.isfinite(direction):
            raise ValueError(f"{name}[{k}].direction == {direction!r}, must be a finite number "
                             "(> 0: rising zeros only, < 0: falling only, 0: both).")
        vectorized = getattr(event, "vectorized", False)
        if not isinstance(vectorized, (bool, np.bool_)):
            raise TypeError(f"{name}[{k}].vectorized == {vectorized!r}, must be True or False.")
        checked.append((event, bool(terminal), float(direction)))
    return checked


class overturning:
    """A terminal event for :func:`nscd.simulate`: ``body`` overturns.

    Its value is the body's rotation from its initial orientation minus ``angle`` (rad;
    2D: the angle change, 3D: the tilt of the body's z axis), so it rises through zero
    when the body has rotated by ``angle``, by default the one definition of overturned,
    :data:`nscd.result.OVERTURN_ANGLE`. Vectorized: in a batch it is evaluated for all
    scenes at once, each from the initial orientation of ``scene``.

    Parameters
    ----------
    scene : Scene
    body : Body, int or str
        The body watched (handle, index or name).
    angle : float
        Rotation (rad) in (0, pi].

    Examples
    --------
    >>> result = nscd.simulate(scene, t_end=10.0, dt=1e-3, events=[overturning(scene, "block")])
    >>> result.status, result.t_events[0]      # "event" and the overturning time if it fell
    """

    terminal = True
    direction = 1.0
    vectorized = True

    def __init__(self, scene: Scene, body, angle: float = OVERTURN_ANGLE) -> None:
        if not (isinstance(angle, (int, float)) and 0.0 < angle <= math.pi):
            raise ValueError(f"angle == {angle!r}, must be in (0, pi] rad.")
        handle = scene.body(body)
        self.index, self.dim, self.angle = handle.index, scene.dim, float(angle)
        self.q0 = np.array(handle.q0, dtype=float)

    def __call__(self, states: States) -> np.ndarray:
        q = states.q[:, self.index]
        if self.dim == 2:
            return np.abs(q[:, 2] - self.q0[2]) - self.angle
        return np.array([tilt_angle(self.q0[3:], quaternion) for quaternion in q[:, 3:]]) - self.angle

