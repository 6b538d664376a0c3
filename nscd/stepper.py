"""The Moreau–Jean time step, one function for single and batched runs, and the simulation loop.

A run is a frozen :class:`~nscd.model.Model` (structure) and a :class:`~nscd.state.Data`
with B rows (per-scene time, positions, velocities, warm starts, solver caches and
driven motions); a single run is B = 1. :func:`step` advances every row of the data by
one step, through named stages over a leading scene axis:

1. **prescribe** fixed and driven bodies at the end of the (sub-)step;
2. **configure**: the configuration where contacts are seen (scheme hook);
3. **detect** contacts within a margin grown by how far the bodies can move in the step
   (:func:`nscd.contact.detect.detect_batch`; the midpoint rule sees a scene with a body
   fast against the thinnest one at the start of the step, see ``_Midpoint.seen_at``);
4. **Jacobian**: per contact, its blocks on its two bodies and the relative velocities
   ``u = H v + w`` (:func:`nscd.contact.frames.contact_kinematics`);
5. **free flight**: ``v_free = v_k + h M^-1 f`` (gravity; in 3D the gyroscopic moment
   ``-omega x I omega`` at ``t_k``);
6. **active set** (scheme hook): contacts closed or predicted to close;
7. **impact localisation**: the event-location stage. An open contact predicted to
   close within the step at an impact speed is an event: that scene's step is split at
   the closing time into an approach in free flight, the impact (a step of zero length:
   Newton's law and Coulomb) and the rest of the step. Each scene runs its own sequence
   of sub-steps; all scenes' current sub-steps go through the stages together;
8. **assemble** the contact problems ``u = W r + q`` (offsets: restitution, the closing
   of small gaps, the second-order gap term of the scheme);
9. **solve**: small problems together with :func:`nscd.solver.core.solve_batch`, large
   ones (more than ``settings.solver.large_problem_unknowns`` unknowns) one by one by
   :func:`nscd.solver.api.solve_velocity_unchecked` (Gauss–Seidel with the scene's
   coarse correction, the interior point after it);
10. **integrate** positions (scheme hook); quaternions by the exact exponential map; the
    deepest end-of-step overlap, predicted, or detected in the end configuration where
    it may be deep (:func:`_predicted_overlaps`).

The scheme (:class:`Scheme`: theta method or Moreau's midpoint rule) chooses the hooks
of stages 2, 3, 6, 7, 8 and 10 (see ``docs/time_step.md``). Every per-scene quantity is
computed by operations that do not mix scenes (elementwise arrays, a scene's own dense
products, problems solved on their own), so a scene stepped in a batch follows its
single run bit for bit.

A step that does not converge is recorded in its :class:`~nscd.result.StepReport`
and in the :class:`~nscd.result.Result`; it warns (default) or raises
(``on_failure="raise"``) — it is never silent.
"""
from __future__ import annotations

import enum
import math
import time as _time
import warnings
from dataclasses import dataclass, field, replace
from typing import Any, Callable

import numpy as np
import scipy.sparse as sp

from nscd._checks import flag, real_number
from nscd._jit import njit
from nscd.contact.detect import detect
from nscd.contact.detect import detect_batch
from nscd.contact.frames import (Contacts, assemble_jacobian, centripetal_acceleration, centripetal_normal,
                                 contact_kinematics)
from nscd.impact_law import dissipation, restitution_factor
from nscd.model import Model
from nscd.result import (OVERTURN_ANGLE, Result, ResultBuilder, SolverFailure, StepReport, checkpoint_path,
                          save_checkpoint)
from nscd.rotation import rotate_quaternion, tilt_angle
from nscd.scene import OVERLAP_TOLERANCE, Scene
from nscd.solver import SolverSettings, Status, core
from nscd.solver.api import solve_velocity_unchecked
from nscd.state import Data, State, WarmStart

__all__ = ["GAP_DEAD_BAND", "PENETRATION_TOLERANCE", "Scheme", "Settings", "Simulator", "StepOutput", "WarmStart",
           "check_overlaps", "initial_state", "overturning", "simulate", "step", "warm_start_of"]

_FAILURE_POLICIES = ("warn", "raise")


class Scheme(str, enum.Enum):
    """The time-stepping scheme: which hooks the one step takes (see ``docs/time_step.md``)."""

    THETA = "theta"
    MIDPOINT = "midpoint"


_SCHEMES = tuple(s.value for s in Scheme)

