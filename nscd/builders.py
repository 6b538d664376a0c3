"""Scene builders: ready-made block assemblies on a base (stacks, running-bond walls, arches).

One idea: turn a few dimensions into a :class:`nscd.Scene` with the blocks already
placed in contact, so that a user (or a benchmark) does not compute coordinates by hand.
Every builder puts its supports (a base whose top face is at y = 0, or the two springers
of an arch), fixed or driven by ``motion``, lays the blocks on them without gaps or
overlaps, sets one contact law for every pair, and returns the scene with the block
handles, bottom course first.

Coordinates: 2D x horizontal, y up; 3D (walls with a ``depth``, columns, colonnades)
x along the assembly, y across it, z up; m. The assembly is centred on x = 0 (and y = 0).
"""
from __future__ import annotations

import math
from numbers import Integral, Real

import numpy as np

from nscd.motion import Motion
from nscd.scene import Body, Scene
from nscd.shapes import Polygon, box, polygon
from nscd.shapes3d import Polyhedron, polyhedron

__all__ = ["arch", "colonnade", "column", "drum", "stack", "tilted_block", "wall"]

#: The base overhangs the assembly by this fraction of the assembly's width on each side.
BASE_OVERHANG = 0.25


def _positive_int(value: object, label: str, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, Integral) or value < low:
        raise ValueError(f"{label} == {value!r}, must be an integer >= {low}.")
    return int(value)


def _positive_length(value: object, label: str, unit: str = "m") -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not (math.isfinite(value) and value > 0.0):
        raise ValueError(f"{label} == {value!r}, must be a finite number > 0 {unit}.")
    return float(value)


def _friction(value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f"friction == {value!r}, must be a finite number >= 0.")
    return float(value)


def _density(value: object) -> float:
    return _positive_length(value, "density", unit="kg/m^3")


def _centroid(corners: np.ndarray, shape: Polygon) -> np.ndarray:
    """World position (m) of ``shape`` = ``polygon(corners)``, which holds ``corners`` about their centroid."""
    return np.mean(corners, axis=0) - np.mean(shape.vertices, axis=0)


def _base_scene(width: float, friction: float, motion: Motion | None, base_height: float | None,
                depth: float | None = None) -> Scene:
    """A scene with a base whose top face is at height 0, overhanging by ``BASE_OVERHANG * width``.

    2D (``depth`` None): a ``(1 + 2 BASE_OVERHANG) width`` wide base, top at y = 0. 3D: a
    ``Scene(dim=3)`` whose base is as wide along x and ``depth + 2 BASE_OVERHANG width``
    deep along y, top at z = 0.
    """
    height = 0.1 * width if base_height is None else _positive_length(base_height, "base_height")
    along = (1.0 + 2.0 * BASE_OVERHANG) * width
    if depth is None:
        scene = Scene()
        scene.add_base(box(along, height), position=(0.0, -0.5 * height), motion=motion, name="base")
    else:
        scene = Scene(dim=3)
        scene.add_base(box(along, depth + 2.0 * BASE_OVERHANG * width, height),
                       position=(0.0, 0.0, -0.5 * height), motion=motion, name="base")
    scene.set_contact(friction=friction, restitution=0.0)
    return scene


def tilted_block(width: float, height: float, theta0: float, friction: float = 0.8,
                 density: float = 2500.0) -> tuple[Scene, Body]:
    """A rectangular block resting on its right bottom corner, turned clockwise by ``theta0``,
    on a fixed base: the free-rocking release of Housner's problem.

    Parameters
    ----------
    width, height : float
        Size of the block, m (> 0); its half-sizes are ``b, h``.
    theta0 : float
        Release angle, rad (>= 0): the block is turned by ``-theta0`` about its corner
        ``(b, 0)``, which touches the base's top face ``y = 0``.
    friction : float
        Coulomb coefficient of the block-base contact (>= 0); restitution is 0.
    density : float
        kg/m^3 (> 0), unit depth.

    Returns
    -------
    scene : Scene
        The base is a 0.2 m thick slab, ``max(3, 4 width)`` m wide, its top face at ``y = 0``.
    block : Body

    Examples
    --------
    >>> scene, block = tilted_block(0.5, 1.5, 0.1)
    >>> round(float(block.q0[2]), 3)
    -0.1
    """
    width = _positive_length(width, "width")
    height = _positive_length(height, "height")
    if not (isinstance(theta0, Real) and math.isfinite(theta0) and theta0 >= 0.0):
        raise ValueError(f"theta0 == {theta0!r}, must be a finite angle >= 0 rad")
    b, h = width / 2, height / 2
    c, s = math.cos(-theta0), math.sin(-theta0)
    scene = Scene()
    scene.add_base(box(max(3.0, 4 * width), 0.2), position=(0.0, -0.1))
    # the corner (b, 0) stays where it is while the body turns by -theta0 about its centre
    block = scene.add_block(box(width, height), position=(b - c * b - s * h, -s * b + c * h), angle=-theta0,
                            density=_density(density))
    scene.set_contact(friction=_friction(friction), restitution=0.0)
    return scene, block


