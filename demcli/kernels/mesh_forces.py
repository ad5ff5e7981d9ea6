"""Forces between spheres and one rigid triangle-mesh wall translating at velocity v_w.

Each contact of :func:`demcli.kernels.mesh.sphere_mesh_contacts` (overlap delta [m], unit
normal n from the mesh to sphere i) goes through the same contact law as the plane walls
(:func:`demcli.kernels.contact.contact_law`, effective radius r_i, mass m_i), with the
contact-point velocity v_c = v_i - v_w - a (omega_i x n), lever arm a = |c - q| + (1 - P_ARM)
delta, and torque on the sphere -a n x F. The tangential spring of sphere i against the mesh
lives in history row i (keyed by sphere and mesh, not by triangle, so it is carried across
triangle edges); where a sphere touches the mesh at several features at once (a concave
corner) the deepest contact carries the history and the others start their springs afresh
each step. Not yet wired into the engine's step loop.
"""

import numpy as np

from demcli.jit import njit
from demcli.kernels.contact import P_ARM, contact_law
from demcli.kernels.mesh import MAX_TOUCH, sphere_mesh_contacts


@njit
def _deepest(delta, count):
    best = 0
    for m in range(1, count):
        if delta[m] > delta[best]:
            best = m
    return best


@njit
def sphere_mesh_forces(xs, vs, ws, rad, smat, smass, verts, tris, lo, dims, cstart, clist, cell, wv, wmat,
                       prm, law, dt, ft, friction, fs, ts):
    """Loads of one mesh wall on every sphere, added to fs and ts; returns the force on the wall [N].

    xs, vs, ws (n, 3) sphere centres [m], velocities [m/s], angular velocities [rad/s]; rad (n,)
    [m]; smat (n,) int64 materials; smass (n,) [kg]; verts (nv, 3) [m] and tris (nt, 3) of the
    mesh where it is now, with its grid from :func:`demcli.kernels.mesh.bin_triangles`; wv (3,)
    wall velocity [m/s]; wmat its material; prm, law, dt as for contact_law; ft (n, 3) tangential
    springs of the spheres against this mesh [N] (row i zeroed when sphere i leaves it);
    friction: switch; fs, ts (n, 3) force [N] and torque [N m] sums, updated."""
    mark = np.full(len(tris), -1, np.int64)
    tri = np.empty(MAX_TOUCH, np.int64)
    q = np.empty((MAX_TOUCH, 3))
    nrm = np.empty((MAX_TOUCH, 3))
    delta = np.empty(MAX_TOUCH)
    scratch = np.zeros((1, 3))
    wall = np.zeros(3)
    for i in range(len(xs)):
        count = sphere_mesh_contacts(xs[i], rad[i], verts, tris, lo, dims, cstart, clist, cell, mark, i, tri, q,
                                     nrm, delta)
        if count == 0:
            ft[i, :] = 0.0
            continue
        deep = _deepest(delta, count)
        for m in range(count):
            hist, row = (ft, i) if m == deep else (scratch, 0)
            if m != deep:
                scratch[0, :] = 0.0
            nx, ny, nz = nrm[m, 0], nrm[m, 1], nrm[m, 2]
            a = rad[i] - delta[m] + (1.0 - prm[smat[i], wmat, P_ARM]) * delta[m]
            vx = vs[i, 0] - wv[0] - a * (ws[i, 1] * nz - ws[i, 2] * ny)
            vy = vs[i, 1] - wv[1] - a * (ws[i, 2] * nx - ws[i, 0] * nz)
            vz = vs[i, 2] - wv[2] - a * (ws[i, 0] * ny - ws[i, 1] * nx)
            fx, fy, fz, _, _, _, _, _ = contact_law(law, prm, smat[i], wmat, delta[m], nx, ny, nz, vx, vy, vz,
                                                    ws[i, 0], ws[i, 1], ws[i, 2], rad[i], smass[i], dt,
                                                    hist, scratch, row, friction, False)
            fs[i, 0] += fx
            fs[i, 1] += fy
            fs[i, 2] += fz
            ts[i, 0] += -a * (ny * fz - nz * fy)
            ts[i, 1] += -a * (nz * fx - nx * fz)
            ts[i, 2] += -a * (nx * fy - ny * fx)
            wall[0] -= fx
            wall[1] -= fy
            wall[2] -= fz
    return wall
