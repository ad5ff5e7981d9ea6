"""Rigid convex polyhedra in a state: per-body rows and a table of shape templates.

Layout (registered below; see docs/state.md):

- ``bodies/*`` as for every body: ``x`` the centroid, ``q`` the rotation from the
  body frame to the world, ``mass`` and ``inertia`` (principal moments, kg m^2).
  The body frame of a polyhedron is its principal frame: centroid at the origin, axes
  along the principal axes of inertia with ascending moments, so ``bodies/inertia``
  is diagonal in it.
- ``polyhedra/*``: one row per polyhedral body (dims ``n_pb``), the polyhedra being the last
  ``n_pb`` bodies in body order: the template ``shape``, the ``material``, and what the
  assembly knows about it (size class, sieve size, library entry, flaky and elongated
  flags). Without spheres (``n_s = 0``) every body is a polyhedron (``n_pb = n_b``); a mixed
  scene (:mod:`demcli.engine.mixed_shape`) has its sphere bodies first.
- ``polyhedron_shapes/*``: the templates, in the body frame, as CSR tables that a
  numba kernel indexes directly. Shape k has vertices
  ``vertices[vertex_start[k]:vertex_start[k + 1]]``, faces
  ``face_start[k]:face_start[k + 1]`` and edges ``edge_start[k]:edge_start[k + 1]``;
  face f has the vertex rows ``face_vertices[face_vertex_start[f]:face_vertex_start[f + 1]]``
  (global rows of ``vertices``, counter-clockwise seen from outside), the outward unit
  normal ``face_normal[f]`` and the offset ``face_offset[f]`` (n . x = d on the face,
  n . x <= d inside); ``edges`` holds global vertex-row pairs. Per shape: ``volume``,
  ``inertia`` (principal moments for unit density, m^5) and ``radius`` (largest vertex
  distance from the centroid, for the broad phase).

A world vertex of body b is ``bodies/x[b] + R(bodies/q[b]) vertices[row]`` for the
rows of shape ``polyhedra/shape[b]``. Several bodies may share one template.
"""

from dataclasses import dataclass

import numpy as np

from demcli.state.fields import Field, register, register_group

register_group("polyhedra", "Rigid convex polyhedra, one row per body (shapes in polyhedron_shapes)",
               writer="stage assemble")
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("shape", "i", ("n_pb",), "", "template of the body in polyhedron_shapes", {"index_of": "n_shape"}),
        ("material", "i", ("n_pb",), "", "index into materials", {"index_of": "n_m"}),
        ("size_class", "i", ("n_pb",), "", "index into gradation/class_* (-1: none)", {}),
        ("sieve_size", "f", ("n_pb",), "m", "square-hole sieve size (projection method)", {}),
        ("library_index", "i", ("n_pb",), "", "entry in the ballast library the body came from (-1: none)", {}),
        ("flaky", "b", ("n_pb",), "", "short side < flaky_ratio x the class's mean size", {}),
        ("elongated", "b", ("n_pb",), "", "length > elongated_ratio x the class's mean size (needle)", {})]:
    register(Field(f"polyhedra/{_name}", _kind, _dims, _unit, _doc, writer="stage assemble", **_kw))

register_group("polyhedron_shapes", "Convex polyhedron templates in the body (principal) frame, CSR tables",
               writer="stage assemble")
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("vertex_start", "i", ("n_shape+1",), "", "first vertex row of each shape, then the total", {}),
        ("vertices", "f", ("n_pv", 3), "m", "vertices in the body frame (centroid origin, principal axes)",
         {"finite": True}),
        ("face_start", "i", ("n_shape+1",), "", "first face of each shape, then the total", {}),
        ("face_vertex_start", "i", ("n_pf+1",), "", "first entry of each face in face_vertices, then the total",
         {}),
        ("face_vertices", "i", ("n_pfv",), "", "vertex rows of each face, counter-clockwise from outside",
         {"index_of": "n_pv"}),
        ("face_normal", "f", ("n_pf", 3), "1", "outward unit normal of each face, body frame",
         {"finite": True, "unit_rows": True}),
        ("face_offset", "f", ("n_pf",), "m", "plane offset d: n . x = d on the face, n . x <= d inside",
         {"finite": True}),
        ("edge_start", "i", ("n_shape+1",), "", "first edge of each shape, then the total", {}),
        ("edges", "i", ("n_pe", 2), "", "vertex-row pairs of each edge (each edge once)", {"index_of": "n_pv"}),
        ("volume", "f", ("n_shape",), "m^3", "volume", {"finite": True, "positive": True}),
        ("inertia", "f", ("n_shape", 3), "m^5", "principal moments of inertia for unit density, ascending",
         {"finite": True, "positive": True}),
        ("radius", "f", ("n_shape",), "m", "largest vertex distance from the centroid",
         {"finite": True, "positive": True})]:
    register(Field(f"polyhedron_shapes/{_name}", _kind, _dims, _unit, _doc, writer="stage assemble", **_kw))

