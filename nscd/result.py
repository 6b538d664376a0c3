"""What a simulation produced: histories, energies, impacts, solver reports.

:class:`Result` is shaped like scipy's ``solve_ivp`` result: arrays over time (time
is the first axis), a ``status`` and ``message``, counters in ``report``, and accessors
per body. It saves to and loads from ``.npz`` (:meth:`Result.save`, :func:`load`).
"""
from __future__ import annotations

import json
import math
import os
import warnings
import zipfile
import zlib
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from nscd._atomic import check_writable, replacing
from nscd._checks import real_number
from nscd._jit import njit
from nscd.impact_law import dissipation
from nscd.rotation import tilt_angle

#: Rotation (rad) from its initial orientation beyond which a body counts as overturned:
#: pi/2 - 0.02, within 0.02 rad (about one degree) of lying on its side. A block that has
#: passed its slenderness angle alpha (< pi/4 for the blocks of the papers) in free
#: motion falls there; at this angle gravity's overturning moment about the pivot is
#: near its largest and no ground acceleration of a shaking table brings the block back.
#: The one definition of "overturned": :meth:`Result.overturned`, the ParaView export
#: (:mod:`nscd.io`), the double-pulse rig (:mod:`nscd.rigs`), the 1-DOF rocking model
#: (:mod:`nscd.rocking`) and the overturning event of a run
#: (:class:`nscd.events.overturning`) use it.
OVERTURN_ANGLE = math.pi / 2 - 0.02

_FORMAT_VERSION = 1


class SolverFailure(RuntimeError):
    """A contact problem was not solved to tolerance and the settings asked to raise."""


class StepReport(NamedTuple):
    """Report of one time step (immutable: a named tuple, made at every step of
    :meth:`~nscd.stepper.Simulator.step` at a fifth of a frozen dataclass's cost).

    Attributes
    ----------
    t : float
        Time at the end of the step, s.
    n_contacts, n_active : int
        Contact points detected (within the margin) and in the active set.
    status : str
        Solver status ("converged", "converged after polish", "no contact", or a failure).
    converged : bool
    iterations : int
        Solver iterations (fixed point on the De Saxcé shift).
    merit : float
        FCLIB merit of the contact problem at the returned impulses (0 without contact).
    penetration : float
        Deepest overlap of two bodies at the end of the step, m (>= 0; 0 when none
        overlaps): predicted to first order from the gaps and relative velocities of every
        contact detected in the step (detection covers every contact that can close in
        the step), or, where that prediction plus its error bound nears the warning
        threshold, detected in the end configuration (see ``docs/time_step.md``).
    """

    t: float
    n_contacts: int
    n_active: int
    status: str
    converged: bool
    iterations: int
    merit: float
    penetration: float = 0.0


@dataclass(frozen=True)
class SolverReport:
    """Solver statistics over a run (arrays have one entry per step).

    Attributes
    ----------
    n_steps : int
    n_unconverged : int
    unconverged_times : ndarray
        End times (s) of steps whose contact problem did not converge.
    statuses : dict
        Count of steps per solver status.
    iterations, merit, n_contacts, n_active : ndarray, shape (n_steps,)
    max_merit : float
    wall_time : float
        Wall-clock seconds spent stepping.
    penetration : ndarray, shape (n_steps,)
        Deepest overlap at the end of each step, m (:attr:`StepReport.penetration`).
    max_penetration : float
        Its maximum over the run, m.
    energy_residual : float
        Largest ``|kinetic + potential + dissipated - work_input - E(0)|`` over the run, J:
        round-off for 2D runs with theta = 1/2 or the midpoint rule, where the step's
        kinetic-energy identity is exact; otherwise the scheme's own energy error too.
    """

    n_steps: int
    n_unconverged: int
    unconverged_times: np.ndarray
    statuses: dict
    iterations: np.ndarray
    merit: np.ndarray
    n_contacts: np.ndarray
    n_active: np.ndarray
    max_merit: float
    wall_time: float
    penetration: np.ndarray = field(default_factory=lambda: np.zeros(0))
    max_penetration: float = 0.0
    energy_residual: float = 0.0

    def __str__(self) -> str:
        per_step = 1e6 * self.wall_time / max(self.n_steps, 1)
        return (f"{self.n_steps} steps, {self.n_unconverged} unconverged, max merit "
                f"{self.max_merit:.2e}, mean solver iterations "
                f"{(self.iterations.mean() if self.n_steps else 0):.2f}, "
                f"{per_step:.0f} us/step, statuses {self.statuses}")


