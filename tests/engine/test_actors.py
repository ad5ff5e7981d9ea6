"""Actors: the loading plate and the sleeper as rigid polyhedral bodies with a prescribed
force or velocity (:mod:`demcli.engine.actors`), paired outside the cell grid.

References: statics (the floor carries every weight plus the prescribed force), a slow
haversine load followed quasi-statically, exact kinematics of a prescribed velocity, a
brute-force pair search, and bit-identical resume.
"""

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).parent))
from test_polyhedra_dynamics import G, RHO, box, planes, random_hull  # noqa: E402

from demcli.engine.actors import actor_index, add_actor, box_polyhedron, haversine, remove_actors  # noqa: E402
from demcli.engine.materials import ContactModel, Material  # noqa: E402
from demcli.engine.plan import make_plan  # noqa: E402
from demcli.engine.poly_shape import polyhedra_groups
from demcli.engine.system import Dynamics, System  # noqa: E402
from demcli.kernels.neighbors import add_actor_pairs, build_pairs  # noqa: E402

STEEL = 7800.0


def _scene(groups, effects=("gravity", "friction", "local_damping"), local=0.7, dt_factor=0.2, **kw):
    walls = planes([[0, 0, 0]], [[0, 0, 1]])
    plan = make_plan(list(effects), walls=True, polyhedra=True)
    mats = [Material("rock", RHO, young=1e9, friction=0.5, restitution=0.3)]
    s = System(groups, mats, ContactModel(), plan, walls, Dynamics(gravity=(0, 0, -G), local_damping=local),
                   dt=1.0, **kw)
    s.dt = dt_factor * s.critical_dt()
    return s


def _cube_under_plate(load=None, velocity=None, plate_z=0.0601):
    g = polyhedra_groups([box(0.05, 0.05, 0.05)], RHO, x=[[0.0, 0.0, 0.025]])
    return add_actor(g, box_polyhedron([0.2, 0.2, 0.02]), [0.0, 0.0, plate_z], STEEL, 0, "plate", load=load,
                     velocity=velocity)


def test_plate_with_a_constant_force_loads_the_bed_by_its_weight_plus_the_force():
    # Given: a 5 cm cube on the floor and a 20 x 20 x 2 cm steel plate on it, pushed down by 500 N
    F = 500.0
    s = _scene(_cube_under_plate(load=haversine(F, F, 0.0)))
    x0, q0 = s.x[1].copy(), s.q[1].copy()
    # When: 20 000 steps settle it; the floor force is averaged over the last 2 000
    s.advance(18000)
    fz = []
    for _ in range(20):
        s.advance(100)
        fz.append(-s.wforce[0, 2])
    # Then: floor force = cube weight + plate weight + F within 0.1 % (measured 2e-6), and the
    # plate moved along z only, without turning (x, y and the attitude exactly as placed)
    expected = s.mass.sum() * G + F
    assert np.mean(fz) == pytest.approx(expected, rel=1e-3)
    assert s.x[1, 0] == x0[0] and s.x[1, 1] == x0[1]
    np.testing.assert_array_equal(s.q[1], q0)
    assert s.x[1, 2] < x0[2]


def test_slow_haversine_load_is_followed_quasi_statically():
    # Given: the plate loaded 100 N -> 900 N at 2 Hz, far below the contact's natural frequency
    # (~1 kHz), with contact dashpots and local damping on the cube; floor reaction sampled through
    # one cycle (the plate itself is not body-damped: a damped plate lags the load by ~10 % of its
    # range, measured with lambda = 0.7)
    f_min, f_max, freq = 100.0, 900.0, 2.0
    s = _scene(_cube_under_plate(load=haversine(f_min, f_max, freq, start=0.1)), local=0.2, dt_factor=0.3,
               contact_damping=True)
    weight = s.mass.sum() * G
    s.advance(int(0.1 / s.dt))  # settle on F_min
    t, fz = [], []
    n = int(round(0.5 / freq / 20 / s.dt))
    for _ in range(20):
        s.advance(n)
        t.append(s.time)
        fz.append(-s.wforce[0, 2])
    t = np.array(t)
    expected = weight + f_min + (f_max - f_min) * 0.5 * (1.0 - np.cos(2.0 * math.pi * freq * (t - 0.1)))
    # Then: the floor carries weight + F(t) within 1 % of the load range at every sample (measured 3e-5)
    assert np.max(np.abs(np.array(fz) - expected)) < 0.01 * (f_max - f_min)


