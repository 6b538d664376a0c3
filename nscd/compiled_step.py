"""Steps of one small scene in one compiled call, recorded in place.

A run (:class:`~nscd.stepper.Simulator`, :func:`~nscd.stepper.simulate`, a batch's) of scenes
of at most ``ALL_PAIRS_BODIES`` bodies takes its steps here:
:func:`plain_steps` runs up to ``n`` steps in one compiled call, each sub-step the composition of
:func:`nscd.stepper._advance`'s compiled stages in the same order (free flight, detection,
the warm starts, :func:`~nscd.stepper._assemble`, the solver's compiled fast path
:func:`nscd.solver.proximal.fast_path` (the Newton, then the proximal point and its polish on
a problem the Newton does not accept), :func:`~nscd.stepper._solution`,
:func:`~nscd.stepper._finish` and, where the predicted end-of-step overlap may hide a deep
one, detection again in the end configuration, as :func:`nscd.stepper._end_overlaps`), and
records each step into the arrays of the run's
:class:`~nscd.result.ResultBuilder` with :meth:`~nscd.result.ResultBuilder.add`'s formulas.
A step that stops at an impact goes on under the plan of :mod:`nscd.event_plan` (approach,
corrections, impact, rest: event location's sub-steps, each through the same stages), as the
general step's does. The kernels are the stepper's own, called, not re-expressed: the step of
a scene is the same floating-point operations on either path.

It hands the step back to Python, before changing anything, where the general step
(:func:`nscd.stepper.step`) is needed: a body turning fast (the step in pieces), a scene
seen early (midpoint rule), an impact located in the step of a scene with a driven body
whose motion is not one of the ready motions (a Python object, evaluated beforehand on the
grid of whole steps; the ready motions' formulas are evaluated inside the call, at every
sub-step's time, :func:`nscd.state.driven_poses`), a contact problem the compiled fast path
does not take (beyond ``fast_path_unknowns``) or accept (neither the Newton nor the proximal
point; the solver's other routes), also among the problems solved again where a solution
reverses a slip or creates energy (9b, solved again here by
:func:`nscd.stepper._dissipative_next`'s plan as the general step does); and where a buffer
is full (grown, then called again). It also returns after a step whose overlap warns.
"""
from __future__ import annotations

import math
import operator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from nscd._jit import njit, njit_helper
from nscd.contact.detect import ALL_PAIRS_BODIES, _detect_small_polyhedra, _detect_small_scenes
from nscd.contact.frames import Contacts
from nscd.impact_law import NO_TRIAL, dissipation
from nscd.result import ResultBuilder, StepReport, driven_work
from nscd.solver import core, proximal, small
from nscd.state import (Data, WarmStarts, _driven_arrays, _find_ids, _matched_rows, driven_poses, scaled_impulses,
                        summed_impulses, trends)
from nscd.event_plan import (FIELDS, FINISHED, LEFT, PHASE, TURN_PER_PIECE, largest_spin, plan_receive, plan_request,
                             plan_start)
from nscd.stepper import (_CONVERGED_STATUS, _CREATES_ENERGY, _POLISHED_STATUS, EARLY_DETECTION_SWEEP, ENERGY_ROUND_OFF,
                          PENETRATION_TOLERANCE, StepOutput, _assemble, _Constants, _deepest_overlaps,
                          _dense_problem, _dissipative_next, _dissipative_plan, _finish, _flight_2d, _flight_3d,
                          _impact_speed, _previous_impulses, _restitution_offsets, _solution,
                          _velocities_after)

#: What :func:`plain_steps` says after its steps: all taken; the next needs the general step;
#: a buffer is full (nothing of the next step written); the last step taken overlaps beyond
#: the warning threshold.
DONE, GENERAL, FULL, OVERLAP = 0, 1, 2, 3

#: Steps of a scene with a driven body posed in Python per compiled call at most: their motions
#: are evaluated beforehand, and those of the steps after a step handed back to Python are not used.
_DRIVEN_STEPS = 32


@njit(nogil=True)
def plain_steps(n_steps, rows, t, q, v, warm, last, record, drive, flight, polygons, polyhedra, stage, solver, taken,
                codes):
    """Up to ``n_steps[b]`` plain steps of each scene ``b`` of ``rows``, in place; each scene's
    steps taken into ``taken[b]`` and the code of its last return (DONE, GENERAL, FULL,
    OVERLAP) into ``codes[b]``.

    The scenes are independent (no value mixes scenes), so the work may be split over threads
    by ``rows`` (the GIL is released). Every array has a leading scene axis of B scenes: ``t``
    (B,), ``q`` (B, n, nq), ``v`` (B, n, nv), the data's state, advanced in place. ``warm``:
    the warm starts, ``(ids (B, w, 3), impulses (B, w, dim), trend (B, w, dim), first (B, 2),
    trended (B, 2))`` with room for ``w`` rows a scene (rows ``first[b, 0]:first[b, 1]``
    used; ``trended[b]``: :class:`~nscd.state.WarmStarts`' ``trended`` and ``linear`` of the
    scene), replaced in place by each step's. ``last``: each scene's last step's contacts
    (:class:`Contacts`' fields body_a, body_b, point, frame, gap, friction, restitution, ids),
    active set, per-active arrays (B, 4, k, dim) of :func:`~nscd.stepper._finish`, their
    numbers (B, 2) and the end times of their sub-steps (B, k), s. ``record``: the arrays of
    :meth:`nscd.result.ResultBuilder.arrays`, each
    with a leading scene axis. ``drive``: the fixed and driven bodies' poses and velocities at
    the end of each of the scene's next steps and their poses at its midpoint (B, steps, n,
    nq), (B, steps, n, nv), (B, steps, n, nq) (:meth:`nscd.state.Drives.write`), their
    indices, whether any body is driven (if not, the arrays are not read: the fixed bodies
    keep their pose, at rest), and the posing of the driven bodies by their ready motions'
    formulas (``posed``, then the arrays of :class:`nscd.state.Drives`' ``compiled``: if
    ``posed``, the poses are computed in the call at every sub-step and the arrays before it
    are not read).
    ``flight``: dynamic_index, dof_of_body, mass, mass diagonal
    (2D), gravity, radius, the dynamic bodies' own inertias (3D), n_dofs. ``polygons`` (2D,
    else None) or ``polyhedra`` (3D, else None): the model's shapes and contact laws as the
    detection kernel takes them. ``stage``: the constants of the stages and of the plan
    of a step's sub-steps (:func:`nscd.stepper._constants`). ``solver``: the settings of the
    solver's compiled fast path (:func:`nscd.solver.core.fast_path_settings`: tol, tol_relative,
    exact cone, max_fast, max_proximal, max_polish, proximal_unknowns).
    """
    ids, impulses, trend, first, trended = warm
    body_a, body_b, point, frame, gap, friction, restitution, ids_l, active, per_active, sizes, solved_at = last
    (times, qs, vs, dissipated, work_input, iterations, merit, n_contacts, n_active, penetration, status, converged,
     impact_time, impact_a, impact_b, impact_point, impact_before, impact_after, impact_impulse, counts) = record
    q_ends, v_ends, q_halves, prescribed_index, driven, posing = drive
    posed, index, q0, direction, kinds, factors, pars, tables, lengths = posing
    for r in range(rows.shape[0]):
        b = rows[r]
        taken[b], codes[b] = _scene_steps(
            n_steps[b], t[b:b + 1], q[b:b + 1], v[b:b + 1], (ids[b], impulses[b], trend[b], first[b], trended[b]),
            (body_a[b], body_b[b], point[b], frame[b], gap[b], friction[b], restitution[b], ids_l[b], active[b],
             per_active[b], sizes[b], solved_at[b]),
            (times[b], qs[b], vs[b], dissipated[b], work_input[b], iterations[b], merit[b], n_contacts[b], n_active[b],
             penetration[b], status[b], converged[b], impact_time[b], impact_a[b], impact_b[b], impact_point[b],
             impact_before[b], impact_after[b], impact_impulse[b], counts[b]),
            (q_ends[b], v_ends[b], q_halves[b]), prescribed_index, driven,
            (posed, index, q0[b], direction, kinds[b], factors[b], pars[b], tables[b], lengths[b]), flight, polygons,
            polyhedra, stage, solver)