register_group("body_contacts", "Persistent polyhedron-polyhedron contacts with their history",
               writer="engine (polyhedra)")
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("i", "i", ("n_bc",), "", "first body (i < j)", {"index_of": "n_b"}),
        ("j", "i", ("n_bc",), "", "second body", {"index_of": "n_b"}),
        ("ft", "f", ("n_bc", 3), "N", "tangential spring force (history)", {"required": False, "finite": True}),
        ("force", "f", ("n_bc", 3), "N", "last contact force on body i", {"finite": True}),
        ("depth", "f", ("n_bc",), "m", "overlap depth d = V / A_c of the last evaluation",
         {"required": False, "finite": True}),
        ("box", "f", ("n_bc", 6), "m", "bounding box of the intersection at the last evaluation (low xyz, high "
         "xyz): the next step's culling box (temporal coherence: the result is the same with or without it, up to round-off)",
         {"required": False, "finite": True}),
        ("linearized", "f", ("n_bc", 28), "", "with contact.geometry_refresh > 1: the last exact evaluation kept for "
         "the linearized steps: V [m^3], S [m^2], centroid g [m], the moments T_i, T_j [m^3], bodies i's and j's "
         "positions [m] and orientations then, steps left before the next exact one "
         "(demcli.kernels.shapes.polyhedra._linear_volume)", {"required": False, "finite": True})]:
    register(Field(f"body_contacts/{_name}", _kind, _dims, _unit, _doc, writer="engine (polyhedra)", **_kw))

register_group("body_wall_contacts", "Persistent polyhedron-wall contacts with their history",
               writer="engine (polyhedra)")
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("body", "i", ("n_bwc",), "", "body index", {"index_of": "n_b"}),
        ("wall", "i", ("n_bwc",), "", "wall index", {"index_of": "n_w"}),
        ("ft", "f", ("n_bwc", 3), "N", "tangential spring force (history)", {"required": False, "finite": True}),
        ("force", "f", ("n_bwc", 3), "N", "last contact force on the body", {"finite": True}),
        ("depth", "f", ("n_bwc",), "m", "overlap depth d = V / A_c of the last evaluation",
         {"required": False, "finite": True})]:
    register(Field(f"body_wall_contacts/{_name}", _kind, _dims, _unit, _doc, writer="engine (polyhedra)", **_kw))

register_group("sphere_body_contacts", "Persistent sphere-polyhedron contacts of a scene with both, with their "
               "history", writer="engine (mixed)")
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("sphere", "i", ("n_sbc",), "", "sphere index", {"index_of": "n_s"}),
        ("body", "i", ("n_sbc",), "", "polyhedral body index", {"index_of": "n_b"}),
        ("ft", "f", ("n_sbc", 3), "N", "tangential spring force (history)", {"required": False, "finite": True}),
        ("mr", "f", ("n_sbc", 3), "N m", "rolling-resistance moment (history)", {"required": False, "finite": True}),
        ("force", "f", ("n_sbc", 3), "N", "last contact force on the sphere", {"finite": True})]:
    register(Field(f"sphere_body_contacts/{_name}", _kind, _dims, _unit, _doc, writer="engine (mixed)", **_kw))

register_group("adaptive_damping", "State of the adaptive mass-proportional damping (seed 002, eqs. 23-27)",
               writer="effect adaptive_damping")
register(Field("adaptive_damping/alpha", "f", (), "1/s", "current damping coefficient alpha",
               writer="effect adaptive_damping"))
register(Field("adaptive_damping/ke_prev", "f", (), "J", "kinetic energy at the previous step",
               writer="effect adaptive_damping"))

register_group("actors", "Rigid bodies that load the bed (loading plate, sleeper): the last bodies of the "
               "scene, moving along their load direction only; prescribed force "
               "F(t) = load_mean + load_amplitude sin(2 pi frequency max(t - start, 0) + phase)",
               writer="stages vibrate, sleeper")
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("body", "i", ("n_a",), "", "body index", {"index_of": "n_b"}),
        ("name", "str", ("n_a",), "", "role: plate or sleeper", {}),
        ("load_mean", "f", ("n_a", 3), "N", "mean prescribed force (besides gravity)", {"finite": True}),
        ("load_amplitude", "f", ("n_a", 3), "N", "amplitude of the sinusoidal part", {"finite": True}),
        ("frequency", "f", ("n_a",), "Hz", "load frequency", {"finite": True}),
        ("phase", "f", ("n_a",), "rad", "phase of the sine at the start time", {"finite": True}),
        ("start", "f", ("n_a",), "s", "time the oscillation starts (before: the force at its phase)",
         {"finite": True})]:
    register(Field(f"actors/{_name}", _kind, _dims, _unit, _doc, writer="stages vibrate, sleeper", **_kw))

