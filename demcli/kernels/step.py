"""The compiled time loop: velocity Verlet (kick-drift-kick) for rigid bodies of spheres.

One call advances a chunk of steps without returning to Python. Each step:

1. half kick and drift of every body (``_kick_drift``), with the displacement check
   that triggers a neighbour-list rebuild when a sphere has moved more than skin/2;
2. clumps only: member spheres follow their body (``_place_members``);
3. walls move (prescribed velocity, servo or force control from the last step);
4. rebuild of the pair and wall lists when needed, history carried over;
5. the pair pass: one force per pair into its own row (``_pair_forces``);
6. the gather: each sphere sums its rows through the CSR lists and its wall contacts
   (race-free, fixed order: bit-identical for any thread count); for plain spheres the
   second half kick is fused in, for clumps ``_body_loads`` sums members per body;
7. wall force sums and wall control;
8. every ``check_every`` steps: NaN/Inf, overlap and kinetic-energy guards.

Spheres-only scenes pass the body arrays as the sphere arrays (sphere i is body i), and
skip the member passes. Rotation of a single sphere integrates omega only (its
orientation has no effect on the physics and is not tracked); clumps integrate angular
momentum with an implicit-midpoint rotation (q_{n+1} = exp(dt omega_{n+1/2}) q_n, with
omega_{n+1/2} from L_{n+1/2} in the midpoint frame), which conserves |L| exactly and
reproduces torque-free precession.
"""

import math

import numpy as np
from numba import prange

from demcli.jit import njit
from demcli.kernels import quat
from demcli.kernels.bonds import bond_gather, bond_pass, drop_bonded
from demcli.kernels.contact import (HERTZ, P_CN, P_ESTAR, P_KN, P_ZETA, contact_law, pair_kinematics,
                                   strain_energy)
from demcli.kernels.neighbors import build_pairs, build_reverse, build_wall_pairs, carry_history
from demcli.kernels.walls import (FORCE, PRESSURE, SERVO, VELOCITY, W_AMPLITUDE, W_AREA, W_FREQ,
                                  W_GAIN, W_MASS, W_PHASE, W_RATE, W_START, W_TARGET, W_VMAX, applied_force,
                                  wall_distance)

from demcli.kernels.layout import (C_BODY, C_BONDS, C_CHECK, C_DAMPING, C_ENERGY, C_FRICTION, C_GATHER,
                                   C_GRAVITY, C_KICK, C_MEMBERS, C_PAIRS, C_REBUILD, C_ROLLING,
                                   C_WALLCTRL, C_WALLMOVE, F_BONDS, F_CLUMPS, F_ENERGY, F_FRICTION, F_GRAVITY,
                                   F_LOCAL, F_PLANAR, F_ROLLING, F_VISCOUS, FIX_ROTATION,
                                   FIX_TRANSLATION, OK, BAD_NUMBER, BAD_OVERLAP, BAD_ENERGY)


@njit(inline="always")
def _kick_v(v, i, fx, fy, fz, im, planar):
    """v_i += F im (im = dt / 2m); planar mode keeps v_z = 0."""
    v[i, 0] += fx * im
    v[i, 1] += fy * im
    v[i, 2] += fz * im
    if planar:
        v[i, 2] = 0.0


@njit(inline="always")
def _kick_w(w, i, tx, ty, tz, iv, planar):
    """omega_i += T iv (iv = dt / 2I, isotropic inertia); planar mode keeps only omega_z."""
    w[i, 0] += tx * iv
    w[i, 1] += ty * iv
    w[i, 2] += tz * iv
    if planar:
        w[i, 0] = 0.0
        w[i, 1] = 0.0


@njit(inline="always")
def _drift(x, v, i, dt, xref, lim2, rebuild):
    """x_i += v_i dt; flags a list rebuild once x_i is more than skin/2 from where it was listed."""
    x[i, 0] += v[i, 0] * dt
    x[i, 1] += v[i, 1] * dt
    x[i, 2] += v[i, 2] * dt
    dx = x[i, 0] - xref[i, 0]
    dy = x[i, 1] - xref[i, 1]
    dz = x[i, 2] - xref[i, 2]
    if dx * dx + dy * dy + dz * dz > lim2:
        rebuild[0] = 1


