"""Narrow phase in 3D: the contact manifolds of convex polyhedra.

Algorithm of :func:`collide_polyhedra` and :func:`collide_posed` (separating axes, then
clipping; the 3D counterpart of Box2D's ``b2CollidePolygons``, after D. Gregorius, "The
Separating Axis Test between Convex Polyhedra", GDC 2013)::

    sa = max over faces f of A of  min_B(n_f . x) - max_A(n_f . x)    # one-sided
    sb = max over faces f of B of  min_A(n_f . x) - max_B(n_f . x)
    se = max over edge-family pairs of the interval separation along dA x dB
    any of them > margin            -> None (a separating axis)
    se clearly above the face axes  -> edge-edge: one point, the closest points
                                       of the two supporting edges
    otherwise                       -> face contact: the reference face (A's face
        unless B's is clearly better); the incident face: of the faces around the other
        body's deepest vertex, the most anti-parallel to the reference face (so that
        vertex, which sets the face-axis separation, is a contact point whenever it
        lies over the reference face); clip the incident polygon by the side planes of
        the reference face (Sutherland-Hodgman; an incident vertex within a band of
        ``_CLIP_RTOL`` outside a side is moved onto it, not cut: the same point and id
        whether round-off puts it just in or just out), keep points within the margin,
        reduce to at most 8 points keeping the outline of the contact patch.

Vertex-face contacts fall out of the face clipping. "Clearly" means by more than
``_FACE_BIAS`` times the smaller bounding radius: face axes win near-ties so that a
block resting or rocking on a face keeps a steady normal and a full point set. Ties
between axes go to the first one (faces of A, faces of B, then edge families of A,
each against the edge families of B, in index order).

Feature ids (int64) of a face contact pack, in bit fields from the top: which body holds
the reference face (1 bit), the reference face (12 bits), the incident face (12 bits),
then the point's two features (10 bits each): an incident-polygon vertex ``(i, 1023)``
or the crossing of segment feature ``s`` with reference side ``j`` as ``(s, j)``, where
``s`` is an incident edge ``i`` or ``512 + j'`` for a reference side ``j'`` (a deep
overlap whose clipped face misses the reference face reports the incident body's
deepest vertex alone, as ``(1023, 1022)``). Edge-edge ids are
``2**46 + (edge_a << 16) + edge_b``. Face, edge and vertex numbers are those of each
body's :class:`~nscd.shapes3d.Polyhedron`. The shapes of :mod:`nscd.shapes3d`
guarantee the field sizes (at most 4096 faces, 512 vertices a face).

Implementation: one kernel, :func:`collide_posed_fields`, runs every pair of a step on the
flat arrays of :class:`~nscd.shapes3d.PolyhedronBatch` and
:class:`~nscd.shapes3d.PosedBatch`. It is compiled by numba
(``NUMBA_DISABLE_JIT=1`` runs the same code as plain Python, for debugging, about a
hundred times slower).
"""
from __future__ import annotations

import math

import numpy as np

from nscd._jit import njit, njit_helper
from nscd.contact.manifold import Manifold, Manifolds, compact_rows, pair_margins
from nscd.shapes3d import PlacedPolyhedron, PolyhedronBatch, PosedBatch

__all__ = ["collide_polyhedra", "collide_posed", "MAX_POINTS"]

#: Largest number of contact points of one pair.
MAX_POINTS = 8

#: A face axis is kept unless another axis separates more by this fraction of the
#: smaller bounding radius (hysteresis-free bias toward stable face contacts).
_FACE_BIAS = 1e-3

#: Edge pairs whose directions are closer than this sine are skipped (their cross
#: product is not a reliable axis; face axes cover parallel edges).
_PARALLEL_SIN = 1e-6

