"""LNEC multi-block tests in 3D beside 003: stacked blocks (Table 5a/5b), trilith (Figs. 10, 11), Table 6.

    python benchmarks/bench_lnec_stacked.py                 # everything (about 1.5 h on a shared 2-core machine)
    python benchmarks/bench_lnec_stacked.py --quick         # 3 cells of Table 5a/5b and Fig. 11, nominal only
    python benchmarks/bench_lnec_stacked.py --budget 3600   # start no new run after 1 h; the rest is "not run"

Writes ``benchmarks/results/lnec_stacked.md`` (+ ``lnec_stacked.csv``). Every finished run is
appended to a checkpoint (``out/lnec_stacked_runs.jsonl``, ``--checkpoint``): rerunning the
command resumes where it stopped and rewrites the results from all finished runs.

What is compared (seed ``003_e23e844b706a29bc.txt``; the motions and imperfections are
nscd's assumptions, the paper gives only frequency and amplitude):

* **Table 5a/5b** (stacked pair, 15 constant-sine and 33 Hanning-sine cells): the 3D pair of
  :func:`nscd.lnec.stacked_pair` (Table 2 stones, granite friction 0.577, restitution 0,
  sharp corners). Per block the class "rocks" (maximum tilt >= 0.05 deg, as the Table 4
  benchmark), "N-R" or "Collapse" (the block fell: tilt above 45 deg at the end or above
  :data:`nscd.result.OVERTURN_ANGLE` at any time), the maximum tilt (deg) and the rocking
  pattern of Spanos et al. (003 Fig. 9: 1 both blocks rotate the same way, 2 opposite ways,
  3 as one body, 4 only the top block): the one the pair spends most time in, from the signed
  in-plane angles (:func:`nscd.stacked.classify_patterns`, tolerance 1e-3 rad). A cell agrees when
  the class of both blocks is the measured one ("Collapse" of the top with the bottom
  rocking counts as the table's "Collapse" cell).
* **Fig. 10** (trilith, final displacement pattern in plan at 1, 1.5, 1.7, 3.3, 5, 6.5 Hz):
  the 3D trilith of :func:`nscd.lnec.trilith` at 5 mm (the only trilith amplitude 003
  gives, Fig. 11; at 1-1.7 Hz even the table's full 10 mm stroke stays below the rigid
  trilith's rocking onset); the final pattern is "torsion" when the lintel ends turned by
  >= 1 deg about the vertical (its ends then move 9 mm, visible in a plan sketch),
  "lateral" when anything else moved (tilt >= 0.05 deg or a slide >= 1 mm), "none",
  or "Collapse". 003: lateral at 1-3.3 Hz, torsion of the lintel at 5 and 6.5 Hz.
* **Fig. 11** (trilith, 3.3 Hz / 5 mm): each pillar's largest signed rocking angle either
  way (003: about 1 deg one way and 0.75 deg the other), the largest and the final
  difference between the pillars' angles (in phase: small; residual 0.25 deg), the lintel's
  residual rotation.
* **Table 6** (dynamic critical angle of single specimens 2 and 3 under random motion): the
  30 EC8-compatible accelerograms of 003 are not published; :func:`nscd.synthetic.spectrum_compatible_records`
  generates records to the same target (PGA 2.8 m/s^2, plateau 0.1-0.3 s at 7 m/s^2, 16 s).
  Each record is scaled by increasing load factors (as the tests, section 6.1) until the
  block overturns; the engine's dynamic critical angle is the largest tilt the block came
  back from (a rocking excursion that did not end in overturning). 2D in-plane scenes
  (:func:`nscd.lnec.single_in_plane`): specimen 4's cut base is not modelled (see
  :mod:`nscd.lnec`).

Motions: constant sine ``Harmonic.from_displacement(D, f, 10 cycles, 1 ramp cycle)``
as the Table 4 benchmark, Hanning sine ``HanningSine(D, f, 10 cycles)``; then 2 s free
(1.5 s after a Hanning sine, which ends at rest). Integration: Moreau's midpoint rule at
dt = 1 ms; **every** nominal run is rerun at dt/2 (:func:`nscd.analysis.verify_time_step`;
converged: the same classes and pattern, maximum angles within 10 % + 0.05 deg); an
unconverged cell never counts as agreeing.

Imperfections (003 sections 5.3, 6.2, 8.2: "natural difference in geometry", lack of
perfect contact, non-repeatable initial conditions). Where a cell's peak table
acceleration reaches 0.8 of the rigid structure's rocking onset, :data:`MEMBERS` perturbed
structures (4 per cell, 2 per Hanning-sine cell) are run beside the nominal one (below it no
perturbation of the sizes below can start rocking: they move the onset by about 2 %), seeded
per cell:

* stacked pair: the bottom block's top face tilted about y and x by N(0, 0.2 deg) each
  (out-of-square stones), the top block resting on it, off centre by N(0, 2 mm) along x
  and y and turned about the vertical by N(0, 0.5 deg); friction of each interface
  N(0.577, 10 %);
* trilith: each column turned about the vertical by N(0, 0.5 deg) and off its place by
  N(0, 2 mm) along y; the lintel off centre by N(0, 2 mm) along x and y and turned by
  N(0, 0.5 deg); friction of each of the four interfaces N(0.577, 10 %).

The probabilities over the members are reported; they are not used for the agreement
count, which is the converged nominal structure's (an experimentalist's single test
against a single rigid model), and the members say how fragile that class is.
"""
from __future__ import annotations

import argparse
import json
import math
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

import nscd
from nscd import lnec
from nscd.analysis import verify_time_step
from nscd.motion import STANDARD_GRAVITY, HanningSine, Harmonic, Motion, Record
from nscd.rotation import quaternion_to_matrix
from nscd.shapes3d import box3, polyhedron
from nscd.stacked import PATTERNS, classify_patterns, dominant_pattern
from nscd.synthetic import ec8_spectrum, spectrum_compatible_records

try:  # run as a script (benchmarks/ on sys.path) or imported as benchmarks.bench_lnec_stacked
    from common import markdown_table, stamp, stamp_lines, write_csv, write_text
except ImportError:  # pragma: no cover
    from benchmarks.common import markdown_table, stamp, stamp_lines, write_csv, write_text