def test_prescribed_velocity_moves_the_actor_exactly():
    # Given: the plate moving down at 1 cm/s, 0.5 mm above the cube (no force prescribed)
    s = _scene(_cube_under_plate(velocity=[0.0, 0.0, -1e-2], plate_z=0.0605))
    z0 = s.x[1, 2]
    # When: it runs long enough to press the cube
    s.advance(10000)
    # Then: it is where the velocity puts it (round-off only), whatever the cube pushes back
    assert s.x[1, 2] == pytest.approx(z0 - 1e-2 * s.time, abs=1e-12)
    assert -s.wforce[0, 2] > s.mass[0] * G * 1.5  # it does press the cube into the floor


def test_actor_pairs_equal_a_brute_force_search():
    # Given: 300 random points with radii 5-15 mm and two actors of radius 0.3 m and 0.2 m
    rng = np.random.default_rng(7)
    n = 300
    x = rng.uniform(0, 0.6, (n + 2, 3))
    rad = np.r_[rng.uniform(0.005, 0.015, n), 0.3, 0.2]
    skin = 0.004
    start, _, pj = build_pairs(x[:n], rad[:n], np.arange(n), skin, 10000, None)
    # When: the actors are added to the particles' list
    st, pi, pj2 = add_actor_pairs(start, pj, x, rad, np.arange(len(x)), n, skin)
    # Then: the pairs are exactly those closer than the skin (bounding spheres), rows sorted by j
    got = set(zip(pi.tolist(), pj2.tolist()))
    d = np.linalg.norm(x[:, None] - x[None], axis=2)
    i, j = np.nonzero(np.triu(d < rad[:, None] + rad[None] + skin, 1))
    assert got == set(zip(i.tolist(), j.tolist()))
    assert len(got) == len(pi)
    for r in range(n + 2):
        row = pj2[st[r]:st[r + 1]]
        assert np.all(np.diff(row) > 0) and np.all(pi[st[r]:st[r + 1]] == r)


def test_remove_actors_gives_back_the_particles():
    # Given: three random hulls with a plate and a sleeper added
    rng = np.random.default_rng(1)
    g = polyhedra_groups([random_hull(rng, (0.01, 0.008, 0.006)) for _ in range(3)], RHO,
                         x=[[0, 0, 0.01], [0.03, 0, 0.01], [0.06, 0, 0.01]])
    a = add_actor(g, box_polyhedron([0.1, 0.05, 0.01]), [0.03, 0, 0.05], STEEL, 0, "plate",
                  load=haversine(0.0, 10.0, 5.0))
    a = add_actor(a, box_polyhedron([0.05, 0.05, 0.02]), [0.03, 0, 0.08], 2800.0, 0, "sleeper")
    assert actor_index(a, "plate") == 3 and actor_index(a, "sleeper") == 4 and actor_index(a, "rail") is None
    # When: the actors are removed
    r = remove_actors(a)
    # Then: every particle array and shape table is what it was
    for grp in ("bodies", "polyhedra", "polyhedron_shapes"):
        assert set(r[grp]) == set(g[grp])
        for k in g[grp]:
            np.testing.assert_array_equal(r[grp][k], g[grp][k], err_msg=f"{grp}/{k}")
    assert "actors" not in r


def test_resume_with_a_cycling_actor_is_bit_identical():
    # Given: four hulls under a plate loaded 10 -> 200 N at 20 Hz, run 3000 steps, copied through
    # groups() as a stage writes them
    rng = np.random.default_rng(5)
    polys = [random_hull(rng, (0.012, 0.01, 0.008)) for _ in range(4)]
    g = polyhedra_groups(polys, RHO, x=[[-0.015, -0.012, 0.01], [0.015, -0.012, 0.01], [-0.015, 0.012, 0.01],
                                        [0.015, 0.012, 0.01]])
    g = add_actor(g, box_polyhedron([0.08, 0.08, 0.01]), [0, 0, 0.027], STEEL, 0, "plate",
                  load=haversine(10.0, 200.0, 20.0, start=0.002))
    a = _scene(g)
    a.advance(3000)
    b = System(a.groups(), a.materials, a.model, a.plan, a.walls, a.dyn, dt=a.dt, time=a.time, step=a.step)
    b.prime = False
    # When: both run 3000 more steps
    a.advance(3000)
    b.advance(3000)
    # Then: bit for bit
    for name in ("x", "v", "q", "L", "f", "tq", "wforce"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
