"""Body damping effects and their energy book-keeping."""

import math

import numpy as np


def test_local_damping_scales_free_fall_by_one_minus_lambda(build):
    # Given a sphere falling from rest with local damping lambda = 0.3 (Cundall: F_d = -lambda |F| sign(v))
    lam, g = 0.3, 9.81
    s = build.sphere_system([[0, 0, 0.0]], [[0, 0, -1e-9]], 0.01, [build.Material("m", 2500.0)],
                            build.ContactModel(law="linear", kn=1e4, kt=0.0), effects=["gravity", "local_damping"],
                            gravity=(0, 0, -g), local_damping=lam)
    s.dt = 1e-4
    # When it falls for 1 s
    assert s.advance(10000) == (0, 10000)
    # Then it moved as a body accelerating at g (1 - lambda) (constant force: velocity Verlet is exact)
    a = g * (1 - lam)
    assert abs(s.v[0, 2] + a * 1.0) < 1e-9
    assert abs(s.x[0, 2] + 0.5 * a * 1.0) < 1e-9


def test_viscous_damping_decays_velocity_and_books_the_loss(build):
    # Given a free sphere moving at 1 m/s with mass-proportional damping alpha = 5 1/s, energy on
    alpha = 5.0
    s = build.sphere_system([[0, 0, 0.0]], [[1.0, 0, 0]], 0.01, [build.Material("m", 2500.0)],
                            build.ContactModel(law="linear", kn=1e4, kt=0.0),
                            effects=["viscous_damping", "energy"], viscous_damping=alpha)
    s.dt = 1e-5
    e0 = s.kinetic_energy()
    # When 0.2 s pass
    assert s.advance(20000) == (0, 20000)
    # Then v = v0 exp(-alpha t) up to the first-order lag of a force evaluated at the half-step
    # velocity, alpha^2 dt t v / 2 = 9.2e-6 here (measured 9.197e-6)
    lag = alpha ** 2 * s.dt * 0.2 * math.exp(-alpha * 0.2) / 2
    assert abs(s.v[0, 0] - math.exp(-alpha * 0.2)) < 1.01 * lag
    # (the loss is booked as alpha m v_half^2 dt: first order in dt, measured 2.2e-5 of e0 here;
    # halving dt halves it)
    rec = s.energy_record()
    assert abs(rec["body_damping"] - (e0 - rec["kinetic"])) < 5e-5 * e0
    assert abs(rec["total"] - e0) < 5e-5 * e0