#: Relative distance of ``round(t_end / dt) * dt`` from ``t_end`` above which ``simulate`` warns
#: that the run ends at another time (round-off of t_end / dt, even with a float32 dt, stays below it).
END_TIME_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Settings:
    """Options of the Moreau–Jean integrator.

    Parameters
    ----------
    theta : float
        Theta scheme: weight of the end-of-step velocity in the position update, in
        [0.5, 1] (0.5: energy-consistent, default; 1: backward Euler). Not used by the
        midpoint rule.
    activation : float or None
        Theta scheme: a contact enters the active set when
        ``gap + activation * dt * min(u~_n, 0) <= 0`` (u~_n: theta-weighted normal relative
        velocity over the step in free flight, m/s), in [0, 1]. None: ``1.5 - theta``,
        which centres the impact gap error on zero.
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
    scheme : {"midpoint", "theta"}
        ``"midpoint"`` (default): Moreau's midpoint rule, ``q_M = q_k + h/2 v_k``, contacts, gaps and Jacobian at ``q_M``
        (driven bodies at ``t_k + h/2``), ``q_{k+1} = q_M + h/2 v_{k+1}`` (``theta`` and
        ``activation`` are then not used). ``"theta"``: contacts detected and the Jacobian
        built at ``q_k``, ``q_{k+1} = q_k + h (theta v_{k+1} + (1 - theta) v_k)``.
        Midpoint rule: gaps are predicted from midpoint to midpoint,
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
    scheme: str = "midpoint"
    solver: SolverSettings = field(default_factory=SolverSettings)
    on_failure: str = "warn"

    def __post_init__(self) -> None:
        for name in ("theta", "activation", "gap_tolerance", "margin", "impact_speed"):
            if getattr(self, name) is not None or name == "theta":
                real_number(name, getattr(self, name))
        flag("localize_impacts", self.localize_impacts)
        if not isinstance(self.solver, SolverSettings):
            raise TypeError(f"solver == {self.solver!r}, must be an nscd.SolverSettings "
                            "(e.g. SolverSettings(tol=1e-10)).")
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

#: End-of-step overlaps deeper than this fraction of the smallest dynamic body's bounding
#: radius warn (0.1 mm for a 0.2 x 0.2 m block). Resolved contacts end 1e-9..1e-12 m deep
#: (solver residue times h); the first-order prediction of the end gap errs by
#: O(h^2 omega^2 R), below 1e-4 R for blocks rocking at 1 rad/s with dt = 1e-2; an overlap
#: of 1e-3 R is invisible in a drawing and 100 times below the tunnelling it guards against.
PENETRATION_TOLERANCE = 1e-3

#: Midpoint rule: a scene is seen at the start of the step instead of its midpoint (``early``,
#: ``_Midpoint.seen_at``) when a body may move within the step (its sweep ``h (|v| + |omega| R)``)
#: by more than this fraction of the thinnest body's thickness. Half a step ahead, a pair has
#: moved relative to each other by at most the larger of their sweeps; the narrow phase finds
#: the pair on the wrong side once they overlap by half the sum of their thicknesses (at least
#: the thinnest): 0.5 keeps a factor two from that. A 1.5 m block rocking at 2 rad/s with
#: dt = 1e-2 sweeps 3 cm, against 10 cm for a 0.2 m base.
EARLY_DETECTION_SWEEP = 0.5

#: The end-of-step overlap of a scene is detected afresh in its end configuration (rather than
#: taken from the first-order prediction of its contacts' gaps) when the prediction plus its
#: error bound reaches this fraction of the warning threshold (``PENETRATION_TOLERANCE``), or
#: when the scene was seen early (its prediction spans a large motion): a factor two of safety
#: on the bound, which covers the turning of the bodies but not new features coming into touch.
FRESH_OVERLAP_CHECK = 0.5

#: Relative round-off of the contacts' dissipation ``-P·(u- + u+)/2`` (of the sum of
#: the magnitudes of its terms) below which an impact is not treated as creating energy:
#: ten times the solver's default tolerance (1e-8), which bounds the relative error of the
#: impulses and velocities. e = 1 without friction dissipates exactly zero, to this round-off.
ENERGY_ROUND_OFF = 1e-7

#: Midpoint rule: approach sub-steps before a localised impact (the first from the free-flight
#: prediction, then corrections from the state reached until the contact is within 1 % of
#: the gap tolerance).
_APPROACHES = 3

#: A step (or what is left of it) in which a body would turn by more than this angle, rad,
#: is taken in equal pieces, each stepped as a step of its own (at most ``_PIECES`` in a
#: step). The end gaps of a step are linearised about its start: a body turning by ``a``
#: brings a corner at distance ``R`` closer than predicted by up to ``a^2 R / 2``; at
#: 0.04 rad that is 8e-4 R, below the overlap that warns (PENETRATION_TOLERANCE, 1e-3 R).
#: A plank spinning at 50 rad/s with dt = 1e-2 is taken in 13 pieces; a block rocking at
#: 2 rad/s is not, up to dt = 2e-2.
_TURN_PER_PIECE = 0.04
_PIECES = 16

#: Impacts localised one after the other within one piece of a step (a fast block hitting a
#: row of blocks: each later impact is approached, located and taken like the first); any
#: further one is taken by the plain step.
_IMPACTS = 4


def _auto_margin(model: Model) -> float:
    return 0.05 * model.smallest_radius


def _gap_tolerance(settings: Settings, model: Model, dt: float) -> float:
    if settings.gap_tolerance is not None:
        return settings.gap_tolerance
    return min(model.gravity * dt * dt, 1e-4 * model.smallest_radius)


def _impact_speed(settings: Settings, model: Model, dt: float) -> float:
    return settings.impact_speed or 2.0 * model.gravity * dt


def initial_state(scene: Scene) -> State:
    """The state of ``scene`` at t = 0 (fixed and driven bodies at their t = 0 pose)."""
    model = Model.from_scene(scene)
    return Data.from_scenes(model, [scene]).state(0)


def check_overlaps(model: Model, state: State, margin: float) -> None:
    """Raise ValueError naming the bodies if any two overlap beyond ``OVERLAP_TOLERANCE``."""
    contacts = detect(model, state.q, margin)
    if len(contacts) == 0:
        return
    worst = int(np.argmin(contacts.gap))
    if contacts.gap[worst] < -OVERLAP_TOLERANCE * (1.0 + 1e-6):  # equal is accepted, to round-off
        a = model.bodies[contacts.body_a[worst]].name
        b = model.bodies[contacts.body_b[worst]].name
        raise ValueError(
            f"bodies {a!r} and {b!r} overlap by {-contacts.gap[worst]:.8g} m at the start; "
            f"penetration must be <= {OVERLAP_TOLERANCE} m."
        )


# --------------------------------------------------------------------------- step outputs


@dataclass
class StepOutput:
    """What one step of one scene produced besides the new state (used by the result builder).

    ``solved_at`` holds, per active contact, the time (s) at the end of the (sub-)step
    that solved it: the impact instant itself for a localised impact. ``driven`` (m/s,
    contact frame), per active contact: the part of its relative velocity due to the
    fixed and driven bodies, averaged over the start and the end of the (sub-)step
    (``(w_k + w_{k+1}) / 2`` of ``u = H v + w``); None: zero (no driven body moves).
    """

    report: StepReport
    contacts: Contacts
    active: np.ndarray
    impulses: np.ndarray
    u_before: np.ndarray
    u_after: np.ndarray
    solved_at: np.ndarray
    driven: np.ndarray | None = None

    def driven_velocity(self) -> np.ndarray:
        """``driven`` as an array (zeros when None), (n_active, dim), m/s."""
        return np.zeros_like(self.u_before) if self.driven is None else self.driven

    def then(self, later: "StepOutput") -> "StepOutput":
        """This sub-step followed by ``later``: reports combined, contact arrays concatenated."""
        a, b = self.report, later.report
        report = StepReport(
            t=b.t, n_contacts=max(a.n_contacts, b.n_contacts), n_active=max(a.n_active, b.n_active),
            status=b.status if a.converged else a.status,
            converged=a.converged and b.converged, iterations=a.iterations + b.iterations,
            merit=max(a.merit, b.merit), penetration=b.penetration)
        offset = len(self.contacts)
        contacts = Contacts(*(np.concatenate([getattr(self.contacts, f), getattr(later.contacts, f)])
                              for f in Contacts.__dataclass_fields__))
        return StepOutput(report=report, contacts=contacts,
                          active=np.concatenate([self.active, later.active + offset]),
                          impulses=np.concatenate([self.impulses, later.impulses]),
                          u_before=np.concatenate([self.u_before, later.u_before]),
                          u_after=np.concatenate([self.u_after, later.u_after]),
                          solved_at=np.concatenate([self.solved_at, later.solved_at]),
                          driven=np.concatenate([self.driven_velocity(), later.driven_velocity()]))


def warm_start_of(out: StepOutput, previous: WarmStart | dict | None = None) -> WarmStart:
    """Impulses (N s, contact frame) of the active contacts of a step, with their contact ids.

    Given the warm start of the step before (``previous``), also their ``trend``: the change
    of each impulse over the step (zero for a contact new in this step).
    """
    ids = out.contacts.ids[out.active]
    if not previous:
        return WarmStart(ids, out.impulses)
    return WarmStart.of(previous, out.impulses.shape[1]).followed_by(ids, out.impulses)


# --------------------------------------------------------------------------- scheme hooks


def _drift(model: Model, q: np.ndarray, v: np.ndarray, span: np.ndarray) -> np.ndarray:
    """Poses (S, n_bodies, nq) after moving the dynamic bodies for ``span`` (S,) seconds at
    constant velocity ``v``; other rows unchanged.

    2D: ``q + span v``; 3D: positions likewise, quaternions by the exact exponential map
    of ``span * omega`` (world frame), renormalised.
    """
    out = q.copy()
    idx = model.dynamic_index
    dim = model.dim
    s = span[:, None, None]
    out[:, idx, :dim] = q[:, idx, :dim] + s * v[:, idx, :dim]
    if dim == 2:
        out[:, idx, 2] = q[:, idx, 2] + span[:, None] * v[:, idx, 2]
    else:
        for k in range(len(q)):
            for i in idx.tolist():
                out[k, i, 3:] = rotate_quaternion(q[k, i, 3:], span[k] * v[k, i, 3:])
    return out


class _Theta:
    """The theta scheme's hooks: contacts at ``q_k``, ``q_{k+1} = q_k + h (theta v_{k+1} + (1 - theta) v_k)``."""

    def __init__(self, settings: Settings) -> None:
        self.settings, self.theta = settings, settings.theta
        self.activation = 1.5 - self.theta if settings.activation is None else settings.activation

    def configure(self, model, data, rows, t, q, v, dt):
        """Configuration where contacts are detected and the Jacobian built: ``q_k``."""
        return q

    def seen_at(self, model, q, q_c, sweep):
        """Contacts are seen at ``q_k`` in every scene: ``(q_k, no scene seen early)``."""
        return q_c, np.zeros(len(q), dtype=bool)

    def prediction_span(self, dt, early):
        """Time (s) over which :meth:`end_gap` extrapolates detected gaps: the whole step."""
        return dt

    def pace(self, dt: np.ndarray) -> np.ndarray:
        """Time (s) over which ``v_{k+1}`` closes a gap target: ``theta h``."""
        return self.theta * dt

    def gap_start(self, gap, u_n, dt_c):
        return gap

    def end_gap(self, gap, u_n, u_next_n, dt_c):
        """Gaps at ``q_{k+1}`` to first order: ``g + h (theta u_{k+1} + (1 - theta) u_k)``."""
        return gap + dt_c * (self.theta * u_next_n + (1.0 - self.theta) * u_n)

    def impacting(self, gap_start, u_n, tol_c, fast, carried):
        """Open contacts approaching: localised, not activated early."""
        return (gap_start > tol_c) & (u_n < 0.0)

    def locate(self, gap_start, u_n, u_free_n, dt, impacting, tol, fast, carried, watch, ids):
        """Closing time (s from the start of the step) of scene's first impact, and its contacts; or None."""
        time = _first_impact_time(gap_start, u_n, u_free_n, dt, impacting)
        return None if time is None else (time, impacting)

    def active(self, gap, u_n, u_free_n, dt_c, tol_c, impacting, localizing):
        closing = np.minimum(self.theta * u_free_n + (1.0 - self.theta) * u_n, 0.0)
        return gap + self.activation * dt_c * closing <= tol_c

    def second_order(self, offset, dt_c, contacts, centres, velocities):
        """Second-order gap term: the centripetal normal acceleration ``c`` of the points makes
        the gap change by ``h^2 c / 2`` beyond the velocity-level prediction while ``v_{k+1}``
        acts over ``theta h``; without it a rocking pivot drifts open, falls back and chatters."""
        offset[:, 0] += 0.5 * dt_c / self.theta * centripetal_normal(contacts, centres, velocities)

    def integrate(self, model, q, q_c, v, v_next, dt):
        v_mid = v.copy()
        dyn = model.dynamic_index
        v_mid[:, dyn] = self.theta * v_next[:, dyn] + (1.0 - self.theta) * v[:, dyn]
        return _drift(model, q, v_mid, dt)


