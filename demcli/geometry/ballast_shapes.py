"""Random angular convex polyhedra for ballast libraries: Voronoi cells and point hulls.

Two routes, both returning a :class:`~demcli.geometry.ConvexPolyhedron` of length
about 1 (unit-free: a library scales each shape to its sieve size afterwards):

``voronoi`` (the default): the cell of one seed in a Voronoi tessellation of random
seeds, the route Eliáš took for ballast ("Simulation of railway ballast using
crushable polyhedral particles", Powder Technol. 264 (2014) 458-465; PARTICLES 2013,
"DEM simulation of railway ballast using polyhedral elemental shapes"). Crushed rock
breaks along planes, and a Voronoi cell is exactly a convex body bounded by a random
set of planes: flat faces meeting at sharp edges and corners, 10-25 faces, with the
face count and the face sizes varying from cell to cell as they do on real stones.

- Seeds: a Matérn type-II hard-core process around the seed at the origin (Poisson
  parents of unit intensity with random marks; a parent is deleted if another one
  with a lower mark lies closer than ``regularity``, the origin having the lowest
  mark). ``regularity = 0`` gives the Poisson-Voronoi typical cell (Slivnyak), larger
  values more equiaxed cells with fewer slivers.
- The cell {x : x . p_i <= |p_i|^2 / 2} is computed through polar duality: the
  facets a . y = 1 of the hull of the dual points 2 p_i / |p_i|^2 are the cell's
  vertices y = a (one Qhull call). It is exact when every vertex is within half the
  seed ball's radius of the origin (no seed outside the ball could cut it);
  otherwise the draw is repeated.
- Voronoi cells carry many very short edges (four seeds nearly on one sphere). A
  contact engine dislikes them, so vertices closer than ``min_edge`` times the cell
  length are merged (single-linkage clusters replaced by their mean) before the
  final hull. Merged corners come out as small triangles; face planarity is kept.

``hull``: the convex hull of random points on an ellipsoid
(:func:`demcli.geometry.random_polyhedron`); all faces are triangles (2 n - 4 of
them), the look is rounder and more faceted. Cheap, and a useful contrast.

Shape control, both routes: the elongation ``e = I/L`` and flatness ``f = S/I``
(Zingg 1935) are drawn uniformly from their ranges. For ``voronoi`` the cell is put
in the principal frame of its vertex cloud and scaled along the three axes so that
its extents become exactly L = 1, I = e, S = e f; the measured ratios (extents along
the principal axes of inertia, :func:`demcli.geometry.shape_indices`) then match the
draw to a few percent. For ``hull`` the ellipsoid has semi-axes 1, e, e f. A draw
whose face count falls outside ``faces`` is rejected and repeated.
"""

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import ConvexHull, QhullError, cKDTree

from demcli.geometry.errors import GeometryError
from demcli.geometry.generate import random_polyhedron
from demcli.geometry.polyhedron import convex_hull

METHODS = ("voronoi", "hull")

# mean number of seeds kept around the origin; the typical cell has ~15 neighbours and
# every vertex must lie within half the ball radius for the cell to be exact
_SEEDS_KEPT = 60


@dataclass(frozen=True)
class ShapeParams:
    """Parameters of the random shape generator (see the module docstring).

    method: "voronoi" or "hull"; faces: (min, max) face count, inclusive;
    elongation: (min, max) of I/L; flatness: (min, max) of S/I; regularity:
    hard-core distance of the Voronoi seeds in units of the parents' spacing
    (0 <= regularity <= 1); min_edge: vertices closer than this fraction of the cell
    length are merged (voronoi only); max_tries: draws before giving up.
    """

    method: str = "voronoi"
    faces: tuple = (8, 30)
    elongation: tuple = (0.55, 0.95)
    flatness: tuple = (0.5, 0.95)
    regularity: float = 0.5
    min_edge: float = 0.05
    max_tries: int = 200

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"method must be one of {METHODS}, got {self.method!r}")
        for name in ("faces", "elongation", "flatness"):
            lo, hi = getattr(self, name)
            if hi < lo:
                raise ValueError(f"{name}: max {hi} < min {lo}")
        if self.faces[1] < 4:
            raise ValueError("a polyhedron has at least 4 faces")
        for name in ("elongation", "flatness"):
            lo, hi = getattr(self, name)
            if not 0.0 < lo <= hi <= 1.0:
                raise ValueError(f"{name} must lie in (0, 1], got ({lo}, {hi})")
        if not 0.0 <= self.regularity <= 1.0:
            raise ValueError(f"regularity must lie in [0, 1], got {self.regularity}")
        if not 0.0 <= self.min_edge < 0.5:
            raise ValueError(f"min_edge must lie in [0, 0.5), got {self.min_edge}")


