"""Batched sweep mode: many scenes of one structure advanced in lock step.

The cells of a map or the frequencies of a spectrum are independent scenes that
share one structure -- the same bodies, shapes, masses, contact laws, in the same
order -- and differ only in the motions of their driven bodies and in their initial
states. :class:`BatchSimulator` advances B such scenes together: each step runs the
stages of :func:`nscd.stepper.moreau_jean_step` once on arrays with a leading scene
axis (prescribed poses, detection, frames and Jacobian, free velocity, active set,
impact localisation), so the Python overhead of a step is paid once for all scenes.

Same arithmetic per scene
-------------------------
Every per-scene quantity is computed by the same floating-point operations, in the
same order, as the single-scene step: the detection's narrow phase is
:func:`nscd.contact.detect2d.collide_polygons_batch`, the frames, Jacobian blocks,
offsets and centripetal term come from the very functions of
:mod:`nscd.contact.frames` applied to all scenes' contacts at once, the small dense
products ``H v``, ``H M^-1 H^T`` are one stacked BLAS call per group of scenes with
the same number of (active) contacts -- the same BLAS kernel on the same shapes as a
scene alone, whereas zero padding would change the rounding -- and each contact
problem goes to the solver unchanged (:func:`nscd.solver.core.solve_batch`, bitwise
equal to :func:`nscd.solver.core.solve`). Each scene therefore follows the trajectory of
:class:`nscd.Simulator` bit for bit (``tests/test_batch.py`` checks it), and splits its
own steps at its own impacts. The stepper's scalar helpers (gap tolerance, first
closing time) are called per scene where they apply.

Cost: on the three-block stack of the double-pulse rig, about 80 us of CPU per scene
and step in batches of 200 scenes (one by one: about 500 us).

2D only: a 3D scene raises ``NotImplementedError``.
"""
from __future__ import annotations

import time as _time
import warnings
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nscd.contact.detect import _pose_polygons
from nscd.contact.detect2d import collide_polygons_batch
from nscd.contact.frames import Contacts, centripetal_normal, jacobian, tangent_frames
from nscd.model import Model
from nscd.result import Result, ResultBuilder, SolverFailure, StepReport
from nscd.scene import Scene
from nscd.solver import SolverSettings, Status, core
from nscd.state import State
from nscd.stepper import (GAP_DEAD_BAND, Settings, StepOutput, _auto_margin, _check_time, _first_impact_time,
                          _gap_tolerance, _impact_speed, check_overlaps, initial_state)

__all__ = ["BatchSimulator", "check_same_structure", "simulate_batch"]

_CONVERGED = (Status.CONVERGED, Status.POLISHED)


# --------------------------------------------------------------------------- structure


def _body_fields(body) -> dict:
    """What must agree between scenes for one body (its motion and initial state may differ)."""
    return {"name": body.name, "kind": body.kind.value, "vertices": np.asarray(body.shape.vertices),
            "mass": body.mass, "inertia": np.asarray(body.inertia, dtype=float), "material": body.material,
            "direction": None if body.direction is None else np.asarray(body.direction)}


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return a is not None and b is not None and np.shape(a) == np.shape(b) and bool(np.array_equal(a, b))
    return a == b


def check_same_structure(scenes: Sequence[Scene]) -> list[Model]:
    """Compile ``scenes`` and check that they share one structure.

    Scenes share a structure when they have the same dimension and gravity, the same
    bodies in the same order (name, kind, shape vertices, mass, inertia, material,
    direction of motion) and the same contact law for every pair of bodies. Motions
    of driven bodies and initial positions and velocities may differ.

    Returns
    -------
    list of Model
        One per scene, in order.

    Raises
    ------
    ValueError
        Naming the first scene and the first field that differs from ``scenes[0]``,
        or if ``scenes`` is empty.
    NotImplementedError
        For 3D scenes.
    """
    scenes = list(scenes)
    if not scenes:
        raise ValueError("scenes is empty, must hold at least one Scene.")
    for k, scene in enumerate(scenes):
        if not isinstance(scene, Scene):
            raise TypeError(f"scenes[{k}] is a {type(scene).__name__}, must be a Scene.")
    if scenes[0].dim != 2:
        raise NotImplementedError(f"dim == {scenes[0].dim}: the batch mode handles 2D scenes only.")
    models = [Model.from_scene(scene) for scene in scenes]
    ref = models[0]
    ref_bodies = [_body_fields(b) for b in ref.bodies]
    n = len(ref.bodies)
    pairs = [(i, j) for i in range(n) for j in range(i + 1, n) if ref.dynamic[i] or ref.dynamic[j]]
    ref_laws = [ref.contact_law(i, j) for i, j in pairs]
    for k, model in enumerate(models[1:], start=1):
        where = f"scenes[{k}] differs from scenes[0]:"
        for name in ("dim", "gravity"):
            if getattr(model.scene, name) != getattr(ref.scene, name):
                raise ValueError(f"{where} {name} == {getattr(model.scene, name)!r}, "
                                 f"scenes[0] has {getattr(ref.scene, name)!r}.")
        if len(model.bodies) != n:
            raise ValueError(f"{where} {len(model.bodies)} bodies, scenes[0] has {n}.")
        for i, body in enumerate(model.bodies):
            for field_name, value in _body_fields(body).items():
                if not _same(value, ref_bodies[i][field_name]):
                    raise ValueError(f"{where} body {i} ({body.name!r}) {field_name} == {value!r}, "
                                     f"scenes[0] has {ref_bodies[i][field_name]!r}.")
        for (i, j), law in zip(pairs, ref_laws):
            if model.contact_law(i, j) != law:
                raise ValueError(f"{where} contact law (friction, restitution) between bodies {i} and {j} "
                                 f"== {model.contact_law(i, j)}, scenes[0] has {law}.")
    return models


