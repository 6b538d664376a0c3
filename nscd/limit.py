"""Limit analysis by simulation: the collapse load factor of an assembly on a tilting table.

:func:`collapse_load_factor` drives the supports of a scene (its fixed bodies) with a
horizontal acceleration that grows linearly in time, ``a(t) = g (start + rate t)``, slowly
enough to be quasi-static, and finds when the assembly starts to move relative to the
supports. In the frame of the supports the ramp is a horizontal body force ``-lambda g``
per unit mass on every block (d'Alembert), so the acceleration at the onset of motion,
divided by g, is the horizontal collapse load factor of limit analysis ("tilting table",
"equivalent static" or "quasi-static" acceleration of arches and walls). The mechanism
that formed is read from the joints: :func:`mechanism` lists which joints hinged (opened
on one side), slid or separated between two configurations.

Collapse detection (definitions used throughout):

* ``L``: the height of the assembly (vertical extent of its dynamic bodies), m;
  ``T = sqrt(L / g)``: its characteristic time (a block of height L tips over on this
  scale once it starts; an arch's mechanism grows like ``exp(t / T)``).
* Relative motion of a body w.r.t. the supports (which only translate):
  displacement ``|x - x0 - d_base| + r |rotation|`` (an upper bound of the displacement of
  any of its points, ``r`` its bounding radius) and speed ``|v - v_base| + r |omega|``.
* Collapse is *detected* when some body's relative displacement exceeds
  ``detect * L`` (default 1e-3 L: far above solver noise, far below a change of geometry).
* The *onset* is the last time before detection at which every body's relative speed
  was at most ``REST_SPEED * sqrt(g L)``; the load factor is the ramp's value then.
  After the onset the relative speed grows like ``g s tau^2 / 2`` (``s`` the ramp rate,
  ``tau`` the time since onset: a block sliding with acceleration ``(lambda - mu) g``; a
  rocking block or an arch mechanism grows at least as fast), so the speed threshold
  ``v`` is crossed ``tau = sqrt(2 v / (g s))`` after the onset and the load factor is
  overestimated by ``s tau = sqrt(2 v s / g)``: with ``v = 1e-6 sqrt(g L)`` and the
  quasi-static bound ``s T <= 0.01`` below, at most ``sqrt(2e-8) = 1.4e-4``.

Quasi-static ramp: the load factor may rise by at most :data:`QUASI_STATIC_RISE` (0.01)
per characteristic time T, ``rate <= 0.01 / T``. A rigid assembly at rest follows its
supports exactly, whatever the ramp, so the rate does not move the onset itself; it
bounds what happens after it: between onset and detection (a few T for a rocking or
hinging mechanism, whose motion grows like ``exp(tau / T)``) the load keeps rising, and
the mechanism read at detection must still be the one that formed at the collapse load,
not one a larger load would have triggered (a block whose friction is just below
``b / h`` slides first and would rock soon after under a fast ramp). With 0.01 per T
the load rises by a few hundredths of g at most between onset and detection.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from nscd.contact.detect import detect
from nscd.model import Model
from nscd.motion import Prescribed
from nscd.result import Result
from nscd.rotation import quaternion_multiply
from nscd.scene import BodyKind, Scene
from nscd.stepper import Settings, Simulator

__all__ = ["QUASI_STATIC_RISE", "REST_SPEED", "Joint", "Collapse", "collapse_load_factor",
           "mechanism", "characteristic_time"]

#: Largest rise of the load factor per characteristic time T = sqrt(L / g) of a
#: quasi-static ramp (dimensionless, per T).
QUASI_STATIC_RISE = 0.01

#: Relative speed, in units of sqrt(g L), below which an assembly counts as at rest.
REST_SPEED = 1e-6

#: A joint point counts as opened (slid) when its relative normal (tangential)
#: displacement exceeds this fraction of the largest joint displacement of the mechanism.
JOINT_FRACTION = 0.1


@dataclass(frozen=True)
class Joint:
    """A joint of a mechanism: two bodies that touched at the start and moved relative to each other.

    Attributes
    ----------
    body_a, body_b : int
        Scene indices of the two bodies (the contact normal points from a to b).
    kind : str
        ``"hinge"``: some of the joint's contact points opened while others stayed closed
        (a rotation about the closed ones); ``"slip"``: every point stayed closed and the
        joint slid; ``"open"``: every point opened (the bodies separated).
    points : ndarray, shape (k, dim)
        The contact points (world, at the start, m) that stayed closed: the hinge's
        pivot(s) for a hinge, all points for a slip, none for an open joint.
    opening : float
        Largest normal opening of a contact point of the joint, m (>= 0 up to round-off).
    slip : float
        Largest tangential relative displacement of a closed contact point, m.
    """

    body_a: int
    body_b: int
    kind: str
    points: np.ndarray
    opening: float
    slip: float


@dataclass(frozen=True)
class Collapse:
    """Result of :func:`collapse_load_factor`.

    Attributes
    ----------
    load_factor : float
        Horizontal acceleration of the supports at the onset of collapse, in g (> 0);
        nan when nothing moved up to ``max_load_factor``.
    collapsed : bool
    direction : int
        +1: the supports accelerate toward +x (the load on the assembly, in their frame,
        points to -x); -1 the opposite.
    rate : float
        Ramp rate of the load factor, 1/s.
    onset_time, detection_time : float
        s (nan if no collapse).
    joints : list of Joint
        The mechanism: joints that hinged, slid or opened between the onset and the
        detection; their points in the scene's coordinates (the supports' frame).
    time : ndarray, shape (n,)
        s.
    load : ndarray, shape (n,)
        Load factor lambda(t) = |base acceleration| / g.
    displacement, speed : ndarray, shape (n,)
        Largest relative displacement (m) and speed (m/s) of a body w.r.t. the supports.
    characteristic_time : float
        T = sqrt(L / g), s.
    height : float
        L, m.
    result : Result
        The simulation (positions in the world frame: the supports move with the ramp).
    """

    load_factor: float
    collapsed: bool
    direction: int
    rate: float
    onset_time: float
    detection_time: float
    joints: list
    time: np.ndarray
    load: np.ndarray
    displacement: np.ndarray
    speed: np.ndarray
    characteristic_time: float
    height: float
    result: Result

    @property
    def hinges(self) -> list:
        """The joints of kind ``"hinge"``."""
        return [j for j in self.joints if j.kind == "hinge"]

    @property
    def slips(self) -> list:
        """The joints of kind ``"slip"``."""
        return [j for j in self.joints if j.kind == "slip"]


def _world_vertices(scene: Scene) -> np.ndarray:
    """All vertices (m, world, initial pose) of the dynamic bodies, stacked."""
    out = []
    for body in scene.dynamic_bodies:
        if scene.dim == 2:
            out.append(body.shape.world_vertices(body.q0[:2], body.q0[2]))
        else:
            from nscd.rotation import quaternion_to_matrix
            out.append(body.shape.world_vertices(body.q0[:3], quaternion_to_matrix(body.q0[3:])))
    return np.concatenate(out)


def characteristic_time(scene: Scene) -> tuple[float, float]:
    """(T, L): the height L (m) of the scene's dynamic bodies and T = sqrt(L / g) (s)."""
    if not scene.dynamic_bodies:
        raise ValueError("scene has no dynamic body: nothing can collapse.")
    if not scene.gravity > 0.0:
        raise ValueError(f"scene gravity == {scene.gravity}, must be > 0 m/s^2 for a load factor.")
    vertical = _world_vertices(scene)[:, scene.dim - 1]
    height = float(np.ptp(vertical))
    return math.sqrt(height / scene.gravity), height


