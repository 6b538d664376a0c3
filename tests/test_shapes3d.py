"""Convex polyhedra: mass properties against closed forms, topology, input checks."""
from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import ConvexHull
from scipy.spatial.transform import Rotation

from nscd.shapes3d import Polyhedron, box3, polyhedron

# Mass properties are sums of a few exact tetrahedron integrals: round-off only.
RTOL = 1e-12


def _octahedron(a: float) -> np.ndarray:
    return np.vstack([np.eye(3) * a, -np.eye(3) * a])


def _tetrahedron(edge: float) -> np.ndarray:
    # alternate corners of a cube of side edge / sqrt(2)
    c = edge / (2.0 * np.sqrt(2.0))
    return c * np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], dtype=float)


def test_box_mass_and_inertia_closed_form():
    a, b, c, rho = 0.22, 0.65, 0.80, 2670.0
    shape = box3(a, b, c)
    m = rho * a * b * c
    assert shape.mass(rho) == pytest.approx(m, rel=RTOL)
    expected = m / 12.0 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    np.testing.assert_allclose(shape.inertia(rho), expected, rtol=RTOL, atol=RTOL * m * c**2)
    np.testing.assert_allclose(shape.half_extents, [a / 2, b / 2, c / 2], rtol=RTOL)
    assert shape.radius == pytest.approx(0.5 * np.sqrt(a * a + b * b + c * c), rel=RTOL)
    assert len(shape.faces) == 6 and len(shape.edges) == 12 and len(shape.edge_directions) == 3


def test_regular_tetrahedron_closed_form():
    s = 0.3
    shape = polyhedron(_tetrahedron(s) + [1.0, -2.0, 0.5])   # off-origin input: recentred
    volume = s**3 / (6.0 * np.sqrt(2.0))
    assert shape.volume == pytest.approx(volume, rel=RTOL)
    # a regular tetrahedron's inertia is isotropic: I = m s^2 / 20
    np.testing.assert_allclose(shape.inertia_unit, volume * s**2 / 20.0 * np.eye(3),
                               atol=RTOL * volume * s**2)
    np.testing.assert_allclose(shape.vertices.mean(axis=0), 0.0, atol=1e-15)
    assert len(shape.faces) == 4 and len(shape.edge_directions) == 6


def test_regular_octahedron_closed_form():
    a = 0.4
    shape = polyhedron(_octahedron(a))
    s = a * np.sqrt(2.0)                        # edge length
    volume = np.sqrt(2.0) / 3.0 * s**3
    assert shape.volume == pytest.approx(volume, rel=RTOL)
    # I = m s^2 / 10 for a regular octahedron of edge s
    np.testing.assert_allclose(shape.inertia_unit, volume * s**2 / 10.0 * np.eye(3),
                               atol=RTOL * volume * s**2)
    assert len(shape.faces) == 8 and len(shape.edges) == 12


def test_rotated_box_inertia_transforms_as_a_tensor():
    rot = Rotation.from_euler("xyz", [0.3, -0.7, 1.1]).as_matrix()
    half = np.array([0.1, 0.2, 0.35])
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * half
    shape = polyhedron(corners @ rot.T)
    ref = box3(*(2 * half))
    np.testing.assert_allclose(shape.inertia_unit, rot @ ref.inertia_unit @ rot.T,
                               atol=RTOL * ref.volume)
    # coplanar triangles of the hull are merged: 6 quadrilateral faces, 3 edge families
    assert len(shape.faces) == 6 and all(len(f) == 4 for f in shape.faces)
    assert len(shape.edge_directions) == 3


