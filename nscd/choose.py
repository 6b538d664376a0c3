"""Model no more than a scene needs: choose the smallest adequate model, run it, check its assumptions.

Four models of the same rigid-block physics, smallest first:

* ``"housner"``: one rectangular block rocking on a rigid base (:mod:`nscd.rocking`,
  1 DOF, exact between impacts);
* ``"stacked"``: two rectangular blocks one on the other (:mod:`nscd.stacked`, 2 DOF);
* ``"2d"``: the engine on the planar scene;
* ``"3d"``: the engine in 3D (a 2D scene is extruded along the depth).

:func:`choose_model` reads a scene and says which model suffices, with each check and
its numbers (``reasons``) and what would invalidate the choice during a run
(``limits``). :func:`run` runs a model (``"auto"``: the chosen one) and returns a
result with one interface whichever ran. After every run of a reduced model the
assumptions are checked from its own history (:func:`check_assumptions`): the friction
the motion needed at each sampled instant and at each impact against the friction given
(no sliding), the normal contact forces (no lift-off); a violated check warns and is
flagged on the result with its time and margin. ``verify=True`` reruns the next larger
model and reports the difference in outcome.

Reduced models assume, and :func:`choose_model` checks before the run: rectangular
blocks standing flat and at rest on a horizontal base top (or on each other, the top
block's base within the bottom block's top face), impacts without bounce (restitution
0), a base that never accelerates down faster than g, and friction enough for pure
rocking at the onset (Shenton's criterion, seed ``000_b03963299c8d30d2.txt`` eq. 2-7).
"""
from __future__ import annotations

import math
import time as _time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nscd.motion import Motion, Scaled
from nscd.result import OVERTURN_ANGLE
from nscd.rocking import HousnerBlock
from nscd.scene import Scene
from nscd.stacked import StackedBlocks, classify_patterns, dominant_pattern

__all__ = ["ModelChoice", "ReducedResult", "AssumptionCheck", "MODELS", "choose_model", "run",
           "check_assumptions", "extrude"]

#: The models, smallest first.
MODELS = ("housner", "stacked", "2d", "3d")

_GEOMETRY_TOL = 1e-9  # m, relative to the block size: "standing flat on" and "axis aligned"
_SCAN_POINTS = 20001  # samples of a motion's acceleration for peak / onset checks


class AssumptionWarning(UserWarning):
    """A reduced model's assumption failed during a run (sliding, lift-off)."""


@dataclass(frozen=True)
class ModelChoice:
    """The smallest model adequate for a scene.

    Attributes
    ----------
    kind : str
        One of :data:`MODELS`.
    reasons : list of str
        The checks that justify it (and rule out the smaller models), each with its numbers.
    limits : list of str
        What would invalidate it during a run.
    reduced : HousnerBlock or StackedBlocks or None
        The reduced model the scene's geometry maps to, also when its physics (friction)
        rules it out, so that it can be forced; None when the geometry has none.
    """

    kind: str
    reasons: list[str]
    limits: list[str]
    reduced: Any = None

    def __str__(self) -> str:
        lines = [f"model: {self.kind}", "reasons:"] + [f"  - {r}" for r in self.reasons]
        return "\n".join(lines + ["limits:"] + [f"  - {x}" for x in self.limits])


@dataclass(frozen=True)
class AssumptionCheck:
    """One assumption checked on a reduced model's history.

    Attributes
    ----------
    name : str
        e.g. "no sliding at the base".
    ok : bool
    worst_time : float
        s, where the margin is smallest (nan if never loaded).
    margin : float
        Smallest margin (given minus needed friction coefficient; normal force in N for lift-off).
    message : str
    """

    name: str
    ok: bool
    worst_time: float
    margin: float
    message: str


# --------------------------------------------------------------------------- scene reading
@dataclass(frozen=True)
class _Block:
    body: Any
    width: float      # along the shaking direction, m
    height: float     # m
    x: float          # centre along the shaking direction when upright on its pivot, m
    bottom: float     # height of the lowest point (the base face, or the pivot corner if tilted), m
    angle: float = 0.0  # initial tilt (2D), rad, CCW positive


def _rectangle(body, dim: int, axis: int) -> tuple[float, float] | None:
    """(extent along ``axis``, height) of an axis-aligned box body at its initial pose, else None."""
    verts = np.asarray(body.shape.vertices, float)
    if dim == 2:
        if len(verts) != 4:
            return None
    else:
        if len(verts) != 8 or not np.allclose(body.q0[3:], (1.0, 0.0, 0.0, 0.0), atol=1e-12):
            return None
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    size = hi - lo
    corners = np.abs(np.abs(verts - 0.5 * (lo + hi)) - 0.5 * size)
    if np.max(corners) > _GEOMETRY_TOL * max(size):
        return None
    return float(size[axis]), float(size[dim - 1])


def _peak(motion: Motion | None, horizon: float) -> tuple[float, float]:
    """(``max |a|``, ``min a``) in m/s^2 of a motion over [0, horizon], sampled."""
    if motion is None:
        return 0.0, 0.0
    end = min(horizon, motion.duration) if math.isfinite(motion.duration) else horizon
    ts = np.linspace(0.0, max(end, 1e-9), _SCAN_POINTS)
    a = np.asarray(motion.acceleration(ts), float)
    return float(np.max(np.abs(a))), float(np.min(a))


