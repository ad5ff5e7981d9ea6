"""Loads of a triangle-mesh wall on spheres (demcli.kernels.mesh_forces) against the analytic plane
z = 0 through the same contact law: a ball bouncing and sliding with spin on a jittered mesh floor
follows the plane ball to round-off (the tangential spring carried across triangle edges), and a
floor moving up strikes a resting ball away."""

import numpy as np

from demcli.kernels.contact import LINEAR, N_PARAMS, P_ARM, P_CTR, P_KN, P_KT, P_MU, P_NOTENSION, P_ZETA, contact_law
from demcli.kernels.mesh import bin_triangles
from demcli.kernels.mesh_forces import sphere_mesh_forces

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


def mesh_loads(x, v, w, ft, prm, mesh, wv=np.zeros(3)):
    verts, tris, grid = mesh
    fs, ts = np.zeros((1, 3)), np.zeros((1, 3))
    sphere_mesh_forces(x[None], v[None], w[None], np.array([R]), np.zeros(1, np.int64), np.array([MASS]), verts, tris,
                       *grid, 0.05, wv, 0, prm, LINEAR, DT, ft, True, fs, ts)
    return fs[0], ts[0]


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
    mesh = (verts, tris, bin_triangles(verts, tris, 0.05))
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
    for step in range(4000):
        moved = verts + up * DT * step
        f, _ = mesh_loads(x, v, w, ft, prm, (moved, tris, bin_triangles(moved, tris, 0.05)), up)
        v = v + DT * f / MASS
        x = x + DT * v
    # Then the ball is struck away: restitution e ~ 0.53 (damping ratio 0.2) sends it up at
    # (1 + e) times the floor's speed, and it is above the floor
    assert 1.4 * 0.05 < v[2] < 1.7 * 0.05 and abs(v[:2]).max() < 1e-12
    assert x[2] > R + 0.05 * DT * 4000
