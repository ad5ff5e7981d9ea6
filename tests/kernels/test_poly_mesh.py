"""A polyhedron against a mesh wall (demcli.kernels.poly_mesh): the overlaps with the prisms under
the triangles of a flat mesh sum to the half-space's V, centroid and S (so the contact frame and the
force are the plane wall's), wherever the body sits across triangle edges and vertices; at a 90
degree fold the prisms leave out (concave) or count twice (convex) the wedge under the edge, as the
construction says (the numbers quoted in docs/walls.md)."""

import itertools
import math

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

from demcli.geometry import convex_hull, random_polyhedron
from demcli.kernels.mesh import mesh_arrays
from demcli.kernels.poly_mesh import R_GX, R_SX, R_V, mesh_pieces, mesh_scratch, plane_sums
from demcli.kernels.polyhedra import PARALLEL_COS, contact_frame, max_row, place, polyhedron_plane_overlap

CUBE = convex_hull(np.array(list(itertools.product([-0.5, 0.5], repeat=3))))


def mesh_contact(placed, verts, tris):
    """(V, centroid, S) per plane of the body's prisms contact with the mesh (verts [m], tris); the
    wall's point is its first vertex, as the case reader sets it. Returns a list, one per plane."""
    p = verts[0].copy()
    mesh = mesh_arrays([(verts - p, tris)])
    args = placed.args()
    ms = mesh_scratch(max_row(args[1]), len(args[1]) - 1)
    n = mesh_pieces(*args, mesh, 0, p[0], p[1], p[2], ms)
    res, lead = ms[5], ms[3]
    plane_sums(res, n, lead, args[9])
    mesh_contact.touched = ms[0][:n][lead[:n] >= 0].copy()  # the triangles whose prisms the body overlaps
    return [(res[m, R_V], res[m, R_GX:R_GX + 3].copy(), res[m, R_SX:R_SX + 3].copy()) for m in range(n)
            if lead[m] == m]


def faces_along_sides(placed, verts, tris, normal):
    """Whether a face of the body lies within the tie angle (|cos| > PARALLEL_COS) of a prism's side,
    the plane through a triangle edge along the mesh ``normal`` (their pieces count with the band
    weight of :mod:`demcli.kernels.polyhedra`, on each side of the edge differently); ``tris``: the
    triangles whose prisms it overlaps."""
    edges = verts[tris[:, [1, 2, 0]]] - verts[tris]
    sides = np.cross(edges.reshape(-1, 3), normal)
    sides /= np.linalg.norm(sides, axis=1)[:, None]
    return np.abs(placed.normals @ sides.T).max() > PARALLEL_COS


def frame(placed, vol, s, normal):
    """contact_frame of a wall contact (the wall's centre one unit behind the body along ``normal``)."""
    c = placed.center
    return np.array(contact_frame(vol, *s, *c, *(c - normal), placed.radius, placed.radius))


def random_quat(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


@pytest.mark.parametrize("seed", range(4))
def test_prisms_of_a_flat_mesh_give_the_half_space_contact(seed, grid_mesh):
    # Given a flat mesh of 18 jittered triangles in a tilted plane, and a random stone (or a unit cube,
    # also aligned with the mesh's axes: faces parallel to the prisms' sides) pressed into it at 12
    # random places and orientations, across triangle edges and vertices
    rng = np.random.default_rng(seed)
    verts, tris, n = grid_mesh(3, 0.4, rot=(0.3, -0.2, 0.1), shift=(-0.6, -0.5, 0.1), seed=seed)
    d = float(n @ verts[0])
    body = convex_hull(CUBE.vertices * 0.2) if seed == 0 else random_polyhedron(rng, 14, (0.3, rng.uniform(0.1, 0.3),
                                                                                            0.12))
    rad = np.linalg.norm(body.vertices - body.centroid, axis=1).max()
    touched = exact = 0
    for k in range(12):
        q = random_quat(rng) if k % 3 or seed else np.array([1.0, 0.0, 0.0, 0.0])
        x = verts.mean(axis=0) + rng.uniform(-0.3, 0.3, 3)
        x += (rng.uniform(0.02, 1.05) * rad - (n @ x - d)) * n  # the centroid above the mesh (its side)
        placed = place(body, x, q)
        got = mesh_contact(placed, verts, tris)
        vol, g, s = polyhedron_plane_overlap(placed, n, d)
        # Then one plane, whose V and centroid are the half-space's to round-off (measured over the 32
        # touching poses of the 4 seeds: 1.7e-14 relative, 1.2e-15 r), and so are S, the contact frame
        # (normal, area, depth) and the force, unless a face of the body lies within the tie angle of a
        # prism side (the band rounds S there on each side of the edge differently: 8.6e-5 at most)
        if vol == 0.0:
            assert got == []
            continue
        touched += 1
        assert len(got) == 1
        v1, g1, s1 = got[0]
        assert v1 == pytest.approx(vol, rel=1e-12)
        np.testing.assert_allclose(g1, g, rtol=0, atol=1e-12 * placed.radius)
        tol = 1e-3 if faces_along_sides(placed, verts, tris[mesh_contact.touched], n) else 1e-12
        exact += bool(np.abs(s1 - s).max() <= 1e-12 * np.linalg.norm(s))
        np.testing.assert_allclose(s1, s, rtol=0, atol=tol * np.linalg.norm(s))
        got_frame, plane_frame = frame(placed, v1, s1, n), frame(placed, vol, s, n)
        np.testing.assert_allclose(got_frame[:3], plane_frame[:3], rtol=0, atol=10 * tol)  # unit normal
        np.testing.assert_allclose(got_frame[3:], plane_frame[3:], rtol=10 * tol)  # area, depth
    assert touched >= 6 and exact >= touched // 2  # measured: 30 of 32 over the seeds, 5 of 7 at least


def fold(sign, half=1.0):
    """Two faces meeting at 90 degrees along the y axis: z = sign |x| (sign 1 a valley, -1 a ridge),
    each face two triangles; the solid lies below."""
    h = sign * half
    v = np.array([[-half, -half, h], [0, -half, 0], [0, half, 0], [-half, half, h], [half, -half, h], [half, half, h]])
    return v, np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]], np.int64)


