"""Polyhedra against mesh walls in the engine (demcli.kernels.poly_mesh, the mesh path of
demcli.kernels.shapes.polyhedra._wall_forces): on a flat mesh of many triangles a falling and
bouncing body follows the plane wall's trajectory to round-off, a body at rest on it carries its
weight, a servo-driven mesh lid presses as the plane lid does, the results do not depend on the
thread count, and the smoke case's stones come to rest on an STL floor that carries their weight."""

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import Delaunay
from scipy.spatial.transform import Rotation

from demcli.engine.materials import ContactModel, Material
from demcli.engine.plan import make_plan
from demcli.engine.poly_shape import polyhedra_groups
from demcli.engine.system import Dynamics, System, Walls
from demcli.geometry import convex_hull
from demcli.kernels.walls import MESH, N_WPARAMS, PLANE, SERVO, W_AREA, W_GAIN, W_TARGET, W_VMAX

G = 9.81
RHO = 2600.0


def hull(seed, size, n=20):
    """Hull of n random points in an ellipsoid of semi-axes ``size`` [m] (a stone)."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return convex_hull(d * np.cbrt(rng.uniform(0.3, 1.0, n))[:, None] * np.asarray(size))


def cube(a):
    return convex_hull(np.array([[i, j, k] for i in (0, a) for j in (0, a) for k in (0, a)], float) - a / 2)


def floor_mesh(n=4, size=0.05, seed=2):
    """Flat mesh z = 0 over [-n size / 2, n size / 2]^2: the Delaunay triangles of an (n + 1)^2 grid
    whose inner points are moved in the plane (triangles of many shapes and angles)."""
    xs = (np.arange(n + 1) - n / 2) * size
    pts = np.array([(x, y) for x in xs for y in xs])
    inner = np.all(np.abs(pts) < xs[-1], axis=1)
    pts[inner] += np.random.default_rng(seed).uniform(-0.2, 0.2, (inner.sum(), 2)) * size
    return np.column_stack([pts, np.zeros(len(pts))]), np.asarray(Delaunay(pts).simplices, np.int64)


def mesh_walls(verts, tris):
    """One fixed mesh wall, its point the first vertex (as the case reader places it)."""
    p = verts[0].copy()
    return Walls(name=["floor"], kind=np.array([MESH], np.int8), point=p[None], normal=np.array([[0.0, 0.0, 1.0]]),
                 radius=np.zeros(1), v=np.zeros((1, 3)), material=np.zeros(1, np.int64), control=np.zeros(1, np.int8),
                 prm=np.zeros((1, N_WPARAMS)), extent=np.array([[-1.0, -1.0, -1.0, 1.0, 1.0, 1.0]]),
                 mesh=[(verts - p, tris)])


def system(polys, x, q, v, omega, walls, effects=("gravity", "friction"), dt=None, local_damping=0.0):
    groups = polyhedra_groups(polys, RHO, x=x, q=q, v=v, omega=omega)
    mats = [Material("rock", RHO, young=1e8, friction=0.5, restitution=0.5)]
    s = System(groups, mats, ContactModel(), make_plan(list(effects), walls=True), walls,
               Dynamics(gravity=(0.0, 0.0, -G), local_damping=local_damping), dt=1.0)
    s.dt = 0.1 * s.critical_dt() if dt is None else dt
    return s


def scene(walls, dt=None):
    """A cube and a stone, thrown turning onto the floor from 1 mm above it (their lowest vertices),
    across triangle edges."""
    polys = [cube(0.02), hull(4, (0.015, 0.012, 0.009))]
    q = np.array([[0.97, 0.1, -0.2, 0.1], [0.8, 0.3, 0.5, -0.1]])
    q /= np.linalg.norm(q, axis=1)[:, None]
    x = np.array([[-0.031, 0.012, 0.0], [0.024, -0.018, 0.0]])
    for b, p in enumerate(polys):
        low = Rotation.from_quat(q[b, [1, 2, 3, 0]]).apply(p.vertices - p.centroid)[:, 2].min()
        x[b, 2] = 1e-3 - low
    v = np.array([[0.05, -0.02, -0.1], [-0.03, 0.04, 0.0]])
    omega = np.array([[1.0, 3.0, -2.0], [-4.0, 2.0, 5.0]])
    return system(polys, x, q, v, omega, walls, dt=dt)


def test_bodies_bounce_on_a_flat_mesh_as_on_the_plane():
    # Given the same two bodies dropped onto a plane and onto a flat mesh of 32 triangles (same dt)
    verts, tris = floor_mesh()
    plane = scene(Walls.fixed_planes([[0.0, 0.0, 0.0]], [[0.0, 0.0, 1.0]]))
    mesh = scene(mesh_walls(verts, tris), dt=plane.dt)
    # When both run 10000 steps (impacts, bounces, sliding across triangle edges)
    touched = 0
    for _ in range(100):
        plane.advance(100)
        mesh.advance(100)
        touched += plane.contact_count()[1]
        # Then the trajectories agree to round-off (measured: 4e-15 m, 2e-9 rad/s, 1.2e-10 N), and the
        # walls' reactions too
        np.testing.assert_allclose(mesh.x, plane.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(mesh.w, plane.w, rtol=0, atol=1e-6)
        np.testing.assert_allclose(mesh.wforce, plane.wforce, rtol=1e-6, atol=1e-9)
    assert touched >= 10  # measured: 20 of the 100 looks


def test_a_body_at_rest_on_a_mesh_carries_its_weight():
    # Given a cube set on the flat mesh across a triangle edge, damped to rest
    verts, tris = floor_mesh()
    s = system([cube(0.02)], np.array([[0.003, -0.004, 0.00999]]), np.array([[1.0, 0, 0, 0]]), np.zeros((1, 3)),
               np.zeros((1, 3)), mesh_walls(verts, tris), effects=("gravity", "friction", "local_damping"),
               local_damping=0.4)
    # When it settles
    s.advance(20000)
    # Then the mesh's reaction is its weight (measured: 1e-8 relative) and it has stopped
    weight = s.mass[0] * G
    assert abs(-s.wforce[0, 2] - weight) < 1e-6 * weight
    assert np.abs(s.v).max() < 1e-6
    # and its contact record is on the floor under its centre, along +z, with the weight
    from demcli.stages.contact_record import contact_rows

    (row,) = contact_rows(s)
    assert (row["j"], row["nz"]) == (-1, pytest.approx(1.0, abs=1e-9))
    assert row["fn"] == pytest.approx(weight, rel=1e-6)
    assert abs(row["cz"]) < 1e-3 and np.hypot(row["cx"] - s.x[0, 0], row["cy"] - s.x[0, 1]) < 1e-4


def test_mesh_contacts_do_not_depend_on_the_thread_count():
    # Given 40 stones (three chunks of rows of the wall pass) set 20 um into the mesh, run on one
    # thread and on all threads (2 here)
    import numba

    from demcli.jit import set_threads

    verts, tris = floor_mesh()
    polys = [hull(10 + b, (0.008, 0.006, 0.005)) for b in range(40)]
    x = np.array([[-0.07 + 0.02 * (b % 8), -0.04 + 0.02 * (b // 8), 0.0] for b in range(40)])
    x[:, 2] = [(p.centroid - p.vertices)[:, 2].max() - 2e-5 for p in polys]  # 20 um into the floor
    runs = []
    before = numba.get_num_threads()
    try:
        for n in (1, numba.config.NUMBA_NUM_THREADS):
            set_threads(n)
            s = system(polys, x, np.tile([1.0, 0.0, 0.0, 0.0], (40, 1)), np.zeros((40, 3)), np.zeros((40, 3)),
                       mesh_walls(verts, tris), effects=("gravity", "friction", "local_damping"), local_damping=0.7)
            s.advance(3000)
            runs.append(s)
    finally:
        set_threads(before)
    # Then every bit is the same (each body's rows have one owner and a fixed order)
    a, b = runs
    assert a.contact_count()[1] >= 10  # measured: 16 touching at the end
    for name in ("x", "v", "q", "L", "wforce"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def servo_scene(lid_kind):
    """A 20 mm cube on a plane floor under a lid 0.1 mm above it (a plane or a flat mesh of 32
    triangles facing down) that a servo drives to 2 kPa (0.8 N on the cube's 4 cm^2)."""
    verts, tris = floor_mesh()
    verts = verts + [0.004, -0.003, 0.0201]
    walls = Walls(name=["floor", "lid"], kind=np.array([PLANE, lid_kind], np.int8),
                  point=np.array([[0.0, 0.0, 0.0], verts[0]]), normal=np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]),
                  radius=np.zeros(2), v=np.zeros((2, 3)), material=np.zeros(2, np.int64),
                  control=np.array([0, SERVO], np.int8), prm=np.zeros((2, N_WPARAMS)),
                  extent=np.tile([-1.0, -1.0, -1.0, 1.0, 1.0, 1.0], (2, 1)),
                  mesh=[None, (verts - verts[0], tris)] if lid_kind == MESH else None)
    walls.prm[1, [W_TARGET, W_GAIN, W_VMAX, W_AREA]] = 2000.0, 0.2, 0.05, 4e-4
    return system([cube(0.02)], np.array([[0.0, 0.0, 0.01]]), np.array([[1.0, 0, 0, 0]]), np.zeros((1, 3)),
                  np.zeros((1, 3)), walls, effects=("gravity", "friction", "local_damping"), local_damping=0.7)


