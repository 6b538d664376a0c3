"""ParaView export (nscd.io): the files read back with meshio hold the simulated motion.

Oracles: the written steps, point and cell counts follow from the definitions (every
``every``-th time plus the last; a 2D box is a prism of 8 points and 6 faces, a 3D box has
8 points and 6 faces); the centroid of each body's points is its centre of mass (boxes);
a block thrown clear of everything follows the ballistic path x0 + v0 t - g t^2 / 2 and
rotates at its initial rate; a block resting on the ground receives the impulse m g dt
per step, straight up, at its bottom corners; the overturned flag switches on for good
the first time the rotation exceeds pi/2 - 0.02 rad.
"""
from __future__ import annotations

import dataclasses
import math
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np
import pytest

import nscd
from nscd.cli import main
from nscd.io import to_paraview
from nscd.motion import STANDARD_GRAVITY as G

DT = 1e-3
T_END = 0.05
RHO = 2000.0                      # kg/m^3
REST = (0.2, 0.6)                 # 2D resting block, m; in 3D (0.2, 0.3, 0.6)
THROWN_V = (1.0, 2.0)             # m/s, horizontal and up
THROWN_OMEGA = 5.0                # rad/s
THROWN_ANGLE = 0.3                # rad

# Geometry is placed in float64 from the stored q; coordinates of order 1 m agree to
# a few ulp.
ROUND_OFF = 1e-12
# The ballistic path and impulses come from the engine: the midpoint rule (theta = 1/2)
# integrates constant gravity exactly, so only round-off over 50 steps remains (positions
# ~1 m); impulses are solved to the solver tolerance (relative 1e-8 of m g dt).
BALLISTIC_TOL = 1e-9
IMPULSE_RTOL = 1e-6


def _scene(dim: int) -> nscd.Scene:
    """Ground, a block resting on it (body 1), a small cube thrown clear of it (body 2)."""
    scene = nscd.Scene(dim=dim)
    if dim == 2:
        scene.add_base(nscd.box(1.0, 0.2), position=(0.0, -0.1))
        scene.add_block(nscd.box(*REST), position=(0.0, REST[1] / 2), density=RHO)
        scene.add_block(nscd.box(0.1, 0.1), position=(0.4, 0.5), angle=THROWN_ANGLE, density=RHO,
                        velocity=THROWN_V, omega=THROWN_OMEGA)
    else:
        scene.add_base(nscd.box(1.0, 1.0, 0.2), position=(0.0, 0.0, -0.1))
        scene.add_block(nscd.box(0.2, 0.3, 0.6), position=(0.0, 0.0, 0.3), density=RHO)
        scene.add_block(nscd.box(0.1, 0.1, 0.1), position=(0.4, 0.0, 0.5), density=RHO,
                        velocity=(THROWN_V[0], 0.0, THROWN_V[1]), omega=(0.0, 0.0, THROWN_OMEGA))
    return scene


@pytest.fixture(scope="module", params=[2, 3])
def result(request) -> nscd.Result:
    return nscd.simulate(_scene(request.param), t_end=T_END, dt=DT, store_impulses=True)


def _series(pvd: Path) -> list[tuple[float, Path]]:
    """(time, file) of every data set of a ParaView collection."""
    root = ET.parse(pvd).getroot()
    return [(float(d.get("timestep")), pvd.parent / d.get("file")) for d in root.iter("DataSet")]


def _body_points(mesh: meshio.Mesh, n_bodies: int) -> list[np.ndarray]:
    """Points of each body, found through the cells' body_id."""
    out = []
    for body in range(n_bodies):
        index = np.concatenate([c.data[ids == body].ravel()
                                for c, ids in zip(mesh.cells, mesh.cell_data["body_id"])])
        out.append(mesh.points[np.unique(index)])
    return out


def _cells_of(mesh: meshio.Mesh, name: str) -> np.ndarray:
    return np.concatenate(mesh.cell_data[name])


