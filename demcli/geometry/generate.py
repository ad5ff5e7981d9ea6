"""Point sets on the sphere and random convex polyhedra (test shapes, ballast libraries).

Lengths in m.
"""

import numpy as np

from demcli.geometry.polyhedron import convex_hull


def fibonacci_sphere(n):
    """n nearly uniform unit vectors, (n, 3): the Fibonacci (golden-angle) lattice.

    Point i sits at height z = 1 - (2 i + 1)/n and longitude i * pi (3 - sqrt 5)
    (Gonzalez 2010, "Measurement of areas on a sphere using Fibonacci and
    latitude-longitude lattices", Math. Geosci. 42).
    """
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - (2.0 * i + 1.0) / n
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = i * np.pi * (3.0 - np.sqrt(5.0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def random_polyhedron(rng, n_points, semi_axes=(1.0, 1.0, 1.0)):
    """Convex hull of n_points random points on an ellipsoid surface.

    rng: numpy Generator; semi_axes (m): the ellipsoid's semi-axes along x, y, z.
    Directions are uniform on the unit sphere, then scaled per axis. The hull is
    simplicial with probability one: 2 n_points - 4 triangular faces when every point
    is a vertex (always, as the points lie on a strictly convex surface).
    """
    d = rng.normal(size=(n_points, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    return convex_hull(d * np.asarray(semi_axes, dtype=np.float64))
