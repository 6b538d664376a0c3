"""ParaView export: a :class:`~nscd.result.Result` as a time series of meshes (meshio).

:func:`to_paraview` writes

* the **block surfaces** moving in time: for ``run.pvd`` one VTU file per written step in
  the folder ``run/`` and the ParaView collection ``run.pvd`` (XML, one ``DataSet`` per
  time); for ``run.xdmf`` one XDMF 3 file, a temporal collection of one grid per written
  time, each with its own points (inline XML; written here rather than with meshio, whose
  time series adds a static mesh that ParaView's readers show as a second block frozen at
  t = 0);
* the **contact impulses**, when the result stored them (``simulate(...,
  store_impulses=True)``): ``run_contacts.pvd`` and the folder ``run_contacts/``, one
  vertex per active contact point, for ParaView's Glyph filter;
* ``run_view.py``, a ParaView Python script that opens both, colours the blocks by
  ``body_id`` and draws every contact impulse as an arrow (Glyph Mode "All Points"):
  ``paraview --script=run_view.py`` or ``pvpython run_view.py --screenshot view.png``.

PVD is the format to prefer: ParaView opens it with one reader, with no question, and
the VTU files are also read by plain VTK and meshio. XDMF keeps a run in one file.

Geometry. 3D bodies are their convex hull faces (faces with more than four vertices are
fanned into triangles). A 2D body is the prism of its polygon extruded along z from
``-depth / 2`` to ``+depth / 2``: the 2D plane (x right, y up) is ParaView's x-y plane, so
ParaView's default view (y up) shows the 2D picture. Coordinates are in m.

Cell data of the block surfaces (one value per face, constant over a body):

``body_id``
    int, index of the body in ``result.body_names``
``velocity``
    (3,) centre-of-mass velocity, m/s (2D: (vx, vy, 0))
``overturned``
    int, 1 from the first time the body has rotated by more than
    :data:`nscd.result.OVERTURN_ANGLE` (the test of :meth:`Result.overturned`), else 0

Point data of the contacts (world frame; 2D vectors get z = 0):

``normal_impulse``
    (3,) ``P_n n``, N s (N s per m of depth in 2D), impulse on body
    ``body_b`` over the step ending at that time (``body_a`` gets the
    opposite); the normal ``n`` points from ``body_a`` to ``body_b``
``friction_impulse``
    (3,) ``P_t1 t1 (+ P_t2 t2)``, N s, on ``body_b`` likewise
``body_a``, ``body_b``
    int, body indices

Steps without an active contact give an empty contact file, which ParaView
reads (meshio 5.3 cannot read empty VTU files back).
"""
from __future__ import annotations

import math
import warnings
import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path
from typing import NamedTuple

import meshio
import numpy as np

from nscd._atomic import replacing, write_text
from nscd.result import OVERTURN_ANGLE, Result
from nscd.rotation import quaternion_to_matrix, rotation_2d
from nscd.shapes3d import polyhedron

__all__ = ["to_paraview"]


#: Default 2D extrusion depth as a fraction of the largest block size.
_DEPTH_FRACTION = 0.2

#: Length of the arrow of the largest normal contact impulse in the view script, as a
#: fraction of the largest block size.
_ARROW_FRACTION = 0.3