COLLAPSE = "Collapse"
#: 003 Table 5a / 5b: (kind, f Hz, D mm) -> (top block, bottom block); a float is the maximum
#: rocking angle in deg, None is "N - R", COLLAPSE the block fell. Blank cells (not tested) absent.
TABLE5: dict[tuple[str, float, int], tuple] = {
    ("sine", 3.0, 2): (2.907, None), ("sine", 3.0, 3): (3.159, None),
    ("sine", 3.3, 2): (2.105, None), ("sine", 3.3, 3): (3.021, None), ("sine", 3.3, 4): (4.145, 0.674),
    ("sine", 4.0, 1): (1.422, None), ("sine", 4.0, 2): (1.99, None), ("sine", 4.0, 3): (3.536, 0.557),
    ("sine", 4.0, 4): (3.128, 0.361), ("sine", 4.0, 5): (COLLAPSE, 5.278),
    ("sine", 5.0, 2): (2.357, 0.419), ("sine", 5.0, 3): (1.852, 0.285), ("sine", 5.0, 4): (COLLAPSE, 9.704),
    ("sine", 6.5, 1): (0.880, 0.132), ("sine", 6.5, 2): (3.472, 1.794),
    ("hanning", 1.0, 1): (None, None),
    ("hanning", 2.0, 2): (0.260, None), ("hanning", 2.0, 3): (0.233, None), ("hanning", 2.0, 4): (0.700, None),
    ("hanning", 2.0, 5): (5.700, None),
    ("hanning", 3.0, 1): (None, None), ("hanning", 3.0, 2): (2.685, None), ("hanning", 3.0, 3): (2.87, None),
    ("hanning", 3.0, 4): (3.598, None),
    ("hanning", 4.0, 1): (1.272, None), ("hanning", 4.0, 2): (1.586, None), ("hanning", 4.0, 3): (1.924, None),
    ("hanning", 4.0, 4): (2.175, 0.224), ("hanning", 4.0, 5): (3.578, 0.600),
    ("hanning", 5.0, 1): (0.605, None), ("hanning", 5.0, 2): (1.524, None), ("hanning", 5.0, 3): (1.652, 0.358),
    ("hanning", 5.0, 4): (2.268, 0.363),
    ("hanning", 6.0, 1): (0.430, None), ("hanning", 6.0, 2): (1.644, 0.346), ("hanning", 6.0, 3): (2.64, 1.72),
    ("hanning", 6.0, 4): (3.672, 2.343),
    ("hanning", 7.0, 1): (0.937, 0.217), ("hanning", 7.0, 2): (2.165, 1.412), ("hanning", 7.0, 3): (2.578, 1.350),
    ("hanning", 7.0, 4): (1.996, 1.406),
    ("hanning", 8.0, 1): (2.527, 0.133), ("hanning", 8.0, 2): (2.048, 1.055), ("hanning", 8.0, 3): (1.568, 1.061),
    ("hanning", 8.0, 4): (1.698, 1.182),
    ("hanning", 9.0, 1): (0.671, 0.207), ("hanning", 9.0, 2): (1.731, 0.926), ("hanning", 9.0, 3): (1.374, 0.873),
}
#: 003 Fig. 10: frequency (Hz) -> final displacement pattern of the trilith.
FIG10: dict[float, str] = {1.0: "lateral", 1.5: "lateral", 1.7: "lateral", 3.3: "lateral",
                           5.0: "torsion", 6.5: "torsion"}
#: 003 Table 6: specimen -> (static, dynamic) critical angle, deg.
TABLE6: dict[int, tuple[float, float]] = {2: (9.6, 11.2), 3: (6.8, 6.9)}

DT, SCHEME, CYCLES = 1e-3, "midpoint", 10
FREE_TIME = {"sine": 2.0, "hanning": 1.5}
#: maximum tilt (deg) below which a block "does not rock" (as the Table 4 benchmark)
NO_ROCKING_DEG = 0.05
#: convergence tolerance on maximum angles, as the Table 4 benchmark
ANGLE_RTOL, ANGLE_ATOL_DEG = 0.1, NO_ROCKING_DEG
#: a block lying beyond this tilt at the end has fallen (deg): to come back from 45 deg a stone of
#: critical angle <= 20 deg needs a table acceleration above g tan(25 deg) = 0.47 g for long enough
FALLEN_DEG = 45.0
#: Fig. 10's classes: lintel yaw (deg) of "torsion", slide (m) that counts as motion
TORSION_DEG, SLIDE_M = 1.0, 1e-3
#: Fig. 10 / 11 amplitude, m (003 gives 5 mm for Fig. 11 only)
TRILITH_AMPLITUDE = 0.005
#: perturbed structures per cell (fewer for the Hanning sine: 33 cells on a shared machine)
MEMBERS = {"sine": 4, "hanning": 2, "trilith": 4}
TILT_DEG, OFFSET_M, YAW_DEG, FRICTION_REL = 0.2, 0.002, 0.5, 0.10
#: ensembles run where the peak table acceleration reaches this fraction of the rigid onset
ENSEMBLE_FROM = 0.8
#: Table 6: records (003 used 30), their length (s), load factors tried in turn, free time after
TABLE6_RECORDS, TABLE6_DURATION, TABLE6_FREE = 1, 16.0, 3.0
LOAD_FACTORS = tuple(np.round(np.arange(0.8, 3.01, 0.2), 2))

#: an outcome's count of steps whose contact problem was not solved to tolerance (reported, not compared)
UNCONVERGED = "unconverged steps"

#: the measured pattern where both blocks rocked
BOTH_ROCK = "pattern 1 or 2"
#: 003 sec. 5.2: "Pattern 2 was recorded with constant sine base motion with frequencies between 4
#: and 5 Hz and amplitudes greater than 4 mm [...]. Pattern 4 was recorded with constant sine base
#: motions with frequencies between 1 and 5 Hz with amplitudes lesser than 4 mm." (f Hz, D mm) -> the
#: pattern the statement gives, or None where it says nothing.
PATTERN_STATEMENTS: dict[str, Callable[[float, float], str | None]] = {
    "sine": lambda f, d: PATTERNS[2] if 4 <= f <= 5 and d > 4 else PATTERNS[4] if 1 <= f <= 5 and d < 4 else None,
}

Cache = dict[str, dict]


# ---------------------------------------------------------------------------------------------
# motions and rigid-body onsets


def table_motion(kind: str, frequency: float, amplitude: float) -> Motion:
    """Constant sine (``"sine"``) or Hanning sine (``"hanning"``) of displacement amplitude (m)."""
    if kind == "sine":
        return Harmonic.from_displacement(amplitude, frequency=frequency, cycles=CYCLES, ramp_cycles=1)
    if kind == "hanning":
        return HanningSine(amplitude, frequency=frequency, cycles=CYCLES)
    raise ValueError(f"kind == {kind!r}, must be 'sine' or 'hanning'.")


def peak_acceleration_g(motion: Motion) -> float:
    """Peak table acceleration of ``motion``, in g."""
    t = np.linspace(0.0, motion.duration, 20001)
    return float(np.max(np.abs(motion.acceleration(t)))) / STANDARD_GRAVITY


def stack_onset() -> float:
    """Static rocking onset of the rigid stacked pair, in g: the lowest of the top block rocking
    on the bottom one (b/h of the top) and the pair rocking as one body about the bottom block's
    corner (half-width of the bottom over the pair's centre-of-mass height)."""
    bottom, top = lnec.SPECIMENS["stacked_bottom"], lnec.SPECIMENS["stacked_top"]
    m_b = bottom.width * bottom.height * bottom.thickness
    m_t = top.width * top.height * top.thickness
    z = (m_b * bottom.height / 2 + m_t * (bottom.height + top.height / 2)) / (m_b + m_t)
    return min(top.width / top.height, bottom.width / 2 / z)


def trilith_onset() -> float:
    """Static rocking onset of the rigid trilith, in g: the portal mechanism (both columns turning
    about their leeward base corners, the lintel carried on their windward top corners), by
    virtual work: sum(m * vertical rise) / sum(m * horizontal travel) of the centres of mass."""
    column, lintel = lnec.SPECIMENS["trilith_column"], lnec.SPECIMENS["trilith_lintel"]
    m_c, m_l = column.width * column.height, lintel.width * lintel.height  # the density and depth cancel
    rise = 2 * m_c * column.width / 2 + m_l * column.width
    travel = 2 * m_c * column.height / 2 + m_l * column.height
    return rise / travel