@dataclass
class Result:
    """Histories of a simulation.

    Attributes
    ----------
    time : ndarray, shape (n,)
        s, including t = 0.
    q : ndarray, shape (n, n_bodies, nq)
        Generalised positions (see :class:`nscd.State`).
    v : ndarray, shape (n, n_bodies, nv)
        Velocities.
    kinetic, potential : ndarray, shape (n,)
        Kinetic and gravitational potential energy of the dynamic bodies, J
        (per unit depth in 2D); potential is zero at height 0.
    dissipated : ndarray, shape (n,)
        Energy dissipated at the contacts since t = 0, J (>= 0 up to solver tolerance):
        the sum over steps and contacts of ``-P . (u_k + u_{k+1}) / 2`` (impulse times the
        mean relative velocity).
    work_input : ndarray, shape (n,)
        Work done on the dynamic bodies by driven bodies since t = 0, J: the sum of
        ``-P . (w_k + w_{k+1}) / 2``, ``w`` the part of the contacts' relative velocity due
        to the driven bodies' motion. Computed from impulses and velocities, independently
        of the energies: ``kinetic + potential + dissipated - work_input`` stays at its
        initial value up to :attr:`SolverReport.energy_residual`.
    impacts : dict of ndarray
        Impact events (a contact point that closes: inactive in the previous step, active
        now, approaching faster than ``Settings.impact_speed``): ``time`` (s: the impact instant
        when impacts are localised, else the end of the step), ``body_a``, ``body_b`` (indices), ``point`` (m),
        ``u_before``, ``u_after`` (normal relative velocity, m/s), ``impulse`` (N s).
    report : SolverReport
    status : str
        "finished", "interrupted", "event" (stopped by a terminal event) or "running" (a checkpoint).
    message : str
    body_names : list of str
    dim : int
    dt : float
    contacts : list of dict or None
        Per step, when ``store_impulses=True``: ``body_a``, ``body_b``, ``point``, ``frame``,
        ``impulse`` (N s, in the contact frame) of the active contacts.
    shapes : list of ndarray
        Body-frame vertices of each body (for export).
    t_events : list of ndarray
        With ``simulate(..., events=[...])``: per event, the times (s) at which it
        occurred, located within the step (see :func:`nscd.stepper.simulate`).
    """

    time: np.ndarray
    q: np.ndarray
    v: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    dissipated: np.ndarray
    work_input: np.ndarray
    impacts: dict
    report: SolverReport
    status: str
    message: str
    body_names: list
    dim: int
    dt: float
    shapes: list
    body_kinds: list = field(default_factory=list)
    contacts: list | None = None
    t_events: list = field(default_factory=list)

    @property
    def success(self) -> bool:
        """True when the run finished and every step converged."""
        return self.status == "finished" and self.report.n_unconverged == 0

    # -- per-body accessors ------------------------------------------------------
    def _index(self, body: Any) -> int:
        if isinstance(body, (int, np.integer)):
            index = int(body)
        elif isinstance(body, str):
            if body not in self.body_names:
                raise ValueError(f"no body named {body!r}; bodies are {self.body_names}.")
            index = self.body_names.index(body)
        else:
            index = int(body.index)
        if not 0 <= index < len(self.body_names):
            raise ValueError(f"body index {index} out of range [0, {len(self.body_names) - 1}].")
        return index

    def position(self, body: Any) -> np.ndarray:
        """Centre-of-mass position, m, shape (n, dim)."""
        return self.q[:, self._index(body), :self.dim]

    def angle(self, body: Any) -> np.ndarray:
        """2D rotation angle, rad (CCW positive), shape (n,)."""
        if self.dim != 2:
            raise ValueError("angle() is for 2D results; use orientation() or rotation() in 3D.")
        return self.q[:, self._index(body), 2]

    def orientation(self, body: Any) -> np.ndarray:
        """3D unit quaternion (w, x, y, z), shape (n, 4)."""
        if self.dim != 3:
            raise ValueError("orientation() is for 3D results; use angle() in 2D.")
        return self.q[:, self._index(body), 3:]

    def velocity(self, body: Any) -> np.ndarray:
        """Centre-of-mass velocity, m/s, shape (n, dim)."""
        return self.v[:, self._index(body), :self.dim]

    def omega(self, body: Any) -> np.ndarray:
        """Angular velocity, rad/s: shape (n,) in 2D (CCW), (n, 3) in 3D (world frame)."""
        w = self.v[:, self._index(body), self.dim:]
        return w[:, 0] if self.dim == 2 else w

    def rotation(self, body: Any) -> np.ndarray:
        """Rotation from the initial orientation, rad, shape (n,).

        2D: signed angle change (CCW positive). 3D: tilt of the body's z axis (>= 0).
        """
        i = self._index(body)
        if self.dim == 2:
            return self.q[:, i, 2] - self.q[0, i, 2]
        q0 = self.q[0, i, 3:]
        return np.array([tilt_angle(q0, qk) for qk in self.q[:, i, 3:]])

    def overturned(self, body: Any, angle: float | None = None) -> bool:
        """Whether ``body`` overturned: it rotated at some time by more than ``angle``
        (default :data:`OVERTURN_ANGLE`; this test needs ``t_end`` long enough for the fall)."""
        limit = OVERTURN_ANGLE if angle is None else float(angle)
        return bool(np.max(np.abs(self.rotation(body))) > limit)

    def to_paraview(self, path: str | Path, every: int = 1, depth: float | None = None) -> list[Path]:
        """Write ParaView time series of the blocks and contact impulses; see :func:`nscd.io.to_paraview`."""
        from nscd.io import to_paraview  # io imports this module

        return to_paraview(self, path, every=every, depth=depth)

    # -- persistence -------------------------------------------------------------
    def animate(self, path: str | Path, **options: Any) -> Path:
        """Write a GIF (Pillow) or MP4 (ffmpeg) of the run; see :func:`nscd.plot.animate.animate`."""
        from nscd.plot.animate import animate

        return animate(self, path, **options)

    def save(self, path: str | Path) -> Path:
        """Save to a compressed ``.npz`` file (no pickles); returns the path.

        The file is written atomically (a temporary file in the same folder, renamed over
        ``path``): a crash during the save leaves the previous file whole. The suffix
        ``.npz`` is added when missing.
        """
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_suffix(".npz")
        path.parent.mkdir(parents=True, exist_ok=True)
        rep = self.report
        meta = {
            "format": _FORMAT_VERSION, "status": self.status, "message": self.message,
            "body_names": self.body_names, "body_kinds": self.body_kinds, "dim": self.dim,
            "dt": self.dt, "statuses": rep.statuses, "wall_time": rep.wall_time,
        }
        arrays = {
            "time": self.time, "q": self.q, "v": self.v, "kinetic": self.kinetic,
            "potential": self.potential, "dissipated": self.dissipated,
            "work_input": self.work_input, "rep_iterations": rep.iterations,
            "rep_merit": rep.merit, "rep_n_contacts": rep.n_contacts,
            "rep_n_active": rep.n_active, "rep_unconverged_times": rep.unconverged_times,
            "rep_penetration": rep.penetration,
        }
        arrays.update({f"impact_{k}": v for k, v in self.impacts.items()})
        arrays.update({f"shape_{i}": s for i, s in enumerate(self.shapes)})
        with replacing(path) as tmp, open(tmp, "wb") as handle:
            np.savez_compressed(handle, meta=np.array(json.dumps(meta)), **arrays)
        return path


