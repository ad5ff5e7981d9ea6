"""Rigid-body motion shared by every shape: kicks, drift, rotation, body loads, actors, damping.

Velocity Verlet (kick-drift-kick). A body is a *spin rotor* (a single sphere: isotropic
inertia, omega integrated directly, orientation not tracked) or a *rigid rotor* (clumps,
polyhedra: world angular momentum L integrated, q_{n+1} = exp(dt omega_{n+1/2}) q_n with
omega_{n+1/2} from L_{n+1/2} in the midpoint frame, which keeps |L| exactly and reproduces
torque-free precession).

Half kick of a body with the adaptive damping factor (seed 002, Shao et al. 2017, eqs. 23-24):
v <- [v (1 - alpha h/2) + F h/m] / (1 + alpha h/2), L likewise; without that effect
alpha = 0 and the factors are exactly 1. Held components (FIX_X << d) keep their velocity,
FIX_TRANSLATION / FIX_ROTATION hold the whole body; planar mode keeps v_z = 0 and only the
z rotation. Actors (LOADED bodies: a loading plate, a sleeper) take their prescribed force
F0 + F1 sin(omega max(t - t0, 0) + phase) (table ``load``, columns L_*) and no body damping:
a damping force on a loading device would change the load it applies.

Body loads: gravity m g; local (Cundall 1987) damping F_d,k = -lambda |F_k| sign(v_k) per
component; constant mass-proportional damping F_d = -alpha m v, T_d = -alpha I omega
(spin rotors) or -alpha L (rigid rotors). The power absorbed by damping is booked per body.

The kernels import only numpy, numba and other kernels (no I/O).
"""

import math

import numpy as np
from numba import prange

from demcli.jit import njit
from demcli.kernels import quat
from demcli.kernels.layout import (F_ADAPTIVE, F_ENERGY, F_PLANAR, F_VISCOUS, FIX_ROTATION, FIX_TRANSLATION, FIX_X,
                                   FIX_XYZ, LOADED)
from demcli.kernels.switch import choose, on
from demcli.kernels.walls import (FORCE, PRESSURE, SERVO, W_AMPLITUDE, W_AREA, W_FREQ, W_GAIN, W_MASS,
                                  W_PHASE, W_RATE, W_START, W_TARGET, W_VMAX, applied_force)

# columns of the body load table load[b, :], read for LOADED bodies only: the prescribed force
# F(t) = F0 + F1 sin(omega max(t - t0, 0) + phase) [N] (a haversine from F_min to F_max:
# F0 = (F_min + F_max)/2, F1 = (F_max - F_min)/2 along the load direction, phase = -pi/2)
L_F0 = 0      # 3 columns: mean force [N]
L_F1 = 3      # 3 columns: amplitude [N]
L_OMEGA = 6   # angular frequency [rad/s]
L_PHASE = 7   # phase at t0 [rad]
L_T0 = 8      # time the oscillation starts [s]; before it the force stays at F0 + F1 sin(phase)
N_LOAD = 9

# adaptive damping state ``adamp`` (float64): alpha [1/s], kinetic energy at the end of the
# last step [J], last ratio R [-], the clamps [1/s]
A_ALPHA, A_KE, A_RATIO, A_MIN, A_MAX = range(5)
N_ADAMP = 5
ADAPT_UP = 1.1       # seed eq. 27: R < 0.5
ADAPT_DOWN = 0.99    # R > 0.5
ADAPT_TARGET = 0.5


@njit(internal=True)
def omega_from_L(qw, qx, qy, qz, lx, ly, lz, i0, i1, i2):
    """World angular velocity from world angular momentum and principal inertia."""
    bx, by, bz = quat.rotate_inv(qw, qx, qy, qz, lx, ly, lz)
    return quat.rotate(qw, qx, qy, qz, bx / i0, by / i1, bz / i2)


@njit(inline="always")
def rotate(b, w, q, L, inert, dt):
    """q_{n+1} = exp(dt w_half) q_n with w_half from the (already kicked) L_{n+1/2} at the
    midpoint frame (three fixed-point passes); w[b] = w_half."""
    h = 0.5 * dt
    qw, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    i0, i1, i2 = inert[b, 0], inert[b, 1], inert[b, 2]
    wx, wy, wz = omega_from_L(qw, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2], i0, i1, i2)
    for _ in range(3):  # fixed point for the midpoint orientation
        ew, ex, ey, ez = quat.exp_rotation(wx, wy, wz, h)
        mw, mx, my, mz = quat.mul(ew, ex, ey, ez, qw, qx, qy, qz)
        wx, wy, wz = omega_from_L(mw, mx, my, mz, L[b, 0], L[b, 1], L[b, 2], i0, i1, i2)
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