#: The ParaView Python script written beside every export (``<stem>_view.py``).
_VIEW_SCRIPT = '''"""ParaView view of the nscd export {blocks!r} (written by nscd.io.to_paraview).

    paraview --script={script}                         # the ParaView GUI with this pipeline
    pvpython {script} --screenshot view.png [--time T]  # a picture (on a server: xvfb-run pvpython ...)

Blocks coloured by body_id; contact impulses (when exported) as arrows along the
normal impulse, every contact drawn (Glyph Mode "All Points": ParaView's default
"Uniform Spatial Distribution" samples the points and hides most contacts).
"""
import sys
from pathlib import Path

from paraview.simple import (ColorBy, GetActiveViewOrCreate, GetAnimationScene, Glyph, OpenDataFile,
                             Render, ResetCamera, SaveScreenshot, Show)

HERE = Path(__file__).resolve().parent
BLOCKS = HERE / {blocks!r}
CONTACTS = HERE / {contacts!r}
ARROW_SCALE = {arrow_scale!r}   # m of arrow per N s of normal impulse{per_depth}
UP = {up!r}                     # the vertical axis of the scene

view = GetActiveViewOrCreate("RenderView")
blocks = OpenDataFile(str(BLOCKS))
blocks_display = Show(blocks, view)
ColorBy(blocks_display, ("CELLS", "body_id"))
blocks_display.Opacity = 0.5     # the arrows start at the contact points, under and inside the blocks
arrows = None
if CONTACTS.exists():
    contacts = OpenDataFile(str(CONTACTS))
    arrows = Glyph(registrationName="contact impulses", Input=contacts, GlyphType="Arrow")
    arrows.OrientationArray = ["POINTS", "normal_impulse"]
    arrows.ScaleArray = ["POINTS", "normal_impulse"]
    arrows.ScaleFactor = ARROW_SCALE
    arrows.GlyphMode = "All Points"
    arrows_display = Show(arrows, view)
    arrows_display.ColorArrayName = ["POINTS", ""]   # one solid colour
    arrows_display.AmbientColor = arrows_display.DiffuseColor = [1.0, 0.4, 0.0]
scene = GetAnimationScene()
scene.UpdateAnimationUsingDataTimeSteps()
view.CameraViewUp = [0.0, 0.0, 1.0] if UP == "z" else [0.0, 1.0, 0.0]
view.CameraPosition = [0.0, -10.0, 0.0] if UP == "z" else [0.0, 0.0, 10.0]
view.CameraFocalPoint = [0.0, 0.0, 0.0]
ResetCamera(view)

if "--time" in sys.argv:
    scene.AnimationTime = float(sys.argv[sys.argv.index("--time") + 1])
if "--screenshot" in sys.argv:
    Render(view)
    SaveScreenshot(sys.argv[sys.argv.index("--screenshot") + 1], view, ImageResolution=[1200, 800])
'''

#: meshio cell type of a face with 3 and 4 vertices (larger faces are fanned).
_FACE_TYPE = {3: "triangle", 4: "quad"}


class _Surface(NamedTuple):
    """Surfaces of all bodies in their body frames, stacked.

    points : (p, 3) body-frame coordinates, m
    point_body : (p,) body index of each point
    cells : list of (meshio cell type, (c, k) int point indices)
    cell_body : list of (c,) body index of each cell, one array per block of ``cells``
    """

    points: np.ndarray
    point_body: np.ndarray
    cells: list[tuple[str, np.ndarray]]
    cell_body: list[np.ndarray]


def to_paraview(result: Result, path: str | Path, every: int = 1,
                depth: float | None = None) -> list[Path]:
    """Write ``result`` as ParaView time series of the block surfaces and contact impulses.

    Parameters
    ----------
    result : Result
        A simulation result (from :func:`nscd.simulate` or :func:`nscd.load`; a loaded
        result carries no contact impulses).
    path : str or Path
        ``*.pvd`` (VTU files in the folder ``<stem>/`` next to it) or ``*.xdmf``
        (one XDMF 3 file, XML data). Parent folders are created; existing files of the
        same names are overwritten.
    every : int
        Write every ``every``-th stored time (>= 1); the last time is always written.
    depth : float, optional
        2D only: extrusion depth along z in m (> 0); default 0.2 times the largest side of
        the bounding boxes of the dynamic bodies (of all bodies if none is dynamic).

    Returns
    -------
    list of Path
        The block series (``path``), when ``result.contacts`` is not None the contact
        series ``<stem>_contacts.pvd``, and the ParaView script ``<stem>_view.py``.

    Raises
    ------
    ValueError
        For ``every < 1``, ``depth <= 0`` or not finite, or a suffix other than ``.pvd``
        or ``.xdmf``.
    TypeError
        If ``every`` is not an integer.
    """
    path = Path(path)
    if path.suffix not in (".pvd", ".xdmf"):
        raise ValueError(f"path == {str(path)!r}, must end with .pvd or .xdmf.")
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)):
        raise TypeError(f"every == {every!r}, must be an integer >= 1.")
    if every < 1:
        raise ValueError(f"every == {every}, must be >= 1.")
    if depth is not None:
        if not math.isfinite(depth) or depth <= 0.0:
            raise ValueError(f"depth == {depth}, must be > 0 m.")
        if result.dim == 3:
            warnings.warn("depth has no effect on a 3D result.", stacklevel=2)
    steps = _written_steps(len(result.time), every)
    surface = _surface(result, depth)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".pvd":
        _write_pvd(path, result.time[steps], steps, _block_meshes(result, surface, steps))
    else:
        _write_xdmf(path, result, surface, steps)
    written = [path]
    if result.contacts is not None:
        contacts_path = path.with_name(f"{path.stem}_contacts.pvd")
        # contacts[k] belongs to the step ending at time[k + 1]; t = 0 has none.
        contact_steps = steps[steps > 0]
        meshes = (_contact_mesh(result.contacts[k - 1]) for k in contact_steps)
        _write_pvd(contacts_path, result.time[contact_steps], contact_steps, meshes)
        written.append(contacts_path)
    written.append(_write_view_script(path, result, surface))
    return written


