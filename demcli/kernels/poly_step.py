"""The compiled time loop for rigid convex polyhedra (seed 002, Shao, Lian & Yang 2017, sec. 3).

Velocity Verlet (kick-drift-kick) like :func:`demcli.kernels.step.run_steps`; one call
advances a chunk of steps without returning to Python. Each step:

1. first half kick of v and of the world angular momentum L, rotation of q through
   L (``_rotate_rigid``: implicit midpoint, |L| kept exactly), drift of the centroid,
   and the displacement check of the centroids against the Verlet reference (the
   bounding spheres are centred on the centroid, so rotation does not invalidate the
   list);
2. walls move (prescribed velocity, servo or force control from the last step);
3. rebuild of the pair list on bounding spheres (``build_pairs``) and of the wall
   list when needed, tangential history carried over (``carry_history``);
4. world vertices and face planes of every body (prange);
5. the pair pass: prange over CSR rows i, the exact overlap (``overlap``) of each
   listed pair whose bounding spheres meet, unless a cached separating face or direction
   (``sep``, ``sdir``) still clears it by a margin, one force per pair into its own row;
   the row owner sums i's side (race-free, as ``_pair_forces`` in step.py);
6. the gather per body: own row sums, the j sides through the reverse list, the
   plane-wall contacts (``plane_overlap`` against the solid half-space
   n_in . x <= n_in . p), body loads (gravity, local damping, viscous damping), and
   the second half kick (L += h T, omega from L);
7. adaptive damping (when on): the step's absorbed energy and kinetic energy change
   update alpha (seed eqs. 23-27);
8. wall force sums and control; every ``check_every`` steps: NaN/Inf, overlap and
   kinetic-energy guards.

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

Actors (LOADED bodies: the loading plate, the sleeper) take their prescribed force
F0 + F1 sin(omega (t - t0) + phase) (table ``bload``) and are not body-damped: a
damping force on a loading device would change the load it applies (Cundall's local
damping acts like a friction of lambda |F| on an oscillating body and makes a plate lag
a cyclic load by a tenth of its range). Held velocity components (FIX_X << d) are
left as they are by the kicks.

Body damping: local (Cundall) and constant viscous damping through ``_body_loads``
semantics, plus the seed's adaptive mass-proportional damping: c1 = alpha m,
c2 = alpha I (T_d = -alpha L). It enters each half kick in the seed's central
difference form (eqs. 23-24): v <- [v (1 - alpha h/2) + F h/m] / (1 + alpha h/2),
L likewise, which is stable for any alpha. After each step R = E_a / |Delta E_k|
(E_a the energy the alpha-damping absorbed this step, Delta E_k the change of kinetic
energy); R < 0.5: alpha *= 1.1, R > 0.5: alpha *= 0.99 (eq. 27), kept inside
[alpha_min, alpha_max] (see ``ADAPT_*``).

The kernels import only numpy, numba and other kernels (no I/O).
"""

import math

import numpy as np
from numba import prange

from demcli.jit import njit
from demcli.kernels.contact import _to_tangent_plane
from demcli.kernels.layout import (BAD_ENERGY, BAD_NUMBER, BAD_OVERLAP, C_BODY, C_CHECK, C_DAMPING,
                                   C_ENERGY, C_FRICTION, C_GATHER, C_GRAVITY, C_KICK, C_PAIRS, C_REBUILD,
                                   C_WALLCTRL, C_WALLMOVE, FIX_ROTATION, FIX_TRANSLATION, FIX_X, LOADED, OK)
from demcli.kernels.neighbors import build_pairs, build_reverse, build_wall_pairs, carry_history
from demcli.kernels.polyhedra import (contact_frame, max_row, overlap_ws, plane_overlap, scratch,
                                      to_world_planes, to_world_vertices)
from demcli.kernels.separation import gap, separating_direction
from demcli.kernels.step import _body_loads, _drift, _omega_from_L, _rotate_rigid, _wall_control, move_walls

# columns of the material-pair table prm[a, b, :]
Q_KN = 0      # k_n = 4 E / (3 sqrt(pi)) [Pa]
Q_MU = 1      # Coulomb friction coefficient [-]
Q_ZETA = 2    # damping ratio of the optional normal dashpot [-]
N_QPARAMS = 3

