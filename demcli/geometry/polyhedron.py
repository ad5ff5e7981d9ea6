"""Convex polyhedra: hull construction, exact mass properties and shape indices.

Lengths in m, areas in m^2, volumes in m^3; the inertia tensor is for unit density
(kg/m^3 = 1, so in m^5): multiply by the density for kg m^2.
"""

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError

from demcli.geometry.errors import GeometryError

# adjacent hull triangles merge into one face when their unit normals agree to
# 1 - cos(angle) <= _COPLANAR_COS (angle ~ 1.4e-6 rad) and their plane offsets to
# _COPLANAR_OFFSET times the point-set extent; Qhull's own merged facets come out
# of its triangulation ("Qt") with identical planes, so this only has to absorb
# round-off.
_COPLANAR_COS = 1e-12
_COPLANAR_OFFSET = 1e-12


@dataclass(frozen=True, repr=False, eq=False)
class ConvexPolyhedron:
    """A convex polyhedron with polygonal faces and its unit-density mass properties.

    Build it with :func:`convex_hull`. Arrays (float64 unless said):

    - ``vertices`` (n, 3), m: the hull vertices only.
    - ``face_indices`` (int64, flat) and ``face_offsets`` (int64, (f + 1,)): face k
      has vertices ``face_indices[face_offsets[k]:face_offsets[k + 1]]``, counter-
      clockwise seen from outside (CSR layout, numba friendly; see ``faces``).
    - ``normals`` (f, 3): outward unit normals; ``offsets`` (f,), m: plane offsets,
      n . x = d on the face and n . x <= d inside; ``areas`` (f,), m^2.
    - ``edges`` (int64, (e, 2)): vertex pairs, each edge once.
    - ``volume`` m^3; ``centroid`` (3,), m; ``inertia`` (3, 3), m^5: inertia tensor
      about the centroid for unit density.
    - ``principal_moments`` (3,), m^5, ascending; ``principal_axes`` (3, 3): columns
      are the matching unit axes, a proper rotation (det +1) from the principal
      frame to the world frame.
    - ``circles`` (g, 3): the face normals with parallel and antiparallel duplicates
      removed (the great circles n . u = 0 bounding the cells of the minimal-shadow
      search); ``circle_weights`` (g,), m^2: the summed area of the faces normal to
      each, so that the shadow area is 1/2 sum_c w_c |n_c . u|.
    """

    vertices: np.ndarray
    face_indices: np.ndarray
    face_offsets: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray
    areas: np.ndarray
    edges: np.ndarray
    volume: float
    centroid: np.ndarray
    inertia: np.ndarray
    principal_moments: np.ndarray
    principal_axes: np.ndarray
    circles: np.ndarray
    circle_weights: np.ndarray

    @property
    def faces(self):
        """List of int64 vertex-index arrays, one per face, counter-clockwise from outside."""
        o = self.face_offsets
        return [self.face_indices[o[k]:o[k + 1]] for k in range(len(o) - 1)]

    @property
    def n_faces(self):
        return len(self.face_offsets) - 1

    def __repr__(self):
        return (f"ConvexPolyhedron(n_vertices={len(self.vertices)}, n_faces={self.n_faces}, "
                f"volume={self.volume:.6g})")


def as_polyhedron(particle):
    """``particle`` itself if it is a ConvexPolyhedron, else ``convex_hull(particle)``."""
    if isinstance(particle, ConvexPolyhedron):
        return particle
    return convex_hull(particle)


