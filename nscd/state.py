"""What changes during a run: a snapshot :class:`State`, and the per-scene :class:`Data` of a batch.

A run is one frozen :class:`nscd.model.Model` (the structure) and one :class:`Data`
with B rows (B scenes of that structure; a single run is B = 1). A row holds all that
differs between scenes or changes from step to step: time, positions, velocities, the
warm-start impulses by contact id, the solver's cached coarse factor, and the inputs of
the scene -- the motions of its driven bodies (:class:`Drives`) and its initial state.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from nscd._jit import njit, njit_helper
from nscd.model import Model
from nscd.motion import _ZERO, _kinematics_at
from nscd.scene import Scene
from nscd.solver.coarse import CoarseCorrection


@dataclass(frozen=True)
class State:
    """Positions and velocities of every body of a scene at time ``t``.

    Attributes
    ----------
    t : float
        Time in s.
    q : ndarray, shape (n_bodies, nq)
        Generalised positions: 2D ``(x, y, angle)`` in m, m, rad (CCW);
        3D ``(x, y, z, qw, qx, qy, qz)`` (unit quaternion, body to world).
    v : ndarray, shape (n_bodies, nv)
        Velocities: 2D ``(vx, vy, omega)`` in m/s, m/s, rad/s;
        3D ``(vx, vy, vz, wx, wy, wz)`` with omega in the world frame.

    Rows of fixed and driven bodies hold their prescribed pose and velocity.
    The arrays are read-only: a step returns a new ``State``.
    """

    t: float
    q: np.ndarray
    v: np.ndarray

    def __post_init__(self) -> None:
        for arr in (self.q, self.v):
            arr.setflags(write=False)


@dataclass(frozen=True)
class States:
    """Snapshots of S scenes of a run at the end of a step: what a vectorized event is given
    (:mod:`nscd.events`).

    Attributes
    ----------
    t : ndarray, shape (S,)
        Time of each scene, s.
    q, v : ndarray, shapes (S, n_bodies, nq) and (S, n_bodies, nv)
        Positions and velocities of each scene (see :class:`State`).
    rows : ndarray of int, shape (S,)
        Each scene's row in the run (0 in a single run): an event that carries data per
        scene reads it there.

    The arrays are read-only copies.
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    rows: np.ndarray

    def __post_init__(self) -> None:
        for arr in (self.t, self.q, self.v, self.rows):
            arr.setflags(write=False)

    def __len__(self) -> int:
        return len(self.t)


# Odd 64-bit multipliers of the contact-id hash (splitmix64 / golden-ratio constants).
_HASH = np.array([0x9E3779B97F4A7C15, 0xBF58476D1CE4E5B9, 0x94D049BB133111EB], dtype=np.uint64)


@njit_helper
def _id_hash(ids):
    """One uint64 per contact id row ``(body_a, body_b, feature)``: ``sum_j ids[:, j] _HASH[j]``
    modulo 2^64 (wrapping arithmetic, on whole columns: numpy wraps integer arrays silently,
    also when run uncompiled; a few arrays for all rows, not one per row)."""
    out = ids[:, 0].astype(np.uint64)
    out *= _HASH[0]
    for j in range(1, 3):
        column = ids[:, j].astype(np.uint64)
        column *= _HASH[j]
        out += column
    return out


@njit_helper
def _hash_order(keys):
    """``keys`` (k,) uint64, spread evenly by :func:`_id_hash`, sorted stably (equal keys keep
    their order) in linear time: a counting sort on their top bits (about k buckets), then an
    insertion sort within each bucket (a key or two). Returns the permutation (k,), the keys in
    that order, each bucket's first row (2^bits + 1,) and the shift that gives a key's bucket."""
    k = keys.shape[0]
    bits = 1
    while (1 << bits) < k:
        bits += 1
    shift = np.uint64(64 - bits)
    start = np.zeros((1 << bits) + 1, dtype=np.int64)
    for i in range(k):
        start[keys[i] >> shift] += 1
    total = 0
    for b in range(1 << bits):  # counts -> first rows
        count = start[b]
        start[b] = total
        total += count
    start[1 << bits] = total
    fill = start.copy()
    order, held = np.empty(k, dtype=np.int64), np.empty(k, dtype=np.uint64)
    for i in range(k):  # in index order: stable
        b = keys[i] >> shift
        order[fill[b]], held[fill[b]] = i, keys[i]
        fill[b] += 1
    for b in range(1 << bits):  # stable: a key moves only past strictly greater ones
        for p in range(start[b] + 1, start[b + 1]):
            key, index = held[p], order[p]
            q = p - 1
            while q >= start[b] and held[q] > key:
                held[q + 1], order[q + 1] = held[q], order[q]
                q -= 1
            held[q + 1], order[q + 1] = key, index
    return order, held, start, shift


