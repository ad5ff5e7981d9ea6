"""Scenes of spheres and convex polyhedra in one engine (#28 item 1; kernels/shapes/mixed.py).

Sphere-polyhedron contacts are point contacts under the sphere law (R* = the sphere's radius,
the polyhedron locally flat): on a face they must reproduce a sphere on a plane wall, conserve
momentum exactly and energy to the integrator's order, and hold the Hertz equilibrium; the
sphere-sphere and polyhedron-polyhedron pairs of the same scene keep their own laws.
"""

import math

import numpy as np
import pytest

from demcli.engine.materials import ContactModel, Material
from demcli.engine.mixed_shape import MixedShape, mixed_groups
from demcli.engine.plan import make_plan
from demcli.engine.poly_shape import polyhedra_groups
from demcli.engine.system import Dynamics, System, Walls
from demcli.geometry import convex_hull
from demcli.kernels import layout as K

RHO = 2600.0
R = 0.01
HELD = K.FIX_TRANSLATION | K.FIX_ROTATION


def cube(edge, centre=(0.0, 0.0, 0.0)):
    """Cube polyhedron of the given edge [m] centred at ``centre``."""
    h = 0.5 * edge
    c = np.asarray(centre, float)
    return convex_hull(np.array([[i, j, k] for i in (-h, h) for j in (-h, h) for k in (-h, h)], float) + c)


def sphere_groups(x, v=None, omega=None, r=R, flags=None):
    x = np.asarray(x, float).reshape(-1, 3)
    n = len(x)
    m = np.full(n, RHO * 4.0 / 3.0 * math.pi * r ** 3)
    bodies = {"x": x, "v": np.zeros((n, 3)) if v is None else np.asarray(v, float).reshape(n, 3),
              "omega": np.zeros((n, 3)) if omega is None else np.asarray(omega, float).reshape(n, 3),
              "q": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), "mass": m, "inertia": (0.4 * m * r * r)[:, None],
              "flags": np.zeros(n, np.int8) if flags is None else np.asarray(flags, np.int8),
              "id": np.arange(n, dtype=np.int64)}
    spheres = {"body": np.arange(n, dtype=np.int64), "offset": np.zeros((n, 3)), "radius": np.full(n, r),
               "material": np.zeros(n, np.int64)}
    return {"bodies": bodies, "spheres": spheres}


def system(groups, effects=(), gravity=(0.0, 0.0, 0.0), walls=None, restitution=1.0, friction=0.5, dt=2e-6,
           **kw):
    walls = Walls() if walls is None else walls
    mats = [Material("rock", RHO, young=1e8, poisson=0.25, friction=friction, restitution=restitution)]
    return System(groups, mats, ContactModel(), make_plan(list(effects), walls=len(walls) > 0), walls,
                  Dynamics(gravity=gravity, **kw), dt=dt)


def estar():
    e, nu = 1e8, 0.25
    return 1.0 / (2.0 * (1.0 - nu * nu) / e)


def test_the_mixed_plugin_serves_a_state_with_spheres_and_polyhedra():
    # Given: two spheres and a cube
    g = mixed_groups(sphere_groups([[0.0, 0.0, 0.1], [0.05, 0.0, 0.1]]), polyhedra_groups([cube(0.04)], RHO))
    # When
    s = system(g)
    # Then: spheres first, then the cube's bounding sphere; every body a rigid rotor
    assert isinstance(s.plugin, MixedShape)
    assert s.ns == 2 and len(s.rad) == 3 and s.rigid
    assert s.rad[2] == pytest.approx(0.02 * math.sqrt(3.0), rel=1e-9)
    np.testing.assert_array_equal(s.sbody, [0, 1, 2])


