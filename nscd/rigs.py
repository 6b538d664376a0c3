"""The double-pulse rig of Čeh et al. (seed 002, "ROORI-1"): blocks on a sliding base.

The rig (002, lines 60-73, 86-90, 106, 257-264): an aluminium base (0.2 m long,
0.01 m thick) sliding on PTFE is launched by a projectile to a peak velocity
``v_peak``, slides freely (decelerated by friction ``mu_b``), hits a stopper after
travelling the stop gap ``BD`` (the reverse impulse) and slides back. On it stand
aluminium specimens: a single block 10 x 45 mm (scale 1) or 20 x 90 mm (scale 2),
or a stack of three blocks 10 x 15 mm (scale 1) or 20 x 30 mm (scale 2); restitution 0
(002, lines 106, 127, 197). Block friction: the experiments measured 0.54 between blocks and
on the base (002, line 73), but the paper's SOLFEC simulations adopted "a high coefficient
of friction ... to prevent inter block sliding" (002, line 106), without a value. The rig
follows the simulations by default (:data:`SIMULATED_FRICTION`); ``friction=0.54``
(:data:`MEASURED_FRICTION`) is the tests' surface.

Two models of the base:

``base="kinematic"``
    The base follows the closed-form :class:`DoublePulse` (the paper's SOLFEC
    simulations prescribe the base motion: constant acceleration over a rise time
    of 0.005 s up to ``v_peak``, 002 line 106).
``base="dynamic"``
    The base is a body (aluminium, 0.2 x 0.01 m) on a fixed PTFE floor with
    friction ``mu_b``; a driven pusher (the projectile) accelerates it uniformly
    to ``v_peak`` over the rise time and then withdraws, so the base slides
    freely, hits a fixed stopper at distance ``gap`` with Newton restitution
    ``stopper_restitution`` (an instantaneous impact, unlike the kinematic ramp)
    and slides back. The engine computes blocks and base together, so the blocks
    load the base (their mass is a tenth of the base's or more).

Direction convention (as the figures of 002, lines 285-303): the first impulse
pushes the base toward +x and the stopper stands at +x. "L" (left, -x) is the side
toward which the first impulse throws the blocks (they rock about their left,
trailing corner: counter-clockwise, angle > 0); "R" (right, +x) is the side of
the reverse impulse (clockwise, angle < 0).

Modes (002, lines 131-135 and 199-207): ``A`` everything stands; ``B_L``/``B_R``
the single block, or the top block of a stack, overturned; ``C_L``/``C_R`` the
two upper blocks; ``D_L``/``D_R`` the whole stack. The letter is decided by the
lowest overturned block and the side by its final tilt.
"""
from __future__ import annotations

import dataclasses
import math
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nscd._jit import njit
from nscd.convergence import SCHEMES, TimeStepCheck, verify_time_step
from nscd.motion import STANDARD_GRAVITY, ConstantAccelerationPhases, Motion
from nscd.result import OVERTURN_ANGLE

__all__ = [
    "DoublePulse", "DoublePulseRig", "Outcome", "EnsembleOutcome", "Perturbation",
    "MODES", "MEASURED_FRICTION", "SIMULATED_FRICTION", "MEASURED_MASS_RATIO", "classify", "housner_p",
]

#: Every mode a rig run can end in, in the order of the paper's legends.
MODES = ("A", "B_L", "B_R", "C_L", "C_R", "D_L", "D_R")

#: Block friction (between blocks and on the base) measured in the experiments (002, line 73).
MEASURED_FRICTION = 0.54
#: Default block friction, as the "high coefficient of friction ... adopted to prevent inter
#: block sliding" of 002's simulations (line 106, no value given): 2.0 is the smallest of
#: 0.54, 1 and 2 at which the pivot corner of the single block does not slide during the
#: launch of Figure 23's run (v_peak 0.59 m/s; checked in tests/test_rigs.py).
SIMULATED_FRICTION = 2.0
#: Mass of the scale-2 single block over the scale-1 one as measured, m2/m1 (002, line 179;
#: the geometric ratio is 2^3 = 8). 002 gives no measured ratio for the stacks; the same is
#: assumed for them (same aluminium stock and machining).
MEASURED_MASS_RATIO = 6.83
#: Friction between the aluminium base and PTFE used in the paper's simulations
#: (002, line 106; the experiments measured 0.23, line 73).
BASE_FRICTION = 0.26
#: Rise time of both pulses, s (002, lines 106 and 264).
RISE_TIME = 0.005
#: Coefficient of restitution of the base on the stopper (rubber cushion). 002 does
#: not give it: 0.5 is an assumption of nscd, to be identified from Figure 22.
STOPPER_RESTITUTION = 0.5

_SPECIMENS = {  # name -> (number of blocks, block width, block height) at scale 1, m
    "single": (1, 0.010, 0.045),
    "stack3": (3, 0.010, 0.015),
}
_BASES = ("kinematic", "dynamic")
_BASE_SIZE = (0.2, 0.01)          # length, thickness of the sliding base, m (002, line 66)
_BASE_DEPTH = 0.02                 # out-of-plane width of the base, m (002, line 66)
_DEPTH = 0.010                     # out-of-plane depth of a block at scale 1, m (002, line 127)


def _check(name: str, value: float, low: float, high: float = math.inf, *,
           low_open: bool = False, high_open: bool = True) -> float:
    """``float(value)`` if finite and within the bounds, else ValueError naming it."""
    value = float(value)
    above = value > low if low_open else value >= low
    below = value < high if high_open else value <= high
    if not (math.isfinite(value) and above and below):
        lo, hi = "(" if low_open else "[", ")" if high_open else "]"
        raise ValueError(f"{name} == {value}, must be in {lo}{low}, {high}{hi}.")
    return value


def housner_p(width: float, height: float, g: float = STANDARD_GRAVITY) -> float:
    """Housner's frequency parameter ``p = sqrt(3 g / (4 R))`` of a rectangle, rad/s.

    ``R = sqrt(b^2 + h^2)`` with ``b``, ``h`` the half width and half height (m).
    """
    _check("width", width, 0.0, low_open=True)
    _check("height", height, 0.0, low_open=True)
    return math.sqrt(3.0 * g / (4.0 * math.hypot(width / 2.0, height / 2.0)))


# --------------------------------------------------------------------------- base motion


