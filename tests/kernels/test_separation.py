"""Separating directions between convex vertex sets (demcli.kernels.separation) against slow
references: the closest point of a simplex by brute force over its faces, edges and vertices,
and the distance of two convex hulls from Qhull's hull of their Minkowski difference."""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from demcli.geometry import convex_hull, random_polyhedron
from demcli.kernels.polyhedra import place, polyhedron_overlap
from demcli.kernels.separation import _closest, gap, separating_direction


def min_norm_point(points):
    """The point of the convex hull of ``points`` (k <= 4, 3) nearest the origin, by brute force:
    the origin's projection onto the affine hull of every subset, kept where its barycentric
    weights are all >= 0, the nearest of those."""
    best = None
    for mask in range(1, 2 ** len(points)):
        sub = points[[i for i in range(len(points)) if mask >> i & 1]]
        e = (sub[1:] - sub[0]).T
        mu = np.linalg.lstsq(e, -sub[0], rcond=1e-12)[0] if len(sub) > 1 else np.zeros(0)
        x = sub[0] + e @ mu
        if np.all(mu >= -1e-12) and mu.sum() <= 1 + 1e-12 and (best is None or x @ x < best @ best):
            best = x
    return best


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
            assert n == 4 and np.linalg.norm(ref) < 1e-9
            inside += 1
            continue
        # Then the point is the reference point to 1e-9, and the kept rows are points of the
        # simplex whose hull holds it
        assert np.linalg.norm([x, y, z] - ref) < 1e-9 * max(1.0, np.linalg.norm(ref))
        kept_rows = buf[:kept]
        assert all(np.min(np.linalg.norm(w - r, axis=1)) == 0.0 for r in kept_rows)
        assert np.linalg.norm(min_norm_point(kept_rows) - [x, y, z]) < 1e-9 * max(1.0, np.linalg.norm(ref))
    if n == 4:
        assert inside > 0  # the enclosing case was exercised


def test_separated_pairs_get_a_direction_that_clears_them():
    # Given 60 random pairs of convex polyhedra (size ~1) pulled apart along a random direction u
    # until their gap along u is 1e-8 .. 0.3 (their hull distance is at least that; the engine's
    # margin is 1e-9 of the bodies' size)
    rng = np.random.default_rng(5)
    for _ in range(60):
        a, b0, u = random_pair(rng)
        target = 10.0 ** rng.uniform(-8, np.log10(0.3))
        vb = b0.vertices + first_shift(lambda t: gap(*u, a.vertices, b0.vertices + t * u) <= target) * u
        dist = hull_distance(a.vertices, vb)
        margin = 1e-9
        # When GJK searches from the centre line
        d = vb.mean(axis=0) - a.vertices.mean(axis=0)
        found, ux, uy, uz = separating_direction(a.vertices, vb, *d, margin, 32, np.empty((4, 3)))
        # Then it finds a unit direction whose gap, recomputed here, exceeds the margin and
        # does not exceed the hull distance
        assert found, (target, dist)
        assert abs(np.linalg.norm([ux, uy, uz]) - 1.0) < 1e-14
        g = np.min(vb @ [ux, uy, uz]) - np.max(a.vertices @ [ux, uy, uz])
        assert g > margin
        assert g <= dist * (1 + 1e-6) + 1e-12
        assert g == pytest.approx(gap(ux, uy, uz, a.vertices, vb), rel=1e-12, abs=1e-15)


def test_overlapping_touching_and_too_close_pairs_get_none():
    # Given random pairs (size ~1) that overlap, that touch (B moved along u to where the overlap
    # volume vanishes: hull distance within round-off of 0), or that stand 5e-4 beyond the touch
    # (hull distance at most 5e-4), searched with margins of 1e-9, 1e-9 and 1e-3
    rng = np.random.default_rng(6)
    for k in range(60):
        a, b0, u = random_pair(rng)
        margin = 1e-9
        if k % 3:
            touch = first_shift(lambda t: polyhedron_overlap(a, place(convex_hull(b0.vertices + t * u)))[0] > 0.0)
            if k % 3 == 1:
                vb = b0.vertices + touch * u
                assert hull_distance(a.vertices, vb) < 1e-7
            else:
                vb = b0.vertices + (touch + 5e-4) * u
                assert 0.0 < hull_distance(a.vertices, vb) <= 5e-4 * (1 + 1e-6)
                margin = 1e-3
        else:
            t = rng.uniform(0.0, 0.5)
            for _ in range(40):  # both bodies hold the origin, so a small enough shift overlaps
                if polyhedron_overlap(a, place(convex_hull(b0.vertices + t * u)))[0] > 0.0:
                    break
                t *= 0.5
            vb = b0.vertices + t * u
            assert polyhedron_overlap(a, place(convex_hull(vb)))[0] > 0.0
        # When GJK searches
        found, *_ = separating_direction(a.vertices, vb, *u, margin, 32, np.empty((4, 3)))
        # Then it reports none: no direction clears them by the margin (the pairs 5e-4 apart
        # have directions with gaps between -margin and margin, which a looser success test
        # would take)
        assert not found


def test_degenerate_input_gives_no_direction_and_no_crash():
    # Given a segment, a flat tetrahedron, repeated points, a NaN start direction and NaN vertices
    rng = np.random.default_rng(9)
    a = rng.normal(size=(5, 3))
    w = np.empty((4, 3))
    # When the simplex routine gets exact duplicates, collinear and coplanar points
    for pts in (np.array([a[0], a[0]]), np.array([a[0], a[1], 0.5 * (a[0] + a[1])]),
                np.array([a[0], a[1], a[2], a[0] + 0.3 * (a[1] - a[0]) + 0.2 * (a[2] - a[0])]),
                np.array([a[0], a[0], a[0], a[0]])):
        buf = np.zeros((4, 3))
        buf[:len(pts)] = pts
        x, y, z, kept = _closest(buf, len(pts))
        # Then it returns a point no nearer the origin than the hull's nearest point (or gives
        # up: kept = 0), never a NaN it keeps using
        if kept:
            assert np.linalg.norm([x, y, z]) >= np.linalg.norm(min_norm_point(pts)) - 1e-9
    # And a search from a NaN direction, or over a vertex set of NaNs, finds no direction
    assert not separating_direction(a, a + 10.0, np.nan, 1.0, 1.0, 1e-9, 32, w)[0]
    assert not separating_direction(np.full((4, 3), np.nan), a, 1.0, 0.0, 0.0, 1e-9, 32, w)[0]
    # (while a clean pair is found from the same start)
    assert separating_direction(a, a + 10.0, 1.0, 1.0, 1.0, 1e-9, 32, w)[0]
