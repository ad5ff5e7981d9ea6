"""VTU snapshots and PVD series for ParaView (for viewing only, never read back as state).

Spheres become vertex cells at their world centres with point data ``radius``,
``diameter``, ``velocity``, ``speed``, ``omega``, ``body_id``, ``material`` and, for the
particle sets of a ``generate`` stage, ``set``; in
ParaView apply *Glyph* (Sphere, scale by ``diameter``, scale factor 1). Walls become a
quad surface: planes clipped to their ``extent`` box, cylinders as a 48-sided tube
spanning the extent along the axis; mesh walls are a second block of triangles where they are now
(their vertices relative to the wall's point, given by the stage); all with cell data ``wall``, ``kind``, ``control``,
``velocity`` and ``force``. Bonds become line cells between the centres of the two
spheres, with cell data ``state`` (0 intact, 1 broken in tension, 2 in shear), ``model``,
``force_n`` (compression positive) and ``force_s`` (magnitude), and with bonded aggregates ``intra``
(1: a bond inside an aggregate, docs/asphalt_lab.md); in ParaView apply *Extract
Surface* then *Tube*, or colour the lines. Files are binary zlib-compressed VTU written by meshio, atomically;
the ``.pvd`` collection is rewritten atomically after each snapshot.
"""

from __future__ import annotations

import os
import xml.etree.ElementTree as ET
from pathlib import Path

import meshio
import numpy as np

from demcli.state.atomic import atomic_path, atomic_write_text

CYLINDER_SEGMENTS = 48


def _write_mesh(path, mesh: meshio.Mesh) -> Path:
    path = Path(path)
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="vtu", binary=True, compression="zlib")
    return path


def sphere_mesh(state) -> meshio.Mesh:
    """The spheres of a State as a meshio Mesh of vertex cells (see module doc)."""
    n_s = len(state["spheres/radius"])
    body = np.asarray(state["spheres/body"], dtype=np.int64)
    radius = np.asarray(state["spheres/radius"], dtype=np.float64)
    omega = np.asarray(state["bodies/omega"], dtype=np.float64)[body]
    velocity = state.sphere_velocities()
    point_data = {
        "radius": radius,
        "diameter": 2.0 * radius,
        "velocity": velocity,
        "speed": np.linalg.norm(velocity, axis=1) if n_s else np.zeros(0),
        "omega": omega,
        "body_id": np.asarray(state["bodies/id"], dtype=np.int64)[body],
        "material": np.asarray(state["spheres/material"], dtype=np.int64),
    }
    if state.get("bodies/set") is not None:
        point_data["set"] = np.asarray(state["bodies/set"], dtype=np.int64)[body]
    cells = [("vertex", np.arange(n_s, dtype=np.int64).reshape(-1, 1))]
    return meshio.Mesh(state.sphere_centres(), cells, point_data=point_data)


def write_spheres_vtu(path, state) -> Path:
    """Write the spheres of ``state`` as a binary VTU (atomically); returns the path."""
    return _write_mesh(path, sphere_mesh(state))


def bond_mesh(state) -> meshio.Mesh:
    """The bonds of a State as line cells between sphere centres (see module doc)."""
    i = np.asarray(state["bonds/i"], dtype=np.int64)
    j = np.asarray(state["bonds/j"], dtype=np.int64)
    fs = np.asarray(state["bonds/force_s"], dtype=np.float64).reshape(-1, 3)
    cell_data = {"state": [np.asarray(state["bonds/state"], dtype=np.int64)],
                 "model": [np.asarray(state["bonds/model"], dtype=np.int64)],
                 "force_n": [np.asarray(state["bonds/force_n"], dtype=np.float64)],
                 "force_s": [np.linalg.norm(fs, axis=1)]}
    inside = np.asarray(state["bond_models/materials"], np.int64).reshape(-1, 2)[:, 0] < 0 \
        if "bond_models/materials" in state else np.zeros(0, bool)
    if np.any(inside):  # bonded aggregates: which bonds hold an aggregate together
        cell_data["intra"] = [inside[np.asarray(state["bonds/model"], np.int64)].astype(np.int64)]
    return meshio.Mesh(state.sphere_centres(), [("line", np.stack([i, j], axis=1))], cell_data=cell_data)


def write_bonds_vtu(path, state) -> Path:
    """Write the bonds of ``state`` as binary VTU lines (atomically); returns the path."""
    return _write_mesh(path, bond_mesh(state))


