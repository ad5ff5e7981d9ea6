"""Bonded contacts between spheres: contact bonds, parallel bonds and Burgers bonds.

A bond joins two spheres i < j from its creation until it breaks; it is kept in its own
list (CSR by i, sorted by j, like the pair list) and evaluated by :func:`bond_pass`
whether the spheres touch or not. Sign conventions are those of
:mod:`demcli.kernels.contact`: n points from j to i, ``v`` is the velocity of i's contact
point relative to j's, forces and moments returned act on i (minus on j). Positive
normal force is compression. The contact point sits in the middle of the overlap or gap,
at a_i = r_i - delta/2 from i's centre (delta = r_i + r_j - d, negative for a gap).

Models (``B_KIND`` of a model row, PFC's bond models; Potyondy & Cundall 2004):

* ``CONTACT_BOND`` -- point springs replacing the contact while intact:
  F_n = k_n (delta - delta_0) (tension allowed), dF_s = -k_s v_t dt, with delta_0 [m] the
  bond's reference overlap (``H_D0``): 0 for a bond installed loaded (it takes over the
  contact's force k_n delta), the overlap at creation for one installed stress-free
  (PFC's reference gap: zero force at the installed separation); breaks in tension when
  -F_n >= s_n and in shear when |F_s| >= s_s (strengths in N); force only, no moment.
  Once broken, the pair is an ordinary contact of the stage's contact law (linear with
  slip in the asphalt cases). A stress-free bond (delta_0 > 0) that breaks leaves its pair
  *seated*: the bond pass keeps it and applies the stage's contact law to the overlap beyond
  the reference, delta - delta_0 (zero force for 0 < delta <= delta_0; PFC's linear model
  keeps its reference gap after the bond breaks in the same way), with the history in the
  bond's ``H_FS`` (tangential spring) and ``H_MB`` (rolling moment) columns, until the
  spheres come apart (delta <= 0): then delta_0 is cleared and the pair joins the contact
  list. Without this a broken stress-free bond would hand the contact law the full overlap
  delta_0 it was installed on (up to ~r in the asphalt mastic) and fire the pair apart.
* ``PARALLEL_BOND`` -- a disc of radius R = lambda min(r_i, r_j) in parallel with the
  contact (which the contact law keeps computing): A = pi R^2, I = pi R^4 / 4,
  J = pi R^4 / 2; increments from the bond's creation dF_n = -kn_b A v_n dt,
  dF_s = -ks_b A v_t dt, dM_t = -ks_b J w_n dt (twist), dM_b = -kn_b I w_t dt (bending),
  w the relative angular velocity; largest stresses sigma = -F_n / A + |M_b| R / I and
  tau = |F_s| / A + |M_t| R / J; breaks in tension when sigma >= sigma_c, else in shear
  when tau >= tau_c (strengths in Pa).
* ``BURGERS`` -- the viscoelastic bond of seed 003 (Collop, McDowell & Lee 2006),
  replacing the contact while intact: normal compression elastic, F_n = k_n delta for
  delta >= 0; normal tension and shear each a Burgers element (Maxwell spring K_m and
  dashpot C_m in series with a Kelvin spring K_k parallel to a dashpot C_k), advanced by
  the exact step map of :func:`burgers_coefficients`; optional strengths (N) as for the
  contact bond. With ``compression: burgers`` (``B_COMP`` = 1) the normal element is one
  Burgers element in compression and tension alike: its elongation u = -(delta - delta_i)
  (delta_i the overlap at installation, so a bond is installed unloaded), its force s
  (elongation positive) advanced by the same step map for du = u_1 - u_0, F_n = -s; a
  sinusoidal u = U e^{i w t} gives s = K*(w) u with 1/K* = 1/K_m + 1/(i w C_m) + 1/(K_k + i w C_k).

History of a bond (columns ``H_*`` of ``hist``): the force on i split into its normal
part (tension element force for Burgers) and shear vector, the twist and bending moments,
the Kelvin displacements (Burgers) and the previous separation (Burgers tension).
"""

import math

import numpy as np
from numba import prange

from demcli.jit import njit
from demcli.kernels.contact import P_ARM, _to_tangent_plane, contact_law, pair_kinematics, strain_energy

