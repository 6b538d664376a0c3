"""The Moreau–Jean time step (theta-method, velocity level) and the simulation loop.

One step from ``(q_k, v_k)`` at ``t_k`` to ``t_{k+1} = t_k + h``:

1. Detect contacts at ``q_k`` within a margin: gaps ``g``, frames, Jacobian rows
   ``H`` with ``u = H v + w`` (``w``: velocities of fixed and driven bodies).
2. Free velocity ``v_free = v_k + h M^-1 f`` with gravity (and, in 3D, the gyroscopic
   moment ``-omega x I omega`` evaluated at ``t_k``).
3. Active set: contacts with ``g + a * h * min(u~_n, 0) <= 0``, ``u~_n`` the theta-weighted
   normal velocity of free flight over the step (closed, or predicted to close). With ``a = 3/2 - theta`` (1 for the midpoint rule) the gap left
   at an impact is spread evenly around zero, between -h|u_n|/2 and +h|u_n|/2; Siconos and
   LMGC90 use a = 1/2 whatever theta, which leaves a mean penetration of h|u_n|/2.
4. Solve the frictional contact problem on the active set (``nscd.solver``): Newton's
   impact law ``u~_n = u_n(k+1) + e min(u_n(k), 0)`` and exact Coulomb friction in
   De Saxcé's form; ``v_{k+1} = v_free + M^-1 H^T P``.
5. ``q_{k+1} = q_k + h (theta v_{k+1} + (1 - theta) v_k)``; quaternions by the exact
   exponential map of the theta-weighted world angular velocity, renormalised.

Fixed and driven bodies take their pose and velocity from their motion at each time.

A step that does not converge is recorded in its :class:`~nscd.result.StepReport`
and in the :class:`~nscd.result.Result`; it warns (default) or raises
(``on_failure="raise"``) — it is never silent.
"""
from __future__ import annotations

import logging
import math
import time as _time
import warnings
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from nscd.contact.detect import detect
from nscd.contact.frames import Contacts, centripetal_acceleration, centripetal_normal, jacobian
from nscd.model import Model
from nscd.result import Result, ResultBuilder, SolverFailure, StepReport
from nscd.rotation import rotate_quaternion
from nscd.scene import OVERLAP_TOLERANCE, Scene
from nscd.solver import SolverSettings
from nscd.solver.api import solve_velocity_unchecked
from nscd.solver.coarse import CoarseCorrection
from nscd.state import State

logger = logging.getLogger(__name__)

_FAILURE_POLICIES = ("warn", "raise")
_SCHEMES = ("theta", "midpoint")

#: Scenes with at most this many velocity unknowns use dense matrices (less overhead than sparse).
DENSE_DOFS = 60