def _basis(n):
    """Two unit vectors u, w with (u, w, n) right-handed; u, w axis-aligned when n is."""
    n = np.asarray(n, dtype=float)
    n = n / np.linalg.norm(n)
    e = np.zeros(3)
    e[int(np.argmin(np.abs(n)))] = 1.0
    u = np.cross(n, e)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u), n


def _box_corners(extent):
    lo, hi = np.asarray(extent[:3], float), np.asarray(extent[3:], float)
    return np.array([[(lo, hi)[i][0], (lo, hi)[j][1], (lo, hi)[k][2]]
                     for i in (0, 1) for j in (0, 1) for k in (0, 1)])


def _plane_quad(point, normal, extent):
    """Corner points (4,3) of the plane's patch covering the extent box, counter-clockwise
    seen from the side the normal points to."""
    u, w, _ = _basis(normal)
    rel = _box_corners(extent) - point
    a, b = rel @ u, rel @ w
    p = np.asarray(point, float)
    return np.array([p + u * a.min() + w * b.min(), p + u * a.max() + w * b.min(),
                     p + u * a.max() + w * b.max(), p + u * a.min() + w * b.max()])


def _cylinder_surface(point, axis, radius, extent, segments=CYLINDER_SEGMENTS):
    """Points and quads of a cylinder around ``axis`` through ``point``, spanning the extent
    box's projection on the axis."""
    u, w, a = _basis(axis)
    t = (_box_corners(extent) - point) @ a
    theta = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = radius * (np.cos(theta)[:, None] * u + np.sin(theta)[:, None] * w)
    p = np.asarray(point, float)
    pts = np.concatenate([p + a * t.min() + ring, p + a * t.max() + ring])
    j = np.arange(segments)
    quads = np.stack([j, (j + 1) % segments, (j + 1) % segments + segments, j + segments], axis=1)
    return pts, quads


def _wall_surface(state, k, meshes):
    """(cell type, points, cells) of wall k: triangles of a mesh wall at its point now, quads
    otherwise; None for a wall without a drawable extent."""
    extent = np.asarray(state["walls/extent"][k], dtype=float)
    point = np.asarray(state["walls/point"][k], dtype=float)
    normal = np.asarray(state["walls/normal"][k], dtype=float)
    if meshes is not None and meshes[k] is not None:
        return "triangle", point + np.asarray(meshes[k][0], float), np.asarray(meshes[k][1], np.int64)
    if not (np.all(np.isfinite(extent)) and np.linalg.norm(normal) > 0):
        return None
    if int(state["walls/kind"][k]) == 1:
        return ("quad", *_cylinder_surface(point, normal, float(state["walls/radius"][k]), extent))
    return "quad", _plane_quad(point, normal, extent), np.array([[0, 1, 2, 3]])


def wall_mesh(state, meshes=None) -> meshio.Mesh:
    """The walls of a State as a meshio Mesh of quads, then triangles for mesh walls (see module doc;
    ``meshes``: per wall (vertices relative to its point [m], triangles) or None, as
    :attr:`demcli.engine.system.Walls.mesh`)."""
    n_w = len(state["walls/kind"]) if "walls/kind" in state else 0
    points, blocks, offset = [], {"quad": ([], []), "triangle": ([], [])}, 0
    for k in range(n_w):
        surface = _wall_surface(state, k, meshes)
        if surface is None:
            continue
        ctype, pts, cells = surface
        points.append(pts)
        blocks[ctype][0].append(cells + offset)
        blocks[ctype][1].extend([k] * len(cells))
        offset += len(pts)
    pts = np.concatenate(points) if points else np.zeros((0, 3))

    def per_cell(name, owner, width=None, dtype=np.float64):
        if n_w == 0:
            return np.zeros((0, width) if width else 0, dtype=dtype)
        return np.asarray(state[f"walls/{name}"], dtype=dtype)[owner]

    cells, cell_data = [], {key: [] for key in ("wall", "kind", "control", "velocity", "force")}
    for ctype, width in (("quad", 4), ("triangle", 3)):
        parts, owner = blocks[ctype]
        if not owner and (ctype == "triangle" or blocks["triangle"][1]):  # meshio: no empty block before another
            continue
        owner = np.asarray(owner, dtype=np.int64)
        cells.append((ctype, np.concatenate(parts).astype(np.int64) if parts else np.zeros((0, width), np.int64)))
        for key, data in (("wall", owner), ("kind", per_cell("kind", owner, dtype=np.int64)),
                          ("control", per_cell("control", owner, dtype=np.int64)),
                          ("velocity", per_cell("v", owner, 3)), ("force", per_cell("force", owner, 3))):
            cell_data[key].append(data)
    return meshio.Mesh(pts, cells, cell_data=cell_data)