def _ground(scene: Scene, base) -> tuple[Motion | None, Motion | None, Motion | None]:
    """(horizontal motion along the reduced models' +x, vertical motion, out-of-plane motion) of a base.

    The horizontal motion is the base's along the block axis it shakes (its sign and, in 2D,
    ``cos`` of its angle out of the plane included); the out-of-plane one, 2D only, is
    ``sin`` of that angle times the motion (None when the base moves in its plane).
    """
    motion = base.motion
    if motion is None:
        return None, base.vertical, None
    axis = 0 if scene.dim == 2 else int(np.argmax(np.abs(base.direction[:2])))
    factor = float(base.direction[axis])
    in_plane = motion if factor == 1.0 else Scaled(motion, factor)
    out = Scaled(motion, base.out_of_plane) if base.out_of_plane else None
    return in_plane, base.vertical, out


def _moves_out_of_plane(scene: Scene) -> bool:
    """A 2D scene whose driven base has a motion component perpendicular to the plane."""
    return any(b.out_of_plane and b.motion is not None for b in scene.bodies)


def _reduce(scene: Scene, horizon: float):
    """Read the scene: (base, blocks ordered bottom up, reasons against a reduced model)."""
    against = []
    bases = [b for b in scene.bodies if not b.is_dynamic]
    blocks = scene.dynamic_bodies
    if len(bases) != 1:
        against.append(f"{len(bases)} fixed or driven bodies (a reduced model has one base)")
        return None, [], against
    base = bases[0]
    axis = 0
    if scene.dim == 3:
        direction = np.asarray(base.direction, float)
        if base.motion is not None and abs(direction[0]) < 1.0 - 1e-12:
            if abs(direction[1]) >= 1.0 - 1e-12:
                axis = 1
            else:
                against.append(f"base motion direction {direction.tolist()} is not along a block axis: "
                               "out-of-plane excitation")
                return base, [], against
    base_box = _rectangle(base, scene.dim, axis)
    if base_box is None:
        against.append(f"base {base.name!r} is not an axis-aligned box")
        return base, [], against
    top_of_base = float(base.q0[scene.dim - 1] + 0.5 * base_box[1])
    found = []
    for body in blocks:
        rect = _rectangle(body, scene.dim, axis)
        if rect is None:
            against.append(f"block {body.name!r} is not an axis-aligned rectangular block at rest orientation")
            return base, [], against
        if np.any(body.v0 != 0.0):
            against.append(f"block {body.name!r} starts moving (velocity {body.v0.tolist()})")
            return base, [], against
        tilt = float(body.q0[2]) if scene.dim == 2 else 0.0
        if tilt:  # released from a tilt: standing on the corner of the side of the tilt
            if len(blocks) != 1 or not abs(tilt) < 0.5 * math.pi:
                against.append(f"block {body.name!r} starts tilted ({tilt:g} rad) in a stack")
                return base, [], against
            c, s_ = math.cos(tilt), math.sin(tilt)
            v = np.asarray(body.shape.vertices, float)
            world = np.column_stack([c * v[:, 0] - s_ * v[:, 1], s_ * v[:, 0] + c * v[:, 1]]) + body.q0[:2]
            low = int(np.argmin(world[:, 1]))
            side = 1.0 if tilt > 0 else -1.0
            found.append(_Block(body, rect[0], rect[1], float(world[low, 0] + side * rect[0] / 2),
                                float(world[low, 1]), tilt))
            continue
        found.append(_Block(body, rect[0], rect[1], float(body.q0[axis]),
                            float(body.q0[scene.dim - 1] - 0.5 * rect[1])))
    found.sort(key=lambda b: b.bottom)
    half_base = 0.5 * base_box[0]
    for blk in found[:1]:
        if abs(blk.x - base.q0[axis]) + 0.5 * blk.width > half_base * (1 + 1e-12):
            against.append(f"block {blk.body.name!r} overhangs the base's top face")
            return base, [], against
    below = top_of_base
    for blk in found:
        if abs(blk.bottom - below) > _GEOMETRY_TOL * max(1.0, blk.height) + 1e-9:
            against.append(f"block {blk.body.name!r} does not stand flat on the body below "
                           f"(its base at {blk.bottom:.6g} m, the face below at {below:.6g} m)")
            return base, [], against
        below = blk.bottom + blk.height
    return base, found, against


def choose_model(scene: Scene, t_end: float | None = None) -> ModelChoice:
    """The smallest model adequate for ``scene``, with the checks that justify it.

    Parameters
    ----------
    scene : Scene
    t_end : float, optional
        Duration in s the scene will be run for (the horizon over which the motion's
        peaks are read; default the motion's duration, or 60 s).

    Returns
    -------
    ModelChoice
        ``"housner"``: one rectangular block on a rigid base whose friction rules out
        sliding at the onset of rocking (Shenton), restitution 0, no lift-off by the
        vertical motion; ``"stacked"``: two such blocks one on the other;
        ``"2d"``: any other planar scene (driven in its plane); ``"3d"``: any other 3D scene.
    """
    if not isinstance(scene, Scene):
        raise TypeError(f"scene must be an nscd.Scene, got {type(scene).__name__}.")
    base, blocks, against = _reduce(scene, t_end or 60.0)
    engine = "2d" if scene.dim == 2 and not _moves_out_of_plane(scene) else "3d"
    g = scene.gravity
    if not against and len(blocks) not in (1, 2):
        against.append(f"{len(blocks)} blocks (the reduced models hold one or two)")
    if against:
        return ModelChoice(engine, [f"not reducible: {a}" for a in against] + [_engine_reason(scene)],
                           _engine_limits(scene))
    motion, vertical, out_of_plane = _ground(scene, base)
    horizon = t_end if t_end is not None else (
        max([m.duration for m in (motion, vertical) if m is not None and math.isfinite(m.duration)] or [60.0]))
    a_peak, _ = _peak(motion, horizon)
    _, av_min = _peak(vertical, horizon)
    reasons, limits = [], []
    if av_min <= -g:
        return ModelChoice(engine, [f"vertical base acceleration reaches {av_min:.4g} m/s^2 <= -g = {-g:.4g}: "
                                    "the blocks lift off the base (free flight, bouncing)", _engine_reason(scene)],
                           _engine_limits(scene))
    if vertical is not None:
        reasons.append(f"vertical base acceleration >= {av_min:.4g} m/s^2 > -g: the base stays loaded")
    limits.append("a vertical base acceleration reaching -g lifts the blocks off (free flight)")
    pairs = [(base, blocks[0].body)] + ([(blocks[0].body, blocks[1].body)] if len(blocks) == 2 else [])
    laws = [scene.contact_law(a, b) for a, b in pairs]
    bouncy = [(a.name, b.name, law.restitution) for (a, b), law in zip(pairs, laws) if law.restitution > 0]
    if bouncy:
        a, b, e = bouncy[0]
        return ModelChoice(engine, [f"restitution {e} > 0 between {a!r} and {b!r}: the reduced models' impacts "
                                    "are plastic (no bounce)", _engine_reason(scene)], _engine_limits(scene))
    reasons.append("plastic impacts (restitution 0 at every contact), as the reduced models assume")
    if len(blocks) == 1:
        choice = _choose_single(scene, base, blocks[0], laws[0], a_peak, motion, horizon, reasons, limits, engine)
    else:
        choice = _choose_stacked(scene, base, blocks, laws, a_peak, reasons, limits, engine)
    if out_of_plane is None or choice.kind not in ("housner", "stacked"):
        return choice
    return _weigh_out_of_plane(choice, scene, blocks, laws, _peak(out_of_plane, horizon)[0], av_min)