@njit_helper(inline=True)
def _scene_steps(n_steps, t, q, v, warm, last, record, drive, prescribed_index, driven, posing, flight, polygons,
                 polyhedra, stage, solver):
    """Up to ``n_steps`` steps of one scene (``t`` (1,), ``q`` (1, n, nq), ``v`` (1, n, nv)
    and its views of :func:`plain_steps`' arrays), in place; returns (steps taken, code).

    Each step is the general step's (:func:`nscd.stepper.step`) of one scene: a plain sub-step,
    and where it stops at an impact the sub-steps of the plan of :mod:`nscd.event_plan`
    (approach, corrections, impact, rest), each through the same stages; the step's state,
    warm start and record are written only once it is whole (a step handed back leaves
    nothing changed)."""
    ids_w, impulses_w, trend_w, first_w, trended_w = warm
    q_ends, v_ends, q_halves = drive
    posed, index, q0, direction, kinds, factors, pars, tables, lengths = posing
    (times, qs, vs, dissipated, work_input, iterations, merit, n_contacts, n_active, penetration, status, converged,
     impact_time, impact_a, impact_b, impact_point, impact_before, impact_after, impact_impulse, counts) = record
    dynamic_index, dof_of_body, mass, mass_diagonal, gravity, radius, inertia_body, n_dofs = flight
    (step_dt, margin, impact_speed, dead_band, noise, fast, midpoint, theta, activation, early_sweep, turn_limit,
     overlap_check, warn_overlap, energy_round_off, record_speed, converged_code, polished_code, no_contact_code,
     fixed_tolerance, smallest_radius, localize, localize_large, dense) = stage
    tol, tol_relative, exact, max_fast, max_proximal, max_polish, proximal_unknowns = solver
    S, n = q.shape[0], q.shape[1]
    dim = impulses_w.shape[1]
    early = np.zeros(S, dtype=np.bool_)
    touching = 0.0  # the margin of the fresh detection of an overlap
    # one sub-step's rows (nscd.stepper._Rows of one scene), filled from the plan's requests
    dt, tolerance, pace = np.empty(S), np.empty(S), np.empty(S)
    localizing, deferring, watching = np.empty(S, dtype=np.bool_), np.empty(S, dtype=np.bool_), np.empty(
        S, dtype=np.bool_)
    watch_first = np.zeros(S + 1, dtype=np.int64)
    plan = np.empty(FIELDS)
    v_spare = np.empty(v.shape[1:])  # the midpoint's driven velocities, not used (q_M only)
    for step in range(n_steps):
        # the general step's own conditions (nscd.stepper.step, _Midpoint.seen_at): a body
        # turning fast (the step in pieces), a scene seen early
        # the sub-step's start; the latest impulses (the step before's, then each sub-step's)
        t_s, q_s, v_s = t.copy(), q.copy(), v.copy()
        spin = largest_spin(v_s)[0]
        if spin * step_dt > turn_limit:
            return step, GENERAL
        plan_start(plan, step_dt, spin)
        latest_ids, latest_impulses, latest_first = ids_w, impulses_w, first_w
        watch_ids = np.zeros((0, 3), dtype=np.int64)  # the contacts of the impact located
        planned = False  # the plain sub-step stopped at an impact
        # the step's sub-steps end to end (nscd.stepper.StepOutput.joined) in the buffers ``last``:
        # their contacts and active ones so far, and the report's counts, sums and last values
        m_all, k_all = 0, 0
        parts, m_most, k_most, iterations_sum, merit_most, status_last, overlap_last = 0, 0, 0, 0, 0.0, 0, 0.0
        while plan[PHASE] != FINISHED:
            length, tolerance[0], pace[0], localize_r, deferring[0], watch, factor = plan_request(
                plan, fixed_tolerance, gravity, smallest_radius, midpoint, theta)
            dt[0], watching[0] = length, watch
            # a scene whose step before had more unknowns than the dense routes take is not
            # located (Settings.localize_large; nscd.stepper._Rows.unlocated)
            localizing[0] = localize_r and localize and (localize_large
                                                         or (latest_first[1] - latest_first[0]) * dim <= dense)
            watch_first[1] = watch_ids.shape[0] if watch else 0
            start_impulses = latest_impulses if factor == 1.0 else scaled_impulses(latest_impulses, factor)
            # 1. prescribe: the driven bodies posed at the sub-step's end by their ready motions'
            # formulas (nscd.state.driven_poses), or else evaluated in Python beforehand for whole
            # steps (a driven scene's impact is then handed back)
            q_next, v_next = q_s.copy(), v_s.copy()
            if driven and posed:
                driven_poses(q_next[0], v_next[0], t_s[0] + dt[0], index, q0, direction, kinds, factors, pars, tables,
                             lengths)
            elif driven:
                for i in prescribed_index:
                    for j in range(q.shape[2]):
                        q_next[0, i, j] = q_ends[step, i, j]
                    for j in range(v.shape[2]):
                        v_next[0, i, j] = v_ends[step, i, j]
            # 5. free flight, the sweeps of 3. and 2. configure
            # 2D or 3D: the branch of the other dimension is pruned at compilation (its shapes are None)
            if polyhedra is None and polygons is not None:
                v_free, sweep, fastest, q_c = _flight_2d(q_s, v_s, v_next, dt, dynamic_index, dof_of_body, mass,
                                                         mass_diagonal, gravity, radius, midpoint)
                inverse_blocks = np.zeros((S, 0, 6, 6))
            if polygons is None and polyhedra is not None:
                v_free, inverse_blocks, sweep, fastest, q_c = _flight_3d(q_s, v_s, v_next, dt, dynamic_index,
                                                                         dof_of_body, mass, gravity, inertia_body,
                                                                         radius, midpoint)
            if midpoint and driven and posed:  # the hook: the driven bodies at the midpoint of the step
                driven_poses(q_c[0], v_spare, t_s[0] + 0.5 * dt[0], index, q0, direction, kinds, factors, pars,
                             tables, lengths)
            elif midpoint and driven:
                for i in prescribed_index:
                    for j in range(q.shape[2]):
                        q_c[0, i, j] = q_halves[step, i, j]
            if midpoint and fastest > early_sweep:
                return step, GENERAL
            # 3. detect
            scene, a, b, point, frame, gap, ids, friction, restitution = _detect(q_c, sweep.reshape(S * n), margin,
                                                                                 polygons, polyhedra)
            # 4, 6-8. warm starts, Jacobian, active set, event location, the small problems
            first, previous = _previous_impulses(ids, scene, S, latest_ids, start_impulses, latest_first)
            (blocks, velocities, closing_time, closing, n_closing, active, active_first, offset, which, sizes, W,
             q_free, mu, r0, H, MinvHT) = _assemble(
                a, b, point, frame, gap, ids, restitution, friction, scene, first, previous, q_c, v_s, v_next, v_free,
                early, dt, tolerance, pace, localizing, deferring, watching, watch_ids, watch_first, dof_of_body,
                n_dofs, mass_diagonal, inverse_blocks, impact_speed, gravity, dead_band, noise, fast, midpoint, theta,
                activation)
            if n_closing:  # 7. an impact located: the scene stops there, its step goes on under the plan
                if driven and not posed:
                    return step, GENERAL
                n_watch = 0
                for c in range(closing.shape[0]):
                    n_watch += closing[c]
                watch_ids = np.empty((n_watch, 3), dtype=np.int64)
                w = 0
                for c in range(closing.shape[0]):
                    if closing[c]:
                        for d in range(3):
                            watch_ids[w, d] = ids[c, d]
                        w += 1
                plan_receive(plan, closing_time[0], 0.0, 0, midpoint)
                planned = True
                continue
            # 9. solve (nscd.solver.core.newton_batch's kernel call: the Newton, the proximal point
            # and its polish)
            r, u = np.empty(q_free.shape), np.empty(q_free.shape)
            merit_p, info = np.empty(sizes.size), np.empty((sizes.size, 5), dtype=np.int64)
            if sizes.size:
                proximal.fast_path(W, q_free, mu, sizes, dim, r0, tol, tol_relative, exact, max_fast, max_proximal,
                                   max_polish, proximal_unknowns, r, u, merit_p, info)
            impulses, u_after, v_dyn_next, left, n_left = _solution(
                H, MinvHT, r, sizes, which, info, active, active_first, v_free, velocities, restitution,
                energy_round_off, noise)
            # 9b: a solution that reverses a slip or creates energy solved again (by the fast path
            # here; the general step where it does not accept one of those problems)
            if n_left and not (left[0] == _CREATES_ENERGY and _dissipative_solution(
                    impulses, u_after, v_dyn_next, info, merit_p, active, active_first, offset, blocks, a, b,
                    restitution, friction, previous, velocities, dof_of_body, n_dofs, mass_diagonal, inverse_blocks,
                    v_free, n, noise, energy_round_off, solver)):
                return step, GENERAL
            # 10. integrate
            q_end, v_end, overlap, check, n_check, per_active = _finish(
                q_s, q_c, q_c, v_s, q_next, v_next, v_dyn_next, a, b, point, frame, gap, scene, first, dt, early,
                active, impulses, u_after, velocities, dynamic_index, radius, overlap_check, midpoint, theta)
            if n_check:  # the overlap detected afresh in the end configuration (nscd.stepper._end_overlaps)
                found = _detect(q_end, np.zeros(S * n), touching, polygons, polyhedra)
                overlap[0] = 0.0
                _deepest_overlaps(overlap, found[0], found[5])
            t_end = t_s[0] + dt[0]
            # the sub-step's output after the step's others (StepOutput.joined)
            m, k_active = gap.shape[0], active.shape[0]
            if m_all + m > last[0].shape[0] or k_all + k_active > last[8].shape[0]:
                return step, FULL
            _append_last(last, m_all, k_all, a, b, point, frame, gap, friction, restitution, ids, active, per_active,
                         t_end)
            m_all, k_all = m_all + m, k_all + k_active
            # the report: the counts and merit the largest, the iterations summed, the status and
            # overlap the last sub-step's (every sub-step here converged); a problem's status and
            # iterations as the general step reports them (nscd.stepper._advance: polished by the
            # proximal point's polish or converged, its Newton iterations summed)
            m_most, k_most = max(m_most, m), max(k_most, k_active)
            if which.shape[0]:
                status_last = polished_code if info[0, 0] == small.PROXIMAL_POLISHED else converged_code
                iterations_sum += info[0, 1] + info[0, 3] + info[0, 4]
                merit_most = merit_p[0] if parts == 0 else max(merit_most, merit_p[0])
            else:
                status_last = no_contact_code
                merit_most = 0.0 if parts == 0 else max(merit_most, 0.0)
            overlap_last = overlap[0]
            parts += 1
            t_s[0] = t_end
            q_s, v_s = q_end, v_end
            # the spin at the end sizes the next piece, if any is left (as _Plan.receive); the latest
            # impulses warm-start the plan's next sub-step (none after the last)
            spin = largest_spin(v_s)[0] if plan[LEFT] > 0.0 else 0.0
            if plan_receive(plan, math.nan, spin, k_active, midpoint) and plan[PHASE] != FINISHED:
                latest_ids = np.empty((k_active, 3), dtype=np.int64)
                for k in range(k_active):
                    for d in range(3):
                        latest_ids[k, d] = ids[active[k], d]
                latest_impulses = np.ascontiguousarray(per_active[0])
                latest_first = np.zeros(2, dtype=np.int64)
                latest_first[1] = k_active
        (a_j, b_j, point_j, _, _, _, _, ids_j, active_j, per_active_l, sizes_l, solved_at_j) = last
        m, k_active = m_all, k_all
        sizes_l[0], sizes_l[1] = m, k_active
        per_active_j = _first_active(per_active_l, k_active)
        # impacts (ResultBuilder.add): active, approaching faster than record_speed, not active
        # in the step before (the warm start lists the step before's active contacts)
        new_ids = np.empty((k_active, 3), dtype=np.int64)
        for k in range(k_active):
            for d in range(3):
                new_ids[k, d] = ids_j[active_j[k], d]
        _, was_active = _find_ids(ids_w[first_w[0]:first_w[1]], new_ids)
        impact = np.zeros(k_active, dtype=np.bool_)
        n_impacts = 0
        for k in range(k_active):
            impact[k] = per_active_j[1, k, 0] < -record_speed and not was_active[k]
            n_impacts += impact[k]
        # the warm start handed on: a planned step's impulses summed over its sub-steps by id
        # (nscd.stepper._Plan.step_impulses: the sub-steps here are small problems)
        if planned:
            warm_ids, warm_impulses = summed_impulses(new_ids, np.ascontiguousarray(per_active_j[0]))
        else:
            warm_ids, warm_impulses = new_ids, np.ascontiguousarray(per_active_j[0])
        k_warm = warm_ids.shape[0]
        row = counts[0]
        if row >= times.shape[0] or counts[1] + n_impacts > impact_time.shape[0] or k_warm > ids_w.shape[0]:
            return step, FULL
        # its trend since the step before's (WarmStarts.followed_by)
        bounds = np.array([0, k_warm])
        trend, linear = trends(warm_impulses, bounds, _matched_rows(warm_ids, bounds, ids_w, first_w), impulses_w,
                               trend_w, trended_w[:1])
        trended_w[0], trended_w[1] = first_w[1] > first_w[0], linear[0]
        first_w[0], first_w[1] = 0, k_warm
        for k in range(k_warm):
            for d in range(3):
                ids_w[k, d] = warm_ids[k, d]
            for d in range(dim):
                impulses_w[k, d] = warm_impulses[k, d]
                trend_w[k, d] = trend[k, d]
        # the new state
        t[0] = t_s[0]
        for i in range(n):
            for j in range(q.shape[2]):
                q[0, i, j] = q_s[0, i, j]
            for j in range(v.shape[2]):
                v[0, i, j] = v_s[0, i, j]
        # the recording (ResultBuilder.add)
        lost, _ = dissipation(per_active_j[0], per_active_j[1], per_active_j[2])
        work = driven_work(per_active_j[0], per_active_j[3])
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
        n_contacts[j], n_active[j], penetration[j], converged[j] = m_most, k_most, overlap_last, True
        status[j], iterations[j], merit[j] = status_last, iterations_sum, merit_most
        for k in range(k_active):
            if impact[k]:
                c, e = active_j[k], counts[1]
                counts[1] = e + 1
                impact_time[e], impact_a[e], impact_b[e] = solved_at_j[k], a_j[c], b_j[c]
                for d in range(dim):
                    impact_point[e, d] = point_j[c, d]
                impact_before[e], impact_after[e] = per_active_j[1, k, 0], per_active_j[2, k, 0]
                impact_impulse[e] = per_active_j[0, k, 0]
        if overlap_last > warn_overlap:
            return step + 1, OVERLAP
    return n_steps, DONE