# --------------------------------------------------------------------------- solver


def _solve_problems(W: np.ndarray, q: np.ndarray, mu: np.ndarray, dim: int, settings: SolverSettings,
                   r0: np.ndarray, warm: np.ndarray, sizes: np.ndarray) -> list[core.CoreResult]:
    """Solve a stack of padded contact problems ``u = W r + q``, some warm-started.

    Parameters
    ----------
    W : ndarray, shape (P, n, n)
        Delassus matrices (m/s per N s), problem ``p`` in ``W[p, :sizes[p], :sizes[p]]``.
    q : ndarray, shape (P, n)
        Free relative velocities, m/s.
    mu : ndarray, shape (P, n // dim)
        Friction coefficients (>= 0).
    dim : int
        2 or 3.
    settings : SolverSettings
    r0 : ndarray, shape (P, n)
        Warm starts (impulses, N s) of the problems where ``warm`` is True.
    warm : ndarray of bool, shape (P,)
        Which problems are warm-started; the others start cold.
    sizes : ndarray of int, shape (P,)
        Unknowns of each problem (contacts x dim).

    Returns
    -------
    list of CoreResult
        In order; each equal to :func:`nscd.solver.core.solve` on the unpadded problem
        with its warm start (a cold start is not a zero warm start: the conic fallback
        starts its shift from the warm start). Hence two calls of
        :func:`nscd.solver.core.solve_batch`: the warm-started problems, then the others.
    """
    results: list = [None] * len(sizes)
    for group, starts in ((np.flatnonzero(warm), r0), (np.flatnonzero(~warm), None)):
        if len(group) == 0:
            continue
        width = int(sizes[group].max())
        solved = core.solve_batch(W[group, :width, :width], q[group, :width], mu[group, :width // dim], dim,
                                  settings, None if starts is None else starts[group, :width], sizes[group])
        for p, res in zip(group.tolist(), solved):
            results[p] = res
    return results


# --------------------------------------------------------------------------- prescribed bodies


class _Prescribed:
    """Poses and velocities of one fixed or driven body in every scene of a batch.

    :meth:`nscd.scene.Body.prescribed` for all scenes at once: constant for a fixed
    body; for driven bodies whose motions share a class with a ``kinematics_many(motions)``
    class method (it returns ``evaluate(t, which)``: displacement and velocity arrays of
    ``motions[which[k]]`` at ``t[k]``, each equal to that motion's own ``kinematics``), one
    call; otherwise scene by scene.
    """

    def __init__(self, models: list[Model], index: int) -> None:
        self.index = index
        self.bodies = [model.bodies[index] for model in models]
        self.q0 = np.array([b.q0 for b in self.bodies])
        self.direction = self.bodies[0].direction
        motions = [b.motion for b in self.bodies]
        self.fixed = all(m is None and b.vertical is None for m, b in zip(motions, self.bodies))
        many = getattr(type(motions[0]), "kinematics_many", None)
        self.evaluate = None
        if many is not None and all(type(m) is type(motions[0]) and b.vertical is None
                                    for m, b in zip(motions, self.bodies)):
            self.evaluate = many(motions)

    def write(self, rows: np.ndarray, t: np.ndarray, q: np.ndarray, v: np.ndarray) -> None:
        """Write the body's pose and velocity in scenes ``rows`` at times ``t`` (S,) into q, v (S, n_bodies, nq)."""
        i = self.index
        if self.fixed or self.evaluate is not None:
            q[:, i] = self.q0[rows]
            v[:, i] = 0.0
            if self.evaluate is not None:
                d, vel = self.evaluate(t, rows)
                dim = len(self.direction)
                q[:, i, :dim] += d[:, None] * self.direction
                v[:, i, :dim] += vel[:, None] * self.direction
            return
        for k, (row, tk) in enumerate(zip(rows.tolist(), t.tolist())):
            q[k, i], v[k, i] = self.bodies[row].prescribed(tk)


# --------------------------------------------------------------------------- one batched step


#: Bits of the feature id in a warm-start key (nscd.contact.detect2d packs ids in 33 bits).
_FEATURE_BITS = 34


class _WarmTable:
    """Warm starts of many scenes: impulses (N s, contact frame) keyed by scene and contact id.

    The batched counterpart of :class:`nscd.stepper.WarmStart` (a dict in effect): a key
    given twice keeps its last impulse. Keys pack ``(scene, body_a, body_b, feature)``
    exactly into one int64 (:meth:`key`), so there are no collisions.

    Parameters
    ----------
    keys : ndarray of int64, shape (k,)
    impulses : ndarray, shape (k, dim)
    scenes : ndarray of int, shape (k,)
        Scene of each entry (index in the batch).
    n_scenes : int
    """

    def __init__(self, keys: np.ndarray, impulses: np.ndarray, scenes: np.ndarray, n_scenes: int) -> None:
        order = np.argsort(keys, kind="stable")
        self.keys, self.impulses, self.scenes = keys[order], impulses[order], scenes[order]
        self.has = np.zeros(n_scenes, dtype=bool)
        self.has[scenes] = True

    @staticmethod
    def key(scenes: np.ndarray, ids: np.ndarray, n_bodies: int) -> np.ndarray:
        """int64 keys of contact ids ``(body_a, body_b, feature)`` (k, 3) of the given scenes (k,)."""
        pair = (scenes.astype(np.int64) * n_bodies + ids[:, 0]) * n_bodies + ids[:, 1]
        return (pair << _FEATURE_BITS) | ids[:, 2]

    @classmethod
    def join(cls, parts: list["_WarmTable"], n_scenes: int) -> "_WarmTable":
        """One table of several; a key in a later part overrides the earlier ones."""
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("keys", "impulses", "scenes")),
                   n_scenes)

    def of_scenes(self, mask: np.ndarray) -> "_WarmTable":
        """The entries of the scenes selected by ``mask`` (bool, (n_scenes,))."""
        keep = mask[self.scenes]
        return _WarmTable(self.keys[keep], self.impulses[keep], self.scenes[keep], len(mask))

    def lookup(self, keys: np.ndarray) -> np.ndarray:
        """Impulses (k, dim) of ``keys`` (k,); zero for a key not in the table (the last entry of a key)."""
        out = np.zeros((len(keys), self.impulses.shape[1]))
        if len(self.keys) == 0 or len(keys) == 0:
            return out
        pos = np.searchsorted(self.keys, keys, side="right") - 1
        hit = (pos >= 0) & (self.keys[np.maximum(pos, 0)] == keys)
        out[hit] = self.impulses[pos[hit]]
        return out


