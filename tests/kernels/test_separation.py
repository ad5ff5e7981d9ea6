"""Separating directions between convex vertex sets (demcli.kernels.separation) against slow
references: the closest point of a simplex as a quadratic program over convex weights (scipy
SLSQP), and the distance of two convex hulls from Qhull's hull of their Minkowski difference."""

import numpy as np
import pytest
from scipy.optimize import minimize
from scipy.spatial import ConvexHull

from demcli.geometry import convex_hull, random_polyhedron
from demcli.kernels.polyhedra import place, polyhedron_overlap
from demcli.kernels.separation import _closest, gap, separating_direction


def min_norm_point(points):
    """The point of the convex hull of ``points`` (k, 3) nearest the origin (SLSQP on convex weights)."""
    k = len(points)
    res = minimize(lambda lam: float(np.sum((lam @ points) ** 2)), np.full(k, 1.0 / k),
                   jac=lambda lam: 2.0 * points @ (lam @ points), method="SLSQP", bounds=[(0.0, 1.0)] * k,
                   constraints=[{"type": "eq", "fun": lambda lam: lam.sum() - 1.0, "jac": lambda lam: np.ones(k)}],
                   options={"ftol": 1e-15, "maxiter": 500})
    return res.x @ points


def _segment_point(p, q):
    e = q - p
    t = np.clip(-(p @ e) / (e @ e), 0.0, 1.0) if e @ e > 0 else 0.0
    return p + t * e


def _triangle_point(a, b, c):
    """Point of the triangle nearest the origin: the plane's foot if it lies inside (barycentric
    coordinates from a 2x2 solve), else the nearest of the three edges'."""
    n = np.cross(b - a, c - a)
    if n @ n > 1e-24:
        x = (a @ n) / (n @ n) * n
        m = np.array([[(b - a) @ (b - a), (b - a) @ (c - a)], [(b - a) @ (c - a), (c - a) @ (c - a)]])
        s, t = np.linalg.solve(m, [(x - a) @ (b - a), (x - a) @ (c - a)])
        if s >= 0 and t >= 0 and s + t <= 1:
            return x
    return min((_segment_point(a, b), _segment_point(b, c), _segment_point(c, a)), key=lambda y: y @ y)


def hull_distance(va, vb):
    """Distance between the convex hulls of va and vb: of the origin from the hull of B - A
    (Qhull), 0 if inside, else the nearest of its triangular facets."""
    d = (vb[None, :, :] - va[:, None, :]).reshape(-1, 3)
    hull = ConvexHull(d)
    if np.all(hull.equations[:, 3] <= 0.0):
        return 0.0
    return min(float(np.linalg.norm(_triangle_point(*d[s]))) for s in hull.simplices)


def random_body(rng):
    q = rng.normal(size=4)
    p = random_polyhedron(rng, int(rng.integers(8, 25)), (1.0, rng.uniform(0.3, 1), rng.uniform(0.2, 1)))
    return place(p, np.zeros(3), q / np.linalg.norm(q))


def random_pair(rng):
    """Two random bodies about the origin (size ~1) and a random unit direction u."""
    a, b = random_body(rng), random_body(rng)
    u = rng.normal(size=3)
    return a, b, u / np.linalg.norm(u)


def first_shift(keep_going):
    """The smallest t in [0, 6] (bisection to round-off) with keep_going(t) False, keep_going(0) True."""
    lo, hi = 0.0, 6.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if keep_going(mid) else (lo, mid)
    return hi


