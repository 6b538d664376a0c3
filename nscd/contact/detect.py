"""Contact detection for a whole scene: broad phase, narrow phase, contact laws.

``detect(model, q, margin)`` returns every contact point whose gap is at most
``margin`` (m) as :class:`~nscd.contact.frames.Contacts`. Pairs of two non-dynamic
bodies (fixed or driven) are never tested. The narrow phase is
:func:`nscd.contact.detect2d.collide_polygons` in 2D and
:func:`nscd.contact.detect3d.collide_polyhedra` in 3D.
"""
from __future__ import annotations

import numpy as np

from nscd.contact.broad import broad_phase
from nscd.contact.detect2d import collide_polygons
from nscd.contact.detect3d import collide_polyhedra
from nscd.contact.frames import Contacts, tangent_frames
from nscd.model import Model
from nscd.rotation import quaternion_to_matrix


def posed_shapes(model: Model, q: np.ndarray) -> list:
    """Every body's shape in the world: (n_i, 2) vertex arrays in 2D, placed polyhedra in 3D."""
    out = []
    if model.dim == 2:
        for body, qi in zip(model.bodies, q):
            c, s = np.cos(qi[2]), np.sin(qi[2])
            local = body.shape.vertices
            out.append(np.column_stack([qi[0] + c * local[:, 0] - s * local[:, 1],
                                        qi[1] + s * local[:, 0] + c * local[:, 1]]))
    else:
        for body, qi in zip(model.bodies, q):
            out.append(body.shape.place(qi[:3], quaternion_to_matrix(qi[3:])))
    return out


def _vertices(posed) -> np.ndarray:
    return posed if isinstance(posed, np.ndarray) else posed.vertices


def _narrow_phase(dim: int, a, b, margin: float):
    if dim == 2:
        return collide_polygons(a, b, margin)
    return collide_polyhedra(a, b, margin)


#: Scenes with at most this many bodies test all pairs of bounding boxes at once (cheaper
#: than sort-and-sweep for a few bodies; the same pairs in the same order).
ALL_PAIRS_BODIES = 16


def candidate_pairs(model: Model, posed: list, margin: float) -> np.ndarray:
    """Pairs (i, j), i < j, whose bounding boxes overlap within ``margin`` and that involve a dynamic body.

    Boxes pair as in :func:`nscd.contact.broad.broad_phase` (overlap on every axis once
    grown by ``margin``), sorted by ``i`` then ``j``.
    """
    verts = [_vertices(p) for p in posed]
    lower = np.array([v.min(axis=0) for v in verts])
    upper = np.array([v.max(axis=0) for v in verts])
    if len(verts) <= ALL_PAIRS_BODIES:
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
    """All contact points of configuration ``q`` with gap <= ``margin`` (m)."""
    posed = posed_shapes(model, q)
    pairs = candidate_pairs(model, posed, margin)
    body_a, body_b, points, normals, gaps, feature, mu, e = [], [], [], [], [], [], [], []
    for i, j in pairs.tolist():
        manifold = _narrow_phase(model.dim, posed[i], posed[j], margin)
        if manifold is None or len(manifold.gaps) == 0:
            continue
        k = len(manifold.gaps)
        friction, restitution = model.contact_law(i, j)
        body_a.append(np.full(k, i))
        body_b.append(np.full(k, j))
        points.append(0.5 * (manifold.points_a + manifold.points_b))
        normals.append(np.broadcast_to(manifold.normal, (k, model.dim)))
        gaps.append(manifold.gaps)
        feature.append(manifold.ids)
        mu.append(np.full(k, friction))
        e.append(np.full(k, restitution))
    if not gaps:
        return Contacts.empty(model.dim)
    a = np.concatenate(body_a)
    b = np.concatenate(body_b)
    return Contacts(
        body_a=a, body_b=b, point=np.concatenate(points),
        frame=tangent_frames(np.concatenate(normals)), gap=np.concatenate(gaps),
        friction=np.concatenate(mu), restitution=np.concatenate(e),
        ids=np.column_stack([a, b, np.concatenate(feature)]),
    )
