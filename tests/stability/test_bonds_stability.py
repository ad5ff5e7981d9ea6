"""Bonds at the edge: chains loaded to just below and just above their strength, and Burgers
bonds stepped far above their retardation time (fast sizes; DEMCLI_STRESS=1 runs longer).

Each test states its reference, its tolerance and the value measured when it was written.
"""

import math

import numpy as np
import pytest

from demcli.engine.bonds import model_row
from demcli.kernels import bonds as B
from demcli.kernels import layout as K

R = 0.01
RHO = 2650.0
MASS = RHO * 4 / 3 * math.pi * R ** 3
FIXED = K.FIX_TRANSLATION | K.FIX_ROTATION
N_CHAIN = 6
S_N = 1.0      # strength of the top bond [N]: contact and Burgers bonds; parallel bonds: S_N / A [Pa]
G_REF = S_N / ((N_CHAIN - 1) * MASS)   # gravity at which the top bond carries S_N (18.0 m/s^2)


def chain_row(kind):
    area = math.pi * R * R
    if kind == "contact_bond":
        return model_row("contact_bond", kn=1e5, ks=5e4, normal_strength=S_N, shear_strength=10 * S_N)
    if kind == "parallel_bond":
        return model_row("parallel_bond", bond_kn=1e9, bond_ks=5e8, normal_strength=S_N / area,
                         shear_strength=10 * S_N / area)
    el = dict(km=1e5, cm=2e4, kk=1e5, ck=1e2)   # tau_k = 1 ms, Maxwell time 0.2 s
    return model_row("burgers", kn=1e5, tension=el, shear=el, normal_strength=S_N, shear_strength=10 * S_N)


def top_force(s, kind):
    """Tension carried by the top bond (sphere 0 to 1) [N]."""
    h = s.bonds.hist[0]
    return h[B.H_FN] if kind == "burgers" else -h[B.H_FN]


@pytest.mark.parametrize("load", [0.98, 1.02])
@pytest.mark.parametrize("kind", ["contact_bond", "parallel_bond", "burgers"])
def test_hanging_chain_loaded_to_its_strength(scene, kind, load):
    # Given a chain of 6 bonded spheres hanging from the top one (held), its weight ramped
    # quasi-statically (gravity from 0 to load x G_REF in 0.5 s, viscous damping 50 1/s) so that
    # the top bond, which carries the weight of the 5 below, reaches load x its strength
    x = np.zeros((N_CHAIN, 3))
    x[:, 2] = -2 * R * np.arange(N_CHAIN)
    s = scene.spheres(x, np.zeros_like(x), R, [scene.Material("m", RHO, friction=0.0)],
                      scene.ContactModel(law="linear", kn=1e5), ["bonds", "gravity", "viscous_damping"],
                      gravity=(0.0, 0.0, 0.0), viscous_damping=50.0, dt_factor=0.2)
    s.bonds.set_models([(0, 0)], [chain_row(kind)])
    s.bflags[0] = FIXED
    assert s.bond_touching(1e-9 * R) == N_CHAIN - 1
    s.dt = 0.2 * s.critical_dt()
    ramp, hold, chunk = 0.5, 0.2, 50
    t_end = ramp + hold
    broke_at = None
    peak = 0.0
    while s.time < t_end:
        g = load * G_REF * min(1.0, (s.time + 0.5 * chunk * s.dt) / ramp)
        s.gravity[:] = (0.0, 0.0, -g)
        before = s.bonds.state.copy()
        peak = max(peak, top_force(s, kind))
        status, _ = s.advance(chunk)
        assert status == K.OK
        assert np.isfinite(s.x).all() and np.isfinite(s.v).all()
        if broke_at is None and np.any(s.bonds.state != before):
            broke_at = g / G_REF
    c = s.bonds.counts()
    print(f"{kind} at {load}: counts {c}, broke at {broke_at}, peak top force {peak:.5f} N, "
          f"top force / load {top_force(s, kind) / (load * S_N) - 1:.1e}")
    if load < 1:
        # Then below its strength nothing breaks, and the top bond carries the weight of the five
        # spheres below (static, tolerance 1e-3; measured: contact 5.6e-6, parallel 8.7e-6, Burgers
        # -3.1e-4: its creep still flows and the damping drags on it), no NaN
        assert c == {"intact": N_CHAIN - 1, "broken_tension": 0, "broken_shear": 0}
        assert top_force(s, kind) == pytest.approx(load * S_N, rel=1e-3)
    else:
        # Then above it the top bond, and only it, breaks in tension, when the load reaches its
        # strength (tolerance 1 %: the ramp's chunk is 0.07 % of the load; the damping's drag and
        # the dynamic lag of the ramp add to it; measured: contact 0.99985, parallel 1.0011,
        # Burgers 0.9991 of the strength; the largest tension seen at a chunk's start 0.9967,
        # 0.9991, 0.9960 N), the rest falls as one bonded chain, and nothing is NaN
        assert c == {"intact": N_CHAIN - 2, "broken_tension": 1, "broken_shear": 0}
        assert s.bonds.state[0] == B.BROKEN_TENSION
        assert broke_at == pytest.approx(1.0, abs=0.01)
        assert peak < S_N
        assert np.all(s.bonds.hist[0] == 0.0)
        g_end = load * G_REF   # falling at the damping's terminal speed g / alpha (measured 1e-9)
        assert np.allclose(s.v[1:, 2], -g_end / 50.0, rtol=1e-3)
        d = np.linalg.norm(np.diff(s.x[1:], axis=0), axis=1)
        assert np.all(np.abs(d - 2 * R) < 0.05 * R)     # still a chain


