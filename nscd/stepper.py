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
9. **solve**: the routes of :func:`nscd.solver.core.solve`: problems of at most
   ``settings.solver.fast_path_unknowns`` unknowns by the solver's compiled fast path, all
   scenes in one call (:func:`nscd.solver.proximal.fast_path`: the semismooth Newton of
   :mod:`nscd.solver.small`, then the proximal point and its polish on a problem it does not
   accept; one neither accepts, and one up to ``large_problem_unknowns``, by the conic fixed
   point); larger ones one by one by
   :func:`nscd.solver.api.solve_velocity_unchecked` (Gauss–Seidel with the scene's
   coarse correction, the interior point after it);
10. **integrate** positions (scheme hook); quaternions by the exact exponential map; the
    deepest end-of-step overlap, predicted, or detected in the end configuration where
    it may be deep (:func:`_predicted_overlaps`).

A sub-step of S scenes (:func:`_advance`) is a handful of compiled calls over flat arrays,
each composing several stages (:func:`_free_flight`, detection, :func:`_previous_impulses`,
:func:`_assemble`, the compiled fast path, :func:`_solution`, :func:`_finish`), with large
problems, the solver's other routes, the scaling of the restitution and the fresh detection
of an end-of-step overlap in Python between them, only where a scene needs them.

