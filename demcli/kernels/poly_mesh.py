"""Polyhedron against a triangle mesh wall: the overlap with the prism under each triangle.

A triangle T = (a, b, c) of a mesh wall acts on a body through the convex region under it:
the half-space behind T's unit normal n (turned to the side of the body's centroid x_b, the
mesh is two-sided: n = sign((x_b - a) . n_f) n_f, n_f = (b - a) x (c - a) / |(b - a) x (c - a)|),
restricted to the infinite prism over T and truncated at the depth D = 2 r_b (r_b the body's
bounding radius), a closed convex polyhedron of 6 vertices and 5 faces:

* top    n . x <= n . a                     (T's plane)
* bottom -n . x <= -(n . a - D)
* sides  m_e . x <= m_e . p_e, m_e = (p_{e+1} - p_e) x n / |...| for the edges p_e -> p_{e+1}
  of T ordered counter-clockwise about n (the outward in-plane edge normals).

The body's overlap with each prism is the exact convex-convex overlap
(:func:`demcli.kernels.polyhedra.overlap_ws`, the body A, the prism B): volume V_T [m^3],
centroid g_T [m] and area vector S_T [m^2] (from the prism into the body). The prisms of a flat
mesh tile the slab under it, so the sums V = sum V_T, g = sum V_T g_T / V, S = sum S_T equal the
half-space's (:func:`demcli.kernels.polyhedra.plane_overlap_ws`) to round-off
(tests/kernels/test_poly_mesh.py). At an edge between triangles at an angle the prisms overlap
(a convex edge: the body's volume in both counts twice) or leave a wedge out (a concave edge):
docs/walls.md gives a measured example.

Candidate triangles are those within r_b of the centroid (the mesh's cell grid,
:func:`demcli.kernels.mesh._touching`, at most MAX_TOUCH of them); each is visited once, in the
grid's fixed order (the sums do not depend on the thread count).
"""

import math

import numpy as np
from numba import types
from numba.extending import overload

from demcli.jit import njit
from demcli.kernels.mesh import MAX_TOUCH, _touching, mesh_of
from demcli.kernels.polyhedra import overlap_ws, scratch

# the prism's faces (CCW seen from outside): top p0 p1 p2, bottom p0' p2' p1', sides over the edges
_PRISM_FACE_START = (0, 3, 6, 10, 14, 18)
_PRISM_FACE_VERTS = (0, 1, 2, 3, 5, 4, 0, 3, 4, 1, 1, 4, 5, 2, 2, 5, 3, 0)
# columns of a candidate's row in MeshScratch.res
R_V, R_GX, R_GY, R_GZ, R_SX, R_SY, R_SZ, R_NX, R_NY, R_NZ, R_D = range(11)
N_RES = 11


@njit
def mesh_scratch(max_face_vertices, max_faces):
    """Scratch of :func:`mesh_pieces` for bodies with at most ``max_faces`` faces of at most
    ``max_face_vertices`` vertices (allocate once per chunk of bodies): (tri, dist, q, region, nrm) of
    :func:`demcli.kernels.mesh._touching`, res (MAX_TOUCH, N_RES), the prism (pv (6, 3), pfs (6,),
    pfv (18,), pn (5, 3), pd (5,)), the overlap scratch (buf, fw, planes) of
    :func:`demcli.kernels.polyhedra.overlap_ws` and a point (3,)."""
    pfs = np.empty(6, np.int64)
    pfv = np.empty(18, np.int64)
    for k in range(6):
        pfs[k] = _PRISM_FACE_START[k]
    for k in range(18):
        pfv[k] = _PRISM_FACE_VERTS[k]
    buf, fw, planes = scratch(max(max_face_vertices, 4), max(max_faces, 5))
    return (np.empty(MAX_TOUCH, np.int64), np.empty(MAX_TOUCH), np.empty((MAX_TOUCH, 3)),
            np.empty(MAX_TOUCH, np.int64), np.empty((MAX_TOUCH, 3)), np.empty((MAX_TOUCH, N_RES)),
            np.empty((6, 3)), pfs, pfv, np.empty((5, 3)), np.empty(5), buf, fw, planes, np.empty(3))