# kernel switches: positions in the ``sw`` tuple (all bool)
S_FRICTION, S_ENERGY, S_GRAVITY, S_LOCAL, S_VISCOUS, S_DASHPOT, S_ADAPTIVE, S_WALLS = range(8)
N_SWITCHES = 8

# adaptive damping state ``adamp`` (float64): alpha [1/s], kinetic energy at the end of the
# last step [J], last ratio R [-], the clamps [1/s] (the absorbed energy is booked as body damping
# when the energy effect is on)
A_ALPHA, A_KE, A_RATIO, A_MIN, A_MAX = range(5)
N_ADAMP = 5
ADAPT_UP = 1.1       # seed eq. 27: R < 0.5
ADAPT_DOWN = 0.99    # R > 0.5
ADAPT_TARGET = 0.5

# columns of the body load table bload[b, :], read for LOADED bodies only: the prescribed force
# F(t) = F0 + F1 sin(omega max(t - t0, 0) + phase) [N] (a haversine from F_min to F_max:
# F0 = (F_min + F_max)/2, F1 = (F_max - F_min)/2 along the load direction, phase = -pi/2)
L_F0 = 0      # 3 columns: mean force [N]
L_F1 = 3      # 3 columns: amplitude [N]
L_OMEGA = 6   # angular frequency [rad/s]
L_PHASE = 7   # phase at t0 [rad]
L_T0 = 8      # time the oscillation starts [s]; before it the force stays at F0 + F1 sin(phase)
N_LOAD = 9

# positions in the neighbour-state tuple ``nl`` of :func:`run_poly_steps`
PNL_FIELDS = ("start", "pi", "pj", "rstart", "rlist", "ft", "fc", "tj", "act", "epair", "geo",
              "wstart", "wbody", "wwall", "wft", "wfc", "wgeo", "xref", "wref", "sep", "sdir")
(P_START, P_PI, P_PJ, P_RSTART, P_RLIST, P_FT, P_FC, P_TJ, P_ACT, P_EPAIR, P_GEO,
 P_WSTART, P_WBODY, P_WWALL, P_WFT, P_WFC, P_WGEO, P_XREF, P_WREF, P_SEP, P_SDIR) = range(len(PNL_FIELDS))
# sep[c] (int32), why pair c does not touch: 0 unknown (or touching), k + 1 face k of body i,
# -(k + 1) face k of body j (its plane clears the other body), SEP_DIR the unit direction
# sdir[c] (float64 (3,), from i to j) separates them (demcli.kernels.separation; pairs
# separated only across two edges), SEP_NONE none found (overlap() every step)
SEP_NONE = -(2 ** 30)
SEP_DIR = SEP_NONE + 1
SEP_ITER = 32  # GJK iterations allowed when searching a separating direction
SEP_MARGIN = 1e-9  # a cached face or direction must clear by this x (r_i + r_j) + 1e-12 max |x|
# columns of geo / wgeo (per contact, last evaluation): depth d [m], elastic normal force F_N [N],
# tangential stiffness K_t [N/m]
G_DEPTH, G_FN, G_KT = 0, 1, 2


@njit(inline="always")
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


@njit(parallel=True)
def _kick_drift(x, v, w, q, L, f, tq, mass, inert, bflags, dt, alpha, ztq, xref, lim2, rebuild, eabs):
    """First half kick (with the adaptive damping factor), rotation and drift; sets
    rebuild[0] when a centroid moved more than skin/2 from its listed position."""
    h = 0.5 * dt
    a = 0.5 * alpha * h
    c1p = 1.0 - a
    c2p = 1.0 / (1.0 + a)
    for b in prange(x.shape[0]):
        fl = bflags[b]
        ea = 0.0
        c1 = c1p
        c2 = c2p
        if fl & LOADED:  # a loading device takes its prescribed force undamped
            c1 = 1.0
            c2 = 1.0
        if fl & FIX_TRANSLATION == 0:
            im = h / mass[b]
            s = 0.0
            for d in range(3):
                if fl & (FIX_X << d) == 0:
                    v0 = v[b, d]
                    v1 = (v0 * c1 + f[b, d] * im) * c2
                    v[b, d] = v1
                    s += (0.5 * (v0 + v1)) ** 2
            ea += mass[b] * s
        if fl & FIX_ROTATION == 0:
            e0 = w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2]
            for d in range(3):
                L[b, d] = (L[b, d] * c1 + h * tq[b, d]) * c2
            _rotate_rigid(b, w, q, L, ztq, inert, dt, False)  # ztq = 0: rotation only, L already kicked
            ea += 0.5 * (e0 + w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2])
        if fl & LOADED == 0:
            eabs[b] = alpha * h * ea
        _drift(x, v, b, dt, xref, lim2, rebuild)


