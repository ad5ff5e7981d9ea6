"""``assemble`` stage: draw a graded set of polyhedra from the ballast library and place it.

Seed 002, section 2, steps 1-5 (Shao, Lian & Yang 2017), on the classes and volumes
of the ``gradation`` state and the library of the ``ballast_library`` state:

1. start count per class n_j from the gradation's 40 mm-cube estimate
   (``gradation/class_count``, n_j = P_j V_c / d_m^3);
2. pick n_j distinct library entries of the class at random;
3. while the picked volume is below the class volume V_j, add a random unpicked
   entry; while above, drop a random picked one; of the last two totals keep the one
   closer to V_j, so each class ends within half a particle of its volume;
4. put the classes together in a random order, then
5. shuffle all particles.

Needle (elongated) and flaky particles: with ``needle_share`` and/or ``flaky_share``
(mass fractions of each class) the class volume is split into pools (needle;
flaky and not needle; neither) and steps 1-3 run in each pool. Without them the
picks ignore shape and the shares are whatever the library holds.

Placement: each particle gets a uniform random orientation (Shoemake 1992), then
(``placement: drop``, the default) the particles are dropped one by one, in the
shuffled order, onto a height map of the growing stack: a ballistic deposition
without rolling (Visscher & Bolsterli 1972, Nature 239, in its simplest, sticking
form). Each particle is tried at ``tries`` random (x, y) inside the box's side
walls, kept where it comes to rest lowest, and slid downhill a few steps; the height
map only samples the surfaces at grid points, so every particle is finally checked
against its neighbours with the exact separating-axis test
(:mod:`demcli.geometry.intersect`) and lifted until it is at least ``clearance / 2``
from each. The stack starts on the box floor and rises above the box top as far as
it must (a loose, non-overlapping start for gravity deposition: some 20 % solids,
about 2.5 box heights for the seed's beds). ``placement: shelf`` packs the rotated
bounding boxes in rows and layers instead: simpler, faster, twice as tall.

State: ``bodies`` (centroid, principal-frame orientation, mass, principal inertia),
``polyhedra`` and ``polyhedron_shapes`` (:mod:`demcli.state.polyhedra`); ``spheres``
is empty. Records: ``gradation_check`` (target and achieved passing at every sieve,
CSV and PNG of both curves) and ``classes`` (target and achieved volume per class).
A VTU snapshot of the polyhedra goes to ``<run>/<stage>/polyhedra.pvd``.
"""

import math

import numpy as np

from demcli.config.schema import Bool, Float, Int, Optional, Section, Str, Vector
from demcli.errors import StageError
from demcli.stages.base import StageType, earlier_stage, register_stage
from demcli.state.records import describe_column

for _name, _label, _unit, _table, _doc in [
        ("target", "Target passing", "%", "gradation_check", "mass percent passing the sieve, as asked"),
        ("achieved", "Achieved passing", "%", "gradation_check", "mass percent passing, sieving the drawn set"),
        ("target", "Target volume", "cm^3", "classes", "solid volume of the class, as asked"),
        ("achieved", "Achieved volume", "cm^3", "classes", "solid volume of the class drawn")]:
    describe_column(_name, _label, _unit, table=_table, doc=_doc)


def _check(node, report):
    for d in range(3):
        if node.box.max[d] <= node.box.min[d]:
            report(f"box.max.{d}", f"must be > box.min ({node.box.min[d]:g} m)", node.box.max[d])
    total = (node.needle_share or 0.0) + (node.flaky_share or 0.0)
    if total > 1.0:
        report("flaky_share", f"needle_share + flaky_share must not exceed 1 (got {total:g})", node.flaky_share)


def _case_check(cfg, case, k, scene, report):
    """Every class with a volume must be one a library covers (a positive lower size)."""
    from demcli.stages.ballast.library import library_classes
    from demcli.stages.specimen.gradation import compute

    grading = earlier_stage(case, k, "gradation")
    if grading is None:
        return
    res = compute(grading)
    covered = set(library_classes(res["class_lower"], res["class_upper"]).tolist())
    for j, (lo, hi, share) in enumerate(zip(res["class_lower"], res["class_upper"], res["class_share"])):
        if res["class_amount"][j] > 0 and j not in covered:
            report("", f"size class {lo * 1e3:g}-{hi * 1e3:g} mm of stage {grading.name!r} holds {share:g} % of the "
                   "mass but a library has no particles for it (a library covers classes with a positive lower "
                   "size)", hint="set the gradation's volumetrics.min_size")


