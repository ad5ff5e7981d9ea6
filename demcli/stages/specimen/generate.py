"""``generate`` stage: spheres or rigid clumps placed without overlap in a region.

Radii follow ``radius:`` (:mod:`demcli.stages.specimen.sizes`: uniform between ``min`` and
``max`` as before, lognormal, a sieve curve by mass, or a discrete list), ``count`` of them or
as many as fill ``volume_fraction`` of the region. ``sets:`` gives several particle sets (each
with its amount, sizes, material and clump) placed together in one region; their bodies carry
``bodies/set``. The particles are placed largest first by random sequential addition, or on a simple cubic
lattice. A ``clump`` template turns each particle into a rigid body of several
spheres (member centres and radii in units of the drawn radius), with mass and
inertia of the union of its members (overlaps counted once) and a random
orientation. In 2D cases the particles are disks in the plane z = region z, with
masses per ``thickness``. With ``add: true`` the particles join the scene of the stage before
(:mod:`demcli.stages.specimen.particles`); they are placed without overlap among themselves,
not against that scene: give them a region clear of it.
"""

import math

import numpy as np

from demcli.config.schema import Float, Int, List, Optional, Section, Str, Tagged, Vector
from demcli.errors import StageError
from demcli.stages.base import StageType, register_stage
from demcli.stages.specimen.particles import ADD, check_addable, scene_or_added
from demcli.stages.specimen.sizes import SIZE, describe_size, draw_amount, draw_radii, radius_range

REGION = Tagged("shape", {
    "box": Section({"min": Vector(3, "m", doc="lower corner"), "max": Vector(3, "m", doc="upper corner")}),
    "cylinder": Section({
        "base": Vector(3, "m", doc="centre of the bottom face"),
        "radius": Float("m", min=0, min_inclusive=False),
        "height": Float("m", min=0),
    }),
}, doc="where particle centres may go (the whole particle stays inside)")


SET_KEYS = ("count", "volume_fraction", "radius", "material", "clump")


def _check_amount(node, report):
    if node.count is None and node.volume_fraction is None:
        report("count", "required key is missing (or give volume_fraction)")
    elif node.count is not None and node.volume_fraction is not None:
        report("volume_fraction", "give either count or volume_fraction, not both", node.volume_fraction)


def _check(node, report):
    if node.sets is not None:
        given = [key for key in SET_KEYS if node[key] is not None]
        if given:
            report(given[0], "give the particles either as sets or at the top level, not both", node[given[0]])
    else:
        for key in ("radius", "material"):
            if node[key] is None:
                report(key, "required key is missing (or give sets)")
        _check_amount(node, report)
    if node.placement == "lattice" and node.region.shape != "box":
        report("placement", "lattice placement needs region shape: box", node.placement)
    if node.region.shape == "box":
        for d in range(3):
            if node.region.max[d] < node.region.min[d]:
                report(f"region.max.{d}", f"must be >= region.min ({node.region.min[d]:g} m)", node.region.max[d])


CLUMP = Optional(Section({
    "spheres": List(Vector(4), min_len=1, doc="member [x, y, z, r] in units of the particle radius"),
    "resolution": Int(min=16, default=96, doc="voxels along the clump for mass properties"),
}), doc="rigid clump template (omit for single spheres)")
COUNT = Optional(Int(min=1), doc="number of particles (or give volume_fraction)")
FRACTION = Optional(Float(min=0, max=1, min_inclusive=False),
                    doc="solid volume (2D: area) of the particles over the region's volume (or give count)")
SET = Section({"count": COUNT, "volume_fraction": FRACTION, "radius": SIZE, "material": Str(doc="material name"),
               "clump": CLUMP}, check=_check_amount, doc="one particle set")