def creep_pair(scene, ratio, mode, ck_zero=False):
    """Sphere 1 held, sphere 0 pulled by its weight along (tension) or across (shear) a Burgers
    bond whose retardation time is dt / ratio; returns (system, force, element)."""
    km, cm, kk = 1e4, 5e3, 1e4
    g = 9.81
    gravity = (-g, 0.0, 0.0) if mode == "tension" else (0.0, 0.0, -g)
    alpha = 0.5 * math.sqrt(km / MASS)
    s = scene.spheres([[0, 0, 0], [2 * R, 0, 0]], np.zeros((2, 3)), R, [scene.Material("m", RHO, friction=0.0)],
                      scene.ContactModel(law="linear", kn=1e4), ["bonds", "gravity", "viscous_damping"],
                      gravity=gravity, viscous_damping=alpha)
    el = dict(km=km, cm=cm, kk=kk, ck=1.0)
    s.bonds.set_models([(0, 0)], [model_row("burgers", kn=1e4, tension=el, shear=el)])
    s.bflags[0] = K.FIX_ROTATION
    s.bflags[1] = FIXED
    assert s.bond_touching(1e-9) == 1
    s.dt = 0.3 * s.critical_dt()
    ck = 0.0 if ck_zero else kk * s.dt / ratio   # tau_k = dt / ratio
    for col in ((B.B_CKN, B.B_CKS)):
        s.bonds.prm[0, col] = ck
    return s, MASS * g, (km, cm, kk, ck)