def _write_view_script(path: Path, result: Result, surface: _Surface) -> Path:
    """``<stem>_view.py``: the ParaView Python script that shows the export (see _VIEW_SCRIPT)."""
    size = float(np.ptp(surface.points, axis=0).max())
    largest = max((float(np.max(np.abs(c["impulse"][:, 0]), initial=0.0)) for c in result.contacts or []),
                  default=0.0)
    script = path.with_name(f"{path.stem}_view.py")
    text = _VIEW_SCRIPT.format(
        blocks=path.name, contacts=f"{path.stem}_contacts.pvd", script=script.name,
        arrow_scale=_ARROW_FRACTION * size / largest if largest > 0.0 else 1.0,
        per_depth=" (per m of depth in 2D)" if result.dim == 2 else "",
        up="z" if result.dim == 3 else "y")
    write_text(script, text)
    return script


def _written_steps(n_times: int, every: int) -> np.ndarray:
    """Indices 0, every, 2 every, ... of the stored times, plus the last one."""
    steps = np.arange(0, n_times, every)
    return steps if steps[-1] == n_times - 1 else np.append(steps, n_times - 1)


def _default_depth(result: Result) -> float:
    """0.2 x the largest bounding-box side of the dynamic bodies (all bodies if none), m."""
    bodies = [i for i, kind in enumerate(result.body_kinds) if kind == "dynamic"]
    shapes = [result.shapes[i] for i in bodies] if bodies else result.shapes
    return _DEPTH_FRACTION * max(float(np.ptp(s, axis=0).max()) for s in shapes)


def _prism(vertices: np.ndarray, depth: float) -> tuple[np.ndarray, list[np.ndarray]]:
    """Points (2k, 3) and outward-oriented faces of a CCW polygon (k, 2) extruded along z."""
    k = len(vertices)
    points = np.vstack([np.column_stack([vertices, np.full(k, -depth / 2)]),
                        np.column_stack([vertices, np.full(k, depth / 2)])])
    i = np.arange(k)
    j = (i + 1) % k
    sides = list(np.column_stack([i, j, j + k, i + k]))  # outward: CCW edge, then up
    return points, [i[::-1], i + k, *sides]


