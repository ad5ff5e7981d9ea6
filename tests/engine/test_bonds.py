"""Bonds between spheres (issue #9): Burgers creep and relaxation, a parallel-bonded
cantilever, breakage by mode, energy book-keeping and the critical time step.

Every test compares a measured quantity with an analytic value and states its reference,
its tolerance and the value measured when it was written. Kernel-level tests call
:func:`demcli.kernels.bonds.burgers_update` from a small compiled driver; engine-level
tests build spheres-only Systems with the ``build`` fixture of ``conftest.py``. Sign
conventions (:mod:`demcli.kernels.bonds`): sphere i < j, n from j to i, forces on i,
normal force positive in compression.
"""

import math

import numba
import numpy as np
import pytest

from demcli.engine.bonds import model_row
from demcli.kernels import bonds as B
from demcli.kernels import layout as K
from demcli.kernels.bonds import burgers_update

R = 0.01            # sphere radius [m]
RHO = 2650.0        # density [kg/m^3]
MASS = RHO * 4.0 / 3.0 * math.pi * R ** 3
INERT = 0.4 * MASS * R * R
FIXED = K.FIX_TRANSLATION | K.FIX_ROTATION   # prescribed velocity and spin


# ---- Burgers element, kernel level -----------------------------------------------------
# A Burgers element: Maxwell spring K_m and dashpot C_m in series with a Kelvin element
# (K_k parallel to C_k), tau_k = C_k / K_k the (shortest) retardation time.
KM, CM, KK, CK = 1e5, 5e4, 5e4, 5e2
TAU_K = CK / KK                                    # 0.01 s
KELVIN_LIMIT = 1.0 / (1.0 / KM + 1.0 / KK)         # Kelvin dashpot negligible: springs in series


def creep_exact(t, force, km=KM, cm=CM, kk=KK, ck=CK):
    """Burgers creep under a constant force applied at t = 0 (e.g. Findley, Lai & Onaran
    1976, ch. 5): u = F/K_m + F t/C_m + F/K_k (1 - exp(-t K_k/C_k))."""
    return force / km + force * t / cm + force / kk * (1.0 - np.exp(-t * kk / ck))


def _laplace(km, cm, kk, ck):
    """(a2, b1, b2, p1, p2) of the Burgers relaxation in Laplace form (see relaxation_exact)."""
    a1 = ck / kk + cm * (1.0 / kk + 1.0 / km)
    a2 = ck * cm / (kk * km)
    disc = math.sqrt(a1 * a1 - 4.0 * a2)
    return a2, cm, ck * cm / kk, (-a1 + disc) / (2.0 * a2), (-a1 - disc) / (2.0 * a2)


def relaxation_exact(t, u0, km=KM, cm=CM, kk=KK, ck=CK):
    """Burgers relaxation under a displacement u0 held from t = 0 (PFC's Burgers model).

    Laplace: u(p) = s(p) J(p), J = 1/K_m + 1/(C_m p) + 1/(K_k + C_k p); for u = u0 / p,
    s(p) = u0 (b1 + b2 p) / (1 + a1 p + a2 p^2) with a1 = C_k/K_k + C_m (1/K_k + 1/K_m),
    a2 = C_k C_m / (K_k K_m), b1 = C_m, b2 = C_k C_m / K_k. The roots p1, p2 of
    a2 p^2 + a1 p + 1 are real and negative (a1^2 - 4 a2 >= (C_m/K_m - C_k/K_k)^2), so
    s(t) = u0 / a2 [(b1 + b2 p1) e^{p1 t} - (b1 + b2 p2) e^{p2 t}] / (p1 - p2);
    s(0) = u0 b2 / a2 = K_m u0 (checked in the test).
    """
    a2, b1, b2, p1, p2 = _laplace(km, cm, kk, ck)
    return u0 / a2 * ((b1 + b2 * p1) * np.exp(p1 * t) - (b1 + b2 * p2) * np.exp(p2 * t)) / (p1 - p2)


def ramp_exact(t, v, km=KM, cm=CM, kk=KK, ck=CK):
    """Burgers force under a displacement u = v t from rest: v times the integral of the
    relaxation modulus (relaxation_exact with u0 = 1), each e^{p t} integrating to
    (e^{p t} - 1) / p."""
    a2, b1, b2, p1, p2 = _laplace(km, cm, kk, ck)
    return v / a2 * ((b1 + b2 * p1) * np.expm1(p1 * t) / p1 - (b1 + b2 * p2) * np.expm1(p2 * t) / p2) / (p1 - p2)


@numba.njit(cache=False)  # not cached: a test module has no stable import name
def _drive(s0, uk0, du, dt, km, cm, kk, ck):
    """Element force, Kelvin displacement and dissipation after each increment du[k]."""
    n = du.shape[0]
    s = np.empty(n + 1)
    uk = np.empty(n + 1)
    ed = np.empty(n)
    s[0] = s0
    uk[0] = uk0
    for k in range(n):
        s[k + 1], uk[k + 1], ed[k] = burgers_update(s[k], uk[k], du[k], dt, km, cm, kk, ck)
    return s, uk, ed


@pytest.mark.parametrize("ratio", [1e-4, 1e-3, 1e-2, 1e-1, 1.0, 10.0, 100.0])
def test_burgers_update_is_exact_for_a_steady_displacement_rate(ratio):
    # Given an element at rest stretched at a constant rate v (what the engine's drift gives
    # within a step), dt / tau_k = ratio
    v = 1e-3
    dt = ratio * TAU_K
    n = max(20, int(round(3 * TAU_K / dt)))
    s, uk, ed = _drive(0.0, 0.0, np.full(n, v * dt), dt, KM, CM, KK, CK)
    ex = ramp_exact(np.arange(n + 1) * dt, v)
    # Then the force is the analytic response at every step, for any dt: the update is the exact
    # step map (tolerance 1e-9 of the largest force; measured 2e-16 .. 9e-16), and each step
    # dissipates (the trapezoid's work less the stored energy's change, >= 0 to round-off)
    err = np.abs(s - ex).max() / np.abs(ex).max()
    print(f"dt/tau_k={ratio:g}: max |s - s_exact| / max s {err:.1e}")
    assert err < 1e-9
    assert ed.min() > -1e-12 * np.abs(ex).max() * v * dt


@pytest.mark.parametrize("ratio", [1e-4, 1e-3, 1e-2, 1e-1])
def test_burgers_update_creeps_on_the_analytic_curve(ratio):
    # Given an element just after a load F was applied (s = F, u_k = 0, u = F / K_m), driven by
    # the displacement increments of the analytic creep curve, dt / tau_k = ratio
    force = 2.0
    dt = ratio * TAU_K
    n = max(20, int(round(3 * TAU_K / dt)))
    t = np.arange(n + 1) * dt
    u = creep_exact(t, force)
    s, uk, ed = _drive(force, 0.0, np.diff(u), dt, KM, CM, KK, CK)
    # Then the force stays F within 1 % (issue #9, dt / tau_k from 1e-4 to 1e-1): the creep curve
    # bends inside each step while the update takes the displacement as linear in it, an error of
    # second order (measured 5.2e-10, 5.2e-8, 5.2e-6, 5.1e-4 of F), and the Kelvin element
    # follows F/K_k (1 - exp(-t/tau_k)) as closely
    dev = np.abs(s / force - 1.0).max()
    print(f"dt/tau_k={ratio:g}: max |s/F - 1| {dev:.1e}")
    assert dev < 0.01
    assert np.abs(uk - force / KK * (1.0 - np.exp(-t / TAU_K))).max() < 0.01 * force / KK
    # and the dashpots dissipate: F du - d(stored) >= 0 each step
    assert ed.min() > -1e-15


