"""The packing record of a dem stage (``output.packing``): solid fraction and coordination in a
sampling window away from the walls, at every record row.

The window is an axis-aligned box: the one given (``window: {min, max}``), or a box shrunk by
``margin`` mean body diameters d on each side (d = 2 x the mean bounding radius of the bodies,
the stop criterion's d), recomputed at every record: the bodies' bounding box (``around:
bodies``, the default), or the walls' (``around: walls``: along each axis the innermost
axis-aligned plane walls, box faces included; the bodies' extent where an axis has no such wall,
an open top). In 2D (planar) cases the window is its x-y rectangle (z plays no part).
Columns (table ``packing``, file ``records/<stage>_packing.csv``):

* time [s], step;
* solid_fraction: the bodies' volume inside the window / the window's volume (2D: the disks'
  area inside the window's rectangle / its area). A sphere cut by the window counts its exact
  part (:func:`demcli.geometry.window.sphere_box_volume`, closed form; 2D
  :func:`~demcli.geometry.window.disk_rectangle_area`), a polyhedron its exact part (its convex
  intersection with the box, :func:`~demcli.geometry.window.convex_box_volume`). A clump's volume
  is its body's, mass / density (the union of its overlapping members, as the clump's mass
  was integrated: demcli/engine/clumps.py), not the sum of its members'; a clump wholly inside
  counts it whole. A clump the window cuts counts, by inclusion-exclusion, its members' exact
  parts inside less the parts inside of the lenses its members share, and that last term is
  the approximation: each lens (:func:`~demcli.geometry.window.sphere_lens`) is taken as the
  ball of its volume at its centroid, and the lenses' parts are scaled by the clump's excess
  sum |s_k| - V_body over the sum of its lens volumes (which triple overlaps make smaller than
  the sum of the lenses). It is exact for a clump without overlaps and for a cut that leaves
  each lens wholly inside or outside; a cut through a lens errs by at most that lens's part,
  a few % of the clump's volume for members overlapping by half a radius. (2D clumps: the
  members' areas inside x V_body / their sum, V_body = mass / (density x thickness).)
* coordination: the mean number of contacts of the bodies whose centre lies in the window, less
  the rattlers. A body's contacts are the other bodies it touches (a clump pair touching at two
  member pairs is one contact; an intact bond is a contact) and the walls it touches (a box face
  is one wall). A rattler is a body with fewer than ``min_contacts`` contacts (default: with
  friction 2, the fewest that can hold a body, as a single contact cannot balance a force
  (Agnolin & Roux 2007); without, dimension + 1: 4 in 3D, 3 in 2D, the isostatic count); rattlers are removed over the whole scene, lowering their
  neighbours' counts, until none is left (bodies held fixed are never rattlers: they hold as
  walls do), and the others' contacts with rattlers do not count;
* raw_coordination: the same mean before the rattlers are removed (every body in the window);
* rattler_fraction: rattlers / bodies in the window; bodies: the bodies whose centre lies in
  the window;
* xmin, ymin, zmin, xmax, ymax, zmax [m]: the window.

An empty window (a margin wider than half the box) gives NaN fractions and coordinations and
0 bodies. Sphere, clump and polyhedron scenes; not yet a scene of spheres with polyhedra.
"""

import math

import numpy as np

from demcli.errors import InputError
from demcli.state.records import describe_column

COLUMNS = {"time": "s", "step": "1", "solid_fraction": "1", "coordination": "1", "raw_coordination": "1",
           "rattler_fraction": "1", "bodies": "1", "xmin": "m", "ymin": "m", "zmin": "m", "xmax": "m", "ymax": "m",
           "zmax": "m"}

for _name, _label, _doc in (
        ("solid_fraction", "Solid fraction", "volume of the bodies inside the sampling window / its volume (2D: "
                                             "area fraction of the disks); cut bodies count their part inside "
                                             "(demcli/stages/packing_record.py)"),
        ("coordination", "Coordination number", "mean contacts (bodies and walls) of the bodies centred in the "
                                                "window, rattlers excluded"),
        ("raw_coordination", "Coordination number with rattlers", "mean contacts of every body centred in the "
                                                                  "window"),
        ("rattler_fraction", "Rattler fraction", "bodies in the window with fewer than min_contacts contacts "
                                                 "(removed iteratively) / bodies in the window")):
    describe_column(_name, _label, table="packing", doc=_doc)
describe_column("bodies", "Bodies in the window", table="packing", integer=True,
                doc="bodies whose centre lies in the sampling window")
for _axis in "xyz":
    for _end, _word in (("min", "lower"), ("max", "upper")):
        describe_column(f"{_axis}{_end}", f"Window {_axis}{_end}", "m", "mm", 1e3, table="packing",
                        doc=f"{_word} bound of the sampling window along {_axis}")


