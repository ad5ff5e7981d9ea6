"""Polyhedron carving of aggregates from a ball lattice (seed 000, Tian, Liu & Wang 2007).

The recipe, steps 1-5 of the seed: spheres placed by gradation are kept as "seeds"
(centre, radius, material); a region is filled with small balls on a simple cubic
lattice; each seed sphere is cut by three pairs of parallel planes, each pair
symmetric about its centre, with random spacings d_1, d_2, d_3 and random angles
between the pairs; the lattice balls inside (sphere and slabs) become one rigid
aggregate; balls covered by no polyhedron are deleted.

Conventions (SI units, lengths in m):

* lattice: ``counts = floor(extent / spacing)`` balls per axis, centred in the region,
  ball radius ``spacing / 2`` (neighbours touch, none overlap), index
  ``i + nx (j + ny k)`` (x fastest);
* a pair of planes is a unit normal n and a full spacing d: a point x is between them
  when ``|n . (x - c)| <= d / 2``; a ball belongs to a seed when its centre (``shrink =
  0``) or the whole ball (``shrink = r``) is inside every slab and the sphere;
* an aggregate's volume is its cells (``mass_model="cells"``: n spacing^3, the voxel
  volume of the polyhedron, which tends to its volume as the balls shrink) or its balls
  (``"balls"``: n 4/3 pi r^3, the union of member balls, exact since they do not
  overlap); mass and inertia follow from the same model (a cell is a cube of side
  ``spacing``, a ball a solid sphere), as exact sums with parallel axes.

Kernels here are numba functions of arrays (no I/O); the wrappers validate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from demcli.geometry._kernels import _basis, hull2d, square_aperture
from demcli.jit import njit

MASS_MODELS = ("cells", "balls")


# ---------------------------------------------------------------------------------------
# lattice
# ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Lattice:
    """A simple cubic lattice of touching balls in a box (see the module doc)."""

    origin: np.ndarray    # (3,) centre of ball (0, 0, 0), m
    spacing: float        # m (ball diameter)
    counts: np.ndarray    # (3,) int64 balls per axis

    @property
    def radius(self) -> float:
        return 0.5 * self.spacing

    @property
    def size(self) -> int:
        return int(np.prod(self.counts))

    def centres(self, index=None) -> np.ndarray:
        """Centres (n, 3) of the lattice balls ``index`` (all when None), m."""
        idx = np.arange(self.size, dtype=np.int64) if index is None else np.asarray(index, np.int64)
        nx, ny = int(self.counts[0]), int(self.counts[1])
        ijk = np.stack([idx % nx, (idx // nx) % ny, idx // (nx * ny)], axis=1)
        return self.origin + ijk * self.spacing


def make_lattice(lo, hi, spacing=None, count=None) -> Lattice:
    """Lattice of a box: give the ``spacing`` (m) or the ball ``count`` along its longest side.

    ``count`` sets spacing = longest extent / count; each axis then holds
    floor(extent / spacing) balls, the lattice centred in the box. The seed's 120 mm cube
    with ``count=66`` holds 66^3 = 287 496 balls of 1.818 mm.
    """
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    ext = hi - lo
    if np.any(ext <= 0):
        raise ValueError(f"empty region {lo} - {hi}")
    if (spacing is None) == (count is None):
        raise ValueError("give exactly one of spacing or count")
    if spacing is None:
        spacing = float(ext.max()) / int(count)
    counts = np.floor(ext / spacing + 1e-9).astype(np.int64)
    if np.any(counts < 1):
        raise ValueError(f"spacing {spacing:g} m is larger than the region {ext}")
    origin = lo + 0.5 * (ext - counts * spacing) + 0.5 * spacing
    return Lattice(origin, float(spacing), counts)


# ---------------------------------------------------------------------------------------
# random cutting planes
# ---------------------------------------------------------------------------------------

def random_unit_vectors(rng, n):
    """(n, 3) unit vectors uniform on the sphere."""
    v = rng.normal(size=(n, 3))
    norm = np.linalg.norm(v, axis=1)
    bad = norm < 1e-12
    while np.any(bad):  # practically never
        v[bad] = rng.normal(size=(int(bad.sum()), 3))
        norm = np.linalg.norm(v, axis=1)
        bad = norm < 1e-12
    return v / norm[:, None]


def random_plane_normals(rng, n, angle_min):
    """(n, 3, 3) normals ``N[k, p]`` of the three plane pairs of n polyhedra.

    The angle between two pairs of planes (arccos |n_p . n_q|, in [0, pi/2]) is at
    least ``angle_min`` (rad) for every pair p, q: n_1 uniform on the sphere; n_2 at an
    angle uniform in [angle_min, pi/2] from n_1 with a uniform azimuth; n_3 uniform on
    the sphere, redrawn until both of its angles are at least ``angle_min``.
    """
    if not 0.0 <= angle_min <= math.pi / 2:
        raise ValueError(f"angle_min must be in [0, pi/2], got {angle_min}")
    n1 = random_unit_vectors(rng, n)
    # a unit vector normal to n1 with a uniform azimuth
    helper = np.where(np.abs(n1[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = np.cross(n1, helper)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(n1, e1)
    phi = rng.uniform(0.0, 2 * math.pi, n)
    u = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    theta = rng.uniform(angle_min, math.pi / 2, n)
    n2 = np.cos(theta)[:, None] * n1 + np.sin(theta)[:, None] * u
    n3 = np.empty((n, 3))
    todo = np.arange(n)
    c = math.cos(angle_min) + 1e-12
    while len(todo):
        cand = random_unit_vectors(rng, len(todo))
        ok = (np.abs((cand * n1[todo]).sum(1)) <= c) & (np.abs((cand * n2[todo]).sum(1)) <= c)
        n3[todo[ok]] = cand[ok]
        todo = todo[~ok]
    return np.stack([n1, n2, n3], axis=1)


def draw_spacings(rng, diameters, longest, fe_share, fe_ratio, ratio_range, fe=None):
    """Full spacings (n, 3) of the three plane pairs, and which were drawn flat/elongated.

    diameters (n,): seed sphere diameters D (m). For each polyhedron:

    * the largest spacing d_max = D u, u uniform in ``longest`` = (lo, hi);
    * the ratio rho = d_max / d_min: with probability ``fe_share`` the particle is
      flat/elongated and rho is uniform in [fe_ratio, ratio_range[1]], otherwise uniform in
      [ratio_range[0], fe_ratio);
    * d_min = d_max / rho and the middle spacing uniform in [d_min, d_max];
    * the three spacings go to the three pairs in random order.

    ``fe`` (n,) bool, when given, fixes which particles are flat/elongated instead of drawing
    it (a seed cut again keeps its kind; ``fe_share`` is then unused).

    Returns (spacings (n, 3), drawn_fe (n,) bool, rho (n,)).
    """
    d = np.asarray(diameters, float)
    n = len(d)
    dmax = d * rng.uniform(longest[0], longest[1], n)
    fe = rng.random(n) < fe_share if fe is None else np.asarray(fe, bool).copy()
    lo, hi = ratio_range
    rho = np.where(fe, rng.uniform(fe_ratio, hi, n), rng.uniform(lo, fe_ratio, n))
    dmin = dmax / rho
    dmid = rng.uniform(dmin, dmax)
    sp = np.stack([dmax, dmid, dmin], axis=1)
    perm = np.argsort(rng.random((n, 3)), axis=1)
    return np.take_along_axis(sp, perm, axis=1), fe, rho


@njit
def _extent(n, a, ha, b, hb, big_r):
    """max n . x over {|a . x| <= ha, |b . x| <= hb, |x| <= R} (unit n, a, b; a, b not parallel)."""
    best = -np.inf
    # the sphere's pole
    if abs(a[0] * n[0] + a[1] * n[1] + a[2] * n[2]) * big_r <= ha + 1e-12 and \
            abs(b[0] * n[0] + b[1] * n[1] + b[2] * n[2]) * big_r <= hb + 1e-12:
        return big_r
    # on one slab face, the sphere active
    for f in range(2):
        u = a if f == 0 else b
        hu = ha if f == 0 else hb
        v = b if f == 0 else a
        hv = hb if f == 0 else ha
        nu = u[0] * n[0] + u[1] * n[1] + u[2] * n[2]
        px, py, pz = n[0] - nu * u[0], n[1] - nu * u[1], n[2] - nu * u[2]
        pn = math.sqrt(px * px + py * py + pz * pz)
        for sgn in (-1.0, 1.0):
            s = sgn * hu
            if abs(s) > big_r:
                continue
            rho = math.sqrt(big_r * big_r - s * s)
            if pn > 1e-15:
                x0 = s * u[0] + rho * px / pn
                x1 = s * u[1] + rho * py / pn
                x2 = s * u[2] + rho * pz / pn
            else:
                x0, x1, x2 = s * u[0], s * u[1], s * u[2]
            if abs(v[0] * x0 + v[1] * x1 + v[2] * x2) <= hv + 1e-12:
                best = max(best, n[0] * x0 + n[1] * x1 + n[2] * x2)
    # on an edge of the two slabs, the sphere active (or not, when n is normal to the edge)
    ex = a[1] * b[2] - a[2] * b[1]
    ey = a[2] * b[0] - a[0] * b[2]
    ez = a[0] * b[1] - a[1] * b[0]
    en = math.sqrt(ex * ex + ey * ey + ez * ez)
    ex, ey, ez = ex / en, ey / en, ez / en
    ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    det = 1.0 - ab * ab
    for sa in (-1.0, 1.0):
        for sb in (-1.0, 1.0):
            s, t = sa * ha, sb * hb
            # x0 = p a + q b with a . x0 = s, b . x0 = t
            p = (s - ab * t) / det
            q = (t - ab * s) / det
            x0 = p * a[0] + q * b[0]
            x1 = p * a[1] + q * b[1]
            x2 = p * a[2] + q * b[2]
            r2 = x0 * x0 + x1 * x1 + x2 * x2
            if r2 > big_r * big_r:
                continue
            lam = math.sqrt(big_r * big_r - r2)
            best = max(best, n[0] * x0 + n[1] * x1 + n[2] * x2 + abs(n[0] * ex + n[1] * ey + n[2] * ez) * lam)
    return best


@njit
def polyhedron_widths(normals, spacings, radii):
    """Widths (n, 3) of each carved polyhedron (sphere and three slabs, centred) along its
    three plane normals: 2 min(d_p / 2, extent of the sphere and the other two slabs along n_p),
    m. A slab wider than what the sphere and the other slabs leave is not a cut."""
    n = normals.shape[0]
    out = np.empty((n, 3))
    for k in range(n):
        for p in range(3):
            q = (p + 1) % 3
            r = (p + 2) % 3
            g = _extent(normals[k, p], normals[k, q], 0.5 * spacings[k, q], normals[k, r], 0.5 * spacings[k, r],
                        radii[k])
            out[k, p] = 2.0 * min(0.5 * spacings[k, p], g)
    return out


def shape_planes(rng, diameters, angle_min, longest, fe_share, fe_ratio, ratio_range, fe=None):
    """Normals (n, 3, 3) and spacings (n, 3) of the cutting planes of n seed spheres.

    Spacings as :func:`draw_spacings` (``fe``: the kinds, when fixed); then the thinnest
    pair is narrowed until the polyhedron's own widths (:func:`polyhedron_widths`: a wide
    slab may not cut the sphere at all, or only a cap) have the drawn ratio max / min, so
    that a particle drawn flat/elongated is one, and one drawn regular is not. Returns
    (normals, spacings, drawn_fe (n,), rho (n,), widths (n, 3)).
    """
    d = np.asarray(diameters, float)
    normals = random_plane_normals(rng, len(d), angle_min)
    sp, fe, rho = draw_spacings(rng, d, longest, fe_share, fe_ratio, ratio_range, fe=fe)
    radii = 0.5 * d
    for _ in range(40):  # a fixed point: narrowing one pair can narrow the others' widths
        w = polyhedron_widths(normals, sp, radii)
        eff = w.max(axis=1) / w.min(axis=1)
        off = np.abs(eff / rho - 1.0) > 1e-9
        if not off.any():
            break
        thin = np.argmin(sp, axis=1)
        rows = np.flatnonzero(off)
        sp[rows, thin[rows]] = w[rows].max(axis=1) / rho[rows]
    return normals, sp, fe, rho, polyhedron_widths(normals, sp, radii)


# ---------------------------------------------------------------------------------------
# carving
# ---------------------------------------------------------------------------------------

@njit
def _carve(origin, spacing, counts, centres, radii, normals, half, shrink, label, seed_ids):
    """Label lattice balls inside each seed's polyhedron (sphere and three slabs).

    label: (n_lattice,) int64, -1 for free balls; only free balls are claimed.
    seed_ids: (m,) ids written into ``label`` for the m seeds. Returns the number of
    balls that fell inside a seed but were already claimed by another.
    """
    nx, ny, nz = counts[0], counts[1], counts[2]
    clash = 0
    for s in range(centres.shape[0]):
        cx, cy, cz = centres[s, 0], centres[s, 1], centres[s, 2]
        rr = radii[s] - shrink
        if rr <= 0.0:
            continue
        lo = np.empty(3, np.int64)
        hi = np.empty(3, np.int64)
        for d in range(3):
            c = centres[s, d]
            lo[d] = max(0, int(math.ceil((c - rr - origin[d]) / spacing)))
            hi[d] = min(counts[d] - 1, int(math.floor((c + rr - origin[d]) / spacing)))
        h0 = half[s, 0] - shrink
        h1 = half[s, 1] - shrink
        h2 = half[s, 2] - shrink
        for k in range(lo[2], hi[2] + 1):
            dz = origin[2] + k * spacing - cz
            for j in range(lo[1], hi[1] + 1):
                dy = origin[1] + j * spacing - cy
                for i in range(lo[0], hi[0] + 1):
                    dx = origin[0] + i * spacing - cx
                    if dx * dx + dy * dy + dz * dz > rr * rr:
                        continue
                    if abs(normals[s, 0, 0] * dx + normals[s, 0, 1] * dy + normals[s, 0, 2] * dz) > h0:
                        continue
                    if abs(normals[s, 1, 0] * dx + normals[s, 1, 1] * dy + normals[s, 1, 2] * dz) > h1:
                        continue
                    if abs(normals[s, 2, 0] * dx + normals[s, 2, 1] * dy + normals[s, 2, 2] * dz) > h2:
                        continue
                    idx = i + nx * (j + ny * k)
                    if label[idx] < 0:
                        label[idx] = seed_ids[s]
                    else:
                        clash += 1
    return clash


def carve(lattice, label, centres, radii, normals, spacings, seed_ids, membership="centre"):
    """Claim free lattice balls for seeds (in place on ``label``); returns the clash count.

    centres (m, 3), radii (m,), normals (m, 3, 3), spacings (m, 3) full widths;
    seed_ids (m,) labels to write. membership "centre": a ball whose centre is inside;
    "whole": a ball lying wholly inside.
    """
    shrink = 0.0 if membership == "centre" else lattice.radius
    return int(_carve(np.asarray(lattice.origin, float), float(lattice.spacing),
                      np.asarray(lattice.counts, np.int64), np.ascontiguousarray(centres, float),
                      np.ascontiguousarray(radii, float), np.ascontiguousarray(normals, float),
                      np.ascontiguousarray(0.5 * np.asarray(spacings, float)), float(shrink), label,
                      np.ascontiguousarray(seed_ids, np.int64)))


def body_lattice(lo, hi, spacing):
    """Lattice of balls of diameter ``spacing`` with a ball centred at the origin, covering
    the box [lo, hi] (m): the nodes k spacing, k integer, inside it. A body carved in its
    own frame (centroid at the origin) so always holds the ball at its centroid."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    k0 = np.ceil(lo / spacing - 1e-9)
    k1 = np.floor(hi / spacing + 1e-9)
    counts = np.maximum(k1 - k0 + 1, 0).astype(np.int64)
    return Lattice(k0 * spacing, float(spacing), counts)