@pytest.mark.parametrize("ratio, tol", [(1e-4, 1e-9), (1e-3, 1e-9), (1e-2, 1e-9), (1e-1, 1e-9), (10.0, 1e-9),
                                        (100.0, 1e-9)])
def test_burgers_update_relaxes_on_the_two_exponential_curve(ratio, tol):
    # Given an element just after a displacement u0 was applied (s = K_m u0, u_k = 0), held (du = 0)
    u0 = 1e-5
    t_end = 5.0  # > 3 x the slow relaxation time (1.51 s); the fast one is 3.3e-3 s
    dt = ratio * TAU_K
    n = int(round(t_end / dt))
    assert relaxation_exact(np.zeros(1), u0)[0] == pytest.approx(KM * u0, rel=1e-12)
    s, uk, ed = _drive(KM * u0, 0.0, np.zeros(n), dt, KM, CM, KK, CK)
    ex = relaxation_exact(np.arange(n + 1) * dt, u0)
    # Then the force follows the analytic curve. Reference: relaxation_exact. Tolerance: issue #9 asks
    # for 1 % at dt/tau_k 1e-4..1e-1; here tol of K_m u0 and 2 tol relative while s > 1 % of K_m u0.
    # Measured (second order in dt): max |s - s_exact| / (K_m u0) = 1.3e-9, 1.3e-7, 1.3e-5, 1.3e-3;
    # relative 2.4e-9, 2.4e-7, 2.4e-5, 2.4e-3.
    err = np.abs(s - ex)
    print(f"dt/tau_k={ratio:g}: max err / s0 {err.max() / (KM * u0):.3e}")
    assert err.max() < tol * KM * u0
    big = ex > 0.01 * KM * u0
    assert (err[big] / ex[big]).max() < 2 * tol
    # and every step dissipates, the losses adding up to the stored energy released
    assert ed.min() > 0.0
    released = 0.5 * KM * u0 ** 2 - 0.5 * s[-1] ** 2 / KM - 0.5 * KK * uk[-1] ** 2
    assert ed.sum() == pytest.approx(released, rel=1e-9)


CM_SLOW = 1e6  # Maxwell time C_m / K_m = 10 s = 1000 tau_k: above the largest step tried


@pytest.mark.parametrize("ratio", [10.0, 100.0])
def test_burgers_relaxation_with_steps_far_above_the_retardation_time_is_bounded(ratio):
    # Given the held element of the previous test with dt = 10 and 100 tau_k and a Maxwell time of
    # 1000 tau_k, so that the slow decay spans many steps
    u0 = 1e-5
    s0 = KM * u0
    dt = ratio * TAU_K
    n = int(round(20.0 / dt))
    s, uk, _ = _drive(s0, 0.0, np.zeros(n), dt, KM, CM_SLOW, KK, CK)
    ex = relaxation_exact(np.arange(n + 1) * dt, u0, cm=CM_SLOW)
    # Then it stays bounded and positive, 0 < s <= s0, decays monotonically (the first step after
    # the jump included: the step map is exact, no overshoot), and sits on the exact curve
    # (tolerance 1e-9 of s0; measured 4e-16 at 10 and 3e-16 at 100)
    assert np.all(s > 0.0) and np.all(s <= s0)
    assert np.all(np.diff(s) <= 0.0)
    err = np.abs(s - ex).max() / s0
    print(f"dt/tau_k={ratio:g}: max |s - s_exact| / s0 {err:.1e}, s1/s0 {s[1] / s0:.4f} "
          f"(Kelvin-as-spring limit {KELVIN_LIMIT / KM:.4f})")
    assert err < 1e-9
    # and the Kelvin element has settled at s / K_k: after one step of 10 tau_k its dashpot is spent
    # (lag tau_k / tau_M = 3.3e-4 of the slow decay, measured 3.3e-4; tolerance 1e-3)
    assert abs(uk[-1] * KK / s[-1] - 1.0) < 1e-3


def test_burgers_relaxation_after_a_jump_is_monotone_at_ten_retardation_times():
    # Given the held element at dt = 10 tau_k (the issue asks for a monotone decay at 10 and 100)
    s, _, _ = _drive(KM * 1e-5, 0.0, np.zeros(200), 10 * TAU_K, KM, CM_SLOW, KK, CK)
    # Then the force never rises: the exact step map has no overshoot (the earlier update took the
    # force as linear within a step and undershot the first step by 15 %, then rose back)
    assert np.all(np.diff(s) <= 0.0)


def test_explicit_euler_of_the_same_element_blows_up_where_the_update_does_not():
    # Given the held element at dt = 10 tau_k, integrated by explicit Euler of
    # s' = K_m (u' - s/C_m - u_k'), u_k' = (s - K_k u_k)/C_k with u' = 0
    dt = 10 * TAU_K
    s, uk = KM * 1e-5, 0.0
    for _ in range(20):
        duk = (s - KK * uk) / CK
        s, uk = s + dt * KM * (-s / CM - duk), uk + dt * duk
    # Then it diverges (growth factor about 1 - dt (1/tau_k + K_m/C_k) = -29 per step) ...
    assert abs(s) > 1e20
    # ... while burgers_update stays bounded (previous test)
    s2, _, _ = _drive(KM * 1e-5, 0.0, np.zeros(20), dt, KM, CM, KK, CK)
    assert np.all(np.abs(s2) <= KM * 1e-5)


# ---- engine helpers ------------------------------------------------------------------------
def pair(build, row, v=((0, 0, 0), (0, 0, 0)), omega=((0, 0, 0), (0, 0, 0)), flags=(FIXED, FIXED),
         effects=("bonds",), contact_kn=1e5, contact_kt=0.0, dt_factor=0.1, gap=0.0, friction=0.0,
         restitution=1.0, stress_free=False, **kw):
    """Two spheres, 0 at the origin and 1 at (2R + gap, 0, 0), bonded with model ``row``
    (``stress_free``: delta_0 = -gap); n (from j = 1 to i = 0) is -x. Contact: linear,
    ``restitution`` (1: no dashpot), tangential spring ``contact_kt``, Coulomb ``friction``."""
    s = build.sphere_system([[0, 0, 0], [2 * R + gap, 0, 0]], v, R,
                            [build.Material("m", RHO, friction=friction, restitution=restitution)],
                            build.ContactModel(law="linear", kn=contact_kn, kt=contact_kt), effects=effects, omega=omega,
                            dt_factor=dt_factor, **kw)
    s.bonds.set_models([(0, 0)], [row])
    s.bflags[:] = flags
    assert s.bond_touching(1e-9 + max(gap, 0.0), stress_free=stress_free) == 1
    s.dt = dt_factor * s.critical_dt()
    return s