class DoublePulse(ConstantAccelerationPhases):
    """Base motion of the double-pulse rig (002), in closed form.

    Phases, with ``g`` the standard gravity and ``t_r`` the rise time:

    1. launch: constant acceleration ``v_peak / t_r`` for ``t_r`` (velocity from 0 to ``v_peak``);
    2. free sliding toward the stopper, decelerated by friction: ``a = -mu_b g``;
    3. if the travelled distance reaches ``gap`` at ``t_impact`` with velocity
       ``v_impact > 0``: reverse impulse, constant acceleration for ``t_r`` taking the
       velocity to ``-stopper_restitution * v_impact`` (friction neglected during it);
       then sliding back, decelerated by friction (``a = +mu_b g``) to rest;
       otherwise the base stops before the stopper (no reverse impulse).

    Positive toward the stopper (+x). Starts from rest at t = 0; at rest after
    :attr:`duration`.

    Parameters
    ----------
    v_peak : float
        Peak velocity after the launch, m/s (> 0).
    gap : float
        Stop gap BD: distance travelled before the base touches the stopper, m;
        must exceed the launch travel ``v_peak t_r / 2`` (the launch must end first).
    rise_time : float
        Duration of each impulse, s (> 0); 0.005 s in 002.
    base_friction : float
        Friction coefficient mu_b of the base on PTFE (>= 0); 0.26 in 002's simulations.
    stopper_restitution : float
        Ratio e_s in [0, 1] of the rebound velocity to the approach velocity (assumed 0.5).
    g : float
        Gravity, m/s^2.

    Attributes
    ----------
    t_impact : float
        Start of the reverse impulse, s (nan if the base stops before the stopper).
    v_impact : float
        Velocity when the base touches the stopper, m/s (nan if it never does).
    t_rest : float
        Time when the base comes to rest for good, s (= ``duration``).
    """

    def __init__(self, v_peak: float, gap: float, rise_time: float = RISE_TIME,
                 base_friction: float = BASE_FRICTION, stopper_restitution: float = STOPPER_RESTITUTION,
                 g: float = STANDARD_GRAVITY) -> None:
        self.v_peak = _check("v_peak", v_peak, 0.0, low_open=True)
        self.gap = _check("gap", gap, 0.0, low_open=True)
        self.rise_time = _check("rise_time", rise_time, 0.0, low_open=True)
        self.base_friction = _check("base_friction", base_friction, 0.0)
        self.stopper_restitution = _check("stopper_restitution", stopper_restitution, 0.0, 1.0, high_open=False)
        self.g = _check("g", g, 0.0)
        t_r, v, mu_g = self.rise_time, self.v_peak, self.base_friction * self.g
        launch = 0.5 * v * t_r
        if self.gap <= launch:
            raise ValueError(f"gap == {self.gap} m, must be > v_peak * rise_time / 2 == {launch:.6g} m "
                             "(the base would reach the stopper during the launch).")
        remaining = self.gap - launch
        disc = v * v - 2.0 * mu_g * remaining
        if disc <= 0.0:  # friction stops the base before the stopper
            self.t_impact = self.v_impact = math.nan
            t_stop = t_r + v / mu_g
            super().__init__([0.0, t_r], [v / t_r, -mu_g], t_stop, at_rest_after=True)
        else:
            root = math.sqrt(disc)
            self.t_impact = t_r + 2.0 * remaining / (v + root)  # stable form of the quadratic's root
            self.v_impact = root
            rebound = self.stopper_restitution * root
            t_back = self.t_impact + t_r
            starts, accelerations = [0.0, t_r, self.t_impact], [v / t_r, -mu_g, -(root + rebound) / t_r]
            end = t_back
            if rebound > 0.0:
                if mu_g == 0.0:
                    raise ValueError("base_friction == 0 with stopper_restitution > 0: the base would "
                                     "slide back forever; give base_friction > 0.")
                starts.append(t_back)
                accelerations.append(mu_g)
                end = t_back + rebound / mu_g
            super().__init__(starts, accelerations, end, at_rest_after=True)
        if not math.isfinite(self.duration):
            raise ValueError("base_friction == 0 and the base never reaches the stopper: it would slide "
                             "forever; give base_friction > 0.")
        self.t_rest = self.duration

    def __repr__(self) -> str:
        return (f"DoublePulse(v_peak={self.v_peak!r} m/s, gap={self.gap!r} m, rise_time={self.rise_time!r} s, "
                f"base_friction={self.base_friction!r}, stopper_restitution={self.stopper_restitution!r})")


def _launch(v_peak: float, rise_time: float) -> Motion:
    """Motion of the pusher of the dynamic rig: accelerate to ``v_peak`` over ``rise_time``,
    then reverse to ``-v_peak`` over ``rise_time`` and withdraw at constant speed."""
    a = v_peak / rise_time
    return ConstantAccelerationPhases([0.0, rise_time], [a, -2.0 * a], 2.0 * rise_time)


# --------------------------------------------------------------------------- classification

#: Final tilt (rad) beyond which a block of the rig counts as fallen when the run ends. This is
#: a classification of the final state, as 002 classifies its tests by where the blocks end up;
#: it is not the instantaneous overturning threshold ``nscd.result.OVERTURN_ANGLE`` that
#: ``Result.overturned`` and the export use: a stacked block that falls onto the rig or against
#: its neighbour comes to rest at 1.4-1.5 rad without ever passing ``pi/2 - 0.02``.
FALLEN_ANGLE = math.pi / 4


def classify(final_angles: Sequence[float], overturn_angle: float = FALLEN_ANGLE) -> str:
    """Overturning mode of 002 from the final tilt of each block.

    Parameters
    ----------
    final_angles : sequence of float, shape (n_blocks,)
        Final angle of each block, rad, counter-clockwise positive, ordered from the
        bottom block to the top block (one value for a single block).
    overturn_angle : float
        A block whose final ``|angle|`` exceeds this (rad, in (0, pi)) has fallen
        (default :data:`FALLEN_ANGLE`, pi/4: a final-state class, not the instantaneous
        :data:`nscd.result.OVERTURN_ANGLE`).

    Returns
    -------
    str
        ``"A"`` when no block overturned; otherwise a letter from the lowest
        overturned block (top block ``B``, the one below ``C``, the bottom block of a
        three-block stack ``D``; a single block gives ``B``) and a side from its
        tilt: ``_L`` for angle > 0 (fallen toward -x, the side the first impulse
        throws it), ``_R`` for angle < 0.
    """
    angles = np.asarray(final_angles, dtype=float)
    if angles.ndim != 1 or angles.size not in (1, 3):
        raise ValueError(f"final_angles has shape {angles.shape}, must be (1,) or (3,) (bottom to top).")
    if not np.all(np.isfinite(angles)):
        raise ValueError(f"final_angles == {angles.tolist()}, must be finite.")
    _check("overturn_angle", overturn_angle, 0.0, math.pi, low_open=True)
    fallen = np.flatnonzero(np.abs(angles) > overturn_angle)
    if fallen.size == 0:
        return "A"
    lowest = int(fallen[0])
    letter = "B" if angles.size == 1 else "DCB"[lowest]
    return f"{letter}_{'L' if angles[lowest] > 0 else 'R'}"


# --------------------------------------------------------------------------- outcomes