@njit(inline="always")
def drift(x, v, i, dt, xref, lim2, rebuild):
    """x_i += v_i dt; flags a list rebuild once x_i is more than skin/2 from where it was listed."""
    x[i, 0] += v[i, 0] * dt
    x[i, 1] += v[i, 1] * dt
    x[i, 2] += v[i, 2] * dt
    dx = x[i, 0] - xref[i, 0]
    dy = x[i, 1] - xref[i, 1]
    dz = x[i, 2] - xref[i, 2]
    if dx * dx + dy * dy + dz * dz > lim2:
        rebuild[0] = 1


@njit(inline="always")
def kick(b, fl, v, w, L, inert, m, im, iv, fx, fy, fz, tx, ty, tz, h, c1, c2, rotate_body, planar, adaptive):
    """Half kick of body b: v, and omega (spin rotor) or L (rigid rotor; omega is left to the
    caller, who rotates or recomputes it). L: the bodies' L (rigid rotors) or None (spin rotors:
    the switch is the argument's type, see :func:`rotors`). im = h / m, iv = h / I (spin rotors):
    computed once by the caller for both kicks of a fused step (a division costs more than the
    kick). With ``adaptive`` the damped form (c1, c2) and the
    energy measures of the adaptive damping (m sum ((v0 + v1)/2)^2, the rotational omega.L before
    the kick, and for spin rotors after it) are returned; zeros otherwise (c1 = c2 = 1: the plain
    kick, the same numbers)."""
    et = 0.0
    er0 = 0.0
    er1 = 0.0
    if fl & FIX_TRANSLATION == 0:
        if adaptive or fl & FIX_XYZ:
            s = 0.0
            for d in range(3):
                if fl & (FIX_X << d) == 0:
                    v0 = v[b, d]
                    v[b, d] = (v0 * c1 + (fx if d == 0 else fy if d == 1 else fz) * im) * c2
                    s += (0.5 * (v0 + v[b, d])) ** 2
            et = m * s
        else:
            v[b, 0] += fx * im
            v[b, 1] += fy * im
            v[b, 2] += fz * im
        if planar:
            v[b, 2] = 0.0
    if rotate_body and fl & FIX_ROTATION == 0:
        if L is not None:
            if adaptive:
                er0 = w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2]
                L[b, 0] = (L[b, 0] * c1 + h * tx) * c2
                L[b, 1] = (L[b, 1] * c1 + h * ty) * c2
                L[b, 2] = (L[b, 2] * c1 + h * tz) * c2
            else:
                L[b, 0] += h * tx
                L[b, 1] += h * ty
                L[b, 2] += h * tz
            if planar:
                L[b, 0] = 0.0
                L[b, 1] = 0.0
        else:
            ii = inert[b, 0]
            if adaptive:
                er0 = ii * (w[b, 0] ** 2 + w[b, 1] ** 2 + w[b, 2] ** 2)
                w[b, 0] = (w[b, 0] * c1 + tx * iv) * c2
                w[b, 1] = (w[b, 1] * c1 + ty * iv) * c2
                w[b, 2] = (w[b, 2] * c1 + tz * iv) * c2
                er1 = ii * (w[b, 0] ** 2 + w[b, 1] ** 2 + w[b, 2] ** 2)
            else:
                w[b, 0] += tx * iv
                w[b, 1] += ty * iv
                w[b, 2] += tz * iv
            if planar:
                w[b, 0] = 0.0
                w[b, 1] = 0.0
    return et, er0, er1


@njit
def rotors(spin, L):
    """The engine's rotor switch: L for rigid rotors (clumps, polyhedra), None for spin rotors
    (single spheres), decided by the type of ``spin`` (the shape's ``spin_rotors``: None for
    rigid rotors). Passed as the ``L`` of the motion kernels: with None, numba prunes their rigid
    rotor branches at compile time (:mod:`demcli.kernels.switch`)."""
    return choose(spin, L, None)


@njit(internal=True)
def damping_factors(alpha, h):
    """(c1, c2) of a half kick of length h with the adaptive alpha: (1 - alpha h/2, 1/(1 + alpha h/2))."""
    a = 0.5 * alpha * h
    return 1.0 - a, 1.0 / (1.0 + a)


