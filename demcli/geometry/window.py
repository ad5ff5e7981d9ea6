"""Exact parts of particles inside an axis-aligned box: disks and rectangles, balls and boxes,
convex polyhedra and boxes (the packing record's sampling window, demcli/stages/packing_record.py).

Lengths in m; NumPy only (and scipy's ConvexHull for the clipped polyhedra): no numba kernel.

Disk and rectangle (:func:`disk_rectangle_area`): inclusion-exclusion over the rectangle's
corners of the quadrant area Q(a, b) = |disk(0, rho) & {x >= a, y >= b}|, which is closed
form for any signs of a and b (:func:`_quadrant_area`).

Ball and box (:func:`sphere_box_volume`): closed form, no quadrature. The ball is symmetric
under the reflection of each axis, so each axis's interval [lo, hi] (relative to the centre)
is a signed sum of at most three one-sided constraints |x| >= t with t >= 0, or no constraint:
[lo, hi] = {x >= lo} - {x >= hi} for 0 <= lo; its mirror for hi <= 0; all - {-x >= -lo} -
{x >= hi} for lo < 0 < hi. The box is then a signed sum of at most 27 regions
{x >= a, y >= b, z >= c} (a, b, c >= 0, some axes free), whose volumes follow from the
divergence theorem, V = (1/3) sum over the boundary of x . n dA:

* no constraint: 4/3 pi R^3; one, the cap z >= c: pi (R - c)^2 (2R + c) / 3 (= pi h^2 (3R - h) / 3,
  h = R - c);
* two, y >= b, z >= c: V = (R A - b S(c; k_b) - c S(b; k_c)) / 3, the plane faces being disk
  segments S(t; k) = k^2 acos(t/k) - t sqrt(k^2 - t^2) of the circles of radius k_b = sqrt(R^2 -
  b^2), k_c; the spherical part's area A = 2 R [I(b; k_b) - I(b; c)] (Archimedes: the sphere's
  area between two heights is 2 pi R times their distance, spread evenly over the azimuth, so
  A = R int Phi(z) dz with Phi the azimuth the constraint keeps, here 2 acos(b / rho(z)));
* three, x >= a, y >= b, z >= c: V = (R A - a Q_x - b Q_y - c Q_z) / 3 with the quadrant areas
  Q of the three plane faces and A = R [I(a; z*) - I(a; c) + I(b; z*) - I(b; c) - pi/2 (z* - c)],
  z* = sqrt(R^2 - a^2 - b^2) (Phi = acos(a/rho) + acos(b/rho) - pi/2);

with I(a; z) = int acos(a / sqrt(R^2 - z^2)) dz = z acos(a / rho) - a asin(z / k) +
R atan(a z / (R sqrt(k^2 - z^2))), rho = sqrt(R^2 - z^2), k = sqrt(R^2 - a^2) (by parts and
int dz / ((R^2 - z^2) sqrt(k^2 - z^2)) = atan(a z / (R sqrt(k^2 - z^2))) / (R a)). Every angle
is taken as atan2 of two legs (acos(a / rho) = atan2(sqrt(R^2 - a^2 - z^2), a), ...): acos and
asin of an argument near 1 lose half the digits, 1e-8 of the volume where a face is nearly
tangent or a chord nearly a diameter. The round-off is then about 1e-15 of the ball's volume
(tests/stages/test_packing_record.py: quadrature of the slices' exact areas, Monte Carlo, the
closed forms of a cap, a half, a quarter and an octant).

Convex polyhedron and box (:func:`convex_box_volume`): their intersection is convex, and its
vertices are among the polyhedron's vertices inside the box, the box's corners inside the
polyhedron, and the crossings of either's edges with the other's face planes: its volume is
that of their convex hull, exact up to round-off.
"""

import math

import numpy as np

_PI = math.pi


# ---- disks and rectangles ---------------------------------------------------------------------
# A point of a circle of radius rho is carried as both its coordinates (x, h), h = sqrt(rho^2 -
# x^2), and its angle taken as atan2(x, h): asin(x / rho) or acos(a / rho) lose half the digits
# where their argument nears 1 (a chord close to a diameter: an error of 1e-8 rho^2).

def _complement(x, rho):
    """sqrt(rho^2 - x^2) for |x| <= rho, as sqrt((rho - x)(rho + x))."""
    return np.sqrt(np.maximum((rho - x) * (rho + x), 0.0))


def _chord_primitive(x, h, rho):
    """int_0^x sqrt(rho^2 - t^2) dt, for |x| <= rho and h = sqrt(rho^2 - x^2)."""
    return 0.5 * (x * h + rho * rho * np.arctan2(x, h))