CONTACT_BOND = 0
PARALLEL_BOND = 1
BURGERS = 2
KIND_NAMES = ("contact_bond", "parallel_bond", "burgers")

# columns of the bond-model table bprm[m, :]
B_KIND = 0     # CONTACT_BOND, PARALLEL_BOND or BURGERS
B_KN = 1       # point normal stiffness [N/m] (contact bond; Burgers compression)
B_KS = 2       # point shear stiffness [N/m] (contact bond)
B_SN = 3       # normal (tensile) strength: N (contact bond, Burgers) or Pa (parallel bond); inf: none
B_SS = 4       # shear strength: N or Pa; inf: none
B_PKN = 5      # parallel bond normal stiffness per area [Pa/m]
B_PKS = 6      # parallel bond shear stiffness per area [Pa/m]
B_LAMBDA = 7   # parallel bond radius multiplier [-]
B_KMN = 8      # Burgers, normal tension: Maxwell spring [N/m]
B_CMN = 9      # Maxwell dashpot [N s/m]
B_KKN = 10     # Kelvin spring [N/m]
B_CKN = 11     # Kelvin dashpot [N s/m]
B_KMS = 12     # Burgers, shear: Maxwell spring [N/m]
B_CMS = 13
B_KKS = 14
B_CKS = 15
B_COMP = 16    # Burgers, normal compression: 0 elastic (k_n), 1 the normal Burgers element (as in tension)
N_BPARAMS = 17
# the kernel's table appends the Burgers step coefficients for the stage's time step
# (:func:`burgers_coefficients`, 6 per direction: phi00 phi01 phi10 phi11 g0 g1)
B_COEF_N = 17  # normal (tension, or both signs with B_COMP = 1)
B_COEF_S = 23  # shear
N_BTABLE = 29

# columns of the bond history hist[b, :]
H_FN = 0       # normal force on i [N], compression positive (Burgers: tension element force, >= 0 pulls)
H_FS = 1       # shear force on i [N], 3 columns
H_MT = 4       # twist moment on i about n [N m] (parallel bond)
H_MB = 5       # bending moment on i [N m], 3 columns (parallel bond)
H_UKN = 8      # Kelvin displacement, normal tension [m] (Burgers)
H_UKS = 9      # Kelvin displacement, shear [m], 3 columns (Burgers)
H_SEP = 12     # separation max(-delta, 0) at the last step [m] (Burgers; B_COMP = 1: the elongation -delta
               # from the bond's installed state, signed)
H_D0 = 13      # reference overlap delta_0 [m] (contact bond; 0: installed loaded; kept when it breaks)
N_HIST = 14

# state of a bond
INTACT = 0
BROKEN_TENSION = 1
BROKEN_SHEAR = 2


