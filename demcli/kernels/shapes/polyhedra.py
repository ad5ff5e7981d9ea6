"""Shape plug-in: rigid convex polyhedra (seed 002, Shao, Lian & Yang 2017, sec. 3).

Contact law (seed eqs. 17-19, Shao, Lian & Yang 2017), for the intersection I of the two
bodies with volume V, contact area A_c = |S| and normal n = S/|S|
(:func:`demcli.kernels.polyhedra.contact_frame`), depth d = V / A_c, contact point the
centroid g of I:

* normal: F_N = k_n sqrt(V d), k_n = 4 E / (3 sqrt(pi)) [Pa], E = 2 E1 E2 / (E1 + E2).
  For a flat face-face overlap V = A_c d, so F_N = k_n sqrt(A_c) d: the contact's
  normal stiffness is K_n = k_n sqrt(A_c) [N/m].
* optional normal dashpot: c_n = 2 zeta sqrt(m* K_n), zeta from the restitution
  coefficient, on the normal relative velocity at g; the normal force is clamped at
  zero (no cohesion), which only removes energy.
* tangential: incremental spring dF_s = -K_t v_t dt, history turned into the current
  tangent plane (``_to_tangent_plane``), K_t = k_s sqrt(A_c), k_s = 0.25 k_n. The
  paper prints dF_s = k_s du_s A, which is not a force (Pa m m^2 = N m); with
  V ~ A d the normal law's stiffness is k_n sqrt(A), so K_t = k_s sqrt(A) keeps
  k_s / k_n = 0.25 as the ratio of tangential to normal contact stiffness.
* Coulomb slip: |F_s| <= mu F_N (the stored spring is scaled back to the limit).

The pair pass: prange over CSR rows i, the exact overlap (``overlap_ws``) of each listed
pair whose bounding spheres meet, unless a cached separating face or direction (``sep``,
``sdir``) still clears it by a margin, one force per pair into its own row; the row owner sums
i's side (race-free). Plane walls: the overlap of the body with the solid half-space
n_in . x <= n_in . p (``plane_overlap``). Actors (bodies nsmall..) stay out of the cell grid and
are paired with every body near them (:func:`add_actor_pairs`).

Provides the engine's hooks (:mod:`demcli.kernels.shapes`): ``place`` (world vertices and face
planes), ``primitives`` (bounding spheres on the centroids), ``pair_pass``, ``wall_pass``,
``worst_overlap`` (depth / bounding radius).
"""

import math
from collections import namedtuple

import numpy as np
from numba import prange

from demcli.jit import njit
from demcli.kernels.contact import _to_tangent_plane
from demcli.kernels.layout import F_DASHPOT, F_ENERGY, F_FRICTION
from demcli.kernels.poly_mesh import R_GX, R_NX, R_SX, R_V, mesh_pieces, plane_sums, scratch_for
from demcli.kernels.polyhedra import (BOX_PAD, contact_frame, max_row, overlap_in_box, overlap_ws, plane_overlap_ws,
                                      plane_scratch, scratch, to_world_planes)
from demcli.kernels.quat import mul, rotate
from demcli.kernels.separation import gap, separating_direction
from demcli.kernels.walls import MESH

PolyGeometry = namedtuple("PolyGeometry", "rad mat shape vertex_start vertices face_start fvstart fverts "
                                          "face_normal face_offset bvstart bfstart wvert wnorm woff travel refresh")
"""Polyhedra: rad (n_b,) bounding radius about the centroid [m]; mat (n_b,) material; shape (n_b,)
template of each body; vertex_start .. face_offset: the polyhedron_shapes CSR tables (body frame);
bvstart, bfstart (n_b + 1,) each body's rows of the world arrays wvert (n_v, 3), wnorm (n_f, 3),
woff (n_f,) (rewritten every step); travel (n_b,) [m]: each body's travel so far, the sum over
steps of its largest vertex displacement (a bound on how far any of its points has moved since
an earlier step: the displacement of a rigid motion is affine in the point, its norm largest at
a vertex); refresh (int): a touching pair's geometry is evaluated exactly every refresh-th step,
linearized in between (contact.geometry_refresh > 1); None: every step, the exact law (the linearized
path is not compiled)."""

# columns of the material-pair table prm[a, b, :]
Q_KN = 0      # k_n = 4 E / (3 sqrt(pi)) [Pa]
Q_MU = 1      # Coulomb friction coefficient [-]
Q_ZETA = 2    # damping ratio of the optional normal dashpot [-]
N_QPARAMS = 3

# sep[c] (int32), why pair c does not touch: 0 unknown (or touching), k + 1 face k of body i,
# -(k + 1) face k of body j (its plane clears the other body), SEP_DIR the unit direction
# sdir[c] (float64 (3,), from i to j) separates them (demcli.kernels.separation; pairs
# separated only across two edges), SEP_NONE none found (overlap() every step)
SEP_NONE = -(2 ** 30)
SEP_DIR = SEP_NONE + 1
SEP_ITER = 32  # GJK iterations allowed when searching a separating direction
# the pair and wall passes run over chunks of this many rows (bodies), the scratch allocated once per chunk
ROW_CHUNK = 16
SEP_MARGIN = 1e-9  # a cached face or direction must clear by this x (r_i + r_j) + 1e-12 max |x|
# columns of geo / wgeo (per contact, last evaluation): depth d [m], elastic normal force F_N [N],
# tangential stiffness K_t [N/m]
G_DEPTH, G_FN, G_KT = 0, 1, 2
# pbox columns: the culling box (0-5); with contact.geometry_refresh k > 1 also the last exact
# evaluation's V [m^3] (L_V), S [m^2] (L_S), centroid g [m] (L_G), the moments T_i, T_j [m^3] (L_TI,
# L_TJ), both bodies' positions [m] (L_XI, L_XJ) and orientations (L_QI, L_QJ) then, and the linearized
# steps left before the next exact one (L_LEFT); see _linear_volume
BOX_COLS = 6
L_V, L_S, L_G, L_TI, L_TJ, L_XI, L_XJ, L_QI, L_QJ, L_LEFT = 6, 7, 10, 13, 16, 19, 22, 25, 29, 33
LINEAR_COLS = 34