def checkpoint_path(checkpoint: str | Path | None, every: float) -> Path | None:
    """Check the ``checkpoint`` and ``checkpoint_every`` arguments of a run before its first step.

    Returns the path the checkpoint is saved to (suffix ``.npz``), or None without one.

    Raises
    ------
    ValueError
        ``checkpoint_every`` is not a number > 0 s, or no file can be written at ``checkpoint``.
    """
    every = real_number("checkpoint_every", every)
    if not every > 0.0:
        raise ValueError(f"checkpoint_every == {every}, must be > 0 s (wall-clock seconds between saves).")
    if checkpoint is None:
        return None
    if not isinstance(checkpoint, (str, os.PathLike)) or str(checkpoint) == "":
        raise TypeError(f"checkpoint == {checkpoint!r}, must be a file path (str or Path) or None.")
    path = Path(checkpoint)
    return check_writable(path if path.suffix == ".npz" else path.with_suffix(".npz"), "checkpoint")


def save_checkpoint(result: Result, path: Path | None) -> None:
    """Save ``result`` to ``path`` (when given); a failed save warns and never raises.

    The run's result is returned to the caller in any case, so a full disk or a removed
    folder costs the file, never the computed histories.
    """
    if path is None:
        return
    try:
        result.save(path)
    except OSError as exc:
        warnings.warn(f"checkpoint {str(path)!r} could not be saved ({exc}); the result is returned "
                      "but not on disk.", RuntimeWarning, stacklevel=3)