# ---------------------------------------------------------------------------------------------
# scenes with documented imperfections


def _quaternion(matrix: np.ndarray) -> tuple[float, float, float, float]:
    x, y, z, w = Rotation.from_matrix(matrix).as_quat()
    return (w, x, y, z)


def _yaw(angle: float) -> np.ndarray:
    return Rotation.from_rotvec([0.0, 0.0, angle]).as_matrix()


def stack_scene(shake: Motion, imperfection: dict | None = None) -> nscd.Scene:
    """The stacked pair in 3D, nominal (``imperfection`` None: :func:`nscd.lnec.stacked_pair`) or
    perturbed: ``imperfection`` has ``tilt_x``, ``tilt_y`` (rad, slopes of the bottom block's top
    face along x and y), ``offset`` (m, (x, y) of the top block along that face), ``yaw`` (rad, of
    the top block) and ``friction`` (base-bottom, bottom-top)."""
    if imperfection is None:
        return lnec.stacked_pair(motion=shake)
    bottom, top = lnec.SPECIMENS["stacked_bottom"], lnec.SPECIMENS["stacked_top"]
    sx, sy = math.tan(imperfection["tilt_x"]), math.tan(imperfection["tilt_y"])
    scene = nscd.Scene(dim=3)
    base = scene.add_base(box3(lnec.BASE.width, lnec.BASE.thickness, lnec.BASE.height),
                          position=(0.0, 0.0, -lnec.BASE.height / 2), motion=shake, name="base")
    bx, by, h = bottom.width / 2, bottom.thickness / 2, bottom.height
    corners = np.array([[x, y, z] for x in (-bx, bx) for y in (-by, by)
                        for z in (0.0, h + sx * x + sy * y)])  # top face: z = h + sx x + sy y
    shape = polyhedron(corners)
    centroid = corners.min(axis=0) - shape.vertices.min(axis=0)
    low = scene.add_block(shape, position=tuple(centroid), density=lnec.GRANITE_DENSITY, name="bottom")
    normal = np.array([-sx, -sy, 1.0]) / math.sqrt(1.0 + sx * sx + sy * sy)
    tilt, _ = Rotation.align_vectors([normal], [[0.0, 0.0, 1.0]])
    turn = tilt.as_matrix() @ _yaw(imperfection["yaw"])
    ox, oy = imperfection["offset"]
    centre = np.array([0.0, 0.0, h]) + turn @ np.array([ox, oy, top.height / 2])
    high = scene.add_block(box3(top.width, top.thickness, top.height), position=tuple(centre),
                           orientation=_quaternion(turn), density=lnec.GRANITE_DENSITY, name="top")
    mu_base, mu_joint = imperfection["friction"]
    scene.set_contact(friction=lnec.GRANITE_FRICTION, restitution=0.0)
    scene.set_contact(friction=mu_base, restitution=0.0, between=(base, low))
    scene.set_contact(friction=mu_joint, restitution=0.0, between=(low, high))
    return scene


def trilith_scene(shake: Motion, imperfection: dict | None = None) -> nscd.Scene:
    """The trilith in 3D, nominal (:func:`nscd.lnec.trilith`) or perturbed: ``imperfection`` has
    ``yaw`` (rad: left, right, lintel), ``shift`` (m: y of left and right), ``offset`` (m: (x, y)
    of the lintel) and ``friction`` (base-left, base-right, left-lintel, right-lintel)."""
    if imperfection is None:
        return lnec.trilith(motion=shake)
    column, lintel = lnec.SPECIMENS["trilith_column"], lnec.SPECIMENS["trilith_lintel"]
    span = lintel.width - column.width
    scene = nscd.Scene(dim=3)
    base = scene.add_base(box3(lintel.width, lnec.BASE.thickness, lnec.BASE.height),
                          position=(0.0, 0.0, -lnec.BASE.height / 2), motion=shake, name="base")
    yaw_l, yaw_r, yaw_lintel = imperfection["yaw"]
    pillars = []
    for name, x, yaw, shift in (("left", -span / 2, yaw_l, imperfection["shift"][0]),
                                ("right", span / 2, yaw_r, imperfection["shift"][1])):
        pillars.append(scene.add_block(box3(column.width, column.thickness, column.height),
                                       position=(x, shift, column.height / 2), orientation=_quaternion(_yaw(yaw)),
                                       density=lnec.GRANITE_DENSITY, name=name))
    ox, oy = imperfection["offset"]
    top = scene.add_block(box3(lintel.width, lintel.thickness, lintel.height),
                          position=(ox, oy, column.height + lintel.height / 2),
                          orientation=_quaternion(_yaw(yaw_lintel)), density=lnec.GRANITE_DENSITY, name="lintel")
    scene.set_contact(friction=lnec.GRANITE_FRICTION, restitution=0.0)
    mu = imperfection["friction"]
    for k, pair in enumerate(((base, pillars[0]), (base, pillars[1]), (pillars[0], top), (pillars[1], top))):
        scene.set_contact(friction=mu[k], restitution=0.0, between=pair)
    return scene


def stack_imperfection(rng: np.random.Generator) -> dict:
    """One perturbed stacked pair (see the module docstring)."""
    return {"tilt_x": math.radians(TILT_DEG) * rng.standard_normal(),
            "tilt_y": math.radians(TILT_DEG) * rng.standard_normal(),
            "offset": tuple(OFFSET_M * rng.standard_normal(2)),
            "yaw": math.radians(YAW_DEG) * rng.standard_normal(),
            "friction": tuple(lnec.GRANITE_FRICTION * (1 + FRICTION_REL * rng.standard_normal(2)))}


def trilith_imperfection(rng: np.random.Generator) -> dict:
    """One perturbed trilith (see the module docstring)."""
    return {"yaw": tuple(math.radians(YAW_DEG) * rng.standard_normal(3)),
            "shift": tuple(OFFSET_M * rng.standard_normal(2)),
            "offset": tuple(OFFSET_M * rng.standard_normal(2)),
            "friction": tuple(lnec.GRANITE_FRICTION * (1 + FRICTION_REL * rng.standard_normal(4)))}


# ---------------------------------------------------------------------------------------------
# outcomes


def _simulate(scene: nscd.Scene, t_end: float, dt: float, scheme: str) -> nscd.Result:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # deep-overlap warnings: counted in the report
        return nscd.simulate(scene, t_end, dt=dt, settings=nscd.Settings(scheme=scheme))


def signed_angles(result: nscd.Result, body: str) -> tuple[np.ndarray, np.ndarray]:
    """In-plane rocking angle (about y, positive when the body's top moves to +x) and torsion
    (about the vertical z, counter-clockwise seen from above) of ``body``, rad, relative to its
    initial orientation, per stored step."""
    q = result.orientation(body)
    back = quaternion_to_matrix(q[0]).T
    relative = np.array([quaternion_to_matrix(qk) @ back for qk in q])
    return (np.arctan2(relative[:, 0, 2], relative[:, 2, 2]),
            np.arctan2(relative[:, 1, 0], relative[:, 0, 0]))


def _fallen(result: nscd.Result, body: str) -> bool:
    """Overturned at some time (:meth:`nscd.Result.overturned`), or lying beyond :data:`FALLEN_DEG` at the end."""
    return result.overturned(body) or abs(float(result.rotation(body)[-1])) > math.radians(FALLEN_DEG)