def check_scene(system):
    """InputError for a scene the record cannot measure (spheres with polyhedra)."""
    if system.plugin.name not in ("spheres", "polyhedra"):
        raise InputError(f"output.packing: the packing record is for sphere, clump and polyhedron scenes; this one "
                         f"has {system.plugin.name} bodies (spheres with polyhedra)")


def contact_counts(n_bodies, pairs, walls, min_contacts, held):
    """Contacts per body before and after the rattlers are removed, and the rattlers.

    Args:
        n_bodies: number of bodies.
        pairs: (k, 2) int, distinct body pairs in contact (each pair once).
        walls: (k,) int, the body of each distinct body-wall contact.
        min_contacts: a body with fewer contacts is a rattler.
        held: (n_bodies,) bool, bodies that are never rattlers.

    Returns:
        (z0, z, rattler): (n_bodies,) int contacts of each body, the same counting only the
        bodies left once the rattlers have been removed one sweep after another until none is
        left (rattlers' own counts included), and (n_bodies,) bool.
    """
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    zw = np.bincount(np.asarray(walls, np.int64), minlength=n_bodies)
    i, j = pairs[:, 0], pairs[:, 1]
    z0 = zw + np.bincount(i, minlength=n_bodies) + np.bincount(j, minlength=n_bodies)
    alive = np.ones(n_bodies, bool)
    z = z0
    while True:
        keep = alive & ((z >= min_contacts) | held)
        if np.array_equal(keep, alive):
            break
        alive = keep
        ok = alive[i] & alive[j]
        z = zw + np.bincount(i[ok], minlength=n_bodies) + np.bincount(j[ok], minlength=n_bodies)
    return z0, z, ~alive


