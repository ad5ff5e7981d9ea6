"""Wall geometry and wall control: cylinder contact, prescribed velocity, force and servo stress."""

import math

import numpy as np
import pytest

from demcli.engine.system import Walls
from demcli.kernels import walls as W


def one_wall(kind, point, normal, radius=0.0, control=W.FIXED, v=(0, 0, 0), **prm):
    row = np.zeros((1, W.N_WPARAMS))
    for key, value in prm.items():
        row[0, getattr(W, key)] = value
    n = np.asarray(normal, float)
    return Walls(name=["w"], kind=np.array([kind], np.int8), point=np.array([point], float),
                 normal=np.array([n / np.linalg.norm(n)]), radius=np.array([radius], float),
                 v=np.array([v], float), material=np.zeros(1, np.int64), control=np.array([control], np.int8),
                 prm=row, extent=np.array([[-1, -1, -1, 1, 1, 1]], float))


def join(*walls):
    cat = lambda name: np.concatenate([getattr(w, name) for w in walls])  # noqa: E731
    return Walls(name=[f"w{i}" for i in range(len(walls))], kind=cat("kind"), point=cat("point"),
                 normal=cat("normal"), radius=cat("radius"), v=cat("v"), material=cat("material"),
                 control=cat("control"), prm=cat("prm"), extent=cat("extent"))


def test_sphere_resting_on_the_inside_of_a_cylinder(build):
    # Given a sphere inside a vertical cylinder (R = 50 mm) with gravity pushing it sideways (+x)
    kn, r, R, g = 1e4, 0.01, 0.05, 9.81
    mat = [build.Material("m", 2500.0, friction=0.0)]
    wall = one_wall(W.CYLINDER, (0, 0, 0), (0, 0, 1), radius=R)
    s = build.sphere_system([[0.0, 0, 0]], [[0, 0, 0]], r, mat, build.ContactModel(law="linear", kn=kn, kt=0.0),
                            effects=["gravity", "local_damping"], walls=wall, gravity=(g, 0, 0),
                            local_damping=0.7, dt_factor=0.05)
    m = s.mass[0]
    # When it comes to rest
    assert s.advance(40000) == (0, 40000)
    # Then it sits against the wall with the linear overlap m g / kn and the wall carries m g
    delta = m * g / kn
    assert abs(s.x[0, 0] - (R - r + delta)) < 1e-6 * R
    assert abs(s.wforce[0, 0] - m * g) < 1e-6 * m * g
    assert abs(s.x[0, 1]) < 1e-12


def test_prescribed_velocity_wall_moves_exactly(build):
    # Given a plane wall with prescribed velocity and a sphere far away
    wall = one_wall(W.PLANE, (0, 0, 0), (0, 0, 1), control=W.VELOCITY, v=(0, 0, 0.3))
    s = build.sphere_system([[0, 0, 1.0]], [[0, 0, 0]], 0.01, [build.Material("m", 2500.0)],
                            build.ContactModel(law="linear", kn=1e4, kt=0.0), walls=wall)
    s.dt = 1e-4
    # When 1000 steps run
    s.advance(1000)
    # Then the wall moved v t
    assert abs(s.wpoint[0, 2] - 0.3 * 0.1) < 1e-12


def test_force_controlled_wall_accelerates_as_a_free_mass(build):
    # Given a free wall of mass 2 kg pushed by 10 N, no particle in reach
    wall = one_wall(W.PLANE, (0, 0, 0), (0, 0, 1), control=W.FORCE, W_TARGET=10.0, W_MASS=2.0)
    s = build.sphere_system([[0, 0, 10.0]], [[0, 0, 0]], 0.01, [build.Material("m", 2500.0)],
                            build.ContactModel(law="linear", kn=1e4, kt=0.0), walls=wall)
    s.dt = 1e-4
    s.advance(10000)
    # Then it moved a t^2 / 2 with a = F / M (symplectic Euler: error a dt t / 2)
    t = 1.0
    assert abs(s.wpoint[0, 2] - 0.5 * 5.0 * t * t) < 5.0 * s.dt * t
    assert abs(s.wv[0, 2] - 5.0 * t) < 1e-9


