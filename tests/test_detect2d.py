"""Tests of 2D polygon contact detection against geometry facts.

Every case is run through both the single-pair function and the batched one
(``impl`` fixture), so both are checked against geometry, not against each other.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from nscd.contact.detect2d import (
    REFERENCE_TOLERANCE,
    collide_polygons,
    collide_polygons_batch,
    split_ids,
)
from nscd.contact.manifold import Manifold

# Round-off: coordinates of order 1-10 m carry ~1e-16 relative error per
# operation and the algorithm chains a few tens of them.
ATOL = 1e-12


def _batched(a, b, margin):
    return collide_polygons_batch(a[None], b[None], margin).manifold(0)


@pytest.fixture(params=[collide_polygons, _batched], ids=["single", "batch"])
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


def test_batch_matches_single_on_random_pairs():
    """Cross-check of the two implementations (each is checked against geometry above)."""
    rng = np.random.default_rng(7)
    for n, k in ((4, 4), (3, 6)):
        a = np.array([random_polygon(rng, n, 1.0) for _ in range(400)])
        b = np.array([random_polygon(rng, k, 0.8) + rng.uniform(-2.2, 2.2, 2) for _ in range(400)])
        batch = collide_polygons_batch(a, b, 0.2)
        assert np.all(np.diff(batch.pair) >= 0)
        for i in range(len(a)):
            single, row = collide_polygons(a[i], b[i], 0.2), batch.manifold(i)
            assert (single is None) == (row is None)
            if single is not None:
                np.testing.assert_array_equal(single.ids, row.ids)
                for field in ("normal", "points_a", "points_b", "gaps"):
                    # same formulas, possibly different summation order in numpy: round-off
                    np.testing.assert_allclose(getattr(row, field), getattr(single, field), atol=1e-12)


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
