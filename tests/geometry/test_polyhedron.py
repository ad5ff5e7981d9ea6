"""Convex hull construction, exact mass properties and shape indices (Given/When/Then)."""

import itertools

import numpy as np
import pytest
from scipy.spatial import Delaunay

from demcli.geometry import (
    GeometryError,
    convex_hull,
    mass_properties,
    random_polyhedron,
    shape_indices,
)


def box(a, b, c):
    return np.array(list(itertools.product((0.0, a), (0.0, b), (0.0, c))))


def regular_tetrahedron(edge):
    return edge * np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]]) / np.sqrt(8.0)


def check_faces(poly, tol=1e-12):
    """Every face: planar, outward, counter-clockwise from outside, all vertices inside."""
    scale = np.ptp(poly.vertices, axis=0).max()
    for k, f in enumerate(poly.faces):
        n, d = poly.normals[k], poly.offsets[k]
        p = poly.vertices[f]
        assert np.allclose(p @ n, d, atol=tol * scale)
        assert np.all(poly.vertices @ n <= d + tol * scale)
        assert np.isclose(np.linalg.norm(n), 1.0)
        newell = 0.5 * np.cross(p, np.roll(p, -1, axis=0)).sum(axis=0)
        assert newell @ n > 0.0  # counter-clockwise seen from outside
        assert np.isclose(np.linalg.norm(newell), poly.areas[k])
    assert len(poly.vertices) - len(poly.edges) + poly.n_faces == 2  # Euler


def test_cube_with_extra_points_merges_into_six_quads():
    # Given a cube plus face centres, edge midpoints and interior points
    cube = box(1.0, 1.0, 1.0)
    extra = [[0.5, 0.5, 0.0], [0.5, 0.5, 1.0], [0.5, 0.0, 0.5], [0.0, 0.5, 0.0], [0.5, 0.5, 0.5]]
    # When its hull is built
    poly = convex_hull(np.vstack([cube, extra]))
    # Then it has the 8 corners, 6 square faces and 12 edges
    assert len(poly.vertices) == 8 and poly.n_faces == 6 and len(poly.edges) == 12
    assert all(len(f) == 4 for f in poly.faces)
    assert np.allclose(np.sort(poly.areas), 1.0)
    assert len(poly.circles) == 3  # opposite faces share a great circle
    check_faces(poly)


def test_random_polyhedra_faces_are_consistent():
    rng = np.random.default_rng(3)
    for _ in range(10):
        poly = random_polyhedron(rng, int(rng.integers(5, 40)), rng.uniform(0.01, 0.05, 3))
        check_faces(poly)
        assert np.isclose(poly.areas.sum(), _scipy_area(poly.vertices))


def _scipy_area(points):
    from scipy.spatial import ConvexHull

    return ConvexHull(points).area


@pytest.mark.parametrize("points, message", [
    (np.zeros((3, 3)), "at least 4 distinct"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]] * 3, dtype=float), "at least 4 distinct"),
    (np.ones((20, 3)), "at least 4 distinct"),
    (np.c_[np.random.default_rng(0).random((10, 2)), np.zeros(10)], "coplanar"),
    (np.outer(np.arange(6.0), [1.0, 2.0, 3.0]), "coplanar or collinear"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.nan]]), "NaN"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, np.inf]]), "NaN or inf"),
    (np.zeros((5, 2)), "shape"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1e-14]]), "coplanar"),
])
def test_degenerate_input_raises_geometry_error(points, message):
    with pytest.raises(GeometryError, match=message) as info:
        convex_hull(points)
    assert isinstance(info.value, ValueError)
    assert "QH" not in str(info.value)  # no Qhull jargon


def test_cube_mass_properties():
    a = 0.04
    poly = convex_hull(box(a, a, a) + 7.0)  # far from the origin
    assert np.isclose(poly.volume, a**3, rtol=1e-12)
    assert np.allclose(poly.centroid, 7.0 + a / 2, rtol=1e-12)
    assert np.allclose(poly.inertia, np.eye(3) * a**5 / 6.0, rtol=1e-9, atol=1e-9 * a**5)


def test_cuboid_mass_properties_and_principal_frame():
    a, b, c = 0.064, 0.004, 0.1
    poly = convex_hull(box(a, b, c))
    m = a * b * c
    expected = m / 12.0 * np.array([b * b + c * c, a * a + c * c, a * a + b * b])
    assert np.isclose(poly.volume, m)
    assert np.allclose(np.diag(poly.inertia), expected, rtol=1e-12)
    assert np.allclose(poly.principal_moments, np.sort(expected), rtol=1e-12)
    axes = poly.principal_axes
    assert np.isclose(np.linalg.det(axes), 1.0)  # right-handed
    assert np.isclose(abs(axes[2, 0]), 1.0)  # least inertia along the 100 mm side
    assert np.allclose(axes.T @ poly.inertia @ axes, np.diag(poly.principal_moments), atol=1e-20)


