"""Rigid convex polyhedra in 3D: geometry, topology and mass properties.

A :class:`Polyhedron` stores its vertices about its centroid, so the body frame origin
is the centre of mass (the body axes are the axes of the input coordinates, not
necessarily the principal axes). Faces are convex polygons, counter-clockwise seen from
outside; coplanar hull triangles are merged. Mass properties follow from the geometry
and a density in kg/m^3: ``mass = density * volume`` (kg) and
``inertia = density * inertia_unit`` (kg m^2, about the centroid, body axes).

Build one with :func:`polyhedron` (convex point set), :func:`box3` (cuboid),
:func:`chamfered_box` (cuboid with 45-degree cuts along its base edges) or
:meth:`Polyhedron.from_trimesh` (a watertight convex ``trimesh.Trimesh``). A posed copy
for contact detection comes from :meth:`Polyhedron.place`; the time step lays all bodies
end to end in a :class:`PolyhedronBatch` and poses them at once
(:meth:`PolyhedronBatch.pose`).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, NamedTuple, Sequence

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from nscd._jit import njit

#: Relative tolerance (scaled by the size of the point set) for coincident points,
#: flat point sets and the merging of coplanar hull triangles into one face.
_REL_TOL = 1e-9

#: Size limits that keep contact feature ids unique (nscd.contact.detect3d).
_MAX_FACES = 4096
_MAX_FACE_VERTICES = 512

#: Two edge directions are the same if the sine of their angle is below this.
_PARALLEL_SIN = 1e-9


@dataclass(frozen=True, eq=False)
class Polyhedron:
    """A rigid convex polyhedron in its body frame (origin at the centroid).

    Attributes
    ----------
    vertices : ndarray, shape (n, 3)
        Vertices in m, relative to the centroid.
    faces : tuple of ndarray of int
        Vertex indices of each face, counter-clockwise seen from outside.
    face_normals : ndarray, shape (f, 3)
        Outward unit normals of the faces.
    face_offsets : ndarray, shape (f,)
        Plane offsets in m: ``face_normals[i] @ x == face_offsets[i]`` on face ``i``
        (positive, the centroid is inside).
    edges : ndarray of int, shape (e, 2)
        Unique edges as vertex index pairs ``(i, j)`` with ``i < j``.
    edge_directions : ndarray, shape (u, 3)
        Unit directions of the edges, one per family of parallel edges (sign arbitrary).
    edge_family : ndarray of int, shape (e,)
        Row of ``edge_directions`` parallel to each edge.
    vertex_faces : tuple of ndarray of int
        Indices of the faces around each vertex.
    side_planes : ndarray, shape (s, 4)
        For every face edge (face after face; edge ``i`` of a face runs from its vertex
        ``i`` to ``i + 1``), the plane through the edge perpendicular to the face: outward
        unit normal ``(sx, sy, sz)`` and ``offset = s . x`` on it, m (face clipping).
    side_start : ndarray of int, shape (f + 1,)
        Rows ``side_start[i]:side_start[i + 1]`` of ``side_planes`` belong to face ``i``.
    volume : float
        Volume in m^3.
    inertia_unit : ndarray, shape (3, 3)
        Inertia tensor about the centroid per unit density, m^5 (kg m^2 per kg/m^3).
    half_extents : ndarray, shape (3,)
        Half sides in m of the smallest box centred on the centroid and aligned with
        the body axes that contains the polyhedron (``max |vertices|`` per axis).
    radius : float
        Bounding radius about the centroid, m.
    dim : int
        Space dimension, 3.
    """

    vertices: np.ndarray
    faces: tuple[np.ndarray, ...]
    face_normals: np.ndarray
    face_offsets: np.ndarray
    edges: np.ndarray
    edge_directions: np.ndarray
    edge_family: np.ndarray
    vertex_faces: tuple[np.ndarray, ...]
    side_planes: np.ndarray
    side_start: np.ndarray
    volume: float
    inertia_unit: np.ndarray
    half_extents: np.ndarray
    radius: float
    dim: int = 3

    def mass(self, density: float) -> float:
        """Mass in kg at ``density`` (kg/m^3)."""
        return density * self.volume

    def inertia(self, density: float) -> np.ndarray:
        """Inertia tensor (3, 3) in kg m^2 about the centroid, body axes, at ``density``."""
        return density * self.inertia_unit

    @property
    def thickness(self) -> float:
        """Smallest extent along a face normal, m: the smallest width of a prism or a box
        (of a general polyhedron, at most ``2 / sqrt(3)`` of it: a regular tetrahedron's width
        is across two opposite edges)."""
        return float(np.min(np.ptp(self.vertices @ self.face_normals.T, axis=0)))

    def world_vertices(self, position: Sequence[float], rotation: np.ndarray) -> np.ndarray:
        """Vertices (n, 3) in the world frame, m.

        Parameters
        ----------
        position : array_like, shape (3,)
            World position of the centroid, m.
        rotation : ndarray, shape (3, 3)
            Rotation matrix from body to world (``x_world = rotation @ x_body + position``).
        """
        return self.vertices @ np.asarray(rotation).T + np.asarray(position, dtype=float)

    def place(self, position: Sequence[float], rotation: np.ndarray) -> PlacedPolyhedron:
        """This polyhedron posed in the world, with the data contact detection needs.

        One body at a time; the time step poses every body at once with
        :meth:`PolyhedronBatch.pose` (the same arithmetic).

        Parameters
        ----------
        position : array_like, shape (3,)
            World position of the centroid, m.
        rotation : ndarray, shape (3, 3)
            Rotation matrix from body to world.
        """
        pos = np.asarray(position, dtype=float)
        rot = np.asarray(rotation, dtype=float)
        posed = self._batch.pose(pos[None, :], rot[None, :, :])
        return PlacedPolyhedron(self, pos, rot, *posed)

    @cached_property
    def _batch(self) -> PolyhedronBatch:
        """This polyhedron alone as a :class:`PolyhedronBatch` (built on first use)."""
        return PolyhedronBatch((self,))

    @classmethod
    def from_trimesh(cls, mesh: Any) -> Polyhedron:
        """A polyhedron from a watertight convex ``trimesh.Trimesh``.

        Mass properties come from trimesh (``volume``, ``center_mass``,
        ``moment_inertia`` at unit density); the body frame origin is moved to the
        centre of mass, the axes are kept.

        Raises
        ------
        ValueError
            If the mesh is not watertight or not convex.
        """
        if not all(hasattr(mesh, a) for a in ("is_watertight", "is_convex", "vertices", "center_mass")):
            raise TypeError(f"mesh == {mesh!r} ({type(mesh).__name__}), must be a trimesh.Trimesh "
                            "(e.g. trimesh.creation.box((1, 1, 1))).")
        if not mesh.is_watertight:
            raise ValueError("mesh is not watertight; a Polyhedron needs a closed convex mesh.")
        if not mesh.is_convex:
            raise ValueError("mesh is non-convex; a Polyhedron must be convex (use mesh.convex_hull).")
        points = np.asarray(mesh.vertices, dtype=float)
        hull = _hull(points, "mesh.vertices")
        return _build(
            points[hull.vertices] - np.asarray(mesh.center_mass, dtype=float),
            volume=float(mesh.volume),
            inertia_unit=np.asarray(mesh.moment_inertia, dtype=float),
        )


class PlacedPolyhedron(NamedTuple):
    """A :class:`Polyhedron` posed in the world frame (all arrays world, m).

    Attributes
    ----------
    shape : Polyhedron
        The body-frame polyhedron (for its topology).
    position : ndarray, shape (3,)
        World position of the centroid, m.
    rotation : ndarray, shape (3, 3)
        Rotation matrix from body to world.
    vertices : ndarray, shape (n, 3)
        World vertices, m.
    face_normals : ndarray, shape (f, 3)
        World outward unit face normals.
    face_offsets : ndarray, shape (f,)
        World plane offsets, m: ``face_normals[i] @ x == face_offsets[i]`` on face ``i``.
    edge_directions : ndarray, shape (u, 3)
        World unit edge directions, one per family of parallel edges.
    side_planes : ndarray, shape (s, 4)
        World side planes of the faces (rows as :attr:`Polyhedron.side_planes`).
    """

    shape: Polyhedron
    position: np.ndarray
    rotation: np.ndarray
    vertices: np.ndarray
    face_normals: np.ndarray
    face_offsets: np.ndarray
    edge_directions: np.ndarray
    side_planes: np.ndarray


class PosedBatch(NamedTuple):
    """World geometry of the bodies of a :class:`PolyhedronBatch` (rows laid out as in the batch).

    Attributes
    ----------
    vertices : ndarray, shape (V, 3)
        World vertices, m.
    face_normals : ndarray, shape (F, 3)
        World outward unit face normals.
    face_offsets : ndarray, shape (F,)
        World plane offsets, m: ``face_normals[i] @ x == face_offsets[i]`` on face ``i``.
    edge_directions : ndarray, shape (U, 3)
        World unit directions of the edge families.
    side_planes : ndarray, shape (S, 4)
        World side planes ``(sx, sy, sz, offset)`` of the faces, m.
    """

    vertices: np.ndarray
    face_normals: np.ndarray
    face_offsets: np.ndarray
    edge_directions: np.ndarray
    side_planes: np.ndarray


class PolyhedronBatch:
    """Several polyhedra laid end to end in flat arrays: posed all at once, collided in one call.

    Body ``i`` owns rows ``vertex_start[i]:vertex_start[i + 1]`` of the vertex arrays,
    and likewise ``face_start`` (faces), ``side_start[face_start[i]]`` onwards (face
    sides), ``edge_start`` (edges) and ``family_start`` (edge families). Index arrays
    hold batch-wide (global) indices: a face's vertices, an edge's ends, the faces
    around a vertex. All arrays are read-only, int64 or float64, C-contiguous.

    Parameters
    ----------
    shapes : sequence of Polyhedron
        The bodies, in order (a shape may appear several times).

    Attributes
    ----------
    shapes : tuple of Polyhedron
    vertex_start, face_start, edge_start, family_start : ndarray of int64, shape (n + 1,)
        First row of each body in the vertex, face, edge and edge-family arrays.
    radius : ndarray, shape (n,)
        Bounding radius of each body, m.
    face_vertices : ndarray of int64, shape (S,)
        The faces' vertex indices, face after face, counter-clockwise from outside.
    side_start : ndarray of int64, shape (F + 1,)
        Face ``f`` has vertices ``face_vertices[side_start[f]:side_start[f + 1]]`` and
        the side planes of the same rows.
    edges : ndarray of int64, shape (E, 2)
        Edge ends (vertex indices).
    edge_family : ndarray of int64, shape (E,)
        Edge family (row of the edge directions) of each edge.
    vertex_faces : ndarray of int64, shape (W,)
        Faces around each vertex: ``vertex_faces[vertex_face_start[v]:vertex_face_start[v + 1]]``.
    vertex_face_start : ndarray of int64, shape (V + 1,)
    """

    def __init__(self, shapes: Sequence[Polyhedron]) -> None:
        self.shapes = tuple(shapes)
        if not self.shapes:
            raise ValueError("shapes is empty, must hold at least one Polyhedron.")
        for k, shape in enumerate(self.shapes):
            if not isinstance(shape, Polyhedron):
                raise ValueError(f"shapes[{k}] is a {type(shape).__name__}, must be a Polyhedron.")

        def starts(counts: list[int]) -> np.ndarray:
            return np.concatenate(([0], np.cumsum(counts))).astype(np.int64)

        self.vertex_start = starts([len(s.vertices) for s in self.shapes])
        self.face_start = starts([len(s.faces) for s in self.shapes])
        self.edge_start = starts([len(s.edges) for s in self.shapes])
        self.family_start = starts([len(s.edge_directions) for s in self.shapes])
        side_counts = [int(s.side_start[-1]) for s in self.shapes]
        sides = starts(side_counts)
        self.radius = np.array([s.radius for s in self.shapes])
        v0 = self.vertex_start[:-1]
        self.face_vertices = np.concatenate([np.concatenate(s.faces) + v for s, v in zip(self.shapes, v0)])
        self.side_start = np.concatenate([s.side_start[:-1] + k for s, k in zip(self.shapes, sides)] + [sides[-1:]])
        self.edges = np.concatenate([s.edges + v for s, v in zip(self.shapes, v0)])
        self.edge_family = np.concatenate([s.edge_family + u for s, u in zip(self.shapes, self.family_start)])
        self.vertex_faces = np.concatenate([np.concatenate(s.vertex_faces) + f
                                            for s, f in zip(self.shapes, self.face_start)])
        around = starts([len(fs) for s in self.shapes for fs in s.vertex_faces])
        self.vertex_face_start = around
        # body-frame vectors rotated together, kind after kind: vertices, edge directions,
        # then the plane normals (faces, then sides) with their offsets; the body of each row
        kinds = [[s.vertices for s in self.shapes], [s.edge_directions for s in self.shapes],
                 [s.face_normals for s in self.shapes], [s.side_planes[:, :3] for s in self.shapes]]
        self._local = np.concatenate([np.concatenate(kind) for kind in kinds])
        self._owner = np.concatenate([np.repeat(np.arange(len(self.shapes)), [len(x) for x in kind])
                                      for kind in kinds])
        self._plane_offsets = np.concatenate([s.face_offsets for s in self.shapes]
                                             + [s.side_planes[:, 3] for s in self.shapes])
        for name, value in list(vars(self).items()):
            if isinstance(value, np.ndarray):
                value = np.ascontiguousarray(value, dtype=np.int64 if value.dtype.kind == "i" else float)
                value.setflags(write=False)
                setattr(self, name, value)

    def __len__(self) -> int:
        return len(self.shapes)

    def pose(self, positions: np.ndarray, rotations: np.ndarray) -> PosedBatch:
        """World geometry of every body at once.

        Parameters
        ----------
        positions : ndarray, shape (n, 3)
            World positions of the centroids, m.
        rotations : ndarray, shape (n, 3, 3)
            Rotation matrices from body to world.

        Returns
        -------
        PosedBatch
            ``x_world = R x_body + p`` for vertices, ``R n`` for normals and directions,
            ``offset + (R n) . p`` for plane offsets.
        """
        positions = np.asarray(positions, dtype=float)
        rotations = np.asarray(rotations, dtype=float)
        n = len(self.shapes)
        if positions.shape != (n, 3) or rotations.shape != (n, 3, 3):
            raise ValueError(f"positions and rotations have shapes {positions.shape} and {rotations.shape}, "
                             f"must be ({n}, 3) and ({n}, 3, 3) for this batch of {n} bodies.")
        vertices, face_normals, face_offsets, edge_directions, side_planes = pose_rows(
            np.ascontiguousarray(rotations), np.ascontiguousarray(positions), self._local, self._owner,
            self._plane_offsets, self.vertex_start[-1], self.family_start[-1], self.face_start[-1])
        return PosedBatch(vertices=vertices, face_normals=face_normals, face_offsets=face_offsets,
                          edge_directions=edge_directions, side_planes=side_planes)


@njit
def pose_rows(rotations, positions, local, owner, plane_offsets, n_vertices, n_families, n_faces):
    """Kernel of :meth:`PolyhedronBatch.pose`, returning the fields of :class:`PosedBatch`.

    The body-frame rows ``local`` (vertices, edge directions, face normals, side normals;
    the body of each row ``owner``) rotated by ``rotations[owner]`` (n, 3, 3); vertices
    moved by ``positions[owner]`` (n, 3), m; plane offsets ``plane_offsets + (R n) . p``.
    """
    planes = n_vertices + n_families
    vertices = np.empty((n_vertices, 3))
    directions = np.empty((n_families, 3))
    normals = np.empty((n_faces, 3))
    offsets = np.empty(n_faces)
    sides = np.empty((local.shape[0] - planes - n_faces, 4))
    for r in range(local.shape[0]):
        o = owner[r]
        x, y, z = local[r, 0], local[r, 1], local[r, 2]
        w0 = rotations[o, 0, 0] * x + rotations[o, 0, 1] * y + rotations[o, 0, 2] * z
        w1 = rotations[o, 1, 0] * x + rotations[o, 1, 1] * y + rotations[o, 1, 2] * z
        w2 = rotations[o, 2, 0] * x + rotations[o, 2, 1] * y + rotations[o, 2, 2] * z
        p0, p1, p2 = positions[o, 0], positions[o, 1], positions[o, 2]
        if r < n_vertices:
            vertices[r, 0], vertices[r, 1], vertices[r, 2] = w0 + p0, w1 + p1, w2 + p2
        elif r < planes:
            k = r - n_vertices
            directions[k, 0], directions[k, 1], directions[k, 2] = w0, w1, w2
        else:
            offset = plane_offsets[r - planes] + (w0 * p0 + w1 * p1 + w2 * p2)
            k = r - planes
            if k < n_faces:
                normals[k, 0], normals[k, 1], normals[k, 2] = w0, w1, w2
                offsets[k] = offset
            else:
                k -= n_faces
                sides[k, 0], sides[k, 1], sides[k, 2], sides[k, 3] = w0, w1, w2, offset
    return vertices, normals, offsets, directions, sides


def polyhedron(vertices: Sequence[Sequence[float]]) -> Polyhedron:
    """A convex polyhedron from its vertices.

    Parameters
    ----------
    vertices : array_like, shape (n, 3)
        Vertex coordinates in m, n >= 4, in any order; every point must be a vertex of
        the convex hull. The body frame origin becomes the centroid.

    Raises
    ------
    ValueError
        For fewer than 4 points, non-finite or coincident points, a flat (coplanar or
        collinear) point set, or points that are not hull vertices (non-convex input).
    """
    points = np.asarray(vertices, dtype=float)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"vertices has shape {points.shape}, must be (n, 3).")
    hull = _hull(points, "vertices")
    if len(hull.vertices) < len(points):
        inside = np.setdiff1d(np.arange(len(points)), hull.vertices)
        raise ValueError(
            f"vertices are non-convex: {len(inside)} of {len(points)} points lie inside the "
            f"convex hull of the others (or on its faces), indices {inside.tolist()}; "
            "give only the hull vertices of a convex body."
        )
    volume, centroid, inertia = _mass_properties(points, hull)
    return _build(points[hull.vertices] - centroid, volume=volume, inertia_unit=inertia)


def box3(wx: float, wy: float, wz: float) -> Polyhedron:
    """A cuboid with full side lengths ``wx``, ``wy``, ``wz`` in m, centred, axis-aligned."""
    for label, value in (("wx", wx), ("wy", wy), ("wz", wz)):
        if not np.isfinite(value) or value <= 0.0:
            raise ValueError(f"box {label} == {value}, must be > 0 m.")
    half = np.array([wx, wy, wz], dtype=float) / 2.0
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return polyhedron(corners * half)


def chamfered_box(wx: float, wy: float, wz: float, chamfer: float) -> Polyhedron:
    """A cuboid whose four base edges are cut at 45 degrees (a convex polyhedron).

    Parameters
    ----------
    wx, wy, wz : float
        Full side lengths in m of the uncut box, axis-aligned, z up.
    chamfer : float
        Leg in m of the 45-degree cut along each bottom edge, ``0 < chamfer <
        min(wx, wy) / 2`` and ``chamfer < wz``: the base face is the
        ``(wx - 2 chamfer) x (wy - 2 chamfer)`` rectangle and the sides start ``chamfer``
        above it.

    Notes
    -----
    12 vertices and 10 faces. The body origin is the centroid, which lies above the
    centre of the uncut box (the cut removes material at the base): the base face is
    at ``z = vertices[:, 2].min()``, not at ``-wz / 2``.
    """
    for label, value in (("wx", wx), ("wy", wy), ("wz", wz)):
        if not np.isfinite(value) or value <= 0.0:
            raise ValueError(f"box {label} == {value}, must be > 0 m.")
    limit = min(wx / 2.0, wy / 2.0, wz)
    if not (np.isfinite(chamfer) and 0.0 < chamfer < limit):
        raise ValueError(f"chamfer == {chamfer}, must be in (0, {limit:g}) m for a {wx} x {wy} x {wz} m box.")
    a, b, h = wx / 2.0, wy / 2.0, wz / 2.0
    corners = [(sx, sy) for sx in (-1, 1) for sy in (-1, 1)]
    return polyhedron(
        [(sx * a, sy * b, h) for sx, sy in corners]
        + [(sx * a, sy * b, chamfer - h) for sx, sy in corners]
        + [(sx * (a - chamfer), sy * (b - chamfer), -h) for sx, sy in corners]
    )


def _hull(points: np.ndarray, label: str) -> ConvexHull:
    """Convex hull of ``points`` (n, 3), checking the point set is a proper solid."""
    n = len(points)
    if n < 4:
        raise ValueError(f"{label} has {n} points, must have at least 4 (a polyhedron needs volume).")
    if not np.all(np.isfinite(points)):
        raise ValueError(f"{label} contains non-finite coordinates.")
    centred = points - points.mean(axis=0)
    scale = float(np.max(np.linalg.norm(centred, axis=1)))
    dist = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2)
    i, j = np.nonzero(np.triu(dist <= _REL_TOL * scale, k=1))
    if len(i) or scale == 0.0:
        a, b = (int(i[0]), int(j[0])) if len(i) else (0, 1)
        raise ValueError(f"{label}[{a}] and {label}[{b}] coincide; points must be distinct.")
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv[2] <= _REL_TOL * sv[0]:
        kind = "collinear" if sv[1] <= _REL_TOL * sv[0] else "coplanar"
        raise ValueError(f"{label} are {kind} (flat, zero volume); a polyhedron needs volume.")
    try:
        return ConvexHull(points)
    except QhullError as err:  # degenerate beyond the checks above
        raise ValueError(f"{label} do not span a convex hull: {err}") from err


def _mass_properties(points: np.ndarray, hull: ConvexHull) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume (m^3), centroid (3,) and unit-density inertia about the centroid (3, 3).

    Sums the signed tetrahedra (apex at a point inside) over the hull triangles, with
    the second-moment (covariance) tensor of a tetrahedron with one vertex at the origin
    ``C = det(A) / 120 * A S A^T``, ``A = [a b c]``, ``S = 1 + I``
    (Tonon, J. Math. Stat. 1(1), 2005).
    """
    apex = points[hull.vertices].mean(axis=0)
    tri = points[hull.simplices] - apex                    # (t, 3 vertices, 3 coords)
    # orient each triangle outward (qhull does not guarantee the winding)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    flip = np.einsum("ij,ij->i", normal, hull.equations[:, :3]) < 0.0
    tri[flip] = tri[flip][:, ::-1]
    det = np.linalg.det(tri)                               # 6 x signed volume
    volume = float(det.sum() / 6.0)
    centroid_rel = (det[:, None] * tri.sum(axis=1)).sum(axis=0) / (24.0 * volume)
    s = np.ones((3, 3)) + np.eye(3)
    cov = np.einsum("t,tai,ab,tbj->ij", det, tri, s, tri) / 120.0   # about the apex
    cov -= volume * np.outer(centroid_rel, centroid_rel)           # about the centroid
    inertia = np.trace(cov) * np.eye(3) - cov
    return volume, apex + centroid_rel, inertia