def test_a_servo_mesh_lid_presses_as_the_plane_lid():
    # Given a cube under a servo lid, once a plane and once a flat mesh (same dt)
    plane = servo_scene(PLANE)
    mesh = servo_scene(MESH)
    mesh.dt = plane.dt
    # When both run 20000 steps
    plane.advance(20000)
    mesh.advance(20000)
    # Then the mesh lid moves and carries the load as the plane lid does (measured: the same position,
    # 9e-13 N), the servo's target reached (0.8 N to 1e-6)
    np.testing.assert_allclose(mesh.wpoint[1, 2] - mesh.wpoint0[1, 2], plane.wpoint[1, 2] - plane.wpoint0[1, 2],
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(mesh.wforce, plane.wforce, rtol=0, atol=1e-9)
    assert mesh.wforce[1, 2] == pytest.approx(0.8, rel=1e-6)  # the cube pushes the lid up
    assert mesh.wpoint[1, 2] < mesh.wpoint0[1, 2]


def test_smoke_case_stones_come_to_rest_on_an_stl_floor(tmp_path):
    # Given the smoke case: 32 ballast stones assembled up to 0.24 m fall onto a flat STL floor of 18
    # triangles (cases/meshes/poly_floor.stl), local damping 0.8, 4 s
    import meshio

    from demcli import run_case
    from demcli.compare import read_record
    from demcli.state import read_state

    case = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "poly_mesh_wall.yaml"
    run_case(case, out=tmp_path / "run", quiet=True, threads=1)
    state = read_state(tmp_path / "run" / "03-drop.h5")
    walls, _ = read_record(tmp_path / "run" / "records" / "drop_walls.csv")
    # Then they are at rest on it and the floor carries their weight (measured: 2e-8 relative, v 4e-10 m/s)
    weight = state["bodies/mass"].sum() * G
    assert walls["floor.force"][-1] == pytest.approx(weight, rel=0.01)
    assert np.abs(state["bodies/v"]).max() < 1e-3
    assert state["bodies/x"][:, 2].min() > 0.0
    # and the snapshots draw the mesh where it is
    drawn = meshio.read(tmp_path / "run" / "drop" / "walls_000002.vtu")
    assert [(c.type, len(c.data)) for c in drawn.cells] == [("triangle", 18)]