def convex_hull(points):
    """Convex polyhedron spanned by 3D points (Qhull via ``scipy.spatial.ConvexHull``).

    points: (n, 3), m. Qhull's triangles are merged into polygonal faces where they
    are coplanar; each face gets an outward unit normal, a plane offset and its
    vertices counter-clockwise seen from outside; collinear and face-interior
    points are dropped. Mass properties are computed exactly (see
    :func:`mass_properties`). Raises GeometryError for fewer than 4 distinct
    points, coplanar points, NaN or inf, or a hull too flat to have a volume.
    """
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise GeometryError(f"points must have shape (n, 3), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise GeometryError("points contain NaN or inf")
    n_distinct = len(np.unique(pts, axis=0))
    if n_distinct < 4:
        raise GeometryError(f"a polyhedron needs at least 4 distinct points, got {n_distinct}")
    try:
        hull = ConvexHull(pts)
    except QhullError:
        raise GeometryError("the points are coplanar or collinear: their hull has no volume") from None
    scale = float(np.ptp(pts, axis=0).max())
    if hull.volume <= 1e-12 * scale**3:
        raise GeometryError(f"the points are nearly coplanar: hull volume {hull.volume:.3g} "
                            f"for an extent of {scale:.3g}")
    faces = _merged_faces(pts, hull, scale)
    used = np.unique(np.concatenate(faces))
    remap = np.full(len(pts), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    faces = [remap[f] for f in faces]
    return _build(pts[used], faces)


def _merged_faces(pts, hull, scale):
    """Qhull triangles merged into counter-clockwise polygons (indices into pts)."""
    from demcli.geometry import _kernels

    tri = hull.simplices
    eq = hull.equations  # n . x + c <= 0 inside
    nt = len(tri)
    t = np.repeat(np.arange(nt), 3)
    u = hull.neighbors.ravel()
    same = ((np.einsum("ij,ij->i", eq[t, :3], eq[u, :3]) >= 1.0 - _COPLANAR_COS)
            & (np.abs(eq[t, 3] - eq[u, 3]) <= _COPLANAR_OFFSET * scale))
    graph = coo_matrix((np.ones(same.sum()), (t[same], u[same])), shape=(nt, nt))
    n_comp, label = connected_components(graph, directed=False)
    sizes = np.bincount(label, minlength=n_comp)
    # lone triangles: orient counter-clockwise about the outward normal
    lone = sizes[label] == 1
    t3 = tri[lone].astype(np.int64)
    a, b, c = pts[t3[:, 0]], pts[t3[:, 1]], pts[t3[:, 2]]
    flip = np.einsum("ij,ij->i", np.cross(b - a, c - a), eq[lone, :3]) < 0.0
    t3[flip] = t3[flip][:, [0, 2, 1]]
    faces = list(t3)
    for comp in np.flatnonzero(sizes > 1):  # merged coplanar triangles: hull in the plane
        members = np.flatnonzero(label == comp)
        n = eq[members[0], :3]
        ids = np.unique(tri[members])
        e1 = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(n, e1)  # e1 x e2 = n: counter-clockwise in (e1, e2) is seen from outside
        p2 = np.ascontiguousarray(np.stack([pts[ids] @ e1, pts[ids] @ e2], axis=1))
        faces.append(ids[_kernels.hull2d(p2)])
    return faces


def _csr(faces):
    """Face lists as (flat indices, offsets, the next vertex along each face, face of each)."""
    offsets = np.zeros(len(faces) + 1, dtype=np.int64)
    offsets[1:] = np.cumsum([len(f) for f in faces])
    flat = np.concatenate(faces).astype(np.int64)
    face_of = np.repeat(np.arange(len(faces)), np.diff(offsets))
    pos = np.arange(len(flat)) + 1
    last = pos == offsets[face_of + 1]
    pos[last] = offsets[face_of[last]]  # wrap to the face's first vertex
    return flat, offsets, flat[pos], face_of


def _build(vertices, faces):
    """ConvexPolyhedron from vertices and counter-clockwise face index lists."""
    flat, offsets, nxt, face_of = _csr(faces)
    # Newell's area vector 1/2 sum p_i x p_i+1 gives each face's area and normal
    ref = vertices.mean(axis=0)
    area_vec = np.zeros((len(faces), 3))
    np.add.at(area_vec, face_of, 0.5 * np.cross(vertices[flat] - ref, vertices[nxt] - ref))
    areas = np.linalg.norm(area_vec, axis=1)
    normals = area_vec / areas[:, None]
    plane = np.zeros(len(faces))
    np.add.at(plane, face_of, np.einsum("ij,ij->i", vertices[flat], normals[face_of]))
    plane /= np.diff(offsets)
    edges = np.unique(np.sort(np.stack([flat, nxt], axis=1), axis=1), axis=0)
    volume, centroid, inertia = _mass(vertices, flat, offsets, nxt, face_of)
    moments, axes = np.linalg.eigh(inertia)
    if np.linalg.det(axes) < 0.0:
        axes[:, 2] *= -1.0
    parallel = np.abs(normals @ normals.T) >= 1.0 - _COPLANAR_COS
    keep = ~np.tril(parallel, -1).any(axis=1)
    circle_of = np.argmax(parallel[:, keep], axis=1)  # first kept circle parallel to each face
    return ConvexPolyhedron(
        vertices=np.ascontiguousarray(vertices), face_indices=flat, face_offsets=offsets,
        normals=normals, offsets=plane, areas=areas, edges=edges, volume=volume,
        centroid=centroid, inertia=inertia, principal_moments=moments, principal_axes=axes,
        circles=np.ascontiguousarray(normals[keep]),
        circle_weights=np.bincount(circle_of, weights=areas, minlength=keep.sum()))


def mass_properties(vertices, faces):
    """Exact volume (m^3), centroid (m) and unit-density inertia about the centroid (m^5).

    vertices: (n, 3); faces: index arrays, counter-clockwise seen from outside. The
    solid is split into tetrahedra (r, a, b, c) from a reference point r to a fan
    triangulation of each face (divergence theorem, as in Mirtich 1996, "Fast and
    accurate computation of polyhedral mass properties", J. Graphics Tools 1(2));
    each tetrahedron contributes its signed volume V = (a x b) . c / 6, first moment
    V (a + b + c)/4 and covariance V/20 (sum_k p_k p_k^T + s s^T), s = a + b + c
    (Tonon 2004, "Explicit exact formulas for the 3-D tetrahedron inertia tensor",
    J. Math. Stat. 1(1)). The inertia tensor is I = tr(C) Id - C for the centroidal
    covariance C.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    return _mass(vertices, *_csr(faces))


def _mass(vertices, flat, offsets, nxt, face_of):
    """mass_properties on faces in the layout of :func:`_csr`."""
    first = flat[offsets[face_of]]
    fan = (flat != first) & (nxt != first)  # edges (v_i, v_i+1) away from each face's first vertex
    tris = np.stack([first[fan], flat[fan], nxt[fan]], axis=1)
    ref = vertices.mean(axis=0)
    a, b, c = (vertices[tris[:, k]] - ref for k in range(3))
    vol = np.einsum("ij,ij->i", np.cross(a, b), c) / 6.0
    volume = vol.sum()
    s = a + b + c
    moment1 = (vol[:, None] * s).sum(axis=0) / 4.0
    cov = np.einsum("t,tij->ij", vol / 20.0,
                    np.einsum("ti,tj->tij", a, a) + np.einsum("ti,tj->tij", b, b)
                    + np.einsum("ti,tj->tij", c, c) + np.einsum("ti,tj->tij", s, s))
    d = moment1 / volume
    cov_c = cov - volume * np.outer(d, d)
    inertia = np.trace(cov_c) * np.eye(3) - cov_c
    return float(volume), ref + d, inertia


@dataclass(frozen=True)
class ShapeIndices:
    """Principal dimensions and flaky / elongated flags of one particle.

    ``length >= intermediate >= short`` (m) are the extents of the vertices along the
    three principal axes of inertia (not the minimal-volume bounding box, which can
    be smaller for skew particles); ``elongation = I/L`` and ``flatness = S/I`` are
    Zingg's (1935) ratios. ``flaky``: short < flaky_ratio * reference_size;
    ``elongated``: length > elongated_ratio * reference_size (BS 812-105.1 and
    105.2: flakiness gauge 0.6 and length gauge 1.8 times the mean sieve size of the
    particle's fraction). ``reference_size`` (m) is the size used for the flags.
    """

    length: float
    intermediate: float
    short: float
    elongation: float
    flatness: float
    flaky: bool
    elongated: bool
    reference_size: float


def shape_indices(particle, reference_size=None, flaky_ratio=0.6, elongated_ratio=1.8):
    """Shape indices of a convex particle (vertices (n, 3) in m, or a ConvexPolyhedron).

    reference_size (m): the mean sieve size of the particle's fraction, (d + D)/2 as
    in BS 812-105; None uses the particle's own projection sieve size
    (:func:`demcli.geometry.sieve_size`), a per-particle stand-in for the fraction
    mean. flaky_ratio, elongated_ratio: the gauge ratios (BS 812 defaults 0.6, 1.8).
    Returns a :class:`ShapeIndices`.
    """
    poly = as_polyhedron(particle)
    ext = np.ptp((poly.vertices - poly.centroid) @ poly.principal_axes, axis=0)
    big, mid, small = np.sort(ext)[::-1]
    if reference_size is None:
        from demcli.geometry.projection import sieve_size

        reference_size = sieve_size(poly)
    return ShapeIndices(
        length=float(big), intermediate=float(mid), short=float(small),
        elongation=float(mid / big), flatness=float(small / mid),
        flaky=bool(small < flaky_ratio * reference_size),
        elongated=bool(big > elongated_ratio * reference_size),
        reference_size=float(reference_size))