#: Points within this fraction of the reference radius of a side plane count as on it
#: (those outside are moved onto it): the clipping band. Equal blocks stacked flush (a wall
#: one block thick) put the incident face's corners on the reference face's sides, where
#: a band of round-off (1e-9) let a sub-micrometre wobble turn a corner into a crossing and
#: back, with a new feature id each time, and the contact lost its warm start
#: (``docs/solver.md``, "3D"). 1e-5 (2.5 um on a 0.4 m block) holds them while a wall
#: rocks by micrometres; a contact point is never more than the band away from the
#: exact patch.
_CLIP_RTOL = 1e-5

_VERTEX = 1023
_DEEPEST = (1023 << 10) | 1022
_SIDE = 512
_EDGE_IDS = 1 << 46


def collide_polyhedra(a: PlacedPolyhedron, b: PlacedPolyhedron, margin: float) -> Manifold | None:
    """Contact manifold of two posed convex polyhedra.

    Parameters
    ----------
    a, b : PlacedPolyhedron
        Bodies A and B posed in the world (:meth:`nscd.shapes3d.Polyhedron.place`);
        their ``position`` and ``rotation`` define the pose.
    margin : float
        Detection margin in m, >= 0: points whose gap is at most ``margin`` are reported.

    Returns
    -------
    Manifold or None
        ``None`` if a separating axis shows a gap larger than ``margin``; otherwise the
        normal (3,) from A to B and up to 8 points with ``gaps`` (k,) in m, negative
        when penetrating, and feature ``ids`` (k,) packed as in the module docstring.

    Notes
    -----
    For one pair; the time step poses every body once and runs all candidate pairs in
    one call of :func:`collide_posed`, which gives the same manifolds.
    """
    batch = PolyhedronBatch((a.shape, b.shape))
    posed = batch.pose(np.array([a.position, b.position]), np.array([a.rotation, b.rotation]))
    return collide_posed(batch, posed, np.array([[0, 1]]), margin).manifold(0)


def collide_posed(batch: PolyhedronBatch, posed: PosedBatch, pairs: np.ndarray,
                  margin: float | np.ndarray) -> Manifolds:
    """Contact points of many pairs of posed polyhedra in one call.

    Parameters
    ----------
    batch : PolyhedronBatch
        The bodies' shapes laid end to end.
    posed : PosedBatch
        Their world geometry (:meth:`PolyhedronBatch.pose`).
    pairs : ndarray of int, shape (p, 2)
        Body indices ``(a, b)`` into ``batch``: the normal points from a to b.
    margin : float or ndarray, shape (p,)
        Detection margin in m, >= 0: one for all pairs, or one per pair (a pair's margin
        may cover its approach within a time step).

    Returns
    -------
    Manifolds
        One row per contact point, pair after pair in the order of ``pairs``, each
        pair's points as :func:`collide_polyhedra` lists them (``pair`` indexes rows of
        ``pairs``).
    """
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    return Manifolds(*collide_posed_arrays(batch, posed, pairs, pair_margins(margin, len(pairs))))


def collide_posed_arrays(batch: PolyhedronBatch, posed: PosedBatch, pairs: np.ndarray, margins: np.ndarray) -> tuple:
    """:func:`collide_posed` without its checks (the step's own call: int64 ``pairs`` (p, 2),
    margins (p,) already >= 0), returning the fields of :class:`Manifolds` as a tuple."""
    return collide_posed_fields(
        batch.vertex_start, batch.face_start, batch.edge_start, batch.family_start, batch.radius,
        batch.face_vertices, batch.side_start, batch.edges, batch.edge_family,
        batch.vertex_faces, batch.vertex_face_start,
        posed.vertices, posed.face_normals, posed.face_offsets, posed.edge_directions, posed.side_planes,
        pairs, margins,
    )