@njit(parallel=True)
def _world_geometry(x, q, shape, vertex_start, vertices, face_start, face_normal, face_offset,
                    bvstart, bfstart, wvert, wnorm, woff):
    """World vertices and face planes of every body (rows bvstart / bfstart)."""
    for b in prange(x.shape[0]):
        k = shape[b]
        to_world_vertices(vertices[vertex_start[k]:vertex_start[k + 1]], x[b], q[b],
                          wvert[bvstart[b]:bvstart[b + 1]])
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
def _still_separated(code, na, da, va, nb_, db_, vb, margin):
    """Whether the cached face ``code`` (see P_SEP) still clears the other body by ``margin``."""
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
    for k in range(verts.shape[0]):
        if n[f, 0] * verts[k, 0] + n[f, 1] * verts[k, 1] + n[f, 2] * verts[k, 2] - d[f] <= margin:
            return False
    return True


@njit(parallel=True)
def _pair_forces(start, pj, x, v, w, mass, rad, bmat, prm, sw, dt,
                 shape, vertex_start, face_start, fvstart, fverts, bvstart, bfstart, wvert, wnorm, woff,
                 ft, fc, tj, act, epair, geo, frow, trow, erow, sep, sdir):
    """Force of every listed pair into its own row; the row owner i sums its side.

    fc[c]: force on i [N]; tj[c]: torque on j [N m]; geo[c]: (depth, F_N, K_t);
    epair[c]: (dashpot, slip) losses this step [J]; frow/trow/erow[i]: i's sums.
    sep[c], sdir[c]: the cached separating face or direction (P_SEP): a pair still cleared by
    it skips the exact overlap, which would find V = 0 (the results do not depend on the
    cache). A direction that no longer clears is searched again from where it was.
    """
    friction = sw[S_FRICTION]
    energy = sw[S_ENERGY]
    dashpot = sw[S_DASHPOT]
    # scratch of overlap_ws for any pair of these shapes: largest face, most faces
    max_fv = max_row(fvstart)
    max_f = max_row(face_start)
    for i in prange(start.shape[0] - 1):
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
            buf, fw, planes = scratch(max_fv, max_f)  # once per row, not per pair
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
                if dx * dx + dy * dy + dz * dz < rs * rs:
                    kj = shape[j]
                    vb = wvert[bvstart[j]:bvstart[j + 1]]
                    nb_ = wnorm[bfstart[j]:bfstart[j + 1]]
                    db_ = woff[bfstart[j]:bfstart[j + 1]]
                    code = sep[c]
                    margin = SEP_MARGIN * rs + 1e-12 * max(abs(xi0), abs(xi1), abs(xi2), abs(xj0), abs(xj1),
                                                          abs(xj2))
                    if code == SEP_DIR:
                        apart = gap(sdir[c, 0], sdir[c, 1], sdir[c, 2], va, vb) > margin
                        if not apart:
                            apart, ux, uy, uz = separating_direction(va, vb, sdir[c, 0], sdir[c, 1], sdir[c, 2],
                                                                     margin, SEP_ITER, buf)
                            if apart:
                                sdir[c, 0] = ux
                                sdir[c, 1] = uy
                                sdir[c, 2] = uz
                    else:
                        apart = code != 0 and code != SEP_NONE and _still_separated(code, na, da, va, nb_, db_, vb,
                                                                                    margin)
                    if apart:
                        vol = 0.0
                    else:
                        vol, gx, gy, gz, sx, sy, sz = overlap_ws(
                            va, fsa, fverts, offa, na, da, xi0, xi1, xi2, ri,
                            vb, fvstart[face_start[kj]:face_start[kj + 1] + 1], fverts,
                            vertex_start[kj], nb_, db_, xj0, xj1, xj2, rj, buf, fw, planes)
                        if not vol > 0.0 and code != SEP_NONE:
                            ga, fa = _clearance(na, da, vb)
                            gb, fb = _clearance(nb_, db_, va)
                            if ga > margin and ga >= gb:
                                sep[c] = fa + 1
                            elif gb > margin:
                                sep[c] = -(fb + 1)
                            else:
                                found, ux, uy, uz = separating_direction(va, vb, -dx, -dy, -dz, margin, SEP_ITER,
                                                                         buf)
                                if found:
                                    sep[c] = SEP_DIR
                                    sdir[c, 0] = ux
                                    sdir[c, 1] = uy
                                    sdir[c, 2] = uz
                                else:
                                    sep[c] = SEP_NONE
                        elif vol > 0.0:
                            sep[c] = 0
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