@njit(parallel=True)
def _kick_drift(x, v, w, q, L, f, tq, mass, inert, bflags, dt, rotate_bodies, clumps, planar,
                xref, lim2, rebuild):
    """First half kick and drift; sets rebuild[0] when a sphere body moved > skin/2."""
    h = 0.5 * dt
    for b in prange(x.shape[0]):
        fl = bflags[b]
        if fl & FIX_TRANSLATION == 0:
            _kick_v(v, b, f[b, 0], f[b, 1], f[b, 2], h / mass[b], planar)
        if rotate_bodies and fl & FIX_ROTATION == 0:
            if clumps:
                _rotate_rigid(b, w, q, L, tq, inert, dt, planar)
            else:
                _kick_w(w, b, tq[b, 0], tq[b, 1], tq[b, 2], h / inert[b, 0], planar)
        if clumps:  # members are checked when placed
            x[b, 0] += v[b, 0] * dt
            x[b, 1] += v[b, 1] * dt
            x[b, 2] += v[b, 2] * dt
        else:
            _drift(x, v, b, dt, xref, lim2, rebuild)


@njit(inline="always")
def _omega_from_L(qw, qx, qy, qz, lx, ly, lz, i0, i1, i2):
    """World angular velocity from world angular momentum and principal inertia."""
    bx, by, bz = quat.rotate_inv(qw, qx, qy, qz, lx, ly, lz)
    return quat.rotate(qw, qx, qy, qz, bx / i0, by / i1, bz / i2)


@njit(inline="always")
def _rotate_rigid(b, w, q, L, tq, inert, dt, planar):
    """Half kick of L, then q_{n+1} = exp(dt w_half) q_n with w_half at the midpoint frame."""
    h = 0.5 * dt
    L[b, 0] += h * tq[b, 0]
    L[b, 1] += h * tq[b, 1]
    L[b, 2] += h * tq[b, 2]
    if planar:
        L[b, 0] = 0.0
        L[b, 1] = 0.0
    qw, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    i0, i1, i2 = inert[b, 0], inert[b, 1], inert[b, 2]
    wx, wy, wz = _omega_from_L(qw, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2], i0, i1, i2)
    for _ in range(3):  # fixed point for the midpoint orientation
        ew, ex, ey, ez = quat.exp_rotation(wx, wy, wz, h)
        mw, mx, my, mz = quat.mul(ew, ex, ey, ez, qw, qx, qy, qz)
        wx, wy, wz = _omega_from_L(mw, mx, my, mz, L[b, 0], L[b, 1], L[b, 2], i0, i1, i2)
    ew, ex, ey, ez = quat.exp_rotation(wx, wy, wz, dt)
    nw, nx, ny, nz = quat.mul(ew, ex, ey, ez, qw, qx, qy, qz)
    nw, nx, ny, nz = quat.normalize(nw, nx, ny, nz)
    q[b, 0] = nw
    q[b, 1] = nx
    q[b, 2] = ny
    q[b, 3] = nz
    w[b, 0] = wx
    w[b, 1] = wy
    w[b, 2] = wz


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