FIELDS = {
    "region": REGION,
    "count": COUNT,
    "volume_fraction": FRACTION,
    "radius": Optional(SIZE, doc="particle radius distribution (without distribution: uniform between min and max)"),
    "material": Optional(Str(), doc="material name"),
    "placement": Str(choices=["random", "lattice"], default="random"),
    "velocity": Float("m/s", min=0, default=0.0, doc="random initial velocity, uniform in +-value per component"),
    "clump": CLUMP,
    "sets": Optional(List(SET, min_len=1), doc="several particle sets in one region, each with its count or "
                     "volume_fraction, radius, material and clump (instead of those keys at the top level)"),
    "add": ADD,
}


def particle_sets(cfg):
    """The stage's particle sets: ``cfg.sets``, or the stage itself for the single-set form
    (each has count, volume_fraction, radius, material and clump)."""
    return list(cfg.sets) if cfg.sets is not None else [cfg]


def region_amount(region, planar):
    """Volume of the region (m^3), or in 2D its area in the plane (m^2)."""
    if region.shape == "box":
        size = np.subtract(region.max, region.min)
        return float(size[0] * size[1] * (1.0 if planar else size[2]))
    return math.pi * region.radius ** 2 * (1.0 if planar else region.height)


def _set_radii(rng, st, region, planar):
    """Radii (m) of one set: ``count`` draws, or draws until ``volume_fraction`` of the region."""
    if st.count is not None:
        return draw_radii(rng, st.radius, st.count)
    return draw_amount(rng, st.radius, st.volume_fraction * region_amount(region, planar), planar)


def _expected_count(st, region, planar):
    """The set's count, or for a volume fraction the count expected from 4096 trial draws."""
    if st.count is not None:
        return st.count
    r = draw_radii(np.random.default_rng(0), st.radius, 4096)
    each = float(np.mean(math.pi * r ** 2 if planar else 4.0 / 3.0 * math.pi * r ** 3))
    return max(1, int(math.ceil(st.volume_fraction * region_amount(region, planar) / each)))


def _random_quaternions(rng, n):
    """Uniform random unit quaternions (Shoemake 1992), scalar first."""
    u1, u2, u3 = rng.random((3, n))
    a, b = np.sqrt(1 - u1), np.sqrt(u1)
    return np.stack([b * np.cos(2 * np.pi * u3), a * np.sin(2 * np.pi * u2), a * np.cos(2 * np.pi * u2),
                     b * np.sin(2 * np.pi * u3)], axis=1)


def _region_box(region):
    if region.shape == "box":
        return np.array(region.min), np.array(region.max)
    b = np.array(region.base)
    return b - [region.radius, region.radius, 0], b + [region.radius, region.radius, region.height]


def _lattice_counts(lo, hi, a, planar):
    """Sites along x, y, z of the simple cubic lattice of spacing ``a`` in the box lo-hi."""
    counts = [max(1, int(math.floor((hi[d] - lo[d]) / a))) for d in range(3)]
    if planar:
        counts[2] = 1
    return counts


