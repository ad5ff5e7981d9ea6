"""Sphere against a triangle mesh (demcli.kernels.mesh): the closest point against a brute-force
reference, and a flat mesh of many triangles against the analytic plane wherever the sphere sits
(face interior, edge, vertex: one contact, the plane's overlap and normal to 1e-12 relative);
a concave corner gives both faces, a convex edge one contact along the edge's normal."""

import numpy as np
import pytest

from demcli.kernels.mesh import (MAX_TOUCH, bin_triangles, closest_on_triangle, mesh_arrays, mesh_of,
                                 sphere_mesh_contacts)

TOL = 1e-12


def brute_closest(p, a, b, c, n=400):
    """Nearest of the vertices, the exact projections onto the three edges, and (when inside) the face."""
    cands = [a, b, c]
    for u, v in ((a, b), (b, c), (c, a)):
        t = np.clip((p - u) @ (v - u) / ((v - u) @ (v - u)), 0.0, 1.0)
        cands.append(u + t * (v - u))
    nrm = np.cross(b - a, c - a)
    nrm /= np.linalg.norm(nrm)
    f = p - (p - a) @ nrm * nrm
    w = np.linalg.solve(np.array([b - a, c - a, nrm]).T, f - a)
    if w[0] >= 0 and w[1] >= 0 and w[0] + w[1] <= 1:
        cands.append(f)
    return min(cands, key=lambda q: np.linalg.norm(p - q))


def contacts(centre, r, verts, tris, cell):
    """(triangles, points, normals, overlaps) of one sphere, through the kernel."""
    grid = bin_triangles(verts, tris, cell)
    t, q, n, s = (np.empty(MAX_TOUCH, np.int64), np.empty((MAX_TOUCH, 3)), np.empty((MAX_TOUCH, 3)),
                  np.empty(MAX_TOUCH))
    k = sphere_mesh_contacts(np.asarray(centre, float), r, verts, tris, *grid, cell, t, q, n, s)
    return t[:k], q[:k], n[:k], r - s[:k]


def test_closest_point_matches_brute_force():
    # Given random triangles and points, including points far outside every edge and vertex
    rng = np.random.default_rng(3)
    for _ in range(2000):
        a, b, c, p = rng.normal(size=(4, 3))
        p *= 3.0
        # When the kernel finds the closest point, Then it is the brute-force one
        q = np.array(closest_on_triangle(p, a, b, c)[:3])
        np.testing.assert_allclose(q, brute_closest(p, a, b, c), atol=1e-12)


def test_binning_lists_every_triangle_in_its_cells(grid_mesh):
    verts, tris, _ = grid_mesh(6, 0.1, seed=1)
    lo, dims, cstart, clist = bin_triangles(verts, tris, 0.13)
    # every triangle appears at least once, and each cell lists distinct triangles
    assert set(clist) == set(range(len(tris)))
    for k in range(len(cstart) - 1):
        cell = clist[cstart[k]:cstart[k + 1]]
        assert len(set(cell)) == len(cell)


def _plane_points(verts, tris, size, rng):
    """Sphere feet: triangle centroids (faces), edge midpoints, vertices, and random points."""
    feet = [verts[tris].mean(axis=1)[:20], 0.5 * (verts[tris[:, 0]] + verts[tris[:, 1]])[:20],
            0.5 * (verts[tris[:, 1]] + verts[tris[:, 2]])[:20], verts[:30]]
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    feet.append(lo + rng.uniform(0.2, 0.8, (100, 3)) * (hi - lo))
    return np.concatenate(feet)


@pytest.mark.parametrize("rot, seed", [((0.0, 0.0, 0.0), None), ((23.0, -41.0, 67.0), 5)])
def test_flat_mesh_gives_the_plane_force_everywhere(grid_mesh, rot, seed):
    # Given a flat mesh of 2 x 8 x 8 triangles (tilted, jittered) and spheres pressed into it
    size, r, k_n = 0.1, 0.07, 1.0e6
    verts, tris, normal = grid_mesh(8, size, rot, (0.3, -0.2, 0.5), seed)
    rng = np.random.default_rng(11)
    for foot in _plane_points(verts, tris, size, rng):
        foot = foot - (foot - verts[0]) @ normal * normal      # exactly in the plane (round-off)
        height = rng.uniform(0.2, 0.99) * r
        centre = foot + height * normal
        # When the mesh contacts are summed
        tri, q, n, delta = contacts(centre, r, verts, tris, 0.15)
        # Then there is exactly one, with the plane's overlap, normal and linear-spring force
        plane_delta = r - (centre - verts[0]) @ normal
        assert len(tri) == 1, (foot, tri)
        assert abs(delta[0] - plane_delta) <= TOL * plane_delta * 10
        np.testing.assert_allclose(n[0], normal, atol=TOL * 10)
        f_mesh = (k_n * delta[:, None] * n).sum(axis=0)
        f_plane = k_n * plane_delta * normal
        assert np.linalg.norm(f_mesh - f_plane) <= 1e-11 * np.linalg.norm(f_plane)