@njit(parallel=True)
def _pair_forces(start, pj, xs, vs, ws, rad, smat, smass, prm, law, dt, ft, mr, friction, rolling,
                 energy, fc, tj, act, epair, frow, trow, erow):
    """Force, torques and dissipation of every listed pair, each pair writing its own row.

    Walks the CSR rows (sphere i, then its j > i), so i's data is loaded once per row, and
    the row's owner sums i's side of its pairs into frow/trow/erow[i] (race-free); the
    gather then adds only the j sides.
    """
    for i in prange(start.shape[0] - 1):
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
            dx = xi0 - xs[j, 0]
            dy = xi1 - xs[j, 1]
            dz = xi2 - xs[j, 2]
            rj = rad[j]
            rs = ri + rj
            d2 = dx * dx + dy * dy + dz * dz
            if d2 >= rs * rs:
                if act[c]:  # a contact that just opened drops its history (most listed pairs never touch)
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
            ai = ri - 0.5 * delta
            aj = rj - 0.5 * delta
            vx, vy, vz, wx, wy, wz = pair_kinematics(vs, ws, i, j, nx, ny, nz, ai, aj)
            mi = smass[i]
            mj = smass[j]
            fx, fy, fz, mx, my, mz, ed, ef = contact_law(
                law, prm, smat[i], smat[j], delta, nx, ny, nz, vx, vy, vz,
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
    """Force and torque on sphere i from wall w (history row k); zero when apart."""
    s, nx, ny, nz = wall_distance(wkind[w], wpoint[w, 0], wpoint[w, 1], wpoint[w, 2],
                                  wnormal[w, 0], wnormal[w, 1], wnormal[w, 2], wradius[w],
                                  xs[i, 0], xs[i, 1], xs[i, 2])
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
    a = s  # branch from the centre to the contact point on the wall surface
    wix, wiy, wiz = ws[i, 0], ws[i, 1], ws[i, 2]
    vx = vs[i, 0] - wv[w, 0] - a * (wiy * nz - wiz * ny)
    vy = vs[i, 1] - wv[w, 1] - a * (wiz * nx - wix * nz)
    vz = vs[i, 2] - wv[w, 2] - a * (wix * ny - wiy * nx)
    ma = smat[i]
    mb = wmat[w]
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


@njit(inline="always")
def _body_loads(fx, fy, fz, tx, ty, tz, m, ii, vx, vy, vz, wx, wy, wz, gravity, local, visc,
                use_gravity, use_local, use_visc):
    """Add gravity, local (Cundall) damping and mass-proportional damping to a body load.

    Local damping: F_d,k = -lambda |F_k| sign(v_k) per component (Cundall 1987);
    viscous: F_d = -alpha m v, T_d = -alpha I omega. Returns the loads and the power
    absorbed by damping [W].
    """
    if use_gravity:
        fx += m * gravity[0]
        fy += m * gravity[1]
        fz += m * gravity[2]
    p = 0.0
    if use_local:
        dfx = -local * abs(fx) * np.sign(vx)
        dfy = -local * abs(fy) * np.sign(vy)
        dfz = -local * abs(fz) * np.sign(vz)
        dtx = -local * abs(tx) * np.sign(wx)
        dty = -local * abs(ty) * np.sign(wy)
        dtz = -local * abs(tz) * np.sign(wz)
        fx += dfx
        fy += dfy
        fz += dfz
        tx += dtx
        ty += dty
        tz += dtz
        p -= dfx * vx + dfy * vy + dfz * vz + dtx * wx + dty * wy + dtz * wz
    if use_visc:
        a = visc * m
        b = visc * ii
        fx -= a * vx
        fy -= a * vy
        fz -= a * vz
        tx -= b * wx
        ty -= b * wy
        tz -= b * wz
        p += a * (vx * vx + vy * vy + vz * vz) + b * (wx * wx + wy * wy + wz * wz)
    return fx, fy, fz, tx, ty, tz, p


@njit(parallel=True)
def _gather(frow, trow, erow, rstart, rlist, fc, tj, act, epair, wstart, wwall, wfc,
            xs, vs, ws, rad, smat, smass, wkind, wpoint, wnormal, wradius, wv, wmat, prm, law, dt,
            wft, wmr, flags, fs, ts, esph,
            # fused second half kick (spheres-only scenes)
            fuse, v, w, mass, inert, bflags, ebody, gravity, local, visc,
            # fused first half kick and drift of the next step
            drift_next, x, xref, lim2, rebuild):
    """Per-sphere sum of pair and wall forces; with ``fuse``, body loads and half kick too.

    With ``drift_next`` (spheres-only, not the chunk's last step) the sphere also takes the
    next step's first half kick and drift, the same arithmetic as :func:`_kick_drift`.
    """
    friction = flags[F_FRICTION]
    rolling = flags[F_ROLLING]
    energy = flags[F_ENERGY]
    pair_torque = friction or rolling
    torque = pair_torque or flags[F_BONDS]  # bonds add theirs to trow
    h = 0.5 * dt
    for i in prange(xs.shape[0]):
        # i's side of its own row, summed by the pair pass in the same order
        fx = frow[i, 0]
        fy = frow[i, 1]
        fz = frow[i, 2]
        tx = 0.0
        ty = 0.0
        tz = 0.0
        e0 = 0.0
        e1 = 0.0
        if torque:
            tx = trow[i, 0]
            ty = trow[i, 1]
            tz = trow[i, 2]
        if energy:
            e0 = erow[i, 0]
            e1 = erow[i, 1]
        for a in range(rstart[i], rstart[i + 1]):
            c = rlist[a]
            if act[c]:
                fx -= fc[c, 0]
                fy -= fc[c, 1]
                fz -= fc[c, 2]
                if pair_torque:
                    tx += tj[c, 0]
                    ty += tj[c, 1]
                    tz += tj[c, 2]
                if energy:
                    e0 += epair[c, 0]
                    e1 += epair[c, 1]
        for k in range(wstart[i], wstart[i + 1]):
            wfx, wfy, wfz, wtx, wty, wtz, ed, ef, kn, wfn = _wall_contact(
                i, k, wwall[k], xs, vs, ws, rad, smat, smass, wkind, wpoint, wnormal, wradius, wv,
                wmat, prm, law, dt, wft, wmr, friction, rolling)
            wfc[k, 0] = wfx
            wfc[k, 1] = wfy
            wfc[k, 2] = wfz
            wfc[k, 3] = kn
            wfc[k, 4] = wfn
            fx += wfx
            fy += wfy
            fz += wfz
            tx += wtx
            ty += wty
            tz += wtz
            # a wall contact's loss is wholly the sphere's (pairs split theirs in half)
            e0 += 2.0 * ed
            e1 += 2.0 * ef
        if energy:
            esph[i, 0] += 0.5 * e0
            esph[i, 1] += 0.5 * e1
        if not fuse:
            fs[i, 0] = fx
            fs[i, 1] = fy
            fs[i, 2] = fz
            ts[i, 0] = tx
            ts[i, 1] = ty
            ts[i, 2] = tz
            continue
        # spheres-only: sphere i is body i
        fl = bflags[i]
        m = mass[i]
        ii = inert[i, 0]
        fx, fy, fz, tx, ty, tz, p = _body_loads(
            fx, fy, fz, tx, ty, tz, m, ii, v[i, 0], v[i, 1], v[i, 2], w[i, 0], w[i, 1], w[i, 2],
            gravity, local, visc, flags[F_GRAVITY], flags[F_LOCAL], flags[F_VISCOUS])
        if energy:
            ebody[i] += p * dt
        planar = flags[F_PLANAR]
        im = h / m
        iv = h / ii
        if fl & FIX_TRANSLATION == 0:
            _kick_v(v, i, fx, fy, fz, im, planar)
        if torque and fl & FIX_ROTATION == 0:
            _kick_w(w, i, tx, ty, tz, iv, planar)
        if not drift_next:
            # the loads are kept only where the next kick reads them from memory: at the chunk's
            # end (a fused step uses its registers; skipping the stores saves 48 B per sphere-step)
            fs[i, 0] = fx
            fs[i, 1] = fy
            fs[i, 2] = fz
            if torque:
                ts[i, 0] = tx
                ts[i, 1] = ty
                ts[i, 2] = tz
            continue
        # the next step's first half kick and drift
        if fl & FIX_TRANSLATION == 0:
            _kick_v(v, i, fx, fy, fz, im, planar)
        if torque and fl & FIX_ROTATION == 0:
            _kick_w(w, i, tx, ty, tz, iv, planar)
        _drift(x, v, i, dt, xref, lim2, rebuild)


@njit(parallel=True)
def _clump_loads(mstart, mlist, xs, fs_s, ts_s, x, v, w, q, L, f, tq, mass, inert, bflags, flags,
                 gravity, local, visc, dt, ebody):
    """Sum member forces into their bodies, add body loads, second half kick (clumps)."""
    h = 0.5 * dt
    for b in prange(x.shape[0]):
        fx = 0.0
        fy = 0.0
        fz = 0.0
        tx = 0.0
        ty = 0.0
        tz = 0.0
        for a in range(mstart[b], mstart[b + 1]):
            s = mlist[a]
            rx = xs[s, 0] - x[b, 0]
            ry = xs[s, 1] - x[b, 1]
            rz = xs[s, 2] - x[b, 2]
            fx += fs_s[s, 0]
            fy += fs_s[s, 1]
            fz += fs_s[s, 2]
            tx += ts_s[s, 0] + ry * fs_s[s, 2] - rz * fs_s[s, 1]
            ty += ts_s[s, 1] + rz * fs_s[s, 0] - rx * fs_s[s, 2]
            tz += ts_s[s, 2] + rx * fs_s[s, 1] - ry * fs_s[s, 0]
        m = mass[b]
        imean = (inert[b, 0] + inert[b, 1] + inert[b, 2]) / 3.0
        fx, fy, fz, tx, ty, tz, p = _body_loads(
            fx, fy, fz, tx, ty, tz, m, imean, v[b, 0], v[b, 1], v[b, 2], w[b, 0], w[b, 1], w[b, 2],
            gravity, local, visc, flags[F_GRAVITY], flags[F_LOCAL], flags[F_VISCOUS])
        if flags[F_ENERGY]:
            ebody[b] += p * dt
        f[b, 0] = fx
        f[b, 1] = fy
        f[b, 2] = fz
        tq[b, 0] = tx
        tq[b, 1] = ty
        tq[b, 2] = tz
        fl = bflags[b]
        if fl & FIX_TRANSLATION == 0:
            _kick_v(v, b, fx, fy, fz, h / m, flags[F_PLANAR])
        if fl & FIX_ROTATION == 0:
            L[b, 0] += h * tx
            L[b, 1] += h * ty
            L[b, 2] += h * tz
            if flags[F_PLANAR]:
                L[b, 0] = 0.0
                L[b, 1] = 0.0
            wx, wy, wz = _omega_from_L(q[b, 0], q[b, 1], q[b, 2], q[b, 3], L[b, 0], L[b, 1], L[b, 2],
                                       inert[b, 0], inert[b, 1], inert[b, 2])
            w[b, 0] = wx
            w[b, 1] = wy
            w[b, 2] = wz


@njit(inline="always")
def move_walls(wpoint, wref, wv, dt, lim2, rebuild):
    """Walls translate by v dt; one that moved more than skin/2 since the last list build
    flags a rebuild (wref: displacement since then)."""
    for k in range(wv.shape[0]):
        for d in range(3):
            wpoint[k, d] += wv[k, d] * dt
            wref[k, d] += wv[k, d] * dt
        if wref[k, 0] ** 2 + wref[k, 1] ** 2 + wref[k, 2] ** 2 > lim2:
            rebuild[0] = 1


@njit
def move_radii(wctrl, wprm, wradius, wref, dt, lim2, rebuild):
    """Pressure-loaded cylinders change their radius by W_RATE dt; one whose radius moved
    more than skin/2 since the last list build flags a rebuild (wref[w, 0] holds that change)."""
    for k in range(wctrl.shape[0]):
        if wctrl[k] == PRESSURE:
            wradius[k] += wprm[k, W_RATE] * dt
            wref[k, 0] += wprm[k, W_RATE] * dt
            if wref[k, 0] ** 2 > lim2:
                rebuild[0] = 1


@njit
def _mark_history(act, ft, mr, friction, rolling):
    """Flag carried pairs with history as active, so the pair pass clears it if they opened."""
    for c in range(act.shape[0]):
        if friction and (ft[c, 0] != 0.0 or ft[c, 1] != 0.0 or ft[c, 2] != 0.0):
            act[c] = 1
        if rolling and (mr[c, 0] != 0.0 or mr[c, 1] != 0.0 or mr[c, 2] != 0.0):
            act[c] = 1


@njit
def _wall_control(time, dt, wstart_n, wwall, wfc, wnormal, wv, wctrl, wprm, wforce, wkn, eacc, energy):
    """Sum contact forces on each wall (fixed order), then set each wall's velocity."""
    nw = wv.shape[0]
    fnsum = np.zeros(nw)  # normal force the particles press on each wall with (wfc column 4: spheres)
    for w in range(nw):
        wforce[w, 0] = 0.0
        wforce[w, 1] = 0.0
        wforce[w, 2] = 0.0
        wkn[w] = 0.0
    for k in range(wstart_n):
        w = wwall[k]
        wforce[w, 0] -= wfc[k, 0]
        wforce[w, 1] -= wfc[k, 1]
        wforce[w, 2] -= wfc[k, 2]
        if wfc.shape[1] > 4:
            fnsum[w] += wfc[k, 4]
        if wfc[k, 3] > 0.0 and (wfc[k, 0] != 0.0 or wfc[k, 1] != 0.0 or wfc[k, 2] != 0.0):
            wkn[w] += wfc[k, 3]
    for w in range(nw):
        nx, ny, nz = wnormal[w, 0], wnormal[w, 1], wnormal[w, 2]
        if energy:
            # work done by the wall on the particles this step
            eacc[0] -= (wforce[w, 0] * wv[w, 0] + wforce[w, 1] * wv[w, 1] + wforce[w, 2] * wv[w, 2]) * dt
        mode = wctrl[w]
        if mode == PRESSURE:
            # a membrane of mass M: M dR'/dt = (normal force of the particles) - pressure x area
            wprm[w, W_RATE] += dt * (fnsum[w] - wprm[w, W_TARGET] * wprm[w, W_AREA]) / wprm[w, W_MASS]
        elif mode == SERVO:
            # compressive stress carried by the wall (particles push it along -n)
            sig = -(wforce[w, 0] * nx + wforce[w, 1] * ny + wforce[w, 2] * nz) / wprm[w, W_AREA]
            err = wprm[w, W_TARGET] - sig
            vmax = wprm[w, W_VMAX]
            if wkn[w] > 0.0:
                vn = wprm[w, W_GAIN] * wprm[w, W_AREA] * err / (wkn[w] * dt)
            else:
                vn = vmax if err > 0.0 else -vmax
            vn = min(vmax, max(-vmax, vn))
            wv[w, 0] = vn * nx
            wv[w, 1] = vn * ny
            wv[w, 2] = vn * nz
        elif mode == FORCE:
            # applied force pushes the wall into the domain (+n)
            fa = applied_force(wprm[w, W_TARGET], wprm[w, W_AMPLITUDE], wprm[w, W_FREQ], wprm[w, W_PHASE],
                               wprm[w, W_START], time)
            fn = fa + wforce[w, 0] * nx + wforce[w, 1] * ny + wforce[w, 2] * nz
            vn = wv[w, 0] * nx + wv[w, 1] * ny + wv[w, 2] * nz + dt * fn / wprm[w, W_MASS]
            wv[w, 0] = vn * nx
            wv[w, 1] = vn * ny
            wv[w, 2] = vn * nz


@njit
def _check(x, v, w, L, mass, inert, clumps, pi, pj, act, xs, rad, overlap_limit, ke_limit, info,
           wsph, wwall, wkind, wpoint, wnormal, wradius):
    """Guards: NaN/Inf in body state, overlap ratio (sphere pairs: overlap / smaller radius;
    sphere-wall: overlap / radius, info[1] = -1), runaway kinetic energy."""
    ke = 0.0
    for b in range(x.shape[0]):
        s = 0.0
        for d in range(3):
            s += x[b, d] + v[b, d] + w[b, d]
        if not math.isfinite(s):
            info[0] = b
            return BAD_NUMBER
        ke += 0.5 * mass[b] * (v[b, 0] ** 2 + v[b, 1] ** 2 + v[b, 2] ** 2)
        if clumps:
            ke += 0.5 * (w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2])
        else:
            ke += 0.5 * inert[b, 0] * (w[b, 0] ** 2 + w[b, 1] ** 2 + w[b, 2] ** 2)
    worst = 0.0
    wc = -1
    for c in range(pi.shape[0]):
        if act[c]:
            i = pi[c]
            j = pj[c]
            d = math.sqrt((xs[i, 0] - xs[j, 0]) ** 2 + (xs[i, 1] - xs[j, 1]) ** 2 + (xs[i, 2] - xs[j, 2]) ** 2)
            ratio = (rad[i] + rad[j] - d) / min(rad[i], rad[j])
            if ratio > worst:
                worst = ratio
                wc = c
    wi = -1
    for k in range(wsph.shape[0]):
        i = wsph[k]
        wl = wwall[k]
        sd, _, _, _ = wall_distance(wkind[wl], wpoint[wl, 0], wpoint[wl, 1], wpoint[wl, 2], wnormal[wl, 0],
                                    wnormal[wl, 1], wnormal[wl, 2], wradius[wl], xs[i, 0], xs[i, 1], xs[i, 2])
        ratio = (rad[i] - sd) / rad[i]
        if ratio > worst:
            worst = ratio
            wi = i
    info[2] = worst
    info[3] = ke
    if worst > overlap_limit:
        if wi >= 0:
            info[0] = wi
            info[1] = -1
        else:
            info[0] = pi[wc]
            info[1] = pj[wc]
        return BAD_OVERLAP
    if ke > ke_limit:
        return BAD_ENERGY
    return OK