@dataclass
class _Stepped:
    """Outcome of :func:`_mj_step` for S scenes (flat contact arrays, scenes in order).

    Attributes
    ----------
    t, q, v : ndarray, shapes (S,), (S, n_bodies, nq), (S, n_bodies, nv)
        New states (rows of scenes that must localise an impact: unchanged).
    closing : ndarray, shape (S,)
        Predicted closing time (s from the start of the step) of scenes whose step was
        not taken (:func:`nscd.stepper.step` splits it); nan for the others.
    contacts : Contacts
        Every scene's contacts, scene after scene (body indices of the scene).
    first : ndarray of int, shape (S + 1,)
        Scene ``s`` owns contacts ``first[s]:first[s + 1]``.
    active : ndarray of int
        Flat indices of the active contacts, scene after scene.
    active_first : ndarray of int, shape (S + 1,)
        Scene ``s`` owns ``active[active_first[s]:active_first[s + 1]]``.
    impulses, u_before, u_after : ndarray, shape (len(active), dim)
        As :class:`nscd.stepper.StepOutput`.
    converged : ndarray of bool, shape (S,)
        Whether each scene's contact problem converged (True without one).
    solved : dict
        Scene -> :class:`StepReport` of the scenes whose contact problem was solved
        (:meth:`report` gives every scene's).
    warm : _WarmTable
        The impulses of the active contacts (:func:`nscd.stepper.warm_start_of` of every scene).
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    closing: np.ndarray
    contacts: Contacts
    first: np.ndarray
    active: np.ndarray
    active_first: np.ndarray
    impulses: np.ndarray
    u_before: np.ndarray
    u_after: np.ndarray
    converged: np.ndarray
    solved: dict
    warm: _WarmTable

    def report(self, s: int) -> StepReport:
        """The :class:`StepReport` of scene ``s`` (as the single-scene step gives it)."""
        if s in self.solved:
            return self.solved[s]
        return StepReport(t=float(self.t[s]), n_contacts=int(self.first[s + 1] - self.first[s]), n_active=0,
                          status="no contact", converged=True, iterations=0, merit=0.0)

    def output(self, s: int) -> StepOutput:
        """The :class:`~nscd.stepper.StepOutput` of scene ``s`` (as the single-scene step gives it)."""
        lo, hi = self.first[s], self.first[s + 1]
        a = slice(self.active_first[s], self.active_first[s + 1])
        return StepOutput(report=self.report(s), contacts=self.contacts.subset(slice(lo, hi)),
                          active=self.active[a] - lo, impulses=self.impulses[a], u_before=self.u_before[a],
                          u_after=self.u_after[a], solved_at=np.full(a.stop - a.start, self.t[s]))


def _groups(counts: np.ndarray, first: np.ndarray):
    """Scenes grouped by a count: yields ``(c, scenes (G,), positions (G, c))`` for every count
    c > 0, positions ``first[s] + arange(c)`` (scene by scene products of a group of equal
    sizes are one stacked BLAS call, bit-identical to a call per scene)."""
    for c in np.unique(counts[counts > 0]).tolist():
        scenes = np.flatnonzero(counts == c)
        yield c, scenes, first[scenes][:, None] + np.arange(c)


def _mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Stacked matrix-vector products ``A[s] @ x[s]``: (G, r, c) and (G, c) -> (G, r)."""
    return np.matmul(A, x[:, :, None])[:, :, 0]