def test_force_controlled_wall_follows_a_haversine_load_as_a_free_mass(build):
    # Given a free wall of mass M = 2 kg loaded as the ballast plate is: F_min held until t0,
    # then F(t) = F_mean + A sin(2 pi f (t - t0) - pi/2), a haversine F_min -> F_max -> F_min
    M, f_min, f_max, f, t0 = 2.0, 2.0, 10.0, 2.0, 0.1
    f0, amp, om = 0.5 * (f_min + f_max), 0.5 * (f_max - f_min), 2 * math.pi * f
    wall = one_wall(W.PLANE, (0, 0, 0), (0, 0, 1), control=W.FORCE, W_TARGET=f0, W_AMPLITUDE=amp, W_FREQ=f,
                    W_PHASE=-0.5 * math.pi, W_START=t0, W_MASS=M)
    s = build.sphere_system([[0, 0, 10.0]], [[0, 0, 0]], 0.01, [build.Material("m", 2500.0)],
                            build.ContactModel(law="linear", kn=1e4, kt=0.0), walls=wall)
    s.dt = 1e-4

    def exact(t):
        """x(t), v(t) of M under F(t), from rest at 0."""
        if t <= t0:
            return f_min * t * t / (2 * M), f_min * t / M
        x0, v0, tau = f_min * t0 * t0 / (2 * M), f_min * t0 / M, t - t0
        v = v0 + (f0 * tau - amp * math.sin(om * tau) / om) / M
        x = x0 + v0 * tau + (0.5 * f0 * tau * tau - amp * (1 - math.cos(om * tau)) / om ** 2) / M
        return x, v

    # When it moves for 1.1 s (two load cycles after t0), checked every 0.05 s
    for k in range(22):
        s.advance(500)
        t = s.time
        x, v = exact(t)
        # Then it follows x(t) and v(t) from F(t)/M to the first-order error of the symplectic
        # Euler step (|F|max / M dt t)
        assert abs(s.wpoint[0, 2] - x) < f_max / M * s.dt * t, t
        assert abs(s.wv[0, 2] - v) < f_max / M * s.dt, t


def test_force_wall_weight_phase_and_start_come_from_the_case():
    # Given the plate of the clump smoke case: 3.25 +- 3.25 kN from -90 deg after 2 ms, 10.5 kg, weight on
    from pathlib import Path

    from demcli.stages import dem
    from demcli.stages.base import load_case

    case = load_case(Path(__file__).resolve().parents[2] / "cases" / "smoke" / "ballast_clumps.yaml")
    cfg = next(c for c in case.stages if c.name == "plate")
    walls = dem.build_walls(cfg, case)
    k = walls.name.index("plate")
    # Then the wall's mean force holds its weight M g along its normal (-z, with gravity)
    prm = walls.prm[k]
    assert walls.control[k] == W.FORCE
    assert prm[W.W_TARGET] == pytest.approx(3250.0 + 10.5 * 9.81, rel=1e-12)
    assert (prm[W.W_AMPLITUDE], prm[W.W_FREQ], prm[W.W_MASS]) == (3250.0, 10.0, 10.5)
    assert prm[W.W_PHASE] == pytest.approx(-0.5 * math.pi, rel=1e-12) and prm[W.W_START] == pytest.approx(0.002)


def test_servo_lid_holds_the_target_stress(build):
    # Given 64 spheres on a lattice in a box, and a servo lid with a target stress of 20 kPa
    r = 0.005
    g = np.arange(4) * 2.02 * r + r
    x = np.array([[a, b, c] for c in g for b in g for a in g])
    side = 8 * r + 0.0
    area = side * side
    target = 20e3
    walls = join(
        one_wall(W.PLANE, (0, 0, 0), (1, 0, 0)), one_wall(W.PLANE, (side, 0, 0), (-1, 0, 0)),
        one_wall(W.PLANE, (0, 0, 0), (0, 1, 0)), one_wall(W.PLANE, (0, side, 0), (0, -1, 0)),
        one_wall(W.PLANE, (0, 0, 0), (0, 0, 1)),
        one_wall(W.PLANE, (0, 0, 8.5 * r), (0, 0, -1), control=W.SERVO, W_TARGET=target, W_GAIN=0.3,
                 W_VMAX=0.05, W_AREA=area))
    mat = [build.Material("m", 2500.0, friction=0.3)]
    s = build.sphere_system(x, np.zeros((64, 3)), r, mat, build.ContactModel(law="linear", kn=1e6, kt=2.5e5),
                            effects=["friction", "local_damping"], walls=walls, local_damping=0.5,
                            dt_factor=0.1)
    z0 = s.wpoint[5, 2]
    # When it runs long enough for the lid to close the gap and settle
    stress = []
    for _ in range(60):
        assert s.advance(500) == (0, 500)
        stress.append(s.wforce[5, 2] / area)  # particles push the lid up (+z)
    # Then the lid moved down and the stress it carries is the target within 1 %
    assert s.wpoint[5, 2] < z0
    assert abs(np.mean(stress[-10:]) - target) < 0.01 * target, stress[-10:]
    # and it got there without chattering (a bang-bang servo swings by tens of percent)
    assert np.std(stress[-10:]) < 0.01 * target