def scratch_for(mesh, max_face_vertices, max_faces):
    """:func:`mesh_scratch`, or None when ``mesh`` is None (no mesh wall); decided at compile time
    from the type of ``mesh`` (:mod:`demcli.kernels.switch`): a scene without mesh walls allocates
    nothing."""
    return None if mesh is None else mesh_scratch(max_face_vertices, max_faces)


@overload(scratch_for, inline="always")
def _scratch_for(mesh, max_face_vertices, max_faces):
    if isinstance(mesh, types.NoneType):
        return lambda mesh, max_face_vertices, max_faces: None
    return lambda mesh, max_face_vertices, max_faces: mesh_scratch(max_face_vertices, max_faces)


@njit(inline="always")
def _set_plane(pn, pd, f, nx, ny, nz, p):
    """Face f of the prism: unit normal (nx, ny, nz) and offset n . p [m] (p (3,) on the face)."""
    pn[f, 0] = nx
    pn[f, 1] = ny
    pn[f, 2] = nz
    pd[f] = nx * p[0] + ny * p[1] + nz * p[2]


@njit(_nrt=False)
def build_prism(verts, tri, px, py, pz, cx, cy, cz, depth, pv, pn, pd):
    """The prism of triangle ``tri`` (rows of ``verts``, relative to the wall's point (px, py, pz) [m])
    on the side of the point (cx, cy, cz) [m], ``depth`` [m] deep (module notes): its world vertices
    pv (6, 3) and face planes pn (5, 3), pd (5,). Returns (n_x, n_y, n_z, centre x, y, z, radius [m]),
    n T's unit normal towards the point; radius 0 for a degenerate triangle (no prism)."""
    for k in range(3):
        pv[k, 0] = px + verts[tri[k], 0]
        pv[k, 1] = py + verts[tri[k], 1]
        pv[k, 2] = pz + verts[tri[k], 2]
    e1x, e1y, e1z = pv[1, 0] - pv[0, 0], pv[1, 1] - pv[0, 1], pv[1, 2] - pv[0, 2]
    e2x, e2y, e2z = pv[2, 0] - pv[0, 0], pv[2, 1] - pv[0, 1], pv[2, 2] - pv[0, 2]
    fx, fy, fz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    ln = math.sqrt(fx * fx + fy * fy + fz * fz)
    if not ln > 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    nx, ny, nz = fx / ln, fy / ln, fz / ln
    if (cx - pv[0, 0]) * nx + (cy - pv[0, 1]) * ny + (cz - pv[0, 2]) * nz < 0.0:
        nx, ny, nz = -nx, -ny, -nz  # the body's side: swap b and c, so that p0 p1 p2 turn CCW about n
        for d in range(3):
            pv[1, d], pv[2, d] = pv[2, d], pv[1, d]
    for k in range(3):
        pv[3 + k, 0] = pv[k, 0] - depth * nx
        pv[3 + k, 1] = pv[k, 1] - depth * ny
        pv[3 + k, 2] = pv[k, 2] - depth * nz
    _set_plane(pn, pd, 0, nx, ny, nz, pv[0])
    _set_plane(pn, pd, 1, -nx, -ny, -nz, pv[3])
    for e in range(3):
        f = (e + 1) % 3
        ex, ey, ez = pv[f, 0] - pv[e, 0], pv[f, 1] - pv[e, 1], pv[f, 2] - pv[e, 2]
        mx, my, mz = ey * nz - ez * ny, ez * nx - ex * nz, ex * ny - ey * nx
        lm = math.sqrt(mx * mx + my * my + mz * mz)
        _set_plane(pn, pd, 2 + e, mx / lm, my / lm, mz / lm, pv[e])
    ox = oy = oz = 0.0
    for k in range(6):
        ox += pv[k, 0]
        oy += pv[k, 1]
        oz += pv[k, 2]
    ox /= 6.0
    oy /= 6.0
    oz /= 6.0
    r2 = 0.0
    for k in range(6):
        r2 = max(r2, (pv[k, 0] - ox) ** 2 + (pv[k, 1] - oy) ** 2 + (pv[k, 2] - oz) ** 2)
    return nx, ny, nz, ox, oy, oz, math.sqrt(r2)


