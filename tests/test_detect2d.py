"""Tests of 2D polygon contact detection against geometry facts.

Every case is run through each way of computing a pair (``impl`` fixture): the
single-pair function, the batched one and the kernel run as plain Python (what
``NUMBA_DISABLE_JIT=1`` runs), so each is checked against geometry, not against the
others. Their bit-for-bit agreement is checked on thousands of random pairs.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from scipy.spatial import ConvexHull

import nscd.contact.detect2d as detect2d
from nscd.contact.detect import detect, detect_batch
from nscd.stepper import initial_state
from nscd.contact.detect2d import (
    REFERENCE_TOLERANCE,
    collide_polygons,
    collide_polygons_batch,
    collide_posed_polygons,
    split_ids,
)
from nscd.contact.manifold import Manifold, Manifolds
from nscd.model import Model
from nscd.scene import Scene
from nscd.shapes import box as block_shape
from nscd.shapes import regular_polygon

# Round-off: coordinates of order 1-10 m carry ~1e-16 relative error per
# operation and the algorithm chains a few tens of them.
ATOL = 1e-12


def _batched(a, b, margin):
    return collide_polygons_batch(a[None], b[None], margin).manifold(0)


#: The kernel as plain Python (what runs with NUMBA_DISABLE_JIT=1).
_PYTHON_KERNEL = getattr(detect2d.collide_posed_xy, "py_func", detect2d.collide_posed_xy)


def _python_kernel_pairs(vertices, start, pairs, margin):
    """:func:`collide_posed_polygons` through the plain-Python kernel (one margin per pair)."""
    pairs = np.asarray(pairs, dtype=np.int64)
    return Manifolds(*_PYTHON_KERNEL(np.ascontiguousarray(vertices[:, 0]), np.ascontiguousarray(vertices[:, 1]),
                                     np.asarray(start, dtype=np.int64), pairs, np.full(len(pairs), float(margin))))


def _python_kernel(a, b, margin):
    return _python_kernel_pairs(np.concatenate((a, b)), [0, len(a), len(a) + len(b)], [[0, 1]], margin).manifold(0)


@pytest.fixture(params=[collide_polygons, _batched, _python_kernel],
                ids=["single", "batch", "python-kernel"])
def impl(request):
    return request.param


def box(w, h, x=0.0, y=0.0):
    """Rectangle w x h with its lower-left corner at (x, y), CCW."""
    return np.array([[x, y], [x + w, y], [x + w, y + h], [x, y + h]], dtype=float)


def rotation(theta):
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s], [s, c]])


def rotate(p, theta, centre=(0.0, 0.0)):
    centre = np.asarray(centre, dtype=float)
    return (p - centre) @ rotation(theta).T + centre


def regular(n, radius, centre=(0.0, 0.0), phase=0.0):
    ang = phase + 2 * np.pi * np.arange(n) / n
    return np.c_[radius * np.cos(ang), radius * np.sin(ang)] + np.asarray(centre)


def check_consistent(m: Manifold, a, b):
    """Contract facts: unit normal, gap = (pb - pa).n, points on the surfaces of A and B."""
    assert m.points_a.shape == m.points_b.shape == (m.count, 2)
    assert 1 <= m.count <= 2
    assert abs(np.linalg.norm(m.normal) - 1.0) < ATOL
    np.testing.assert_allclose((m.points_b - m.points_a) @ m.normal, m.gaps, atol=ATOL)
    for p in m.points_a:
        assert boundary_distance(p, a) < 1e-9  # on A's boundary, to round-off of the clipping
    for p in m.points_b:
        assert boundary_distance(p, b) < 1e-9


# --- brute-force geometry, independent of the code under test -----------------

def edges(p):
    return [(p[i], p[(i + 1) % len(p)]) for i in range(len(p))]


def point_segment(p, s0, s1):
    d = s1 - s0
    lam = np.clip(np.dot(p - s0, d) / np.dot(d, d), 0.0, 1.0)
    return float(np.linalg.norm(p - s0 - lam * d))


def boundary_distance(p, poly):
    return min(point_segment(p, *e) for e in edges(poly))


def cross(o, a, b):
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def inside(p, poly):
    return all(cross(s0, s1, p) >= 0.0 for s0, s1 in edges(poly))


def overlap(a, b):
    """Closed convex polygons intersect: a vertex inside the other, or two edges cross."""
    if any(inside(p, b) for p in a) or any(inside(q, a) for q in b):
        return True
    return any(cross(*e, f[0]) * cross(*e, f[1]) < 0 and cross(*f, e[0]) * cross(*f, e[1]) < 0
               for e in edges(a) for f in edges(b))


def distance(a, b):
    """Distance between disjoint convex polygons: min over vertex-edge distances."""
    return min(min(point_segment(p, *e) for p in a for e in edges(b)),
               min(point_segment(q, *e) for q in b for e in edges(a)))


def penetration_depth(a, b):
    """Length of the smallest translation separating overlapping convex polygons.

    The minimum over all edge normals of the overlap of the projections
    (separating axis theorem; the minimum translation of two convex polygons
    is along an edge normal of their Minkowski difference).
    """
    depth = math.inf
    for poly in (a, b):
        for s0, s1 in edges(poly):
            n = np.array([s1[1] - s0[1], s0[0] - s1[0]]) / np.linalg.norm(s1 - s0)
            pa, pb = a @ n, b @ n
            depth = min(depth, min(pa.max() - pb.min(), pb.max() - pa.min()))
    return depth


def random_polygon(rng, n, radius):
    """Convex CCW polygon: n points at sorted random angles on a circle."""
    ang = np.sort(rng.uniform(0.0, 2 * np.pi, n))
    while np.min(np.diff(np.r_[ang, ang[0] + 2 * np.pi])) < 0.05:  # avoid sliver edges
        ang = np.sort(rng.uniform(0.0, 2 * np.pi, n))
    return np.c_[radius * np.cos(ang), radius * np.sin(ang)]


# --- resting, tilting, sliding blocks ------------------------------------------

BASE = box(3.0, 0.2, -1.5, -0.2)  # top face y = 0 from x = -1.5 to 1.5


def test_block_resting_flat_on_base(impl):
    block = box(1.0, 2.0, -0.3, 0.0)
    m = impl(BASE, block, 1e-3)
    check_consistent(m, BASE, block)
    np.testing.assert_array_equal(m.normal, [0.0, 1.0])
    np.testing.assert_array_equal(m.gaps, [0.0, 0.0])  # exact: all coordinates are exact binary numbers
    np.testing.assert_allclose(sorted(m.points_b[:, 0]), [-0.3, 0.7], atol=ATOL)
    ref_is_b, ref_edge, inc_vertex = split_ids(m.ids)
    assert not ref_is_b.any() and (ref_edge == 2).all()  # the base's top edge (vertex 2 -> 3)
    assert sorted(inc_vertex) == [0, 1]  # the block's bottom corners


def test_swapping_a_and_b_flips_normal_swaps_points_keeps_base_reference(impl):
    block = rotate(box(1.0, 2.0, -0.3, 0.0), 0.01, (0.7, 0.0))  # rocking on its right corner
    ab, ba = impl(BASE, block, 0.05), impl(block, BASE, 0.05)
    check_consistent(ab, BASE, block)
    check_consistent(ba, block, BASE)
    np.testing.assert_allclose(ba.normal, -ab.normal, atol=ATOL)
    np.testing.assert_allclose(ba.points_a, ab.points_b, atol=ATOL)
    np.testing.assert_allclose(ba.points_b, ab.points_a, atol=ATOL)
    np.testing.assert_allclose(ba.gaps, ab.gaps, atol=ATOL)
    # the base (longer edge, larger separation) is the reference in both orders
    assert not split_ids(ab.ids)[0].any() and split_ids(ba.ids)[0].all()
    np.testing.assert_array_equal(split_ids(ab.ids)[2], split_ids(ba.ids)[2])


def test_equal_blocks_flat_tie_goes_to_a_in_both_orders(impl):
    # equal faces, both separations 0: the tie rule picks A, whichever body A is
    lower, upper = box(1.0, 1.0), box(1.0, 1.0, 0.0, 1.0)
    for a, b in ((lower, upper), (upper, lower)):
        m = impl(a, b, 1e-3)
        assert not split_ids(m.ids)[0].any()
        np.testing.assert_array_equal(m.gaps, [0.0, 0.0])


@pytest.mark.parametrize("theta", [1e-9, 1e-5, 0.003, 0.2])
def test_tilted_block_on_corner_keeps_lifted_corner_within_margin(impl, theta):
    w, h, margin = 0.4, 1.2, 1e-3
    # rotate clockwise (negative) about the bottom-right corner: the left corner lifts
    block = rotate(box(w, h, -0.2, 0.0), -theta, (0.2, 0.0))
    m = impl(BASE, block, margin)
    lift = w * math.sin(theta)  # height of the lifted bottom-left corner
    expected = sorted(g for g in (0.0, lift) if g <= margin)
    check_consistent(m, BASE, block)
    np.testing.assert_allclose(m.normal, [0.0, 1.0], atol=ATOL)
    np.testing.assert_allclose(sorted(m.gaps), expected, atol=ATOL)
    # ids: pivot = block vertex 1, lifted = vertex 0; same ids as when flat
    flat = impl(BASE, box(w, h, -0.2, 0.0), margin)
    pivot_id = flat.ids[split_ids(flat.ids)[2] == 1]
    np.testing.assert_array_equal(m.ids[np.argmin(m.gaps)], pivot_id[0])


def test_rotated_square_on_a_line_closed_form_gaps(impl):
    # square of half side c, centre at height y0, rotated by theta in (0, pi/4):
    # corner heights y0 - c (cos t + sin t) (lowest) and y0 - c (cos t - sin t)
    c, theta = 0.5, 0.3
    for y0 in (0.75, 0.7, 0.6):  # apart, touching, penetrating
        sq = rotate(box(2 * c, 2 * c, -c, -c), theta) + [0.3, y0]
        m = impl(BASE, sq, margin=0.5)
        check_consistent(m, BASE, sq)
        expected = [y0 - c * (math.cos(theta) + math.sin(theta)),
                    y0 - c * (math.cos(theta) - math.sin(theta))]
        np.testing.assert_allclose(sorted(m.gaps), expected, atol=ATOL)
        np.testing.assert_allclose(m.normal, [0.0, 1.0], atol=ATOL)


def test_penetration_gives_negative_gaps(impl):
    delta = 2e-3
    block = box(0.5, 0.5, 0.1, -delta)
    m = impl(BASE, block, 1e-3)
    np.testing.assert_allclose(m.gaps, [-delta, -delta], atol=ATOL)
    np.testing.assert_allclose(m.normal, [0.0, 1.0], atol=ATOL)


def test_separated_beyond_margin_is_none_and_at_margin_is_kept(impl):
    margin = 0.25  # exactly representable, so "gap == margin" is exact
    assert impl(BASE, box(1.0, 1.0, 0.0, 0.5), margin) is None
    m = impl(BASE, box(1.0, 1.0, 0.0, 0.25), margin)
    np.testing.assert_array_equal(m.gaps, [margin, margin])
    # far apart sideways, close in height: still None
    assert impl(BASE, box(1.0, 1.0, 2.0, 0.0), margin) is None


def test_edge_on_edge_partial_overlap_clips_at_overlap_ends(impl):
    lower = box(1.0, 1.0, 0.0, 0.0)
    upper = box(1.0, 1.0, 0.6, 1.0 - 1e-3)  # overhangs by 0.6, sunk by 1 mm
    m = impl(lower, upper, 1e-2)
    check_consistent(m, lower, upper)
    np.testing.assert_allclose(m.gaps, [-1e-3, -1e-3], atol=ATOL)
    # contact spans the overlap x in [0.6, 1.0]
    np.testing.assert_allclose(sorted(m.points_a[:, 0]), [0.6, 1.0], atol=ATOL)
    np.testing.assert_allclose(sorted(m.points_b[:, 0]), [0.6, 1.0], atol=ATOL)


def test_vertex_on_vertex_separated_gives_true_distance(impl):
    # two diamonds (squares at 45 degrees), tips facing, 1 mm apart vertically
    lower = regular(4, 1.0, (0.0, 0.0), np.pi / 2)
    upper = regular(4, 1.0, (0.0, 2.001), np.pi / 2)
    m = impl(lower, upper, 5e-3)
    check_consistent(m, lower, upper)
    assert m.count == 1
    np.testing.assert_allclose(m.gaps, [1e-3], atol=ATOL)
    np.testing.assert_allclose(m.normal, [0.0, 1.0], atol=ATOL)
    np.testing.assert_allclose(m.points_a, [[0.0, 1.0]], atol=ATOL)
    np.testing.assert_allclose(m.points_b, [[0.0, 1.001]], atol=ATOL)


def test_corner_to_corner_diagonal_distance(impl):
    # unit squares with corners facing diagonally: distance = |offset|, normal along it
    g = 2e-3
    lower = box(1.0, 1.0)
    upper = box(1.0, 1.0, 1.0 + g, 1.0 + g)
    m = impl(lower, upper, 5e-3)
    check_consistent(m, lower, upper)
    np.testing.assert_allclose(m.gaps.min(), g * math.sqrt(2), atol=ATOL)
    np.testing.assert_allclose(m.normal, [math.sqrt(0.5)] * 2, atol=ATOL)


def test_vertex_on_face_touching(impl):
    diamond = regular(4, 0.1, (0.4, 0.1), np.pi / 2)  # bottom tip at (0.4, 0)
    m = impl(BASE, diamond, 1e-3)
    check_consistent(m, BASE, diamond)
    np.testing.assert_allclose(m.gaps, [0.0], atol=ATOL)
    np.testing.assert_allclose(m.points_b, [[0.4, 0.0]], atol=ATOL)


def test_very_different_sizes_rotated_and_far_from_origin(impl):
    # 10 mm block tilted by t about its centre, lifted 0.05 mm: its lowest corner sinks
    # 0.005 (cos t + sin t - 1) - 5e-5 ~ 0.05 mm into a 3 m base; whole scene rotated, moved 1 km
    t = 0.02
    block = rotate(box(0.01, 0.01, 0.37, 0.0), t, (0.375, 0.005)) + [0.0, 5e-5]
    low = 5e-5 - 0.005 * (math.cos(t) + math.sin(t) - 1.0)
    angle, shift = 1.1, np.array([1000.0, -700.0])
    a, b = rotate(BASE, angle) + shift, rotate(block, angle) + shift
    m = impl(a, b, 1e-3)
    check_consistent(m, a, b)
    # round-off of coordinates of 1e3 m: ~1e-13 m per operation
    np.testing.assert_allclose(m.gaps.min(), low, atol=1e-11)
    np.testing.assert_allclose(m.normal, rotation(angle) @ [0.0, 1.0], atol=1e-12)
    # and the 10 mm block as A
    m2 = impl(b, a, 1e-3)
    np.testing.assert_allclose(m2.gaps.min(), low, atol=1e-11)
    np.testing.assert_allclose(m2.normal, -m.normal, atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_invariance_under_rigid_motion(impl, seed):
    rng = np.random.default_rng(seed)
    a = random_polygon(rng, 5, 1.0)
    b = random_polygon(rng, 4, 0.7) + rng.uniform(-1.2, 1.2, 2)
    m = impl(a, b, 0.3)
    if m is None:
        pytest.skip("pair not within margin for this seed")
    angle, shift = rng.uniform(0, 2 * np.pi), rng.uniform(-50, 50, 2)
    mm = impl(rotate(a, angle) + shift, rotate(b, angle) + shift, 0.3)
    R = rotation(angle)
    # round-off of the moved coordinates (|shift| <= 50 m): ~1e-14 m per operation
    np.testing.assert_allclose(mm.gaps, m.gaps, atol=1e-11)
    np.testing.assert_allclose(mm.normal, R @ m.normal, atol=1e-11)
    np.testing.assert_allclose(mm.points_a, m.points_a @ R.T + shift, atol=1e-11)
    np.testing.assert_allclose(mm.points_b, m.points_b @ R.T + shift, atol=1e-11)
    np.testing.assert_array_equal(mm.ids, m.ids)


def test_random_pairs_against_brute_force(impl):
    """Separated: min gap = true distance; overlapping: min gap = -penetration depth."""
    rng = np.random.default_rng(42)
    margin = 0.3
    seen = {"apart": 0, "overlap": 0, "none": 0}
    for _ in range(600):
        a = random_polygon(rng, rng.integers(3, 8), rng.uniform(0.5, 1.5))
        b = random_polygon(rng, rng.integers(3, 8), rng.uniform(0.5, 1.5)) + rng.uniform(-3, 3, 2)
        m = impl(a, b, margin)
        # the reference-face choice may trade up to this much gap for stability
        tol = REFERENCE_TOLERANCE * 3.0 + ATOL
        if overlap(a, b):
            seen["overlap"] += 1
            check_consistent(m, a, b)
            depth = penetration_depth(a, b)
            assert -depth - tol <= m.gaps.min() <= -depth + ATOL
            # moving B by -min_gap along the normal separates the pair (up to tol)
            assert not overlap(a, b + (tol - m.gaps.min() + 1e-9) * m.normal)
            swapped = impl(b, a, margin)
            np.testing.assert_allclose(swapped.normal, -m.normal, atol=ATOL)
            np.testing.assert_allclose(swapped.points_a, m.points_b, atol=ATOL)
            continue
        d = distance(a, b)
        if d > margin:
            seen["none"] += 1
            assert m is None
            continue
        seen["apart"] += 1
        check_consistent(m, a, b)
        assert (m.gaps <= margin).all()
        assert d - tol <= m.gaps.min() <= d + ATOL
        # swapping A and B flips the normal and swaps the points (no ties in random data)
        swapped = impl(b, a, margin)
        np.testing.assert_allclose(swapped.normal, -m.normal, atol=ATOL)
        np.testing.assert_allclose(swapped.gaps, m.gaps, atol=ATOL)
        np.testing.assert_allclose(swapped.points_a, m.points_b, atol=ATOL)
        np.testing.assert_allclose(swapped.points_b, m.points_a, atol=ATOL)
    assert min(seen.values()) >= 20, seen  # all three regimes were exercised


def _random_pairs(rng, count):
    """``count`` random pairs (A, B) of convex CCW polygons and a margin, in every regime.

    Blocks on a base (flat, tilted, lifted or sunk by up to a few mm), regular polygons,
    hulls of random points and random circle polygons, placed to touch, penetrate, or be
    apart within and beyond the margin; some far from the origin, some exactly
    symmetric (ties of the reference face and of the incident edge).
    """
    base = box(3.0, 0.2, -1.5, -0.2)
    out = []
    for i in range(count):
        kind = i % 5
        margin = float(rng.choice([0.0, 1e-3, 0.05, 0.3]))
        if kind == 0:  # a block on the base: resting, rocking on a corner, lifted or sunk
            w, h = rng.uniform(0.1, 1.0, 2)
            theta = float(rng.choice([0.0, rng.normal(0.0, 0.05), rng.normal(0.0, 0.5)]))
            shape = rotate(box(w, h, -w / 2, 0.0), theta)
            lift = float(rng.choice([0.0, rng.normal(0.0, 1e-3), rng.normal(0.0, 0.1)]))
            a, b = base, shape - [0.0, shape[:, 1].min()] + [rng.uniform(-1.8, 1.8), lift]
        elif kind == 1:  # regular polygons, one rotated by a random or a symmetric angle
            n, k = rng.integers(3, 13, 2)
            a = regular(n, 1.0, phase=float(rng.choice([0.0, rng.uniform(0, 6.3)])))
            b = regular(k, 0.7, rng.uniform(-2.0, 2.0, 2), phase=float(rng.choice([np.pi / k, rng.uniform(0, 6.3)])))
        elif kind == 2:  # hulls of random points
            polys = []
            for _ in range(2):
                pts = rng.normal(0.0, 0.6, (int(rng.integers(3, 15)), 2))
                polys.append(pts[ConvexHull(pts).vertices])  # 2D hull vertices are counter-clockwise
            a, b = polys[0], polys[1] + rng.uniform(-1.8, 1.8, 2)
        elif kind == 3:  # random circle polygons, far from the origin
            far = rng.uniform(-1e3, 1e3, 2)
            a = random_polygon(rng, rng.integers(3, 9), 1.0) + far
            b = random_polygon(rng, rng.integers(3, 9), 0.8) + far + rng.uniform(-2.2, 2.2, 2)
        else:  # equal boxes side by side or stacked: exact ties
            w, h = rng.uniform(0.2, 1.0, 2)
            dx, dy = (w + rng.choice([0.0, 1e-3, -1e-3, 0.4]), 0.0) if rng.random() < 0.5 else (0.0, h)
            a = box(w, h)
            b = box(w, h, dx + float(rng.choice([0.0, rng.normal(0.0, 0.1)])), dy)
        out.append((np.asarray(a, dtype=float), np.asarray(b, dtype=float), margin))
    return out


def _assert_identical(got, want, what):
    assert (got is None) == (want is None), what
    if want is not None:
        for field in ("normal", "points_a", "points_b", "gaps", "ids"):
            g, w = getattr(got, field), getattr(want, field)
            assert g.shape == w.shape and g.dtype == w.dtype, (what, field)
            np.testing.assert_array_equal(g, w, err_msg=f"{what}: {field}")  # bit for bit, tolerance 0


def test_all_paths_agree_bit_for_bit_on_random_pairs():
    """Compiled kernel (one call, all pairs) == plain-Python kernel == one pair at a time,
    to the last bit and with equal ids: the batched sweep must equal single runs exactly
    (tests/test_batch.py), compiled or run as plain Python (NUMBA_DISABLE_JIT=1)."""
    rng = np.random.default_rng(2026)
    cases = _random_pairs(rng, 3000)
    for margin in (0.0, 1e-3, 0.05, 0.3):
        chosen = [(a, b) for a, b, m in cases if m == margin]
        vertices = np.concatenate([p for pair in chosen for p in pair])
        start = np.concatenate(([0], np.cumsum([len(p) for pair in chosen for p in pair])))
        pairs = np.arange(2 * len(chosen)).reshape(-1, 2)
        compiled = collide_posed_polygons(vertices, start, pairs, margin)
        python = _python_kernel_pairs(vertices, start, pairs, margin)
        for field in ("pair", "normal", "points_a", "points_b", "gaps", "ids"):
            np.testing.assert_array_equal(getattr(compiled, field), getattr(python, field), err_msg=field)
        for i, (a, b) in enumerate(chosen):
            want = compiled.manifold(i)
            _assert_identical(collide_polygons(a, b, margin), want, f"single, pair {i}")
    # every regime was exercised (counts of this seed: 1228 none, 218 apart within the margin,
    # 1037 penetrating, 517 touching exactly, 332 one point, 1440 two points; floor 150 each)
    found = [collide_polygons(a, b, m) for a, b, m in cases]
    assert sum(f is None for f in found) >= 150
    assert sum(f is not None and f.gaps.min() > 0.0 for f in found) >= 150
    assert sum(f is not None and f.gaps.min() < 0.0 for f in found) >= 150
    assert sum(f is not None and f.gaps.min() == 0.0 for f in found) >= 150
    assert sum(f is not None and f.count == 1 for f in found) >= 150
    assert sum(f is not None and f.count == 2 for f in found) >= 150


def test_batch_of_equal_vertex_counts_agrees_bit_for_bit():
    """collide_polygons_batch on many pairs at once == pair by pair."""
    rng = np.random.default_rng(7)
    for n, k in ((4, 4), (3, 6)):
        a = np.array([random_polygon(rng, n, 1.0) for _ in range(400)])
        b = np.array([random_polygon(rng, k, 0.8) + rng.uniform(-2.2, 2.2, 2) for _ in range(400)])
        batch = collide_polygons_batch(a, b, 0.2)
        assert np.all(np.diff(batch.pair) >= 0)
        for i in range(len(a)):
            _assert_identical(batch.manifold(i), collide_polygons(a[i], b[i], 0.2), f"pair {i}")


def _mixed_scene():
    """Bodies of 3, 4, 6 and 8 vertices jumbled on a base, touching and apart."""
    scene = Scene()
    scene.add_base(block_shape(6.0, 0.2), position=(0.0, -0.1))
    rng = np.random.default_rng(5)
    shapes = [block_shape(0.4, 0.6), regular_polygon(3, 0.3), regular_polygon(6, 0.25), regular_polygon(8, 0.3)]
    for i in range(24):
        shape = shapes[i % 4]
        scene.add_block(shape, position=(-2.6 + 0.22 * i, 0.2 + 0.45 * (i % 3) + rng.uniform(0.0, 0.05)),
                        angle=float(rng.uniform(-0.3, 0.3)))
    return scene


def test_detection_of_a_batch_equals_scene_by_scene():
    """detect_batch over several configurations of one model gives each scene the contacts
    that detect() gives it alone, bit for bit, and each pair's points those of collide_polygons."""
    scene = _mixed_scene()
    model = Model.from_scene(scene)
    q0 = initial_state(scene).q
    rng = np.random.default_rng(11)
    qs = np.array([q0 + rng.normal(scale=0.01, size=q0.shape) * model.dynamic[:, None] for _ in range(4)])
    margin = 0.02
    contacts, scene_of = detect_batch(model, qs, margin)
    assert len(contacts) > 4 * 20  # every scene has contacts
    for s, q in enumerate(qs):
        alone = detect(model, q, margin)
        mine = contacts.subset(scene_of == s)
        for field in alone.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(mine, field), getattr(alone, field), err_msg=field)
        for i, j in {(int(a), int(b)) for a, b in zip(alone.body_a, alone.body_b)}:
            pair = (alone.body_a == i) & (alone.body_b == j)
            local = [np.asarray(b.shape.vertices) for b in model.bodies]
            posed = [q[k, :2] + local[k] @ np.array([[np.cos(q[k, 2]), np.sin(q[k, 2])],
                                                     [-np.sin(q[k, 2]), np.cos(q[k, 2])]]) for k in (i, j)]
            manifold = collide_polygons(posed[0], posed[1], margin)
            # posed here by a matrix product, in detect() by a compiled kernel: rounding of
            # coordinates of O(1) m only
            np.testing.assert_allclose(alone.gap[pair], manifold.gaps, rtol=0, atol=1e-12)