@njit_helper
def _first_active(per_active, k):
    """The first ``k`` rows of the per-active arrays ``per_active`` (4, rows, dim), a new
    C-contiguous array (4, k, dim)."""
    out = np.empty((4, k, per_active.shape[2]))
    for i in range(4):
        for c in range(k):
            for d in range(per_active.shape[2]):
                out[i, c, d] = per_active[i, c, d]
    return out


@njit_helper(inline=True)
def _detect(q, grow, margin, polygons, polyhedra):
    """Stage 3 of a scene (:func:`nscd.contact.detect.detect_batch` of scenes of at most
    ``ALL_PAIRS_BODIES`` bodies): its contacts within ``margin`` (m) in the configuration
    ``q`` (1, n, nq), each body's box grown by ``grow`` (n,), m. 2D or 3D: the branch of the
    other dimension is pruned at compilation (its shapes are None)."""
    if polyhedra is None and polygons is not None:
        local, owner, start, dynamic, material, table, keys, values = polygons
        found = _detect_small_scenes(q, grow, local, owner, start, dynamic, margin, material, table, keys, values)
    if polygons is None and polyhedra is not None:
        (local, owner, plane_offsets, vertex_start, face_start, edge_start, family_start, shape_radius, face_vertices,
         side_start, edges, edge_family, vertex_faces, vertex_face_start, dynamic, material, table, keys,
         values) = polyhedra
        found = _detect_small_polyhedra(q, grow, local, owner, plane_offsets, vertex_start, face_start, edge_start,
                                        family_start, shape_radius, face_vertices, side_start, edges, edge_family,
                                        vertex_faces, vertex_face_start, dynamic, margin, material, table, keys,
                                        values)
    return found


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
def _dissipative_solution(impulses, u_after, v_dyn_next, info, merit, active, active_first, offset, blocks, body_a,
                          body_b, restitution, friction, previous, velocities, dof_of_body, n_dofs, mass_diagonal,
                          inverse_blocks, v_free, n_bodies, noise, round_off, solver):
    """9b of one scene's small problem in compiled code: solved again, one problem after another
    as :func:`nscd.stepper._dissipative_next` asks (the offsets of reversing joints, the
    restitution scaled), each assembled by :func:`nscd.stepper._dense_problem` and solved by
    the fast path (:func:`nscd.solver.proximal.fast_path`, as :func:`nscd.solver.core.solve`
    solves it, from the same warm start), its velocities by
    :func:`nscd.stepper._velocities_after`: the general step's 9b (:func:`nscd.stepper._solve_left`)
    with the same floating-point operations. The solution kept replaces the scene's
    ``impulses``, ``u_after`` (its active rows), ``v_dyn_next[0]``, ``info[0]`` and
    ``merit[0]``; returns True, or False, with nothing changed, where the fast path does not
    accept one of those problems (the general step's other routes then solve it)."""
    tol, tol_relative, exact, max_fast, max_proximal, max_polish, proximal_unknowns = solver
    u_k, w_next = velocities[0], velocities[1]
    a0, a1 = active_first[0], active_first[1]
    idx = active[a0:a1]
    k, dim = a1 - a0, impulses.shape[1]
    size = k * dim
    mu, start = np.empty((1, k)), np.empty((1, size))
    bounce = _restitution_offsets(idx, restitution, u_k)
    for i in range(k):
        c = idx[i]
        mu[0, i] = friction[c]
        for d in range(dim):
            start[0, i * dim + d] = previous[c, d]
    sizes = np.full(1, size)
    r, u, merit_s, info_s = np.empty((1, size)), np.empty((1, size)), np.empty(1), np.empty((1, 5), dtype=np.int64)
    solution_impulses, solution_u = impulses[a0:a1].copy(), u_after[a0:a1].copy()
    solution_v, solution_info, solution_merit = v_dyn_next[0].copy(), info[0].copy(), merit[0]
    kept = (solution_impulses, solution_u, solution_v, solution_info, solution_merit)
    plan = _dissipative_plan()
    while True:
        lam, keep = _dissipative_next(plan, idx, u_k, w_next, restitution, body_a, body_b, n_bodies,
                                      offset[a0:a1], solution_impulses, solution_u, noise, round_off)
        if keep:
            kept = (solution_impulses, solution_u, solution_v, solution_info, solution_merit)
        if lam == NO_TRIAL:
            break
        H, MinvHT, W, q = _dense_problem(blocks, idx, body_a, body_b, dof_of_body, n_dofs, mass_diagonal,
                                         inverse_blocks[0], v_free[0], offset[a0:a1])
        for i in range(k):
            q[i * dim] -= (1.0 - lam) * bounce[i, 0]  # the tangential rows: minus (1 - lam) 0.0, unchanged
        proximal.fast_path(W.reshape(1, size, size), q.reshape(1, size), mu, sizes, dim, start, tol, tol_relative,
                           exact, max_fast, max_proximal, max_polish, proximal_unknowns, r, u, merit_s, info_s)
        if info_s[0, 0] == small.NOT_ACCEPTED:
            return False
        solution_v, solution_u = _velocities_after(H, MinvHT, r[0], v_free[0], w_next, idx)
        solution_impulses = r[0].reshape(k, dim).copy()
        solution_info, solution_merit = info_s[0].copy(), merit_s[0]
    kept_impulses, kept_u, kept_v, kept_info, kept_merit = kept
    for i in range(k):
        for d in range(dim):
            impulses[a0 + i, d] = kept_impulses[i, d]
            u_after[a0 + i, d] = kept_u[i, d]
    for j in range(kept_v.shape[0]):
        v_dyn_next[0, j] = kept_v[j]
    for j in range(5):
        info[0, j] = kept_info[j]
    merit[0] = kept_merit
    return True


