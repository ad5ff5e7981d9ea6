"""Wall meshes read from STL (ascii, binary) and OBJ (demcli.geometry.mesh_file): vertices merged,
placed by scale, rotation and translation; bad files are configuration errors (exit code 2) that
name the case file, the key, the rule and the value."""

from pathlib import Path

import meshio
import numpy as np
import pytest

from demcli.errors import ConfigError
from demcli.geometry.mesh_file import read_mesh

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
TWO_TRIANGLES = np.array([[0, 1, 2], [0, 2, 3]])


@pytest.mark.parametrize("name, fmt, binary", [("a.stl", "stl", False), ("b.stl", "stl", True),
                                               ("c.obj", "obj", False)])
def test_reads_stl_and_obj_with_shared_vertices(tmp_path, name, fmt, binary):
    # Given a unit square of two triangles written in each format
    path = tmp_path / name
    kw = {"binary": binary} if fmt == "stl" else {}
    meshio.write(path, meshio.Mesh(SQUARE, [("triangle", TWO_TRIANGLES)]), file_format=fmt, **kw)
    # When it is read in millimetres, turned 90 degrees about z and moved
    verts, tris = read_mesh(name, case_file=str(tmp_path / "case.yaml"), key="walls[0].file", scale=1e-3,
                            translation=(1.0, 2.0, 3.0), rotate=(0.0, 0.0, 90.0))
    # Then the triangle soup of an STL shares its 4 vertices, placed as asked
    assert verts.shape == (4, 3) and tris.shape == (2, 3)
    expected = SQUARE[:, [1, 0, 2]] * [-1e-3, 1e-3, 1e-3] + [1.0, 2.0, 3.0]
    got = verts[tris].reshape(-1, 3)
    want = expected[TWO_TRIANGLES].reshape(-1, 3)
    np.testing.assert_allclose(np.sort(got, axis=0), np.sort(want, axis=0), atol=1e-6)   # float32 in binary STL
    assert len(np.unique(tris)) == 4


def _error(tmp_path, name):
    with pytest.raises(ConfigError) as exc:
        read_mesh(name, case_file=str(tmp_path / "case.yaml"), key="walls[1].file")
    assert exc.value.exit_code == 2
    text = str(exc.value)
    assert "case.yaml" in text and "walls[1].file" in text
    return text


def test_missing_file_is_a_config_error(tmp_path):
    assert "file not found (got" in _error(tmp_path, "nothere.stl")


def test_other_format_is_a_config_error(tmp_path):
    (tmp_path / "m.ply").write_text("ply\n")
    assert "must be a .obj or .stl file" in _error(tmp_path, "m.ply")


def test_quad_cells_are_refused(tmp_path):
    (tmp_path / "q.obj").write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    assert "must hold triangles only (got 'q.obj: quad cells')" in _error(tmp_path, "q.obj")


def test_degenerate_triangle_is_refused(tmp_path):
    points = np.vstack([SQUARE, [[2.0, 0, 0]]])
    cells = [("triangle", np.vstack([TWO_TRIANGLES, [[0, 1, 4]]]))]      # 0, 1, 4 on one line
    meshio.write(tmp_path / "d.obj", meshio.Mesh(points, cells))
    assert "no degenerate (zero-area) triangles (got 'd.obj: 1 of 3, first triangle 2')" in _error(tmp_path, "d.obj")


def test_unreadable_file_is_a_config_error(tmp_path):
    (tmp_path / "g.stl").write_bytes(b"\x00garbage")
    assert "cannot read as STL" in _error(tmp_path, "g.stl")


def test_shipped_marshall_head_mesh():
    # Given the breaking-head mesh shipped in cases/meshes (made by make_marshall_head.py)
    root = Path(__file__).resolve().parents[2]
    verts, tris = read_mesh(root / "cases" / "meshes" / "marshall_head.stl", scale=1e-3)
    # Then it is one arc of radius 50.8 mm with its normals towards the specimen's axis (y)
    assert tris.shape == (128, 3) and verts.shape == (85, 3)
    np.testing.assert_allclose(np.hypot(verts[:, 0], verts[:, 2]), 0.0508, rtol=1e-6)
    normal = np.cross(verts[tris[:, 1]] - verts[tris[:, 0]], verts[tris[:, 2]] - verts[tris[:, 0]])
    inward = -verts[tris].mean(axis=1) * [1, 0, 1]
    assert (np.einsum("ij,ij->i", normal, inward) > 0).all()
