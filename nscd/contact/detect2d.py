"""Narrow-phase contact detection between two convex polygons (2D).

The algorithm is the one of Box2D's ``b2CollidePolygons`` (separating axes,
reference and incident edges, clipping), written afresh for nscd with its
conventions: the normal points from A to B, gaps are signed distances in m,
and points within a detection ``margin`` are kept so that a lifting corner
stays known to the solver while it may still land within the step.

Two entry points compute the same thing:

* :func:`collide_polygons` -- one pair, plain Python floats (for polygons of a
  few vertices this is several times faster than numpy on tiny arrays);
* :func:`collide_polygons_batch` -- many pairs with the same vertex counts at
  once, vectorised with numpy (for walls of thousands of blocks).

They follow the same steps, one helper per step, and are cross-checked by the
tests. Inputs are not validated here (a :class:`~nscd.scene.Scene` validates its
shapes when it is built); polygons must be convex, counter-clockwise, without
repeated vertices, in world coordinates.

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

from nscd.contact.broad import broad_phase  # re-exported: docs/architecture.md lists it here
from nscd.contact.manifold import Manifold, Manifolds

__all__ = ["broad_phase", "collide_polygons", "collide_polygons_batch", "split_ids"]

#: Relative tolerance of the reference-face choice: separations within
#: ``REFERENCE_TOLERANCE * (longest candidate edge)`` count as a tie, and a tie
#: goes to the longer edge (the base under a block), then to A. Keeps the
#: reference, hence the normal and the ids, from flickering on round-off
#: (e.g. a block resting flat, where both separations are 0).
REFERENCE_TOLERANCE = 1e-6


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


def _edge_normals(poly: list[list[float]]) -> list[tuple[float, float, float]]:
    """Outward unit normal ``(nx, ny)`` and length of each edge of a CCW polygon."""
    out = []
    for (x0, y0), (x1, y1) in zip(poly, poly[1:] + poly[:1]):
        dx = x1 - x0
        dy = y1 - y0
        length = math.sqrt(dx * dx + dy * dy)
        out.append((dy / length, -dx / length, length))
    return out


def _max_separation(
    poly: list[list[float]],
    normals: list[tuple[float, float, float]],
    other: list[list[float]],
    margin: float,
) -> tuple[int, float]:
    """Separating-axis test over the edge normals of ``poly``.

    Returns the edge of ``poly`` along whose normal ``other`` is most separated,
    and that separation in m (``min`` over ``other``'s vertices of their signed
    distance to the edge line; negative: overlap along this axis). Stops at the
    first edge separating by more than ``margin``: the pair is then out of reach.
    """
    best_edge, best = 0, -math.inf
    i = 0
    for (px, py), (nx, ny, _) in zip(poly, normals):
        s = math.inf
        for qx, qy in other:  # plain loops: faster than numpy or min() on a few vertices
            d = nx * (qx - px) + ny * (qy - py)
            if d < s:
                s = d
        if s > best:
            best_edge, best = i, s
            if s > margin:
                break
        i += 1
    return best_edge, best


def _reference_is_b(sep_a: float, len_a: float, sep_b: float, len_b: float) -> bool:
    """Whether B's edge is the reference: larger separation, near ties to the longer edge, then A."""
    tol = REFERENCE_TOLERANCE * max(len_a, len_b)
    if abs(sep_b - sep_a) > tol:
        return sep_b > sep_a
    return len_b > len_a * (1.0 + REFERENCE_TOLERANCE)


def _incident_edge(nx: float, ny: float, normals: list[tuple[float, float, float]]) -> int:
    """Edge of the incident polygon whose normal is most anti-parallel to ``(nx, ny)``."""
    dots = [nx * mx + ny * my for mx, my, _ in normals]
    return dots.index(min(dots))