def block_class(fallen: bool, max_deg: float) -> str:
    return COLLAPSE if fallen else ("rocks" if max_deg >= NO_ROCKING_DEG else "N-R")


def stack_outcome(kind: str, frequency: float, amplitude_mm: float, dt: float, scheme: str,
                  imperfection: dict | None = None) -> dict:
    """Class, maximum tilt (deg) of both blocks and the rocking pattern of one stacked-pair run."""
    shake = table_motion(kind, frequency, amplitude_mm * 1e-3)
    result = _simulate(stack_scene(shake, imperfection), shake.duration + FREE_TIME[kind], dt, scheme)
    out = {}
    for name in ("top", "bottom"):
        peak = math.degrees(float(np.max(result.rotation(name))))
        out[f"{name} class"] = block_class(_fallen(result, name), peak)
        out[f"{name} max (deg)"] = peak
    top, _ = signed_angles(result, "top")
    bottom, _ = signed_angles(result, "bottom")
    out["pattern"] = dominant_pattern(classify_patterns(result.time, bottom, top))
    out[UNCONVERGED] = int(result.report.n_unconverged)
    return out


def trilith_outcome(frequency: float, dt: float, scheme: str, imperfection: dict | None = None) -> dict:
    """Fig. 10 pattern and Fig. 11 quantities (deg, m) of one trilith run at ``frequency`` / 5 mm."""
    shake = table_motion("sine", frequency, TRILITH_AMPLITUDE)
    result = _simulate(trilith_scene(shake, imperfection), shake.duration + FREE_TIME["sine"], dt, scheme)
    rock, yaw = {}, {}
    for name in ("left", "right", "lintel"):
        r, z = signed_angles(result, name)
        rock[name], yaw[name] = np.degrees(r), np.degrees(z)
    base_end = result.position("base")[-1]
    slide = max(float(np.linalg.norm((result.position(n)[-1] - result.position(n)[0])[:2] - (base_end - result.position("base")[0])[:2]))
                for n in ("left", "right", "lintel"))
    fallen = any(_fallen(result, n) for n in ("left", "right", "lintel"))
    moved = max(float(np.max(result.rotation(n))) for n in ("left", "right", "lintel")) >= math.radians(NO_ROCKING_DEG)
    lintel_yaw = float(yaw["lintel"][-1])
    pattern = (COLLAPSE if fallen else "torsion" if abs(lintel_yaw) >= TORSION_DEG
               else "lateral" if moved or slide >= SLIDE_M else "none")
    difference = rock["left"] - rock["right"]
    return {
        "pattern": pattern,
        "left + (deg)": float(rock["left"].max()), "left - (deg)": float(-rock["left"].min()),
        "right + (deg)": float(rock["right"].max()), "right - (deg)": float(-rock["right"].min()),
        "max pillar difference (deg)": float(np.max(np.abs(difference))),
        "final pillar difference (deg)": float(difference[-1]),
        "lintel residual (deg)": float(rock["lintel"][-1]),
        "lintel final yaw (deg)": lintel_yaw,
        "largest slide (m)": slide,
        UNCONVERGED: int(result.report.n_unconverged),
    }


def fig11_checks(outcome: dict) -> dict[str, bool]:
    """003 Fig. 11's three findings, each as a yes / no of one trilith outcome.

    * amplitudes: each pillar's larger signed maximum within 50 % of 1 deg and the smaller
      within 50 % of 0.75 deg (003 reads them off a plot: "around 1 degree", "around 0.75");
    * in phase: the pillars rock (>= 0.05 deg) and their angles never differ by more than
      half the larger amplitude (pillars in opposite phase would differ by twice it);
    * lintel residual: the lintel ends turned in the rocking plane by >= 0.05 deg.
    """
    def amplitudes_match(plus: float, minus: float) -> bool:
        big, small = max(plus, minus), min(plus, minus)
        return abs(big - 1.0) <= 0.5 and abs(small - 0.75) <= 0.375

    amplitude = max(outcome["left + (deg)"], outcome["left - (deg)"], outcome["right + (deg)"],
                    outcome["right - (deg)"])
    return {
        "amplitudes about 1 / 0.75 deg": (amplitudes_match(outcome["left + (deg)"], outcome["left - (deg)"])
                                          and amplitudes_match(outcome["right + (deg)"], outcome["right - (deg)"])),
        "pillars in phase": amplitude >= NO_ROCKING_DEG and outcome["max pillar difference (deg)"] <= amplitude / 2,
        "lintel residual rotation": abs(outcome["lintel residual (deg)"]) >= NO_ROCKING_DEG,
    }


def critical_angle_runs(specimen: int, record: Record, dt: float, scheme: str) -> dict:
    """Table 6 for one record: scale it by :data:`LOAD_FACTORS` in turn until the block overturns.
    Returns the largest tilt (deg) the block came back from, the load factor of that run, and the
    first overturning load factor (nan when none overturns)."""
    back_from, at_factor, overturning = 0.0, math.nan, math.nan
    for factor in LOAD_FACTORS:
        scaled = Record(record.samples_mps2 * factor, record.dt, "m/s^2", name=f"{record.name} x{factor:g}")
        scene = lnec.single_in_plane(specimen, motion=scaled)
        result = _simulate(scene, scaled.duration + TABLE6_FREE, dt, scheme)
        tilt = np.degrees(np.abs(result.rotation("block")))
        fell = _fallen(result, "block")
        if fell:
            # excursions before the fatal one: local maxima of the tilt followed by a return to zero
            last_zero = int(np.flatnonzero(tilt < NO_ROCKING_DEG)[-1]) if np.any(tilt < NO_ROCKING_DEG) else 0
            survived = float(np.max(tilt[:last_zero + 1]))
        else:
            survived = float(np.max(tilt))
        if survived > back_from:
            back_from, at_factor = survived, float(factor)
        if fell:
            overturning = float(factor)
            break
    return {"critical (deg)": back_from, "at load factor": at_factor, "overturning load factor": overturning}


def table6_records() -> list[Record]:
    """EC8-compatible records of 003 section 2.3 (PGA 2.8 m/s^2, plateau 0.1-0.3 s at 7 m/s^2)."""
    return spectrum_compatible_records(lambda periods: ec8_spectrum(periods, 2.8, TB=0.1, TC=0.3),
                                       n=TABLE6_RECORDS, duration=TABLE6_DURATION, seed=3)


# ---------------------------------------------------------------------------------------------
# checkpointed driver


class Runner:
    """Runs keyed computations once: finished ones are read from a JSON-lines checkpoint; new
    ones are appended to it; none is started after ``deadline`` (time.monotonic)."""

    def __init__(self, checkpoint: Path, deadline: float):
        self.path, self.deadline = checkpoint, deadline
        self.cache: Cache = {}
        self.commits: dict[str, str] = {}  # key -> commit of the engine the run was computed with
        if checkpoint.exists():
            for line in checkpoint.read_text(encoding="utf-8").splitlines():
                if line.strip():
                    entry = json.loads(line)
                    self.cache[entry["key"]] = entry["value"]
                    self.commits[entry["key"]] = entry["commit"]
        info = stamp()
        self.commit = info["commit"] + (" (nscd/ modified)" if info.get("dirty_engine") else "")
        self.seconds: dict[str, float] = {}

    def __call__(self, key: str, compute: Callable[[], dict]) -> dict | None:
        if key in self.cache:
            return self.cache[key]
        if time.monotonic() > self.deadline:
            return None
        start = time.perf_counter()
        value = compute()
        self.seconds[key] = time.perf_counter() - start
        value = json.loads(json.dumps(value, default=float))
        self.cache[key] = value
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open("a", encoding="utf-8") as stream:  # one line per run: a crash loses one run only
            stream.write(json.dumps({"key": key, "commit": self.commit, "value": value}) + "\n")
        self.commits[key] = self.commit
        print(f"{key}: {self.seconds[key]:.0f} s", flush=True)
        return value