SHAPE_FIELDS = ("vertex_start", "vertices", "face_start", "face_vertex_start", "face_vertices", "face_normal",
                "face_offset", "edge_start", "edges", "volume", "inertia", "radius")


@dataclass(frozen=True, eq=False)
class ShapeTable:
    """Shape templates as CSR arrays (the layout of ``polyhedron_shapes``, see the module doc)."""

    vertex_start: np.ndarray
    vertices: np.ndarray
    face_start: np.ndarray
    face_vertex_start: np.ndarray
    face_vertices: np.ndarray
    face_normal: np.ndarray
    face_offset: np.ndarray
    edge_start: np.ndarray
    edges: np.ndarray
    volume: np.ndarray
    inertia: np.ndarray
    radius: np.ndarray

    def __len__(self):
        return len(self.volume)

    @classmethod
    def from_polyhedra(cls, polys, scales=None):
        """Templates from ConvexPolyhedron objects, moved to their principal frames.

        polys: sequence of ConvexPolyhedron (any frame); scales: optional factor per
        shape (lengths x s, volume x s^3, inertia x s^5).
        """
        scales = np.ones(len(polys)) if scales is None else np.asarray(scales, dtype=np.float64)
        verts, fvs, normals, offsets, edges, vol, mom, rad = [], [], [], [], [], [], [], []
        nv = [0]
        nf = [0]
        ne = [0]
        for poly, s in zip(polys, scales):
            axes = poly.principal_axes
            v = (poly.vertices - poly.centroid) @ axes * s
            base = nv[-1]
            verts.append(v)
            fvs.append(poly.face_indices + base)
            normals.append(poly.normals @ axes)
            offsets.append((poly.offsets - poly.normals @ poly.centroid) * s)
            edges.append(poly.edges + base)
            vol.append(poly.volume * s ** 3)
            mom.append(poly.principal_moments * s ** 5)
            rad.append(float(np.sqrt(np.max(np.einsum("ij,ij->i", v, v)))))
            nv.append(base + len(v))
            nf.append(nf[-1] + poly.n_faces)
            ne.append(ne[-1] + len(poly.edges))
        sizes = [np.diff(p.face_offsets) for p in polys]
        fvstart = np.zeros(nf[-1] + 1, dtype=np.int64)
        if sizes:
            fvstart[1:] = np.cumsum(np.concatenate(sizes))
        return cls(
            vertex_start=np.asarray(nv, dtype=np.int64),
            vertices=np.concatenate(verts) if verts else np.zeros((0, 3)),
            face_start=np.asarray(nf, dtype=np.int64),
            face_vertex_start=fvstart,
            face_vertices=np.concatenate(fvs).astype(np.int64) if fvs else np.zeros(0, np.int64),
            face_normal=np.concatenate(normals) if normals else np.zeros((0, 3)),
            face_offset=np.concatenate(offsets) if offsets else np.zeros(0),
            edge_start=np.asarray(ne, dtype=np.int64),
            edges=np.concatenate(edges).astype(np.int64) if edges else np.zeros((0, 2), np.int64),
            volume=np.asarray(vol, dtype=np.float64), inertia=np.asarray(mom, dtype=np.float64).reshape(-1, 3),
            radius=np.asarray(rad, dtype=np.float64))

    @classmethod
    def concat(cls, tables):
        """One ShapeTable of several, in order (indices shifted)."""
        tables = list(tables)
        if not tables:
            return cls.from_polyhedra([])
        out = {}
        for name in ("vertex_start", "face_start", "face_vertex_start", "edge_start"):  # CSR offsets, shifted
            starts = [np.zeros(1, dtype=np.int64)]
            base = 0
            for t in tables:
                starts.append(getattr(t, name)[1:] + base)
                base += getattr(t, name)[-1]
            out[name] = np.concatenate(starts).astype(np.int64)
        vbase = np.cumsum([0] + [t.vertex_start[-1] for t in tables[:-1]])
        out["face_vertices"] = np.concatenate([t.face_vertices + b for t, b in zip(tables, vbase)]).astype(np.int64)
        out["edges"] = np.concatenate([t.edges + b for t, b in zip(tables, vbase)]).astype(np.int64)
        for name in ("vertices", "face_normal", "face_offset", "volume", "inertia", "radius"):
            out[name] = np.concatenate([getattr(t, name) for t in tables])
        return cls(**out)

    def to_group(self):
        """The ``polyhedron_shapes`` group dict."""
        return {name: getattr(self, name) for name in SHAPE_FIELDS}

    @classmethod
    def from_group(cls, group):
        """A ShapeTable from a ``polyhedron_shapes``-like dict (a state group or a library file group)."""
        return cls(**{name: np.asarray(group[name]) for name in SHAPE_FIELDS})

    def shape(self, k):
        """Shape k: (vertices (n, 3), faces [local index arrays], normals (f, 3), offsets (f,),
        edges (e, 2) as local indices)."""
        v0, v1 = self.vertex_start[k], self.vertex_start[k + 1]
        f0, f1 = self.face_start[k], self.face_start[k + 1]
        fv = self.face_vertex_start
        faces = [self.face_vertices[fv[f]:fv[f + 1]] - v0 for f in range(f0, f1)]
        e = self.edges[self.edge_start[k]:self.edge_start[k + 1]] - v0
        return self.vertices[v0:v1], faces, self.face_normal[f0:f1], self.face_offset[f0:f1], e

    def subset(self, index):
        """A new ShapeTable of the shapes ``index`` (in that order), re-indexed."""
        index = np.asarray(index, dtype=np.int64)

        def gather(start, k):
            lo, hi = start[k], start[k + 1]
            lens = hi - lo
            out = np.zeros(len(k) + 1, dtype=np.int64)
            out[1:] = np.cumsum(lens)
            rows = np.repeat(lo - out[:-1], lens) + np.arange(out[-1])
            return rows, out

        vrows, vstart = gather(self.vertex_start, index)
        frows, fstart = gather(self.face_start, index)
        erows, estart = gather(self.edge_start, index)
        fvrows, fvstart = gather(self.face_vertex_start, frows)
        owner_fv = np.repeat(np.repeat(np.arange(len(index)), np.diff(fstart)), np.diff(fvstart))
        owner_e = np.repeat(np.arange(len(index)), np.diff(estart))
        shift = vstart[:-1] - self.vertex_start[index]  # new row - old row of each kept shape's vertices
        return ShapeTable(
            vertex_start=vstart, vertices=self.vertices[vrows], face_start=fstart, face_vertex_start=fvstart,
            face_vertices=self.face_vertices[fvrows] + shift[owner_fv], face_normal=self.face_normal[frows],
            face_offset=self.face_offset[frows], edge_start=estart, edges=self.edges[erows] + shift[owner_e][:, None],
            volume=self.volume[index], inertia=self.inertia[index], radius=self.radius[index])


