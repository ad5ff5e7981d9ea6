"""Numba kernels of the geometry toolkit: 2D hull, rotating calipers, minimal shadow.

Stateless functions of arrays and scalars; the public wrappers in
``demcli.geometry`` validate their input and import this module lazily, so that
importing ``demcli.geometry`` compiles nothing. Lengths are in the caller's unit
(metres in demcli), areas in that unit squared, angles in radians.
"""

import math

import numpy as np

from demcli.jit import njit

SQRT2 = math.sqrt(2.0)


@njit
def hull2d(pts):
    """Convex hull of 2D points: Andrew's monotone chain (Andrew 1979) on exact turns,
    then the round-off vertices dropped.

    pts: (n, 2) float64. Returns the int64 indices of the hull vertices in
    counter-clockwise order, starting from the lexicographically smallest one kept.
    The chain decides each turn by the exact sign of the orientation determinant
    (:func:`_turn`), so it builds the exact hull of the given floats, coincident, nearly
    coincident and collinear points included. The tolerance comes after the chain, not
    in it: in the chain a near-zero turn also arises where the middle point is far from
    the other two (round-off twins that the lexicographic sort puts on either side of a
    third point), and popping it there loses a true vertex. From the exact hull every
    vertex within 1e-12 extent (pts' unit) of the segment joining its neighbours is
    dropped (:func:`_prune_hull`): round-off twins, such as the front and back corners of
    a box seen along an axis, and nearly collinear points. Every turn left is strictly
    convex, as the rotating calipers need. Fewer than 3 points that far apart give 1 or
    2 indices.
    """
    ext = max(pts[:, 0].max() - pts[:, 0].min(), pts[:, 1].max() - pts[:, 1].min())
    return _prune_hull(pts, _exact_chain(pts), 1e-12 * ext)


@njit
def _exact_chain(pts):
    """Indices of the exact hull vertices of pts (n, 2), counter-clockwise from the
    lexicographically smallest point; duplicate and collinear points are dropped."""
    n = pts.shape[0]
    # lexicographic (x, then y) order from two stable sorts
    o1 = np.argsort(pts[:, 1], kind="mergesort")
    o2 = np.argsort(pts[o1, 0], kind="mergesort")
    order = o1[o2]
    out = np.empty(2 * n + 1, dtype=np.int64)
    k = 0
    for t in range(n):  # lower chain
        i = order[t]
        while k >= 2 and _turn(pts, out[k - 2], out[k - 1], i) <= 0.0:
            k -= 1
        out[k] = i
        k += 1
    lower = k + 1
    for t in range(n - 2, -1, -1):  # upper chain
        i = order[t]
        while k >= lower and _turn(pts, out[k - 2], out[k - 1], i) <= 0.0:
            k -= 1
        out[k] = i
        k += 1
    if k > 1:
        k -= 1  # the last point repeats the first
    return out[:k].copy()


@njit
def _prune_hull(pts, hull, delta):
    """The vertices of a convex polygon that lie farther than delta from the segment
    joining their neighbours (removing one rechecks its neighbours).

    pts: (n, 2) float64; hull: indices of a convex polygon, counter-clockwise; delta: a
    length in pts' unit. Two vertices within delta of each other become one. Returns the
    kept indices, counter-clockwise from the lexicographically smallest.
    """
    h = hull.shape[0]
    prv = np.empty(h, np.int64)
    nxt = np.empty(h, np.int64)
    for j in range(h):
        prv[j] = (j - 1) % h
        nxt[j] = (j + 1) % h
    alive = np.ones(h, np.bool_)
    todo = np.empty(3 * h, np.int64)  # h to start, 2 for each removal
    todo[:h] = np.arange(h)
    m = h
    left = h
    while m > 0 and left > 1:
        m -= 1
        j = todo[m]
        if not alive[j]:
            continue
        a = hull[prv[j]]
        c = hull[nxt[j]]
        if left == 2:  # a segment: its ends are one point if within delta
            far = math.hypot(pts[hull[j], 0] - pts[c, 0], pts[hull[j], 1] - pts[c, 1]) > delta
        else:
            far = _segment_distance(pts, hull[j], a, c) > delta
        if not far:
            alive[j] = False
            left -= 1
            nxt[prv[j]] = nxt[j]
            prv[nxt[j]] = prv[j]
            todo[m] = prv[j]
            todo[m + 1] = nxt[j]
            m += 2
    kept = hull[alive]
    first = 0
    for j in range(1, kept.shape[0]):
        p = pts[kept[j]]
        q = pts[kept[first]]
        if p[0] < q[0] or (p[0] == q[0] and p[1] < q[1]):
            first = j
    return np.concatenate((kept[first:], kept[:first]))


