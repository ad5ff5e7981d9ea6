"""Contact laws for sphere-sphere and sphere-wall contacts (pure scalar kernels).

One function, :func:`contact_law`, evaluates the normal, tangential and rolling parts
of one contact from its geometry and relative motion, and updates the contact's
history in place. It is inlined into the pair pass and the wall pass.

Laws (``law`` argument):

* ``LINEAR`` -- linear spring-dashpot (Cundall & Strack 1979):
  F_n = k_n delta - c_n v_n, with c_n = c_abs + 2 zeta sqrt(m* k_n);
  zeta = -ln e / sqrt(pi^2 + ln^2 e) gives the restitution coefficient e for an
  isolated pair (contact ends when delta returns to 0, tension allowed).
* ``HERTZ`` -- Hertz-Mindlin with Tsuji-type damping (as in LIGGGHTS ``hertz``):
  F_n = 4/3 E* sqrt(R*) delta^(3/2) - 2 sqrt(5/6) beta sqrt(S_n m*) v_n,
  S_n = 2 E* sqrt(R* delta), k_t = S_t = 8 G* sqrt(R* delta),
  beta = -ln e / sqrt(pi^2 + ln^2 e).

Normal force: by default the dashpot may pull at the end of a contact (F_n < 0 while the
spheres separate faster than the spring pushes), so that an isolated impact ends at delta = 0
with exactly the restitution e. ``P_NOTENSION`` = 1 (the stage's ``contact.no_tension``)
clips F_n at 0 instead: no attraction, and a rebound a little above e.

Tangential (when friction is active): incremental spring dF_t = -k_t v_t dt with the
history rotated into the current tangent plane (magnitude kept), optional dashpot
c_t = ratio * c_n, Coulomb limit |F_t| <= mu F_c (the stored spring is scaled back to the
limit). F_c is the part of the normal force whose impulse is the contact's normal impulse,
so that a contact that slides throughout gets a tangential impulse of exactly mu times its
normal impulse (the rigid-body limit mu (1 + e) m v_n of an oblique impact, Maw, Barber &
Fawcett 1976): with tension allowed the elastic force k_n delta (the dashpot's impulse
int c_n(delta) v_n dt = -int c_n(delta) d delta vanishes over a contact that starts and ends
at delta = 0, for any c_n(delta): linear and Hertz alike); with no tension the clipped F_n
itself. (Capping with max(F_n, 0) would count the compressive part of the dashpot but not
its tensile end: an e = 0.5 impact in gross sliding then leaves 2-3 % faster than the limit.)

Rolling resistance (when active): elastic-plastic spring (Ai, Chen, Rotter & Ooi 2011,
model C without the viscous term): dM_r = -k_r omega_rel,t dt, k_r = 2.25 k_n mu_r^2 R*^2,
|M_r| <= mu_r R* F_c.

Lever arm: the contact point lies a_i = R_i - P_ARM delta / 2 from sphere i's centre (and
R - P_ARM delta from a sphere's centre for a wall contact): P_ARM = 1 (``contact.lever_arm:
deformed``, the default) puts it in the middle of the overlap, where the deformed spheres
touch; P_ARM = 0 (``radius``) uses the undeformed radius, as the rigid-body formulas of an
oblique impact do (soft contacts: the spin after an impact differs by about the mean
delta / R between the two).

Sign convention: n points from j to i, ``v`` is the velocity of i's contact point
relative to j's, the returned force and moment act on i (minus on j).
"""

import math

from demcli.jit import njit

LINEAR = 0
HERTZ = 1

# columns of the material-pair table prm[a, b, :]
P_KN = 0      # linear normal stiffness [N/m]
P_KT = 1      # linear tangential stiffness [N/m]
P_CN = 2      # absolute normal damping coefficient [N s/m]
P_ZETA = 3    # damping ratio from restitution [-] (linear and Hertz)
P_MU = 4      # Coulomb friction coefficient [-]
P_MUR = 5     # rolling friction coefficient [-]
P_ESTAR = 6   # effective Young's modulus E* [Pa]
P_GSTAR = 7   # effective shear modulus G* [Pa]
P_CTR = 8     # tangential / normal damping ratio [-]
P_NOTENSION = 9  # 1: the normal force is clipped at 0 (no attraction); 0: the dashpot may pull [-]
P_ARM = 10    # fraction of the overlap the lever arm loses: 1 deformed (R - delta/2), 0 radius [-]
N_PARAMS = 11