@pytest.mark.parametrize("n", [1, 2, 3, 4])
def test_closest_point_of_a_simplex_matches_the_quadratic_program(n):
    # Given 200 random simplices of n points (near the origin, some degenerate-ish: one point
    # repeated with a 1e-9 offset)
    rng = np.random.default_rng(70 + n)
    inside = 0
    for k in range(200):
        w = rng.normal(size=(n, 3)) + rng.normal(size=3) * rng.choice([0.0, 1.0, 3.0])
        if k % 20 == 0 and n > 1:
            w[-1] = w[0] + 1e-9 * rng.normal(size=3)
        ref = min_norm_point(w)
        buf = np.zeros((4, 3))
        buf[:n] = w
        x, y, z, kept = _closest(buf, n)
        if kept == 0:
            # Then "origin inside" only for a tetrahedron that holds it (reference distance ~0)
            assert n == 4 and np.linalg.norm(ref) < 1e-6
            inside += 1
            continue
        # Then the point is the reference min-norm point to 1e-6 (SLSQP's accuracy), it is at
        # least as near the origin, and the kept rows are points of the simplex whose hull holds it
        assert np.linalg.norm([x, y, z] - ref) < 1e-6 * max(1.0, np.linalg.norm(ref))
        assert np.linalg.norm([x, y, z]) <= np.linalg.norm(ref) + 1e-9
        kept_rows = buf[:kept]
        assert all(np.min(np.linalg.norm(w - r, axis=1)) == 0.0 for r in kept_rows)
        assert np.linalg.norm(min_norm_point(kept_rows) - [x, y, z]) < 1e-6 * max(1.0, np.linalg.norm(ref))
    if n == 4:
        assert inside > 0  # the enclosing case was exercised


def test_separated_pairs_get_a_direction_that_clears_them():
    # Given 60 random pairs of convex polyhedra (size ~1) pulled apart along a random direction u
    # until their gap along u is 1e-6 .. 0.3 (their hull distance is at least that)
    rng = np.random.default_rng(5)
    for _ in range(60):
        a, b0, u = random_pair(rng)
        target = 10.0 ** rng.uniform(-6, np.log10(0.3))
        vb = b0.vertices + first_shift(lambda t: gap(*u, a.vertices, b0.vertices + t * u) <= target) * u
        dist = hull_distance(a.vertices, vb)
        margin = 1e-9
        # When GJK searches from the centre line
        d = vb.mean(axis=0) - a.vertices.mean(axis=0)
        found, ux, uy, uz = separating_direction(a.vertices, vb, *d, margin, 32)
        # Then it finds a unit direction whose gap, recomputed here, exceeds the margin and
        # does not exceed the hull distance
        assert found, (target, dist)
        assert abs(np.linalg.norm([ux, uy, uz]) - 1.0) < 1e-14
        g = np.min(vb @ [ux, uy, uz]) - np.max(a.vertices @ [ux, uy, uz])
        assert g > margin
        assert g <= dist * (1 + 1e-6) + 1e-12
        assert g == pytest.approx(gap(ux, uy, uz, a.vertices, vb), rel=1e-12, abs=1e-15)


def test_touching_and_overlapping_pairs_get_none():
    # Given random pairs with a positive overlap volume, and pairs that touch (B moved along u
    # to where the overlap volume vanishes: hull distance within round-off of 0)
    rng = np.random.default_rng(6)
    for k in range(60):
        a, b0, u = random_pair(rng)
        if k % 2:  # to the first touch along u
            vb = b0.vertices + first_shift(lambda t: polyhedron_overlap(a, place(convex_hull(b0.vertices + t * u)))[0]
                                           > 0.0) * u
            assert hull_distance(a.vertices, vb) < 1e-7
        else:
            t = rng.uniform(0.0, 0.5)
            for _ in range(40):  # both bodies hold the origin, so a small enough shift overlaps
                if polyhedron_overlap(a, place(convex_hull(b0.vertices + t * u)))[0] > 0.0:
                    break
                t *= 0.5
            vb = b0.vertices + t * u
            assert polyhedron_overlap(a, place(convex_hull(vb)))[0] > 0.0
        # When GJK searches with a margin of 1e-9
        found, *_ = separating_direction(a.vertices, vb, *u, 1e-9, 32)
        # Then it finds nothing (no direction can clear them)
        assert not found