@njit
def collide_posed_fields(
    vertex_start, face_start, edge_start, family_start, radius,
    face_vertices, side_start, edges, edge_family, vertex_faces, vertex_face_start,
    vertices, face_normals, face_offsets, edge_directions, side_planes,
    pairs, margin,
):
    """Kernel of :func:`collide_posed` (arguments: the fields of the two batches; ``margin`` (p,) per pair).

    Returns the fields of :class:`~nscd.contact.manifold.Manifolds`, one row per
    contact point: ``pair`` (k,), ``normal``, ``points_a``, ``points_b`` (k, 3),
    ``gaps`` (k,) and ``ids`` (k,).
    """
    n_pairs = pairs.shape[0]
    counts = np.zeros(n_pairs, dtype=np.int64)
    normal = np.zeros((n_pairs, 3))
    points_a = np.zeros((n_pairs * MAX_POINTS, 3))
    points_b = np.zeros((n_pairs * MAX_POINTS, 3))
    gaps = np.zeros(n_pairs * MAX_POINTS)
    ids = np.zeros(n_pairs * MAX_POINTS, dtype=np.int64)
    axis = np.zeros(3)
    for p in range(n_pairs):
        a, b = pairs[p, 0], pairs[p, 1]
        reach = margin[p]
        va0, va1, vb0, vb1 = vertex_start[a], vertex_start[a + 1], vertex_start[b], vertex_start[b + 1]
        # face axes of A, then of B, then edge axes: the first largest separation of each
        face_a, sa = _best_face(face_normals, face_start[a], face_start[a + 1], vertices, va0, va1, vb0, vb1)
        if sa > reach:
            continue
        face_b, sb = _best_face(face_normals, face_start[b], face_start[b + 1], vertices, vb0, vb1, va0, va1)
        if sb > reach:
            continue
        se, family_a, family_b = _best_edge_axis(edge_directions, family_start[a], family_start[a + 1],
                                                 family_start[b], family_start[b + 1], vertices, va0, va1, vb0, vb1,
                                                 axis)
        if se > reach:
            continue
        tol = _FACE_BIAS * min(radius[a], radius[b])
        row = p * MAX_POINTS
        if se > max(sa, sb) + tol:
            # one point: closest points of A's edge most along the axis and B's most against it
            edge_a = _support_edge(edges, edge_family, edge_start[a], edge_start[a + 1], family_a, vertices, axis, 1.0)
            edge_b = _support_edge(edges, edge_family, edge_start[b], edge_start[b + 1], family_b, vertices, axis, -1.0)
            gap = _closest_on_segments(vertices, edges[edge_a, 0], edges[edge_a, 1], edges[edge_b, 0],
                                       edges[edge_b, 1], axis, points_a, points_b, row)
            if gap <= reach:
                counts[p] = 1
                normal[p] = axis
                gaps[row] = gap
                ids[row] = _EDGE_IDS + ((edge_a - edge_start[a]) << 16) + (edge_b - edge_start[b])
        elif sb > sa + tol:
            counts[p] = _face_contact(
                b, face_b, a, True, reach, vertex_start, face_start, radius, face_vertices, side_start,
                vertex_faces, vertex_face_start, vertices, face_normals, face_offsets, side_planes,
                normal[p], points_b, points_a, gaps, ids, row)
        else:
            counts[p] = _face_contact(
                a, face_a, b, False, reach, vertex_start, face_start, radius, face_vertices, side_start,
                vertex_faces, vertex_face_start, vertices, face_normals, face_offsets, side_planes,
                normal[p], points_a, points_b, gaps, ids, row)
    return compact_rows(counts, MAX_POINTS, normal, points_a, points_b, gaps, ids)


