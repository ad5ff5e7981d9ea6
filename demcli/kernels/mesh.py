"""Sphere against a triangle mesh wall: closest points, a cell grid of triangles, and one contact per touched feature.

A sphere of centre c and radius r touches triangle T when the closest point q of T to c
(Ericson, *Real-Time Collision Detection*, 2005, sec. 5.1.5) lies within r: overlap
delta = r - |c - q| [m], unit normal n = (c - q) / |c - q| from the mesh to the sphere.
The region of T that holds q is recorded: the face interior, an edge or a vertex.

A sphere that touches several triangles of one mesh must feel one contact per touched
surface feature, so that a sphere on a flat mesh of many triangles feels exactly the plane's
force wherever it sits. Rule: a face contact is kept (once per point); an edge or vertex contact of T
is kept only when T comes first, in the order (face contacts first, then distance, then triangle
index), among the touching triangles that share that edge or vertex (they are at least as close,
since the feature is part of each); contacts at one point (within 1e-9 r: round-off on a shared
edge) count once. On a flat mesh exactly one contact survives, at the foot of the perpendicular; a
convex edge gives one contact along the edge's outward normal; a concave corner gives one
face contact per face. Vertices must be shared by index (the mesh reader merges them).

A face contact takes the face's unit normal n_f = (b - a) x (c - a) / |(b - a) x (c - a)|, turned
to the sphere's side, and the distance s = (c - a) . n [m] (the plane wall's arithmetic: a flat
mesh parallel to a coordinate plane gives the plane's s and n bit for bit); edge and vertex
contacts n = (c - q) / |c - q|. Each triangle is visited once per query, in the first cell its
bounding box shares with the sphere's (no marks: queries run in parallel without shared writes).
"""

import math

import numpy as np

from demcli.jit import njit

# region of the closest point on triangle (a, b, c)
FACE, EDGE_AB, EDGE_BC, EDGE_CA, VERT_A, VERT_B, VERT_C = range(7)

MAX_TOUCH = 64
"""Most triangles of one mesh one sphere may touch at a time (the rest are ignored)."""

SAME_POINT = 1e-9
"""Closest points of two triangles closer than this fraction of the radius are one contact point."""


@njit(inline="always")
def _dot(ax, ay, az, bx, by, bz):
    return ax * bx + ay * by + az * bz


@njit
def closest_on_triangle(p, a, b, c):
    """Closest point q of triangle (a, b, c) to point p (all (3,) [m]) and its region (FACE,
    EDGE_*, VERT_*); Ericson 2005, sec. 5.1.5, by Voronoi regions. Returns (qx, qy, qz, region)."""
    abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
    apx, apy, apz = p[0] - a[0], p[1] - a[1], p[2] - a[2]
    d1 = _dot(abx, aby, abz, apx, apy, apz)
    d2 = _dot(acx, acy, acz, apx, apy, apz)
    if d1 <= 0.0 and d2 <= 0.0:
        return a[0], a[1], a[2], VERT_A
    bpx, bpy, bpz = p[0] - b[0], p[1] - b[1], p[2] - b[2]
    d3 = _dot(abx, aby, abz, bpx, bpy, bpz)
    d4 = _dot(acx, acy, acz, bpx, bpy, bpz)
    if d3 >= 0.0 and d4 <= d3:
        return b[0], b[1], b[2], VERT_B
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        v = d1 / (d1 - d3)
        return a[0] + v * abx, a[1] + v * aby, a[2] + v * abz, EDGE_AB
    cpx, cpy, cpz = p[0] - c[0], p[1] - c[1], p[2] - c[2]
    d5 = _dot(abx, aby, abz, cpx, cpy, cpz)
    d6 = _dot(acx, acy, acz, cpx, cpy, cpz)
    if d6 >= 0.0 and d5 <= d6:
        return c[0], c[1], c[2], VERT_C
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        w = d2 / (d2 - d6)
        return a[0] + w * acx, a[1] + w * acy, a[2] + w * acz, EDGE_CA
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return b[0] + w * (c[0] - b[0]), b[1] + w * (c[1] - b[1]), b[2] + w * (c[2] - b[2]), EDGE_BC
    denom = 1.0 / (va + vb + vc)
    v = vb * denom
    w = vc * denom
    return a[0] + abx * v + acx * w, a[1] + aby * v + acy * w, a[2] + abz * v + acz * w, FACE