@njit(parallel=True)
def _gather(frow, trow, erow, rstart, rlist, fc, tj, act, epair,
            wstart, wwall, wft, wfc, wgeo, wkind, wpoint, wnormal, wv, wmat,
            x, v, w, q, L, f, tq, mass, inert, bflags, rad, bmat, prm, sw, dt, kick_dt,
            shape, vertex_start, face_start, fvstart, fverts, bvstart, bfstart, wvert, wnorm, woff,
            gravity, local, visc, alpha, esph, ebody, eabs, kevec, bload, tload):
    """Per body: own row sums, reverse rows, plane walls, body loads, second half kick.

    dt: the contact step (0 when priming: no history or loss increments); kick_dt: the
    half-kick step (0 when priming). tload: the time of the positions [s], for the
    prescribed forces of LOADED bodies (table ``bload``, columns L_*). Writes f, tq
    (total loads), kevec[b] (kinetic energy after the kick) and adds the adaptive
    damping's absorbed energy to eabs[b].
    """
    friction = sw[S_FRICTION]
    energy = sw[S_ENERGY]
    dashpot = sw[S_DASHPOT]
    h = 0.5 * kick_dt
    a = 0.5 * alpha * h
    c1p = 1.0 - a
    c2p = 1.0 / (1.0 + a)
    for b in prange(x.shape[0]):
        fl = bflags[b]
        damped = fl & LOADED == 0  # a loading device takes its prescribed force undamped
        fx = frow[b, 0]
        fy = frow[b, 1]
        fz = frow[b, 2]
        tx = trow[b, 0]
        ty = trow[b, 1]
        tz = trow[b, 2]
        e0 = 0.0
        e1 = 0.0
        if energy:
            e0 = erow[b, 0]
            e1 = erow[b, 1]
        for r in range(rstart[b], rstart[b + 1]):
            c = rlist[r]
            if act[c]:
                fx -= fc[c, 0]
                fy -= fc[c, 1]
                fz -= fc[c, 2]
                tx += tj[c, 0]
                ty += tj[c, 1]
                tz += tj[c, 2]
                if energy:
                    e0 += epair[c, 0]
                    e1 += epair[c, 1]
        xb0 = x[b, 0]
        xb1 = x[b, 1]
        xb2 = x[b, 2]
        m = mass[b]
        k0 = wstart[b]
        k1 = wstart[b + 1]
        if k1 > k0:
            kb = shape[b]
            rb = rad[b]
            va = wvert[bvstart[b]:bvstart[b + 1]]
            na = wnorm[bfstart[b]:bfstart[b + 1]]
            da = woff[bfstart[b]:bfstart[b + 1]]
            fsa = fvstart[face_start[kb]:face_start[kb + 1] + 1]
            offa = vertex_start[kb]
            for k in range(k0, k1):
                wl = wwall[k]
                wnx = wnormal[wl, 0]
                wny = wnormal[wl, 1]
                wnz = wnormal[wl, 2]
                vol = 0.0
                gx = gy = gz = sx = sy = sz = 0.0
                if wkind[wl] == 0:  # plane; other kinds are rejected by PolySystem
                    wd = wnx * wpoint[wl, 0] + wny * wpoint[wl, 1] + wnz * wpoint[wl, 2]
                    vol, gx, gy, gz, sx, sy, sz = plane_overlap(va, fsa, fverts, offa, na, da, xb0, xb1, xb2, rb,
                                                                wnx, wny, wnz, wd)
                if not vol > 0.0:
                    wfc[k, 0] = 0.0
                    wfc[k, 1] = 0.0
                    wfc[k, 2] = 0.0
                    wfc[k, 3] = 0.0
                    wgeo[k, 0] = 0.0
                    wgeo[k, 1] = 0.0
                    wgeo[k, 2] = 0.0
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
                    prm, bmat[b], wmat[wl], vol, depth, area, nx, ny, nz, vx, vy, vz, m, dt, wft, k, friction,
                    dashpot)
                wfc[k, 0] = cfx
                wfc[k, 1] = cfy
                wfc[k, 2] = cfz
                wfc[k, 3] = kserv
                wgeo[k, 0] = depth
                wgeo[k, 1] = fel
                wgeo[k, 2] = kt
                fx += cfx
                fy += cfy
                fz += cfz
                tx += ay * cfz - az * cfy
                ty += az * cfx - ax * cfz
                tz += ax * cfy - ay * cfx
                # a wall contact's loss is wholly the body's (pairs split theirs in half)
                e0 += 2.0 * ed
                e1 += 2.0 * ef
        if energy:
            esph[b, 0] += 0.5 * e0
            esph[b, 1] += 0.5 * e1
        fx, fy, fz, tx, ty, tz, p = _body_loads(
            fx, fy, fz, tx, ty, tz, m, 0.0, v[b, 0], v[b, 1], v[b, 2], w[b, 0], w[b, 1], w[b, 2],
            gravity, local, 0.0, sw[S_GRAVITY], sw[S_LOCAL] and damped, False)
        if sw[S_VISCOUS] and damped:
            # constant mass-proportional damping: F = -alpha m v, T = -alpha I omega = -alpha L
            am = visc * m
            fx -= am * v[b, 0]
            fy -= am * v[b, 1]
            fz -= am * v[b, 2]
            tx -= visc * L[b, 0]
            ty -= visc * L[b, 1]
            tz -= visc * L[b, 2]
            p += am * (v[b, 0] ** 2 + v[b, 1] ** 2 + v[b, 2] ** 2) + visc * (
                w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2])
        if energy:
            ebody[b] += p * dt
        if fl & LOADED:
            arg = bload[b, L_OMEGA] * max(tload - bload[b, L_T0], 0.0) + bload[b, L_PHASE]
            sn = math.sin(arg)
            fx += bload[b, L_F0] + bload[b, L_F1] * sn
            fy += bload[b, L_F0 + 1] + bload[b, L_F1 + 1] * sn
            fz += bload[b, L_F0 + 2] + bload[b, L_F1 + 2] * sn
        f[b, 0] = fx
        f[b, 1] = fy
        f[b, 2] = fz
        tq[b, 0] = tx
        tq[b, 1] = ty
        tq[b, 2] = tz
        # second half kick (seed eqs. 23-24 form for the adaptive alpha; c1 = c2 = 1 without it)
        ea = 0.0
        c1 = c1p if damped else 1.0
        c2 = c2p if damped else 1.0
        if fl & FIX_TRANSLATION == 0:
            im = h / m
            s = 0.0
            if fl & FIX_X == 0:
                v0 = v[b, 0]
                v1 = (v0 * c1 + fx * im) * c2
                v[b, 0] = v1
                s += (0.5 * (v0 + v1)) ** 2
            if fl & (FIX_X << 1) == 0:
                v0 = v[b, 1]
                v1 = (v0 * c1 + fy * im) * c2
                v[b, 1] = v1
                s += (0.5 * (v0 + v1)) ** 2
            if fl & (FIX_X << 2) == 0:
                v0 = v[b, 2]
                v1 = (v0 * c1 + fz * im) * c2
                v[b, 2] = v1
                s += (0.5 * (v0 + v1)) ** 2
            ea += m * s
        if fl & FIX_ROTATION == 0:
            r0 = w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2]
            L[b, 0] = (L[b, 0] * c1 + h * tx) * c2
            L[b, 1] = (L[b, 1] * c1 + h * ty) * c2
            L[b, 2] = (L[b, 2] * c1 + h * tz) * c2
            wx, wy, wz = _omega_from_L(q[b, 0], q[b, 1], q[b, 2], q[b, 3], L[b, 0], L[b, 1], L[b, 2],
                                       inert[b, 0], inert[b, 1], inert[b, 2])
            w[b, 0] = wx
            w[b, 1] = wy
            w[b, 2] = wz
            ea += 0.5 * (r0 + wx * L[b, 0] + wy * L[b, 1] + wz * L[b, 2])
        if damped:
            eabs[b] += alpha * h * ea
        kevec[b] = 0.5 * (m * (v[b, 0] ** 2 + v[b, 1] ** 2 + v[b, 2] ** 2)
                          + w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2])