def carve_polyhedron(normals, offsets, vertices, spacing, membership="centre"):
    """Balls of a lattice of ``spacing`` (ball diameter, m) inside a convex polyhedron.

    The polyhedron is {x: n_f . x <= d_f} (``normals`` (f, 3) outward unit, ``offsets``
    (f,) m, ``vertices`` (v, 3) its corners), given in its body frame (centroid at the
    origin: :func:`body_lattice` puts a ball there). Membership as in :func:`carve`: a
    ball belongs when its centre (``"centre"``) or the whole ball (``"whole"``) is inside,
    with a round-off allowance of 1e-9 spacing (lattice nodes on a face count as inside).
    Returns (centres (n, 3) m in the body frame, the lattice); n = 0 only for ``"whole"``
    when no ball fits.
    """
    normals = np.asarray(normals, float)
    offsets = np.asarray(offsets, float)
    vertices = np.asarray(vertices, float)
    if membership not in ("centre", "whole"):
        raise ValueError(f"membership must be 'centre' or 'whole', got {membership!r}")
    shrink = 0.0 if membership == "centre" else 0.5 * spacing
    lat = body_lattice(vertices.min(axis=0) + shrink, vertices.max(axis=0) - shrink, spacing)
    if lat.size == 0:
        return np.zeros((0, 3)), lat
    pts = lat.centres()
    inside = np.all(pts @ normals.T <= offsets - shrink + 1e-9 * spacing, axis=1)
    return pts[inside], lat