@dataclass(frozen=True)
class Outcome:
    """What one run of the rig ended in, and how.

    Attributes
    ----------
    mode : str
        One of :data:`MODES`.
    t_impact : float
        Time of the reverse impact (base touching the stopper), s; nan if none.
    theta_impact : tuple of float, shape (n_blocks,)
        Angle of each block (bottom to top) at the last step before ``t_impact``
        (within one ``dt``), rad, CCW positive (> 0: leaning left, the way the
        first impulse threw it); nan if there is no impact.
    omega_impact : tuple of float, shape (n_blocks,)
        Angular velocity of each block at the same instant, rad/s, CCW positive
        (> 0: turning toward the left).
    theta_final : tuple of float, shape (n_blocks,)
        Angle of each block at the end, rad.
    max_tilt : tuple of float, shape (n_blocks,)
        Largest ``|angle|`` of each block during the run, rad.
    t_stop : float
        Time the run stopped, s: when everything came to rest, or the requested ``t_end``.
    settled : bool
        True when the mode is final: everything came to rest, or a single block's
        energy fell below its overturning barrier with the base at rest (the run
        then stops early). False: ``t_end`` came first.
    unconverged_steps : int
        Steps whose contact solver did not converge (see the engine's warnings).
    result : nscd.Result or None
        The full histories, when ``run(..., keep_result=True)``.
    """

    mode: str
    t_impact: float
    theta_impact: tuple[float, ...]
    omega_impact: tuple[float, ...]
    theta_final: tuple[float, ...]
    max_tilt: tuple[float, ...]
    t_stop: float
    settled: bool
    unconverged_steps: int
    result: Any = field(default=None, repr=False, compare=False)

    def to_row(self) -> dict[str, Any]:
        """Scalar fields for a sweep's CSV (per-block values as ``name_<i>``, i = 0 bottom)."""
        row: dict[str, Any] = {"mode": self.mode, "t_impact": self.t_impact}
        for name in ("theta_impact", "omega_impact", "theta_final", "max_tilt"):
            row.update({f"{name}_{i}": value for i, value in enumerate(getattr(self, name))})
        row.update(t_stop=self.t_stop, settled=self.settled, unconverged_steps=self.unconverged_steps)
        return row


@dataclass(frozen=True)
class EnsembleOutcome:
    """Mode probabilities of a cell over perturbed runs.

    Attributes
    ----------
    modes : tuple of str, shape (n,)
        Mode of each member.
    """

    modes: tuple[str, ...]

    @property
    def probabilities(self) -> dict[str, float]:
        """Share of members in each of :data:`MODES`."""
        n = len(self.modes)
        return {mode: self.modes.count(mode) / n for mode in MODES}

    @property
    def mode(self) -> str:
        """The most frequent mode (ties: first in :data:`MODES`)."""
        p = self.probabilities
        return max(MODES, key=lambda m: (p[m], -MODES.index(m)))

    def to_row(self) -> dict[str, Any]:
        row: dict[str, Any] = {"mode": self.mode, "n": len(self.modes)}
        row.update({f"p_{mode}": value for mode, value in self.probabilities.items()})
        return row


@dataclass(frozen=True)
class Perturbation:
    """Standard deviations of the random perturbations of an ensemble member.

    Normal draws, independent per member. Defaults are nscd's assumptions of the
    experimental scatter (manual placement, 002 line 353), not published numbers.

    Parameters
    ----------
    placement : float
        Horizontal offset of each block from the one below (or the base centre), m.
    friction : float
        Relative change of the block friction coefficient (same for all contacts).
    v_peak : float
        Relative change of the peak base velocity.
    gap : float
        Change of the stop gap, m.
    """

    placement: float = 0.5e-3
    friction: float = 0.05
    v_peak: float = 0.02
    gap: float = 0.5e-3

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            _check(f"Perturbation.{f.name}", getattr(self, f.name), 0.0)


# --------------------------------------------------------------------------- the rig