def _lattice(lo, hi, radii, planar):
    """Simple cubic lattice, spacing 2.02 r_max, filled x fastest."""
    a = 2.02 * radii.max()
    counts = _lattice_counts(lo, hi, a, planar)
    idx = np.arange(len(radii))  # (validation checks that the lattice has room: _case_check)
    pos = np.empty((len(radii), 3))
    pos[:, 0] = lo[0] + (idx % counts[0] + 0.5) * a
    pos[:, 1] = lo[1] + ((idx // counts[0]) % counts[1] + 0.5) * a
    pos[:, 2] = lo[2] + (idx // (counts[0] * counts[1]) + 0.5) * a if not planar else 0.5 * (lo[2] + hi[2])
    return pos


def _envelope(st):
    """Radius of a particle's bounding sphere in units of its drawn radius (1 for a sphere)."""
    if st.clump is None:
        return 1.0
    t = np.array(st.clump.spheres, float)
    return float(np.max(np.linalg.norm(t[:, :3], axis=1) + t[:, 3]))


def _case_check(cfg, case, k, scene, report):
    """What the case decides: 2D clumps, the materials, the lattice's room, and the memory of the particles."""
    from demcli.config.memory import check_memory

    check_addable(cfg, scene, report)
    planar = case.dimension == 2
    sets = particle_sets(cfg)
    prefix = (lambda j: f"sets.{j}.") if cfg.sets is not None else (lambda j: "")
    for j, st in enumerate(sets):
        if planar and st.clump is not None:
            report(prefix(j) + "clump", "clumps are 3D only in this version; use dimension: 3")
    counts = [_expected_count(st, cfg.region, planar) for st in sets]
    if cfg.placement == "lattice":
        lo, hi = _region_box(cfg.region)
        a = 2.02 * max(radius_range(st.radius)[1] * _envelope(st) for st in sets)
        sites = int(np.prod(_lattice_counts(lo, hi, a, planar)))
        if sum(counts) > sites:
            report("count" if cfg.sets is None else "sets", f"the region's lattice (spacing {a:.4g} m) has {sites} "
                   "sites", sum(counts), "enlarge the region, lower the count or use placement: random")
    members = sum(n * (len(st.clump.spheres) if st.clump is not None else 1) for n, st in zip(counts, sets))
    check_memory(report, "count" if cfg.sets is None else "sets", members, "the generated particles", sum(counts))


def _sphere_properties(density, radii, planar, thickness):
    """Mass (kg) and principal inertia (kg m^2, (n, 3)) of spheres (2D: disks of ``thickness``):
    m = rho 4/3 pi r^3, I = 2/5 m r^2 (disk: m = rho t pi r^2, I = 1/2 m r^2)."""
    if planar:
        mass = density * thickness * np.pi * radii ** 2
        return mass, np.repeat((0.5 * mass * radii ** 2)[:, None], 3, axis=1)
    mass = density * 4.0 / 3.0 * np.pi * radii ** 3
    return mass, np.repeat((0.4 * mass * radii ** 2)[:, None], 3, axis=1)


def _assemble(ctx, sets, set_of, radii, rng):
    """Per-body mass, inertia and orientation, and the member spheres (grouped by body in body
    order) of bodies whose set is ``set_of`` (n,) and drawn radius ``radii`` (n,), m. A clump
    set's orientations are drawn (in set order) after everything else."""
    from demcli.engine.clumps import union_mass_properties

    n = len(radii)
    planar = ctx.case.dimension == 2
    k = np.array([len(st.clump.spheres) if st.clump is not None else 1 for st in sets], np.int64)[set_of]
    start = np.concatenate([[0], np.cumsum(k)[:-1]]).astype(np.int64)
    ns = int(k.sum())
    mass, inertia, q = np.empty(n), np.empty((n, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    sphere = {"body": np.repeat(np.arange(n, dtype=np.int64), k), "offset": np.zeros((ns, 3)),
              "radius": np.empty(ns), "material": np.empty(ns, np.int64)}
    for j, st in enumerate(sets):
        idx = np.flatnonzero(set_of == j)
        r = radii[idx]
        density = ctx.case.materials[st.material].density
        sphere["material"][set_of[sphere["body"]] == j] = list(ctx.case.materials).index(st.material)
        if st.clump is None:
            mass[idx], inertia[idx] = _sphere_properties(density, r, planar, ctx.case.thickness)
            sphere["radius"][start[idx]] = r
            continue
        t = np.array(st.clump.spheres, float)  # (2D clumps are refused at validation)
        m1, com, mom, axes = union_mass_properties(t[:, :3], t[:, 3], density, st.clump.resolution)
        local = (t[:, :3] - com) @ axes  # member centres in the principal frame
        mass[idx], inertia[idx] = m1 * r ** 3, mom[None, :] * r[:, None] ** 5
        slots = (start[idx][:, None] + np.arange(len(t))).reshape(-1)
        sphere["offset"][slots] = (local[None, :, :] * r[:, None, None]).reshape(-1, 3)
        sphere["radius"][slots] = (t[None, :, 3] * r[:, None]).reshape(-1)
    for j, st in enumerate(sets):
        if st.clump is not None:
            idx = np.flatnonzero(set_of == j)
            q[idx] = _random_quaternions(rng, len(idx))
    return mass, inertia, q, sphere


def _place(ctx, cfg, env, planar):
    """Centres (n, 3) for bodies of envelope radii ``env`` in the region, by lattice or random addition."""
    from demcli.kernels.placement import place_random

    lo, hi = _region_box(cfg.region)
    if planar:
        lo[2] = hi[2] = 0.5 * (lo[2] + hi[2])
    if cfg.placement == "lattice":
        return _lattice(lo, hi, env, planar)
    cyl = None
    if cfg.region.shape == "cylinder":
        cyl = (cfg.region.base[0], cfg.region.base[1], cfg.region.radius)
    pos, placed = place_random(ctx.rng, lo, hi, env, cylinder=cyl)
    if placed < len(env):
        raise StageError(f"stage {ctx.name}: placed only {placed} of {len(env)} particles without overlap; "
                         "enlarge the region or lower the count")
    return pos


def run(ctx, cfg, state_in):
    from demcli.state.order import spatial_permutation

    rng = ctx.rng
    planar = ctx.case.dimension == 2
    sets = particle_sets(cfg)
    drawn = [_set_radii(rng, st, cfg.region, planar) for st in sets]
    radii = np.concatenate(drawn)
    set_of = np.repeat(np.arange(len(sets), dtype=np.int64), [len(r) for r in drawn])
    env = radii * np.array([_envelope(st) for st in sets])[set_of]  # the envelope radius used for placement
    n = len(radii)
    pos = _place(ctx, cfg, env, planar)
    # particles are stored in cell order (cells of the mean spacing, z slowest): neighbours sit
    # close in memory, which the contact loops rely on for cache locality
    order = spatial_permutation(pos)
    pos, radii, set_of = pos[order], radii[order], set_of[order]
    vel = rng.uniform(-cfg.velocity, cfg.velocity, (n, 3)) if cfg.velocity > 0 else np.zeros((n, 3))
    if planar:
        vel[:, 2] = 0.0
    mass, inertia, q, sphere = _assemble(ctx, sets, set_of, radii, rng)
    bodies = {"x": pos, "v": vel, "q": q, "omega": np.zeros((n, 3)), "mass": mass, "inertia": inertia,
              "id": np.arange(n, dtype=np.int64), "flags": np.zeros(n, np.int8)}
    if cfg.sets is not None:
        bodies["set"] = set_of
    for j, st in enumerate(sets):
        r = radii[set_of == j]
        kind = "clumps" if st.clump is not None else "spheres"
        label = f"set {j}: " if cfg.sets is not None else ""
        span = f"{r.min() * 1e3:.3g}-{r.max() * 1e3:.3g} mm"
        ctx.log(f"generated {label}{len(r)} {kind} of {st.material} (radius {span}, "
                f"{cfg.placement} placement)" + (", added to the scene" if cfg.add else ""))
    return scene_or_added(ctx, cfg, state_in, bodies, sphere)


def describe(cfg, case):
    """One line for ``demcli check``."""
    parts = []
    for st in particle_sets(cfg):
        kind = f"clumps of {len(st.clump.spheres)} spheres" if st.clump is not None else "spheres"
        amount = f"{st.count}" if st.count is not None else f"volume fraction {st.volume_fraction:g} of"
        parts.append(f"{amount} {kind}, {describe_size(st.radius)}, material {st.material}")
    return "; ".join(parts) + f", {cfg.placement} placement"


register_stage(StageType(
    "generate", FIELDS, run, needs_input=False, adds="add", check=_check, describe=describe, case_check=_case_check,
    provides=("bodies/*", "spheres/*"),
    doc="place spheres or rigid clumps without overlap in a region"))