def _out_of_plane_arms(blocks: list) -> list[tuple[str, float, float, float]]:
    """Per interface, bottom up: (name, mass above in kg, first moment of that mass about the interface
    in kg m at rest, half depth of the contact in m; nan if a depth is not given)."""
    low = blocks[0]
    heights = [b.bottom + 0.5 * b.height - low.bottom for b in blocks]
    arms = [("at the base", sum(b.body.mass for b in blocks),
             sum(b.body.mass * y for b, y in zip(blocks, heights)), 0.5 * low.body.depth)]
    if len(blocks) == 2:
        top = blocks[1]
        arms.append(("at the joint", top.body.mass, top.body.mass * 0.5 * top.height,
                     0.5 * min(low.body.depth, top.body.depth)))
    return arms


def _weigh_out_of_plane(choice: ModelChoice, scene: Scene, blocks, laws, az_peak: float, av_min: float) -> ModelChoice:
    """Keep a reduced model for a 2D scene shaken out of its plane only if, at rest, the out-of-plane
    acceleration neither tips nor slides the blocks out of the plane.

    Tipping: Housner's static uplift criterion (seed ``000_b03963299c8d30d2.txt`` lines 492-495,
    ``a > g tan(alpha)``) about the contact's edge across the plane: ``|a_z| sum m_i y_i > (g + a_v)
    M b_z``, with ``b_z`` the contact's half depth and ``y_i`` the centroids' heights above it.
    Sliding: ``|a_z| > mu (g + a_v)``. Both with the smallest ``g + a_v`` of the run.
    """
    g_eff = scene.gravity + min(av_min, 0.0)
    missing = [b.body.name for b in blocks if not math.isfinite(b.body.depth)]
    failed = None
    if missing:
        failed = (f"the base moves out of the plane (peak {az_peak:.4g} m/s^2) and block {missing[0]!r} has no "
                  "depth (Scene.add_block(depth=...)): the out-of-plane demand cannot be weighed")
    thresholds = []
    for (name, mass, moment, half_depth), law in zip(_out_of_plane_arms(blocks), laws):
        if failed:
            break
        tip = g_eff * mass * half_depth / moment
        thresholds.append(f"{name}: tips at {tip:.4g}, slides at mu (g + a_v) = {law.friction * g_eff:.4g}")
        if az_peak > tip:
            failed = (f"out-of-plane base acceleration peak {az_peak:.4g} m/s^2 > {tip:.4g} m/s^2 = (g + a_v) M b_z / "
                      f"sum(m y) {name} (Housner's uplift criterion across the plane): the blocks rock out of plane")
        elif az_peak > law.friction * g_eff:
            failed = (f"out-of-plane base acceleration peak {az_peak:.4g} m/s^2 > mu (g + a_v) = "
                      f"{law.friction * g_eff:.4g} m/s^2 {name}: the blocks slide out of plane")
    if failed:
        return ModelChoice("3d", [failed, _engine_reason(scene)], _engine_limits(scene), choice.reduced)
    reasons = choice.reasons + [f"out-of-plane base acceleration peak {az_peak:.4g} m/s^2 below the static "
                                "out-of-plane thresholds (m/s^2; " + "; ".join(thresholds) + ")"]
    limits = choice.limits + ["an out-of-plane demand above the restoring moment of the contact's depth, or "
                              "a combined in- and out-of-plane friction demand above mu (checked after the run)"]
    return ModelChoice(choice.kind, reasons, limits, choice.reduced)


def _engine_reason(scene: Scene) -> str:
    if _moves_out_of_plane(scene):
        return "a planar scene whose base also moves out of its plane: the 3D engine on the extruded scene"
    if scene.dim == 2:
        return "a planar scene driven in its plane: the 2D engine"
    return "a 3D scene (out-of-plane excitation, torsion or an asymmetric plan possible): the 3D engine"


def _engine_limits(scene: Scene) -> list[str]:
    if scene.dim == 2 and not _moves_out_of_plane(scene):
        return ["out-of-plane motion is not represented (run model='3d' on the extruded scene to see it)"]
    return []