@njit(internal=True)
def _volumetric_law(prm, ma, mb, vol, depth, area, nx, ny, nz, vx, vy, vz, mstar, dt, ft, k, friction, dashpot):
    """Force on A of one contact (seed eqs. 17-19; see the module docstring).

    Args:
        prm: (n_m, n_m, N_QPARAMS) material-pair table; ma, mb: the pair's materials (indices:
        a row view costs two atomic reference-count updates per contact). vol [m^3],
        depth [m], area [m^2]: overlap volume, depth V/A_c and contact area. n: unit normal from B into A. v: velocity
        of A's material point at the contact point relative to B's [m/s]. mstar [kg].
        dt: step [s] (0 for the priming evaluation: no history increment).
        ft: (n, 3) tangential springs [N], row k updated in place.

    Returns:
        (fx, fy, fz, e_damp, e_fric, F_N elastic, K_n (+ c_n/dt for the servo), K_t).
    """
    kn = prm[ma, mb, Q_KN]
    sq = math.sqrt(area)
    knc = kn * sq                      # contact normal stiffness k_n sqrt(A_c) [N/m]
    fel = kn * math.sqrt(vol * depth)  # eq. 17
    vn = vx * nx + vy * ny + vz * nz
    fn = fel
    e_damp = 0.0
    kserv = knc
    if dashpot:
        cn = 2.0 * prm[ma, mb, Q_ZETA] * math.sqrt(mstar * knc)
        fn = fel - cn * vn
        if fn < 0.0:
            fn = 0.0
        e_damp = (fel - fn) * vn * dt  # >= 0: cn vn^2 dt, or fel vn dt when clamped (vn > 0)
        if dt > 0.0:
            kserv += cn / dt
    fx = fn * nx
    fy = fn * ny
    fz = fn * nz
    e_fric = 0.0
    kt = 0.25 * knc                    # k_s sqrt(A_c), k_s = 0.25 k_n (eq. 19 made dimensionally sound)
    if friction:
        vtx = vx - vn * nx
        vty = vy - vn * ny
        vtz = vz - vn * nz
        hx, hy, hz = _to_tangent_plane(ft[k, 0], ft[k, 1], ft[k, 2], nx, ny, nz)
        hx -= kt * vtx * dt
        hy -= kt * vty * dt
        hz -= kt * vtz * dt
        lim = prm[ma, mb, Q_MU] * fn
        hm2 = hx * hx + hy * hy + hz * hz
        if hm2 > lim * lim:
            hm = math.sqrt(hm2)
            s = lim / hm
            e_fric = (hm - lim) * lim / kt if kt > 0.0 else 0.0
            hx *= s
            hy *= s
            hz *= s
        ft[k, 0] = hx
        ft[k, 1] = hy
        ft[k, 2] = hz
        fx += hx
        fy += hy
        fz += hz
    return fx, fy, fz, e_damp, e_fric, fel, kserv, kt


@njit(parallel=True, internal=True)
def _world_geometry(x, q, shape, vertex_start, vertices, face_start, face_normal, face_offset,
                    bvstart, bfstart, wvert, wnorm, woff, travel):
    """World vertices and face planes of every body (rows bvstart / bfstart); each body's travel
    grows by its largest vertex displacement since the last call (the vertices as
    :func:`to_world_vertices` places them, the same arithmetic)."""
    for b in prange(x.shape[0]):
        k = shape[b]
        v0 = vertex_start[k]
        r0 = bvstart[b]
        q0 = q[b, 0]
        q1 = q[b, 1]
        q2 = q[b, 2]
        q3 = q[b, 3]
        step2 = 0.0
        for i in range(vertex_start[k + 1] - v0):
            wx, wy, wz = rotate(q0, q1, q2, q3, vertices[v0 + i, 0], vertices[v0 + i, 1], vertices[v0 + i, 2])
            wx += x[b, 0]
            wy += x[b, 1]
            wz += x[b, 2]
            dx = wx - wvert[r0 + i, 0]
            dy = wy - wvert[r0 + i, 1]
            dz = wz - wvert[r0 + i, 2]
            step2 = max(step2, dx * dx + dy * dy + dz * dz)
            wvert[r0 + i, 0] = wx
            wvert[r0 + i, 1] = wy
            wvert[r0 + i, 2] = wz
        travel[b] += math.sqrt(step2)
        f0 = face_start[k]
        f1 = face_start[k + 1]
        to_world_planes(face_normal[f0:f1], face_offset[f0:f1], x[b], q[b],
                        wnorm[bfstart[b]:bfstart[b + 1]], woff[bfstart[b]:bfstart[b + 1]])