@njit_helper
def _append_last(last, m0, k0, a, b, point, frame, gap, friction, restitution, ids, active, per_active, t_end):
    """A sub-step's contacts, active set (as rows of the step's contacts, after its ``m0``
    earlier ones), per-active arrays and its end time ``t_end`` (s) into the buffers ``last``,
    after the step's ``m0`` contacts and ``k0`` active ones of its earlier sub-steps."""
    (body_a_l, body_b_l, point_l, frame_l, gap_l, friction_l, restitution_l, ids_l, active_l, per_active_l,
     _, solved_at_l) = last
    m, k_active, dim = gap.shape[0], active.shape[0], point.shape[1]
    for c in range(m):
        r = m0 + c
        body_a_l[r], body_b_l[r], gap_l[r] = a[c], b[c], gap[c]
        friction_l[r], restitution_l[r] = friction[c], restitution[c]
        for d in range(3):
            ids_l[r, d] = ids[c, d]
        for d in range(dim):
            point_l[r, d] = point[c, d]
            for e in range(dim):
                frame_l[r, d, e] = frame[c, d, e]
    for k in range(k_active):
        r = k0 + k
        active_l[r] = m0 + active[k]
        solved_at_l[r] = t_end
        for i in range(4):
            for d in range(dim):
                per_active_l[i, r, d] = per_active[i, k, d]