def _clip(
    v1: list[float], nx: float, ny: float, length: float,
    w1: list[float], w2: list[float], u1: float, u2: float,
) -> list[tuple[float, float, float, int]]:
    """Clip the incident edge ``w1 -> w2`` to the side planes of the reference edge.

    ``v1`` is the reference edge's first vertex, ``(nx, ny)`` its outward unit
    normal, ``length`` its length; ``u1``, ``u2`` are the coordinates of ``w1``,
    ``w2`` along the edge's tangent ``(-ny, nx)`` measured from ``v1``, so the
    edge's slab is ``0 <= u <= length``.

    Returns up to two points on the incident edge as ``(x, y, separation, k)``:
    separation is the signed distance to the reference line along the normal;
    ``k`` (0 or 1) names the incident endpoint the point comes from. An endpoint
    inside the slab is kept; one outside is moved along the edge onto the side
    plane it crosses. If the whole edge lies beside the slab (only possible for
    near-degenerate overlaps), the one endpoint nearest to the slab.
    """
    x1, y1 = v1
    if (u1 < 0.0 and u2 < 0.0) or (u1 > length and u2 > length):
        k = int(u2 > u1 if u1 < 0.0 else u2 < u1)
        px, py = (w1, w2)[k]
        return [(px, py, nx * (px - x1) + ny * (py - y1), k)]
    out = []
    for k, ((px, py), u, (qx, qy), uq) in enumerate(((w1, u1, w2, u2), (w2, u2, w1, u1))):
        if u < 0.0 or u > length:
            lam = (u - (0.0 if u < 0.0 else length)) / (u - uq)
            px, py = px + lam * (qx - px), py + lam * (qy - py)
        out.append((px, py, nx * (px - x1) + ny * (py - y1), k))
    return out


def _closest_features(pa: list[list[float]], pb: list[list[float]]
                      ) -> tuple[float, int, int, int, tuple[float, float], tuple[float, float]]:
    """Closest points of two disjoint convex polygons, by brute force over vertex-edge pairs.

    Returns ``(distance, ref_is_b, edge, vertex, on_a, on_b)``: the distance in m,
    which polygon holds the closest edge (0: A, 1: B), that edge, the vertex of
    the other polygon, and the closest points on A and on B.
    """
    best = (math.inf, 0, 0, 0, (0.0, 0.0), (0.0, 0.0))
    for ref_is_b, (poly, other) in enumerate(((pa, pb), (pb, pa))):
        for e, ((x0, y0), (x1, y1)) in enumerate(zip(poly, poly[1:] + poly[:1])):
            dx, dy = x1 - x0, y1 - y0
            dd = dx * dx + dy * dy
            for v, (px, py) in enumerate(other):
                lam = ((px - x0) * dx + (py - y0) * dy) / dd
                fx, fy = (x0, y0) if lam <= 0.0 else (x1, y1) if lam >= 1.0 else (x0 + lam * dx, y0 + lam * dy)
                d2 = (px - fx) ** 2 + (py - fy) ** 2
                if d2 < best[0]:
                    foot, vertex = (fx, fy), (px, py)
                    best = (d2, ref_is_b, e, v) + ((vertex, foot) if ref_is_b else (foot, vertex))
    return (math.sqrt(best[0]),) + best[1:]


