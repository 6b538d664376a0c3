"""3D narrow phase: contact manifolds of convex polyhedra against exact geometry."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from nscd.contact import detect3d
from nscd.contact.detect3d import MAX_POINTS, collide_polyhedra, collide_posed
from nscd.shapes3d import PlacedPolyhedron, Polyhedron, PolyhedronBatch, box3, polyhedron

# Geometry in double precision on O(1 m) bodies: results are exact up to round-off of a
# few rotations and products, far below this.
ATOL = 1e-12
I3 = np.eye(3)
BASE = box3(4.0, 4.0, 1.0)            # top face at z = 0 when placed at z = -0.5
BLOCK = box3(0.2, 0.3, 0.8)
MARGIN = 1e-3


def _rot(seq: str, *angles_deg: float) -> np.ndarray:
    return Rotation.from_euler(seq, angles_deg, degrees=True).as_matrix()


def _on_ground() -> PlacedPolyhedron:
    return BASE.place([0.0, 0.0, -0.5], I3)


def _check_manifold(m, a: PlacedPolyhedron, b: PlacedPolyhedron) -> None:
    """Contract: unit normal, gaps = (pb - pa) . n, points on the bodies' surfaces."""
    assert np.linalg.norm(m.normal) == pytest.approx(1.0, abs=ATOL)
    assert 1 <= m.count <= MAX_POINTS
    np.testing.assert_allclose((m.points_b - m.points_a) @ m.normal, m.gaps, atol=ATOL)
    for body, pts in ((a, m.points_a), (b, m.points_b)):
        signed = pts @ body.face_normals.T - body.face_offsets    # <= 0 inside
        np.testing.assert_allclose(signed.max(axis=1), 0.0, atol=1e-9)


def test_box_resting_on_big_box_has_its_four_corners():
    a, b = _on_ground(), BLOCK.place([0.3, -0.2, 0.4], I3)
    m = collide_polyhedra(a, b, MARGIN)
    _check_manifold(m, a, b)
    np.testing.assert_allclose(m.normal, [0, 0, 1], atol=ATOL)
    np.testing.assert_allclose(m.gaps, 0.0, atol=ATOL)
    corners = {(round(x, 9), round(y, 9)) for x in (0.2, 0.4) for y in (-0.35, -0.05)}
    assert {(round(x, 9), round(y, 9)) for x, y, _ in m.points_b} == corners
    np.testing.assert_allclose(m.points_a[:, 2], 0.0, atol=ATOL)
    assert len(set(m.ids.tolist())) == 4


def test_penetration_gives_negative_gaps():
    a, b = _on_ground(), BLOCK.place([0.0, 0.0, 0.4 - 2e-3], I3)
    m = collide_polyhedra(a, b, MARGIN)
    assert m.count == 4
    np.testing.assert_allclose(m.gaps, -2e-3, atol=ATOL)


@pytest.mark.parametrize("theta_deg", [5.0, 20.0])
def test_tilted_box_on_one_edge(theta_deg):
    theta = np.radians(theta_deg)
    hy, hz = 0.15, 0.4
    # rotated about x by +theta: the corner edge y = +hy, z = -hz is the lowest
    z_low = hy * np.sin(theta) + hz * np.cos(theta)
    a, b = _on_ground(), BLOCK.place([0.0, 0.0, z_low], _rot("x", theta_deg))
    m = collide_polyhedra(a, b, MARGIN)
    _check_manifold(m, a, b)
    np.testing.assert_allclose(m.normal, [0, 0, 1], atol=ATOL)
    assert m.count == 2                       # the lifted edge is beyond the margin
    np.testing.assert_allclose(m.gaps, 0.0, atol=ATOL)
    np.testing.assert_allclose(sorted(m.points_b[:, 0]), [-0.1, 0.1], atol=ATOL)
    # with a margin above the lift 2 hy sin(theta), the lifted corners are reported too
    lift = 2 * hy * np.sin(theta)
    m = collide_polyhedra(a, b, 1.1 * lift)
    assert m.count == 4
    np.testing.assert_allclose(np.sort(m.gaps), [0.0, 0.0, lift, lift], atol=ATOL)