def _choose_single(scene, base, blk, law, a_peak, motion, horizon, reasons, limits, engine) -> ModelChoice:
    g, mu = scene.gravity, law.friction
    housner = HousnerBlock(blk.width, blk.height, g=g)
    tan_a = math.tan(housner.alpha)
    onset = housner.onset_acceleration
    if a_peak > onset:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            needed = housner.check_sliding(mu, motion, t_end=horizon) if motion is not None else tan_a
        needed = tan_a if math.isnan(needed) else needed
        what = (f"friction {mu:g} >= {needed:.4g} needed for pure rocking at the onset "
                f"(Shenton; peak base acceleration {a_peak:.4g} m/s^2 > onset g tan(alpha) = {onset:.4g} m/s^2)")
        if mu < needed:
            return ModelChoice(engine, [f"friction {mu:g} < {needed:.4g} needed for pure rocking at the onset "
                                        f"(Shenton, alpha = {housner.alpha:.4g} rad, peak base acceleration "
                                        f"{a_peak:.4g} m/s^2): the block slides or slide-rocks",
                                        _engine_reason(scene)], _engine_limits(scene), housner)
    else:
        needed = a_peak / g
        what = (f"no rocking onset: peak base acceleration {a_peak:.4g} m/s^2 <= g tan(alpha) = {onset:.4g} m/s^2, "
                f"and friction {mu:g} >= peak / g = {needed:.4g} (no sliding)")
        if mu < needed:
            return ModelChoice(engine, [f"friction {mu:g} < peak base acceleration / g = {needed:.4g}: the block "
                                        "slides without rocking", _engine_reason(scene)], _engine_limits(scene),
                               housner)
    reasons = [f"one rectangular block {blk.width:g} x {blk.height:g} m (alpha = {housner.alpha:.4g} rad, "
               f"p = {housner.p:.4g} rad/s) standing on a rigid base", what] + reasons
    limits = [f"a base acceleration above the sliding threshold mu g = {mu * g:.4g} m/s^2 while the block "
              f"rests (mu < tan(alpha) = {tan_a:.4g} slides before it rocks)",
              f"a friction demand above mu = {mu:g} during rocking or at an impact (checked after the run)",
              "a negative normal force at the pivot (lift-off; checked after the run)"] + limits
    return ModelChoice("housner", reasons, limits, housner)


def _choose_stacked(scene, base, blocks, laws, a_peak, reasons, limits, engine) -> ModelChoice:
    g = scene.gravity
    low, high = blocks
    offset = high.x - low.x
    if high.width / 2 + abs(offset) > low.width / 2 * (1 + 1e-12):
        return ModelChoice(engine, [f"the top block {high.body.name!r} overhangs the bottom one "
                                    f"(half width {high.width / 2:g} m + offset {abs(offset):g} m > "
                                    f"{low.width / 2:g} m): its pivots are not on the bottom's top face",
                                    _engine_reason(scene)], _engine_limits(scene))
    stack = StackedBlocks((low.width, low.height), (high.width, high.height),
                          bottom_mass=low.body.mass, top_mass=high.body.mass, offset=offset, g=g)
    onsets = stack.onset_accelerations()
    first = min(onsets["one body"][0], -onsets["one body"][1], onsets["top alone"][0])
    # before any rocking both interfaces carry T / N = a / g (the stack moves with the base)
    level = min(a_peak, first) / g
    for (a, b), law in zip([(base, low.body), (low.body, high.body)], laws):
        if law.friction < level:
            return ModelChoice(engine, [f"friction {law.friction:g} between {a.name!r} and {b.name!r} < {level:.4g} "
                                        f"= min(peak base acceleration {a_peak:.4g}, first rocking onset "
                                        f"{first:.4g} m/s^2) / g: the joint slides before it rocks",
                                        _engine_reason(scene)], _engine_limits(scene), stack)
    reasons = [f"two rectangular blocks, {low.width:g} x {low.height:g} m under {high.width:g} x {high.height:g} m "
               f"(offset {offset:g} m), on a rigid base",
               f"static onsets: one body at {onsets['one body'][0]:.4g} / {-onsets['one body'][1]:.4g} m/s^2, "
               f"top alone at {onsets['top alone'][0]:.4g} m/s^2; peak base acceleration {a_peak:.4g} m/s^2",
               f"friction base {laws[0].friction:g}, joint {laws[1].friction:g} >= {level:.4g} needed before "
               "the onset (no sliding at the start)"] + reasons
    limits = [f"a base acceleration above mu g ({laws[0].friction * g:.4g} m/s^2 at the base, "
              f"{laws[1].friction * g:.4g} m/s^2 at the joint) before the stack rocks: it slides",
              "a friction demand above mu at the base or at the joint during rocking or at an impact, "
              "the stack sliding at its joint (checked after the run)",
              "a negative normal force at either interface (lift-off of the top block; checked after the run)"] + limits
    return ModelChoice("stacked", reasons, limits, stack)


