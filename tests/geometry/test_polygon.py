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


def assert_hull_of(pts, idx, ref):
    """idx (hull2d of pts) is, counter-clockwise, the hull of ref's points up to round-off twins:
    every ConvexHull vertex of ref lies within 1e-12 extent of one of idx and vice versa, the
    areas agree to 1e-12 and every turn is strictly convex."""
    ext = np.ptp(ref, axis=0).max()
    hv = ref[ConvexHull(ref).vertices]
    got = pts[idx]
    d = np.linalg.norm(got[:, None] - hv[None], axis=-1)
    assert d.min(axis=0).max() <= 1e-12 * ext, "a hull vertex is missing"
    assert d.min(axis=1).max() <= 1e-12 * ext, "a point that is no hull vertex was kept"
    x, y = got.T
    assert 0.5 * (x * np.roll(y, -1) - np.roll(x, -1) * y).sum() == pytest.approx(ConvexHull(ref).volume, rel=1e-12)
    e = np.roll(got, -1, axis=0) - got
    assert np.all(e[:, 0] * np.roll(e[:, 1], -1) - e[:, 1] * np.roll(e[:, 0], -1) > 0.0)


def test_hull_kernel_keeps_the_corner_between_round_off_twins():
    # Given a unit square whose top-left corner has a twin 1e-17 to its left: sorted by x, the
    # bottom-left corner falls between the twins, and the twins and that corner make a turn of
    # 1e-17, which the old tolerance test took for collinear (it popped the bottom-left corner)
    sq = np.array([[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]])
    for twin in ([-1e-17, 1.0], [-1e-13, 1.0 + 1e-13], [-1e-13, 1.0 + 1e-6]):
        pts = np.vstack([[twin], sq])
        # Then the hull is the square (or the twin instead of its corner)
        assert_hull_of(pts, _kernels.hull2d(pts), pts)


def test_turn_sign_is_exact():
    from fractions import Fraction

    # Given triples of floats on a line up to a few units in the last place (the floating-point
    # determinant is then mostly round-off) and exact twins
    rng = np.random.default_rng(3)
    t = rng.random((400, 3))
    p = np.stack([0.1 + 0.7 * t, 0.3 + 0.9 * t], axis=2)  # (400, 3 points, 2)
    p += np.spacing(p) * rng.integers(-2, 3, p.shape)
    p[::10, 2] = p[::10, 0]
    for tri in p:
        a, b, c = [[Fraction(v) for v in q] for q in tri]
        exact = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        # Then the sign of the turn is the exact one
        assert np.sign(_kernels._turn(np.ascontiguousarray(tri), 0, 1, 2)) == np.sign(exact)


def lattice_shadow(rng):
    """A random lattice clump of 1.8 mm balls seen along a lattice direction (many points of
    the shadow coincide up to round-off: the member centres on one line along the view)."""
    a = 0.12 / 66
    ijk = np.stack(np.meshgrid(*[np.arange(k) for k in rng.integers(2, 8, 3)], indexing="ij"), -1).reshape(-1, 3)
    ijk = ijk[rng.random(len(ijk)) < 0.7]
    x = (ijk + rng.integers(0, 60, 3) + 0.5) * a
    u = rng.integers(-3, 4, 3).astype(float)
    while not u.any():
        u = rng.integers(-3, 4, 3).astype(float)
    u /= np.linalg.norm(u)
    e = np.array(_kernels._basis(*u)).reshape(2, 3)
    return np.ascontiguousarray(x @ e.T)


def test_hull_kernel_matches_scipy_on_lattice_shadows():
    # Given 1500 shadows of lattice clumps along lattice directions (the tolerance test in the
    # chain lost a corner of 5 of them)
    rng = np.random.default_rng(0)
    for _ in range(1500):
        pts = lattice_shadow(rng)
        if len(pts) < 3 or np.linalg.matrix_rank(pts - pts[0], tol=1e-9 * np.ptp(pts)) < 2:
            continue
        # Then the hull is Qhull's up to the round-off twins
        assert_hull_of(pts, _kernels.hull2d(pts), pts)


def test_hull_kernel_on_coincident_nearly_coincident_and_collinear_points():
    rng = np.random.default_rng(6)
    # Given random points, each repeated exactly and as twins a few units in the last place
    # away, in random order
    base = rng.random((40, 2)) + [3.0, -2.0]
    twins = [base, base, base + np.spacing(base) * rng.integers(-3, 4, base.shape)]
    pts = np.ascontiguousarray(np.concatenate(twins)[rng.permutation(3 * len(base))])
    # Then the hull is that of the distinct points
    assert_hull_of(pts, _kernels.hull2d(pts), base)
    # Given points on a line up to round-off in y: the two ends
    t = rng.random(30)
    line = np.stack([0.3 + 0.7 * t, 0.1 + 0.2 * t], axis=1)
    line[:, 1] += np.spacing(line[:, 1]) * rng.integers(-2, 3, 30)
    idx = _kernels.hull2d(line)
    assert sorted(idx) == sorted([t.argmin(), t.argmax()])
    # and points on the edges of a triangle are dropped
    tri = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    e = rng.integers(0, 3, 10)
    on_edges = np.concatenate([tri, tri[e] * (1 - t[:10, None]) + tri[(e + 1) % 3] * t[:10, None]])
    assert sorted(_kernels.hull2d(on_edges)) == [0, 1, 2]
    # Given one point repeated: one point; round-off twins of one point and the origin: a segment,
    # and a triangle with a third point
    assert len(_kernels.hull2d(np.ones((5, 2)))) == 1
    one = 1.0 + np.spacing(1.0) * rng.integers(0, 3, (6, 2))
    assert len(_kernels.hull2d(np.vstack([one, [[0.0, 0.0]]]))) == 2
    assert len(_kernels.hull2d(np.vstack([one, [[0.0, 0.0], [0.0, 1.0]]]))) == 3


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