FIELDS = {
    "box": Section({
        "min": Vector(3, "m", default=[0.0, 0.0, 0.0], doc="lower corner (floor)"),
        "max": Vector(3, "m", doc="upper corner"),
    }, doc="the ballast box: particles are stacked from its floor up, inside its side walls"),
    "material": Str(doc="material of the particles"),
    "needle_share": Optional(Float(min=0, max=1), doc="needle (elongated) particles: mass fraction of each class"),
    "flaky_share": Optional(Float(min=0, max=1), doc="flaky particles: mass fraction of each class"),
    "placement": Str(choices=["drop", "shelf"], default="drop",
                     doc="drop: ballistic deposition on a height map, exact-checked; shelf: rows of bounding boxes"),
    "clearance": Float("m", min=0, default="2 mm",
                       doc="gap between placed particles (drop: at least half of it, checked exactly)"),
    "tries": Int(min=1, default=8, doc="drop placement: random (x, y) tried per particle, the lowest kept"),
    "slide": Int(min=0, default=8, doc="drop placement: downhill moves tried after the drop"),
    "snapshot": Bool(default=True, doc="write a VTU snapshot of the polyhedra"),
}


# ---------------------------------------------------------------------------------------
# picking (seed 002, section 2, steps 2-3)
# ---------------------------------------------------------------------------------------

def pick_to_volume(rng, volumes, target, n_start):
    """Random distinct picks whose total volume is within half a particle of ``target``.

    volumes (n,): the pool; target: the volume to reach (same unit); n_start: the
    initial count. Returns the picked indices (random order) or None when the whole
    pool is short of the target.
    """
    n_pool = len(volumes)
    order = rng.permutation(n_pool)
    n = int(min(max(n_start, 0), n_pool))
    total = float(volumes[order[:n]].sum())
    if total < target:
        while total < target and n < n_pool:
            total += float(volumes[order[n]])
            n += 1
        if total < target:
            return None
        if n > 0 and total - target > target - (total - float(volumes[order[n - 1]])):
            n -= 1
    else:
        while total > target and n > 0:
            n -= 1
            total -= float(volumes[order[n]])
        if n < n_pool and (total + float(volumes[order[n]])) - target < target - total:
            n += 1
    return order[:n]


def _pools(flags_needle, flags_flaky, needle_share, flaky_share):
    """(mask, share of the class volume) of each pool for the requested shares."""
    needle, flaky = flags_needle, flags_flaky & ~flags_needle
    if needle_share is None and flaky_share is None:
        return [(np.ones(len(needle), bool), 1.0)]
    pools = []
    rest = np.ones(len(needle), bool)
    left = 1.0
    if needle_share is not None:
        pools.append((needle, needle_share))
        rest &= ~needle
        left -= needle_share
    if flaky_share is not None:
        mask = flaky if needle_share is not None else flags_flaky
        pools.append((mask, flaky_share))
        rest &= ~mask
        left -= flaky_share
    pools.append((rest, max(left, 0.0)))
    return pools


