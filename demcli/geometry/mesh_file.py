"""Triangle meshes for mesh walls, read from STL (ascii or binary) or OBJ with meshio.

A wall mesh is placed in the scene as x = R (scale * x_file) + translation [m]: ``scale``
converts the file's units to metres (0.001 for a CAD file in millimetres), R rotates by
``rotate`` = (rx, ry, rz) degrees about x, then y, then z. Vertices that coincide in the
file are merged, so that triangles share edges and vertices by index (the contact rule of
:mod:`demcli.kernels.mesh` needs it). Problems are configuration errors naming the case
file, the key, the rule and the value.
"""

from pathlib import Path

import numpy as np

from demcli.config.schema import ConfigIssue
from demcli.errors import ConfigError

SUFFIXES = {".stl": "stl", ".obj": "obj"}

DEGENERATE = 1e-12
"""A triangle is degenerate when its area is below this fraction of the squared size of the mesh."""


def _fail(case_file, key, rule, value):
    raise ConfigError([ConfigIssue(case_file, None, key, rule, value)])


def rotation_matrix(degrees):
    """R = Rz Ry Rx for rotations (rx, ry, rz) [deg] about the fixed x, y and z axes."""
    rx, ry, rz = np.radians(np.asarray(degrees, float))
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mz @ my @ mx


def _read_cells(path, case_file, key):
    """(points, triangles) of the file, or a ConfigError."""
    import meshio

    fmt = SUFFIXES.get(path.suffix.lower())
    if fmt is None:
        _fail(case_file, key, f"must be a {' or '.join(sorted(SUFFIXES))} file", str(path))
    if not path.is_file():
        _fail(case_file, key, "file not found", str(path))
    try:
        with np.errstate(over="ignore"):      # meshio's binary-STL size test overflows on ascii files
            mesh = getattr(meshio, fmt).read(str(path))  # the format's reader: meshio.read exits on a bad file
    except Exception as exc:  # noqa: BLE001 - any parse failure is bad input
        _fail(case_file, key, f"cannot read as {fmt.upper()}" + (f": {exc}" if str(exc) else ""), str(path))
    others = sorted({block.type for block in mesh.cells if block.type not in ("triangle", "vertex", "line")})
    if others:
        _fail(case_file, key, "must hold triangles only", f"{path.name}: {', '.join(others)} cells")
    tris = [block.data for block in mesh.cells if block.type == "triangle"]
    if not tris:
        _fail(case_file, key, "holds no triangles", str(path))
    return np.asarray(mesh.points, float)[:, :3], np.concatenate(tris).astype(np.int64)


def _merged(points, tris):
    """Coincident points merged; unused points dropped (vertices renumbered in first-use order)."""
    used = points[tris.ravel()]
    uniq, first, inverse = np.unique(used, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(len(order))
    return np.ascontiguousarray(uniq[order]), rank[inverse.ravel()].reshape(-1, 3)


def _check_degenerate(verts, tris, path, case_file, key):
    e1 = verts[tris[:, 1]] - verts[tris[:, 0]]
    e2 = verts[tris[:, 2]] - verts[tris[:, 0]]
    area = 0.5 * np.linalg.norm(np.cross(e1, e2), axis=1)
    size = np.ptp(verts, axis=0).max()
    bad = np.flatnonzero(area <= DEGENERATE * size * size)
    if len(bad):
        _fail(case_file, key, "must have no degenerate (zero-area) triangles",
              f"{path.name}: {len(bad)} of {len(tris)}, first triangle {int(bad[0])}")


def read_mesh(path, case_file=None, key="mesh", scale=1.0, translation=(0.0, 0.0, 0.0), rotate=(0.0, 0.0, 0.0)):
    """Vertices (nv, 3) [m] and triangles (nt, 3) int64 of a wall mesh file, placed in the scene.

    path: the file (a relative path is taken relative to the case file's folder); case_file and
    key name the setting in errors. Raises ConfigError (exit code 2) for a missing file, another
    format, cells other than triangles, or a degenerate triangle."""
    path = Path(path)
    if not path.is_absolute() and case_file:
        path = Path(case_file).resolve().parent / path
    points, tris = _read_cells(path, case_file, key)
    verts, tris = _merged(points, tris)
    verts = verts * float(scale) @ rotation_matrix(rotate).T + np.asarray(translation, float)
    _check_degenerate(verts, tris, path, case_file, key)
    return np.ascontiguousarray(verts), np.ascontiguousarray(tris)
