"""Scene builders: ready-made block assemblies on a base (stacks, running-bond walls).

One idea: turn a few dimensions into a :class:`nscd.Scene` with the blocks already
placed in contact, so that a user (or a benchmark) does not compute coordinates by hand.
Every builder puts a base (fixed, or driven by ``motion``) whose top face is at y = 0,
lays the blocks on it without gaps or overlaps, sets one contact law for every pair,
and returns the scene with the block handles, bottom course first.

Coordinates: x horizontal, y up, m; the assembly is centred on x = 0.
"""
from __future__ import annotations

import math
from numbers import Integral, Real

from nscd.motion import Motion
from nscd.scene import Body, Scene
from nscd.shapes import box

__all__ = ["stack", "wall"]

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


def _base_scene(width: float, friction: float, motion: Motion | None, base_height: float | None) -> Scene:
    """A scene with a base of ``(1 + 2 BASE_OVERHANG) * width`` whose top face is at y = 0."""
    height = 0.1 * width if base_height is None else _positive_length(base_height, "base_height")
    scene = Scene()
    scene.add_base(box((1.0 + 2.0 * BASE_OVERHANG) * width, height), position=(0.0, -0.5 * height),
                   motion=motion, name="base")
    scene.set_contact(friction=friction, restitution=0.0)
    return scene


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
    >>> len(blocks), blocks[-1].q0[1]
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
         base_height: float | None = None) -> tuple[Scene, list[list[Body]]]:
    """A running-bond wall: courses of blocks, every other course offset by half a block.

    Even courses (0, 2, ...; course 0 on the base) hold ``n_per_course`` whole blocks.
    Odd courses are shifted by half a block: ``n_per_course - 1`` whole blocks between
    two half blocks (``block_width / 2`` wide) at the ends, so both ends are flush and
    every vertical joint sits over the middle of a block below. The wall is
    ``n_per_course * block_width`` wide and ``n_courses * block_height`` high, centred
    on x = 0, standing on a base whose top is at y = 0. It has
    ``n_courses * n_per_course + n_courses // 2`` blocks.

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
    scene = _base_scene(total, _friction(friction), motion, base_height)
    whole, half = box(bw, bh), box(0.5 * bw, bh)
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
        courses.append([scene.add_block(shape, position=(x, y), density=density) for shape, x in placed])
    return scene, courses