_SQRT_5_6 = math.sqrt(5.0 / 6.0)


@njit(internal=True)
def _to_tangent_plane(hx, hy, hz, nx, ny, nz):
    """A history vector turned into the current tangent plane, magnitude kept (the contact
    frame rotated since the last step; as in LIGGGHTS/LAMMPS granular history)."""
    h0 = hx * hx + hy * hy + hz * hz
    if h0 > 0.0:
        hn = hx * nx + hy * ny + hz * nz
        hx -= hn * nx
        hy -= hn * ny
        hz -= hn * nz
        h1 = hx * hx + hy * hy + hz * hz
        if h1 > 0.0:
            s = math.sqrt(h0 / h1)
            hx *= s
            hy *= s
            hz *= s
    return hx, hy, hz


@njit(inline="always")
def pair_kinematics(vs, ws, i, j, nx, ny, nz, ai, aj):
    """Velocity of i's contact point relative to j's, v_i + w_i x (-a_i n) - v_j - w_j x (a_j n)
    [m/s], and the relative angular velocity w_i - w_j [rad/s]; the contact point lies a_i from
    i's centre and a_j from j's along n (from j to i)."""
    wix, wiy, wiz = ws[i, 0], ws[i, 1], ws[i, 2]
    wjx, wjy, wjz = ws[j, 0], ws[j, 1], ws[j, 2]
    vx = vs[i, 0] - vs[j, 0] - ai * (wiy * nz - wiz * ny) - aj * (wjy * nz - wjz * ny)
    vy = vs[i, 1] - vs[j, 1] - ai * (wiz * nx - wix * nz) - aj * (wjz * nx - wjx * nz)
    vz = vs[i, 2] - vs[j, 2] - ai * (wix * ny - wiy * nx) - aj * (wjx * ny - wjy * nx)
    return vx, vy, vz, wix - wjx, wiy - wjy, wiz - wjz