def _verified(runner: Runner, key: str, run: Callable[[float, str], dict], **tolerances) -> dict | None:
    """The run at dt and dt/2 (each checkpointed), compared as :func:`verify_time_step` does."""
    first = runner(f"{key}|dt", lambda: run(DT, SCHEME))
    if first is None:
        return None
    half = runner(f"{key}|dt/2", lambda: run(DT / 2, SCHEME))
    if half is None:
        return None
    outcomes = {DT: _without_counts(first), DT / 2: _without_counts(half)}
    check = verify_time_step(lambda dt, scheme: outcomes[dt], DT, scheme=SCHEME, **tolerances)
    steps = first.get(UNCONVERGED, 0) + half.get(UNCONVERGED, 0)
    return {"outcome": check.outcome, "converged": check.converged, "changes": "; ".join(check.changes),
            UNCONVERGED: steps}


def _without_counts(outcome: dict) -> dict:
    return {k: v for k, v in outcome.items() if k != UNCONVERGED}


#: the top block's own rocking onset on the bottom one (b/h), g
TOP_ONSET = lnec.SPECIMENS["stacked_top"].width / lnec.SPECIMENS["stacked_top"].height

STACK_TOL = {"rtol": ANGLE_RTOL, "atol": {"top max (deg)": ANGLE_ATOL_DEG, "bottom max (deg)": ANGLE_ATOL_DEG}}
TRILITH_TOL = {"rtol": ANGLE_RTOL, "atol": {k: ANGLE_ATOL_DEG for k in (
    "left + (deg)", "left - (deg)", "right + (deg)", "right - (deg)", "max pillar difference (deg)",
    "final pillar difference (deg)", "lintel residual (deg)", "lintel final yaw (deg)")} | {"largest slide (m)": 1e-3}}




def stack_cell(runner: Runner, kind: str, f: float, d: int, ensembles: bool) -> dict | None:
    key = f"stack|{kind}|{f:g}|{d}"
    nominal = _verified(runner, key, lambda dt, scheme: stack_outcome(kind, f, d, dt, scheme),
                        **STACK_TOL)
    if nominal is None:
        return None
    peak = peak_acceleration_g(table_motion(kind, f, d * 1e-3))
    members = []
    if ensembles and peak >= ENSEMBLE_FROM * stack_onset():
        rng = np.random.default_rng([int(f * 10), d, kind == "hanning"])
        for k in range(MEMBERS[kind]):
            imperfection = stack_imperfection(rng)
            member = runner(f"{key}|member {k}", lambda: stack_outcome(kind, f, d, DT, SCHEME, imperfection))
            if member is not None:
                members.append(member)
    return {**nominal, "peak (g)": peak, "members": members}


def trilith_cell(runner: Runner, f: float, ensembles: bool) -> dict | None:
    key = f"trilith|{f:g}"
    nominal = _verified(runner, key, lambda dt, scheme: trilith_outcome(f, dt, scheme), **TRILITH_TOL)
    if nominal is None:
        return None
    peak = peak_acceleration_g(table_motion("sine", f, TRILITH_AMPLITUDE))
    members = []
    if ensembles and peak >= ENSEMBLE_FROM * trilith_onset():
        rng = np.random.default_rng([int(f * 10), 7])
        for k in range(MEMBERS["trilith"]):
            imperfection = trilith_imperfection(rng)
            member = runner(f"{key}|member {k}", lambda: trilith_outcome(f, DT, SCHEME, imperfection))
            if member is not None:
                members.append(member)
    return {**nominal, "peak (g)": peak, "members": members}


def table6_cell(runner: Runner, specimen: int, index: int, record: Record) -> dict | None:
    key = f"table6|{specimen}|record {index}"
    return _verified(runner, key, lambda dt, scheme: critical_angle_runs(specimen, record, dt, scheme),
                     rtol=ANGLE_RTOL, atol={"critical (deg)": ANGLE_ATOL_DEG, "at load factor": 0.0,
                                            "overturning load factor": 0.0})


# ---------------------------------------------------------------------------------------------
# report


def _fmt(value) -> str:
    return "N-R" if value is None else (value if value == COLLAPSE else f"{value:.2f}")


def _measured_class(value) -> str:
    return COLLAPSE if value == COLLAPSE else ("N-R" if value is None else "rocks")


def _measured_pattern(top, bottom) -> str:
    if top is None and bottom is None:
        return "rest"
    if bottom is None:
        return PATTERNS[4]
    return BOTH_ROCK  # 003 section 5.2 names pattern 2 the main one; the table does not say per cell


def _probabilities(members: list[dict], key: str) -> str:
    if not members:
        return "–"
    values = [m[key] for m in members]
    return ", ".join(f"{v} {values.count(v)}/{len(values)}" for v in sorted(set(values), key=str))


#: why the stones rocked where a rigid pair cannot (the report's paragraph)
BELOW_ONSET = (
    "**Below the rigid onset.** A rigid pair on a rigid base under a horizontal acceleration a stays at "
    "rest while a / g is below both edge ratios (the pair about the bottom block's corner, 0.195; the top "
    "block alone, b/h = 0.250) and below the friction coefficient 0.577 (sliding): nothing in a rigid-body "
    "model, 2D or 3D, moves it, and the imperfections of the members (a tilted face of 0.2 deg, a 2 mm offset) move these onsets "
    "by about 2 %. The stones rocked from about a third of it (4 Hz / 1 mm: top block 1.42 deg at 0.27 of "
    "its own b/h). 003 gives the reasons that apply: the stones were sawn and not treated further (sec. "
    "2.1), the contact between them is imperfect and shifts during the test, 'similar to damage in the "
    "base that decreases the critical angle alpha' (sec. 5.3, Fig. 3b), the rotation point is a surface "
    "of a non-rigid stone rather than a corner (sec. 3.3), the multi-block structures slid although eq. "
    "(2.1) forbids it (sec. 8.2), and the stacked tests were not repeatable (sec. 6.2: 3 of 5 repeated "
    "tests differed). The specimen-2 block of Table 4 rocked from 0.67 of its rigid onset "
    "(results/lnec_table4.md); the stacked top block from much lower, which a narrower effective contact "
    "(the top block rocking about a point well inside its 0.15 m base) or a table acceleration with a "
    "peak above the nominal sine's (the records are not published) would explain; neither can be "
    "checked from the paper.")


UNCONVERGED_HEADER = "unconverged steps: nominal at dt + dt/2; members"
UNCONVERGED_NOTE = (
    "Unconverged steps: steps whose frictional contact problem the solver did not bring to its "
    "tolerance (counted in `Result.report`; with `Settings.on_failure='warn'` the run continues from the solver's last iterate); a cell with many "
    "is less certain than its check at dt/2 alone says.")