def stack(n: int, width: float, height: float, density: float = 2500.0, friction: float = 0.7,
          motion: Motion | None = None, base_height: float | None = None) -> tuple[Scene, list[Body]]:
    """A column of ``n`` identical blocks resting on a base.

    Parameters
    ----------
    n : int
        Number of blocks, >= 1.
    width, height : float
        Size of each block, m (> 0).
    density : float
        kg/m^3 (> 0), unit depth.
    friction : float
        Coulomb coefficient of every contact (>= 0); restitution is 0.
    motion : Motion, optional
        Horizontal motion of the base; None: a fixed base.
    base_height : float, optional
        Thickness of the base, m; default a tenth of its width.

    Returns
    -------
    scene : Scene
    blocks : list of Body
        Bottom block first; block ``k`` has its centre at ``(0, (k + 1/2) height)``.

    Examples
    --------
    >>> scene, blocks = stack(3, width=0.4, height=1.0)
    >>> len(blocks), float(blocks[-1].q0[1])
    (3, 2.5)
    """
    n = _positive_int(n, "n")
    width = _positive_length(width, "width")
    height = _positive_length(height, "height")
    scene = _base_scene(width, _friction(friction), motion, base_height)
    shape = box(width, height)
    blocks = [scene.add_block(shape, position=(0.0, (k + 0.5) * height), density=density)
              for k in range(n)]
    return scene, blocks


def wall(n_courses: int, n_per_course: int, block_width: float, block_height: float,
         density: float = 2500.0, friction: float = 0.7, motion: Motion | None = None,
         base_height: float | None = None, depth: float | None = None) -> tuple[Scene, list[list[Body]]]:
    """A running-bond wall: courses of blocks, every other course offset by half a block.

    Even courses (0, 2, ...; course 0 on the base) hold ``n_per_course`` whole blocks.
    Odd courses are shifted by half a block: ``n_per_course - 1`` whole blocks between
    two half blocks (``block_width / 2`` wide) at the ends, so both ends are flush and
    every vertical joint sits over the middle of a block below. The wall is
    ``n_per_course * block_width`` wide and ``n_courses * block_height`` high, centred
    on x = 0, standing on a base whose top is at y = 0. It has
    ``n_courses * n_per_course + n_courses // 2`` blocks. With a ``depth`` the same wall
    is built in 3D (``Scene(dim=3)``): blocks are boxes ``block_width x depth x
    block_height`` centred on y = 0, standing on a base whose top is at z = 0, and the
    base's ``motion`` acts along x (in the plane of the wall).

    Parameters
    ----------
    n_courses : int
        Number of courses (rows), >= 1.
    n_per_course : int
        Whole blocks in an even course, >= 1 (with 1, odd courses are two half blocks).
    block_width, block_height : float
        Size of a whole block, m (> 0).
    density : float
        kg/m^3 (> 0), unit depth.
    friction : float
        Coulomb coefficient of every contact (>= 0); restitution is 0.
    motion : Motion, optional
        Horizontal motion of the base; None: a fixed base.
    base_height : float, optional
        Thickness of the base, m; default a tenth of its width.
    depth : float, optional
        Thickness of the wall across its plane (along y), m (> 0): a 3D wall. None: 2D
        (blocks of unit depth).

    Returns
    -------
    scene : Scene
    blocks : list of list of Body
        One list per course, bottom course first, blocks from left to right.

    Examples
    --------
    >>> scene, courses = wall(3, 4, block_width=0.4, block_height=0.2)
    >>> [len(c) for c in courses]
    [4, 5, 4]
    """
    n_courses = _positive_int(n_courses, "n_courses")
    n_per_course = _positive_int(n_per_course, "n_per_course")
    bw = _positive_length(block_width, "block_width")
    bh = _positive_length(block_height, "block_height")
    total = n_per_course * bw
    if depth is not None:
        depth = _positive_length(depth, "depth")
    scene = _base_scene(total, _friction(friction), motion, base_height, depth)
    if depth is None:
        whole, half = box(bw, bh), box(0.5 * bw, bh)
    else:
        whole, half = box(bw, depth, bh), box(0.5 * bw, depth, bh)
    left = -0.5 * total
    courses = []
    for row in range(n_courses):
        y = (row + 0.5) * bh
        if row % 2 == 0:
            placed = [(whole, left + (k + 0.5) * bw) for k in range(n_per_course)]
        else:
            placed = ([(half, left + 0.25 * bw)]
                      + [(whole, left + (k + 1.0) * bw) for k in range(n_per_course - 1)]
                      + [(half, left + total - 0.25 * bw)])
        courses.append([scene.add_block(shape, position=(x, y) if depth is None else (x, 0.0, y),
                                        density=density) for shape, x in placed])
    return scene, courses