class CompiledSteps:
    """The compiled steps of the B scenes of a run: the arguments of :func:`plain_steps`,
    built once, and its buffers (warm starts, last steps' contacts, the recording), grown
    when full.

    Use :meth:`of` (None where the scenes need the general step every step).
    ``run(data, rows, n_steps)`` takes up to ``n_steps[b]`` steps of each scene ``b`` of
    ``rows``, recorded by its :class:`~nscd.result.ResultBuilder` (``builders``; None: not
    recorded), and makes ``data.warm`` the buffers' warm starts (a single scene: views,
    rewritten in place by the next compiled step). A single scene's builder is written in
    place; the scenes of a batch are recorded into arrays of their own, whose rows are then
    appended to each scene's builder. With ``threads`` > 1, the scenes of a call are dealt
    out to that many threads (:func:`plain_steps` releases the GIL).
    """

    def __init__(self, k: _Constants, n_scenes: int, builders: list[ResultBuilder] | None, threads: int = 1) -> None:
        model, settings = k.model, k.settings
        self.builders = builders
        self.n_scenes = n_scenes
        # a single recorded scene: its builder's arrays are written in place
        self.direct = builders is not None and n_scenes == 1
        self.threads = max(1, int(threads))
        self.dt, self.midpoint, self.driven = float(k.dt), bool(k.midpoint), bool(k.driven)
        self.dim = dim = model.dim
        self.shape = (len(model.bodies), model.nq, model.nv)
        n, nq, nv = self.shape
        self._no_posing = (False, *_driven_arrays(model, n_scenes, []))
        self._no_drive = (np.zeros((n_scenes, 0, n, nq)), np.zeros((n_scenes, 0, n, nv)),
                          np.zeros((n_scenes, 0, n, nq)), model.prescribed_index, False, self._no_posing)
        self._posed: tuple | None = None  # the drives posed by their formulas, and their `drive`
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
        early_sweep = EARLY_DETECTION_SWEEP * model.thinnest if k.midpoint else np.inf
        # the status codes of the recording: the same in every builder (registered first)
        codes = {(b.status_code(_CONVERGED_STATUS), b.status_code(_POLISHED_STATUS), b.status_code("no contact"))
                 for b in builders or []}
        (converged, polished, no_contact), = codes or {(0, 1, 2)}
        self.stage = (float(k.dt), float(k.margin), float(k.impact_speed), float(k.dead_band), float(k.noise),
                      int(k.fast), bool(k.midpoint), float(k.theta), float(k.activation), float(early_sweep),
                      TURN_PER_PIECE, float(k.overlap_check), PENETRATION_TOLERANCE * model.smallest_radius,
                      ENERGY_ROUND_OFF, float(_impact_speed(settings, model, k.dt)), converged, polished, no_contact,
                      float(k.fixed_tolerance), float(model.smallest_radius), bool(k.localize),
                      bool(k.localize_large), int(k.dense))
        self.solver = core.fast_path_settings(settings.solver)
        self.warm = self._warm_buffers(16)
        self._view: WarmStarts | None = None  # the data's warm starts the buffers agree with...
        self._ahead = False  # ...but where the buffers are ahead of them (a batch's compiled steps)
        self.last = self._last_buffers(64)
        self._scratch: tuple | None = None  # a batch's recording (rows, impacts, arrays)
        self._direct: tuple | None = None  # the single builder's arrays and their views
        self.taken, self.codes = np.zeros(n_scenes, dtype=np.int64), np.zeros(n_scenes, dtype=np.int64)
        self._counts = np.zeros(n_scenes, dtype=np.int64)  # the steps each scene may take in a call
        self._single = _RepeatedCall(plain_steps)  # a single run's calls, with the same arguments step after step

    @classmethod
    def of(cls, k: _Constants, n_scenes: int, builders: list[ResultBuilder] | None,
           threads: int = 1) -> "CompiledSteps | None":
        """The compiled steps of ``n_scenes`` scenes of model ``k.model``, or None where every
        step takes the general path: more than ``ALL_PAIRS_BODIES`` bodies (detection with
        the broad phase in Python)."""
        if len(k.model.bodies) > ALL_PAIRS_BODIES:
            return None
        return cls(k, n_scenes, builders, threads)

    def _drive(self, data: Data, rows: np.ndarray, counts: np.ndarray) -> tuple:
        """The ``drive`` of :func:`plain_steps` for the next ``counts[b]`` steps of the scenes
        ``rows`` of ``data``: the motions evaluated at the times the general step evaluates them
        (``t + dt`` step after step, and ``t + dt / 2`` under the midpoint rule); where every
        driven body has a ready motion, its formulas, evaluated in the call at every sub-step."""
        if not self.driven:
            return self._no_drive
        if data.drives.everywhere:  # the same tuple call after call (see _RepeatedCall)
            if self._posed is None or self._posed[0] is not data.drives:
                self._posed = (data.drives, (*self._no_drive[:4], True, (True, *data.drives.compiled)))
            return self._posed[1]
        steps = int(counts[rows].max())
        times = np.full((len(rows), steps + 1), self.dt)
        times[:, 0] = data.t[rows]
        times = np.cumsum(times, axis=1)  # t_k + dt, added step after step
        at = np.repeat(rows, steps)
        n, nq, nv = self.shape
        q_ends, v_ends = np.empty((self.n_scenes, steps, n, nq)), np.empty((self.n_scenes, steps, n, nv))
        q, v = data.q[at], data.v[at]
        data.drives.write(at, times[:, 1:].ravel(), q, v)
        q_ends[rows], v_ends[rows] = q.reshape(-1, steps, n, nq), v.reshape(-1, steps, n, nv)
        q_halves = self._no_drive[2]
        if self.midpoint:
            q_halves = np.empty((self.n_scenes, steps, n, nq))
            q = data.q[at]
            data.drives.write(at, (times[:, :-1] + 0.5 * self.dt).ravel(), q, data.v[at])
            q_halves[rows] = q.reshape(-1, steps, n, nq)
        return q_ends, v_ends, q_halves, self._no_drive[3], True, self._no_posing

    def _warm_buffers(self, rows: int) -> tuple:
        B, dim = self.n_scenes, self.dim
        return (np.zeros((B, rows, 3), dtype=np.int64), np.zeros((B, rows, dim)), np.zeros((B, rows, dim)),
                np.zeros((B, 2), dtype=np.int64), np.zeros((B, 2), dtype=np.bool_))

    def _last_buffers(self, rows: int) -> tuple:
        B, dim = self.n_scenes, self.dim
        return (np.zeros((B, rows), dtype=np.int64), np.zeros((B, rows), dtype=np.int64), np.zeros((B, rows, dim)),
                np.zeros((B, rows, dim, dim)), np.zeros((B, rows)), np.zeros((B, rows)), np.zeros((B, rows)),
                np.zeros((B, rows, 3), dtype=np.int64), np.zeros((B, rows), dtype=np.int64),
                np.zeros((B, 4, rows, dim)), np.zeros((B, 2), dtype=np.int64), np.zeros((B, rows)))

    def _load(self, warm: WarmStarts, rows: np.ndarray | None = None) -> None:
        """Copy the warm starts of scenes ``rows`` (default: all) of ``warm`` into the buffers."""
        rows = np.arange(self.n_scenes) if rows is None else rows
        sizes = np.diff(warm.first)[rows]
        if sizes.max(initial=0) > self.warm[0].shape[1]:
            self._grow_warm(2 * int(sizes.max()))
        ids, impulses, trend, first, trended = self.warm
        owner = np.repeat(rows, sizes)
        at = np.arange(len(owner)) - np.repeat(np.cumsum(sizes) - sizes, sizes)
        picked = at + np.repeat(warm.first[rows], sizes)
        ids[owner, at], impulses[owner, at], trend[owner, at] = warm.ids[picked], warm.impulses[picked], warm.trend[
            picked]
        first[rows, 0], first[rows, 1], trended[rows, 0], trended[rows, 1] = 0, sizes, warm.trended[rows], warm.linear[
            rows]

    def _warm_starts(self, rows: np.ndarray | None = None) -> WarmStarts:
        """The buffers' warm starts: a single scene's as views of the buffers; in a batch, those
        of scenes ``rows`` (default: all), the other scenes' left empty."""
        ids, impulses, trend, first, trended = self.warm
        if self.n_scenes == 1:
            size = first.item(0, 1)
            view = self._view
            if view is not None and len(view.ids) == size and view.ids.base is ids:
                return view
            return WarmStarts(ids[0, :size], impulses[0, :size], trend[0, :size], first[0], trended[0, :1],
                              trended[0, 1:])
        sizes = np.zeros(self.n_scenes, dtype=np.int64)
        sizes[slice(None) if rows is None else rows] = first[slice(None) if rows is None else rows, 1]
        used = np.arange(ids.shape[1]) < sizes[:, None]
        bounds = np.zeros(self.n_scenes + 1, dtype=np.int64)
        np.cumsum(sizes, out=bounds[1:])
        return WarmStarts(ids[used], impulses[used], trend[used], bounds, trended[:, 0].copy(), trended[:, 1].copy())

    def sync(self, data: Data, rows: np.ndarray | None = None) -> None:
        """Make ``data.warm`` hold the warm starts of scenes ``rows`` (default: all) where the
        buffers are ahead of it (a batch's compiled steps leave it behind until asked; with
        ``rows``, the other scenes' are left empty)."""
        if self._ahead and data.warm is self._view:
            every = rows is None or len(rows) == self.n_scenes
            data.warm = self._view = self._warm_starts(None if every else rows)
            self._ahead = not every

    def taken_back(self, data: Data, rows: np.ndarray) -> None:
        """Scenes ``rows`` took a step by the general step, which replaced ``data.warm``: where
        the buffers are ahead of it for other scenes, its rows into the buffers (else the next
        compiled call loads it whole)."""
        if self._ahead:
            self._load(data.warm, rows)
            self._view = data.warm

    def _grow_warm(self, rows: int) -> None:
        """Room for ``rows`` warm-start rows a scene (the buffers' contents kept)."""
        old, self.warm = self.warm, self._warm_buffers(rows)
        for new, kept in zip(self.warm[:3], old[:3]):
            new[:, :kept.shape[1]] = kept
        self.warm[3][:], self.warm[4][:] = old[3], old[4]

    def _grow(self) -> None:
        """Double the warm-start and last-step buffers (their contents kept) and the room for impacts."""
        self._grow_warm(2 * self.warm[0].shape[1])
        self.last = self._last_buffers(2 * self.last[0].shape[1])
        if self.direct:
            builder = self.builders[0]
            builder.reserve(len(builder.times), 2 * len(builder.impact_time))
        else:
            rows, impacts, arrays = self._scratch
            self._scratch = (rows, 2 * impacts, arrays[:12] + tuple(_wider(a, 2 * impacts) for a in arrays[12:19])
                             + arrays[19:])

    def _record(self, rows: np.ndarray, steps: int) -> tuple:
        """The ``record`` of :func:`plain_steps` with room for ``steps`` more steps of each scene."""
        if self.direct:
            return self._direct_record(steps)
        if self._scratch is None or self._scratch[0] < steps + 1:
            self._scratch = self._scratch_arrays(steps + 1, 16 if self._scratch is None else self._scratch[1])
        arrays = self._scratch[2]
        counts = arrays[19]
        counts[rows, 0], counts[rows, 1] = 1, 0
        if self.builders is not None:  # the sums go on from each builder's last row
            for b in rows.tolist():
                builder = self.builders[b]
                arrays[3][b, 0], arrays[4][b, 0] = builder.dissipated[builder.count - 1], builder.work_input[
                    builder.count - 1]
        return arrays

    def _direct_record(self, steps: int) -> tuple:
        """:meth:`_record` of a single run, recorded straight into its builder: the builder's
        arrays (:meth:`~nscd.result.ResultBuilder.arrays`) as views with a scene axis of one,
        with room for ``steps`` more steps."""
        builder = self.builders[0]
        if builder.counts.item(0) + steps > builder.times.shape[0]:
            builder.reserve(steps, 0)
        arrays = builder.arrays()
        if self._direct is None or self._direct[0] is not arrays:
            self._direct = (arrays, tuple(a[None] for a in arrays))
        return self._direct[1]

    def _scratch_arrays(self, rows: int, impacts: int) -> tuple:
        """A batch's recording: ResultBuilder's arrays for each scene, with room for ``rows``
        state rows and ``impacts`` impacts."""
        B, dim = self.n_scenes, self.dim
        n, nq, nv = self.shape
        reports = tuple(np.zeros((B, rows), dtype=dtype) for _, dtype in ResultBuilder._REPORTS)
        return rows, impacts, (np.zeros((B, rows)), np.zeros((B, rows, n, nq)), np.zeros((B, rows, n, nv)),
                               np.zeros((B, rows)), np.zeros((B, rows)), *reports, np.zeros((B, impacts)),
                               np.zeros((B, impacts), dtype=np.int64), np.zeros((B, impacts), dtype=np.int64),
                               np.zeros((B, impacts, dim)), np.zeros((B, impacts)), np.zeros((B, impacts)),
                               np.zeros((B, impacts)), np.ones((B, 2), dtype=np.int64))

    def _call(self, counts: np.ndarray, rows: np.ndarray, data: Data, record: tuple, drive: tuple) -> None:
        """:func:`plain_steps` of ``rows``, dealt out to the threads."""
        args = (data.t, data.q, data.v, self.warm, self.last, record, drive, self.flight, self.polygons,
                self.polyhedra, self.stage, self.solver, self.taken, self.codes)
        chunks = min(self.threads, len(rows) // _SCENES_PER_THREAD) if self.threads > 1 else 1
        if chunks <= 1:
            plain_steps(counts, rows, *args)
            return
        parts = np.array_split(rows, chunks)
        others = [_thread_pool(chunks - 1).submit(plain_steps, counts, part, *args) for part in parts[1:]]
        plain_steps(counts, parts[0], *args)
        for future in others:
            future.result()

    def run(self, data: Data, rows: np.ndarray, n_steps: int | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Up to ``n_steps`` (an int, or one per scene (S,)) steps of scenes ``rows`` (S,) of
        ``data``; returns each one's steps taken and the code of :func:`plain_steps` (DONE,
        GENERAL or OVERLAP)."""
        if data.warm is not self._view:
            self._load(data.warm)
            self._view = data.warm
        counts = self._counts
        counts[rows] = n_steps
        if self.driven and not data.drives.everywhere:
            np.minimum(counts, _DRIVEN_STEPS, out=counts)
        record = self._record(rows, int(counts.max()) if self.n_scenes > 1 else int(counts[0]))
        self._call(counts, rows, data, record, self._drive(data, rows, counts))
        taken, codes = self.taken[rows], self.codes[rows]
        if FULL in codes:
            taken = self._after_full(data, rows, counts, taken)
            codes = self.codes[rows]
        counts[rows] = 0
        if self.n_scenes == 1:
            data.warm = self._view = self._warm_starts()
            if self.direct and taken[0]:
                self.builders[0].was_active(self._view.ids)
            return taken, codes
        self._ahead = True
        if self.builders is not None:
            self._append(rows, taken)
            ids, first = self.warm[0], self.warm[3]
            for b in rows[taken > 0].tolist():
                self.builders[b].was_active(ids[b, :first[b, 1]])
        return taken, codes

    def run_one(self, data: Data, n_steps: int) -> tuple[int, int]:
        """:meth:`run` of a single run's one scene with scalars (the per-step cost of
        ``Simulator.step``): up to ``n_steps`` steps; returns the steps taken and the code."""
        if data.warm is not self._view:
            self._load(data.warm)
            self._view = data.warm
        counts = self._counts
        steps = min(n_steps, _DRIVEN_STEPS) if self.driven and not data.drives.everywhere else n_steps
        counts[0] = steps
        self._single(counts, _SCENE, data.t, data.q, data.v, self.warm, self.last, self._record(_SCENE, steps),
                     self._drive(data, _SCENE, counts), self.flight, self.polygons, self.polyhedra, self.stage,
                     self.solver, self.taken, self.codes)
        taken, code = self.taken.item(0), self.codes.item(0)
        if code == FULL:
            taken, code = int(self._after_full(data, _SCENE, counts, self.taken[_SCENE])[0]), int(self.codes[0])
        counts[0] = 0
        if taken:
            data.warm = self._view = self._warm_starts()
            if self.direct:
                self.builders[0].was_active(self._view.ids)
        return taken, code

    def _after_full(self, data: Data, rows: np.ndarray, counts: np.ndarray, taken: np.ndarray) -> np.ndarray:
        """The scenes of ``rows`` whose buffers were full take their remaining steps once the
        buffers are grown; returns the steps each scene of ``rows`` took in all."""
        total = np.zeros(self.n_scenes, dtype=np.int64)
        total[rows] = taken
        counts[rows] -= taken
        calling = rows[self.codes[rows] == FULL]
        while len(calling):
            self._grow()
            record = self._record(np.zeros(0, dtype=np.int64), 0) if self.direct else self._scratch[2]
            self._call(counts, calling, data, record, self._drive(data, calling, counts))
            total[calling] += self.taken[calling]
            counts[calling] -= self.taken[calling]
            calling = calling[self.codes[calling] == FULL]
        return total[rows]

    def _append(self, rows: np.ndarray, taken: np.ndarray) -> None:
        """Append each scene's recorded steps to its builder."""
        arrays = self._scratch[2]
        counts = arrays[19]
        for b, k in zip(rows.tolist(), taken.tolist()):
            if not k:
                continue
            builder = self.builders[b]
            m = int(counts[b, 1])
            builder.reserve(k, m)
            c, e = builder.count, int(builder.counts[1])
            for name, a in zip(("times", "qs", "vs", "dissipated", "work_input"), arrays[:5]):
                getattr(builder, name)[c:c + k] = a[b, 1:k + 1]
            for (name, _), a in zip(ResultBuilder._REPORTS, arrays[5:12]):
                getattr(builder, name)[c - 1:c - 1 + k] = a[b, :k]
            for name, a in zip(("impact_time", "impact_a", "impact_b", "impact_point", "impact_before",
                                "impact_after", "impact_impulse"), arrays[12:19]):
                getattr(builder, name)[e:e + m] = a[b, :m]
            builder.counts[0], builder.counts[1] = c + k, e + m

    def penetration(self, b: int) -> tuple[float, float]:
        """The end time (s) and overlap (m) of scene ``b``'s last compiled step."""
        if self.builders is not None:
            report = self.builders[b].report(self.builders[b].count - 1)
            return report.t, report.penetration
        arrays = self._scratch[2]
        row = int(arrays[19][b, 0]) - 1
        return float(arrays[0][b, row]), float(arrays[9][b, row - 1])

    def output(self, b: int) -> StepOutput:
        """What scene ``b``'s last compiled step produced (copies)."""
        a, b_, point, frame, gap, friction, restitution, ids, active, per_active, sizes, solved_at = (
            x[b] for x in self.last)
        m, k = int(sizes[0]), int(sizes[1])
        builder = self.builders[b]
        report: StepReport = builder.report(builder.count - 1)
        contacts = Contacts(body_a=a[:m].copy(), body_b=b_[:m].copy(), point=point[:m].copy(),
                            frame=frame[:m].copy(), gap=gap[:m].copy(), friction=friction[:m].copy(),
                            restitution=restitution[:m].copy(), ids=ids[:m].copy())
        return StepOutput(report=report, contacts=contacts, active=active[:k].copy(),
                          impulses=per_active[0, :k].copy(), u_before=per_active[1, :k].copy(),
                          u_after=per_active[2, :k].copy(), solved_at=solved_at[:k].copy(),
                          driven=per_active[3, :k].copy())


