"""Narrow-phase contact detection between two convex polygons (2D).

The algorithm is the one of Box2D's ``b2CollidePolygons`` (separating axes,
reference and incident edges, clipping), written afresh for nscd with its
conventions: the normal points from A to B, gaps are signed distances in m,
and points within a detection ``margin`` are kept so that a lifting corner
stays known to the solver while it may still land within the step.

Entry points:

* :func:`collide_posed_polygons` -- every candidate pair of a step in one call, on
  the flat vertex array of all bodies;
* :func:`collide_posed_xy` -- the same without its checks, on flat coordinate arrays and
  one margin per pair: the compiled kernel itself, called from compiled code (what
  :func:`nscd.contact.detect.detect` uses);
* :func:`collide_polygons` -- one pair;
* :func:`collide_polygons_batch` -- many pairs given as (p, n, 2) and (p, m, 2) arrays.

Implementation: one kernel, :func:`collide_posed_xy`, in scalar loops over flat
arrays with one small helper per step of the algorithm, compiled by numba; it serves
all the entry points, so a pair gives the same bits whichever way it is asked for.
For plain-Python debugging, run with ``NUMBA_DISABLE_JIT=1`` (the same kernel,
uncompiled). The tests check it against geometry.

Inputs are not validated here beyond the margin (a :class:`~nscd.scene.Scene`
validates its shapes when it is built); polygons must be convex,
counter-clockwise, without repeated vertices, in world coordinates.

Feature ids
-----------
Each contact point carries ``id = (ref_is_b << 32) | (ref_edge << 16) | inc_vertex``:
the reference edge index ``ref_edge`` (edge ``i`` joins vertices ``i`` and
``i + 1``) on the reference polygon, the incident vertex ``inc_vertex`` the
point comes from (a clipped point keeps the id of the incident vertex it
replaces), and ``ref_is_b`` = 1 when B holds the reference edge. Use
:func:`split_ids` to unpack them.
"""
from __future__ import annotations

import math

import numpy as np

from nscd._jit import njit, njit_helper
from nscd.contact.broad import broad_phase  # re-exported: docs/architecture.md lists it here
from nscd.contact.manifold import Manifold, Manifolds, compact_rows, pair_margins

__all__ = ["broad_phase", "collide_polygons", "collide_polygons_batch", "collide_posed_polygons", "split_ids"]

#: Relative tolerance of the reference-face choice: separations within
#: ``REFERENCE_TOLERANCE * (longest candidate edge)`` count as a tie, and a tie
#: goes to the longer edge (the base under a block), then to A. Keeps the
#: reference, hence the normal and the ids, from flickering on round-off
#: (e.g. a block resting flat, where both separations are 0).
REFERENCE_TOLERANCE = 1e-6


#: Largest number of contact points of one pair of polygons.
MAX_POINTS = 2

_ONE_PAIR = np.array([[0, 1]], dtype=np.int64)