def step_until_broken(s, max_steps):
    """Advance one step at a time; returns the bond history rows of every intact step."""
    rows = []
    while s.bonds.state[0] == B.INTACT:
        assert len(rows) < max_steps, "the bond never broke"
        rows.append(s.bonds.hist[0].copy())
        assert s.advance(1)[0] == K.OK
    return np.array(rows)


def pb_geometry(lam=1.0):
    rb = lam * R
    area = math.pi * rb * rb
    inert = 0.25 * area * rb * rb
    return rb, area, inert, 2.0 * inert


# ---- Burgers creep, engine level ----------------------------------------------------------
@pytest.mark.parametrize("ratio", [1e-4, 1e-3])
@pytest.mark.parametrize("mode", ["tension", "shear", "compression"])
def test_burgers_bonded_pair_creeps_on_the_analytic_curve(build, mode, ratio):
    # Given sphere 1 held (translation and spin) and sphere 0 pulled by its weight F = m g away
    # from it along the bond (tension element) or across it (shear element; sphere 0 does not spin),
    # a Burgers bond (K_m = K_k = C_m = 1e4, C_k = 3e3: tau_k = 0.3 s, Maxwell time 1 s) and
    # viscous damping alpha = sqrt(K_m/m)/2 that kills the oscillation of period 6.6 ms << tau_k
    km, cm, kk, ck = 1e4, 1e4, 1e4, 3e3
    tau = ck / kk
    el = dict(km=km, cm=cm, kk=kk, ck=ck)
    g = 9.81
    # (compression: pushed into it, the bond's option compression: burgers, the tension element's constants)
    gravity = {"tension": (-g, 0.0, 0.0), "compression": (g, 0.0, 0.0)}.get(mode, (0.0, 0.0, -g))
    alpha = 0.5 * math.sqrt(km / MASS)
    comp = "burgers" if mode == "compression" else "elastic"
    s = pair(build, model_row("burgers", kn=1e4, tension=el, shear=el, compression=comp),
             flags=(K.FIX_ROTATION, FIXED),
             effects=("bonds", "gravity", "viscous_damping"), contact_kn=1e4, gravity=gravity,
             viscous_damping=alpha)
    s.dt = ratio * tau
    assert s.dt < 0.5 * s.critical_dt()   # 0.43 x critical at 1e-3
    force = MASS * g
    errors = []
    for frac in (0.25, 0.5, 1.0, 2.0, 3.0):
        assert s.advance(int(round(frac * tau / s.dt)) - s.step)[0] == K.OK
        u = {"tension": -s.x[0, 0], "compression": s.x[0, 0]}.get(mode, -s.x[0, 2])
        errors.append(u / creep_exact(s.time, force, km, cm, kk, ck) - 1.0)
    # Then the displacement after the transient follows the creep curve. Reference: creep_exact.
    # Tolerance 1 % (issue #9). Measured: -3.4e-3 at t = tau/4 falling to -1.0e-3 at 3 tau, both dt
    # and all three modes (the damping's drag, alpha m / C_k = 1.8e-3, and the transient's delay).
    print(mode, ratio, ["%.2e" % e for e in errors])
    assert max(abs(e) for e in errors) < 0.01
    # and the element carries the weight less the damping's drag alpha m u' (quasi-static):
    # tolerance 1e-3, measured -6.1e-4 (alpha m F / C_m = 5.3e-4 of F)
    carried = {"tension": s.bonds.hist[0, B.H_FN], "compression": -s.bonds.hist[0, B.H_FN]}.get(
        mode, s.bonds.hist[0, B.H_FS + 2])
    assert carried == pytest.approx(force, rel=1e-3)


# ---- parallel-bonded cantilever -----------------------------------------------------------
def test_parallel_bonded_cantilever_deflects_as_euler_bernoulli(build):
    # Given a row of 20 touching spheres along x, sphere 0 clamped, parallel bonds (radius
    # multiplier 1, kn_b = 2e10 Pa/m, ks_b = 8e9 Pa/m), frictionless linear contacts beside them,
    # loaded by its weight along -z and damped to rest (viscous, alpha = 2 omega_1)
    n, g = 20, 9.81
    knb, ksb = 2e10, 8e9
    _, area, ib, _ = pb_geometry()
    ei = knb * ib * 2 * R          # EI = k_r L0: k_r = kn_b I_b per relative rotation, L0 = 2R
    a = 2 * R * np.arange(1, n)    # load positions from the clamp
    length = a[-1]
    w1 = 3.516 * math.sqrt(ei / (MASS / (2 * R) * length ** 4))   # first bending mode of a cantilever
    x = np.zeros((n, 3))
    x[:, 0] = 2 * R * np.arange(n)
    s = build.sphere_system(x, np.zeros((n, 3)), R, [build.Material("m", RHO, friction=0.0)],
                            build.ContactModel(law="linear", kn=knb * area),
                            effects=("bonds", "gravity", "viscous_damping"), gravity=(0, 0, -g),
                            viscous_damping=2 * w1)
    s.bonds.set_models([(0, 0)], [model_row("parallel_bond", bond_kn=knb, bond_ks=ksb, radius_multiplier=1.0)])
    s.bflags[0] = FIXED
    assert s.bond_touching(1e-9 * R) == n - 1
    s.dt = 0.5 * s.critical_dt()
    assert s.advance(int(25 / w1 / s.dt))[0] == K.OK
    assert np.abs(s.v).max() < 1e-6   # at rest (measured 1.5e-8 m/s)
    # Then the tip deflection is the Euler-Bernoulli superposition of the point loads m g at a_k:
    # delta = sum m g a_k^2 (3L - a_k) / (6 EI) (Gere & Timoshenko, Mechanics of Materials, table G-1).
    # Tolerance: 5 % (issue #9); asserted at 1 %. Measured: +6.6e-4 (delta / L = 1.3 %; the rest is
    # the bonds' shear compliance, ~3 kn_b / (16 N^2 ks_b) = 1.2e-3 for a tip load, and the
    # discrete chain, a midpoint rule of the beam integral)
    d_eb = np.sum(MASS * g * a ** 2 * (3 * length - a) / (6 * ei))
    tip = -s.x[-1, 2]
    print(f"tip {tip:.6e} m, Euler-Bernoulli {d_eb:.6e} m, error {tip / d_eb - 1:.3e}")
    assert tip == pytest.approx(d_eb, rel=0.01)
    # and the bond at the clamp carries the statics of the cantilever: shear force (N - 1) m g and
    # bending moment sum m g (a_k - R) about its contact point (tolerance 1e-3; measured -8.8e-7,
    # -6.9e-5)
    h = s.bonds.hist[0]   # bond 0-1; forces and moments on sphere 0, the clamp
    shear = np.linalg.norm(h[B.H_FS:B.H_FS + 3])
    moment = np.linalg.norm(h[B.H_MB:B.H_MB + 3])
    print(f"clamp bond: shear {shear / ((n - 1) * MASS * g) - 1:.2e}, moment "
          f"{moment / np.sum(MASS * g * (a - R)) - 1:.2e}")
    assert shear == pytest.approx((n - 1) * MASS * g, rel=1e-3)
    assert moment == pytest.approx(np.sum(MASS * g * (a - R)), rel=1e-3)