@pytest.mark.parametrize("dim", [2, 3])
def test_all_pairs_route_equals_the_sort_and_sweep_route(dim, monkeypatch):
    """Scenes of at most ALL_PAIRS_BODIES bodies are detected in one compiled call that tests
    every pair of boxes; larger ones by sort-and-sweep. Both routes find the same contacts in
    the same order, bit for bit (the routes differ in which pairs they try, not in what a
    pair gives), on scenes of a few dozen bodies jumbled with speculative sweeps: the 2D
    mixed scene (25 bodies) and a 3D running-bond wall (5 courses, 23 bodies)."""
    import nscd
    from nscd.contact import detect as detection

    scene = _mixed_scene() if dim == 2 else nscd.wall(5, 4, 0.4, 0.2, depth=0.2)[0]
    model = Model.from_scene(scene)
    assert len(model.bodies) <= detection.ALL_PAIRS_BODIES
    q0 = initial_state(scene).q
    rng = np.random.default_rng(3)
    qs = np.array([q0 + rng.normal(scale=0.01, size=q0.shape) * model.dynamic[:, None] for _ in range(3)])
    if dim == 3:  # unit quaternions again
        qs[:, :, 3:] /= np.linalg.norm(qs[:, :, 3:], axis=2, keepdims=True)
    sweep = rng.uniform(0.0, 0.01, qs.shape[:2])
    all_pairs, scene_of = detect_batch(model, qs, 0.02, sweep)
    monkeypatch.setattr(detection, "ALL_PAIRS_BODIES", 1)
    sorted_swept, scene_ref = detect_batch(model, qs, 0.02, sweep)
    assert len(all_pairs) > 3 * 20  # every scene has contacts
    np.testing.assert_array_equal(scene_of, scene_ref)
    for field in all_pairs.__dataclass_fields__:
        np.testing.assert_array_equal(getattr(all_pairs, field), getattr(sorted_swept, field), err_msg=field)


