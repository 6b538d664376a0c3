"""Contact detection for a whole scene: broad phase, narrow phase, contact laws.

``detect(model, q, margin)`` returns every contact point whose gap is at most
``margin`` (m) as :class:`~nscd.contact.frames.Contacts`. Pairs of two non-dynamic
bodies (fixed or driven) are never tested. The narrow phase is
:func:`nscd.contact.detect2d.collide_posed_xy` in 2D (every vertex posed at
once, all candidate pairs in one call of the compiled kernel, from compiled code) and
:func:`nscd.contact.detect3d.collide_posed_fields` in 3D (every body posed at once by
:func:`nscd.shapes3d.pose_rows`, all candidate pairs in one call). Both are their module's
narrow phase without its input checks (``collide_posed_polygons``, ``collide_posed``).
Scenes of at most ``ALL_PAIRS_BODIES`` bodies are detected in one compiled call, posing to
contact laws (:func:`_detect_small_scenes`, :func:`_detect_small_polyhedra`).
"""
from __future__ import annotations

import numpy as np

from nscd.contact.broad import broad_phase
from nscd._jit import njit, njit_helper
from nscd.contact.detect2d import collide_posed_xy
from nscd.contact.detect3d import MAX_POINTS, collide_posed_arrays, collide_posed_fields
from nscd.contact.frames import Contacts, tangent_frames
from nscd.model import Model, pair_laws
from nscd.rotation import rotation_matrices
from nscd.shapes3d import pose_rows


@njit
def _pose_scenes(q, local, owner, start):
    """World vertices (S * V, 2) of every body of S scenes (q (S, n, 3); ``local`` (V, 2)
    body-frame vertices laid end to end, ``owner`` (V,) their bodies, ``start`` (n + 1,)),
    and the bodies' bounding boxes, lower and upper corners (S * n, 2) each, m."""
    S, n = q.shape[0], q.shape[1]
    V = local.shape[0]
    world = np.empty((S * V, 2))
    lower = np.empty((S * n, 2))
    upper = np.empty((S * n, 2))
    for s in range(S):
        for i in range(n):
            c, sn = np.cos(q[s, i, 2]), np.sin(q[s, i, 2])
            lo0 = lo1 = np.inf
            hi0 = hi1 = -np.inf
            for k in range(start[i], start[i + 1]):
                x, y = local[k, 0], local[k, 1]
                wx = q[s, i, 0] + c * x - sn * y
                wy = q[s, i, 1] + sn * x + c * y
                world[s * V + k, 0], world[s * V + k, 1] = wx, wy
                lo0, hi0 = min(lo0, wx), max(hi0, wx)
                lo1, hi1 = min(lo1, wy), max(hi1, wy)
            lower[s * n + i, 0], lower[s * n + i, 1] = lo0, lo1
            upper[s * n + i, 0], upper[s * n + i, 1] = hi0, hi1
    return world, lower, upper


#: Scenes with at most this many bodies test every pair of bounding boxes in one loop,
#: compiled with numba, and are detected in one compiled call (the same pairs in the same
#: order as sort-and-sweep, whose route runs its broad phase in Python and is the dearer one
#: well beyond this size: ``docs/time_step.md``). It also bounds the scenes that take compiled
#: steps (:mod:`nscd.compiled_step`): a few dozen bodies, the scenes whose contact problems
#: mostly fit the solver's dense fast path (stacks, columns, arches, frames). Its pairs' buffer
#: holds ``n (n - 1) / 2`` pairs a scene.
ALL_PAIRS_BODIES = 48


def _pairs_of_boxes(model: Model, lower: np.ndarray, upper: np.ndarray, margin: float) -> np.ndarray:
    """Pairs (i, j), i < j, whose bounding boxes overlap within ``margin`` and that involve a dynamic body.

    ``lower`` and ``upper`` (n_bodies, dim), m, are the corners of the bodies' boxes.
    Boxes pair as in :func:`nscd.contact.broad.broad_phase` (overlap on every axis once
    grown by ``margin``), sorted by ``i`` then ``j``.
    """
    if len(lower) <= ALL_PAIRS_BODIES:
        return _all_pairs(lower, upper, model.dynamic, margin)
    pairs = broad_phase(lower, upper, margin)
    if len(pairs) == 0:
        return np.zeros((0, 2), dtype=int)
    keep = model.dynamic[pairs[:, 0]] | model.dynamic[pairs[:, 1]]
    return pairs[keep]