@njit
def burgers_coefficients(km, cm, kk, ck, dt):
    """Exact one-step map of a Burgers element for a displacement linear in time [SI].

    State x = (s, u_k): the element force (elongation positive) and the Kelvin displacement.
    With u = s/K_m + u_c + u_k, C_m u_c' = s and C_k u_k' = s - K_k u_k, a constant
    displacement rate v gives the linear system x' = A x + b v,

        A = [[-K_m (1/C_m + 1/C_k), K_m K_k / C_k], [1/C_k, -K_k / C_k]],  b = (K_m, 0),

    whose exact solution over a step is x_1 = Phi x_0 + Gamma du (du = v dt) with
    Phi = exp(A dt) and Gamma = phi_1(A dt) b, phi_1(z) = (e^z - 1) / z. A has two real
    negative eigenvalues (trace < 0, determinant K_m K_k / (C_m C_k) > 0, discriminant
    (a - d)^2 + 4 K_m K_k / C_k^2 > 0), so both matrix functions follow from Sylvester's
    formula f(A) = [f(l1) (A - l2 I) - f(l2) (A - l1 I)] / (l1 - l2), phi_1 through expm1.
    C_k = 0 (a Kelvin spring alone): the springs in series, K = K_m K_k / (K_m + K_k), relax
    through C_m with l = -K / C_m, and u_k = s / K_k.

    Returns (phi00, phi01, phi10, phi11, g0, g1). The step the engine takes is exactly this
    (the drift moves every body at its mid-step velocity), so the update is exact for any
    dt / tau and unconditionally stable.
    """
    if ck <= 0.0:
        ks = km * kk / (km + kk)
        z = -ks / cm * dt
        e = math.exp(z)
        f = math.expm1(z) / z if z != 0.0 else 1.0
        return e, 0.0, e / kk, 0.0, ks * f, ks * f / kk
    a = -km * (1.0 / cm + 1.0 / ck)
    b = km * kk / ck
    c = 1.0 / ck
    d = -kk / ck
    half = 0.5 * (a + d)
    root = math.sqrt(0.25 * (a - d) ** 2 + b * c)
    l1 = half + root
    l2 = half - root
    e1 = math.exp(l1 * dt)
    e2 = math.exp(l2 * dt)
    f1 = math.expm1(l1 * dt) / (l1 * dt) if dt > 0.0 else 1.0
    f2 = math.expm1(l2 * dt) / (l2 * dt) if dt > 0.0 else 1.0
    w = l1 - l2
    # f(A) = p I + q A with q = (f1 - f2) / w and p = (l1 f2 - l2 f1) / w
    qe = (e1 - e2) / w
    pe = (l1 * e2 - l2 * e1) / w
    qf = (f1 - f2) / w
    pf = (l1 * f2 - l2 * f1) / w
    return pe + qe * a, qe * b, qe * c, pe + qe * d, (pf + qf * a) * km, qf * c * km


@njit(inline="always")
def burgers_step(s, uk, du, dt, cf, m, k, km, kk):
    """One step of a Burgers element with the coefficients cf[m, k:k+6] of
    :func:`burgers_coefficients` for this dt; dt = 0 (a step of zero length, the engine's
    priming pass) takes du as a jump: the dashpots are rigid, s += K_m du.

    Returns (s1, uk1, dissipated energy [J]): the work 0.5 (s_0 + s_1) du less the change of
    the energy stored in the springs, s^2 / (2 K_m) + K_k u_k^2 / 2.
    """
    if dt > 0.0:
        s1 = cf[m, k] * s + cf[m, k + 1] * uk + cf[m, k + 4] * du
        uk1 = cf[m, k + 2] * s + cf[m, k + 3] * uk + cf[m, k + 5] * du
    else:
        s1 = s + km * du
        uk1 = uk
    stored = (s1 * s1 - s * s) / (2.0 * km) + 0.5 * kk * (uk1 * uk1 - uk * uk)
    return s1, uk1, 0.5 * (s + s1) * du - stored


@njit
def burgers_update(s, uk, du, dt, km, cm, kk, ck):
    """One step of a Burgers element driven by the displacement increment ``du`` [m] spread
    evenly over dt (:func:`burgers_coefficients` computed for this one step)."""
    cf = np.array(burgers_coefficients(km, cm, kk, ck, dt)).reshape(1, 6)
    return burgers_step(s, uk, du, dt, cf, 0, 0, km, kk)


@njit(inline="always")
def _rotate_vec(h, b, col, nx, ny, nz):
    """History vector columns col..col+2 of row b turned into the current tangent plane."""
    return _to_tangent_plane(h[b, col], h[b, col + 1], h[b, col + 2], nx, ny, nz)


@njit(inline="always")
def _burgers_normal(bprm, m, hist, b, u, du, dt):
    """Advance bond b's normal Burgers element by the elongation increment du [m] to the
    elongation u [m] (stored in ``H_SEP``); returns (F_n on i [N], compression positive, the
    energy dissipated [J])."""
    t1, uk1, ed = burgers_step(hist[b, H_FN], hist[b, H_UKN], du, dt, bprm, m, B_COEF_N, bprm[m, B_KMN], bprm[m, B_KKN])
    hist[b, H_FN] = t1
    hist[b, H_UKN] = uk1
    hist[b, H_SEP] = u
    return -t1, ed


