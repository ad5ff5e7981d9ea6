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
    """Convex hull of 2D points, Andrew's monotone chain (Andrew 1979).

    pts: (n, 2) float64. Returns the int64 indices of the hull vertices in
    counter-clockwise order, starting from the lexicographically smallest point.
    Duplicate and collinear points are dropped, and so are points within about
    1e-12 of the extent from the hull of the others (round-off twins, such as the
    front and back corners of a box seen along an axis): every hull turn is then
    strictly convex, as the rotating calipers need. Fewer than 3 distinct points
    give the points found (length 1 or 2).
    """
    n = pts.shape[0]
    ext = max(pts[:, 0].max() - pts[:, 0].min(), pts[:, 1].max() - pts[:, 1].min())
    tol = 1e-12 * ext * ext
    # lexicographic (x, then y) order from two stable sorts
    o1 = np.argsort(pts[:, 1], kind="mergesort")
    o2 = np.argsort(pts[o1, 0], kind="mergesort")
    order = o1[o2]
    out = np.empty(2 * n + 1, dtype=np.int64)
    k = 0
    for t in range(n):  # lower chain
        i = order[t]
        while k >= 2 and _cross(pts, out[k - 2], out[k - 1], i) <= tol:
            k -= 1
        out[k] = i
        k += 1
    lower = k + 1
    for t in range(n - 2, -1, -1):  # upper chain
        i = order[t]
        while k >= lower and _cross(pts, out[k - 2], out[k - 1], i) <= tol:
            k -= 1
        out[k] = i
        k += 1
    if k > 1:
        k -= 1  # the last point repeats the first
    return out[:k].copy()


@njit(inline="always")
def _cross(pts, a, b, c):
    """z of (b - a) x (c - a) for rows a, b, c of pts."""
    return ((pts[b, 0] - pts[a, 0]) * (pts[c, 1] - pts[a, 1])
            - (pts[b, 1] - pts[a, 1]) * (pts[c, 0] - pts[a, 0]))


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


@njit
def project_rectangle(vertices, ux, uy, uz):
    """Minimum-area bounding rectangle of the shadow of points along unit direction u.

    vertices: (n, 3) float64 (m). The shadow lives in the plane normal to u with the
    basis (e1, e2), e1 x e2 = u. Returns (length, width) in m.
    """
    # e1: the coordinate axis least aligned with u, made normal to u
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
    e2x = uy * e1z - uz * e1y
    e2y = uz * e1x - ux * e1z
    e2z = ux * e1y - uy * e1x
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


@njit
def shadow_areas(area_normals, dirs):
    """Projected (shadow) area A(u) = 1/2 sum_f |a_f n_f . u| for each unit direction.

    area_normals: (f, 3) float64, face normal times face area (m^2); dirs: (k, 3)
    unit. Returns (k,) areas in m^2 (Cauchy's projection formula for a closed convex
    surface: every shadow point is covered twice).
    """
    nf = area_normals.shape[0]
    nk = dirs.shape[0]
    out = np.empty(nk)
    for k in range(nk):
        ux = dirs[k, 0]
        uy = dirs[k, 1]
        uz = dirs[k, 2]
        s = 0.0
        for f in range(nf):
            s += abs(area_normals[f, 0] * ux + area_normals[f, 1] * uy + area_normals[f, 2] * uz)
        out[k] = 0.5 * s
    return out


@njit
def best_projection(area_normals, dirs, vertices, rel_tol):
    """Minimal-shadow direction among candidates, and the sieve rectangle there.

    area_normals: (f, 3) (m^2); dirs: (k, 3) unit candidates; vertices: (n, 3) (m);
    rel_tol: candidates whose area is within min * (1 + rel_tol) count as tied and
    the tie goes to the smallest square aperture of the shadow's minimum-area
    rectangle (a cube has three minimal directions, all equivalent).
    Returns (index of the chosen candidate, area m^2, length m, width m, aperture m).
    """
    areas = shadow_areas(area_normals, dirs)
    amin = areas.min()
    best = -1
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
    return best, areas[best], best_l, best_w, best_ap