class _Batch:
    """The static part shared by the scenes: models, settings, margin, detection tables."""

    def __init__(self, models: list[Model], settings: Settings, margin: float) -> None:
        self.models, self.settings, self.margin = models, settings, margin
        model = self.model = models[0]
        self.groups = model.polygon_groups()
        n = len(model.bodies)
        self.group_of = np.empty(n, dtype=int)
        self.slot_of = np.empty(n, dtype=int)
        for g, (index, _) in enumerate(self.groups):
            self.group_of[index] = g
            self.slot_of[index] = np.arange(len(index))
        self.prescribed = [_Prescribed(models, body.index) for body in model.prescribed]
        # per scene, as each scene's own Simulator has it (scenes may differ in size)
        self.dead_band = GAP_DEAD_BAND * np.array([m.smallest_radius for m in models])
        self.may_touch = np.triu(model.dynamic[:, None] | model.dynamic[None, :], k=1)
        self.laws = np.zeros((n, n, 2))
        for i, j in np.argwhere(self.may_touch).tolist():
            self.laws[i, j] = model.contact_law(i, j)
        _, self.mass_diag = model.mass_matrix(np.zeros((n, model.nq)), dense=True)  # 2D: constant diagonal
        # Free flight in 2D: v_free = v + dt * (f / M), f gravity only (nscd.stepper._forces).
        force = np.zeros((len(model.dynamic_index), model.nv))
        force[:, model.dim - 1] = -model.mass[model.dynamic_index] * model.scene.gravity
        self.accel = force.ravel() / self.mass_diag

    def global_dofs(self, S: int) -> np.ndarray:
        """First velocity index of each body of S stacked scenes (scene ``s`` owns dofs
        ``s * n_dofs`` onward), -1 for fixed and driven bodies; shape (S * n_bodies,)."""
        dof = self.model.dof_of_body
        return np.where(dof >= 0, dof[None, :] + self.model.n_dofs * np.arange(S)[:, None], -1).ravel()

    def tolerance(self, dt: np.ndarray) -> np.ndarray:
        """:func:`nscd.stepper._gap_tolerance` for each step length in ``dt`` (S,)."""
        lengths, which = np.unique(dt, return_inverse=True)
        return np.array([_gap_tolerance(self.settings, self.model, d) for d in lengths.tolist()])[which]

    def detect(self, q: np.ndarray) -> tuple[Contacts, np.ndarray]:
        """:func:`nscd.contact.detect.detect` of S configurations ``q`` (S, n_bodies, 3) at once.

        Returns the contacts scene after scene (each scene's in the order of the
        single-scene detection: by body pair ``(i, j)``, then manifold point) and the
        scene of each contact, ndarray of int (m,).
        """
        S, n = q.shape[:2]
        posed = []
        lower, upper = np.empty((S, n, 2)), np.empty((S, n, 2))
        for index, local in self.groups:
            k = len(index)
            world = _pose_polygons(q[:, index].reshape(S * k, 3),
                                   np.broadcast_to(local, (S,) + local.shape).reshape((S * k,) + local.shape[1:]))
            posed.append(world)
            world = world.reshape((S, k) + world.shape[1:])
            lower[:, index], upper[:, index] = world.min(axis=2), world.max(axis=2)
        # all pairs of boxes (the single-scene broad phase finds the same pairs, same order)
        margin = self.margin
        overlap = ((lower[:, None, :, :] <= upper[:, :, None, :] + margin)
                   & (lower[:, :, None, :] <= upper[:, None, :, :] + margin)).all(axis=3)
        scene, i, j = np.nonzero(overlap & self.may_touch)
        if len(scene) == 0:
            return Contacts.empty(2), np.zeros(0, dtype=int)
        n_groups = len(self.groups)
        kind = self.group_of[i] * n_groups + self.group_of[j]
        rows = []
        for code in np.unique(kind):
            sel = np.flatnonzero(kind == code)
            ga, gb = code // n_groups, code % n_groups
            count_a, count_b = len(self.groups[ga][0]), len(self.groups[gb][0])
            found = collide_polygons_batch(posed[ga][scene[sel] * count_a + self.slot_of[i[sel]]],
                                           posed[gb][scene[sel] * count_b + self.slot_of[j[sel]]], margin)
            rows.append((sel[found.pair], found.normal, 0.5 * (found.points_a + found.points_b),
                         found.gaps, found.ids))
        pair, normal, point, gap, feature = (np.concatenate(column) for column in zip(*rows))
        if len(pair) == 0:
            return Contacts.empty(2), np.zeros(0, dtype=int)
        order = np.argsort(pair, kind="stable")
        pair, normal, point, gap, feature = pair[order], normal[order], point[order], gap[order], feature[order]
        a, b = i[pair], j[pair]
        laws = self.laws[a, b]
        contacts = Contacts(body_a=a, body_b=b, point=point, frame=tangent_frames(normal), gap=gap,
                            friction=laws[:, 0].copy(), restitution=laws[:, 1].copy(),
                            ids=np.column_stack([a, b, feature]))
        return contacts, scene[pair]