@njit(inline="always")
def _burgers_shear(bprm, m, hist, b, sx, sy, sz, vtx, vty, vtz, nx, ny, nz, dt):
    """Advance bond b's shear Burgers elements (one per axis: the element's elongation is
    i's tangential displacement v_t dt, its force -F_s); returns (F_s on i [N], dissipated [J])."""
    kx, ky, kz = _rotate_vec(hist, b, H_UKS, nx, ny, nz)
    ex, kx, ed0 = burgers_step(-sx, kx, vtx * dt, dt, bprm, m, B_COEF_S, bprm[m, B_KMS], bprm[m, B_KKS])
    ey, ky, ed1 = burgers_step(-sy, ky, vty * dt, dt, bprm, m, B_COEF_S, bprm[m, B_KMS], bprm[m, B_KKS])
    ez, kz, ed2 = burgers_step(-sz, kz, vtz * dt, dt, bprm, m, B_COEF_S, bprm[m, B_KMS], bprm[m, B_KKS])
    hist[b, H_UKS] = kx
    hist[b, H_UKS + 1] = ky
    hist[b, H_UKS + 2] = kz
    return -ex, -ey, -ez, ed0 + ed1 + ed2


@njit(inline="always")
def _burgers_state(bprm, m, fn, sx, sy, sz):
    """INTACT, or the mode a Burgers bond with these forces [N] breaks in (strengths in N)."""
    if -fn >= bprm[m, B_SN]:
        return BROKEN_TENSION
    if sx * sx + sy * sy + sz * sz >= bprm[m, B_SS] * bprm[m, B_SS]:
        return BROKEN_SHEAR
    return INTACT


@njit(inline="always")
def bond_energy(bprm, m, hist, b, delta, ri, rj):
    """Elastic energy stored in bond b of model m (row of bprm) [J] (springs only; dashpots
    store none)."""
    kind = bprm[m, B_KIND]
    fs2 = hist[b, H_FS] ** 2 + hist[b, H_FS + 1] ** 2 + hist[b, H_FS + 2] ** 2
    if kind == CONTACT_BOND:
        du = delta - hist[b, H_D0]
        return 0.5 * bprm[m, B_KN] * du * du + 0.5 * fs2 / bprm[m, B_KS]
    if kind == PARALLEL_BOND:
        rb = bprm[m, B_LAMBDA] * min(ri, rj)
        area = math.pi * rb * rb
        inert = 0.25 * area * rb * rb
        mb2 = hist[b, H_MB] ** 2 + hist[b, H_MB + 1] ** 2 + hist[b, H_MB + 2] ** 2
        return 0.5 * (hist[b, H_FN] ** 2 / (bprm[m, B_PKN] * area) + fs2 / (bprm[m, B_PKS] * area)
                      + hist[b, H_MT] ** 2 / (bprm[m, B_PKS] * 2.0 * inert) + mb2 / (bprm[m, B_PKN] * inert))
    uks2 = hist[b, H_UKS] ** 2 + hist[b, H_UKS + 1] ** 2 + hist[b, H_UKS + 2] ** 2
    e = 0.5 * fs2 / bprm[m, B_KMS] + 0.5 * bprm[m, B_KKS] * uks2
    if delta >= 0.0 and bprm[m, B_COMP] == 0.0:
        return e + 0.5 * bprm[m, B_KN] * delta * delta
    return e + 0.5 * hist[b, H_FN] ** 2 / bprm[m, B_KMN] + 0.5 * bprm[m, B_KKN] * hist[b, H_UKN] ** 2