def members_by_label(label, n_labels):
    """CSR of lattice balls per label: (start (n_labels + 1,), ball indices), labels >= 0."""
    idx = np.flatnonzero(label >= 0)
    lab = label[idx]
    order = np.argsort(lab, kind="stable")
    start = np.searchsorted(lab[order], np.arange(n_labels + 1)).astype(np.int64)
    return start, idx[order].astype(np.int64)


# ---------------------------------------------------------------------------------------
# rigid clumps of lattice balls
# ---------------------------------------------------------------------------------------

def element_volume(spacing, mass_model):
    """Volume one member ball stands for: its cell (spacing^3) or the ball (pi/6 spacing^3)."""
    if mass_model == "cells":
        return spacing ** 3
    if mass_model == "balls":
        return math.pi / 6.0 * spacing ** 3
    raise ValueError(f"mass_model must be one of {MASS_MODELS}, got {mass_model!r}")


def own_inertia_factor(spacing, mass_model):
    """I of one element about its own centre per unit mass (isotropic): a^2/6 or 2/5 r^2."""
    return spacing ** 2 / 6.0 if mass_model == "cells" else 0.4 * (0.5 * spacing) ** 2


@dataclass(frozen=True)
class ClumpSet:
    """Rigid bodies built from groups of equal elements (lattice balls).

    mass (n,), com (n, 3) world, moments (n, 3) principal (ascending), axes (n, 3, 3)
    with columns the principal directions (world = axes @ body), quat (n, 4) (w, x, y, z)
    body to world, offsets (m, 3) member centres in their body frame, count (n,).
    """

    mass: np.ndarray
    com: np.ndarray
    moments: np.ndarray
    axes: np.ndarray
    quat: np.ndarray
    offsets: np.ndarray
    count: np.ndarray


