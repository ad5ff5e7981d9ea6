"""2D polygon helpers: convex hull, area, centroid, second moment, bounding rectangle.

Lengths in m, areas in m^2, second moments in m^4 (unit areal density); polygons
are (n, 2) vertex arrays without a repeated closing vertex. Area, centroid and
second moment follow from Green's theorem over the edges (the "shoelace" sums;
Steger 1996, "On the calculation of arbitrary moments of polygons", TU Munich
FGBV-96-05, eqs. 3-8), for simple polygons of either orientation.
"""

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from demcli.geometry.errors import GeometryError


def _points_2d(points, name="points"):
    pts = np.ascontiguousarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise GeometryError(f"{name} must have shape (n, 2), got {pts.shape}")
    if not np.all(np.isfinite(pts)):
        raise GeometryError(f"{name} contain NaN or inf")
    return pts


def convex_hull_2d(points):
    """Convex hull of 2D points (Qhull via ``scipy.spatial.ConvexHull``).

    points: (n, 2) in m. Returns the hull vertices, (h, 2), counter-clockwise;
    collinear points are dropped. Raises GeometryError for fewer than 3 distinct
    points, collinear points, NaN or inf.
    """
    pts = _points_2d(points)
    if len(np.unique(pts, axis=0)) < 3:
        raise GeometryError("a 2D hull needs at least 3 distinct points")
    try:
        hull = ConvexHull(pts)
    except QhullError:
        raise GeometryError("the 2D points are collinear: their hull has no area") from None
    return pts[hull.vertices]  # scipy orders 2D hull vertices counter-clockwise


def _shoelace(vertices):
    """Per-edge cross terms relative to the vertex mean (for conditioning)."""
    p = _points_2d(vertices, "vertices")
    if len(p) < 3:
        raise GeometryError(f"a polygon needs at least 3 vertices, got {len(p)}")
    ref = p.mean(axis=0)
    x, y = (p - ref).T
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area2 = cross.sum()
    if area2 == 0.0:
        raise GeometryError("the polygon has zero area")
    return ref, x, y, xn, yn, cross, area2


def polygon_area(vertices):
    """Area (m^2) of a simple polygon, either orientation: |1/2 sum (x_i y_i+1 - x_i+1 y_i)|."""
    return abs(_shoelace(vertices)[-1]) / 2.0


def polygon_centroid(vertices):
    """Area centroid (m), (2,), of a simple polygon: c = sum (p_i + p_i+1) cross_i / (6 A)."""
    ref, x, y, xn, yn, cross, area2 = _shoelace(vertices)
    return ref + np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (3.0 * area2)


def polygon_second_moment(vertices):
    """Second moment of area about the centroid, (2, 2) in m^4: J = int (p - c)(p - c)^T dA.

    J[0, 0] = int x^2 dA, J[1, 1] = int y^2 dA, J[0, 1] = int x y dA (centroidal
    coordinates). The polar moment (2D moment of inertia for unit areal density)
    is trace(J); a body of mass m has inertia m trace(J) / area.
    """
    ref, x, y, xn, yn, cross, area2 = _shoelace(vertices)
    sign = np.sign(area2)
    sxx = (cross * (x * x + x * xn + xn * xn)).sum() / 12.0
    syy = (cross * (y * y + y * yn + yn * yn)).sum() / 12.0
    sxy = (cross * (x * yn + 2.0 * x * y + 2.0 * xn * yn + xn * y)).sum() / 24.0
    area = abs(area2) / 2.0
    c = np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (3.0 * area2)
    about_ref = sign * np.array([[sxx, sxy], [sxy, syy]])
    return about_ref - area * np.outer(c, c)  # parallel-axis shift to the centroid


def min_bounding_rectangle(points_2d):
    """Minimum-area bounding rectangle of 2D points by rotating calipers.

    points_2d: (n, 2) in m. The hull is taken first (monotone chain); one side of the
    optimal rectangle lies on a hull edge (Freeman & Shapira 1975), found in O(h)
    with rotating calipers (Toussaint 1983); this is step 1-9 of Shao et al. 2017,
    section 1.2. Returns (length, width, angle): sides in m with length >= width and
    the angle (rad, [0, pi)) of the length side from the x axis.
    """
    from demcli.geometry import _kernels

    pts = _points_2d(points_2d)
    if len(pts) == 0:
        raise GeometryError("no points given")
    idx = _kernels.hull2d(pts)
    return _kernels.min_area_rectangle(np.ascontiguousarray(pts[idx]))


def square_aperture(length, width):
    """Smallest square hole side (m) that a length x width rectangle passes, rotation allowed.

    min(L, (L + W)/sqrt 2) for L >= W: the square case of Carver's rectangle-in-
    rectangle condition as stated by Wetzel 2000 ("Rectangles in rectangles",
    Math. Mag. 73(3)): flat across the hole, or turned 45 degrees on its diagonal.
    """
    from demcli.geometry import _kernels

    return _kernels.square_aperture(max(length, width), min(length, width))