# --------------------------------------------------------------------------- results
@dataclass
class ReducedResult:
    """The result of a reduced model in the interface of :class:`nscd.Result` (2D accessors).

    Attributes
    ----------
    model : str
        "housner" or "stacked".
    time : ndarray, shape (n,)
        s (an event time appears twice: before and after the jump).
    body_names : list of str
        The scene's bodies (base included, as in :class:`nscd.Result`).
    impacts : dict of ndarray
        ``time`` (s), ``body_a``, ``body_b`` (indices of the body below and above the
        closing interface), ``impulse`` ((k, 2) N s on the upper body: tangential, normal).
    report : dict
        ``model``, ``wall_time`` (s), ``choice`` (the :class:`ModelChoice`), ``checks``
        (list of :class:`AssumptionCheck`), ``verification`` (dict, with ``verify=True``).
    choice : ModelChoice
    checks : list of AssumptionCheck
    raw : RockingResult or StackedResult
        The reduced model's own result.
    """

    model: str
    time: np.ndarray
    body_names: list
    impacts: dict
    report: dict
    choice: ModelChoice
    raw: Any
    checks: list = field(default_factory=list)
    dim: int = 2
    _angles: dict = field(default_factory=dict, repr=False)
    _omegas: dict = field(default_factory=dict, repr=False)
    _positions: dict = field(default_factory=dict, repr=False)

    @property
    def violations(self) -> list[AssumptionCheck]:
        """The failed assumption checks (empty when the reduced model stayed valid)."""
        return [c for c in self.checks if not c.ok]

    def _name(self, body) -> str:
        name = body if isinstance(body, str) else self.body_names[body if isinstance(body, (int, np.integer))
                                                                  else body.index]
        if name not in self.body_names:
            raise ValueError(f"no body named {name!r}; bodies are {self.body_names}.")
        return name

    def angle(self, body) -> np.ndarray:
        """Rotation angle in rad, CCW positive (the engine's convention), shape (n,)."""
        name = self._name(body)
        return self._angles.get(name, np.zeros(len(self.time)))

    rotation = angle

    def omega(self, body) -> np.ndarray:
        """Angular velocity in rad/s, CCW positive, shape (n,)."""
        name = self._name(body)
        return self._omegas.get(name, np.zeros(len(self.time)))

    def position(self, body) -> np.ndarray:
        """Centre-of-mass position in m in the scene's plane, shape (n, 2) (the base follows its motion)."""
        return self._positions[self._name(body)]

    def overturned(self, body, angle: float | None = None) -> bool:
        """Rotated at some time by more than ``angle`` (default :data:`nscd.result.OVERTURN_ANGLE`), as :meth:`nscd.Result.overturned`.

        A single block the Housner model found certain to overturn after the excitation
        (its energy criterion) also counts.
        """
        limit = OVERTURN_ANGLE if angle is None else float(angle)
        decided = self.model == "housner" and angle is None and bool(self.raw.overturned)
        return decided or bool(np.max(np.abs(self.angle(body))) > limit)


def _housner_result(scene, choice, t_end, dt_out) -> ReducedResult:
    base, (blk,), _ = _reduce(scene, t_end)
    block: HousnerBlock = choice.reduced
    motion, vertical, _ = _ground(scene, base)
    raw = block.simulate(motion, t_end, vertical=vertical, dt_out=dt_out, theta0=-blk.angle)
    names = [b.name for b in scene.bodies]
    phi, dphi = -raw.theta, -raw.theta_dot
    side = np.where(phi > 0, 1.0, np.where(phi < 0, -1.0, np.sign(dphi)))
    b, h = block.b, block.h
    ux, uy = side * b, h
    c, s = np.cos(phi), np.sin(phi)
    shift = np.zeros_like(phi) if motion is None else np.asarray(motion.displacement(raw.time), float)
    lift = np.zeros_like(phi) if vertical is None else np.asarray(vertical.displacement(raw.time), float)
    top_of_base = blk.bottom
    x = blk.x + shift - side * b + c * ux - s * uy
    y = top_of_base + lift + s * ux + c * uy
    positions = {blk.body.name: np.column_stack([x, y]),
                 base.name: np.column_stack([base.q0[0] + shift, base.q0[1] + lift])}
    impacts = {"time": raw.impacts.time, "body_a": np.full(len(raw.impacts), base.index),
               "body_b": np.full(len(raw.impacts), blk.body.index),
               "impulse": _housner_impulses(block, blk.body.mass, raw.impacts.theta_dot_before,
                                            raw.impacts.theta_dot_after)}
    return ReducedResult("housner", raw.time, names, impacts, {}, choice, raw,
                         _angles={blk.body.name: phi}, _omegas={blk.body.name: dphi}, _positions=positions)


def _housner_impulses(block: HousnerBlock, mass: float, before: np.ndarray, after: np.ndarray) -> np.ndarray:
    """Impulse (tangential, normal) in N s on the block at each impact: mass times its centre's velocity jump.

    Just before, the block turns about the corner it leaves (engine angle sign k, rate
    w-), after about the other one (rate w+): v_G = w E (k b, h) before, w E (-k b, h) after.
    """
    out = np.zeros((len(before), 2))
    for i, (wb, wa) in enumerate(zip(-np.asarray(before), -np.asarray(after))):
        k = -np.sign(wb) if wb else 1.0  # returning toward 0: the angle has the sign opposite to the rate
        vb = wb * np.array([-block.h, k * block.b])
        va = wa * np.array([-block.h, -k * block.b])
        out[i] = mass * (va - vb)
    return out


def _stacked_result(scene, choice, t_end, dt_out) -> ReducedResult:
    base, (low, high), _ = _reduce(scene, t_end)
    stack: StackedBlocks = choice.reduced
    motion, vertical, _ = _ground(scene, base)
    raw = stack.simulate(motion, t_end, vertical=vertical, dt_out=dt_out)
    names = [b.name for b in scene.bodies]
    shift = np.zeros(len(raw.time)) if motion is None else np.asarray(motion.displacement(raw.time), float)
    lift = np.zeros(len(raw.time)) if vertical is None else np.asarray(vertical.displacement(raw.time), float)
    centroids = raw.centroids()
    c1, c2 = centroids[:, :2], centroids[:, 2:]
    origin = np.column_stack([low.x + shift, low.bottom + lift])
    interface = raw.impacts["interface"]
    impacts = {"time": raw.impacts["time"],
               "body_a": np.where(interface == 0, base.index, low.body.index),
               "body_b": np.where(interface == 0, low.body.index, high.body.index),
               "impulse": np.where(interface[:, None] == 0, raw.impacts["impulse_base"],
                                   raw.impacts["impulse_joint"])}
    positions = {low.body.name: origin + c1, high.body.name: origin + c2,
                 base.name: np.column_stack([base.q0[0] + shift, base.q0[1] + lift])}
    return ReducedResult("stacked", raw.time, names, impacts, {}, choice, raw,
                         _angles={low.body.name: raw.phi[:, 0], high.body.name: raw.phi[:, 1]},
                         _omegas={low.body.name: raw.phi_dot[:, 0], high.body.name: raw.phi_dot[:, 1]},
                         _positions=positions)