def test_box_rotated_45_about_z_keeps_four_corners():
    a, b = _on_ground(), BLOCK.place([0.0, 0.0, 0.4], _rot("z", 45.0))
    m = collide_polyhedra(a, b, MARGIN)
    _check_manifold(m, a, b)
    assert m.count == 4
    np.testing.assert_allclose(m.gaps, 0.0, atol=ATOL)
    expected = np.array([[x, y, 0.0] for x in (-0.1, 0.1) for y in (-0.15, 0.15)]) @ _rot("z", 45.0).T
    for p in expected:
        assert np.min(np.linalg.norm(m.points_b - p, axis=1)) < ATOL


def test_equal_boxes_crossed_give_the_octagon():
    # two equal square prisms, the upper one turned 45 deg: contact patch is a regular octagon
    cube = box3(0.4, 0.4, 0.4)
    a, b = cube.place([0, 0, 0], I3), cube.place([0, 0, 0.4], _rot("z", 45.0))
    m = collide_polyhedra(a, b, MARGIN)
    _check_manifold(m, a, b)
    assert m.count == 8
    np.testing.assert_allclose(m.gaps, 0.0, atol=ATOL)
    area = ConvexHull(m.points_a[:, :2]).volume
    # square of side s minus four corner triangles of legs s (1 - 1/sqrt 2)... = 8 (sqrt2-1) (s/2)^2
    assert area == pytest.approx(8 * (np.sqrt(2) - 1) * 0.2**2, rel=1e-12)


@pytest.mark.parametrize("gap", [0.02, 0.0, -0.003])
def test_edge_edge_crossing_one_point_analytic_gap(gap):
    h = np.array([0.1, 0.15, 0.4])
    top_a = (h[1] + h[2]) / np.sqrt(2)        # box turned 45 deg about x: top is an x edge
    bottom_b = (h[0] + h[2]) / np.sqrt(2)     # box turned 45 deg about y: bottom is a y edge
    # shifted so that the two edges cross over the origin
    a = BLOCK.place([0, (h[2] - h[1]) / np.sqrt(2), 0], _rot("x", 45.0))
    b = BLOCK.place([(h[2] - h[0]) / np.sqrt(2), 0, top_a + bottom_b + gap], _rot("y", 45.0))
    m = collide_polyhedra(a, b, 0.05)
    _check_manifold(m, a, b)
    assert m.count == 1
    np.testing.assert_allclose(m.normal, [0, 0, 1], atol=ATOL)
    assert m.gaps[0] == pytest.approx(gap, abs=ATOL)
    np.testing.assert_allclose(m.points_a[0], [0, 0, top_a], atol=ATOL)
    np.testing.assert_allclose(m.points_b[0], [0, 0, top_a + gap], atol=ATOL)
    # beyond the margin: no manifold
    assert collide_polyhedra(a, b, 0.9 * gap) is None if gap > 0 else True


def test_separated_beyond_margin_is_none():
    a = _on_ground()
    assert collide_polyhedra(a, BLOCK.place([0, 0, 0.4 + 2 * MARGIN], I3), MARGIN) is None
    # side by side, apart horizontally
    assert collide_polyhedra(a, BASE.place([4.0 + 2 * MARGIN, 0, -0.5], I3), MARGIN) is None
    # within the margin: reported with positive gaps
    m = collide_polyhedra(a, BLOCK.place([0, 0, 0.4 + 0.5 * MARGIN], I3), MARGIN)
    np.testing.assert_allclose(m.gaps, 0.5 * MARGIN, atol=ATOL)


