"""Shape plug-in: spheres, and rigid clumps of spheres (the members are the collision primitives).

Contact of two spheres (or a sphere and a wall) at overlap delta = r_i + r_j - |x_i - x_j|
along n = (x_i - x_j) / |x_i - x_j|, contact point at the middle of the overlap; the laws
(linear spring-dashpot or Hertz-Mindlin, Coulomb slip, rolling resistance) are in
:mod:`demcli.kernels.contact`; bonds (contact, parallel, Burgers) in :mod:`demcli.kernels.bonds`.

Provides the engine's hooks (:mod:`demcli.kernels.shapes`): ``place`` (clump members follow
their body), ``primitives`` (the spheres the lists are built on), ``pair_pass`` (sphere pairs,
then bonds), ``wall_pass`` (sphere-wall, planes and cylinders), ``worst_overlap`` (the guard).
"""

import math
from collections import namedtuple

import numpy as np

from numba import prange

from demcli.jit import njit
from demcli.kernels import quat
from demcli.kernels.bonds import bond_forces
from demcli.kernels.contact import (HERTZ, P_ARM, P_CN, P_ESTAR, P_KN, P_ZETA, contact_law, pair_kinematics,
                                   strain_energy)
from demcli.kernels.layout import F_BONDS, F_CLUMPS, F_ENERGY, F_FRICTION, F_ROLLING
from demcli.kernels.mesh import wall_features
from demcli.kernels.periodic import mean_flow, min_image
from demcli.kernels.switch import choose
from demcli.kernels.walls import MESH, surface_distance, wall_distance

SphereGeometry = namedtuple("SphereGeometry", "xs vs ws rad mat smass sbody soff cell")
"""Spheres: xs, vs, ws (n_s, 3) position, velocity and spin of each sphere (for spheres-only
scenes the body arrays: sphere i is body i); rad (n_s,) m; mat (n_s,) material; smass (n_s,) mass
of the sphere's body; sbody (n_s,) its body; soff (n_s, 3) offset in the body frame; cell: the
periodic cell (:mod:`demcli.kernels.periodic`, spheres-only scenes) or None (compiled out)."""


@njit(parallel=True)
def _place_members(x, v, w, q, xs, vs, ws, sbody, soff, xref, lim2, rebuild):
    """Clump members follow their body: position, velocity and spin of each sphere."""
    for s in prange(xs.shape[0]):
        b = sbody[s]
        ox, oy, oz = quat.rotate(q[b, 0], q[b, 1], q[b, 2], q[b, 3], soff[s, 0], soff[s, 1], soff[s, 2])
        xs[s, 0] = x[b, 0] + ox
        xs[s, 1] = x[b, 1] + oy
        xs[s, 2] = x[b, 2] + oz
        vs[s, 0] = v[b, 0] + w[b, 1] * oz - w[b, 2] * oy
        vs[s, 1] = v[b, 1] + w[b, 2] * ox - w[b, 0] * oz
        vs[s, 2] = v[b, 2] + w[b, 0] * oy - w[b, 1] * ox
        ws[s, 0] = w[b, 0]
        ws[s, 1] = w[b, 1]
        ws[s, 2] = w[b, 2]
        dx = xs[s, 0] - xref[s, 0]
        dy = xs[s, 1] - xref[s, 1]
        dz = xs[s, 2] - xref[s, 2]
        if dx * dx + dy * dy + dz * dz > lim2:
            rebuild[0] = 1