The scheme (:class:`Scheme`: theta method or Moreau's midpoint rule) chooses the hooks
of stages 2, 3, 6, 7, 8 and 10 (see ``docs/time_step.md``): Python hooks (configure the
driven bodies, seen_at, pace) and, in the compiled stages, the formulas chosen by the flag
``midpoint``. Every per-scene quantity is
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
from nscd._jit import njit, njit_helper
from nscd.contact.detect import detect
from nscd.contact.detect import detect_batch
from nscd.contact.frames import Contacts, _centripetal, _contact_kinematics, assemble_jacobian
from nscd.event_plan import (FIELDS, FINISHED, LENGTH, LEFT, PHASE, TURN_PER_PIECE, gap_tolerance, largest_spin, pace,
                             plan_receive, plan_request, plan_start, spin_squared)
from nscd.events import Events
from nscd.impact_law import NO_TRIAL, bisection_next, bisection_start, dissipation
from nscd.model import Model, rotated_inertia
from nscd.result import (Result, ResultBuilder, SolverFailure, StepReport, checkpoint_path,
                          save_checkpoint)
from nscd.rotation import drift_poses, rotation_matrices
from nscd.scene import OVERLAP_TOLERANCE, BodyKind, Scene
from nscd.solver import SolverSettings, Status, core
from nscd.solver.api import solve_velocity_unchecked
from nscd.solver.small import NOT_ACCEPTED, PROXIMAL_POLISHED
from nscd.state import (Data, State, WarmStart, WarmStarts, _bounds, _matched_rows, _segments,
                        summed_impulses)

__all__ = ["GAP_DEAD_BAND", "PENETRATION_TOLERANCE", "Scheme", "Settings", "Simulator", "StepOutput", "StepOutputs",
           "WarmStart", "check_overlaps", "initial_state", "simulate", "step", "warm_start_of"]

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
    localize_large : bool
        Also split the steps of a scene whose contact problems go to the Gauss–Seidel sweeps
        of large problems (its step before had more than ``max(solver.large_problem_unknowns,
        solver.fast_path_unknowns)`` unknowns, contacts x dim: an assembly). False (default):
        such a scene takes its impacts within the step, plain Moreau–Jean (Newton's law at
        the velocity level at the end of the step), as LMGC90 and Siconos do for assemblies:
        a wall breaking up has impacts in most steps, each located one costing two more
        solves of the whole wall's problem (three to nine per step), while what location
        buys, the time of each impact, is the single rocking block's accuracy, not an
        assembly's (``docs/solver.md``, seventh round). Only with ``localize_impacts``.
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
        order, the midpoint rule second order, which lets it reach Housner's restitution
        and impact times at a step about a hundred times coarser (validated against the
        1-DOF Housner model in ``tests/test_engine2d.py``, ``test_midpoint_*``; the
        figures in ``BENCHMARKS.md``).
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
    localize_large: bool = False
    scheme: str = "midpoint"
    solver: SolverSettings = field(default_factory=SolverSettings)
    on_failure: str = "warn"

    def __post_init__(self) -> None:
        for name in ("theta", "activation", "gap_tolerance", "margin", "impact_speed"):
            if getattr(self, name) is not None or name == "theta":
                real_number(name, getattr(self, name))
        flag("localize_impacts", self.localize_impacts)
        flag("localize_large", self.localize_large)
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
#: radius warn (0.1 mm for a 0.2 x 0.2 m block). Resolved contacts end deeper only by the
#: solver residue times h; the first-order prediction of the end gap errs by
#: O(h^2 omega^2 R) (1e-4 R at 1 rad/s and dt = 1e-2); an overlap of 1e-3 R is invisible in
#: a drawing and far below the tunnelling it guards against (``tests/test_tunnelling.py``
#: holds impacts and landings to a hundredth of it).
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
#: A problem found creating energy is then solved with the largest restitution factor whose
#: dissipation is >= 0 as computed, with no tolerance: K + P changes by exactly minus the
#: dissipation, and a factor kept within the tolerance on the creating side added 7e-6 J to
#: a 138 J triangle bouncing with friction.
ENERGY_ROUND_OFF = 1e-7
#: Passes of 9b that reflect the slips a problem's friction reverses: each pass adds the
#: contacts the last solve reversed (the reflected ones stay reflected); a reversal is a
#: contact that stops within the step, and the case met (a triangle's corner sticking after
#: a slide, tests/test_properties.py) needed one.
REFLECTION_PASSES = 3

#: A lasting contact counts as stuck in the step before when its friction impulse was below this
#: fraction of the cone's edge ``mu P_n``: a sliding contact's lies on the edge to the solver's
#: relative tolerance (1e-8), so 1 - 1e-6 tells the two apart with a margin of a hundred.
STUCK = 1.0 - 1e-6

def _auto_margin(model: Model) -> float:
    return 0.05 * model.smallest_radius


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
        """This sub-step followed by ``later``: :meth:`joined`."""
        return StepOutput.joined([self, later])

    @staticmethod
    def joined(parts: "list[StepOutput]") -> "StepOutput":
        """The sub-steps ``parts`` of one step in order, as one output: the contact arrays end to
        end; the report's time, overlap and (if all converged) status the last part's, its
        counts and merit the largest, its iterations summed, and the status of the first
        part that did not converge."""
        if len(parts) == 1:
            return parts[0]
        reports = [part.report for part in parts]
        failed = [r for r in reports if not r.converged]
        report = StepReport(
            t=reports[-1].t, n_contacts=max(r.n_contacts for r in reports),
            n_active=max(r.n_active for r in reports), status=(failed[0] if failed else reports[-1]).status,
            converged=not failed, iterations=sum(r.iterations for r in reports),
            merit=max(r.merit for r in reports), penetration=reports[-1].penetration)
        offsets = np.cumsum([0] + [len(part.contacts) for part in parts[:-1]])
        contacts = Contacts(*(np.concatenate([getattr(part.contacts, f) for part in parts])
                              for f in Contacts.__dataclass_fields__))
        return StepOutput(report=report, contacts=contacts,
                          active=np.concatenate([part.active + offset for part, offset in zip(parts, offsets)]),
                          impulses=np.concatenate([part.impulses for part in parts]),
                          u_before=np.concatenate([part.u_before for part in parts]),
                          u_after=np.concatenate([part.u_after for part in parts]),
                          solved_at=np.concatenate([part.solved_at for part in parts]),
                          driven=np.concatenate([part.driven_velocity() for part in parts]))


def warm_start_of(out: StepOutput) -> WarmStart:
    """Impulses (N s, contact frame) of the active contacts of a step, with their contact ids
    (no trend: :meth:`WarmStart.followed_by` adds it, given the step before's)."""
    return WarmStart(out.contacts.ids[out.active], out.impulses)


# --------------------------------------------------------------------------- scheme hooks


class _Theta:
    """The theta scheme's hooks: contacts at ``q_k``, ``q_{k+1} = q_k + h (theta v_{k+1} + (1 - theta) v_k)``."""

    midpoint = False

    def __init__(self, settings: Settings) -> None:
        self.settings, self.theta = settings, settings.theta
        self.activation = 1.5 - self.theta if settings.activation is None else settings.activation

    def configure(self, k, data, rows, t, q_c, v, dt):
        """Configuration where contacts are detected and the Jacobian built: ``q_k`` (``q_c``)."""

    def seen_at(self, model, q, q_c, sweep, fastest):
        """Contacts are seen at ``q_k`` in every scene: ``(q_k, no scene seen early)``."""
        return q_c, np.zeros(len(q), dtype=bool)


class _Midpoint:
    """Moreau's midpoint rule: contacts at ``q_M = q_k + h/2 v_k``, ``q_{k+1} = q_M + h/2 v_{k+1}``."""

    midpoint = True
    # typed placeholders: the compiled stages take the theta scheme's parameters as floats
    # under both schemes (one compiled specialisation) and read them only when not midpoint
    theta = activation = 0.5

    def __init__(self, settings: Settings) -> None:
        self.settings = settings

    def configure(self, k, data, rows, t, q_c, v, dt):
        """The midpoint ``q_M`` (``q_c``, in place): the dynamic bodies drifted h/2 with ``v_k``
        (:func:`_free_flight`), the driven bodies posed at ``t_k + h/2``."""
        if k.driven:
            data.drives.write(rows, t + 0.5 * dt, q_c, v.copy())

    def seen_at(self, model, q, q_c, sweep, fastest):
        """Where contacts are seen: ``q_M``, except in "early" scenes, where a body may move
        by more than ``EARLY_DETECTION_SWEEP`` of the thinnest body's thickness within the
        step (``sweep`` (S, n_bodies), m, the largest ``fastest``): there ``q_k``. Returns the
        configurations (S, n_bodies, nq) and ``early`` (S,).

        Half a step ahead, a fast body may be past the middle of a thin one: the narrow
        phase then finds their separating axis on the far side (the pair seems to separate)
        and the impact is lost (tunnelling). Seen at ``q_k`` the pair is on its true side,
        and the impact is localised from there as any other (:class:`_Plan`); the gaps are
        then carried to ``q_M`` by ``h/2 u_k`` (:func:`_assemble`), and the end gaps
        predicted over the whole step (:func:`_finish`).
        """
        limit = EARLY_DETECTION_SWEEP * model.thinnest
        if fastest <= limit:
            return q_c, np.zeros(len(q), dtype=bool)
        early = sweep.max(axis=1) > limit
        return np.where(early[:, None, None], q, q_c), early


def _hooks(settings: Settings):
    return _Midpoint(settings) if settings.scheme == Scheme.MIDPOINT.value else _Theta(settings)


class _Constants:
    """What every step of one model with given settings, step and margin shares, computed once
    (:func:`_constants`): the scheme's hooks and the scalars and flags of the compiled stages,
    the solver's routes, the plain sub-step of a whole step."""

    def __init__(self, model: Model, settings: Settings, dt: float, margin: float) -> None:
        self.model, self.settings, self.dt, self.margin = model, settings, dt, margin
        self.hooks = hooks = _hooks(settings)
        self.midpoint, self.theta, self.activation = hooks.midpoint, hooks.theta, hooks.activation
        self.impact_speed = settings.impact_speed or 0.0  # 0: 2 g dt (:func:`_screen`)
        self.localize = settings.localize_impacts
        # a scene with more unknowns than `dense` in its step before is not split at its impacts
        self.localize_large = settings.localize_large
        self.dead_band = GAP_DEAD_BAND * model.smallest_radius
        self.noise = settings.solver.tol
        self.overlap_check = FRESH_OVERLAP_CHECK * PENETRATION_TOLERANCE * model.smallest_radius
        # only driven bodies move: the fixed ones keep the pose the data was given (Data.from_scenes)
        self.driven = any(body.kind is BodyKind.DRIVEN for body in model.bodies)
        self.mass_diagonal = model.mass_diagonal if model.dim == 2 else _NO_DIAGONAL
        # 3D: the dynamic bodies' inertias in their own frames, C-contiguous (n_dyn, 3, 3)
        self.dynamic_inertia = np.ascontiguousarray(model.inertia_body[model.dynamic_index], dtype=float)
        solver = settings.solver
        # routes as in nscd.solver.core.solve: at most fast_path_unknowns unknowns the compiled
        # Newton (all scenes in one call), up to `dense` the dense problem by the conic fixed
        # point, above it the Gauss-Seidel route
        self.fast = solver.fast_path_unknowns
        self.dense = max(solver.large_problem_unknowns, solver.fast_path_unknowns)
        self.fast_off = replace(solver, fast_path_unknowns=0)
        # Settings.gap_tolerance, NaN: automatic (nscd.event_plan.gap_tolerance)
        self.fixed_tolerance = math.nan if settings.gap_tolerance is None else float(settings.gap_tolerance)
        self.plain = _plain_request(self)
        self._plain_rows: dict = {}

    def plain_rows(self, S: int) -> _Rows:
        """The per-scene inputs of S scenes all taking the plain sub-step (the whole step,
        stopping at a predicted impact); read only."""
        rows = self._plain_rows.get(S)
        if rows is None:
            rows = self._plain_rows[S] = _Rows.of([self.plain] * S, self.localize)
        return rows


#: The constants of the latest models stepped (:func:`_constants`), at most _KEPT of them.
_CONSTANTS: dict = {}
_KEPT = 16


def _constants(model: Model, settings: Settings, dt: float, margin: float) -> _Constants:
    """The :class:`_Constants` of stepping ``model`` with ``settings``, ``dt`` and ``margin``,
    computed on the first step and kept for the next ones."""
    key = (id(model), id(settings), dt, margin)
    found = _CONSTANTS.get(key)
    if found is None or found.model is not model or found.settings is not settings:
        if len(_CONSTANTS) >= _KEPT:
            _CONSTANTS.clear()
        found = _CONSTANTS[key] = _Constants(model, settings, dt, margin)
    return found


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


class _Rows:
    """The requests of S scenes' sub-steps as the arrays of the compiled stages: lengths ``dt``,
    gap ``tolerance`` and ``pace`` (S,), ``localizing``, ``deferring`` (S,) bool, and the ids
    watched by each scene, ``watch_ids[watch_first[s]:watch_first[s + 1]]`` (``watching`` (S,)
    bool: the scene has a watch)."""

    def __init__(self, dt, tolerance, pace, localizing, deferring, watching, watch_ids, watch_first) -> None:
        self.dt, self.tolerance, self.pace = dt, tolerance, pace
        self.localizing, self.deferring = localizing, deferring
        self.watching, self.watch_ids, self.watch_first = watching, watch_ids, watch_first

    def unlocated(self, scenes: np.ndarray) -> "_Rows":
        """These rows with the impacts of ``scenes`` (S,) bool taken within the sub-step, not
        located (``Settings.localize_large``); these very rows if there are none."""
        if not scenes.any():
            return self
        return _Rows(self.dt, self.tolerance, self.pace, self.localizing & ~scenes, self.deferring, self.watching,
                     self.watch_ids, self.watch_first)

    @classmethod
    def of(cls, requests: list[_Request], localize: bool) -> "_Rows":
        watches = [r.watch for r in requests]
        watched = [w for w in watches if w is not None]
        return cls(np.array([r.dt for r in requests]), np.array([r.tolerance for r in requests]),
                   np.array([r.pace for r in requests]), np.array([r.localize and localize for r in requests]),
                   np.array([r.defer for r in requests]), np.array([w is not None for w in watches]),
                   np.ascontiguousarray(np.concatenate(watched), dtype=np.int64) if watched else _NO_IDS,
                   np.cumsum([0] + [0 if w is None else len(w) for w in watches]))


_NO_IDS = np.zeros((0, 3), dtype=np.int64)


@dataclass
class _SubStep:
    """What a sub-step gave one scene: the new state and output, or where an impact closes."""

    t: float
    q: np.ndarray
    v: np.ndarray
    output: StepOutput | None
    closing: tuple[float, np.ndarray] | None  #: (time from the start, ids of the contacts)


@njit_helper
def _free_flight_2d(v, dt, dynamic_index, mass, mass_diagonal, gravity):
    """2D free flight: ``v + h f / m`` per velocity component of the dynamic bodies,
    ``f = (0, -m g, 0)`` (gravity along -y, no moment), (S, n_dofs)."""
    out = np.empty((v.shape[0], 3 * dynamic_index.shape[0]))
    for s in range(v.shape[0]):
        for k in range(dynamic_index.shape[0]):
            i = dynamic_index[k]
            for j in range(3):
                force = -mass[i] * gravity if j == 1 else 0.0
                out[s, 3 * k + j] = v[s, i, j] + dt[s] * (force / mass_diagonal[3 * k + j])
    return out


def _free_flight(k: _Constants, q: np.ndarray, v: np.ndarray, v_next: np.ndarray,
                 dt: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, np.ndarray]:
    """Stage 5, the sweeps of stage 3 and the dynamic bodies' part of stage 2, in one compiled call.

    ``v_free = v_k + h M^-1 f`` of the dynamic bodies (S, n_dofs), 2D: gravity
    (:func:`_free_flight_2d`), 3D: gravity and the gyroscopic moment ``-omega x I omega`` at
    ``t_k``, the world inertia ``I`` from the orientation at ``t_k`` (:func:`_free_flight_3d`);
    the inverse mass blocks of every scene's dynamic bodies (S, n_dyn, 6, 6) in 3D
    ((S, 0, 6, 6) in 2D); how far each body may move in the sub-step (:func:`_sweep`,
    (S, n_bodies), m) and the largest of these; and the configuration where contacts are
    seen: ``q_k`` (theta scheme), or the midpoint rule's ``q_M``, the dynamic bodies drifted
    h/2 with ``v_k`` (:func:`nscd.rotation.drift_poses`; the hook poses the driven ones).
    ``v_next`` (S, n_bodies, nv): the fixed and driven bodies' velocities at the end.
    """
    model = k.model
    if model.dim == 2:
        v_free, sweep, largest, q_c = _flight_2d(q, v, v_next, dt, model.dynamic_index, model.dof_of_body,
                                                  model.mass, model.mass_diagonal, model.gravity, model.radius,
                                                  k.midpoint)
        return v_free, np.zeros((len(q), 0, 6, 6)), sweep, largest, q_c
    return _flight_3d(q, v, v_next, dt, model.dynamic_index, model.dof_of_body, model.mass, model.gravity,
                      k.dynamic_inertia, model.radius, k.midpoint)


@njit
def _flight_2d(q, v, v_next, dt, dynamic_index, dof_of_body, mass, mass_diagonal, gravity, radius, midpoint):
    """2D :func:`_free_flight` (without the empty inverse mass blocks)."""
    v_free = _free_flight_2d(v, dt, dynamic_index, mass, mass_diagonal, gravity)
    sweep, largest = _swept_distance(v, v_next, v_free, dt, dof_of_body, radius, 2)
    q_c = drift_poses(q, v, 0.5 * dt, dynamic_index) if midpoint else q.copy()
    return v_free, sweep, largest, q_c


@njit
def _flight_3d(q, v, v_next, dt, dynamic_index, dof_of_body, mass, gravity, inertia_body, radius, midpoint):
    """3D :func:`_free_flight` (``inertia_body`` (n_dyn, 3, 3): the dynamic bodies' inertias in their
    own frames, kg m^2, turned to the world frame at ``t_k`` as :meth:`nscd.model.Model.world_inertia`)."""
    S, n_dyn = q.shape[0], dynamic_index.shape[0]
    quats = np.empty((S * n_dyn, 4))
    body = np.empty((S * n_dyn, 3, 3))
    for s in range(S):
        for k in range(n_dyn):
            for d in range(4):
                quats[s * n_dyn + k, d] = q[s, dynamic_index[k], 3 + d]
            for i in range(3):
                for j in range(3):
                    body[s * n_dyn + k, i, j] = inertia_body[k, i, j]
    inertia = rotated_inertia(rotation_matrices(quats), body).reshape(S, n_dyn, 3, 3)
    v_free, inverse_blocks = _free_flight_3d(v, dt, dynamic_index, mass, gravity, inertia)
    sweep, largest = _swept_distance(v, v_next, v_free, dt, dof_of_body, radius, 3)
    q_c = drift_poses(q, v, 0.5 * dt, dynamic_index) if midpoint else q.copy()
    return v_free, inverse_blocks, sweep, largest, q_c


@njit_helper
def _free_flight_3d(v, dt, dynamic_index, mass, gravity, inertia):
    """3D free flight: ``v + h M^-1 f``, ``f = (0, 0, -m g, -omega x I omega)`` per
    dynamic body (``inertia`` (S, n_dyn, 3, 3) in the world frame, kg m^2), (S, n_dofs); and
    the inverse 6 x 6 mass blocks ``diag(1/m, 1/m, 1/m, I^-1)`` (S, n_dyn, 6, 6)."""
    S, n_dyn = v.shape[0], dynamic_index.shape[0]
    out = np.empty((S, 6 * n_dyn))
    inverse = np.zeros((S, n_dyn, 6, 6))
    f = np.empty(6)
    for s in range(S):
        for k in range(n_dyn):
            i = dynamic_index[k]
            I = inertia[s, k]
            for d in range(3):
                inverse[s, k, d, d] = 1.0 / mass[i]
            # the inverse of the symmetric 3 x 3 inertia by its cofactors
            c00 = I[1, 1] * I[2, 2] - I[1, 2] * I[2, 1]
            c01 = I[1, 2] * I[2, 0] - I[1, 0] * I[2, 2]
            c02 = I[1, 0] * I[2, 1] - I[1, 1] * I[2, 0]
            det = I[0, 0] * c00 + I[0, 1] * c01 + I[0, 2] * c02
            J = inverse[s, k, 3:, 3:]
            J[0, 0], J[1, 0], J[2, 0] = c00 / det, c01 / det, c02 / det
            J[0, 1] = (I[0, 2] * I[2, 1] - I[0, 1] * I[2, 2]) / det
            J[1, 1] = (I[0, 0] * I[2, 2] - I[0, 2] * I[2, 0]) / det
            J[2, 1] = (I[0, 1] * I[2, 0] - I[0, 0] * I[2, 1]) / det
            J[0, 2] = (I[0, 1] * I[1, 2] - I[0, 2] * I[1, 1]) / det
            J[1, 2] = (I[0, 2] * I[1, 0] - I[0, 0] * I[1, 2]) / det
            J[2, 2] = (I[0, 0] * I[1, 1] - I[0, 1] * I[1, 0]) / det
            wx, wy, wz = v[s, i, 3], v[s, i, 4], v[s, i, 5]
            lx = I[0, 0] * wx + I[0, 1] * wy + I[0, 2] * wz
            ly = I[1, 0] * wx + I[1, 1] * wy + I[1, 2] * wz
            lz = I[2, 0] * wx + I[2, 1] * wy + I[2, 2] * wz
            f[0], f[1], f[2] = 0.0, 0.0, -mass[i] * gravity
            f[3], f[4], f[5] = -(wy * lz - wz * ly), -(wz * lx - wx * lz), -(wx * ly - wy * lx)
            for r in range(6):
                total = 0.0
                for j in range(6):
                    total += inverse[s, k, r, j] * f[j]
                out[s, 6 * k + r] = v[s, i, r] + dt[s] * total
    return out, inverse


@njit_helper
def _swept_distance(v, v_end, v_free, dt, dof_of_body, radius, dim):
    """How far any point of each body may move within the sub-step, m, (S, n_bodies):
    ``h (|v| + |omega| R)``; and the largest of these, m.

    ``v`` (S, n_bodies, nv) at the start, ``v_end`` with the fixed and driven bodies at the
    end (their prescribed motion), ``v_free`` (S, n_dofs) the dynamic bodies' free flight;
    ``R`` the body's bounding radius (``radius``). Speeds are the larger of the start and the
    end values (in free flight the translational velocity varies linearly, so its norm stays
    below the larger end; the 2D spin is constant). This is the speculative-contact bound
    (Catto, "Speculative contacts", GDC 2013; Box2D's swept AABB): with it the broad and
    narrow phases find every contact that can close in the step.
    """
    S, n, nv = v.shape
    out = np.empty((S, n))
    largest = 0.0
    for s in range(S):
        for i in range(n):
            dof = dof_of_body[i]
            end = v_free[s, dof:dof + nv] if dof >= 0 else v_end[s, i]
            lin0 = lin1 = 0.0
            for j in range(dim):
                lin0 += v[s, i, j] * v[s, i, j]
                lin1 += end[j] * end[j]
            spin = max(spin_squared(v[s, i]), spin_squared(end))
            out[s, i] = dt[s] * (math.sqrt(max(lin0, lin1)) + math.sqrt(spin) * radius[i])
            largest = max(largest, out[s, i])
    return out, largest


_NO_DIAGONAL = np.zeros(0)
_NO_BLOCKS = np.zeros((0, 6, 6))


@njit
def _dense_problem(blocks, idx, body_a, body_b, dof_of_body, n_dofs, mass_diagonal, inverse_blocks, v_free, offset):
    """Stage 8 of a small problem: the dense contact problem of contacts ``idx`` (k,) of one scene.

    ``H`` (k dim, n_dofs) from the Jacobian blocks (columns of fixed and driven bodies
    left out), ``M^-1 H^T`` with the mass matrix of the dynamic bodies given as its
    diagonal ``mass_diagonal`` (2D, kg, kg, kg m^2) or as the inverses of its 6 x 6
    blocks ``inverse_blocks`` (3D), the Delassus operator ``W = H M^-1 H^T`` and the free
    relative velocity ``q = H v_free + offset`` (m/s).

    A contact's rows of ``H`` are zero outside the columns of its (at most two) dynamic
    bodies, and ``M^-1`` is block diagonal: the products run over those columns alone, in
    increasing order (the full sums' order, without their zero terms). The bodies two
    contacts share are found once for their ``dim x dim`` block of ``W``, whose entries then
    read ``M^-1 H^T`` row by row from its transpose.
    """
    k = idx.shape[0]
    dim, nv = blocks.shape[2], blocks.shape[3]
    # each contact's dynamic bodies by their first column, in increasing order (-1: none)
    dofs = np.full((k, 2), -1, dtype=np.int64)
    H = np.zeros((k * dim, n_dofs))
    for a in range(k):
        c = idx[a]
        first, second = dof_of_body[body_b[c]], dof_of_body[body_a[c]]
        if first < 0 or (0 <= second < first):
            first, second = second, first
        if first < 0:
            first, second = second, -1
        dofs[a, 0], dofs[a, 1] = first, second
        for side in range(2):
            dof = dof_of_body[body_b[c] if side == 0 else body_a[c]]
            if dof < 0:
                continue
            for r in range(dim):
                for j in range(nv):
                    H[a * dim + r, dof + j] = blocks[c, side, r, j]
    MinvHT = np.zeros((n_dofs, k * dim))
    HMinv = np.zeros((k * dim, n_dofs))  # (M^-1 H^T)^T: its columns as contiguous rows
    for row in range(k * dim):
        for e in range(2):
            dof = dofs[row // dim, e]
            if dof < 0:
                continue
            if dim == 2:
                for j in range(dof, dof + nv):
                    HMinv[row, j] = MinvHT[j, row] = H[row, j] / mass_diagonal[j]
            else:
                body = dof // 6
                for i in range(6):
                    total = 0.0
                    for j in range(6):
                        total += inverse_blocks[body, i, j] * H[row, 6 * body + j]
                    HMinv[row, 6 * body + i] = MinvHT[6 * body + i, row] = total
    W = np.empty((k * dim, k * dim))
    q = np.empty(k * dim)
    for a in range(k):
        for b in range(k):
            # the dynamic bodies (first columns) of contact a that contact b shares, in a's order
            shared_0, shared_1 = -1, -1
            for e in range(2):
                dof = dofs[a, e]
                if dof >= 0 and (dof == dofs[b, 0] or dof == dofs[b, 1]):
                    if shared_0 < 0:
                        shared_0 = dof
                    else:
                        shared_1 = dof
            # the block's entries summed side by side (a 2 x 2 or 3 x 3 outer product per
            # column j): each entry its own sum, in the order above, none waiting for another's
            row, col = a * dim, b * dim
            w00, w01, w02, w10, w11, w12, w20, w21, w22 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
            for shared in (shared_0, shared_1):
                if shared < 0:
                    continue
                for j in range(shared, shared + nv):
                    h0, h1, m0, m1 = H[row, j], H[row + 1, j], HMinv[col, j], HMinv[col + 1, j]
                    w00 += h0 * m0
                    w01 += h0 * m1
                    w10 += h1 * m0
                    w11 += h1 * m1
                    if dim == 3:
                        h2, m2 = H[row + 2, j], HMinv[col + 2, j]
                        w02 += h0 * m2
                        w12 += h1 * m2
                        w20 += h2 * m0
                        w21 += h2 * m1
                        w22 += h2 * m2
            W[row, col], W[row, col + 1], W[row + 1, col], W[row + 1, col + 1] = w00, w01, w10, w11
            if dim == 3:
                W[row, col + 2], W[row + 1, col + 2] = w02, w12
                W[row + 2, col], W[row + 2, col + 1], W[row + 2, col + 2] = w20, w21, w22
    for row in range(k * dim):
        a = row // dim
        total = 0.0
        for e in range(2):
            dof = dofs[a, e]
            if dof >= 0:
                for j in range(dof, dof + nv):
                    total += H[row, j] * v_free[j]
        q[row] = total + offset[row // dim, row % dim]
    return H, MinvHT, W, q


def _inverse_mass(inverse_blocks: np.ndarray) -> sp.csr_matrix:
    """``M^-1`` of one 3D scene, CSR, from the inverses of its 6x6 blocks (n, 6, 6): every entry of
    each block stored, row by row (no per-block conversion: it was a millisecond per large solve)."""
    n = inverse_blocks.shape[0]
    columns = np.arange(6)[None, None, :] + 6 * np.arange(n)[:, None, None]
    return sp.csr_matrix((np.ascontiguousarray(inverse_blocks, dtype=np.float64).ravel(),
                          np.broadcast_to(columns, (n, 6, 6)).ravel(), np.arange(0, 36 * n + 1, 6)),
                         shape=(6 * n, 6 * n))


_CONVERGED_STATUS = str(Status.CONVERGED)
_POLISHED_STATUS = str(Status.POLISHED)


# ---- the per-contact stages, compiled; ``midpoint`` chooses the scheme's formulas (see the hooks)


@njit_helper
def _screen(gap, u_k, scene, dt, tolerance, impact_speed, gravity, previous, midpoint):
    """Stage 6 per contact: the gap at the start of the step, the impacting contacts (open,
    approaching: candidates for event location) and the impacts to take now (closed at the
    start and approaching as an impact).

    ``gap`` (m,), m; ``u_k`` (m, dim) relative velocities at ``t_k``, m/s; ``scene`` (m,) indexes the per-scene ``dt``, ``tolerance`` (gap tolerance,
    m); ``impact_speed`` (m/s, 0: ``2 g dt``); ``previous`` (m, dim) the warm-start impulses.

    Theta scheme: the gap at ``q_k`` is the start gap; an open contact approaching is
    impacting (localised, not activated early). Midpoint rule: the start gap is
    extrapolated back from ``q_M``, ``g - h/2 u_n``. The midpoint rule would treat an
    impact half a step late (geometry at ``q_M``), so every approach is localised, down to
    gaps of 1 % of the tolerance (which is meant for resting contacts drifting open by
    round-off) -- except two kinds of slow approach, which are the closing of a small gap,
    not an impact, and are left to the active set as under the theta scheme:

    - that of a contact that carried load in the previous step, slower than the impact
      speed (treating it as one makes a block at rest rock between its corners, one
      micro-impact per step);
    - that of a contact within the gap tolerance band (``g0 <= tol``) or already closed,
      whose approach over the whole step is below the precision to which impacts are
      located (``-u_n h <= 0.01 tol``): locating it cannot do better than the step does,
      and the midpoint's late sight of it errs by less than that precision. Such
      approaches are the unloaded joints of an assembly (the head joints of a wall)
      nudged by micrometres per second, and the solver's residue at contacts that carry
      nothing; taken as impacts, each one split its step into an approach, corrections,
      the impact and the rest, each a contact problem of the whole assembly
      (``docs/solver.md``). Faster approaches from within the band are located: at the
      onset of rocking the first uplifts close at a few mm/s from a few micrometres, and
      the block rocks as measured only when those impacts are taken at their instant.

    Returns ``(gap_start, impacting, now)``, (m,) each; ``now`` is always false under the
    theta scheme. :func:`_locate` takes events among
    ``impacting | now``.
    """
    m = gap.shape[0]
    gap_start = np.empty(m)
    impacting = np.zeros(m, dtype=np.bool_)
    now = np.zeros(m, dtype=np.bool_)
    for c in range(m):
        h, tol, u_n = dt[scene[c]], tolerance[scene[c]], u_k[c, 0]
        if midpoint:
            speed = impact_speed if impact_speed > 0.0 else 2.0 * gravity * h
            fast = u_n < -speed
            carried = previous[c, 0] > 0.0
            slow = -u_n * h <= 0.01 * tol
            g0 = gap[c] - 0.5 * h * u_n
            if u_n < 0.0:
                impacting[c] = (g0 > 0.01 * tol and not carried and not (slow and g0 <= tol)) or (fast and g0 > 0.0)
                now[c] = (g0 < -0.01 * tol and not carried and not slow) or (fast and g0 <= 0.0)
        else:
            g0 = gap[c]
            impacting[c] = g0 > tol and u_n < 0.0
        gap_start[c] = g0
    return gap_start, impacting, now


@njit_helper
def _activate(gap, u_k, u_free, w_next, curvature, restitution, friction, previous, scene, dt, tolerance, pace,
              impacting, hit, localizing, deferring, stepping, dead_band, noise, midpoint, theta, activation):
    """Stages 6 and 8 per contact: the active set and the offsets of the contact problems.

    Active: theta scheme, ``g + activation h min(theta u_free + (1 - theta) u_k, 0) <= tol``;
    midpoint rule, the gap predicted at the next midpoint from ``q_M``,
    ``g + h min(u_free, 0) <= tol``, an approach being localised left to its event.
    The contacts ``hit`` by an impact of a step taken in pieces (located for it,
    approaching) are active whatever their gap. Impacting contacts of a scene that defers
    them (the approach) and every contact of a scene that stops at an event are not active.

    Offsets (m/s, (k, dim)) of the active contacts ``u = H v + offset``: the part due to
    the fixed and driven bodies at the end ``w_next``; Newton's restitution
    ``e min(u_k, 0)``; a contact counted as closed with a small positive gap (<= the gap
    tolerance) closes it within the step, ``max(g - bias - dead_band, 0) / pace`` (none in
    an impact, ``dt = 0``), so no body is held off a surface by the tolerance, and gaps
    below the dead band are left alone (``GAP_DEAD_BAND``); midpoint rule, ``bias = h^2 c_n / 8``
    is what the straight drift to ``q_M`` opens a contact whose point turns (``c``, the
    centripetal acceleration of the points, ``curvature``: a pivot resting on its corner
    is ``h^2 c_n / 8`` open at ``q_M``, and closing that was a steady loss); the
    second-order gap term: theta scheme, ``h c_n / (2 theta)`` (the gap changes by
    ``h^2 c / 2`` beyond the velocity-level prediction while ``v_{k+1}`` acts over
    ``theta h``; without it a rocking pivot drifts open, falls back and chatters); midpoint
    rule, the full drift from midpoint to midpoint ``h c / 2``, normal and tangential (a
    stuck pivot creeps otherwise).

    No impulse does positive work. The contacts' work in a (sub-)step is
    ``sum P . (u_k + u_+) / 2``, and where ``P_n > 0`` the normal law makes ``u_+ = -offset``
    (without the part ``w_next``): so the normal offset is at least ``u_k - noise``
    (``P_n (u_k + u_+) <= P_n noise``; ``noise``, m/s, the solver's tolerance: velocities
    below it are the residue of the step before, and following them sets targets at the
    redundant contacts of a hyperstatic wall that no rigid motion meets, which stalled a
    3D wall's problems). Midpoint rule: a lasting contact (it carried load in the step
    before: its warm start ``previous`` has a normal impulse) whose normal velocity at
    ``q_M`` is not approaching (above ``noise``) takes ``u_k`` itself (plus the closure):
    ``u_+ = -u_k``, no work, the discrete form of a contact that stays closed (for a point
    turning at the rate of ``c``, ``u_k = h c_n / 2`` to first order, the second-order term
    it replaces, and the gap from midpoint to midpoint is kept to third order); one that
    was also stuck (its friction impulse ``previous`` inside the cone, ``STUCK``) and whose
    tangential velocity differs from ``h c_t / 2`` by more than ``noise`` takes ``u_k``
    tangentially too, if that difference is of the size of the turning term (at most
    ``h |c_t|``; a real slip reflected step after step would never stop): Coulomb's law on
    the mean tangential velocity, which cannot do positive work.

    Returns the indices of the active contacts (k,) and their offsets (k, dim).
    """
    m, dim = u_k.shape
    active = np.empty(m, dtype=np.int64)
    k = 0
    for c in range(m):
        s = scene[c]
        h, tol = dt[s], tolerance[s]
        if midpoint:
            is_active = gap[c] + h * min(u_free[c, 0], 0.0) <= tol and not (impacting[c] and localizing[s])
        else:
            closing = min(theta * u_free[c, 0] + (1.0 - theta) * u_k[c, 0], 0.0)
            is_active = gap[c] + activation * h * closing <= tol
        is_active = is_active or hit[c]
        if is_active and stepping[s] and not (impacting[c] and deferring[s]):
            active[k] = c
            k += 1
    offset = np.empty((k, dim))
    for a in range(k):
        c = active[a]
        s = scene[c]
        h = dt[s]
        bias = 0.125 * h * h * curvature[c, 0] if midpoint else 0.0
        closure = max(gap[c] - bias - dead_band, 0.0) / pace[s] if h > 0.0 else 0.0
        target = restitution[c] * min(u_k[c, 0], 0.0) + closure
        if midpoint:
            lasting = previous[c, 0] > 0.0
            if lasting and u_k[c, 0] > noise:
                target = u_k[c, 0] + closure
            else:
                target += 0.5 * h * curvature[c, 0]
            tangential = slip = 0.0
            for d in range(1, dim):
                tangential += previous[c, d] * previous[c, d]
                slip += (u_k[c, d] - 0.5 * h * curvature[c, d]) ** 2
            stuck = lasting and math.sqrt(tangential) < STUCK * friction[c] * previous[c, 0]
            turning = 0.0
            for d in range(1, dim):
                turning += (h * curvature[c, d]) ** 2
            reflect = stuck and noise < math.sqrt(slip) <= noise + math.sqrt(turning)
            for d in range(1, dim):
                offset[a, d] = w_next[c, d] + (u_k[c, d] if reflect else 0.5 * h * curvature[c, d])
        else:
            target += 0.5 * h / theta * curvature[c, 0]
            for d in range(1, dim):
                offset[a, d] = w_next[c, d]
        # no normal impulse does positive work beyond the solver's residue: P_n (u_k + u_+) <= P_n noise
        offset[a, 0] = w_next[c, 0] + max(target, u_k[c, 0] - noise)
    return active[:k], offset


@njit_helper
def _end_gaps(gap, u_k, u_end, scene, dt, midpoint, theta):
    """Every detected contact's gap at the end of the sub-step (m,), m, predicted to first order:
    theta scheme ``g + h (theta u_{k+1} + (1 - theta) u_k)``, midpoint rule ``g_M + h/2 u_{k+1}``
    (``q_{k+1} = q_M + h/2 v_{k+1}``)."""
    out = np.empty(gap.shape[0])
    for c in range(gap.shape[0]):
        h = dt[scene[c]]
        if midpoint:
            out[c] = gap[c] + 0.5 * h * u_end[c, 0]
        else:
            out[c] = gap[c] + h * (theta * u_end[c, 0] + (1.0 - theta) * u_k[c, 0])
    return out


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
    overlap = np.zeros(S)
    check = np.zeros(S, dtype=np.bool_)
    for s in range(S):
        possible = -np.inf
        for c in range(first[s], first[s + 1]):
            error = 0.0
            for body in (body_a[c], body_b[c]):
                turn = max(spin_squared(v[s, body]), spin_squared(v_end[s, body]))
                error += 0.5 * turn * span[s] * span[s] * radius[body]
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
    _deepest_overlaps(overlap, rows[scene], found.gap)
    return overlap


@njit
def _deepest_overlaps(overlap: np.ndarray, scene: np.ndarray, gap: np.ndarray) -> None:
    """``overlap[scene[c]] = max(overlap[scene[c]], -gap[c])`` for each contact ``c``, in
    place: the deepest overlap (m, >= 0 where ``overlap`` starts at 0) of each scene's
    contacts, ``scene`` (m,) their scenes, ``gap`` (m,) their gaps (m, negative when the bodies
    overlap). A NaN gap gives NaN, as ``np.maximum`` does."""
    for c in range(gap.shape[0]):
        s = scene[c]
        if not (overlap[s] >= -gap[c] or overlap[s] != overlap[s]):
            overlap[s] = -gap[c]


@njit
def _creates_energy(idx, restitution, u_k, impulses, u_after, round_off):
    """Whether the solved problem of contacts ``idx`` gives the bodies energy: some contact
    impacts with restitution and the contacts' dissipation (:func:`nscd.impact_law.dissipation`)
    is below ``-round_off`` times its scale (9b)."""
    bouncing = False
    for c in idx:
        bouncing = bouncing or (restitution[c] > 0.0 and u_k[c, 0] < 0.0)
    if not bouncing:
        return False
    u_before = np.empty((idx.shape[0], u_k.shape[1]))
    for k in range(idx.shape[0]):  # element by element: no compiled shape-mismatch message
        for d in range(u_k.shape[1]):
            u_before[k, d] = u_k[idx[k], d]
    lost, scale = dissipation(impulses, u_before, u_after)
    return lost < -round_off * scale


@njit
def _reversed_slips(idx, u_k, impulses, u_after, noise):
    """Which contacts of the solved problem of contacts ``idx`` (k,) reverse a slip with a
    friction impulse that does positive work (9b), where the problem's contacts together do
    positive work beyond the solver's residue, ``sum P . (u_k + u_+) / 2 > noise sum |P| / 2``
    (velocities below ``noise``, m/s, are the solver's residue): the contacts whose tangential
    impulse and mean tangential velocity point the same way, ``P_t . (u_k,t + u_+,t) > noise |P_t|``,
    lasting or new: a contact in place from a run's start (no step before it) as an impact's
    (Newton's restitution and its bisection, :func:`_creates_energy`, take the normal work alone,
    and with ``e = 0`` the bisection has nothing to scale).

    A contact that slides and stops within the step while another impulse of the step (its
    own normal impulse through the coupling of ``W``, a neighbour's) pushes it the other
    way ends stuck with a friction impulse along its slip before the step: the impulse of
    the whole step, of which the part that stopped the slip did negative work, is applied
    at once, and ``P_t . u_k,t / 2 > 0``. Where other contacts of the problem dissipate
    more (a wall sliding on its base), the step creates no energy and nothing is reflected.
    """
    out = np.zeros(idx.shape[0], dtype=np.bool_)
    total = allowed = 0.0
    for k in range(idx.shape[0]):
        c = idx[k]
        size = 0.0
        for d in range(u_k.shape[1]):
            total += impulses[k, d] * (u_k[c, d] + u_after[k, d])
            size += impulses[k, d] * impulses[k, d]
        allowed += noise * math.sqrt(size)
    if total <= allowed:
        return out
    for k in range(idx.shape[0]):
        c = idx[k]
        work = size = 0.0
        for d in range(1, u_k.shape[1]):
            work += impulses[k, d] * (u_k[c, d] + u_after[k, d])
            size += impulses[k, d] * impulses[k, d]
        out[k] = work > noise * math.sqrt(size)
    return out


class _SubSteps:
    """The sub-step of S scenes (:func:`_advance`) as arrays over the scenes.

    A scene either stops at an event (``closing[s]``: the time from the start, ids of the
    contacts; its state stays the start's) or steps to its end state; its
    :class:`StepOutput` is built only when read (:meth:`output`, ``self[s]``).
    ``per_active`` (4, k, dim): the active contacts' impulses, relative velocities before
    and after, the driven bodies' part; ``reports`` per scene: None without an active
    contact, else ``(status, converged, iterations, merit)``.
    """

    def __init__(self, t, q, v, t_next, q_next, v_next, contacts, first, active, active_first, per_active, reports,
                 closing, penetration) -> None:
        self.closing = closing
        self.stepped = np.array([c is None for c in closing], dtype=bool)
        self.t = np.where(self.stepped, t_next, t)
        self.q = np.where(self.stepped[:, None, None], q_next, q)
        self.v = np.where(self.stepped[:, None, None], v_next, v)
        self.contacts, self.first, self.active, self.active_first = contacts, first, active, active_first
        self.per_active, self.reports, self.penetration = per_active, reports, penetration
        self.converged = np.array([r is None or r[1] for r in reports], dtype=bool)

    def __len__(self) -> int:
        return len(self.t)

    def __getitem__(self, s: int) -> _SubStep:
        return _SubStep(float(self.t[s]), self.q[s], self.v[s], self.output(s) if self.stepped[s] else None,
                        self.closing[s])

    def output(self, s: int) -> StepOutput:
        """What scene ``s`` (stepped) produced."""
        c, a = slice(self.first[s], self.first[s + 1]), slice(self.active_first[s], self.active_first[s + 1])
        n_active = a.stop - a.start
        status, converged, iterations, merit = (("no contact", True, 0, 0.0) if self.reports[s] is None
                                                else self.reports[s])
        report = StepReport(t=float(self.t[s]), n_contacts=int(c.stop - c.start), n_active=int(n_active),
                            status=status, converged=converged, iterations=iterations, merit=merit,
                            penetration=float(self.penetration[s]))
        own = self.contacts if len(self) == 1 else self.contacts.subset(c)
        per_active = self.per_active
        return StepOutput(report=report, contacts=own, active=self.active[a] - c.start, impulses=per_active[0, a],
                          u_before=per_active[1, a], u_after=per_active[2, a], solved_at=np.full(n_active, self.t[s]),
                          driven=per_active[3, a])

    def impulses(self, scenes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ids (k, 3) and impulses (k, dim) of the active contacts of ``scenes`` (stepped),
        end to end, and each scene's row bounds (S + 1,): their warm starts for the next step."""
        sizes = np.diff(self.active_first)[scenes]
        picked = _segments(self.active_first, scenes, sizes)
        return self.contacts.ids[self.active[picked]], self.per_active[0][picked], _bounds(sizes)


class StepOutputs:
    """What one step produced in each of S scenes (:func:`step`): ``converged`` and
    ``penetration`` as arrays over the scenes, and each scene's :class:`StepOutput`
    (``outputs[k]``) built when it is read.

    Attributes
    ----------
    converged : ndarray of bool, shape (S,)
        Whether each scene's contact problems were solved to tolerance.
    penetration : ndarray, shape (S,)
        Each scene's deepest overlap at the end of the step, m.
    """

    def __init__(self, n_scenes: int) -> None:
        self.converged = np.ones(n_scenes, dtype=bool)
        self.penetration = np.zeros(n_scenes)
        self._subs: _SubSteps | None = None
        self._index = np.full(n_scenes, -1)  # each scene's row in self._subs (-1: its output is kept)
        self._kept: dict[int, StepOutput | list[StepOutput]] = {}

    def __len__(self) -> int:
        return len(self.converged)

    def __getitem__(self, k: int) -> StepOutput:
        if self._index[k] >= 0:
            return self._subs.output(int(self._index[k]))
        if isinstance(self._kept[k], list):
            self._kept[k] = StepOutput.joined(self._kept[k])
        return self._kept[k]

    def take(self, scenes: np.ndarray, subs: _SubSteps, rows: np.ndarray) -> None:
        """Scenes ``scenes`` produced what rows ``rows`` of the sub-steps ``subs`` did."""
        self._subs, self._index[scenes] = subs, rows
        self.converged[scenes], self.penetration[scenes] = subs.converged[rows], subs.penetration[rows]

    def keep(self, k: int, parts: list[StepOutput]) -> None:
        """Scene ``k``'s step was the sub-steps that produced ``parts`` (joined when read,
        :meth:`StepOutput.joined`)."""
        self._kept[k] = parts
        self.converged[k] = all(part.report.converged for part in parts)
        self.penetration[k] = parts[-1].report.penetration


@njit_helper
def _first_impact_time(gap, u_start, u_free, dt, c0, c1, impacting, at_start):
    """Earliest time in (0, dt) at which an ``impacting`` contact of ``c0 <= c < c1`` (open,
    approaching faster than the impact speed) closes, its normal velocity varying linearly
    from ``u_start[c, 0]`` to ``u_free[c, 0]`` over the step (free flight); NaN if there is
    none worth a split.

    A closing within the first 1e-3 of the step is ignored (NaN), or, with ``at_start``
    (midpoint rule), returned as 0.0: the impact is then taken at the start of the step;
    ``at_start`` also localises a closing in the last 1e-3 of the step."""
    t_min = math.inf
    found = False
    for c in range(c0, c1):
        if not impacting[c]:
            continue
        found = True
        g, u0 = gap[c], u_start[c, 0]
        accel = (u_free[c, 0] - u0) / dt
        # g + u0 t + accel t^2 / 2 = 0, smallest positive root (u0 < 0, g > 0)
        disc = max(u0 * u0 - 2.0 * accel * g, 0.0)
        t_min = min(t_min, 2.0 * g / (-u0 + math.sqrt(disc)))
    if not found:
        return math.nan
    if t_min <= 1e-3 * dt:
        return 0.0 if at_start else math.nan
    return t_min if t_min < (1.0 if at_start else 1.0 - 1e-3) * dt else math.nan


@njit_helper
def _is_watched(ids, c, watch_ids, w0, w1):
    """Whether contact ``c`` (its id ``ids[c]``) is among the ids ``watch_ids[w0:w1]``."""
    for w in range(w0, w1):
        if ids[c, 0] == watch_ids[w, 0] and ids[c, 1] == watch_ids[w, 1] and ids[c, 2] == watch_ids[w, 2]:
            return True
    return False


@njit_helper
def _locate(gap_start, u_k, u_free, ids, first, dt, tolerance, localizing, impacting, now, watching, watch_ids,
            watch_first, midpoint):
    """Stage 7, event location: per scene that localises (``localizing``), the closing time
    (s from the start of its sub-step) of its first impact and the contacts that close there,
    or NaN: the scene steps on. Returns ``(closing_time (S,), closing (m,) bool, n_closing)``;
    ``impacting`` is updated in place where a watch narrows it.

    Theta scheme: the first closing in free flight of an ``impacting`` contact
    (:func:`_first_impact_time`). Midpoint rule: the same, and an impact ``now`` (closed at
    the start and approaching fast, or already penetrating: :func:`_screen`), which would be
    seen half a step late at ``q_M``, is taken at the start of the step (time 0). A scene
    correcting a localisation (``watching``: the ids being located, ``watch_ids[watch_first[s]:
    watch_first[s + 1]]``) looks at those contacts alone, approaching; midpoint rule: one closed
    to within 1 % of the gap tolerance is an impact now.
    """
    S = first.shape[0] - 1
    m = gap_start.shape[0]
    closing_time = np.full(S, np.nan)
    closing = np.zeros(m, dtype=np.bool_)
    candidates = np.zeros(m, dtype=np.bool_)
    n_closing = 0
    for s in range(S):
        c0, c1, w0, w1 = first[s], first[s + 1], watch_first[s], watch_first[s + 1]
        if not localizing[s] or c1 == c0:
            continue
        if not watching[s]:
            event = False
            for c in range(c0, c1):
                event = event or impacting[c] or now[c]
            if not event:
                continue
        elif midpoint:
            for c in range(c0, c1):
                impacting[c] = u_k[c, 0] < 0.0 and _is_watched(ids, c, watch_ids, w0, w1)
        taken_now = False
        if midpoint:
            for c in range(c0, c1):
                if watching[s]:
                    now[c] = impacting[c] and gap_start[c] <= 0.01 * tolerance[s]
                candidates[c] = impacting[c] and not now[c]
                taken_now = taken_now or now[c]
            time = _first_impact_time(gap_start, u_k, u_free, dt[s], c0, c1, candidates, midpoint)  # at the start
            if taken_now:
                time = 0.0
        else:
            time = _first_impact_time(gap_start, u_k, u_free, dt[s], c0, c1, impacting, midpoint)  # False
        if math.isnan(time):
            if watching[s] and not midpoint:
                for c in range(c0, c1):
                    impacting[c] = u_k[c, 0] < 0.0 and _is_watched(ids, c, watch_ids, w0, w1)
            continue
        closing_time[s] = time
        n_closing += 1
        for c in range(c0, c1):
            closing[c] = now[c] if taken_now else impacting[c]
    return closing_time, closing, n_closing


@njit_helper
def _stacked_bodies(body_a, body_b, scene, q, dim):
    """The bodies of S scenes stacked: each contact's bodies as ``scene * n + body`` (m,) each,
    and the centres of all bodies (S * n, dim), m, from the poses ``q`` (S, n, nq)."""
    S, n = q.shape[0], q.shape[1]
    m = body_a.shape[0]
    a = np.empty(m, dtype=np.int64)
    b = np.empty(m, dtype=np.int64)
    for c in range(m):
        a[c], b[c] = body_a[c] + scene[c] * n, body_b[c] + scene[c] * n
    centres = np.empty((S * n, dim))
    for s in range(S):
        for i in range(n):
            for d in range(dim):
                centres[s * n + i, d] = q[s, i, d]
    return a, b, centres


@njit
def _assemble(body_a, body_b, point, frame, gap, ids, restitution, friction, scene, first, previous, q_seen, v, v_next,
              v_free, early, dt, tolerance, pace, localizing, deferring, watching, watch_ids, watch_first, dof_of_body,
              n_dofs, mass_diagonal, inverse_blocks, impact_speed, gravity, dead_band, noise, limit, midpoint, theta,
              activation):
    """Stages 4 and 6-8 of S scenes in one compiled call: the Jacobian, the active set, event
    location and the small contact problems (``first`` (S + 1,): each scene's first contact;
    ``previous`` (m, dim): the warm starts, :func:`_previous_impulses`).

    4. Each contact's Jacobian blocks and relative velocities (:func:`nscd.contact.frames.contact_kinematics`) at the
       configuration ``q_seen`` (S, n, nq) where the contacts were seen, and the centripetal
       acceleration of its points (:func:`nscd.contact.frames.centripetal_acceleration`)
       with the start velocities ``v`` (S, n, nv) (``v_next``: the fixed and driven bodies'
       at ``t_{k+1}``; ``v_free`` (S, n_dofs): the dynamic bodies' free flight). Midpoint
       rule: the gaps of a scene seen at ``q_k`` (``early``) carried to ``q_M`` by
       ``h/2 u_k`` (first order), in place.
    6. The start gaps, impacting contacts and impacts now (:func:`_screen`).
    7. Event location (:func:`_locate`); watched contacts of an impact sub-step (``dt = 0``)
       of a step in pieces are ``hit``: active whatever their gap.
    8. The active set and offsets (:func:`_activate`); each scene's dense problem of at most
       ``limit`` unknowns (:func:`_dense_problem`) padded for
       :func:`nscd.solver.small.solve_dense`, warm-started from the step before.

    Returns ``blocks`` (m, 2, dim, nv); ``velocities`` (3, m, dim): ``u_k`` (all bodies at
    ``t_k``), ``w_next`` and ``w_k`` (the fixed and driven bodies' part at ``t_{k+1}`` and
    ``t_k``), m/s; the closing time per scene (S,) (NaN: it steps on), the closing contacts
    (m,) and their number of scenes; the active contacts (k,), each scene's first one
    ``active_first`` (S + 1,) and their offsets (k, dim); then the small problems: the scene
    of each (B,), its unknowns (B,), the padded ``W`` (B, n, n), ``q``, ``mu``, ``r0`` and
    its ``H`` (B, n, n_dofs) and ``M^-1 H^T`` (B, n_dofs, n).
    """
    S, n, nv = v.shape
    dim = point.shape[1]
    m = body_a.shape[0]
    # 4. the Jacobian: the bodies of all scenes stacked (scene * n + body)
    a, b, centres = _stacked_bodies(body_a, body_b, scene, q_seen, dim)
    sets = np.empty((4, S * n, nv))
    for s in range(S):
        for i in range(n):
            dof = dof_of_body[i]
            for j in range(nv):
                sets[0, s * n + i, j] = v[s, i, j]
                sets[1, s * n + i, j] = v_free[s, dof + j] if dof >= 0 else v_next[s, i, j]
                sets[2, s * n + i, j] = 0.0 if dof >= 0 else v_next[s, i, j]
                sets[3, s * n + i, j] = 0.0 if dof >= 0 else v[s, i, j]
    blocks, u = _contact_kinematics(a, b, point, frame, centres, sets)
    curvature = _centripetal(a, b, point, frame, centres, sets[0])
    u_k, u_free, w_next = u[0], u[1], u[2]
    for c in range(m):
        if early[scene[c]]:  # seen at q_k: the gap carried to q_M
            gap[c] = gap[c] + 0.5 * dt[scene[c]] * u_k[c, 0]
    # 6-7. start gaps, impacts, event location
    gap_start, impacting, now = _screen(gap, u_k, scene, dt, tolerance, impact_speed, gravity, previous, midpoint)
    closing_time, closing, n_closing = _locate(gap_start, u_k, u_free, ids, first, dt, tolerance, localizing,
                                               impacting, now, watching, watch_ids, watch_first, midpoint)
    stepping = np.empty(S, dtype=np.bool_)
    hit = np.zeros(m, dtype=np.bool_)
    for s in range(S):
        stepping[s] = math.isnan(closing_time[s])
        # an impact of a step in pieces (a body turning fast) takes the contacts it was located
        # for, approaching, whatever their gap: their located gaps err by the turning
        if dt[s] == 0.0 and watching[s]:
            for c in range(first[s], first[s + 1]):
                hit[c] = u_k[c, 0] < 0.0 and _is_watched(ids, c, watch_ids, watch_first[s], watch_first[s + 1])
    # 8. the active set, its offsets and the small problems
    active, offset = _activate(gap, u_k, u_free, w_next, curvature, restitution, friction, previous, scene, dt,
                               tolerance, pace, impacting, hit, localizing, deferring, stepping, dead_band, noise,
                               midpoint, theta, activation)
    active_first = np.zeros(S + 1, dtype=np.int64)
    for k in range(active.shape[0]):
        active_first[scene[active[k]] + 1] += 1
    for s in range(S):
        active_first[s + 1] += active_first[s]
    B, width = 0, dim
    for s in range(S):
        count = active_first[s + 1] - active_first[s]
        if count > 0 and count * dim <= limit:
            B += 1
            width = max(width, count * dim)
    which = np.empty(B, dtype=np.int64)
    sizes = np.empty(B, dtype=np.int64)
    W = np.zeros((B, width, width))
    q = np.zeros((B, width))
    mu = np.zeros((B, width // dim))
    r0 = np.zeros((B, width))
    H = np.zeros((B, width, n_dofs))
    MinvHT = np.zeros((B, n_dofs, width))
    p = 0
    for s in range(S):
        a0, a1 = active_first[s], active_first[s + 1]
        size = (a1 - a0) * dim
        if size == 0 or size > limit:
            continue
        idx = active[a0:a1]
        H_s, MinvHT_s, W_s, q_s = _dense_problem(blocks, idx, body_a, body_b, dof_of_body, n_dofs, mass_diagonal,
                                                 inverse_blocks[s], v_free[s], offset[a0:a1])
        which[p], sizes[p] = s, size
        # element by element: a slice assignment from an array compiles numba's shape-mismatch
        # message (string formatting), seconds of the first run's compilation
        for i in range(size):
            q[p, i] = q_s[i]
            for j in range(size):
                W[p, i, j] = W_s[i, j]
            for j in range(n_dofs):
                H[p, i, j] = H_s[i, j]
                MinvHT[p, j, i] = MinvHT_s[j, i]
        for k in range(a1 - a0):
            mu[p, k] = friction[idx[k]]
            for d in range(dim):
                r0[p, k * dim + d] = previous[idx[k], d]
        p += 1
    velocities = np.empty((3, m, dim))
    for c in range(m):
        for d in range(dim):
            velocities[0, c, d] = u_k[c, d]
            velocities[1, c, d] = w_next[c, d]
            velocities[2, c, d] = u[3, c, d]
    return (blocks, velocities, closing_time, closing, n_closing, active, active_first, offset, which, sizes, W, q, mu,
            r0, H, MinvHT)


@njit
def _previous_impulses(ids, scene, S, warm_ids, warm_impulses, warm_first):
    """Each scene's first contact (S + 1,) (``scene`` (m,): the scene of each contact, sorted)
    and the warm start of every contact (m, dim), N s: its impulse in the step before, by
    contact id within its own scene (:meth:`nscd.state.WarmStart.lookup`; ``warm_ids`` (w, 3),
    ``warm_impulses`` (w, dim), scene ``s``'s rows ``warm_first[s]:warm_first[s + 1]``), zero
    for a new contact."""
    dim = warm_impulses.shape[1]
    m = ids.shape[0]
    first = np.zeros(S + 1, dtype=np.int64)
    for c in range(m):
        first[scene[c] + 1] += 1
    for s in range(S):
        first[s + 1] += first[s]
    rows = _matched_rows(ids, first, warm_ids, warm_first)
    previous = np.zeros((m, dim))
    for c in range(m):
        if rows[c] >= 0:
            for d in range(dim):
                previous[c, d] = warm_impulses[rows[c], d]
    return first, previous


#: What :func:`_solution` says of a scene's contact problem: solved by the compiled fast path;
#: to be solved in Python (beyond the fast path, or not accepted by it); solved but
#: creating energy (a reversed slip to be reflected, its restitution to be scaled, 9b).
_SOLVED, _TO_SOLVE, _CREATES_ENERGY = 0, 1, 2


@njit
def _solution(H, MinvHT, r, sizes, which, info, active, active_first, v_free, velocities, restitution, round_off,
              noise):
    """Stage 9 after the compiled fast path: the impulses and relative velocities after (k, dim)
    of the active contacts of the small problems it accepted (its ``info`` (B, 5),
    :func:`nscd.solver.proximal.fast_path`: code not :data:`~nscd.solver.small.NOT_ACCEPTED`,
    iterations), and the dynamic bodies' velocities (S, n_dofs)
    (:func:`_velocities_after`; free flight elsewhere); and per scene with active contacts
    what is left to Python (S,): :data:`_TO_SOLVE` (beyond the fast path or not accepted),
    :data:`_CREATES_ENERGY` (accepted, but its contacts give the bodies energy,
    :func:`_creates_energy`, or a friction impulse reverses a slip, :func:`_reversed_slips`),
    else :data:`_SOLVED`; and how many scenes are left."""
    u_k, w_next = velocities[0], velocities[1]
    S = active_first.shape[0] - 1
    dim = w_next.shape[1]
    impulses = np.zeros((active.shape[0], dim))
    u_after = np.zeros((active.shape[0], dim))
    v_next = v_free.copy()
    left = np.zeros(S, dtype=np.int64)
    for s in range(S):
        if active_first[s + 1] > active_first[s]:
            left[s] = _TO_SOLVE
    for p in range(which.shape[0]):
        if info[p, 0] == NOT_ACCEPTED:
            continue
        s, size = which[p], sizes[p]
        a0, a1 = active_first[s], active_first[s + 1]
        v_s, u_s = _velocities_after(H[p, :size], MinvHT[p, :, :size], r[p, :size], v_free[s], w_next,
                                     active[a0:a1])
        for k in range(a1 - a0):
            for d in range(dim):
                impulses[a0 + k, d] = r[p, k * dim + d]
                u_after[a0 + k, d] = u_s[k, d]
        for j in range(v_s.shape[0]):
            v_next[s, j] = v_s[j]
        energy = (_creates_energy(active[a0:a1], restitution, u_k, impulses[a0:a1], u_after[a0:a1], round_off)
                  or _reversed_slips(active[a0:a1], u_k, impulses[a0:a1], u_after[a0:a1], noise).any())
        left[s] = _CREATES_ENERGY if energy else _SOLVED
    n_left = 0
    for s in range(S):
        n_left += left[s] != _SOLVED
    return impulses, u_after, v_next, left, n_left


@njit
def _finish(q, q_c, q_seen, v, q_next, v_next, v_dyn_next, body_a, body_b, point, frame, gap, scene, first, dt,
            early, active, impulses, u_after, velocities, dynamic_index, radius, threshold, midpoint, theta):
    """Stage 10 of S scenes in one compiled call: the end poses and velocities, the predicted
    end-of-step overlaps, and what a step hands on.

    End poses and velocities (S, n, nq), (S, n, nv): the dynamic bodies' from ``v_dyn_next``
    (S, n_dofs) and the scheme's position update, the others as prescribed (``q_next``,
    ``v_next``). Theta scheme ``q_k + h (theta v_{k+1} + (1 - theta) v_k)``; midpoint rule
    ``q_M + h/2 v_{k+1}`` (``q_c``: ``q_M``); quaternions by the exact exponential map.

    The deepest overlap (m) of each scene at the end of the sub-step, predicted for every
    detected contact (seen in ``q_seen``) from the relative velocities at the end
    (:func:`_end_gaps`, over the span ``h``, or ``h/2`` from ``q_M``), the scenes where it is
    to be detected in the end configuration (:func:`_predicted_overlaps`) and their number;
    and per active contact (4, k, dim) its impulse, relative velocities before ``u_k`` and
    after, and the driven bodies' part averaged over the sub-step ``(w_k + w_{k+1}) / 2``.
    """
    S, n, nv = v.shape
    dim = point.shape[1]
    v_end = v_next.copy()
    for s in range(S):
        for k in range(dynamic_index.shape[0]):
            for j in range(nv):
                v_end[s, dynamic_index[k], j] = v_dyn_next[s, k * nv + j]
    span = np.empty(S)
    for s in range(S):
        span[s] = 0.5 * dt[s] if midpoint and not early[s] else dt[s]
    if midpoint:
        moved = drift_poses(q_c, v_end, 0.5 * dt, dynamic_index)
    else:
        v_mid = v.copy()
        for s in range(S):
            for i in dynamic_index:
                for j in range(nv):
                    v_mid[s, i, j] = theta * v_end[s, i, j] + (1.0 - theta) * v[s, i, j]
        moved = drift_poses(q, v_mid, dt, dynamic_index)
    q_end = q_next.copy()
    for s in range(S):
        for i in dynamic_index:
            for j in range(q.shape[2]):  # element by element: no compiled shape-mismatch message
                q_end[s, i, j] = moved[s, i, j]
    a, b, centres = _stacked_bodies(body_a, body_b, scene, q_seen, dim)
    _, u = _contact_kinematics(a, b, point, frame, centres, v_end.reshape(1, S * n, nv))
    end_gap = _end_gaps(gap, velocities[0], u[0], scene, dt, midpoint, theta)
    overlap, check = _predicted_overlaps(end_gap, body_a, body_b, first, v, v_end, span, radius, early, threshold)
    n_check = 0
    for s in range(S):
        n_check += check[s]
    per_active = np.empty((4, active.shape[0], dim))
    for k in range(active.shape[0]):
        c = active[k]
        for d in range(dim):
            per_active[0, k, d] = impulses[k, d]
            per_active[1, k, d] = velocities[0, c, d]
            per_active[2, k, d] = u_after[k, d]
            per_active[3, k, d] = 0.5 * (velocities[2, c, d] + velocities[1, c, d])
    return q_end, v_end, overlap, check, n_check, per_active


def _advance(k: _Constants, data: Data, rows: np.ndarray, t: np.ndarray, q: np.ndarray, v: np.ndarray,
             warm: WarmStarts, requests: list[_Request] | None = None) -> _SubSteps:
    """One plain Moreau–Jean sub-step of each of S scenes, through the stages of the module docstring.

    The common case is a handful of compiled calls: free flight and sweeps, detection,
    stages 4 and 6-8 (:func:`_assemble`), the compiled fast path of the small problems (the
    Newton, then the proximal point: :func:`nscd.solver.core.newton_batch`), their velocities
    (:func:`_solution`) and stage 10 (:func:`_finish`). Python only steps in between for what a
    scene needs now and then: the motions of driven bodies, a scene seen early (midpoint rule),
    an impact located (the scene stops there), a problem the fast path does not take or does
    not accept, one
    whose restitution creates energy, and the fresh detection of an end-of-step overlap.

    Parameters
    ----------
    k : _Constants
        The model, settings, step and margin, and what they fix (:func:`_constants`).
    rows : ndarray of int, shape (S,)
        Rows of ``data`` (drives and coarse corrections of the scenes).
    t, q, v : ndarray, shapes (S,), (S, n_bodies, nq), (S, n_bodies, nv)
        States at the start of the sub-step.
    warm : WarmStarts
        Each scene's warm start.
    requests : list of _Request, optional
        Each scene's sub-step (length, tolerance, pace, localisation mode); None: every
        scene takes the plain sub-step of a whole step.
    """
    model, hooks = k.model, k.hooks
    dim = model.dim
    S = len(rows)
    plan = k.plain_rows(S) if requests is None else _Rows.of(requests, k.localize)
    if k.localize and not k.localize_large:
        plan = plan.unlocated(np.diff(warm.first) * dim > k.dense)
    dt = plan.dt
    # 1. prescribe
    t_next = t + dt
    q_next, v_next = q, v  # read only: the fixed bodies keep their pose, at rest
    if k.driven:
        q_next, v_next = q.copy(), v.copy()
        data.drives.write(rows, t_next, q_next, v_next)
    # 5. free flight, the sweeps of stage 3 and 2. configure (the dynamic bodies; the hook the driven ones)
    v_free, inverse_blocks, sweep, fastest, q_c = _free_flight(k, q, v, v_next, dt)
    hooks.configure(k, data, rows, t, q_c, v, dt)
    # 3. detect, with speculative contacts: every contact that can close within the step; a
    # scene whose bodies move fast against the thinnest one is seen where the step starts (hook)
    q_seen, early = hooks.seen_at(model, q, q_c, sweep, fastest)
    contacts, scene = detect_batch(model, q_seen, k.margin, sweep)
    # 4, 6-8. warm starts, Jacobian, active set, event location, the small problems
    first, previous = _previous_impulses(contacts.ids, scene, S, warm.ids, warm.impulses, warm.first)
    (blocks, velocities, closing_time, closing, n_closing, active, active_first, offset, which, sizes, W, q_free, mu,
     r0, H, MinvHT) = _assemble(
        contacts.body_a, contacts.body_b, contacts.point, contacts.frame, contacts.gap, contacts.ids,
        contacts.restitution, contacts.friction, scene, first, previous, q_seen, v, v_next, v_free, early, dt,
        plan.tolerance, plan.pace, plan.localizing, plan.deferring, plan.watching, plan.watch_ids, plan.watch_first,
        model.dof_of_body, model.n_dofs, k.mass_diagonal, inverse_blocks, k.impact_speed, model.gravity, k.dead_band,
        k.noise, k.fast, k.midpoint, k.theta, k.activation)
    # 9. solve: the small problems in one compiled call
    r, u, merit, info = core.newton_batch(W, q_free, mu, sizes, dim, k.settings.solver, r0)
    impulses, u_after, v_dyn_next, left, n_left = _solution(
        H, MinvHT, r, sizes, which, info, active, active_first, v_free, velocities, contacts.restitution,
        ENERGY_ROUND_OFF, k.noise)
    reports: list = [None] * S
    for s, (code, fast, _, inner, polish), value in zip(which.tolist(), info.tolist(), merit.tolist()):
        if code != NOT_ACCEPTED:
            # the Newton iterations, as CoreResult.iterations counts them (the proximal point's
            # outer iterations by their inner Newton's)
            reports[s] = (_POLISHED_STATUS if code == PROXIMAL_POLISHED else _CONVERGED_STATUS, True,
                          fast + inner + polish, value)
    if n_left:
        rejected = {s: core.compiled_result(r[p, :sizes[p]], u[p, :sizes[p]], float(merit[p]), info[p],
                                            k.settings.solver)
                    for p, s in enumerate(which.tolist()) if info[p, 0] == NOT_ACCEPTED}
        _solve_left(k, data, rows, left, rejected, contacts, blocks, previous, velocities, active, active_first,
                    offset, v_free, inverse_blocks, warm, impulses, u_after, v_dyn_next, reports)
    # 10. integrate, and the deepest overlap at the end of the sub-step: predicted for every
    # detected contact, detected afresh in the end configuration where the prediction may hide a deep one
    q_end, v_end, overlap, check, n_check, per_active = _finish(
        q, q_c, q_seen, v, q_next, v_next, v_dyn_next, contacts.body_a, contacts.body_b, contacts.point,
        contacts.frame, contacts.gap, scene, first, dt, early, active, impulses, u_after, velocities,
        model.dynamic_index, model.radius, k.overlap_check, k.midpoint, k.theta)
    penetration = _end_overlaps(model, q_end, overlap, check) if n_check else overlap
    closings: list = [None] * S
    if n_closing:
        for s in np.flatnonzero(~np.isnan(closing_time)).tolist():
            c = slice(first[s], first[s + 1])
            closings[s] = (float(closing_time[s]), contacts.ids[c][closing[c]])
    return _SubSteps(t, q, v, t_next, q_end, v_end, contacts, first, active, active_first, per_active, reports,
                     closings, penetration)


@njit
def _restitution_offsets(idx, restitution, u_k):
    """The restitution part of the offsets of contacts ``idx`` (k, dim), m/s: ``e u_k,n`` where
    the contact approaches (``np.minimum(u_k,n, 0)``: also NaN), zero otherwise and in the
    tangential rows; removed by ``(1 - lambda)`` when the restitution is scaled (9b), on the
    general and the compiled step alike."""
    out = np.zeros((idx.shape[0], u_k.shape[1]))
    for i in range(idx.shape[0]):
        u_n = u_k[idx[i], 0]
        out[i, 0] = restitution[idx[i]] * (u_n if u_n < 0.0 or u_n != u_n else 0.0)
    return out


#: The phases of :func:`_dissipative_next`: reflecting reversed slips, bisecting the restitution.
_REFLECTING, _BISECTING = 0.0, 1.0


@njit_helper
def _dissipative_plan() -> np.ndarray:
    """The state of :func:`_dissipative_next` before its first move: phase, reflection passes
    taken, and the state of :func:`nscd.impact_law.bisection_next`."""
    plan, start = np.zeros(5), bisection_start()
    plan[0] = _REFLECTING
    for i in range(start.shape[0]):
        plan[2 + i] = start[i]
    return plan


@njit
def _dissipative_next(plan, idx, u_k, w_next, restitution, body_a, body_b, n_bodies, offset, impulses,
                      u_after, noise, round_off):
    """9b of one scene's solved contact problem, one solve at a time, in place on ``plan``
    (:func:`_dissipative_plan`) and ``offset``: told the latest solution (``impulses``,
    ``u_after`` (k, dim) of contacts ``idx`` (k,)), returns the factor on the restitution of the
    next solve (:data:`nscd.impact_law.NO_TRIAL`: none) and whether the latest solution is kept (the
    one kept last is the step's). The one source of 9b for the compiled and the general step.

    First, at most :data:`REFLECTION_PASSES` times, a problem in which a friction impulse
    reverses a slip (:func:`_reversed_slips`) is solved again with Coulomb's law on the
    mean tangential velocity of every contact of each reversing joint (the pair of
    bodies: its points share the slip, and targets that differ between them no rigid motion
    meets), tangential offset ``u_k,t`` in ``offset`` (k, dim), the problem's rows of
    :func:`_activate`'s (the impulse then does the work ``-mu P_n |u_k,t + u_+,t| / 2 <=
    0``). Then a problem whose contacts would still give the bodies energy
    (:func:`_creates_energy`; Newton's restitution with friction) is solved again with its
    restitution scaled to the largest factor that dissipates, ``D >= 0`` as computed, by the
    bisection of :func:`nscd.impact_law.bisection_next`. ``n_bodies``: bodies of the model
    (a pair of bodies' key)."""
    if plan[0] == _REFLECTING:
        if plan[1] < REFLECTION_PASSES:
            reversed_slips = _reversed_slips(idx, u_k, impulses, u_after, noise)
            if reversed_slips.any():
                # the pairs of bodies (keys) with a reversing contact, sorted, then every contact
                # of those pairs: O(k log k) (a wall's problem has thousands of contacts)
                k = idx.shape[0]
                pairs = np.empty(k, dtype=np.int64)
                for j in range(k):
                    pairs[j] = body_a[idx[j]] * n_bodies + body_b[idx[j]]
                reversing = np.unique(pairs[reversed_slips])
                for j in range(k):
                    c = idx[j]
                    at = np.searchsorted(reversing, pairs[j])
                    if at < reversing.shape[0] and reversing[at] == pairs[j]:
                        for d in range(1, offset.shape[1]):
                            offset[j, d] = w_next[c, d] + u_k[c, d]
                plan[1] += 1.0
                return 1.0, True
        plan[0] = _BISECTING
        if not _creates_energy(idx, restitution, u_k, impulses, u_after, round_off):
            return NO_TRIAL, True
        lam, _ = bisection_next(plan[2:], False)
        return lam, True
    u_before = np.empty((idx.shape[0], u_k.shape[1]))
    for i in range(idx.shape[0]):
        for d in range(u_k.shape[1]):
            u_before[i, d] = u_k[idx[i], d]
    lost, _ = dissipation(impulses, u_before, u_after)
    # restitution_factor's test with no round-off allowed: D >= 0 as computed
    return bisection_next(plan[2:], lost >= 0.0)


def _solve_left(k: _Constants, data: Data, rows: np.ndarray, left: np.ndarray, rejected: dict, contacts: Contacts,
                blocks: np.ndarray, previous: np.ndarray, velocities: np.ndarray, active: np.ndarray,
                active_first: np.ndarray, offset: np.ndarray, v_free: np.ndarray, inverse_blocks: np.ndarray,
                warm: WarmStarts, impulses: np.ndarray, u_after: np.ndarray, v_dyn_next: np.ndarray,
                reports: list) -> None:
    """Stage 9 of the scenes the compiled Newton left (``left``, :func:`_solution`), in place:
    a problem beyond the fast path, or not accepted by its compiled Newton and proximal point
    (``rejected``: scene -> their best iterate, :func:`nscd.solver.core.compiled_result`), by
    the solver's other routes; then (9b) no contact does positive
    work: a problem in which a friction impulse reverses a slip (:func:`_reversed_slips`) is
    solved again with Coulomb's law on those contacts' mean tangential velocity (tangential
    offset ``u_k,t``, as :func:`_activate` does for a stuck pivot: the impulse then does
    the work ``-mu P_n |u_k,t + u_+,t| / 2 <= 0``), at most :data:`REFLECTION_PASSES` times
    as new reversals appear; and a problem whose contacts would still give the bodies energy
    (Newton's restitution with friction) is solved again with its restitution scaled down,
    to the largest factor that dissipates, D >= 0 as computed (:mod:`nscd.impact_law`)."""
    model, settings, hooks = k.model, k.settings, k.hooks
    dim = model.dim
    u_k, w_next = velocities[0], velocities[1]

    def bounce(idx: np.ndarray) -> np.ndarray:
        return _restitution_offsets(idx, contacts.restitution, u_k)

    def solve_small(lam: float, s: int, a: slice, idx: np.ndarray, rejected: core.CoreResult | None = None) -> tuple:
        """Scene ``s``'s small problem by :func:`nscd.solver.core.solve` (the compiled Newton
        and proximal point within ``fast_path_unknowns``, the conic fixed point if they do not
        accept it or beyond); ``rejected``: the best iterate of the compiled call that did not
        accept this very problem, which then goes straight to the conic fixed point."""
        H, MinvHT, W, q_free = _dense_problem(blocks, idx, contacts.body_a, contacts.body_b, model.dof_of_body,
                                              model.n_dofs, k.mass_diagonal, inverse_blocks[s], v_free[s], offset[a])
        start = previous[idx] if len(warm[s]) else None
        problem = (s, a, idx, H, MinvHT, W, q_free - (1.0 - lam) * bounce(idx).ravel(), contacts.friction[idx], start)
        if rejected is None:
            res = _solve_small(problem, dim, settings.solver)
        else:
            res = core.solve_rejected(W, problem[6], problem[7], dim, k.fast_off,
                                      None if start is None else start.ravel(), rejected)
        return _small_solution(res, problem, v_free, w_next)

    def solve_large(lam: float, s: int, a: slice, idx: np.ndarray) -> tuple:
        """Scene ``s``'s large problem by the Gauss–Seidel route (its coarse correction kept)."""
        H = assemble_jacobian(blocks[idx], contacts.body_a[idx], contacts.body_b[idx], model.dof_of_body,
                              model.n_dofs)
        mass = model.mass_diagonal if dim == 2 else _inverse_mass(inverse_blocks[s])
        extrapolate = len(idx) * dim > settings.solver.large_problem_unknowns
        start = (warm[s].lookup(contacts.ids[idx], extrapolate) if extrapolate or not hooks.midpoint
                 else previous[idx]) if len(warm[s]) else None
        sol = solve_velocity_unchecked(mass, v_free[s], H, (offset[a] - (1.0 - lam) * bounce(idx)).ravel(),
                                       contacts.friction[idx], dim, settings.solver, start, data.coarse[rows[s]])
        return (sol.P, (H @ sol.v + w_next[idx].ravel()).reshape(-1, dim), sol.v,
                (str(sol.status), bool(sol.converged), int(sol.iterations), float(sol.merit)))

    for s in np.flatnonzero(left).tolist():
        a = slice(active_first[s], active_first[s + 1])
        idx = active[a]
        solve = solve_large if len(idx) * dim > k.dense else solve_small
        if left[s] == _TO_SOLVE:
            impulses[a], u_after[a], v_dyn_next[s], reports[s] = (
                solve_large(1.0, s, a, idx) if solve is solve_large else solve_small(1.0, s, a, idx, rejected.get(s)))
        # 9b, one solve at a time (_dissipative_next): the solution kept last stands
        plan = _dissipative_plan()
        kept = solution = (impulses[a].copy(), u_after[a].copy(), v_dyn_next[s].copy(), reports[s])
        while True:
            lam, keep = _dissipative_next(plan, idx, u_k, w_next, contacts.restitution, contacts.body_a,
                                          contacts.body_b, len(model.mass), offset[a], solution[0], solution[1],
                                          k.noise, ENERGY_ROUND_OFF)
            if keep:
                kept = solution
            if lam == NO_TRIAL:
                break
            solution = solve(lam, s, a, idx)
        impulses[a], u_after[a], v_dyn_next[s], reports[s] = kept


def _small_solution(res, problem: tuple, v_free: np.ndarray, w_next: np.ndarray) -> tuple:
    """Impulses (m, dim), relative velocities after (m, dim), velocities of the dynamic bodies
    and the report tuple of a small problem of :func:`_advance` solved as ``res``."""
    s, a, idx, H, MinvHT = problem[:5]
    v_s, u_after = _velocities_after(H, MinvHT, res.r, v_free[s], w_next, idx)
    report = (str(res.status), res.accepted,
              int(res.iterations),
              float(res.merit))
    return res.r.reshape(-1, w_next.shape[1]), u_after, v_s, report


@njit
def _velocities_after(H, MinvHT, r, v_free, w_next, idx):
    """Stage 9 of a small problem: the dynamic bodies' velocities ``v = v_free + M^-1 H^T r``
    (n_dofs,) and the contacts' relative velocities after, ``u = H v + w_next`` (k, dim)."""
    n_dofs, rows = MinvHT.shape
    dim = w_next.shape[1]
    v = np.empty(n_dofs)
    for j in range(n_dofs):
        total = 0.0
        for i in range(rows):
            total += MinvHT[j, i] * r[i]
        v[j] = v_free[j] + total
    u = np.empty((rows // dim, dim))
    for i in range(rows):
        total = 0.0
        for j in range(n_dofs):
            total += H[i, j] * v[j]
        u[i // dim, i % dim] = total + w_next[idx[i // dim], i % dim]
    return v, u


def _solve_small(problem: tuple, dim: int, settings: SolverSettings):
    """Solve the dense problem ``(.., W, q, mu, warm start)`` of :func:`_advance` with
    :func:`nscd.solver.core.solve` (the compiled Newton, then the conic fixed point if it does
    not accept it; a cold start is not a zero warm start there)."""
    *_, W, q, mu, start = problem
    return core.solve(W, q, mu, dim, settings, None if start is None else start.ravel())


# --------------------------------------------------------------------------- event location: the whole step


def _plain_request(k: "_Constants") -> _Request:
    """The first sub-step of every step: the whole step, stopping at a predicted impact
    (the plan's first request, :func:`nscd.event_plan.plan_request`)."""
    return _Request(k.dt, float(gap_tolerance(k.fixed_tolerance, k.model.gravity, k.model.smallest_radius, k.dt)),
                    float(pace(k.dt, k.midpoint, k.theta)), True)


class _Plan:
    """The sub-steps of one scene within one step (the event-location stage): the plan of
    :mod:`nscd.event_plan` (its array, advanced by its functions, which the compiled steps
    of a small scene call too), the scene's state, the latest impulses and the outputs of
    the sub-steps taken.

    A step starts as a plain step that stops at a predicted impact; then the approach, the
    impact and the rest of the step (see :mod:`nscd.event_plan`); a step in which a body
    turns fast is taken in pieces. Each call of :meth:`request` names the next sub-step,
    :meth:`warm_start` its warm start, :meth:`receive` takes its outcome.
    """

    def __init__(self, k: "_Constants", t: float, q: np.ndarray, v: np.ndarray, warm: WarmStart) -> None:
        self.k = k
        self.t, self.q, self.v = t, q, v
        # the latest impulses of the contacts: the step before's, then each sub-step's of
        # finite length (an impact's percussions are not kept); the plan holds their span
        self.warm = warm
        self.outputs: list[StepOutput] = []
        self.lasting: list[StepOutput] = []  # the outputs of the sub-steps of finite length (not impacts)
        self.closing_ids: np.ndarray | None = None  # the contacts of the impact located
        self.plan = np.empty(FIELDS)
        self.factor = 1.0  # on the latest impulses, for the warm start of the sub-step requested
        plan_start(self.plan, k.dt, largest_spin(v[None])[0])

    @property
    def done(self) -> bool:
        return self.plan[PHASE] == FINISHED

    def request(self) -> _Request:
        """The next sub-step; its warm start is :meth:`warm_start`."""
        k = self.k
        dt, tolerance, pace_, localize, defer, watch, self.factor = plan_request(
            self.plan, k.fixed_tolerance, k.model.gravity, k.model.smallest_radius, k.midpoint, k.theta)
        return _Request(float(dt), float(tolerance), float(pace_), bool(localize), bool(defer),
                        self.closing_ids if watch else None)

    def warm_start(self) -> WarmStart:
        """The warm start of the sub-step just requested: the latest impulses scaled to its
        length (the factor :func:`nscd.event_plan.plan_request` gives)."""
        return self.warm.scaled(self.factor) if len(self.warm) else self.warm

    def receive(self, sub: _SubStep) -> None:
        """The outcome of the sub-step just requested."""
        if sub.closing is not None:  # plain, correct or rest: an impact to locate
            self.closing_ids = sub.closing[1]
            plan_receive(self.plan, sub.closing[0], 0.0, 0, self.k.midpoint)
            return
        self.t, self.q, self.v = sub.t, sub.q, sub.v
        self.outputs.append(sub.output)
        if self.plan[LENGTH] > 0.0:
            self.lasting.append(sub.output)
        latest = warm_start_of(sub.output)
        # the spin at the end sizes the next piece, if any is left
        spin = largest_spin(sub.v[None])[0] if self.plan[LEFT] > 0.0 else 0.0
        if plan_receive(self.plan, np.nan, spin, len(latest), self.k.midpoint):
            self.warm = latest

    def step_impulses(self, previous: WarmStart) -> WarmStart:
        """The warm start of the next step: each contact's impulse summed over the sub-steps
        of this one (the whole step's, as an unsplit step gives; its last sub-step's alone
        was a fraction of it; :func:`nscd.state.summed_impulses`), with its trend since
        ``previous``.

        A scene whose problems go to the Gauss–Seidel sweeps (more than ``large_problem_unknowns``
        and ``fast_path_unknowns``) sums its sub-steps of finite length only: an impact's
        percussions do not come back in the next step, and with them the warm start and its
        trend carried twice a percussion that the next step does not have (97-block wall breaking
        up, theta scheme: the first sweep after an impact step at relative merit 1.3e-1, 5.8e-2
        without them; ``docs/solver.md``, sixth round). Small problems keep the sum: their
        compiled Newton converges from either, but the impulses of a joint's corners are not
        unique, and the warm start picks the distribution (a stacked pair's LNEC onset,
        ``tests/test_lnec_multiblock.py``, moved with it)."""
        dim = self.k.model.dim
        swept = any(len(part.active) * dim > self.k.dense for part in self.lasting)
        parts = self.lasting if swept else self.outputs
        # the active contacts' ids and impulses of the parts end to end (as StepOutput.joined
        # lays them out), without joining their other arrays
        ids, total = summed_impulses(
            np.ascontiguousarray(np.concatenate([part.contacts.ids[part.active] for part in parts]), dtype=np.int64),
            np.ascontiguousarray(np.concatenate([part.impulses for part in parts]), dtype=float))
        return WarmStart.of(previous, dim).followed_by(ids, total) if previous else WarmStart(ids, total)


def step(model: Model, data: Data, dt: float, settings: Settings, margin: float,
         rows: np.ndarray | None = None) -> "StepOutputs":
    """Advance scenes ``rows`` of ``data`` (default: all) by one step of ``dt`` seconds, in place.

    Each scene's step is split at its own impacts (see :class:`_Plan`); the sub-steps of
    all scenes go through the stages together. ``data.t``, ``q``, ``v`` and ``warm``
    of the rows are updated.

    Returns
    -------
    StepOutputs
        What each row's step produced, in order (``outputs[k]``: a :class:`StepOutput`).
    """
    k = _constants(model, settings, dt, margin)
    rows = np.arange(len(data)) if rows is None else np.asarray(rows)
    # every scene of the data, in order: its arrays are read and written whole, not row by row
    every = len(rows) == len(data) and rows.tolist() == list(range(len(data)))
    v = data.v if every else data.v[rows]
    # Every scene's step starts as a plain step; a scene whose plain step stops at an impact
    # goes on under a _Plan (approach, impact, rest), and so from the start does a scene in
    # which a body turns fast (the step taken in pieces).
    outputs = StepOutputs(len(rows))
    plans: dict = {}
    spin = largest_spin(v)
    if max(spin.tolist(), default=0.0) * dt > TURN_PER_PIECE:
        turning = spin * dt > TURN_PER_PIECE
        for i in np.flatnonzero(turning).tolist():
            r = int(rows[i])
            plans[i] = _Plan(k, float(data.t[r]), data.q[r].copy(), data.v[r].copy(), data.warm[r])
        plain = np.flatnonzero(~turning)
        v = v[plain]
        every = False
    else:
        plain = np.arange(len(rows))
    at = rows[plain]
    updates = []  # (rows, their warm starts for the next step)
    whole = False  # every scene of the data took its whole step in one plain sub-step
    if len(plain):
        warm = data.warm if every else data.warm.rows(at)
        subs = _advance(k, data, at, data.t if every else data.t[at], data.q if every else data.q[at], v, warm)
        if subs.stepped.all():
            done, finished = (plain if len(plain) == len(rows) else np.arange(len(at))), at
            if every:
                data.t[:], data.q[:], data.v[:] = subs.t, subs.q, subs.v
            else:
                data.t[at], data.q[at], data.v[at] = subs.t, subs.q, subs.v
            whole = every
        else:
            done = np.flatnonzero(subs.stepped)
            finished = at[done]
            if len(done):  # not every scene stopped at an impact
                warm = warm.rows(done)
                data.t[finished], data.q[finished], data.v[finished] = subs.t[done], subs.q[done], subs.v[done]
        if len(done):  # some scene took its whole step
            updates.append((finished, warm.followed_by(*subs.impulses(done))))
            outputs.take(plain[done], subs, done)
        for s in np.flatnonzero(~subs.stepped).tolist():
            i, r = int(plain[s]), int(at[s])
            plans[i] = _Plan(k, float(data.t[r]), data.q[r].copy(), data.v[r].copy(), data.warm[r])
            plans[i].receive(subs[s])
    pending = list(plans)
    while pending:
        requests = [plans[i].request() for i in pending]
        subs = _advance(k, data, rows[pending], np.array([plans[i].t for i in pending]),
                        np.array([plans[i].q for i in pending]), np.array([plans[i].v for i in pending]),
                        WarmStarts.stack([plans[i].warm_start() for i in pending], model.dim), requests)
        for i, sub in zip(pending, subs):
            plans[i].receive(sub)
        pending = [i for i in pending if not plans[i].done]
    if plans:
        planned = rows[list(plans)]
        for i, plan in plans.items():
            r = int(rows[i])
            outputs.keep(i, plan.outputs)
            data.t[r], data.q[r], data.v[r] = plan.t, plan.q, plan.v
        updates.append((planned, WarmStarts.stack([plan.step_impulses(data.warm[int(r)])
                                                   for plan, r in zip(plans.values(), planned)], model.dim)))
    if whole:
        data.warm = updates[0][1]
        return outputs
    for scenes, warm in updates:
        data.warm = data.warm.updated(scenes, warm)
    return outputs


# --------------------------------------------------------------------------- running


#: The rows of a single run.
_ONE_ROW = np.zeros(1, dtype=np.int64)


#: Steps :func:`simulate` takes between two looks at the checkpoint's clock (and Ctrl-C).
_CHUNK = 256



class _Paths:
    """Which path a run's next call of :meth:`Run._steps` (a single run's: :meth:`Run._single_steps`)
    takes: the compiled steps (the scenes handed back by the general step) or a lock step of
    every scene by the general step.

    A compiled step of a scene costs no less than its share of the stages of a lock step of
    many scenes, which run over all of them at once (and allocate their arrays once for all),
    and a step handed back costs a whole general step (its Python, about a millisecond,
    whatever the number of scenes) beside the compiled call. So a batch takes the compiled
    steps while it has at most ``_COMPILED_SCENES`` running scenes per thread (beyond, a lock
    step costs less than the Python it saves), and after a compiled call in which some scene
    needed the general step it takes the next ``backoff`` calls as lock steps (1, 2, 4, ...
    up to ``_LONGEST_BACKOFF`` after each such call, back to 1 after a call in which none
    did): while impacts keep some scene of the batch in the general step at nearly every
    step, lock steps are cheaper. A single run takes the compiled steps, and backs off the
    same way only once its calls hand back their first step twice in a row: a scene whose
    every step needs the general step (contact problems beyond the compiled fast path, as a
    wall of a few dozen blocks has), whose compiled calls would each be detection and
    assembly thrown away; an isolated step handed back (an impact the compiled step does not
    locate, a problem for the solver's other routes) costs no general step more. The path
    changes no result: every scene's steps are those of its single run on either
    (``tests/test_compiled_step.py``)."""

    def __init__(self, single: bool, threads: int) -> None:
        self.single, self.threads = single, threads
        self.backoff, self.general_for = 1, 0
        self.handed = False  # whether the last compiled call handed a step back

    def compiled_next(self, scenes: int) -> bool:
        """Whether the next call, of ``scenes`` running scenes, takes the compiled steps."""
        if self.general_for:
            self.general_for -= 1
            return False
        return self.single or scenes <= _COMPILED_SCENES * self.threads

    def handed_back(self, any_scene: bool) -> None:
        """After a compiled call: whether some scene needed the general step (a single run's:
        at the call's first step)."""
        again, self.handed = self.handed and any_scene, any_scene
        if any_scene and (again or not self.single):
            self.general_for, self.backoff = self.backoff, min(2 * self.backoff, _LONGEST_BACKOFF)
        elif not any_scene:
            self.backoff = 1


#: Running scenes per thread up to which a batch takes the compiled steps, and the longest run of
#: lock steps after a compiled call in which some scene needed the general step (:class:`_Paths`).
_COMPILED_SCENES, _LONGEST_BACKOFF = 64, 64


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
                 names: list[str], events=None, threads: int = 1) -> None:
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
        self._last: tuple = (np.zeros(0, dtype=int), StepOutputs(0))  # the rows of the last general step, outputs
        speed = _impact_speed(settings, model, self.dt)
        self.builders = ([ResultBuilder(model, self.data.state(k), store_impulses, impact_speed=speed)
                          for k in range(len(scenes))] if record else None)
        self.wall = 0.0
        self.events = Events(events, self.data)
        # scenes of a few bodies take their plain steps in compiled code
        self._compiled = None
        self.last_compiled = np.zeros(len(scenes), dtype=bool)  # whether a scene's last step was a compiled one
        self._paths = _Paths(len(scenes) == 1, threads)  # a batch's choice of compiled or lock steps
        if not store_impulses:
            from nscd.compiled_step import GENERAL, OVERLAP, CompiledSteps  # it composes this module's kernels
            self._GENERAL, self._OVERLAP = GENERAL, OVERLAP
            self._compiled = CompiledSteps.of(_constants(model, settings, self.dt, self.margin), len(scenes),
                                              self.builders, threads)

    def step(self, stacklevel: int) -> np.ndarray:
        """Advance every running scene by one step; returns the rows stepped."""
        if self._paths.single:
            if not self.running[0]:
                return _ONE_ROW[:0]
            self._single_steps(1, stacklevel + 1)
            return _ONE_ROW
        rows = np.flatnonzero(self.running)
        self._steps(rows, 1, stacklevel + 1)
        if self._compiled is not None:
            self._compiled.sync(self.data)
        return rows

    def step_single(self, stacklevel: int) -> StepReport | None:
        """One step of a single run's scene (:meth:`Simulator.step`); returns its report, or None
        once a terminal event has stopped the run."""
        if not self.running[0]:
            return None
        self._single_steps(1, stacklevel + 1)
        if self.last_compiled[0]:
            builder = self.builders[0]
            return builder.report(builder.count - 1)
        return self.output(0).report

    def advance(self, n_steps: int, stacklevel: int) -> int:
        """Up to ``n_steps`` steps of every running scene (fewer in a scene a terminal event
        stops); returns the most steps a scene took (:meth:`advance_scenes`)."""
        remaining = np.where(self.running, n_steps, 0)
        self.advance_scenes(remaining, stacklevel + 1)
        return int(n_steps - remaining.min(initial=n_steps))

    def advance_scenes(self, remaining: np.ndarray, stacklevel: int,
                       ended: Callable[[np.ndarray], Any] | None = None) -> None:
        """Step each running scene ``b`` ``remaining[b]`` times (B,), counted down in place,
        or until a terminal event stops it; ``ended(rows)`` is called with the scenes that end
        (stopped or done) as they end. Without events the scenes take their steps in compiled
        calls of many steps (each step as :meth:`step` takes it, the scenes out of lock step);
        with events, one step of every scene at a time (the events are evaluated after each)."""
        while True:
            rows = np.flatnonzero((remaining > 0) & self.running)
            if not len(rows):
                break
            if self._paths.single:
                remaining[0] -= self._single_steps(1 if self.events else int(remaining[0]), stacklevel + 1)
            else:
                remaining[rows] -= self._steps(rows, 1 if self.events else remaining[rows], stacklevel + 1)
            if ended is not None:
                done = rows[~self.running[rows] | (remaining[rows] <= 0)]
                if len(done):
                    ended(done)
        if self._compiled is not None:
            self._compiled.sync(self.data)

    def _single_steps(self, n_steps: int, stacklevel: int) -> int:
        """:meth:`_steps` of a single run's one scene (running), with scalars: up to ``n_steps``
        compiled steps, the next by :func:`step` if the compiled call handed it back (or one step by
        :func:`step` while :class:`_Paths` backs off)."""
        events = bool(self.events)  # evaluated after the step, if any
        t_before = self.data.t.copy() if events else None
        taken, general = 0, True
        if self._compiled is not None and self._paths.compiled_next(1):
            start = _time.perf_counter()
            taken, code = self._compiled.run_one(self.data, n_steps)
            self.wall += _time.perf_counter() - start
            self._paths.handed_back(not taken)
            general = code == self._GENERAL and taken < n_steps
            if taken:
                self.last_compiled[0] = self.converged[0] = True
                if code == self._OVERLAP:
                    self._warn_overlap(0, *self._compiled.penetration(0), stacklevel + 1)
        if general:
            self._general_step(_ONE_ROW, stacklevel + 1)
            taken += 1
        if events:
            self.running[self.events.locate(self.data, _ONE_ROW, t_before)] = False
        return taken

    def _steps(self, rows: np.ndarray, n_steps, stacklevel: int) -> np.ndarray:
        """Up to ``n_steps`` (S,) steps of scenes ``rows`` (S,), at least one each; then the
        events of the scenes stepped. Returns the steps each took.

        The plain steps are compiled (:mod:`nscd.compiled_step`): each scene steps until its
        next step needs the general step, which :func:`step` then takes for all such scenes
        together. A batch may instead take a lock step of every scene by :func:`step`, whose
        Python is shared by all and whose stages run over all the scenes at once
        (:class:`_Paths` says when). Single runs take the compiled steps."""
        if not len(rows):
            return np.zeros(0, dtype=np.int64)
        t_before = self.data.t[rows].copy() if self.events else None
        if self._compiled is not None and self._paths.compiled_next(len(rows)):
            taken, codes = self._compiled_steps(rows, n_steps, stacklevel + 1)
            general = rows[:0]
            if self._GENERAL in codes:  # a scene handed back before it took all its steps takes the general step now
                general = rows[(codes == self._GENERAL) & (taken < n_steps)]
            self._paths.handed_back(len(general) > 0)
        else:
            taken, general = np.zeros(len(rows), dtype=np.int64), rows
        if len(general):
            self._general_step(general, stacklevel + 1)
            taken[np.isin(rows, general)] += 1
        if self.events:
            self.running[self.events.locate(self.data, rows, t_before)] = False
        return taken

    def _compiled_steps(self, rows: np.ndarray, n_steps, stacklevel: int) -> tuple[np.ndarray, np.ndarray]:
        """Up to ``n_steps`` (S,) compiled steps of scenes ``rows`` (:mod:`nscd.compiled_step`);
        returns each one's steps taken and code."""
        start = _time.perf_counter()
        taken, codes = self._compiled.run(self.data, rows, n_steps)
        self.wall += _time.perf_counter() - start
        stepped = taken > 0
        self.last_compiled[rows] |= stepped
        self.converged[rows] |= stepped
        if self._OVERLAP in codes:
            for r in rows[stepped & (codes == self._OVERLAP)].tolist():
                self._warn_overlap(r, *self._compiled.penetration(r), stacklevel + 1)
        return taken, codes

    def _warn_overlap(self, r: int, t: float, penetration: float, stacklevel: int) -> None:
        warnings.warn(f"{self.names[r]}bodies overlap by {penetration:.3g} m at t = "
                      f"{t:.6g} s, more than {self.penetration_tolerance:.3g} m "
                      "(PENETRATION_TOLERANCE of the smallest body's radius); see "
                      "result.report.penetration", RuntimeWarning, stacklevel=stacklevel + 1)

    def _general_step(self, rows: np.ndarray, stacklevel: int) -> None:
        """One step of scenes ``rows`` by :func:`step` (every case), recorded."""
        self.last_compiled[rows] = False
        start = _time.perf_counter()
        if self._compiled is not None:
            self._compiled.sync(self.data, rows)
        outputs = step(self.model, self.data, self.dt, self.settings, self.margin, rows)
        self.wall += _time.perf_counter() - start
        self._last = (rows, outputs)
        if self.builders is not None:
            for k, r in enumerate(rows.tolist()):
                self.builders[r].add(float(self.data.t[r]), self.data.q[r], self.data.v[r], outputs[k])
        if self._compiled is not None:
            # after the recording: the contacts active before the step (ResultBuilder.add's
            # impacts) may be views of the buffers this rewrites
            self._compiled.taken_back(self.data, rows)
        self.converged[rows] = outputs.converged
        for k in np.flatnonzero(outputs.penetration > self.penetration_tolerance).tolist():
            report = outputs[k].report
            self._warn_overlap(int(rows[k]), report.t, report.penetration, stacklevel + 1)
        failed = np.flatnonzero(~outputs.converged)
        self.unconverged[rows[failed]] += 1
        for k in failed.tolist():
            report = outputs[k].report
            message = (f"{self.names[rows[k]]}contact solver did not converge at t = {report.t:.6g} s "
                       f"({report.status}, merit {report.merit:.3g})")
            if self.settings.on_failure == "raise":
                raise SolverFailure(message)
            warnings.warn(message, RuntimeWarning, stacklevel=stacklevel + 1)

    def output(self, r: int) -> StepOutput | None:
        """What the last step produced in scene ``r`` (None if it was not stepped in it)."""
        if self.last_compiled[r]:
            return self._compiled.output(r)
        rows, outputs = self._last
        k = int(np.searchsorted(rows, r))
        return outputs[k] if k < len(rows) and rows[k] == r else None

    def results(self, status: str, message: str, wall_share: float) -> list[Result]:
        out = []
        for k, builder in enumerate(self.builders):
            own_status, own_message = status, message
            if self.events.stopped_by[k] is not None and status == "finished":
                i, t_event = self.events.stopped_by[k]
                own_status, own_message = "event", f"stopped by terminal event {i} at t = {t_event:.6g} s"
            result = builder.build(status=own_status, message=own_message, wall_time=self.wall * wall_share,
                                   dt=self.dt, settings=self.settings)
            out.append(replace(result, t_events=[np.array(times) for times in self.events.t_events[k]]))
        return out


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
        return self._run.output(0)

    @property
    def stopped(self) -> bool:
        """Whether a terminal event has stopped the run (:meth:`step` then does nothing)."""
        return self._run.events.stopped_by[0] is not None

    def step(self) -> StepReport | None:
        """Advance one step; return its report (warns or raises if it did not converge).

        After a terminal event (:attr:`stopped`) nothing is stepped and None is returned."""
        return self._run.step_single(stacklevel=2)

    def run(self, until: float, callback: Callable[[State], Any] | None = None) -> None:
        """Step until time ``until`` (s); ``callback(state)`` after each step may return True to stop."""
        if not math.isfinite(real_number("until", until)):
            raise ValueError(f"until == {until}, must be a finite time in s.")
        n_steps = int(round((until - float(self.data.t[0])) / self.dt))
        if callback is None:
            self._run.advance(max(n_steps, 0), stacklevel=2)
            return
        for _ in range(max(n_steps, 0)):
            self.step()
            if self.stopped or callback(self.state):
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
        ``terminal`` is True stops the run at the end of that step. One whose attribute
        ``vectorized`` is True is a function of a :class:`~nscd.state.States` (one row
        here, all the scenes of a step in a batch) returning one value per row
        (:mod:`nscd.events`). :class:`~nscd.events.overturning` is the ready event of a
        body that overturns. The times are in ``Result.t_events`` (one array per event).

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
        taken = 0
        while taken < n_steps and not sim.stopped:
            # chunks of steps (compiled calls of many steps where it can): Ctrl-C and the
            # checkpoint are seen between them
            taken += sim._run.advance(min(_CHUNK, n_steps - taken), stacklevel=2)
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