def clump_set(start, points, spacing, density, mass_model="cells"):
    """Mass properties of clumps whose members are ``points[start[k]:start[k+1]]`` (m).

    Members are equal, non-overlapping elements (see :func:`element_volume`), so mass,
    centre and inertia tensor are exact sums: I = sum_i m_e (|d_i|^2 1 - d_i d_i^T) +
    n m_e c 1, with c the element's own factor. Every clump needs at least one member.
    """
    from scipy.spatial.transform import Rotation

    start = np.asarray(start, np.int64)
    pts = np.asarray(points, float)
    n = len(start) - 1
    count = np.diff(start)
    if np.any(count < 1):
        raise ValueError("every clump needs at least one member")
    owner = np.repeat(np.arange(n), count)
    m_e = density * element_volume(spacing, mass_model)
    com = np.stack([np.bincount(owner, pts[:, d], n) for d in range(3)], axis=1) / count[:, None]
    d = pts - com[owner]
    t = np.zeros((n, 3, 3))
    r2 = (d * d).sum(1)
    for a in range(3):
        for b in range(a, 3):
            val = np.bincount(owner, (r2 if a == b else 0.0) - d[:, a] * d[:, b], n) * m_e
            t[:, a, b] = val
            t[:, b, a] = val
    own = count * m_e * own_inertia_factor(spacing, mass_model)
    t[:, [0, 1, 2], [0, 1, 2]] += own[:, None]
    moments, axes = np.linalg.eigh(t)
    flip = np.linalg.det(axes) < 0
    axes[flip, :, 2] *= -1.0
    xyzw = Rotation.from_matrix(axes).as_quat()
    quat = np.ascontiguousarray(xyzw[:, [3, 0, 1, 2]])
    offsets = np.einsum("ij,ijk->ik", d, axes[owner])  # body = axes^T world
    return ClumpSet(count * m_e, com, moments, axes, quat, offsets, count)


