"""Long runs: bounded energy drift (1e5 steps in ``make test``, 1e6 under ``make stress``).

Spheres: an elastic gas in a closed box (Hertz and linear laws, restitution 1, no friction):
nothing dissipates, so the total E_k + E_s + E_g is the drift. Polyhedra: a resting stack of
plates and slivers (damped) must neither creep nor gain energy; an undamped polyhedral
system does not conserve energy at all, because the seed's volumetric law is not a
conservative force (shown on a closed path below, and by a gas that heats itself up).
"""

import math
import os

import numpy as np
import pytest

from demcli.kernels import layout as K

G = 9.81


def _gas(scene, law, dt_factor):
    """27 spheres (r = 5 mm, 0.5 m/s random velocities) in a closed 60 mm box, gravity, restitution
    1, no friction (the scene of tests/engine/test_contact_physics.py, at the stage's default step)."""
    r, side = 0.005, 0.06
    rng = np.random.default_rng(7)
    grid = (np.arange(3) + 1.0) * side / 4
    x = np.array([[a, b, c] for a in grid for b in grid for c in grid]) + rng.uniform(-2e-3, 2e-3, (27, 3))
    v = rng.normal(0.0, 0.5, (27, 3))
    mats = [scene.Material("a", 2500.0, young=1e7, poisson=0.3, restitution=1.0, friction=0.0)]
    model = (scene.ContactModel(law="hertz_mindlin") if law == "hertz_mindlin"
             else scene.ContactModel(law="linear", kn=2e4, kt=5e3))
    return scene.spheres(x, v, r, mats, model, ["energy", "gravity"], walls=scene.closed_box(side),
                         gravity=(0.0, 0.0, -G), dt_factor=dt_factor)


# tolerance (1e5 steps, 1e6 steps) and the values measured when written; the gas is chaotic, so
# another CPU (another rounding) is another realisation of the random walk: over 1e5 steps the
# Hertz gas's max drift was 3.2e-4 for seed 7 where written, 0.84e-3 to 1.71e-3 for seeds 1-8 on
# another AMD EPYC (seed 7: 1.05e-3), hence 3e-3 (Hertz) at 1e5 steps
DRIFT = {"hertz_mindlin": (3e-3, 1e-2), "linear": (1e-2, 5e-2)}


@pytest.mark.parametrize("law", ["hertz_mindlin", "linear"])
def test_elastic_sphere_gas_energy_drift_stays_bounded(scene, law):
    # Given: the elastic gas at dt = 0.1 x critical (the dem stage's default dt_factor)
    s = _gas(scene, law, 0.1)
    e0 = s.energy_record()["total"]
    steps = 1_000_000 if scene.STRESS else 100_000
    # When: 1e5 steps (1e6 under stress; 4.3 s and 43 s of gas, Hertz), sampled 100 times
    drift = []
    for _ in range(100):
        status, _ = s.advance(steps // 100)
        assert status == K.OK
        drift.append((s.energy_record()["total"] - e0) / e0)
    drift = np.abs(drift)
    # Then: |E - E0| / E0 stays below 3e-3 / 1e-2 (Hertz; measured 3.2e-4 over 1e5 steps, 4.3e-3 over
    # 1e6, a slow upward trend: none at dt = 0.05 x critical, 2.9e-4 over 1e6) and 1e-2 / 5e-2
    # (linear; measured 4.0e-3, 3.2e-2). Every contact entry and exit costs or gains up to
    # (omega dt)^2 / 4 (1 % here for the linear law, whose force jumps in slope at contact; less
    # for Hertz, whose stiffness starts at zero); with random phases that is a random walk
    assert drift.max() < DRIFT[law][1 if scene.STRESS else 0], f"max drift {drift.max():.3g}"
    assert s.counters[K.C_KICK] == steps


def test_resting_stack_of_plates_and_slivers_does_not_creep(scene):
    # Given: the stack of test_slivers_plates_degenerate (plate, plate turned 30 deg, sliver, crossed
    # sliver) settled for 0.05 s at dt = 0.3 x critical, with energy book-keeping
    t = 0.002
    polys = [scene.box(0.04, 0.04, t), scene.box(0.04, 0.04, t), scene.box(0.04, t, t), scene.box(0.04, t, t)]
    x = [[0, 0, t / 2 + 1e-5], [0.003, 0, 1.5 * t + 3e-5], [0, 0, 2.5 * t + 5e-5], [0, 0, 3.5 * t + 7e-5]]
    q = [scene.quat([0, 0, 0]), scene.quat([0, 0, math.radians(30)]), scene.quat([0, 0, 0.02]),
         scene.quat([0, 0, math.pi / 2])]
    s = scene.polyhedra(polys, x=x, q=q, effects=["gravity", "friction", "local_damping", "energy"],
                        walls=scene.planes([0, 0, 0], [0, 0, 1]), friction=0.5, restitution=0.3, contact_damping=True,
                        local_damping=0.4, dt_factor=0.3, check_every=100)
    s.advance(int(0.05 / s.dt))
    # and then stopped: the landing leaves the sliver a yaw spin that no contact resists (a model
    # property, docs/stability.md; 5e-6 .. 8e-3 rad/s depending on the step), turning it about its
    # contact point; creep is measured from rest
    s.v[:], s.w[:], s.L[:] = 0.0, 0.0, 0.0
    x1, q1, e1 = s.x.copy(), s.q.copy(), s.energy_record()["total"]
    steps = 1_000_000 if scene.STRESS else 100_000
    # When: 1e5 more steps (0.13 s; 1e6 under stress, 1.3 s)
    status, _ = s.advance(steps)
    # Then: no guard; the bodies did not move (< 1e-9 m; measured 1.2e-15 over 1e5 steps), their
    # attitudes changed by < 1e-4 rad (measured 9e-13 rad), and the energy balance did not drift
    # (< 1e-9 J against a potential energy of 3.8e-4 J; measured 5e-20 J). Under stress, 1e6 steps,
    # measured before the bodies were stopped and with the translational step (2.6 times longer):
    # 1e-12 m, 1.7e-5 rad (the free yaw), 7e-18 J
    assert status == K.OK
    assert np.abs(s.x - x1).max() < 1e-9
    dq = np.minimum(np.linalg.norm(s.q - q1, axis=1), np.linalg.norm(s.q + q1, axis=1))
    assert 2 * dq.max() < 1e-4
    assert abs(s.energy_record()["total"] - e1) < 1e-9


@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="the seed's volumetric law F_N = k_n sqrt(V d) n, d = V / A_c, is not conservative: "
                   "work on a closed path is not zero (see docs/stability.md)")