@njit(inline="always")
def _segment_distance(pts, v, a, c):
    """Distance from row v of pts to the segment from row a to row c."""
    ex = pts[c, 0] - pts[a, 0]
    ey = pts[c, 1] - pts[a, 1]
    dx = pts[v, 0] - pts[a, 0]
    dy = pts[v, 1] - pts[a, 1]
    ee = ex * ex + ey * ey
    s = min(max((dx * ex + dy * ey) / ee, 0.0), 1.0) if ee > 0.0 else 0.0
    return math.hypot(dx - s * ex, dy - s * ey)


# Shewchuk's bound on the round-off of the orientation determinant in floating point
# (Shewchuk 1997, "Adaptive precision floating-point arithmetic and fast robust geometric
# predicates", Discrete Comput. Geom. 18, ccwerrboundA): (3 + 16 eps) eps, eps = 2^-53
_EPS = 2.0 ** -53
_TURN_BOUND = (3.0 + 16.0 * _EPS) * _EPS


@njit(inline="always")
def _turn(pts, a, b, c):
    """A number of the exact sign of (b - a) x (c - a) for rows a, b, c of pts: > 0 for a
    counter-clockwise turn, 0 when collinear.

    The determinant in floating point where its sign is certain (Shewchuk's filter), else
    the exact sign from :func:`_exact_turn`.
    """
    left = (pts[a, 0] - pts[c, 0]) * (pts[b, 1] - pts[c, 1])
    right = (pts[a, 1] - pts[c, 1]) * (pts[b, 0] - pts[c, 0])
    det = left - right
    if abs(det) > _TURN_BOUND * (abs(left) + abs(right)):
        return det
    return _exact_turn(pts[a, 0], pts[a, 1], pts[b, 0], pts[b, 1], pts[c, 0], pts[c, 1])


@njit
def _exact_turn(ax, ay, bx, by, cx, cy):
    """Exact sign (-1.0, 0.0 or 1.0) of ax by - ay bx + bx cy - by cx + cx ay - cy ax.

    Each product is split into two floats that sum to it exactly (Dekker's two-product)
    and the twelve are summed into a non-overlapping expansion (Shewchuk's
    grow-expansion), whose sign is that of its largest non-zero component.
    """
    terms = np.empty(12)
    terms[0], terms[1] = _two_product(ax, by)
    terms[2], terms[3] = _two_product(-ay, bx)
    terms[4], terms[5] = _two_product(bx, cy)
    terms[6], terms[7] = _two_product(-by, cx)
    terms[8], terms[9] = _two_product(cx, ay)
    terms[10], terms[11] = _two_product(-cy, ax)
    e = np.zeros(12)
    for m in range(12):
        q = terms[m]
        for i in range(m):
            q, e[i] = _two_sum(q, e[i])
        e[m] = q
    for i in range(11, -1, -1):
        if e[i] != 0.0:
            return 1.0 if e[i] > 0.0 else -1.0
    return 0.0


@njit(inline="always")
def _two_sum(a, b):
    """(s, err) with s = fl(a + b) and s + err = a + b exactly (Knuth)."""
    s = a + b
    bv = s - a
    return s, (a - (s - bv)) + (b - bv)


@njit(inline="always")
def _two_product(a, b):
    """(p, err) with p = fl(a b) and p + err = a b exactly (Dekker, Veltkamp's split)."""
    p = a * b
    ah, al = _split(a)
    bh, bl = _split(b)
    return p, al * bl - (((p - ah * bh) - al * bh) - ah * bl)


@njit(inline="always")
def _split(a):
    """a = hi + lo with hi, lo of 26 significant bits each (Veltkamp)."""
    c = 134217729.0 * a  # 2^27 + 1
    hi = c - (c - a)
    return hi, a - hi


