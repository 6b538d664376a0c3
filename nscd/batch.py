"""Batched runs: many scenes of one structure advanced in lock step by the one time step.

The cells of a map or the frequencies of a spectrum are independent scenes that share
one structure (one :class:`~nscd.model.Model`: the same bodies, shapes, masses, contact
laws, in the same order) and differ only in the motions of their driven bodies and in
their initial states (their :class:`~nscd.state.Data` rows). :class:`BatchSimulator`
advances B such scenes with :func:`nscd.stepper.step`, the very step of single runs,
over a leading scene axis: the Python overhead of a step is paid once for all scenes,
and each scene follows its single run bit for bit (same operations, no value mixes
scenes; ``tests/test_batch.py`` checks it), splitting its steps at its own impacts.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from nscd._checks import selection
from nscd.model import Model
from nscd.result import Result
from nscd.scene import Scene
from nscd.state import State
from nscd.stepper import Run, Settings, _check_time

__all__ = ["BatchSimulator", "check_same_structure", "default_threads", "simulate_batch"]


#: The environment variable that sets :func:`default_threads` (the workers of a sweep's
#: process pool set it to 1: the pool spreads the batches over the cores already).
THREADS_VARIABLE = "NSCD_THREADS"


def default_threads() -> int:
    """Threads of a batch by default: ``NSCD_THREADS`` when set (an int >= 1), else every core
    this process may use."""
    text = os.environ.get(THREADS_VARIABLE, "").strip()
    if text:
        if not text.isdigit() or int(text) < 1:
            raise ValueError(f"{THREADS_VARIABLE} == {text!r}, must be an int >= 1 (threads of a batch).")
        return int(text)
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def check_same_structure(scenes: Sequence[Scene]) -> Model:
    """The one :class:`~nscd.model.Model` of ``scenes``, checked to be the same for all.

    Scenes share a model when they have the same dimension and gravity, the same bodies
    in the same order (name, kind, shape vertices, mass, inertia, material, direction of
    motion) and the same contact law for every pair of bodies. Motions of driven bodies
    and initial positions and velocities may differ.

    Raises
    ------
    ValueError
        Naming the first scene and the first body or field that differs from
        ``scenes[0]``, or if ``scenes`` is empty.
    TypeError
        If an entry is not a Scene.
    """
    scenes = list(scenes)
    if not scenes:
        raise ValueError("scenes is empty, must hold at least one Scene.")
    for k, scene in enumerate(scenes):
        if not isinstance(scene, Scene):
            raise TypeError(f"scenes[{k}] is a {type(scene).__name__}, must be a Scene.")
    model = Model.from_scene(scenes[0])
    for k, scene in enumerate(scenes[1:], start=1):
        difference = model.difference(Model.from_scene(scene), this="scenes[0]")
        if difference is not None:
            raise ValueError(f"scenes[{k}] differs from scenes[0]: {difference}.")
    return model


class BatchSimulator:
    """Advance B scenes of one structure in lock step, each exactly as :class:`nscd.Simulator` would.

    Parameters
    ----------
    scenes : sequence of Scene
        Scenes sharing one structure (:func:`check_same_structure`), 2D or 3D: they may
        differ in the motions of their driven bodies and in their initial states.
    dt : float
        Time step of every scene, s (> 0).
    settings : Settings, optional
        Integrator and solver options, shared (either scheme). ``on_failure="raise"``
        raises :class:`nscd.result.SolverFailure` naming the scene; ``"warn"`` warns once
        per unconverged step and scene, as single runs do.
    record : bool
        Keep every scene's histories for :meth:`results` (default). False keeps only
        the current states and the counters (:attr:`unconverged`): less memory and
        less work per step, for sweeps that look at the states as they go.
    store_impulses : bool
        With ``record``, keep contact points and impulses of every step.
    events : sequence of callable, or one such sequence per scene, optional
        Event functions of the state (see :func:`nscd.simulate`): one list evaluated in
        every scene, or a list of lists, scene by scene (e.g. events that know their
        scene's motion); a terminal event stops its scene (:attr:`running` turns False).
    threads : int, optional
        Threads among which the compiled steps of the scenes are dealt out (scenes of at most
        48 bodies, ``ALL_PAIRS_BODIES``; the general steps run in the calling thread); default
        :func:`default_threads`. 1: the calling thread only.

    Attributes
    ----------
    model : Model
    data : Data
        The B rows: :attr:`t`, :attr:`q`, :attr:`v` are its arrays.
    running : ndarray of bool, shape (B,)
        Scenes still stepped; :meth:`stop` takes a scene out (it then costs nothing).
    unconverged : ndarray of int, shape (B,)
        Steps of each scene whose contact problem did not converge.
    converged : ndarray of bool, shape (B,)
        Whether the last step of each scene converged.

    Examples
    --------
    >>> sim = BatchSimulator([scene_a, scene_b], dt=1e-3)
    >>> sim.run(until=1.0)
    >>> result_a, result_b = sim.results()
    """

    def __init__(self, scenes: Sequence[Scene], dt: float, settings: Settings | None = None,
                 record: bool = True, store_impulses: bool = False, *, events=None,
                 threads: int | None = None) -> None:
        _check_time(0.0, dt)
        if threads is None:
            threads = default_threads()
        if isinstance(threads, bool) or not isinstance(threads, (int, np.integer)) or threads < 1:
            raise ValueError(f"threads == {threads!r}, must be an int >= 1 or None (every core).")
        self.settings = settings or Settings()
        self.dt = float(dt)
        scenes = list(scenes)
        self.model = check_same_structure(scenes)
        self._run = Run(self.model, scenes, dt, self.settings, record, store_impulses,
                        [f"scene {k}: " for k in range(len(scenes))], events, int(threads))
        self.data = self._run.data
        self.running, self.unconverged, self.converged = self._run.running, self._run.unconverged, self._run.converged

    @property
    def t(self) -> np.ndarray:
        """Time of each scene, s, shape (B,)."""
        return self.data.t

    @property
    def q(self) -> np.ndarray:
        """Positions of every scene, shape (B, n_bodies, nq)."""
        return self.data.q

    @property
    def v(self) -> np.ndarray:
        """Velocities of every scene, shape (B, n_bodies, nv)."""
        return self.data.v

    def __len__(self) -> int:
        return len(self.data)

    def state(self, k: int) -> State:
        """The current state of scene ``k`` (a read-only snapshot)."""
        return self.data.state(k)

    def stop(self, k: int | np.ndarray) -> None:
        """Stop stepping scene(s) ``k`` (index, indices or boolean mask)."""
        self.running[selection("k", k, len(self))] = False

    def step(self) -> np.ndarray:
        """Advance every running scene by one step (split at its own impacts, if any).

        Returns
        -------
        ndarray of int
            Indices of the scenes stepped. Unconverged steps are counted in
            :attr:`unconverged` and warn or raise as ``settings.on_failure`` says.
        """
        return self._run.step(stacklevel=2)

    def run(self, until: float) -> None:
        """Step every running scene until time ``until`` (s), as :meth:`nscd.Simulator.run`."""
        n_steps = int(round((until - float(np.min(self.t[self.running], initial=until))) / self.dt))
        self._run.advance(max(n_steps, 0), stacklevel=2)

    def advance(self, steps: np.ndarray, ended: Callable[[np.ndarray], Any] | None = None) -> None:
        """Step each running scene ``k`` ``steps[k]`` times (an int array (B,), counted down in
        place), or until a terminal event stops it, each as :meth:`step` would; ``ended(rows)``
        is called with the indices of the scenes that end (stopped or done) as they end.
        Without events the scenes are not kept in lock step (each takes many compiled steps
        per call); every scene's steps are those of its single run all the same."""
        if not (isinstance(steps, np.ndarray) and steps.shape == (len(self),) and steps.dtype.kind == "i"):
            raise ValueError(f"steps has shape {np.shape(steps)} and dtype {getattr(steps, 'dtype', type(steps))}, "
                             f"must be an int array of shape ({len(self)},).")
        self._run.advance_scenes(steps, stacklevel=2, ended=ended)

    def results(self, status: str = "finished", message: str = "") -> list[Result]:
        """Each scene's :class:`nscd.Result` (needs ``record=True``).

        ``wall_time`` of each result is the batch's stepping time divided by the number
        of scenes.
        """
        if self._run.builders is None:
            raise ValueError("record == False: this BatchSimulator kept no histories; "
                             "create it with record=True to get results.")
        return self._run.results(status, message, 1.0 / len(self))


def simulate_batch(scenes: Sequence[Scene], t_end: float, dt: float, settings: Settings | None = None,
                   store_impulses: bool = False, *, events=None) -> list[Result]:
    """Simulate scenes of one structure from t = 0 to ``t_end``, together.

    The batched counterpart of :func:`nscd.simulate`: ``simulate_batch(scenes, t_end, dt)[k]``
    equals ``nscd.simulate(scenes[k], t_end, dt)`` (same trajectory, impacts and solver
    reports; only ``report.wall_time`` differs).

    Parameters
    ----------
    scenes : sequence of Scene
        Scenes of one structure (see :func:`check_same_structure`).
    t_end : float
        End time, s (>= 0).
    dt : float
        Time step, s, in (0, t_end].
    settings : Settings, optional
    store_impulses : bool
        Keep contact points and impulses of every step.
    events : sequence of callable, optional
        As in :func:`nscd.simulate`, in every scene.

    Returns
    -------
    list of Result
        One per scene, in order.
    """
    _check_time(t_end, dt)
    sim = BatchSimulator(scenes, dt, settings, record=True, store_impulses=store_impulses, events=events)
    sim._run.advance(int(round(t_end / dt)), stacklevel=2)
    return sim.results()