# ---------------------------------------------------------------------------------------
# measures of carved clumps
# ---------------------------------------------------------------------------------------

def _aperture(length, width):
    from demcli.geometry import square_aperture

    return square_aperture(length, width)


@njit
def _grown_shadow_rectangle(vertices, dirs, r):
    """Least-area shadow of (hull of ``vertices``) + ball of radius r over directions ``dirs``.

    The shadow of the grown hull along u is the shadow polygon P(u) of the vertices grown
    by a disk: area A + r Per + pi r^2 (Steiner). Its bounding rectangle with a side on
    hull edge e of P is (L_e + 2r) x (W_e + 2r); the least-area one is kept (ties by the
    aperture). Returns (length, width) of the best direction's rectangle, m.
    """
    n = vertices.shape[0]
    pts = np.empty((n, 2))
    best_area = np.inf
    best_l = 0.0
    best_w = 0.0
    best_ap = np.inf
    for k in range(dirs.shape[0]):
        e1x, e1y, e1z, e2x, e2y, e2z = _basis(dirs[k, 0], dirs[k, 1], dirs[k, 2])
        for j in range(n):
            pts[j, 0] = vertices[j, 0] * e1x + vertices[j, 1] * e1y + vertices[j, 2] * e1z
            pts[j, 1] = vertices[j, 0] * e2x + vertices[j, 1] * e2y + vertices[j, 2] * e2z
        idx = hull2d(pts)
        h = idx.shape[0]
        area = 0.0
        per = 0.0
        for i in range(h):
            a = idx[i]
            b = idx[(i + 1) % h]
            area += pts[a, 0] * pts[b, 1] - pts[b, 0] * pts[a, 1]
            per += math.hypot(pts[b, 0] - pts[a, 0], pts[b, 1] - pts[a, 1])
        grown = 0.5 * abs(area) + r * per + math.pi * r * r
        if grown > best_area * (1.0 + 1e-9):
            continue
        # least-area bounding rectangle of the grown shadow: a side on a hull edge
        rl = 0.0
        rw = 0.0
        rarea = np.inf
        rap = np.inf
        for i in range(h):
            a = idx[i]
            b = idx[(i + 1) % h]
            ex = pts[b, 0] - pts[a, 0]
            ey = pts[b, 1] - pts[a, 1]
            le = math.hypot(ex, ey)
            if le <= 0.0:
                continue
            ex /= le
            ey /= le
            lo1 = np.inf
            hi1 = -np.inf
            lo2 = np.inf
            hi2 = -np.inf
            for t in range(h):
                c = idx[t]
                p1 = pts[c, 0] * ex + pts[c, 1] * ey
                p2 = -pts[c, 0] * ey + pts[c, 1] * ex
                lo1 = min(lo1, p1)
                hi1 = max(hi1, p1)
                lo2 = min(lo2, p2)
                hi2 = max(hi2, p2)
            u = hi1 - lo1 + 2.0 * r
            v = hi2 - lo2 + 2.0 * r
            ra = u * v
            ap = square_aperture(max(u, v), min(u, v))
            if ra < rarea * (1.0 - 1e-12) or (ra <= rarea * (1.0 + 1e-12) and ap < rap):
                rarea = ra
                rap = ap
                rl = max(u, v)
                rw = min(u, v)
        if grown < best_area * (1.0 - 1e-9) or rap < best_ap:
            best_area = min(best_area, grown)
            best_l = rl
            best_w = rw
            best_ap = rap
    return best_area, best_l, best_w