@dataclass(frozen=True)
class Settings:
    """Options of the Moreau–Jean integrator.

    Parameters
    ----------
    theta : float
        Weight of the end-of-step velocity in the position update, in [0.5, 1]
        (0.5: the energy-consistent midpoint rule, default; 1: backward Euler).
    activation : float or None
        A contact enters the active set when ``gap + activation * dt * min(u~_n, 0) <= 0``
        (u~_n: theta-weighted normal relative velocity over the step in free flight, m/s),
        in [0, 1].
        None: ``1.5 - theta``, which centres the impact gap error on zero.
    gap_tolerance : float or None
        Predicted gaps up to this value (m) count as closed. A velocity-level scheme lets a
        closed contact drift open by O(dt^2) per step (the contact point moves with the
        body); without a tolerance such a contact falls freely for one step, then hits
        back (chatter). A closed contact that really separates still does: the solver
        gives it zero impulse. None: ``gravity * dt^2`` (twice the fall from rest in one
        step), at most 1e-4 of the smallest dynamic body's radius, so that a coarse step
        cannot hold a small block tilted on a corner that is visibly open.
    margin : float or None
        Contact detection margin in m: points with gap <= margin are tracked
        (so a lifting corner stays known). None: 5 % of the smallest dynamic body's
        bounding radius.
    impact_speed : float or None
        Approach speed (m/s) above which a closing contact is recorded as an impact event.
        None: ``2 * gravity * dt``, more than a free fall over the residual gap of one step.
    localize_impacts : bool
        Split a step at the predicted closing time of an impacting contact (default), so
        the impact happens with the gap closed; False: plain Moreau–Jean.
    scheme : {"theta", "midpoint"}
        ``"theta"`` (default): contacts detected and the Jacobian built at ``q_k``,
        ``q_{k+1} = q_k + h (theta v_{k+1} + (1 - theta) v_k)``. ``"midpoint"``: Moreau's
        midpoint rule, ``q_M = q_k + h/2 v_k``, contacts, gaps and Jacobian at ``q_M``
        (driven bodies at ``t_k + h/2``), ``q_{k+1} = q_M + h/2 v_{k+1}`` (``theta`` and
        ``activation`` are then not used). Gaps are predicted from midpoint to midpoint,
        with the full second-order drift of the contact points (a stuck pivot otherwise
        creeps along the surface by ``h^2 omega^2 |r| / 2`` per step); impacts are
        localised from the gap at the start of the step and the closing time corrected
        from the state the approach reaches. Between impacts the theta scheme is first
        order, the midpoint rule second order (rocking block, angle error 0.4 s after
        release: 2.6e-6 / 6.6e-7 rad at dt = 4e-3 / 2e-3, theta 0.5: 3.7e-4 / 1.9e-4 rad):
        restitution within 0.02 % and the 5th impact time within 1 ms at dt = 1e-2
        where the theta scheme needs dt = 1e-4.
    solver : SolverSettings
        Options of the contact solver: ``coulomb`` ("exact" or the explicitly chosen
        "relaxed" cone), fixed-point tolerance and iteration cap, Clarabel tolerances.
    on_failure : {"warn", "raise"}
        What an unconverged step does besides being recorded in the result.
    """

    theta: float = 0.5
    activation: float | None = None
    gap_tolerance: float | None = None
    margin: float | None = None
    impact_speed: float | None = None
    localize_impacts: bool = True
    scheme: str = "theta"
    solver: SolverSettings = field(default_factory=SolverSettings)
    on_failure: str = "warn"

    def __post_init__(self) -> None:
        if not (0.5 <= self.theta <= 1.0):
            raise ValueError(f"theta == {self.theta}, must be in [0.5, 1].")
        if self.activation is not None and not (0.0 <= self.activation <= 1.0):
            raise ValueError(f"activation == {self.activation}, must be in [0, 1].")
        if self.gap_tolerance is not None and not (math.isfinite(self.gap_tolerance) and self.gap_tolerance >= 0.0):
            raise ValueError(f"gap_tolerance == {self.gap_tolerance}, must be >= 0 m (or None for automatic).")
        if self.margin is not None and not (math.isfinite(self.margin) and self.margin > 0.0):
            raise ValueError(f"margin == {self.margin}, must be > 0 m (or None for automatic).")
        if self.impact_speed is not None and not (math.isfinite(self.impact_speed) and self.impact_speed > 0.0):
            raise ValueError(f"impact_speed == {self.impact_speed}, must be > 0 m/s.")
        if self.scheme not in _SCHEMES:
            raise ValueError(f"scheme == {self.scheme!r}, must be one of {_SCHEMES}.")
        if self.on_failure not in _FAILURE_POLICIES:
            raise ValueError(f"on_failure == {self.on_failure!r}, must be one of {_FAILURE_POLICIES}.")


def _auto_margin(model: Model) -> float:
    return 0.05 * model.smallest_radius


def initial_state(model: Model) -> State:
    """The state at t = 0 given by the scene (prescribed bodies at their t = 0 pose)."""
    q = np.array([b.q0 for b in model.bodies], dtype=float)
    v = np.array([b.v0 for b in model.bodies], dtype=float)
    model.prescribe(q, v, 0.0)
    return State(0.0, q, v)


def check_overlaps(model: Model, state: State, margin: float) -> None:
    """Raise ValueError naming the bodies if any two overlap beyond ``OVERLAP_TOLERANCE``."""
    contacts = detect(model, state.q, margin)
    if len(contacts) == 0:
        return
    worst = int(np.argmin(contacts.gap))
    if contacts.gap[worst] < -OVERLAP_TOLERANCE:
        a = model.bodies[contacts.body_a[worst]].name
        b = model.bodies[contacts.body_b[worst]].name
        raise ValueError(
            f"bodies {a!r} and {b!r} overlap by {-contacts.gap[worst]:.3g} m at the start; "
            f"penetration must be <= {OVERLAP_TOLERANCE} m."
        )


def _forces(model: Model, q: np.ndarray, v: np.ndarray, mass_data: np.ndarray) -> np.ndarray:
    """Generalised forces on dynamic bodies (N, N m): gravity and the 3D gyroscopic moment."""
    g = model.scene.gravity
    mass = model.mass[model.dynamic_index]
    f = np.zeros((len(mass), model.nv))
    f[:, model.dim - 1] = -mass * g
    if model.dim == 3:
        omega = v[model.dynamic_index, 3:]
        inertia = mass_data[:, 3:, 3:]
        f[:, 3:] = -np.cross(omega, np.einsum("nij,nj->ni", inertia, omega))
    return f.ravel()