@njit
def bin_triangles(verts, tris, cell):
    """Cell grid of the triangles: each triangle listed in every cell its bounding box overlaps.

    verts (nv, 3) [m]; tris (nt, 3) int64; cell edge [m] (> 0). Returns (lo (3,) grid origin [m],
    dims (3,) int64, cstart (ncell + 1,) int64, clist) in CSR form: the triangles of cell k are
    clist[cstart[k]:cstart[k + 1]], cell k = (ix * dims[1] + iy) * dims[2] + iz."""
    lo = np.empty(3)
    dims = np.empty(3, np.int64)
    for d in range(3):
        lo[d] = verts[:, d].min()
        dims[d] = max(1, int(math.floor((verts[:, d].max() - lo[d]) / cell)) + 1)
    cstart = np.zeros(dims[0] * dims[1] * dims[2] + 1, np.int64)
    _bin_sweep(verts, tris, lo, dims, cell, cstart[1:], cstart[:1], False)
    for k in range(len(cstart) - 1):
        cstart[k + 1] += cstart[k]
    clist = np.empty(cstart[-1], np.int64)
    _bin_sweep(verts, tris, lo, dims, cell, cstart[:-1].copy(), clist, True)
    return lo, dims, cstart, clist


@njit
def _bin_sweep(verts, tris, lo, dims, cell, fill, clist, listing):
    """One sweep over the triangles' cells: fill[k] += 1 for each triangle t in cell k, and with
    ``listing`` also clist[fill[k]] = t first (counting sweep: clist unused)."""
    for t in range(len(tris)):
        i0, i1 = _cell_span(verts, tris[t], lo, dims, cell, 0)
        j0, j1 = _cell_span(verts, tris[t], lo, dims, cell, 1)
        k0, k1 = _cell_span(verts, tris[t], lo, dims, cell, 2)
        for ix in range(i0, i1 + 1):
            for iy in range(j0, j1 + 1):
                for iz in range(k0, k1 + 1):
                    k = (ix * dims[1] + iy) * dims[2] + iz
                    if listing:
                        clist[fill[k]] = t
                    fill[k] += 1


@njit(inline="always")
def _cell_index(x, lo, cell, n):
    return min(max(int(math.floor((x - lo) / cell)), 0), n - 1)


@njit
def _cell_span(verts, tri, lo, dims, cell, d):
    """First and last cell index along axis d of the bounding box of triangle ``tri``."""
    a, b, c = verts[tri[0], d], verts[tri[1], d], verts[tri[2], d]
    return (_cell_index(min(a, b, c), lo[d], cell, dims[d]),
            _cell_index(max(a, b, c), lo[d], cell, dims[d]))


@njit
def _touching(centre, r, verts, tris, lo, dims, cstart, clist, cell, tri, dist, q, region, nrm):
    """Triangles within r of ``centre`` from the cells the sphere's box overlaps, each once (in the
    first cell shared by its box and the sphere's). Fills tri, dist (s [m]), q (rows: closest
    point), region, nrm (rows: unit normal from the mesh to the centre); returns the count."""
    n = 0
    ilo = np.empty(3, np.int64)
    ihi = np.empty(3, np.int64)
    for d in range(3):
        ilo[d] = _cell_index(centre[d] - r, lo[d], cell, dims[d])
        ihi[d] = _cell_index(centre[d] + r, lo[d], cell, dims[d])
    for ix in range(ilo[0], ihi[0] + 1):
        for iy in range(ilo[1], ihi[1] + 1):
            for iz in range(ilo[2], ihi[2] + 1):
                k = (ix * dims[1] + iy) * dims[2] + iz
                for m in range(cstart[k], cstart[k + 1]):
                    t = clist[m]
                    if n == MAX_TOUCH or not _first_cell(verts, tris[t], lo, dims, cell, ilo, ix, iy, iz):
                        continue
                    if _triangle_contact(centre, r, verts, tris[t], n, dist, q, region, nrm):
                        tri[n] = t
                        n += 1
    return n


@njit(inline="always")
def _first_cell(verts, tri, lo, dims, cell, ilo, ix, iy, iz):
    """Whether cell (ix, iy, iz) is the first one the triangle's box shares with the query's (from ilo)."""
    return (ix == max(_cell_span(verts, tri, lo, dims, cell, 0)[0], ilo[0])
            and iy == max(_cell_span(verts, tri, lo, dims, cell, 1)[0], ilo[1])
            and iz == max(_cell_span(verts, tri, lo, dims, cell, 2)[0], ilo[2]))