@njit(inline="always")
def square_aperture(length, width):
    """Side (m) of the smallest square a length x width rectangle fits in, rotation allowed.

    A rectangle p x q (p >= q) turned by t inside a square needs the side
    max(p cos t + q sin t, p sin t + q cos t); over t in [0, pi/2] this is least at
    t = 0 (side p) or t = pi/4 (side (p + q)/sqrt 2), so the answer is
    min(p, (p + q)/sqrt 2). This is the square case of Carver's rectangle-in-
    rectangle condition (as stated by Wetzel 2000, Math. Mag. 73(3)).
    """
    return min(length, (length + width) / SQRT2)


@njit
def min_area_rectangle(hull):
    """Minimum-area bounding rectangle of a convex polygon by rotating calipers.

    hull: (h, 2) float64, strictly convex and counter-clockwise as :func:`hull2d`
    returns it, no repeated closing vertex. One side of
    the optimal rectangle lies on a hull edge (Freeman & Shapira 1975, CACM 18(7));
    the extreme vertices along the edge and its inward normal advance monotonically
    with the edge (Toussaint 1983, Proc. IEEE MELECON). Ties in area (relative
    1e-12) go to the rectangle with the smaller square aperture.
    Returns (length, width, angle): sides (m), length >= width, and the angle (rad,
    in [0, pi)) of the length side from the x axis. One or two points give a
    degenerate rectangle (width 0).
    """
    h = hull.shape[0]
    if h == 1:
        return 0.0, 0.0, 0.0
    if h == 2:
        dx = hull[1, 0] - hull[0, 0]
        dy = hull[1, 1] - hull[0, 1]
        return math.hypot(dx, dy), 0.0, math.atan2(dy, dx) % math.pi
    best_area = np.inf
    best_ap = np.inf
    best_l = 0.0
    best_w = 0.0
    best_ang = 0.0
    jn = 0  # farthest along the inward normal
    jr = 0  # farthest along the edge
    jl = 0  # farthest against the edge
    for i in range(h):
        i1 = (i + 1) % h
        ex = hull[i1, 0] - hull[i, 0]
        ey = hull[i1, 1] - hull[i, 1]
        le = math.hypot(ex, ey)
        ex /= le
        ey /= le
        nx = -ey
        ny = ex
        if i == 0:  # first edge: full scan
            for j in range(1, h):
                if _dot(hull, j, nx, ny) > _dot(hull, jn, nx, ny):
                    jn = j
                if _dot(hull, j, ex, ey) > _dot(hull, jr, ex, ey):
                    jr = j
                if _dot(hull, j, ex, ey) < _dot(hull, jl, ex, ey):
                    jl = j
        else:
            jn = _advance(hull, jn, nx, ny)
            jr = _advance(hull, jr, ex, ey)
            jl = _advance(hull, jl, -ex, -ey)
        a = _dot(hull, jr, ex, ey) - _dot(hull, jl, ex, ey)  # along the edge
        b = _dot(hull, jn, nx, ny) - _dot(hull, i, nx, ny)  # across the edge
        area = a * b
        ap = square_aperture(max(a, b), min(a, b))
        if area < best_area * (1.0 - 1e-12) or (area <= best_area * (1.0 + 1e-12) and ap < best_ap):
            best_area = area
            best_ap = ap
            if a >= b:
                best_l, best_w, best_ang = a, b, math.atan2(ey, ex)
            else:
                best_l, best_w, best_ang = b, a, math.atan2(ny, nx)
    return best_l, best_w, best_ang % math.pi


@njit(inline="always")
def _dot(pts, j, x, y):
    return pts[j, 0] * x + pts[j, 1] * y


@njit(inline="always")
def _advance(pts, j, x, y):
    """Walk counter-clockwise from vertex j while the support along (x, y) does not drop."""
    h = pts.shape[0]
    for _ in range(h):
        j1 = (j + 1) % h
        if _dot(pts, j1, x, y) >= _dot(pts, j, x, y):
            j = j1
        else:
            break
    return j