def _hull(vertices: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """Points (n, 3) and outward CCW faces of the convex hull of body-frame vertices."""
    poly = polyhedron(vertices)
    return poly.vertices, [np.asarray(f) for f in poly.faces]


def _surface(result: Result, depth: float | None) -> _Surface:
    """Body-frame surfaces of all bodies; faces grouped into meshio cell blocks."""
    if result.dim == 2:
        depth = _default_depth(result) if depth is None else float(depth)
    points, point_body, faces, face_body = [], [], [], []
    offset = 0
    for body, vertices in enumerate(result.shapes):
        pts, body_faces = _prism(vertices, depth) if result.dim == 2 else _hull(vertices)
        for face in body_faces:
            # fan larger faces into triangles; the VTU and XDMF writers share cell types
            pieces = [face] if len(face) <= 4 else [face[[0, m, m + 1]] for m in range(1, len(face) - 1)]
            faces.extend(p + offset for p in pieces)
            face_body.extend([body] * len(pieces))
        points.append(pts)
        point_body.append(np.full(len(pts), body))
        offset += len(pts)
    face_body = np.array(face_body)
    sizes = np.array([len(f) for f in faces])
    cells, cell_body = [], []
    for size in (3, 4):
        mine = np.flatnonzero(sizes == size)
        if len(mine):
            cells.append((_FACE_TYPE[size], np.array([faces[m] for m in mine])))
            cell_body.append(face_body[mine])
    return _Surface(np.vstack(points), np.concatenate(point_body), cells, cell_body)


def _pose(result: Result, step: int) -> tuple[np.ndarray, np.ndarray]:
    """Rotations (n_bodies, 3, 3) body to world and positions (n_bodies, 3), m, at ``step``."""
    q = result.q[step]
    if result.dim == 3:
        return np.array([quaternion_to_matrix(qi[3:]) for qi in q]), q[:, :3]
    rotations = np.zeros((len(q), 3, 3))
    rotations[:, :2, :2] = [rotation_2d(a) for a in q[:, 2]]
    rotations[:, 2, 2] = 1.0
    return rotations, np.column_stack([q[:, :2], np.zeros(len(q))])


def _placed_points(result: Result, surface: _Surface, step: int) -> np.ndarray:
    """World coordinates (p, 3) of the surface points at ``step``, m."""
    rotations, positions = _pose(result, step)
    b = surface.point_body
    return np.einsum("pij,pj->pi", rotations[b], surface.points) + positions[b]


def _overturned(result: Result) -> np.ndarray:
    """(n, n_bodies) int: 1 once the body's rotation has exceeded the overturning angle."""
    rotation = np.column_stack([np.abs(result.rotation(i)) for i in range(len(result.body_names))])
    return (np.maximum.accumulate(rotation, axis=0) > OVERTURN_ANGLE).astype(np.int32)


def _cell_data(result: Result, surface: _Surface, overturned: np.ndarray,
               step: int) -> dict[str, list[np.ndarray]]:
    """Per-block cell data ``body_id``, ``velocity`` (m/s, 3-vector), ``overturned`` at ``step``."""
    velocity = np.zeros((len(result.body_names), 3))
    velocity[:, :result.dim] = result.v[step, :, :result.dim]
    return {"body_id": [b.astype(np.int32) for b in surface.cell_body],
            "velocity": [velocity[b] for b in surface.cell_body],
            "overturned": [overturned[step, b] for b in surface.cell_body]}


def _block_meshes(result: Result, surface: _Surface, steps: np.ndarray) -> Iterator[meshio.Mesh]:
    """The placed block surfaces at each of ``steps``, one mesh at a time."""
    overturned = _overturned(result)
    for step in steps:
        yield meshio.Mesh(_placed_points(result, surface, step), surface.cells,
                          cell_data=_cell_data(result, surface, overturned, step))


def _contact_mesh(record: dict) -> meshio.Mesh:
    """Vertex cells at the active contact points of one step, with world-frame impulses."""
    point = np.asarray(record["point"], float)
    m, dim = point.shape
    frame = np.asarray(record["frame"], float)      # rows [n, t1, (t2)], (m, dim, dim)
    impulse = np.asarray(record["impulse"], float)  # (m, dim) in the contact frame, N s
    normal = impulse[:, :1] * frame[:, 0]
    friction = np.einsum("mk,mkd->md", impulse[:, 1:], frame[:, 1:])

    def as_3d(a: np.ndarray) -> np.ndarray:
        return np.column_stack([a, np.zeros((m, 3 - dim))])

    return meshio.Mesh(
        as_3d(point), [("vertex", np.arange(m).reshape(m, 1))],
        point_data={"normal_impulse": as_3d(normal), "friction_impulse": as_3d(friction),
                    "body_a": np.asarray(record["body_a"], np.int32),
                    "body_b": np.asarray(record["body_b"], np.int32)},
    )


def _write_pvd(path: Path, times: np.ndarray, steps: np.ndarray, meshes: Iterator[meshio.Mesh]) -> None:
    """VTU files ``<stem>/<stem>_<step>.vtu`` and the collection ``path`` listing them by time."""
    folder = path.with_suffix("")
    folder.mkdir(parents=True, exist_ok=True)
    collection = ET.Element("Collection")
    for t, step, mesh in zip(times, steps, meshes):
        name = f"{path.stem}_{step:06d}.vtu"
        with replacing(folder / name) as tmp:
            meshio.write(tmp, mesh)
        ET.SubElement(collection, "DataSet", timestep=repr(float(t)), group="", part="0",
                      file=f"{folder.name}/{name}")
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    root.append(collection)
    ET.indent(root)
    with replacing(path) as tmp:
        ET.ElementTree(root).write(tmp, encoding="utf-8", xml_declaration=True)


#: XDMF codes of the cell types in a Mixed topology (XDMF model: Triangle 4, Quadrilateral 5).
_XDMF_CELL_CODE = {"triangle": 4, "quad": 5}


def _xdmf_item(parent: ET.Element, values: np.ndarray, number_type: str, **attributes: str) -> ET.Element:
    """An inline XML DataItem holding ``values`` (floats written with 17 digits: exact)."""
    values = np.asarray(values)
    item = ET.SubElement(parent, "DataItem", Dimensions=" ".join(map(str, values.shape)),
                         NumberType=number_type, Precision="8" if number_type == "Float" else "4",
                         Format="XML", **attributes)
    fmt = "%.17g" if number_type == "Float" else "%d"
    rows = values.reshape(len(values), -1) if values.ndim > 1 else np.array_split(values, -(-len(values) // 10))
    item.text = "\n" + "\n".join(" ".join(fmt % x for x in row) for row in rows) + "\n"
    return item


def _write_xdmf(path: Path, result: Result, surface: _Surface, steps: np.ndarray) -> None:
    """One XDMF 3 file: a temporal collection of the placed surfaces, one grid per written time.

    Every grid carries its own point coordinates and topology (no static mesh beside the
    series, which some readers show as an extra block that stays at t = 0; no references
    between grids, which ParaView's Xdmf3 reader does not resolve). Data is inline XML.
    """
    overturned = _overturned(result)
    mixed = np.concatenate([np.column_stack([np.full(len(c), _XDMF_CELL_CODE[kind]), c]).ravel()
                            for kind, c in surface.cells])
    n_cells = sum(len(c) for _, c in surface.cells)
    root = ET.Element("Xdmf", Version="3.0")
    domain = ET.SubElement(root, "Domain")
    series = ET.SubElement(domain, "Grid", Name="blocks", GridType="Collection", CollectionType="Temporal")
    for step in steps:
        grid = ET.SubElement(series, "Grid", Name=f"blocks_{step:06d}", GridType="Uniform")
        ET.SubElement(grid, "Time", Value=repr(float(result.time[step])))
        topology = ET.SubElement(grid, "Topology", TopologyType="Mixed", NumberOfElements=str(n_cells))
        _xdmf_item(topology, mixed, "Int")
        geometry = ET.SubElement(grid, "Geometry", GeometryType="XYZ")
        _xdmf_item(geometry, _placed_points(result, surface, step), "Float")
        for name, blocks in _cell_data(result, surface, overturned, step).items():
            values = np.concatenate(blocks)
            attribute = ET.SubElement(grid, "Attribute", Name=name, Center="Cell",
                                      AttributeType="Vector" if values.ndim == 2 else "Scalar")
            _xdmf_item(attribute, values, "Float" if values.dtype.kind == "f" else "Int")
    ET.indent(root)
    text = ET.tostring(root, encoding="unicode")
    write_text(path, '<?xml version="1.0" ?>\n<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>\n' + text + "\n")