class _Midpoint:
    """Moreau's midpoint rule: contacts at ``q_M = q_k + h/2 v_k``, ``q_{k+1} = q_M + h/2 v_{k+1}``."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings

    def configure(self, model, data, rows, t, q, v, dt):
        """The midpoint ``q_M``: dynamic bodies drift h/2 with ``v_k``, driven bodies posed at ``t_k + h/2``."""
        q_c = _drift(model, q, v, 0.5 * dt)
        data.drives.write(rows, t + 0.5 * dt, q_c, v.copy())
        return q_c

    def seen_at(self, model, q, q_c, sweep):
        """Where contacts are seen: ``q_M``, except in "early" scenes, where a body may move
        by more than ``EARLY_DETECTION_SWEEP`` of the thinnest body's thickness within the
        step: there ``q_k``. Returns the configurations (S, n_bodies, nq) and ``early`` (S,).

        Half a step ahead, a fast body may be past the middle of a thin one: the narrow
        phase then finds their separating axis on the far side (the pair seems to separate)
        and the impact is lost (tunnelling). Seen at ``q_k`` the pair is on its true side,
        and the impact is localised from there as any other (:class:`_Plan`);
        :meth:`seen_gaps` carries the gaps to ``q_M``.
        """
        limit = EARLY_DETECTION_SWEEP * model.thinnest
        if sweep.max() <= limit:
            return q_c, np.zeros(len(q), dtype=bool)
        early = sweep.max(axis=1) > limit
        return np.where(early[:, None, None], q, q_c), early

    def seen_gaps(self, gap, u_n, dt_c, early_c):
        """Gaps at ``q_M``: those seen at ``q_k`` (``early_c``) moved by ``h/2 u_k`` (first order)."""
        return np.where(early_c, gap + 0.5 * dt_c * u_n, gap)

    def prediction_span(self, dt, early):
        """Time (s) over which :meth:`end_gap` extrapolates detected gaps: ``h/2`` from
        ``q_M``, ``h`` from ``q_k`` in an early scene."""
        return np.where(early, dt, 0.5 * dt) if early.any() else 0.5 * dt

    def pace(self, dt: np.ndarray) -> np.ndarray:
        """Gap targets are the next midpoint, reached by ``v_{k+1}`` acting over ``h``."""
        return dt

    def gap_start(self, gap, u_n, dt_c):
        """The gap at the start of the step, extrapolated back from ``q_M``."""
        return gap - 0.5 * dt_c * u_n

    def end_gap(self, gap, u_n, u_next_n, dt_c):
        """Gaps at ``q_{k+1} = q_M + h/2 v_{k+1}`` to first order: ``g_M + h/2 u_{k+1}``."""
        return gap + 0.5 * dt_c * u_next_n

    def impacting(self, gap_start, u_n, tol_c, fast, carried):
        # The midpoint rule would treat an impact half a step late (geometry at q_M), so
        # every approach is localised, down to gaps of 1 % of the tolerance (which is
        # meant for resting contacts drifting open by round-off) -- except the slow
        # approach of a contact that carried load in the previous step: that is the
        # closing of a small gap, not an impact (treating it as one makes a block at
        # rest rock between its corners, one micro-impact per step).
        return (u_n < 0.0) & (((gap_start > 0.01 * tol_c) & ~carried) | (fast & (gap_start > 0.0)))

    def locate(self, gap_start, u_n, u_free_n, dt, impacting, tol, fast, carried, watch, ids):
        if watch is not None:
            # correcting a localisation: only the watched contacts; one closed to within
            # 1 % of the tolerance is an impact now
            impacting = (u_n < 0.0) & _watched(ids, watch)
            now = impacting & (gap_start <= 0.01 * tol)
        else:
            # Closed at the start and approaching (fast, or already penetrating): the
            # midpoint rule would see this impact half a step late (at q_M), so it is
            # taken at the start of the step.
            now = (u_n < 0.0) & (((gap_start < -0.01 * tol) & ~carried) | (fast & (gap_start <= 0.0)))
        time = _first_impact_time(gap_start, u_n, u_free_n, dt, impacting & ~now, True)
        if now.any():
            return 0.0, now
        return None if time is None else (time, impacting)

    def active(self, gap, u_n, u_free_n, dt_c, tol_c, impacting, localizing):
        """The gap predicted at the next midpoint, from ``q_M``; an approach closing after
        the end of the step is left to the next one."""
        is_active = gap + dt_c * np.minimum(u_free_n, 0.0) <= tol_c
        return is_active & ~(impacting & localizing)

    def second_order(self, offset, dt_c, contacts, centres, velocities):
        """The full second-order drift of the points from midpoint to midpoint
        (``h^2 c / (2 tau)``, ``tau = h``): normal and tangential (a stuck pivot creeps otherwise)."""
        offset += 0.5 * dt_c[:, None] * centripetal_acceleration(contacts, centres, velocities)

    def integrate(self, model, q, q_c, v, v_next, dt):
        return _drift(model, q_c, v_next, 0.5 * dt)


def _hooks(settings: Settings):
    return _Midpoint(settings) if settings.scheme == Scheme.MIDPOINT.value else _Theta(settings)


def _watched(ids: np.ndarray, watch: np.ndarray) -> np.ndarray:
    """Which contacts of ``ids`` (m, 3) are among the contact ids ``watch`` (k, 3): (m,) bool."""
    return (ids[:, None, :] == watch[None]).all(axis=2).any(axis=1)


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


# --------------------------------------------------------------------------- one sub-step of S scenes


@dataclass
class _Request:
    """One sub-step asked for by a scene's event location (see :class:`_Plan`)."""

    dt: float                    #: length, s (0: an impact)
    tolerance: float             #: gap tolerance, m
    pace: float                  #: time over which small gaps of active contacts close, s
    localize: bool               #: stop and report a closing instead of stepping across it
    defer: bool = False          #: keep impacting contacts out of the active set (the approach)
    watch: np.ndarray | None = None  #: ids of the contacts being located (a correction) or hit (an impact)


@dataclass
class _SubStep:
    """What a sub-step gave one scene: the new state and output, or where an impact closes."""

    t: float
    q: np.ndarray
    v: np.ndarray
    output: StepOutput | None
    closing: tuple[float, np.ndarray] | None  #: (time from the start, ids of the contacts)


def _global(contacts: Contacts, scene: np.ndarray, n_bodies: int) -> Contacts:
    """``contacts`` with body indices into the stacked bodies of all scenes (``scene * n_bodies + body``)."""
    offset = scene * n_bodies
    return Contacts(contacts.body_a + offset, contacts.body_b + offset, contacts.point, contacts.frame,
                    contacts.gap, contacts.friction, contacts.restitution, contacts.ids)