@njit(parallel=True, internal=True)
def _pair_forces(start, pj, xs, vs, ws, rad, smat, smass, prm, law, dt, ft, mr, friction, rolling,
                 energy, fc, tj, act, epair, frow, trow, erow, split, cell):
    """Force, torques and dissipation of every listed pair, each pair writing its own row.

    Walks the CSR rows (sphere i, then its j > i), so i's data is loaded once per row, and
    the row's owner sums i's side of its pairs into frow/trow/erow[i] (race-free); the
    gather then adds only the j sides. ``split``: None (every primitive a sphere), or the
    number of spheres of a mixed scene (:mod:`demcli.kernels.shapes.mixed`): rows and partners
    below it only, and every open pair drops its history (nothing is marked at a rebuild).
    ``cell``: the periodic cell (minimum-image branch, mean flow in the relative velocity) or None.
    """
    nrow = start.shape[0] - 1
    if split is not None:
        nrow = split
    for i in prange(nrow):
        xi0 = xs[i, 0]
        xi1 = xs[i, 1]
        xi2 = xs[i, 2]
        ri = rad[i]
        sfx = 0.0
        sfy = 0.0
        sfz = 0.0
        stx = 0.0
        sty = 0.0
        stz = 0.0
        se0 = 0.0
        se1 = 0.0
        for c in range(start[i], start[i + 1]):
            j = pj[c]
            if split is not None:
                if j >= split:
                    continue
            dx, dy, dz = min_image(cell, xi0 - xs[j, 0], xi1 - xs[j, 1], xi2 - xs[j, 2])
            rj = rad[j]
            rs = ri + rj
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= rs * rs:
                if act[c] or split is not None:  # an opened contact drops its history (most pairs never touch)
                    act[c] = 0
                    if friction:
                        ft[c, 0] = 0.0
                        ft[c, 1] = 0.0
                        ft[c, 2] = 0.0
                    if rolling:
                        mr[c, 0] = 0.0
                        mr[c, 1] = 0.0
                        mr[c, 2] = 0.0
                continue
            act[c] = 1
            d = math.sqrt(d2)
            inv = 1.0 / d
            nx = dx * inv
            ny = dy * inv
            nz = dz * inv
            delta = rs - d
            ma = smat[i]
            mb = smat[j]
            arm = 0.5 * delta * prm[ma, mb, P_ARM]  # lever arms R - delta/2 or R (contact.lever_arm)
            ai = ri - arm
            aj = rj - arm
            vx, vy, vz, wx, wy, wz = pair_kinematics(vs, ws, i, j, nx, ny, nz, ai, aj)
            vx, vy, vz = mean_flow(cell, vx, vy, vz, dx, dy, dz)
            mi = smass[i]
            mj = smass[j]
            fx, fy, fz, mx, my, mz, ed, ef = contact_law(
                law, prm, ma, mb, delta, nx, ny, nz, vx, vy, vz,
                wx, wy, wz, ri * rj / rs, mi * mj / (mi + mj), dt,
                ft, mr, c, friction, rolling)
            fc[c, 0] = fx
            fc[c, 1] = fy
            fc[c, 2] = fz
            sfx += fx
            sfy += fy
            sfz += fz
            if friction or rolling:
                # torque = (xc - x) x F, xc - xi = -ai n, xc - xj = aj n
                cx = ny * fz - nz * fy
                cy = nz * fx - nx * fz
                cz = nx * fy - ny * fx
                stx += -ai * cx + mx
                sty += -ai * cy + my
                stz += -ai * cz + mz
                tj[c, 0] = -aj * cx - mx
                tj[c, 1] = -aj * cy - my
                tj[c, 2] = -aj * cz - mz
            if energy:
                epair[c, 0] = ed
                epair[c, 1] = ef
                se0 += ed
                se1 += ef
        frow[i, 0] = sfx
        frow[i, 1] = sfy
        frow[i, 2] = sfz
        if friction or rolling:
            trow[i, 0] = stx
            trow[i, 1] = sty
            trow[i, 2] = stz
        if energy:
            erow[i, 0] = se0
            erow[i, 1] = se1


@njit(inline="always")
def _wall_contact(i, k, w, xs, vs, ws, rad, smat, smass, wkind, wpoint, wnormal, wradius, wv, wmat,
                  prm, law, dt, wft, wmr, friction, rolling):
    """Force and torque on sphere i from plane or cylinder wall w (history row k); zero when apart."""
    s, nx, ny, nz = wall_distance(wkind[w], wpoint[w, 0], wpoint[w, 1], wpoint[w, 2],
                                  wnormal[w, 0], wnormal[w, 1], wnormal[w, 2], wradius[w],
                                  xs[i, 0], xs[i, 1], xs[i, 2])
    return _surface_contact(i, w, s, nx, ny, nz, xs, vs, ws, rad, smat, smass, wv, wmat, prm, law, dt, wft, wmr, k,
                            friction, rolling)


