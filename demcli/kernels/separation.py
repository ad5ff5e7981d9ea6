"""Separating directions between two convex vertex sets (GJK distance iteration), numba kernels.

Used by the polyhedron pair pass (:mod:`demcli.kernels.shapes.polyhedra`) to remember why a listed
pair does not touch: a unit direction u with

    gap(u) = min_b u . b - max_a u . a > margin,

so that B lies beyond A along u by more than ``margin`` [m] and the exact overlap of the two
bodies is empty. Checking a remembered u costs one pass over both vertex sets; the exact
overlap (:func:`demcli.kernels.polyhedra.overlap_ws`) of such a pair costs ~2 us
(bench/README.md, "Polyhedron narrow phase"). Face normals separate most such pairs (the
``sep`` face cache); this covers the rest, pairs separated only across two edges.

Search (:func:`separating_direction`): the GJK distance iteration (Gilbert, Johnson & Keerthi
1988, "A fast procedure for computing the distance between complex objects in three-dimensional
space", IEEE J. Robot. Autom. 4(2)) on the Minkowski difference D = B - A = {b - a}. A simplex W
of up to four support points of D is reduced each iteration to the face, edge or vertex that
holds its point v closest to the origin (closest point of a triangle to a point: Ericson 2005,
"Real-Time Collision Detection", sec. 5.1.5; of a tetrahedron: sec. 5.1.6); the next support
point s minimises v . x over D (s = argmin_b v . b - argmax_a v . a). It stops with

* success when gap(v / |v|) > margin: u . s = min over D of u . x, the test the cache repeats;
* failure when v no longer moves toward the origin (|v|^2 - v . s <= 1e-12 |v|^2: v is the
  closest point of D, so the distance is at most margin (1 + 1e-12) up to round-off), when the
  origin lies in the simplex or on its boundary (the sets touch or overlap), when v is not
  finite (degenerate simplices) or after ``max_iter`` iterations.

A failure only means that no direction was found; callers then use the exact overlap, so the
search cannot change a result, only skip work that would find V = 0.
"""

import math

from demcli.jit import njit


@njit(inline="always")
def gap(ux, uy, uz, va, vb):
    """min_b u . b - max_a u . a [m] for vertex arrays va, vb (n, 3) and a unit direction u:
    positive when B lies beyond A along u."""
    amax = -math.inf
    for k in range(va.shape[0]):
        t = ux * va[k, 0] + uy * va[k, 1] + uz * va[k, 2]
        if t > amax:
            amax = t
    bmin = math.inf
    for k in range(vb.shape[0]):
        t = ux * vb[k, 0] + uy * vb[k, 1] + uz * vb[k, 2]
        if t < bmin:
            bmin = t
    return bmin - amax


@njit(inline="always")
def _keep(w, n, i0, i1, i2):
    """Reduce the simplex rows w[0:n] to the rows i0, i1, i2 (-1: unused); returns the count."""
    k = 0
    for i in (i0, i1, i2):
        if i >= 0:
            if i != k:
                w[k, 0] = w[i, 0]
                w[k, 1] = w[i, 1]
                w[k, 2] = w[i, 2]
            k += 1
    return k


@njit(inline="always")
def _triangle(w, ia, ib, ic):
    """Closest point of the triangle (w[ia], w[ib], w[ic]) to the origin (Ericson 5.1.5).

    Returns (x, y, z, i0, i1, i2): the point and the rows of the vertex, edge or face that
    holds it (-1 for unused)."""
    ax, ay, az = w[ia, 0], w[ia, 1], w[ia, 2]
    abx, aby, abz = w[ib, 0] - ax, w[ib, 1] - ay, w[ib, 2] - az
    acx, acy, acz = w[ic, 0] - ax, w[ic, 1] - ay, w[ic, 2] - az
    d1 = -(abx * ax + aby * ay + abz * az)
    d2 = -(acx * ax + acy * ay + acz * az)
    if d1 <= 0.0 and d2 <= 0.0:
        return ax, ay, az, ia, -1, -1
    bx, by, bz = w[ib, 0], w[ib, 1], w[ib, 2]
    d3 = -(abx * bx + aby * by + abz * bz)
    d4 = -(acx * bx + acy * by + acz * bz)
    if d3 >= 0.0 and d4 <= d3:
        return bx, by, bz, ib, -1, -1
    vc = d1 * d4 - d3 * d2
    if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:
        t = d1 / (d1 - d3)
        return ax + t * abx, ay + t * aby, az + t * abz, ia, ib, -1
    cx, cy, cz = w[ic, 0], w[ic, 1], w[ic, 2]
    d5 = -(abx * cx + aby * cy + abz * cz)
    d6 = -(acx * cx + acy * cy + acz * cz)
    if d6 >= 0.0 and d5 <= d6:
        return cx, cy, cz, ic, -1, -1
    vb = d5 * d2 - d1 * d6
    if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:
        t = d2 / (d2 - d6)
        return ax + t * acx, ay + t * acy, az + t * acz, ia, ic, -1
    va = d3 * d6 - d5 * d4
    if va <= 0.0 and d4 - d3 >= 0.0 and d5 - d6 >= 0.0:
        t = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        return bx + t * (cx - bx), by + t * (cy - by), bz + t * (cz - bz), ib, ic, -1
    s = 1.0 / (va + vb + vc)
    v = vb * s
    t = vc * s
    return ax + v * abx + t * acx, ay + v * aby + t * acy, az + v * abz + t * acz, ia, ib, ic