def test_a_sphere_falling_on_a_polyhedron_face_moves_as_on_a_plane_wall():
    # Given: a sphere falling from rest onto the top face (z = 0) of a held cube, elastic Hertz,
    # and the same sphere onto a plane wall at z = 0 of the same material
    x0 = [[0.003, -0.002, R + 0.0005]]
    on_cube = system(mixed_groups(sphere_groups(x0), polyhedra_groups([cube(0.1, (0, 0, -0.05))], RHO,
                                                                     flags=np.array([HELD], np.int8))),
                     effects=["gravity"], gravity=(0.0, 0.0, -9.81))
    on_wall = system(sphere_groups(x0), effects=["gravity"], gravity=(0.0, 0.0, -9.81),
                     walls=Walls.fixed_planes([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]]))
    z_cube, z_wall = [], []
    cube0 = on_cube.x[1].copy()
    # When: the fall (~10 ms), the bounce and the rise
    for _ in range(40):
        on_cube.advance(500)
        on_wall.advance(500)
        z_cube.append(on_cube.x[0, 2])
        z_wall.append(on_wall.x[0, 2])
    # Then: the same trajectory (the same law, R*, normal and overlap; the face's normal is exact)
    assert min(z_wall) < R  # it did touch
    np.testing.assert_allclose(z_cube, z_wall, rtol=0, atol=1e-15)
    # and the held cube did not move
    np.testing.assert_array_equal(on_cube.x[1], cube0)


@pytest.mark.parametrize("friction", (0.0, 0.5))
def test_momentum_is_conserved_in_a_sphere_polyhedron_collision(friction):
    # Given: a spinning sphere striking a free, turned cube off-centre (no gravity)
    q = np.array([[math.cos(0.4), 0.3, 0.5, math.sin(0.4)]])
    g = mixed_groups(sphere_groups([[-0.04, 0.006, 0.004]], v=[[2.0, 0.1, -0.2]], omega=[[10.0, -30.0, 5.0]]),
                     polyhedra_groups([cube(0.03)], RHO, x=[[0.0, 0.0, 0.0]], q=q))
    s = system(g, effects=["friction"] if friction else [], friction=friction)

    def momenta():
        p = (s.mass[:, None] * s.v).sum(axis=0)
        ang = (s.mass[:, None] * np.cross(s.x, s.v)).sum(axis=0) + s.L.sum(axis=0)
        return p, ang

    p0, a0 = momenta()
    # When: 20 ms (the contact lasts ~0.3 ms)
    s.advance(10000)
    p1, a1 = momenta()
    # Then: both bodies moved, and linear and angular momentum (about the origin) are kept to
    # round-off: equal and opposite forces at one contact point, x_{n+1} x v = x_n x v in the drift
    assert np.linalg.norm(s.v[1]) > 0.1 and np.linalg.norm(s.w[1]) > 1.0
    np.testing.assert_allclose(p1, p0, rtol=0, atol=1e-13 * np.abs(p0).max())
    np.testing.assert_allclose(a1, a0, rtol=0, atol=1e-11 * np.abs(a0).max())  # measured 7.7e-13


def test_an_elastic_frictionless_sphere_polyhedron_collision_keeps_the_kinetic_energy():
    # Given: a sphere hitting a free cube's edge region, elastic Hertz, no friction
    g = mixed_groups(sphere_groups([[-0.035, 0.0, 0.012]], v=[[1.5, 0.0, 0.0]]),
                     polyhedra_groups([cube(0.03)], RHO, x=[[0.0, 0.0, 0.0]]))
    s = system(g)
    ke0 = s.kinetic_energy()
    # When
    s.advance(10000)
    # Then: the cube took a third of it, the sum is kept to the Verlet step's order (measured 3.2e-7)
    assert 0.5 * s.mass[1] * float(s.v[1] @ s.v[1]) > 0.05 * ke0
    assert s.contact_count()[0] == 0
    assert s.kinetic_energy() == pytest.approx(ke0, rel=1e-6)


def test_a_sphere_rests_on_a_polyhedron_with_the_hertz_overlap():
    # Given: a damped sphere settling on a held cube under gravity
    g = mixed_groups(sphere_groups([[0.0, 0.0, R + 1e-4]]),
                     polyhedra_groups([cube(0.05, (0, 0, -0.025))], RHO, flags=np.array([HELD], np.int8)))
    s = system(g, effects=["gravity"], gravity=(0.0, 0.0, -9.81), restitution=0.2)
    # When: 0.2 s
    s.advance(100000)
    # Then: F = m g = 4/3 E* sqrt(R) delta^1.5 (R* = R: the face is flat)
    m = s.mass[0]
    delta = (3.0 * m * 9.81 / (4.0 * estar() * math.sqrt(R))) ** (2.0 / 3.0)
    assert R - s.x[0, 2] == pytest.approx(delta, rel=1e-9)  # measured 1.0e-12
    assert abs(s.v[0, 2]) < 1e-9