def _build(vertices: np.ndarray, volume: float, inertia_unit: np.ndarray) -> Polyhedron:
    """Assemble the topology of the convex polyhedron with these hull ``vertices``."""
    hull = ConvexHull(vertices)
    scale = float(np.max(np.linalg.norm(vertices, axis=1)))
    faces, normals, offsets = _merge_coplanar(vertices, hull, _REL_TOL * scale)
    edge_set = {
        (min(a, b), max(a, b))
        for face in faces
        for a, b in zip(face.tolist(), np.roll(face, -1).tolist())
    }
    edges = np.array(sorted(edge_set), dtype=int)
    # bounds of the contact feature-id fields (nscd.contact.detect3d)
    largest = max(len(face) for face in faces)
    if len(faces) > _MAX_FACES or largest > _MAX_FACE_VERTICES:
        raise ValueError(
            f"polyhedron has {len(faces)} faces of up to {largest} vertices, must have at most "
            f"{_MAX_FACES} faces of at most {_MAX_FACE_VERTICES} vertices; simplify the mesh."
        )
    directions, family = _edge_families(vertices, edges)
    side_planes = np.concatenate([_side_planes(vertices[face], n) for face, n in zip(faces, normals)])
    side_start = np.cumsum([0] + [len(face) for face in faces])
    around: list[list[int]] = [[] for _ in vertices]
    for f, face in enumerate(faces):
        for v in face.tolist():
            around[v].append(f)
    vertex_faces = tuple(np.array(fs, dtype=int) for fs in around)
    arrays = dict(
        vertices=vertices, face_normals=normals, face_offsets=offsets, edges=edges,
        side_planes=side_planes, side_start=side_start,
        edge_directions=directions, edge_family=family,
        inertia_unit=0.5 * (inertia_unit + inertia_unit.T),
        half_extents=np.max(np.abs(vertices), axis=0),
    )
    for value in (*arrays.values(), *faces, *vertex_faces):
        value.setflags(write=False)
    return Polyhedron(faces=faces, vertex_faces=vertex_faces, volume=volume, radius=scale,
                      **arrays)