CANDIDATES = 48  # least-shadow directions of the centres' hull re-ranked for the grown hull


def lattice_clump_shadow(centres, radius):
    """Least shadow of a clump of equal balls: (area m^2, length m, width m of its rectangle).

    The clump's convex hull is the hull K of the member centres grown by the ball radius
    r. Its shadow along u has the area A_K(u) + r Per_K(u) + pi r^2 (Steiner) and a
    bounding rectangle grown by 2r. The candidate directions are the face-pair
    directions of K (where A_K is least: the exact set for K, see
    :mod:`demcli.geometry.projection`): the ``CANDIDATES`` of least A_K, K's face normals
    and its principal axes are ranked by the grown area. Degenerate clumps: one ball or
    a row of balls, seen end-on, are a disk of diameter 2r; a single layer of balls
    (coplanar centres) is seen edge-on: (w + 2r) x 2r, w the least width of its outline.
    """
    from demcli.geometry import GeometryError, _kernels, convex_hull

    c = np.asarray(centres, float).reshape(-1, 3)
    r = float(radius)
    disk = (math.pi * r * r, 2.0 * r, 2.0 * r)
    if len(c) <= 2:  # one ball, or two: a row (the common fines of a coarse lattice; no hull needed)
        return disk
    uniq = np.unique(np.round(c / (1e-6 * r)).astype(np.int64), axis=0)
    if len(uniq) == 1:
        return disk
    x = c - c.mean(axis=0)
    _, sv, vt = np.linalg.svd(x, full_matrices=False)
    tol = 1e-9 * max(sv[0], r)
    if len(sv) < 2 or sv[1] <= tol:
        return disk  # a row of balls: seen end-on
    if len(sv) < 3 or sv[2] <= tol:
        from demcli.geometry import min_bounding_rectangle

        _, width, _ = min_bounding_rectangle(x @ vt[:2].T)
        return ((width + 2 * r) * 2 * r, width + 2 * r, 2 * r)
    try:
        poly = convex_hull(c)
    except GeometryError:  # nearly flat: hull of the member surfaces, sampled
        from demcli.geometry import fibonacci_sphere, projection_sieve

        res = projection_sieve(convex_hull((c[:, None, :] + r * fibonacci_sphere(64)[None]).reshape(-1, 3)))
        return res.area, res.length, res.width
    dirs = _kernels.pair_directions(poly.circles)
    areas = _kernels.shadow_areas(poly.circles, poly.circle_weights, dirs)
    top = dirs[np.argsort(areas, kind="stable")[:CANDIDATES]]
    cand = np.ascontiguousarray(np.concatenate([top, poly.circles, vt]))
    return _grown_shadow_rectangle(np.ascontiguousarray(poly.vertices), cand, r)