def _quadrant_area(a, b, rho):
    """Area of the disk of radius ``rho`` about the origin where x >= a and y >= b (any signs)."""
    a, b, rho = np.broadcast_arrays(*(np.asarray(v, np.float64) for v in (a, b, rho)))
    ok = rho > 0.0
    r = np.where(ok, rho, 1.0)
    a = np.clip(a, -r, r)
    b = np.clip(b, -r, r)
    bb = np.abs(b)
    xb = _complement(bb, r)                      # the chord y = |b| spans |x| <= xb
    lo = np.clip(a, -xb, xb)
    h_lo = np.where(np.abs(a) >= xb, bb, _complement(lo, r))
    upper = _chord_primitive(xb, bb, r) - _chord_primitive(lo, h_lo, r) - bb * (xb - lo)  # x >= a, y >= |b|
    right = 0.5 * np.pi * r * r - 2.0 * _chord_primitive(a, _complement(a, r), r)            # x >= a
    out = np.where(b >= 0.0, upper, right - upper)   # y >= b < 0: all of x >= a but y <= b = -|b|
    return np.where(ok, np.maximum(out, 0.0), 0.0)


def disk_rectangle_area(centres, radii, lo, hi):
    """Areas [m^2] of the disks (``centres`` (n, 2), ``radii`` (n,)) inside the rectangle
    [lo, hi] (two (2,) corners): closed form."""
    c = np.asarray(centres, np.float64).reshape(-1, 2)
    r = np.asarray(radii, np.float64).reshape(-1)
    (x0, y0), (x1, y1) = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if x1 <= x0 or y1 <= y0:
        return np.zeros(len(r))
    ax0, ax1, by0, by1 = x0 - c[:, 0], x1 - c[:, 0], y0 - c[:, 1], y1 - c[:, 1]
    area = (_quadrant_area(ax0, by0, r) - _quadrant_area(ax1, by0, r) - _quadrant_area(ax0, by1, r)
            + _quadrant_area(ax1, by1, r))
    return np.clip(area, 0.0, _PI * r * r)


# ---- balls and boxes --------------------------------------------------------------------------

def _rest(R, *t):
    """sqrt(R^2 - sum t^2), 0 where negative."""
    return np.sqrt(np.maximum(R * R - sum(v * v for v in t), 0.0))


def _azimuth_integral(a, z, w, R):
    """I(a; z) = int_0^z acos(a / sqrt(R^2 - t^2)) dt, for 0 <= a < R, 0 <= z and w =
    sqrt(R^2 - a^2 - z^2) >= 0 (acos(a / rho) = atan2(w, a), asin(z / k) = atan2(z, w))."""
    phi = np.where((a == 0.0) & (w == 0.0), 0.5 * _PI, np.arctan2(w, a))  # a = 0 at the pole: pi/2 all along
    return z * phi - a * np.arctan2(z, w) + R * np.arctan2(a * z, R * w)


def _cap(c, R):
    """Volume of the ball where z >= c, 0 <= c <= R."""
    return _PI * (R - c) ** 2 * (2.0 * R + c) / 3.0


def _wedge(b, c, R):
    """Volume of the ball where y >= b and z >= c (b, c >= 0)."""
    empty = b * b + c * c >= R * R
    b = np.where(empty, 0.0, b)
    c = np.where(empty, 0.0, c)
    w = _rest(R, b, c)                  # the corner line's half-length: y = b, z = c on the sphere
    kb, kc = _complement(b, R), _complement(c, R)
    area = 2.0 * R * (_azimuth_integral(b, kb, 0.0, R) - _azimuth_integral(b, c, w, R))
    seg_b = kb * kb * np.arctan2(w, c) - c * w    # the face y = b: the disk of radius kb beyond z = c
    seg_c = kc * kc * np.arctan2(w, b) - b * w    # the face z = c
    v = (R * area - b * seg_b - c * seg_c) / 3.0
    return np.where(empty, 0.0, v)


def _corner(a, b, c, R):
    """Volume of the ball where x >= a, y >= b and z >= c (a, b, c >= 0)."""
    empty = a * a + b * b + c * c >= R * R
    a, b, c = (np.where(empty, 0.0, v) for v in (a, b, c))
    zs = _rest(R, a, b)
    area = R * (_azimuth_integral(a, zs, b, R) - _azimuth_integral(a, c, _rest(R, a, c), R)
                + _azimuth_integral(b, zs, a, R) - _azimuth_integral(b, c, _rest(R, b, c), R)
                - 0.5 * _PI * (zs - c))
    ka, kb, kc = (_complement(v, R) for v in (a, b, c))
    v = (R * area - a * _quadrant_area(b, c, ka) - b * _quadrant_area(a, c, kb) - c * _quadrant_area(a, b, kc)) / 3.0
    return np.where(empty, 0.0, v)