@pytest.mark.parametrize("pose_b", [
    ([0.0, 0.0, 0.395], ("x", 3.0)),
    ([0.05, 0.02, 0.40], ("zx", 30.0, 2.0)),
])
def test_swapping_bodies_flips_the_normal(pose_b):
    pos, (seq, *ang) = pose_b
    a, b = _on_ground(), BLOCK.place(pos, _rot(seq, *ang))
    ab, ba = collide_polyhedra(a, b, 0.05), collide_polyhedra(b, a, 0.05)
    np.testing.assert_allclose(ba.normal, -ab.normal, atol=ATOL)
    order_ab, order_ba = np.lexsort(ab.points_a.T), np.lexsort(ba.points_b.T)
    np.testing.assert_allclose(ba.points_b[order_ba], ab.points_a[order_ab], atol=ATOL)
    np.testing.assert_allclose(ba.points_a[order_ba], ab.points_b[order_ab], atol=ATOL)
    np.testing.assert_allclose(ba.gaps[order_ba], ab.gaps[order_ab], atol=ATOL)


def test_rigid_motion_invariance():
    rng = np.random.default_rng(7)
    cube = box3(0.3, 0.3, 0.3)
    configs = [
        (_on_ground(), BLOCK.place([0.1, 0.0, 0.399], _rot("xz", 4.0, 25.0))),
        # crossed edges of two cubes, 1 mm interpenetration
        (cube.place([0, 0, 0], _rot("x", 45.0)),
         cube.place([0, 0, 0.3 * np.sqrt(2) - 1e-3], _rot("y", 45.0))),
    ]
    for a, b in configs:
        ref = collide_polyhedra(a, b, 0.01)
        for _ in range(5):
            rot = Rotation.random(random_state=rng).as_matrix()
            shift = rng.normal(size=3)
            moved = [body.shape.place(rot @ body.position + shift, rot @ body.rotation)
                     for body in (a, b)]
            m = collide_polyhedra(*moved, 0.01)
            np.testing.assert_allclose(m.normal, rot @ ref.normal, atol=1e-12)
            np.testing.assert_allclose(m.points_a, ref.points_a @ rot.T + shift, atol=1e-12)
            np.testing.assert_allclose(m.points_b, ref.points_b @ rot.T + shift, atol=1e-12)
            np.testing.assert_allclose(m.gaps, ref.gaps, atol=1e-12)
            np.testing.assert_array_equal(m.ids, ref.ids)


def test_feature_ids_are_stable_under_small_motion():
    a = _on_ground()
    ids = [collide_polyhedra(a, BLOCK.place([x, 0.0, 0.4 - 1e-4], _rot("z", z)), MARGIN).ids
           for x, z in ((0.0, 0.0), (0.01, 1.0), (-0.02, -2.0))]
    for other in ids[1:]:
        np.testing.assert_array_equal(other, ids[0])


def test_many_point_patch_is_reduced_keeping_the_outline():
    n = 16
    ring = [(np.cos(t), np.sin(t)) for t in 2 * np.pi * np.arange(n) / n]
    prism = polyhedron([(0.3 * x, 0.3 * y, z) for z in (-0.2, 0.2) for x, y in ring])
    a = _on_ground()
    # a slight tilt makes one bottom corner the deepest
    b = prism.place([0, 0, 0.2 - 1e-4], _rot("y", 0.01))
    m = collide_polyhedra(a, b, MARGIN)
    _check_manifold(m, a, b)
    assert m.count == MAX_POINTS
    # the deepest corner of the full 16-gon is kept
    bottom = b.vertices[b.vertices[:, 2] < 0]
    assert np.min(np.linalg.norm(m.points_b - bottom[bottom[:, 2].argmin()], axis=1)) < ATOL
    # the kept points are corners spread round the patch: every other corner of the
    # 16-gon spans the regular octagon, area ratio cos(pi/8) = 0.924
    kept_area = ConvexHull(m.points_a[:, :2]).volume
    full_area = 0.5 * n * 0.3**2 * np.sin(2 * np.pi / n)
    # (1e-6: the 0.01 deg tilt shrinks projected lengths by 1 - 1.5e-8)
    assert kept_area >= np.cos(np.pi / 8) * full_area * (1 - 1e-6)