@njit
def bond_law(bprm, m, hist, b, delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, ri, rj, dt):
    """Force and moment on i from bond b; updates its history row in place.

    Args:
        bprm: (n_models, N_BTABLE) model table with the Burgers coefficients for dt; m: the
            bond's model (an index rather than the row bprm[m]: a view costs two atomic
            reference-count updates per call); hist: (n_bonds, N_HIST).
        delta: r_i + r_j - d [m] (negative: a gap); n: unit normal from j to i.
        v: contact-point velocity of i relative to j [m/s]; w: omega_i - omega_j [rad/s].
        ri, rj: radii [m]; dt: time step [s].

    Returns:
        (fx, fy, fz, mx, my, mz, e_diss, state): force [N] and moment [N m] on i (moments
        without the branch torques), energy dissipated this step [J], INTACT or the mode in
        which the bond broke this step (then force and moment are zero).
    """
    kind = bprm[m, B_KIND]
    vn = vx * nx + vy * ny + vz * nz
    vtx = vx - vn * nx
    vty = vy - vn * ny
    vtz = vz - vn * nz
    sx, sy, sz = _rotate_vec(hist, b, H_FS, nx, ny, nz)
    mx = 0.0
    my = 0.0
    mz = 0.0
    e_diss = 0.0
    state = INTACT
    if kind == CONTACT_BOND:
        fn = bprm[m, B_KN] * (delta - hist[b, H_D0])
        sx -= bprm[m, B_KS] * vtx * dt
        sy -= bprm[m, B_KS] * vty * dt
        sz -= bprm[m, B_KS] * vtz * dt
        if -fn >= bprm[m, B_SN]:
            state = BROKEN_TENSION
        elif sx * sx + sy * sy + sz * sz >= bprm[m, B_SS] * bprm[m, B_SS]:
            state = BROKEN_SHEAR
    elif kind == PARALLEL_BOND:
        rb = bprm[m, B_LAMBDA] * min(ri, rj)
        area = math.pi * rb * rb
        inert = 0.25 * area * rb * rb
        polar = 2.0 * inert
        fn = hist[b, H_FN] - bprm[m, B_PKN] * area * vn * dt
        sx -= bprm[m, B_PKS] * area * vtx * dt
        sy -= bprm[m, B_PKS] * area * vty * dt
        sz -= bprm[m, B_PKS] * area * vtz * dt
        wn = wx * nx + wy * ny + wz * nz
        mt = hist[b, H_MT] - bprm[m, B_PKS] * polar * wn * dt
        bx, by, bz = _rotate_vec(hist, b, H_MB, nx, ny, nz)
        bx -= bprm[m, B_PKN] * inert * (wx - wn * nx) * dt
        by -= bprm[m, B_PKN] * inert * (wy - wn * ny) * dt
        bz -= bprm[m, B_PKN] * inert * (wz - wn * nz) * dt
        mb = math.sqrt(bx * bx + by * by + bz * bz)
        sigma = -fn / area + mb * rb / inert
        tau = math.sqrt(sx * sx + sy * sy + sz * sz) / area + abs(mt) * rb / polar
        if sigma >= bprm[m, B_SN]:
            state = BROKEN_TENSION
        elif tau >= bprm[m, B_SS]:
            state = BROKEN_SHEAR
        hist[b, H_MT] = mt
        hist[b, H_MB] = bx
        hist[b, H_MB + 1] = by
        hist[b, H_MB + 2] = bz
        mx = mt * nx + bx
        my = mt * ny + by
        mz = mt * nz + bz
    elif bprm[m, B_COMP] != 0.0:  # BURGERS, one normal element in compression and tension
        fn, ed = _burgers_normal(bprm, m, hist, b, -delta, -delta - hist[b, H_SEP], dt)
        e_diss += ed
    else:  # BURGERS
        sep = -delta if delta < 0.0 else 0.0
        if delta >= 0.0:  # compression: elastic; the tension element restarts unloaded
            fn = bprm[m, B_KN] * delta
            # The element's energy is lost with it, less the work its force s_0 (from the step
            # before, gap g) did in this step, which closes the gap: the integrator's trapezoid
            # gives that force half the step's displacement g + delta. Without that term the
            # balance lost s_0 (g + delta) / 2 at every closing, first order in dt once the
            # dashpots have crept (s_0 of either sign, not small: -7.4e-3 of the energy over 37
            # closings at 0.05 x the critical step, against 5e-4 with it).
            e_diss += (0.5 * hist[b, H_FN] ** 2 / bprm[m, B_KMN] + 0.5 * bprm[m, B_KKN] * hist[b, H_UKN] ** 2
                       - 0.5 * hist[b, H_FN] * (hist[b, H_SEP] + delta))
            hist[b, H_FN] = 0.0
            hist[b, H_UKN] = 0.0
        else:
            fn, ed = _burgers_normal(bprm, m, hist, b, sep, sep - hist[b, H_SEP], dt)
            e_diss += ed
        hist[b, H_SEP] = sep
    if kind == BURGERS:  # shear and strengths alike in both normal laws (inlined once)
        sx, sy, sz, ed = _burgers_shear(bprm, m, hist, b, sx, sy, sz, vtx, vty, vtz, nx, ny, nz, dt)
        e_diss += ed
        state = _burgers_state(bprm, m, fn, sx, sy, sz)
    else:
        hist[b, H_FN] = fn
    hist[b, H_FS] = sx
    hist[b, H_FS + 1] = sy
    hist[b, H_FS + 2] = sz
    if state != INTACT:
        # The energy the bond holds is lost with it, and the work its force F and moment M would
        # have done in the step's second half kick, 0.5 dt (F . v + M . w): the integrator
        # applies no force this step (trapezoid work 0.5 dt F_n . v), the spring energy fell by
        # 0.5 dt (F_n + F) . v (exact for a linear spring); without the term the balance was off
        # by that much at every break, first order in dt. delta_0 stays (a seated pair).
        fx = fn * nx + sx
        fy = fn * ny + sy
        fz = fn * nz + sz
        e_diss += bond_energy(bprm, m, hist, b, delta, ri, rj) + 0.5 * dt * (fx * vx + fy * vy + fz * vz
                                                                       + mx * wx + my * wy + mz * wz)
        d0 = hist[b, H_D0]
        for col in range(N_HIST):
            hist[b, col] = 0.0
        hist[b, H_D0] = d0
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, e_diss, state
    return fn * nx + sx, fn * ny + sy, fn * nz + sz, mx, my, mz, e_diss, state