def _one_sided(t, free, R):
    """Volume of the ball under the one-sided constraints |x_k| >= t_k (t >= 0; ``free`` axes
    unconstrained): (n, 3) arrays."""
    vals = np.sort(np.where(free, np.inf, np.abs(t)), axis=1)  # the constrained axes first (|t|: no -0.0)
    n_con = 3 - free.sum(axis=1)
    v0, v1, v2 = (np.where(np.isfinite(vals[:, k]), vals[:, k], 0.0) for k in range(3))
    return np.select([n_con == 3, n_con == 2, n_con == 1],
                     [_corner(v0, v1, v2, R), _wedge(v0, v1, R), _cap(v0, R)], 4.0 / 3.0 * _PI * R ** 3)


def _axis_terms(lo, hi):
    """(weight, t, free), each (n, 3): the interval [lo, hi] (-R <= lo <= hi <= R) as a signed sum
    of one-sided constraints |x| >= t (t >= 0) or no constraint (free)."""
    n = len(lo)
    w, t, free = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3), bool)
    right, left = lo >= 0.0, hi <= 0.0
    across = ~(right | left)
    w[right, 0], t[right, 0], w[right, 1], t[right, 1] = 1.0, lo[right], -1.0, hi[right]
    left &= ~right
    w[left, 0], t[left, 0], w[left, 1], t[left, 1] = 1.0, -hi[left], -1.0, -lo[left]
    w[across, 0], free[across, 0] = 1.0, True
    w[across, 1], t[across, 1], w[across, 2], t[across, 2] = -1.0, -lo[across], -1.0, hi[across]
    return w, t, free


def _cut_ball_volume(c, r, lo, hi):
    """Closed-form volumes of the balls (centres ``c`` (m, 3), radii ``r``) inside the box."""
    rel_lo = np.clip(lo[None, :] - c, -r[:, None], r[:, None])
    rel_hi = np.clip(hi[None, :] - c, -r[:, None], r[:, None])
    terms = [_axis_terms(rel_lo[:, k], rel_hi[:, k]) for k in range(3)]
    out = np.zeros(len(r))
    for i in range(3):
        for j in range(3):
            for k in range(3):
                w = terms[0][0][:, i] * terms[1][0][:, j] * terms[2][0][:, k]
                if not np.any(w):
                    continue
                t = np.stack([terms[0][1][:, i], terms[1][1][:, j], terms[2][1][:, k]], axis=1)
                free = np.stack([terms[0][2][:, i], terms[1][2][:, j], terms[2][2][:, k]], axis=1)
                out += w * _one_sided(t, free, r)
    return out


def sphere_box_volume(centres, radii, lo, hi):
    """Volumes [m^3] of the balls (``centres`` (n, 3), ``radii`` (n,)) inside the box [lo, hi]:
    closed form (the module's doc); a ball wholly inside gives 4/3 pi r^3, one wholly outside 0."""
    c = np.asarray(centres, np.float64).reshape(-1, 3)
    r = np.asarray(radii, np.float64).reshape(-1)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    out = np.zeros(len(r))
    if np.any(hi <= lo):
        return out
    inside = np.all((c - r[:, None] >= lo) & (c + r[:, None] <= hi), axis=1)
    outside = np.any((c + r[:, None] <= lo) | (c - r[:, None] >= hi), axis=1)
    out[inside] = 4.0 / 3.0 * _PI * r[inside] ** 3
    cut = ~(inside | outside) & (r > 0.0)
    if np.any(cut):
        out[cut] = np.clip(_cut_ball_volume(c[cut], r[cut], lo, hi), 0.0, 4.0 / 3.0 * _PI * r[cut] ** 3)
    return out