def test_pvd_steps_counts_and_positions(result, tmp_path):
    written = result.to_paraview(tmp_path / "run.pvd", every=7)
    assert written == [tmp_path / "run.pvd", tmp_path / "run_contacts.pvd", tmp_path / "run_view.py"]
    series = _series(written[0])
    steps = [0, 7, 14, 21, 28, 35, 42, 49, 50]    # every 7th and the last of 51 times
    assert [t for t, _ in series] == pytest.approx(result.time[steps], abs=0)
    for step, (_, file) in zip(steps, series):
        mesh = meshio.read(file)
        assert len(mesh.points) == 3 * 8          # three boxes of 8 corners (2D: prisms)
        assert sum(len(c) for c in mesh.cells) == 3 * 6
        assert {c.type for c in mesh.cells} == {"quad"}
        for body, points in enumerate(_body_points(mesh, 3)):
            expected = np.zeros(3)
            expected[:result.dim] = result.position(body)[step]
            np.testing.assert_allclose(points.mean(axis=0), expected, atol=ROUND_OFF)
        body_id = _cells_of(mesh, "body_id")
        np.testing.assert_array_equal(np.bincount(body_id), [6, 6, 6])
        velocity = _cells_of(mesh, "velocity")
        np.testing.assert_allclose(velocity[:, :result.dim], result.v[step, body_id, :result.dim], atol=0)
        assert np.all(_cells_of(mesh, "overturned") == 0)


def test_thrown_block_follows_the_ballistic_path(result, tmp_path):
    series = _series(result.to_paraview(tmp_path / "run.pvd", every=10)[0])
    up = result.dim - 1
    for t, file in series:
        points = _body_points(meshio.read(file), 3)[2]
        centre = points.mean(axis=0)
        expected = np.zeros(3)
        expected[0] = 0.4 + THROWN_V[0] * t
        expected[up] = 0.5 + THROWN_V[1] * t - G * t * t / 2
        np.testing.assert_allclose(centre, expected, atol=BALLISTIC_TOL)
        # a rigid 0.1 m cube (2D: 0.1 x 0.1 x depth prism): corners at fixed distances
        if result.dim == 3:
            np.testing.assert_allclose(np.linalg.norm(points - centre, axis=1),
                                       0.05 * math.sqrt(3), atol=ROUND_OFF)
        # the box's side directions turn at the initial rate (about z in both dimensions)
        in_plane = points[:, :2] - centre[:2]
        angles = np.arctan2(in_plane[:, 1], in_plane[:, 0])
        start = THROWN_ANGLE if result.dim == 2 else 0.0
        turned = np.mod(angles - (start + THROWN_OMEGA * t) - math.pi / 4, math.pi / 2)
        np.testing.assert_allclose(np.minimum(turned, math.pi / 2 - turned), 0.0, atol=BALLISTIC_TOL)


def test_2d_prism_default_depth(tmp_path):
    result = nscd.simulate(_scene(2), t_end=2 * DT, dt=DT)
    first = _series(to_paraview(result, tmp_path / "run.pvd")[0])[0][1]
    z = meshio.read(first).points[:, 2]
    depth = 0.2 * max(REST)                     # 0.2 x the largest side of a block
    np.testing.assert_allclose(np.sort(np.unique(np.round(z, 12))), [-depth / 2, depth / 2], atol=ROUND_OFF)
    z = meshio.read(_series(to_paraview(result, tmp_path / "d.pvd", depth=0.05)[0])[0][1]).points[:, 2]
    np.testing.assert_allclose(np.abs(z), 0.025, atol=ROUND_OFF)


def test_contacts_carry_the_weight_of_the_resting_block(result, tmp_path):
    contacts = _series(result.to_paraview(tmp_path / "run.pvd", every=10)[1])
    assert [t for t, _ in contacts] == pytest.approx(result.time[[10, 20, 30, 40, 50]], abs=0)
    volume = np.prod(REST) if result.dim == 2 else 0.2 * 0.3 * 0.6
    weight = RHO * volume * G * DT                # N s per step (per m of depth in 2D)
    up = np.eye(3)[result.dim - 1]
    for _, file in contacts:
        mesh = meshio.read(file)
        n = 2 if result.dim == 2 else 4           # the bottom corners of the resting block
        assert len(mesh.points) == n and len(mesh.cells[0]) == n
        on_block = np.where(mesh.point_data["body_b"] == 1, 1.0, -1.0)
        assert set(mesh.point_data["body_a"]) | set(mesh.point_data["body_b"]) == {0, 1}
        total = np.sum(on_block[:, None] * mesh.point_data["normal_impulse"], axis=0)
        np.testing.assert_allclose(total, weight * up, rtol=IMPULSE_RTOL, atol=IMPULSE_RTOL * weight)
        np.testing.assert_allclose(mesh.point_data["friction_impulse"], 0.0, atol=IMPULSE_RTOL * weight)
        np.testing.assert_allclose(mesh.points @ up, 0.0, atol=1e-6)  # on the ground, within the gap tolerance