#: Arrays every saved result holds (besides ``meta``, ``impact_*`` and ``shape_*``).
_ARRAYS = ("time", "q", "v", "kinetic", "potential", "dissipated", "work_input", "rep_iterations",
           "rep_merit", "rep_n_contacts", "rep_n_active", "rep_unconverged_times")
_META = ("format", "status", "message", "body_names", "body_kinds", "dim", "dt", "statuses", "wall_time")


def load(path: str | Path) -> Result:
    """Load a :class:`Result` saved with :meth:`Result.save`.

    Raises
    ------
    FileNotFoundError
        No file at ``path``.
    ValueError
        Naming the file, when it is not a result saved by nscd (not an ``.npz`` archive, cut
        short, another program's archive, an unknown format version) or its histories are
        inconsistent (array lengths, non-finite or decreasing times).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no result file {str(path)!r}.")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        reason = str(exc).split(". ")[0]  # numpy's "pickled data" message runs on for 3 sentences
        raise ValueError(f"{path} is not a NumPy .npz archive ({type(exc).__name__}: {reason}); results are "
                         "saved with Result.save.") from None
    missing = [k for k in ("meta", *_ARRAYS) if k not in arrays]
    if missing:
        raise ValueError(f"{path} is not an nscd result (no {', '.join(repr(k) for k in missing[:3])}"
                         f"{'...' if len(missing) > 3 else ''} entry); results are saved with Result.save.")
    try:
        meta = json.loads(str(arrays["meta"]))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: its 'meta' entry is not JSON ({exc}).") from None
    if not isinstance(meta, dict) or meta.get("format") != _FORMAT_VERSION:
        found = meta.get("format") if isinstance(meta, dict) else meta
        raise ValueError(f"{path}: unknown result format {found!r}, this nscd reads format {_FORMAT_VERSION}.")
    absent = [k for k in _META if k not in meta]
    if absent:
        raise ValueError(f"{path}: the result description lacks {absent}.")
    _check_histories(path, arrays, len(meta["body_names"]))
    n_bodies = len(meta["body_names"])
    report = _report(arrays["rep_iterations"], arrays["rep_merit"], arrays["rep_n_contacts"],
                     arrays["rep_n_active"], arrays["rep_unconverged_times"],
                     meta["statuses"], meta["wall_time"],
                     arrays.get("rep_penetration", np.zeros(len(arrays["rep_iterations"]))))
    report = replace(report, energy_residual=energy_residual(arrays["kinetic"], arrays["potential"],
                                                             arrays["dissipated"], arrays["work_input"]))
    impacts = {k[len("impact_"):]: arrays[k] for k in arrays if k.startswith("impact_")}
    return Result(
        time=arrays["time"], q=arrays["q"], v=arrays["v"], kinetic=arrays["kinetic"],
        potential=arrays["potential"], dissipated=arrays["dissipated"],
        work_input=arrays["work_input"], impacts=impacts, report=report,
        status=meta["status"], message=meta["message"], body_names=meta["body_names"],
        dim=meta["dim"], dt=meta["dt"], body_kinds=meta["body_kinds"],
        shapes=[arrays[f"shape_{i}"] for i in range(n_bodies)],
    )


def _check_histories(path: Path, arrays: dict[str, np.ndarray], n_bodies: int) -> None:
    """ValueError naming the file when the saved histories do not fit together."""
    time = arrays["time"]
    if time.ndim != 1 or time.size == 0 or not np.issubdtype(time.dtype, np.floating):
        raise ValueError(f"{path}: time has shape {time.shape} and dtype {time.dtype}, must be a 1-D "
                         "float array with t = 0 first.")
    bad = np.flatnonzero(~np.isfinite(time))
    if bad.size:
        raise ValueError(f"{path}: time[{bad[0]}] == {time[bad[0]]} ({bad.size} of {time.size} times "
                         "not finite); the file is damaged.")
    if np.any(np.diff(time) < 0.0):
        raise ValueError(f"{path}: times decrease at index {int(np.argmax(np.diff(time) < 0.0)) + 1}; "
                         "the file is damaged.")
    n = time.size
    for name in ("q", "v"):
        if arrays[name].ndim != 3 or arrays[name].shape[:2] != (n, n_bodies):
            raise ValueError(f"{path}: {name} has shape {arrays[name].shape}, must be ({n}, {n_bodies}, ...).")
    for name in ("kinetic", "potential", "dissipated", "work_input"):
        if arrays[name].shape != (n,):
            raise ValueError(f"{path}: {name} has shape {arrays[name].shape}, must be ({n},) like time.")
    for name in ("rep_iterations", "rep_merit", "rep_n_contacts", "rep_n_active"):
        if arrays[name].shape != (n - 1,):
            raise ValueError(f"{path}: {name} has shape {arrays[name].shape}, must be ({n - 1},): one per step.")
    shapes = [k for k in arrays if k.startswith("shape_")]
    if len(shapes) != n_bodies:
        raise ValueError(f"{path}: {len(shapes)} body shapes for {n_bodies} bodies.")


def _collapse_hint(settings, unknowns: np.ndarray) -> str:
    """What the message of a run adds when steps with large contact problems (``unknowns``:
    each unconverged step's active rows) missed the absolute merit with no relative tolerance
    set: the setting for assemblies that break up (``docs/guide/solver.md``); else ''."""
    solver = settings.solver
    if solver.tol_relative is not None or not unknowns.size or unknowns.max() <= solver.large_problem_unknowns:
        return ""
    return (f"; an assembly breaking up reaches the absolute merit {solver.tol:g} on few steps: for a collapse "
            "study, Settings(solver=SolverSettings(tol_relative=1e-4, max_conic_unknowns=0)) "
            "(docs/guide/solver.md)")


def _report(iterations, merit, n_contacts, n_active, unconverged_times, statuses, wall,
            penetration) -> SolverReport:
    penetration = np.asarray(penetration, float)
    return SolverReport(
        n_steps=len(iterations), n_unconverged=len(unconverged_times),
        unconverged_times=np.asarray(unconverged_times, float), statuses=dict(statuses),
        iterations=np.asarray(iterations), merit=np.asarray(merit, float),
        n_contacts=np.asarray(n_contacts), n_active=np.asarray(n_active),
        max_merit=float(np.max(merit)) if len(merit) else 0.0, wall_time=float(wall),
        penetration=penetration, max_penetration=float(np.max(penetration)) if len(penetration) else 0.0,
    )


def energy_residual(kinetic: np.ndarray, potential: np.ndarray, dissipated: np.ndarray,
                    work_input: np.ndarray) -> float:
    """Largest drift of ``kinetic + potential + dissipated - work_input`` from its initial value, J."""
    balance = kinetic + potential + dissipated - work_input
    return float(np.max(np.abs(balance - balance[0]))) if len(balance) else 0.0


class ResultBuilder:
    """Accumulates a run's steps into a :class:`Result` (used by the simulator).

    Every history lives in an array preallocated with room for more rows and doubled when
    full (:meth:`reserve`); rows ``[0, count)`` of the state histories are filled (the
    initial state first), and row ``k - 1`` of the per-step reports belongs to the step that
    ended in state row ``k``. A step is recorded by :meth:`add` (from its
    :class:`~nscd.stepper.StepOutput`), or by the compiled step of a small scene
    (:mod:`nscd.compiled_step`), which writes the same arrays in place (:meth:`arrays`)
    with the same formulas: one recording, whichever path took the step.
    """

    #: the per-step report arrays and their dtypes
    _REPORTS = (("iterations", np.int64), ("merit", float), ("n_contacts", np.int64), ("n_active", np.int64),
                ("penetration", float), ("status", np.int64), ("converged", np.bool_))

    def __init__(self, model, state, store_impulses: bool, impact_speed: float) -> None:
        self.model = model
        self.store_impulses = store_impulses
        self.impact_speed = impact_speed
        #: rows of the state histories filled, and impacts recorded
        self.counts = np.array([1, 0], dtype=np.int64)
        self.times = np.array([state.t])
        self.qs, self.vs = state.q[None].copy(), state.v[None].copy()
        self.dissipated = np.zeros(1)
        self.work_input = np.zeros(1)
        for name, dtype in self._REPORTS:
            setattr(self, name, np.zeros(1, dtype=dtype))
        dim = model.dim
        # impacts: contacts that close, active now, not active in the step before, approaching
        # faster than impact_speed: time (s), bodies, point (m), normal velocities before and
        # after (m/s) and normal impulse (N s)
        self.impact_time, self.impact_a, self.impact_b = np.zeros(1), np.zeros(1, np.int64), np.zeros(1, np.int64)
        self.impact_point, self.impact_before = np.zeros((1, dim)), np.zeros(1)
        self.impact_after, self.impact_impulse = np.zeros(1), np.zeros(1)
        self.status_names: list[str] = []  # the solver statuses met, by the codes of ``status``
        self._status_codes: dict[str, int] = {}
        self.contacts: list[dict] = []
        self._was_active = np.zeros((0, 3), dtype=np.int64)  # ids of the last step's active contacts
        self._arrays: tuple | None = None

    @property
    def count(self) -> int:
        """Rows of the state histories filled (the initial state and one per step)."""
        return self.counts.item(0)

    def status_code(self, status: str) -> int:
        """The code of the solver status ``status`` in :attr:`status`."""
        code = self._status_codes.get(status)
        if code is None:
            code = self._status_codes[status] = len(self.status_names)
            self.status_names.append(status)
        return code

    def reserve(self, steps: int, impacts: int) -> None:
        """Room for ``steps`` more steps and ``impacts`` more impacts (arrays doubled as needed)."""
        rows, filled = len(self.times), self.count
        if filled + steps > rows:
            size = max(2 * rows, filled + steps)
            for name in ("times", "qs", "vs", "dissipated", "work_input", *(n for n, _ in self._REPORTS)):
                setattr(self, name, _grown(getattr(self, name), size))
            self._arrays = None
        rows = len(self.impact_time)
        impacts_filled = self.counts.item(1)
        if impacts_filled + impacts > rows:
            size = max(2 * rows, impacts_filled + impacts)
            for name in ("impact_time", "impact_a", "impact_b", "impact_point", "impact_before", "impact_after",
                         "impact_impulse"):
                setattr(self, name, _grown(getattr(self, name), size))
            self._arrays = None

    def arrays(self) -> tuple:
        """The history arrays as the compiled step writes them (:mod:`nscd.compiled_step`):
        times, qs, vs, dissipated, work_input, the per-step reports, the impacts, counts.
        New arrays after :meth:`reserve` has grown them."""
        if self._arrays is None:
            self._arrays = self._all_arrays()
        return self._arrays

    def _all_arrays(self) -> tuple:
        return (self.times, self.qs, self.vs, self.dissipated, self.work_input,
                *(getattr(self, name) for name, _ in self._REPORTS),
                self.impact_time, self.impact_a, self.impact_b, self.impact_point, self.impact_before,
                self.impact_after, self.impact_impulse, self.counts)

    def report(self, k: int) -> StepReport:
        """The report of the step that ended in state row ``k`` (>= 1)."""
        j = k - 1
        # positional, the values read as Python numbers (``item``): a report per step of Simulator.step
        return StepReport(self.times.item(k), self.n_contacts.item(j), self.n_active.item(j),
                          self.status_names[self.status.item(j)], self.converged.item(j), self.iterations.item(j),
                          self.merit.item(j), self.penetration.item(j))

    def _energies(self, q: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Kinetic and potential energy (J) of the dynamic bodies over a history q (n, n_bodies, nq), v."""
        model = self.model
        dyn = model.dynamic_index
        mass = model.mass[dyn]
        v_dyn = v[:, dyn]
        kinetic = 0.5 * np.sum(mass * np.sum(v_dyn[..., :model.dim] ** 2, axis=-1), axis=-1)
        inertia = model.world_inertia(q)
        if model.dim == 2:
            kinetic += 0.5 * np.sum(inertia * v_dyn[..., 2] ** 2, axis=-1)
        else:
            w = v_dyn[..., 3:]
            kinetic += 0.5 * np.einsum("tni,tnij,tnj->t", w, inertia, w)
        potential = model.gravity * np.sum(mass * q[:, dyn, model.dim - 1], axis=-1)
        return kinetic, potential

    def add(self, t: float, q: np.ndarray, v: np.ndarray, out) -> None:
        """Record one step that ended at time ``t`` (s) in ``q``, ``v`` (copied) and produced ``out`` (a StepOutput)."""
        self.reserve(1, len(out.active))
        k = int(self.counts[0])
        self.counts[0] = k + 1
        self.times[k], self.qs[k], self.vs[k] = t, q, v
        # The step's kinetic-energy identity: with M (v+ - v-) = h f + H^T P (dynamic bodies),
        # K+ - K- = v_avg . (h f + H^T P), v_avg = (v+ + v-)/2, and P . H v_avg = P . (u_avg - w_avg)
        # (u = H v + w, w: the part of the relative velocity due to fixed and driven bodies).
        # So K+ - K- = h f . v_avg - D + W with the contacts' dissipation D = -P . u_avg
        # (from impulses and relative velocities) and the driven bodies' work W = -P . w_avg.
        # h f . v_avg is the change of potential energy exactly when q+ - q- = h v_avg
        # (theta = 1/2, midpoint rule; 2D): kinetic + potential + D - W is then constant to
        # round-off, a check of the step, not a definition.
        driven = out.driven_velocity()
        lost, _ = dissipation(out.impulses, out.u_before, out.u_after)
        self.dissipated[k] = self.dissipated[k - 1] + lost
        self.work_input[k] = self.work_input[k - 1] - driven_work(out.impulses, driven)
        report = out.report
        j = k - 1
        self.iterations[j], self.merit[j], self.penetration[j] = report.iterations, report.merit, report.penetration
        self.n_contacts[j], self.n_active[j] = report.n_contacts, report.n_active
        self.status[j], self.converged[j] = self.status_code(report.status), report.converged
        c = out.contacts
        # An impact is a contact that closes: active now, not active in the previous step,
        # approaching faster than impact_speed.
        active_ids = c.ids[out.active]
        approaching = np.flatnonzero(out.u_before[:, 0] < -self.impact_speed)
        if approaching.size:
            # only the approaching contacts are looked up (a resting wall has none)
            was_active = set(map(tuple, self._was_active.tolist()))  # plain ints: cheap to hash
            for a in approaching.tolist():
                if tuple(active_ids[a].tolist()) not in was_active:
                    i, n = out.active[a], int(self.counts[1])
                    self.counts[1] = n + 1
                    self.impact_time[n], self.impact_a[n], self.impact_b[n] = out.solved_at[a], c.body_a[i], c.body_b[i]
                    self.impact_point[n] = c.point[i]
                    self.impact_before[n], self.impact_after[n] = out.u_before[a, 0], out.u_after[a, 0]
                    self.impact_impulse[n] = out.impulses[a, 0]
        self._was_active = active_ids
        if self.store_impulses:
            act = out.active
            self.contacts.append({"body_a": c.body_a[act], "body_b": c.body_b[act],
                                  "point": c.point[act], "frame": c.frame[act],
                                  "impulse": out.impulses})

    def was_active(self, ids: np.ndarray) -> None:
        """The contacts active in the last step recorded are ``ids`` (k, 3) (a step the compiled
        path recorded: the warm start it hands on lists them)."""
        self._was_active = ids

    def build(self, status: str, message: str, wall_time: float, dt: float, settings) -> Result:
        model = self.model
        n = int(self.counts[0])
        steps = n - 1
        codes, first, counts = np.unique(self.status[:steps], return_index=True, return_counts=True)
        statuses = {self.status_names[codes[i]]: int(counts[i]) for i in np.argsort(first, kind="stable")}
        converged = self.converged[:steps]
        report = _report(self.iterations[:steps].copy(), self.merit[:steps].copy(), self.n_contacts[:steps].copy(),
                         self.n_active[:steps].copy(), self.times[1:n][~converged], statuses, wall_time,
                         self.penetration[:steps].copy())
        if not message:
            message = ("all steps converged" if report.n_unconverged == 0 else
                       f"{report.n_unconverged} of {report.n_steps} steps did not converge "
                       f"(first at t = {report.unconverged_times[0]:.6g} s)"
                       + _collapse_hint(settings, self.n_active[:steps][~converged] * model.dim))
        q, v = self.qs[:n].copy(), self.vs[:n].copy()
        kinetic, potential = self._energies(q, v)
        dissipated = self.dissipated[:n].copy()
        dim = model.dim
        m = int(self.counts[1])
        impacts = {"time": self.impact_time[:m].copy(), "body_a": self.impact_a[:m].copy(),
                   "body_b": self.impact_b[:m].copy(), "point": self.impact_point[:m].copy(),
                   "u_before": self.impact_before[:m].copy(), "u_after": self.impact_after[:m].copy(),
                   "impulse": self.impact_impulse[:m].copy()}
        work_input = self.work_input[:n].copy()
        report = replace(report, energy_residual=energy_residual(kinetic, potential, dissipated, work_input))
        return Result(
            time=self.times[:n].copy(), q=q, v=v,
            kinetic=kinetic, potential=potential, dissipated=dissipated,
            work_input=work_input,
            impacts=impacts, report=report, status=status, message=message,
            body_names=[b.name for b in model.bodies], dim=dim, dt=dt,
            body_kinds=[b.kind.value for b in model.bodies],
            shapes=[np.asarray(b.shape.vertices) for b in model.bodies],
            contacts=self.contacts if self.store_impulses else None,
        )


def _grown(a: np.ndarray, rows: int) -> np.ndarray:
    """``a`` with ``rows`` rows, its own rows first (the rest uninitialised)."""
    out = np.empty((rows, *a.shape[1:]), dtype=a.dtype)
    out[:len(a)] = a
    return out


@njit
def driven_work(impulses: np.ndarray, driven: np.ndarray) -> float:
    """The sum of the products of a step's impulses and driven velocities, J.

    ``impulses`` (k, dim), N s, and ``driven`` (k, dim), m/s (the driven bodies' part of the
    relative velocities) of the active contacts: ``sum P . w``, summed as
    ``np.sum(impulses * driven)`` sums them (numpy's pairwise summation in C order), the same bits.
    """
    products = np.empty(impulses.size)
    for c in range(impulses.shape[0]):
        for d in range(impulses.shape[1]):
            products[c * impulses.shape[1] + d] = impulses[c, d] * driven[c, d]
    return _pairwise_sum(products, np.int64(0), products.size)  # not a literal 0 (_jit)


@njit
def _pairwise_sum(a: np.ndarray, start: int, n: int) -> float:
    """numpy's pairwise sum of ``a[start:start + n]`` (``pairwise_sum`` of its ``loops_utils``):
    blocks of at most 128 terms (:func:`_block_sum`), a longer run summed as its two halves
    (the first a multiple of 8 terms), left + right; the halving taken with an explicit stack
    (a recursive kernel does not load from numba's cache)."""
    if n <= 128:
        return _block_sum(a, start, n)
    # frames (start, length, halves done) and the values of the finished halves, in post-order
    frames = np.empty((128, 3), dtype=np.int64)
    values = np.empty(128)
    frames[0, 0], frames[0, 1], frames[0, 2] = start, n, 0
    top, count = 1, 0
    while top:
        top -= 1
        s, m, done = frames[top, 0], frames[top, 1], frames[top, 2]
        if m <= 128:
            values[count] = _block_sum(a, s, m)
            count += 1
        elif done:
            values[count - 2] = values[count - 2] + values[count - 1]
            count -= 1
        else:
            half = m // 2
            half -= half % 8
            frames[top, 0], frames[top, 1], frames[top, 2] = s, m, 1  # then the sum of the two
            frames[top + 1, 0], frames[top + 1, 1], frames[top + 1, 2] = s + half, m - half, 0  # second
            frames[top + 2, 0], frames[top + 2, 1], frames[top + 2, 2] = s, half, 0  # first
            top += 3
    return values[0]


@njit
def _block_sum(a: np.ndarray, start: int, n: int) -> float:
    """numpy's pairwise sum of at most 128 terms: a plain loop below 8, else eight accumulators."""
    if n < 8:
        total = -0.0
        for i in range(start, start + n):
            total += a[i]
        return total
    r = np.empty(8)
    for j in range(8):
        r[j] = a[start + j]
    i = 8
    while i < n - n % 8:
        for j in range(8):
            r[j] += a[start + i + j]
        i += 8
    total = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]))
    while i < n:
        total += a[start + i]
        i += 1
    return total