def test_regular_tetrahedron_mass_properties():
    # Given a regular tetrahedron of edge a: V = a^3/(6 sqrt 2), I = m a^2/20 (isotropic)
    a = 0.05
    poly = convex_hull(regular_tetrahedron(a) + [1.0, -2.0, 0.5])
    vol = a**3 / (6.0 * np.sqrt(2.0))
    assert np.isclose(poly.volume, vol, rtol=1e-12)
    assert np.allclose(poly.centroid, [1.0, -2.0, 0.5], atol=1e-14)
    assert np.allclose(poly.inertia, np.eye(3) * vol * a * a / 20.0, rtol=1e-9, atol=1e-12 * vol * a * a)


def _delaunay_reference(points):
    """Naive reference: mass properties summed over a Delaunay tetrahedralisation."""
    tet = points[Delaunay(points).simplices]
    p0 = tet[:, 0]
    a, b, c = tet[:, 1] - p0, tet[:, 2] - p0, tet[:, 3] - p0
    vol = np.abs(np.einsum("ij,ij->i", np.cross(a, b), c)) / 6.0
    cen = tet.mean(axis=1)
    centroid = (vol[:, None] * cen).sum(axis=0) / vol.sum()
    cov = np.zeros((3, 3))
    for v, t in zip(vol, tet - centroid):
        s = t.sum(axis=0)
        cov += v / 20.0 * (t.T @ t + np.outer(s, s))
    return vol.sum(), centroid, np.trace(cov) * np.eye(3) - cov


def test_random_polyhedra_match_delaunay_reference():
    rng = np.random.default_rng(11)
    for _ in range(5):
        poly = random_polyhedron(rng, 30, rng.uniform(0.01, 0.05, 3))
        vol, cen, inertia = _delaunay_reference(poly.vertices)
        assert np.isclose(poly.volume, vol, rtol=1e-10)
        assert np.allclose(poly.centroid, cen, rtol=0, atol=1e-12)
        assert np.allclose(poly.inertia, inertia, rtol=1e-9, atol=1e-9 * np.abs(inertia).max())


def test_mass_properties_of_listed_faces():
    # Given a triangular prism as 2 triangles and 3 quads (counter-clockwise from outside)
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 2], [1, 0, 2], [0, 1, 2]], float)
    faces = [[0, 2, 1], [3, 4, 5], [0, 1, 4, 3], [1, 2, 5, 4], [2, 0, 3, 5]]
    volume, centroid, inertia = mass_properties(v, faces)
    assert np.isclose(volume, 1.0)
    assert np.allclose(centroid, [1 / 3, 1 / 3, 1.0])
    poly = convex_hull(v)
    assert np.isclose(poly.volume, volume) and np.allclose(poly.inertia, inertia)


def test_random_polyhedron_matches_monte_carlo():
    # Given a skewed random polyhedron and 400 000 uniform points in its bounding box
    rng = np.random.default_rng(5)
    poly = random_polyhedron(rng, 25, [0.05, 0.03, 0.015])
    lo, hi = poly.vertices.min(axis=0), poly.vertices.max(axis=0)
    x = lo + (hi - lo) * rng.random((400_000, 3))
    inside = x[np.all(x @ poly.normals.T <= poly.offsets, axis=1)]
    box_vol = np.prod(hi - lo)
    # Then volume agrees to 1 % (the MC standard error is ~0.2 %), the centroid to
    # 0.5 % of the extent and the inertia to 2 % of its largest entry
    vol = box_vol * len(inside) / len(x)
    assert np.isclose(poly.volume, vol, rtol=0.01)
    assert np.allclose(poly.centroid, inside.mean(axis=0), atol=0.005 * np.ptp(poly.vertices, axis=0).max())
    d = inside - inside.mean(axis=0)
    cov = vol * (d.T @ d) / len(d)
    inertia = np.trace(cov) * np.eye(3) - cov
    assert np.allclose(poly.inertia, inertia, atol=0.02 * np.abs(inertia).max())


def test_shape_indices_of_plate_and_cube():
    # Given the seed's 64 x 4 x 100 mm plate and a 40 mm cube
    plate = shape_indices(box(0.064, 0.004, 0.1))
    cube = shape_indices(box(0.04, 0.04, 0.04))
    # Then the principal dimensions, Zingg ratios and BS 812 flags follow
    assert np.allclose([plate.length, plate.intermediate, plate.short], [0.1, 0.064, 0.004])
    assert np.isclose(plate.elongation, 0.64) and np.isclose(plate.flatness, 0.0625)
    assert np.isclose(plate.reference_size, 0.068 / np.sqrt(2.0))
    assert plate.flaky and plate.elongated
    assert not cube.flaky and not cube.elongated and np.isclose(cube.flatness, 1.0)
    # and an explicit fraction mean size overrides the particle's own sieve size
    assert not shape_indices(box(0.064, 0.004, 0.1), reference_size=0.006).flaky
    assert not shape_indices(box(0.064, 0.004, 0.1), reference_size=0.06).elongated