def sphere_lens(r1, r2, d):
    """(volume [m^3], t [m]) of the lens two balls of radii ``r1``, ``r2`` at centre distance
    ``d`` share, t its centroid's distance from the first centre towards the second: the caps
    of heights h1 = r1 - x, h2 = r2 - (d - x) beyond the radical plane at x = (d^2 + r1^2 -
    r2^2) / (2 d), each of volume pi h^2 (3r - h) / 3 and centroid 3 (2r - h)^2 / (4 (3r - h))
    from its ball's centre. (0, 0) apart; the smaller ball when one holds the other."""
    r1, r2, d = np.broadcast_arrays(*(np.asarray(v, np.float64) for v in (r1, r2, d)))
    apart = d >= r1 + r2
    nested = d <= np.abs(r1 - r2)
    ds = np.where(apart | nested | (d <= 0.0), 1.0, d)
    x = (ds * ds + r1 * r1 - r2 * r2) / (2.0 * ds)
    h1 = np.clip(r1 - x, 0.0, 2.0 * r1)
    h2 = np.clip(r2 - (ds - x), 0.0, 2.0 * r2)
    v1 = _PI * h1 * h1 * (3.0 * r1 - h1) / 3.0
    v2 = _PI * h2 * h2 * (3.0 * r2 - h2) / 3.0
    t1 = 3.0 * (2.0 * r1 - h1) ** 2 / (4.0 * (3.0 * r1 - h1))
    t2 = ds - 3.0 * (2.0 * r2 - h2) ** 2 / (4.0 * (3.0 * r2 - h2))
    vol = v1 + v2
    t = np.divide(v1 * t1 + v2 * t2, vol, out=np.zeros_like(vol), where=vol > 0.0)
    small = np.minimum(r1, r2)
    vol = np.where(apart, 0.0, np.where(nested, 4.0 / 3.0 * _PI * small ** 3, vol))
    t = np.where(apart, 0.0, np.where(nested, np.where(r1 <= r2, 0.0, d), t))
    return vol, t


# ---- convex polyhedra and boxes ---------------------------------------------------------------

_BOX_EDGES = np.array([(0, 1), (2, 3), (4, 5), (6, 7), (0, 2), (1, 3), (4, 6), (5, 7), (0, 4), (1, 5), (2, 6),
                       (3, 7)])


def box_corners(lo, hi):
    """The 8 corners (8, 3) of the box [lo, hi], corner k at (hi if bit d of k else lo) per axis d."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    bits = (np.arange(8)[:, None] >> np.arange(3)[None, :]) & 1
    return np.where(bits == 1, hi, lo)


def convex_box_volume(vertices, edges, normals, offsets, lo, hi):
    """Volume [m^3] of the convex polyhedron {x: normals . x <= offsets} (its ``vertices`` (n, 3),
    ``edges`` (m, 2) rows of vertices, face planes ``normals`` (f, 3) outward, ``offsets`` (f,))
    inside the box [lo, hi]: the convex hull of the intersection's candidate vertices (module doc)."""
    from scipy.spatial import ConvexHull, QhullError

    v = np.asarray(vertices, np.float64)
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if np.any(hi <= lo):
        return 0.0
    vmin, vmax = v.min(axis=0), v.max(axis=0)
    if np.any(vmax <= lo) or np.any(vmin >= hi):
        return 0.0
    nrm, off = np.asarray(normals, np.float64), np.asarray(offsets, np.float64)
    scale = float(max(np.abs(v).max(), np.abs(lo).max(), np.abs(hi).max(), 1e-300))
    tol = 1e-12 * scale
    in_box = lambda p: np.all((p >= lo - tol) & (p <= hi + tol), axis=1)  # noqa: E731
    in_poly = lambda p: np.all(p @ nrm.T <= off + tol, axis=1)  # noqa: E731
    pts = [v[in_box(v)]]
    corners = box_corners(lo, hi)
    pts.append(corners[in_poly(corners)])
    # the polyhedron's edges across the box's planes
    p, q = v[edges[:, 0]], v[edges[:, 1]]
    for d in range(3):
        for plane in (lo[d], hi[d]):
            dp, dq = p[:, d] - plane, q[:, d] - plane
            cross = dp * dq < 0.0
            s = dp[cross] / (dp[cross] - dq[cross])
            x = p[cross] + s[:, None] * (q[cross] - p[cross])
            pts.append(x[in_box(x)])
    # the box's edges across the polyhedron's face planes
    a, b = corners[_BOX_EDGES[:, 0]], corners[_BOX_EDGES[:, 1]]
    da = a @ nrm.T - off   # (12, f)
    db = b @ nrm.T - off
    ei, fi = np.nonzero(da * db < 0.0)
    if len(ei):
        s = da[ei, fi] / (da[ei, fi] - db[ei, fi])
        x = a[ei] + s[:, None] * (b[ei] - a[ei])
        pts.append(x[in_poly(x) & in_box(x)])
    pts = np.concatenate(pts)
    if len(pts) < 4:
        return 0.0
    try:
        return float(ConvexHull(pts).volume)
    except QhullError:  # a flat or empty intersection
        return 0.0