@njit
def add_actor_pairs(start, pj, x, rad, nsmall, skin):
    """Pair list of all bodies from the cell-grid list of the first ``nsmall`` ones.

    Bodies nsmall.. are actors (a loading plate, a sleeper): far larger than the
    particles, so they stay out of the cell grid (whose cells follow the largest
    radius) and are paired here with every body whose bounding sphere comes within
    ``skin`` of theirs. Rows stay sorted by j (actors have the highest indices).
    Returns (start, pi, pj) over all bodies.
    """
    nb = x.shape[0]
    cnt = np.zeros(nb, np.int64)
    for i in range(nb):
        if i < nsmall:
            cnt[i] = start[i + 1] - start[i]
        for a in range(max(i + 1, nsmall), nb):
            r = rad[i] + rad[a] + skin
            if (x[i, 0] - x[a, 0]) ** 2 + (x[i, 1] - x[a, 1]) ** 2 + (x[i, 2] - x[a, 2]) ** 2 < r * r:
                cnt[i] += 1
    nstart = np.zeros(nb + 1, np.int64)
    for i in range(nb):
        nstart[i + 1] = nstart[i] + cnt[i]
    npi = np.empty(nstart[nb], np.int64)
    npj = np.empty(nstart[nb], np.int64)
    for i in range(nb):
        k = nstart[i]
        if i < nsmall:
            for c in range(start[i], start[i + 1]):
                npi[k] = i
                npj[k] = pj[c]
                k += 1
        for a in range(max(i + 1, nsmall), nb):
            r = rad[i] + rad[a] + skin
            if (x[i, 0] - x[a, 0]) ** 2 + (x[i, 1] - x[a, 1]) ** 2 + (x[i, 2] - x[a, 2]) ** 2 < r * r:
                npi[k] = i
                npj[k] = a
                k += 1
    return nstart, npi, npj