@njit
def run_steps(nsteps, time, dt, law, flags, prm, gravity, local, visc,
              bodies, mass, inert, bflags,
              spheres, rad, smat, smass, sbody, soff, mstart, mlist,
              wkind, wpoint, wnormal, wradius, wv, wmat, wctrl, wprm, wforce, wkn,
              nl, skin, max_cells,
              esph, ebody, eacc, bl, bprm,
              check_every, overlap_limit, ke_limit, counters, info, force_rebuild, step0, prime):
    """Advance ``nsteps`` steps; returns (status, steps_done, time, nl).

    Args:
        bodies: (x, v, w, q, L, f, tq) float64 arrays, (n_b, 3) or (n_b, 4) for q.
        spheres: (xs, vs, ws, fs, ts) float64 (n_s, 3); the body arrays themselves for
            spheres-only scenes.
        nl: neighbour state (start, pi, pj, rstart, rlist, ft, mr, fc, tj, act, epair,
            wstart, wsph, wwall, wft, wmr, wfc, xref, wref); rebuilt here when needed.
        bl: bond state (bstart, bj, brstart, brlist, model, state, hist, bfc, btj, bed), see
            :mod:`demcli.kernels.bonds`; bprm: (n_models, N_BPARAMS) bond-model table.
        esph: (n_s, 2) cumulative contact damping and friction losses [J];
        ebody: (n_b,) cumulative body damping losses [J]; eacc: (1,) wall work [J].
        counters: (N_COUNTERS,) int64 pass counters, incremented per executed pass.
        info: (4,) float64 diagnosis of a failed guard (indices, worst overlap, kinetic energy).
        force_rebuild: build the lists before the first step (fresh or resumed system).
        step0: global step count at entry; guards run at global multiples of check_every,
            and after global step 1.
        prime: before the first step, evaluate the loads at the current state with a step of
            zero length (no motion, no history or energy increments), so the first half kick
            uses F(x_0) (a fresh stage; a resumed one keeps its stored loads).
    """
    x, v, w, q, L, f, tq = bodies
    xs, vs, ws, fs, ts = spheres
    (start, pi, pj, rstart, rlist, ft, mr, fc, tj, act, epair,
     wstart, wsph, wwall, wft, wmr, wfc, xref, wref) = nl
    bstart, bj, brstart, brlist, bmodel, bstate, bhist, bfc, btj, bed = bl
    clumps = flags[F_CLUMPS]
    friction = flags[F_FRICTION]
    rolling = flags[F_ROLLING]
    energy = flags[F_ENERGY]
    bonds = flags[F_BONDS]
    rotate_bodies = friction or rolling or clumps or bonds
    broke = np.zeros(1, np.int64)
    lim2 = (0.5 * skin) ** 2
    rebuild = np.zeros(1, np.int64)
    rebuild[0] = 1 if force_rebuild else 0
    nw = wv.shape[0]
    ns = xs.shape[0]
    # per-sphere sums of each sphere's own pair row (race-free: the row owner writes them)
    frow = np.zeros((ns, 3))
    trow = np.zeros((ns if friction or rolling or bonds else 0, 3))
    erow = np.zeros((ns if energy else 0, 2))
    status = OK
    n = 0
    drifted = False  # the next step's kick and drift were fused into the last gather
    while n < nsteps or prime:
        h = 0.0 if prime else dt
        if prime:
            rebuild[0] = 1
        elif drifted:
            drifted = False
        else:
            _kick_drift(x, v, w, q, L, f, tq, mass, inert, bflags, dt, rotate_bodies, clumps,
                        flags[F_PLANAR], xref, lim2, rebuild)
            counters[C_KICK] += 1
        if clumps:
            _place_members(x, v, w, q, xs, vs, ws, sbody, soff, xref, lim2, rebuild)
            counters[C_MEMBERS] += 1
        if nw > 0 and not prime:
            move_walls(wpoint, wref, wv, dt, lim2, rebuild)
            move_radii(wctrl, wprm, wradius, wref, dt, lim2, rebuild)
            counters[C_WALLMOVE] += 1
        if rebuild[0]:
            rebuild[0] = 0
            nstart, npi, npj = build_pairs(xs, rad, sbody, skin, max_cells)
            if bonds:
                nstart, npi, npj = drop_bonded(nstart, npi, npj, bstart, bj, bmodel, bstate, bhist, bprm)
            npair = npi.shape[0]
            nft = np.zeros((npair if friction else 0, 3))
            nmr = np.zeros((npair if rolling else 0, 3))
            carry_history(ns, nstart, npj, start, pj, ft, nft)
            carry_history(ns, nstart, npj, start, pj, mr, nmr)
            start, pi, pj, ft, mr = nstart, npi, npj, nft, nmr
            rstart, rlist = build_reverse(ns, pj)
            fc = np.empty((npair, 3))
            tj = np.zeros((npair if friction or rolling else 0, 3))
            act = np.zeros(npair, np.uint8)
            _mark_history(act, ft, mr, friction, rolling)
            epair = np.zeros((npair if energy else 0, 2))
            if nw > 0:
                nws, nwsph, nww = build_wall_pairs(xs, rad, skin, wkind, wpoint, wnormal, wradius)
                nq = nww.shape[0]
                nwft = np.zeros((nq if friction else 0, 3))
                nwmr = np.zeros((nq if rolling else 0, 3))
                carry_history(ns, nws, nww, wstart, wwall, wft, nwft)
                carry_history(ns, nws, nww, wstart, wwall, wmr, nwmr)
                wstart, wsph, wwall, wft, wmr = nws, nwsph, nww, nwft, nwmr
                wfc = np.zeros((nq, 5))
                wref[:, :] = 0.0
            xref = xs.copy()
            counters[C_REBUILD] += 1
        # spheres-only: fuse the next step's kick and drift into this gather, except after the
        # chunk's last step (the state between chunks has synchronized velocities) and the prime
        fuse_next = not clumps and not prime and n + 1 < nsteps
        _pair_forces(start, pj, xs, vs, ws, rad, smat, smass, prm, law, h, ft, mr, friction, rolling,
                     energy, fc, tj, act, epair, frow, trow, erow)
        counters[C_PAIRS] += 1
        if bonds:
            if not (friction or rolling):
                trow[:, :] = 0.0
            bond_pass(bstart, bj, bmodel, bstate, bhist, bprm, xs, vs, ws, rad, smat, smass, prm, law, h,
                      friction, rolling, bfc, btj, bed, frow, trow, erow, energy, broke)
            bond_gather(brstart, brlist, bfc, btj, bed, frow, trow, erow, energy)
            if broke[0]:
                broke[0] = 0
                rebuild[0] = 1
            counters[C_BONDS] += 1
        if friction:
            counters[C_FRICTION] += 1
        if rolling:
            counters[C_ROLLING] += 1
        if energy:
            counters[C_ENERGY] += 1
        if flags[F_GRAVITY]:
            counters[C_GRAVITY] += 1
        if flags[F_LOCAL] or flags[F_VISCOUS]:
            counters[C_DAMPING] += 1
        _gather(frow, trow, erow, rstart, rlist, fc, tj, act, epair, wstart, wwall, wfc,
                xs, vs, ws, rad, smat, smass, wkind, wpoint, wnormal, wradius, wv, wmat, prm, law, h,
                wft, wmr, flags, fs, ts, esph,
                not clumps, v, w, mass, inert, bflags, ebody, gravity, local, visc,
                fuse_next, x, xref, lim2, rebuild)
        counters[C_GATHER] += 1
        if fuse_next:
            drifted = True
            counters[C_KICK] += 1
        if clumps:
            _clump_loads(mstart, mlist, xs, fs, ts, x, v, w, q, L, f, tq, mass, inert, bflags, flags,
                         gravity, local, visc, h, ebody)
            counters[C_BODY] += 1
        if prime:
            prime = False
            continue
        n += 1
        time += dt
        if nw > 0:
            _wall_control(time, dt, wstart[ns], wwall, wfc, wnormal, wv, wctrl, wprm, wforce, wkn,
                          eacc, energy)
            counters[C_WALLCTRL] += 1
        gstep = step0 + n
        if check_every > 0 and (gstep % check_every == 0 or gstep == 1):
            status = _check(x, v, w, L, mass, inert, clumps, pi, pj, act, xs, rad, overlap_limit, ke_limit, info,
                            wsph, wwall, wkind, wpoint, wnormal, wradius)
            counters[C_CHECK] += 1
            if status != OK:
                break
    nl = (start, pi, pj, rstart, rlist, ft, mr, fc, tj, act, epair,
          wstart, wsph, wwall, wft, wmr, wfc, xref, wref)
    return status, n, time, nl