@pytest.mark.parametrize("points", [
    np.vstack([np.eye(3), -np.eye(3)]),
    np.random.default_rng(1).normal(size=(30, 3)),
])
def test_topology_is_a_closed_convex_surface(points):
    shape = polyhedron(points[ConvexHull(points).vertices])   # random points: keep the hull
    v = shape.vertices
    # Euler characteristic of a convex polyhedron
    assert len(v) - len(shape.edges) + len(shape.faces) == 2
    for face, n, d in zip(shape.faces, shape.face_normals, shape.face_offsets):
        poly = v[face]
        # all vertices on or behind every face plane (convexity, outward normals)
        assert np.max(v @ n - d) <= 1e-12
        np.testing.assert_allclose(poly @ n, d, atol=1e-12)
        # counter-clockwise seen from outside: the polygon's area vector is along n
        area_vec = 0.5 * np.cross(poly, np.roll(poly, -1, axis=0)).sum(axis=0)
        assert area_vec @ n > 0.0
        np.testing.assert_allclose(area_vec / np.linalg.norm(area_vec), n, atol=1e-9)
    # divergence theorem: V = 1/3 sum_faces area . offset
    areas = [np.linalg.norm(0.5 * np.cross(v[f], np.roll(v[f], -1, axis=0)).sum(axis=0))
             for f in shape.faces]
    assert shape.volume == pytest.approx(np.dot(areas, shape.face_offsets) / 3.0, rel=1e-12)


def test_world_vertices_and_place():
    shape = box3(1.0, 2.0, 3.0)
    rot = Rotation.from_euler("z", 90, degrees=True).as_matrix()
    pos = np.array([1.0, 2.0, 3.0])
    world = shape.world_vertices(pos, rot)
    # a quarter turn about z swaps the x and y extents
    np.testing.assert_allclose(np.ptp(world, axis=0), [2.0, 1.0, 3.0], atol=1e-12)
    placed = shape.place(pos, rot)
    np.testing.assert_allclose(placed.vertices, world)
    for f, (face, n, d) in enumerate(zip(shape.faces, placed.face_normals, placed.face_offsets)):
        np.testing.assert_allclose(world[face] @ n, d, atol=1e-12)
        # side plane i passes through face edge (i, i + 1), perpendicular to the face,
        # with the whole face behind it
        sides = placed.side_planes[shape.side_start[f]:shape.side_start[f + 1]]
        np.testing.assert_allclose(sides[:, :3] @ n, 0.0, atol=1e-12)
        signed = world[face] @ sides[:, :3].T - sides[:, 3]       # (vertex, side)
        for i in range(len(face)):
            np.testing.assert_allclose(signed[[i, (i + 1) % len(face)], i], 0.0, atol=1e-12)
        assert signed.max() <= 1e-12 and signed.min() < -0.5   # sides 1, 2, 3 m apart


@pytest.mark.parametrize("points, match", [
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "at least 4"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [0.5, 0.3, 0]], "coplanar"),
    ([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]], "collinear"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 0, 0]], "coincide"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [0.1, 0.1, 0.1], [0.2, 0.1, 0.1]],
     "non-convex: 2 of 6 points lie inside"),
    ([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]], "non-finite"),
    ([[0, 0], [1, 0], [0, 1], [1, 1]], r"shape \(4, 2\)"),
])
def test_polyhedron_rejects_bad_input(points, match):
    with pytest.raises(ValueError, match=match):
        polyhedron(points)


@pytest.mark.parametrize("sides", [(0.0, 1.0, 1.0), (1.0, -2.0, 1.0), (1.0, 1.0, np.inf)])
def test_box3_rejects_bad_sides(sides):
    with pytest.raises(ValueError, match="must be > 0 m"):
        box3(*sides)


def test_from_trimesh_matches_closed_form():
    a, b, c = 1.02, 0.65, 0.15
    mesh = trimesh.creation.box(extents=(a, b, c))
    mesh.apply_translation([0.3, -0.2, 1.0])
    shape = Polyhedron.from_trimesh(mesh)
    assert shape.volume == pytest.approx(a * b * c, rel=1e-12)
    expected = a * b * c / 12.0 * np.diag([b**2 + c**2, a**2 + c**2, a**2 + b**2])
    np.testing.assert_allclose(shape.inertia_unit, expected, atol=1e-12 * a * b * c)
    np.testing.assert_allclose(shape.vertices.mean(axis=0), 0.0, atol=1e-12)
    assert len(shape.faces) == 6


def test_from_trimesh_rejects_open_and_non_convex_meshes():
    open_box = trimesh.creation.box()
    open_box.update_faces(np.arange(len(open_box.faces)) > 1)   # drop one square
    with pytest.raises(ValueError, match="not watertight"):
        Polyhedron.from_trimesh(open_box)
    ring = trimesh.creation.annulus(r_min=0.5, r_max=1.0, height=0.2)
    with pytest.raises(ValueError, match="non-convex"):
        Polyhedron.from_trimesh(ring)