@njit_helper
def _stable_order(keys):
    """The permutation (k,) that sorts ``keys`` (k,) stably (equal keys keep their order), as
    ``np.argsort(keys, kind="stable")``: a bottom-up merge sort (numba's own compiles for
    seconds)."""
    k = keys.shape[0]
    order = np.empty(k, dtype=np.int64)
    for i in range(k):
        order[i] = i
    merged = np.empty(k, dtype=np.int64)
    width = 1
    while width < k:
        for lo in range(0, k, 2 * width):
            mid, hi = min(lo + width, k), min(lo + 2 * width, k)
            i, j = lo, mid
            for out in range(lo, hi):
                if i < mid and (j >= hi or keys[order[i]] <= keys[order[j]]):  # the left one first when equal
                    merged[out] = order[i]
                    i += 1
                else:
                    merged[out] = order[j]
                    j += 1
        order, merged = merged, order
        width *= 2
    return order


#: Known x wanted ids up to which :func:`_find_ids` compares each wanted id with the known ones
#: (from the last) instead of hashing them: a scene of a few bodies, whose handful of contacts
#: the comparisons find sooner than the hash's arrays are allocated.
_SCAN_PAIRS = 256


@njit
def _find_ids(known, wanted):
    """Kernel of :meth:`WarmStart.find`: each wanted id's last row in ``known`` (where ``hit``;
    elsewhere the row is meaningless). Few ids are compared directly (:data:`_SCAN_PAIRS`);
    many are hashed to one integer, ``known`` sorted by hash (stably, :func:`_hash_order`),
    each wanted id searched in its bucket (the last known one of its hash) and confirmed on
    the full id."""
    found = np.zeros(wanted.shape[0], dtype=np.int64)
    hit = np.zeros(wanted.shape[0], dtype=np.bool_)
    if known.shape[0] == 0 or wanted.shape[0] == 0:
        return found, hit
    if known.shape[0] * wanted.shape[0] <= _SCAN_PAIRS:
        for k in range(wanted.shape[0]):
            for row in range(known.shape[0] - 1, -1, -1):
                if known[row, 0] == wanted[k, 0] and known[row, 1] == wanted[k, 1] and known[row, 2] == wanted[k, 2]:
                    found[k], hit[k] = row, True
                    break
        return found, hit
    order, keys, start, shift = _hash_order(_id_hash(known))
    wanted_keys = _id_hash(wanted)
    for k in range(wanted.shape[0]):
        # lo = the number of known keys <= the wanted one: those of the buckets before its own,
        # and of its own bucket (sorted) those up to it
        b = wanted_keys[k] >> shift
        lo = start[b]
        while lo < start[b + 1] and keys[lo] <= wanted_keys[k]:
            lo += 1
        row = order[max(lo - 1, 0)]
        found[k] = row
        hit[k] = known[row, 0] == wanted[k, 0] and known[row, 1] == wanted[k, 1] and known[row, 2] == wanted[k, 2]
    return found, hit


#: The linear prediction of a scene's impulses is kept for its next step where its summed squared
#: error was at most this fraction of the plain prediction's (:func:`trends`): an RMS error under a
#: quarter of the plain one's. At comparable errors the plain impulses are the better start of the
#: Gauss–Seidel sweeps (a solution of the step before: in the cones, complementary; the
#: extrapolation is neither), so the extrapolation must be clearly closer to earn its place: on the
#: walls of ``benchmarks/bench_scaling.py`` riding a gently shaken base the ratio is about 1e-3
#: (at most 1e-2), on the 990-block wall shaken at 8 m/s^2 mostly 0.2–1.5 before it breaks up,
#: where the plain start costs fewer sweeps (``docs/solver.md``, "Eleventh round").
LINEAR_PREDICTION_GAIN = 0.05