@njit
def _adapt(adamp, eabs, kevec, energy, ebody):
    """Seed eq. 27: R = E_a / |Delta E_k|; R < 0.5: alpha *= 1.1, R > 0.5: alpha *= 0.99.

    Sums in body order (serial): the decision does not depend on the thread count.
    """
    ea = 0.0
    ke = 0.0
    for b in range(kevec.shape[0]):
        ea += eabs[b]
        ke += kevec[b]
        if energy:
            ebody[b] += eabs[b]
    dke = abs(ke - adamp[A_KE])
    r = ea / dke if dke > 0.0 else math.inf
    alpha = adamp[A_ALPHA]
    if r < ADAPT_TARGET:
        alpha *= ADAPT_UP
    elif r > ADAPT_TARGET:
        alpha *= ADAPT_DOWN
    adamp[A_ALPHA] = min(max(alpha, adamp[A_MIN]), adamp[A_MAX])
    adamp[A_KE] = ke
    adamp[A_RATIO] = r


@njit
def _check(x, v, w, q, L, mass, pi, pj, act, geo, wstart, wgeo, rad, overlap_limit, ke_limit, info):
    """Guards: NaN/Inf in the body state, overlap depth / bounding radius, runaway kinetic energy.

    info: (body i, body j or -1 for a wall, worst depth ratio, kinetic energy).
    """
    ke = 0.0
    for b in range(x.shape[0]):
        s = q[b, 0] + q[b, 1] + q[b, 2] + q[b, 3]
        for d in range(3):
            s += x[b, d] + v[b, d] + w[b, d] + L[b, d]
        if not math.isfinite(s):
            info[0] = b
            return BAD_NUMBER
        ke += 0.5 * (mass[b] * (v[b, 0] ** 2 + v[b, 1] ** 2 + v[b, 2] ** 2)
                     + w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2])
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
    for b in range(x.shape[0]):
        for k in range(wstart[b], wstart[b + 1]):
            ratio = wgeo[k, G_DEPTH] / rad[b]
            if ratio > worst:
                worst = ratio
                wi = b
                wj = -1
    info[2] = worst
    info[3] = ke
    if worst > overlap_limit:
        info[0] = wi
        info[1] = wj
        return BAD_OVERLAP
    if ke > ke_limit:
        return BAD_ENERGY
    return OK