def _random_polyhedron(rng: np.random.Generator) -> Polyhedron:
    pts = rng.normal(size=(12, 3)) * rng.uniform(0.1, 0.5, size=3)
    return polyhedron(pts[ConvexHull(pts).vertices])


def _overlap(a: PlacedPolyhedron, b: PlacedPolyhedron) -> bool:
    """Do the two hulls share a point? LP feasibility over barycentric weights."""
    na, nb = len(a.vertices), len(b.vertices)
    eq = np.zeros((5, na + nb))
    eq[:3, :na], eq[:3, na:] = a.vertices.T, -b.vertices.T
    eq[3, :na], eq[4, na:] = 1.0, 1.0
    res = linprog(np.zeros(na + nb), A_eq=eq, b_eq=[0, 0, 0, 1, 1], bounds=(0, None))
    return res.status == 0


def _segment_distances(p0, p1, q0, q1) -> np.ndarray:
    """Distances of segment pairs p0p1, q0q1 (k, 3): min of |r + s d1 - t d2| on [0, 1]^2.

    The minimum of this convex quadratic is the stationary point if it lies in the
    square, else on one of the four sides, where it is a clamped 1D minimum.
    """
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, b = (d1 * d1).sum(1), (d2 * d2).sum(1), (d1 * d2).sum(1)
    c, f = (d1 * r).sum(1), (d2 * r).sum(1)

    def dist(s, t):
        return np.linalg.norm(r + s[:, None] * d1 - t[:, None] * d2, axis=1)

    one = np.ones_like(a)
    found = [dist(np.clip((t * b - c) / a, 0, 1), t) for t in (0 * one, one)]
    found += [dist(s, np.clip((s * b + f) / e, 0, 1)) for s in (0 * one, one)]
    det = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s, t = (b * f - c * e) / det, (a * f - b * c) / det
    inside = (det > 1e-12 * a * e) & (s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)
    found.append(np.where(inside, dist(np.where(inside, s, 0), np.where(inside, t, 0)), np.inf))
    return np.min(found, axis=0)


def _distance(a: PlacedPolyhedron, b: PlacedPolyhedron) -> float:
    """Distance of two disjoint convex hulls by brute force over features.

    The closest points of disjoint convex polytopes are a vertex over a face or two
    edges (vertex-edge and vertex-vertex are clamped edge-edge cases). Hull triangles
    come from scipy's ConvexHull, independent of the code under test.
    """
    found = []
    hulls = [ConvexHull(body.vertices) for body in (a, b)]
    for (this, _), (other, hull) in (((a, None), (b, hulls[1])), ((b, None), (a, hulls[0]))):
        tri = other.vertices[hull.simplices]                        # (t, 3, 3)
        n, off = hull.equations[:, :3], -hull.equations[:, 3]
        height = this.vertices @ n.T - off                          # (v, t)
        foot = this.vertices[:, None, :] - height[..., None] * n    # projections
        # inside the triangle: on the same side of its three edges (either winding)
        side = np.stack([
            np.einsum("vtk,tk->vt", np.cross(tri[:, (i + 1) % 3] - tri[:, i], foot - tri[:, i]), n)
            for i in range(3)
        ])
        inside = (side >= 0).all(axis=0) | (side <= 0).all(axis=0)
        found.append(np.where(inside & (height >= 0), height, np.inf).min())
    edges = [np.concatenate([h.simplices[:, [i, (i + 1) % 3]] for i in range(3)]) for h in hulls]
    ea, eb = np.meshgrid(np.arange(len(edges[0])), np.arange(len(edges[1])), indexing="ij")
    pa, pb = a.vertices[edges[0][ea.ravel()]], b.vertices[edges[1][eb.ravel()]]
    found.append(_segment_distances(pa[:, 0], pa[:, 1], pb[:, 0], pb[:, 1]).min())
    return float(min(found))


