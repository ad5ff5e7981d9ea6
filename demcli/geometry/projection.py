"""Minimal projection (shadow) of a convex polyhedron and the sieve size built on it.

Source: Shao, Lian, Yang 2017 (seed 002), section 1: a particle passes a square
hole if its minimal-area projection does; the projection's minimum-area bounding
rectangle decides. Lengths in m, areas in m^2.

The shadow area along a unit direction u is A(u) = 1/2 sum_f a_f |n_f . u|
(seed eq. 2 with both sides of the surface counted). It is linear on each cell of
the arrangement of great circles n_f . u = 0, and on a cell the map u -> p = u / A(u)
sends it to a convex polygon on the plane p . N = 1, where A = 1/|p| is least at the
farthest vertex (seed eq. 3). The cell vertices are the directions n_a x n_b for
every pair of faces, so the exact minimum is among those (McKenna & Seidel 1985,
"Finding the optimal shadows of a convex polytope", Proc. SoCG). The seed keeps
only the edge directions (pairs of adjacent faces): exact for tetrahedra, where
all face pairs are adjacent, but it can miss the minimum of larger polyhedra.
"""

from dataclasses import dataclass

import numpy as np

from demcli.geometry.polyhedron import as_polyhedron

# candidates whose shadow area is within this relative margin of the minimum count
# as tied; the tie goes to the smallest aperture (a cube's three face-on shadows)
_TIE = 1e-9
# above this many distinct face planes the exact search sweeps the great circles
# (O(g^2 log g)) instead of evaluating every pair direction (O(g^3))
_SWEEP_ABOVE = 128

METHODS = ("projection", "volume_sphere", "volume_cube", "inertia_square")


def projected_area(particle, directions):
    """Shadow area (m^2) of a convex particle along each direction.

    particle: vertices (n, 3) in m or a ConvexPolyhedron; directions: (k, 3) or (3,),
    need not be unit. Returns (k,) or a float: A(u) = 1/2 sum_f a_f |n_f . u|.
    """
    from demcli.geometry import _kernels

    poly = as_polyhedron(particle)
    d = np.asarray(directions, dtype=np.float64)
    single = d.ndim == 1
    d = np.atleast_2d(d)
    d = np.ascontiguousarray(d / np.linalg.norm(d, axis=1)[:, None])
    out = _kernels.shadow_areas(poly.circles, poly.circle_weights, d)
    return float(out[0]) if single else out


@dataclass(frozen=True, eq=False)
class ProjectionSieve:
    """Sieve size of a convex polyhedron by the minimal-projection method.

    ``size`` (m): smallest square hole side the particle passes; ``length >= width``
    (m): the minimum-area bounding rectangle of the minimal shadow; ``area`` (m^2):
    the minimal shadow area; ``direction`` (3,): unit viewing direction of that
    shadow (sign arbitrary).
    """

    size: float
    length: float
    width: float
    area: float
    direction: np.ndarray


def _best(poly, method):
    from demcli.geometry import _kernels

    if method == "exact" and len(poly.circles) > _SWEEP_ABOVE:
        res = _kernels.best_by_sweep(poly.circles, poly.circle_weights, poly.vertices, _TIE)
    else:
        if method == "exact":
            dirs = _kernels.pair_directions(poly.circles)
        elif method == "edges":
            d = poly.vertices[poly.edges[:, 1]] - poly.vertices[poly.edges[:, 0]]
            dirs = np.ascontiguousarray(d / np.linalg.norm(d, axis=1)[:, None])
        else:
            raise ValueError(f"method must be 'exact' or 'edges', got {method!r}")
        res = _kernels.best_of_directions(poly.circles, poly.circle_weights, dirs,
                                          poly.vertices, _TIE)
    ux, uy, uz, area, length, width, size = res
    return ProjectionSieve(size=size, length=length, width=width, area=area,
                           direction=np.array([ux, uy, uz]))


def min_projection(particle, method="exact"):
    """Minimal shadow area (m^2) of a convex polyhedron and its unit direction.

    particle: vertices (n, 3) in m or a ConvexPolyhedron. method "exact" searches all
    directions n_a x n_b over pairs of distinct face planes (the vertices of the
    great-circle arrangement, see the module docstring); "edges" searches the edge
    directions only (Shao et al. 2017, section 1.1), which is never below "exact".
    Directions whose area ties the minimum (relative 1e-9) are told apart by the
    smaller sieve aperture, as in :func:`projection_sieve`. Returns (area, direction).
    """
    best = _best(as_polyhedron(particle), method)
    return best.area, best.direction


def projection_sieve(particle, method="exact"):
    """Sieve size by the minimal projection (Shao et al. 2017, sections 1.1-1.2).

    particle: vertices (n, 3) in m or a ConvexPolyhedron (pass one to skip Qhull).
    The vertices are projected along the minimal-shadow direction (``method`` as in
    :func:`min_projection`), the shadow's minimum-area bounding rectangle L x W is
    found by rotating calipers, and the size is the smallest square hole that
    rectangle passes, turned if need be: min(L, (L + W)/sqrt 2) (Carver's
    condition; see :func:`demcli.geometry.square_aperture`).

    This follows the paper's definition. It is not always the smallest hole the
    particle passes: another direction with a larger shadow can have a rectangle
    with a smaller aperture, and the rectangle can need a larger hole than the
    shadow polygon itself. Returns a :class:`ProjectionSieve`.
    """
    return _best(as_polyhedron(particle), method)


def sieve_size(particle, method="projection"):
    """Sieve size (m) of a convex particle: the square hole side it just passes.

    particle: vertices (n, 3) in m, or a prebuilt ConvexPolyhedron (no Qhull call).
    method:

    - "projection" (default): minimal projection and its bounding rectangle, see
      :func:`projection_sieve` (Shao et al. 2017).
    - "volume_sphere": diameter of the sphere of equal volume, (6 V / pi)^(1/3).
    - "volume_cube": edge of the cube of equal volume, V^(1/3).
    - "inertia_square": side of the least bounding square of the projection on the
      plane normal to the minimum-inertia axis (Elias 2014, Powder Technol. 264, as
      used by Shao et al. 2017, section 1.3): the length of that projection's
      minimum-area bounding rectangle, so a 64 x 4 x 100 mm plate gets 64 mm. Only
      defined when the least principal moment is simple; for a cube or a regular
      tetrahedron the axis is whichever one the eigen-solver returns.
    """
    poly = as_polyhedron(particle)
    if method == "projection":
        return _best(poly, "exact").size
    if method == "volume_sphere":
        return float(np.cbrt(6.0 * poly.volume / np.pi))
    if method == "volume_cube":
        return float(np.cbrt(poly.volume))
    if method == "inertia_square":
        from demcli.geometry import _kernels

        return float(_kernels.project_rectangle(poly.vertices, *poly.principal_axes[:, 0])[0])
    raise ValueError(f"method must be one of {METHODS}, got {method!r}")