def _free_flight(model: Model, q: np.ndarray, v: np.ndarray, dt: np.ndarray) -> tuple[np.ndarray, list]:
    """Stage 5: ``v_free = v_k + h M^-1 f`` of the dynamic bodies, (S, n_dofs); and the 3D mass blocks per scene."""
    S, dyn = len(q), model.dynamic_index
    v_dyn = v[:, dyn].reshape(S, model.n_dofs)
    if model.dim == 2:
        accel = np.zeros((len(dyn), model.nv))
        accel[:, 1] = -model.mass[dyn] * model.gravity
        return v_dyn + dt[:, None] * (accel.ravel() / model.mass_diagonal), []
    blocks, v_free = [], np.empty_like(v_dyn)
    for s in range(S):
        _, mass_data = model.mass_matrix(q[s], dense=False)
        mass = model.mass[dyn]
        f = np.zeros((len(mass), 6))
        f[:, 2] = -mass * model.gravity
        omega = v[s, dyn, 3:]
        f[:, 3:] = -np.cross(omega, np.einsum("nij,nj->ni", mass_data[:, 3:, 3:], omega))
        v_free[s] = v_dyn[s] + dt[s] * np.linalg.solve(mass_data, f.reshape(-1, 6, 1)).ravel()
        blocks.append(mass_data)
    return v_free, blocks