@njit
def _all_pairs(lower, upper, dynamic, margin):
    """:func:`_pairs_of_boxes` of a few bodies by testing every pair: (p, 2) int64, sorted by i then j."""
    n, dim = lower.shape
    out = np.empty((n * (n - 1) // 2, 2), dtype=np.int64)
    k = 0
    for i in range(n):
        for j in range(i + 1, n):
            if not (dynamic[i] or dynamic[j]):
                continue
            overlap = True
            for d in range(dim):
                if not (lower[j, d] <= upper[i, d] + margin and lower[i, d] <= upper[j, d] + margin):
                    overlap = False
                    break
            if overlap:
                out[k, 0], out[k, 1] = i, j
                k += 1
    return out[:k]


def detect(model: Model, q: np.ndarray, margin: float) -> Contacts:
    """All contact points of configuration ``q`` (n_bodies, nq) with gap <= ``margin`` (m).

    Contacts come pair by pair (pairs sorted by body ``i``, then ``j``), each pair's
    points in the order of its manifold.
    """
    return detect_batch(model, q[None], margin)[0]


def detect_batch(model: Model, q: np.ndarray, margin: float,
                 sweep: np.ndarray | None = None) -> tuple[Contacts, np.ndarray]:
    """:func:`detect` of S configurations ``q`` (S, n_bodies, nq) of one model at once.

    ``sweep`` (S, n_bodies), m, >= 0, optional: how far any point of each body may move
    in the coming step (speculative contacts). Each body's bounding box is grown by its
    sweep in the broad phase (a box covering the box swept over the step), and the pair
    ``(a, b)`` is searched with the margin ``margin + sweep[a] + sweep[b]``, so a contact
    that can close within the step is found however fast the bodies move (contacts then
    come with gaps up to that margin).

    Returns
    -------
    contacts : Contacts
        Every scene's contacts, scene after scene, each scene's in the order of
        :func:`detect` (body indices are the scene's own).
    scene : ndarray of int, shape (m,)
        The scene of each contact.

    Each contact is computed by the same floating-point operations whatever the other
    scenes: posing is elementwise, and the narrow phase treats every pair on its own.
    """
    sweep = np.zeros(q.shape[:2]) if sweep is None else np.asarray(sweep, dtype=float)
    if model.dim == 2:
        return _detect_polygons(model, q, margin, sweep)
    if q.shape[1] <= ALL_PAIRS_BODIES:
        return _detect_few_polyhedra(model, q, margin, sweep)
    found = [_detect_polyhedra(model, q_s, margin, sweep_s) for q_s, sweep_s in zip(q, sweep)]
    if len(found) == 1:
        return found[0], np.zeros(len(found[0]), dtype=np.int64)
    scene = np.repeat(np.arange(len(q)), [len(c) for c in found])
    if len(scene) == 0:
        return Contacts.empty(3), scene
    return Contacts(*(np.concatenate([getattr(c, f) for c in found]) for f in Contacts.__dataclass_fields__)), scene


def _detect_few_polyhedra(model: Model, q: np.ndarray, margin: float,
                          sweep: np.ndarray) -> tuple[Contacts, np.ndarray]:
    """3D :func:`detect_batch` of scenes of at most ``ALL_PAIRS_BODIES`` bodies in one compiled
    call (:func:`_detect_small_polyhedra`: posing, swept boxes, all pairs, narrow phase, frames,
    contact laws)."""
    batch = model.polyhedra
    if not (q.dtype == np.float64 and q.flags.c_contiguous):
        q = np.ascontiguousarray(q, dtype=np.float64)
    S, n = q.shape[:2]
    grow = (sweep if sweep.flags.c_contiguous else np.ascontiguousarray(sweep)).reshape(S * n)
    scene, a, b, point, frame, gap, ids, friction, restitution = _detect_small_polyhedra(
        q, grow, batch._local, batch._owner, batch._plane_offsets, batch.vertex_start, batch.face_start,
        batch.edge_start, batch.family_start, batch.radius, batch.face_vertices, batch.side_start, batch.edges,
        batch.edge_family, batch.vertex_faces, batch.vertex_face_start, model.dynamic, margin, model.law_material,
        model.law_table, model.law_keys, model.law_values)
    return Contacts(body_a=a, body_b=b, point=point, frame=frame, gap=gap, friction=friction,
                    restitution=restitution, ids=ids), scene


@njit
def _detect_small_polyhedra(q, grow, local, owner, plane_offsets, vertex_start, face_start, edge_start, family_start,
                            radius, face_vertices, side_start, edges, edge_family, vertex_faces, vertex_face_start,
                            dynamic, margin, material, table, keys, values):
    """:func:`_detect_few_polyhedra` in one compiled call, scene by scene: the bodies posed
    (:func:`nscd.shapes3d.pose_rows`), their boxes grown by the sweeps ``grow`` (S * n,), every
    pair of boxes tested (:func:`_all_pairs`), the pairs' narrow phase within
    ``margin + grow[a] + grow[b]`` (:func:`nscd.contact.detect3d.collide_posed_fields`), then
    per contact its point (the midpoint of the two surface points), frame, id and law.
    Returns the fields of :func:`_contacts_of_pairs`."""
    S, n = q.shape[0], q.shape[1]
    n_vertices, n_families, n_faces = vertex_start[n], family_start[n], face_start[n]
    capacity = S * (n * (n - 1) // 2) * MAX_POINTS
    scene = np.empty(capacity, dtype=np.int64)
    a = np.empty(capacity, dtype=np.int64)
    b = np.empty(capacity, dtype=np.int64)
    point = np.empty((capacity, 3))
    normals = np.empty((capacity, 3))
    gap = np.empty(capacity)
    ids = np.empty((capacity, 3), dtype=np.int64)
    quats = np.empty((n, 4))
    positions = np.empty((n, 3))
    lower = np.empty((n, 3))
    upper = np.empty((n, 3))
    m = 0
    for s in range(S):
        for i in range(n):
            for d in range(3):
                positions[i, d] = q[s, i, d]
            for d in range(4):
                quats[i, d] = q[s, i, 3 + d]
        vertices, face_normals, face_offsets, edge_directions, side_planes = pose_rows(
            rotation_matrices(quats), positions, local, owner, plane_offsets, n_vertices, n_families, n_faces)
        for i in range(n):
            for d in range(3):
                low = high = vertices[vertex_start[i], d]
                for v in range(vertex_start[i] + 1, vertex_start[i + 1]):
                    low, high = min(low, vertices[v, d]), max(high, vertices[v, d])
                lower[i, d], upper[i, d] = low - grow[s * n + i], high + grow[s * n + i]
        pairs = _all_pairs(lower, upper, dynamic, margin)
        margins = np.empty(pairs.shape[0])
        for p in range(pairs.shape[0]):
            margins[p] = margin + grow[s * n + pairs[p, 0]] + grow[s * n + pairs[p, 1]]
        pair, normal, points_a, points_b, gaps, feature = collide_posed_fields(
            vertex_start, face_start, edge_start, family_start, radius, face_vertices, side_start, edges,
            edge_family, vertex_faces, vertex_face_start, vertices, face_normals, face_offsets, edge_directions,
            side_planes, pairs, margins)
        for c in range(gaps.shape[0]):
            scene[m], a[m], b[m] = s, pairs[pair[c], 0], pairs[pair[c], 1]
            for d in range(3):
                point[m, d] = 0.5 * (points_a[c, d] + points_b[c, d])
                normals[m, d] = normal[c, d]
            gap[m] = gaps[c]
            ids[m, 0], ids[m, 1], ids[m, 2] = a[m], b[m], feature[c]
            m += 1
    # copies: C-contiguous arrays of their own (one compiled specialisation of the callees)
    scene, a, b, point, normals, gap, ids = (scene[:m].copy(), a[:m].copy(), b[:m].copy(), point[:m].copy(),
                                             normals[:m].copy(), gap[:m].copy(), ids[:m].copy())
    friction, restitution = pair_laws(a, b, material, table, keys, values)
    return scene, a, b, point, tangent_frames(normals), gap, ids, friction, restitution


def _detect_polyhedra(model: Model, q: np.ndarray, margin: float, sweep: np.ndarray) -> Contacts:
    """3D :func:`detect`: every body posed at once, all candidate pairs in one narrow-phase call."""
    batch = model.polyhedra
    posed = batch.pose(q[:, :3], rotation_matrices(np.ascontiguousarray(q[:, 3:])))
    starts = batch.vertex_start[:-1]
    pairs = _pairs_of_boxes(model, np.minimum.reduceat(posed.vertices, starts, axis=0) - sweep[:, None],
                            np.maximum.reduceat(posed.vertices, starts, axis=0) + sweep[:, None], margin)
    if len(pairs) == 0:
        return Contacts.empty(3)
    pairs = np.ascontiguousarray(pairs, dtype=np.int64)
    pair, normal, points_a, points_b, gaps, feature = collide_posed_arrays(
        batch, posed, pairs, margin + sweep[pairs[:, 0]] + sweep[pairs[:, 1]])
    if len(gaps) == 0:
        return Contacts.empty(3)
    a, b = pairs[pair, 0], pairs[pair, 1]
    friction, restitution = model.contact_laws(a, b)
    return Contacts(
        body_a=a, body_b=b, point=0.5 * (points_a + points_b), frame=tangent_frames(normal),
        gap=gaps, friction=friction, restitution=restitution, ids=np.column_stack([a, b, feature]),
    )


def _detect_polygons(model: Model, q: np.ndarray, margin: float, sweep: np.ndarray) -> tuple[Contacts, np.ndarray]:
    """2D :func:`detect_batch`: every vertex of every scene posed at once, all candidate
    pairs of all scenes in one call of the compiled narrow phase. Scenes of at most
    ``ALL_PAIRS_BODIES`` bodies go through detection in one compiled call
    (:func:`_detect_small_scenes`: posing, boxes, pairs, narrow phase, frames, contact laws)."""
    local, owner, start = model.polygons
    S, n = q.shape[:2]
    # writable C-contiguous float64 whatever the caller's array: one compiled specialisation
    if not (q.dtype == np.float64 and q.flags.c_contiguous and q.flags.writeable):
        q = np.require(q, np.float64, ('C', 'W'))
    grow = (sweep if sweep.flags.c_contiguous else np.ascontiguousarray(sweep)).reshape(S * n)
    laws = (model.law_material, model.law_table, model.law_keys, model.law_values)
    if n <= ALL_PAIRS_BODIES:
        found = _detect_small_scenes(q, grow, local, owner, start, model.dynamic, margin, *laws)
    else:
        world, lower, upper = _pose_scenes(q, local, owner, start)
        lower, upper = lower - grow[:, None], upper + grow[:, None]
        pairs = [_pairs_of_boxes(model, lower[s * n:(s + 1) * n], upper[s * n:(s + 1) * n], margin)
                 for s in range(S)]
        scene_of_pair = np.repeat(np.arange(S), [len(p) for p in pairs])
        found = _contacts_of_pairs(world, start, np.concatenate(pairs), scene_of_pair, n, grow, margin, *laws)
    scene, a, b, point, frame, gap, ids, friction, restitution = found
    return Contacts(body_a=a, body_b=b, point=point, frame=frame, gap=gap, friction=friction,
                    restitution=restitution, ids=ids), scene


@njit
def _detect_small_scenes(q, grow, local, owner, start, dynamic, margin, material, table, keys, values):
    """:func:`_detect_polygons` of S scenes of a few bodies in one compiled call: the
    vertices posed, the boxes grown by the sweeps ``grow`` (S * n,), every pair of boxes
    tested, then :func:`_contacts_of_pairs`."""
    n = q.shape[1]
    world, lower, upper = _pose_scenes(q, local, owner, start)
    for k in range(lower.shape[0]):
        for d in range(2):
            lower[k, d] -= grow[k]
            upper[k, d] += grow[k]
    pairs, scene_of_pair = _all_pairs_of_scenes(lower, upper, dynamic, margin)
    return _contacts_of_pairs(world, start, pairs, scene_of_pair, n, grow, margin, material, table, keys, values)


@njit
def _contacts_of_pairs(world, start, pairs, scene_of_pair, n, grow, margin, material, table, keys, values):
    """The narrow phase of the candidate ``pairs`` (p, 2) (body indices of scenes
    ``scene_of_pair`` (p,), n bodies each) on the posed vertices ``world`` (S * V, 2)
    (body ``i`` of a scene owns its ``start[i]:start[i + 1]``), each pair searched within
    ``margin + grow[a] + grow[b]`` (``grow`` (S * n,), m).

    Returns the scene (k,), bodies ``a``, ``b`` (k,), contact point (midpoint of the two
    surface points), frame ``[n, t1]`` (k, 2, 2) (:func:`nscd.contact.frames.tangent_frames`),
    gap (k,), ids (k, 3) ``(a, b, feature)`` of every contact point, and its friction
    coefficient and restitution (k,) each (:func:`nscd.model.pair_laws` of the model's
    ``law_material``, ``law_table``, ``law_keys`` and ``law_values``).
    """
    p = pairs.shape[0]
    V = start[start.shape[0] - 1]
    n_scenes = world.shape[0] // V if V > 0 else 0
    global_start = np.empty(n_scenes * n + 1, dtype=np.int64)
    for s in range(n_scenes):
        for i in range(n):
            global_start[s * n + i] = start[i] + s * V
    global_start[n_scenes * n] = n_scenes * V
    stacked = np.empty((p, 2), dtype=np.int64)
    margins = np.empty(p)
    for k in range(p):
        stacked[k, 0] = pairs[k, 0] + n * scene_of_pair[k]
        stacked[k, 1] = pairs[k, 1] + n * scene_of_pair[k]
        margins[k] = margin + grow[stacked[k, 0]] + grow[stacked[k, 1]]
    pair, normal, points_a, points_b, gaps, feature = collide_posed_xy(
        np.ascontiguousarray(world[:, 0]), np.ascontiguousarray(world[:, 1]), global_start, stacked, margins)
    m = gaps.shape[0]
    scene = np.empty(m, dtype=np.int64)
    a = np.empty(m, dtype=np.int64)
    b = np.empty(m, dtype=np.int64)
    point = np.empty((m, 2))
    frame = tangent_frames(normal)
    ids = np.empty((m, 3), dtype=np.int64)
    for c in range(m):
        scene[c], a[c], b[c] = scene_of_pair[pair[c]], pairs[pair[c], 0], pairs[pair[c], 1]
        for d in range(2):
            point[c, d] = 0.5 * (points_a[c, d] + points_b[c, d])
        ids[c, 0], ids[c, 1], ids[c, 2] = a[c], b[c], feature[c]
    friction, restitution = pair_laws(a, b, material, table, keys, values)
    return scene, a, b, point, frame, gaps, ids, friction, restitution


@njit_helper
def _all_pairs_of_scenes(lower, upper, dynamic, margin):
    """:func:`_all_pairs` of S scenes of n bodies (boxes (S * n, dim)): pairs (p, 2) of body
    indices and the scene of each pair (p,), scene after scene."""
    n = dynamic.shape[0]
    S = lower.shape[0] // n
    pairs = np.empty((S * (n * (n - 1) // 2), 2), dtype=np.int64)
    scene = np.empty(S * (n * (n - 1) // 2), dtype=np.int64)
    k = 0
    for s in range(S):
        found = _all_pairs(lower[s * n:(s + 1) * n], upper[s * n:(s + 1) * n], dynamic, margin)
        for p in range(found.shape[0]):
            pairs[k, 0], pairs[k, 1] = found[p, 0], found[p, 1]
            scene[k] = s
            k += 1
    return pairs[:k], scene[:k]