def rotation_matrices(q):
    """Rotation matrices (n, 3, 3) of unit quaternions (n, 4) given as (w, x, y, z)."""
    q = np.asarray(q, dtype=np.float64).reshape(-1, 4)
    w, x, y, z = q.T
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1)], axis=1)


def first_polyhedral_body(state):
    """Body index of the first polyhedron: the polyhedra are the last bodies, one row of
    ``polyhedra`` each in body order (0 in a polyhedra-only scene; after the sphere bodies in a
    mixed one)."""
    return len(state["bodies/mass"]) - len(state["polyhedra/shape"])


def world_vertices(state):
    """(vertices (n_v, 3) in the world frame, owner body (n_v,)) of every polyhedral body."""
    table = ShapeTable.from_group(state.groups["polyhedron_shapes"])
    shape = np.asarray(state["polyhedra/shape"], dtype=np.int64)
    sub = table.subset(shape)
    owner = np.repeat(np.arange(len(shape)), np.diff(sub.vertex_start)) + first_polyhedral_body(state)
    rot = rotation_matrices(state["bodies/q"])
    x = np.asarray(state["bodies/x"], dtype=np.float64)
    return np.einsum("nij,nj->ni", rot[owner], sub.vertices) + x[owner], owner


def body_convex(state, b, table=None):
    """Body b of a state as a :class:`demcli.geometry.intersect.Convex` in the world frame."""
    from demcli.geometry.intersect import Convex

    table = table if table is not None else ShapeTable.from_group(state.groups["polyhedron_shapes"])
    v, _, normals, _, edges = table.shape(int(state["polyhedra/shape"][b - first_polyhedral_body(state)]))
    rot = rotation_matrices(state["bodies/q"][b])[0]
    d = v[edges[:, 1]] - v[edges[:, 0]]
    d /= np.linalg.norm(d, axis=1)[:, None]
    return Convex(v @ rot.T + np.asarray(state["bodies/x"][b], dtype=np.float64), normals @ rot.T, d @ rot.T)


__all__ = ["SHAPE_FIELDS", "ShapeTable", "body_convex", "first_polyhedral_body", "rotation_matrices",
           "world_vertices"]