@njit_helper
def _best_edge_axis(edge_directions, fa0, fa1, fb0, fb1, vertices, va0, va1, vb0, vb1, axis):
    """Largest separation (m) along the crosses of edge families ``fa0:fa1`` (A) and ``fb0:fb1`` (B).

    Returns it (``-inf`` if every family pair is parallel) with the two families, and
    writes the unit axis, oriented from A to B, into ``axis`` (3,).
    """
    best, family_a, family_b = -np.inf, -1, -1
    for i in range(fa0, fa1):
        for j in range(fb0, fb1):
            c = (edge_directions[i, 0] * edge_directions[j, 0] + edge_directions[i, 1] * edge_directions[j, 1]
                 + edge_directions[i, 2] * edge_directions[j, 2])
            sin2 = 1.0 - c * c                      # |dA x dB|^2
            if sin2 <= _PARALLEL_SIN * _PARALLEL_SIN:
                continue
            length = math.sqrt(sin2)
            x = (edge_directions[i, 1] * edge_directions[j, 2] - edge_directions[i, 2] * edge_directions[j, 1]) / length
            y = (edge_directions[i, 2] * edge_directions[j, 0] - edge_directions[i, 0] * edge_directions[j, 2]) / length
            z = (edge_directions[i, 0] * edge_directions[j, 1] - edge_directions[i, 1] * edge_directions[j, 0]) / length
            low_a, top_a = _interval(vertices, va0, va1, x, y, z)
            low_b, top_b = _interval(vertices, vb0, vb1, x, y, z)
            forward, backward = low_b - top_a, low_a - top_b     # B on the + side, on the - side
            if max(forward, backward) > best:
                best, family_a, family_b = max(forward, backward), i, j
                sign = 1.0 if forward >= backward else -1.0
                axis[0], axis[1], axis[2] = sign * x, sign * y, sign * z
    return best, family_a, family_b


@njit_helper
def _interval(vertices, start, stop, x, y, z):
    """Smallest and largest ``(x, y, z) . v`` over ``vertices[start:stop]``."""
    low = top = vertices[start, 0] * x + vertices[start, 1] * y + vertices[start, 2] * z
    for v in range(start + 1, stop):
        d = vertices[v, 0] * x + vertices[v, 1] * y + vertices[v, 2] * z
        low = min(low, d)
        top = max(top, d)
    return low, top


@njit_helper
def _best_face(face_normals, start, stop, vertices, own0, own1, other0, other1):
    """Face (global index) of the body owning faces ``start:stop`` that separates most, and that separation, m.

    Separation of face ``f``: ``min_other(n_f . x) - max_own(n_f . x)``.
    """
    best, best_sep = start, -np.inf
    for f in range(start, stop):
        x, y, z = face_normals[f, 0], face_normals[f, 1], face_normals[f, 2]
        top = _interval(vertices, own0, own1, x, y, z)[1]
        low = _interval(vertices, other0, other1, x, y, z)[0]
        if low - top > best_sep:
            best, best_sep = f, low - top
    return best, best_sep


@njit_helper
def _support_edge(edges, edge_family, start, stop, family, vertices, axis, sign):
    """Edge (global index) of ``family`` among ``edges[start:stop]`` farthest along ``sign * axis``."""
    best, best_d = -1, -np.inf
    for e in range(start, stop):
        if edge_family[e] != family:
            continue
        i, k = edges[e, 0], edges[e, 1]
        d = sign * ((vertices[i, 0] + vertices[k, 0]) * axis[0] + (vertices[i, 1] + vertices[k, 1]) * axis[1]
                    + (vertices[i, 2] + vertices[k, 2]) * axis[2])
        if d > best_d:
            best, best_d = e, d
    return best


@njit_helper
def _closest_on_segments(vertices, p0, p1, q0, q1, normal, points_a, points_b, row):
    """Closest points of segments p0p1 (on A) and q0q1 (on B), written at ``row``; returns their gap along ``normal``.

    Segments non-degenerate and not parallel. Ericson, *Real-Time Collision
    Detection*, 2005, section 5.1.9.
    """
    d1 = vertices[p1] - vertices[p0]
    d2 = vertices[q1] - vertices[q0]
    r = vertices[p0] - vertices[q0]
    a, e, f = _dot(d1, d1), _dot(d2, d2), _dot(d2, r)
    c, bb = _dot(d1, r), _dot(d1, d2)
    denom = a * e - bb * bb
    s = min(max((bb * f - c * e) / denom, 0.0), 1.0) if denom > 0.0 else 0.0
    t = (bb * s + f) / e
    if t < 0.0:
        t, s = 0.0, min(max(-c / a, 0.0), 1.0)
    elif t > 1.0:
        t, s = 1.0, min(max((bb - c) / a, 0.0), 1.0)
    points_a[row] = vertices[p0] + s * d1
    points_b[row] = vertices[q0] + t * d2
    return _dot(points_b[row] - points_a[row], normal)