@njit(inline="always")
def _surface_contact(i, w, s, nx, ny, nz, xs, vs, ws, rad, smat, smass, wv, wmat, prm, law, dt, wft, wmr, k,
                     friction, rolling):
    """Force and torque on sphere i from wall w at distance s [m] from its surface along the unit
    normal n (wall to sphere), springs in row k of wft, wmr; zero (springs cleared) when apart.
    Returns (F (3) [N], torque (3) [N m], dashpot and slip losses [J], servo stiffness k_n + c_n/dt
    [N/m], normal force F . n [N])."""
    ri = rad[i]
    delta = ri - s
    if delta <= 0.0:
        if friction:
            wft[k, 0] = 0.0
            wft[k, 1] = 0.0
            wft[k, 2] = 0.0
        if rolling:
            wmr[k, 0] = 0.0
            wmr[k, 1] = 0.0
            wmr[k, 2] = 0.0
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    ma = smat[i]
    mb = wmat[w]
    # branch from the centre to the contact point on the wall surface: s = R - delta (deformed),
    # or R (contact.lever_arm: radius)
    a = s + (1.0 - prm[ma, mb, P_ARM]) * delta
    wix, wiy, wiz = ws[i, 0], ws[i, 1], ws[i, 2]
    vx = vs[i, 0] - wv[w, 0] - a * (wiy * nz - wiz * ny)
    vy = vs[i, 1] - wv[w, 1] - a * (wiz * nx - wix * nz)
    vz = vs[i, 2] - wv[w, 2] - a * (wix * ny - wiy * nx)
    fx, fy, fz, mx, my, mz, ed, ef = contact_law(law, prm, ma, mb, delta, nx, ny, nz, vx, vy, vz,
                                                 wix, wiy, wiz, ri, smass[i], dt,
                                                 wft, wmr, k, friction, rolling)
    tx = -a * (ny * fz - nz * fy) + mx
    ty = -a * (nz * fx - nx * fz) + my
    tz = -a * (nx * fy - ny * fx) + mz
    # stiffness the wall's servo sees: spring plus dashpot over one step (a change of wall
    # velocity changes the dashpot force at once), k_n + c_n / dt
    m = smass[i]
    if law == HERTZ:
        kn = 2.0 * prm[ma, mb, P_ESTAR] * math.sqrt(ri * delta)
        cn = 2.0 * math.sqrt(5.0 / 6.0) * prm[ma, mb, P_ZETA] * math.sqrt(kn * m)
    else:
        kn = prm[ma, mb, P_KN]
        cn = prm[ma, mb, P_CN] + 2.0 * prm[ma, mb, P_ZETA] * math.sqrt(m * kn)
    if dt > 0.0:
        kn += cn / dt
    return fx, fy, fz, tx, ty, tz, ed, ef, kn, fx * nx + fy * ny + fz * nz


@njit
def _mesh_contact(i, k, w, xs, vs, ws, rad, smat, smass, wpoint, wv, wmat, prm, law, dt, wft, wmr, friction,
                  rolling, mesh):
    """Loads of mesh wall w on sphere i: the sum over its contacts, one per touched feature
    (:func:`demcli.kernels.mesh.wall_contacts`), of the plane wall's contact (:func:`_surface_contact`)
    at each feature's distance s and normal n: F = sum_m F(s_m, n_m) [N]. The nearest feature
    carries the sphere's springs against the mesh (row k: kept across triangle edges); the others
    (a concave corner) start theirs afresh each step. One face contact: the plane's arithmetic."""
    count, near, nrm, s = wall_features(mesh, w, wpoint[w, 0], wpoint[w, 1], wpoint[w, 2], xs[i, 0], xs[i, 1],
                                        xs[i, 2], rad[i])
    fresh_ft = np.zeros((1, 3))
    fresh_mr = np.zeros((1, 3))
    out = _surface_contact(i, w, rad[i] if count == 0 else s[near], 0.0 if count == 0 else nrm[near, 0],
                           0.0 if count == 0 else nrm[near, 1], 1.0 if count == 0 else nrm[near, 2], xs, vs, ws,
                           rad, smat, smass, wv, wmat, prm, law, dt, wft, wmr, k, friction, rolling)
    for m in range(count):
        if m == near:
            continue
        fresh_ft[0, :] = 0.0
        fresh_mr[0, :] = 0.0
        add = _surface_contact(i, w, s[m], nrm[m, 0], nrm[m, 1], nrm[m, 2], xs, vs, ws, rad, smat, smass, wv, wmat,
                               prm, law, dt, fresh_ft, fresh_mr, 0, friction, rolling)
        out = (out[0] + add[0], out[1] + add[1], out[2] + add[2], out[3] + add[3], out[4] + add[4], out[5] + add[5],
               out[6] + add[6], out[7] + add[7], out[8] + add[8], out[9] + add[9])
    return out


@njit
def place(g, bd, flags, xref, lim2, rebuild):
    """Clumps: the members follow their body (spheres-only scenes: nothing to do)."""
    if flags[F_CLUMPS]:
        _place_members(bd.x, bd.v, bd.w, bd.q, g.xs, g.vs, g.ws, g.sbody, g.soff, xref, lim2, rebuild)