@njit(inline="always")
def _clearance(n, d, verts):
    """min over ``verts`` of n_f . v - d_f for every face f of (n, d): the largest is the
    widest gap a face plane of one body leaves to the other body; returns (gap, face)."""
    best = -math.inf
    bf = -1
    for f in range(n.shape[0]):
        g = math.inf
        for k in range(verts.shape[0]):
            t = n[f, 0] * verts[k, 0] + n[f, 1] * verts[k, 1] + n[f, 2] * verts[k, 2] - d[f]
            if t < g:
                g = t
                if g <= best:
                    break
        if g > best:
            best = g
            bf = f
    return best, bf


@njit(inline="always")
def _face_gap(code, na, da, va, nb_, db_, vb, margin):
    """The gap the cached face ``code`` (see ``sep`` in the constants above) leaves to the other
    body [m]: min over its vertices of n . v - d, or the first value <= ``margin`` met."""
    if code > 0:
        f = code - 1
        n = na
        d = da
        verts = vb
    else:
        f = -code - 1
        n = nb_
        d = db_
        verts = va
    g = math.inf
    for k in range(verts.shape[0]):
        t = n[f, 0] * verts[k, 0] + n[f, 1] * verts[k, 1] + n[f, 2] * verts[k, 2] - d[f]
        if t <= margin:
            return t
        g = min(g, t)
    return g


@njit(inline="always")
def _turn(q, b, pbox, c, k):
    """Rotation vector [rad] of body b since its orientation kept in pbox[c, k:k + 4]: 2 vec(q q_0*),
    the sign of q q_0* taken with w >= 0 (first order in the angle, as the expansion it enters)."""
    w, x, y, z = mul(q[b, 0], q[b, 1], q[b, 2], q[b, 3], pbox[c, k], -pbox[c, k + 1], -pbox[c, k + 2], -pbox[c, k + 3])
    s = 2.0 if w >= 0.0 else -2.0
    return s * x, s * y, s * z


@njit(inline="always")
def _linear_volume(pbox, c, x, q, i, j):
    """Overlap volume of pair c linearized about its last exact evaluation (contact.geometry_refresh).

    V is expanded to first order in the rigid motions of both bodies since that evaluation
    (translations dx_i, dx_j [m], rotation vectors phi_i, phi_j [rad] about their centroids then):

        V = V_0 - S . dx_i + S . dx_j + phi_i . T_i + phi_j . T_j,

    S = -dV/dx_i [m^2] (:mod:`demcli.kernels.polyhedra`) and T_b = int (p - x_b) x n_b dA [m^3] over
    body b's part of the intersection's boundary (n_b its outward normal), the rotational
    derivative: turning b by phi moves that boundary by phi x (p - x_b), along n_b by phi . ((p - x_b)
    x n_b). Returns (V, contact point), the point the centroid g_0 moved to with the bodies (the mean of
    g_0 carried by each). Between two exact evaluations the force U'(V) S is the gradient of U(V(x)) in
    translation, so the law stays conservative; what is left out is the change of S, T and g over
    the k steps (second order in the motion).
    """
    pix, piy, piz = _turn(q, i, pbox, c, L_QI)
    pjx, pjy, pjz = _turn(q, j, pbox, c, L_QJ)
    dix = x[i, 0] - pbox[c, L_XI]
    diy = x[i, 1] - pbox[c, L_XI + 1]
    diz = x[i, 2] - pbox[c, L_XI + 2]
    djx = x[j, 0] - pbox[c, L_XJ]
    djy = x[j, 1] - pbox[c, L_XJ + 1]
    djz = x[j, 2] - pbox[c, L_XJ + 2]
    vol = (pbox[c, L_V] - pbox[c, L_S] * (dix - djx) - pbox[c, L_S + 1] * (diy - djy) - pbox[c, L_S + 2] * (diz - djz)
           + pix * pbox[c, L_TI] + piy * pbox[c, L_TI + 1] + piz * pbox[c, L_TI + 2]
           + pjx * pbox[c, L_TJ] + pjy * pbox[c, L_TJ + 1] + pjz * pbox[c, L_TJ + 2])
    # g_0 carried by i: g_0 + dx_i + phi_i x (g_0 - x_i0); by j likewise; their mean
    rix = pbox[c, L_G] - pbox[c, L_XI]
    riy = pbox[c, L_G + 1] - pbox[c, L_XI + 1]
    riz = pbox[c, L_G + 2] - pbox[c, L_XI + 2]
    rjx = pbox[c, L_G] - pbox[c, L_XJ]
    rjy = pbox[c, L_G + 1] - pbox[c, L_XJ + 1]
    rjz = pbox[c, L_G + 2] - pbox[c, L_XJ + 2]
    gx = pbox[c, L_G] + 0.5 * (dix + djx + (piy * riz - piz * riy) + (pjy * rjz - pjz * rjy))
    gy = pbox[c, L_G + 1] + 0.5 * (diy + djy + (piz * rix - pix * riz) + (pjz * rjx - pjx * rjz))
    gz = pbox[c, L_G + 2] + 0.5 * (diz + djz + (pix * riy - piy * rix) + (pjx * rjy - pjy * rjx))
    return vol, gx, gy, gz