class _RepeatedCall:
    """Calls of a compiled kernel that repeat the argument objects of the call before.

    numba's dispatcher types every argument of every call to choose the kernel's machine
    code: for :func:`plain_steps`, about 70 arrays and 30 numbers in nested tuples, a tenth
    of a single run's step. A single run calls it step after step with the same objects (its
    state arrays, buffers and constant tuples, replaced only when a buffer grows), whose types
    cannot have changed: such a call goes straight to the machine code the dispatcher chose
    for them (numba's entry from Python, which unboxes the arguments as the dispatcher's call
    does). Any other call goes through the dispatcher, which compiles if need be; where the
    kernel then has one specialisation (its machine code for one set of argument types), the
    calls after it that repeat those objects take its entry (:func:`_only_entry`). A process
    that compiled several (2D and 3D steps) has the dispatcher choose among them at every
    call (typing the nested tuples in Python: about as long as the step itself); there, the
    ``RESOLVE_AFTER``-th call in a row with the same objects types them once (about 0.4 ms in
    Python) and looks up the specialisation of exactly those types, whose entry the calls after
    it take (the dispatcher's own choice where the types match one exactly); a run of fewer
    calls does not pay for it. With ``NUMBA_DISABLE_JIT=1``, the plain function. One per run
    (:class:`CompiledSteps`): the arguments it remembers are that run's, freed with it.
    """

    #: Calls in a row with the same argument objects after which a kernel of several
    #: specialisations has the one for their types looked up.
    RESOLVE_AFTER = 8

    def __init__(self, kernel) -> None:
        self.kernel = kernel
        self._args: tuple = ()
        self._entry = kernel
        self._repeats = 0

    def __call__(self, *args):
        if len(args) == len(self._args) and all(map(operator.is_, args, self._args)):
            if self._entry is self.kernel:
                self._repeats += 1
                if self._repeats == self.RESOLVE_AFTER:
                    self._entry = _entry_for(self.kernel, args)
            return self._entry(*args)
        result = self.kernel(*args)
        # the dispatcher compiles a specialisation for each new set of argument types, so with
        # one, it is the one just called
        self._args, self._entry, self._repeats = args, _only_entry(self.kernel), 0
        return result