@njit
def _triangle_contact(centre, r, verts, tri, n, dist, q, region, nrm):
    """Row n of dist, q, region, nrm for one triangle (module notes); whether it lies within r."""
    a, b, c = verts[tri[0]], verts[tri[1]], verts[tri[2]]
    qx, qy, qz, reg = closest_on_triangle(centre, a, b, c)
    if reg == FACE:
        abx, aby, abz = b[0] - a[0], b[1] - a[1], b[2] - a[2]
        acx, acy, acz = c[0] - a[0], c[1] - a[1], c[2] - a[2]
        fx, fy, fz = aby * acz - abz * acy, abz * acx - abx * acz, abx * acy - aby * acx
        ln = math.sqrt(fx * fx + fy * fy + fz * fz)
        nx, ny, nz = fx / ln, fy / ln, fz / ln
        s = (centre[0] - a[0]) * nx + (centre[1] - a[1]) * ny + (centre[2] - a[2]) * nz
        if s < 0.0:
            nx, ny, nz, s = -nx, -ny, -nz, -s
    else:
        s = math.sqrt((centre[0] - qx) ** 2 + (centre[1] - qy) ** 2 + (centre[2] - qz) ** 2)
        d = s if s > 0.0 else 1.0  # divided, not times 1/s: a vertex straight below gives n = (0, 0, 1) exactly
        nx, ny, nz = (centre[0] - qx) / d, (centre[1] - qy) / d, (centre[2] - qz) / d
    if not s < r:
        return False
    dist[n], region[n] = s, reg
    q[n, 0], q[n, 1], q[n, 2] = qx, qy, qz
    nrm[n, 0], nrm[n, 1], nrm[n, 2] = nx, ny, nz
    return True


@njit(inline="always")
def _feature(tris, t, reg):
    """Vertex indices (u, v) of the edge or vertex (u == v) of triangle t that holds region ``reg``."""
    a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
    if reg == EDGE_AB:
        return a, b
    if reg == EDGE_BC:
        return b, c
    if reg == EDGE_CA:
        return c, a
    if reg == VERT_A:
        return a, a
    if reg == VERT_B:
        return b, b
    return c, c


@njit(inline="always")
def _has_vertex(tris, t, u):
    return tris[t, 0] == u or tris[t, 1] == u or tris[t, 2] == u


@njit(inline="always")
def _before(o, m, tri, dist, region):
    """Whether touching triangle o comes before m in the order (face contacts first, distance,
    triangle index)."""
    fo = region[o] != FACE
    fm = region[m] != FACE
    if fo != fm:
        return fm
    return dist[o] < dist[m] or (dist[o] == dist[m] and tri[o] < tri[m])


@njit
def _first_at_feature(m, n, tris, tri, dist, q, region, tol):
    """Whether touching triangle m keeps its contact: no triangle before it (:func:`_before`) has
    the same closest point (within tol [m]: a point on a shared edge seen as inside both faces by
    round-off) or, for an edge or vertex contact, holds the same feature."""
    for o in range(n):
        if o != m and _before(o, m, tri, dist, region) and (abs(q[o, 0] - q[m, 0]) + abs(q[o, 1] - q[m, 1])
                                                    + abs(q[o, 2] - q[m, 2]) <= tol):
            return False
    if region[m] == FACE:
        return True
    u, v = _feature(tris, tri[m], region[m])
    for o in range(n):
        if o == m or not (_has_vertex(tris, tri[o], u) and _has_vertex(tris, tri[o], v)):
            continue
        if _before(o, m, tri, dist, region):
            return False
    return True


@njit
def sphere_mesh_contacts(centre, r, verts, tris, lo, dims, cstart, clist, cell, out_tri, out_q, out_n, out_s):
    """Contacts of one sphere (centre (3,) [m], radius r [m]) with one mesh, one per touched
    feature (see the module notes). Grid from :func:`bin_triangles`. Writes row k < count of
    out_tri (triangle), out_q (closest point on the mesh [m]), out_n (unit normal, mesh to
    sphere), out_s (distance s from the centre [m]; overlap r - s); returns count. Out arrays have
    MAX_TOUCH rows. Reads only: safe in a parallel loop."""
    region = np.empty(MAX_TOUCH, np.int64)
    n = _touching(centre, r, verts, tris, lo, dims, cstart, clist, cell, out_tri, out_s, out_q, region, out_n)
    keep = np.empty(n, np.bool_)
    for m in range(n):
        keep[m] = _first_at_feature(m, n, tris, out_tri, out_s, out_q, region, SAME_POINT * r)
    count = 0
    for m in range(n):
        if not keep[m] or out_s[m] <= 0.0:        # centre on the surface: no direction to push along
            continue
        out_tri[count] = out_tri[m]
        out_s[count] = out_s[m]
        for d in range(3):
            out_n[count, d] = out_n[m, d]
            out_q[count, d] = out_q[m, d]
        count += 1
    return count


