"""Convex geometry for demcli: polyhedra, minimal projections, sieve sizes, gradations.

Units are SI (m, m^2, m^3, kg); importing this package compiles no numba kernel
(``_kernels`` is imported on first use).

Main entry points:

- :func:`convex_hull` -> :class:`ConvexPolyhedron` (faces, normals, exact mass properties)
- :func:`min_projection`, :func:`projection_sieve`, :func:`sieve_size` (Shao et al. 2017)
- :func:`min_bounding_rectangle`, :func:`square_aperture` and the 2D polygon helpers
- :func:`sieve_set`, :func:`class_shares`, :func:`compare_gradation` (virtual sieving)
"""

from demcli.geometry.errors import GeometryError
from demcli.geometry.generate import fibonacci_sphere, random_polyhedron
from demcli.geometry.polygon import (
    convex_hull_2d,
    min_bounding_rectangle,
    polygon_area,
    polygon_centroid,
    polygon_second_moment,
    square_aperture,
)
from demcli.geometry.polyhedron import (
    ConvexPolyhedron,
    ShapeIndices,
    as_polyhedron,
    convex_hull,
    mass_properties,
    shape_indices,
)
from demcli.geometry.projection import (
    ProjectionSieve,
    min_projection,
    projected_area,
    projection_sieve,
    sieve_size,
)
from demcli.geometry.sieve import (
    GradationComparison,
    class_shares,
    clump_sieve_size,
    compare_gradation,
    polygon_sieve_size,
    sieve_set,
    sphere_sieve_sizes,
)

__all__ = [
    "ConvexPolyhedron",
    "GeometryError",
    "GradationComparison",
    "ProjectionSieve",
    "ShapeIndices",
    "as_polyhedron",
    "class_shares",
    "clump_sieve_size",
    "compare_gradation",
    "convex_hull",
    "convex_hull_2d",
    "fibonacci_sphere",
    "mass_properties",
    "min_bounding_rectangle",
    "min_projection",
    "polygon_area",
    "polygon_centroid",
    "polygon_second_moment",
    "polygon_sieve_size",
    "projected_area",
    "projection_sieve",
    "random_polyhedron",
    "shape_indices",
    "sieve_set",
    "sieve_size",
    "sphere_sieve_sizes",
    "square_aperture",
]