def test_random_pairs_separated_along_a_face_have_the_exact_gap():
    """B's lowest vertex along -n sits at distance g over the centre of a face of A.

    A lies below that face's plane and B above the parallel plane at g, so the distance
    is exactly g, attained between the face and the vertex: the manifold's smallest gap
    must be g, and no manifold may be reported with a margin below g.
    """
    rng = np.random.default_rng(3)
    for _ in range(30):
        shape_a, shape_b = _random_polyhedron(rng), _random_polyhedron(rng)
        a = shape_a.place(rng.normal(size=3), Rotation.random(random_state=rng).as_matrix())
        rot_b = Rotation.random(random_state=rng).as_matrix()
        f = int(rng.integers(len(shape_a.faces)))
        n = a.face_normals[f]
        centre = a.vertices[shape_a.faces[f]].mean(axis=0)
        local_b = shape_b.vertices @ rot_b.T
        g = float(rng.uniform(0.0, 0.05))
        b = shape_b.place(centre + g * n - local_b[(local_b @ n).argmin()], rot_b)
        m = collide_polyhedra(a, b, 0.06)
        _check_manifold(m, a, b)
        assert m.gaps.min() == pytest.approx(g, abs=1e-12)
        if g > 1e-3:
            assert collide_polyhedra(a, b, 0.9 * g) is None


def test_random_pairs_against_the_true_distance():
    """Random pairs against a brute-force distance and an LP overlap test.

    Overlapping pairs have a negative gap. Separated pairs have only positive gaps (a
    separating axis exists among face normals and edge crosses); a face contact's
    points are pairs of surface points along the normal, so its gaps are not below the
    distance, and equal to it when the closest points lie along the normal. Pairs
    closer than the margin are never missed.
    """
    rng = np.random.default_rng(11)
    apart = exact = touching = 0
    for _ in range(60):
        shape_a, shape_b = _random_polyhedron(rng), _random_polyhedron(rng)
        a = shape_a.place(np.zeros(3), Rotation.random(random_state=rng).as_matrix())
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        reach = shape_a.radius + shape_b.radius
        b = shape_b.place(direction * reach * rng.uniform(0.3, 0.8),
                          Rotation.random(random_state=rng).as_matrix())
        m = collide_polyhedra(a, b, 10.0)          # a margin that reports every pair
        _check_manifold(m, a, b)
        if _overlap(a, b):
            assert m.gaps.min() <= 1e-12           # touching within round-off
            touching += 1
            continue
        apart += 1
        dist = _distance(a, b)
        if collide_polyhedra(a, b, 0.05) is None:
            assert dist > 0.05
        assert m.gaps.min() > 0.0
        if m.ids[0] < 2**46:                       # face contact (ids: module docstring)
            # 1e-12 m: round-off of the brute-force projections
            assert m.gaps.min() >= dist - 1e-12
            if m.gaps.min() <= dist * (1 + 1e-9):
                exact += 1
    assert apart >= 10 and touching >= 10 and exact >= 5    # all cases exercised


# ---------------------------------------------------------------- batched and compiled paths
def _prism(n: int, radius: float, height: float, turn: float) -> Polyhedron:
    angles = 2 * np.pi * np.arange(n) / n + turn
    return polyhedron([(radius * np.cos(t), radius * np.sin(t), z)
                       for z in (-height / 2, height / 2) for t in angles])


