"""Contact detection for a whole scene: broad phase, narrow phase, contact laws.

``detect(model, q, margin)`` returns every contact point whose gap is at most
``margin`` (m) as :class:`~nscd.contact.frames.Contacts`. Pairs of two non-dynamic
bodies (fixed or driven) are never tested. The narrow phase is
:func:`nscd.contact.detect2d.collide_posed_polygons` in 2D (every vertex posed at
once, all candidate pairs in one call of the compiled kernel) and
:func:`nscd.contact.detect3d.collide_posed` in 3D (every body posed at once with
:class:`nscd.shapes3d.PolyhedronBatch`, all candidate pairs in one call).
"""
from __future__ import annotations

import weakref

import numpy as np

from nscd.contact.broad import broad_phase
from nscd._jit import HAVE_NUMBA, njit
from nscd.contact.detect2d import collide_polygons_batch, collide_posed_polygons
from nscd.contact.detect3d import collide_posed
from nscd.contact.frames import Contacts, tangent_frames
from nscd.contact.manifold import Manifolds
from nscd.model import Model
from nscd.rotation import quaternion_to_matrix
from nscd.shapes3d import PolyhedronBatch


def _pose_polygons(q: np.ndarray, local: np.ndarray) -> np.ndarray:
    """World vertices (k, n, 2), m, of k polygons with body-frame vertices ``local`` (k, n, 2) at poses q (k, 3)."""
    c, s = np.cos(q[:, 2:3]), np.sin(q[:, 2:3])
    x, y = local[..., 0], local[..., 1]
    return np.stack([q[:, 0:1] + c * x - s * y, q[:, 1:2] + s * x + c * y], axis=2)


#: Scenes with at most this many bodies test every pair of bounding boxes in one loop,
#: compiled with numba (cheaper than sort-and-sweep for a few bodies; the same pairs in
#: the same order).
ALL_PAIRS_BODIES = 16


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
    """All contact points of configuration ``q`` with gap <= ``margin`` (m).

    Contacts come pair by pair (pairs sorted by body ``i``, then ``j``), each pair's
    points in the order of its manifold.
    """
    if model.dim == 2:
        return _detect_polygons(model, q, margin)
    return _detect_polyhedra(model, q, margin)


#: The bodies' shapes of each 3D model laid end to end, built on first use.
_BATCHES: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _detect_polyhedra(model: Model, q: np.ndarray, margin: float) -> Contacts:
    """3D :func:`detect`: every body posed at once, all candidate pairs in one narrow-phase call."""
    batch = _BATCHES.get(model)
    if batch is None:
        batch = _BATCHES[model] = PolyhedronBatch([body.shape for body in model.bodies])
    # quaternion_to_matrix on the (4, n) columns gives (3, 3, n)
    posed = batch.pose(q[:, :3], quaternion_to_matrix(q[:, 3:].T).transpose(2, 0, 1))
    starts = batch.vertex_start[:-1]
    pairs = _pairs_of_boxes(model, np.minimum.reduceat(posed.vertices, starts, axis=0),
                            np.maximum.reduceat(posed.vertices, starts, axis=0), margin)
    if len(pairs) == 0:
        return Contacts.empty(3)
    found = collide_posed(batch, posed, pairs, margin)
    if found.count == 0:
        return Contacts.empty(3)
    counts = np.bincount(found.pair, minlength=len(pairs))
    touching = np.flatnonzero(counts)
    counts = counts[touching]
    laws = np.array([model.contact_law(i, j) for i, j in pairs[touching].tolist()])
    a, b = pairs[found.pair, 0], pairs[found.pair, 1]
    return Contacts(
        body_a=a, body_b=b, point=0.5 * (found.points_a + found.points_b), frame=tangent_frames(found.normal),
        gap=found.gaps, friction=np.repeat(laws[:, 0], counts), restitution=np.repeat(laws[:, 1], counts),
        ids=np.column_stack([a, b, found.ids]),
    )