@njit(parallel=True, internal=True)
def kick_drift(x, v, w, q, L, f, tq, mass, inert, bflags, dt, alpha, rotate_body, static, xref, lim2,
               rebuild, eabs):
    """First half kick, rotation (rigid rotors) and drift of every body; sets rebuild[0] when a
    body that is its own collision primitive moved > skin/2; eabs[b]: the adaptive damping's
    absorbed energy of this half kick. L: None for spin rotors (:func:`rotors`); static: the mask
    of the static switches (planar, adaptive), the literal 0 when none is on; xref: the list's
    reference positions, or None when clump members are the primitives (checked when placed):
    either drift is compiled out of the other scenes."""
    h = 0.5 * dt
    c1p, c2p = damping_factors(alpha, h)
    for b in prange(x.shape[0]):
        planar = on(static, F_PLANAR)  # constants when static is the literal 0
        adaptive = on(static, F_ADAPTIVE)
        fl = bflags[b]
        c1 = c1p
        c2 = c2p
        if fl & LOADED:
            c1 = 1.0
            c2 = 1.0
        im = h / mass[b]
        iv = 0.0
        if L is None:
            if rotate_body:
                iv = h / inert[b, 0]
        et, er0, er1 = kick(b, fl, v, w, L, inert, mass[b], im, iv, f[b, 0], f[b, 1], f[b, 2], tq[b, 0], tq[b, 1],
                            tq[b, 2], h, c1, c2, rotate_body, planar, adaptive)
        if L is not None:
            if rotate_body and fl & FIX_ROTATION == 0:
                rotate(b, w, q, L, inert, dt)
                if adaptive:
                    er1 = w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2]
        if adaptive and fl & LOADED == 0:
            ea = et
            ea += 0.5 * (er0 + er1)
            eabs[b] = alpha * h * ea
        if xref is None:
            x[b, 0] += v[b, 0] * dt
            x[b, 1] += v[b, 1] * dt
            x[b, 2] += v[b, 2] * dt
        else:
            drift(x, v, b, dt, xref, lim2, rebuild)


