"""Steps of one small scene in one compiled call, recorded in place.

A single run (:class:`~nscd.stepper.Simulator`, :func:`~nscd.stepper.simulate`) of a scene
of at most ``ALL_PAIRS_BODIES`` bodies takes its plain steps here:
:func:`plain_steps` runs up to ``n`` steps in one compiled call, each the composition of
:func:`nscd.stepper._advance`'s compiled stages in the same order (free flight, detection,
the warm starts, :func:`~nscd.stepper._assemble`, the compiled Newton
:func:`nscd.solver.small.solve_dense`, :func:`~nscd.stepper._solution`,
:func:`~nscd.stepper._finish`), and records each step into the arrays of the run's
:class:`~nscd.result.ResultBuilder` with :meth:`~nscd.result.ResultBuilder.add`'s formulas.
The kernels are the stepper's own, called, not re-expressed: the step of a scene is the same
floating-point operations on either path.

It hands the step back to Python, before changing anything, where the general step
(:func:`nscd.stepper.step`) is needed: a body turning fast (the step in pieces), a scene
seen early (midpoint rule), an impact located in the step (event location's sub-steps), a
contact problem the compiled Newton does not take or accept, or one that creates energy
(the solver's other routes), an end-of-step overlap to detect afresh; and where a buffer is
full (grown, then called again). It also returns after a step whose overlap warns.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from nscd._jit import njit, njit_helper
from nscd.contact.detect import ALL_PAIRS_BODIES, _detect_small_polyhedra, _detect_small_scenes
from nscd.contact.frames import Contacts
from nscd.impact_law import dissipation
from nscd.result import ResultBuilder, StepReport, driven_work
from nscd.solver import small
from nscd.state import Data, WarmStarts, _find_ids, _matched_rows
from nscd.stepper import (_CONVERGED_STATUS, _TURN_PER_PIECE, EARLY_DETECTION_SWEEP, ENERGY_ROUND_OFF,
                          PENETRATION_TOLERANCE, StepOutput, _assemble, _Constants, _finish, _flight_2d, _flight_3d,
                          _largest_spin, _previous_impulses, _solution)

#: What :func:`plain_steps` says after its steps: all taken; the next needs the general step;
#: a buffer is full (nothing of the next step written); the last step taken overlaps beyond
#: the warning threshold.
DONE, GENERAL, FULL, OVERLAP = 0, 1, 2, 3

#: Steps of a scene with a driven body per compiled call at most: their motions are evaluated
#: beforehand, and those of the steps after a step handed back to Python are not used.
_DRIVEN_STEPS = 32


@njit
def plain_steps(n_steps, t, q, v, warm, last, record, drive, flight, polygons, polyhedra, stage, solver):
    """Up to ``n_steps`` plain steps of one scene, in place; returns (steps taken, code).

    ``t`` (1,), ``q`` (1, n, nq), ``v`` (1, n, nv): the data's state, advanced in place.
    ``warm``: the warm start, ``(ids (w, 3), impulses (w, dim), trend (w, dim), first (2,),
    trended (1,))`` with room for ``w`` rows (rows ``first[0]:first[1]`` used), replaced in
    place by each step's. ``last``: the last step's contacts (:class:`Contacts`' fields
    body_a, body_b, point, frame, gap, friction, restitution, ids), active set, per-active
    arrays (4, k, dim) of :func:`~nscd.stepper._finish` and their numbers (2,).
    ``record``: :meth:`nscd.result.ResultBuilder.arrays`. ``drive``: the fixed and driven
    bodies' poses and velocities at the end of each of the ``n_steps`` steps and their poses at
    its midpoint (n_steps, n, nq), (n_steps, n, nv), (n_steps, n, nq) (:meth:`nscd.state.Drives.write`),
    their indices, and whether any body is driven (if not, the arrays are not read: the fixed
    bodies keep their pose, at rest). ``flight``: dynamic_index,
    dof_of_body, mass, mass diagonal (2D), gravity, radius, the dynamic bodies' own inertias
    (3D), n_dofs. ``polygons`` (2D, else None) or ``polyhedra`` (3D, else None): the
    model's shapes and contact laws as the detection kernel takes them. ``stage``: the
    plain sub-step's rows (:class:`nscd.stepper._Rows`) and the constants of the stages
    (:func:`nscd.stepper._constants`). ``solver``: tol, exact cone, max_fast.
    """
    ids_w, impulses_w, trend_w, first_w, trended_w = warm
    q_ends, v_ends, q_halves, prescribed_index, driven = drive
    (times, qs, vs, dissipated, work_input, iterations, merit, n_contacts, n_active, penetration, status, converged,
     impact_time, impact_a, impact_b, impact_point, impact_before, impact_after, impact_impulse, counts) = record
    dynamic_index, dof_of_body, mass, mass_diagonal, gravity, radius, inertia_body, n_dofs = flight
    (dt, tolerance, pace, localizing, deferring, watching, watch_ids, watch_first, step_dt, margin, impact_speed,
     dead_band, noise, fast, midpoint, theta, activation, early_sweep, turn_limit, overlap_check, warn_overlap,
     energy_round_off, record_speed, converged_code, no_contact_code) = stage
    tol, exact, max_fast = solver
    S, n = q.shape[0], q.shape[1]
    dim = impulses_w.shape[1]
    early = np.zeros(S, dtype=np.bool_)
    for step in range(n_steps):
        # the general step's own conditions (nscd.stepper.step, _Midpoint.seen_at): a body
        # turning fast, a scene seen early
        if _largest_spin(v)[0] * step_dt > turn_limit:
            return step, GENERAL
        # 1. prescribe (the driven bodies' motions evaluated in Python beforehand)
        q_next, v_next = q.copy(), v.copy()
        if driven:
            for i in prescribed_index:
                for j in range(q.shape[2]):
                    q_next[0, i, j] = q_ends[step, i, j]
                for j in range(v.shape[2]):
                    v_next[0, i, j] = v_ends[step, i, j]
        # 5. free flight, the sweeps of 3. and 2. configure
        # 2D or 3D: the branch of the other dimension is pruned at compilation (its shapes are None)
        if polyhedra is None and polygons is not None:
            v_free, sweep, fastest, q_c = _flight_2d(q, v, v_next, dt, dynamic_index, dof_of_body, mass, mass_diagonal,
                                                     gravity, radius, midpoint)
            inverse_blocks = np.zeros((S, 0, 6, 6))
        if polygons is None and polyhedra is not None:
            v_free, inverse_blocks, sweep, fastest, q_c = _flight_3d(q, v, v_next, dt, dynamic_index, dof_of_body, mass,
                                                                     gravity, inertia_body, radius, midpoint)
        if midpoint and driven:  # the hook: the driven bodies at the midpoint of the step
            for i in prescribed_index:
                for j in range(q.shape[2]):
                    q_c[0, i, j] = q_halves[step, i, j]
        if midpoint and fastest > early_sweep:
            return step, GENERAL
        # 3. detect
        grow = sweep.reshape(S * n)
        if polyhedra is None and polygons is not None:
            local, owner, start, dynamic, material, table, keys, values = polygons
            scene, a, b, point, frame, gap, ids, friction, restitution = _detect_small_scenes(
                q_c, grow, local, owner, start, dynamic, margin, material, table, keys, values)
        if polygons is None and polyhedra is not None:
            (local, owner, plane_offsets, vertex_start, face_start, edge_start, family_start, shape_radius,
             face_vertices, side_start, edges, edge_family, vertex_faces, vertex_face_start, dynamic, material,
             table, keys, values) = polyhedra
            scene, a, b, point, frame, gap, ids, friction, restitution = _detect_small_polyhedra(
                q_c, grow, local, owner, plane_offsets, vertex_start, face_start, edge_start, family_start,
                shape_radius, face_vertices, side_start, edges, edge_family, vertex_faces, vertex_face_start, dynamic,
                margin, material, table, keys, values)
        # 4, 6-8. warm starts, Jacobian, active set, event location, the small problems
        first, previous = _previous_impulses(ids, scene, S, ids_w, impulses_w, first_w)
        (blocks, velocities, closing_time, closing, n_closing, active, active_first, offset, which, sizes, W, q_free,
         mu, r0, H, MinvHT) = _assemble(
            a, b, point, frame, gap, ids, restitution, friction, scene, first, previous, q_c, v, v_next, v_free, early, dt,
            tolerance, pace, localizing, deferring, watching, watch_ids, watch_first, dof_of_body, n_dofs,
            mass_diagonal, inverse_blocks, impact_speed, gravity, dead_band, noise, fast, midpoint, theta, activation)
        if n_closing:
            return step, GENERAL
        # 9. solve (nscd.solver.core.newton_batch's kernel call)
        r, u = np.empty(q_free.shape), np.empty(q_free.shape)
        merit_p, info = np.empty(sizes.size), np.empty((sizes.size, 2), dtype=np.int64)
        if sizes.size:
            small.solve_dense(W, q_free, mu, sizes, dim, r0, tol, exact, max_fast, small.FAST_PATIENCE,
                              small.JUNK_START, r, u, merit_p, info)
        impulses, u_after, v_dyn_next, left, n_left = _solution(
            H, MinvHT, r, sizes, which, info, active, active_first, v_free, velocities, restitution, previous,
            energy_round_off, noise)
        if n_left:
            return step, GENERAL
        # 10. integrate
        q_end, v_end, overlap, check, n_check, per_active = _finish(
            q, q_c, q_c, v, q_next, v_next, v_dyn_next, a, b, point, frame, gap, scene, first, dt, early, active, impulses,
            u_after, velocities, dynamic_index, radius, overlap_check, midpoint, theta)
        if n_check:
            return step, GENERAL
        m, k_active = gap.shape[0], active.shape[0]
        # impacts (ResultBuilder.add): active, approaching faster than record_speed, not active
        # in the step before (the warm start lists the step before's active contacts)
        new_ids = np.empty((k_active, 3), dtype=np.int64)
        for k in range(k_active):
            for d in range(3):
                new_ids[k, d] = ids[active[k], d]
        _, was_active = _find_ids(ids_w[first_w[0]:first_w[1]], new_ids)
        impact = np.zeros(k_active, dtype=np.bool_)
        n_impacts = 0
        for k in range(k_active):
            impact[k] = per_active[1, k, 0] < -record_speed and not was_active[k]
            n_impacts += impact[k]
        row = counts[0]
        if (row >= times.shape[0] or counts[1] + n_impacts > impact_time.shape[0] or k_active > ids_w.shape[0]
                or m > last[0].shape[0] or k_active > last[8].shape[0]):
            return step, FULL
        # the warm start handed on (WarmStarts.followed_by): impulses by id, their trend
        matched = _matched_rows(new_ids, np.array([0, k_active]), ids_w, first_w)
        trend = np.zeros((k_active, dim))
        for k in range(k_active):
            if matched[k] >= 0:
                for d in range(dim):
                    trend[k, d] = per_active[0, k, d] - impulses_w[matched[k], d]
        trended_w[0] = first_w[1] > first_w[0]
        first_w[0], first_w[1] = 0, k_active
        for k in range(k_active):
            for d in range(3):
                ids_w[k, d] = new_ids[k, d]
            for d in range(dim):
                impulses_w[k, d] = per_active[0, k, d]
                trend_w[k, d] = trend[k, d]
        # the new state
        for s in range(S):
            t[s] = t[s] + dt[s]
        for i in range(n):
            for j in range(q.shape[2]):
                q[0, i, j] = q_end[0, i, j]
            for j in range(v.shape[2]):
                v[0, i, j] = v_end[0, i, j]
        # the recording (ResultBuilder.add)
        lost, _ = dissipation(per_active[0], per_active[1], per_active[2])
        work = driven_work(per_active[0], per_active[3])
        counts[0] = row + 1
        times[row] = t[0]
        for i in range(n):
            for j in range(q.shape[2]):
                qs[row, i, j] = q[0, i, j]
            for j in range(v.shape[2]):
                vs[row, i, j] = v[0, i, j]
        dissipated[row] = dissipated[row - 1] + lost
        work_input[row] = work_input[row - 1] - work
        j = row - 1
        n_contacts[j], n_active[j], penetration[j], converged[j] = m, k_active, overlap[0], True
        if which.shape[0]:
            status[j], iterations[j], merit[j] = converged_code, info[0, 1], merit_p[0]
        else:
            status[j], iterations[j], merit[j] = no_contact_code, 0, 0.0
        for k in range(k_active):
            if impact[k]:
                c, e = active[k], counts[1]
                counts[1] = e + 1
                impact_time[e], impact_a[e], impact_b[e] = t[0], a[c], b[c]
                for d in range(dim):
                    impact_point[e, d] = point[c, d]
                impact_before[e], impact_after[e] = per_active[1, k, 0], per_active[2, k, 0]
                impact_impulse[e] = per_active[0, k, 0]
        _keep_last(last, a, b, point, frame, gap, friction, restitution, ids, active, per_active)
        if overlap[0] > warn_overlap:
            return step + 1, OVERLAP
    return n_steps, DONE


def _stamped_by_the_package(kernel) -> None:
    """Keep ``kernel``'s numba cache only while no source file of nscd changes.

    numba stamps a cached kernel with its own source file alone, and the compiled callees it
    links (here the stages of six modules) are part of its machine code: edited, they would
    leave the cached :func:`plain_steps` running their old code. So its stamp also holds the
    time and size of every ``.py`` file of the package (an edit anywhere compiles it again, a
    fresh install as before). Without numba's cache (``NUMBA_DISABLE_JIT=1``) nothing to do."""
    cache = getattr(kernel, "_cache", None)
    index = getattr(cache, "_cache_file", None)
    if index is None or not hasattr(index, "_source_stamp"):
        return
    root = Path(__file__).resolve().parent
    files = sorted(root.rglob("*.py"))
    index._source_stamp = (index._source_stamp, tuple((str(f.relative_to(root)), f.stat().st_mtime, f.stat().st_size)
                                                      for f in files))