# ---- breakage ---------------------------------------------------------------------------
def test_contact_bond_breaks_in_tension_at_its_normal_strength(build):
    # Given a contact bond (kn 1e5 N/m, s_n = 1 N), sphere 1 pulled away at 1 mm/s, sphere 0 held
    kn, sn, v = 1e5, 1.0, 1e-3
    s = pair(build, model_row("contact_bond", kn=kn, ks=5e4, normal_strength=sn, shear_strength=10.0),
             v=((0, 0, 0), (v, 0, 0)))
    rows = step_until_broken(s, 2000)
    # Then it breaks in tension when -F_n reaches s_n: the largest tension carried is within one
    # step's increment kn v dt below s_n (measured: s_n - 0.95 increment, after 352 steps)
    tension = -rows[:, B.H_FN]
    inc = kn * v * s.dt
    print(f"largest tension {tension.max():.6f} N, increment {inc:.2e} N, steps {len(rows)}")
    assert sn - inc <= tension.max() < sn
    # and until then F_n = kn delta, delta = -v t (row k: after k steps)
    assert np.allclose(tension, inc * np.arange(len(rows)), rtol=1e-6, atol=1e-9 * sn)
    assert s.bonds.state[0] == B.BROKEN_TENSION
    assert s.bonds.counts() == {"intact": 0, "broken_tension": 1, "broken_shear": 0}
    # the broken bond holds nothing and the spheres feel no force (apart, no contact)
    assert np.all(s.bonds.hist[0] == 0.0) and np.all(s.f == 0.0)


def test_contact_bond_breaks_in_shear_at_its_shear_strength(build):
    # Given a contact bond (ks 5e4 N/m, s_s = 1 N, s_n = 10 N), sphere 1 moved sideways at 1 mm/s,
    # neither sphere turning
    ks, ss, v = 5e4, 1.0, 1e-3
    s = pair(build, model_row("contact_bond", kn=1e5, ks=ks, normal_strength=10.0, shear_strength=ss),
             v=((0, 0, 0), (0, v, 0)))
    rows = step_until_broken(s, 2000)
    # Then it breaks in shear when |F_s| reaches s_s, within one step's increment ks v dt (measured
    # s_s - 0.91 increment; the tension stays ~kn y^2 / 4R, measured at most 1.0e-3 N)
    fs = np.linalg.norm(rows[:, B.H_FS:B.H_FS + 3], axis=1)
    inc = ks * v * s.dt
    print(f"largest shear {fs.max():.6f} N, increment {inc:.2e} N, largest tension {-rows[:, B.H_FN].min():.2e} N")
    assert ss - inc <= fs.max() < ss
    assert s.bonds.counts() == {"intact": 0, "broken_tension": 0, "broken_shear": 1}
    # the shear force on sphere 0 pulled it along +y, after sphere 1 (F_s = -ks (v_0 - v_1) t)
    assert rows[-1, B.H_FS + 1] > 0.99 * fs.max()


def _break_then_push_back(build, stepwise):
    """A contact bond (kn_b 2e5 N/m, s_n = 1 N) beside a linear contact law (kn 1e5 N/m, no
    dashpot): sphere 1 pushed into sphere 0 for 100 steps, pulled off until the bond breaks
    (in one call of 2000 steps, or one step per call), then pushed back until the overlap is
    2 um. Returns (system, overlap function, bonded overlap and force on 0)."""
    kb, kc, v = 2e5, 1e5, 1e-3
    s = pair(build, model_row("contact_bond", kn=kb, ks=5e4, normal_strength=1.0), v=((0, 0, 0), (-v, 0, 0)),
             contact_kn=kc)

    def overlap():
        return 2 * R - (s.x[1, 0] - s.x[0, 0])

    assert s.advance(100)[0] == K.OK
    bonded = (overlap(), s.f[0, 0])
    s.v[1, 0] = v
    if stepwise:
        step_until_broken(s, 5000)
    else:
        assert s.advance(2000)[0] == K.OK   # breaks at step 284 of the 2000
    assert s.bonds.counts()["broken_tension"] == 1
    s.v[1, 0] = -v
    while overlap() < 2e-6:
        assert s.advance(1)[0] == K.OK
        if overlap() < 0:
            assert np.all(s.f == 0.0)   # apart: no tension once broken
    return s, overlap, bonded


def test_broken_contact_bond_leaves_an_ordinary_contact(build):
    # Given a contact bond (kn_b 2e5 N/m, s_n = 1 N) beside a frictionless linear contact law
    # (kn 1e5 N/m, no dashpot): pushed together, pulled apart until it breaks (inside one
    # advance() call), pushed back to a 2 um overlap
    kb, kc = 2e5, 1e5
    s, overlap, (ov_bonded, f_bonded) = _break_then_push_back(build, stepwise=False)
    # Then while bonded the bond replaces the contact: F = kn_b delta, not (kn_b + kn) delta
    # (relative 1e-9; measured 0)
    assert ov_bonded > 0 and f_bonded == pytest.approx(-kb * ov_bonded, rel=1e-9)
    # and after it broke the pair repels with the contact law, F = kn delta (relative 1e-9;
    # measured 0)
    assert s.contact_count()[0] == 1
    n = (s.x[0] - s.x[1]) / np.linalg.norm(s.x[0] - s.x[1])
    np.testing.assert_allclose(s.f[0], kc * overlap() * n, rtol=1e-12, atol=1e-12 * kc * D0)
    assert s.f[1, 0] == pytest.approx(kc * overlap(), rel=1e-9)


def test_bond_broken_on_the_last_step_of_a_call_leaves_an_ordinary_contact(build):
    # Given the same pair, but stepped one step per advance() call, so that the bond breaks on
    # the last step of a call (a stage's chunk ends there too, once per chunk)
    s, overlap, _ = _break_then_push_back(build, stepwise=True)
    # Then the pair repels with the contact law: System.advance sees the bond state change and
    # rebuilds the pair list at the next call (run_steps' own rebuild request ends with the call;
    # before the fix: F = 0 at 2 um overlap, an empty pair list)
    assert s.f[0, 0] == pytest.approx(-1e5 * overlap(), rel=1e-9)


# ---- a broken stress-free contact bond: the seated pair -------------------------------------
D0 = 2e-5   # installed overlap [m]


def _seated_pair(build, **kw):
    """A contact bond (kn_b 2e5, ks 5e4 N/m, s_s = 0.05 N) installed stress-free on a 20 um
    overlap beside a linear contact law (kn 1e5 N/m, no dashpot), broken in shear by sliding
    sphere 1 along y at 1 mm/s; then stopped. Returns the system and its overlap function."""
    s = pair(build, model_row("contact_bond", kn=2e5, ks=5e4, normal_strength=10.0, shear_strength=0.05),
             v=((0, 0, 0), (0, 1e-3, 0)), gap=-D0, stress_free=True, **kw)
    assert s.bonds.hist[0, B.H_D0] == pytest.approx(D0, rel=1e-9)
    step_until_broken(s, 5000)
    s.v[1] = 0.0

    def overlap():
        return 2 * R - np.linalg.norm(s.x[1] - s.x[0])
    return s, overlap