@njit(inline="always")
def volumetric(g):
    """Sphere contacts need no depth or separation cache; normal forces pass through the centres."""
    return False


@njit
def spin_rotors(g, mb, xref):
    """Single spheres (no clump members, mb None) are spin rotors: xref; clumps: None."""
    return choose(mb, xref, None)


@njit
def primitives(g, bd):
    """The spheres themselves: (positions, radii, body of each)."""
    return g.xs, g.rad, g.sbody


@njit
def pair_pass(g, bd, nl, prm, law, flags, dt, frow, trow, erow, bonds, bprm, broke):
    """Sphere pairs into their rows, then the bonds (their forces into the same row sums)."""
    friction = flags[F_FRICTION]
    rolling = flags[F_ROLLING]
    energy = flags[F_ENERGY]
    _pair_forces(nl.start, nl.pj, g.xs, g.vs, g.ws, g.rad, g.mat, g.smass, prm, law, dt, nl.ft, nl.mr, friction,
                 rolling, energy, nl.fc, nl.tj, nl.act, nl.epair, frow, trow, erow, None, g.cell)
    if flags[F_BONDS]:
        bond_forces(bonds, bprm, g.xs, g.vs, g.ws, g.rad, g.mat, g.smass, prm, law, dt, friction, rolling, energy,
                    frow, trow, erow, broke)


@njit
def wall_pass(g, bd, nl, wa, prm, law, flags, dt):
    """Every sphere-wall contact into its own rows: wfc[k] (force on the sphere, servo stiffness,
    normal force), wtq[k] (torque), wen[k] (dashpot and slip losses, with energy)."""
    _wall_forces(nl.wprim, nl.wwall, g.xs, g.vs, g.ws, g.rad, g.mat, g.smass, wa.kind, wa.point, wa.normal,
                 wa.radius, wa.v, wa.material, prm, law, dt, nl.wft, nl.wmr, flags[F_FRICTION], flags[F_ROLLING],
                 flags[F_ENERGY], nl.wfc, nl.wtq, nl.wen, None, wa.mesh)


@njit(parallel=True, internal=True)
def _wall_forces(wprim, wwall, xs, vs, ws, rad, smat, smass, wkind, wpoint, wnormal, wradius, wv, wmat, prm, law,
                 dt, wft, wmr, friction, rolling, energy, wfc, wtq, wen, split, mesh):
    """Every sphere-wall contact k (prange over contacts: each writes its own rows); ``split``
    as in :func:`_pair_forces` (a mixed scene: the contacts of primitives below it only); ``mesh``
    the MeshArrays of the mesh walls (read only), None without (the mesh path is then not compiled:
    :mod:`demcli.kernels.switch`)."""
    for k in prange(wprim.shape[0]):
        if split is not None:
            if wprim[k] >= split:
                continue
        if mesh is None:
            out = _wall_contact(wprim[k], k, wwall[k], xs, vs, ws, rad, smat, smass, wkind, wpoint, wnormal, wradius,
                                wv, wmat, prm, law, dt, wft, wmr, friction, rolling)
        elif wkind[wwall[k]] == MESH:
            out = _mesh_contact(wprim[k], k, wwall[k], xs, vs, ws, rad, smat, smass, wpoint, wv, wmat, prm, law, dt,
                                wft, wmr, friction, rolling, mesh)
        else:
            out = _wall_contact(wprim[k], k, wwall[k], xs, vs, ws, rad, smat, smass, wkind, wpoint, wnormal, wradius,
                                wv, wmat, prm, law, dt, wft, wmr, friction, rolling)
        wfx, wfy, wfz, wtx, wty, wtz, ed, ef, kn, wfn = out
        wfc[k, 0] = wfx
        wfc[k, 1] = wfy
        wfc[k, 2] = wfz
        wfc[k, 3] = kn
        wfc[k, 4] = wfn
        wtq[k, 0] = wtx
        wtq[k, 1] = wty
        wtq[k, 2] = wtz
        if energy:
            wen[k, 0] = ed
            wen[k, 1] = ef