@njit(inline="always")
def _store_linear(pbox, c, x, q, i, j, vol, gx, gy, gz, sx, sy, sz, fw, refresh):
    """Keep pair c's exact evaluation for the next refresh - 1 steps: V, S, g, both bodies' positions and
    orientations, and their moments T_b about their centroids from fw (fw[6:9] and fw[9:12]: about the
    clipping's cone origin o = fw[18:21], :func:`demcli.kernels.polyhedra._faces_inside`), T_b = T_b(o) -
    (x_b - o) x S_b with S_i = -S, S_j = S (the two bodies' area vectors, equal and opposite)."""
    pbox[c, L_V] = vol
    pbox[c, L_S] = sx
    pbox[c, L_S + 1] = sy
    pbox[c, L_S + 2] = sz
    pbox[c, L_G] = gx
    pbox[c, L_G + 1] = gy
    pbox[c, L_G + 2] = gz
    _store_body(pbox, c, x, q, i, L_XI, L_QI, L_TI, fw, 6, -sx, -sy, -sz)
    _store_body(pbox, c, x, q, j, L_XJ, L_QJ, L_TJ, fw, 9, sx, sy, sz)
    pbox[c, L_LEFT] = refresh - 1


@njit(inline="always")
def _store_body(pbox, c, x, q, b, kx, kq, kt, fw, t0, sx, sy, sz):
    """Body b's position, orientation and moment T_b = T_b(o) - (x_b - o) x S_b (S_b = (sx, sy, sz))."""
    rx = x[b, 0] - fw[18]
    ry = x[b, 1] - fw[19]
    rz = x[b, 2] - fw[20]
    pbox[c, kt] = fw[t0] - (ry * sz - rz * sy)
    pbox[c, kt + 1] = fw[t0 + 1] - (rz * sx - rx * sz)
    pbox[c, kt + 2] = fw[t0 + 2] - (rx * sy - ry * sx)
    for k in range(3):
        pbox[c, kx + k] = x[b, k]
    for k in range(4):
        pbox[c, kq + k] = q[b, k]