def _asymmetry_remark(runner: Runner) -> str:
    """What the 5 Hz trilith of Fig. 10 (if run) says about Fig. 11's asymmetric amplitudes."""
    out = runner.cache.get("trilith|5|dt")
    if out is None:
        return ""
    big = max(out["left + (deg)"], out["left - (deg)"])
    small = min(out["left + (deg)"], out["left - (deg)"])
    return (f"Without any imperfection the rigid trilith's amplitudes need not be symmetric (the response to a sine "
            f"that starts one way is not its own mirror image): at 5 Hz / 5 mm (Fig. 10 table) the nominal "
            f"trilith rocks {big:.2f} deg one way and {small:.2f} deg the other ({1 - small / big:.0%} lower), "
            f"pillars in phase (largest difference {out['max pillar difference (deg)']:.2f} deg), with no "
            f"residual lintel rotation ({out['lintel residual (deg)']:.3f} deg).")


def _unconverged(cell: dict) -> str:
    members = "; ".join(str(m.get(UNCONVERGED, 0)) for m in cell["members"]) or "–"
    return f"{cell.get(UNCONVERGED, 0)}; {members}"


def _explain_stack(kind: str, f: float, d: int, cell: dict, measured: tuple) -> str:
    """Why a converged cell disagrees (physics, from the onset and 003's own remarks)."""
    out, peak, onset = cell["outcome"], cell["peak (g)"], stack_onset()
    top_m, bottom_m = measured
    if out["top class"] == "N-R" and _measured_class(top_m) != "N-R":
        if peak < onset:
            return (f"below the onset ({peak / onset:.2f} x {onset:.3f} g, {peak / TOP_ONSET:.2f} x the top block's "
                    f"{TOP_ONSET:.3f} g): no rigid pair on a rigid base moves (see below)")
        return (f"peak {peak:.3f} g is only {peak / onset:.2f} x the rigid onset {onset:.3f} g: the rigid pair "
                f"lifts by {out['bottom max (deg)']:.3f} deg, below the {NO_ROCKING_DEG} deg rocking threshold (the "
                "excursions above the onset are too brief for rocking to grow); the stones rocked as below the onset "
                "(see below)")
    if _measured_class(top_m) == COLLAPSE and out["top class"] != COLLAPSE:
        return ("the rigid top block rocks but stays up; 003 reports sliding and lost contact in the multi-block "
                "tests (sec. 8.2) and a top block that overturned 'with excessive sliding' (sec. 6.2)")
    if out["top class"] == COLLAPSE and _measured_class(top_m) != COLLAPSE:
        return "the rigid top block overturns where the stones, held by friction-lost energy, did not"
    if out["bottom class"] != _measured_class(bottom_m):
        if out["bottom class"] == "rocks":
            return ("above the pair's onset the rigid pair starts as one body (pattern 3) and the bottom block "
                    "lifts; the stones' bottom block has a larger experimental critical angle (Table 3: 0.366 "
                    "rad against 0.322 theoretical)")
        return ("the bottom block stays down: the pair's onset is not reached in the model, the stones' bottom "
                "block rocked by less than a degree (lack of perfect contact, 003 sec. 8.2)")
    return "see the pattern"


