"""VTU snapshots of polyhedral bodies for ParaView (viewing only, never read back).

Each body becomes a closed triangulated surface in the world frame: its faces
(convex polygons) are fan-triangulated from their first vertex, counter-clockwise
seen from outside, so the normals ParaView computes point outwards. Cell data on
every triangle: ``body``, ``body_id``, ``size_class`` (index into the gradation's
classes; colour by it for one colour per size class), ``sieve_size`` (m),
``material``, ``flaky``, ``elongated`` (0/1) and ``speed`` (m/s). Files are binary
zlib-compressed VTU written by meshio, atomically; ``polyhedra.pvd`` collects them.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from demcli.state.polyhedra import ShapeTable, first_polyhedral_body, rotation_matrices
from demcli.state.vtu import PvdSeries, _write_mesh


def _fan_triangles(table):
    """Triangles (t, 3) of every face of a ShapeTable (global vertex rows) and the shape of each."""
    fvs = table.face_vertex_start
    m = np.maximum(np.diff(fvs) - 2, 0)  # triangles per face
    face = np.repeat(np.arange(len(m)), m)
    k = np.arange(m.sum()) - np.repeat(np.cumsum(m) - m, m)  # triangle number within its face
    first = table.face_vertices[fvs[face]]
    tri = np.stack([first, table.face_vertices[fvs[face] + k + 1], table.face_vertices[fvs[face] + k + 2]], axis=1)
    shape_of_face = np.repeat(np.arange(len(table)), np.diff(table.face_start))
    return tri.astype(np.int64), shape_of_face[face]


def polyhedra_mesh(state) -> meshio.Mesh:
    """The polyhedral bodies of a State as a meshio Mesh of triangles (see module doc)."""
    table = ShapeTable.from_group(state.groups["polyhedron_shapes"])
    shape = np.asarray(state["polyhedra/shape"], dtype=np.int64)
    sub = table.subset(shape)  # one copy of the template per body, in body order
    n = len(shape)
    b0 = first_polyhedral_body(state)  # a mixed scene's polyhedra follow its sphere bodies
    owner = np.repeat(np.arange(n), np.diff(sub.vertex_start))
    rot = rotation_matrices(state["bodies/q"][b0:]) if n else np.zeros((0, 3, 3))
    x = np.asarray(state["bodies/x"], dtype=np.float64)[b0:]
    points = np.einsum("nij,nj->ni", rot[owner], sub.vertices) + x[owner] if n else np.zeros((0, 3))
    tri, row = _fan_triangles(sub)
    body = row + b0
    v = np.asarray(state["bodies/v"], dtype=np.float64)

    def per_body(name, dtype):
        return [np.asarray(state[f"polyhedra/{name}"]).astype(dtype)[row]]

    cell_data = {
        "body": [body],
        "body_id": [np.asarray(state["bodies/id"], dtype=np.int64)[body]],
        "size_class": per_body("size_class", np.int64),
        "sieve_size": per_body("sieve_size", np.float64),
        "material": per_body("material", np.int64),
        "flaky": per_body("flaky", np.int64),
        "elongated": per_body("elongated", np.int64),
        "speed": [np.linalg.norm(v, axis=1)[body] if n else np.zeros(0)],
    }
    return meshio.Mesh(points, [("triangle", tri)], cell_data=cell_data)


def write_polyhedra_vtu(path, state) -> Path:
    """Write the polyhedra of ``state`` as a binary VTU (atomically); returns the path."""
    return _write_mesh(path, polyhedra_mesh(state))


class PolyhedraSnapshots:
    """Numbered polyhedra snapshots in one folder with ``polyhedra.pvd``."""

    def __init__(self, folder, *, resume: bool = False):
        self.folder = Path(folder)
        self.series = PvdSeries(self.folder / "polyhedra.pvd", resume=resume)
        self.count = len(self.series)

    def write(self, state) -> list[Path]:
        out = write_polyhedra_vtu(self.folder / f"polyhedra_{self.count:06d}.vtu", state)
        self.series.add(float(state.meta.get("time", 0.0)), out)
        self.count += 1
        return [out]


__all__ = ["PolyhedraSnapshots", "polyhedra_mesh", "write_polyhedra_vtu"]