#: The entry of each kernel's one specialisation, once looked up (numba's types hash in
#: Python: a lookup in its table of specialisations costs about 30 us).
_ONLY_ENTRIES: dict = {}


def _only_entry(kernel):
    """The entry from Python of ``kernel``'s one specialisation; the dispatcher itself where it
    has several or none (with ``NUMBA_DISABLE_JIT=1``, the plain function)."""
    overloads = getattr(kernel, "overloads", {})
    if len(overloads) != 1:
        return kernel
    entry = _ONLY_ENTRIES.get(kernel)
    if entry is None:
        entry = _ONLY_ENTRIES[kernel] = next(iter(overloads.values())).entry_point
    return entry


def _entry_for(kernel, args: tuple):
    """The entry from Python of ``kernel``'s specialisation for exactly the types of ``args``
    (numba's typing of arguments, ``typeof_pyval``, as its dispatcher types them); the
    dispatcher itself where it has none for them (it would convert some argument) or with
    ``NUMBA_DISABLE_JIT=1``."""
    overloads = getattr(kernel, "overloads", None)
    if not overloads:
        return kernel
    found = overloads.get(tuple(kernel.typeof_pyval(a) for a in args))
    return kernel if found is None else found.entry_point


#: The rows of a single run's one scene.
_SCENE = np.zeros(1, dtype=np.int64)

#: Scenes per thread at least: below, a batch's compiled call runs in the calling thread alone.
_SCENES_PER_THREAD = 8

_pools: dict[int, ThreadPoolExecutor] = {}


def _thread_pool(workers: int) -> ThreadPoolExecutor:
    """The process's pool of ``workers`` threads for the compiled steps of batches (made once)."""
    pool = _pools.get(workers)
    if pool is None:
        pool = _pools[workers] = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="nscd-steps")
    return pool


def _wider(a: np.ndarray, columns: int) -> np.ndarray:
    """``a`` (B, c, ...) with ``columns`` columns, its own first (the rest zeros)."""
    out = np.zeros((a.shape[0], columns, *a.shape[2:]), dtype=a.dtype)
    out[:, :a.shape[1]] = a
    return out