def _quat_matrices(q):
    """Rotation matrices (n, 3, 3) of unit quaternions (n, 4), scalar first."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=1)], axis=1)


class PackingProbe:
    """The ``packing`` row of a system at each record (:data:`COLUMNS`).

    Args:
        system: the stage's :class:`~demcli.engine.system.System` (spheres, clumps or polyhedra).
        spec: the validated ``output.packing`` section.
        planar: a 2D case (disks in a plane).
        thickness: the 2D case's thickness [m] (a 2D clump's area is mass / (density x thickness)).
        size: the mean body diameter d [m] a margin counts in.
        log: ``log(message)`` for a warning (an empty window), once.
    """

    def __init__(self, system, spec, planar, thickness, size, log=None, friction=False):
        from demcli.kernels.layout import FIX_TRANSLATION

        check_scene(system)
        self.planar = bool(planar)
        self.window = None if spec.window is None else (np.array(spec.window.min, float),
                                                        np.array(spec.window.max, float))
        margin = 2.0 if spec.margin is None else float(spec.margin)
        self.margin = margin * float(size)
        self.around = spec.around or "bodies"
        default = 2 if friction else 3 if self.planar else 4  # see the module docstring
        self.min_contacts = spec.min_contacts if spec.min_contacts is not None else default
        self.held = (np.asarray(system.bflags) & FIX_TRANSLATION) != 0
        self.log = log
        self._warned = False
        self.poly = system.plugin.name == "polyhedra"
        if self.poly:
            self._setup_polyhedra(system)
        else:
            self._setup_spheres(system, thickness)

    # ---- the bodies' volumes ----------------------------------------------------------------------
    def _setup_spheres(self, s, thickness):
        from demcli.geometry.window import sphere_lens

        nb = len(s.mass)
        r = np.asarray(s.rad, float)
        self.member_volume = math.pi * r ** 2 if self.planar else 4.0 / 3.0 * math.pi * r ** 3
        members = np.bincount(s.sbody, minlength=nb)
        summed = np.bincount(s.sbody, weights=self.member_volume, minlength=nb)
        first = np.zeros(nb, np.int64)  # a member of each body (its material gives the density)
        bodies, where = np.unique(s.sbody, return_index=True)
        first[bodies] = where
        density = np.array([m.density for m in s.materials], float)
        self.body_volume = summed.copy()
        self.clump = members > 1
        if np.any(self.clump):
            per = (thickness if self.planar else 1.0) * density[s.smat[first[self.clump]]]
            self.body_volume[self.clump] = s.mass[self.clump] / s.mass_scale / per
        self.summed = summed
        # 2D clumps: V_body / sum of the members' areas scales their parts inside
        self.share = np.divide(self.body_volume, summed, out=np.zeros(nb), where=summed > 0)
        # 3D clumps: the lenses of their overlapping members (i, j, centroid t from i, volume w,
        # equal-volume radius), the excess sum |s_k| - V_body they share out by volume
        li, lj = [], []
        if not self.planar and np.any(self.clump):
            order = np.argsort(s.sbody, kind="stable")
            start = np.searchsorted(s.sbody[order], np.arange(nb + 1))
            for b in np.flatnonzero(self.clump):
                m = order[start[b]:start[b + 1]]
                a, c = np.triu_indices(len(m), 1)
                li.append(m[a])
                lj.append(m[c])
        li = np.concatenate(li) if li else np.zeros(0, np.int64)
        lj = np.concatenate(lj) if lj else np.zeros(0, np.int64)
        d = np.linalg.norm(np.asarray(s.soff)[li] - np.asarray(s.soff)[lj], axis=1)
        w, t = sphere_lens(r[li], r[lj], d)
        keep = w > 0.0
        self.lens = (li[keep], lj[keep], t[keep], w[keep], np.cbrt(3.0 * w[keep] / (4.0 * math.pi)))
        lens_body = s.sbody[li[keep]]
        self.lens_total = np.bincount(lens_body, weights=w[keep], minlength=nb)
        self.excess = np.maximum(summed - self.body_volume, 0.0)

    def _clump_parts(self, s, part, lo, hi):
        """Volume of each body inside the box from its members' parts ``part``: a sphere's own;
        a clump wholly inside or outside its volume or 0; a cut clump (3D) the members' parts
        less its lenses' parts, each lens taken as the ball of its volume at its centroid, scaled
        to the clump's excess sum |s_k| - V_body; 2D: the members' parts x V_body / sum |s_k|."""
        from demcli.geometry.window import sphere_box_volume

        nb = len(s.mass)
        per_body = np.bincount(s.sbody, weights=part, minlength=nb)
        if self.planar or not np.any(self.clump):
            return self.share * per_body
        out = np.where(self.clump, 0.0, per_body)
        tol = 1e-12 * self.summed
        inside = self.clump & (per_body >= self.summed - tol)
        cut = self.clump & ~inside & (per_body > tol)
        out[inside] = self.body_volume[inside]
        if np.any(cut):
            li, lj, t, w, rho = self.lens
            sel = cut[s.sbody[li]]
            xi, xj = s.xs[li[sel]], s.xs[lj[sel]]
            axis = xj - xi
            axis /= np.maximum(np.linalg.norm(axis, axis=1), 1e-300)[:, None]
            frac = sphere_box_volume(xi + t[sel, None] * axis, rho[sel], lo, hi) / (4.0 / 3.0 * math.pi * rho[sel] ** 3)
            lens_in = np.bincount(s.sbody[li[sel]], weights=w[sel] * frac, minlength=nb)
            scale = np.divide(self.excess, self.lens_total, out=np.zeros(nb), where=self.lens_total > 0)
            out[cut] = np.clip(per_body[cut] - scale[cut] * lens_in[cut], 0.0, self.body_volume[cut])
        return out

    def _setup_polyhedra(self, s):
        from scipy.spatial import ConvexHull

        vs, verts, fs, fvs, fv, fn, fo = s.shapes
        self.shape = np.asarray(s.shape, np.int64)
        self.templates = []
        for k in range(len(vs) - 1):
            ring_edges = set()
            for f in range(fs[k], fs[k + 1]):
                ring = fv[fvs[f]:fvs[f + 1]] - vs[k]
                for a, b in zip(ring, np.roll(ring, -1)):
                    ring_edges.add((min(a, b), max(a, b)))
            v = verts[vs[k]:vs[k + 1]]
            self.templates.append((v, np.array(sorted(ring_edges), np.int64).reshape(-1, 2), fn[fs[k]:fs[k + 1]],
                                   fo[fs[k]:fs[k + 1]], float(ConvexHull(v).volume)))

    def _world_vertices(self, s):
        """World vertices of every polyhedron: a list of (n_v, 3) arrays and their rotations."""
        rot = _quat_matrices(np.asarray(s.q, float))
        return [self.templates[k][0] @ rot[b].T + s.x[b] for b, k in enumerate(self.shape)], rot

    def solid_volume(self, s, lo, hi, world=None):
        """Volume [m^3] (2D: area [m^2]) of the bodies inside the box [lo, hi]."""
        from demcli.geometry.window import convex_box_volume, disk_rectangle_area, sphere_box_volume

        if not self.poly:
            if self.planar:
                part = disk_rectangle_area(s.xs[:, :2], s.rad, lo[:2], hi[:2])
            else:
                part = sphere_box_volume(s.xs, s.rad, lo, hi)
            return float(np.sum(self._clump_parts(s, part, lo, hi)))
        world, rot = world if world is not None else self._world_vertices(s)
        total = 0.0
        for b, k in enumerate(self.shape):
            v, edges, fn, fo, volume = self.templates[k]
            w = world[b]
            if np.all(w >= lo) and np.all(w <= hi):
                total += volume
            elif np.all(w.max(axis=0) > lo) and np.all(w.min(axis=0) < hi):
                n = fn @ rot[b].T
                total += convex_box_volume(w, edges, n, fo + n @ s.x[b], lo, hi)
        return total

    # ---- the window -------------------------------------------------------------------------------
    def bounds(self, s, world=None):
        """(lo, hi) (3,) of the sampling window now."""
        if self.window is not None:
            return self.window
        if self.poly:
            pts = np.concatenate(world[0]) if world is not None else np.concatenate(self._world_vertices(s)[0])
            lo, hi = pts.min(axis=0), pts.max(axis=0)
        else:
            lo, hi = (s.xs - s.rad[:, None]).min(axis=0), (s.xs + s.rad[:, None]).max(axis=0)
        if self.around == "walls":
            lo, hi = self._wall_box(s, lo, hi)
        axes = 2 if self.planar else 3
        lo, hi = lo.copy(), hi.copy()
        lo[:axes] += self.margin
        hi[:axes] -= self.margin
        return lo, hi

    @staticmethod
    def _wall_box(s, lo, hi):
        """Along each axis the innermost axis-aligned plane walls facing into the domain; the
        bodies' ``lo``/``hi`` where there is none."""
        from demcli.kernels.walls import PLANE

        lo, hi = lo.copy(), hi.copy()
        w = s.walls
        for d in range(3):
            lows, highs = [], []
            for k in range(len(w)):
                if int(w.kind[k]) != PLANE:
                    continue
                n = w.normal[k]
                if n[d] > 1.0 - 1e-9:
                    lows.append(float(s.wpoint[k, d]))
                elif n[d] < -1.0 + 1e-9:
                    highs.append(float(s.wpoint[k, d]))
            if lows:
                lo[d] = max(lows)
            if highs:
                hi[d] = min(highs)
        return lo, hi

    # ---- the contacts -----------------------------------------------------------------------------
    @staticmethod
    def body_contacts(s):
        """(pairs (k, 2), walls (m,)): the distinct touching body pairs (i < j) and the body of each
        distinct touching body-wall pair."""
        (pi, pj), (wp, ww) = s.touching()
        of = s.plugin.body_of_primitive(s)
        a, b = of[pi], of[pj]
        pairs = np.stack([np.minimum(a, b), np.maximum(a, b)], axis=1)
        pairs = np.unique(pairs[pairs[:, 0] != pairs[:, 1]], axis=0)
        walls = np.unique(np.stack([of[wp], ww], axis=1), axis=0)[:, 0] if len(wp) else np.zeros(0, np.int64)
        return pairs, walls

    # ---- the row ----------------------------------------------------------------------------------
    def row(self, s):
        """The ``packing`` row of the system now."""
        world = self._world_vertices(s) if self.poly else None
        lo, hi = self.bounds(s, world)
        axes = 2 if self.planar else 3
        size = hi[:axes] - lo[:axes]
        row = {"time": s.time, "step": s.step}
        row.update({f"{a}min": float(lo[d]) for d, a in enumerate("xyz")})
        row.update({f"{a}max": float(hi[d]) for d, a in enumerate("xyz")})
        if np.any(size <= 0.0):
            if self.log is not None and not self._warned:
                self.log(f"output.packing: the sampling window is empty at t = {s.time:.4g} s (a margin of "
                         f"{self.margin:.4g} m on each side of a box {np.round(size + 2 * self.margin, 6).tolist()} m)")
                self._warned = True
            row.update(solid_fraction=math.nan, coordination=math.nan, raw_coordination=math.nan,
                       rattler_fraction=math.nan, bodies=0)
            return row
        row["solid_fraction"] = self.solid_volume(s, lo, hi, world) / float(np.prod(size))
        pairs, walls = self.body_contacts(s)
        z0, z, rattler = contact_counts(len(s.mass), pairs, walls, self.min_contacts, self.held)
        x = np.asarray(s.x)[:, :axes]
        inside = np.all((x >= lo[:axes]) & (x <= hi[:axes]), axis=1)
        n = int(inside.sum())
        kept = inside & ~rattler
        row["bodies"] = n
        row["raw_coordination"] = float(z0[inside].mean()) if n else math.nan
        row["coordination"] = float(z[kept].mean()) if kept.any() else math.nan
        row["rattler_fraction"] = float((inside & rattler).sum()) / n if n else math.nan
        return row