def lattice_clump_sieve_size(centres, radius):
    """Sieve size (m) of a clump of equal balls by the projection method (Shao et al. 2017):
    the square aperture of the bounding rectangle of its least shadow
    (:func:`lattice_clump_shadow`), min(L, (L + W) / sqrt 2). Like every minimal-projection
    sieve size it can jump between nearly equal shadows of a near-isometric particle (the
    tests compare the shadow area, which does not, with the sampled-surface method)."""
    _, length, width = lattice_clump_shadow(centres, radius)
    return _aperture(length, width)


def sieve_sizes(start, points, radius):
    """Sieve size (m) of each clump ``points[start[k]:start[k+1]]`` of equal balls."""
    return np.array([lattice_clump_sieve_size(points[start[k]:start[k + 1]], radius)
                     for k in range(len(start) - 1)])


def normal_widths(start, points, normals, radius):
    """Widths (n, 3) of each clump of balls along its three plane normals, m.

    w_p = max n_p . x - min n_p . x + 2r over the member centres x: the extent of the
    balls between each pair of cutting planes (the carved counterpart of d_p).
    """
    start = np.asarray(start, np.int64)
    n = len(start) - 1
    count = np.diff(start)
    owner = np.repeat(np.arange(n), count)
    proj = np.einsum("ij,ipj->ip", points, normals[owner])  # (m, 3)
    hi = np.full((n, 3), -np.inf)
    lo = np.full((n, 3), np.inf)
    np.maximum.at(hi, owner, proj)
    np.minimum.at(lo, owner, proj)
    return hi - lo + 2.0 * radius


def sieve_class(sizes, lower, upper):
    """Class of each sieve size: k with lower_k < s <= upper_k; -1 below the smallest class
    (fines, passing every class sieve); sizes above the largest class count in it."""
    s = np.asarray(sizes, float)
    lower = np.asarray(lower, float)
    k = np.searchsorted(lower, s, side="left") - 1  # lower[k] < s
    return np.where(s <= lower[0], -1, np.minimum(k, len(lower) - 1)).astype(np.int64)


# ---------------------------------------------------------------------------------------
# random sequential addition among fixed obstacles
# ---------------------------------------------------------------------------------------

@njit
def _rsa(cand, lo, size, radii, placed, n_placed, tries, max_tries, head, nxt, allc, allr, n_all, cell, ncell,
         gap):
    """Place radii[n_placed:] from candidate points among ``allc[:n_all]`` (placed and obstacles).

    Same scheme as :func:`demcli.kernels.placement.rsa_batch`, with obstacles already in the
    grid and a clearance ``gap``. Returns (n_placed, n_all, tries, used).
    """
    n = radii.shape[0]
    used = 0
    p = np.empty(3)
    c = np.empty(3, np.int64)
    while used < cand.shape[0] and n_placed < n:
        r = radii[n_placed]
        for d in range(3):
            span = size[d] - 2.0 * r
            p[d] = lo[d] + r + cand[used, d] * max(span, 0.0)
        used += 1
        tries += 1
        for d in range(3):
            c[d] = min(ncell[d] - 1, max(0, int((p[d] - lo[d]) / cell)))
        ok = True
        for z in range(max(c[2] - 1, 0), min(c[2] + 2, ncell[2])):
            for y in range(max(c[1] - 1, 0), min(c[1] + 2, ncell[1])):
                for x in range(max(c[0] - 1, 0), min(c[0] + 2, ncell[0])):
                    k = head[x + ncell[0] * (y + ncell[1] * z)]
                    while k >= 0 and ok:
                        dd = 0.0
                        for d in range(3):
                            dd += (allc[k, d] - p[d]) ** 2
                        rs = r + allr[k] + gap
                        if dd < rs * rs:
                            ok = False
                        k = nxt[k]
        if ok:
            for d in range(3):
                placed[n_placed, d] = p[d]
                allc[n_all, d] = p[d]
            allr[n_all] = r
            ci = c[0] + ncell[0] * (c[1] + ncell[1] * c[2])
            nxt[n_all] = head[ci]
            head[ci] = n_all
            n_all += 1
            n_placed += 1
            tries = 0
        elif tries > max_tries:
            break
    return n_placed, n_all, tries, used