@njit(parallel=True, internal=True)
def _pair_forces(start, pj, x, v, w, q, mass, rad, bmat, prm, sw, dt,
                 shape, vertex_start, face_start, fvstart, fverts, bvstart, bfstart, wvert, wnorm, woff,
                 ft, fc, tj, act, epair, geo, frow, trow, erow, sep, sdir, sclear, pbox, travel, r0, refresh):
    """Force of every listed pair into its own row; the row owner i sums its side; rows from
    ``r0`` (0; a mixed scene: its polyhedra, :mod:`demcli.kernels.shapes.mixed`).

    fc[c]: force on i [N]; tj[c]: torque on j [N m]; geo[c]: (depth, F_N, K_t);
    epair[c]: (dashpot, slip) losses this step [J]; frow/trow/erow[i]: i's sums.
    sep[c], sdir[c]: the cached separating face or direction (SEP_* codes above): a pair still cleared by
    it skips the exact overlap, which would find V = 0 (the results do not depend on the
    cache). A direction that no longer clears is searched again from where it was.
    sclear[c] [m]: the gap the cache left when last checked plus both bodies' travel then
    (``travel``, :class:`PolyGeometry`); while sclear[c] - travel[i] - travel[j] > margin the
    bodies have not moved enough to close it (the fixed plane of that check still parts them:
    each body's points moved less than its travel since) and the check itself is skipped.
    pbox[c] (6): the bounding box of pair c's intersection at its last evaluation (zeros: none, the
    pair did not touch); a touching pair is evaluated in that box widened by BOX_PAD min(r_i, r_j)
    (:func:`overlap_in_box`, exact when I stays inside it; else the full :func:`overlap_ws`).
    refresh (contact.geometry_refresh > 1, pbox of LINEAR_COLS columns; None: the exact law, and numba
    compiles the pass without the linearized path): a touching pair is evaluated exactly every
    refresh-th step and linearized in between (:func:`_linear_volume`; q: the bodies' orientations), or
    at once when its linearized V is not positive.
    """
    friction = sw[F_FRICTION]
    energy = sw[F_ENERGY]
    dashpot = sw[F_DASHPOT]
    # scratch of overlap_ws for any pair of these shapes: largest face, most faces
    max_fv = max_row(fvstart)
    max_f = max_row(face_start)
    nrow = start.shape[0] - 1
    for ch in prange((nrow - r0 + ROW_CHUNK - 1) // ROW_CHUNK):
        # scratch of overlap_ws once per chunk of rows: an allocation per row cost 12-19 % of the loaded bed's
        # step (bench/README.md, "Temporal coherence on the loaded bed")
        buf, fw, planes = scratch(max_fv, max_f)
        box = np.empty(6)
        for i in range(r0 + ch * ROW_CHUNK, min(r0 + (ch + 1) * ROW_CHUNK, nrow)):
            sfx = 0.0
            sfy = 0.0
            sfz = 0.0
            stx = 0.0
            sty = 0.0
            stz = 0.0
            se0 = 0.0
            se1 = 0.0
            c0 = start[i]
            c1 = start[i + 1]
            if c1 > c0:
                xi0 = x[i, 0]
                xi1 = x[i, 1]
                xi2 = x[i, 2]
                ri = rad[i]
                ki = shape[i]
                va = wvert[bvstart[i]:bvstart[i + 1]]
                na = wnorm[bfstart[i]:bfstart[i + 1]]
                da = woff[bfstart[i]:bfstart[i + 1]]
                fsa = fvstart[face_start[ki]:face_start[ki + 1] + 1]
                offa = vertex_start[ki]
                mi = mass[i]
                for c in range(c0, c1):
                    j = pj[c]
                    xj0 = x[j, 0]
                    xj1 = x[j, 1]
                    xj2 = x[j, 2]
                    dx = xi0 - xj0
                    dy = xi1 - xj1
                    dz = xi2 - xj2
                    rj = rad[j]
                    rs = ri + rj
                    vol = 0.0
                    gx = gy = gz = sx = sy = sz = 0.0
                    exact = True  # False: linearized about the kept evaluation (refresh > 1)
                    if dx * dx + dy * dy + dz * dz < rs * rs:
                        kj = shape[j]
                        vb = wvert[bvstart[j]:bvstart[j + 1]]
                        nb_ = wnorm[bfstart[j]:bfstart[j + 1]]
                        db_ = woff[bfstart[j]:bfstart[j + 1]]
                        fsb = fvstart[face_start[kj]:face_start[kj + 1] + 1]
                        if refresh is not None:  # compiled only for contact.geometry_refresh > 1
                            if pbox[c, 3] > pbox[c, 0] and pbox[c, L_LEFT] > 0.0:
                                vol, gx, gy, gz = _linear_volume(pbox, c, x, q, i, j)
                                if vol > 0.0:
                                    exact = False
                                    sx = pbox[c, L_S]
                                    sy = pbox[c, L_S + 1]
                                    sz = pbox[c, L_S + 2]
                                    pbox[c, L_LEFT] -= 1.0
                        if exact and pbox[c, 3] > pbox[c, 0]:  # touching at the last evaluation: coherent culling
                            pad = BOX_PAD * min(ri, rj)
                            for k in range(3):
                                box[k] = pbox[c, k] - pad
                                box[3 + k] = pbox[c, 3 + k] + pad
                            ok, vol, gx, gy, gz, sx, sy, sz = overlap_in_box(
                                va, fsa, fverts, offa, na, da, xi0, xi1, xi2, ri,
                                vb, fsb, fverts, vertex_start[kj], nb_, db_, xj0, xj1, xj2, rj, box, buf, fw, planes)
                            if not ok:
                                vol, gx, gy, gz, sx, sy, sz = overlap_ws(
                                    va, fsa, fverts, offa, na, da, xi0, xi1, xi2, ri,
                                    vb, fsb, fverts, vertex_start[kj], nb_, db_, xj0, xj1, xj2, rj, buf, fw, planes)
                        elif exact:
                            code = sep[c]
                            margin = SEP_MARGIN * rs + 1e-12 * max(abs(xi0), abs(xi1), abs(xi2), abs(xj0), abs(xj1),
                                                                  abs(xj2))
                            moved = travel[i] + travel[j]
                            if sclear[c] - moved > margin:  # not moved enough since the cache last cleared them
                                apart = True
                            elif code == SEP_DIR:
                                g_ = gap(sdir[c, 0], sdir[c, 1], sdir[c, 2], va, vb)
                                if not g_ > margin:
                                    found, ux, uy, uz = separating_direction(va, vb, sdir[c, 0], sdir[c, 1], sdir[c, 2],
                                                                             margin, SEP_ITER, buf)
                                    g_ = -math.inf
                                    if found:
                                        sdir[c, 0] = ux
                                        sdir[c, 1] = uy
                                        sdir[c, 2] = uz
                                        g_ = gap(ux, uy, uz, va, vb)
                                apart = g_ > margin
                                if apart:
                                    sclear[c] = g_ + moved
                            else:
                                apart = code != 0 and code != SEP_NONE
                                if apart:
                                    g_ = _face_gap(code, na, da, va, nb_, db_, vb, margin)
                                    apart = g_ > margin
                                    if apart:
                                        sclear[c] = g_ + moved
                            if apart:
                                vol = 0.0
                            else:
                                vol, gx, gy, gz, sx, sy, sz = overlap_ws(
                                    va, fsa, fverts, offa, na, da, xi0, xi1, xi2, ri,
                                    vb, fsb, fverts, vertex_start[kj], nb_, db_, xj0, xj1, xj2, rj, buf, fw, planes)
                                if not vol > 0.0 and code != SEP_NONE:
                                    ga, fa = _clearance(na, da, vb)
                                    gb, fb = _clearance(nb_, db_, va)
                                    if ga > margin and ga >= gb:
                                        sep[c] = fa + 1
                                        sclear[c] = ga + moved
                                    elif gb > margin:
                                        sep[c] = -(fb + 1)
                                        sclear[c] = gb + moved
                                    else:
                                        found, ux, uy, uz = separating_direction(va, vb, -dx, -dy, -dz, margin, SEP_ITER,
                                                                                 buf)
                                        if found:
                                            sep[c] = SEP_DIR
                                            sdir[c, 0] = ux
                                            sdir[c, 1] = uy
                                            sdir[c, 2] = uz
                                            sclear[c] = gap(ux, uy, uz, va, vb) + moved
                                        else:
                                            sep[c] = SEP_NONE
                                elif vol > 0.0:
                                    sep[c] = 0
                    if not exact:  # linearized: the box and the kept evaluation stay
                        pass
                    elif vol > 0.0:  # the pieces' box of this evaluation (fw[22:28]): the next step's culling box
                        for k in range(6):
                            pbox[c, k] = fw[22 + k]
                        if refresh is not None:
                            _store_linear(pbox, c, x, q, i, j, vol, gx, gy, gz, sx, sy, sz, fw, refresh)
                    elif pbox[c, 3] != 0.0 or pbox[c, 0] != 0.0:
                        for k in range(6):
                            pbox[c, k] = 0.0
                    if not vol > 0.0:
                        if act[c]:
                            act[c] = 0
                            geo[c, 0] = 0.0
                            geo[c, 1] = 0.0
                            geo[c, 2] = 0.0
                            fc[c, 0] = 0.0
                            fc[c, 1] = 0.0
                            fc[c, 2] = 0.0
                        if friction:  # the contact opened (or a carried one never closed): history dropped
                            ft[c, 0] = 0.0
                            ft[c, 1] = 0.0
                            ft[c, 2] = 0.0
                        continue
                    act[c] = 1
                    nx, ny, nz, area, depth = contact_frame(vol, sx, sy, sz, xi0, xi1, xi2, xj0, xj1, xj2, ri, rj)
                    # branches from the centroids to the contact point, and its relative velocity
                    aix = gx - xi0
                    aiy = gy - xi1
                    aiz = gz - xi2
                    ajx = gx - xj0
                    ajy = gy - xj1
                    ajz = gz - xj2
                    vx = (v[i, 0] + w[i, 1] * aiz - w[i, 2] * aiy) - (v[j, 0] + w[j, 1] * ajz - w[j, 2] * ajy)
                    vy = (v[i, 1] + w[i, 2] * aix - w[i, 0] * aiz) - (v[j, 1] + w[j, 2] * ajx - w[j, 0] * ajz)
                    vz = (v[i, 2] + w[i, 0] * aiy - w[i, 1] * aix) - (v[j, 2] + w[j, 0] * ajy - w[j, 1] * ajx)
                    mj = mass[j]
                    fx, fy, fz, ed, ef, fel, _, kt = _volumetric_law(
                        prm, bmat[i], bmat[j], vol, depth, area, nx, ny, nz, vx, vy, vz, mi * mj / (mi + mj), dt,
                        ft, c, friction, dashpot)
                    fc[c, 0] = fx
                    fc[c, 1] = fy
                    fc[c, 2] = fz
                    geo[c, 0] = depth
                    geo[c, 1] = fel
                    geo[c, 2] = kt
                    sfx += fx
                    sfy += fy
                    sfz += fz
                    stx += aiy * fz - aiz * fy
                    sty += aiz * fx - aix * fz
                    stz += aix * fy - aiy * fx
                    tj[c, 0] = -(ajy * fz - ajz * fy)
                    tj[c, 1] = -(ajz * fx - ajx * fz)
                    tj[c, 2] = -(ajx * fy - ajy * fx)
                    if energy:
                        epair[c, 0] = ed
                        epair[c, 1] = ef
                        se0 += ed
                        se1 += ef
            frow[i, 0] = sfx
            frow[i, 1] = sfy
            frow[i, 2] = sfz
            trow[i, 0] = stx
            trow[i, 1] = sty
            trow[i, 2] = stz
            if energy:
                erow[i, 0] = se0
                erow[i, 1] = se1


@njit
def place(g, bd, flags, xref, lim2, rebuild):
    """World vertices and face planes of every body."""
    _world_geometry(bd.x, bd.q, g.shape, g.vertex_start, g.vertices, g.face_start, g.face_normal, g.face_offset,
                    g.bvstart, g.bfstart, g.wvert, g.wnorm, g.woff, g.travel)


@njit(inline="always")
def volumetric(g):
    """Contacts keep a depth (geo) and a separation cache (sep, sdir); normal forces turn bodies."""
    return True


@njit
def spin_rotors(g, mb, xref):
    """Polyhedra are rigid rotors: None."""
    return None


@njit
def primitives(g, bd):
    """Bounding spheres centred on the centroids (rotation does not move them)."""
    return bd.x, g.rad, np.arange(bd.x.shape[0])


@njit
def pair_pass(g, bd, nl, prm, law, flags, dt, frow, trow, erow, bonds, bprm, broke):
    """Every listed pair's force into its own row (bonds do not join polyhedra)."""
    _pair_forces(nl.start, nl.pj, bd.x, bd.v, bd.w, bd.q, bd.mass, g.rad, g.mat, prm, flags, dt,
                 g.shape, g.vertex_start, g.face_start, g.fvstart, g.fverts, g.bvstart, g.bfstart, g.wvert, g.wnorm,
                 g.woff, nl.ft, nl.fc, nl.tj, nl.act, nl.epair, nl.geo, frow, trow, erow, nl.sep, nl.sdir, nl.sclear,
                 nl.pbox, g.travel, 0, g.refresh)


@njit
def wall_pass(g, bd, nl, wa, prm, law, flags, dt):
    """Every body-plane contact into its own rows: the overlap with the solid half-space, the
    volumetric law; wfc[k] (force, servo stiffness), wtq[k] (torque about the centroid), wen[k]
    (dashpot and slip losses, with energy), wgeo[k] (depth, F_N, K_t)."""
    _wall_forces(nl.wstart, nl.wwall, bd.x, bd.v, bd.w, bd.mass, g.rad, g.mat, g.shape, g.vertex_start,
                 g.face_start, g.fvstart, g.fverts, g.bvstart, g.bfstart, g.wvert, g.wnorm, g.woff, wa.kind, wa.point,
                 wa.normal, wa.v, wa.material, prm, dt, flags[F_FRICTION], flags[F_DASHPOT], flags[F_ENERGY], nl.wft,
                 nl.wfc, nl.wtq, nl.wen, nl.wgeo, 0, wa.mesh)


@njit(parallel=True, internal=True)
def _wall_forces(wstart, wwall, x, v, w, mass, rad, bmat, shape, vertex_start, face_start, fvstart, fverts, bvstart,
                 bfstart, wvert, wnorm, woff, wkind, wpoint, wnormal, wv, wmat, prm, dt, friction, dashpot, energy,
                 wft, wfc, wtq, wen, wgeo, r0, mesh):
    """Per body (prange), its wall contacts (rows wstart[b]..wstart[b + 1], race-free): planes, and
    with ``mesh`` (the MeshArrays; None without mesh walls: that path is not compiled) mesh walls
    (:func:`_mesh_forces`); bodies from ``r0`` (0; a mixed scene: its polyhedra)."""
    nrow = wstart.shape[0] - 1
    max_fv = max_row(fvstart)
    max_v = max_row(bvstart)
    max_f = max_row(face_start)
    for ch in prange((nrow - r0 + ROW_CHUNK - 1) // ROW_CHUNK):
        buf, heights, sd, work = plane_scratch(max_fv, max_v)  # once per chunk of bodies
        ms = scratch_for(mesh, max_fv, max_f)  # None without mesh walls
        for b in range(r0 + ch * ROW_CHUNK, min(r0 + (ch + 1) * ROW_CHUNK, nrow)):
            k0 = wstart[b]
            k1 = wstart[b + 1]
            if k1 == k0:
                continue
            kb = shape[b]
            rb = rad[b]
            va = wvert[bvstart[b]:bvstart[b + 1]]
            na = wnorm[bfstart[b]:bfstart[b + 1]]
            da = woff[bfstart[b]:bfstart[b + 1]]
            fsa = fvstart[face_start[kb]:face_start[kb + 1] + 1]
            offa = vertex_start[kb]
            xb0 = x[b, 0]
            xb1 = x[b, 1]
            xb2 = x[b, 2]
            m = mass[b]
            for k in range(k0, k1):
                wl = wwall[k]
                if mesh is not None:  # compiled for scenes with mesh walls only
                    if wkind[wl] == MESH:
                        _mesh_forces(k, wl, b, x, v, w, m, rb, bmat[b], va, fsa, fverts, offa, na, da, mesh, wpoint,
                                     wv, wmat, prm, dt, friction, dashpot, energy, wft, wfc, wtq, wen, wgeo, ms)
                        continue
                wnx = wnormal[wl, 0]
                wny = wnormal[wl, 1]
                wnz = wnormal[wl, 2]
                vol = 0.0
                gx = gy = gz = sx = sy = sz = 0.0
                if wkind[wl] == 0:  # plane; the registry refuses cylinders for polyhedra
                    wd = wnx * wpoint[wl, 0] + wny * wpoint[wl, 1] + wnz * wpoint[wl, 2]
                    vol, gx, gy, gz, sx, sy, sz = plane_overlap_ws(va, fsa, fverts, offa, na, da, xb0, xb1, xb2, rb,
                                                                   wnx, wny, wnz, wd, buf, heights, sd, work)
                if not vol > 0.0:
                    for col in range(4):
                        wfc[k, col] = 0.0
                    for col in range(3):
                        wtq[k, col] = 0.0
                        wgeo[k, col] = 0.0
                    if energy:
                        wen[k, 0] = 0.0
                        wen[k, 1] = 0.0
                    if friction:
                        wft[k, 0] = 0.0
                        wft[k, 1] = 0.0
                        wft[k, 2] = 0.0
                    continue
                # B = the wall: its "centre" one unit behind the body along the wall normal, so the
                # normal falls back to n_w if the cross-section vanishes (body wholly in the wall)
                nx, ny, nz, area, depth = contact_frame(vol, sx, sy, sz, xb0, xb1, xb2, xb0 - wnx, xb1 - wny,
                                                        xb2 - wnz, rb, rb)
                ax = gx - xb0
                ay = gy - xb1
                az = gz - xb2
                vx = v[b, 0] + w[b, 1] * az - w[b, 2] * ay - wv[wl, 0]
                vy = v[b, 1] + w[b, 2] * ax - w[b, 0] * az - wv[wl, 1]
                vz = v[b, 2] + w[b, 0] * ay - w[b, 1] * ax - wv[wl, 2]
                cfx, cfy, cfz, ed, ef, fel, kserv, kt = _volumetric_law(
                    prm, bmat[b], wmat[wl], vol, depth, area, nx, ny, nz, vx, vy, vz, m, dt, wft, k, friction, dashpot)
                wfc[k, 0] = cfx
                wfc[k, 1] = cfy
                wfc[k, 2] = cfz
                wfc[k, 3] = kserv
                wtq[k, 0] = ay * cfz - az * cfy
                wtq[k, 1] = az * cfx - ax * cfz
                wtq[k, 2] = ax * cfy - ay * cfx
                wgeo[k, 0] = depth
                wgeo[k, 1] = fel
                wgeo[k, 2] = kt
                if energy:
                    wen[k, 0] = ed
                    wen[k, 1] = ef

@njit(internal=True)
def _mesh_forces(k, wl, b, x, v, w, m, rb, mb, va, fsa, fverts, offa, na, da, mesh, wpoint, wv, wmat, prm, dt,
                 friction, dashpot, energy, wft, wfc, wtq, wen, wgeo, ms):
    """Row k: the loads of mesh wall wl on body b (bounding radius rb [m], mass m [kg], material mb).

    The body's overlap with the prism under each triangle near it
    (:func:`demcli.kernels.poly_mesh.mesh_pieces`), summed per plane (coplanar triangles:
    :func:`demcli.kernels.poly_mesh.plane_sums`): V, centroid g and S of each plane give one contact
    of the volumetric law, as a plane wall would (a flat mesh: the plane wall's contact to round-off).
    The loads of the planes are summed into row k: wfc (force, servo stiffness), wtq (torque about
    the centroid), wgeo (deepest depth d = V / A_c, summed F_N, K_t of the row's spring), wen. The
    row's tangential spring wft[k] is carried by the plane of the largest V; the others start theirs
    afresh each step (the sphere-mesh rule, docs/walls.md)."""
    res = ms[5]
    lead = ms[3]
    fresh = ms[2]  # the closest points of the triangles (free once the pieces are found): a spring from zero
    n = mesh_pieces(va, fsa, fverts, offa, na, da, x[b, 0], x[b, 1], x[b, 2], rb, mesh, wl, wpoint[wl, 0],
                    wpoint[wl, 1], wpoint[wl, 2], ms)
    plane_sums(res, n, lead, rb)
    carrier = -1
    for c in range(n):
        if lead[c] == c and (carrier < 0 or res[c, R_V] > res[carrier, R_V]):
            carrier = c
    wfc[k, :4] = 0.0  # the sums below start from zero (and stay so when nothing touches)
    wtq[k, :] = 0.0
    wgeo[k, :] = 0.0
    if energy:
        wen[k, :] = 0.0
    if carrier < 0 and friction:
        wft[k, :] = 0.0  # the contact opened: its spring dropped
    for c in range(n):
        if lead[c] != c:
            continue
        vol = res[c, R_V]
        wnx, wny, wnz = res[c, R_NX], res[c, R_NX + 1], res[c, R_NX + 2]
        nx, ny, nz, area, depth = contact_frame(vol, res[c, R_SX], res[c, R_SX + 1], res[c, R_SX + 2], x[b, 0],
                                                x[b, 1], x[b, 2], x[b, 0] - wnx, x[b, 1] - wny, x[b, 2] - wnz, rb, rb)
        ax = res[c, R_GX] - x[b, 0]
        ay = res[c, R_GX + 1] - x[b, 1]
        az = res[c, R_GX + 2] - x[b, 2]
        vx = v[b, 0] + w[b, 1] * az - w[b, 2] * ay - wv[wl, 0]
        vy = v[b, 1] + w[b, 2] * ax - w[b, 0] * az - wv[wl, 1]
        vz = v[b, 2] + w[b, 0] * ay - w[b, 1] * ax - wv[wl, 2]
        if c == carrier:
            spring, row = wft, k
        else:
            fresh[0, 0] = fresh[0, 1] = fresh[0, 2] = 0.0
            spring, row = fresh, 0
        cfx, cfy, cfz, ed, ef, fel, kserv, kt = _volumetric_law(
            prm, mb, wmat[wl], vol, depth, area, nx, ny, nz, vx, vy, vz, m, dt, spring, row, friction, dashpot)
        wfc[k, 0] += cfx
        wfc[k, 1] += cfy
        wfc[k, 2] += cfz
        wfc[k, 3] += kserv
        wtq[k, 0] += ay * cfz - az * cfy
        wtq[k, 1] += az * cfx - ax * cfz
        wtq[k, 2] += ax * cfy - ay * cfx
        wgeo[k, 0] = max(wgeo[k, 0], depth)
        wgeo[k, 1] += fel
        if c == carrier:
            wgeo[k, 2] = kt
        if energy:
            wen[k, 0] += ed
            wen[k, 1] += ef


@njit
def worst_overlap(g, nl, wa):
    """Largest depth / bounding radius over touching pairs and wall contacts; returns
    (ratio, i, j) with j = -1 for a wall (i = -1 when nothing touches)."""
    rad = g.rad
    pi = nl.pi
    pj = nl.pj
    act = nl.act
    geo = nl.geo
    worst = 0.0
    wi = -1
    wj = -1
    for c in range(pi.shape[0]):
        if act[c]:
            ratio = geo[c, G_DEPTH] / min(rad[pi[c]], rad[pj[c]])
            if ratio > worst:
                worst = ratio
                wi = pi[c]
                wj = pj[c]
    for b in range(rad.shape[0]):
        for k in range(nl.wstart[b], nl.wstart[b + 1]):
            ratio = nl.wgeo[k, G_DEPTH] / rad[b]
            if ratio > worst:
                worst = ratio
                wi = b
                wj = -1
    return worst, wi, wj


@njit
def strain_energy_estimate(act, geo, ft, wgeo, wft, friction):
    """Elastic energy of the contacts [J], estimated (serial, fixed order).

    The volumetric law F_N = k_n sqrt(V d) has no potential in general (a potential
    U(V) would give a force U'(V) S, i.e. |F| proportional to the contact area
    A_c at fixed V; here F_N = k_n V / sqrt(A_c)). For a flat face-face overlap of
    constant area it is a linear spring of stiffness k_n sqrt(A_c), energy F_N d / 2;
    that value is used for every contact, plus |F_s|^2 / (2 K_t) for the tangential
    springs. Exact for face-face contacts, an estimate otherwise.
    """
    e = 0.0
    for c in range(act.shape[0]):
        if act[c]:
            e += 0.5 * geo[c, G_FN] * geo[c, G_DEPTH]
            if friction and geo[c, G_KT] > 0.0:
                e += 0.5 * (ft[c, 0] ** 2 + ft[c, 1] ** 2 + ft[c, 2] ** 2) / geo[c, G_KT]
    for k in range(wgeo.shape[0]):
        if wgeo[k, G_DEPTH] > 0.0:
            e += 0.5 * wgeo[k, G_FN] * wgeo[k, G_DEPTH]
            if friction and wgeo[k, G_KT] > 0.0:
                e += 0.5 * (wft[k, 0] ** 2 + wft[k, 1] ** 2 + wft[k, 2] ** 2) / wgeo[k, G_KT]
    return e