def _solve_mass(model: Model, mass_data: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    if model.dim == 2:
        return rhs / mass_data
    return np.linalg.solve(mass_data, rhs.reshape(-1, 6, 1)).ravel()


def _solver_mass(model: Model, mass_data: np.ndarray, dense: bool):
    """The mass of the dynamic bodies as :func:`~nscd.solver.api.solve_velocity_unchecked`
    takes it: in 2D the diagonal of ``M`` itself (n,); in 3D ``M^-1``, the inverse of the
    6x6 blocks ``mass_data`` assembled block-diagonal, dense (n, n) or CSR."""
    if model.dim == 2:
        return mass_data
    inverse = np.linalg.inv(mass_data)
    if not dense:
        return sp.block_diag(list(inverse), format="csr")
    start = 6 * np.arange(len(inverse))[:, None, None]
    full = np.zeros((model.n_dofs, model.n_dofs))
    full[start + np.arange(6)[None, :, None], start + np.arange(6)[None, None, :]] = inverse
    return full


@dataclass
class StepOutput:
    """What one step produced besides the new state (used by the result builder).

    ``solved_at`` holds, per active contact, the time (s) at the end of the (sub-)step
    that solved it: the impact instant itself for a localised impact.
    """

    report: StepReport
    contacts: Contacts
    active: np.ndarray
    impulses: np.ndarray
    u_before: np.ndarray
    u_after: np.ndarray
    solved_at: np.ndarray

    def then(self, later: "StepOutput") -> "StepOutput":
        """This sub-step followed by ``later``: reports combined, contact arrays concatenated."""
        a, b = self.report, later.report
        report = StepReport(
            t=b.t, n_contacts=max(a.n_contacts, b.n_contacts), n_active=max(a.n_active, b.n_active),
            status=b.status if a.converged else a.status,
            converged=a.converged and b.converged, iterations=a.iterations + b.iterations,
            merit=max(a.merit, b.merit))
        offset = len(self.contacts)
        contacts = Contacts(*(np.concatenate([getattr(self.contacts, f), getattr(later.contacts, f)])
                              for f in Contacts.__dataclass_fields__))
        return StepOutput(report=report, contacts=contacts,
                          active=np.concatenate([self.active, later.active + offset]),
                          impulses=np.concatenate([self.impulses, later.impulses]),
                          u_before=np.concatenate([self.u_before, later.u_before]),
                          u_after=np.concatenate([self.u_after, later.u_after]),
                          solved_at=np.concatenate([self.solved_at, later.solved_at]))


# Odd 64-bit multipliers of the contact-id hash (splitmix64 / golden-ratio constants).
_HASH = np.array([0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB], dtype=np.uint64)


def _id_hash(ids: np.ndarray) -> np.ndarray:
    """One uint64 per contact id row ``(body_a, body_b, feature)`` (wrapping arithmetic)."""
    return (ids.astype(np.uint64) * _HASH).sum(axis=1, dtype=np.uint64)


@dataclass(frozen=True)
class WarmStart:
    """Impulses of the active contacts of a step, looked up by contact id for the next step.

    Attributes
    ----------
    ids : ndarray of int, shape (k, 3)
        Contact ids ``(body_a, body_b, feature)`` (:class:`~nscd.contact.frames.Contacts`).
    impulses : ndarray, shape (k, dim)
        Their impulses, N s, contact frame ``[n, t1 (, t2)]``.
    trend : ndarray, shape (k, dim), optional
        Change of each impulse since the step before (N s; zero for a contact new in this
        step), for a linearly extrapolated warm start (see :meth:`lookup`).
    """

    ids: np.ndarray
    impulses: np.ndarray
    trend: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.ids)

    @classmethod
    def of(cls, warm_start: "WarmStart | dict", dim: int) -> "WarmStart":
        """A WarmStart from itself or from a dict ``{(body_a, body_b, feature): impulse (dim,)}``."""
        if isinstance(warm_start, WarmStart):
            return warm_start
        ids = np.array(list(warm_start.keys()), dtype=np.int64).reshape(-1, 3)
        return cls(ids, np.array(list(warm_start.values()), dtype=float).reshape(-1, dim))

    def lookup(self, ids: np.ndarray, extrapolate: bool = False) -> np.ndarray:
        """Impulses (m, dim) of the contacts ``ids`` (m, 3); zero for an id not in this warm start.

        With ``extrapolate`` (and a ``trend``), ``impulses + trend``: the linear prediction
        of the next step's impulses. For the Gauss–Seidel path of large problems, whose
        sweeps converge linearly, it cuts the sweeps about fourfold on a 990-block wall on
        a shaking base (the impulses follow the base acceleration smoothly); the Newton
        fast path of small problems converges quadratically and is given the plain impulses.

        An id listed twice (a step split at an impact) takes its last impulse, as a dict
        built in order would. A few ids (at most ``DIRECT_LOOKUP`` on both sides together)
        are matched through such a dict; more are vectorised: hashed to one integer,
        matched by a stable sort and binary search, and every match confirmed on the full
        id (a hash collision only loses a warm start).
        """
        values = self.impulses + self.trend if extrapolate and self.trend is not None else self.impulses
        out = np.zeros((len(ids), self.impulses.shape[1]))
        found, hit = self._find(ids)
        out[hit] = values[found[hit]]
        return out

    #: Lookups with at most this many ids on both sides together go through a dict (a few
    #: microseconds for the handful of contacts of a small scene, several times less than
    #: the hash, sort and search of the vectorised path).
    DIRECT_LOOKUP = 16

    def _find(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row of each of ``ids`` (m, 3) in this warm start (its last occurrence), and whether found."""
        if len(self.ids) == 0 or len(ids) == 0:
            return np.zeros(len(ids), dtype=int), np.zeros(len(ids), dtype=bool)
        if len(self.ids) + len(ids) <= self.DIRECT_LOOKUP:
            row = {key: k for k, key in enumerate(map(tuple, self.ids.tolist()))}  # the last occurrence wins
            found = [row.get(key, -1) for key in map(tuple, ids.tolist())]
            hit = np.array(found) >= 0
            return np.maximum(found, 0), hit
        keys = _id_hash(self.ids)
        order = np.argsort(keys, kind="stable")
        wanted = _id_hash(ids)
        pos = np.maximum(np.searchsorted(keys[order], wanted, side="right") - 1, 0)
        found = order[pos]
        return found, (self.ids[found] == ids).all(axis=1)


def warm_start_of(out: StepOutput, previous: WarmStart | dict | None = None) -> WarmStart:
    """Impulses (N s, contact frame) of the active contacts of a step, with their contact ids.

    Given the warm start of the step before (``previous``), also their ``trend``: the change
    of each impulse over the step (zero for a contact new in this step).
    """
    ids = out.contacts.ids[out.active]
    if not previous:
        return WarmStart(ids, out.impulses)
    before = WarmStart.of(previous, out.impulses.shape[1])
    found, hit = before._find(ids)
    trend = np.zeros_like(out.impulses)
    trend[hit] = out.impulses[hit] - before.impulses[found[hit]]
    return WarmStart(ids, out.impulses, trend)


def step(model: Model, state: State, dt: float, settings: Settings, margin: float,
         warm_start: WarmStart | dict | None = None,
         coarse: CoarseCorrection | None = None) -> tuple[State, StepOutput]:
    """Advance ``state`` by ``dt`` seconds: one Moreau–Jean step, split at an impact.

    With ``settings.localize_impacts`` (the default), when a contact that is open at
    the start is predicted to close within the step at an approach speed above the
    impact speed, the step is split at the predicted closing time: a first sub-step
    takes the body up to the contact in free flight (existing contacts still act),
    then the impact is an instantaneous velocity jump (a Moreau–Jean step of zero
    length: Newton's law and Coulomb on the contacts closed at that instant), and a
    last sub-step carries on from the post-impact velocity. Plain Moreau–Jean places an
    impact only to within a step and moves the bodies over the rest of that step with
    the mean of the pre- and post-impact velocities (first order: a landing corner
    sinks by ``h |u_n| / 2``); the split removes both errors at the cost of two more
    contact solves per impact. See :func:`moreau_jean_step` for the arguments.
    """
    new_state, out, closing = moreau_jean_step(model, state, dt, settings, margin, warm_start, coarse=coarse)
    if closing is None:
        return new_state, out
    midpoint = settings.scheme == "midpoint"
    # Midpoint rule: sub-steps close small gaps at the pace of the whole step, not of the
    # sub-step (a gap closed over a tiny sub-step would leave a large spurious velocity).
    closure = dict(closure_dt=dt) if midpoint else {}
    approaches: list[StepOutput] = []
    mid_state, elapsed = state, 0.0
    for attempt in range(_APPROACHES if midpoint else 1):
        if attempt:
            # Midpoint rule: the closing time was predicted from free flight; correct it
            # from the state reached (the contact may still be open).
            rest_state, rest, closing = moreau_jean_step(model, mid_state, dt - elapsed, settings, margin,
                                                         warm_start, watch=closing.ids, coarse=coarse, **closure)
            if closing is None:  # the contact will not close in this step after all
                return rest_state, _chain(approaches + [rest])
        if closing.time <= 0.0:
            break
        mid_state, approach, _ = moreau_jean_step(model, mid_state, closing.time, settings, margin, warm_start,
                                                  localize=False, defer_impacts=True, coarse=coarse, **closure)
        approaches.append(approach)
        warm_start = warm_start_of(approach) or warm_start
        elapsed += closing.time
    # Contacts within the step's gap tolerance take part in the impact.
    at_impact = replace(settings, gap_tolerance=_gap_tolerance(settings, model, dt))
    impact_state, impact, _ = moreau_jean_step(model, mid_state, 0.0, at_impact, margin, warm_start, coarse=coarse,
                                               localize=False)
    new_state, rest, _ = moreau_jean_step(model, impact_state, dt - elapsed, settings, margin,
                                          warm_start_of(impact) or warm_start, localize=False, coarse=coarse,
                                          **closure)
    return new_state, _chain(approaches + [impact, rest])


#: Midpoint rule: approach sub-steps before a localised impact (the first from the free-flight
#: prediction, then corrections from the state reached until the contact is within 1 % of
#: the gap tolerance).
_APPROACHES = 3


@dataclass(frozen=True)
class _Closing:
    """Where :func:`moreau_jean_step` stopped to have an impact localised."""

    time: float       #: s from the start of the step
    ids: np.ndarray   #: (k, 3) ids of the contacts predicted to close then


def _chain(outputs: list[StepOutput]) -> StepOutput:
    """Sub-step outputs combined in order (:meth:`StepOutput.then`)."""
    out = outputs[0]
    for later in outputs[1:]:
        out = out.then(later)
    return out


def moreau_jean_step(model: Model, state: State, dt: float, settings: Settings, margin: float,
                     warm_start: WarmStart | dict | None = None, localize: bool = True,
                     defer_impacts: bool = False, closure_dt: float | None = None,
                     watch: np.ndarray | None = None,
                     coarse: CoarseCorrection | None = None) -> tuple[State, StepOutput | None, _Closing | None]:
    """One plain Moreau–Jean step of ``dt`` seconds from ``state``.

    Parameters
    ----------
    model : Model
        The compiled scene (``Model.from_scene(scene)``).
    state : State
        State at the start of the step.
    dt : float
        Time step, s.
    settings : Settings
    margin : float
        Detection margin, m.
    warm_start : WarmStart or dict, optional
        Impulses of the previous step (:func:`warm_start_of`), or a dict of them keyed by
        contact id ``(body_a, body_b, feature)``.
    localize : bool
        If True and ``settings.localize_impacts``, return without stepping when an
        impact falls inside the step (see :func:`step`).
    defer_impacts : bool
        Keep open contacts that approach faster than the impact speed out of the active
        set (the free-flight sub-step before a localised impact).
    closure_dt : float, optional
        Length (s) of the whole step this is a sub-step of: it sets the gap tolerance
        and the pace at which small positive gaps of active contacts close (default ``dt``).
    watch : ndarray of int, shape (k, 3), optional
        Midpoint rule, correcting a localisation: ids of the contacts whose impact is
        being located; only they are considered, and one closed to within 1 % of the gap
        tolerance is an impact now.
    coarse : CoarseCorrection, optional
        The body-space correction of the Gauss–Seidel sweeps of large 2D problems
        (:mod:`nscd.solver.coarse`), kept from step to step by the caller.

    Returns
    -------
    State, StepOutput, closing
        ``closing`` (time from the start of the step and ids of the contacts) is not
        None when the step was not taken because an impact should be localised first;
        the StepOutput is then None.
    """
    dim, nv = model.dim, model.nv
    t_next = state.t + dt
    q, v = state.q, state.v
    q_next = q.copy()
    v_next = v.copy()
    model.prescribe(q_next, v_next, t_next)

    midpoint = settings.scheme == "midpoint"
    # Configuration where contacts are detected and the Jacobian is built: q_k, or the
    # midpoint q_M (dynamic bodies drift h/2 with v_k, driven bodies posed at t_k + h/2).
    q_c = _drift(model, q, v, 0.5 * dt, state.t + 0.5 * dt) if midpoint else q
    # Gap targets: theta scheme, the end of the step, reached by v_{k+1} acting over
    # tau = theta h; midpoint rule, the next midpoint, reached by v_{k+1} acting over h.
    tau = dt if midpoint else settings.theta * dt
    tau_closure = tau if closure_dt is None else (closure_dt if midpoint else settings.theta * closure_dt)
    contacts = detect(model, q_c, margin)
    m = len(contacts)
    dense = model.n_dofs <= DENSE_DOFS
    _, mass_data = model.mass_matrix(q, dense)
    dyn_idx = model.dynamic_index
    v_dyn = v[dyn_idx].ravel()
    v_free = v_dyn + dt * _solve_mass(model, mass_data, _forces(model, q, v, mass_data))

    if m:
        H, w = jacobian(contacts, q_c[:, :dim], np.stack([v, v_next]), model.dof_of_body,
                        model.n_dofs, dense=dense)
        u_k = (H @ v_dyn + w[0]).reshape(m, dim)
        # Closing speed over the step in free flight (gravity included): a resting or
        # pivoting contact whose gap drifts open by round-off stays active instead of
        # falling freely for one step and chattering.
        u_free_n = (H @ v_free + w[1]).reshape(m, dim)[:, 0]
        closing = np.minimum(settings.theta * u_free_n + (1.0 - settings.theta) * u_k[:, 0], 0.0)
        tolerance = _gap_tolerance(settings, model, dt if closure_dt is None else closure_dt)
        # Open contacts that approach: localised (not activated early, which would stop
        # them short of the surface and leave a body hovering at coarse steps).
        # Gap at the start of the step (midpoint rule: extrapolated back from q_M).
        gap_start = contacts.gap - 0.5 * dt * u_k[:, 0] if midpoint else contacts.gap
        if midpoint:
            fast = u_k[:, 0] < -_impact_speed(settings, model, dt)
            # The midpoint rule would treat an impact half a step late (geometry at q_M), so
            # every approach is localised, down to gaps of 1 % of the tolerance (which is
            # meant for resting contacts drifting open by round-off) -- except the slow
            # approach of a contact that carried load in the previous step: that is the
            # closing of a small gap (below), not an impact (treating it as one makes a
            # block at rest rock between its corners, one micro-impact per step).
            carried = np.zeros(m, dtype=bool)
            if warm_start:
                previous = WarmStart.of(warm_start, dim).lookup(contacts.ids)  # reused for the warm start
                carried = previous[:, 0] > 0.0
            slow_ok = ~carried
            impacting = (u_k[:, 0] < 0.0) & (((gap_start > 0.01 * tolerance) & slow_ok) | (fast & (gap_start > 0.0)))
        else:
            impacting = (gap_start > tolerance) & (u_k[:, 0] < 0.0)
        if localize and settings.localize_impacts:
            if not midpoint:
                closing_time = _first_impact_time(gap_start, u_k[:, 0], u_free_n, dt, impacting)
            else:
                if watch is not None:
                    impacting = (u_k[:, 0] < 0.0) & (contacts.ids[:, None, :] == watch[None]).all(axis=2).any(axis=1)
                    now = impacting & (gap_start <= 0.01 * tolerance)
                else:
                    # Closed at the start and approaching (fast, or already penetrating): the
                    # midpoint rule would see this impact half a step late (at q_M), so it is
                    # taken at the start of the step.
                    now = (u_k[:, 0] < 0.0) & (((gap_start < -0.01 * tolerance) & slow_ok) | (fast & (gap_start <= 0.0)))
                closing_time = _first_impact_time(gap_start, u_k[:, 0], u_free_n, dt, impacting & ~now, True)
                if now.any():
                    closing_time, impacting = 0.0, now
            if closing_time is not None:
                return state, None, _Closing(closing_time, contacts.ids[impacting])
        activation = 1.5 - settings.theta if settings.activation is None else settings.activation
        if midpoint:  # the gap predicted at the next midpoint, from q_M
            is_active = contacts.gap + dt * np.minimum(u_free_n, 0.0) <= tolerance
            if localize and settings.localize_impacts:
                # closing after the end of the step: localised in the next one
                is_active &= ~impacting
        else:
            is_active = contacts.gap + activation * dt * closing <= tolerance
        if defer_impacts:
            is_active &= ~impacting
        active = np.flatnonzero(is_active)
    else:
        active = np.zeros(0, dtype=int)

    if len(active):
        all_active = len(active) == m
        rows = slice(None) if all_active else (active[:, None] * dim + np.arange(dim)).ravel()
        H_act = H[rows]
        offset = w[1][rows].reshape(-1, dim).copy()
        offset[:, 0] += contacts.restitution[active] * np.minimum(u_k[active, 0], 0.0)
        # A contact counted as closed with a small positive gap (<= the gap tolerance) may
        # close it within the step, so no body is held off a surface by the tolerance;
        # gaps below the dead band are left alone (see GAP_DEAD_BAND).
        if dt > 0.0:
            dead_band = GAP_DEAD_BAND * model.smallest_radius
            offset[:, 0] += np.maximum(contacts.gap[active] - dead_band, 0.0) / tau_closure
        # Second-order gap term: the centripetal normal acceleration c of the points makes
        # the gap change by h^2 c / 2 beyond the velocity-level prediction over the step
        # (theta: start to end; midpoint: midpoint to midpoint) while v_{k+1} acts over
        # tau; without it a rocking pivot drifts open, falls back for a step and chatters.
        sub = contacts if all_active else contacts.subset(active)
        if midpoint:
            offset += 0.5 * dt * centripetal_acceleration(sub, q_c[:, :dim], v)  # h^2 c / (2 tau), tau = h
        else:
            offset[:, 0] += 0.5 * dt / settings.theta * centripetal_normal(sub, q[:, :dim], v)
        warm = None
        if warm_start:
            # extrapolated for the linearly converging Gauss-Seidel of large problems only
            extrapolate = len(active) * dim > settings.solver.large_problem_unknowns
            if midpoint and not extrapolate:
                warm = previous[active]
            else:
                warm = WarmStart.of(warm_start, dim).lookup(contacts.ids[active], extrapolate)
        sol = solve_velocity_unchecked(_solver_mass(model, mass_data, dense), v_free, H_act, offset.ravel(),
                                       contacts.friction[active], dim, settings.solver, warm, coarse)
        v_dyn_next = sol.v
        impulses = sol.P
        u_after = (H_act @ v_dyn_next + w[1][rows]).reshape(-1, dim)
        report = StepReport(t=t_next, n_contacts=m, n_active=len(active), status=str(sol.status),
                            converged=bool(sol.converged), iterations=int(sol.iterations),
                            merit=float(sol.merit))
    else:
        v_dyn_next = v_free
        impulses = np.zeros((0, dim))
        u_after = np.zeros((0, dim))
        report = StepReport(t=t_next, n_contacts=m, n_active=0, status="no contact",
                            converged=True, iterations=0, merit=0.0)

    v_next[dyn_idx] = v_dyn_next.reshape(-1, nv)
    if midpoint:
        q_next[dyn_idx] = _drift(model, q_c, v_next, 0.5 * dt)[dyn_idx]
    else:
        theta = settings.theta
        v_mid = v.copy()
        v_mid[dyn_idx] = theta * v_next[dyn_idx] + (1.0 - theta) * v[dyn_idx]
        q_next[dyn_idx] = _drift(model, q, v_mid, dt)[dyn_idx]

    output = StepOutput(report=report, contacts=contacts, active=active, impulses=impulses,
                        u_before=u_k[active] if m else np.zeros((0, dim)), u_after=u_after,
                        solved_at=np.full(len(active), t_next))
    return State(t_next, q_next, v_next), output, None


def _drift(model: Model, q: np.ndarray, v: np.ndarray, span: float, t: float | None = None) -> np.ndarray:
    """Poses after moving the dynamic bodies for ``span`` seconds at constant velocity ``v``.

    2D: ``q + span v``; 3D: positions likewise, quaternions by the exact exponential map
    of ``span * omega`` (world frame), renormalised. With ``t``, fixed and driven bodies
    are posed at time ``t``; otherwise they keep their rows of ``q``.
    """
    out = q.copy()
    idx = model.dynamic_index
    if model.dim == 2:
        out[idx] = q[idx] + span * v[idx]
    else:
        out[idx, :3] = q[idx, :3] + span * v[idx, :3]
        for i in idx:
            out[i, 3:] = rotate_quaternion(q[i, 3:], span * v[i, 3:])
    if t is not None:
        model.prescribe(out, v.copy(), t)
    return out


#: Gaps of active contacts below this fraction of the smallest body's bounding radius are
#: not closed by a velocity target (1.4e-9 m for a 0.2 x 0.4 m block). They are the
#: solver's own residue: a step solved to merit 1e-8 leaves relative velocities of
#: ~1e-8 m/s, i.e. gaps of ~1e-11 m per millisecond step. Closing them at ``g / tau``
#: fed that noise back as velocity targets as large as the tolerance, different at
#: the redundant contacts of a hyperstatic assembly, which no rigid motion meets: on a
#: 13 x 7 wall carried by a shaking base a third of the steps then stalled at merit
#: 1e-8..2e-7 (and were handed to the slow interior point); with the dead band all
#: 1000 steps converge. A body may rest up to this far off a surface: 1e-8 of its size.
GAP_DEAD_BAND = 1e-8


def _gap_tolerance(settings: Settings, model: Model, dt: float) -> float:
    if settings.gap_tolerance is not None:
        return settings.gap_tolerance
    return min(model.scene.gravity * dt * dt, 1e-4 * model.smallest_radius)


def _impact_speed(settings: Settings, model: Model, dt: float) -> float:
    return settings.impact_speed or 2.0 * model.scene.gravity * dt


def _first_impact_time(gap: np.ndarray, u_start: np.ndarray, u_free: np.ndarray, dt: float,
                       impacting: np.ndarray, at_start: bool = False) -> float | None:
    """Earliest time in (0, dt) at which an ``impacting`` contact (open, approaching faster
    than the impact speed) closes, its normal velocity varying linearly from ``u_start``
    to ``u_free`` over the step (free flight); None if there is none worth a split.

    A closing within the first 1e-3 of the step is ignored (None), or, with ``at_start``
    (midpoint rule), returned as 0.0: the impact is then taken at the start of the step;
    ``at_start`` also localises a closing in the last 1e-3 of the step."""
    candidates = np.flatnonzero(impacting)
    if len(candidates) == 0:
        return None
    g, u0 = gap[candidates], u_start[candidates]
    accel = (u_free[candidates] - u0) / dt
    # g + u0 t + accel t^2 / 2 = 0, smallest positive root (u0 < 0, g > 0).
    disc = np.maximum(u0 * u0 - 2.0 * accel * g, 0.0)
    times = 2.0 * g / (-u0 + np.sqrt(disc))
    t_min = float(np.min(times))
    if t_min <= 1e-3 * dt:
        return 0.0 if at_start else None
    return t_min if t_min < (1.0 if at_start else 1.0 - 1e-3) * dt else None


def _check_time(t_end: float, dt: float) -> None:
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt == {dt}, must be a finite number > 0 s.")
    if not (isinstance(t_end, (int, float)) and math.isfinite(t_end) and t_end >= 0.0):
        raise ValueError(f"t_end == {t_end}, must be a finite number >= 0 s.")
    if t_end > 0.0 and dt > t_end:
        raise ValueError(f"dt == {dt}, must be in (0, t_end] = (0, {t_end}] s.")


class Simulator:
    """Step a scene by hand or run it to an end time.

    Parameters
    ----------
    scene : Scene
    dt : float
        Time step in s (> 0).
    settings : Settings, optional
    store_impulses : bool
        Keep the contact points and impulses of every step in the result (memory!).

    Examples
    --------
    >>> sim = nscd.Simulator(scene, dt=1e-3)
    >>> sim.step()            # one step; returns its StepReport
    >>> sim.run(until=2.0)    # more steps
    >>> result = sim.result()
    """

    def __init__(self, scene: Scene, dt: float, settings: Settings | None = None,
                 store_impulses: bool = False) -> None:
        _check_time(0.0, dt)
        self.settings = settings or Settings()
        self.dt = float(dt)
        self.model = Model.from_scene(scene)
        self.margin = self.settings.margin or _auto_margin(self.model)
        self.state = initial_state(self.model)
        check_overlaps(self.model, self.state, self.margin)
        self._warm: dict = {}
        self._coarse = CoarseCorrection()  # kept across steps: its factor is reused
        self._builder = ResultBuilder(self.model, self.state, store_impulses,
                                      impact_speed=_impact_speed(self.settings, self.model, self.dt))
        self._wall = 0.0

    def step(self) -> StepReport:
        """Advance one step; return its report (warns or raises if it did not converge)."""
        start = _time.perf_counter()
        new_state, out = step(self.model, self.state, self.dt, self.settings, self.margin, self._warm, self._coarse)
        self._wall += _time.perf_counter() - start
        self._warm = warm_start_of(out, self._warm)
        self._builder.add(self.state, new_state, out)
        self.state = new_state
        if not out.report.converged:
            message = (f"contact solver did not converge at t = {out.report.t:.6g} s "
                       f"({out.report.status}, merit {out.report.merit:.3g})")
            if self.settings.on_failure == "raise":
                raise SolverFailure(message)
            warnings.warn(message, RuntimeWarning, stacklevel=2)
        return out.report

    def run(self, until: float, callback: Callable[[State], Any] | None = None) -> None:
        """Step until time ``until`` (s); ``callback(state)`` after each step may return True to stop."""
        n_steps = int(round((until - self.state.t) / self.dt))
        for _ in range(max(n_steps, 0)):
            self.step()
            if callback is not None and callback(self.state):
                break

    def result(self, status: str = "finished", message: str = "") -> Result:
        """The result of the steps taken so far."""
        return self._builder.build(status=status, message=message, wall_time=self._wall,
                                   dt=self.dt, settings=self.settings)


def simulate(scene: Scene, t_end: float, dt: float, theta: float = 0.5,
             settings: Settings | None = None, store_impulses: bool = False,
             checkpoint: str | None = None, checkpoint_every: float = 60.0) -> Result:
    """Simulate ``scene`` from t = 0 to ``t_end`` with time step ``dt``.

    Parameters
    ----------
    scene : Scene
    t_end : float
        End time in s (>= 0).
    dt : float
        Time step in s, in (0, t_end].
    theta : float
        Theta-method weight in [0.5, 1] (ignored if ``settings`` is given).
    settings : Settings, optional
        All integrator and solver options.
    store_impulses : bool
        Keep contact points and impulses of every step (off by default for memory).
    checkpoint : str, optional
        Path of an ``.npz`` file where the partial result is saved every
        ``checkpoint_every`` wall-clock seconds and on interruption (Ctrl-C),
        so a long run loses nothing.

    Returns
    -------
    Result
        ``status`` is "finished", or "interrupted" if stopped by KeyboardInterrupt
        (then the partial result is returned, and saved to ``checkpoint`` if given).
    """
    _check_time(t_end, dt)
    settings = settings or Settings(theta=theta)
    if settings.theta != theta and theta != 0.5:
        settings = replace(settings, theta=theta)
    sim = Simulator(scene, dt, settings, store_impulses=store_impulses)
    n_steps = int(round(t_end / dt))
    last_save = _time.perf_counter()
    try:
        for _ in range(n_steps):
            sim.step()
            if checkpoint and _time.perf_counter() - last_save > checkpoint_every:
                sim.result(status="running").save(checkpoint)
                last_save = _time.perf_counter()
    except KeyboardInterrupt:
        result = sim.result(status="interrupted", message=f"interrupted at t = {sim.state.t:.6g} s")
        if checkpoint:
            result.save(checkpoint)
        warnings.warn(result.message, RuntimeWarning, stacklevel=2)
        return result
    result = sim.result()
    if checkpoint:
        result.save(checkpoint)
    return result
