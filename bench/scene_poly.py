"""The peers' "poly" scene (../shared/peers/yade/poly.py) as a polyhedral :class:`demcli.engine.system.System`.

500 random convex polyhedra fall in a closed box: each shape is YADE's
``Polyhedra::GenerateRandomGeometry`` redone in numpy (the Voronoi cell of a centre
nucleus among hard-core random nuclei, minimal distance 0.75, filled by random
sequential addition until 500 trials in a row fail, scaled per axis by the body's
size (sx, sy, sz), each uniform in 10-20 mm, then a random rotation); YADE's C
``rand()`` stream cannot be reproduced, so the shapes are statistically alike, not
identical (numbers printed by :func:`describe`). Lattice spacing 2 r_max x 1.02, box
nx sp x nx sp x 2 nz sp, density 2600, young 1e9, friction 0.5 (atan 0.5), local
damping 0.3, gravity 9.81, dt 2e-5 s.

The contact law differs from YADE's (its Law2_..._Volumetric is F = k V with
k = 5e8 N/m^3; demcli uses the seed's F = 4E sqrt(V d) / (3 sqrt(pi)), a stiffer
law at E = 1e9 Pa): the scene, not the law, is shared.
"""

import math

import numpy as np
from scipy.spatial import ConvexHull

SIZE_MIN, SIZE_MAX = 0.010, 0.020
RHO = 2600.0
YOUNG = 1e9
FRICTION = 0.5
LOCAL_DAMPING = 0.3
DT = 2e-5


def _nuclei(seed, radius=2.4, dmin=0.75, patience=500):
    """Hard-core random sequential addition around a nucleus at the origin (compiled).

    YADE fills a 5 x 5 x 5 box around the centre; only nuclei within about twice
    the cell size shape the centre cell, so a ball of ``radius`` is filled instead
    (same density, a fraction of the work).
    """
    from numba import njit

    global _rsa
    if _rsa is None:
        @njit(cache=True)
        def _rsa(seed, radius, dmin, patience):
            np.random.seed(seed)
            pts = np.zeros((4096, 3))
            n = 1
            fails = 0
            d2 = dmin * dmin
            while fails < patience and n < pts.shape[0]:
                t0 = np.random.uniform(-radius, radius)
                t1 = np.random.uniform(-radius, radius)
                t2 = np.random.uniform(-radius, radius)
                if t0 * t0 + t1 * t1 + t2 * t2 > radius * radius:
                    continue
                ok = True
                for k in range(n):
                    if (pts[k, 0] - t0) ** 2 + (pts[k, 1] - t1) ** 2 + (pts[k, 2] - t2) ** 2 <= d2:
                        ok = False
                        break
                if ok:
                    pts[n, 0] = t0
                    pts[n, 1] = t1
                    pts[n, 2] = t2
                    n += 1
                    fails = 0
                else:
                    fails += 1
            return pts[1:n].copy()
    return _rsa(seed, radius, dmin, patience)


_rsa = None


def _voronoi_cell(seeds):
    """Vertices of the Voronoi cell of the origin among ``seeds`` (polar duality)."""
    q = 2.0 * seeds / np.einsum("ij,ij->i", seeds, seeds)[:, None]
    hull = ConvexHull(q)
    c = -hull.equations[:, 3]
    return hull.equations[:, :3] / c[:, None]


def _quat(rng):
    q = rng.uniform(0.0, 1.0, 4)  # YADE: Quaternionr(rand, rand, rand, rand).normalized()
    return q / np.linalg.norm(q)


def _rotmat(q):
    w, x, y, z = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def random_yade_polyhedron(size, seed):
    """One YADE-like random polyhedron of the given size (3,) [m], centroid anywhere."""
    from demcli.geometry import convex_hull

    rng = np.random.RandomState(seed)
    sub = seed
    while True:
        v = _voronoi_cell(_nuclei(sub))
        if len(v) >= 8 and np.max(np.linalg.norm(v, axis=1)) < 1.2:  # 0.5 x ball radius: cell is exact
            break
        sub += 100003
    v = (v * np.asarray(size)) @ _rotmat(_quat(rng)).T
    return convex_hull(v)


def build(n=500, seed=2024, young=YOUNG):
    """(groups, walls, materials, box (L, L, H)) of the scene."""
    from demcli.engine.poly_shape import polyhedra_groups
    from demcli.engine.system import Walls
    from demcli.engine.materials import Material

    rng = np.random.RandomState(seed)
    polys = [random_yade_polyhedron(rng.uniform(SIZE_MIN, SIZE_MAX, 3), k + 1) for k in range(n)]
    rcirc = np.array([np.max(np.linalg.norm(p.vertices - p.centroid, axis=1)) for p in polys])
    sp = 2.0 * rcirc.max() * 1.02
    nx = int(math.ceil(n ** (1.0 / 3.0)))
    lx = nx * sp
    h = 2.0 * int(math.ceil(n / (nx * nx))) * sp
    k = np.arange(n)
    x = np.stack([(k % nx + 0.5) * sp, ((k // nx) % nx + 0.5) * sp, (k // (nx * nx) + 0.5) * sp], axis=1)
    groups = polyhedra_groups(polys, RHO, x=x)
    walls = Walls.box_faces((lx, lx, h))
    mats = [Material("rock", RHO, young=young, friction=FRICTION)]
    return groups, walls, mats, (lx, lx, h), rcirc


def make_system(n=500, seed=2024, skin=0.3, dt=DT, check_every=100, young=YOUNG):
    """The scene as a System (gravity, friction, local damping 0.3, six plane walls)."""
    from demcli.engine.materials import ContactModel
    from demcli.engine.plan import make_plan
    from demcli.engine.system import System
    from demcli.engine.system import Dynamics

    groups, walls, mats, box, rcirc = build(n, seed, young)
    plan = make_plan(["gravity", "friction", "local_damping"], walls=True)
    s = System(groups, mats, ContactModel(), plan, walls,
                   Dynamics(gravity=(0.0, 0.0, -9.81), local_damping=LOCAL_DAMPING, skin=skin,
                            check_every=check_every), dt=dt)
    s.box = box
    s.rcirc = rcirc
    return s


def describe(s):
    """One line on the shapes, comparable with the YADE run's header."""
    nv = np.diff(s.shapes[0])
    return (f"box={s.box[0]:.4f}x{s.box[1]:.4f}x{s.box[2]:.4f} "
            f"vertices min/mean/max={nv.min()}/{nv.mean():.1f}/{nv.max()} "
            f"circumradius_mm min/mean/max={1e3 * s.rcirc.min():.2f}/{1e3 * s.rcirc.mean():.2f}/"
            f"{1e3 * s.rcirc.max():.2f} mass_g min/max={1e3 * s.mass.min():.2f}/{1e3 * s.mass.max():.2f}")