def split_ids(ids: np.ndarray | int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unpack feature ids into their three fields.

    Parameters
    ----------
    ids : int or ndarray of int
        Feature ids of a :class:`~nscd.contact.manifold.Manifold` built by this module.

    Returns
    -------
    ref_is_b : ndarray of bool
        True where B holds the reference edge.
    ref_edge : ndarray of int
        Index of the reference edge on its polygon (edge ``i`` joins vertices ``i``, ``i + 1``).
    inc_vertex : ndarray of int
        Index of the incident vertex on the other polygon.
    """
    ids = np.asarray(ids, dtype=np.int64)
    return (ids >> 32).astype(bool), (ids >> 16) & 0xFFFF, ids & 0xFFFF


def collide_posed_polygons(vertices: np.ndarray, start: np.ndarray, pairs: np.ndarray,
                           margin: float | np.ndarray) -> Manifolds:
    """Contact points of many pairs of posed polygons in one call.

    Parameters
    ----------
    vertices : ndarray, shape (V, 2)
        World vertices in m of all polygons laid end to end, each polygon
        counter-clockwise and convex.
    start : ndarray of int, shape (n_polygons + 1,)
        Polygon ``i`` owns ``vertices[start[i]:start[i + 1]]`` (at least 3 vertices).
    pairs : ndarray of int, shape (p, 2)
        Polygon indices ``(a, b)``: the normal points from a to b.
    margin : float or ndarray, shape (p,)
        Detection margin in m, >= 0 (as in :func:`collide_polygons`): one for all pairs,
        or one per pair (a pair's margin may cover its approach within a time step).

    Returns
    -------
    Manifolds
        One row per contact point, pair after pair in the order of ``pairs``, each pair's
        points as :func:`collide_polygons` lists them (``pair`` indexes rows of ``pairs``).

    Raises
    ------
    ValueError
        If ``margin`` is negative or not finite.
    """
    pairs = np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2)
    margins = pair_margins(margin, len(pairs))
    vertices = np.asarray(vertices, dtype=float)
    return Manifolds(*collide_posed_xy(
        np.ascontiguousarray(vertices[:, 0]), np.ascontiguousarray(vertices[:, 1]),
        np.ascontiguousarray(start, dtype=np.int64), pairs, margins))


def collide_polygons(a: np.ndarray, b: np.ndarray, margin: float) -> Manifold | None:
    """Contact manifold between two convex polygons A and B.

    Parameters
    ----------
    a, b : ndarray, shape (n, 2) and (m, 2)
        World coordinates of the vertices in m, counter-clockwise, convex,
        no repeated vertex (not checked here: the Scene validates shapes).
    margin : float
        Detection margin in m, >= 0: points whose gap is <= margin are kept,
        and None is returned when the polygons are farther apart than that.

    Returns
    -------
    Manifold or None
        ``normal`` (2,) from A to B; ``points_a``, ``points_b`` (k, 2) with
        k = 1 or 2; ``gaps`` (k,) in m, negative when penetrating; ``ids`` (k,)
        packed as described in the module docstring. None when separated by
        more than ``margin``.

    Raises
    ------
    ValueError
        If ``margin`` is negative or not finite.

    Notes
    -----
    The algorithm (:func:`_collide_pair`), after Box2D's ``b2CollidePolygons``::

        shift both polygons so that A's vertex 0 is the origin (round-off)
        edge ea of A separating B most: sa       (_max_separation); sa > margin -> None
        edge eb of B separating A most: sb       (_max_separation); sb > margin -> None
        reference edge = the larger of sa, sb: separation s, outward normal n;
            a near tie goes to the longer edge, then to A   (_reference_is_b)
        incident edge = edge of the other polygon most anti-parallel to n
                                                 (_incident_edge)
        clip the incident edge to the side planes of the reference edge (_clip)
        if s > 0 (apart) and no clipped point is at distance s (the closest
            vertex lies beside the reference edge): the face normal does not
            realise the distance; one point at the true closest points, normal
            along them                           (_closest_features)
        keep points with gap <= margin; a clipped point and its projection on
            the reference line go to A and B; the normal is n, negated when B
            holds the reference edge; shift back to the world

    For separated polygons the smallest gap is the true distance between them
    (to within ``REFERENCE_TOLERANCE`` times the reference edge's length, the
    price of a stable reference face). For overlapping ones it is minus the
    smallest translation along an edge normal that separates them.

    Examples
    --------
    A unit square resting on a 3 m wide base (A = base, B = block):

    >>> import numpy as np
    >>> base = np.array([[-1.5, -0.2], [1.5, -0.2], [1.5, 0.0], [-1.5, 0.0]])
    >>> block = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    >>> m = collide_polygons(base, block, margin=1e-3)
    >>> m.normal, m.gaps
    (array([0., 1.]), array([0., 0.]))
    """
    found = collide_posed_polygons(np.concatenate((a, b)), np.array((0, len(a), len(a) + len(b))),
                                   _ONE_PAIR, margin)
    if found.count == 0:
        return None
    return Manifold(normal=found.normal[0], points_a=found.points_a, points_b=found.points_b,
                    gaps=found.gaps, ids=found.ids)


# --- the kernel: scalar loops over flat arrays, compiled by numba ---
# A polygon's scratch array ``poly`` (5, n) holds, per vertex i: x, y (shifted to A's
# vertex 0), then the outward unit normal nx, ny and the length of edge i (i -> i + 1).


@njit
def collide_posed_xy(x, y, start, pairs, margin):
    """:func:`collide_posed_polygons` without its checks, compiled: vertex coordinates x, y (V,) in m,
    ``start`` (n_polygons + 1,) and ``pairs`` (p, 2) int64, ``margin`` (p,) per pair, m, >= 0.

    Returns the fields of :class:`~nscd.contact.manifold.Manifolds`: ``pair`` (k,),
    ``normal``, ``points_a``, ``points_b`` (k, 2), ``gaps`` (k,), ``ids`` (k,).
    """
    n_pairs = pairs.shape[0]
    most = 0
    for i in range(start.shape[0] - 1):
        most = max(most, start[i + 1] - start[i])
    pa = np.empty((5, most))
    pb = np.empty((5, most))
    clipped = np.empty((2, 4))
    counts = np.zeros(n_pairs, dtype=np.int64)
    normal = np.zeros((n_pairs, 2))
    points_a = np.zeros((n_pairs * MAX_POINTS, 2))
    points_b = np.zeros((n_pairs * MAX_POINTS, 2))
    gaps = np.zeros(n_pairs * MAX_POINTS)
    ids = np.zeros(n_pairs * MAX_POINTS, dtype=np.int64)
    for p in range(n_pairs):
        a0, a1 = start[pairs[p, 0]], start[pairs[p, 0] + 1]
        b0, b1 = start[pairs[p, 1]], start[pairs[p, 1] + 1]
        ox, oy = x[a0], y[a0]
        _shifted(x, y, a0, a1, ox, oy, pa)
        _shifted(x, y, b0, b1, ox, oy, pb)
        counts[p] = _collide_pair(pa, a1 - a0, pb, b1 - b0, ox, oy, margin[p], clipped,
                                  normal[p], points_a, points_b, gaps, ids, p * MAX_POINTS)
    return compact_rows(counts, MAX_POINTS, normal, points_a, points_b, gaps, ids)


@njit_helper
def _shifted(x, y, v0, v1, ox, oy, poly):
    """Fill ``poly`` (5, >= n) with vertices ``v0:v1`` shifted by ``-(ox, oy)`` and their edges' normals, lengths."""
    n = v1 - v0
    for i in range(n):
        poly[0, i] = x[v0 + i] - ox
        poly[1, i] = y[v0 + i] - oy
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        dx = poly[0, j] - poly[0, i]
        dy = poly[1, j] - poly[1, i]
        length = math.sqrt(dx * dx + dy * dy)
        poly[2, i] = dy / length
        poly[3, i] = -dx / length
        poly[4, i] = length


@njit_helper
def _collide_pair(pa, n, pb, m, ox, oy, margin, clipped, normal, points_a, points_b, gaps, ids, row):
    """Contact points of polygons ``pa`` (n vertices) and ``pb`` (m), shifted by (ox, oy): the steps of
    :func:`collide_polygons`. Writes the normal and the points from ``row`` on; returns their count."""
    ea, sa = _max_separation(pa, n, pb, m, margin)
    if sa > margin:
        return 0
    eb, sb = _max_separation(pb, m, pa, n, margin)
    if sb > margin:
        return 0
    flip = _reference_is_b(sa, pa[4, ea], sb, pb[4, eb])
    if flip:
        ref, edge, sep, inc, n_inc = pb, eb, sb, pa, n
    else:
        ref, edge, sep, inc, n_inc = pa, ea, sa, pb, m
    nx, ny, length = ref[2, edge], ref[3, edge], ref[4, edge]
    v1x, v1y = ref[0, edge], ref[1, edge]
    i1 = _incident_edge(nx, ny, inc, n_inc)
    i2 = i1 + 1 if i1 + 1 < n_inc else 0
    w1x, w1y, w2x, w2y = inc[0, i1], inc[1, i1], inc[0, i2], inc[1, i2]
    u1 = nx * (w1y - v1y) - ny * (w1x - v1x)  # along the tangent (-ny, nx)
    u2 = nx * (w2y - v1y) - ny * (w2x - v1x)
    k = _clip(v1x, v1y, nx, ny, length, w1x, w1y, w2x, w2y, u1, u2, clipped)
    beside = (u1 < 0.0 and u2 < 0.0) or (u1 > length and u2 > length)
    if sep > 0.0 and (beside or min(clipped[0, 2], clipped[1, 2]) > sep + REFERENCE_TOLERANCE * length):
        d2, ref_is_b, c_edge, c_vertex, fax, fay, fbx, fby = _closest_features(pa, n, pb, m)
        dist = math.sqrt(d2)
        if dist > margin:
            return 0
        normal[0], normal[1] = (fbx - fax) / dist, (fby - fay) / dist
        points_a[row, 0], points_a[row, 1] = fax + ox, fay + oy
        points_b[row, 0], points_b[row, 1] = fbx + ox, fby + oy
        gaps[row] = dist
        ids[row] = (ref_is_b << 32) | (c_edge << 16) | c_vertex
        return 1
    tag = (np.int64(flip) << 32) | (np.int64(edge) << 16)
    count = 0
    for c in range(k):
        px, py, s = clipped[c, 0], clipped[c, 1], clipped[c, 2]
        if s <= margin:
            rx, ry = px - s * nx + ox, py - s * ny + oy  # on the reference line, back to the world
            px, py = px + ox, py + oy
            if flip:
                points_a[row + count, 0], points_a[row + count, 1] = px, py
                points_b[row + count, 0], points_b[row + count, 1] = rx, ry
            else:
                points_a[row + count, 0], points_a[row + count, 1] = rx, ry
                points_b[row + count, 0], points_b[row + count, 1] = px, py
            gaps[row + count] = s
            ids[row + count] = tag | (i1 if clipped[c, 3] == 0.0 else i2)
            count += 1
    if flip:  # n is B's outward normal: it points from B to A
        normal[0], normal[1] = 0.0 - nx, 0.0 - ny
    else:
        normal[0], normal[1] = nx, ny
    return count


@njit_helper
def _max_separation(poly, n, other, m, margin):
    """Separating-axis test over the edge normals of ``poly`` (n vertices) against ``other`` (m).

    Returns the edge of ``poly`` along whose normal ``other`` is most separated (the
    first one on ties), and that separation in m (``min`` over ``other``'s vertices of
    their signed distance to the edge line; negative: overlap along this axis). Stops at
    the first edge separating by more than ``margin``: the pair is then out of reach.
    """
    best_edge, best = 0, -math.inf
    for i in range(n):
        px, py, nx, ny = poly[0, i], poly[1, i], poly[2, i], poly[3, i]
        s = math.inf
        for j in range(m):
            d = nx * (other[0, j] - px) + ny * (other[1, j] - py)
            if d < s:
                s = d
        if s > best:
            best_edge, best = i, s
            if s > margin:
                break
    return best_edge, best


@njit_helper
def _reference_is_b(sep_a, len_a, sep_b, len_b):
    """Whether B's edge is the reference: larger separation, near ties to the longer edge, then A."""
    tol = REFERENCE_TOLERANCE * max(len_a, len_b)
    if abs(sep_b - sep_a) > tol:
        return sep_b > sep_a
    return len_b > len_a * (1.0 + REFERENCE_TOLERANCE)


@njit_helper
def _incident_edge(nx, ny, poly, n):
    """Edge of ``poly`` (n vertices) whose normal is most anti-parallel to ``(nx, ny)`` (the first on ties)."""
    best_edge, best = 0, math.inf
    for i in range(n):
        d = nx * poly[2, i] + ny * poly[3, i]
        if d < best:
            best_edge, best = i, d
    return best_edge


@njit_helper
def _clip(v1x, v1y, nx, ny, length, w1x, w1y, w2x, w2y, u1, u2, out):
    """Clip the incident edge ``w1 -> w2`` to the side planes of the reference edge.

    ``v1`` is the reference edge's first vertex, ``(nx, ny)`` its outward unit
    normal, ``length`` its length; ``u1``, ``u2`` are the coordinates of ``w1``,
    ``w2`` along the edge's tangent ``(-ny, nx)`` measured from ``v1``, so the
    edge's slab is ``0 <= u <= length``.

    Writes up to two points on the incident edge as rows ``(x, y, separation, k)`` of
    ``out`` (2, 4) and returns their number: separation is the signed distance to the
    reference line along the normal; ``k`` (0.0 or 1.0) names the incident endpoint the
    point comes from. An endpoint inside the slab is kept; one outside is moved along
    the edge onto the side plane it crosses. If the whole edge lies beside the slab
    (only possible for near-degenerate overlaps), the one endpoint nearest to the slab.
    """
    if (u1 < 0.0 and u2 < 0.0) or (u1 > length and u2 > length):
        second = u2 > u1 if u1 < 0.0 else u2 < u1
        px, py = (w2x, w2y) if second else (w1x, w1y)
        out[0, 0], out[0, 1], out[0, 2], out[0, 3] = px, py, nx * (px - v1x) + ny * (py - v1y), 1.0 if second else 0.0
        return 1
    for k in range(2):
        px, py, u, qx, qy, uq = (w1x, w1y, u1, w2x, w2y, u2) if k == 0 else (w2x, w2y, u2, w1x, w1y, u1)
        if u < 0.0 or u > length:
            lam = (u - (0.0 if u < 0.0 else length)) / (u - uq)
            px, py = px + lam * (qx - px), py + lam * (qy - py)
        out[k, 0], out[k, 1], out[k, 2], out[k, 3] = px, py, nx * (px - v1x) + ny * (py - v1y), float(k)
    return 2


@njit_helper
def _closest_features(pa, n, pb, m):
    """Closest points of two disjoint convex polygons, by brute force over vertex-edge pairs.

    Returns ``(d2, ref_is_b, edge, vertex, ax, ay, bx, by)``: the squared distance in
    m^2, which polygon holds the closest edge (0: A, 1: B), that edge, the vertex of the
    other polygon, and the closest points on A and on B (first minimum in the order A's
    edges against B's vertices, then B's edges against A's vertices).
    """
    best, best_ref, best_edge, best_vertex = math.inf, 0, 0, 0
    fax, fay, fbx, fby = 0.0, 0.0, 0.0, 0.0
    for ref_is_b in range(2):
        poly, n_poly, other, n_other = (pb, m, pa, n) if ref_is_b else (pa, n, pb, m)
        for e in range(n_poly):
            f = e + 1 if e + 1 < n_poly else 0
            x0, y0, x1, y1 = poly[0, e], poly[1, e], poly[0, f], poly[1, f]
            dx, dy = x1 - x0, y1 - y0
            dd = dx * dx + dy * dy
            for v in range(n_other):
                px, py = other[0, v], other[1, v]
                lam = ((px - x0) * dx + (py - y0) * dy) / dd
                if lam <= 0.0:
                    fx, fy = x0, y0
                elif lam >= 1.0:
                    fx, fy = x1, y1
                else:
                    fx, fy = x0 + lam * dx, y0 + lam * dy
                d2 = (px - fx) * (px - fx) + (py - fy) * (py - fy)
                if d2 < best:
                    best, best_ref, best_edge, best_vertex = d2, ref_is_b, e, v
                    if ref_is_b:
                        fax, fay, fbx, fby = px, py, fx, fy
                    else:
                        fax, fay, fbx, fby = fx, fy, px, py
    return best, best_ref, best_edge, best_vertex, fax, fay, fbx, fby


def collide_polygons_batch(a: np.ndarray, b: np.ndarray, margin: float) -> Manifolds:
    """Contact points of many polygon pairs at once (vectorised :func:`collide_polygons`).

    Parameters
    ----------
    a, b : ndarray, shape (p, n, 2) and (p, m, 2)
        World vertices in m of the p polygons A and of the p polygons B, each
        counter-clockwise and convex; pair ``i`` is ``(a[i], b[i])``. All A have
        n vertices and all B have m (group pairs by vertex counts beforehand).
    margin : float
        Detection margin in m, >= 0 (as in :func:`collide_polygons`).

    Returns
    -------
    Manifolds
        One row per contact point of the pairs within ``margin``; ``pair``
        gives the index of its pair. Pair by pair the same points, gaps,
        normals and ids as :func:`collide_polygons`, bit for bit.

    Notes
    -----
    One call of the compiled kernel (:func:`collide_posed_polygons`).
    """
    p, n, m = a.shape[0], a.shape[1], b.shape[1]
    start = np.concatenate((np.arange(p + 1) * n, p * n + np.arange(1, p + 1) * m))
    pairs = np.stack((np.arange(p), p + np.arange(p)), axis=1)
    return collide_posed_polygons(np.concatenate((a.reshape(-1, 2), b.reshape(-1, 2))), start, pairs, margin)
