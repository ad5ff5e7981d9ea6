"""2D asphalt sections (seed 001): random convex polygons placed without intersection in a
specimen, a hexagonal ball lattice over the specimen, and balls grouped by polygon.

Units are SI (m, m^2). Specimens are centred at the origin: a circle of radius ``a``, or
a rectangle ``a`` wide and ``b`` high. The numba kernels are in
:mod:`demcli.kernels.polygons` and are imported on first use (importing this module
compiles nothing).
"""

import math
import time
from dataclasses import dataclass

import numpy as np

from demcli.geometry.errors import GeometryError

TESTS = ("exact", "bounding_circle")


@dataclass(frozen=True)
class Specimen:
    """A 2D specimen centred at the origin: ``circle`` (a = radius) or ``rectangle`` (a x b)."""

    shape: str
    a: float
    b: float = 0.0

    def __post_init__(self):
        if self.shape not in ("circle", "rectangle"):
            raise GeometryError(f"specimen shape {self.shape!r}: use 'circle' or 'rectangle'")
        if not self.a > 0 or (self.shape == "rectangle" and not self.b > 0):
            raise GeometryError(f"specimen sizes must be > 0, got {self.a!r}, {self.b!r}")

    @classmethod
    def from_config(cls, node):
        """From a gradation-style ``specimen`` section (circle: radius; rectangle: width, height)."""
        if node.shape == "circle":
            return cls("circle", float(node.radius))
        if node.shape == "rectangle":
            return cls("rectangle", float(node.width), float(node.height))
        raise GeometryError(f"a 2D section needs a circle or rectangle specimen, not {node.shape!r}")

    @property
    def kind(self):
        return 0 if self.shape == "circle" else 1

    @property
    def area(self):
        return math.pi * self.a ** 2 if self.shape == "circle" else self.a * self.b

    @property
    def size(self):
        """(radius, radius) or (width, height), m."""
        return (self.a, self.a) if self.shape == "circle" else (self.a, self.b)

    def outline(self, segments=128):
        """Closed outline points (k, 2) for drawing."""
        if self.shape == "circle":
            t = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
            return self.a * np.stack([np.cos(t), np.sin(t)], axis=1)
        w, h = 0.5 * self.a, 0.5 * self.b
        return np.array([[-w, -h], [w, -h], [w, h], [-w, h]])

    def contains(self, pts, margin=0.0):
        """Mask of points (n, 2) at least ``margin`` inside the specimen."""
        pts = np.asarray(pts, float)
        if self.shape == "circle":
            return np.hypot(pts[:, 0], pts[:, 1]) <= self.a - margin
        return (np.abs(pts[:, 0]) <= 0.5 * self.a - margin) & (np.abs(pts[:, 1]) <= 0.5 * self.b - margin)


@dataclass
class Placement:
    """Result of :func:`place_polygons`.

    Polygon p has vertices ``vertices[vertex_start[p]:vertex_start[p + 1]]`` (m,
    counter-clockwise), class ``pclass[p]``, area ``area[p]`` (m^2), centroid
    ``centroid[p]`` (m). Per class: ``target`` and ``placed`` area (m^2), ``tries``
    (placements attempted), ``accepted`` (polygons kept), ``out_of_class`` (polygons
    scaled outside the class to meet a target no in-class polygon could), ``quantiles``
    (low, median, high area of the class's natural polygons, m^2). ``complete`` is False
    when a polygon could not be placed in ``max_tries`` attempts (``failed_class``).
    """

    complete: bool
    failed_class: int
    vertex_start: np.ndarray
    vertices: np.ndarray
    pclass: np.ndarray
    area: np.ndarray
    centroid: np.ndarray
    target: np.ndarray
    placed: np.ndarray
    tries: np.ndarray
    accepted: np.ndarray
    out_of_class: np.ndarray
    quantiles: np.ndarray
    seconds: float

    def __len__(self):
        return len(self.pclass)

    def polygon(self, p):
        return self.vertices[self.vertex_start[p]:self.vertex_start[p + 1]]

    def polygons(self):
        return [self.polygon(p) for p in range(len(self))]