@njit(inline="always")
def contact_law(law, prm, ma, mb, delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, rstar, mstar, dt,
                ft, mr, k, friction, rolling):
    """Force and rolling moment on i for one contact.

    Args:
        law: LINEAR or HERTZ.
        prm: (n_m, n_m, N_PARAMS) float64 material-pair table; ma, mb: the pair's materials
            (indices rather than the row prm[ma, mb]: an array view costs two atomic
            reference-count updates per contact, on one counter that every thread
            shares; passing indices made the dense sphere step 2 % faster on one thread
            and 6 % on two).
        delta: overlap [m], > 0.
        nx, ny, nz: unit normal from j to i.
        vx, vy, vz: contact-point velocity of i relative to j [m/s].
        wx, wy, wz: angular velocity of i relative to j [rad/s] (rolling only).
        rstar, mstar: effective radius [m] and mass [kg].
        dt: time step [s].
        ft: (n, 3) tangential spring forces [N], row k updated in place.
        mr: (n, 3) rolling moments [N m], row k updated in place (rolling only).
        k: history row.
        friction, rolling: effect switches.

    Returns:
        (fx, fy, fz, mx, my, mz, e_damp, e_fric): force [N] and rolling moment [N m]
        on i, energy dissipated this step by dashpots and by slip [J].
    """
    vn = vx * nx + vy * ny + vz * nz
    if law == HERTZ:
        sq = math.sqrt(rstar * delta)
        kn_tan = 2.0 * prm[ma, mb, P_ESTAR] * sq
        kn = kn_tan * (2.0 / 3.0)
        cn = 2.0 * _SQRT_5_6 * prm[ma, mb, P_ZETA] * math.sqrt(kn_tan * mstar)
        kt = 8.0 * prm[ma, mb, P_GSTAR] * sq
        ct = prm[ma, mb, P_CTR] * 2.0 * _SQRT_5_6 * prm[ma, mb, P_ZETA] * math.sqrt(kt * mstar)
    else:
        kn = prm[ma, mb, P_KN]
        kn_tan = kn
        cn = prm[ma, mb, P_CN] + 2.0 * prm[ma, mb, P_ZETA] * math.sqrt(mstar * kn)
        kt = prm[ma, mb, P_KT]
        ct = prm[ma, mb, P_CTR] * cn
    fel = kn * delta
    fn = fel - cn * vn
    e_damp = cn * vn * vn * dt
    fcap = fel  # the Coulomb and rolling limits' normal force (module docstring)
    if prm[ma, mb, P_NOTENSION] != 0.0:
        if fn < 0.0:
            fn = 0.0
            e_damp = fel * vn * dt  # the clipped dashpot absorbs the spring's work (vn > 0)
        fcap = fn
    e_fric = 0.0
    fx = fn * nx
    fy = fn * ny
    fz = fn * nz
    if friction:
        vtx = vx - vn * nx
        vty = vy - vn * ny
        vtz = vz - vn * nz
        hx, hy, hz = _to_tangent_plane(ft[k, 0], ft[k, 1], ft[k, 2], nx, ny, nz)
        hx -= kt * vtx * dt
        hy -= kt * vty * dt
        hz -= kt * vtz * dt
        tx = hx - ct * vtx
        ty = hy - ct * vty
        tz = hz - ct * vtz
        lim = prm[ma, mb, P_MU] * fcap
        tmag2 = tx * tx + ty * ty + tz * tz
        if tmag2 > lim * lim:
            tmag = math.sqrt(tmag2)
            s = lim / tmag
            tx *= s
            ty *= s
            tz *= s
            e_fric = (tmag - lim) * lim / kt if kt > 0.0 else 0.0
            hx = tx
            hy = ty
            hz = tz
        else:
            e_damp += ct * (vtx * vtx + vty * vty + vtz * vtz) * dt
        ft[k, 0] = hx
        ft[k, 1] = hy
        ft[k, 2] = hz
        fx += tx
        fy += ty
        fz += tz
    mx = 0.0
    my = 0.0
    mz = 0.0
    if rolling:
        wn = wx * nx + wy * ny + wz * nz
        wtx = wx - wn * nx
        wty = wy - wn * ny
        wtz = wz - wn * nz
        mur = prm[ma, mb, P_MUR]
        kr = 2.25 * kn_tan * mur * mur * rstar * rstar
        ax, ay, az = _to_tangent_plane(mr[k, 0], mr[k, 1], mr[k, 2], nx, ny, nz)
        ax -= kr * wtx * dt
        ay -= kr * wty * dt
        az -= kr * wtz * dt
        lim = mur * rstar * fcap
        amag2 = ax * ax + ay * ay + az * az
        if amag2 > lim * lim:
            amag = math.sqrt(amag2)
            s = lim / amag
            e_fric += (amag - lim) * lim / kr if kr > 0.0 else 0.0
            ax *= s
            ay *= s
            az *= s
        mr[k, 0] = ax
        mr[k, 1] = ay
        mr[k, 2] = az
        mx = ax
        my = ay
        mz = az
    return fx, fy, fz, mx, my, mz, e_damp, e_fric


@njit(inline="always")
def strain_energy(law, prm, ma, mb, delta, rstar, ft, mr, k, friction, rolling):
    """Elastic energy stored in one contact [J] (normal + tangential + rolling springs)."""
    if law == HERTZ:
        sq = math.sqrt(rstar * delta)
        e = 0.4 * (4.0 / 3.0) * prm[ma, mb, P_ESTAR] * sq * delta * delta
        kn_tan = 2.0 * prm[ma, mb, P_ESTAR] * sq
        kt = 8.0 * prm[ma, mb, P_GSTAR] * sq
    else:
        e = 0.5 * prm[ma, mb, P_KN] * delta * delta
        kn_tan = prm[ma, mb, P_KN]
        kt = prm[ma, mb, P_KT]
    if friction and kt > 0.0:
        e += 0.5 * (ft[k, 0] ** 2 + ft[k, 1] ** 2 + ft[k, 2] ** 2) / kt
    if rolling:
        kr = 2.25 * kn_tan * prm[ma, mb, P_MUR] ** 2 * rstar * rstar
        if kr > 0.0:
            e += 0.5 * (mr[k, 0] ** 2 + mr[k, 1] ** 2 + mr[k, 2] ** 2) / kr
    return e