@dataclass(frozen=True)
class DoublePulseRig:
    """The double-pulse rig of 002 with one specimen.

    Parameters
    ----------
    specimen : {"single", "stack3"}
        A single block (10 x 45 mm at scale 1) or a stack of three (10 x 15 mm each).
    scale : float
        Geometric scale of the specimen (1 and 2 in 002); the rig itself is unchanged.
    base : {"kinematic", "dynamic"}
        Prescribed base motion (:class:`DoublePulse`), or a base body computed
        with the blocks (see the module docstring).
    density : float
        Density of the blocks (and of the dynamic base), kg/m^3; aluminium 2700.
    friction : float
        Coulomb friction between blocks and on the base: :data:`SIMULATED_FRICTION` (high,
        no sliding, as 002's simulations) or :data:`MEASURED_FRICTION` (0.54, the tests).
    restitution : float
        Newton restitution between blocks and on the base, in [0, 1] (0 in 002).
    base_friction : float
        Friction mu_b of the base on PTFE (0.26, 002's simulations).
    stopper_restitution : float
        e_s of the base on the stopper, in [0, 1] (0.5, assumed).
    rise_time : float
        Duration of the launch (and, kinematic base, of the reverse impulse), s.
    dt : float
        Time step, s. Default 5e-4 s (see :meth:`run` and the docs for its convergence).
    overturn_angle : float
        Final ``|angle|`` beyond which a block counts as fallen, rad (default
        :data:`FALLEN_ANGLE`).
    scheme : {"midpoint", "theta"}
        Integration scheme (:class:`nscd.Settings`): Moreau's midpoint rule by default.
    mass_ratio : {"geometric", "measured"}
        Mass of a scale-2 specimen over its scale-1 twin: ``"geometric"`` (``scale**3`` at
        ``density``) or ``"measured"`` (:data:`MEASURED_MASS_RATIO` = 6.83, 002 line 179: the
        blocks' density is lowered by 6.83 / 8; scale 1 or 2 only). It sets :attr:`mass`
        (the energy axis of the scaled maps) and, with the dynamic base, the blocks' weight
        on the base; with the kinematic base the motion does not depend on it.
    """

    specimen: str = "single"
    scale: float = 1.0
    base: str = "kinematic"
    density: float = 2700.0
    friction: float = SIMULATED_FRICTION
    restitution: float = 0.0
    base_friction: float = BASE_FRICTION
    stopper_restitution: float = STOPPER_RESTITUTION
    rise_time: float = RISE_TIME
    dt: float = 5e-4
    overturn_angle: float = FALLEN_ANGLE
    scheme: str = "midpoint"
    mass_ratio: str = "geometric"

    def __post_init__(self) -> None:
        if self.specimen not in _SPECIMENS:
            raise ValueError(f"specimen == {self.specimen!r}, must be one of {sorted(_SPECIMENS)}.")
        if self.base not in _BASES:
            raise ValueError(f"base == {self.base!r}, must be one of {list(_BASES)}.")
        _check("scale", self.scale, 0.0, low_open=True)
        _check("density", self.density, 0.0, low_open=True)
        _check("friction", self.friction, 0.0)
        _check("restitution", self.restitution, 0.0, 1.0, high_open=False)
        _check("base_friction", self.base_friction, 0.0, low_open=True)
        _check("stopper_restitution", self.stopper_restitution, 0.0, 1.0, high_open=False)
        _check("rise_time", self.rise_time, 0.0, low_open=True)
        _check("dt", self.dt, 0.0, self.rise_time, low_open=True, high_open=False)
        _check("overturn_angle", self.overturn_angle, 0.0, math.pi, low_open=True)
        if self.mass_ratio not in ("geometric", "measured"):
            raise ValueError(f"mass_ratio == {self.mass_ratio!r}, must be 'geometric' or 'measured'.")
        if self.mass_ratio == "measured" and self.scale not in (1.0, 2.0):
            raise ValueError(f"scale == {self.scale} with mass_ratio == 'measured': 002 measured the masses "
                             "of scales 1 and 2 only.")
        if self.scheme not in SCHEMES:
            raise ValueError(f"scheme == {self.scheme!r}, must be one of {list(SCHEMES)}.")

    # -- geometry ------------------------------------------------------------------
    @property
    def n_blocks(self) -> int:
        return _SPECIMENS[self.specimen][0]

    @property
    def block_size(self) -> tuple[float, float]:
        """Width and height of one block, m."""
        _, width, height = _SPECIMENS[self.specimen]
        return width * self.scale, height * self.scale

    @property
    def block_density(self) -> float:
        """Density given to the blocks, kg/m^3 (:attr:`density`, scaled for ``mass_ratio="measured"``)."""
        if self.mass_ratio == "measured" and self.scale == 2.0:
            return self.density * MEASURED_MASS_RATIO / 8.0
        return self.density

    @property
    def mass(self) -> float:
        """Mass of the whole specimen in 3D, kg (depth = width, as in 002)."""
        width, height = self.block_size
        return self.block_density * self.n_blocks * width * height * _DEPTH * self.scale

    @property
    def p(self) -> float:
        """Housner's p of the specimen's overall outline, rad/s (used for stacks too, 002 line 241)."""
        width, height = self.block_size
        return housner_p(width, self.n_blocks * height)

    def excitation_period(self, v_peak: float, gap: float) -> float:
        """T_d of 002 (line 179): rise time plus the frictionless free-sliding time to the stopper, s."""
        v = _check("v_peak", v_peak, 0.0, low_open=True)
        return self.rise_time + (_check("gap", gap, 0.0, low_open=True) - 0.5 * v * self.rise_time) / v

    def scaled(self, v_peak: float, gap: float) -> tuple[float, float]:
        """Coordinates of the scaled maps of 002 (Figures 13, 14, 20, 21).

        Returns
        -------
        p_td : float
            Excitation period scaled by Housner's frequency parameter, ``p * T_d`` (-).
        energy : float
            Input kinetic energy of the specimen at the peak velocity,
            ``mass * v_peak^2 / 2``, J (the mass carries the scale).
        """
        return self.p * self.excitation_period(v_peak, gap), 0.5 * self.mass * float(v_peak) ** 2

    def to_dict(self) -> dict[str, Any]:
        """The rig's settings (recorded by :func:`nscd.sweep.grid` in its JSON file)."""
        return dataclasses.asdict(self)

    # -- scene -------------------------------------------------------------------
    def motion(self, v_peak: float, gap: float) -> DoublePulse:
        """The closed-form base motion for these settings (the kinematic base)."""
        return DoublePulse(v_peak, gap, self.rise_time, self.base_friction, self.stopper_restitution)

    def _check_launch(self, v_peak: float, gap: float) -> None:
        """ValueError unless v_peak > 0 and the launch ends before the stopper (gap > v_peak t_r / 2)."""
        _check("v_peak", v_peak, 0.0, low_open=True)
        _check("gap", gap, 0.0, low_open=True)
        launch = 0.5 * v_peak * self.rise_time
        if gap <= launch:
            raise ValueError(f"gap == {gap} m, must be > v_peak * rise_time / 2 == {launch:.6g} m for "
                             f"v_peak == {v_peak} m/s (the base would reach the stopper during the launch).")

    def scene(self, v_peak: float, gap: float, offsets: Sequence[float] | None = None,
              friction: float | None = None, bare: bool = False) -> tuple[Any, list[Any], Any]:
        """Build the scene of one run.

        Parameters
        ----------
        v_peak, gap : float
            Peak base velocity (m/s, > 0) and stop gap (m, > 0).
        offsets : sequence of float, shape (n_blocks,), optional
            Horizontal offset of each block from the one below (bottom block: from
            the base centre), m.
        friction : float, optional
            Block friction overriding :attr:`friction`.
        bare : bool
            The rig without the specimen (to check the base alone).

        Returns
        -------
        scene : nscd.Scene
        blocks : list of Body
            Bottom to top.
        base : Body
            The base (driven for the kinematic rig, dynamic for the dynamic one).
        """
        from nscd.scene import Scene
        from nscd.shapes import box

        self._check_launch(v_peak, gap)
        offsets = np.zeros(self.n_blocks) if offsets is None else np.asarray(offsets, dtype=float)
        if offsets.shape != (self.n_blocks,):
            raise ValueError(f"offsets has shape {offsets.shape}, must be ({self.n_blocks},).")
        length, thickness = _BASE_SIZE
        scene = Scene()
        if self.base == "kinematic":
            # the prescribed base stands for the base and the bench around it: long
            # enough that a fallen block lands on it
            base = scene.add_base(box(3.0 * length, thickness), position=(0.0, -thickness / 2),
                                  motion=self.motion(v_peak, gap), material="base", name="base")
        else:
            base = self._dynamic_base(scene, v_peak, gap)
        width, height = self.block_size
        blocks, x = [], 0.0
        for i in range(0 if bare else self.n_blocks):
            x += offsets[i]
            blocks.append(scene.add_block(box(width, height), position=(x, (i + 0.5) * height),
                                          density=self.block_density, material="block", name=f"block{i}"))
        mu = self.friction if friction is None else _check("friction", friction, 0.0)
        scene.set_contact(friction=mu, restitution=self.restitution)
        return scene, blocks, base

    def _dynamic_base(self, scene: Any, v_peak: float, gap: float) -> Any:
        from nscd.shapes import box

        length, thickness = _BASE_SIZE
        # the blocks are a 2D slice of depth _DEPTH * scale; the base is _BASE_DEPTH deep, so
        # its 2D density carries the ratio of depths to keep the real base/block mass ratio
        base_density = self.density * _BASE_DEPTH / (_DEPTH * self.scale)
        base = scene.add_block(box(length, thickness), position=(0.0, -thickness / 2),
                               density=base_density, material="base", name="base")
        travel_back = (self.stopper_restitution * v_peak) ** 2 / (2 * self.base_friction * STANDARD_GRAVITY)
        left, right = -length / 2 - travel_back - length, length / 2 + gap + length
        scene.add_base(box(right - left, thickness), position=((left + right) / 2, -1.5 * thickness),
                       material="ptfe", name="floor")
        # the stopper and the pusher stand clear of the floor and below the top of the base
        scene.add_base(box(thickness, 0.8 * thickness), position=(length / 2 + gap + thickness / 2, -thickness / 2),
                       material="stopper", name="stopper")
        scene.add_base(box(thickness, 0.6 * thickness), position=(-length / 2 - thickness / 2, -thickness / 2),
                       motion=_launch(v_peak, self.rise_time), material="pusher", name="pusher")
        scene.set_contact(self.base_friction, 0.0, between=("base", "ptfe"))
        scene.set_contact(0.0, self.stopper_restitution, between=("base", "stopper"))
        scene.set_contact(0.0, 0.0, between=("base", "pusher"))
        return base

    # -- runs --------------------------------------------------------------------
    def run(self, v_peak: float, gap: float, t_end: float = 1.0, dt: float | None = None,
            seed: int | None = None, perturbation: Perturbation | None = None,
            keep_result: bool = False, stop_early: bool = True) -> Outcome:
        """Simulate one double pulse and classify the outcome.

        Parameters
        ----------
        v_peak : float
            Peak base velocity after the launch, m/s (> 0).
        gap : float
            Stop gap BD, m (> 0; kinematic base: > ``v_peak * rise_time / 2``).
        t_end : float
            Latest end time, s; the run stops earlier once everything is at rest.
        dt : float, optional
            Time step, s; default :attr:`dt`.
        seed : int, optional
            None: the nominal run. An int: an ensemble member, with random
            perturbations (:class:`Perturbation`) drawn from ``numpy.random.default_rng(seed)``.
        perturbation : Perturbation, optional
            Spreads of a perturbed member (default ``Perturbation()``).
        keep_result : bool
            Keep the engine's :class:`nscd.Result` in :attr:`Outcome.result`.
        stop_early : bool
            Stop once the outcome is decided (the run's terminal event, see :class:`_Watch`);
            False runs to ``t_end`` whatever happens (the reference the early stops are
            checked against in ``tests/test_rigs.py`` and ``benchmarks/bench_maps.py``).

        Returns
        -------
        Outcome
        """
        from nscd.stepper import Settings, Simulator

        dt = self.dt if dt is None else _check("dt", dt, 0.0, self.rise_time, low_open=True, high_open=False)
        _check("t_end", t_end, dt, low_open=False)
        offsets, friction = None, None
        if seed is not None:
            rng = np.random.default_rng(seed)
            spread = perturbation or Perturbation()
            v_peak = float(v_peak) * (1.0 + spread.v_peak * rng.standard_normal())
            gap = float(gap) + spread.gap * rng.standard_normal()
            friction = max(0.0, self.friction * (1.0 + spread.friction * rng.standard_normal()))
            offsets = spread.placement * rng.standard_normal(self.n_blocks)
        scene, blocks, base, cell = self._cell(v_peak, gap, offsets, friction)
        watch = _Watch(blocks, base, dt, **cell, stacked=offsets is None, terminal=stop_early)
        sim = Simulator(scene, dt, Settings(scheme=self.scheme, on_failure="warn"), store_impulses=False,
                        events=[watch])
        unconverged = 0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # counted below, reported once
            for _ in range(int(round(t_end / dt))):
                report = sim.step()
                if report is None:  # the watch, a terminal event, stopped the run
                    break
                unconverged += not report.converged
        if unconverged:
            warnings.warn(f"DoublePulseRig.run(v_peak={v_peak}, gap={gap}): {unconverged} steps did not "
                          "converge; see Outcome.unconverged_steps.", RuntimeWarning, stacklevel=2)
        return self._outcome(watch, 0, sim.state, unconverged, sim.result() if keep_result else None)

    def run_verified(self, v_peak: float, gap: float, t_end: float = 1.0,
                     other_scheme: bool = False) -> TimeStepCheck:
        """:meth:`run` with its mode checked at ``dt / 2`` (and with the other scheme).

        Parameters
        ----------
        v_peak, gap, t_end : float
            As :meth:`run` (the nominal run).
        other_scheme : bool
            Also rerun at :attr:`dt` with the other integration scheme.

        Returns
        -------
        nscd.convergence.TimeStepCheck
            ``outcome["mode"]`` is the mode at :attr:`dt`; ``converged`` is False when a
            rerun ended in another mode (``changes`` says which).
        """
        def mode(dt: float, scheme: str) -> dict[str, str]:
            return {"mode": dataclasses.replace(self, dt=dt, scheme=scheme).run(v_peak, gap, t_end).mode}
        return verify_time_step(mode, self.dt, scheme=self.scheme, other_scheme=other_scheme)

    def _cell(self, v_peak: float, gap: float, offsets: np.ndarray | None = None,
              friction: float | None = None) -> tuple[Any, list[Any], Any, dict[str, Any]]:
        """The scene of one run, its blocks and base, and the watch's parameters of its cell
        (:class:`_Watch`: ``t_impact``, ``stopper_x``, ``rest_after``, ``lying_stays``)."""
        scene, blocks, base = self.scene(v_peak, gap, offsets, friction)
        width, height = self.block_size
        mu = self.friction if friction is None else friction
        # A single block past OVERTURN_ANGLE lies on its long side for good: the base tips a
        # lying block back up only through friction, which would have to carry m a > m g
        # height / width (impossible when mu < height / width), and without restitution its
        # landing does not bounce it back. Its final tilt is then past overturn_angle too.
        lying_stays = (self.n_blocks == 1 and self.restitution == 0.0 and mu < height / width
                       and self.overturn_angle < OVERTURN_ANGLE)
        if self.base == "kinematic":
            t_impact, stopper_x = base.motion.t_impact, math.nan
        else:
            t_impact = math.nan
            stopper_x = _BASE_SIZE[0] / 2 + gap  # left face of the stopper; base right face starts at length/2
        return scene, blocks, base, dict(t_impact=t_impact, stopper_x=stopper_x, rest_after=self._rest_after(base),
                                         lying_stays=lying_stays)

    def _outcome(self, watch: "_Watch", k: int, state: Any, unconverged: int, result: Any) -> Outcome:
        """The :class:`Outcome` of cell ``k`` of ``watch``, whose run ended in ``state``."""
        final = state.q[watch.rows, 2]
        return Outcome(
            mode=classify(final, self.overturn_angle),
            t_impact=float(watch.t_impact[k]),
            theta_impact=tuple(float(a) for a in watch.theta_impact[k]),
            omega_impact=tuple(float(w) for w in watch.omega_impact[k]),
            theta_final=tuple(float(a) for a in final), max_tilt=tuple(float(a) for a in watch.max_tilt[k]),
            t_stop=float(state.t), settled=bool(watch.decided[k] or not math.isnan(watch.quiet_since[k])),
            unconverged_steps=unconverged, result=result,
        )

    def run_batch(self, cases: Sequence[dict],
                  on_result: Callable[[int, Outcome], None] | None = None) -> list[Outcome]:
        """Nominal runs of many cells advanced together (:class:`nscd.batch.BatchSimulator`).

        Each cell gives the :class:`Outcome` that :meth:`run` gives it (bit-identical
        trajectories, the same early stop), at a fraction of the cost: each cell's watch is
        its terminal event, so a cell leaves the batch (and stops costing) once it is
        decided. Kinematic base only.

        Parameters
        ----------
        cases : sequence of dict
            Keyword arguments of :meth:`run` per cell: ``v_peak`` and ``gap`` (required),
            ``t_end`` (default 1.0 s), ``stop_early`` (default True). Every cell uses the
            rig's :attr:`dt`.
        on_result : callable, optional
            ``on_result(k, outcome)`` as soon as cell ``k`` is decided (before the batch ends);
            :func:`nscd.sweep.grid` passes one to save each cell as it finishes.

        Returns
        -------
        list of Outcome
            In the order of ``cases`` (``result`` is None).
        """
        from nscd.batch import BatchSimulator
        from nscd.stepper import Settings

        if self.base != "kinematic":
            raise ValueError(f"base == {self.base!r}: run_batch needs base == 'kinematic' (the floor and the "
                             "stopper of the dynamic rig depend on gap and v_peak, so its cells do not share "
                             "one structure).")
        cases = [dict(case) for case in cases]
        if not cases:
            return []
        for k, case in enumerate(cases):
            unknown = set(case) - {"v_peak", "gap", "t_end", "stop_early"}
            if unknown or not {"v_peak", "gap"} <= set(case):
                raise ValueError(f"cases[{k}] has keys {sorted(case)}, must be v_peak, gap and optionally "
                                 "t_end, stop_early.")
            _check("t_end", case.setdefault("t_end", 1.0), self.dt)
        cells = [self._cell(case["v_peak"], case["gap"]) for case in cases]
        per_cell = {name: [cell[name] for *_, cell in cells] for name in cells[0][3]}
        _, blocks, base, _ = cells[0]  # one structure: the same bodies in every cell
        watch = _Watch(blocks, base, self.dt, **per_cell, stacked=True,
                       terminal=[case.get("stop_early", True) for case in cases])
        sim = BatchSimulator([scene for scene, *_ in cells], self.dt, Settings(scheme=self.scheme, on_failure="warn"),
                             record=False, events=[watch])
        remaining = np.array([int(round(case["t_end"] / self.dt)) for case in cases])

        def stop(k: int) -> None:
            sim.stop(k)
            if on_result is not None:
                on_result(k, self._outcome(watch, k, sim.state(k), int(sim.unconverged[k]), None))

        for k in np.flatnonzero(remaining <= 0).tolist():
            stop(k)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # counted below, reported once per cell
            # each cell until decided (the watch) or at t_end
            sim.advance(remaining, ended=lambda cells: [stop(k) for k in cells.tolist()])
        for k in np.flatnonzero(sim.unconverged).tolist():
            warnings.warn(f"DoublePulseRig.run_batch: cell v_peak={cases[k]['v_peak']}, gap={cases[k]['gap']}: "
                          f"{sim.unconverged[k]} steps did not converge; see Outcome.unconverged_steps.",
                          RuntimeWarning, stacklevel=2)
        return [self._outcome(watch, k, sim.state(k), int(sim.unconverged[k]), None) for k in range(len(cases))]

    def _rest_after(self, base: Any) -> float:
        """Time after which the base may be at rest (kinematic: end of its motion)."""
        return base.motion.duration if self.base == "kinematic" else 2.0 * self.rise_time

    def ensemble(self, v_peak: float, gap: float, n: int = 10, seed: int = 0, t_end: float = 1.0,
                 perturbation: Perturbation | None = None) -> EnsembleOutcome:
        """Run ``n`` perturbed members (seeds ``seed * 100003 + k``) and count their modes.

        Parameters
        ----------
        v_peak, gap, t_end : float
            As :meth:`run` (nominal values, perturbed per member).
        n : int
            Number of members (>= 1).
        seed : int
            Seed of the ensemble; the same seed gives the same members.
        perturbation : Perturbation, optional
            Spreads (default ``Perturbation()``).
        """
        if not (isinstance(n, (int, np.integer)) and n >= 1):
            raise ValueError(f"n == {n!r}, must be an int >= 1.")
        modes = tuple(self.run(v_peak, gap, t_end, seed=int(seed) * 100003 + k, perturbation=perturbation).mode
                      for k in range(n))
        return EnsembleOutcome(modes)


    def map(self, gaps: Sequence[float], v_peaks: Sequence[float], out: str | None = None,
            executor: Any = None, ensemble: int | None = None, seed: int = 0, t_end: float = 1.0,
            progress: bool = True, resume: bool = True, batch: bool = False,
            chunks: int | None = None, verify_dt: bool = False) -> Any:
        """Overturning map over stop gaps and peak velocities (002, Figures 10-19).

        A thin layer over :func:`nscd.sweep.grid` that checks the grid first:
        ``nscd.sweep.grid(rig.run, {"gap": gaps, "v_peak": v_peaks}, ...)`` gives
        the same table (cells ordered gap-major: the gap varies slowest).

        Parameters
        ----------
        gaps : sequence of float
            Stop gaps BD, m: non-empty, increasing, > 0.
        v_peaks : sequence of float
            Peak base velocities, m/s: non-empty, increasing, > 0.
        out : path, optional
            CSV file (resumable; see :mod:`nscd.sweep`).
        executor : concurrent.futures.Executor, optional
            Default: a local process pool over all cores.
        ensemble : int, optional
            Members per cell: cells run :meth:`ensemble` (mode probabilities) instead of :meth:`run`.
        seed : int
            Seed of the ensembles.
        t_end : float
            Latest end time of each run, s.
        batch : bool
            Run the cells with :meth:`run_batch`: one batch of cells per worker, advanced
            together (:mod:`nscd.batch`); the same outcomes as the default cell-by-cell
            map, several times faster. Kinematic base only, not with ``ensemble``.
        chunks : int, optional
            Batches of a batched map (default: one per worker; more batches let the
            progress bar move more often, smaller ones amortise less; see :func:`nscd.sweep.grid`).
        verify_dt : bool
            Run each cell with :meth:`run_verified`: the mode is checked at ``dt / 2`` and
            the table gains ``converged`` and ``changes`` columns (:func:`nscd.plot.maps.mode_map`
            rings the unconverged cells). Not with ``batch`` or ``ensemble``.

        Returns
        -------
        nscd.sweep.Table
        """
        from nscd import sweep

        gaps, v_peaks = _axis("gaps", gaps), _axis("v_peaks", v_peaks)
        self._check_launch(v_peaks[-1], gaps[0])
        _check("t_end", t_end, self.dt)
        params = {"gap": gaps, "v_peak": v_peaks}
        label = f"double-pulse map, {self.specimen} scale {self.scale:g}"
        if verify_dt:
            if batch or ensemble is not None:
                raise ValueError(f"verify_dt == True with batch == {batch!r}, ensemble == {ensemble!r}: "
                                 "the time-step check runs nominal cells one by one (batch=False, ensemble=None).")
            return sweep.grid(self.run_verified, params, out=out, executor=executor, fixed={"t_end": t_end},
                              progress=progress, resume=resume, desc=label + ", dt checked")
        if batch:
            if ensemble is not None:
                raise ValueError(f"ensemble == {ensemble!r} with batch == True: the batched map runs "
                                 "nominal cells only; use batch=False for ensembles.")
            return sweep.grid(self.run_batch, params, out=out, executor=executor, fixed={"t_end": t_end},
                              progress=progress, resume=resume, batch=True, chunks=chunks, desc=label + ", batched")
        if ensemble is None:
            return sweep.grid(self.run, params, out=out, executor=executor, fixed={"t_end": t_end},
                              progress=progress, resume=resume, desc=label)
        return sweep.grid(self.ensemble, params, out=out, executor=executor,
                          fixed={"n": ensemble, "seed": seed, "t_end": t_end}, progress=progress, resume=resume,
                          desc=f"{label}, ensembles of {ensemble}")