@njit
def run_poly_steps(nsteps, time, dt, sw, prm, gravity, local, visc, adamp,
                   bodies, mass, inert, bflags, rad, bmat,
                   shapes, shape, bvstart, bfstart, world,
                   wkind, wpoint, wnormal, wv, wmat, wctrl, wprm, wforce, wkn,
                   nl, skin, max_cells,
                   esph, ebody, eacc,
                   check_every, overlap_limit, ke_limit, counters, info, force_rebuild, step0, prime,
                   bload, nsmall):
    """Advance ``nsteps`` steps of rigid convex polyhedra; returns (status, steps_done, time, nl).

    Args:
        nsteps: steps to run. time [s], dt [s]: clock and step.
        sw: (N_SWITCHES,) bool tuple of active effects (S_*).
        prm: (n_m, n_m, N_QPARAMS) float64 material-pair table (Q_*).
        gravity: (3,) m/s^2. local: Cundall lambda [-]. visc: constant alpha [1/s].
        adamp: (N_ADAMP,) float64 adaptive damping state (A_*), updated in place.
        bodies: (x, v, w, q, L, f, tq) float64 (n_b, 3), q (n_b, 4) (w, x, y, z) body to
            world, L world angular momentum [kg m^2/s], f [N] and tq [N m] the loads of the
            last step; updated in place.
        mass (n_b,) kg; inert (n_b, 3) principal moments kg m^2; bflags (n_b,) int8;
        rad (n_b,) m bounding radius about the centroid; bmat (n_b,) material index.
        shapes: (vertex_start, vertices, face_start, face_vertex_start, face_vertices,
            face_normal, face_offset): the polyhedron_shapes CSR tables (body frame).
        shape (n_b,) template of each body; bvstart, bfstart (n_b + 1,) rows of each
            body's vertices and faces in the world arrays.
        world: (wvert (n_v, 3), wnorm (n_f, 3), woff (n_f,)) scratch for world geometry.
        wkind ... wkn: wall arrays as in :func:`demcli.kernels.step.run_steps` (planes only).
        nl: neighbour state (PNL_FIELDS); rebuilt here when needed.
        skin [m], max_cells: Verlet list parameters.
        esph (n_b or 0, 2) cumulative contact dashpot and slip losses per body [J];
        ebody (n_b or 0,) body damping losses [J]; eacc (1,) wall work [J].
        check_every, overlap_limit (depth / bounding radius), ke_limit [J]: guards.
        counters (N_COUNTERS,) int64; info (4,) float64 guard diagnosis.
        force_rebuild: build the lists before the first step. step0: global step at entry.
        prime: evaluate the loads at the current state first (zero-length step).
        bload: (n_b, N_LOAD) float64 prescribed forces of LOADED bodies (L_* columns).
        nsmall: bodies 0..nsmall-1 go through the cell grid; the rest are actors
            (:func:`add_actor_pairs`).
    """
    x, v, w, q, L, f, tq = bodies
    vertex_start, vertices, face_start, fvstart, fverts, face_normal, face_offset = shapes
    wvert, wnorm, woff = world
    (start, pi, pj, rstart, rlist, ft, fc, tj, act, epair, geo,
     wstart, wbody, wwall, wft, wfc, wgeo, xref, wref, sep, sdir) = nl
    friction = sw[S_FRICTION]
    energy = sw[S_ENERGY]
    adaptive = sw[S_ADAPTIVE]
    nb = x.shape[0]
    nw = wv.shape[0]
    lim2 = (0.5 * skin) ** 2
    rebuild = np.zeros(1, np.int64)
    rebuild[0] = 1 if force_rebuild else 0
    frow = np.zeros((nb, 3))
    trow = np.zeros((nb, 3))
    erow = np.zeros((nb if energy else 0, 2))
    ztq = np.zeros((nb, 3))
    eabs = np.zeros(nb)
    kevec = np.zeros(nb)
    body_idx = np.arange(nb)
    wradius = np.zeros(nw)
    status = OK
    n = 0
    while n < nsteps or prime:
        h = 0.0 if prime else dt
        alpha = adamp[A_ALPHA] if adaptive else 0.0
        if prime:
            rebuild[0] = 1
            eabs[:] = 0.0
        else:
            _kick_drift(x, v, w, q, L, f, tq, mass, inert, bflags, dt, alpha, ztq, xref, lim2, rebuild, eabs)
            counters[C_KICK] += 1
            if nw > 0:
                move_walls(wpoint, wref, wv, dt, lim2, rebuild)
                counters[C_WALLMOVE] += 1
        if rebuild[0]:
            rebuild[0] = 0
            nstart, npi, npj = build_pairs(x[:nsmall], rad[:nsmall], body_idx[:nsmall], skin, max_cells)
            if nsmall < nb:
                nstart, npi, npj = add_actor_pairs(nstart, npj, x, rad, nsmall, skin)
            npair = npi.shape[0]
            nft = np.zeros((npair if friction else 0, 3))
            carry_history(nb, nstart, npj, start, pj, ft, nft)
            start, pi, pj, ft = nstart, npi, npj, nft
            rstart, rlist = build_reverse(nb, pj)
            fc = np.zeros((npair, 3))
            tj = np.zeros((npair, 3))
            act = np.zeros(npair, np.uint8)
            epair = np.zeros((npair if energy else 0, 2))
            geo = np.zeros((npair, 3))
            sep = np.zeros(npair, np.int32)
            sdir = np.zeros((npair, 3))
            if nw > 0:
                nws, nwb, nww = build_wall_pairs(x, rad, skin, wkind, wpoint, wnormal, wradius)
                nq = nww.shape[0]
                nwft = np.zeros((nq if friction else 0, 3))
                carry_history(nb, nws, nww, wstart, wwall, wft, nwft)
                wstart, wbody, wwall, wft = nws, nwb, nww, nwft
                wfc = np.zeros((nq, 4))
                wgeo = np.zeros((nq, 3))
                wref[:, :] = 0.0
            xref = x.copy()
            counters[C_REBUILD] += 1
        _world_geometry(x, q, shape, vertex_start, vertices, face_start, face_normal, face_offset,
                        bvstart, bfstart, wvert, wnorm, woff)
        _pair_forces(start, pj, x, v, w, mass, rad, bmat, prm, sw, h,
                     shape, vertex_start, face_start, fvstart, fverts, bvstart, bfstart, wvert, wnorm, woff,
                     ft, fc, tj, act, epair, geo, frow, trow, erow, sep, sdir)
        counters[C_PAIRS] += 1
        if friction:
            counters[C_FRICTION] += 1
        if energy:
            counters[C_ENERGY] += 1
        if sw[S_GRAVITY]:
            counters[C_GRAVITY] += 1
        if sw[S_LOCAL] or sw[S_VISCOUS] or adaptive:
            counters[C_DAMPING] += 1
        _gather(frow, trow, erow, rstart, rlist, fc, tj, act, epair,
                wstart, wwall, wft, wfc, wgeo, wkind, wpoint, wnormal, wv, wmat,
                x, v, w, q, L, f, tq, mass, inert, bflags, rad, bmat, prm, sw, h, h,
                shape, vertex_start, face_start, fvstart, fverts, bvstart, bfstart, wvert, wnorm, woff,
                gravity, local, visc, alpha, esph, ebody, eabs, kevec, bload, time + h)
        counters[C_GATHER] += 1
        counters[C_BODY] += 1
        if prime:
            prime = False
            if adaptive:
                ke = 0.0
                for b in range(nb):
                    ke += kevec[b]
                adamp[A_KE] = ke
            continue
        if adaptive:
            _adapt(adamp, eabs, kevec, energy, ebody)
        n += 1
        time += dt
        if nw > 0:
            _wall_control(time, dt, wstart[nb], wwall, wfc, wnormal, wv, wctrl, wprm, wforce, wkn, eacc, energy)
            counters[C_WALLCTRL] += 1
        gstep = step0 + n
        if check_every > 0 and (gstep % check_every == 0 or gstep == 1):
            status = _check(x, v, w, q, L, mass, pi, pj, act, geo, wstart, wgeo, rad, overlap_limit, ke_limit,
                            info)
            counters[C_CHECK] += 1
            if status != OK:
                break
    nl = (start, pi, pj, rstart, rlist, ft, fc, tj, act, epair, geo,
          wstart, wbody, wwall, wft, wfc, wgeo, xref, wref, sep, sdir)
    return status, n, time, nl


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