@njit(inline="always")
def _outside(w, ia, ib, ic, idd):
    """Whether the origin and w[idd] lie strictly on opposite sides of the plane through
    w[ia], w[ib], w[ic]."""
    ax, ay, az = w[ia, 0], w[ia, 1], w[ia, 2]
    e1x, e1y, e1z = w[ib, 0] - ax, w[ib, 1] - ay, w[ib, 2] - az
    e2x, e2y, e2z = w[ic, 0] - ax, w[ic, 1] - ay, w[ic, 2] - az
    nx = e1y * e2z - e1z * e2y
    ny = e1z * e2x - e1x * e2z
    nz = e1x * e2y - e1y * e2x
    so = -(nx * ax + ny * ay + nz * az)
    sd = nx * (w[idd, 0] - ax) + ny * (w[idd, 1] - ay) + nz * (w[idd, 2] - az)
    return so * sd < 0.0


@njit(inline="always")
def _closest(w, n):
    """Closest point of the simplex w[0:n] (n = 1..4) to the origin; w is reduced in place to
    the sub-simplex that holds it. Returns (x, y, z, n_kept); n_kept = 0 when the origin lies
    inside the tetrahedron or on its boundary, or the tetrahedron is flat."""
    if n == 1:
        return w[0, 0], w[0, 1], w[0, 2], 1
    if n == 2:
        ax, ay, az = w[0, 0], w[0, 1], w[0, 2]
        ex, ey, ez = w[1, 0] - ax, w[1, 1] - ay, w[1, 2] - az
        ee = ex * ex + ey * ey + ez * ez
        t = -(ax * ex + ay * ey + az * ez) / ee if ee > 0.0 else 0.0
        if t <= 0.0:
            return ax, ay, az, _keep(w, 2, 0, -1, -1)
        if t >= 1.0:
            return w[1, 0], w[1, 1], w[1, 2], _keep(w, 2, 1, -1, -1)
        return ax + t * ex, ay + t * ey, az + t * ez, 2
    if n == 3:
        x, y, z, i0, i1, i2 = _triangle(w, 0, 1, 2)
        return x, y, z, _keep(w, 3, i0, i1, i2)
    best = math.inf
    bx = by = bz = 0.0
    b0 = b1 = b2 = -1
    for ia, ib, ic, idd in ((0, 1, 2, 3), (0, 1, 3, 2), (0, 2, 3, 1), (1, 2, 3, 0)):
        if _outside(w, ia, ib, ic, idd):
            x, y, z, i0, i1, i2 = _triangle(w, ia, ib, ic)
            d2 = x * x + y * y + z * z
            if d2 < best:
                best = d2
                bx, by, bz = x, y, z
                b0, b1, b2 = i0, i1, i2
    if b0 < 0:
        return 0.0, 0.0, 0.0, 0
    return bx, by, bz, _keep(w, 4, b0, b1, b2)


@njit(_nrt=False)
def separating_direction(va, vb, dx, dy, dz, margin, max_iter, w):
    """A unit direction u with gap(u) > margin (B beyond A along u), searched by GJK.

    Args:
        va, vb: (n, 3) float64 vertices [m] of A and B (world frame).
        dx, dy, dz: start direction (any length; the centre line c_B - c_A or a direction that
            separated the pair before).
        margin: the gap required [m]. max_iter: iteration limit (a few suffice when the
            gap is not tiny; 32 in the pair pass).
        w: (>= 4, 3) float64 scratch for the simplex (rows 0-3 are overwritten).

    Returns:
        (found, ux, uy, uz): found is True when gap(u) > margin, as :func:`gap` computes it
        (never from a non-finite direction or a vertex set of NaNs; a single NaN vertex is
        skipped by the comparisons, which matters only in a run the NaN guard stops anyway).
    """
    n = 0
    vx, vy, vz = dx, dy, dz
    for _ in range(max_iter):
        vv = vx * vx + vy * vy + vz * vz
        if not (0.0 < vv < math.inf):
            break
        nv = math.sqrt(vv)
        ux, uy, uz = vx / nv, vy / nv, vz / nv
        # support of D = B - A minimising v . x
        amax = -math.inf
        ia = 0
        for k in range(va.shape[0]):
            t = ux * va[k, 0] + uy * va[k, 1] + uz * va[k, 2]
            if t > amax:
                amax = t
                ia = k
        bmin = math.inf
        ib = 0
        for k in range(vb.shape[0]):
            t = ux * vb[k, 0] + uy * vb[k, 1] + uz * vb[k, 2]
            if t < bmin:
                bmin = t
                ib = k
        if bmin - amax > margin and amax > -math.inf and bmin < math.inf:  # not from NaN projections
            return True, ux, uy, uz
        sx, sy, sz = vb[ib, 0] - va[ia, 0], vb[ib, 1] - va[ia, 1], vb[ib, 2] - va[ia, 2]
        if n > 0 and vv - (vx * sx + vy * sy + vz * sz) <= 1e-12 * vv:
            break  # v is the closest point of D: the distance is at most margin
        w[n, 0] = sx
        w[n, 1] = sy
        w[n, 2] = sz
        vx, vy, vz, n = _closest(w, n + 1)
        if n == 0:
            break  # the origin is inside the simplex: A and B touch or overlap
    return False, 0.0, 0.0, 0.0