@njit(inline="always")
def mesh_of(mesh, w):
    """(verts, tris, lo, dims, cstart, clist, cell) of mesh wall w in the MeshArrays ``mesh``
    (:data:`demcli.kernels.layout.MeshArrays`): views, the vertices relative to the wall's point."""
    cs = mesh.cstart[mesh.cbase[w]:mesh.cbase[w + 1]]
    cl = mesh.clist[mesh.lbase[w]:mesh.lbase[w + 1]]
    return (mesh.verts[mesh.vstart[w]:mesh.vstart[w + 1]], mesh.tris[mesh.tstart[w]:mesh.tstart[w + 1]], mesh.lo[w],
            mesh.dims[w], cs, cl, mesh.cell[w])


@njit
def wall_contacts(mesh, w, px, py, pz, x, y, z, r, out_tri, out_q, out_n, out_s):
    """:func:`sphere_mesh_contacts` of the sphere at (x, y, z) [m] of radius r with mesh wall w
    whose point is (px, py, pz) now (the mesh translated with it); out_q relative to that point."""
    c = np.empty(3)
    c[0], c[1], c[2] = x - px, y - py, z - pz
    verts, tris, lo, dims, cstart, clist, cell = mesh_of(mesh, w)
    return sphere_mesh_contacts(c, r, verts, tris, lo, dims, cstart, clist, cell, out_tri, out_q, out_n, out_s)


@njit
def wall_features(mesh, w, px, py, pz, x, y, z, r):
    """(count, nearest, normals (MAX_TOUCH, 3), distances s (MAX_TOUCH,) [m]) of the contacts of the
    sphere at (x, y, z) of radius r [m] with mesh wall w (point (px, py, pz)): :func:`wall_contacts`
    in fresh arrays, and the row of the nearest one (0 when none)."""
    tri = np.empty(MAX_TOUCH, np.int64)
    q = np.empty((MAX_TOUCH, 3))
    nrm = np.empty((MAX_TOUCH, 3))
    s = np.empty(MAX_TOUCH)
    count = wall_contacts(mesh, w, px, py, pz, x, y, z, r, tri, q, nrm, s)
    near = 0
    for m in range(1, count):
        if s[m] < s[near]:
            near = m
    return count, near, nrm, s


@njit
def nearest_feature(mesh, w, px, py, pz, x, y, z, reach):
    """(s, nx, ny, nz): distance [m] from the point (x, y, z) to mesh wall w (point (px, py, pz))
    and the unit normal of its nearest contact, among the features within ``reach`` [m];
    (reach, 0, 0, 0) when none is."""
    count, near, nrm, s = wall_features(mesh, w, px, py, pz, x, y, z, reach)
    if count == 0:
        return reach, 0.0, 0.0, 0.0
    return s[near], nrm[near, 0], nrm[near, 1], nrm[near, 2]


def cell_size(verts, tris):
    """Cell edge of a mesh's grid [m]: the mean over its triangles of their bounding boxes' largest side."""
    corners = verts[tris]
    return float(np.mean(np.ptp(corners, axis=1).max(axis=1)))


def mesh_arrays(meshes):
    """MeshArrays (:data:`demcli.kernels.layout.MeshArrays`) of the walls: ``meshes`` per wall
    (vertices relative to the wall's point [m], triangles) or None (not a mesh wall); None when no
    wall is a mesh (meshes None or all None): nothing allocated, and the kernels compile without
    the mesh path (:mod:`demcli.kernels.switch`)."""
    from demcli.kernels.layout import MeshArrays

    i64 = np.int64
    if meshes is None or all(m is None for m in meshes):
        return None
    nw = len(meshes)
    parts = {"verts": [], "tris": [], "cstart": [], "clist": []}
    lo, dims, cell = np.zeros((nw, 3)), np.ones((nw, 3), i64), np.ones(nw)
    for w, m in enumerate(meshes):
        if m is None:
            continue
        verts, tris = np.ascontiguousarray(m[0], float), np.ascontiguousarray(m[1], i64)
        cell[w] = cell_size(verts, tris)
        lo[w], dims[w], cstart, clist = bin_triangles(verts, tris, cell[w])
        for key, a in zip(parts, (verts, tris, cstart, clist)):
            parts[key].append(a)

    def offsets(key):
        sizes = np.zeros(nw + 1, i64)
        it = iter(parts[key])
        for w, m in enumerate(meshes):
            sizes[w + 1] = 0 if m is None else len(next(it))
        return np.cumsum(sizes)

    return MeshArrays(np.concatenate(parts["verts"]), np.concatenate(parts["tris"]), offsets("verts"),
                      offsets("tris"), lo, dims, cell, np.concatenate(parts["cstart"]), offsets("cstart"),
                      np.concatenate(parts["clist"]), offsets("clist"))