def _manifold(nx: float, ny: float, rows: list[list[float]], ids: list[int]) -> Manifold:
    """Pack world rows ``[xa, ya, xb, yb, gap]`` and ids into a :class:`Manifold`."""
    out = np.array(rows)  # one array, three views: cheaper than three arrays
    return Manifold(normal=np.array((nx, ny)), points_a=out[:, 0:2], points_b=out[:, 2:4],
                    gaps=out[:, 4], ids=np.array(ids, dtype=np.int64))


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

    Notes
    -----
    The algorithm, after Box2D's ``b2CollidePolygons``::

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
            holds the reference edge
        shift back to the world                  (_manifold)

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
    pa = a.tolist()
    ox, oy = pa[0]
    pa = [[x - ox, y - oy] for x, y in pa]
    pb = [[x - ox, y - oy] for x, y in b.tolist()]
    na = _edge_normals(pa)
    ea, sa = _max_separation(pa, na, pb, margin)
    if sa > margin:
        return None
    nb = _edge_normals(pb)
    eb, sb = _max_separation(pb, nb, pa, margin)
    if sb > margin:
        return None

    flip = _reference_is_b(sa, na[ea][2], sb, nb[eb][2])
    if flip:
        ref, ref_normals, edge, sep, inc, inc_normals = pb, nb, eb, sb, pa, na
    else:
        ref, ref_normals, edge, sep, inc, inc_normals = pa, na, ea, sa, pb, nb
    nx, ny, length = ref_normals[edge]
    v1 = ref[edge]
    ie = _incident_edge(nx, ny, inc_normals)
    inc_vertices = (ie, (ie + 1) % len(inc))
    w1, w2 = inc[inc_vertices[0]], inc[inc_vertices[1]]
    u1 = nx * (w1[1] - v1[1]) - ny * (w1[0] - v1[0])  # along the tangent (-ny, nx)
    u2 = nx * (w2[1] - v1[1]) - ny * (w2[0] - v1[0])
    clipped = _clip(v1, nx, ny, length, w1, w2, u1, u2)

    beside = (u1 < 0.0 and u2 < 0.0) or (u1 > length and u2 > length)
    if sep > 0.0 and (beside or min(c[2] for c in clipped) > sep + REFERENCE_TOLERANCE * length):
        dist, ref_is_b, edge, vertex, on_a, on_b = _closest_features(pa, pb)
        if dist > margin:
            return None
        row = [on_a[0] + ox, on_a[1] + oy, on_b[0] + ox, on_b[1] + oy, dist]
        return _manifold((on_b[0] - on_a[0]) / dist, (on_b[1] - on_a[1]) / dist, [row],
                         [(ref_is_b << 32) | (edge << 16) | vertex])

    rows, ids = [], []
    tag = (int(flip) << 32) | (edge << 16)
    for x, y, s, k in clipped:
        if s <= margin:
            on_ref, on_inc = [x - s * nx + ox, y - s * ny + oy], [x + ox, y + oy]  # back to the world
            rows.append(on_inc + on_ref + [s] if flip else on_ref + on_inc + [s])
            ids.append(tag | inc_vertices[k])
    if not rows:
        return None
    if flip:  # n is B's outward normal: it points from B to A
        return _manifold(0.0 - nx, 0.0 - ny, rows, ids)
    return _manifold(nx, ny, rows, ids)


# --- batched path: the same steps on arrays of x and y coordinates, one row per pair ---
# (separate contiguous x and y arrays: several times faster than strided (..., 2) arrays)