@njit(inline="always")
def body_loads(fx, fy, fz, tx, ty, tz, m, ii, vx, vy, vz, wx, wy, wz, gravity, local, visc,
               use_gravity, use_local, use_visc):
    """Add gravity, local (Cundall) damping and mass-proportional damping to a body load.

    Local damping: F_d,k = -lambda |F_k| sign(v_k) per component (Cundall 1987);
    viscous: F_d = -alpha m v, T_d = -alpha ii omega (ii: isotropic inertia). Returns the
    loads and the power absorbed by damping [W].
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


@njit(inline="always")
def finish_body(b, fx, fy, fz, tx, ty, tz, v, w, L, q, inert, mass, bflags, f, tq, load, gravity, damping, sw,
                dt, h, cc, alpha, tload, store, ebody, eabs, kevec):
    """Second half of a step for body b with its contact loads (fx..tz): body loads (gravity,
    damping, actor force), the loads kept in f/tq when ``store``, the second half kick (rigid
    rotors: omega from the kicked L), losses booked. Returns the total loads and the kick's
    h / m, h / I (for a fused next kick).

    The arrays are the Bodies' (load: the actor table); gravity (3,) and damping (local lambda,
    viscous alpha) the Params'; L: None for spin rotors (:func:`rotors`); sw: switches (gravity,
    local, rotate, and the mask of the static ones, the literal 0 when none is on: viscous,
    energy, planar, adaptive, :mod:`demcli.kernels.switch`); dt: the contact step (0 when
    priming); h: the half kick; cc: the adaptive damping factors (c1, c2); tload: the time of the positions [s] for actor loads. (At most 30
    arguments: CPython passes more as *args, which numba cannot inline.)
    """
    use_gravity, use_local, rotate_body, static = sw
    use_visc = on(static, F_VISCOUS)
    energy = on(static, F_ENERGY)
    planar = on(static, F_PLANAR)
    adaptive = on(static, F_ADAPTIVE)
    rigid = L is not None
    local, visc = damping
    c1p, c2p = cc
    fl = bflags[b]
    damped = fl & LOADED == 0  # a loading device takes its prescribed force undamped
    m = mass[b]
    ii = 0.0
    if L is None:
        ii = inert[b, 0]
    fx, fy, fz, tx, ty, tz, p = body_loads(
        fx, fy, fz, tx, ty, tz, m, ii, v[b, 0], v[b, 1], v[b, 2], w[b, 0], w[b, 1], w[b, 2],
        gravity, local, visc, use_gravity, use_local and damped, use_visc and damped and not rigid)
    if L is not None:
        if use_visc and damped:  # F = -alpha m v, T = -alpha I omega = -alpha L
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
        arg = load[b, L_OMEGA] * max(tload - load[b, L_T0], 0.0) + load[b, L_PHASE]
        sn = math.sin(arg)
        fx += load[b, L_F0] + load[b, L_F1] * sn
        fy += load[b, L_F0 + 1] + load[b, L_F1 + 1] * sn
        fz += load[b, L_F0 + 2] + load[b, L_F1 + 2] * sn
    if store:
        f[b, 0] = fx
        f[b, 1] = fy
        f[b, 2] = fz
        if rotate_body:
            tq[b, 0] = tx
            tq[b, 1] = ty
            tq[b, 2] = tz
    c1 = c1p if damped else 1.0
    c2 = c2p if damped else 1.0
    im = h / m
    iv = 0.0
    if L is None:
        if rotate_body:
            iv = h / ii
    et, er0, er1 = kick(b, fl, v, w, L, inert, m, im, iv, fx, fy, fz, tx, ty, tz, h, c1, c2, rotate_body, planar,
                        adaptive)
    if L is not None and rotate_body and fl & FIX_ROTATION == 0:
        wx, wy, wz = omega_from_L(q[b, 0], q[b, 1], q[b, 2], q[b, 3], L[b, 0], L[b, 1], L[b, 2],
                                  inert[b, 0], inert[b, 1], inert[b, 2])
        w[b, 0] = wx
        w[b, 1] = wy
        w[b, 2] = wz
        if adaptive:
            er1 = wx * L[b, 0] + wy * L[b, 1] + wz * L[b, 2]
    if adaptive:
        if damped:
            ea = et
            ea += 0.5 * (er0 + er1)
            eabs[b] += alpha * h * ea
        kevec[b] = kinetic_energy(b, v, w, L, m, ii)
    return fx, fy, fz, tx, ty, tz, im, iv


@njit(inline="always")
def kinetic_energy(b, v, w, L, m, ii):
    """Kinetic energy of body b [J]: m v^2/2 + omega.L/2 (rigid rotors) or ii omega^2/2 (spin
    rotors: L None)."""
    if L is not None:
        return 0.5 * (m * (v[b, 0] ** 2 + v[b, 1] ** 2 + v[b, 2] ** 2)
                      + w[b, 0] * L[b, 0] + w[b, 1] * L[b, 1] + w[b, 2] * L[b, 2])
    return 0.5 * m * (v[b, 0] ** 2 + v[b, 1] ** 2 + v[b, 2] ** 2) + 0.5 * ii * (
        w[b, 0] ** 2 + w[b, 1] ** 2 + w[b, 2] ** 2)


@njit(internal=True)
def adapt(adamp, eabs, kevec, energy, ebody):
    """Seed eq. 27: R = E_a / |Delta E_k|; R < 0.5: alpha *= 1.1, R > 0.5: alpha *= 0.99, kept in
    [A_MIN, A_MAX]. Sums in body order (serial): the decision does not depend on the thread count."""
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


@njit(internal=True)
def move_radii(wctrl, wprm, wradius, wref, dt, lim2, rebuild):
    """Pressure-loaded cylinders change their radius by W_RATE dt; one whose radius moved
    more than skin/2 since the last list build flags a rebuild (wref[w, 0] holds that change)."""
    for k in range(wctrl.shape[0]):
        if wctrl[k] == PRESSURE:
            wradius[k] += wprm[k, W_RATE] * dt
            wref[k, 0] += wprm[k, W_RATE] * dt
            if wref[k, 0] ** 2 > lim2:
                rebuild[0] = 1


@njit(internal=True)
def wall_control(time, dt, nq, wwall, wfc, wnormal, wv, wctrl, wprm, wforce, wkn, eacc, energy):
    """Sum contact forces on each wall (fixed order), then set each wall's velocity.

    wfc[k]: force on the particle (3), stiffness the servo sees k_n + c_n/dt (column 3) and
    the contact's normal force (column 4, for pressure-loaded membranes)."""
    nw = wv.shape[0]
    fnsum = np.zeros(nw)
    for w in range(nw):
        wforce[w, 0] = 0.0
        wforce[w, 1] = 0.0
        wforce[w, 2] = 0.0
        wkn[w] = 0.0
    for k in range(nq):
        w = wwall[k]
        wforce[w, 0] -= wfc[k, 0]
        wforce[w, 1] -= wfc[k, 1]
        wforce[w, 2] -= wfc[k, 2]
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


@njit(inline="always")
def check_bodies(bd, L, info):
    """Guards on the body state: (finite, kinetic energy [J]); info[0] = the first bad body.
    L: the bodies' L, None for spin rotors (:func:`rotors`)."""
    x, v, w, q, mass, inert = bd.x, bd.v, bd.w, bd.q, bd.mass, bd.inert
    ke = 0.0
    for b in range(x.shape[0]):
        s = 0.0
        for d in range(3):
            s += x[b, d] + v[b, d] + w[b, d]
        if L is not None:
            s += q[b, 0] + q[b, 1] + q[b, 2] + q[b, 3] + L[b, 0] + L[b, 1] + L[b, 2]
        if not math.isfinite(s):
            info[0] = b
            return False, ke
        ke += kinetic_energy(b, v, w, L, mass[b], inert[b, 0])
    return True, ke