def _side_planes(polygon: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Outward side planes (m, 4) ``(sx, sy, sz, offset)`` of a CCW face ``polygon`` (m, 3)."""
    side = np.cross(np.roll(polygon, -1, axis=0) - polygon, normal)
    side /= np.linalg.norm(side, axis=1)[:, None]
    return np.column_stack([side, np.einsum("ij,ij->i", side, polygon)])


def _merge_coplanar(
    vertices: np.ndarray, hull: ConvexHull, tol: float
) -> tuple[tuple[np.ndarray, ...], np.ndarray, np.ndarray]:
    """Group hull triangles by plane; each group becomes one CCW polygon face."""
    planes = hull.equations                                # (t, 4): n . x + c = 0, n outward
    faces, normals, offsets = [], [], []
    unused = np.ones(len(planes), dtype=bool)
    for t in range(len(planes)):
        if not unused[t]:
            continue
        # triangles whose vertices all lie on plane t belong to the same face
        on_plane = np.abs(vertices[hull.simplices] @ planes[t, :3] + planes[t, 3]) <= tol
        members = unused & on_plane.all(axis=1)
        unused &= ~members
        idx = np.unique(hull.simplices[members])
        normal = planes[t, :3] / np.linalg.norm(planes[t, :3])
        faces.append(_ccw(vertices, idx, normal))
        normals.append(normal)
        offsets.append(float(np.mean(vertices[idx] @ normal)))
    return tuple(faces), np.array(normals), np.array(offsets)


def _ccw(vertices: np.ndarray, idx: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Sort the vertex indices ``idx`` of a planar convex face CCW about ``normal``."""
    pts = vertices[idx]
    centre = pts.mean(axis=0)
    u = pts[0] - centre
    u /= np.linalg.norm(u)
    w = np.cross(normal, u)
    rel = pts - centre
    order = np.argsort(np.arctan2(rel @ w, rel @ u))
    return idx[order].astype(int)


def _edge_families(vertices: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions (u, 3) of the families of parallel edges and each edge's family."""
    d = vertices[edges[:, 1]] - vertices[edges[:, 0]]
    d /= np.linalg.norm(d, axis=1)[:, None]
    directions = np.empty_like(d)
    count = 0
    family = np.empty(len(edges), dtype=int)
    for k, dk in enumerate(d):
        sines = np.linalg.norm(np.cross(directions[:count], dk), axis=1)
        match = np.flatnonzero(sines <= _PARALLEL_SIN)
        if len(match):
            family[k] = match[0]
        else:
            family[k] = count
            directions[count] = dk
            count += 1
    return directions[:count].copy(), family
