"""Contact manifolds: what narrow-phase detection hands to the contact frames.

One idea: the plain data a collision test returns, shared by 2D polygons
(:func:`nscd.contact.detect2d.collide_polygons`) and 3D polyhedra
(:func:`nscd.contact.detect3d.collide_polyhedra`). ``d`` is the dimension (2 or 3).

Sign conventions (``docs/architecture.md``, "Contact manifold contract"):

* the normal is a unit vector in the world frame pointing **from body A to body B**;
* ``gaps = (points_b - points_a) . normal`` in m, negative when the bodies
  interpenetrate, and equal to the signed distance of the two surfaces along
  the normal at that point;
* ``ids`` are integer feature ids that stay the same while the same features
  touch, so that impulses can be warm-started and a lifting corner identified.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nscd._jit import njit_helper

__all__ = ["Manifold", "Manifolds"]


@dataclass(frozen=True)
class Manifold:
    """Contact between one pair of convex bodies A and B.

    Attributes
    ----------
    normal : ndarray, shape (d,)
        Unit contact normal in the world frame, pointing from A to B.
    points_a : ndarray, shape (k, d)
        Contact points on the surface of A, world frame, m.
    points_b : ndarray, shape (k, d)
        Contact points on the surface of B, world frame, m; ``points_b[i]`` is
        the partner of ``points_a[i]``.
    gaps : ndarray, shape (k,)
        Signed normal distance ``(points_b - points_a) @ normal`` in m;
        negative when penetrating, positive (up to the detection margin)
        for points that are close but not touching.
    ids : ndarray of int64, shape (k,)
        Feature ids, stable while the same features touch (their packing is
        documented by the function that builds the manifold).

    Notes
    -----
    ``k`` is the number of contact points: ``1 <= k <= 2`` in 2D and
    ``1 <= k <= 8`` in 3D. The arrays are not copied; treat them as read-only.
    """

    normal: np.ndarray
    points_a: np.ndarray
    points_b: np.ndarray
    gaps: np.ndarray
    ids: np.ndarray

    @property
    def count(self) -> int:
        """Number of contact points ``k``."""
        return int(self.gaps.shape[0])


@dataclass(frozen=True)
class Manifolds:
    """Contact points of many pairs at once, flattened one row per point.

    Returned by the batched narrow phase
    (:func:`nscd.contact.detect2d.collide_polygons_batch`): the rows of all
    pairs that touch (within the margin), pair after pair, in the order of
    the pairs given, each pair's points in the order :class:`Manifold` would
    list them.

    Attributes
    ----------
    pair : ndarray of int64, shape (k,)
        Index of the pair (row of the batch input) each contact point belongs to.
    normal : ndarray, shape (k, d)
        Unit normal of the point's pair, world frame, from A to B.
    points_a, points_b : ndarray, shape (k, d)
        Contact points on A and on B, world frame, m.
    gaps : ndarray, shape (k,)
        Signed normal distance ``sum((points_b - points_a) * normal, axis=1)``
        in m; negative when penetrating.
    ids : ndarray of int64, shape (k,)
        Feature ids, with the same packing as the single-pair function.
    """

    pair: np.ndarray
    normal: np.ndarray
    points_a: np.ndarray
    points_b: np.ndarray
    gaps: np.ndarray
    ids: np.ndarray

    @property
    def count(self) -> int:
        """Number of contact points ``k`` over all pairs."""
        return int(self.gaps.shape[0])

    def manifold(self, pair: int) -> Manifold | None:
        """The :class:`Manifold` of one pair, or None if that pair has no point."""
        rows = np.flatnonzero(self.pair == pair)
        if rows.size == 0:
            return None
        return Manifold(
            normal=self.normal[rows[0]],
            points_a=self.points_a[rows],
            points_b=self.points_b[rows],
            gaps=self.gaps[rows],
            ids=self.ids[rows],
        )


@njit_helper
def compact_rows(counts: np.ndarray, max_points: int, normal: np.ndarray, points_a: np.ndarray,
                 points_b: np.ndarray, gaps: np.ndarray, ids: np.ndarray):
    """Rows of a narrow-phase kernel's output kept and flattened, pair by pair.

    The kernels write pair ``p``'s points into rows ``p * max_points`` onward and its
    count into ``counts[p]``; this keeps the first ``counts[p]`` rows of each block, in
    order. Returns ``pair`` (index of each row's pair), then the normal of its pair and
    the kept rows of ``points_a``, ``points_b``, ``gaps`` and ``ids``.
    """
    total = 0
    for p in range(len(counts)):
        total += counts[p]
    dim = normal.shape[1]
    pair = np.empty(total, dtype=np.int64)
    kept_normal = np.empty((total, dim))
    kept_a = np.empty((total, dim))
    kept_b = np.empty((total, dim))
    kept_gaps = np.empty(total)
    kept_ids = np.empty(total, dtype=np.int64)
    k = 0
    for p in range(len(counts)):  # explicit loops: fancy indexing compiles numpy's indexing machinery
        for i in range(counts[p]):
            row = p * max_points + i
            pair[k] = p
            for d in range(dim):
                kept_normal[k, d] = normal[p, d]
                kept_a[k, d] = points_a[row, d]
                kept_b[k, d] = points_b[row, d]
            kept_gaps[k], kept_ids[k] = gaps[row], ids[row]
            k += 1
    return pair, kept_normal, kept_a, kept_b, kept_gaps, kept_ids


def pair_margins(margin: float | np.ndarray, n_pairs: int) -> np.ndarray:
    """Detection margins (n_pairs,), m, of a narrow-phase call: ``margin`` one for all pairs or one per pair.

    Raises
    ------
    ValueError
        If a margin is negative or not finite, or there is not one per pair.
    """
    given = np.asarray(margin, dtype=float)
    bad = np.flatnonzero(~(np.isfinite(given) & (given >= 0.0)))
    if bad.size:
        where = "" if given.ndim == 0 else f" (pair {bad[0]})"
        raise ValueError(f"margin == {given.ravel()[bad[0]]}{where}, must be >= 0 m and finite.")
    if given.ndim == 1 and len(given) != n_pairs:
        raise ValueError(f"len(margin) == {len(given)}, must be one margin or one per pair ({n_pairs}).")
    return np.ascontiguousarray(np.broadcast_to(given, (n_pairs,)))