@njit
def trends(impulses, first, rows, known, known_trend, known_trended):
    """Each contact's impulse change since the step before, and whether the linear prediction
    of this step's impulses was the clearly better one in each scene.

    ``impulses`` (k, dim), N s, of S scenes (rows ``first[s]:first[s + 1]``); ``rows[k]`` the
    row of the same contact among the step before's ``known`` (w, dim) impulses, -1 for a new
    contact; ``known_trend`` (w, dim) their own changes since the step before them, where
    ``known_trended[s]`` (S,) (else zeros). Returns the trend ``impulses[k] - known[rows[k]]``
    (zero for a new contact), (k, dim), and per scene (S,) whether the linear prediction
    ``known + known_trend`` had a summed squared error (over the scene's contacts kept, the
    impulses' components alike) at most :data:`LINEAR_PREDICTION_GAIN` times the plain
    prediction's ``known`` (True where the step before had no trend: nothing to tell): whether
    :meth:`WarmStart.lookup` extrapolates the next step's start. The trend of
    :meth:`WarmStart.followed_by`, :meth:`WarmStarts.followed_by` and the compiled steps."""
    out = np.zeros(impulses.shape)
    linear = np.ones(first.shape[0] - 1, dtype=np.bool_)
    for s in range(first.shape[0] - 1):
        plain_error, linear_error = 0.0, 0.0
        for k in range(first[s], first[s + 1]):
            if rows[k] >= 0:
                for d in range(impulses.shape[1]):
                    change = impulses[k, d] - known[rows[k], d]
                    out[k, d] = change
                    plain_error += change * change
                    miss = change - known_trend[rows[k], d]
                    linear_error += miss * miss
        linear[s] = not known_trended[s] or linear_error <= LINEAR_PREDICTION_GAIN * plain_error
    return out, linear


@njit
def scaled_impulses(impulses, factor):
    """``impulses`` (k, dim) times ``factor``, a new array: the warm start of a sub-step
    ``factor`` times as long as the one they were taken over (:meth:`WarmStart.scaled`; the
    factor of :func:`nscd.event_plan.plan_request`)."""
    out = np.empty(impulses.shape)
    for k in range(impulses.shape[0]):
        for d in range(impulses.shape[1]):
            out[k, d] = impulses[k, d] * factor
    return out


@njit
def summed_impulses(ids, impulses):
    """Each contact's impulse summed over the sub-steps of a step: the next step's warm start.

    ``ids`` (k, 3) and ``impulses`` (k, dim), N s, of the active contacts of the sub-steps end
    to end. Returns the distinct ids (u, 3) in lexicographic order (``np.unique(ids, axis=0)``'s:
    stable sorts by the last column, then the middle one, then the first) and their impulses
    summed in the order of the rows (``np.add.at``'s, from zero): (u, dim)."""
    k, dim = ids.shape[0], impulses.shape[1]
    order = np.empty(k, dtype=np.int64)
    for j in range(k):
        order[j] = j
    keys, sorted_order = np.empty(k, dtype=np.int64), np.empty(k, dtype=np.int64)
    for column in range(2, -1, -1):
        for j in range(k):
            keys[j] = ids[order[j], column]
        by = _stable_order(keys)
        for j in range(k):
            sorted_order[j] = order[by[j]]
        order, sorted_order = sorted_order, order
    rank = np.empty(k, dtype=np.int64)
    n_unique = 0
    for j in range(k):
        i, before = order[j], order[j - 1]
        if j == 0 or ids[i, 0] != ids[before, 0] or ids[i, 1] != ids[before, 1] or ids[i, 2] != ids[before, 2]:
            n_unique += 1
        rank[i] = n_unique - 1
    unique = np.empty((n_unique, 3), dtype=np.int64)
    total = np.zeros((n_unique, dim))
    for i in range(k):
        for d in range(3):
            unique[rank[i], d] = ids[i, d]
        for d in range(dim):
            total[rank[i], d] += impulses[i, d]
    return unique, total