@njit
def total_strain_energy(pi, pj, xs, rad, smat, prm, law, ft, mr, friction, rolling,
                        wstart, wwall, wkind, wpoint, wnormal, wradius, wmat, wft, wmr):
    """Elastic energy in all contacts [J] (serial, fixed order)."""
    e = 0.0
    for c in range(pi.shape[0]):
        i = pi[c]
        j = pj[c]
        d = math.sqrt((xs[i, 0] - xs[j, 0]) ** 2 + (xs[i, 1] - xs[j, 1]) ** 2 + (xs[i, 2] - xs[j, 2]) ** 2)
        delta = rad[i] + rad[j] - d
        if delta > 0.0:
            e += strain_energy(law, prm, smat[i], smat[j], delta, rad[i] * rad[j] / (rad[i] + rad[j]),
                               ft, mr, c, friction, rolling)
    for i in range(xs.shape[0]):
        for k in range(wstart[i], wstart[i + 1]):
            wl = wwall[k]
            s, _, _, _ = wall_distance(wkind[wl], wpoint[wl, 0], wpoint[wl, 1], wpoint[wl, 2],
                                       wnormal[wl, 0], wnormal[wl, 1], wnormal[wl, 2], wradius[wl],
                                       xs[i, 0], xs[i, 1], xs[i, 2])
            delta = rad[i] - s
            if delta > 0.0:
                e += strain_energy(law, prm, smat[i], wmat[wl], delta, rad[i], wft, wmr, k, friction, rolling)
    return e