@pytest.mark.parametrize("mode", ["tension", "shear"])
@pytest.mark.parametrize("ratio", [10.0, 100.0])
def test_burgers_with_a_step_far_above_its_retardation_time(scene, ratio, mode):
    # Given the creep pair of tests/engine/test_bonds.py (sphere 0 pulled by its weight through a
    # Burgers bond, K_m = K_k = 1e4 N/m, C_m = 1e3 N s/m: Maxwell time 0.1 s) at dt = 0.3 x critical
    # (2.2e-4 s) and a Kelvin dashpot with tau_k = dt / 10 and dt / 100
    s, force, (km, cm, kk, ck) = creep_pair(scene, ratio, mode)
    lim, _, _ = creep_pair(scene, ratio, mode, ck_zero=True)
    steps = int((1.0 if scene.STRESS else 0.2) / s.dt)
    rel, dev = [], []
    for _ in range(5):
        assert s.advance(steps // 5)[0] == K.OK
        assert lim.advance(steps // 5)[0] == K.OK
        assert np.isfinite(s.x).all()
        u = -s.x[0, 0] if mode == "tension" else -s.x[0, 2]
        ul = -lim.x[0, 0] if mode == "tension" else -lim.x[0, 2]
        exact = force / km + force * s.time / cm + force / kk * (1 - math.exp(-s.time * kk / ck))
        rel.append(u / exact - 1)
        dev.append(u / ul - 1)
    # Then it is stable and creeps on the analytic curve, which for t >> tau_k is the limit where the
    # Kelvin element acts as a spring, F/K_m + F/K_k + F t/C_m: tolerance 1 % (issue #9); measured
    # -2.1e-3 .. -1.9e-3 at every ratio and mode (the damping's drag, alpha m / C_m = 1e-3, and
    # the transient); and it tends to that limit: the same run with C_k = 0 within
    # 2e-4 tau_k / dt (measured 4.6e-6 at 10 and 4.8e-7 at 100, then 1e-8 once the transient is over)
    print(f"{mode} dt/tau_k={ratio:g}: against the curve {['%.1e' % e for e in rel]}, "
          f"against C_k = 0 {['%.1e' % e for e in dev]}")
    assert max(abs(e) for e in rel) < 0.01
    assert max(abs(e) for e in dev) < 2e-4 / ratio


def rebounding_pair(scene, ratio, dt_factor):
    """The rebounding pair of tests/engine/test_bonds.py (two free spheres sent together and
    sideways; compression spring 1e5 N/m, Burgers elements K_m = K_k = 1e5 N/m, C_m = 2e3 N s/m)
    with tau_k = dt / ratio, run for 0.3 s (2 s under STRESS). Returns (largest |balance error| / E_0,
    largest rise of the mechanical energy above its start / its start, closings, omega dt, system)."""
    s = scene.spheres([[0, 0, 0], [2 * R, 0, 0]], [[0.02, 0.01, 0], [-0.02, -0.01, 0]], R,
                      [scene.Material("m", RHO, friction=0.0)], scene.ContactModel(law="linear", kn=1e5),
                      ["bonds", "energy"])
    el = dict(km=1e5, cm=2e3, kk=1e5, ck=1.0)
    s.bonds.set_models([(0, 0)], [model_row("burgers", kn=1e5, tension=el, shear=el)])
    assert s.bond_touching(1e-9) == 1
    s.dt = dt_factor * s.critical_dt()
    s.bonds.prm[0, B.B_CKN] = s.bonds.prm[0, B.B_CKS] = 1e5 * s.dt / ratio
    wdt = math.sqrt(7 * 1e5 / MASS) * s.dt     # the stiffest mode's omega dt
    e0 = s.energy_record()["total"]
    mech0 = scene.mechanical_energy(s)
    drift, rise, touching = 0.0, -math.inf, []
    for _ in range(int((2.0 if scene.STRESS else 0.3) / s.dt) // 20):
        assert s.advance(20)[0] == K.OK
        assert np.isfinite(s.x).all() and np.isfinite(s.v).all()
        drift = max(drift, abs(s.energy_record()["total"] - e0) / e0)
        rise = max(rise, scene.mechanical_energy(s) / mech0 - 1)
        touching.append(np.linalg.norm(s.x[1] - s.x[0]) <= 2 * R)
    closings = int(np.sum(np.diff(np.array(touching, int)) == 1))
    return drift, rise, closings, wdt, s


@pytest.mark.parametrize("ratio", [10.0, 100.0])
def test_rebounding_burgers_pair_with_a_step_far_above_its_retardation_time(scene, ratio):
    # Given the rebounding pair at dt = 0.1 x critical (the dem stage's default) and tau_k = dt / 10,
    # dt / 100, and the same at half the step
    drift, rise, closings, wdt, s = rebounding_pair(scene, ratio, 0.1)
    drift2, _, _, _, _ = rebounding_pair(scene, ratio, 0.05)
    print(f"dt/tau_k={ratio:g}: {closings} closings, max |balance| {drift:.2e} (half the step: {drift2:.2e}), "
          f"max rise {rise:.2e}, (omega dt)^2/4 {wdt * wdt / 4:.2e}")
    # Then it stays stable through ~170 closings: the mechanical energy never rises above its start
    # by more than the Verlet error (omega dt)^2 / 4 = 7.8e-3 (measured 2.6e-4 / 8.7e-4), the bond
    # holds (no strengths)
    assert closings > 100
    assert rise <= wdt * wdt / 4
    assert s.bonds.counts()["intact"] == 1
    # and the energy balance holds within 3 % of E_0, converging at second order (half the step:
    # below 0.35 of it). The error is the integrator's at the kink where the stiffness changes
    # from the compression spring k_n to the tension element's K_m K_k / (K_m + K_k) = k_n / 2 (the
    # Kelvin element acts as a spring within a step when dt >> tau_k), at every closing and
    # opening. Measured 1.7e-2 / 2.1e-2, half the step 4.8e-3 / 5.4e-3 (ratios 0.29 / 0.25). Before
    # the closing step booked the element's work (demcli/kernels/bonds.py) the error did not
    # converge: 7.7e-3 at 0.1 and 5.4e-3 at 0.025 x critical (a first-order loss at every
    # closing, partly cancelling the kink's)
    assert drift < 0.03
    assert drift2 < 0.35 * drift