def _global(contacts: Contacts, scene: np.ndarray, n_bodies: int) -> Contacts:
    """``contacts`` with body indices into the stacked bodies of all scenes (``scene * n_bodies + body``)."""
    offset = scene * n_bodies
    return Contacts(contacts.body_a + offset, contacts.body_b + offset, contacts.point, contacts.frame,
                    contacts.gap, contacts.friction, contacts.restitution, contacts.ids)


def _mj_step(batch: _Batch, t: np.ndarray, q: np.ndarray, v: np.ndarray, dt: np.ndarray, tolerance: np.ndarray,
             warm: _WarmTable, localize: bool, defer_impacts: bool, rows: np.ndarray) -> _Stepped:
    """:func:`nscd.stepper.moreau_jean_step` for S scenes at once.

    Parameters
    ----------
    batch : _Batch
    t, q, v : ndarray, shapes (S,), (S, n_bodies, 3), (S, n_bodies, 3)
        States at the start of the step (s, m and rad, m/s and rad/s).
    dt : ndarray, shape (S,)
        Step length of each scene, s (>= 0; 0 for an impact).
    tolerance : ndarray, shape (S,)
        Gap tolerance of each scene, m (:func:`nscd.stepper._gap_tolerance`).
    warm : _WarmTable
        Warm starts, keyed by the scenes' indices in the batch (``rows``).
    localize, defer_impacts : bool
        As in :func:`nscd.stepper.moreau_jean_step`.
    rows : ndarray of int, shape (S,)
        Index of each scene in the batch.
    """
    settings, model = batch.settings, batch.model
    dim, nv, theta = model.dim, model.nv, settings.theta
    S, n_bodies = q.shape[:2]
    dyn = model.dynamic_index
    n_dofs = model.n_dofs
    t_next = t + dt
    q_next, v_next = q.copy(), v.copy()
    for body in batch.prescribed:
        body.write(rows, t_next, q_next, v_next)

    contacts, scene = batch.detect(q)
    m = len(contacts)
    first = np.searchsorted(scene, np.arange(S + 1))
    v_dyn = v[:, dyn].reshape(S, n_dofs)
    v_free = v_dyn + dt[:, None] * batch.accel
    closing_time = np.full(S, np.nan)
    centres = q.reshape(S * n_bodies, -1)[:, :dim]
    if m:
        flat = _global(contacts, scene, n_bodies)
        # one sparse Jacobian of all scenes (block diagonal), then each scene's dense block
        H_all, w = jacobian(flat, centres, np.stack([v.reshape(S * n_bodies, -1), v_next.reshape(S * n_bodies, -1)]),
                            batch.global_dofs(S), S * n_dofs, dense=False)
        coo = H_all.tocoo()
        owner = coo.row // dim
        H = np.zeros((S, int(np.max(np.diff(first))), dim, n_dofs))
        H[scene[owner], owner - first[scene[owner]], coo.row % dim, coo.col % n_dofs] = coo.data
        w = w.reshape(2, m, dim)
        u_k = np.empty((m, dim))
        u_free_n = np.empty(m)
        for c, group, index in _groups(np.diff(first), first):
            Hg = H[group, :c].reshape(len(group), c * dim, n_dofs)
            u_k[index] = (_mv(Hg, v_dyn[group]) + w[0][index].reshape(len(group), -1)).reshape(len(group), c, dim)
            u_free_n[index] = (_mv(Hg, v_free[group]) + w[1][index].reshape(len(group), -1)
                               ).reshape(len(group), c, dim)[:, :, 0]
        dt_c, tol_c = dt[scene], tolerance[scene]
        closing = np.minimum(theta * u_free_n + (1.0 - theta) * u_k[:, 0], 0.0)
        impacting = (contacts.gap > tol_c) & (u_k[:, 0] < 0.0)
        if localize and settings.localize_impacts:
            for s in np.unique(scene[impacting]).tolist():
                c = slice(first[s], first[s + 1])
                found = _first_impact_time(contacts.gap[c], u_k[c, 0], u_free_n[c], float(dt[s]), impacting[c])
                if found is not None:
                    closing_time[s] = found
        activation = 1.5 - theta if settings.activation is None else settings.activation
        is_active = contacts.gap + activation * dt_c * closing <= tol_c
        if defer_impacts:
            is_active &= ~impacting
        is_active &= np.isnan(closing_time)[scene]
        active = np.flatnonzero(is_active)
    else:
        active = np.zeros(0, dtype=int)
        u_k = np.zeros((0, dim))
    active_first = np.searchsorted(scene[active], np.arange(S + 1))
    n_active = np.diff(active_first)

    v_dyn_next = v_free.copy()
    impulses = np.zeros((len(active), dim))
    u_after = np.zeros((len(active), dim))
    waiting = ~np.isnan(closing_time)
    converged = np.ones(S, dtype=bool)
    reports: dict = {}
    if len(active):
        sa = scene[active]
        offset = w[1, active].copy()
        offset[:, 0] += contacts.restitution[active] * np.minimum(u_k[active, 0], 0.0)
        dt_a = dt[sa]
        # a contact counted closed may close its small gap within the step (not at an impact,
        # dt = 0), above the dead band (nscd.stepper.GAP_DEAD_BAND)
        dead_band = batch.dead_band[sa]
        with np.errstate(divide="ignore", invalid="ignore"):
            lift = np.maximum(contacts.gap[active] - dead_band, 0.0) / (theta * dt_a)
        offset[:, 0] = np.where(dt_a > 0.0, offset[:, 0] + lift, offset[:, 0])
        offset[:, 0] += 0.5 * dt_a * centripetal_normal(flat.subset(active), centres,
                                                         v.reshape(S * n_bodies, -1)) / theta
        keys = _WarmTable.key(rows[sa], contacts.ids[active], n_bodies)
        starts = warm.lookup(keys)
        # the problems, grouped by size: products of equal shapes stacked
        solved = np.flatnonzero(n_active)
        slot = np.empty(S, dtype=int)
        slot[solved] = np.arange(len(solved))
        width = int(n_active.max()) * dim
        W = np.zeros((len(solved), width, width))
        q_free = np.zeros((len(solved), width))
        mu = np.zeros((len(solved), width // dim))
        r0 = np.zeros((len(solved), width))
        groups = []
        for c, group, index in _groups(n_active, active_first):
            idx = active[index]
            H_act = H[group[:, None], idx - first[group][:, None]].reshape(len(group), c * dim, n_dofs)
            MinvHT = H_act.transpose(0, 2, 1) / batch.mass_diag[:, None]  # M diagonal in 2D (nscd.solver.api)
            p = slot[group]
            W[p, :c * dim, :c * dim] = np.matmul(H_act, MinvHT)
            q_free[p, :c * dim] = _mv(H_act, v_free[group]) + offset[index].reshape(len(group), -1)
            mu[p, :c] = contacts.friction[idx]
            r0[p, :c * dim] = starts[index].reshape(len(group), -1)
            groups.append((c, group, index, idx, H_act, MinvHT))
        results = _solve_problems(W, q_free, mu, dim, settings.solver, r0, warm.has[rows[solved]],
                                 n_active[solved] * dim)
        for c, group, index, idx, H_act, MinvHT in groups:
            r = np.array([results[p].r for p in slot[group].tolist()])
            v_group = v_free[group] + _mv(MinvHT, r)
            v_dyn_next[group] = v_group
            impulses[index] = r.reshape(len(group), c, dim)
            u_after[index] = (_mv(H_act, v_group) + w[1][idx].reshape(len(group), -1)).reshape(len(group), c, dim)
        for s, p in zip(solved.tolist(), range(len(solved))):
            res = results[p]
            converged[s] = res.status in _CONVERGED
            reports[s] = StepReport(
                t=float(t_next[s]), n_contacts=int(first[s + 1] - first[s]), n_active=int(n_active[s]),
                status=str(res.status), converged=bool(converged[s]),
                iterations=int(res.fast_iterations + res.sweeps + res.fixed_point_iterations + res.polish_iterations),
                merit=float(res.merit))
    else:
        keys = np.zeros(0, dtype=np.int64)

    v_next[:, dyn] = v_dyn_next.reshape(S, len(dyn), nv)
    v_mid = theta * v_next[:, dyn] + (1.0 - theta) * v[:, dyn]
    q_next[:, dyn] = q[:, dyn] + dt[:, None, None] * v_mid
    t_next[waiting], q_next[waiting], v_next[waiting] = t[waiting], q[waiting], v[waiting]
    return _Stepped(t=t_next, q=q_next, v=v_next, closing=closing_time, contacts=contacts, first=first,
                    active=active, active_first=active_first, impulses=impulses,
                    u_before=u_k[active] if m else np.zeros((0, dim)), u_after=u_after, converged=converged, solved=reports,
                    warm=_WarmTable(keys, impulses, rows[scene[active]], len(warm.has)))


# --------------------------------------------------------------------------- the simulator


class BatchSimulator:
    """Advance B scenes of one structure in lock step, each exactly as :class:`nscd.Simulator` would.

    Parameters
    ----------
    scenes : sequence of Scene
        2D scenes sharing one structure (:func:`check_same_structure`): they may
        differ in the motions of their driven bodies and in their initial states.
    dt : float
        Time step of every scene, s (> 0).
    settings : Settings, optional
        Integrator and solver options, shared; ``scheme="theta"`` only (the midpoint
        rule is not batched yet: ValueError). ``on_failure="raise"`` raises
        :class:`nscd.result.SolverFailure` naming the scene; ``"warn"`` warns once per
        unconverged step and scene, as single runs do.
    record : bool
        Keep every scene's histories for :meth:`results` (default). False keeps only
        the current states and the counters (:attr:`unconverged`): less memory and
        less work per step, for sweeps that look at the states as they go.
    store_impulses : bool
        With ``record``, keep contact points and impulses of every step.

    Attributes
    ----------
    t : ndarray, shape (B,)
        Time of each scene, s (scenes that split a step at an impact may differ from
        the others in the last bits).
    q, v : ndarray, shape (B, n_bodies, 3)
        Positions ``(x, y, angle)`` (m, m, rad CCW) and velocities ``(vx, vy, omega)``.
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
                 record: bool = True, store_impulses: bool = False) -> None:
        _check_time(0.0, dt)
        self.settings = settings or Settings()
        if self.settings.scheme != "theta":
            raise ValueError(f"settings.scheme == {self.settings.scheme!r}: the batched mode runs the theta "
                             "scheme only (scheme='theta'); run midpoint-rule scenes one by one.")
        self.dt = float(dt)
        models = check_same_structure(scenes)
        margin = self.settings.margin or _auto_margin(models[0])
        self._batch = _Batch(models, self.settings, margin)
        states = [initial_state(model) for model in models]
        for k, (model, state) in enumerate(zip(models, states)):
            try:
                check_overlaps(model, state, margin)
            except ValueError as exc:
                raise ValueError(f"scenes[{k}]: {exc}") from None
        self.t = np.array([s.t for s in states])
        self.q = np.array([s.q for s in states])
        self.v = np.array([s.v for s in states])
        self.running = np.ones(len(models), dtype=bool)
        self.unconverged = np.zeros(len(models), dtype=int)
        self.converged = np.ones(len(models), dtype=bool)
        n_bodies = len(models[0].bodies)
        if len(models) * n_bodies**2 >= 2 ** (63 - _FEATURE_BITS):
            raise ValueError(f"{len(models)} scenes of {n_bodies} bodies: scenes x bodies^2 == "
                             f"{len(models) * n_bodies**2}, must be < 2^{63 - _FEATURE_BITS} (warm-start keys); "
                             "split the batch.")
        self._warm = _WarmTable(np.zeros(0, dtype=np.int64), np.zeros((0, 2)), np.zeros(0, dtype=int), len(models))
        speed = _impact_speed(self.settings, models[0], self.dt)
        self._builders = ([ResultBuilder(model, state, store_impulses, impact_speed=speed)
                           for model, state in zip(models, states)] if record else None)
        self._wall = 0.0

    def __len__(self) -> int:
        return len(self.t)

    def state(self, k: int) -> State:
        """The current state of scene ``k`` (a read-only snapshot)."""
        return State(float(self.t[k]), self.q[k].copy(), self.v[k].copy())

    def stop(self, k: int | np.ndarray) -> None:
        """Stop stepping scene(s) ``k`` (index, indices or boolean mask)."""
        self.running[k] = False

    def step(self) -> np.ndarray:
        """Advance every running scene by one step (split at its own impact, if any).

        Returns
        -------
        ndarray of int
            Indices of the scenes stepped. Unconverged steps are counted in
            :attr:`unconverged` and warn or raise as ``settings.on_failure`` says.
        """
        rows = np.flatnonzero(self.running)
        if len(rows) == 0:
            return rows
        start = _time.perf_counter()
        batch, dt = self._batch, np.full(len(rows), self.dt)
        t, q, v = self.t[rows], self.q[rows], self.v[rows]
        plain = _mj_step(batch, t, q, v, dt, batch.tolerance(dt), self._warm, True, False, rows)
        new_t, new_q, new_v = plain.t, plain.q, plain.v
        outputs = [plain.output(s) for s in range(len(rows))] if self._builders is not None else None
        converged = plain.converged.copy()
        failing = {}  # scene -> report of its first unconverged (sub-)step
        warm = [plain.warm]
        split = np.flatnonzero(~np.isnan(plain.closing))
        if len(split):
            parts = self._split(rows[split], t[split], q[split], v[split], plain.closing[split])
            approach, impact, rest = parts
            new_t[split], new_q[split], new_v[split] = rest.t, rest.q, rest.v
            warm.extend(p.warm for p in parts)  # later sub-steps override, as warm_start_of(out) does
            for k, s in enumerate(split.tolist()):
                converged[s] = all(p.converged[k] for p in parts)
                if not converged[s]:
                    failing[s] = next(p.report(k) for p in parts if not p.converged[k])
                if outputs is not None:
                    outputs[s] = approach.output(k).then(impact.output(k)).then(rest.output(k))
        self._warm = _WarmTable.join(warm, len(self))
        self._wall += _time.perf_counter() - start
        if self._builders is not None:
            for k, s in enumerate(rows.tolist()):
                self._builders[s].add(State(float(t[k]), q[k], v[k]), State(float(new_t[k]), new_q[k], new_v[k]),
                                      outputs[k])
        self.t[rows], self.q[rows], self.v[rows] = new_t, new_q, new_v
        self.converged[rows] = converged
        self.unconverged[rows] += ~converged
        for k in np.flatnonzero(~converged).tolist():
            self._fail(int(rows[k]), failing.get(k) or plain.report(k))
        return rows

    def _split(self, rows: np.ndarray, t: np.ndarray, q: np.ndarray, v: np.ndarray,
               closing: np.ndarray) -> tuple[_Stepped, _Stepped, _Stepped]:
        """:func:`nscd.stepper.step`'s split of the steps of scenes ``rows`` at their closing
        times (s from the start of the step): the approach in free flight, the impact, the rest."""
        batch, dt = self._batch, np.full(len(rows), self.dt)
        approach = _mj_step(batch, t, q, v, closing, batch.tolerance(closing), self._warm, False, True, rows)
        warm = self._or(approach.warm, self._warm)
        impact = _mj_step(batch, approach.t, approach.q, approach.v, np.zeros(len(rows)), batch.tolerance(dt),
                          warm, False, False, rows)
        rest_dt = dt - closing
        rest = _mj_step(batch, impact.t, impact.q, impact.v, rest_dt, batch.tolerance(rest_dt),
                        self._or(impact.warm, warm), False, False, rows)
        return approach, impact, rest

    def _or(self, warm: _WarmTable, otherwise: _WarmTable) -> _WarmTable:
        """``warm_start_of(sub_step) or warm_start`` for every scene: the sub-step's impulses,
        or ``otherwise`` for a scene whose sub-step had no active contact."""
        return _WarmTable.join([otherwise.of_scenes(~warm.has), warm], len(self))

    def _fail(self, k: int, report: StepReport) -> None:
        message = (f"scene {k}: contact solver did not converge at t = {report.t:.6g} s "
                   f"({report.status}, merit {report.merit:.3g})")
        if self.settings.on_failure == "raise":
            raise SolverFailure(message)
        warnings.warn(message, RuntimeWarning, stacklevel=3)

    def run(self, until: float) -> None:
        """Step every running scene until time ``until`` (s), as :meth:`nscd.Simulator.run`."""
        n_steps = int(round((until - float(np.min(self.t[self.running], initial=until))) / self.dt))
        for _ in range(max(n_steps, 0)):
            self.step()

    def results(self, status: str = "finished", message: str = "") -> list[Result]:
        """Each scene's :class:`nscd.Result` (needs ``record=True``).

        ``wall_time`` of each result is the batch's stepping time divided by the number
        of scenes.
        """
        if self._builders is None:
            raise ValueError("record == False: this BatchSimulator kept no histories; "
                             "create it with record=True to get results.")
        wall = self._wall / len(self._builders)
        return [builder.build(status=status, message=message, wall_time=wall, dt=self.dt,
                              settings=self.settings) for builder in self._builders]


def simulate_batch(scenes: Sequence[Scene], t_end: float, dt: float, settings: Settings | None = None,
                   store_impulses: bool = False) -> list[Result]:
    """Simulate scenes of one structure from t = 0 to ``t_end``, together.

    The batched counterpart of :func:`nscd.simulate`: ``simulate_batch(scenes, t_end, dt)[k]``
    equals ``nscd.simulate(scenes[k], t_end, dt)`` (same trajectory, impacts and solver
    reports; only ``report.wall_time`` differs).

    Parameters
    ----------
    scenes : sequence of Scene
        2D scenes of one structure (see :func:`check_same_structure`).
    t_end : float
        End time, s (>= 0).
    dt : float
        Time step, s, in (0, t_end].
    settings : Settings, optional
    store_impulses : bool
        Keep contact points and impulses of every step.

    Returns
    -------
    list of Result
        One per scene, in order.
    """
    _check_time(t_end, dt)
    sim = BatchSimulator(scenes, dt, settings, record=True, store_impulses=store_impulses)
    for _ in range(int(round(t_end / dt))):
        sim.step()
    return sim.results()
