"""2D helpers: hull, area moments, minimum bounding rectangle, rectangle-in-square rule."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from demcli.geometry import (
    GeometryError,
    convex_hull_2d,
    min_bounding_rectangle,
    polygon_area,
    polygon_centroid,
    polygon_second_moment,
    square_aperture,
)
from demcli.geometry import _kernels


def rot2(t):
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def rectangle(length, width, angle=0.0, centre=(0.0, 0.0)):
    p = np.array([[0, 0], [length, 0], [length, width], [0, width]], dtype=float)
    return (p - [length / 2, width / 2]) @ rot2(angle).T + centre


def test_rectangle_and_triangle_moments_both_orientations():
    # Given a b x h rectangle centred at (1, 2): area b h, J = diag(h b^3, b h^3)/12
    b, h = 0.3, 0.1
    rect = rectangle(b, h, centre=(1.0, 2.0))
    for poly in (rect, rect[::-1]):
        assert np.isclose(polygon_area(poly), b * h)
        assert np.allclose(polygon_centroid(poly), [1.0, 2.0])
        assert np.allclose(polygon_second_moment(poly), np.diag([h * b**3, b * h**3]) / 12.0)
    # Given a right triangle with legs b (x) and h (y): int x y dA about the centroid = -b^2 h^2 / 72
    tri = np.array([[0.0, 0.0], [b, 0.0], [0.0, h]])
    j = polygon_second_moment(tri)
    assert np.allclose(polygon_centroid(tri), [b / 3, h / 3])
    assert np.allclose(j, [[h * b**3 / 36, -b * b * h * h / 72], [-b * b * h * h / 72, b * h**3 / 36]])


def test_second_moment_rotates_as_a_tensor():
    rng = np.random.default_rng(1)
    poly = convex_hull_2d(rng.random((30, 2)))
    r = rot2(0.7)
    assert np.allclose(polygon_second_moment(poly @ r.T), r @ polygon_second_moment(poly) @ r.T)


def test_hull_kernel_matches_scipy():
    rng = np.random.default_rng(2)
    for n in (3, 5, 20, 200):
        pts = rng.random((n, 2))
        idx = _kernels.hull2d(pts)
        ref = ConvexHull(pts).vertices  # counter-clockwise
        start = int(np.flatnonzero(ref == idx[0])[0])
        assert np.array_equal(idx, np.roll(ref, -start))
    # duplicates and collinear points on the boundary are dropped
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [0.5, 0], [1, 0.5], [0, 0], [0.5, 0.5]], float)
    assert sorted(_kernels.hull2d(sq)) == [0, 1, 2, 3]
    hull = convex_hull_2d(sq)
    assert sorted(map(tuple, hull)) == sorted(map(tuple, sq[:4]))
    x, y = hull.T
    assert (x * np.roll(y, -1) - np.roll(x, -1) * y).sum() > 0.0  # counter-clockwise


@pytest.mark.parametrize("points", [np.zeros((4, 2)), np.outer(np.arange(5.0), [1.0, 2.0]),
                                    np.array([[0, 0], [1, np.nan], [2, 1]])])
def test_degenerate_polygons_raise(points):
    with pytest.raises(GeometryError):
        convex_hull_2d(points)
    with pytest.raises(GeometryError):
        polygon_area(points)


def test_rotated_rectangle_is_recovered():
    for angle in (0.0, 0.3, 1.2, 2.9):
        pts = rectangle(0.064, 0.004, angle, centre=(5.0, -3.0))
        length, width, ang = min_bounding_rectangle(pts)
        assert np.isclose(length, 0.064) and np.isclose(width, 0.004)
        assert np.isclose(np.cos(ang - angle) ** 2, 1.0)  # same line, either sense


def brute_rectangle(pts, n=20001):
    """Naive reference: the least-area axis box over a fine grid of rotations."""
    t = np.linspace(0.0, np.pi / 2, n)
    c, s = np.cos(t), np.sin(t)
    u = np.outer(c, pts[:, 0]) + np.outer(s, pts[:, 1])
    v = np.outer(-s, pts[:, 0]) + np.outer(c, pts[:, 1])
    area = np.ptp(u, axis=1) * np.ptp(v, axis=1)
    return area.min()


def test_rotating_calipers_match_brute_force():
    rng = np.random.default_rng(4)
    for _ in range(20):
        pts = rng.normal(size=(int(rng.integers(3, 60)), 2)) * rng.uniform(0.1, 2.0, 2)
        length, width, ang = min_bounding_rectangle(pts)
        assert length >= width
        # the rectangle does bound the points, along its own axes
        e = np.array([np.cos(ang), np.sin(ang)])
        assert np.ptp(pts @ e) <= length * (1 + 1e-12)
        assert np.ptp(pts @ [-e[1], e[0]]) <= width * (1 + 1e-12)
        ref = brute_rectangle(pts)
        assert length * width <= ref * (1 + 1e-12)
        assert length * width >= ref * (1 - 2e-4)  # grid step 7.9e-5 rad, kinked minimum


def brute_square(length, width, n=200001):
    """Naive reference: least square side over a fine grid of rotations of the rectangle."""
    t = np.linspace(0.0, np.pi / 2, n)
    side = np.maximum(length * np.cos(t) + width * np.sin(t), length * np.sin(t) + width * np.cos(t))
    return side.min()


def test_square_aperture_matches_rotation_search():
    rng = np.random.default_rng(5)
    pairs = [(0.062, 0.062), (0.064, 0.004), (0.1, 0.0), (1.0, 0.4142), (1.0, 0.4143)]
    pairs += [tuple(rng.uniform(0.0, 1.0, 2)) for _ in range(30)]
    for length, width in pairs:
        assert np.isclose(square_aperture(length, width), brute_square(length, width), rtol=1e-9)
    # the seed's plate fits a 63 mm hole only when turned onto the diagonal
    assert square_aperture(0.064, 0.004) < 0.063 < 0.064