def report(runner: Runner, parts: list[str], quick: bool, seconds: float, load: tuple) -> None:
    lines = ["# LNEC multi-block tests of 003 in 3D: stacked blocks (Table 5a/5b), trilith (Figs. 10, 11), "
             "critical angles (Table 6)", "", *stamp_lines(),
             f"- generated by `python benchmarks/bench_lnec_stacked.py{' --quick' if quick else ''}` "
             f"({seconds:.0f} s wall in this invocation, resumed from {runner.path} where runs were finished; "
             f"load average {load[0]:.1f} at the start, {load[1]:.1f} at the end)",
             f"- runs computed with the engine at commit(s): {', '.join(sorted(set(runner.commits.values())))} "
             "(the stamp's commit above is the one that wrote this file)", "",
             "Set-up, motions, imperfections and the classes: the script's docstring. In short: rigid granite "
             f"stones of 003 Table 2 in 3D, friction 0.577, restitution 0, Moreau's midpoint rule at dt = "
             f"{DT * 1e3:g} ms, every nominal run rerun at dt/2 (converged: the same classes and pattern, "
             f"maximum angles within {ANGLE_RTOL:.0%} + {ANGLE_ATOL_DEG} deg); unconverged cells never count "
             f"as agreeing. Constant sine: 10 cycles with raised-cosine ramps, then 2 s free; Hanning sine: 10 "
             f"cycles, then 1.5 s free. A block \"rocks\" at a maximum tilt >= {NO_ROCKING_DEG} deg. Rigid-body "
             f"rocking onsets (static): stacked pair {stack_onset():.3f} g (the pair as one body about the "
             f"bottom block's corner; the top block alone: 0.250 g), trilith {trilith_onset():.3f} g.", ""]
    csv_rows: list[list] = []
    summary: list[str] = []
    for kind, title in (("sine", "constant sine"), ("hanning", "Hanning sine")):
        if ("table5" if kind == "sine" else "hanning") not in parts:
            continue
        cells = [(k, v) for k, v in TABLE5.items() if k[0] == kind]
        rows, notes, agree, unconverged, compared, missing = [], [], 0, 0, 0, []
        block_agree = {"top": 0, "bottom": 0}
        angle_ratios = []
        pattern_agree = pattern_n = 0
        for (kd, f, d), measured in cells:
            cell = stack_cell(runner, kd, f, d, ensembles=not quick)
            if cell is None:
                missing.append(f"{f:g} Hz / {d} mm")
                continue
            compared += 1
            out = cell["outcome"]
            same = (out["top class"] == _measured_class(measured[0])
                    and out["bottom class"] == ("rocks" if measured[1] == COLLAPSE else _measured_class(measured[1])))
            agree += same and cell["converged"]
            unconverged += not cell["converged"]
            block_agree["top"] += cell["converged"] and out["top class"] == _measured_class(measured[0])
            block_agree["bottom"] += cell["converged"] and out["bottom class"] == (
                "rocks" if measured[1] == COLLAPSE else _measured_class(measured[1]))
            mp = _measured_pattern(*measured) if measured[0] != COLLAPSE else "collapse"
            statement = PATTERN_STATEMENTS.get(kind, lambda f, d: None)(f, d)
            if cell["converged"] and statement is not None and out["pattern"] != "rest":
                pattern_n += 1
                pattern_agree += out["pattern"] == statement
            for name, value in (("top", measured[0]), ("bottom", measured[1])):
                if (isinstance(value, float) and measured[0] != COLLAPSE and out[f"{name} class"] == "rocks"
                        and cell["converged"]):
                    angle_ratios.append(out[f"{name} max (deg)"] / value)
            verdict = ("yes" if same else "**no**") if cell["converged"] else "(unconverged)"
            rows.append([f"{f:g}", d, f"{cell['peak (g)']:.3f}", _fmt(measured[0]), _fmt(measured[1]), mp,
                         f"{out['top class']} {out['top max (deg)']:.2f}", f"{out['bottom class']} {out['bottom max (deg)']:.2f}",
                         out["pattern"], "yes" if cell["converged"] else f"**no** ({cell['changes']})",
                         _unconverged(cell), _probabilities(cell["members"], "top class"), _probabilities(cell["members"], "bottom class"),
                         _probabilities(cell["members"], "pattern"), verdict])
            if cell["converged"] and not same:
                notes.append(f"- {f:g} Hz / {d} mm: {_explain_stack(kd, f, d, cell, measured)}.")
            csv_rows.append([f"table5-{kind}", f, d, _fmt(measured[0]), _fmt(measured[1]), out["top class"],
                             round(out["top max (deg)"], 4), out["bottom class"], round(out["bottom max (deg)"], 4),
                             out["pattern"], cell["converged"], round(cell["peak (g)"], 4),
                             _probabilities(cell["members"], "top class"), _probabilities(cell["members"], "bottom class")])
        if not compared and not missing:
            continue
        lines += [f"## Table 5a/5b, {title}", "", UNCONVERGED_NOTE, "",
                  *markdown_table(["f (Hz)", "D (mm)", "peak (g)", "measured top (deg)", "measured bottom (deg)",
                                   "measured pattern", "engine top", "engine bottom", "engine pattern",
                                   "converged at dt/2", UNCONVERGED_HEADER, "members: top", "members: bottom", "members: pattern",
                                   "agrees"], rows), ""]
        ratio_text = (f"engine / measured maximum angle where both rock (converged): median "
                      f"{np.median(angle_ratios):.2f}, range {min(angle_ratios):.2f} to {max(angle_ratios):.2f} "
                      f"over {len(angle_ratios)} block-cells" if angle_ratios else "no block-cell where both rock")
        lines += [f"- cells agreeing ({title}): {agree} of {compared} ({unconverged} unconverged, not counted)"
                  + (f"; not run: {', '.join(missing)}" if missing else "") + ".",
                  f"- per block: the top block's class agrees in {block_agree['top']}, the bottom block's in "
                  f"{block_agree['bottom']} of {compared - unconverged} converged cells.",
                  *([f"- 003 sec. 5.2 (pattern 4 at 1-5 Hz below 4 mm, pattern 2 at 4-5 Hz above 4 mm): the "
                     f"engine's dominant pattern agrees in {pattern_agree} of the {pattern_n} converged cells it "
                     "covers where the engine's pair moves."] if kind in PATTERN_STATEMENTS else []),
                  f"- {ratio_text} (cells where the top block fell excluded).", "",
                  "Disagreements (converged cells):", "", *(notes or ["- none"]), "", BELOW_ONSET, ""]
        if compared:
            summary.append(f"- cells agreeing: {agree} of {compared} ({unconverged} unconverged) [Table 5a/5b {title}]")
    if "fig10" in parts or "fig11" in parts:
        frequencies = [3.3] if quick else sorted(FIG10)
        rows, agree, unconverged, compared, missing, notes = [], 0, 0, 0, [], []
        fig11 = None
        for f in frequencies:
            cell = trilith_cell(runner, f, ensembles=not quick)
            if cell is None:
                missing.append(f"{f:g} Hz")
                continue
            if f == 3.3:
                fig11 = cell
            compared += 1
            out = cell["outcome"]
            same = out["pattern"] == FIG10[f]
            agree += same and cell["converged"]
            unconverged += not cell["converged"]
            rows.append([f"{f:g}", f"{cell['peak (g)']:.3f}", FIG10[f], out["pattern"],
                         f"{out['left + (deg)']:.2f} / {out['left - (deg)']:.2f}, "
                         f"{out['right + (deg)']:.2f} / {out['right - (deg)']:.2f}",
                         f"{out['lintel final yaw (deg)']:.2f}", f"{out['largest slide (m)'] * 1e3:.1f}",
                         "yes" if cell["converged"] else f"**no** ({cell['changes']})", _unconverged(cell),
                         _probabilities(cell["members"], "pattern"),
                         ("yes" if same else "**no**") if cell["converged"] else "(unconverged)"])
            csv_rows.append(["fig10", f, TRILITH_AMPLITUDE * 1e3, FIG10[f], "", out["pattern"],
                             round(out["lintel final yaw (deg)"], 4), "", round(out["largest slide (m)"], 6), "",
                             cell["converged"], round(cell["peak (g)"], 4), _probabilities(cell["members"], "pattern"), ""])
            if cell["converged"] and not same:
                if cell["peak (g)"] < trilith_onset() and out["pattern"] == "none":
                    notes.append(f"- {f:g} Hz: peak {cell['peak (g)']:.3f} g < rigid onset {trilith_onset():.3f} g "
                                 "and < friction 0.577 g: a rigid trilith neither rocks nor slides; the stones did "
                                 "(003 sec. 8.2: multi-block structures slid although eq. 2.1 forbids it, 'insufficient "
                                 "contact between stones').")
                elif FIG10[f] == "torsion":
                    twisted = sum(m["pattern"] == "torsion" for m in cell["members"])
                    sliding = cell["peak (g)"] >= lnec.GRANITE_FRICTION
                    notes.append(
                        f"- {f:g} Hz: no lintel torsion >= {TORSION_DEG:g} deg: the nominal trilith is symmetric "
                        f"about the shaking plane, so its lintel cannot turn; {twisted} of {len(cell['members'])} "
                        "perturbed triliths (stones turned by 0.5 deg, 2 mm offsets, 10 % friction scatter) "
                        f"twisted; the stones slid by at most {out['largest slide (m)'] * 1e3:.1f} mm "
                        + ("(the peak stays below the friction coefficient). " if not sliding
                           else "(the peak exceeds the friction coefficient). ")
                        + "003's pillars slid and turned ('sliding rotation of the pillars', sec. 5.3) although eq. "
                        "2.1 says they should not (sec. 8.2: 'insufficient contact between stones'); the rigid "
                        "model with the documented imperfections does not reproduce that sliding.")
                else:
                    notes.append(f"- {f:g} Hz: engine {out['pattern']}, 003 {FIG10[f]}.")
        lines += ["## Fig. 10: trilith, final displacement pattern (5 mm)", "",
                  *markdown_table(["f (Hz)", "peak (g)", "003", "engine",
                                   "pillar rocking each way, left, right (deg)", "lintel final yaw (deg)",
                                   "largest slide (mm)", "converged at dt/2", UNCONVERGED_HEADER, "members: pattern",
                                   "agrees"], rows), "",
                  UNCONVERGED_NOTE, "",
                  f"- cells agreeing: {agree} of {compared} ({unconverged} unconverged, not counted)"
                  + (f"; not run: {', '.join(missing)}" if missing else "") + ".", "",
                  "Disagreements (converged cells):", "", *(notes or ["- none"]), ""]
        if compared:
            summary.append(f"- cells agreeing: {agree} of {compared} ({unconverged} unconverged) [Fig. 10]")
        if fig11 is not None:
            tri = fig11["outcome"]
            rocks = max(tri["left + (deg)"], tri["left - (deg)"]) >= NO_ROCKING_DEG
            checks = fig11_checks(tri)
            n_ok = sum(checks.values()) if fig11["converged"] else 0
            summary.append(f"- cells agreeing: {n_ok} of {len(checks)} ({0 if fig11['converged'] else len(checks)} "
                           "unconverged) [Fig. 11]")
            lines += ["## Fig. 11: trilith, 3.3 Hz / 5 mm", "",
                      f"Peak table acceleration {fig11['peak (g)']:.3f} g against the rigid trilith's onset "
                      f"{trilith_onset():.3f} g ({fig11['peak (g)'] / trilith_onset():.2f} of it).", "",
                      *markdown_table(["quantity", "engine (nominal)", "members", "003"], [
                          ["max pillar rocking, each way (deg)",
                           f"left {tri['left + (deg)']:.2f} / {tri['left - (deg)']:.2f}, "
                           f"right {tri['right + (deg)']:.2f} / {tri['right - (deg)']:.2f}",
                           "; ".join(f"{m['left + (deg)']:.2f} / {m['left - (deg)']:.2f}" for m in fig11["members"]) or "–",
                           "about 1 one way, 0.75 the other"],
                          ["largest / final difference between the pillars' angles (deg)",
                           f"{tri['max pillar difference (deg)']:.3f} / {tri['final pillar difference (deg)']:.3f}",
                           "; ".join(f"{m['max pillar difference (deg)']:.2f} / {m['final pillar difference (deg)']:.2f}"
                                     for m in fig11["members"]) or "–",
                           "very small (in phase) / residual 0.25"],
                          ["lintel residual rotation (deg)", f"{tri['lintel residual (deg)']:.3f}",
                           "; ".join(f"{m['lintel residual (deg)']:.2f}" for m in fig11["members"]) or "–",
                           "a residual in one direction"],
                          ["converged at dt/2", "yes" if fig11["converged"] else f"no ({fig11['changes']})", "", ""],
                      ]), "",
                      "Quantities agreeing (nominal trilith; the tolerances are in `fig11_checks`): "
                      + ", ".join(f"{name}: {'yes' if ok else 'no'}" for name, ok in checks.items())
                      + "; members: " + ("; ".join(
                          ", ".join(name for name, ok in fig11_checks(m).items() if ok) or "none"
                          for m in fig11["members"]) or "–") + ".", "",
                      ("The pillars rock: compare the amplitudes above." if rocks else
                       "The rigid trilith does not rock at 3.3 Hz / 5 mm: the assumed motion stays below the "
                       "rigid-body onset, where the tested stones rocked by about 1 deg, as specimen 2 rocked in "
                       "Table 4 from 0.67 of its onset (results/lnec_table4.md; 003 attributes such differences to the lack of perfect "
                       "contact and the stones' non-rigid rotation surface, secs. 3.3 and 8.2).")
                      + " 003 attributes the 25 % asymmetry and the residual to sliding rotation of the pillars, "
                      "sliding of the lintel and the stones' 'natural difference in geometry'. "
                      + _asymmetry_remark(runner), ""]
    if "table6" in parts and not quick:
        records = table6_records()
        rows, compared, agree, unconverged, missing = [], 0, 0, 0, []
        for specimen, (static, dynamic) in TABLE6.items():
            found = []
            for index, record in enumerate(records):
                cell = table6_cell(runner, specimen, index, record)
                if cell is None:
                    missing.append(f"specimen {specimen} record {index}")
                    continue
                found.append(cell)
                unconverged += not cell["converged"]
            ok = [c["outcome"]["critical (deg)"] for c in found if c["converged"]
                  and not math.isnan(c["outcome"]["overturning load factor"])]
            if not found:
                continue
            compared += 1
            engine = float(np.mean(ok)) if ok else math.nan
            same = bool(ok) and engine > static
            agree += same
            rows.append([specimen, f"{static:.1f}", f"{dynamic:.1f}",
                         f"{engine:.1f}" if ok else "–", f"{len(ok)} of {len(found)}",
                         "; ".join(f"{c['outcome']['critical (deg)']:.1f} (x{c['outcome']['at load factor']:g}, "
                                   f"falls x{c['outcome']['overturning load factor']:g})" for c in found),
                         "yes" if same else "**no**"])
        lines += ["## Table 6: dynamic critical angle, single specimens 2 and 3 (2D, synthetic EC8 records)", "",
                  *markdown_table(["specimen", "static (deg, 003)", "dynamic (deg, 003)", "engine: mean over records",
                                   "records converged and overturned", "per record: largest tilt returned from "
                                   "(load factor; first overturning factor)",
                                   "dynamic > static, as 003"], rows), "",
                  f"- cells agreeing: {agree} of {compared} ({unconverged} unconverged record runs)"
                  + (f"; not run: {', '.join(missing)}" if missing else "") + ".", "",
                  "The engine's critical angle is the largest tilt a rigid block returned from before the record "
                  "scaling that overturned it; the records are synthetic (the tests' are not published), so the "
                  "comparison is of the finding (dynamic above static, by how much), not record by record. It is "
                  "a lower bound: it only sees the excursions that happened, with load factors "
                  f"{LOAD_FACTORS[1] - LOAD_FACTORS[0]:.1f} apart and {TABLE6_RECORDS} record(s) where 003 used "
                  "thirty; a value below the static angle says that this probe did not reach the regime where a "
                  "rigid block comes back from beyond alpha (the table's acceleration pushing it back), not that "
                  "the rigid model cannot.", ""]
        if compared:
            summary.append(f"- cells agreeing: {agree} of {compared} ({unconverged} unconverged) [Table 6]")
    lines += ["## Summary", "", *summary, ""]
    write_csv("lnec_stacked.csv", ["part", "frequency_hz", "amplitude_mm", "measured_top", "measured_bottom",
                                   "engine_top", "engine_top_deg", "engine_bottom", "engine_bottom_deg",
                                   "engine_pattern", "converged", "peak_g", "members_top", "members_bottom"],
              csv_rows)
    print(f"wrote {write_text('lnec_stacked.md', lines)}")