@njit(inline="always")
def replaces_contact(kind, state, d0):
    """Whether a bond keeps its pair out of the contact list: an intact contact or Burgers
    bond, or a broken stress-free contact bond still seated (delta_0 > 0)."""
    if state == INTACT:
        return kind != PARALLEL_BOND
    return kind == CONTACT_BOND and d0 > 0.0


@njit
def seated_contact(law, prm, ma, mb, overlap, nx, ny, nz, vx, vy, vz, wx, wy, wz, ri, rj, mi, mj, dt, fts, mrs, b,
                   friction, rolling, took_over, ed):
    """The stage's contact law on a seated pair (overlap = delta - delta_0 [m]): force, moment,
    (damping, friction) losses [J], as :func:`bond_pass` books them. A call, not inlined: the
    contact law compiles once here, not inside the parallel bond loop (bond pass 22.6 -> 10.5 s cold)."""
    rstar = ri * rj / (ri + rj)
    fx, fy, fz, mx, my, mz, ec, ef = contact_law(
        law, prm, ma, mb, overlap, nx, ny, nz, vx, vy, vz, wx, wy, wz, rstar, mi * mj / (mi + mj), dt,
        fts, mrs, b, friction, rolling)
    if took_over:
        # its spring energy and the work of its force in the second half kick move
        # over from the bond's loss (bond_law's break term); that work holds half the
        # step's dashpot and slip losses, so the step books the other half of each,
        # the same half-step lead as the first step of any contact (it cancels when
        # the contact ends)
        ed += 0.5 * ec - strain_energy(law, prm, ma, mb, overlap, rstar, fts, mrs, b, friction, rolling) \
            - 0.5 * dt * (fx * vx + fy * vy + fz * vz + mx * wx + my * wy + mz * wz)
        ef *= 0.5
    else:
        ed = ec
    return fx, fy, fz, mx, my, mz, ed, ef


