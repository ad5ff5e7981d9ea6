"""Wall geometry and wall control: cylinder contact, prescribed velocity, force and servo stress."""

import numpy as np

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