def voronoi_seeds(rng, regularity, kept=_SEEDS_KEPT):
    """Matérn type-II hard-core seeds around the origin (the origin itself excluded).

    Returns (points (k, 3), ball radius R). Parents have unit intensity in a ball
    sized so that about ``kept`` seeds survive the thinning: the retained intensity
    is (1 - exp(-v)) / v with v the volume of a ball of radius ``regularity``
    (Stoyan, Kendall & Mecke, "Stochastic geometry and its applications", 2nd ed.,
    section 5.4).
    """
    v = 4.0 / 3.0 * np.pi * regularity ** 3
    lam = (1.0 - np.exp(-v)) / v if v > 0.0 else 1.0
    radius = (3.0 * kept / (4.0 * np.pi * lam)) ** (1.0 / 3.0)
    n = int(rng.poisson(4.0 / 3.0 * np.pi * radius ** 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    p = np.vstack([np.zeros(3), d * (radius * np.cbrt(rng.random(n)))[:, None]])
    mark = rng.random(n + 1)
    mark[0] = -1.0  # the origin always survives
    if regularity > 0.0:
        pairs = cKDTree(p).query_pairs(regularity, output_type="ndarray")
        if len(pairs):
            loser = np.where(mark[pairs[:, 0]] > mark[pairs[:, 1]], pairs[:, 0], pairs[:, 1])
            keep = np.ones(n + 1, dtype=bool)
            keep[loser] = False
            p = p[keep]
    return p[1:], radius


def voronoi_cell_vertices(seeds, radius):
    """Vertices of the Voronoi cell of the origin among ``seeds`` (k, 3), or None.

    Polar duality: the half-spaces x . p <= |p|^2 / 2 are y . q <= 1 with
    q = 2 p / |p|^2, and the cell's vertices are the facet normals a of the dual
    hull scaled to a . q = 1. None when the origin is not inside the dual hull
    (an unbounded cell) or a vertex lies beyond radius / 2 (the cell could be cut by
    a seed outside the ball).
    """
    q = 2.0 * seeds / np.einsum("ij,ij->i", seeds, seeds)[:, None]
    try:
        hull = ConvexHull(q)
    except QhullError:
        return None
    c = -hull.equations[:, 3]  # facet n . y = c, with c > 0 when the origin is inside
    if np.any(c <= 1e-12):
        return None
    v = hull.equations[:, :3] / c[:, None]
    if np.max(np.einsum("ij,ij->i", v, v)) > (0.5 * radius) ** 2:
        return None
    return v


def merge_close_vertices(points, tol):
    """Points with neighbours closer than ``tol`` replaced by their cluster means.

    Single-linkage clusters (connected components of the pairs closer than tol).
    Returns (m, 3), m <= n, in the order of the clusters' first members.
    """
    pairs = cKDTree(points).query_pairs(tol, output_type="ndarray")
    if not len(pairs):
        return points
    n = len(points)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    n_comp, label = connected_components(graph, directed=False)
    sums = np.zeros((n_comp, 3))
    np.add.at(sums, label, points)
    return sums / np.bincount(label, minlength=n_comp)[:, None]


def _principal_extents(points):
    """Points in the principal frame of their covariance (axes by decreasing spread),
    centred on the middle of their extents, and the extents (3,)."""
    centred = points - points.mean(axis=0)
    _, vecs = np.linalg.eigh(centred.T @ centred)
    local = centred @ vecs[:, ::-1]
    lo, hi = local.min(axis=0), local.max(axis=0)
    return local - 0.5 * (lo + hi), hi - lo


def _voronoi_draw(rng, params):
    for _ in range(20):
        seeds, radius = voronoi_seeds(rng, params.regularity)
        v = voronoi_cell_vertices(seeds, radius)
        if v is not None:
            break
    else:
        raise GeometryError("no bounded Voronoi cell in 20 draws (regularity too high?)")
    e = rng.uniform(*params.elongation)
    f = rng.uniform(*params.flatness)
    local, ext = _principal_extents(v)
    order = np.argsort(ext)[::-1]
    local, ext = local[:, order], ext[order]
    stretched = local * (np.array([1.0, e, e * f]) / ext)
    if params.min_edge > 0.0:
        stretched = merge_close_vertices(stretched, params.min_edge)
    return convex_hull(stretched)


def _hull_draw(rng, params):
    lo = max(4, (params.faces[0] + 5) // 2)  # 2 n - 4 faces from n points
    hi = max(lo, (params.faces[1] + 4) // 2)
    e = rng.uniform(*params.elongation)
    f = rng.uniform(*params.flatness)
    return random_polyhedron(rng, int(rng.integers(lo, hi + 1)), (1.0, e, e * f))


def random_ballast_shape(rng, params=ShapeParams()):
    """One random angular convex polyhedron of length about 1 (see the module docstring).

    rng: numpy Generator (the only source of randomness, so a seeded generator gives
    the same shape bit for bit); params: :class:`ShapeParams`. Returns a
    ConvexPolyhedron whose face count lies in ``params.faces``. Raises GeometryError
    when ``max_tries`` draws all miss the face range.
    """
    draw = _voronoi_draw if params.method == "voronoi" else _hull_draw
    lo, hi = params.faces
    counts = []
    for _ in range(params.max_tries):
        try:
            poly = draw(rng, params)
        except GeometryError:
            continue
        if lo <= poly.n_faces <= hi:
            return poly
        counts.append(poly.n_faces)
    seen = f"{min(counts)}-{max(counts)}" if counts else "none (degenerate draws)"
    raise GeometryError(f"no {params.method} shape with {lo}-{hi} faces in {params.max_tries} draws "
                        f"(face counts seen: {seen}); widen the face range")


__all__ = ["METHODS", "ShapeParams", "merge_close_vertices", "random_ballast_shape", "voronoi_cell_vertices",
           "voronoi_seeds"]