def arch(radius: float, thickness: float, n_voussoirs: int, friction: float = 0.8,
         density: float = 2000.0, angle: float = math.pi,
         motion: Motion | None = None) -> tuple[Scene, list[Body]]:
    """A circular arch of ``n_voussoirs`` equal voussoirs with radial joints on two springers.

    The arch is the ring between the intrados radius ``radius - thickness / 2`` and the
    extrados radius ``radius + thickness / 2`` about the centre (0, 0), over the angles
    ``pi/2 - angle/2 .. pi/2 + angle/2`` (symmetric about the y axis; ``angle = pi``:
    semicircular, springings on y = 0). It is cut by ``n_voussoirs + 1`` radial joints
    into equal voussoirs; each voussoir is the convex quadrilateral of its joint corners
    (intrados and extrados are chords, so a voussoir's area is
    ``radius * thickness * sin(angle / n)``, slightly less than the annular sector's
    ``radius * thickness * angle / n``). The two springers are
    rectangles of the arch's thickness continuing the ring straight past each springing
    joint (tangent to the centreline there); they are fixed, or both driven by ``motion``.
    Every joint is closed at the start (shared corners, no gap, no overlap).

    Parameters
    ----------
    radius : float
        Radius of the centreline (the circle midway between intrados and extrados), m (> 0).
        Limit-analysis results quoted as ``t / R`` (Heyman) use this radius.
    thickness : float
        Radial thickness of the ring, m, in ``(0, radius)``: the intrados radius
        ``radius - thickness / 2`` stays above ``radius / 2`` (a thicker ring is a
        perforated solid rather than an arch).
    n_voussoirs : int
        Number of voussoirs, >= 2.
    friction : float
        Coulomb coefficient of every joint (>= 0); restitution is 0.
    density : float
        kg/m^3 (> 0), unit depth.
    angle : float
        Embrace (angle subtended by the arch at the centre), rad, in (0, 2 pi); default pi.
    motion : Motion, optional
        Horizontal motion of both springers; None: fixed springers.

    Returns
    -------
    scene : Scene
        Bodies: the springers ``"springer_left"`` and ``"springer_right"``, then the voussoirs.
    voussoirs : list of Body
        From the left springing (x < 0) to the right one.

    Examples
    --------
    >>> scene, voussoirs = arch(radius=1.0, thickness=0.15, n_voussoirs=9)
    >>> len(voussoirs), round(float(voussoirs[4].q0[0]), 12)
    (9, 0.0)
    """
    radius = _positive_length(radius, "radius")
    thickness = _positive_length(thickness, "thickness")
    if not thickness < radius:
        raise ValueError(f"thickness == {thickness!r}, must be in (0, radius) = (0, {radius!r}) m "
                         "(radius is the centreline radius).")
    n = _positive_int(n_voussoirs, "n_voussoirs", low=2)
    if isinstance(angle, bool) or not isinstance(angle, Real) or not (
            math.isfinite(angle) and 0.0 < angle < 2.0 * math.pi):
        raise ValueError(f"angle == {angle!r}, must be in (0, 2 pi) = (0, {2.0 * math.pi:.6f}) rad.")
    friction = _friction(friction)
    density = _density(density)
    inner, outer = radius - 0.5 * thickness, radius + 0.5 * thickness
    # Joint k at polar angle phi_k, from the left springing (phi_0 = pi/2 + angle/2) down to the right.
    phi = 0.5 * math.pi + 0.5 * angle - angle * np.arange(n + 1) / n
    joint_in = inner * np.column_stack([np.cos(phi), np.sin(phi)])
    joint_out = outer * np.column_stack([np.cos(phi), np.sin(phi)])
    scene = Scene()
    # Springers: rectangles thickness x length past the springing joints, along the tangent
    # that leaves the arch. Two springers subtend at most 2 atan(length / inner) at the centre;
    # for embraces near 2 pi the gap 2 pi - angle at the bottom bounds their length.
    length = thickness
    if angle > math.pi:
        length = min(length, 0.5 * inner * math.tan(0.5 * (2.0 * math.pi - angle)))
    for label, k, sign in (("springer_left", 0, 1.0), ("springer_right", n, -1.0)):
        away = sign * np.array([-math.sin(phi[k]), math.cos(phi[k])])  # leaves the arch
        corners = [joint_in[k], joint_out[k], joint_out[k] + length * away, joint_in[k] + length * away]
        shape = polygon(corners, name=label)
        scene.add_base(shape, position=_centroid(corners, shape), motion=motion, name=label)
    scene.set_contact(friction=friction, restitution=0.0)
    voussoirs = []
    for k in range(n):
        corners = np.array([joint_in[k], joint_out[k], joint_out[k + 1], joint_in[k + 1]])
        shape = polygon(corners, name=f"voussoir{k}")
        voussoirs.append(scene.add_block(shape, position=_centroid(corners, shape), density=density,
                                         name=f"voussoir{k}"))
    return scene, voussoirs