_stamped_by_the_package(plain_steps)


@njit_helper
def _keep_last(last, a, b, point, frame, gap, friction, restitution, ids, active, per_active):
    """The last step's contacts, active set and per-active arrays into the buffers ``last``."""
    (body_a_l, body_b_l, point_l, frame_l, gap_l, friction_l, restitution_l, ids_l, active_l, per_active_l,
     sizes_l) = last
    m, k_active, dim = gap.shape[0], active.shape[0], point.shape[1]
    sizes_l[0], sizes_l[1] = m, k_active
    for c in range(m):
        body_a_l[c], body_b_l[c], gap_l[c] = a[c], b[c], gap[c]
        friction_l[c], restitution_l[c] = friction[c], restitution[c]
        for d in range(3):
            ids_l[c, d] = ids[c, d]
        for d in range(dim):
            point_l[c, d] = point[c, d]
            for e in range(dim):
                frame_l[c, d, e] = frame[c, d, e]
    for k in range(k_active):
        active_l[k] = active[k]
        for i in range(4):
            for d in range(dim):
                per_active_l[i, k, d] = per_active[i, k, d]


class CompiledSteps:
    """The compiled steps of one scene's run: the arguments of :func:`plain_steps`, built
    once, and its buffers (warm start, last step's contacts), grown when full.

    Use :meth:`of` (None where the scene needs the general step every step).
    ``run(data, n)`` takes up to ``n`` steps of ``data``'s one scene, recorded by
    ``builder``, and makes ``data.warm`` a view of the warm-start buffers (rewritten in
    place by the next compiled step).
    """

    def __init__(self, k: _Constants, builder: ResultBuilder) -> None:
        model, settings = k.model, k.settings
        self.builder = builder
        self.dt, self.midpoint, self.driven = float(k.dt), bool(k.midpoint), bool(k.driven)
        dim = model.dim
        n, nq, nv = len(model.bodies), (3 if dim == 2 else 7), (3 if dim == 2 else 6)
        self._no_drive = (np.zeros((0, n, nq)), np.zeros((0, n, nv)), np.zeros((0, n, nq)),
                          model.prescribed_index, False)
        self.flight = (model.dynamic_index, model.dof_of_body, model.mass, k.mass_diagonal, float(model.gravity),
                       model.radius, k.dynamic_inertia, int(model.n_dofs))
        laws = (model.law_material, model.law_table, model.law_keys, model.law_values)
        if dim == 2:
            local, owner, start = model.polygons
            self.polygons, self.polyhedra = (local, owner, start, model.dynamic, *laws), None
        else:
            p = model.polyhedra
            self.polygons = None
            self.polyhedra = (p._local, p._owner, p._plane_offsets, p.vertex_start, p.face_start, p.edge_start,
                              p.family_start, p.radius, p.face_vertices, p.side_start, p.edges, p.edge_family,
                              p.vertex_faces, p.vertex_face_start, model.dynamic, *laws)
        rows = k.plain_rows(1)
        early_sweep = EARLY_DETECTION_SWEEP * model.thinnest if k.midpoint else np.inf
        self.stage = (rows.dt, rows.tolerance, rows.pace, rows.localizing, rows.deferring, rows.watching,
                      rows.watch_ids, rows.watch_first, float(k.dt), float(k.margin), float(k.impact_speed),
                      float(k.dead_band), float(k.noise), int(k.fast), bool(k.midpoint), float(k.theta),
                      float(k.activation), float(early_sweep), _TURN_PER_PIECE, float(k.overlap_check),
                      PENETRATION_TOLERANCE * model.smallest_radius, ENERGY_ROUND_OFF, float(builder.impact_speed),
                      builder.status_code(_CONVERGED_STATUS), builder.status_code("no contact"))
        solver = settings.solver
        self.solver = (float(solver.tol), bool(solver.exact), int(solver.max_fast))
        self.warm = self._warm_buffers(16, dim)
        self._view: WarmStarts | None = None
        self.last = self._last_buffers(64, dim)

    @classmethod
    def of(cls, k: _Constants, builder: ResultBuilder) -> "CompiledSteps | None":
        """The compiled steps of a scene of model ``k.model``, or None where every step takes
        the general path: more than ``ALL_PAIRS_BODIES`` bodies (detection with the broad
        phase in Python)."""
        if len(k.model.bodies) > ALL_PAIRS_BODIES:
            return None
        return cls(k, builder)

    def _drive(self, data: Data, n: int) -> tuple:
        """The ``drive`` of :func:`plain_steps` for the next ``n`` steps of ``data``: the motions
        evaluated at the times the general step evaluates them (``t + dt`` step after step,
        and ``t + dt / 2`` under the midpoint rule)."""
        if not self.driven:
            return self._no_drive
        times = np.cumsum(np.concatenate([data.t, np.full(n, self.dt)]))  # t_k + dt, added step after step
        rows = np.zeros(n, dtype=np.int64)
        q_ends, v_ends = np.repeat(data.q, n, axis=0), np.repeat(data.v, n, axis=0)
        data.drives.write(rows, times[1:], q_ends, v_ends)
        q_halves = self._no_drive[2]
        if self.midpoint:
            q_halves = np.repeat(data.q, n, axis=0)
            data.drives.write(rows, times[:-1] + 0.5 * self.dt, q_halves, np.repeat(data.v, n, axis=0))
        return q_ends, v_ends, q_halves, self._no_drive[3], True

    @staticmethod
    def _warm_buffers(rows: int, dim: int) -> tuple:
        return (np.zeros((rows, 3), dtype=np.int64), np.zeros((rows, dim)), np.zeros((rows, dim)),
                np.zeros(2, dtype=np.int64), np.zeros(1, dtype=np.bool_))

    @staticmethod
    def _last_buffers(rows: int, dim: int) -> tuple:
        return (np.zeros(rows, dtype=np.int64), np.zeros(rows, dtype=np.int64), np.zeros((rows, dim)),
                np.zeros((rows, dim, dim)), np.zeros(rows), np.zeros(rows), np.zeros(rows),
                np.zeros((rows, 3), dtype=np.int64), np.zeros(rows, dtype=np.int64), np.zeros((4, rows, dim)),
                np.zeros(2, dtype=np.int64))

    def _load(self, warm: WarmStarts) -> None:
        """Copy the warm start ``warm`` (one scene) into the buffers."""
        rows = len(warm.ids)
        if rows > len(self.warm[0]):
            self.warm = self._warm_buffers(2 * rows, warm.impulses.shape[1])
        ids, impulses, trend, first, trended = self.warm
        ids[:rows], impulses[:rows], trend[:rows] = warm.ids, warm.impulses, warm.trend
        first[:], trended[:] = (0, rows), warm.trended[:1]

    def _grow(self) -> None:
        """Double every buffer (the warm start kept)."""
        ids, impulses, trend, first, trended = self.warm
        rows = int(first[1])
        dim = impulses.shape[1]
        self.warm = self._warm_buffers(2 * len(ids), dim)
        for new, old in zip(self.warm, (ids[:rows], impulses[:rows], trend[:rows], first, trended)):
            new[:len(old)] = old
        self.last = self._last_buffers(2 * len(self.last[0]), dim)
        self.builder.reserve(len(self.builder.times), 2 * len(self.builder.impact_time))
        self._view = None

    def run(self, data: Data, n: int) -> tuple[int, int]:
        """Up to ``n`` steps of ``data`` (one scene); returns (steps taken, the code of
        :func:`plain_steps`: DONE, GENERAL or OVERLAP)."""
        if data.warm is not self._view:
            self._load(data.warm)
            self._view = None
        builder = self.builder
        if self.driven:
            n = min(n, _DRIVEN_STEPS)
        builder.reserve(n, 0)
        drive = self._drive(data, n)
        taken = 0
        while True:
            done, code = plain_steps(n - taken, data.t, data.q, data.v, self.warm, self.last, builder.arrays(),
                                     drive, self.flight, self.polygons, self.polyhedra, self.stage, self.solver)
            taken += done
            if self.driven:
                drive = (drive[0][done:], drive[1][done:], drive[2][done:] if self.midpoint else drive[2],
                         *drive[3:])
            if code != FULL:
                break
            self._grow()
        rows = int(self.warm[3][1])
        view = self._view
        if view is None or len(view.ids) != rows:
            ids, impulses, trend, first, trended = self.warm
            view = self._view = WarmStarts(ids[:rows], impulses[:rows], trend[:rows], first, trended)
        data.warm = view
        if taken:
            builder.was_active(view.ids)
        return taken, code

    def output(self) -> StepOutput:
        """What the last compiled step produced (copies)."""
        a, b, point, frame, gap, friction, restitution, ids, active, per_active, sizes = self.last
        m, k = int(sizes[0]), int(sizes[1])
        report: StepReport = self.builder.report(self.builder.count - 1)
        contacts = Contacts(body_a=a[:m].copy(), body_b=b[:m].copy(), point=point[:m].copy(), frame=frame[:m].copy(),
                            gap=gap[:m].copy(), friction=friction[:m].copy(), restitution=restitution[:m].copy(),
                            ids=ids[:m].copy())
        return StepOutput(report=report, contacts=contacts, active=active[:k].copy(),
                          impulses=per_active[0, :k].copy(), u_before=per_active[1, :k].copy(),
                          u_after=per_active[2, :k].copy(), solved_at=np.full(k, report.t),
                          driven=per_active[3, :k].copy())