def pick_classes(rng, lib, gradation, needle_share=None, flaky_share=None):
    """Library rows of the assembly and the size class of each (seed 002 steps 1-5).

    Returns (rows (n,), class index into the gradation (n,), per-class report rows).
    """
    lower, upper = gradation["class_lower"], gradation["class_upper"]
    amount, estimate = gradation["class_amount"], gradation["class_count"]
    sets, report = [], []
    p = lib.particles
    for j in range(len(lower)):
        if amount[j] <= 0.0:
            continue
        k = lib.find_class(lower[j], upper[j])
        if k is None:
            raise StageError(f"size class {lower[j] * 1e3:g}-{upper[j] * 1e3:g} mm holds "
                             f"{gradation['class_share'][j]:g} % of the mass but the library has no particles "
                             "for it (a library covers classes with a positive lower size: set the gradation's "
                             "volumetrics.min_size)")
        rows = lib.class_rows(k)
        picked = []
        for mask, share in _pools(p["elongated"][rows], p["flaky"][rows], needle_share, flaky_share):
            target = share * amount[j]
            if target <= 0.0:
                continue
            pool = rows[mask]
            got = pick_to_volume(rng, p["volume"][pool], target, round(share * estimate[j]))
            if got is None:
                have = p["volume"][pool].sum()
                need = math.ceil(len(rows) * target / max(have, 1e-300))
                raise StageError(f"size class {lower[j] * 1e3:g}-{upper[j] * 1e3:g} mm needs "
                                 f"{target * 1e6:.4g} cm^3 from {'all' if share == 1.0 else 'a pool of'} its "
                                 f"{len(pool)} library particles, which hold only {have * 1e6:.4g} cm^3; raise "
                                 f"the library's per_class to about {need} or more")
            picked.append(pool[got])
        chosen = np.concatenate(picked) if picked else np.zeros(0, np.int64)
        sets.append((j, chosen))
        vol = p["volume"][chosen]
        report.append(dict(j=j, lower=lower[j], upper=upper[j], target=amount[j], achieved=vol.sum(),
                           count=len(chosen), largest=vol.max() if len(vol) else 0.0,
                           needle=100.0 * vol[p["elongated"][chosen]].sum() / max(vol.sum(), 1e-300),
                           flaky=100.0 * vol[p["flaky"][chosen]].sum() / max(vol.sum(), 1e-300)))
    if not sets:
        raise StageError("the gradation asks for no particles (every class volume is zero)")
    order = rng.permutation(len(sets))  # step 4: the classes in random order
    rows = np.concatenate([sets[i][1] for i in order])
    cls = np.concatenate([np.full(len(sets[i][1]), sets[i][0], np.int64) for i in order])
    perm = rng.permutation(len(rows))  # step 5: then the particles
    return rows[perm], cls[perm], report


# ---------------------------------------------------------------------------------------
# placement
# ---------------------------------------------------------------------------------------

def random_quaternions(rng, n):
    """Uniform random unit quaternions (w, x, y, z) (Shoemake 1992, "Uniform random rotations")."""
    u1, u2, u3 = rng.random((3, n))
    a, b = np.sqrt(1.0 - u1), np.sqrt(u1)
    return np.stack([b * np.cos(2 * np.pi * u3), a * np.sin(2 * np.pi * u2), a * np.cos(2 * np.pi * u2),
                     b * np.sin(2 * np.pi * u3)], axis=1)


def shelf_pack(lo, hi, box_min, box_max, clearance):
    """Centroid positions packing the boxes [x + lo_i, x + hi_i] in rows, rows in layers.

    lo, hi (n, 3): each body's bounding box relative to its centroid; in the given
    order, boxes widened by ``clearance`` go along x from the box's x-min, a new row
    starts (further along y) when x runs out, a new layer (higher up) when y runs out.
    Returns (x (n, 3), top of the stack).
    """
    size = hi - lo + clearance
    span = np.asarray(box_max, float) - np.asarray(box_min, float)
    if np.any(size[:, 0] > span[0]) or np.any(size[:, 1] > span[1]):
        raise StageError(f"a particle's bounding box ({size[:, :2].max(axis=0) * 1e3} mm) does not fit the box "
                         f"floor ({span[0] * 1e3:g} x {span[1] * 1e3:g} mm)")
    pos = np.empty_like(lo)
    x = y = z = 0.0
    row_depth = layer_height = 0.0
    for i in range(len(lo)):
        sx, sy, sz = size[i]
        if x + sx > span[0]:
            x, y = 0.0, y + row_depth
            row_depth = 0.0
        if y + sy > span[1]:
            x, y, z = 0.0, 0.0, z + layer_height
            row_depth = layer_height = 0.0
        pos[i] = np.asarray(box_min, float) + np.array([x, y, z]) + 0.5 * clearance - lo[i]
        x += sx
        row_depth = max(row_depth, sy)
        layer_height = max(layer_height, sz)
    return pos, float(box_min[2] + z + layer_height)


_VERTICAL = np.array([[0.0, 0.0, 1.0]])