@njit
def worst_overlap(g, nl, wa):
    """Largest overlap ratio: sphere pairs overlap / smaller radius, sphere-wall overlap / radius;
    returns (ratio, i, j) with j = -1 for a wall (i = -1 when nothing touches)."""
    xs = g.xs
    rad = g.rad
    pi = nl.pi
    pj = nl.pj
    act = nl.act
    worst = 0.0
    wi = -1
    wj = -1
    for c in range(pi.shape[0]):
        if act[c]:
            i = pi[c]
            j = pj[c]
            dx, dy, dz = min_image(g.cell, xs[i, 0] - xs[j, 0], xs[i, 1] - xs[j, 1], xs[i, 2] - xs[j, 2])
            d = math.sqrt(dx ** 2 + dy ** 2 + dz ** 2)
            ratio = (rad[i] + rad[j] - d) / min(rad[i], rad[j])
            if ratio > worst:
                worst = ratio
                wi = i
                wj = j
    for k in range(nl.wprim.shape[0]):
        i = nl.wprim[k]
        wl = nl.wwall[k]
        sd, _, _, _ = surface_distance(wa.kind[wl], wa.point[wl, 0], wa.point[wl, 1], wa.point[wl, 2],
                                       wa.normal[wl, 0], wa.normal[wl, 1], wa.normal[wl, 2], wa.radius[wl], xs[i, 0],
                                       xs[i, 1], xs[i, 2], wa.mesh, wl, rad[i])
        ratio = (rad[i] - sd) / rad[i]
        if ratio > worst:
            worst = ratio
            wi = i
            wj = -1
    return worst, wi, wj


@njit
def total_strain_energy(pi, pj, xs, rad, smat, prm, law, ft, mr, friction, rolling,
                        wstart, wwall, wkind, wpoint, wnormal, wradius, wmat, wft, wmr, mesh, cell):
    """Elastic energy in all contacts [J] (serial, fixed order; ``cell``: periodic cell or None)."""
    e = 0.0
    for c in range(pi.shape[0]):
        i = pi[c]
        j = pj[c]
        dx, dy, dz = min_image(cell, xs[i, 0] - xs[j, 0], xs[i, 1] - xs[j, 1], xs[i, 2] - xs[j, 2])
        d = math.sqrt(dx ** 2 + dy ** 2 + dz ** 2)
        delta = rad[i] + rad[j] - d
        if delta > 0.0:
            e += strain_energy(law, prm, smat[i], smat[j], delta, rad[i] * rad[j] / (rad[i] + rad[j]),
                               ft, mr, c, friction, rolling)
    return e + wall_strain_energy(xs, rad, smat, prm, law, wstart, wwall, wkind, wpoint, wnormal, wradius, wmat, wft,
                                  wmr, friction, rolling, mesh)


@njit
def wall_strain_energy(xs, rad, smat, prm, law, wstart, wwall, wkind, wpoint, wnormal, wradius, wmat, wft, wmr,
                       friction, rolling, mesh):
    """Elastic energy in the wall contacts of the spheres 0..len(xs)-1 [J] (serial, fixed order);
    ``mesh``: the mesh walls' MeshArrays, None without."""
    e = 0.0
    for i in range(xs.shape[0]):
        for k in range(wstart[i], wstart[i + 1]):
            wl = wwall[k]
            if mesh is not None:  # compiled for scenes with mesh walls only
                if wkind[wl] == MESH:
                    e += _mesh_strain_energy(i, k, wl, xs, rad, smat, wmat, prm, law, wpoint, wft, wmr, friction,
                                             rolling, mesh)
                    continue
            sd, _, _, _ = wall_distance(wkind[wl], wpoint[wl, 0], wpoint[wl, 1], wpoint[wl, 2],
                                        wnormal[wl, 0], wnormal[wl, 1], wnormal[wl, 2], wradius[wl],
                                        xs[i, 0], xs[i, 1], xs[i, 2])
            delta = rad[i] - sd
            if delta > 0.0:
                e += strain_energy(law, prm, smat[i], wmat[wl], delta, rad[i], wft, wmr, k, friction, rolling)
    return e


@njit
def _mesh_strain_energy(i, k, wl, xs, rad, smat, wmat, prm, law, wpoint, wft, wmr, friction, rolling, mesh):
    """Elastic energy [J] of sphere i's contacts with mesh wall wl, each feature's, the springs
    (row k) in the nearest one's (:func:`_mesh_contact`)."""
    count, near, _, s = wall_features(mesh, wl, wpoint[wl, 0], wpoint[wl, 1], wpoint[wl, 2], xs[i, 0], xs[i, 1],
                                      xs[i, 2], rad[i])
    fresh = np.zeros((1, 3))
    e = 0.0
    for m in range(count):
        hist, mr, row = (wft, wmr, k) if m == near else (fresh, fresh, 0)
        e += strain_energy(law, prm, smat[i], wmat[wl], rad[i] - s[m], rad[i], hist, mr, row, friction, rolling)
    return e
