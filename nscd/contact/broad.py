"""Broad phase: candidate pairs of bodies whose bounding boxes come within a margin.

One idea: sort-and-sweep over axis-aligned bounding boxes (AABB), the same code
for 2D and 3D. The boxes are sorted along the axis on which their centres
spread most; each box is swept against the boxes that start before it ends
(found by binary search), and those candidates are kept if their boxes overlap
on every axis. Everything is vectorised with numpy: cost O(n log n + c) for
n boxes and c candidates from the sweep.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["broad_phase"]

Exclude = Callable[[np.ndarray, np.ndarray], np.ndarray]


def broad_phase(
    lower: np.ndarray,
    upper: np.ndarray,
    margin: float,
    exclude: Exclude | np.ndarray | None = None,
) -> np.ndarray:
    """Pairs of boxes that overlap once grown by ``margin``.

    Boxes ``i`` and ``j`` form a pair when, on every axis ``k``,
    ``lower[j, k] <= upper[i, k] + margin`` and ``lower[i, k] <= upper[j, k] + margin``
    (boxes whose gap is exactly ``margin`` do pair).

    Parameters
    ----------
    lower, upper : array_like, shape (n, d)
        Lower and upper corners of the n axis-aligned bounding boxes in m,
        world frame; any dimension d >= 1 (2 and 3 in nscd).
    margin : float
        Detection margin in m, >= 0: boxes closer than this still pair.
    exclude : callable or ndarray of bool, shape (n, n), optional
        Pairs to leave out (e.g. two fixed bodies, or bodies of one rigid
        group). A callable is called once as ``exclude(i, j)`` with two int
        arrays of candidate pairs (``i < j``) and returns a bool array of the
        same shape, True to drop the pair. A boolean matrix drops ``(i, j)``
        when ``exclude[i, j]`` or ``exclude[j, i]`` is True.

    Returns
    -------
    ndarray of int64, shape (p, 2)
        The pairs ``(i, j)`` with ``i < j``, sorted by ``i`` then ``j``.

    Raises
    ------
    ValueError
        If ``lower`` and ``upper`` are not two arrays of equal shape (n, d),
        a box has ``upper < lower``, ``margin`` is negative or not finite, or
        an ``exclude`` matrix is not (n, n).

    Examples
    --------
    >>> import numpy as np
    >>> lower = np.array([[0.0, 0.0], [1.0, 0.0], [5.0, 0.0]])
    >>> upper = lower + 1.0
    >>> broad_phase(lower, upper, margin=0.01)
    array([[0, 1]])
    """
    lower = np.asarray(lower, dtype=float)
    upper = np.asarray(upper, dtype=float)
    if lower.ndim != 2 or lower.shape != upper.shape:
        raise ValueError(
            f"lower.shape == {lower.shape} and upper.shape == {upper.shape}, "
            "must be equal, (n, d)."
        )
    if not (np.isfinite(margin) and margin >= 0.0):
        raise ValueError(f"margin == {margin}, must be finite and >= 0.")
    bad = np.flatnonzero(~(upper >= lower).all(axis=1))
    if bad.size:
        i = bad[0]
        raise ValueError(
            f"box {i}: lower == {lower[i].tolist()}, upper == {upper[i].tolist()}, "
            "must have upper >= lower on every axis."
        )
    n = lower.shape[0]
    if n < 2:
        return np.empty((0, 2), dtype=np.int64)

    # sweep axis: the one along which the box centres spread most
    axis = int(np.argmax((lower + upper).var(axis=0)))
    order = np.argsort(lower[:, axis], kind="stable")
    lo, up = lower[order].T.copy(), upper[order].T.copy()  # (d, n): contiguous columns
    # box s (in sorted order) meets the boxes t > s whose start is <= its end + margin
    end = np.searchsorted(lo[axis], up[axis] + margin, side="right")
    counts = np.maximum(end - np.arange(n) - 1, 0)
    s = np.repeat(np.arange(n), counts)
    t = s + 1 + np.arange(s.size) - np.repeat(np.cumsum(counts) - counts, counts)
    # on the sweep axis they overlap by construction; test the other axes, one column at a time
    keep = np.ones(s.size, dtype=bool)
    for k in range(lower.shape[1]):
        if k != axis:
            lo_k, up_k = lo[k], up[k]
            keep &= (lo_k[t] <= up_k[s] + margin) & (lo_k[s] <= up_k[t] + margin)
    i, j = order[s[keep]], order[t[keep]]
    i, j = np.minimum(i, j), np.maximum(i, j)

    if exclude is not None:
        if callable(exclude):
            drop = np.asarray(exclude(i, j), dtype=bool)
        else:
            mask = np.asarray(exclude, dtype=bool)
            if mask.shape != (n, n):
                raise ValueError(f"exclude.shape == {mask.shape}, must be ({n}, {n}).")
            drop = mask[i, j] | mask[j, i]
        i, j = i[~drop], j[~drop]

    rank = np.lexsort((j, i))
    return np.stack((i[rank], j[rank]), axis=1).astype(np.int64)