def _axis(name: str, values: Sequence[float]) -> list[float]:
    """A map axis as a list of floats: non-empty, 1-D, finite, > 0, strictly increasing."""
    arr = np.asarray(values, dtype=float)
    if arr.ndim != 1 or arr.size == 0:
        raise ValueError(f"{name} has shape {arr.shape}, must be a non-empty 1-D sequence.")
    if not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
        raise ValueError(f"{name} == {arr.tolist()}, every value must be finite and > 0.")
    if np.any(np.diff(arr) <= 0.0):
        raise ValueError(f"{name} == {arr.tolist()}, must be strictly increasing.")
    return arr.tolist()


class _Watch:
    """Follows the cells of a run step by step (rocking phase at the reverse impact, peak tilts,
    rest) and is their terminal event, in the style of :func:`scipy.integrate.solve_ivp`'s events.

    One watch follows B cells of one structure (a single run: B = 1) as arrays over the cells,
    updated for all the scenes of a step in one compiled call (:func:`_watch_update`, the same
    operations for each cell whatever the batch). As a vectorized event (``watch(states)``,
    passed to :class:`nscd.Simulator` or :class:`nscd.batch.BatchSimulator` in ``events``;
    :mod:`nscd.events`) its value for a cell is -1 while the outcome may still change and +1
    once it cannot, in a cell whose run stops then (``terminal``); the cell then leaves the
    run. :meth:`update` does the work and returns, per scene, whether its outcome is decided:

    - **rest**: every block and the base at rest for ``QUIET_TIME`` after ``rest_after``;
    - **energy barrier**: the base at rest, every block tilted less than ``tilt_limit`` and
      the mechanical energy of the blocks (and of a dynamic base) below ``barrier``, the
      lowest potential barrier of rigid rocking: the top ``k`` blocks of the stack rocking
      as one body over a bottom corner lift their centre of mass by ``R_k - c_k`` (``c_k``
      its height above the pivot, ``R_k`` its distance from it), at a cost
      ``m_k g (R_k - c_k)``, the lowest over k = 1..n. With the base at rest the contacts
      only dissipate (``nscd.impact_law``), so no block can be carried over a pivot. A single
      block: ``m g (R - h/2)``, within its slenderness alpha (past alpha it may be falling
      already, whatever its energy). A stack (``stacked``: nominal placements, one column):
      every block within half the stack's slenderness, so that each block leans on the one
      below by less than any sub-stack's alpha. That the rigid modes give the lowest barrier
      of the stack is an assumption, checked against full-length runs over whole maps
      (``benchmarks/bench_maps.py``, ``tests/test_rigs.py``);
    - **lying** (``lying_stays``): a single block tilted past :data:`nscd.result.OVERTURN_ANGLE`
      has fallen onto its long side for good when the base cannot stand it back up (no
      restitution, friction below its height / width ratio: see :meth:`DoublePulseRig._cell`).

    Parameters
    ----------
    blocks : list of Body
        The blocks, bottom to top (the same rows and masses in every cell).
    base : Body
        The base.
    dt : float
        Time step, s.
    t_impact, stopper_x, rest_after, lying_stays, terminal : scalar or sequence of B
        Per cell (one value: every cell): the time of the kinematic base's reverse impact (s,
        nan if none); the left face of a dynamic base's stopper (m; None or nan: a kinematic
        base); the time after which the base may rest (s); whether a lying single block has
        fallen for good; whether the cell stops once decided.
    g : float
        Gravity, m/s^2.
    stacked : bool
        Nominal placements (one column): the energy barrier applies.

    Attributes
    ----------
    t_impact, theta_impact, omega_impact, max_tilt, quiet_since, decided : ndarray
        Per cell (B,) or (B, n_blocks): the reverse impact's time (a dynamic base's as
        detected, :meth:`update`), the blocks' angles and angular velocities at the last
        step before it, their largest tilts, the start of the current rest (nan: moving)
        and whether the outcome is decided.
    """

    QUIET_TIME = 0.05      # s of continuous rest before stopping early
    OMEGA_REST = 1e-2      # rad/s: a block turning slower than this is at rest...
    SPEED_REST = 1e-3      # m/s: ...if it also moves slower than this relative to the base
    terminal = True        # a terminal event: a cell whose outcome is decided leaves the run...
    direction = 1.0        # ...as its value rises through zero
    vectorized = True      # evaluated for all the scenes of a step at once (nscd.events)

    def __init__(self, blocks: list[Any], base: Any, dt: float, t_impact: Any, stopper_x: Any, rest_after: Any,
                 g: float = STANDARD_GRAVITY, stacked: bool = False, lying_stays: Any = False,
                 terminal: Any = True) -> None:
        stopper_x = math.nan if stopper_x is None else stopper_x
        cells = np.broadcast_arrays(*(np.atleast_1d(np.asarray(x, dtype=float))
                                      for x in (t_impact, stopper_x, rest_after, lying_stays, terminal)))
        self.t_impact, self.stopper_x, self.rest_after = (np.array(x) for x in cells[:3])
        self.lying_stays, self.stops = cells[3].astype(bool), cells[4].astype(bool)
        B, n = len(self.t_impact), len(blocks)
        self.rows = np.array([b.index for b in blocks], dtype=np.int64)
        self.g = float(g)
        self.barrier, self.tilt_limit = math.nan, math.nan  # nan: no barrier (placements not nominal)
        if len(blocks) == 1 or stacked:
            self.barrier, self.tilt_limit = _rocking_barrier(blocks, g)
        self.base_row = int(base.index)
        # a dynamic base's kinetic energy counts
        self.base_mass = np.where(np.isnan(self.stopper_x), 0.0, getattr(base, "mass", 0.0))
        self.dt, self.x0 = float(dt), float(base.q0[0])
        self.mass = np.array([b.mass for b in blocks], dtype=float)
        self.inertia = np.array([b.inertia for b in blocks], dtype=float)
        self.height0 = np.array([b.q0[1] for b in blocks], dtype=float)
        self.theta_impact = np.full((B, n), math.nan)
        self.omega_impact = np.full((B, n), math.nan)
        self.max_tilt = np.zeros((B, n))
        self.quiet_since = np.full(B, math.nan)
        self.decided = np.zeros(B, dtype=bool)
        # the state of the step before: whether there is one, t, block angles, block omegas, base x, base v
        self._seen = np.zeros(B, dtype=bool)
        self._previous_t, self._previous_x, self._previous_v = np.zeros((3, B))
        self._previous_theta, self._previous_omega = np.zeros((2, B, n))

    def __call__(self, states: Any) -> np.ndarray:
        """The event's value per scene: +1.0 once its outcome is decided (:meth:`update`) in a
        cell that stops then, else -1.0."""
        decided = self.update(states)
        return np.where(decided & self.stops[states.rows], 1.0, -1.0)

    def update(self, states: Any) -> np.ndarray:
        """Follow the scenes ``states`` (:class:`nscd.state.States`, rows = cells) one step on;
        whether each one's outcome is decided, (S,)."""
        return _watch_update(
            np.ascontiguousarray(states.t, dtype=float), np.ascontiguousarray(states.q, dtype=float),
            np.ascontiguousarray(states.v, dtype=float), np.ascontiguousarray(states.rows, dtype=np.int64),
            self.rows, self.base_row, self.mass, self.inertia, self.height0, self.g, self.barrier, self.tilt_limit,
            self.base_mass, self.dt, self.x0, _BASE_SIZE[0] / 2, self.stopper_x, self.rest_after, self.lying_stays,
            OVERTURN_ANGLE, self.QUIET_TIME, self.OMEGA_REST, self.SPEED_REST, self.t_impact, self.theta_impact,
            self.omega_impact, self.max_tilt, self.quiet_since, self.decided, self._seen, self._previous_t,
            self._previous_theta, self._previous_omega, self._previous_x, self._previous_v)


