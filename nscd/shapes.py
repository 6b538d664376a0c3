"""Rigid convex shapes in 2D: polygons and their mass properties.

A :class:`Polygon` stores its vertices counter-clockwise about its centroid, so the
body frame origin is the centre of mass. Mass properties follow from the geometry
and a density (kg/m^3 per unit depth in 2D: a 2D body is a prism of unit depth, so
``mass = density * area`` in kg, ``inertia = density * polar second moment`` in kg m^2).

3D polyhedra live in :mod:`nscd.shapes3d`; :func:`box` dispatches on its number of
arguments.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Sequence

import numpy as np

#: Relative tolerance for collinearity / degeneracy tests, scaled by the polygon size.
_REL_TOL = 1e-10


@dataclass(frozen=True, eq=False)
class Polygon:
    """A rigid convex polygon in its body frame (origin at the centroid).

    Attributes
    ----------
    vertices : ndarray, shape (n, 2)
        Vertices in m, counter-clockwise, relative to the centroid.
    area : float
        Area in m^2.
    polar_moment : float
        Polar second moment of area about the centroid, m^4
        (inertia per unit density and unit depth).
    radius : float
        Bounding radius about the centroid, m.
    """

    vertices: np.ndarray
    area: float
    polar_moment: float
    radius: float
    dim: int = 2

    def mass(self, density: float) -> float:
        """Mass in kg of a unit-depth prism of this section at ``density`` (kg/m^3)."""
        return density * self.area

    def inertia(self, density: float) -> float:
        """Moment of inertia about the centroid, kg m^2 (unit depth)."""
        return density * self.polar_moment

    @property
    def width(self) -> float:
        """Extent along the body x axis, m."""
        return float(np.ptp(self.vertices[:, 0]))

    @property
    def height(self) -> float:
        """Extent along the body y axis, m."""
        return float(np.ptp(self.vertices[:, 1]))

    @property
    def thickness(self) -> float:
        """Smallest width, m: the least extent of the polygon along its edge normals (the
        width of a convex polygon is smallest across one of its edges)."""
        edges = np.roll(self.vertices, -1, axis=0) - self.vertices
        normals = np.column_stack([edges[:, 1], -edges[:, 0]]) / np.linalg.norm(edges, axis=1)[:, None]
        return float(np.min(np.ptp(self.vertices @ normals.T, axis=0)))

    def world_vertices(self, position: Sequence[float], angle: float) -> np.ndarray:
        """Vertices in the world frame for a body at ``position`` (m) and ``angle`` (rad, CCW)."""
        c, s = np.cos(angle), np.sin(angle)
        rot = np.array([[c, -s], [s, c]])
        return self.vertices @ rot.T + np.asarray(position, dtype=float)


def _signed_area_terms(v: np.ndarray) -> np.ndarray:
    nxt = np.roll(v, -1, axis=0)
    return v[:, 0] * nxt[:, 1] - nxt[:, 0] * v[:, 1]


def _segments_intersect(p1, p2, p3, p4) -> bool:
    """Proper intersection of segments p1p2 and p3p4 (shared endpoints excluded)."""
    def orient(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    d1, d2 = orient(p3, p4, p1), orient(p3, p4, p2)
    d3, d4 = orient(p1, p2, p3), orient(p1, p2, p4)
    return (d1 * d2 < 0) and (d3 * d4 < 0)


def polygon(vertices: Sequence[Sequence[float]], name: str = "polygon") -> Polygon:
    """Build a convex polygon from its vertices.

    Parameters
    ----------
    vertices : array_like, shape (n, 2)
        Vertices in m, in counter-clockwise or clockwise order (a simple polygon,
        not self-intersecting). The polygon is re-centred on its centroid.
    name : str
        Used in error messages.

    Raises
    ------
    ValueError
        Fewer than 3 vertices, non-finite values, repeated vertices, zero area,
        collinear consecutive vertices, a self-intersecting order, or a non-convex
        polygon — the message says which.
    """
    v = np.asarray(vertices, dtype=float)
    if v.ndim != 2 or v.shape[1] != 2:
        raise ValueError(f"{name}: vertices must have shape (n, 2), got {v.shape}.")
    n = len(v)
    if n < 3:
        raise ValueError(f"{name}: a polygon needs at least 3 vertices, got {n}.")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"{name}: vertices contain NaN or inf.")
    size = float(np.max(np.ptp(v, axis=0)))
    if size <= 0.0:
        raise ValueError(f"{name}: all vertices coincide (zero area).")
    edges = np.roll(v, -1, axis=0) - v
    if np.any(np.linalg.norm(edges, axis=1) <= _REL_TOL * size):
        raise ValueError(f"{name}: repeated consecutive vertices (zero-length edge).")
    for i in range(n):
        for j in range(i + 2, n):
            if i == 0 and j == n - 1:
                continue
            if _segments_intersect(v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]):
                raise ValueError(
                    f"{name}: self-intersecting polygon (edges {i} and {j} cross)."
                )
    area2 = float(np.sum(_signed_area_terms(v)))
    if abs(area2) <= _REL_TOL * size * size:
        raise ValueError(f"{name}: zero area (vertices collinear).")
    if area2 < 0.0:
        v = v[::-1].copy()
        edges = np.roll(v, -1, axis=0) - v
    cross = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(edges, -1, axis=0)[:, 0]
    tol = _REL_TOL * size * size
    if np.any(cross < -tol):
        bad = int(np.argmin(cross))
        raise ValueError(f"{name}: non-convex polygon (reflex vertex {(bad + 1) % n}).")
    if np.any(np.abs(cross) <= tol):
        bad = int(np.argmin(np.abs(cross)))
        raise ValueError(
            f"{name}: collinear consecutive edges at vertex {(bad + 1) % n}; remove it."
        )
    terms = _signed_area_terms(v)
    area = 0.5 * float(np.sum(terms))
    nxt = np.roll(v, -1, axis=0)
    centroid = np.sum((v + nxt) * terms[:, None], axis=0) / (6.0 * area)
    v = v - centroid
    nxt = np.roll(v, -1, axis=0)
    terms = _signed_area_terms(v)
    # Polar second moment about the origin (= centroid): sum over triangle fans.
    jz = float(np.sum(terms * (v[:, 0] ** 2 + v[:, 0] * nxt[:, 0] + nxt[:, 0] ** 2
                               + v[:, 1] ** 2 + v[:, 1] * nxt[:, 1] + nxt[:, 1] ** 2)) / 12.0)
    radius = float(np.max(np.linalg.norm(v, axis=1)))
    v.setflags(write=False)
    return Polygon(vertices=v, area=area, polar_moment=jz, radius=radius)


def box(*sides: float):
    """A rectangle ``box(width, height)`` (2D) or a cuboid ``box(wx, wy, wz)`` (3D).

    Sides are full lengths in m, centred on the origin and aligned with the body axes.
    """
    if len(sides) == 3:
        from nscd.shapes3d import box3

        return box3(*sides)
    if len(sides) != 2:
        raise ValueError(f"box takes 2 (2D) or 3 (3D) side lengths, got {len(sides)}.")
    w, h = (float(s) for s in sides)
    for label, value in (("width", w), ("height", h)):
        if not np.isfinite(value) or value <= 0.0:
            raise ValueError(f"box {label} == {value}, must be > 0 m.")
    return _rectangle(w, h)


@functools.lru_cache(maxsize=1024)
def _rectangle(w: float, h: float) -> Polygon:
    """The rectangle of :func:`box` (sides checked). Built once per pair of sides: a
    :class:`Polygon` is immutable (frozen, read-only vertices), so the scenes of a sweep or a
    batch, which build the same blocks cell after cell, share it."""
    return polygon([(-w / 2, -h / 2), (w / 2, -h / 2), (w / 2, h / 2), (-w / 2, h / 2)], name="box")


def regular_polygon(n: int, radius: float) -> Polygon:
    """A regular polygon with ``n`` >= 3 vertices on a circle of ``radius`` m (a vertex on +x)."""
    if int(n) != n or n < 3:
        raise ValueError(f"regular_polygon n == {n}, must be an integer >= 3.")
    if not np.isfinite(radius) or radius <= 0.0:
        raise ValueError(f"regular_polygon radius == {radius}, must be > 0 m.")
    a = 2.0 * np.pi * np.arange(int(n)) / n
    return polygon(np.column_stack([radius * np.cos(a), radius * np.sin(a)]), name="regular_polygon")
