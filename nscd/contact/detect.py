"""Contact detection for a whole scene: broad phase, narrow phase, contact laws.

``detect(model, q, margin)`` returns every contact point whose gap is at most
``margin`` (m) as :class:`~nscd.contact.frames.Contacts`. Pairs of two non-dynamic
bodies (fixed or driven) are never tested. The narrow phase is
:func:`nscd.contact.detect2d.collide_polygons` in 2D and
:func:`nscd.contact.detect3d.collide_posed` in 3D (every body posed at once with
:class:`nscd.shapes3d.PolyhedronBatch`, all candidate pairs in one call).
"""
from __future__ import annotations

import weakref

import numpy as np

from nscd.contact.broad import broad_phase
from nscd.contact.detect2d import collide_polygons, collide_polygons_batch
from nscd.contact.detect3d import collide_posed
from nscd.contact.frames import Contacts, tangent_frames
from nscd.model import Model
from nscd.rotation import quaternion_to_matrix
from nscd.shapes3d import PolyhedronBatch


def _pose_polygons(q: np.ndarray, local: np.ndarray) -> np.ndarray:
    """World vertices (k, n, 2), m, of k polygons with body-frame vertices ``local`` (k, n, 2) at poses q (k, 3)."""
    c, s = np.cos(q[:, 2:3]), np.sin(q[:, 2:3])
    x, y = local[..., 0], local[..., 1]
    return np.stack([q[:, 0:1] + c * x - s * y, q[:, 1:2] + s * x + c * y], axis=2)


#: Scenes with at most this many bodies test all pairs of bounding boxes at once (cheaper
#: than sort-and-sweep for a few bodies; the same pairs in the same order).
ALL_PAIRS_BODIES = 16


def _pairs_of_boxes(model: Model, lower: np.ndarray, upper: np.ndarray, margin: float) -> np.ndarray:
    """Pairs (i, j), i < j, whose bounding boxes overlap within ``margin`` and that involve a dynamic body.

    ``lower`` and ``upper`` (n_bodies, dim), m, are the corners of the bodies' boxes.
    Boxes pair as in :func:`nscd.contact.broad.broad_phase` (overlap on every axis once
    grown by ``margin``), sorted by ``i`` then ``j``.
    """
    if len(lower) <= ALL_PAIRS_BODIES:
        overlap = ((lower[None, :, :] <= upper[:, None, :] + margin)
                   & (lower[:, None, :] <= upper[None, :, :] + margin)).all(axis=2)
        overlap &= model.dynamic[:, None] | model.dynamic[None, :]
        return np.argwhere(np.triu(overlap, k=1))
    pairs = broad_phase(lower, upper, margin)
    if len(pairs) == 0:
        return np.zeros((0, 2), dtype=int)
    keep = model.dynamic[pairs[:, 0]] | model.dynamic[pairs[:, 1]]
    return pairs[keep]


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


def _contacts(model: Model, found: list) -> Contacts:
    """Contacts from ``(i, j, manifold)`` triples, in the order given."""
    if not found:
        return Contacts.empty(model.dim)
    counts = [len(m.gaps) for _, _, m in found]
    laws = np.array([model.contact_law(i, j) for i, j, _ in found]).reshape(-1, 2)
    a = np.repeat([i for i, _, _ in found], counts)
    b = np.repeat([j for _, j, _ in found], counts)
    normals = np.concatenate([np.broadcast_to(m.normal, (k, model.dim)) for (_, _, m), k in zip(found, counts)])
    points = np.concatenate([0.5 * (m.points_a + m.points_b) for _, _, m in found])
    return Contacts(
        body_a=a, body_b=b, point=points, frame=tangent_frames(normals),
        gap=np.concatenate([m.gaps for _, _, m in found]),
        friction=np.repeat(laws[:, 0], counts), restitution=np.repeat(laws[:, 1], counts),
        ids=np.column_stack([a, b, np.concatenate([m.ids for _, _, m in found])]),
    )


#: Scenes with fewer candidate pairs than this run the narrow phase pair by pair (less
#: overhead than the batched one for a few pairs; the same contacts).
BATCH_PAIRS = 8


def _detect_polygons(model: Model, q: np.ndarray, margin: float) -> Contacts:
    """2D :func:`detect`: bodies posed per vertex-count group, narrow phase batched per group pair."""
    groups = model.polygon_groups()
    posed = [_pose_polygons(q[index], local) for index, local in groups]
    n_bodies = len(model.bodies)
    group_of = np.empty(n_bodies, dtype=int)
    slot_of = np.empty(n_bodies, dtype=int)
    lower = np.empty((n_bodies, 2))
    upper = np.empty((n_bodies, 2))
    for g, ((index, _), world) in enumerate(zip(groups, posed)):
        group_of[index] = g
        slot_of[index] = np.arange(len(index))
        lower[index] = world.min(axis=1)
        upper[index] = world.max(axis=1)
    pairs = _pairs_of_boxes(model, lower, upper, margin)
    if len(pairs) == 0:
        return Contacts.empty(2)
    if len(pairs) < BATCH_PAIRS:
        found = []
        for i, j in pairs.tolist():
            manifold = collide_polygons(posed[group_of[i]][slot_of[i]], posed[group_of[j]][slot_of[j]], margin)
            if manifold is not None and len(manifold.gaps):
                found.append((i, j, manifold))
        return _contacts(model, found)
    i, j = pairs[:, 0], pairs[:, 1]
    kind = group_of[i] * len(groups) + group_of[j]
    rows = []  # per group pair: pair index, normal, point, gap, feature id of each contact point
    for code in np.unique(kind):
        sel = np.flatnonzero(kind == code)
        m = collide_polygons_batch(posed[code // len(groups)][slot_of[i[sel]]],
                                   posed[code % len(groups)][slot_of[j[sel]]], margin)
        rows.append((sel[m.pair], m.normal, 0.5 * (m.points_a + m.points_b), m.gaps, m.ids))
    pair, normal, point, gap, feature = (np.concatenate(column) for column in zip(*rows))
    if len(pair) == 0:
        return Contacts.empty(2)
    order = np.argsort(pair, kind="stable")
    pair, normal, point, gap, feature = pair[order], normal[order], point[order], gap[order], feature[order]
    a, b = i[pair], j[pair]
    friction, restitution = model.contact_laws(a, b)
    return Contacts(
        body_a=a, body_b=b, point=point, frame=tangent_frames(normal), gap=gap,
        friction=friction, restitution=restitution, ids=np.column_stack([a, b, feature]),
    )