#: The bodies' polygons of each 2D model laid end to end, built on first use.
_POLYGONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _flat_polygons(model: Model) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Body-frame vertices (V, 1, 2) of all bodies laid end to end, m; each vertex's body (V,); starts (n + 1,)."""
    flat = _POLYGONS.get(model)
    if flat is None:
        shapes = [np.asarray(body.shape.vertices, dtype=float) for body in model.bodies]
        counts = np.array([len(s) for s in shapes])
        flat = _POLYGONS[model] = (np.concatenate(shapes)[:, None, :], np.repeat(np.arange(len(shapes)), counts),
                                   np.concatenate(([0], np.cumsum(counts))))
    return flat


#: Contact laws of every pair of bodies of each small model, built on first use.
_LAWS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _law_table(model: Model) -> np.ndarray:
    """Friction and restitution of every body pair ``(i, j)`` of a model of a few bodies, (n, n, 2).

    The values of :meth:`nscd.model.Model.contact_laws`, looked up by fancy indexing
    (cheaper than its search for the few contacts of a small scene).
    """
    table = _LAWS.get(model)
    if table is None:
        i, j = np.divmod(np.arange(len(model.bodies) ** 2), len(model.bodies))
        table = _LAWS[model] = np.stack(model.contact_laws(i, j), axis=1).reshape(len(model.bodies), -1, 2)
    return table


#: Without numba, scenes with at least this many candidate pairs run the narrow phase
#: vectorised by numpy per vertex-count group (cheaper than the kernel run as plain
#: Python; the same contacts, bit for bit).
BATCH_PAIRS = 8


def _detect_polygons(model: Model, q: np.ndarray, margin: float) -> Contacts:
    """2D :func:`detect`: every vertex posed at once, all candidate pairs in one narrow-phase call."""
    local, owner, start = _flat_polygons(model)
    world = _pose_polygons(q[owner], local).reshape(-1, 2)
    first = start[:-1]
    pairs = _pairs_of_boxes(model, np.minimum.reduceat(world, first, axis=0),
                            np.maximum.reduceat(world, first, axis=0), margin)
    if len(pairs) == 0:
        return Contacts.empty(2)
    if HAVE_NUMBA or len(pairs) < BATCH_PAIRS:
        found = collide_posed_polygons(world, start, pairs, margin)
    else:
        found = _collide_grouped(model, world, start, pairs, margin)
    if found.count == 0:
        return Contacts.empty(2)
    a, b = pairs[found.pair, 0], pairs[found.pair, 1]
    if len(model.bodies) <= ALL_PAIRS_BODIES:
        laws = _law_table(model)[a, b]
        friction, restitution = laws[:, 0], laws[:, 1]
    else:
        friction, restitution = model.contact_laws(a, b)
    return Contacts(
        body_a=a, body_b=b, point=0.5 * (found.points_a + found.points_b), frame=tangent_frames(found.normal),
        gap=found.gaps, friction=friction, restitution=restitution, ids=np.column_stack([a, b, found.ids]),
    )


def _collide_grouped(model: Model, world: np.ndarray, start: np.ndarray, pairs: np.ndarray,
                     margin: float) -> Manifolds:
    """:func:`~nscd.contact.detect2d.collide_posed_polygons` by the numpy path of
    :func:`~nscd.contact.detect2d.collide_polygons_batch`, one call per pair of vertex counts."""
    groups = model.polygon_groups()
    posed = [world[start[index][:, None] + np.arange(local.shape[1])] for index, local in groups]
    n_bodies = len(model.bodies)
    group_of = np.empty(n_bodies, dtype=int)
    slot_of = np.empty(n_bodies, dtype=int)
    for g, (index, _) in enumerate(groups):
        group_of[index] = g
        slot_of[index] = np.arange(len(index))
    i, j = pairs[:, 0], pairs[:, 1]
    kind = group_of[i] * len(groups) + group_of[j]
    found = []
    for code in np.unique(kind):
        sel = np.flatnonzero(kind == code)
        m = collide_polygons_batch(posed[code // len(groups)][slot_of[i[sel]]],
                                   posed[code % len(groups)][slot_of[j[sel]]], margin)
        found.append((sel[m.pair], m.normal, m.points_a, m.points_b, m.gaps, m.ids))
    columns = [np.concatenate(column) for column in zip(*found)]
    order = np.argsort(columns[0], kind="stable")
    return Manifolds(*(column[order] for column in columns))