# --------------------------------------------------------------------------- assumption checks
#: m/s: an impact whose tangential impulse exceeds mu times its normal impulse by less than this
#: velocity change of the bodies above the contact is not counted as sliding. The last, absorbed
#: bounces of a Zeno sequence stop a corner at once and need a large impulse ratio, but the slip
#: they start is stopped by friction within v^2 / (2 mu g) < 1e-5 m at mu >= 0.5.
SLIP_VELOCITY_TOL = 1e-2


def _friction_check(name, time, tangential, normal, mu, impulses, mass_above) -> list[AssumptionCheck]:
    """No sliding (``|T| <= mu N``) and no lift-off (``N >= 0``) over a history of contact forces (N) and impulses (N s)."""
    checks = []
    tangential, normal = np.asarray(tangential, float), np.asarray(normal, float)
    scale = max(float(np.max(np.abs(normal))), 1e-300)
    loaded = normal > 1e-9 * scale
    i_low = int(np.argmin(normal))
    lift_ok = bool(normal[i_low] >= -1e-9 * scale)
    checks.append(AssumptionCheck(
        f"no lift-off {name}", lift_ok, float(time[i_low]), float(normal[i_low]),
        f"smallest normal force {name} {normal[i_low]:.4g} N at t = {time[i_low]:.6g} s"
        + ("" if lift_ok else ": the contact would pull (lift-off/bouncing); the reduced model does not apply")))
    demand = np.where(loaded, np.abs(tangential) / np.where(loaded, normal, 1.0), 0.0)
    i = int(np.argmax(demand))
    worst, t_worst = float(demand[i]), float(time[i])
    ok = worst <= mu
    message = (f"largest friction demand {name} {worst:.4g} at t = {t_worst:.6g} s against mu = {mu:g}: "
               f"margin {mu - worst:.4g}")
    t_imp, imp = impulses
    if len(t_imp):
        excess = (np.abs(imp[:, 0]) - mu * np.maximum(imp[:, 1], 0.0)) / mass_above  # m/s of slip
        j = int(np.argmax(excess))
        message += f"; at impacts the largest slip the friction cannot stop is {max(excess[j], 0.0):.3g} m/s " \
                   f"(t = {t_imp[j]:.6g} s, tolerance {SLIP_VELOCITY_TOL:g} m/s)"
        if excess[j] > SLIP_VELOCITY_TOL and ok:
            ok, t_worst = False, float(t_imp[j])
    if not ok:
        message += "; the contact slides and the reduced model does not apply"
    checks.append(AssumptionCheck(f"no sliding {name}", ok, t_worst, mu - worst, message))
    return checks


def _out_of_plane_check(name, time, normal, first_moment, half_depth, az, body) -> AssumptionCheck:
    """No rocking out of the plane over a history: ``|a_z| sum m_i y_i <= N b_z`` at every loaded instant.

    The moment balance of seed ``000_b03963299c8d30d2.txt`` eqs. 2-2..2-4 taken about the
    contact's edge across the plane: the inertial force of the out-of-plane ground
    acceleration ``a_z`` at the centroids' heights ``y_i`` above the contact against the
    normal force ``N`` (from the in-plane motion: it includes the vertical ground acceleration
    and the rocking) at the contact's half depth ``b_z``. At rest it is Housner's uplift
    criterion ``|a_z| > g b_z / h`` (000 lines 492-495) across the plane.
    """
    check = f"no rocking out of the plane {name}"
    if not math.isfinite(half_depth):
        return AssumptionCheck(check, False, math.nan, math.nan,
                               f"block {body!r} has no depth (Scene.add_block(depth=...)): the out-of-plane rocking "
                               f"{name} cannot be checked while the base moves out of the plane")
    normal = np.asarray(normal, float)
    loaded = normal > 1e-9 * max(float(np.max(np.abs(normal))), 1e-300)
    demand = np.where(loaded, np.abs(az) * first_moment / np.where(loaded, normal * half_depth, 1.0), 0.0)
    i = int(np.argmax(demand))
    worst = float(demand[i])
    ok = worst <= 1.0
    message = (f"largest out-of-plane overturning demand {name} |a_z| sum(m y) / (N b_z) = {worst:.4g} at "
               f"t = {time[i]:.6g} s (a_z = {az[i]:.4g} m/s^2, b_z = {half_depth:g} m): margin {1.0 - worst:.4g}")
    if not ok:
        message += "; the blocks rock out of the plane and the planar model does not apply"
    return AssumptionCheck(check, ok, float(time[i]), 1.0 - worst, message)