def test_overturned_flag_is_cumulative(tmp_path):
    base = nscd.simulate(_scene(2), t_end=10 * DT, dt=DT)
    time = np.linspace(0.0, 1.0, 11)
    q = np.repeat(base.q[:1], len(time), axis=0)
    q[:, 1, 2] = 2.0 * np.sin(math.pi * time)     # tips past pi/2 - 0.02 at t = 0.3, back to 0
    synthetic = dataclasses.replace(base, time=time, q=q, v=np.zeros_like(q), contacts=None)
    written = to_paraview(synthetic, tmp_path / "run.pvd")
    assert written == [tmp_path / "run.pvd", tmp_path / "run_view.py"]
    flags = []
    for _, file in _series(written[0]):
        mesh = meshio.read(file)
        flags.append(_cells_of(mesh, "overturned")[_cells_of(mesh, "body_id") == 1])
    first = int(np.argmax(np.abs(q[:, 1, 2]) > math.pi / 2 - 0.02))
    assert first == 3                              # 2 sin(0.3 pi) = 1.62 > 1.551 > 2 sin(0.2 pi)
    for k, f in enumerate(flags):
        assert np.all(f == (k >= first))


def _vtk_series(path: Path) -> list[tuple[float, object]]:
    """(time, data set) of every step of a .pvd (each VTU read by VTK's XML reader) or an
    .xdmf (VTK's vtkXdmfReader, the reader behind ParaView's "XDMF Reader")."""
    from vtkmodules.vtkCommonExecutionModel import vtkStreamingDemandDrivenPipeline
    from vtkmodules.vtkIOXdmf2 import vtkXdmfReader
    from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader

    out = []
    if path.suffix == ".pvd":
        for t, file in _series(path):
            reader = vtkXMLUnstructuredGridReader()
            reader.SetFileName(str(file))
            reader.Update()
            out.append((t, reader.GetOutput()))
        return out
    reader = vtkXdmfReader()
    reader.SetFileName(str(path))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    for t in times:
        reader.UpdateTimeStep(t)
        data = reader.GetOutputDataObject(0)
        copy = data.NewInstance()
        copy.DeepCopy(data)
        out.append((t, copy))
    return out


@pytest.mark.parametrize("suffix", [".pvd", ".xdmf"])
def test_vtk_reads_one_grid_per_step_with_the_bodies_in_place(result, tmp_path, suffix):
    from vtkmodules.util.numpy_support import vtk_to_numpy

    written = result.to_paraview(tmp_path / f"run{suffix}", every=25)
    assert written == [tmp_path / f"run{suffix}", tmp_path / "run_contacts.pvd", tmp_path / "run_view.py"]
    series = _vtk_series(written[0])
    assert [t for t, _ in series] == pytest.approx(result.time[[0, 25, 50]], abs=0)  # 0, 25 dt, 50 dt
    for (t, data), step in zip(series, [0, 25, 50]):
        # one unstructured grid per time, no second (static) block beside it
        assert data.GetClassName() == "vtkUnstructuredGrid"
        assert data.GetNumberOfPoints() == 3 * 8 and data.GetNumberOfCells() == 3 * 6
        points = vtk_to_numpy(data.GetPoints().GetData())
        body_id = vtk_to_numpy(data.GetCellData().GetArray("body_id"))
        np.testing.assert_array_equal(np.bincount(body_id), [6, 6, 6])
        for body in range(3):
            corners = np.unique(np.concatenate([
                [data.GetCell(c).GetPointId(k) for k in range(4)] for c in np.flatnonzero(body_id == body)]))
            np.testing.assert_allclose(points[corners].mean(axis=0)[:result.dim], result.position(body)[step],
                                       atol=ROUND_OFF)
    contacts = _vtk_series(written[1])
    n = 2 if result.dim == 2 else 4          # the resting block's bottom corners, every step
    assert [(d.GetNumberOfPoints(), d.GetNumberOfCells()) for _, d in contacts] == [(n, n), (n, n)]


def test_loaded_result_and_cli(result, tmp_path):
    saved = result.save(tmp_path / "result.npz")
    assert main(["export", str(saved), "-o", str(tmp_path / "out" / "run.pvd"), "--every", "50"]) == 0
    series = _series(tmp_path / "out" / "run.pvd")
    assert len(series) == 2                        # times 0 and 50 dt
    assert not (tmp_path / "out" / "run_contacts.pvd").exists()  # a saved result has no impulses
    mesh = meshio.read(series[-1][1])
    for body, points in enumerate(_body_points(mesh, 3)):
        np.testing.assert_allclose(points.mean(axis=0)[:result.dim], result.position(body)[-1], atol=ROUND_OFF)
    assert main(["export", str(saved), "-o", str(tmp_path / "run.pvd"), "--every", "0"]) == 2


