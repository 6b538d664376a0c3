"""The static description of a scene: bodies, contact laws, gravity, base motion.

A :class:`Scene` is built by scripting (``add_block``, ``add_base``, ``set_contact``)
and validated as it is built, so the time step need not check anything. It holds no
mutable state of the simulation: positions and velocities live in :class:`nscd.State`.

Conventions
-----------
2D (``Scene()``, ``dim=2``): x horizontal, y up, gravity along -y, angles in rad,
counter-clockwise positive. A body's generalised position is ``(x, y, angle)`` and its
velocity ``(vx, vy, omega)``.

3D (``Scene(dim=3)``): z up, gravity along -z. Position ``(x, y, z)``, orientation a
unit quaternion ``(w, x, y, z)`` (body to world), linear velocity and angular
velocity ``omega`` in the world frame (rad/s).
"""
from __future__ import annotations

import enum
import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from nscd._checks import real_number
from nscd.motion import STANDARD_GRAVITY, Motion

#: m/s; initial speeds are refused at and beyond it.
SPEED_OF_LIGHT = 299_792_458.0

#: Overlap allowed between bodies at the start, m: a penetration up to and including it is
#: accepted (to round-off of the positions), a deeper one raises.
OVERLAP_TOLERANCE = 1e-6

#: Bounding radius, m, above which a dynamic body's size warns that it may not be in metres:
#: a 200 m chimney rocking as one block stays below it, a 500 mm block given as 500 (m) is
#: far above it (sizes in millimetres of blocks of 0.1 m and more).
PLAUSIBLE_BLOCK_RADIUS = 100.0


class BodyKind(enum.Enum):
    """How a body moves.

    DYNAMIC: free rigid body under gravity and contact.
    FIXED: never moves.
    DRIVEN: follows a prescribed motion (a shaking base); infinite mass for contacts.
    """

    DYNAMIC = "dynamic"
    FIXED = "fixed"
    DRIVEN = "driven"


@dataclass(frozen=True)
class ContactLaw:
    """Contact parameters of a pair: Coulomb ``friction`` mu >= 0, Newton ``restitution`` e in [0, 1]."""

    friction: float
    restitution: float

    def __post_init__(self) -> None:
        mu, e = real_number("friction", self.friction), real_number("restitution", self.restitution)
        if not (math.isfinite(mu) and mu >= 0.0):
            raise ValueError(f"friction == {mu}, must be a finite number >= 0.")
        if not (math.isfinite(e) and 0.0 <= e <= 1.0):
            raise ValueError(f"restitution == {e}, must be in [0, 1].")
        object.__setattr__(self, "friction", mu)
        object.__setattr__(self, "restitution", e)