def _shadow(normals, offsets, px, py):
    """Lower and upper surface heights of a convex body (centroid at the origin) over the
    points (px, py); z_low > z_high where the vertical line misses the body."""
    nz = normals[:, 2]
    rhs = offsets[None, :] - np.stack([px, py], axis=1) @ normals[:, :2].T  # n_z z <= rhs on each face
    down, up, side = nz < -1e-12, nz > 1e-12, np.abs(nz) <= 1e-12
    z_low = np.max(rhs[:, down] / nz[down], axis=1) if down.any() else np.full(len(px), -np.inf)
    z_high = np.min(rhs[:, up] / nz[up], axis=1) if up.any() else np.full(len(px), np.inf)
    if side.any():
        outside = np.any(rhs[:, side] < 0.0, axis=1)
        z_low[outside], z_high[outside] = np.inf, -np.inf
    return z_low, z_high


def drop_pack(rng, bodies, box_min, box_max, clearance, tries=4, slide=0, max_cells=4_000_000):
    """Ballistic deposition on a height map, checked with the exact separating-axis test.

    bodies: per body (Convex rotated to the world with its centroid at the origin, its
    face normals, its face offsets), as made by :func:`rotated_shapes`. In the given order
    each body is tried at ``tries`` random (x, y) inside the box's side walls and
    dropped onto a height map of what lies below (the largest top height over each
    grid point, plus ``clearance``); the lowest try is kept and then slid downhill
    (``slide`` moves of a quarter of its width, halved when no move goes lower). The
    map samples the surfaces at grid points only, so the body is finally checked
    against every placed neighbour with the exact test and lifted until it is at
    least ``clearance / 2`` from each. Returns (x (n, 3), top of the stack).
    """
    from demcli.geometry.intersect import Convex, separated, separation

    box_min, box_max = np.asarray(box_min, float), np.asarray(box_max, float)
    lo = np.array([b.vertices.min(axis=0) for b, _, _ in bodies]).reshape(-1, 3)
    hi = np.array([b.vertices.max(axis=0) for b, _, _ in bodies]).reshape(-1, 3)
    span = box_max - box_min
    h = max(0.15 * float(np.percentile(np.min(hi - lo, axis=1), 10)) if len(lo) else 1.0,
            np.sqrt(span[0] * span[1] / max_cells))
    nxg, nyg = max(1, int(span[0] / h)), max(1, int(span[1] / h))
    gx = box_min[0] + (np.arange(nxg) + 0.5) * span[0] / nxg
    gy = box_min[1] + (np.arange(nyg) + 0.5) * span[1] / nyg
    height = np.full((nxg, nyg), box_min[2])
    pos = np.zeros((len(bodies), 3))
    for i, (conv, normals, offsets) in enumerate(bodies):
        xlo, xhi = box_min[:2] + clearance - lo[i, :2], box_max[:2] - clearance - hi[i, :2]
        if np.any(xhi < xlo):
            raise StageError(f"a particle ({(hi[i] - lo[i]) * 1e3} mm across) does not fit the box floor "
                             f"({span[0] * 1e3:g} x {span[1] * 1e3:g} mm)")
        def drop(cx, cy):
            ix = np.flatnonzero((gx >= cx + lo[i, 0]) & (gx <= cx + hi[i, 0]))
            iy = np.flatnonzero((gy >= cy + lo[i, 1]) & (gy <= cy + hi[i, 1]))
            px = np.repeat(gx[ix] - cx, len(iy))
            py = np.tile(gy[iy] - cy, len(ix))
            z_low, z_high = _shadow(normals, offsets, px, py)
            inside = z_low <= z_high
            under = height[np.repeat(ix, len(iy)), np.tile(iy, len(ix))]
            cz = box_min[2] + clearance - lo[i, 2]
            if inside.any():
                cz = max(cz, float(np.max(under[inside] - z_low[inside])) + clearance)
            return cx, cy, cz, ix, iy, z_high, inside

        best = None
        for _ in range(tries):
            cand = drop(*rng.uniform(xlo, xhi))
            if best is None or cand[2] < best[2]:
                best = cand
        # slide downhill: steps in four directions, halved when none goes lower
        step = 0.25 * float(np.min(hi[i, :2] - lo[i, :2]))
        for _ in range(slide):
            moved = False
            for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1)):
                cxy = np.clip([best[0] + dx * step, best[1] + dy * step], xlo, xhi)
                cand = drop(*cxy)
                if cand[2] < best[2] - 1e-9:
                    best, moved = cand, True
                    break
            if not moved:
                step *= 0.5
        cx, cy, cz, ix, iy, z_high, inside = best
        # exact check against the placed neighbours (world boxes closer than the clearance); lift until clear
        for _ in range(10000):
            c = np.array([cx, cy, cz])
            near = np.flatnonzero(np.all((pos[:i] + lo[:i] < c + hi[i] + clearance)
                                         & (c + lo[i] < pos[:i] + hi[:i] + clearance), axis=1))
            moved = Convex(conv.vertices + c, conv.normals, conv.directions)
            worst = None
            for j in near:
                other = Convex(bodies[j][0].vertices + pos[j], bodies[j][0].normals, bodies[j][0].directions)
                if not separated(moved, other, 0.5 * clearance, hints=_VERTICAL):
                    worst = min(separation(moved, other)[0], np.inf if worst is None else worst)
            if worst is None:
                break
            cz += max(clearance - worst, 0.1 * clearance, 1e-9)
        else:
            raise StageError(f"particle {i} could not be placed clear of its neighbours")
        pos[i] = cx, cy, cz
        if inside.any():
            cols = np.repeat(ix, len(iy))[inside], np.tile(iy, len(ix))[inside]
            height[cols] = np.maximum(height[cols], cz + z_high[inside])
    top = float(np.max(pos[:, 2] + hi[:, 2])) if len(pos) else float(box_min[2])
    return pos, top