@njit(inline="always")
def _basis(ux, uy, uz):
    """Orthonormal e1, e2 normal to unit u with e1 x e2 = u (e1 from the axis least along u)."""
    ax = abs(ux)
    ay = abs(uy)
    az = abs(uz)
    if ax <= ay and ax <= az:
        e1x, e1y, e1z = 1.0 - ux * ux, -ux * uy, -ux * uz
    elif ay <= az:
        e1x, e1y, e1z = -uy * ux, 1.0 - uy * uy, -uy * uz
    else:
        e1x, e1y, e1z = -uz * ux, -uz * uy, 1.0 - uz * uz
    inv = 1.0 / math.sqrt(e1x * e1x + e1y * e1y + e1z * e1z)
    e1x *= inv
    e1y *= inv
    e1z *= inv
    return e1x, e1y, e1z, uy * e1z - uz * e1y, uz * e1x - ux * e1z, ux * e1y - uy * e1x


@njit
def project_rectangle(vertices, ux, uy, uz):
    """Minimum-area bounding rectangle of the shadow of points along unit direction u.

    vertices: (n, 3) float64 (m). The shadow lives in the plane normal to u with the
    basis (e1, e2), e1 x e2 = u. Returns (length, width) in m.
    """
    e1x, e1y, e1z, e2x, e2y, e2z = _basis(ux, uy, uz)
    n = vertices.shape[0]
    pts = np.empty((n, 2))
    for j in range(n):
        pts[j, 0] = vertices[j, 0] * e1x + vertices[j, 1] * e1y + vertices[j, 2] * e1z
        pts[j, 1] = vertices[j, 0] * e2x + vertices[j, 1] * e2y + vertices[j, 2] * e2z
    idx = hull2d(pts)
    length, width, _ = min_area_rectangle(pts[idx])
    return length, width