@dataclass(frozen=True, eq=False)
class Body:
    """One rigid body of a scene (a handle: pass it to ``Result`` accessors).

    Attributes
    ----------
    index : int
        Position of the body in the scene (rows of state arrays).
    name : str
    shape : Polygon or Polyhedron
    kind : BodyKind
    mass : float
        kg (``inf`` for fixed and driven bodies).
    inertia : float or ndarray (3, 3)
        kg m^2 about the centre of mass, body frame (2D: scalar, unit depth).
    material : str
        Name used to look up contact laws.
    q0 : ndarray
        Initial generalised position (2D ``(x, y, angle)``; 3D ``(x, y, z, qw, qx, qy, qz)``).
    v0 : ndarray
        Initial velocity (2D ``(vx, vy, omega)``; 3D ``(vx, vy, vz, wx, wy, wz)``, world frame).
    motion : Motion or None
        Horizontal prescribed motion of a driven body along ``direction``.
    vertical : Motion or None
        Vertical prescribed motion of a driven body (m, up positive).
    direction : ndarray
        Unit horizontal direction of ``motion`` ((1, 0) in 2D, (1, 0, 0) in 3D by default);
        2D with an ``out_of_plane`` component: the in-plane component of that unit direction.
    density : float
        kg/m^3 (nan for fixed and driven bodies).
    depth : float
        2D only: the block's extent perpendicular to the plane, m (nan: not given). The 2D
        dynamics are per unit depth whatever it is; it serves the out-of-plane checks of
        :mod:`nscd.choose` and the extrusion to 3D.
    out_of_plane : float
        2D only: the component perpendicular to the plane of the unit direction of a driven
        base's ``motion`` (``sin`` of its angle out of the plane; 3D +y after extrusion).
        The 2D models do not simulate it; :mod:`nscd.choose` checks what it demands.
    """

    index: int
    name: str
    shape: Any
    kind: BodyKind
    mass: float
    inertia: Any
    material: str
    q0: np.ndarray
    v0: np.ndarray
    motion: Motion | None = None
    vertical: Motion | None = None
    direction: np.ndarray | None = None
    density: float = math.nan
    depth: float = math.nan
    out_of_plane: float = 0.0

    @property
    def is_dynamic(self) -> bool:
        return self.kind is BodyKind.DYNAMIC

    def prescribed(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Position and velocity of a fixed or driven body at time ``t`` (s)."""
        q = self.q0.copy()
        v = np.zeros_like(self.v0)
        dim = len(self.direction)
        if self.motion is not None:
            q[:dim] += float(self.motion.displacement(t)) * self.direction
            v[:dim] += float(self.motion.velocity(t)) * self.direction
        if self.vertical is not None:
            q[dim - 1] += float(self.vertical.displacement(t))
            v[dim - 1] += float(self.vertical.velocity(t))
        return q, v

    def __repr__(self) -> str:
        return f"Body({self.index}, {self.name!r}, {self.kind.value})"


def _vector(value: Sequence[float], size: int, label: str, owner: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float).reshape(-1)
    if arr.shape != (size,):
        raise ValueError(f"{owner}: {label} must have {size} components, got {arr.shape[0]}.")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{owner}: {label} == {arr.tolist()} contains NaN or inf.")
    return arr


def _quaternion(value: Sequence[float], owner: str) -> np.ndarray:
    quat = _vector(value, 4, "orientation", owner)
    norm = float(np.linalg.norm(quat))
    if norm < 1e-12:
        raise ValueError(f"{owner}: orientation quaternion has zero norm; give a unit (w, x, y, z).")
    return quat / norm


@dataclass
class Scene:
    """A scene under construction: bodies, contact laws and gravity.

    Parameters
    ----------
    dim : {2, 3}
        Spatial dimension.
    gravity : float
        Magnitude of gravity in m/s^2, acting along -y (2D) or -z (3D); default the
        standard gravity 9.80665 m/s^2, the same ``g`` that converts motions given in g.

    Examples
    --------
    >>> import nscd
    >>> scene = nscd.Scene()
    >>> base = scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1))
    >>> block = scene.add_block(nscd.box(0.5, 1.5), position=(0.0, 0.75), density=2500.0)
    >>> scene.set_contact(friction=0.8, restitution=0.0)
    """

    dim: int = 2
    gravity: float = STANDARD_GRAVITY
    bodies: list[Body] = field(default_factory=list)
    default_contact: ContactLaw = field(default_factory=lambda: ContactLaw(0.5, 0.0))
    _material_laws: dict = field(default_factory=dict, repr=False)
    _body_laws: dict = field(default_factory=dict, repr=False)

    def __post_init__(self) -> None:
        if self.dim not in (2, 3):
            raise ValueError(f"dim == {self.dim}, must be 2 or 3.")
        if not (math.isfinite(self.gravity) and self.gravity >= 0.0):
            raise ValueError(f"gravity == {self.gravity}, must be a finite number >= 0 m/s^2.")

    # -- sizes --------------------------------------------------------------
    @property
    def nq(self) -> int:
        """Generalised coordinates per body (3 in 2D, 7 in 3D)."""
        return 3 if self.dim == 2 else 7

    @property
    def nv(self) -> int:
        """Velocity components per body (3 in 2D, 6 in 3D)."""
        return 3 if self.dim == 2 else 6

    # -- building -------------------------------------------------------------
    def _check_shape(self, shape: Any, owner: str) -> None:
        shape_dim = getattr(shape, "dim", None)
        if shape_dim != self.dim:
            kind = "2D polygon" if self.dim == 2 else "3D polyhedron"
            raise ValueError(
                f"{owner}: shape is {shape_dim}D but the scene is {self.dim}D; give a {kind} "
                f"(nscd.box with {self.dim} sides)."
            )

    def _pose(self, position, angle, orientation, owner: str) -> np.ndarray:
        pos = _vector(position, self.dim, "position", owner)
        if self.dim == 2:
            if orientation is not None:
                raise ValueError(f"{owner}: orientation is for 3D scenes; use angle= (rad) in 2D.")
            if not math.isfinite(angle):
                raise ValueError(f"{owner}: angle == {angle}, must be finite (rad).")
            return np.array([pos[0], pos[1], float(angle)])
        if angle not in (0, 0.0):
            raise ValueError(f"{owner}: angle is for 2D scenes; use orientation=(w, x, y, z) in 3D.")
        quat = _quaternion((1.0, 0.0, 0.0, 0.0) if orientation is None else orientation, owner)
        return np.concatenate([pos, quat])

    def _velocity(self, velocity, omega, owner: str, radius: float) -> np.ndarray:
        lin = _vector(velocity, self.dim, "velocity", owner)
        if self.dim == 2:
            ang = _vector([omega], 1, "omega", owner)
        else:
            ang = _vector(np.zeros(3) if np.isscalar(omega) and omega == 0 else omega, 3, "omega", owner)
        # Newtonian rigid-body mechanics ends well below the speed of light; beyond it the
        # energies (m v^2) overflow to inf and every balance becomes NaN.
        if np.max(np.abs(lin)) >= SPEED_OF_LIGHT or np.linalg.norm(lin) >= SPEED_OF_LIGHT:
            raise ValueError(f"{owner}: velocity == {lin.tolist()} m/s, its norm must be below the speed of "
                             f"light ({SPEED_OF_LIGHT:.4g} m/s).")
        if np.max(np.abs(ang)) * radius >= SPEED_OF_LIGHT or np.linalg.norm(ang) * radius >= SPEED_OF_LIGHT:
            raise ValueError(f"{owner}: omega == {ang.tolist()} rad/s, |omega| times the body's radius "
                             f"({radius:.3g} m) must be below the speed of light ({SPEED_OF_LIGHT:.4g} m/s).")
        return np.concatenate([lin, ang])

    def _name(self, name: str | None, prefix: str) -> str:
        name = f"{prefix}{len(self.bodies)}" if name is None else str(name)
        if any(b.name == name for b in self.bodies):
            raise ValueError(f"body name {name!r} is already used in this scene.")
        return name

    def add_block(
        self,
        shape: Any,
        position: Sequence[float],
        angle: float = 0.0,
        density: float = 2500.0,
        velocity: Sequence[float] | None = None,
        omega: Any = 0.0,
        orientation: Sequence[float] | None = None,
        material: str = "default",
        name: str | None = None,
        depth: float | None = None,
    ) -> Body:
        """Add a dynamic rigid body.

        Parameters
        ----------
        shape : Polygon (2D) or Polyhedron (3D)
        position : (dim,) m
            Position of the centre of mass.
        angle : float
            2D only: rotation in rad, counter-clockwise.
        density : float
            kg/m^3 (> 0). In 2D the body is a prism of unit depth.
        velocity : (dim,) m/s
            Initial velocity of the centre of mass.
        omega : float (2D, rad/s CCW) or (3,) (3D, world frame)
        orientation : (4,)
            3D only: unit quaternion (w, x, y, z), body to world.
        material : str
            Material name for contact-law lookup.
        name : str, optional
            Defaults to ``"block<i>"``.
        depth : float, optional
            2D only: the block's extent perpendicular to the plane in m (> 0). The 2D
            dynamics stay per unit depth; the depth serves the out-of-plane checks of the
            reduced models (:func:`nscd.choose_model`) and :func:`nscd.choose.extrude`.

        Returns
        -------
        Body
            The handle to use with :class:`nscd.Result` accessors.
        """
        name = self._name(name, "block")
        owner = f"body {name!r}"
        self._check_shape(shape, owner)
        if shape.radius > PLAUSIBLE_BLOCK_RADIUS:
            warnings.warn(f"{owner}: its bounding radius is {shape.radius:.4g} m, more than "
                          f"{PLAUSIBLE_BLOCK_RADIUS:g} m (PLAUSIBLE_BLOCK_RADIUS); sizes are in metres, "
                          "and a size given in millimetres is 1000 times too large.", UserWarning, stacklevel=2)
        try:
            density = real_number("density", density)
        except TypeError as exc:
            raise TypeError(f"{owner}: {exc}") from None
        if not (math.isfinite(density) and density > 0.0):
            raise ValueError(f"{owner}: density == {density}, must be > 0 kg/m^3.")
        if depth is not None:
            if self.dim != 2:
                raise ValueError(f"{owner}: depth == {depth!r} is for 2D scenes (a 3D shape has its own depth).")
            depth = real_number("depth", depth)
            if not (math.isfinite(depth) and depth > 0.0):
                raise ValueError(f"{owner}: depth == {depth}, must be > 0 m.")
        q0 = self._pose(position, angle, orientation, owner)
        v0 = self._velocity(np.zeros(self.dim) if velocity is None else velocity, omega, owner, shape.radius)
        body = Body(
            index=len(self.bodies), name=name, shape=shape, kind=BodyKind.DYNAMIC,
            mass=float(shape.mass(density)), inertia=shape.inertia(density),
            material=str(material), q0=q0, v0=v0, density=float(density),
            direction=np.eye(self.dim)[0], depth=math.nan if depth is None else float(depth),
        )
        self.bodies.append(body)
        return body

    def add_base(
        self,
        shape: Any,
        position: Sequence[float],
        motion: Motion | None = None,
        vertical: Motion | None = None,
        direction: Sequence[float] | None = None,
        angle: float = 0.0,
        orientation: Sequence[float] | None = None,
        material: str = "default",
        name: str | None = None,
        out_of_plane_angle: float = 0.0,
    ) -> Body:
        """Add a fixed body, or a driven one when a ``motion`` is given (a shaking base).

        Parameters
        ----------
        shape : Polygon (2D) or Polyhedron (3D)
        position : (dim,) m
            Position of the base's centroid at t = 0 (its reference position).
        motion : Motion, optional
            Horizontal ground motion; the base's position is
            ``position + motion.displacement(t) * direction``. None: no horizontal motion.
        vertical : Motion, optional
            Vertical ground motion (m, up positive). None: no vertical motion.
        direction : (dim,), optional
            Horizontal direction of ``motion`` (normalised); default +x.
        out_of_plane_angle : float
            2D only: angle in rad, in [-pi/2, pi/2], between the direction of ``motion`` and
            the scene's plane (toward 3D +y after :func:`nscd.choose.extrude`). The 2D models
            run the in-plane component ``cos(angle) motion``; the out-of-plane component
            ``sin(angle) motion`` is not simulated in 2D, but :func:`nscd.choose_model` and the
            reduced models' checks weigh what it demands (out-of-plane rocking, sliding).
        """
        name = self._name(name, "base")
        owner = f"body {name!r}"
        self._check_shape(shape, owner)
        for label, m in (("motion", motion), ("vertical", vertical)):
            if m is not None and not isinstance(m, Motion):
                raise TypeError(f"{owner}: {label} must be an nscd.motion.Motion, got {type(m).__name__}.")
        if direction is None:
            unit = np.eye(self.dim)[0]
        else:
            unit = _vector(direction, self.dim, "direction", owner)
            if abs(unit[-1]) > 1e-12 or np.linalg.norm(unit) < 1e-12:
                raise ValueError(f"{owner}: direction == {unit.tolist()}, must be a nonzero horizontal vector.")
            unit = unit / np.linalg.norm(unit)
        try:
            beta = real_number("out_of_plane_angle", out_of_plane_angle)
        except TypeError as exc:
            raise TypeError(f"{owner}: {exc}") from None
        if beta != 0.0:
            if self.dim != 2:
                raise ValueError(f"{owner}: out_of_plane_angle == {beta} is for 2D scenes; in 3D give the "
                                 "direction of the motion.")
            if not abs(beta) <= 0.5 * math.pi:
                raise ValueError(f"{owner}: out_of_plane_angle == {beta}, must be in [-pi/2, pi/2] rad.")
            if motion is None:
                raise ValueError(f"{owner}: out_of_plane_angle == {beta} without a motion to direct.")
            unit = unit * math.cos(beta)
        q0 = self._pose(position, angle, orientation, owner)
        kind = BodyKind.FIXED if motion is None and vertical is None else BodyKind.DRIVEN
        body = Body(
            index=len(self.bodies), name=name, shape=shape, kind=kind, mass=math.inf,
            inertia=math.inf if self.dim == 2 else np.full((3, 3), math.inf),
            material=str(material), q0=q0, v0=np.zeros(self.nv),
            motion=motion, vertical=vertical, direction=unit,
            out_of_plane=math.sin(beta) if beta else 0.0,
        )
        if kind is BodyKind.DRIVEN:
            _, v_start = body.prescribed(0.0)
            if not np.all(np.isfinite(v_start)):
                raise ValueError(f"{owner}: the motion gives a non-finite velocity at t = 0.")
        self.bodies.append(body)
        return body

    def set_contact(
        self,
        friction: float,
        restitution: float = 0.0,
        between: tuple[Any, Any] | None = None,
    ) -> None:
        """Set the contact law: for every pair, or for one pair of materials or bodies.

        Parameters
        ----------
        friction : float
            Coulomb coefficient mu >= 0 (0: frictionless).
        restitution : float
            Newton's coefficient e in [0, 1] on the normal relative velocity.
        between : (a, b), optional
            Two material names (str) or two :class:`Body` handles; None sets the default.
            Body-pair laws take precedence over material-pair laws over the default.
        """
        law = ContactLaw(friction, restitution)
        if between is None:
            self.default_contact = law
            return
        if isinstance(between, (str, bytes)) or not isinstance(between, Sequence) or len(between) != 2:
            raise TypeError(f"between == {between!r}, must be a pair (a, b) of material names or of "
                            "Body handles, or None for the default law.")
        a, b = between
        if isinstance(a, Body) and isinstance(b, Body):
            self._body_laws[frozenset((a.index, b.index))] = law
        elif isinstance(a, str) and isinstance(b, str):
            self._material_laws[frozenset((a, b))] = law
        else:
            raise TypeError(f"between == {between!r}, must be two material names (str) or two Body handles.")

    def contact_law(self, a: Body, b: Body) -> ContactLaw:
        """The contact law that applies between bodies ``a`` and ``b``."""
        law = self._body_laws.get(frozenset((a.index, b.index)))
        if law is None:
            law = self._material_laws.get(frozenset((a.material, b.material)), self.default_contact)
        return law

    # -- lookup ----------------------------------------------------------------
    def body(self, key: Body | int | str) -> Body:
        """The body given by handle, index or name."""
        if isinstance(key, Body):
            return self.bodies[key.index]
        if isinstance(key, (int, np.integer)):
            if not 0 <= key < len(self.bodies):
                raise ValueError(f"body index {key} out of range [0, {len(self.bodies) - 1}].")
            return self.bodies[int(key)]
        for b in self.bodies:
            if b.name == key:
                return b
        raise ValueError(f"no body named {key!r} in the scene.")

    @property
    def dynamic_bodies(self) -> list[Body]:
        return [b for b in self.bodies if b.is_dynamic]
