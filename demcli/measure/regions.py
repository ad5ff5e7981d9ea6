"""Measurement regions of a dynamic stage (``measure:``): their schema, which bodies they hold
and their volume.

A region is named and has a type (docs/measure.md):

* ``sphere``: ``centre`` [m], ``radius`` [m]; V = 4/3 pi R^3;
* ``box``: ``min``, ``max`` [m], an axis-aligned box; V = prod(max - min);
* ``cylinder``: ``base`` [m] (a point on the axis), ``axis`` (direction, normalised), ``radius``
  [m] and ``span`` [m] (from, to) along the axis measured from ``base``; V = pi R^2 (to - from);
* ``all``: the whole specimen: the axis-aligned box ``around`` the bodies (their bounding box,
  default) or the walls (the innermost axis-aligned plane walls on each side, the bodies' extent
  where there is none), recomputed at every record.

A body belongs to a region when its centre (centre of mass) lies inside or on the boundary.
"""

import math

import numpy as np

from demcli.config.schema import Float, List, Section, Str, Tagged, Vector

NAME = Str(pattern=r"[A-Za-z][A-Za-z0-9_-]*", doc="the region's name: its table is records/<stage>_measure_<name>.csv")


def check_box(node, report):
    """Schema rule of a section with ``min`` and ``max`` vectors: max > min on every axis."""
    for d in range(3):
        if node.max[d] <= node.min[d]:
            report(f"max.{d}", f"must be > min ({node.min[d]:g} m)", node.max[d])


def _check_cylinder(node, report):
    if node.span[1] <= node.span[0]:
        report("span.1", f"must be > span.0 ({node.span[0]:g} m)", node.span[1])
    if math.hypot(*node.axis) == 0.0:
        report("axis", "must not be the zero vector", list(node.axis))


REGION = Tagged("type", {
    "sphere": Section({"name": NAME, "centre": Vector(3, "m"), "radius": Float("m", min=0, min_inclusive=False)},
                      doc="a ball"),
    "box": Section({"name": NAME, "min": Vector(3, "m"), "max": Vector(3, "m")}, check=check_box,
                   doc="an axis-aligned box"),
    "cylinder": Section({
        "name": NAME, "base": Vector(3, "m", doc="a point on the axis"),
        "axis": Vector(3, default=(0.0, 0.0, 1.0), doc="axis direction"),
        "radius": Float("m", min=0, min_inclusive=False),
        "span": Vector(2, "m", doc="from and to along the axis, measured from base"),
    }, check=_check_cylinder, doc="a finite cylinder"),
    "all": Section({"name": NAME, "around": Str(choices=["bodies", "walls"], default="bodies",
                                                doc="the box of the bodies or of the walls")},
                   doc="the whole specimen: an axis-aligned box recomputed at every record"),
}, doc="a measurement region")

MEASURE = List(REGION, default=(), unique_by="name",
               doc="measurement regions: at every record row each writes its Love-Weber stress, solid fraction, "
                   "coordination (rattlers excluded), fabric and velocity statistics (records/<stage>_measure_"
                   "<name>.csv and .png; sphere, clump and polyhedron scenes; docs/measure.md)")


class Region:
    """A measurement region from its validated ``measure:`` entry.

    ``box``: (lo, hi) of an ``all`` region, set at each record with :meth:`set_box`.
    """

    def __init__(self, spec):
        self.name = spec.name
        self.kind = spec.type
        self.spec = spec
        self.box = None
        if self.kind == "box":
            self.box = (np.array(spec.min, float), np.array(spec.max, float))
        elif self.kind == "cylinder":
            a = np.array(spec.axis, float)
            self.axis = a / np.linalg.norm(a)

    def set_box(self, lo, hi):
        """The box of an ``all`` region now [m]."""
        self.box = (np.asarray(lo, float), np.asarray(hi, float))

    def inside(self, x):
        """(n,) bool: the points ``x`` (n, 3) [m] inside the region or on its boundary."""
        x = np.asarray(x, float).reshape(-1, 3)
        s = self.spec
        if self.kind == "sphere":
            return np.sum((x - np.asarray(s.centre)) ** 2, axis=1) <= s.radius ** 2
        if self.kind == "cylinder":
            rel = x - np.asarray(s.base)
            t = rel @ self.axis
            radial = rel - t[:, None] * self.axis
            return (t >= s.span[0]) & (t <= s.span[1]) & (np.sum(radial ** 2, axis=1) <= s.radius ** 2)
        lo, hi = self.box
        return np.all((x >= lo) & (x <= hi), axis=1)

    def volume(self):
        """V [m^3] of the region (an ``all`` region: of its box now; 0 for an empty box)."""
        s = self.spec
        if self.kind == "sphere":
            return 4.0 / 3.0 * math.pi * s.radius ** 3
        if self.kind == "cylinder":
            return math.pi * s.radius ** 2 * (s.span[1] - s.span[0])
        lo, hi = self.box
        return float(np.prod(np.maximum(hi - lo, 0.0)))