def _sweep(model: Model, v: np.ndarray, v_end: np.ndarray, v_free: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """How far any point of each body may move within the sub-step, m, (S, n_bodies): ``h (|v| + |omega| R)``.

    ``v`` (S, n_bodies, nv) at the start, ``v_end`` with the fixed and driven bodies at the
    end (their prescribed motion), ``v_free`` (S, n_dofs) the dynamic bodies' free flight;
    ``R`` the body's bounding radius. Speeds are the larger of the start and the end
    values (in free flight the translational velocity varies linearly, so its norm stays
    below the larger end; the 2D spin is constant). This is the speculative-contact
    bound (Catto, "Speculative contacts", GDC 2013; Box2D's swept AABB): with it the
    broad and narrow phases find every contact that can close in the step.
    """
    dim, nv = model.dim, model.nv
    end = v_end.copy()
    end[:, model.dynamic_index] = v_free.reshape(len(v), len(model.dynamic_index), nv)
    linear = np.maximum(np.linalg.norm(v[..., :dim], axis=-1), np.linalg.norm(end[..., :dim], axis=-1))
    angular = np.maximum(np.linalg.norm(v[..., dim:], axis=-1), np.linalg.norm(end[..., dim:], axis=-1))
    return dt[:, None] * (linear + angular * model.radius[None, :])


@njit
def _predicted_overlaps(end_gap, body_a, body_b, first, v, v_end, span, radius, early, threshold):
    """Deepest overlap of each scene at the end of a sub-step, predicted to first order,
    and which scenes to check by detection: ``(overlap, check)``, (S,) each, m and bool.

    ``end_gap`` (m,): the predicted end gaps of the contacts of all scenes, bodies
    ``body_a``, ``body_b`` (scene indices), ``first`` (S + 1,): each scene's first contact;
    ``v``, ``v_end`` (S, n_bodies, nv): velocities at the start and the end; ``span`` (S,),
    s: the time over which the gaps were extrapolated; ``radius`` (n_bodies,), m;
    ``early`` (S,): scenes seen at the start of a midpoint step; ``threshold``, m.

    ``overlap`` is ``max(0, -min end_gap)`` (0 for a scene without contacts). The
    prediction errs by at most the turning of the two bodies: a point at distance ``R``
    from the centre of a body turning at ``omega`` leaves the line of its velocity by
    ``R (1 - cos(omega span)) <= (omega span)^2 R / 2`` (``|omega|`` the larger of its two
    ends' values); translation is extrapolated exactly. A scene with contacts is checked
    when the predicted overlap plus that bound reaches ``threshold``, or when it was seen
    ``early`` (its prediction spans a large motion).
    """
    S = first.shape[0] - 1
    nv = v.shape[2]
    overlap = np.zeros(S)
    check = np.zeros(S, dtype=np.bool_)
    for s in range(S):
        possible = -np.inf
        for c in range(first[s], first[s + 1]):
            error = 0.0
            for body in (body_a[c], body_b[c]):
                turn_k = turn_end = 0.0
                for j in range(nv // 2, nv):  # angular components: 1 in 2D, 3 in 3D
                    turn_k += v[s, body, j] * v[s, body, j]
                    turn_end += v_end[s, body, j] * v_end[s, body, j]
                error += 0.5 * max(turn_k, turn_end) * span[s] * span[s] * radius[body]
            overlap[s] = max(overlap[s], -end_gap[c])
            possible = max(possible, error - end_gap[c])
        check[s] = first[s + 1] > first[s] and (early[s] or possible >= threshold)
    return overlap, check


def _end_overlaps(model: Model, q_end: np.ndarray, overlap: np.ndarray, check: np.ndarray) -> np.ndarray:
    """Deepest overlap of two bodies (S,), m (>= 0), at the end of each scene's sub-step:
    the prediction ``overlap`` (S,), or, in the scenes to ``check`` (S,)
    (:func:`_predicted_overlaps`), the overlap detected in the end configuration
    ``q_end`` (S, n_bodies, nq). A scene without contacts cannot overlap: its contacts
    were searched within the distance its bodies can move (speculative contacts)."""
    if not check.any():
        return overlap
    rows = np.flatnonzero(check)
    found, scene = detect_batch(model, q_end[rows], 0.0)
    overlap = overlap.copy()
    overlap[rows] = 0.0
    np.maximum.at(overlap, rows[scene], -found.gap)
    return overlap


def _inverse_mass(model: Model, blocks: np.ndarray, dense: bool):
    """``M^-1`` of one 3D scene from its 6x6 blocks: dense (n, n) or CSR."""
    inverse = np.linalg.inv(blocks)
    if not dense:
        return sp.block_diag(list(inverse), format="csr")
    start = 6 * np.arange(len(inverse))[:, None, None]
    full = np.zeros((model.n_dofs, model.n_dofs))
    full[start + np.arange(6)[None, :, None], start + np.arange(6)[None, None, :]] = inverse
    return full


_CONVERGED = (Status.CONVERGED, Status.POLISHED)


def _advance(model: Model, data: Data, settings: Settings, margin: float, rows: np.ndarray,
             t: np.ndarray, q: np.ndarray, v: np.ndarray, warm: list, requests: list[_Request]) -> list[_SubStep]:
    """One plain Moreau–Jean sub-step of each of S scenes, through the stages of the module docstring.

    Parameters
    ----------
    rows : ndarray of int, shape (S,)
        Rows of ``data`` (drives and coarse corrections of the scenes).
    t, q, v : ndarray, shapes (S,), (S, n_bodies, nq), (S, n_bodies, nv)
        States at the start of the sub-step.
    warm : list of WarmStart
        Each scene's warm start.
    requests : list of _Request
        Each scene's sub-step (length, tolerance, pace, localisation mode).
    """
    hooks = _hooks(settings)
    dim, nv, n = model.dim, model.nv, len(model.bodies)
    S = len(rows)
    dyn = model.dynamic_index
    dt = np.array([r.dt for r in requests])
    tolerance = np.array([r.tolerance for r in requests])
    pace = np.array([r.pace for r in requests])
    localizing = np.array([r.localize for r in requests]) & settings.localize_impacts

    # 1. prescribe
    t_next = t + dt
    q_next, v_next = q.copy(), v.copy()
    data.drives.write(rows, t_next, q_next, v_next)
    # 2. configure
    q_c = hooks.configure(model, data, rows, t, q, v, dt)
    # 5. free flight (before detection: the sweep of stage 3 needs it)
    v_free, mass_blocks = _free_flight(model, q, v, dt)
    # 3. detect, with speculative contacts: every contact that can close within the step; a
    # scene whose bodies move fast against the thinnest one is seen where the step starts (hook)
    sweep = _sweep(model, v, v_next, v_free, dt)
    q_seen, early = hooks.seen_at(model, q, q_c, sweep)
    contacts, scene = detect_batch(model, q_seen, margin, sweep)
    m = len(contacts)
    first = np.searchsorted(scene, np.arange(S + 1))
    # 4. Jacobian: u_k (all bodies at t_k), u_free (dynamic bodies in free flight, others at t_{k+1})
    flat = _global(contacts, scene, n)
    centres = q_seen.reshape(S * n, -1)[:, :dim]
    # start; free flight; fixed and driven bodies only, at t_{k+1} and at t_k
    sets = np.stack([v, v_next, v_next, v])
    sets[1][:, dyn] = v_free.reshape(S, len(dyn), nv)
    sets[2][:, dyn] = 0.0
    sets[3][:, dyn] = 0.0
    blocks, (u_k, u_free, w_next, w_k) = contact_kinematics(flat, centres, sets.reshape(4, S * n, nv))
    u_free_n = u_free[:, 0]

    # 6-7. active set and impact localisation
    dt_c, tol_c = dt[scene], tolerance[scene]
    if early.any():
        contacts = replace(contacts, gap=hooks.seen_gaps(contacts.gap, u_k[:, 0], dt_c, early[scene]))
    speed = settings.impact_speed if settings.impact_speed else 2.0 * model.gravity * dt_c
    fast = u_k[:, 0] < -speed
    gap_start = hooks.gap_start(contacts.gap, u_k[:, 0], dt_c)
    previous = np.zeros((m, dim))
    for s in range(S):
        if first[s + 1] > first[s] and len(warm[s]):
            previous[first[s]:first[s + 1]] = warm[s].lookup(contacts.ids[first[s]:first[s + 1]])
    carried = previous[:, 0] > 0.0
    impacting = hooks.impacting(gap_start, u_k[:, 0], tol_c, fast, carried)
    closing: list = [None] * S
    for s in np.flatnonzero(localizing).tolist():
        c = slice(first[s], first[s + 1])
        if c.stop == c.start:
            continue
        found = hooks.locate(gap_start[c], u_k[c, 0], u_free_n[c], float(dt[s]), impacting[c], float(tolerance[s]),
                             fast[c], carried[c], requests[s].watch, contacts.ids[c])
        if found is not None:
            closing[s] = (found[0], contacts.ids[c][found[1]])
        elif requests[s].watch is not None:
            impacting[c] = (u_k[c, 0] < 0.0) & _watched(contacts.ids[c], requests[s].watch)
    is_active = hooks.active(contacts.gap, u_k[:, 0], u_free_n, dt_c, tol_c, impacting, localizing[scene])
    for s, request in enumerate(requests):
        if request.dt > 0.0 or request.watch is None:
            continue
        # an impact of a step in pieces (a body turning fast) takes the contacts it was located
        # for, approaching, whatever their gap: their located gaps err by the turning
        c = slice(first[s], first[s + 1])
        is_active[c] |= (u_k[c, 0] < 0.0) & _watched(contacts.ids[c], requests[s].watch)
    deferring = np.array([r.defer for r in requests])
    is_active &= ~(impacting & deferring[scene])
    stepping = np.array([c is None for c in closing])
    is_active &= stepping[scene]
    active = np.flatnonzero(is_active)
    active_first = np.searchsorted(scene[active], np.arange(S + 1))

    # 8. assemble
    offset = w_next[active].copy()
    offset[:, 0] += contacts.restitution[active] * np.minimum(u_k[active, 0], 0.0)
    # A contact counted as closed with a small positive gap (<= the gap tolerance) may
    # close it within the step, so no body is held off a surface by the tolerance;
    # gaps below the dead band are left alone (see GAP_DEAD_BAND).
    dead_band = GAP_DEAD_BAND * model.smallest_radius
    dt_a, pace_a = dt[scene[active]], pace[scene[active]]
    with np.errstate(divide="ignore", invalid="ignore"):
        lift = np.maximum(contacts.gap[active] - dead_band, 0.0) / pace_a
    offset[:, 0] = np.where(dt_a > 0.0, offset[:, 0] + lift, offset[:, 0])
    hooks.second_order(offset, dt_a, flat.subset(active), centres, v.reshape(S * n, nv))

    # 9. solve
    v_dyn_next = v_free.copy()
    impulses = np.zeros((len(active), dim))
    u_after = np.zeros((len(active), dim))
    reports: list = [None] * S
    small: list = []  # (s, a, H, MinvHT, W, q_free, mu, warm start)
    resolvers: dict = {}  # scene -> its problem solved again with the restitution scaled (9b)
    limit = max(settings.solver.large_problem_unknowns, settings.solver.fast_path_unknowns)
    for s in np.flatnonzero(np.diff(active_first)).tolist():
        a = slice(active_first[s], active_first[s + 1])
        idx = active[a]
        local = contacts.subset(idx)
        unknowns = len(idx) * dim
        large = unknowns > limit
        H = assemble_jacobian(blocks[idx], local.body_a, local.body_b, model.dof_of_body, model.n_dofs,
                              dense=not large)
        extrapolate = unknowns > settings.solver.large_problem_unknowns
        if isinstance(hooks, _Midpoint) and not extrapolate:
            start = previous[idx]
        else:
            start = warm[s].lookup(local.ids, extrapolate)
        start = start if len(warm[s]) else None
        # the restitution part of the offset, removed by (1 - lambda) when the restitution is scaled (9b)
        bounce = np.zeros((len(idx), dim))
        bounce[:, 0] = contacts.restitution[idx] * np.minimum(u_k[idx, 0], 0.0)
        if large:
            mass = model.mass_diagonal if dim == 2 else _inverse_mass(model, mass_blocks[s], dense=False)

            def solve_large(lam, s=s, a=a, idx=idx, H=H, mass=mass, local=local, start=start, bounce=bounce):
                sol = solve_velocity_unchecked(mass, v_free[s], H, (offset[a] - (1.0 - lam) * bounce).ravel(),
                                               local.friction, dim, settings.solver, start, data.coarse[rows[s]])
                return (sol.P, (H @ sol.v + w_next[idx].ravel()).reshape(-1, dim), sol.v,
                        (str(sol.status), bool(sol.converged), int(sol.iterations), float(sol.merit)))

            impulses[a], u_after[a], v_dyn_next[s], reports[s] = solve_large(1.0)
            resolvers[s] = solve_large
            continue
        MinvHT = H.T / model.mass_diagonal[:, None] if dim == 2 else _inverse_mass(model, mass_blocks[s], True) @ H.T
        small.append((s, a, idx, H, MinvHT, H @ MinvHT, H @ v_free[s] + offset[a].ravel(), local.friction, start))
        resolvers[s] = lambda lam, problem=small[-1], bounce=bounce: _small_solution(
            _solve_small([problem[:6] + (problem[6] - (1.0 - lam) * bounce.ravel(),) + problem[7:]], dim,
                         settings.solver)[0], problem, v_free, w_next)
    for problem, res in zip(small, _solve_small(small, dim, settings.solver)):
        s, a = problem[:2]
        impulses[a], u_after[a], v_dyn_next[s], reports[s] = _small_solution(res, problem, v_free, w_next)

    # 9b. an impact law that cannot create energy: a problem whose contacts would give the
    # bodies energy (Newton's restitution with friction) is solved again with its
    # restitution scaled down, to the largest factor that dissipates (nscd.impact_law)
    for s, resolve in resolvers.items():
        a = slice(active_first[s], active_first[s + 1])
        idx = active[a]
        if not np.any((contacts.restitution[idx] > 0.0) & (u_k[idx, 0] < 0.0)):
            continue
        lost, scale = dissipation(impulses[a], u_k[idx], u_after[a])
        if lost >= -ENERGY_ROUND_OFF * scale:
            continue
        _, solution = restitution_factor(resolve, u_k[idx], ENERGY_ROUND_OFF)
        impulses[a], u_after[a], v_dyn_next[s], reports[s] = solution

    # 10. integrate
    v_next[:, dyn] = v_dyn_next.reshape(S, len(dyn), nv)
    q_end = hooks.integrate(model, q, q_c, v, v_next, dt)
    q_next[:, dyn] = q_end[:, dyn]
    # the deepest overlap at the end of the sub-step: predicted for every detected contact,
    # detected afresh in the end configuration where the prediction may hide a deep one
    _, (u_end,) = contact_kinematics(flat, centres, v_next.reshape(1, S * n, nv))
    end_gap = hooks.end_gap(contacts.gap, u_k[:, 0], u_end[:, 0], dt_c)
    overlap = _end_overlaps(model, q_next, *_predicted_overlaps(
        end_gap, contacts.body_a, contacts.body_b, first, v, v_next, hooks.prediction_span(dt, early), model.radius,
        early, FRESH_OVERLAP_CHECK * PENETRATION_TOLERANCE * model.smallest_radius))

    out = []
    for s in range(S):
        if closing[s] is not None:
            out.append(_SubStep(float(t[s]), q[s], v[s], None, closing[s]))
            continue
        c, a = slice(first[s], first[s + 1]), slice(active_first[s], active_first[s + 1])
        n_active = a.stop - a.start
        penetration = float(overlap[s])
        if reports[s] is None:
            report = StepReport(t=float(t_next[s]), n_contacts=c.stop - c.start, n_active=0, status="no contact",
                                converged=True, iterations=0, merit=0.0, penetration=penetration)
        else:
            status, converged, iterations, merit = reports[s]
            report = StepReport(t=float(t_next[s]), n_contacts=c.stop - c.start, n_active=n_active, status=status,
                                converged=converged, iterations=iterations, merit=merit, penetration=penetration)
        output = StepOutput(report=report, contacts=contacts.subset(c), active=active[a] - c.start,
                            impulses=impulses[a], u_before=u_k[active[a]], u_after=u_after[a],
                            solved_at=np.full(n_active, t_next[s]),
                            driven=0.5 * (w_k[active[a]] + w_next[active[a]]))
        out.append(_SubStep(float(t_next[s]), q_next[s], v_next[s], output, None))
    return out


def _small_solution(res, problem: tuple, v_free: np.ndarray, w_next: np.ndarray) -> tuple:
    """Impulses (m, dim), relative velocities after (m, dim), velocities of the dynamic bodies
    and the report tuple of a small problem of :func:`_advance` solved as ``res``."""
    s, a, idx, H, MinvHT = problem[:5]
    v_s = v_free[s] + MinvHT @ res.r
    dim = w_next.shape[1]
    report = (str(res.status), res.status in _CONVERGED,
              int(res.fast_iterations + res.sweeps + res.fixed_point_iterations + res.polish_iterations),
              float(res.merit))
    return res.r.reshape(-1, dim), (H @ v_s + w_next[idx].ravel()).reshape(-1, dim), v_s, report


def _solve_small(problems: list, dim: int, settings: SolverSettings) -> list:
    """Solve the dense problems ``(.., W, q, mu, warm start)`` of :func:`_advance` with
    :func:`nscd.solver.core.solve_batch`: each as :func:`nscd.solver.core.solve` solves it
    alone, bit for bit (the warm-started ones and the cold ones in two calls: a cold start
    is not a zero warm start). A single problem goes to :func:`~nscd.solver.core.solve`
    itself (the same kernel without the batch's input checks)."""
    if len(problems) == 1:
        *_, W, q, mu, start = problems[0]
        return [core.solve(W, q, mu, dim, settings, None if start is None else start.ravel())]
    results: list = [None] * len(problems)
    for warm in (True, False):
        group = [k for k, p in enumerate(problems) if (p[8] is not None) == warm]
        if not group:
            continue
        sizes = np.array([len(problems[k][6]) for k in group])
        width = int(sizes.max())
        W = np.zeros((len(group), width, width))
        q = np.zeros((len(group), width))
        mu = np.zeros((len(group), width // dim))
        r0 = np.zeros((len(group), width)) if warm else None
        for g, k in enumerate(group):
            size = sizes[g]
            W[g, :size, :size] = problems[k][5]
            q[g, :size] = problems[k][6]
            mu[g, :size // dim] = problems[k][7]
            if warm:
                r0[g, :size] = problems[k][8].ravel()
        for k, res in zip(group, core.solve_batch(W, q, mu, dim, settings, r0, sizes)):
            results[k] = res
    return results


# --------------------------------------------------------------------------- event location: the whole step


class _Plan:
    """The sub-steps of one scene within one step (the event-location stage).

    A step starts as a plain step that stops at a predicted impact; then the approach in
    free flight up to the closing time (the midpoint rule corrects the closing time from
    the state reached, up to ``_APPROACHES`` approaches), the impact (a sub-step of zero
    length with the step's gap tolerance) and the rest of the step, which stops at the
    next impact in the same way (up to ``_IMPACTS``). A step in which a body turns fast is
    taken in pieces (``_TURN_PER_PIECE``), each planned as a step. Each call of
    :meth:`request` names the next sub-step, :meth:`receive` takes its outcome.
    """

    def __init__(self, model: Model, settings: Settings, dt: float, t: float, q: np.ndarray, v: np.ndarray,
                 warm: WarmStart) -> None:
        self.model, self.settings = model, settings
        self.midpoint = settings.scheme == Scheme.MIDPOINT.value
        self.t, self.q, self.v, self.warm = t, q, v, warm
        self.outputs: list[StepOutput] = []
        self.hooks = _hooks(settings)
        self.step_dt, self.left = dt, dt  # the step's length and what is left of it, s
        self.pieces = 0
        self._start_piece()

    def _start_piece(self) -> None:
        """The next piece of the step: all that is left of it, or, if a body would turn by
        more than ``_TURN_PER_PIECE`` in that time, an equal share of it (``_PIECES`` pieces
        at most in a step). A step's contacts are linearised about its start: a corner that
        comes round within a large turn is not seen coming."""
        spin = self.v[:, self.model.dim:]  # every body's: a driven one may turn too
        turn = math.sqrt(float(np.max(spin * spin if spin.shape[1] == 1 else np.sum(spin * spin, axis=1)))) * self.left
        shares = min(math.ceil(turn / _TURN_PER_PIECE), _PIECES - self.pieces) if turn > _TURN_PER_PIECE else 1
        self.dt = self.left / max(shares, 1)
        self.left -= self.dt
        self.pieces += 1
        self.split = self.pieces > 1 or shares > 1  # a step in pieces: a body turns fast
        self.phase = "plain"
        self.elapsed = 0.0
        self.approaches = 0
        self.impacts = 0
        self.closing: tuple | None = None

    @property
    def done(self) -> bool:
        return self.phase == "done"

    def _request(self, length: float, localize: bool, closure: float | None = None, defer: bool = False,
                 watch=None) -> _Request:
        span = length if closure is None else closure
        tol = _gap_tolerance(self.settings, self.model, span)
        pace = float(self.hooks.pace(np.array([span]))[0])
        return _Request(length, tol, pace, localize, defer, watch)

    def request(self) -> _Request:
        # Midpoint rule: sub-steps close small gaps at the pace of the whole step, not of the
        # sub-step (a gap closed over a tiny sub-step would leave a large spurious velocity).
        closure = self.dt if self.midpoint else None
        if self.phase == "plain":
            return self._request(self.dt, True)
        if self.phase == "correct":
            return self._request(self.dt - self.elapsed, True, closure, watch=self.closing[1])
        if self.phase == "approach":
            return self._request(self.closing[0], False, closure, defer=True)
        if self.phase == "impact":
            # contacts within the whole step's gap tolerance take part in the impact (also in a
            # piece); in a step taken in pieces, also the contacts located, whatever their gap:
            # a fast-turning body's located gaps err by its turning
            return _Request(0.0, _gap_tolerance(self.settings, self.model, self.step_dt), 0.0, False,
                            watch=self.closing[1] if self.split else None)
        return self._request(self.dt - self.elapsed, self.impacts < _IMPACTS, closure)  # rest

    def receive(self, sub: _SubStep) -> None:
        phase = self.phase
        if sub.closing is not None:  # plain, correct or rest: an impact to locate
            if phase == "rest":
                self.approaches = 0
            self.closing = sub.closing
            self.phase = "impact" if (self.midpoint and self.closing[0] <= 0.0) else "approach"
            return
        self.t, self.q, self.v = sub.t, sub.q, sub.v
        self.outputs.append(sub.output)
        if phase in ("plain", "correct", "rest"):
            if self.left > 0.0:
                self.warm = warm_start_of(sub.output) or self.warm
                self._start_piece()
            else:
                self.phase = "done"
        elif phase == "approach":
            self.warm = warm_start_of(sub.output) or self.warm
            self.elapsed += self.closing[0]
            self.approaches += 1
            self.phase = "correct" if self.midpoint and self.approaches < _APPROACHES else "impact"
        elif phase == "impact":
            self.warm = warm_start_of(sub.output) or self.warm
            self.impacts += 1
            self.phase = "rest"

    def output(self) -> StepOutput:
        out = self.outputs[0]
        for later in self.outputs[1:]:
            out = out.then(later)
        return out


def step(model: Model, data: Data, dt: float, settings: Settings, margin: float,
         rows: np.ndarray | None = None) -> list[StepOutput]:
    """Advance scenes ``rows`` of ``data`` (default: all) by one step of ``dt`` seconds, in place.

    Each scene's step is split at its own impacts (see :class:`_Plan`); the sub-steps of
    all scenes go through the stages together. ``data.t``, ``q``, ``v`` and ``warm``
    of the rows are updated.

    Returns
    -------
    list of StepOutput
        One per row, in order.
    """
    rows = np.arange(len(data)) if rows is None else np.asarray(rows)
    plans = [_Plan(model, settings, dt, float(data.t[r]), data.q[r], data.v[r], data.warm[r]) for r in rows.tolist()]
    pending = list(range(len(plans)))
    while pending:
        subs = _advance(model, data, settings, margin, rows[pending], np.array([plans[k].t for k in pending]),
                        np.array([plans[k].q for k in pending]), np.array([plans[k].v for k in pending]),
                        [plans[k].warm for k in pending], [plans[k].request() for k in pending])
        for k, sub in zip(pending, subs):
            plans[k].receive(sub)
        pending = [k for k in pending if not plans[k].done]
    outputs = []
    for r, plan in zip(rows.tolist(), plans):
        out = plan.output()
        data.t[r], data.q[r], data.v[r] = plan.t, plan.q, plan.v
        data.warm[r] = warm_start_of(out, data.warm[r])
        outputs.append(out)
    return outputs


# --------------------------------------------------------------------------- running


def _check_time(t_end: float, dt: float) -> None:
    dt, t_end = real_number("dt", dt), real_number("t_end", t_end)
    if not (math.isfinite(dt) and dt > 0.0):
        raise ValueError(f"dt == {dt}, must be a finite number > 0 s.")
    if not (math.isfinite(t_end) and t_end >= 0.0):
        raise ValueError(f"t_end == {t_end}, must be a finite number >= 0 s.")
    if t_end > 0.0 and dt > t_end:
        raise ValueError(f"dt == {dt}, must be in (0, t_end] = (0, {t_end}] s.")
    n_steps = round(t_end / dt)
    if abs(n_steps * dt - t_end) > END_TIME_TOLERANCE * t_end:
        warnings.warn(f"t_end == {t_end} s is not a whole number of steps dt == {dt} s: the run takes the "
                      f"nearest whole number, {n_steps} steps, and ends at t = {n_steps * dt:.10g} s.",
                      RuntimeWarning, stacklevel=3)


class Run:
    """B scenes of one model stepped together: the loop shared by :class:`Simulator` and
    :class:`nscd.batch.BatchSimulator`.

    Parameters
    ----------
    model : Model
    scenes : sequence of Scene
        Scenes of structure ``model`` (their motions and initial states are read).
    dt : float
        Time step, s (> 0).
    settings : Settings
    record : bool
        Keep every scene's histories for :meth:`results`.
    store_impulses : bool
        With ``record``, keep contact points and impulses of every step.
    names : list of str
        How a failure names each scene (empty strings for a single run).
    events : sequence of callable, or one such sequence per scene, optional
        Event functions of the state (see :func:`simulate`): one list evaluated in every
        scene, or a list of lists, scene by scene (events that carry a scene's own data).
    """

    def __init__(self, model: Model, scenes, dt: float, settings: Settings, record: bool, store_impulses: bool,
                 names: list[str], events=None) -> None:
        self.model, self.dt, self.settings = model, float(dt), settings
        self.margin = settings.margin or _auto_margin(model)
        self.penetration_tolerance = PENETRATION_TOLERANCE * model.smallest_radius
        self.data = Data.from_scenes(model, scenes)
        for k in range(len(scenes)):
            try:
                check_overlaps(model, self.data.state(k), self.margin)
            except ValueError as exc:
                raise ValueError(f"{names[k]}{exc}") from None
        self.names = names
        self.running = np.ones(len(scenes), dtype=bool)
        self.unconverged = np.zeros(len(scenes), dtype=int)
        self.converged = np.ones(len(scenes), dtype=bool)
        self.outputs: list = [None] * len(scenes)
        speed = _impact_speed(settings, model, self.dt)
        self.builders = ([ResultBuilder(model, self.data.state(k), store_impulses, impact_speed=speed)
                          for k in range(len(scenes))] if record else None)
        self.wall = 0.0
        self.events = _scene_events(events, len(scenes))
        self.event_values = [[float(event(self.data.state(k))) for event, _, _ in self.events[k]]
                             for k in range(len(scenes))]
        self.t_events = [[[] for _ in self.events[k]] for k in range(len(scenes))]
        self.stopped_by: list = [None] * len(scenes)  # (event index, time) of a terminal event

    def step(self, stacklevel: int) -> np.ndarray:
        """Advance every running scene by one step; returns the rows stepped."""
        rows = np.flatnonzero(self.running)
        if len(rows) == 0:
            return rows
        start = _time.perf_counter()
        before = [self.data.state(r) for r in rows.tolist()] if self.builders is not None else None
        t_before = self.data.t[rows].copy()
        outputs = step(self.model, self.data, self.dt, self.settings, self.margin, rows)
        self.wall += _time.perf_counter() - start
        for k, (r, out) in enumerate(zip(rows.tolist(), outputs)):
            self.outputs[r] = out
            after = self.data.state(r) if (self.builders is not None or self.events[r]) else None
            if self.builders is not None:
                self.builders[r].add(before[k], after, out)
            if self.events[r]:
                self._locate_events(r, float(t_before[k]), after)
            self.converged[r] = out.report.converged
            if out.report.penetration > self.penetration_tolerance:
                warnings.warn(f"{self.names[r]}bodies overlap by {out.report.penetration:.3g} m at t = "
                              f"{out.report.t:.6g} s, more than {self.penetration_tolerance:.3g} m "
                              "(PENETRATION_TOLERANCE of the smallest body's radius); see "
                              "result.report.penetration", RuntimeWarning, stacklevel=stacklevel + 1)
            if not out.report.converged:
                self.unconverged[r] += 1
                message = (f"{self.names[r]}contact solver did not converge at t = {out.report.t:.6g} s "
                           f"({out.report.status}, merit {out.report.merit:.3g})")
                if self.settings.on_failure == "raise":
                    raise SolverFailure(message)
                warnings.warn(message, RuntimeWarning, stacklevel=stacklevel + 1)
        return rows

    def _locate_events(self, r: int, t_before: float, after: State) -> None:
        """Events of scene ``r`` in the step that ended in ``after``: a zero of an event
        function between the step's ends (in its ``direction``), located by linear
        interpolation of the function over the step; a terminal one stops the scene."""
        for i, (event, terminal, direction) in enumerate(self.events[r]):
            g0, g1 = self.event_values[r][i], float(event(after))
            self.event_values[r][i] = g1
            rising, falling = g0 < 0.0 <= g1, g0 > 0.0 >= g1
            if (rising and direction >= 0.0) or (falling and direction <= 0.0):
                t_event = t_before + (after.t - t_before) * g0 / (g0 - g1)
                self.t_events[r][i].append(t_event)
                if terminal and self.stopped_by[r] is None:
                    self.stopped_by[r] = (i, t_event)
                    self.running[r] = False

    def results(self, status: str, message: str, wall_share: float) -> list[Result]:
        out = []
        for k, builder in enumerate(self.builders):
            own_status, own_message = status, message
            if self.stopped_by[k] is not None and status == "finished":
                i, t_event = self.stopped_by[k]
                own_status, own_message = "event", f"stopped by terminal event {i} at t = {t_event:.6g} s"
            result = builder.build(status=own_status, message=own_message, wall_time=self.wall * wall_share,
                                   dt=self.dt, settings=self.settings)
            out.append(replace(result, t_events=[np.array(times) for times in self.t_events[k]]))
        return out


def _scene_events(events, n_scenes: int) -> list[list[tuple[Callable, bool, float]]]:
    """The checked events of each of ``n_scenes`` scenes: ``events`` is None, one sequence of
    callables for every scene, or a sequence of ``n_scenes`` such sequences (scene by scene)."""
    if events is None:
        return [[] for _ in range(n_scenes)]
    events = list(events)
    if not events or not all(isinstance(scene_events, (list, tuple)) for scene_events in events):
        shared = _check_events(events)
        return [shared for _ in range(n_scenes)]
    if len(events) != n_scenes:
        raise ValueError(f"events has {len(events)} lists, must be one list of events per scene ({n_scenes}) "
                         "or one list of callables for every scene.")
    return [_check_events(scene_events, f"events[{k}]") for k, scene_events in enumerate(events)]


def _check_events(events, name: str = "events") -> list[tuple[Callable, bool, float]]:
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
        checked.append((event, bool(terminal), float(direction)))
    return checked


class overturning:
    """A terminal event for :func:`simulate`: ``body`` overturns.

    Its value is the body's rotation from its initial orientation minus ``angle`` (rad;
    2D: the angle change, 3D: the tilt of the body's z axis), so it rises through zero
    when the body has rotated by ``angle``, by default the one definition of overturned,
    :data:`nscd.result.OVERTURN_ANGLE`.

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

    def __init__(self, scene: Scene, body, angle: float = OVERTURN_ANGLE) -> None:
        if not (isinstance(angle, (int, float)) and 0.0 < angle <= math.pi):
            raise ValueError(f"angle == {angle!r}, must be in (0, pi] rad.")
        handle = scene.body(body)
        self.index, self.dim, self.angle = handle.index, scene.dim, float(angle)
        self.q0 = np.array(handle.q0, dtype=float)

    def __call__(self, state: State) -> float:
        q = state.q[self.index]
        if self.dim == 2:
            return abs(float(q[2] - self.q0[2])) - self.angle
        return tilt_angle(self.q0[3:], q[3:]) - self.angle


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

    Attributes
    ----------
    model : Model
        The scene's structure.
    data : Data
        Its one row of data (time, state, warm start, solver cache, motions).
    output : StepOutput or None
        What the last step produced (contacts, active set, impulses, report).

    Examples
    --------
    >>> sim = nscd.Simulator(scene, dt=1e-3)
    >>> sim.step()            # one step; returns its StepReport
    >>> sim.run(until=2.0)    # more steps
    >>> result = sim.result()
    """

    def __init__(self, scene: Scene, dt: float, settings: Settings | None = None,
                 store_impulses: bool = False, *, events=None) -> None:
        if not isinstance(scene, Scene):
            raise TypeError(f"scene == {scene!r}, must be an nscd.Scene.")
        if settings is not None and not isinstance(settings, Settings):
            raise TypeError(f"settings == {settings!r}, must be an nscd.Settings or None.")
        _check_time(0.0, dt)
        self.settings = settings or Settings()
        self.dt = float(dt)
        self.model = Model.from_scene(scene)
        self._run = Run(self.model, [scene], dt, self.settings, True, store_impulses, [""], events)
        self.margin = self._run.margin
        self.data = self._run.data

    @property
    def state(self) -> State:
        """The current state (a read-only snapshot)."""
        return self.data.state(0)

    @property
    def output(self) -> StepOutput | None:
        return self._run.outputs[0]

    @property
    def stopped(self) -> bool:
        """Whether a terminal event has stopped the run (:meth:`step` then does nothing)."""
        return self._run.stopped_by[0] is not None

    def step(self) -> StepReport | None:
        """Advance one step; return its report (warns or raises if it did not converge).

        After a terminal event (:attr:`stopped`) nothing is stepped and None is returned."""
        if not len(self._run.step(stacklevel=2)):
            return None
        return self._run.outputs[0].report

    def run(self, until: float, callback: Callable[[State], Any] | None = None) -> None:
        """Step until time ``until`` (s); ``callback(state)`` after each step may return True to stop."""
        if not math.isfinite(real_number("until", until)):
            raise ValueError(f"until == {until}, must be a finite time in s.")
        n_steps = int(round((until - float(self.data.t[0])) / self.dt))
        for _ in range(max(n_steps, 0)):
            self.step()
            if self.stopped or (callback is not None and callback(self.state)):
                break

    def result(self, status: str = "finished", message: str = "") -> Result:
        """The result of the steps taken so far."""
        return self._run.results(status, message, 1.0)[0]


def simulate(scene: Scene, t_end: float, dt: float, theta: float = 0.5,
             settings: Settings | None = None, store_impulses: bool = False,
             checkpoint: str | None = None, checkpoint_every: float = 60.0,
             model: str | None = None, verify: bool = False, *, events=None) -> Result:
    """Simulate ``scene`` from t = 0 to ``t_end`` with time step ``dt``.

    Parameters
    ----------
    scene : Scene
    t_end : float
        End time in s (>= 0). The run takes ``round(t_end / dt)`` whole steps (no partial
        last step); when that does not end at ``t_end`` (relative ``END_TIME_TOLERANCE``)
        a RuntimeWarning gives the end time reached.
    dt : float
        Time step in s, in (0, t_end].
    theta : float
        Theta-method weight in [0.5, 1] (ignored if ``settings`` is given); a value other
        than 0.5 selects the theta scheme.
    settings : Settings, optional
        All integrator and solver options.
    store_impulses : bool
        Keep contact points and impulses of every step (off by default for memory).
    checkpoint : str, optional
        Path of an ``.npz`` file where the partial result is saved every
        ``checkpoint_every`` wall-clock seconds (> 0), on interruption (Ctrl-C) and at
        the end, so a long run loses nothing. Each save is atomic (a crash during it
        leaves the previous checkpoint whole). The path is checked before the first step
        (ValueError when no file can be written there); a save that fails later warns and
        the result is returned all the same.
    model : {None, "auto", "housner", "stacked", "2d", "3d"}
        None (default): this engine, in the scene's dimension. Otherwise the model to
        run, "auto" the smallest adequate one: see :func:`nscd.choose.run`.
    verify : bool
        With a ``model``: also run the next larger model and report the difference.
    events : sequence of callable, optional
        As in :func:`scipy.integrate.solve_ivp`: functions ``event(state) -> float`` of
        the :class:`~nscd.state.State`; an event occurs where the function crosses zero
        (from below if its attribute ``direction`` > 0, from above if < 0, either way if 0
        or absent), located within the step by linear interpolation of the function
        between the step's two ends (error of order dt^2). An event whose attribute
        ``terminal`` is True stops the run at the end of that step.
        :class:`overturning` is the ready event of a body that overturns. The times are
        in ``Result.t_events`` (one array per event).

    Returns
    -------
    Result
        ``status`` is "finished", "event" if a terminal event stopped it, or
        "interrupted" if stopped by KeyboardInterrupt (then the partial result is
        returned, and saved to ``checkpoint`` if given).
    """
    if model is not None or verify:
        from nscd.choose import run  # the model choice sits above the engine
        return run(scene, t_end, dt, model or "auto", verify=verify, theta=theta, settings=settings,
                   store_impulses=store_impulses, checkpoint=checkpoint, checkpoint_every=checkpoint_every)
    _check_time(t_end, dt)
    checkpoint = checkpoint_path(checkpoint, checkpoint_every)
    settings = settings or Settings(theta=theta, scheme="theta" if theta != 0.5 else Settings.scheme)
    if settings.theta != theta and theta != 0.5:
        settings = replace(settings, theta=theta, scheme="theta")
    sim = Simulator(scene, dt, settings, store_impulses=store_impulses, events=events)
    n_steps = int(round(t_end / dt))
    last_save = _time.perf_counter()
    try:
        for _ in range(n_steps):
            if sim.stopped:
                break
            sim.step()
            if checkpoint is not None and _time.perf_counter() - last_save > checkpoint_every:
                save_checkpoint(sim.result(status="running"), checkpoint)
                last_save = _time.perf_counter()
    except KeyboardInterrupt:
        result = sim.result(status="interrupted", message=f"interrupted at t = {sim.state.t:.6g} s")
        save_checkpoint(result, checkpoint)
        warnings.warn(result.message, RuntimeWarning, stacklevel=2)
        return result
    result = sim.result()
    save_checkpoint(result, checkpoint)
    return result