def test_margin_out_of_range_raises():
    with pytest.raises(ValueError, match="margin == -0.1"):
        collide_polygons(box(1.0, 1.0), box(1.0, 1.0, 0.0, 1.0), -0.1)
    with pytest.raises(ValueError, match="margin == nan"):
        collide_posed_polygons(box(1.0, 1.0), [0, 4], np.zeros((0, 2), dtype=int), math.nan)


def test_batch_with_no_pair_in_reach_is_empty():
    a = np.array([box(1.0, 1.0)] * 3)
    b = a + 5.0
    res = collide_polygons_batch(a, b, 0.1)
    assert res.count == 0 and res.points_a.shape == (0, 2) and res.manifold(0) is None


def test_split_ids_round_trip():
    ids = np.array([(1 << 32) | (5 << 16) | 7, (0 << 32) | (65535 << 16) | 0])
    ref_is_b, edge, vertex = split_ids(ids)
    np.testing.assert_array_equal(ref_is_b, [True, False])
    np.testing.assert_array_equal(edge, [5, 65535])
    np.testing.assert_array_equal(vertex, [7, 0])


def test_reference_and_ids_do_not_flicker_under_round_off_noise(impl):
    # a block resting flat (both separations 0, a tie) jittered by 1e-12 m, as a
    # solver would leave it: the base stays the reference, ids and normal stay put
    rng = np.random.default_rng(3)
    block = box(0.4, 1.2, 0.1, 0.0)
    for a_is_base in (True, False):
        seen = set()
        for _ in range(50):
            jitter = block + rng.normal(0.0, 1e-12, block.shape)
            m = impl(BASE, jitter, 1e-3) if a_is_base else impl(jitter, BASE, 1e-3)
            ref_is_b = split_ids(m.ids)[0]
            assert (ref_is_b == (not a_is_base)).all()  # the base's face is the reference
            seen.add(tuple(sorted(m.ids)))
            # normal from A to B within the jitter's angle (~1e-12 / 0.4 m)
            np.testing.assert_allclose(m.normal, [0.0, 1.0] if a_is_base else [0.0, -1.0], atol=1e-10)
        assert len(seen) == 1
    # equal blocks stacked (equal faces, separations both ~ the jitter): without a
    # tolerance the reference would follow the sign of the noise; with it, A keeps it
    lower, upper = box(0.4, 0.2, 0.0, 0.0), box(0.4, 0.2, 0.0, 0.2)
    for _ in range(50):
        m = impl(lower + rng.normal(0.0, 1e-12, (4, 2)), upper + rng.normal(0.0, 1e-12, (4, 2)), 1e-3)
        assert not split_ids(m.ids)[0].any()
        assert sorted(split_ids(m.ids)[2]) == [0, 1]