def _relative_rotation(scene: Scene, q: np.ndarray, q0: np.ndarray) -> np.ndarray:
    """Rotation angle (rad, >= 0) of each body from pose q0 to pose q; q, q0 (n_bodies, nq)."""
    if scene.dim == 2:
        return np.abs(q[:, 2] - q0[:, 2])
    conj = q0[:, 3:] * np.array([1.0, -1.0, -1.0, -1.0])
    rel = np.array([quaternion_multiply(a, b) for a, b in zip(q[:, 3:], conj)])
    return 2.0 * np.arctan2(np.linalg.norm(rel[:, 1:], axis=1), np.abs(rel[:, 0]))


def _material_displacement(scene: Scene, q_from: np.ndarray, q_to: np.ndarray,
                           bodies: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Displacement (m) of the material point of body ``bodies[k]`` at ``points[k]`` (world, pose q_from)."""
    dim = scene.dim
    x0, x1 = q_from[bodies, :dim], q_to[bodies, :dim]
    arm = points - x0
    if dim == 2:
        turn = q_to[bodies, 2] - q_from[bodies, 2]
        c, s = np.cos(turn), np.sin(turn)
        rotated = np.column_stack([c * arm[:, 0] - s * arm[:, 1], s * arm[:, 0] + c * arm[:, 1]])
    else:
        from nscd.rotation import quaternion_to_matrix
        rotated = np.empty_like(arm)
        for k, body in enumerate(bodies):
            r0 = quaternion_to_matrix(q_from[body, 3:])
            r1 = quaternion_to_matrix(q_to[body, 3:])
            rotated[k] = r1 @ (r0.T @ arm[k])
    return x1 + rotated - points


def mechanism(scene: Scene, q_from: np.ndarray, q_to: np.ndarray,
              fraction: float = JOINT_FRACTION) -> list[Joint]:
    """The joints that hinged, slid or opened between two configurations of a scene.

    The joints are the contacts of ``q_from`` (gap within a millionth of the scene's
    height). For each contact point, the relative displacement of the two bodies'
    material points there, from ``q_from`` to ``q_to``, is split along the contact
    normal (opening, positive when separating) and tangent (slip). A point is open (has
    slid) when its opening (slip) exceeds ``fraction`` times the largest relative
    displacement of any joint point: a joint whose points all stayed closed and did not
    slide is not part of the mechanism and is left out.

    Parameters
    ----------
    scene : Scene
    q_from, q_to : ndarray, shape (n_bodies, nq)
        Two configurations (e.g. ``result.q[k]``).
    fraction : float
        In (0, 1).

    Returns
    -------
    list of Joint
        Ordered by body pair.
    """
    if not 0.0 < fraction < 1.0:
        raise ValueError(f"fraction == {fraction}, must be in (0, 1).")
    model = Model.from_scene(scene)
    _, height = characteristic_time(scene)
    contacts = detect(model, np.asarray(q_from, dtype=float), margin=1e-6 * height)
    if len(contacts) == 0:
        return []
    q_from, q_to = np.asarray(q_from, dtype=float), np.asarray(q_to, dtype=float)
    move_a = _material_displacement(scene, q_from, q_to, contacts.body_a, contacts.point)
    move_b = _material_displacement(scene, q_from, q_to, contacts.body_b, contacts.point)
    relative = move_b - move_a
    normal = contacts.frame[:, 0, :]
    opening = np.einsum("ij,ij->i", relative, normal)
    slip = np.linalg.norm(relative - opening[:, None] * normal, axis=1)
    scale = float(np.max(np.linalg.norm(relative, axis=1)))
    if scale == 0.0:
        return []
    threshold = fraction * scale
    joints = []
    pairs = np.column_stack([contacts.body_a, contacts.body_b])
    for a, b in sorted(set(map(tuple, pairs.tolist()))):
        rows = np.flatnonzero((pairs[:, 0] == a) & (pairs[:, 1] == b))
        is_open = opening[rows] > threshold
        closed = rows[~is_open]
        slid = slip[closed] > threshold if closed.size else np.zeros(0, bool)
        if is_open.all():
            kind = "open"
        elif is_open.any():
            kind = "hinge"
        elif slid.any():
            kind = "slip"
        else:
            continue
        joints.append(Joint(body_a=int(a), body_b=int(b), kind=kind,
                            points=contacts.point[closed].copy(),
                            opening=float(max(opening[rows].max(), 0.0)),
                            slip=float(slip[closed].max()) if closed.size else 0.0))
    return joints


def _ramp(start: float, rate: float, gravity: float) -> Prescribed:
    """Base acceleration ``g (start + rate t)`` for t >= 0 (m/s^2), from rest, as a motion."""
    a0, k = gravity * start, gravity * rate

    def displacement(t):
        t = np.maximum(t, 0.0)
        return a0 * t**2 / 2.0 + k * t**3 / 6.0

    def velocity(t):
        t = np.maximum(t, 0.0)
        return a0 * t + k * t**2 / 2.0

    def acceleration(t):
        return np.where(np.asarray(t) >= 0.0, a0 + k * np.maximum(t, 0.0), 0.0)

    return Prescribed(displacement, velocity, acceleration)


def _tilting_table(scene: Scene, motion: Prescribed, direction: int) -> Scene:
    """A copy of ``scene`` whose fixed bodies are driven by ``motion`` along ``direction`` x."""
    unit = direction * np.eye(scene.dim)[0]
    bodies = []
    for body in scene.bodies:
        if body.kind is BodyKind.FIXED:
            body = dataclasses.replace(body, kind=BodyKind.DRIVEN, motion=motion, direction=unit)
        bodies.append(body)
    return dataclasses.replace(scene, bodies=bodies)


def collapse_load_factor(scene: Scene, direction: int = +1, rate: float | None = None,
                         start: float = 0.0, max_load_factor: float = 1.0, dt: float = 1e-3,
                         detect: float = 1e-3, settings: Settings | None = None) -> Collapse:
    """Horizontal collapse load factor of an assembly by a quasi-static tilting-table run.

    The fixed bodies of ``scene`` (its supports: base, springers) are driven together
    with the horizontal acceleration ``direction * g * (start + rate * t)`` along x; the
    run stops when collapse is detected or the load factor passes ``max_load_factor``.
    See the module docstring for the definitions of onset, detection and the
    quasi-static bound.

    Parameters
    ----------
    scene : Scene
        2D or 3D, with at least one fixed body and no driven one (the supports).
    direction : {+1, -1}
        Sign of the supports' acceleration along x. +1: in the supports' frame the
        inertial load on the assembly points to -x (a block tips toward -x).
    rate : float, optional
        Ramp rate of the load factor, 1/s, in (0, QUASI_STATIC_RISE / T]; default half the bound.
    start : float
        Load factor at t = 0, in [0, max_load_factor) (the acceleration jumps to it from
        rest, which a rigid assembly in equilibrium follows without moving). Use it to
        skip a range where the assembly is known to stand.
    max_load_factor : float
        Stop (no collapse) beyond this load factor, > 0.
    dt : float
        Time step, s.
    detect : float
        Relative displacement that declares collapse, in units of the height L, in (0, 0.1].
    settings : Settings, optional
        Integrator and solver options of the run.

    Returns
    -------
    Collapse

    Raises
    ------
    ValueError
        For a ramp faster than quasi-static (the message gives the largest admissible
        rate), a scene without fixed bodies or with driven ones, bad parameters, or a
        start above the collapse load factor (motion from the first steps).

    Examples
    --------
    >>> scene, (block,) = nscd.stack(1, width=0.3, height=1.0, friction=1.0)
    >>> c = nscd.analysis.collapse_load_factor(scene, start=0.25)
    >>> round(c.load_factor, 2), c.hinges[0].kind
    (0.3, 'hinge')
    """
    if direction not in (1, -1) or isinstance(direction, bool):
        raise ValueError(f"direction == {direction!r}, must be +1 or -1.")
    if not (isinstance(max_load_factor, (int, float)) and math.isfinite(max_load_factor)
            and max_load_factor > 0.0):
        raise ValueError(f"max_load_factor == {max_load_factor!r}, must be a finite number > 0.")
    if not (isinstance(start, (int, float)) and 0.0 <= start < max_load_factor):
        raise ValueError(f"start == {start!r}, must be in [0, max_load_factor) = [0, {max_load_factor}).")
    if not (isinstance(detect, (int, float)) and 0.0 < detect <= 0.1):
        raise ValueError(f"detect == {detect!r}, must be in (0, 0.1] (a fraction of the height).")
    for body in scene.bodies:
        if body.kind is BodyKind.DRIVEN:
            raise ValueError(f"body {body.name!r} already has a motion; collapse_load_factor drives the "
                             "supports itself: build the scene with fixed supports (motion=None).")
    if not any(b.kind is BodyKind.FIXED for b in scene.bodies):
        raise ValueError("scene has no fixed body: collapse_load_factor drives the fixed bodies "
                         "(the supports) with the ramp.")
    period, height = characteristic_time(scene)
    fastest = QUASI_STATIC_RISE / period
    if rate is None:
        rate = 0.5 * fastest
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and rate > 0.0):
        raise ValueError(f"rate == {rate!r}, must be a finite number > 0 (1/s).")
    if rate > fastest:
        raise ValueError(
            f"rate == {rate:.6g} 1/s is too fast to be quasi-static: the load factor may rise by at "
            f"most {QUASI_STATIC_RISE} per characteristic time T = sqrt(L / g) = {period:.4g} s "
            f"(L = {height:.4g} m, the assembly's height), so rate must be <= {fastest:.6g} 1/s.")
    gravity = scene.gravity
    motion = _ramp(start, rate, gravity)
    table = _tilting_table(scene, motion, direction)
    sim = Simulator(table, dt, settings)
    dyn = np.array([b.index for b in table.dynamic_bodies])
    radius = np.array([b.shape.radius if scene.dim == 2 else _radius3(b.shape) for b in table.dynamic_bodies])
    dim = scene.dim
    unit = direction * np.eye(dim)[0]
    q0 = sim.state.q[dyn].copy()
    rest_speed = REST_SPEED * math.sqrt(gravity * height)
    times, displacement, speed = [0.0], [0.0], [0.0]
    t_end = (max_load_factor - start) / rate
    n_steps = int(math.ceil(t_end / dt))
    detected = None
    for _ in range(n_steps):
        sim.step()
        state = sim.state
        base_d = float(motion.displacement(state.t)) * unit
        base_v = float(motion.velocity(state.t)) * unit
        q, v = state.q[dyn], state.v[dyn]
        turned = _relative_rotation(scene, q, q0)
        moved = np.linalg.norm(q[:, :dim] - q0[:, :dim] - base_d, axis=1) + radius * turned
        spin = np.abs(v[:, 2]) if dim == 2 else np.linalg.norm(v[:, 3:], axis=1)
        fast = np.linalg.norm(v[:, :dim] - base_v, axis=1) + radius * spin
        times.append(state.t)
        displacement.append(float(moved.max()))
        speed.append(float(fast.max()))
        if displacement[-1] > detect * height:
            detected = len(times) - 1
            break
    result = sim.result()
    time = np.array(times)
    speed_arr, disp_arr = np.array(speed), np.array(displacement)
    load = start + rate * time
    if detected is None:
        return Collapse(load_factor=math.nan, collapsed=False, direction=direction, rate=rate,
                        onset_time=math.nan, detection_time=math.nan, joints=[], time=time,
                        load=load, displacement=disp_arr, speed=speed_arr,
                        characteristic_time=period, height=height, result=result)
    at_rest = np.flatnonzero(speed_arr[:detected + 1] <= rest_speed)
    onset = int(at_rest[-1]) if at_rest.size else 0
    if onset == 0:
        raise ValueError(f"start == {start}: the assembly moved from the first step, so its collapse "
                         "load factor is below start; give a smaller start.")
    # Joint points in the scene's own coordinates (the supports' frame at t = 0).
    shift = float(motion.displacement(time[onset])) * unit
    joints = [dataclasses.replace(j, points=j.points - shift)
              for j in mechanism(table, result.q[onset], result.q[detected])]
    return Collapse(load_factor=float(load[onset]), collapsed=True, direction=direction, rate=rate,
                    onset_time=float(time[onset]), detection_time=float(time[detected]),
                    joints=joints, time=time, load=load, displacement=disp_arr, speed=speed_arr,
                    characteristic_time=period, height=height, result=result)


def _radius3(shape) -> float:
    """Bounding radius (m) of a polyhedron about its centroid."""
    return float(np.max(np.linalg.norm(shape.vertices, axis=1)))