def test_broken_stress_free_bond_keeps_its_reference_overlap_until_the_spheres_part(build):
    # Given the seated pair: broken in shear at an overlap just under delta_0 (the slide moved the
    # spheres 5 um along y, delta = 20 um - 6e-4 um)
    s, overlap = _seated_pair(build)
    kc = 1e5
    assert s.bonds.counts()["broken_shear"] == 1 and 0 < overlap() < D0
    assert s.advance(5)[0] == K.OK
    # Then the pair carries no force while 0 < delta <= delta_0 (before: the contact law took the
    # full 20 um overlap, 2.0 N), and it is no contact of the pair list (the bond pass keeps it)
    assert np.all(s.f == 0.0)
    assert s.contact_count()[0] == 0 and s.bonds.seated().tolist() == [True]
    # When sphere 1 is pushed in along -x until delta = delta_0 + 3 um
    s.v[1] = (-1e-3, 0, 0)
    while overlap() < D0 + 3e-6:
        assert s.advance(1)[0] == K.OK
    assert s.advance(1)[0] == K.OK  # (the force of the last step's positions)
    # Then it pushes back with the contact law on the overlap beyond delta_0, F = kn (delta -
    # delta_0) along n (from 1 to 0; relative 1e-12, measured 2e-16), and counts as a contact of
    # both spheres
    s.v[1] = 0.0
    assert s.advance(1)[0] == K.OK
    n = (s.x[0] - s.x[1]) / np.linalg.norm(s.x[0] - s.x[1])
    np.testing.assert_allclose(s.f[0], kc * (overlap() - D0) * n, rtol=1e-12, atol=1e-12 * kc * D0)
    np.testing.assert_array_equal(s.f[1], -s.f[0])
    assert s.contacts_per_sphere().tolist() == [1, 1]
    # When it is pulled apart until the spheres part (delta < 0) and pushed back to delta = 2 um
    s.v[1] = (1e-3, 0, 0)
    while overlap() >= 0:
        assert s.advance(1)[0] == K.OK
    assert s.advance(1)[0] == K.OK
    # Then delta_0 is cleared (released) and the pair is an ordinary contact again: F = kn delta
    assert s.bonds.hist[0, B.H_D0] == 0.0 and s.bonds.seated().tolist() == [False]
    s.v[1] = (-1e-3, 0, 0)
    while overlap() < 2e-6:
        assert s.advance(1)[0] == K.OK
    s.v[1] = 0.0
    assert s.advance(1)[0] == K.OK
    assert s.contact_count()[0] == 1
    n = (s.x[0] - s.x[1]) / np.linalg.norm(s.x[0] - s.x[1])
    np.testing.assert_allclose(s.f[0], kc * overlap() * n, rtol=1e-12, atol=1e-12 * kc * D0)


def test_seated_pair_slides_with_coulomb_friction_on_its_own_normal_force(build):
    # Given the seated pair with friction mu = 0.4 (contact kt 5e4 N/m), pushed 3 um beyond
    # delta_0 and then slid along z at 1 mm/s (the spring reaches the limit after ~0.5 um)
    mu, kc = 0.4, 1e5
    s, overlap = _seated_pair(build, effects=("bonds", "friction", "energy"), friction=mu, contact_kt=5e4)
    s.v[1] = (-1e-3, 0, 0)
    while overlap() < D0 + 3e-6:
        assert s.advance(1)[0] == K.OK
    s.v[1] = (0, 0, 1e-3)
    assert s.advance(400)[0] == K.OK
    # Then the force on sphere 0 has the normal part kn (delta - delta_0) and a tangential part at
    # the Coulomb limit mu kn (delta - delta_0), dragging it along +z (relative 1e-9; measured
    # 1e-16), and the bond's history row holds that spring
    fn = kc * (overlap() - D0)
    n = (s.x[0] - s.x[1]) / np.linalg.norm(s.x[0] - s.x[1])
    f_n = s.f[0] @ n
    f_t = s.f[0] - f_n * n
    assert f_n == pytest.approx(fn, rel=1e-9)
    assert np.linalg.norm(f_t) == pytest.approx(mu * fn, rel=1e-9) and f_t[2] > 0.999 * mu * fn
    assert np.linalg.norm(s.bonds.hist[0, B.H_FS:B.H_FS + 3]) == pytest.approx(mu * fn, rel=1e-9)
    # and the slip dissipated mu F_n (slide - mu F_n / kt) (relative 1e-2: F_n drifts as the
    # spheres slide; measured 4.4e-4)
    slide = 400 * s.dt * 1e-3
    expect = mu * fn * (slide - mu * fn / 5e4)
    print(f"friction loss {s.losses()['friction']:.6e} J against {expect:.6e} J")
    assert s.losses()["friction"] == pytest.approx(expect, rel=1e-2)


def test_free_seated_pair_does_not_fire_apart_and_balances_its_energy(build):
    # Given two free spheres bonded stress-free on a 0.2 mm overlap (kn_b 2e5, ks 5e4 N/m,
    # s_s = 0.05 N; contact kn 1e5 N/m, no dashpot, frictionless), sent towards each other at
    # 1 mm/s each and sliding past at 5 mm/s: the bond breaks in shear while compressed
    d0 = 2e-4
    s = pair(build, model_row("contact_bond", kn=2e5, ks=5e4, normal_strength=10.0, shear_strength=0.05),
             v=((1e-3, 5e-3, 0), (-1e-3, -5e-3, 0)), gap=-d0, stress_free=True, flags=(0, 0),
             effects=("bonds", "energy"), dt_factor=0.05)
    e0 = s.energy_record()["total"]
    ke0 = s.kinetic_energy()
    total, ke = [], []
    for _ in range(3000):
        assert s.advance(10)[0] == K.OK
        rec = s.energy_record()
        total.append(rec["total"])
        ke.append(rec["kinetic"])
    total = np.array(total)
    # Then it broke, the seated contact rebounded the spheres and they parted (released)
    assert s.bonds.counts()["broken_shear"] == 1 and s.bonds.hist[0, B.H_D0] == 0.0
    assert np.linalg.norm(s.x[1] - s.x[0]) > 2 * R
    # and the kinetic energy never rose above its start (before: the contact law took the whole
    # 0.2 mm overlap, 0.5 kn d0^2 = 2e-3 J against E_k0 = 2.9e-7 J, and fired the pair apart:
    # max E_k / E_k0 = 6950; measured now 0.913, records every 10 steps)
    print(f"max E_k / E_k0 {max(ke) / ke0:.6f}, max |drift| {np.abs(total - e0).max() / e0:.2e}")
    assert max(ke) <= ke0 * (1 + 1e-6)
    # and E_k + E_s + losses stays at its start within 1e-4 of E_0 (measured 2.6e-5): the bond's
    # energy is booked as lost when it breaks, with the work its force would have done in the
    # step's second half kick, less the seated contact's spring energy and work, which take over
    # in the same step. Booking the bond's energy alone left a jump of 1.2e-2 E_0 at the break
    # (0.5 dt F . v with F = 0.05 N), first order in dt
    assert np.abs(total - e0).max() < 1e-4 * e0