def place_spheres(rng, lo, hi, radii, obstacles=None, obstacle_radii=None, gap=0.0, max_tries=20000):
    """Random sequential addition of spheres (largest first) in the box [lo, hi].

    Spheres stay inside the box and clear each other and the ``obstacles`` (centres
    (k, 3), radii (k,)) by ``gap``. The broad phase is a uniform grid of cells of side
    2 r_max + gap. Returns (centres (n, 3) in input order, NaN where not placed; number
    placed): fewer than requested when ``max_tries`` candidates in a row fail.
    """
    radii = np.asarray(radii, float)
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    order = np.argsort(-radii, kind="stable")
    rs = np.ascontiguousarray(radii[order])
    oc = np.zeros((0, 3)) if obstacles is None else np.asarray(obstacles, float).reshape(-1, 3)
    orad = np.zeros(0) if obstacle_radii is None else np.asarray(obstacle_radii, float)
    rmax = max(rs.max() if len(rs) else 0.0, orad.max() if len(orad) else 0.0)
    size = hi - lo
    cell = max(2.0 * rmax + gap, 1e-300)
    ncell = np.maximum(1, np.ceil(size / cell)).astype(np.int64)
    head = -np.ones(int(np.prod(ncell)), np.int64)
    n_tot = len(oc) + len(rs)
    nxt = -np.ones(n_tot, np.int64)
    allc = np.zeros((n_tot, 3))
    allr = np.zeros(n_tot)
    for k in range(len(oc)):  # obstacles into the grid (clipped to the box)
        ci = np.clip(((oc[k] - lo) / cell).astype(np.int64), 0, ncell - 1)
        flat = int(ci[0] + ncell[0] * (ci[1] + ncell[1] * ci[2]))
        allc[k] = oc[k]
        allr[k] = orad[k]
        nxt[k] = head[flat]
        head[flat] = k
    placed = np.zeros((len(rs), 3))
    n_placed, n_all, tries = 0, len(oc), 0
    while n_placed < len(rs):
        cand = rng.random((min(65536, 64 * (len(rs) - n_placed) + 1024), 3))
        n_placed, n_all, tries, _ = _rsa(cand, lo, size, rs, placed, n_placed, tries, max_tries, head, nxt,
                                         allc, allr, n_all, cell, ncell, float(gap))
        if tries > max_tries:
            break
    out = np.full((len(rs), 3), math.nan)
    out[order[:n_placed]] = placed[:n_placed]
    return out, n_placed


# ---------------------------------------------------------------------------------------
# sizes within a class
# ---------------------------------------------------------------------------------------

def mean_sphere_volume(lower, upper):
    """Mean volume (m^3) of spheres with diameters uniform in [lower, upper]."""
    lower = np.asarray(lower, float)
    upper = np.asarray(upper, float)
    span = np.maximum(upper - lower, 1e-300)
    e_d3 = np.where(upper > lower, (upper ** 4 - lower ** 4) / (4.0 * span), lower ** 3)
    return math.pi / 6.0 * e_d3


def draw_diameters(rng, lower, upper, n):
    """n diameters uniform in [lower, upper] (m)."""
    return rng.uniform(lower, upper, n) if upper > lower else np.full(n, float(lower))


def diameters_for_volume(rng, lower, upper, volume):
    """Diameters uniform in [lower, upper] drawn until their sphere volume reaches ``volume``
    (the last one kept when that brings the total closer to it)."""
    out = []
    total = 0.0
    batch = max(16, int(volume / mean_sphere_volume(lower, upper) * 1.2) + 1)
    while total < volume:
        for d in draw_diameters(rng, lower, upper, batch):
            v = math.pi / 6.0 * d ** 3
            if total + v > volume:
                if (total + v - volume) < (volume - total):
                    out.append(d)
                    total += v
                return np.array(out)
            out.append(d)
            total += v
    return np.array(out)