def place_polygons(rng, specimen, radius_lower, radius_upper, target, *, order=None, vertices=(6, 10),
                   angle_fluctuation=0.5, gap=0.0, test="exact", max_tries=200_000, cell=None, nsample=512,
                   quantiles=(0.1, 0.9)):
    """Random convex polygons in ``specimen`` until each class reaches its target area.

    rng: numpy Generator (advanced in place, reproducibly). radius_lower, radius_upper,
    target: (n_class,) polar-radius range (m) and area (m^2) of each class; order: class
    indices in placement order (default: by upper radius, largest first). vertices:
    (m_lo, m_hi) vertex-count range; angle_fluctuation: delta in [0, 1); gap: clearance
    between polygons and to the boundary (m); test: 'exact' (separating axes) or
    'bounding_circle' (conservative); max_tries: consecutive failed placements before the
    placement gives up; cell: broad-phase grid spacing (default: the smallest class's
    largest diameter, at least 1/512 of the specimen). Returns a :class:`Placement`.
    See :func:`demcli.kernels.polygons.place_polygons` for the algorithm.
    """
    from demcli.kernels import polygons as K

    lo = np.ascontiguousarray(radius_lower, np.float64)
    hi = np.ascontiguousarray(radius_upper, np.float64)
    tg = np.ascontiguousarray(target, np.float64)
    if not (lo.shape == hi.shape == tg.shape and lo.ndim == 1):
        raise GeometryError("radius_lower, radius_upper and target need the same (n_class,) shape")
    if np.any(lo <= 0) or np.any(hi < lo) or np.any(tg < 0) or not np.all(np.isfinite(tg)):
        raise GeometryError("class radii must be 0 < lower <= upper and targets finite and >= 0")
    m_lo, m_hi = int(vertices[0]), int(vertices[1])
    if not 3 <= m_lo <= m_hi:
        raise GeometryError(f"vertex counts need 3 <= min <= max, got {vertices}")
    if not 0.0 <= angle_fluctuation < 1.0:
        raise GeometryError(f"angle_fluctuation must be in [0, 1), got {angle_fluctuation}")
    if test not in TESTS:
        raise GeometryError(f"test {test!r}: use one of {TESTS}")
    if order is None:
        order = np.argsort(-hi, kind="stable")
    order = np.ascontiguousarray(order, np.int64)
    active = tg > 0
    if cell is None:
        span = 2.0 * max(specimen.size)
        cell = max(2.0 * float(hi[active].min()) if active.any() else span, span / 512.0)
    est = int(np.sum(np.ceil(tg[active] / (2.5 * lo[active] ** 2)))) + 16
    t0 = time.perf_counter()
    out = K.place_polygons(rng, specimen.kind, float(specimen.size[0]), float(specimen.size[1]), lo, hi, tg, order,
                           m_lo, m_hi, float(angle_fluctuation), float(gap), TESTS.index(test), int(max_tries),
                           float(cell), int(nsample), float(quantiles[0]), float(quantiles[1]), est)
    seconds = time.perf_counter() - t0
    status, failed, n, pstart, vx, vy, pcls, parea, pcent, placed, tries, accepted, ooc, quant = out
    return Placement(status == K.PLACED, int(failed), pstart, np.stack([vx, vy], axis=1), pcls, parea, pcent, tg,
                     placed, tries, accepted, ooc, quant, seconds)


def polygons_overlap(a, b, gap=0.0):
    """Exact separating-axis test of two convex counter-clockwise polygons (n, 2), (k, 2)."""
    from demcli.kernels.polygons import convex_polygons_overlap

    a = np.ascontiguousarray(a, np.float64)
    b = np.ascontiguousarray(b, np.float64)
    return bool(convex_polygons_overlap(a[:, 0].copy(), a[:, 1].copy(), b[:, 0].copy(), b[:, 1].copy(),
                                        float(gap)))


def graham_hull(points):
    """Convex hull (h, 2) of 2D points by the patent's Graham scan, counter-clockwise."""
    from demcli.kernels.polygons import graham_scan

    p = np.ascontiguousarray(points, np.float64)
    if p.ndim != 2 or p.shape[1] != 2 or len(p) == 0:
        raise GeometryError(f"points must have shape (n, 2), got {p.shape}")
    hx, hy = np.empty(len(p)), np.empty(len(p))
    h = graham_scan(p[:, 0].copy(), p[:, 1].copy(), len(p), hx, hy)
    return np.stack([hx[:h], hy[:h]], axis=1)