def _random_configurations(rng: np.random.Generator, count: int) -> list:
    """(shape_a, pose_a, shape_b, pose_b, margin) of boxes, prisms and random hulls.

    Half in general position (face, edge-edge, vertex contacts, separated pairs), half
    resting face on face with small tilts and overlaps (clipping, reduction to 8 points).
    """
    shapes = [BLOCK, box3(1.0, 1.0, 0.25), box3(0.3, 0.3, 0.3), _prism(3, 0.2, 0.4, 0.3),
              _prism(6, 0.3, 0.2, 0.1), _prism(16, 0.3, 0.4, 0.2), _random_polyhedron(rng)]
    out = []
    for k in range(count):
        sa, sb = shapes[rng.integers(len(shapes))], shapes[rng.integers(len(shapes))]
        ra, rb = Rotation.random(2, random_state=rng).as_matrix()
        if k % 2:
            ra = _rot("z", rng.uniform(0, 90))
            rb = _rot("xyz", *rng.normal(0, 2, size=2), rng.uniform(0, 90))
            lift = (sa.vertices @ ra.T)[:, 2].max() - (sb.vertices @ rb.T)[:, 2].min()
            pb = np.array([*rng.normal(0, 0.05, size=2), lift + rng.uniform(-2e-3, 2e-3)])
        else:
            direction = rng.normal(size=3)
            pb = direction / np.linalg.norm(direction) * (sa.radius + sb.radius) * rng.uniform(0.3, 1.0)
        out.append((sa, (np.zeros(3), ra), sb, (pb, rb), float(rng.choice([1e-3, 1e-2, 1e-1]))))
    return out


def test_batch_pose_is_place_of_each_body():
    rng = np.random.default_rng(5)
    shapes = [BLOCK, _prism(6, 0.3, 0.2, 0.1), BLOCK, _random_polyhedron(rng)]
    positions = rng.normal(size=(4, 3))
    rotations = Rotation.random(4, random_state=rng).as_matrix()
    batch = PolyhedronBatch(shapes)
    posed = batch.pose(positions, rotations)
    for k, shape in enumerate(shapes):
        placed = shape.place(positions[k], rotations[k])
        rows = {
            "vertices": slice(batch.vertex_start[k], batch.vertex_start[k + 1]),
            "face_normals": slice(batch.face_start[k], batch.face_start[k + 1]),
            "face_offsets": slice(batch.face_start[k], batch.face_start[k + 1]),
            "edge_directions": slice(batch.family_start[k], batch.family_start[k + 1]),
            "side_planes": slice(batch.side_start[batch.face_start[k]], batch.side_start[batch.face_start[k + 1]]),
        }
        for field, row in rows.items():
            # the same arithmetic row by row: equal to the last bit
            np.testing.assert_array_equal(getattr(posed, field)[row], getattr(placed, field))
        # topology with batch-wide indices: shifted by the body's first vertex / face
        for f, face in enumerate(shape.faces):
            g = batch.face_start[k] + f
            np.testing.assert_array_equal(
                batch.face_vertices[batch.side_start[g]:batch.side_start[g + 1]], face + batch.vertex_start[k])
        np.testing.assert_array_equal(batch.edges[batch.edge_start[k]:batch.edge_start[k + 1]],
                                      shape.edges + batch.vertex_start[k])


def test_batched_pairs_equal_single_pairs():
    """All pairs of one batch at once: each pair's rows are its own manifold (local feature ids)."""
    rng = np.random.default_rng(21)
    configs = _random_configurations(rng, 40)
    shapes = [s for sa, _, sb, _, _ in configs for s in (sa, sb)]
    poses = [p for _, pa, _, pb, _ in configs for p in (pa, pb)]
    batch = PolyhedronBatch(shapes)
    posed = batch.pose(np.array([p for p, _ in poses]), np.array([r for _, r in poses]))
    pairs = np.arange(len(shapes)).reshape(-1, 2)
    margin = 0.01
    found = collide_posed(batch, posed, pairs, margin)
    touching = 0
    for k, (sa, pa, sb, pb, _) in enumerate(configs):
        single = collide_polyhedra(sa.place(*pa), sb.place(*pb), margin)
        many = found.manifold(k)
        assert (single is None) == (many is None)
        if single is not None:
            touching += 1
            for field in ("normal", "points_a", "points_b", "gaps", "ids"):
                np.testing.assert_array_equal(getattr(many, field), getattr(single, field))
    assert touching >= 10


