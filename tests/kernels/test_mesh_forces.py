"""Loads of a triangle-mesh wall on a sphere (demcli.kernels.shapes.spheres._mesh_contact) against the analytic plane
z = 0 through the same contact law: a ball bouncing and sliding with spin on a jittered mesh floor
follows the plane ball to round-off (the tangential spring carried across triangle edges), and a
floor moving up strikes a resting ball away."""

import numpy as np

from demcli.kernels.contact import LINEAR, N_PARAMS, P_ARM, P_CTR, P_KN, P_KT, P_MU, P_NOTENSION, P_ZETA, contact_law
from demcli.kernels.mesh import mesh_arrays
from demcli.kernels.shapes.spheres import _mesh_contact

R, MASS, DT = 0.01, 0.01, 2e-5
G = np.array([0.0, 0.0, -9.81])


def materials():
    prm = np.zeros((1, 1, N_PARAMS))
    prm[0, 0, [P_KN, P_KT, P_ZETA, P_MU, P_NOTENSION, P_ARM]] = [2e4, 1.6e4, 0.2, 0.4, 1.0, 1.0]
    return prm


def plane_loads(x, v, w, ft, prm):
    """Force and torque of the plane z = 0 (at rest) on the sphere: the analytic reference."""
    delta = R - x[2]
    if delta <= 0:
        ft[:] = 0.0
        return np.zeros(3), np.zeros(3)
    a = R - delta
    n = np.array([0.0, 0.0, 1.0])
    vc = v - a * np.cross(w, n)
    f = np.array(contact_law(LINEAR, prm, 0, 0, delta, *n, *vc, *w, R, MASS, DT, ft, ft, 0, True, False)[:3])
    return f, -a * np.cross(n, f)


def mesh_loads(x, v, w, ft, prm, mesh, point=np.zeros(3), wv=np.zeros(3)):
    """Force and torque of the mesh wall (MeshArrays of one wall, its point ``point``) on the sphere."""
    out = _mesh_contact(0, 0, 0, x[None], v[None], w[None], np.array([R]), np.zeros(1, np.int64), np.array([MASS]),
                        point[None], wv[None], np.zeros(1, np.int64), prm, LINEAR, DT, ft, np.zeros((0, 3)), True,
                        False, mesh)
    return np.array(out[:3]), np.array(out[3:6])


def run(loads, steps, x, v, w):
    """Symplectic Euler of one ball (moment of inertia 2/5 m R^2); the force at every step."""
    ft = np.zeros((1, 3))
    inertia = 0.4 * MASS * R * R
    forces = []
    for _ in range(steps):
        f, t = loads(x, v, w, ft)
        v = v + DT * (f / MASS + G)
        w = w + DT * t / inertia
        x = x + DT * v
        forces.append(f)
    return x, v, np.array(forces)


def test_ball_on_mesh_floor_follows_the_plane_ball(grid_mesh):
    # Given a jittered floor of 2 x 10 x 10 triangles of 0.03 m and a ball dropped on it while
    # sliding fast with backspin, so that it bounces, slides and rolls across many edges
    prm = materials()
    verts, tris, _ = grid_mesh(10, 0.03, seed=4)
    mesh = mesh_arrays([(verts, tris)])
    x0, v0, w0 = np.array([0.02, 0.03, 0.012]), np.array([0.6, 0.35, -0.2]), np.array([5.0, -20.0, 3.0])
    # When both run 12000 steps (0.24 s)
    xm, vm, fm = run(lambda x, v, w, ft: mesh_loads(x, v, w, ft, prm, mesh), 12000, x0, v0, w0)
    xp, vp, fp = run(lambda x, v, w, ft: plane_loads(x, v, w, ft, prm), 12000, x0, v0, w0)
    # Then the contact forces agree to round-off at every step (no jump where an edge is crossed)
    assert np.abs(fp).max() > 1.0 and np.abs(fp[:, :2]).max() > 0.1        # it did bounce and slide
    np.testing.assert_allclose(fm, fp, rtol=0, atol=1e-9 * np.abs(fp).max())
    np.testing.assert_allclose(xm, xp, rtol=0, atol=1e-12)
    assert xm[0] - x0[0] > 0.06                                              # it crossed several squares


def test_rising_floor_strikes_a_ball_away(grid_mesh):
    # Given a ball resting just on a floor mesh that moves up at 0.05 m/s (no gravity)
    prm = materials()
    verts, tris, _ = grid_mesh(4, 0.03, seed=1)
    x, v, w = np.array([0.05, 0.05, R]), np.zeros(3), np.zeros(3)
    ft = np.zeros((1, 3))
    up = np.array([0.0, 0.0, 0.05])
    mesh = mesh_arrays([(verts, tris)])
    for step in range(4000):
        f, _ = mesh_loads(x, v, w, ft, prm, mesh, up * DT * step, up)
        v = v + DT * f / MASS
        x = x + DT * v
    # Then the ball is struck away: restitution e ~ 0.53 (damping ratio 0.2) sends it up at
    # (1 + e) times the floor's speed, and it is above the floor
    assert 1.4 * 0.05 < v[2] < 1.7 * 0.05 and abs(v[:2]).max() < 1e-12
    assert x[2] > R + 0.05 * DT * 4000
