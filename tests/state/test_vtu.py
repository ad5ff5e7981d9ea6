"""VTU snapshots and PVD series read back with meshio (ParaView: see paraview_check.py)."""

import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from demcli.state.fields import example_state
from demcli.state.vtu import PvdSeries, Snapshots, write_spheres_vtu, write_walls_vtu


@pytest.fixture
def state():
    return example_state(n_bodies=5, spheres_per_body=2, seed=4)


def test_spheres_vtu_round_trip(tmp_path, state):
    # Given a state with clumps (rotated bodies, offset spheres)
    # When the spheres are written and read back with meshio
    mesh = meshio.read(write_spheres_vtu(tmp_path / "s.vtu", state))
    # Then points are the world sphere centres, one vertex cell each
    assert np.allclose(mesh.points, state.sphere_centres())
    assert mesh.cells[0].type == "vertex" and len(mesh.cells[0].data) == 10
    pd = mesh.point_data
    # And the point data carry radius, diameter, velocity, body id and material
    assert np.allclose(pd["radius"], state["spheres/radius"])
    assert np.allclose(pd["diameter"], 2 * state["spheres/radius"])
    assert np.allclose(pd["velocity"], state.sphere_velocities())
    assert np.allclose(pd["speed"], np.linalg.norm(state.sphere_velocities(), axis=1))
    assert np.array_equal(pd["body_id"], state["bodies/id"][state["spheres/body"]])
    assert np.array_equal(pd["material"], state["spheres/material"])
    assert np.allclose(pd["omega"], state["bodies/omega"][state["spheres/body"]])


def test_spheres_vtu_is_binary_compressed(tmp_path, state):
    text = write_spheres_vtu(tmp_path / "s.vtu", state).read_text()
    assert 'compressor="vtkZLibDataCompressor"' in text and 'format="binary"' in text


def test_walls_vtu_geometry(tmp_path, state):
    # Given a bottom plane, a side plane and a cylinder in a 0.1 x 0.1 x 0.15 box
    # When the walls are written and read back
    mesh = meshio.read(write_walls_vtu(tmp_path / "w.vtu", state))
    quads = mesh.cells_dict["quad"]
    wall = mesh.cell_data["wall"][0]
    # Then the bottom plane is the box's bottom face, wound counter-clockwise about +z
    bottom = mesh.points[quads[wall == 0][0]]
    assert np.allclose(bottom[:, 2], 0.0)
    assert np.allclose(np.sort(bottom[:, 0])[[0, -1]], [0.0, 0.1])
    assert np.allclose(np.sort(bottom[:, 1])[[0, -1]], [0.0, 0.1])
    n = np.cross(bottom[1] - bottom[0], bottom[2] - bottom[1])
    assert n[2] > 0
    # And the side plane x = 0 spans y and z of the box
    side = mesh.points[quads[wall == 1][0]]
    assert np.allclose(side[:, 0], 0.0) and np.isclose(side[:, 2].max(), 0.15)
    # And the cylinder is a 48-sided tube of radius 0.05 around (0.05, 0.05) from z 0 to 0.15
    cyl = mesh.points[np.unique(quads[wall == 2])]
    assert (wall == 2).sum() == 48
    assert np.allclose(np.hypot(cyl[:, 0] - 0.05, cyl[:, 1] - 0.05), 0.05)
    assert np.allclose(sorted(set(np.round(cyl[:, 2], 12))), [0.0, 0.15])
    # And the cell data carry per-wall force and velocity
    assert np.allclose(mesh.cell_data["force"][0], state["walls/force"][wall])
    assert np.array_equal(mesh.cell_data["kind"][0], state["walls/kind"][wall])


def test_snapshots_write_pvd_series(tmp_path, state):
    # Given a snapshot writer for a stage folder
    snaps = Snapshots(tmp_path / "compaction")
    # When two snapshots are written at different times
    for t in (0.0, 0.5):
        state.meta["time"] = t
        snaps.write(state)
    # Then spheres.pvd lists both files with their times, relative to the .pvd
    root = ET.parse(tmp_path / "compaction" / "spheres.pvd").getroot()
    assert root.get("type") == "Collection"
    entries = [(float(d.get("timestep")), d.get("file")) for d in root.iter("DataSet")]
    assert entries == [(0.0, "spheres_000000.vtu"), (0.5, "spheres_000001.vtu")]
    # And every listed file reads back with meshio
    for _, name in entries:
        assert "radius" in meshio.read(tmp_path / "compaction" / name).point_data
    # And the walls series exists alongside; no temp files are left
    assert (tmp_path / "compaction" / "walls.pvd").exists()
    assert not [p for p in (tmp_path / "compaction").iterdir() if p.name.startswith(".")]


def test_pvd_resume_keeps_entries(tmp_path, state):
    # Given a series with one entry
    vtu = write_spheres_vtu(tmp_path / "a.vtu", state)
    PvdSeries(tmp_path / "s.pvd").add(0.25, vtu)
    # When it is reopened with resume and extended, then truncated
    series = PvdSeries(tmp_path / "s.pvd", resume=True)
    series.add(0.5, vtu)
    assert [e[0] for e in series.entries] == [0.25, 0.5]
    series.truncate(0.3)
    # Then the file on disk follows
    assert [e[0] for e in PvdSeries(tmp_path / "s.pvd", resume=True).entries] == [0.25]


def test_mesh_wall_vtu_round_trip(tmp_path, state):
    # Given the example walls (two planes and a cylinder) with the last one a mesh wall of two
    # triangles instead, its point moved to z = 0.25 and loaded
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    state["walls/kind"] = np.array([0, 0, 2], np.int8)
    state["walls/point"] = np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0.25]], float)
    state["walls/force"] = np.array([[0, 0, 1.0], [1.0, 0, 0], [0, 0, 12.5]])
    # When the walls are written with the mesh and read back with meshio
    back = meshio.read(write_walls_vtu(tmp_path / "walls_000001.vtu", state, [None, None, (verts, tris)]))
    # Then the planes are quads and the mesh its triangles where its point is now, with its wall data
    assert [c.type for c in back.cells] == ["quad", "triangle"] and len(back.cells[0].data) == 2
    np.testing.assert_array_equal(back.points[back.cells[1].data], (verts + [0, 0, 0.25])[tris])
    np.testing.assert_array_equal(back.cell_data["wall"][1], [2, 2])
    np.testing.assert_array_equal(back.cell_data["kind"][1], [2, 2])
    np.testing.assert_array_equal(back.cell_data["force"][1], [[0, 0, 12.5]] * 2)