def _far_sphere():
    """A resting sphere far from everything: it makes a scene mixed and touches nothing."""
    return sphere_groups([[1.0, 1.0, 1.0]])


def test_polyhedron_pairs_of_a_mixed_scene_follow_the_volumetric_law_as_alone():
    # Given: two cubes colliding obliquely with friction, alone and beside a far sphere
    q = np.array([[1.0, 0.0, 0.0, 0.0], [math.cos(0.3), 0.2, -0.4, math.sin(0.3)]])
    cubes = dict(x=[[0.0, 0.0, 0.0], [0.042, 0.004, -0.003]], v=[[1.0, 0.0, 0.0], [-1.0, 0.2, 0.0]], q=q)
    alone = system(polyhedra_groups([cube(0.03)] * 2, RHO, **cubes), effects=["friction"], dt=1e-6)
    mixed = system(mixed_groups(_far_sphere(), polyhedra_groups([cube(0.03)] * 2, RHO, **cubes)),
                   effects=["friction"], dt=1e-6)
    touching = 0
    # When: 6 ms
    for _ in range(30):
        alone.advance(200)
        mixed.advance(200)
        touching += alone.contact_count()[0]
    # Then: the same motion (the primitives sit on the centroids: the member pass adds nothing)
    assert touching > 0 and abs(alone.v[0, 0] - 1.0) > 0.1  # they collided
    np.testing.assert_allclose(mixed.x[1:], alone.x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(mixed.v[1:], alone.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(mixed.L[1:], alone.L, rtol=0, atol=1e-15)


def test_sphere_pairs_of_a_mixed_scene_follow_the_sphere_law_as_alone():
    # Given: two spheres colliding obliquely with friction, alone and beside a far cube
    spheres = dict(x=[[0.0, 0.0, 0.0], [0.0195, 0.004, 0.0]], v=[[1.0, 0.0, 0.0], [-1.0, 0.0, 0.3]])
    alone = system(sphere_groups(**spheres), effects=["friction"])
    mixed = system(mixed_groups(sphere_groups(**spheres), polyhedra_groups([cube(0.03, (1, 1, 1))], RHO)),
                   effects=["friction"])
    # When
    alone.advance(5000)
    mixed.advance(5000)
    # Then: the same motion to round-off (a sphere here is a rigid rotor: omega = L / I)
    assert np.abs(alone.w).max() > 1.0
    np.testing.assert_allclose(mixed.x[:2], alone.x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(mixed.v[:2], alone.v, rtol=0, atol=1e-12)
    np.testing.assert_allclose(mixed.w[:2], alone.w, rtol=1e-12, atol=1e-12)


def bed_centres():
    """3 x 3 x 2 sphere centres [m] (radius R) in a 0.06 m square box."""
    return np.array([[0.01 + 0.02 * i, 0.01 + 0.02 * j, 0.0105 + 0.021 * k]
                     for i in range(3) for j in range(3) for k in range(2)])


def plate_on_a_bed(load=20.0):
    """3 x 3 x 2 spheres in a box of plane walls and a loaded cuboid plate (an actor) on top:
    (groups, walls, the System's keyword arguments)."""
    from demcli.engine.actors import box_polyhedron

    xs = bed_centres()
    plate = polyhedra_groups([box_polyhedron([0.058, 0.058, 0.01])], RHO, x=[[0.03, 0.03, 0.048]],
                             flags=np.array([K.FIX_ROTATION | K.FIX_X | K.FIX_Y | K.LOADED], np.int8))
    g = mixed_groups(sphere_groups(xs), plate)
    g["actors"] = {"body": np.array([18]), "name": np.array(["plate"], dtype=object),
                   "load_mean": np.array([[0.0, 0.0, -load]]), "load_amplitude": np.zeros((1, 3)),
                   "frequency": np.zeros(1), "phase": np.zeros(1), "start": np.zeros(1)}
    kw = dict(effects=["gravity", "friction", "local_damping"], gravity=(0.0, 0.0, -9.81), restitution=0.3,
              dt=5e-6, local_damping=0.7)
    return g, Walls.box_faces([0.06, 0.06, 0.2]), kw


def test_a_polyhedral_plate_loads_a_sphere_bed_in_a_box():
    # Given: the plate of 20 N on the bed, gravity, damping
    load = 20.0
    g, box, kw = plate_on_a_bed(load)
    s = system(g, walls=box, **kw)
    assert s.nsmall == 18  # the plate is paired outside the cell grid
    # When: 0.15 s
    s.advance(30000)
    # Then: at rest, the floor carries the spheres' and the plate's weights and the load, and the
    # plate rests on the spheres (its contacts with them carry its weight and the load)
    weight = 9.81 * float(s.mass.sum())
    floor = [k for k in range(len(box)) if box.normal[k][2] > 0.5][0]
    assert np.abs(s.v).max() < 1e-3
    assert s.wforce[floor, 2] == pytest.approx(-(weight + load), rel=1e-3)
    nl = s.nl
    on_plate = (nl.pj == 18) & (nl.act == 1)
    assert on_plate.sum() >= 3
    assert nl.fc[on_plate, 2].sum() == pytest.approx(-(9.81 * s.mass[18] + load), rel=1e-3)


def test_a_mixed_scene_resumes_from_its_state_groups_bit_for_bit():
    # Given: the plate scene halfway down, and a second System built from its state groups
    # (contacts stored by kind: contacts, sphere_body_contacts, body_contacts, wall_contacts)
    g, box, kw = plate_on_a_bed()
    s = system(g, walls=box, **kw)
    s.advance(3000)
    groups = s.groups()
    assert len(groups["sphere_body_contacts"]["sphere"]) + len(groups["contacts"]["i"]) > 0
    r = system(groups, walls=Walls.box_faces([0.06, 0.06, 0.2]), **kw)
    r.prime = False  # the stored loads, as a resumed stage (stages/loop.py)
    # When: both go on
    s.advance(2000)
    r.advance(2000)
    # Then: the same numbers
    np.testing.assert_array_equal(r.x, s.x)
    np.testing.assert_array_equal(r.L, s.L)
    np.testing.assert_array_equal(r.nl.ft, s.nl.ft)


def test_an_actor_added_to_a_sphere_bed_makes_the_mixed_scene_and_removing_it_gives_the_bed_back():
    from demcli.engine.actors import actor_index, add_actor, box_polyhedron, remove_actors

    # Given: the plate of plate_on_a_bed added by add_actor to the bed of spheres alone
    ref, box, kw = plate_on_a_bed(20.0)
    bed = sphere_groups(bed_centres())
    load = {"load_mean": [0.0, 0.0, -20.0], "load_amplitude": [0.0, 0.0, 0.0], "frequency": 0.0, "phase": 0.0,
            "start": 0.0}
    a = add_actor(bed, box_polyhedron([0.058, 0.058, 0.01]), [0.03, 0.03, 0.048], RHO, 0, "plate", load=load)
    # Then: the groups are those mixed_groups builds (every body a rigid rotor, the plate last)
    assert actor_index(a, "plate") == 18
    for grp in ("bodies", "spheres", "polyhedra", "polyhedron_shapes"):
        assert set(a[grp]) == set(ref[grp]), grp
        for k in ref[grp]:
            np.testing.assert_array_equal(a[grp][k], ref[grp][k], err_msg=f"{grp}/{k}")
    # and the scene runs as a mixed one; once the plate touches the bed, removing it gives back
    # the spheres' bodies (single spheres again: inertia (n, 1)) without the plate's contacts
    s = system(a, walls=box, **kw)
    assert isinstance(s.plugin, MixedShape)
    s.advance(6000)
    st = dict(s.groups(), actors=a["actors"])
    assert len(st["sphere_body_contacts"]["sphere"]) > 0
    r = remove_actors(st)
    assert "polyhedra" not in r and "polyhedron_shapes" not in r and "sphere_body_contacts" not in r
    assert r["bodies"]["inertia"].shape == (18, 1)
    for k in st["bodies"]:
        np.testing.assert_array_equal(r["bodies"][k], np.asarray(st["bodies"][k])[:18, :1] if k == "inertia"
                                      else np.asarray(st["bodies"][k])[:18], err_msg=k)
    assert type(system(r, walls=box, **kw).plugin).__name__ == "SphereShape"