@njit
def _watch_update(t, q, v, cells, rows, base_row, mass, inertia, height0, g, barrier, tilt_limit, base_mass, dt, x0,
                  half_length, stopper_x, rest_after, lying_stays, overturn_angle, quiet_time, omega_rest, speed_rest,
                  t_impact, theta_impact, omega_impact, max_tilt, quiet_since, decided, seen, previous_t,
                  previous_theta, previous_omega, previous_x, previous_v):
    """:meth:`_Watch.update` of scenes ``cells`` (S,) at times ``t`` (S,), s, in ``q``, ``v``
    (S, n_bodies, 3); the cells' records (the arrays after ``rest_after``) updated in place.

    A dynamic base (``stopper_x`` not nan) hits the stopper in the step in which its velocity
    falls by more than half: friction alone takes ``mu_b g dt`` (1.3e-3 m/s at dt = 5e-4 s)
    per step, so only the stopper halves the velocity of a base moving faster than twice
    that. The phase is the state before that step; the contact instant is estimated from its
    gap and velocity. A kinematic base's impact is known (``t_impact``): the phase is
    recorded at the last step before it.
    """
    S, n = t.shape[0], rows.shape[0]
    out = np.zeros(S, dtype=np.bool_)
    for s in range(S):
        c, ts = cells[s], t[s]
        base_x, base_v = q[s, base_row, 0], v[s, base_row, 0]
        for i in range(n):
            max_tilt[c, i] = max(max_tilt[c, i], abs(q[s, rows[i], 2]))
        if not math.isnan(stopper_x[c]) and math.isnan(t_impact[c]) and seen[c]:
            v0 = previous_v[c]
            if v0 > 0.0 and base_v < 0.5 * v0:
                gap = stopper_x[c] - (previous_x[c] - x0 + half_length)
                t_impact[c] = previous_t[c] + min(max(gap, 0.0) / v0, ts - previous_t[c])
                for i in range(n):
                    theta_impact[c, i] = previous_theta[c, i]
                    omega_impact[c, i] = previous_omega[c, i]
        elif math.isnan(theta_impact[c, 0]) and ts + dt > t_impact[c]:
            for i in range(n):  # the next step contains the impact: record the phase now
                theta_impact[c, i] = q[s, rows[i], 2]
                omega_impact[c, i] = v[s, rows[i], 2]
        seen[c] = True
        previous_t[c], previous_x[c], previous_v[c] = ts, base_x, base_v
        for i in range(n):
            previous_theta[c, i] = q[s, rows[i], 2]
            previous_omega[c, i] = v[s, rows[i], 2]
        if lying_stays[c] and abs(q[s, rows[0], 2]) > overturn_angle:
            decided[c] = out[s] = True
            continue
        base_at_rest = ts > rest_after[c] and abs(base_v) < speed_rest
        if base_at_rest and not math.isnan(barrier):
            within = True
            for i in range(n):
                within = within and abs(q[s, rows[i], 2]) < tilt_limit
            if within:
                # kinetic + potential energy (from rest) of the blocks, summed in order
                energy = 0.0
                for i in range(n):
                    vb = v[s, rows[i]]
                    term = (0.5 * mass[i]) * (vb[0] * vb[0] + vb[1] * vb[1]) + (0.5 * inertia[i]) * (vb[2] * vb[2]) \
                        + (mass[i] * g) * (q[s, rows[i], 1] - height0[i])
                    energy = term if i == 0 else energy + term
                energy += (0.5 * base_mass[c]) * (base_v * base_v)
                if energy < barrier:
                    decided[c] = out[s] = True
                    continue
        quiet = base_at_rest
        for i in range(n):
            quiet = quiet and abs(v[s, rows[i], 2]) < omega_rest
            for j in range(2):
                quiet = quiet and abs(v[s, rows[i], j] - v[s, base_row, j]) < speed_rest
        if not quiet:
            quiet_since[c] = math.nan
            continue
        if math.isnan(quiet_since[c]):
            quiet_since[c] = ts
        out[s] = ts - quiet_since[c] >= quiet_time
    return out