def write_walls_vtu(path, state, meshes=None) -> Path:
    """Write the walls of ``state`` as a binary VTU surface (atomically; ``meshes`` as for
    :func:`wall_mesh`); returns the path."""
    return _write_mesh(path, wall_mesh(state, meshes))


class PvdSeries:
    """A ParaView ``.pvd`` collection, rewritten atomically on every :meth:`add`.

    File names are stored relative to the .pvd's folder, so a run folder can be moved.
    ``resume=True`` keeps the entries of an existing file (a resumed stage).
    """

    def __init__(self, path, *, resume: bool = False):
        self.path = Path(path)
        self.entries: list[tuple[float, int, str]] = []  # (time, part, relative file)
        if resume and self.path.exists():
            root = ET.parse(self.path).getroot()
            for ds in root.iter("DataSet"):
                self.entries.append((float(ds.get("timestep", 0)), int(ds.get("part", 0)), ds.get("file")))

    def __len__(self) -> int:
        return len(self.entries)

    def add(self, time: float, file, part: int = 0) -> None:
        """Append a snapshot file at ``time`` and rewrite the .pvd."""
        rel = os.path.relpath(Path(file).resolve(), self.path.parent.resolve())
        self.entries.append((float(time), int(part), Path(rel).as_posix()))
        self.write()

    def truncate(self, after_time: float) -> None:
        """Drop entries later than ``after_time`` (resuming from an earlier checkpoint); a series
        never written stays unwritten."""
        self.entries = [e for e in self.entries if e[0] <= after_time]
        if self.path.exists():
            self.write()

    def to_xml(self) -> str:
        root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
        coll = ET.SubElement(root, "Collection")
        for time, part, rel in self.entries:
            ET.SubElement(coll, "DataSet", timestep=repr(time), group="", part=str(part), file=rel)
        ET.indent(root)
        return '<?xml version="1.0"?>\n' + ET.tostring(root, encoding="unicode") + "\n"

    def write(self) -> Path:
        atomic_write_text(self.path, self.to_xml())
        return self.path


class Snapshots:
    """Numbered sphere and wall snapshots in one folder with ``spheres.pvd``/``walls.pvd``.

    ``Snapshots(run_dir / "compaction").write(state)`` writes ``spheres_000000.vtu``
    (and ``walls_000000.vtu`` when the state has walls) at ``state.meta['time']``.
    """

    def __init__(self, folder, *, resume: bool = False, meshes=None):
        self.folder = Path(folder)
        self.meshes = meshes  # the mesh walls' triangles (wall_mesh), None without
        self.spheres = PvdSeries(self.folder / "spheres.pvd", resume=resume)
        self.walls = PvdSeries(self.folder / "walls.pvd", resume=resume)
        self.bonds = PvdSeries(self.folder / "bonds.pvd", resume=resume)
        self.count = len(self.spheres)

    def write(self, state) -> list[Path]:
        time = float(state.meta.get("time", 0.0))
        out = [write_spheres_vtu(self.folder / f"spheres_{self.count:06d}.vtu", state)]
        self.spheres.add(time, out[-1])
        if "walls/kind" in state and len(state["walls/kind"]):
            out.append(write_walls_vtu(self.folder / f"walls_{self.count:06d}.vtu", state, self.meshes))
            self.walls.add(time, out[-1])
        if "bonds/i" in state and len(state["bonds/i"]):
            out.append(write_bonds_vtu(self.folder / f"bonds_{self.count:06d}.vtu", state))
            self.bonds.add(time, out[-1])
        self.count += 1
        return out

    def truncate(self, time: float) -> None:
        """Drop the entries after ``time`` from every series (a resumed stage)."""
        for series in (self.spheres, self.walls, self.bonds):
            series.truncate(time)
        self.count = len(self.spheres)


__all__ = ["PvdSeries", "Snapshots", "bond_mesh", "sphere_mesh", "wall_mesh", "write_bonds_vtu", "write_spheres_vtu",
           "write_walls_vtu"]