def rotated_shapes(table, rot):
    """The polyhedra of ``table`` turned by the rotation matrices ``rot``, as :func:`drop_pack` takes
    them: per body (Convex rotated to the world with its centroid at the origin, face normals, offsets)."""
    from demcli.geometry.intersect import Convex

    out = []
    for k in range(len(table)):
        v, _, normals, offsets, edges = table.shape(k)
        d = v[edges[:, 1]] - v[edges[:, 0]]
        d = d / np.linalg.norm(d, axis=1)[:, None]
        r = rot[k]
        n = normals @ r.T
        out.append((Convex(v @ r.T, n, d @ r.T), n, offsets))
    return out


# ---------------------------------------------------------------------------------------
# the stage
# ---------------------------------------------------------------------------------------

def run(ctx, cfg, state_in):
    import json

    from demcli.geometry import sieve_set
    from demcli.stages.ballast.library import ensure_library
    from demcli.state import RecordTable
    from demcli.state.polyhedra import rotation_matrices

    g = {k: np.asarray(v) for k, v in state_in.groups["gradation"].items()}
    attrs = state_in.group_attrs["library"]
    gen = json.loads(attrs["generator"])
    path = attrs["path"]
    lib, path, info = ensure_library(gen, path=path, log=ctx.log)
    if info["built"]:
        ctx.log(f"library file was missing; rebuilt {path}")
    rng = ctx.rng
    rows, cls, report = pick_classes(rng, lib, g, cfg.needle_share, cfg.flaky_share)
    n = len(rows)
    q = random_quaternions(rng, n)
    shapes = lib.shapes.subset(rows)
    rot = rotation_matrices(q)
    box_min, box_max = np.array(cfg.box.min), np.array(cfg.box.max)
    if cfg.placement == "drop":
        x, top = drop_pack(rng, rotated_shapes(shapes, rot), box_min, box_max, cfg.clearance, tries=cfg.tries,
                           slide=cfg.slide)
    else:
        owner = np.repeat(np.arange(n), np.diff(shapes.vertex_start))
        world = np.einsum("nij,nj->ni", rot[owner], shapes.vertices)
        lo = np.full((n, 3), np.inf)
        hi = np.full((n, 3), -np.inf)
        np.minimum.at(lo, owner, world)
        np.maximum.at(hi, owner, world)
        x, top = shelf_pack(lo, hi, box_min, box_max, cfg.clearance)

    mats = list(ctx.case.materials)
    density = ctx.case.materials[cfg.material].density
    p = lib.particles
    state = ctx.new_state()
    state.groups["bodies"] = {
        "x": x, "v": np.zeros((n, 3)), "q": q, "omega": np.zeros((n, 3)), "mass": density * shapes.volume,
        "inertia": density * shapes.inertia, "id": np.arange(n, dtype=np.int64), "flags": np.zeros(n, np.int8)}
    state.groups["spheres"] = {"body": np.zeros(0, np.int64), "offset": np.zeros((0, 3)), "radius": np.zeros(0),
                               "material": np.zeros(0, np.int64)}
    state.groups["polyhedra"] = {
        "shape": np.arange(n, dtype=np.int64), "material": np.full(n, mats.index(cfg.material), np.int64),
        "size_class": cls, "sieve_size": p["sieve_size"][rows], "library_index": rows.astype(np.int64),
        "flaky": p["flaky"][rows], "elongated": p["elongated"][rows]}
    state.groups["polyhedron_shapes"] = shapes.to_group()
    state.groups["gradation"] = g
    state.groups["library"] = {k: np.asarray(v) for k, v in state_in.groups["library"].items()}
    state.group_attrs["library"] = dict(attrs)

    # gradation check: target against achieved passing at every sieve
    sieves, target = g["sieves"], g["passing"]
    achieved = sieve_set(p["sieve_size"][rows], shapes.volume, sieves)
    check = RecordTable("gradation_check", {"sieve": "mm", "target": "%", "achieved": "%", "difference": "pp"})
    for s, t, a in zip(sieves, target, achieved):
        check.append(sieve=s * 1e3, target=float(t), achieved=float(a), difference=round(float(a - t), 9) + 0.0)
    classes = RecordTable("classes", {"lower": "mm", "upper": "mm", "target": "cm^3", "achieved": "cm^3",
                                      "difference": "%", "largest": "cm^3", "count": "", "needle": "%", "flaky": "%"})
    for r in report:
        classes.append(lower=r["lower"] * 1e3, upper=r["upper"] * 1e3, target=r["target"] * 1e6,
                       achieved=r["achieved"] * 1e6, difference=100.0 * (r["achieved"] / r["target"] - 1.0),
                       largest=r["largest"] * 1e6, count=r["count"], needle=r["needle"], flaky=r["flaky"])
    check.to_state(state)
    classes.to_state(state)
    ctx.write_records(check, x="sieve", ys=["target", "achieved"], logx=True)
    ctx.write_records(classes, x="upper", ys=["target", "achieved"])

    solids = shapes.volume.sum()
    ctx.log(f"{n} particles, {solids * 1e6:.5g} cm^3 of solids (target {g['class_amount'].sum() * 1e6:.5g} cm^3), "
            f"{density * solids:.4g} kg; needle {100 * shapes.volume[p['elongated'][rows]].sum() / solids:.1f} %, "
            f"flaky {100 * shapes.volume[p['flaky'][rows]].sum() / solids:.1f} % by mass")
    for r in report:
        ctx.log(f"  class {r['lower'] * 1e3:g}-{r['upper'] * 1e3:g} mm: {r['count']} particles, "
                f"{r['achieved'] * 1e6:.5g} of {r['target'] * 1e6:.5g} cm^3 "
                f"({r['achieved'] - r['target']:+.3g} m^3, largest particle {r['largest'] * 1e6:.3g} cm^3)")
    ctx.log("  sieve [mm]  target [%]  achieved [%]  difference [pp]")
    for s, t, a in zip(sieves, target, achieved):
        ctx.log(f"  {s * 1e3:9.4g}  {t:10.2f}  {a:12.2f}  {round(a - t, 9) + 0.0:+15.2f}")
    ctx.log(f"placed without overlap in {cfg.box.max[0] - cfg.box.min[0]:g} x {cfg.box.max[1] - cfg.box.min[1]:g} m, "
            f"stack from z = {box_min[2]:g} to {top:.3f} m (box top {box_max[2]:g} m); library {lib.hash[:12]}")
    if cfg.snapshot:
        from demcli.state.vtu_poly import PolyhedraSnapshots

        files = PolyhedraSnapshots(ctx.snapshot_dir).write(state)
        ctx.log(f"snapshot {files[0]}")
    return state


register_stage(StageType(
    "assemble", FIELDS, run, needs_input=True, check=_check, case_check=_case_check,
    requires=("gradation/sieves", "gradation/passing", "gradation/class_lower", "gradation/class_upper",
              "gradation/class_amount", "gradation/class_count", "library/path", "library/generator"),
    provides=("bodies/*", "spheres/*", "polyhedra/*", "polyhedron_shapes/*", "records/*"),
    keeps=("gradation", "library"),
    doc="draw a graded set of polyhedra from the ballast library (Shao et al. 2017) and stack it in the box"))