def test_flat_mesh_force_is_continuous_across_edges(grid_mesh):
    # Given a sphere sliding along a line that crosses many edges and vertices
    verts, tris, normal = grid_mesh(8, 0.1, seed=2)
    r = 0.05
    forces = []
    for s in np.linspace(0.05, 0.75, 701):
        _, _, n, delta = contacts((s, 0.37 * s + 0.1, 0.04), r, verts, tris, 0.12)
        forces.append((delta[:, None] * n).sum(axis=0))
    # Then the summed force is the plane's at every position: no jump at an edge
    np.testing.assert_allclose(np.array(forces), np.tile([0.0, 0.0, 0.01], (701, 1)), rtol=0, atol=1e-15)


def _corner(convex):
    """Two perpendicular faces meeting along the y axis: floor z = 0 for x >= 0 and wall x = 0 for
    z >= 0 (concave: an inside corner), or top z = 0 for x <= 0 and side x = 0 for z <= 0 (convex)."""
    s = -1.0 if convex else 1.0
    verts = np.array([[0, 0, 0], [0, 1, 0], [s, 0, 0], [s, 1, 0], [0, 0, s], [0, 1, s]], float)
    return verts, np.array([[0, 2, 1], [1, 2, 3], [0, 1, 4], [1, 5, 4]], np.int64)


def test_concave_corner_gives_both_faces():
    verts, tris = _corner(convex=False)
    # Given a sphere of radius 0.1 touching the floor and the wall of an inside corner
    tri, _, n, delta = contacts((0.08, 0.5, 0.09), 0.1, verts, tris, 0.3)
    # Then it feels one contact on each face, along each face's normal
    order = np.argsort(tri)
    np.testing.assert_allclose(n[order], [[0, 0, 1], [1, 0, 0]], atol=TOL)
    np.testing.assert_allclose(delta[order], [0.1 - 0.09, 0.1 - 0.08], rtol=TOL)


def test_convex_edge_gives_one_contact_along_its_normal():
    verts, tris = _corner(convex=True)
    # Given a sphere beyond an outside edge, at 45 degrees
    a = 0.06
    tri, q, n, delta = contacts((a, 0.5, a), 0.1, verts, tris, 0.3)
    # Then one contact, at the edge, along the bisector
    assert len(tri) == 1
    np.testing.assert_allclose(q[0], [0, 0.5, 0], atol=TOL)
    np.testing.assert_allclose(n[0], [2 ** -0.5, 0, 2 ** -0.5], atol=TOL)
    np.testing.assert_allclose(delta[0], 0.1 - a * 2 ** 0.5, rtol=TOL)


def test_mesh_arrays_give_each_wall_its_own_mesh_and_grid(grid_mesh):
    # Given four walls, the second and the fourth meshes of 8 and 18 triangles
    a, ta, _ = grid_mesh(2, 0.1)
    b, tb, _ = grid_mesh(3, 0.05, shift=(1.0, 0.0, 0.0))
    mesh = mesh_arrays([None, (a, ta), None, (b, tb)])
    # When wall w's arrays are taken out
    for w, (verts, tris) in ((1, (a, ta)), (3, (b, tb))):
        v, t, lo, dims, cstart, clist, cell = mesh_of(mesh, w)
        # Then they are its mesh and the grid bin_triangles makes of it, at its cell size
        np.testing.assert_array_equal(v, verts)
        np.testing.assert_array_equal(t, tris)
        for got, want in zip((lo, dims, cstart, clist), bin_triangles(verts, tris, cell)):
            np.testing.assert_array_equal(got, want)
    # and the other walls hold none
    assert all(len(x) == 0 for x in mesh_of(mesh, 0)[:2] + mesh_of(mesh, 2)[:2])
