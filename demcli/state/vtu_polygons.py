"""VTU files of 2D sections for ParaView: aggregate polygons and the specimen outline.

Polygons become VTK polygon cells in the plane z = 0 (meshio groups cells of one vertex
count per block; ParaView shows them as one surface). Cell data (one value per polygon,
e.g. ``class``, ``area``) is colourable. The outline is a closed polyline of line cells.
Open ``polygons.vtu`` next to the section's ``spheres.pvd`` to see each aggregate's
clump of balls inside its polygon. Files are binary zlib-compressed VTU, written
atomically; for viewing only.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np

from demcli.state.vtu import _write_mesh


def polygon_mesh(vertex_start, vertices, cell_data=None) -> meshio.Mesh:
    """meshio Mesh of polygons given as CSR (``vertex_start`` (n_p + 1,), ``vertices`` (n_v, 2)).

    cell_data: ``{name: (n_p,) or (n_p, k) array}`` in polygon order. Cells are grouped in
    blocks by vertex count; ``mesh.cell_data['polygon']`` maps them back to polygon indices.
    """
    start = np.asarray(vertex_start, np.int64)
    v = np.asarray(vertices, float)
    n_p = len(start) - 1
    counts = np.diff(start)
    pts = np.zeros((len(v), 3))
    pts[:, :2] = v
    data = {"polygon": np.arange(n_p, dtype=np.int64)}
    data.update({k: np.asarray(a) for k, a in (cell_data or {}).items()})
    for k, a in data.items():
        if len(a) != n_p:
            raise ValueError(f"cell data {k!r} has {len(a)} values for {n_p} polygons")
    cells, out = [], {k: [] for k in data}
    for m in np.unique(counts):
        which = np.flatnonzero(counts == m)
        conn = start[which][:, None] + np.arange(m)[None, :]
        cells.append(("polygon" if m > 4 else {3: "triangle", 4: "quad"}.get(int(m), "polygon"), conn))
        for k, a in data.items():
            out[k].append(a[which])
    return meshio.Mesh(pts, cells, cell_data=out)


def write_polygons_vtu(path, vertex_start, vertices, cell_data=None) -> Path:
    """Write polygons (see :func:`polygon_mesh`) as a binary VTU; returns the path."""
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return _write_mesh(path, polygon_mesh(vertex_start, vertices, cell_data))


def write_outline_vtu(path, outline) -> Path:
    """Write a closed 2D outline (k, 2) as line cells at z = 0; returns the path."""
    o = np.asarray(outline, float)
    pts = np.zeros((len(o), 3))
    pts[:, :2] = o
    k = np.arange(len(o))
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    return _write_mesh(path, meshio.Mesh(pts, [("line", np.stack([k, (k + 1) % len(o)], axis=1))]))


__all__ = ["polygon_mesh", "write_outline_vtu", "write_polygons_vtu"]