@dataclass
class HexLattice:
    """Hexagonally packed balls of radius ``r`` inside a specimen.

    Site (j, i) is at (x_off + (2 i + j % 2) r, y_off + j sqrt(3) r); ``grid[j, i]`` is the
    ball index there (-1: the ball would leave the specimen). ``centres`` (n, 2) m. A ball
    sits at the specimen centre. Each site stands for a hexagonal cell of area 2 sqrt(3) r^2.
    """

    r: float
    centres: np.ndarray
    grid: np.ndarray
    x_off: float
    y_off: float

    @property
    def cell_area(self):
        return 2.0 * math.sqrt(3.0) * self.r ** 2


def hex_lattice(specimen, r):
    """The balls of radius r (m) of a hexagonal packing that lie wholly inside the specimen."""
    if not r > 0:
        raise GeometryError(f"ball radius must be > 0, got {r!r}")
    half_w, half_h = (specimen.a, specimen.a) if specimen.shape == "circle" else (0.5 * specimen.a,
                                                                                  0.5 * specimen.b)
    dy = math.sqrt(3.0) * r
    jc = int(math.ceil(half_h / dy)) + 1
    jc += jc % 2  # even, so the centre row has no shift
    ic = int(math.ceil(half_w / (2.0 * r))) + 1
    nrow, ncol = 2 * jc + 1, 2 * ic + 1
    if nrow * ncol > 50_000_000:
        raise GeometryError(f"{nrow * ncol} lattice sites: the ball radius {r!r} m is too small for the specimen")
    x_off, y_off = -2.0 * ic * r, -jc * dy
    j, i = np.meshgrid(np.arange(nrow), np.arange(ncol), indexing="ij")
    x = x_off + (2 * i + j % 2) * r
    y = y_off + j * dy
    pts = np.stack([x.ravel(), y.ravel()], axis=1)
    keep = specimen.contains(pts, margin=r * (1.0 + 1e-12))
    grid = np.full(nrow * ncol, -1, np.int64)
    grid[keep] = np.arange(int(keep.sum()))
    return HexLattice(float(r), np.ascontiguousarray(pts[keep]), grid.reshape(nrow, ncol), x_off, y_off)


def label_balls(lattice, vertex_start, vertices, membership="centre"):
    """Polygon index of each lattice ball (-1: outside every polygon).

    membership: 'centre' (the ball's centre is inside the polygon) or 'whole' (the
    whole ball is).
    """
    from demcli.kernels.polygons import label_lattice

    if membership not in ("centre", "whole"):
        raise GeometryError(f"membership {membership!r}: use 'centre' or 'whole'")
    v = np.ascontiguousarray(vertices, np.float64)
    return label_lattice(np.ascontiguousarray(vertex_start, np.int64), v[:, 0].copy(), v[:, 1].copy(),
                         lattice.grid, lattice.x_off, lattice.y_off, lattice.r,
                         0.0 if membership == "centre" else lattice.r)


def disk_union_properties(centres, r, areal_density):
    """Mass properties of a rigid group of equal, non-overlapping disks in the plane.

    centres (n, 2) m, disk radius r (m), areal_density (kg/m^2: density x thickness).
    Non-overlapping disks make the sums exact: each disk has m = rho_A pi r^2 and, as a
    lamina, I_xx = I_yy = m r^2 / 4, I_zz = m r^2 / 2 about its centre; parallel axes
    carry them to the group's centre of mass. Returns (mass, com (2,), moments (3,),
    angle): principal moments (I_1 <= I_2 in the plane, I_zz = I_1 + I_2) and the angle
    (rad) of the first principal axis from x.
    """
    c = np.asarray(centres, float)
    m1 = areal_density * math.pi * r * r
    mass = m1 * len(c)
    com = c.mean(axis=0)
    d = c - com
    ixx = mass * r * r / 4.0 + m1 * float(np.sum(d[:, 1] ** 2))
    iyy = mass * r * r / 4.0 + m1 * float(np.sum(d[:, 0] ** 2))
    ixy = -m1 * float(np.sum(d[:, 0] * d[:, 1]))
    vals, vecs = np.linalg.eigh(np.array([[ixx, ixy], [ixy, iyy]]))
    angle = math.atan2(vecs[1, 0], vecs[0, 0])
    return mass, com, np.array([vals[0], vals[1], ixx + iyy]), angle