@njit(parallel=True)
def bond_pass(bstart, bj, bmodel, bstate, hist, bprm, xs, vs, ws, rad, smat, smass, prm, law, dt,
              friction, rolling, bfc, btj, bed, frow, trow, erow, energy, broke):
    """Every intact or seated bond's force into its own row; i's side summed into
    frow/trow/erow[i].

    Runs after the pair pass (which wrote frow[i] and trow[i]) and before
    :func:`bond_gather`; rows of the bond CSR are owned by i, so it is race-free and the
    sums keep a fixed order. A bond that breaks sets its state and ``broke[0]`` (the pair
    list is rebuilt so that the pair becomes an ordinary contact). A seated pair (a broken
    stress-free contact bond, module docstring) gets the stage's contact law
    (``law``, ``prm`` as in the pair pass) on delta - delta_0 until delta <= 0, when it is
    released (delta_0 cleared, ``broke[0]`` set). ``bed[b]``: (damping, friction) losses [J].
    """
    fts = hist[:, H_FS:H_FS + 3]   # a seated pair's tangential spring [N]
    mrs = hist[:, H_MB:H_MB + 3]   # and rolling moment [N m]
    for i in prange(bstart.shape[0] - 1):
        ri = rad[i]
        for b in range(bstart[i], bstart[i + 1]):
            state = bstate[b]
            d0 = hist[b, H_D0]
            if state != INTACT and d0 <= 0.0:  # released: its rows stay zero since it broke
                if energy:
                    bed[b, 0] = 0.0
                    bed[b, 1] = 0.0
                continue
            j = bj[b]
            rj = rad[j]
            dx = xs[i, 0] - xs[j, 0]
            dy = xs[i, 1] - xs[j, 1]
            dz = xs[i, 2] - xs[j, 2]
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            nx = dx / d
            ny = dy / d
            nz = dz / d
            delta = ri + rj - d
            arm = 0.5 * delta * prm[smat[i], smat[j], P_ARM]  # contact.lever_arm, as the pair pass
            ai = ri - arm
            aj = rj - arm
            vx, vy, vz, wx, wy, wz = pair_kinematics(vs, ws, i, j, nx, ny, nz, ai, aj)
            ed = ef = 0.0
            took_over = False  # the bond broke this step and its seated contact acts at once
            seated_force = False
            if state == INTACT:
                fx, fy, fz, mx, my, mz, ed, state = bond_law(
                    bprm, bmodel[b], hist, b, delta, nx, ny, nz, vx, vy, vz, wx, wy, wz, ri, rj, dt)
                if state != INTACT:
                    bstate[b] = state
                    broke[0] = 1
                    took_over = seated_force = d0 > 0.0 and delta > d0
            elif delta <= 0.0:  # the seated pair has come apart: an ordinary contact from now on
                for col in range(N_HIST):
                    hist[b, col] = 0.0
                broke[0] = 1
                fx = fy = fz = mx = my = mz = ed = 0.0
            elif delta > d0:
                seated_force = True
            else:  # seated, no compression beyond delta_0: open, the contact history is dropped
                for col in range(3):
                    fts[b, col] = 0.0
                    mrs[b, col] = 0.0
                fx = fy = fz = mx = my = mz = ed = 0.0
            if seated_force:
                fx, fy, fz, mx, my, mz, ed, ef = seated_contact(
                    law, prm, smat[i], smat[j], delta - d0, nx, ny, nz, vx, vy, vz, wx, wy, wz, ri, rj, smass[i],
                    smass[j], dt, fts, mrs, b, friction, rolling, took_over, ed)
            cx = ny * fz - nz * fy
            cy = nz * fx - nx * fz
            cz = nx * fy - ny * fx
            bfc[b, 0] = fx
            bfc[b, 1] = fy
            bfc[b, 2] = fz
            btj[b, 0] = -aj * cx - mx
            btj[b, 1] = -aj * cy - my
            btj[b, 2] = -aj * cz - mz
            frow[i, 0] += fx
            frow[i, 1] += fy
            frow[i, 2] += fz
            trow[i, 0] += -ai * cx + mx
            trow[i, 1] += -ai * cy + my
            trow[i, 2] += -ai * cz + mz
            if energy:
                bed[b, 0] = ed
                bed[b, 1] = ef
                erow[i, 0] += ed
                erow[i, 1] += ef


@njit(parallel=True)
def bond_gather(brstart, brlist, bfc, btj, bed, frow, trow, erow, energy):
    """j's side of every bond into frow/trow/erow[j] (fixed order, race-free); released
    bonds have zero rows."""
    for j in prange(brstart.shape[0] - 1):
        for a in range(brstart[j], brstart[j + 1]):
            b = brlist[a]
            frow[j, 0] -= bfc[b, 0]
            frow[j, 1] -= bfc[b, 1]
            frow[j, 2] -= bfc[b, 2]
            trow[j, 0] += btj[b, 0]
            trow[j, 1] += btj[b, 1]
            trow[j, 2] += btj[b, 2]
            if energy:
                erow[j, 0] += bed[b, 0]
                erow[j, 1] += bed[b, 1]