def exact_volume(placed, planes):
    """Volume [m^3] of the body cut by the half-spaces n . x <= d of ``planes`` (rows (n, d)): the
    convex intersection built by scipy (a slow reference)."""
    a = np.vstack([placed.normals] + [nn[None] for nn, _ in planes])
    b = np.r_[placed.offsets, [dd for _, dd in planes]]
    # a point well inside: the Chebyshev centre (max r with a x + r |a| <= b)
    lp = linprog(np.r_[np.zeros(3), -1.0], A_ub=np.column_stack([a, np.linalg.norm(a, axis=1)]), b_ub=b,
                 bounds=[(None, None)] * 3 + [(0, None)])
    hs, inner = np.column_stack([a, -b]), lp.x[:3]
    return ConvexHull(HalfspaceIntersection(hs, inner).intersections).volume


@pytest.mark.parametrize("delta", [0.005, 0.02, 0.05])
def test_a_concave_fold_leaves_out_the_wedge_under_its_edge(delta):
    # Given a unit cube sitting in a 90 degree valley with two faces parallel to its sides, pressed
    # delta into both
    a = 1.0
    verts, tris = fold(1.0, half=2.0)
    n1, n2 = np.array([-1.0, 0, 1]) / math.sqrt(2), np.array([1.0, 0, 1]) / math.sqrt(2)
    h = math.sqrt(2) * (a / 2 - delta)
    q = np.r_[math.cos(math.pi / 8), 0, math.sin(math.pi / 8), 0]
    placed = place(CUBE, (0.0, 0.0, h), q)
    got = mesh_contact(placed, verts, tris)
    # Then one contact per face, each the slab under its face beside the edge, (a - delta) delta a,
    # while the union of the two half-spaces holds 2 a^2 delta - a delta^2: the square delta x delta
    # under the edge is missed, a relative error delta / (2 a - delta) (1.27 % at delta = a / 40)
    assert len(got) == 2
    for vol, _, _ in got:
        assert vol == pytest.approx((a - delta) * delta * a, rel=1e-10)
    union = sum(polyhedron_plane_overlap(placed, nn, 0.0)[0] for nn in (n1, n2)) - exact_volume(
        placed, [(n1, 0.0), (n2, 0.0)])
    assert union == pytest.approx(2 * a * a * delta - a * delta * delta, rel=1e-10)
    assert 1 - sum(v for v, _, _ in got) / union == pytest.approx(delta / (2 * a - delta), rel=1e-8)


def test_a_convex_fold_counts_the_wedge_under_its_edge_twice():
    # Given a unit cube pressed with a face flat onto a 90 degree ridge, 0.05 below its crest
    verts, tris = fold(-1.0, half=2.0)
    n1, n2 = np.array([1.0, 0, 1]) / math.sqrt(2), np.array([-1.0, 0, 1]) / math.sqrt(2)
    placed = place(CUBE, (0.0, 0.0, 0.45), np.array([1.0, 0, 0, 0]))
    got = mesh_contact(placed, verts, tris)
    exact = exact_volume(placed, [(n1, 0.0), (n2, 0.0)])
    # Then two contacts, each with the whole slice of the cube above its face's plane within its
    # prism: the wedge 0.05^2 x 1 under the crest counts twice (exact 0.0025, prisms 0.005)
    assert len(got) == 2
    assert exact == pytest.approx(0.05 ** 2, rel=1e-10)
    assert sum(v for v, _, _ in got) == pytest.approx(2 * exact, rel=1e-10)