def check_assumptions(result: ReducedResult, scene: Scene) -> list[AssumptionCheck]:
    """Check a reduced model's assumptions on its own history; warn on each violation.

    Friction: at each sample (up to the instant an overturning block passes its
    slenderness for the last time) the contact force follows from Newton's law for each block
    (``F = m (a_G - g_eff)``), its tangential over normal component is the friction the
    motion needs; at each impact the impulse's ratio likewise. Lift-off: the normal force
    must stay >= 0. Out of the plane (a 2D scene whose base moves out of its plane,
    ``Scene.add_base(out_of_plane_angle=...)``): the friction demand is that of the resultant
    of the in-plane force and the out-of-plane one ``m a_z`` (Coulomb's isotropic cone), and
    the out-of-plane overturning demand (:func:`_out_of_plane_check`) must stay <= 1 at
    each interface, with the blocks' depths (``Scene.add_block(depth=...)``).
    """
    base, blocks, _ = _reduce(scene, float(result.time[-1]) if len(result.time) else 0.0)
    motion, vertical, out_of_plane = _ground(scene, base)
    # a block that overturns is falling once its rotation passes its slenderness for the last time
    # (a corner lifting or slipping as it falls changes nothing): check up to that instant
    upto = np.ones(len(result.time), bool)
    if result.raw.overturned:
        if result.model == "housner":
            standing = np.abs(result.raw.theta) <= result.raw.block.alpha
        else:
            stack = result.raw.stack
            standing = ((np.abs(result.raw.phi[:, 0]) <= math.atan2(stack.b1, stack.h1))
                        & (np.abs(result.raw.phi[:, 1] - result.raw.phi[:, 0]) <= math.atan2(stack.b2, stack.h2)))
        upto[np.flatnonzero(standing)[-1] + 1:] = False
    t = result.time
    az = None if out_of_plane is None else np.asarray(out_of_plane.acceleration(t), float)[upto]
    imp_t, imp = result.impacts["time"], np.asarray(result.impacts["impulse"], float).reshape(-1, 2)
    arms = _out_of_plane_arms(blocks)
    if result.model == "housner":
        blk = blocks[0]
        block: HousnerBlock = result.raw.block
        ag = np.zeros(len(t)) if motion is None else np.asarray(motion.acceleration(t), float)
        av = np.zeros(len(t)) if vertical is None else np.asarray(vertical.acceleration(t), float)
        m = blk.body.mass
        fx, fy, height = block.contact_forces(m, result.raw.theta, result.raw.theta_dot, ag, av)
        mu = scene.contact_law(base, blk.body).friction
        fx, fy, t = fx[upto], fy[upto], t[upto]
        tangential = fx if az is None else np.hypot(fx, m * az)
        checks = _friction_check("at the base", t, tangential, fy, mu, (imp_t, imp), m)
        if az is not None:
            checks.append(_out_of_plane_check("at the base", t, fy, m * height[upto], arms[0][3], az, blk.body.name))
    else:
        forces = result.raw.contact_forces()[upto]
        t = t[upto]
        low, high = blocks
        mu_b = scene.contact_law(base, low.body).friction
        mu_j = scene.contact_law(low.body, high.body).friction
        at = result.impacts["body_a"] == base.index
        m1, m2 = low.body.mass, high.body.mass
        t_base, t_joint = forces[:, 0], forces[:, 2]
        if az is not None:
            t_base, t_joint = np.hypot(t_base, (m1 + m2) * az), np.hypot(t_joint, m2 * az)
        checks = (_friction_check("at the base", t, t_base, forces[:, 1], mu_b, (imp_t[at], imp[at]), m1 + m2)
                  + _friction_check("at the joint", t, t_joint, forces[:, 3], mu_j, (imp_t[~at], imp[~at]), m2))
        if az is not None:
            # heights of the centroids above the base, and of the top one above the joint (along the
            # bottom block's axis: its top face is the joint's plane)
            floor = low.bottom + (0.0 if vertical is None else np.asarray(vertical.displacement(t), float))
            c1, c2 = result.position(low.body.name)[upto], result.position(high.body.name)[upto]
            phi1 = result.angle(low.body.name)[upto]
            above_joint = (-(c2[:, 0] - c1[:, 0]) * np.sin(phi1) + (c2[:, 1] - c1[:, 1]) * np.cos(phi1)
                           - 0.5 * low.height)
            checks += [_out_of_plane_check("at the base", t, forces[:, 1],
                                           m1 * (c1[:, 1] - floor) + m2 * (c2[:, 1] - floor), arms[0][3], az,
                                           low.body.name),
                       _out_of_plane_check("at the joint", t, forces[:, 3], m2 * above_joint, arms[1][3], az,
                                           high.body.name if math.isfinite(low.body.depth) else low.body.name)]
    for check in checks:
        if not check.ok:
            warnings.warn(f"{result.model} model: {check.message}", AssumptionWarning, stacklevel=3)
    return checks


# --------------------------------------------------------------------------- running
def extrude(scene: Scene, depth: float | None = None) -> Scene:
    """The 3D scene of a 2D one: each polygon extruded along the depth (3D y), 2D y -> 3D z.

    Parameters
    ----------
    scene : Scene
        A 2D scene.
    depth : float, optional
        Extrusion depth in m of the bodies that do not give their own (``Scene.add_block(depth=...)``;
        default half the largest extent of the blocks). Densities are kept, so masses scale
        with the depth; the motion keeps its direction: in-plane along x, out of the plane
        (``Scene.add_base(out_of_plane_angle=...)``) along y; vertical along z.
    """
    from nscd.shapes3d import polyhedron

    if scene.dim != 2:
        raise ValueError(f"extrude takes a 2D scene, got dim == {scene.dim}.")
    blocks = scene.dynamic_bodies
    if depth is None:
        depth = 0.5 * max(max(np.ptp(b.shape.vertices, axis=0)) for b in blocks) if blocks else 1.0
    if not (math.isfinite(depth) and depth > 0):
        raise ValueError(f"depth == {depth}, must be > 0 m.")
    out = Scene(dim=3, gravity=scene.gravity)

    def solid(body):
        v = np.asarray(body.shape.vertices, float)
        d = body.depth if math.isfinite(body.depth) else depth
        return polyhedron([(x, y, z) for x, z in v for y in (-d / 2, d / 2)])

    for body in scene.bodies:
        x, y, angle = body.q0
        pose = dict(position=(x, 0.0, y), orientation=(math.cos(angle / 2), 0.0, -math.sin(angle / 2), 0.0),
                    material=body.material, name=body.name)
        if body.is_dynamic:
            vx, vy, w = body.v0
            out.add_block(solid(body), density=body.density, velocity=(vx, 0.0, vy), omega=(0.0, -w, 0.0),
                          **pose)
        else:
            out.add_base(solid(body), motion=body.motion, vertical=body.vertical,
                         direction=(body.direction[0], body.out_of_plane, 0.0), **pose)
    out.default_contact = scene.default_contact
    out._material_laws = dict(scene._material_laws)
    out._body_laws = dict(scene._body_laws)
    return out