@njit
def bond_forces(bonds, bprm, xs, vs, ws, rad, smat, smass, prm, law, dt, friction, rolling, energy, frow, trow,
                erow, broke):
    """The bonds' forces into the pair pass's row sums (:func:`bond_pass`, :func:`bond_gather`).

    ``bonds``: the bond state tuple (bstart, bj, brstart, brlist, model, state, hist, bfc, btj,
    bed), or None for shapes whose bodies do not bond (polyhedra, mixed scenes): numba prunes
    the branch on the argument's type, so those compile none of the bond passes. Sphere scenes
    pass the tuple (empty without bonds) and the pass runs where the flag says."""
    if bonds is None:
        return
    bstart, bj, brstart, brlist, bmodel, bstate, bhist, bfc, btj, bed = bonds
    if not (friction or rolling):
        trow[:, :] = 0.0
    bond_pass(bstart, bj, bmodel, bstate, bhist, bprm, xs, vs, ws, rad, smat, smass, prm, law, dt,
              friction, rolling, bfc, btj, bed, frow, trow, erow, energy, broke)
    bond_gather(brstart, brlist, bfc, btj, bed, frow, trow, erow, energy)


@njit(internal=True)
def unbonded_pairs(bonds, bprm, start, pi, pj):
    """:func:`drop_bonded` with the bond state tuple; the list unchanged without bonds (None:
    compiled out, as in :func:`bond_forces`)."""
    if bonds is None:
        return start, pi, pj
    return drop_bonded(start, pi, pj, bonds[0], bonds[1], bonds[4], bonds[5], bonds[6], bprm)


@njit
def drop_bonded(start, pi, pj, bstart, bj, bmodel, bstate, bhist, bprm):
    """The pair list without the pairs a bond replaces (:func:`replaces_contact`: intact
    contact and Burgers bonds, seated broken contact bonds).

    Both lists are CSR by i and sorted by j inside a row; parallel bonds act beside the
    contact and keep their pair. Returns (start, pi, pj) of the kept pairs.
    """
    n = start.shape[0] - 1
    keep = np.ones(pj.shape[0], np.bool_)
    for i in range(n):
        b = bstart[i]
        b1 = bstart[i + 1]
        for c in range(start[i], start[i + 1]):
            while b < b1 and bj[b] < pj[c]:
                b += 1
            if b < b1 and bj[b] == pj[c] and replaces_contact(bprm[bmodel[b], B_KIND], bstate[b], bhist[b, H_D0]):
                keep[c] = False
    nstart = np.zeros(n + 1, np.int64)
    for i in range(n):
        cnt = 0
        for c in range(start[i], start[i + 1]):
            if keep[c]:
                cnt += 1
        nstart[i + 1] = nstart[i] + cnt
    idx = np.nonzero(keep)[0]
    return nstart, pi[idx].copy(), pj[idx].copy()


@njit
def bond_strain_energy(bstart, bj, bmodel, bstate, hist, bprm, xs, rad, smat, prm, law, friction, rolling):
    """Elastic energy held by all intact bonds and seated pairs [J] (serial, fixed order)."""
    fts = hist[:, H_FS:H_FS + 3]
    mrs = hist[:, H_MB:H_MB + 3]
    e = 0.0
    for i in range(bstart.shape[0] - 1):
        for b in range(bstart[i], bstart[i + 1]):
            d0 = hist[b, H_D0]
            if bstate[b] != INTACT and d0 <= 0.0:
                continue
            j = bj[b]
            d = math.sqrt((xs[i, 0] - xs[j, 0]) ** 2 + (xs[i, 1] - xs[j, 1]) ** 2 + (xs[i, 2] - xs[j, 2]) ** 2)
            delta = rad[i] + rad[j] - d
            if bstate[b] == INTACT:
                e += bond_energy(bprm, bmodel[b], hist, b, delta, rad[i], rad[j])
            elif delta > d0:
                e += strain_energy(law, prm, smat[i], smat[j], delta - d0, rad[i] * rad[j] / (rad[i] + rad[j]),
                                   fts, mrs, b, friction, rolling)
    return e