def test_compiled_kernel_equals_plain_python(monkeypatch):
    """The numba-compiled narrow phase against the plain-Python execution of the same code."""
    rng = np.random.default_rng(17)
    configs = _random_configurations(rng, 400)
    compiled = [collide_polyhedra(sa.place(*pa), sb.place(*pb), m) for sa, pa, sb, pb, m in configs]
    for name, value in vars(detect3d).items():
        if hasattr(value, "py_func"):
            monkeypatch.setattr(detect3d, name, value.py_func)
    assert not hasattr(detect3d.collide_posed_fields, "py_func")     # plain Python from here on
    kinds = set()
    for (sa, pa, sb, pb, m), ref in zip(configs, compiled):
        plain = collide_polyhedra(sa.place(*pa), sb.place(*pb), m)
        assert (plain is None) == (ref is None)
        if ref is None:
            kinds.add("none")
            continue
        kinds.add("edge" if ref.ids[0] >= 2**46 else "face")
        np.testing.assert_array_equal(plain.ids, ref.ids)
        for field in ("normal", "points_a", "points_b", "gaps"):
            # fastmath off: IEEE arithmetic in the same order; 1e-12 m leaves room for a
            # compiler's fused multiply-add, nothing more
            np.testing.assert_allclose(getattr(plain, field), getattr(ref, field), rtol=0, atol=1e-12)
    assert kinds == {"none", "edge", "face"}


def test_collide_posed_rejects_bad_margin():
    batch = PolyhedronBatch([BLOCK, BLOCK])
    posed = batch.pose(np.array([[0, 0, 0], [0, 0, 0.8]]), np.array([I3, I3]))
    with pytest.raises(ValueError, match=r"margin == -0.1, must be >= 0 m"):
        collide_posed(batch, posed, np.array([[0, 1]]), -0.1)


def test_batch_rejects_bad_input():
    with pytest.raises(ValueError, match="shapes is empty"):
        PolyhedronBatch([])
    with pytest.raises(ValueError, match=r"shapes\[1\] is a str, must be a Polyhedron"):
        PolyhedronBatch([BLOCK, "box"])
    with pytest.raises(ValueError, match=r"must be \(2, 3\) and \(2, 3, 3\)"):
        PolyhedronBatch([BLOCK, BLOCK]).pose(np.zeros((3, 3)), np.array([I3, I3]))


def test_flush_equal_faces_keep_their_points_and_ids_under_sub_micrometre_motion():
    """Two equal blocks stacked flush (as in a wall one block thick): the incident face's
    corners lie on the reference face's sides, where round-off decides in or out. Within
    the clipping band they stay the same four points with the same ids, on the reference
    face: the warm start of the next step finds every contact again."""
    lower = BLOCK.place([0.0, 0.0, 0.4], I3)
    reference = None
    for dx, dy, turn in ((0.0, 0.0, 0.0), (3e-8, -2e-8, 1e-7), (-4e-8, 5e-8, -2e-7), (1e-7, 1e-7, 0.0)):
        upper = BLOCK.place([dx, dy, 1.2 - 1e-6], _rot("z", np.degrees(turn)))
        m = collide_polyhedra(lower, upper, MARGIN)
        assert m.count == 4
        # on the reference (lower) face, within round-off: the top face of the lower block
        assert np.abs(m.points_a[:, 0]).max() <= 0.1 + 1e-12 and np.abs(m.points_a[:, 1]).max() <= 0.15 + 1e-12
        # the corners of the upper block moved by at most 1.5e-7 m (rotation 2e-7 rad x 0.18 m + shift)
        np.testing.assert_allclose(np.sort(np.abs(m.points_b[:, :2]), axis=0),
                                   np.tile([0.1, 0.15], (4, 1)), atol=2e-7)
        np.testing.assert_allclose(m.gaps, -1e-6, atol=1e-12)
        if reference is None:
            reference = m.ids
        np.testing.assert_array_equal(m.ids, reference)