@pytest.mark.parametrize("mu", [0.0, 0.3])
def test_seated_pair_with_dashpot_and_slip_balances_its_energy_once_apart(build, mu):
    # Given the free pair of the previous test, but with a dashpot (restitution 0.5) and friction
    # mu (contact kt 5e4 N/m): it breaks in shear while compressed, the seated contact takes over
    # in the break step, (slides,) rebounds the spheres and lets them go; run at 0.05 and 0.025 x
    # the critical step
    d0 = 2e-4
    drift = []
    for dtf in (0.05, 0.025):
        s = pair(build, model_row("contact_bond", kn=2e5, ks=5e4, normal_strength=10.0, shear_strength=0.05),
                 v=((1e-3, 5e-3, 0), (-1e-3, -5e-3, 0)), gap=-d0, stress_free=True, flags=(0, 0),
                 effects=("bonds", "energy", "friction"), dt_factor=dtf, restitution=0.5, friction=mu,
                 contact_kt=5e4)
        e0 = s.energy_record()["total"]
        assert s.advance(int(round(1500 / dtf)))[0] == K.OK
        rec = s.energy_record()
        drift.append(abs(rec["total"] - e0) / e0)
        # Then the pair has parted (released) after losing energy to the dashpot (and to slip)
        assert s.bonds.hist[0, B.H_D0] == 0.0 and rec["strain"] == 0.0
        assert rec["damping"] > 0.0 and (rec["friction"] > 0.0) == (mu > 0.0)
    # and E_k + losses equals E_0 within 2e-3 at 0.05 x critical, converging in dt like an
    # ordinary contact's (an ordinary collision of the same spheres: 5e-4, 6e-4). Measured:
    # 1.9e-4 and 8.3e-5 (mu = 0); 4.0e-4 and 2.5e-4 (mu = 0.3: ratio 0.62; with the earlier
    # Coulomb limit mu max(F_n, 0), docs/contact.md, 1.25e-3 and 6.6e-4). Booking the break
    # step's whole dashpot loss on top of the work term gave 7.5e-4 and 3.6e-4 at mu = 0.
    print(f"mu {mu}: |drift| {drift[0]:.2e} (0.05), {drift[1]:.2e} (0.025)")
    assert drift[0] < 2e-3 and drift[1] < 0.7 * drift[0]