@pytest.mark.parametrize("n", [3, 6, 12])
def test_regular_polygon_resting_on_an_edge(impl, n):
    # regular n-gon of circumradius r with its bottom edge flat on y = 0:
    # two points at x = +-r sin(pi/n), gaps 0 (to round-off of the trigonometry)
    r = 0.3
    poly = regular(n, r, (0.0, 0.0), -np.pi / 2 - np.pi / n)
    poly[:, 1] -= poly[:, 1].min()
    m = impl(BASE, poly, 1e-3)
    check_consistent(m, BASE, poly)
    np.testing.assert_allclose(m.gaps, [0.0, 0.0], atol=ATOL)
    half = r * math.sin(math.pi / n)
    np.testing.assert_allclose(sorted(m.points_b[:, 0]), [-half, half], atol=ATOL)


# --- warm start by feature id (nscd.stepper.WarmStart), the few contacts of a small scene ---------

def test_warm_start_lookup_of_a_few_ids_matches_dict_semantics():
    """A few ids (a small scene's contacts): a repeated id keeps its last impulse (a step split
    at an impact), an unknown id gets 0, as in a dict built in order."""
    from nscd.stepper import WarmStart

    rng = np.random.default_rng(11)
    for _ in range(200):
        k, m = rng.integers(1, 8, 2)
        ids = rng.integers(0, 3, size=(k, 3))  # few distinct values: repeats and misses both occur
        impulses = rng.normal(size=(k, 2))
        as_dict = dict(zip(map(tuple, ids.tolist()), impulses))
        wanted = rng.integers(0, 3, size=(m, 3))
        expected = np.array([as_dict.get(key, np.zeros(2)) for key in map(tuple, wanted.tolist())])
        np.testing.assert_array_equal(WarmStart(ids, impulses).lookup(wanted), expected)