@njit_helper
def _dot(u, v):
    """``u . v`` of two 3-vectors, summed in index order (the same in compiled and plain code)."""
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]


@njit_helper
def _face_contact(
    ref, face, inc, swapped, margin, vertex_start, face_start, radius, face_vertices, side_start,
    vertex_faces, vertex_face_start, vertices, face_normals, face_offsets, side_planes,
    normal, on_ref, on_inc, gaps, ids, row,
):
    """Clip the incident face of body ``inc`` against reference ``face`` (global) of body ``ref``.

    Writes the pair's normal (from A to B: the reference normal, negated when
    ``swapped``, i.e. when the reference body is B) and the points from ``row`` on;
    ``on_ref`` / ``on_inc`` are the output arrays of the reference and incident body.
    Returns the number of points. World frame throughout.
    """
    nx, ny, nz = face_normals[face, 0], face_normals[face, 1], face_normals[face, 2]
    offset = face_offsets[face]
    # the incident body's deepest vertex along -n, then the incident face: of the faces
    # around that vertex (so it is on the face), the most anti-parallel to the reference
    deepest, depth = vertex_start[inc], np.inf
    for v in range(vertex_start[inc], vertex_start[inc + 1]):
        d = vertices[v, 0] * nx + vertices[v, 1] * ny + vertices[v, 2] * nz
        if d < depth:
            deepest, depth = v, d
    inc_face, facing = -1, np.inf
    for k in range(vertex_face_start[deepest], vertex_face_start[deepest + 1]):
        f = vertex_faces[k]
        d = face_normals[f, 0] * nx + face_normals[f, 1] * ny + face_normals[f, 2] * nz
        if d < facing:
            inc_face, facing = f, d
    points, local = _clip(vertices, face_vertices[side_start[inc_face]:side_start[inc_face + 1]],
                          side_planes[side_start[face]:side_start[face + 1]], _CLIP_RTOL * radius[ref])
    # keep the points within the margin
    dist = points[:, 0] * nx + points[:, 1] * ny + points[:, 2] * nz - offset
    kept = np.flatnonzero(dist <= margin)
    if len(kept) == 0:
        # deep overlap where the incident face misses the reference face: report the
        # deepest vertex alone (its gap is this face axis' separation)
        points = vertices[deepest:deepest + 1]
        local = np.array([_DEEPEST], dtype=np.int64)
        dist = points[:, 0] * nx + points[:, 1] * ny + points[:, 2] * nz - offset
        kept = np.zeros(1, dtype=np.int64)
    if len(kept) > MAX_POINTS:
        kept = kept[_spread(points[kept], dist[kept], nx, ny, nz)]
    sign = -1.0 if swapped else 1.0
    normal[0], normal[1], normal[2] = sign * nx, sign * ny, sign * nz
    key = (((1 if swapped else 0) << 12 | (face - face_start[ref])) << 12 | (inc_face - face_start[inc])) << 20
    for k in range(len(kept)):
        i = kept[k]
        d = dist[i]
        on_inc[row + k] = points[i]
        on_ref[row + k, 0] = points[i, 0] - d * nx
        on_ref[row + k, 1] = points[i, 1] - d * ny
        on_ref[row + k, 2] = points[i, 2] - d * nz
        gaps[row + k] = d
        ids[row + k] = key + local[i]
    return len(kept)