@dataclass(frozen=True)
class WarmStart:
    """Impulses of the active contacts of a step, looked up by contact id for the next step.

    Attributes
    ----------
    ids : ndarray of int, shape (k, 3)
        Contact ids ``(body_a, body_b, feature)`` (:class:`~nscd.contact.frames.Contacts`).
    impulses : ndarray, shape (k, dim)
        Their impulses, N s, contact frame ``[n, t1 (, t2)]``.
    trend : ndarray, shape (k, dim), optional
        Change of each impulse since the step before (N s; zero for a contact new in this
        step), for a linearly extrapolated warm start (see :meth:`lookup`).
    linear : bool
        Whether the linear prediction of these impulses from the step before (its impulses
        plus its trend) came clearly closer to them than its plain impulses did (summed
        squared error at most :data:`LINEAR_PREDICTION_GAIN` times, :func:`trends`): the next
        step is then started from the linear prediction too (:meth:`lookup`). True where the
        step before had no trend to tell by.
    """

    ids: np.ndarray
    impulses: np.ndarray
    trend: np.ndarray | None = None
    linear: bool = True

    def __len__(self) -> int:
        return len(self.ids)

    @classmethod
    def of(cls, warm_start: "WarmStart | dict | None", dim: int) -> "WarmStart":
        """A WarmStart from itself, from None (empty) or from a dict ``{(body_a, body_b, feature): impulse (dim,)}``."""
        if isinstance(warm_start, WarmStart):
            return warm_start
        warm_start = warm_start or {}
        ids = np.array(list(warm_start.keys()), dtype=np.int64).reshape(-1, 3)
        return cls(ids, np.array(list(warm_start.values()), dtype=float).reshape(-1, dim))

    def lookup(self, ids: np.ndarray, extrapolate: bool = False) -> np.ndarray:
        """Impulses (m, dim) of the contacts ``ids`` (m, 3), N s; zero for an id not in this warm start.

        With ``extrapolate`` (and a ``trend``) in 2D, ``impulses + trend``, the linear
        prediction of the next step's impulses, where it predicted this step's clearly better
        than the plain impulses did (``linear``). For the Gauss–Seidel path of large problems,
        whose sweeps converge linearly, it cuts the sweeps several fold on walls riding a
        shaking base (the impulses follow the base acceleration smoothly); once the
        assembly breaks up (impacts, contacts opening and sliding), the impulses jump from
        step to step, a prediction by their last change lands farther off than the plain
        impulses, and ``linear`` turns it off (``docs/solver.md``, "Eleventh round"). The
        Newton fast path of small problems converges quadratically and is given the plain
        impulses. In 3D the plain impulses, always: a face contact has four points, 12
        impulse components on the 6 relative velocities of two bodies, so the impulses are
        not unique and their change from step to step is mostly a drift in that null space,
        which the prediction doubles (``docs/solver.md``, "3D").

        An id listed twice (a step split at an impact) takes its last impulse, as a dict
        built in order would. Ids are matched in one compiled call: hashed to one integer,
        matched by a stable sort and a search in the hash's bucket, and every match confirmed
        on the full id (a hash collision only loses a warm start).
        """
        values = (self.impulses + self.trend if extrapolate and self.linear and self.trend is not None
                  and self.impulses.shape[1] == 2 else self.impulses)
        out = np.zeros((len(ids), self.impulses.shape[1]))
        found, hit = self.find(ids)
        out[hit] = values[found[hit]]
        return out

    def find(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Row of each of ``ids`` (m, 3) in this warm start (its last occurrence), and whether found."""
        return _find_ids(np.ascontiguousarray(self.ids, dtype=np.int64), np.ascontiguousarray(ids, dtype=np.int64))

    def scaled(self, factor: float) -> "WarmStart":
        """These impulses and their trend times ``factor``: the warm start of a step ``factor``
        times as long as the one they were taken over (impulses of forces that act through
        the step grow with its length; an impact, of zero length, starts from zero)."""
        return WarmStart(self.ids, scaled_impulses(np.ascontiguousarray(self.impulses, dtype=float), factor),
                         None if self.trend is None else scaled_impulses(np.ascontiguousarray(self.trend, dtype=float),
                                                                          factor), self.linear)

    def followed_by(self, ids: np.ndarray, impulses: np.ndarray) -> "WarmStart":
        """The impulses ``impulses`` (k, dim) of contacts ``ids`` (k, 3), the step after this
        warm start: with their ``trend``, the change since this one (zero for a new contact),
        and whether this one's linear prediction was clearly the better (``linear``)."""
        found, hit = self.find(ids)
        impulses = np.ascontiguousarray(impulses, dtype=float)
        known = np.ascontiguousarray(self.impulses, dtype=float)
        trend, linear = trends(impulses, np.array([0, len(ids)], dtype=np.int64), np.where(hit, found, -1), known,
                               np.zeros_like(known) if self.trend is None else np.ascontiguousarray(self.trend,
                                                                                                  dtype=float),
                               np.array([self.trend is not None]))
        return WarmStart(ids, impulses, trend, bool(linear[0]))


@njit
def _matched_rows(ids, first, known_ids, known_first):
    """For each contact id (k, 3) of S scenes (rows ``first[s]:first[s + 1]``), the row of the same
    id among its own scene's ``known_ids`` (rows ``known_first[s]:known_first[s + 1]``; its last
    occurrence, :meth:`WarmStart.find`), or -1: (k,) int. The one lookup of a batch's warm starts."""
    rows = np.full(ids.shape[0], -1, dtype=np.int64)
    for s in range(first.shape[0] - 1):
        c0, c1, w0, w1 = first[s], first[s + 1], known_first[s], known_first[s + 1]
        if c1 == c0 or w1 == w0:
            continue
        found, hit = _find_ids(known_ids[w0:w1], ids[c0:c1])
        for k in range(c1 - c0):
            if hit[k]:
                rows[c0 + k] = w0 + found[k]
    return rows


def _segments(first: np.ndarray, scenes: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """The rows ``first[s] : first[s] + sizes[k]`` of each ``s = scenes[k]``, end to end."""
    before = np.cumsum(sizes) - sizes  # rows of the scenes listed before each one
    return np.repeat(first[scenes] - before, sizes) + np.arange(int(sizes.sum()))


def _bounds(sizes: np.ndarray) -> np.ndarray:
    """Row bounds (S + 1,) of S scenes of ``sizes`` (S,) rows laid end to end."""
    return np.concatenate([np.zeros(1, dtype=np.int64), np.cumsum(sizes, dtype=np.int64)])


@dataclass(frozen=True)
class WarmStarts:
    """The :class:`WarmStart` of each of S scenes, laid end to end as arrays (the warm starts
    of a batch: no object per scene).

    Scene ``s`` holds rows ``first[s]:first[s + 1]``; ``self[s]`` is its :class:`WarmStart`
    (views). A scene without a ``trend`` (no impulse in the step before) has ``trended[s]``
    False (and zeros in ``trend``); ``linear[s]`` is its :attr:`WarmStart.linear`. The general
    step never changes the arrays in place: an update makes new ones. The compiled steps of a
    single run (:mod:`nscd.compiled_step`) keep ``Data.warm`` as views of their buffers, which
    each compiled step rewrites.

    Attributes
    ----------
    ids : ndarray of int, shape (k, 3)
    impulses, trend : ndarray, shape (k, dim)
        As :class:`WarmStart`, the rows of all scenes.
    first : ndarray of int, shape (S + 1,)
    trended, linear : ndarray of bool, shape (S,)
    """

    ids: np.ndarray
    impulses: np.ndarray
    trend: np.ndarray
    first: np.ndarray
    trended: np.ndarray
    linear: np.ndarray

    @classmethod
    def empty(cls, n_scenes: int, dim: int) -> "WarmStarts":
        """No impulse in any of ``n_scenes`` scenes."""
        return cls(np.zeros((0, 3), dtype=np.int64), np.zeros((0, dim)), np.zeros((0, dim)),
                   np.zeros(n_scenes + 1, dtype=np.int64), np.zeros(n_scenes, dtype=bool),
                   np.ones(n_scenes, dtype=bool))

    @classmethod
    def stack(cls, warm_starts: Sequence[WarmStart], dim: int) -> "WarmStarts":
        """The warm starts ``warm_starts`` of S scenes end to end."""
        if len(warm_starts) == 1:
            (w,) = warm_starts
            return cls(w.ids, w.impulses, np.zeros_like(w.impulses) if w.trend is None else w.trend,
                       np.array([0, len(w)], dtype=np.int64), np.array([w.trend is not None]), np.array([w.linear]))
        no_ids, no_impulses = np.zeros((0, 3), dtype=np.int64), np.zeros((0, dim))
        return cls(np.concatenate([w.ids for w in warm_starts] + [no_ids]),
                   np.concatenate([w.impulses for w in warm_starts] + [no_impulses]),
                   np.concatenate([np.zeros_like(w.impulses) if w.trend is None else w.trend for w in warm_starts]
                                  + [no_impulses]),
                   _bounds(np.array([len(w) for w in warm_starts], dtype=np.int64)),
                   np.array([w.trend is not None for w in warm_starts], dtype=bool),
                   np.array([w.linear for w in warm_starts], dtype=bool))

    def __len__(self) -> int:
        return len(self.trended)

    def __getitem__(self, s: int) -> WarmStart:
        a, b = self.first[s], self.first[s + 1]
        return WarmStart(self.ids[a:b], self.impulses[a:b], self.trend[a:b] if self.trended[s] else None,
                         bool(self.linear[s]))

    def rows(self, scenes: np.ndarray) -> "WarmStarts":
        """The warm starts of ``scenes`` (S,), in that order."""
        if len(scenes) == len(self) and np.array_equal(scenes, np.arange(len(self))):
            return self
        sizes = np.diff(self.first)[scenes]
        picked = _segments(self.first, scenes, sizes)
        return WarmStarts(self.ids[picked], self.impulses[picked], self.trend[picked], _bounds(sizes),
                          self.trended[scenes], self.linear[scenes])

    def followed_by(self, ids: np.ndarray, impulses: np.ndarray, first: np.ndarray) -> "WarmStarts":
        """The impulses ``impulses`` (k, dim) of contacts ``ids`` (k, 3) of each of these scenes
        (rows ``first[s]:first[s + 1]``), the step after these warm starts: with their ``trend``,
        the change since this one, in a scene that had impulses, and whether this one's linear
        prediction was the better (:meth:`WarmStart.followed_by`)."""
        rows = _matched_rows(ids, first, self.ids, self.first)
        impulses = np.ascontiguousarray(impulses, dtype=float)
        trend, linear = trends(impulses, first, rows, np.ascontiguousarray(self.impulses, dtype=float),
                               np.ascontiguousarray(self.trend, dtype=float), self.trended)
        return WarmStarts(ids, impulses, trend, first, np.diff(self.first) > 0, linear)

    def updated(self, scenes: np.ndarray, new: "WarmStarts") -> "WarmStarts":
        """These warm starts with those of ``scenes`` (S,) replaced by ``new`` (S scenes, same order)."""
        if len(scenes) == len(self) and np.array_equal(scenes, np.arange(len(self))):
            return new  # every scene replaced, in order (the arrays are never changed in place)
        sizes = np.diff(self.first)
        kept = np.ones(len(self), dtype=bool)
        kept[scenes] = False
        kept = np.flatnonzero(kept)
        sizes[scenes] = np.diff(new.first)
        first = _bounds(sizes)
        source = _segments(self.first, kept, sizes[kept])
        target, into = _segments(first, kept, sizes[kept]), _segments(first, scenes, sizes[scenes])
        ids = np.empty((int(first[-1]), 3), dtype=np.int64)
        impulses = np.empty((int(first[-1]), self.impulses.shape[1]))
        trend = np.empty_like(impulses)
        ids[target], impulses[target], trend[target] = self.ids[source], self.impulses[source], self.trend[source]
        ids[into], impulses[into], trend[into] = new.ids, new.impulses, new.trend
        trended, linear = self.trended.copy(), self.linear.copy()
        trended[scenes], linear[scenes] = new.trended, new.linear
        return WarmStarts(ids, impulses, trend, first, trended, linear)


class Drives:
    """Poses and velocities of the fixed and driven bodies of B scenes of one model.

    A driven body whose motions (horizontal and vertical, in every scene) are ready motions
    of :mod:`nscd.motion` (pulses, harmonics, sweeps, records, phases of constant
    acceleration, and these scaled) is posed by one compiled formula, :func:`driven_poses`,
    for all scenes at once (:attr:`compiled`, which the compiled steps also call inside a
    step); a body with any other motion by :meth:`nscd.scene.Body.prescribed`, scene by scene.
    Both give ``q0 + d(t) direction`` (the vertical motion added to the last coordinate) and
    ``v(t) direction``, bit for bit the same.

    Parameters
    ----------
    model : Model
    scenes : sequence of Scene
        The scenes (of structure ``model``) whose motions are read.

    Attributes
    ----------
    compiled : tuple
        What :func:`driven_poses` takes for the bodies posed by it: their indices (P,), their
        poses at t = 0 (B, P, nq), directions (P, D), and per scene, body and axis (horizontal,
        vertical) the motion's kind (B, P, 2), factor (B, P, 2), constants (B, P, 2, L), sample
        tables (B, P, 2, 3, T) and table lengths (B, P, 2) (:meth:`nscd.motion.Motion._compiled`;
        kind ``_ZERO``: no motion on that axis; padding not read).
    """

    def __init__(self, model: Model, scenes: Sequence[Scene]) -> None:
        self._fixed, self._python = [], []
        posed = []
        for i in model.prescribed_index.tolist():
            bodies = [scene.bodies[i] for scene in scenes]
            if all(b.motion is None and b.vertical is None for b in bodies):
                self._fixed.append((i, np.array([b.q0 for b in bodies])))
                continue
            specs = [[_ZERO_SPEC if m is None else m._compiled() for m in (b.motion, b.vertical)] for b in bodies]
            if any(spec is None for pair in specs for spec in pair):
                self._python.append((i, bodies))
            else:
                posed.append((i, bodies, specs))
        self.compiled = _driven_arrays(model, len(scenes), posed)

    @property
    def everywhere(self) -> bool:
        """Every driven body is posed by :func:`driven_poses` (none by Python)."""
        return not self._python

    def write(self, rows: np.ndarray, t: np.ndarray, q: np.ndarray, v: np.ndarray) -> None:
        """Write the pose and velocity of every fixed and driven body of scenes ``rows`` (S,)
        at times ``t`` (S,), s, into ``q`` (S, n_bodies, nq) and ``v`` (S, n_bodies, nv)."""
        for i, q0 in self._fixed:
            q[:, i] = q0[rows]
            v[:, i] = 0.0
        if len(self.compiled[0]):
            _write_driven(np.asarray(rows, dtype=np.int64), np.asarray(t, dtype=float), q, v, *self.compiled)
        for i, bodies in self._python:
            for k, (row, tk) in enumerate(zip(rows.tolist(), t.tolist())):
                q[k, i], v[k, i] = bodies[row].prescribed(tk)


#: The compiled spec of no motion on an axis (kind, factor, constants, sample tables).
_ZERO_SPEC = (_ZERO, 1.0, np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0))


def _driven_arrays(model: Model, n_scenes: int, posed: list) -> tuple:
    """:attr:`Drives.compiled` of the bodies ``posed``: (index, bodies, specs per scene)."""
    P = len(posed)
    nq = model.nq
    D = max((len(model.bodies[i].direction) for i, *_ in posed), default=model.dim)
    L = max((len(spec[2]) for *_, specs in posed for pair in specs for spec in pair), default=0)
    T = max((len(spec[3]) for *_, specs in posed for pair in specs for spec in pair), default=0)
    index = np.array([i for i, *_ in posed], dtype=np.int64)
    q0, direction = np.zeros((n_scenes, P, nq)), np.zeros((P, D))
    kinds, lengths = np.zeros((n_scenes, P, 2), dtype=np.int64), np.zeros((n_scenes, P, 2), dtype=np.int64)
    factors, pars, tables = np.ones((n_scenes, P, 2)), np.zeros((n_scenes, P, 2, L)), np.zeros((n_scenes, P, 2, 3, T))
    for p, (i, bodies, specs) in enumerate(posed):
        direction[p] = model.bodies[i].direction
        for b, (body, pair) in enumerate(zip(bodies, specs)):
            q0[b, p] = body.q0
            for axis, (kind, factor, par, *table) in enumerate(pair):
                kinds[b, p, axis], factors[b, p, axis] = kind, factor
                pars[b, p, axis, :len(par)] = par
                lengths[b, p, axis] = len(table[0])
                for j in range(3):
                    tables[b, p, axis, j, :len(table[j])] = table[j]
    return index, q0, direction, kinds, factors, pars, tables, lengths


@njit_helper
def driven_poses(q, v, t, index, q0, direction, kinds, factors, pars, tables, lengths):
    """Pose ``q`` (n_bodies, nq) and velocity ``v`` (n_bodies, nv) of the driven bodies
    ``index`` (P,) of one scene at time ``t`` (s), in place: from their poses at t = 0 ``q0``
    (P, nq), ``q0 + f d(t) direction`` and ``f v(t) direction`` (m, m/s; ``d``, ``v`` of the
    ready motion of ``kinds[p, 0]`` with constants ``pars[p, 0]`` and the first
    ``lengths[p, 0]`` samples of ``tables[p, 0]``, ``f`` its factor), then the vertical
    motion (axis 1) added to the last coordinate of the direction's length (the formula of
    :meth:`nscd.scene.Body.prescribed`, in its order of operations)."""
    D = direction.shape[1]
    for p in range(index.shape[0]):
        i = index[p]
        for j in range(q.shape[1]):
            q[i, j] = q0[p, j]
        for j in range(v.shape[1]):
            v[i, j] = 0.0
        for axis in range(2):
            if kinds[p, axis] == _ZERO:
                continue
            n = lengths[p, axis]
            d, speed, _ = _kinematics_at(kinds[p, axis], pars[p, axis], tables[p, axis, 0, :n],
                                         tables[p, axis, 1, :n], tables[p, axis, 2, :n], t)
            if factors[p, axis] != 1.0:
                d, speed = factors[p, axis] * d, factors[p, axis] * speed
            if axis == 0:
                for j in range(D):
                    q[i, j] += d * direction[p, j]
                    v[i, j] += speed * direction[p, j]
            else:
                q[i, D - 1] += d
                v[i, D - 1] += speed


@njit
def _write_driven(rows, t, q, v, index, q0, direction, kinds, factors, pars, tables, lengths):
    """:func:`driven_poses` of scenes ``rows`` (S,) at times ``t`` (S,) into ``q``, ``v`` (S, ...)."""
    for k in range(rows.shape[0]):
        b = rows[k]
        driven_poses(q[k], v[k], t[k], index, q0[b], direction, kinds[b], factors[b], pars[b], tables[b], lengths[b])


@dataclass
class Data:
    """Everything of B scenes of one :class:`~nscd.model.Model` that is not structure.

    Attributes
    ----------
    t : ndarray, shape (B,)
        Time of each scene, s.
    q, v : ndarray, shapes (B, n_bodies, nq) and (B, n_bodies, nv)
        Positions and velocities (see :class:`State`).
    warm : WarmStarts
        Per scene, the impulses of the last step's active contacts by contact id
        (``warm[k]``: scene ``k``'s :class:`WarmStart`).
    coarse : list of CoarseCorrection
        Per scene, the body-space correction of the Gauss–Seidel sweeps of large
        problems, whose factor is kept from step to step.
    drives : Drives
        The motions of the fixed and driven bodies of every scene.
    q0, v0 : ndarray
        The initial state of every scene (driven bodies at their t = 0 pose).
    """

    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    warm: WarmStarts
    coarse: list
    drives: Drives
    q0: np.ndarray
    v0: np.ndarray

    @classmethod
    def from_scenes(cls, model: Model, scenes: Sequence[Scene]) -> "Data":
        """The data of ``scenes`` (each of structure ``model``) at t = 0."""
        drives = Drives(model, scenes)
        q = np.array([[b.q0 for b in scene.bodies] for scene in scenes], dtype=float)
        v = np.array([[b.v0 for b in scene.bodies] for scene in scenes], dtype=float)
        t = np.zeros(len(scenes))
        drives.write(np.arange(len(scenes)), t, q, v)
        return cls(t=t, q=q, v=v, warm=WarmStarts.empty(len(scenes), model.dim), coarse=[CoarseCorrection() for _ in scenes],
                   drives=drives, q0=q.copy(), v0=v.copy())

    def __len__(self) -> int:
        return len(self.t)

    def state(self, k: int) -> State:
        """A read-only snapshot of scene ``k``."""
        return State(float(self.t[k]), self.q[k].copy(), self.v[k].copy())

    def states(self, rows: np.ndarray) -> States:
        """Read-only snapshots of scenes ``rows`` (S,)."""
        return States(self.t[rows], self.q[rows], self.v[rows], np.array(rows, dtype=np.int64))
