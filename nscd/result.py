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
from typing import Any

import numpy as np

from nscd._atomic import check_writable, replacing
from nscd._checks import real_number
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


@dataclass(frozen=True)
class StepReport:
    """Report of one time step.

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
    """Accumulates step outputs into a :class:`Result` (used by the simulator)."""

    def __init__(self, model, state, store_impulses: bool, impact_speed: float) -> None:
        self.model = model
        self.store_impulses = store_impulses
        self.impact_speed = impact_speed
        # histories in preallocated arrays, doubled when full; rows [0, count) are filled
        self.count = 1
        self.times = np.array([state.t])
        self.qs, self.vs = state.q[None].copy(), state.v[None].copy()
        self.dissipated = np.zeros(1)
        self.work_input = np.zeros(1)
        self.reports: list[StepReport] = []
        self.impacts: list[tuple] = []
        self.contacts: list[dict] = []
        self._was_active = np.zeros((0, 3), dtype=np.int64)  # ids of the last step's active contacts

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
        k = self.count
        if k == len(self.times):
            self.times, self.qs, self.vs, self.dissipated, self.work_input = (
                np.concatenate([a, np.empty_like(a)]) for a in (self.times, self.qs, self.vs, self.dissipated,
                                                                 self.work_input))
        self.count = k + 1
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
        self.work_input[k] = self.work_input[k - 1] - float(np.sum(out.impulses * driven))
        self.reports.append(out.report)
        c = out.contacts
        # An impact is a contact that closes: active now, not active in the previous step,
        # approaching faster than impact_speed.
        active_ids = c.ids[out.active]
        approaching = np.flatnonzero(out.u_before[:, 0] < -self.impact_speed)
        if approaching.size:
            # only the approaching contacts are looked up (a resting wall has none)
            was_active = set(map(tuple, self._was_active.tolist()))  # plain ints: cheap to hash
            for k in approaching.tolist():
                if tuple(active_ids[k].tolist()) not in was_active:
                    i = out.active[k]
                    self.impacts.append((out.solved_at[k], c.body_a[i], c.body_b[i], c.point[i],
                                         out.u_before[k, 0], out.u_after[k, 0], out.impulses[k, 0]))
        self._was_active = active_ids
        if self.store_impulses:
            act = out.active
            self.contacts.append({"body_a": c.body_a[act], "body_b": c.body_b[act],
                                  "point": c.point[act], "frame": c.frame[act],
                                  "impulse": out.impulses})

    def build(self, status: str, message: str, wall_time: float, dt: float, settings) -> Result:
        model = self.model
        reps = self.reports
        statuses: dict[str, int] = {}
        for r in reps:
            statuses[r.status] = statuses.get(r.status, 0) + 1
        report = _report(
            [r.iterations for r in reps], [r.merit for r in reps],
            [r.n_contacts for r in reps], [r.n_active for r in reps],
            [r.t for r in reps if not r.converged], statuses, wall_time,
            [r.penetration for r in reps],
        )
        if not message:
            message = ("all steps converged" if report.n_unconverged == 0 else
                       f"{report.n_unconverged} of {report.n_steps} steps did not converge "
                       f"(first at t = {report.unconverged_times[0]:.6g} s)")
        n = self.count
        q, v = self.qs[:n].copy(), self.vs[:n].copy()
        kinetic, potential = self._energies(q, v)
        dissipated = self.dissipated[:n].copy()
        dim = model.dim
        if self.impacts:
            cols = list(zip(*self.impacts))
            impacts = {"time": np.array(cols[0]), "body_a": np.array(cols[1]),
                       "body_b": np.array(cols[2]), "point": np.array(cols[3]),
                       "u_before": np.array(cols[4]), "u_after": np.array(cols[5]),
                       "impulse": np.array(cols[6])}
        else:
            impacts = {"time": np.zeros(0), "body_a": np.zeros(0, int), "body_b": np.zeros(0, int),
                       "point": np.zeros((0, dim)), "u_before": np.zeros(0),
                       "u_after": np.zeros(0), "impulse": np.zeros(0)}
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