_NEXT = {"housner": "2d", "stacked": "2d", "2d": "3d"}


def run(scene: Scene, t_end: float, dt: float | None = None, model: str = "auto", *, verify: bool = False,
        dt_out: float | None = None, **engine_options) -> Any:
    """Run ``scene`` with ``model`` and return a result with ``.model`` saying which ran.

    Parameters
    ----------
    scene : Scene
    t_end : float
        End time in s.
    dt : float, optional
        The engine's time step in s (required when an engine runs, also for ``verify``).
    model : {"auto", "housner", "stacked", "2d", "3d"}
        "auto": :func:`choose_model`'s choice; a forced model the scene cannot represent
        raises ``ValueError`` naming the model and why.
    verify : bool
        Also run the next larger model (housner/stacked -> 2d -> 3d) and report the
        difference in outcome in ``result.report["verification"]`` (reduced models) or
        ``result.verification`` (engine results).
    dt_out : float, optional
        Output step of a reduced model in s (default min(1 ms, t_end / 2000)).
    **engine_options
        Passed to :func:`nscd.stepper.simulate` (``settings``, ``theta``, ``store_impulses``...).

    Returns
    -------
    ReducedResult or nscd.Result
        Both give ``time``, ``angle(body)`` (2D), ``position(body)``, ``overturned(body)``,
        ``impacts``, ``report`` and ``model``.
    """
    from nscd.stepper import simulate

    if model not in ("auto",) + MODELS:
        raise ValueError(f"model == {model!r}, must be one of 'auto', " + ", ".join(repr(m) for m in MODELS) + ".")
    choice = choose_model(scene, t_end)
    kind = choice.kind if model == "auto" else model
    wanted = {"housner": HousnerBlock, "stacked": StackedBlocks}.get(kind)
    if wanted is not None and choice.kind != kind:
        if not isinstance(choice.reduced, wanted):
            raise ValueError(f"model == {kind!r} cannot represent this scene: " + "; ".join(choice.reasons[:1])
                             + f" (the smallest adequate model is {choice.kind!r}).")
        warnings.warn(f"model == {kind!r} forced although " + "; ".join(choice.reasons[:1])
                      + ": its results are not to be trusted (see result.checks).", AssumptionWarning, stacklevel=2)
        choice = ModelChoice(kind, choice.reasons, choice.limits, choice.reduced)
    if kind == "2d" and scene.dim == 3:
        raise ValueError("model == '2d' cannot represent a 3D scene: nscd does not project 3D scenes to a plane; "
                         "use '3d' (or 'auto').")
    if kind == "2d" and _moves_out_of_plane(scene):
        warnings.warn("model == '2d': the base's motion out of the plane is not simulated (only its in-plane "
                      "component); model='3d' runs the extruded scene with it.", AssumptionWarning, stacklevel=2)
    if kind in ("2d", "3d"):
        if dt is None:
            raise ValueError(f"model == {kind!r} is the engine: give its time step dt (s).")
        target = extrude(scene) if kind == "3d" and scene.dim == 2 else scene
        result = simulate(target, t_end, dt, **engine_options)
        result.model = kind
        result.choice = choice
        if verify and kind == "2d":
            other = run(scene, t_end, dt, "3d", **engine_options)
            result.verification = _compare(result, other, scene)
        return result
    start = _time.perf_counter()
    out_step = dt_out or min(1e-3, t_end / 2000.0)
    if kind == "housner":
        result = _housner_result(scene, choice, t_end, out_step)
    else:
        result = _stacked_result(scene, choice, t_end, out_step)
    result.report = {"model": kind, "wall_time": _time.perf_counter() - start, "choice": choice}
    result.checks = check_assumptions(result, scene)
    result.report["checks"] = result.checks
    if verify:
        if dt is None:
            raise ValueError("verify=True reruns the engine: give its time step dt (s).")
        larger = run(scene, t_end, dt, _NEXT[kind], **engine_options)
        result.report["verification"] = _compare(result, larger, scene)
    return result


def _compare(small, large, scene: Scene) -> dict:
    """Outcome of two models side by side: overturned and peak rotation of each block, and their difference."""
    out = {"models": (small.model, large.model), "blocks": {}}
    for body in scene.dynamic_bodies:
        peak = []
        for res in (small, large):
            rot = res.rotation(body.name)
            peak.append(float(np.max(np.abs(rot))) if len(rot) else 0.0)
        over = (small.overturned(body.name), large.overturned(body.name))
        out["blocks"][body.name] = {
            "overturned": over, "peak_rotation": tuple(peak),
            "relative_difference": abs(peak[0] - peak[1]) / max(peak[1], 1e-12),
            "same_outcome": over[0] == over[1]}
    if scene.dim == 2 and len(scene.dynamic_bodies) == 2 and all(hasattr(r, "angle") for r in (small, large)) \
            and small.dim == large.dim == 2:
        a, b = (body.name for body in scene.dynamic_bodies)
        out["pattern"] = tuple(dominant_pattern(classify_patterns(r.time, r.angle(a), r.angle(b)))
                               for r in (small, large))
    out["same_outcome"] = all(v["same_outcome"] for v in out["blocks"].values())
    return out