def test_volumetric_contact_force_does_no_work_on_a_closed_path(scene):
    # Given: two axis-aligned 10 mm cubes that cannot rotate, B offset from A by (a - p, a - q, 0): an
    # edge overlap of p x q x a with V = p q a, S = grad V = a (q, p), F = k_n V |S|^(-3/2) S on B
    a = 0.01
    s = scene.polyhedra([scene.box(a, a, a)] * 2, x=[[0, 0, 0], [a, a, 0]], gravity=(0.0, 0.0, 0.0), young=1e9)

    def force(p, q):
        s.x[1] = [a - p, a - q, 0.0]
        s.prime, s._fresh_lists = True, True
        s.advance(0)
        return s.f[1, :2].copy()

    # When: B is carried once around the rectangle p in [0.1, 0.2] mm, q in [0.3, 0.5] mm (50 points
    # a side) and the work of the contact force on it summed (trapezoids)
    n = 50
    p0, p1, q0, q1 = 1e-4, 2e-4, 3e-4, 5e-4
    path = np.concatenate([np.stack([np.linspace(p0, p1, n), np.full(n, q0)], 1),
                           np.stack([np.full(n, p1), np.linspace(q0, q1, n)], 1),
                           np.stack([np.linspace(p1, p0, n), np.full(n, q1)], 1),
                           np.stack([np.full(n, p0), np.linspace(q1, q0, n)], 1)])
    f = np.array([force(p, q) for p, q in path])
    dx = -np.diff(path, axis=0)  # B's displacement
    w = np.einsum("ij,ij->i", 0.5 * (f[1:] + f[:-1]), dx)
    # Then (expected of a conservative force): the net work is zero, up to the quadrature error
    # (< 1e-3 of the work done along the way). Measured: -0.15 of it (-11 mJ of 72 mJ); the curl of
    # F is 1.5 k_n sqrt(a) p q (q^2 - p^2) / (p^2 + q^2)^(7/4), zero only on p = q
    assert abs(w.sum()) < 1e-3 * np.abs(w).sum()


@pytest.mark.xfail(strict=True, raises=AssertionError,
                   reason="undamped polyhedra gain energy without bound (non-conservative law)")
def test_undamped_polyhedral_gas_keeps_its_energy(scene):
    # Given: 8 cubes of 8 mm that cannot rotate (flags FIX_ROTATION), random velocities of 0.5 m/s,
    # in a closed 60 mm box, E = 1e7 Pa, no gravity, no damping, dt = 0.1 x critical
    from demcli.engine.plan import make_plan
    from demcli.engine.poly_shape import polyhedra_groups
    from demcli.engine.system import Dynamics, System

    rng = np.random.default_rng(7)
    side, n = 0.06, 8
    g = np.array([0.2, 0.5]) * side
    x = np.array([[a, b, c] for a in g for b in g for c in g])
    groups = polyhedra_groups([scene.box(0.008, 0.008, 0.008)] * n, 2600.0, x=x, v=rng.normal(0, 0.5, (n, 3)),
                              flags=np.full(n, K.FIX_ROTATION, np.int8))
    s = System(groups, [scene.Material("rock", 2600.0, young=1e7)], scene.ContactModel(),
               make_plan(["energy"], walls=True), scene.closed_box(side), Dynamics(gravity=(0.0, 0.0, 0.0)), dt=1.0)
    s.dt = 0.1 * s.critical_dt()
    e0 = s.kinetic_energy()
    # When: 3.5 s of gas (170 000 steps; 8 s under make stress)
    status, _ = s.advance(int((8.0 if os.environ.get("DEMCLI_STRESS") == "1" else 3.5) / s.dt))
    # Then (expected of an energy-conserving contact law): status OK and the energy within 50 %.
    # Measured: the kinetic energy grows without bound (x 1.85 after 3 s, x 5.3 after 6 s, x 172 after
    # 8 s), then the overlap guard trips. A smaller step delays it but does not stop it: at dt = 0.05 x
    # critical x 1.9 after 8 s, x 470 after 14 s (guard); at 0.02 x 2.3 after 12 s and rising. The
    # closed-path test above shows the law itself does work on a loop; the growth then feeds on
    # itself (faster bodies, deeper overlaps). 8 random hulls free to rotate, with gravity: x 3.8
    # after 16 s at dt = 0.1 x critical
    assert status == K.OK and s.kinetic_energy() < 1.5 * e0