@njit
def pair_directions(circles):
    """Unit directions n_a x n_b for all pairs a < b of great-circle normals.

    circles: (g, 3) float64 unit normals, pairwise non-parallel up to sign. These are
    the vertices of the great-circle arrangement n . u = 0 on which the shadow area
    is piecewise linear. Returns (k, 3), k <= g (g - 1) / 2 (parallel pairs skipped).
    """
    g = circles.shape[0]
    out = np.empty((g * (g - 1) // 2, 3))
    k = 0
    for a in range(g):
        for b in range(a + 1, g):
            cx = circles[a, 1] * circles[b, 2] - circles[a, 2] * circles[b, 1]
            cy = circles[a, 2] * circles[b, 0] - circles[a, 0] * circles[b, 2]
            cz = circles[a, 0] * circles[b, 1] - circles[a, 1] * circles[b, 0]
            nrm = math.sqrt(cx * cx + cy * cy + cz * cz)
            if nrm > 1e-12:
                out[k, 0] = cx / nrm
                out[k, 1] = cy / nrm
                out[k, 2] = cz / nrm
                k += 1
    return out[:k]


@njit(inline="always")
def _area(circles, weights, ux, uy, uz):
    s = 0.0
    for c in range(circles.shape[0]):
        s += weights[c] * abs(circles[c, 0] * ux + circles[c, 1] * uy + circles[c, 2] * uz)
    return 0.5 * s


@njit
def shadow_areas(circles, weights, dirs):
    """Projected (shadow) area A(u) = 1/2 sum_c w_c |n_c . u| for each unit direction.

    circles: (g, 3) float64 unit face normals, one per plane direction; weights: (g,)
    the summed area (m^2) of the faces normal to each; dirs: (k, 3) unit. Returns (k,)
    areas in m^2 (Cauchy's projection formula: a closed convex surface covers every
    shadow point twice).
    """
    out = np.empty(dirs.shape[0])
    for k in range(dirs.shape[0]):
        out[k] = _area(circles, weights, dirs[k, 0], dirs[k, 1], dirs[k, 2])
    return out


@njit
def best_of_directions(circles, weights, dirs, vertices, rel_tol):
    """Minimal-shadow direction among given candidates, and the sieve rectangle there.

    circles, weights: as in :func:`shadow_areas`; dirs: (k, 3) unit candidates;
    vertices: (n, 3) (m); rel_tol: candidates whose area is within min * (1 + rel_tol)
    count as tied and the tie goes to the smallest square aperture of the shadow's
    minimum-area rectangle (a cube has three minimal directions, all equivalent).
    Returns (ux, uy, uz, area m^2, length m, width m, aperture m).
    """
    areas = shadow_areas(circles, weights, dirs)
    amin = areas.min()
    best = 0
    best_l = 0.0
    best_w = 0.0
    best_ap = np.inf
    for k in range(dirs.shape[0]):
        if areas[k] <= amin * (1.0 + rel_tol):
            length, width = project_rectangle(vertices, dirs[k, 0], dirs[k, 1], dirs[k, 2])
            ap = square_aperture(length, width)
            if ap < best_ap:
                best = k
                best_l = length
                best_w = width
                best_ap = ap
    return dirs[best, 0], dirs[best, 1], dirs[best, 2], areas[best], best_l, best_w, best_ap


@njit
def best_by_sweep(circles, weights, vertices, rel_tol):
    """Exact minimal shadow over all face-pair directions by sweeping each great circle.

    Same candidates and result as ``best_of_directions(..., pair_directions(circles),
    ...)`` in O(g^2 log g) instead of O(g^3): along circle a, u(phi) = cos phi e1 +
    sin phi e2 (phi in (0, pi], u and -u cast the same shadow) and
    A = alpha cos phi + beta sin phi between crossings with the other circles, where
    one sign |n_b . u| flips (the sweep of McKenna & Seidel 1985). Crossings are
    visited in angular order and alpha, beta updated in O(1) each; the area at a
    crossing does not depend on the sign of the vanishing term. Two passes: the
    least area on each circle, then the rectangles of the tied directions, sweeping
    again only the circles that hold one. Returns as best_of_directions.
    """
    g = circles.shape[0]
    circle_min = np.full(g, np.inf)
    amin = np.inf
    best_ap = np.inf
    best = np.zeros(7)
    key = np.empty(g)
    xs = np.empty(g)
    ys = np.empty(g)
    ps = np.empty(g)
    qs = np.empty(g)
    sg = np.empty(g)
    for stage in range(2):
        for a in range(g):
            if stage == 1 and circle_min[a] > amin * (1.0 + rel_tol):
                continue
            e1x, e1y, e1z, e2x, e2y, e2z = _basis(circles[a, 0], circles[a, 1], circles[a, 2])
            alpha = 0.0
            beta = 0.0
            for b in range(g):
                p = circles[b, 0] * e1x + circles[b, 1] * e1y + circles[b, 2] * e1z
                q = circles[b, 0] * e2x + circles[b, 1] * e2y + circles[b, 2] * e2z
                r = math.sqrt(p * p + q * q)
                if b == a or r <= 1e-12:
                    key[b] = np.inf  # no crossing: sorted last, never visited
                    continue
                # the crossing n_b . u = 0 at (x, y) = (-q, p)/r, taken with y > 0 or at (-1, 0)
                x = -q / r
                y = p / r
                if y < 0.0 or (y == 0.0 and x > 0.0):
                    x = -x
                    y = -y
                key[b] = -x  # phi ascending is x = cos phi descending
                xs[b] = x
                ys[b] = y
                ps[b] = p
                qs[b] = q
                # the sign of n_b . u just after phi = 0
                sg[b] = 1.0 if (p > 0.0 or (p == 0.0 and q > 0.0)) else -1.0
                alpha += 0.5 * weights[b] * sg[b] * p
                beta += 0.5 * weights[b] * sg[b] * q
            order = np.argsort(key)
            for t in range(g):
                b = order[t]
                if key[b] == np.inf:
                    break
                area = alpha * xs[b] + beta * ys[b]
                if stage == 0:
                    circle_min[a] = min(circle_min[a], area)
                elif area <= amin * (1.0 + rel_tol):
                    ux = xs[b] * e1x + ys[b] * e2x
                    uy = xs[b] * e1y + ys[b] * e2y
                    uz = xs[b] * e1z + ys[b] * e2z
                    length, width = project_rectangle(vertices, ux, uy, uz)
                    ap = square_aperture(length, width)
                    if ap < best_ap:
                        best_ap = ap
                        best[0] = ux
                        best[1] = uy
                        best[2] = uz
                        best[3] = area
                        best[4] = length
                        best[5] = width
                        best[6] = ap
                alpha -= weights[b] * sg[b] * ps[b]
                beta -= weights[b] * sg[b] * qs[b]
                sg[b] = -sg[b]
        amin = circle_min.min()
    return best[0], best[1], best[2], best[3], best[4], best[5], best[6]