def drum(radius: float, height: float, n_sides: int = 16) -> Polyhedron:
    """A drum: a right prism on a regular polygon, the polyhedral approximation of a cylinder.

    The ``n_sides`` vertices of each end face lie on the circle of ``radius`` (the
    polygon is inscribed), at polar angles ``(k + 1/2) 2 pi / n_sides``, so that a side
    face is normal to +x (for ``n_sides`` = 4: an axis-aligned box). Its volume is the
    polygon's area ``(n / 2) r^2 sin(2 pi / n)`` times ``height``, below the cylinder's
    ``pi r^2 h`` by the relative amount ``1 - sin(2 pi / n) / (2 pi / n)`` (2.6 % for
    16 sides, 0.16 % for 64). Axis along z, origin at the centroid.

    Parameters
    ----------
    radius : float
        Circumradius of the polygon, m (> 0).
    height : float
        m (> 0).
    n_sides : int
        >= 3.
    """
    radius = _positive_length(radius, "radius")
    height = _positive_length(height, "height")
    n = _positive_int(n_sides, "n_sides", low=3)
    phi = 2.0 * np.pi * (np.arange(n) + 0.5) / n
    ring = np.column_stack([radius * np.cos(phi), radius * np.sin(phi)])
    return polyhedron(np.vstack([np.column_stack([ring, np.full(n, z)]) for z in (-0.5 * height, 0.5 * height)]))


def _column_args(n_drums, radius, drum_height, n_sides, density):
    return (_positive_int(n_drums, "n_drums"), _positive_length(radius, "radius"),
            _positive_length(drum_height, "drum_height"), _positive_int(n_sides, "n_sides", low=3),
            _density(density))