def test_step_without_contact_writes_an_empty_set(tmp_path):
    scene = nscd.Scene()
    scene.add_base(nscd.box(1.0, 0.2), position=(0.0, -0.1))
    scene.add_block(nscd.box(0.1, 0.1), position=(0.0, 1.0), density=RHO)   # falls 0.2 mm in 5 ms
    result = nscd.simulate(scene, t_end=5 * DT, dt=DT, store_impulses=True)
    contacts = _series(to_paraview(result, tmp_path / "run.pvd")[1])
    assert len(contacts) == 5
    for _, file in contacts:
        piece = ET.parse(file).getroot().find("UnstructuredGrid/Piece")
        assert piece.get("NumberOfPoints") == "0" and piece.get("NumberOfCells") == "0"


@pytest.mark.parametrize("kwargs, match", [
    ({"every": 0}, "every == 0, must be >= 1"),
    ({"every": -3}, "every == -3, must be >= 1"),
    ({"depth": 0.0}, "depth == 0.0, must be > 0"),
    ({"depth": -0.1}, "depth == -0.1, must be > 0"),
    ({"depth": math.nan}, "depth == nan, must be > 0"),
    ({"path": "run.vtk"}, "must end with .pvd or .xdmf"),
])
def test_bad_input(kwargs, match, tmp_path):
    result = nscd.simulate(_scene(2), t_end=DT, dt=DT)
    path = tmp_path / kwargs.pop("path", "run.pvd")
    with pytest.raises(ValueError, match=match):
        to_paraview(result, path, **kwargs)
    assert not any(tmp_path.iterdir())             # nothing written
    with pytest.raises(TypeError, match="every == 1.5"):
        to_paraview(result, tmp_path / "run.pvd", every=1.5)


PARAVIEW_DRIVER = '''
import sys
from paraview import servermanager
from paraview.simple import Arrow, GetAnimationScene, GetTimeKeeper
script = sys.argv[1]
sys.argv = [script]
names = {"__file__": script, "__name__": "__main__"}
exec(open(script).read(), names)
arrow_points = servermanager.Fetch(Arrow()).GetNumberOfPoints()
for t in GetTimeKeeper().TimestepValues:
    GetAnimationScene().AnimationTime = t
    blocks = servermanager.Fetch(names["blocks"])
    contacts = servermanager.Fetch(names["contacts"]).GetNumberOfPoints()
    arrows = servermanager.Fetch(names["arrows"]).GetNumberOfPoints() // arrow_points
    print("STEP", t, blocks.GetClassName(), blocks.GetNumberOfPoints(), blocks.GetNumberOfCells(), contacts, arrows)
'''


@pytest.mark.skipif(not (shutil.which("pvpython") and shutil.which("xvfb-run")),
                    reason="needs ParaView's pvpython and xvfb-run (Debian: apt-get install paraview xvfb)")
@pytest.mark.parametrize("suffix", [".xdmf", ".pvd"])
def test_paraview_shows_one_grid_and_every_contact_arrow(result, tmp_path, suffix):
    written = result.to_paraview(tmp_path / f"run{suffix}", every=25)
    (tmp_path / "driver.py").write_text(PARAVIEW_DRIVER)
    for _ in range(3):   # a virtual X server that fails to open a GL window is the machine, not the export
        run = subprocess.run(["xvfb-run", "-a", "pvpython", str(tmp_path / "driver.py"), str(written[-1])],
                             capture_output=True, text=True, timeout=600)
        if not any(word in run.stderr for word in ("CreateAWindow", "bad X server")):
            break
    steps = [line.split()[1:] for line in run.stdout.splitlines() if line.startswith("STEP")]
    assert len(steps) == 3, run.stdout + run.stderr
    n = 2 if result.dim == 2 else 4          # the resting block's bottom corners
    for _, kind, points, cells, contacts, arrows in steps:
        # ParaView's default reader for the file: one grid, no static t = 0 block beside it
        assert (kind, int(points), int(cells)) == ("vtkUnstructuredGrid", 24, 18)
        # contacts only at t > 0: at t = 0 ParaView shows the first contact file
        assert int(contacts) == n and int(arrows) == n      # every contact has its arrow