def test_seated_pair_resumes_from_its_state_file_bit_identically(build, tmp_path):
    # Given the seated pair with friction, pushed 3 um beyond delta_0 and sliding (its spring in
    # the bond's history row), written to a state file and read back into a second system
    from demcli.engine.system import System
    from demcli.state import read_state, write_state
    from demcli.state.fields import new_state

    a, overlap = _seated_pair(build, effects=("bonds", "friction"), friction=0.4, contact_kt=5e4)
    a.v[1] = (-1e-3, 0, 1e-3)
    while overlap() < D0 + 3e-6:
        assert a.advance(1)[0] == K.OK
    assert np.linalg.norm(a.bonds.hist[0, B.H_FS:B.H_FS + 3]) > 0.0
    st = new_state("dem", "dem", effects=("bonds", "friction"), time=a.time, step=a.step, dt=a.dt)
    st.groups.update(a.groups())
    st.groups["materials"] = {"name": np.array([m.name for m in a.materials], dtype=object),
                              **{k: np.array([getattr(m, k) for m in a.materials]) for k in
                                 ("density", "young", "poisson", "friction", "rolling_friction", "restitution")}}
    back = read_state(write_state(tmp_path / "s.h5", st))
    b = System(back.groups, a.materials, a.model, a.plan, a.walls, a.dyn, dt=a.dt, time=a.time, step=a.step)
    b.prime = False
    assert b.bonds.seated().tolist() == [True]
    # When both are pulled apart in one advance() call, long enough for the pair to part, be
    # released to the contact list inside the call and be pushed back into an ordinary contact
    for s in (a, b):
        s.v[1] = (1e-3, 0, 0)
        assert s.advance(1200)[0] == K.OK   # delta = 0 after ~850 of them
        gap = np.linalg.norm(s.x[1] - s.x[0]) - 2 * R
        assert s.bonds.seated().tolist() == [False] and 5e-6 < gap < 1.5e-5
        s.v[1] = (-1e-3, 0, 0)
        assert s.advance(1000)[0] == K.OK   # back to an overlap of ~18 um
    # Then they agree bit for bit, and the pair ended as an ordinary contact of the contact list
    for name in ("x", "v", "w", "f", "tq"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(a.bonds.hist, b.bonds.hist)
    assert a.contact_count()[0] == 1 and a.bonds.hist[0, B.H_D0] == 0.0 and overlap() > 1e-5


def test_energy_balance_holds_through_a_break_in_tension(build):
    # Given two free spheres joined by a contact bond (kn 1e5 N/m, s_n = 0.5 N) flying apart at
    # 20 mm/s each (E_0 = 4.4e-6 J), dt = 0.01 x critical: the bond stretches, breaks after ~5 um
    # (0.5 s_n^2 / kn = 1.25e-6 J in the spring) and the spheres part
    s = pair(build, model_row("contact_bond", kn=1e5, ks=5e4, normal_strength=0.5),
             v=((-2e-2, 0, 0), (2e-2, 0, 0)), flags=(0, 0), effects=("bonds", "energy"), dt_factor=0.01)
    e0 = s.energy_record()["total"]
    assert s.advance(500)[0] == K.OK
    rec = s.energy_record()
    # Then it broke in tension, the spring's energy at the break is booked as lost (within the
    # last step's stretch: relative 2e-2), and after it E_k + losses equals E_0 within 1e-10
    # (exact for a linear spring but for rounding; measured 1.4e-13). Without the break's
    # second-half-kick term, 0.5 dt F . v, the balance was off by 5.5e-3 of E_0.
    drift = abs(rec["total"] - e0) / e0
    print(f"lost {rec['damping']:.4e} J, |drift| after the break {drift:.2e}")
    assert s.bonds.counts()["broken_tension"] == 1 and rec["strain"] == 0.0
    assert rec["damping"] == pytest.approx(0.5 * 0.5 ** 2 / 1e5, rel=2e-2)
    assert drift < 1e-10


PB = dict(bond_kn=1e9, bond_ks=1e9, radius_multiplier=1.0)


def pb_sigma_tau(rows, lam=1.0):
    """Largest tensile and shear stresses of a parallel bond from its history rows."""
    rb, area, inert, polar = pb_geometry(lam)
    sigma = -rows[:, B.H_FN] / area + np.linalg.norm(rows[:, B.H_MB:B.H_MB + 3], axis=1) * rb / inert
    tau = np.linalg.norm(rows[:, B.H_FS:B.H_FS + 3], axis=1) / area + np.abs(rows[:, B.H_MT]) * rb / polar
    return sigma, tau


def test_parallel_bond_breaks_in_tension_when_pulled(build):
    # Given a parallel bond (kn_b = 1e9 Pa/m, sigma_c = 1e4 Pa, tau_c = 1e5 Pa), sphere 1 pulled
    # away at 1 mm/s: sigma = kn_b u
    sc, v = 1e4, 1e-3
    s = pair(build, model_row("parallel_bond", normal_strength=sc, shear_strength=1e5, **PB),
             v=((0, 0, 0), (v, 0, 0)))
    rows = step_until_broken(s, 5000)
    sigma, tau = pb_sigma_tau(rows)
    inc = PB["bond_kn"] * v * s.dt
    # Then it breaks in tension at sigma_c, within one step's increment (measured sigma_c - 0.07 inc)
    print(f"largest sigma {sigma.max():.3f} Pa, increment {inc:.3e} Pa")
    assert sc - inc <= sigma.max() < sc
    assert -rows[-1, B.H_FN] == pytest.approx(PB["bond_kn"] * math.pi * R ** 2 * (s.x[1, 0] - 2 * R - v * s.dt),
                                              rel=1e-6)
    assert s.bonds.counts() == {"intact": 0, "broken_tension": 1, "broken_shear": 0}


@pytest.mark.parametrize("pull", [0.0, 1e-2])
def test_parallel_bond_breaks_in_tension_by_bending(build, pull):
    # Given a parallel bond (sigma_c = 1e4 Pa, tau_c = 1e6 Pa) and both spheres spun in opposite
    # senses about z at 0.5 rad/s (relative rotation 1 rad/s, contact points not sliding), with
    # sphere 1 also pulled away at `pull`: sigma = -F_n / A + |M_b| R / I
    sc, w = 1e4, 0.5
    s = pair(build, model_row("parallel_bond", normal_strength=sc, shear_strength=1e6, **PB),
             v=((0, 0, 0), (pull, 0, 0)), omega=((0, 0, w), (0, 0, -w)))
    rows = step_until_broken(s, 5000)
    sigma, tau = pb_sigma_tau(rows)
    rb, area, inert, _ = pb_geometry()
    inc = PB["bond_kn"] * (2 * w * rb + pull) * s.dt
    # Then the bending moment is -kn_b I (w_0 - w_1) t about z (on sphere 0), no shear builds up,
    # and the bond breaks in tension when sigma reaches sigma_c (within one step's increment;
    # measured: sigma_c - 0.51 inc without pulling, - 0.75 inc with, the bending part then 49 %)
    t = (len(rows) - 1) * s.dt
    assert rows[-1, B.H_MB + 2] == pytest.approx(-PB["bond_kn"] * inert * 2 * w * t, rel=1e-6)
    assert tau.max() < 1e-9 * sc
    bending = np.linalg.norm(rows[:, B.H_MB:B.H_MB + 3], axis=1) * rb / inert
    print(f"pull {pull}: largest sigma {sigma.max():.3f} Pa (bending part {bending[-1]:.1f}), inc {inc:.2e}")
    assert sc - inc <= sigma.max() < sc
    if pull:
        assert 0.3 * sc < bending[-1] < 0.7 * sc   # both parts count
    assert s.bonds.counts() == {"intact": 0, "broken_tension": 1, "broken_shear": 0}


def test_parallel_bond_breaks_in_shear_when_slid(build):
    # Given a parallel bond (ks_b = 1e9 Pa/m, tau_c = 1e4 Pa, sigma_c = 1e5 Pa), sphere 1 moved
    # sideways at 1 mm/s, neither sphere turning: tau = |F_s| / A = ks_b y
    tc, v = 1e4, 1e-3
    s = pair(build, model_row("parallel_bond", normal_strength=1e5, shear_strength=tc, **PB),
             v=((0, 0, 0), (0, 0, v)))
    rows = step_until_broken(s, 5000)
    sigma, tau = pb_sigma_tau(rows)
    inc = PB["bond_ks"] * v * s.dt
    # Then it breaks in shear at tau_c, within one step's increment (measured tau_c - 0.07 inc);
    # sliding without turning leaves the relative rotation zero, so M_b = 0 and sigma = -F_n / A
    # ~ kn_b y^2 / 4R stays far below sigma_c (measured 2.5 Pa)
    print(f"largest tau {tau.max():.3f} Pa, inc {inc:.3e}, largest sigma {sigma.max():.3e} Pa")
    assert tc - inc <= tau.max() < tc
    assert np.abs(rows[:, B.H_MB:B.H_MB + 3]).max() == 0.0
    assert sigma.max() < 0.01 * 1e5
    assert s.bonds.counts() == {"intact": 0, "broken_tension": 0, "broken_shear": 1}


def test_parallel_bond_breaks_in_shear_when_twisted(build):
    # Given a parallel bond (tau_c = 1e4 Pa), sphere 0 spun about the bond axis at 1 rad/s:
    # M_t = -ks_b J w t, tau = |M_t| R / J = ks_b R w t
    tc, w = 1e4, 1.0
    s = pair(build, model_row("parallel_bond", normal_strength=1e5, shear_strength=tc, **PB),
             omega=((w, 0, 0), (0, 0, 0)))
    rows = step_until_broken(s, 5000)
    sigma, tau = pb_sigma_tau(rows)
    inc = PB["bond_ks"] * R * w * s.dt
    # Then it breaks in shear at tau_c within one increment (measured tau_c - 0.51 inc), with no
    # shear force and no bending
    print(f"largest tau {tau.max():.3f} Pa, inc {inc:.3e}")
    assert tc - inc <= tau.max() < tc
    assert np.abs(rows[:, B.H_FS:B.H_FS + 3]).max() < 1e-12 and np.abs(rows[:, B.H_MB:B.H_MB + 3]).max() == 0.0
    assert s.bonds.counts() == {"intact": 0, "broken_tension": 0, "broken_shear": 1}


# ---- energy ------------------------------------------------------------------------------
def _energy_run(s, steps, every):
    rec0 = s.energy_record()
    out = []
    for _ in range(steps // every):
        assert s.advance(every)[0] == K.OK
        out.append(s.energy_record())
    return rec0, out


def test_contact_bonded_pair_oscillating_keeps_its_energy(build):
    # Given two free spheres joined by a contact bond (kn 1e5, ks 5e4 N/m, no strengths), sent
    # towards each other and sideways (normal and shear springs, spins), dt = 0.1 x critical
    s = pair(build, model_row("contact_bond", kn=1e5, ks=5e4), v=((0.01, 0.005, 0), (-0.01, -0.005, 0)),
             flags=(0, 0), effects=("bonds", "energy"))
    rec0, recs = _energy_run(s, 20000, 50)
    e0 = rec0["total"]
    drift = np.array([r["total"] - e0 for r in recs]) / e0
    # Then E_k + E_s stays at its start (no dissipation in a contact bond: damping == 0) within the
    # velocity Verlet error of a linear spring, (omega dt)^2 / 4 with omega dt <= 0.1 x 2: 1e-2;
    # measured max |drift| 3.3e-3, and no secular drift over 20 000 steps (~380 periods of the
    # normal mode): the mean of the last 50 records within 1e-3 of the first 50's (measured -8e-6)
    print(f"contact bond: max |drift| {np.abs(drift).max():.2e}, last {drift[-1]:.2e}, "
          f"trend {np.mean(drift[-50:]) - np.mean(drift[:50]):.1e}")
    assert max(r["damping"] for r in recs) == 0.0
    assert np.abs(drift).max() < 1e-2
    assert abs(np.mean(drift[-50:]) - np.mean(drift[:50])) < 1e-3
    assert s.bonds.counts()["intact"] == 1
    assert np.abs(s.w).max() > 0.0  # the shear spring turned the spheres


@pytest.mark.parametrize("case", ["apart", "rebounding"])
def test_burgers_bonded_pair_oscillating_balances_its_energy(build, case):
    # Given two free spheres joined by a Burgers bond (compression spring kn = 1e5 N/m; tension and
    # shear elements K_m = 1e5 N/m, K_k = 5e4 / 1e5 N/m, C_k = 20 / 10 N s/m: tau_k ~ 1e-4 s, a tenth
    # of the period 1.5 ms), dt = 0.05 x critical:
    # "apart": sent apart and sideways with a weak Maxwell dashpot (C_m = 50 N s/m): the tension
    #   element creeps and never lets go, the spheres drift apart (no closing);
    # "rebounding": sent together and sideways with C_m = 2e3 N s/m: the pair bounces between the
    #   compression spring and the tension element, the gap closing ~37 times in 0.3 s
    if case == "apart":
        el = dict(km=1e5, cm=50.0, kk=5e4, ck=20.0)
        v = ((-0.02, 0.01, 0), (0.02, -0.01, 0))
    else:
        el = dict(km=1e5, cm=2e3, kk=1e5, ck=10.0)
        v = ((0.02, 0.01, 0), (-0.02, -0.01, 0))
    s = pair(build, model_row("burgers", kn=1e5, tension=el, shear=el), v=v, flags=(0, 0),
             effects=("bonds", "energy"), dt_factor=0.05)
    e0 = s.energy_record()["total"]
    total, touching = [], []
    for _ in range(int(0.3 / s.dt) // 20):
        assert s.advance(20)[0] == K.OK
        total.append(s.energy_record()["total"])
        touching.append(np.linalg.norm(s.x[1] - s.x[0]) <= 2 * R)
    total = np.array(total)
    closings = int(np.sum(np.diff(np.array(touching, int)) == 1))
    lost = s.energy_record()["damping"]
    drift = np.abs(total - e0).max() / e0
    # Then the dashpots take most of the energy (measured 86 % in both) and E_k + E_s + losses stays
    # at its start, the losses including the tension element's energy, lost when the gap closes.
    # Tolerance 1e-3 / 2e-3 of E_0 (second order in dt: the trapezoidal work of the update against
    # velocity Verlet, and the kink between k_n and the element's stiffness at each closing and
    # opening). Measured max |drift|: 1.3e-4 apart; 5.1e-4 rebounding (1.2e-4, 1.6e-3, 6.5e-3 at
    # dt = 0.025, 0.1, 0.2 x critical). Before the closing step booked the work of the element's
    # last force (demcli/kernels/bonds.py, compression branch) the rebounding pair drifted by
    # -7.4e-3, first order in dt (-3.8e-3 at 0.025, -2.9e-2 at 0.2 x critical).
    print(f"burgers {case}: {closings} closings, lost {lost / e0:.3f} of E0, max |drift| {drift:.2e}")
    assert lost > 0.5 * e0
    if case == "apart":
        assert closings == 0 and drift < 1e-3
    else:
        assert closings > 20 and drift < 2e-3


# ---- critical time step ---------------------------------------------------------------------
def verlet_bounded(s, wdt, steps=2000):
    """E0 <= E <= E0 / (1 - (w dt / 2)^2) (relative slack 1e-3) over ``steps`` steps, and the
    largest energy of the last quarter no more than 1e-3 above that of the first."""
    e0 = s.kinetic_energy() + s.strain_energy()
    e = []
    for _ in range(steps // 10):
        assert s.advance(10)[0] == K.OK
        e.append((s.kinetic_energy() + s.strain_energy()) / e0)
    e = np.array(e)
    q = len(e) // 4
    print(f"w dt = {wdt:.3f}: E / E0 in [{e.min():.4f}, {e.max():.4f}], bound {1 / (1 - wdt * wdt / 4):.4f}")
    return (e.min() > 1 - 1e-3 and e.max() < (1 + 1e-3) / (1 - wdt * wdt / 4)
            and e[-q:].max() < e[:q].max() * (1 + 1e-3))


@pytest.mark.parametrize("mode", ["normal", "shear"])
def test_critical_step_of_a_contact_bonded_pair(build, mode):
    # Given two free spheres (mass m) joined by a contact bond, stiffness k in the tested mode:
    # normal, omega^2 = 2 k / m (relative motion, m* = m / 2); shear at the contact point, which moves
    # and turns both spheres: omega^2 = k (1/m + 1/m + R^2/I + R^2/I) = 7 k / m
    k = 1e5
    if mode == "normal":
        row, w2 = model_row("contact_bond", kn=k, ks=1e3), 2 * k / MASS
        v, omega = ((1e-3, 0, 0), (-1e-3, 0, 0)), ((0, 0, 0), (0, 0, 0))
    else:
        row, w2 = model_row("contact_bond", kn=1e3, ks=k), 7 * k / MASS
        v, omega = ((0, 1e-3, 0), (0, -1e-3, 0)), ((0, 0, 0.25), (0, 0, 0.25))   # the mode's shape
    s = pair(build, row, v=v, omega=omega, flags=(0, 0), contact_kn=1e3)
    # Then the critical step is at most the pair's 2 / omega (measured 0.995 and 0.999 of it; the
    # contact's own omega^2 is added though the bond replaces it). Before critical_omega2 used
    # 7 k_s / m (it had 5 k_s / m, as for contacts) the shear case gave 1.18 x 2 / omega, and the
    # pair blew up at 0.9 x critical_dt (kinetic energy x 1e210 in 2000 steps)
    dtc = s.critical_dt()
    print(f"{mode}: critical_dt / (2/omega) = {dtc * math.sqrt(w2) / 2:.3f}")
    assert dtc <= 2 / math.sqrt(w2)
    # and a run at 0.9 x critical is stable: velocity Verlet keeps v^2 + w^2 x^2 (1 - (w dt)^2 / 4)
    # of a linear oscillator exactly, so from x = 0 the energy E stays in [E0, E0 / (1 - (w dt / 2)^2)]
    # (w dt = 1.4 and 1.8 here: the bound is 2.0 and 5.2 E0), and does not grow
    s.dt = 0.9 * dtc
    assert verlet_bounded(s, math.sqrt(w2) * s.dt)


def test_critical_step_of_a_parallel_bonded_pair_in_bending(build):
    # Given two free spheres joined by a parallel bond, spun in opposite senses: the bending spring
    # k_r = kn_b I_b between rotations gives omega^2 = 2 k_r / I (I = 0.4 m R^2)
    knb = 1e10
    _, _, ib, _ = pb_geometry()
    w2 = 2 * knb * ib / INERT
    s = pair(build, model_row("parallel_bond", bond_kn=knb, bond_ks=1e7), omega=((0, 0, 1.0), (0, 0, -1.0)),
             flags=(0, 0), contact_kn=1e3)
    dtc = s.critical_dt()
    # Then critical_dt <= 2 / omega (measured 0.790 of it: the bond's normal mode, 2 kn_b A / m =
    # 5.7e8 1/s^2 against 3.5e8 in bending, sets it) and a run at 0.9 x critical is stable
    # (E / E0 within [1, 2.0245], the bound 2.0247)
    print(f"bending: critical_dt / (2/omega) = {dtc * math.sqrt(w2) / 2:.3f}")
    assert dtc <= 2 / math.sqrt(w2)
    s.dt = 0.9 * dtc
    assert verlet_bounded(s, math.sqrt(w2) * s.dt)