def column(n_drums: int, radius: float, drum_height: float, n_sides: int = 16,
           density: float = 2500.0, friction: float = 0.7, motion: Motion | None = None,
           base_height: float | None = None) -> tuple[Scene, list[Body]]:
    """A column of ``n_drums`` identical drums (:func:`drum`) stacked on a base, in 3D.

    Parameters
    ----------
    n_drums : int
        >= 1.
    radius, drum_height : float
        Circumradius and height of each drum, m (> 0).
    n_sides : int
        Sides of the drums' polygon, >= 3.
    density : float
        kg/m^3 (> 0).
    friction : float
        Coulomb coefficient of every contact (>= 0); restitution is 0.
    motion : Motion, optional
        Horizontal motion of the base along x; None: a fixed base.
    base_height : float, optional
        Thickness of the base, m; default a tenth of its width.

    Returns
    -------
    scene : Scene
        ``Scene(dim=3)``, z up, the base's top at z = 0.
    drums : list of Body
        Bottom drum first; drum ``k`` has its centre at ``(0, 0, (k + 1/2) drum_height)``.
    """
    scene, (drums,), _ = _colonnade(1, 0.0, n_drums, radius, drum_height, n_sides, None,
                                    density, friction, motion, base_height)
    return scene, drums


def colonnade(n_columns: int, spacing: float, n_drums: int, radius: float, drum_height: float,
              n_sides: int = 16, architrave_height: float | None = None, density: float = 2500.0,
              friction: float = 0.7, motion: Motion | None = None,
              base_height: float | None = None) -> tuple[Scene, list[list[Body]], list[Body]]:
    """A row of drum columns along x carrying an architrave, in 3D.

    ``n_columns`` columns of ``n_drums`` drums (:func:`drum`) with their axes
    ``spacing`` apart, centred on x = 0, on one base. The architrave is a row of
    ``n_columns - 1`` boxes, each spanning from one column's axis to the next
    (``spacing`` long, as wide along y as the drums' inscribed diameter
    ``2 radius cos(pi / n_sides)``, ``architrave_height`` high), so that every joint of
    the architrave sits over a column axis; a single column carries one block
    ``2 radius`` long.

    Parameters
    ----------
    n_columns : int
        >= 1.
    spacing : float
        Distance between column axes, m, > ``2 radius`` (the drums must not touch).
    n_drums, radius, drum_height, n_sides, density, friction, motion, base_height
        As in :func:`column`.
    architrave_height : float, optional
        m (> 0); default ``drum_height``.

    Returns
    -------
    scene : Scene
    columns : list of list of Body
        One list of drums per column (bottom first), columns from -x to +x.
    architrave : list of Body
        From -x to +x.
    """
    n_columns = _positive_int(n_columns, "n_columns")
    radius = _positive_length(radius, "radius")
    spacing = _positive_length(spacing, "spacing")
    if n_columns > 1 and not spacing > 2.0 * radius:
        raise ValueError(f"spacing == {spacing!r}, must be > 2 radius = {2.0 * radius!r} m "
                         "(neighbouring drums would touch).")
    height = drum_height if architrave_height is None else architrave_height
    height = _positive_length(height, "architrave_height")
    return _colonnade(n_columns, spacing, n_drums, radius, drum_height, n_sides, height,
                      density, friction, motion, base_height)


def _colonnade(n_columns, spacing, n_drums, radius, drum_height, n_sides, architrave_height,
               density, friction, motion, base_height):
    """Columns (and an architrave when ``architrave_height`` is not None); see :func:`colonnade`."""
    n_drums, radius, drum_height, n_sides, density = _column_args(n_drums, radius, drum_height,
                                                                  n_sides, density)
    span = (n_columns - 1) * spacing + 2.0 * radius
    scene = _base_scene(span, _friction(friction), motion, base_height, depth=2.0 * radius)
    shape = drum(radius, drum_height, n_sides)
    axes = (np.arange(n_columns) - 0.5 * (n_columns - 1)) * spacing
    columns = [[scene.add_block(shape, position=(x, 0.0, (k + 0.5) * drum_height), density=density)
                for k in range(n_drums)] for x in axes]
    architrave = []
    if architrave_height is not None:
        top = n_drums * drum_height + 0.5 * architrave_height
        width = 2.0 * radius * math.cos(math.pi / n_sides)
        if n_columns == 1:
            spans = [(axes[0], 2.0 * radius)]
        else:
            spans = [(0.5 * (a + b), spacing) for a, b in zip(axes[:-1], axes[1:])]
        architrave = [scene.add_block(box(length, width, architrave_height), position=(x, 0.0, top),
                                      density=density, name=f"architrave{i}")
                      for i, (x, length) in enumerate(spans)]
    return scene, columns, architrave