@njit
def mesh_pieces(va, fsa, fva, offa, na, da, cx, cy, cz, ra, mesh, w, px, py, pz, ms):
    """The body's overlap with the prism of each triangle of mesh wall w (point (px, py, pz) [m])
    within ``ra`` [m] of its centroid (cx, cy, cz): body arrays as for
    :func:`demcli.kernels.polyhedra.overlap_ws`, ``ms`` from :func:`mesh_scratch`. Row m < count of
    ms res: (V [m^3], centroid (3) [m], S (3) [m^2], the triangle's unit normal n towards the body
    (3), its plane offset n . a [m]); ms tri[m] the triangle. Returns count."""
    tri, dist, q, region, nrm, res, pv, pfs, pfv, pn, pd, buf, fw, planes, centre = ms
    verts, tris, lo, dims, cstart, clist, cell = mesh_of(mesh, w)
    centre[0], centre[1], centre[2] = cx - px, cy - py, cz - pz
    n = _touching(centre, ra, verts, tris, lo, dims, cstart, clist, cell, tri, dist, q, region, nrm)
    for m in range(n):
        nx, ny, nz, ox, oy, oz, rb = build_prism(verts, tris[tri[m]], px, py, pz, cx, cy, cz, 2.0 * ra, pv, pn, pd)
        vol = gx = gy = gz = sx = sy = sz = 0.0
        if rb > 0.0:
            vol, gx, gy, gz, sx, sy, sz = overlap_ws(va, fsa, fva, offa, na, da, cx, cy, cz, ra,
                                                     pv, pfs, pfv, 0, pn, pd, ox, oy, oz, rb, buf, fw, planes)
        row = res[m]
        row[R_V], row[R_GX], row[R_GY], row[R_GZ] = vol, gx, gy, gz
        row[R_SX], row[R_SY], row[R_SZ] = sx, sy, sz
        row[R_NX], row[R_NY], row[R_NZ], row[R_D] = nx, ny, nz, pd[0]
    return n


COPLANAR = 1e-9
"""Two triangles' unit normals within this, and their planes within this x r_b, are one plane."""


@njit(inline="always")
def _same_plane(res, o, m, tol):
    """Whether candidates o and m lie in one plane (:data:`COPLANAR`; tol [m] for the offsets)."""
    return (abs(res[o, R_NX] - res[m, R_NX]) + abs(res[o, R_NY] - res[m, R_NY]) + abs(res[o, R_NZ] - res[m, R_NZ])
            <= COPLANAR and abs(res[o, R_D] - res[m, R_D]) <= tol)


@njit
def plane_sums(res, n, lead, ra):
    """Groups the touching candidates (V > 0) of :func:`mesh_pieces` by plane: lead[m] the first
    candidate of m's plane (-1 when m does not touch). The leader's row then holds its plane's sums:
    V = sum V_T, centroid sum V_T g_T / V, S = sum S_T (candidates added in their order). Returns the
    number of planes."""
    tol = COPLANAR * ra
    count = 0
    for m in range(n):
        lead[m] = -1
        if not res[m, R_V] > 0.0:
            continue
        for o in range(m):
            if lead[o] == o and _same_plane(res, o, m, tol):
                lead[m] = o
                break
        if lead[m] < 0:
            lead[m] = m
            count += 1
            for c in range(R_GX, R_GZ + 1):
                res[m, c] *= res[m, R_V]
        else:
            o = lead[m]
            res[o, R_V] += res[m, R_V]
            for c in range(3):
                res[o, R_GX + c] += res[m, R_V] * res[m, R_GX + c]
                res[o, R_SX + c] += res[m, R_SX + c]
    for m in range(n):
        if lead[m] == m:
            for c in range(R_GX, R_GZ + 1):
                res[m, c] /= res[m, R_V]
    return count