def main() -> None:
    import os

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="3 stacked cells and Fig. 11, nominal only")
    parser.add_argument("--budget", type=float, default=math.inf, help="start no new run after this many s")
    parser.add_argument("--parts", default="table5,fig11,fig10,table6,hanning",
                        help="comma-separated, in order of running: table5, fig11, fig10, table6, hanning")
    parser.add_argument("--checkpoint", type=Path, default=Path("out/lnec_stacked_runs.jsonl"))
    args = parser.parse_args()
    parts = args.parts.split(",")
    load_start = os.getloadavg()[0]
    runner = Runner(args.checkpoint, time.monotonic() + args.budget)
    start = time.perf_counter()
    if args.quick:
        quick_cells = {k: TABLE5[k] for k in (("sine", 3.0, 2), ("sine", 4.0, 4), ("sine", 5.0, 4))}
        TABLE5.clear()
        TABLE5.update(quick_cells)
    # run in the order of --parts (report() computes what the checkpoint lacks, in its own order)
    for part in parts:
        if part in ("table5", "hanning"):
            kind = "sine" if part == "table5" else "hanning"
            # strongest motions first: if the budget ends, the cells left are the far-below-onset ones
            cells = sorted((k for k in TABLE5 if k[0] == kind),
                           key=lambda k: -peak_acceleration_g(table_motion(k[0], k[1], k[2] * 1e-3)))
            for (kd, f, d) in cells:
                stack_cell(runner, kd, f, d, ensembles=not args.quick)
        elif part in ("fig11", "fig10"):
            for f in ([3.3] if part == "fig11" or args.quick else sorted(FIG10)):
                trilith_cell(runner, f, ensembles=not args.quick)
        elif part == "table6" and not args.quick:
            records = table6_records()
            for specimen in TABLE6:
                for index, record in enumerate(records):
                    table6_cell(runner, specimen, index, record)
        elif part not in ("table6",):
            raise SystemExit(f"--parts: unknown part {part!r}")
    report(runner, parts, args.quick, time.perf_counter() - start, (load_start, os.getloadavg()[0]))


if __name__ == "__main__":
    main()