@njit
def _clip(vertices, polygon, planes, tol):
    """Sutherland-Hodgman: the part of a convex polygon behind every plane ``(s, offset)``.

    ``polygon`` holds the vertex indices (into ``vertices``) of the polygon, ``planes``
    (m, 4) the side planes; a point x is kept where ``s . x - offset <= tol``. Returns
    the clipped vertices (k, 3) and their local feature ids (k,) (two 10-bit fields,
    see the module docstring). Each plane adds at most one vertex to a convex polygon.
    """
    size = len(polygon) + len(planes)
    points = np.empty((size, 3))
    local = np.empty(size, dtype=np.int64)
    segment = np.empty(size, dtype=np.int64)   # feature of the segment leaving each vertex
    count = len(polygon)
    for i in range(count):
        points[i] = vertices[polygon[i]]
        local[i] = (i << 10) | _VERTEX
        segment[i] = i
    new_points = np.empty((size, 3))
    new_local = np.empty(size, dtype=np.int64)
    new_segment = np.empty(size, dtype=np.int64)
    dist = np.empty(size)
    for j in range(len(planes)):
        if count == 0:
            break
        sx, sy, sz, off = planes[j, 0], planes[j, 1], planes[j, 2], planes[j, 3]
        for i in range(count):
            dist[i] = sx * points[i, 0] + sy * points[i, 1] + sz * points[i, 2] - off
        if dist[:count].max() <= tol:       # all behind this side: nothing to cut
            for i in range(count):
                if dist[i] > 0.0:  # within the band outside the side: onto it
                    points[i, 0] -= dist[i] * sx
                    points[i, 1] -= dist[i] * sy
                    points[i, 2] -= dist[i] * sz
            continue
        kept = 0
        for i in range(count):
            k = (i + 1) % count
            di, dk = dist[i], dist[k]
            if di <= tol:
                new_points[kept] = points[i]
                if di > 0.0:  # within the band outside the side: onto it
                    new_points[kept, 0] -= di * sx
                    new_points[kept, 1] -= di * sy
                    new_points[kept, 2] -= di * sz
                new_local[kept] = local[i]
                new_segment[kept] = _SIDE + j if (di >= -tol and dk > tol) else segment[i]
                kept += 1
            if (di < -tol and dk > tol) or (di > tol and dk < -tol):
                t = di / (di - dk)
                for c in range(3):
                    new_points[kept, c] = points[i, c] + t * (points[k, c] - points[i, c])
                new_local[kept] = (segment[i] << 10) | j
                new_segment[kept] = _SIDE + j if di < 0.0 else segment[i]
                kept += 1
        points, new_points = new_points, points
        local, new_local = new_local, local
        segment, new_segment = new_segment, segment
        count = kept
    return points[:count], local[:count]


@njit_helper
def _spread(points, depth, nx, ny, nz):
    """Indices (sorted) of ``MAX_POINTS`` of ``points`` (k, 3) that keep the outline of a contact patch.

    ``depth`` (k,) are the points' gaps along the reference normal ``(nx, ny, nz)``; the
    points are compared projected on the reference plane. Starts from the deepest point
    and adds, one at a time, the point farthest from those already chosen. On the
    corners of a convex patch this keeps the extreme corners, so the support polygon is
    preserved up to corners cut from nearly straight runs.
    """
    k = len(depth)
    flat = np.empty((k, 3))
    for i in range(k):
        flat[i, 0] = points[i, 0] - depth[i] * nx
        flat[i, 1] = points[i, 1] - depth[i] * ny
        flat[i, 2] = points[i, 2] - depth[i] * nz
    chosen = np.empty(MAX_POINTS, dtype=np.int64)
    chosen[0] = depth.argmin()
    dist = np.full(k, np.inf)
    for n in range(1, MAX_POINTS):
        last = flat[chosen[n - 1]]
        for i in range(k):
            d = math.sqrt((flat[i, 0] - last[0]) ** 2 + (flat[i, 1] - last[1]) ** 2 + (flat[i, 2] - last[2]) ** 2)
            dist[i] = min(dist[i], d)
        chosen[n] = dist.argmax()
    return np.sort(chosen)