def _rocking_barrier(blocks: list[Any], g: float) -> tuple[float, float]:
    """Lowest potential barrier of rigid rocking of a column of blocks (J) and the tilt limit (rad).

    ``blocks`` bottom to top, standing one on the other at rest (their ``q0``). For each
    k = 1..n the top ``k`` blocks rocking as one body over a bottom corner of the lowest of
    them lift their centre of mass by ``R_k - c_k`` (``c_k``: its height above that corner,
    ``R_k``: its distance from it, half the block width aside); the barrier is the least
    ``m_k g (R_k - c_k)``. The tilt limit is the slenderness ``atan(w / 2 / c_n)`` of a
    single block, half the least of the sub-stacks' for a stack (see :class:`_Watch`).
    """
    barriers, slenderness = [], []
    for k in range(1, len(blocks) + 1):
        top = blocks[len(blocks) - k:]
        half = np.ptp(top[0].shape.vertices, axis=0) / 2  # the lowest block of the k: half width, half height
        bottom = top[0].q0[1] - half[1]
        mass = sum(b.mass for b in top)
        centre = sum(b.mass * (b.q0[1] - bottom) for b in top) / mass
        barriers.append(mass * g * (math.hypot(half[0], centre) - centre))
        slenderness.append(math.atan2(half[0], centre))
    limit = slenderness[0] if len(blocks) == 1 else 0.5 * min(slenderness)
    return min(barriers), limit