def _edge_normals_batch(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched :func:`_edge_normals`: vertex coordinates (p, n) -> normals nx, ny and lengths, each (p, n)."""
    dx = np.roll(x, -1, axis=1) - x
    dy = np.roll(y, -1, axis=1) - y
    length = np.sqrt(dx * dx + dy * dy)
    return dy / length, -dx / length, length


def _max_separation_batch(x: np.ndarray, y: np.ndarray, nx: np.ndarray, ny: np.ndarray,
                          qx: np.ndarray, qy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Batched :func:`_max_separation` of polygons (p, n) against others (p, m): edge (p,), separation (p,)."""
    seps = (nx[:, :, None] * (qx[:, None, :] - x[:, :, None])
            + ny[:, :, None] * (qy[:, None, :] - y[:, :, None])).min(axis=2)
    edge = seps.argmax(axis=1)
    return edge, seps[np.arange(len(edge)), edge]


def _closest_features_batch(ax: np.ndarray, ay: np.ndarray, bx: np.ndarray, by: np.ndarray
                            ) -> tuple[np.ndarray, ...]:
    """Batched :func:`_closest_features` for r pairs of polygons (r, n) and (r, m).

    Returns arrays (r,): distance, ref_is_b, edge, vertex, and the closest
    points on A and on B as (r, 2) arrays.
    """
    r = np.arange(ax.shape[0])
    cand = []  # per direction: foot x, foot y, vertex x, vertex y, each (r, edges * vertices)
    for x, y, qx, qy in ((ax, ay, bx, by), (bx, by, ax, ay)):  # edges of one against vertices of the other
        x1, y1 = np.roll(x, -1, axis=1)[:, :, None], np.roll(y, -1, axis=1)[:, :, None]
        x0, y0 = x[:, :, None], y[:, :, None]
        dx, dy = x1 - x0, y1 - y0
        px, py = qx[:, None, :], qy[:, None, :]
        lam = np.clip(((px - x0) * dx + (py - y0) * dy) / (dx * dx + dy * dy), 0.0, 1.0)
        fx = np.where(lam == 1.0, x1, x0 + lam * dx)
        fy = np.where(lam == 1.0, y1, y0 + lam * dy)
        shape = (len(r), -1)
        cand.append([np.broadcast_to(v, lam.shape).reshape(shape) for v in (fx, fy, px, py)])
    fx, fy, px, py = (np.concatenate(c, axis=1) for c in zip(*cand))
    best = ((px - fx) ** 2 + (py - fy) ** 2).argmin(axis=1)
    fx, fy, px, py = fx[r, best], fy[r, best], px[r, best], py[r, best]
    n_a = ax.shape[1] * bx.shape[1]
    ref_is_b = best >= n_a
    local = np.where(ref_is_b, best - n_a, best)
    n_other = np.where(ref_is_b, ax.shape[1], bx.shape[1])
    foot, vertex = np.stack((fx, fy), axis=1), np.stack((px, py), axis=1)
    on_a = np.where(ref_is_b[:, None], vertex, foot)
    on_b = np.where(ref_is_b[:, None], foot, vertex)
    dist = np.sqrt((on_b[:, 0] - on_a[:, 0]) ** 2 + (on_b[:, 1] - on_a[:, 1]) ** 2)
    return dist, ref_is_b, local // n_other, local % n_other, on_a, on_b


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
        normals and ids as :func:`collide_polygons` (to round-off).

    Notes
    -----
    The steps of :func:`collide_polygons`, on arrays; memory and time grow as
    ``p * n * m``.
    """
    ox, oy = a[:, :1, 0], a[:, :1, 1]
    ax, ay = a[..., 0] - ox, a[..., 1] - oy  # shifted to A's vertex 0, as in the single-pair path
    bx, by = b[..., 0] - ox, b[..., 1] - oy
    nax, nay, la = _edge_normals_batch(ax, ay)
    ea, sa = _max_separation_batch(ax, ay, nax, nay, bx, by)
    nbx, nby, lb = _edge_normals_batch(bx, by)
    eb, sb = _max_separation_batch(bx, by, nbx, nby, ax, ay)
    near = np.flatnonzero((sa <= margin) & (sb <= margin))
    ax, ay, bx, by, nax, nay, la, nbx, nby, lb, ea, sa, eb, sb, ox, oy = (
        v[near] for v in (ax, ay, bx, by, nax, nay, la, nbx, nby, lb, ea, sa, eb, sb, ox, oy))
    rows = np.arange(near.size)
    n, m = ax.shape[1], bx.shape[1]

    # reference edge (_reference_is_b): its first vertex v, outward normal (nx, ny), length
    len_a, len_b = la[rows, ea], lb[rows, eb]
    tie = np.abs(sb - sa) <= REFERENCE_TOLERANCE * np.maximum(len_a, len_b)
    flip = np.where(tie, len_b > len_a * (1.0 + REFERENCE_TOLERANCE), sb > sa)
    edge = np.where(flip, eb, ea)
    sep = np.where(flip, sb, sa)
    length = np.where(flip, len_b, len_a)
    nx = np.where(flip, nbx[rows, eb], nax[rows, ea])
    ny = np.where(flip, nby[rows, eb], nay[rows, ea])
    vx = np.where(flip, bx[rows, eb], ax[rows, ea])
    vy = np.where(flip, by[rows, eb], ay[rows, ea])

    # incident edge (_incident_edge): endpoints k = 0, 1 as columns
    ia = (nax * nx[:, None] + nay * ny[:, None]).argmin(axis=1)
    ib = (nbx * nx[:, None] + nby * ny[:, None]).argmin(axis=1)
    va = np.stack((ia, (ia + 1) % n), axis=1)
    vb = np.stack((ib, (ib + 1) % m), axis=1)
    vertex = np.where(flip[:, None], va, vb)
    r2 = rows[:, None]
    wx = np.where(flip[:, None], ax[r2, va], bx[r2, vb])
    wy = np.where(flip[:, None], ay[r2, va], by[r2, vb])

    # _clip: each endpoint kept, or moved along the edge onto the side plane it lies beyond
    u = nx[:, None] * (wy - vy[:, None]) - ny[:, None] * (wx - vx[:, None])
    length2 = length[:, None]
    beside = (u < 0.0).all(axis=1) | (u > length2).all(axis=1)
    outside = ((u < 0.0) | (u > length2)) & ~beside[:, None]
    plane = np.where(u < 0.0, 0.0, length2)
    uq, wqx, wqy = u[:, ::-1], wx[:, ::-1], wy[:, ::-1]  # the other endpoint
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = np.where(outside, (u - plane) / (u - uq), 0.0)
    px = np.where(outside, wx + lam * (wqx - wx), wx)
    py = np.where(outside, wy + lam * (wqy - wy), wy)
    # beside the slab: only the endpoint nearest to it, as column 0
    nearer = np.where(u[:, 0] < 0.0, u[:, 1] > u[:, 0], u[:, 1] < u[:, 0])
    swap = beside & nearer
    px[swap, 0], py[swap, 0], vertex[swap, 0] = px[swap, 1], py[swap, 1], vertex[swap, 1]
    gaps = nx[:, None] * (px - vx[:, None]) + ny[:, None] * (py - vy[:, None])
    valid = (gaps <= margin) & (~beside[:, None] | (np.arange(2) == 0))
    rx, ry = px - gaps * nx[:, None], py - gaps * ny[:, None]  # projections on the reference line

    flip2 = flip[:, None]
    on_a = np.stack((np.where(flip2, px, rx), np.where(flip2, py, ry)), axis=2)
    on_b = np.stack((np.where(flip2, rx, px), np.where(flip2, ry, py)), axis=2)
    normal = np.where(flip2, 0.0 - np.stack((nx, ny), axis=1), np.stack((nx, ny), axis=1))
    ids = ((flip.astype(np.int64) << 32) | (edge.astype(np.int64) << 16))[:, None] | vertex

    # apart, and the face normal does not realise the distance: _closest_features
    closest = (sep > 0.0) & (beside | (gaps.min(axis=1) > sep + REFERENCE_TOLERANCE * length))
    if closest.any():
        c = np.flatnonzero(closest)
        dist, ref_is_b, c_edge, c_vertex, c_a, c_b = _closest_features_batch(ax[c], ay[c], bx[c], by[c])
        normal[c] = (c_b - c_a) / dist[:, None]
        on_a[c, 0], on_b[c, 0], gaps[c, 0] = c_a, c_b, dist
        ids[c, 0] = (ref_is_b.astype(np.int64) << 32) | (c_edge.astype(np.int64) << 16) | c_vertex
        valid[c] = (dist <= margin)[:, None] & (np.arange(2) == 0)

    pair, k = np.nonzero(valid)
    origin = np.stack((ox[pair, 0], oy[pair, 0]), axis=1)
    return Manifolds(pair=near[pair], normal=normal[pair], points_a=on_a[pair, k] + origin,
                     points_b=on_b[pair, k] + origin, gaps=gaps[pair, k], ids=ids[pair, k])
