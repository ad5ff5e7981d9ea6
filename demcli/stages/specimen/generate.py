"""``generate`` stage: spheres or rigid clumps placed without overlap in a region.

Radii are drawn uniformly between ``radius.min`` and ``radius.max`` (or one size),
then placed largest first by random sequential addition, or on a simple cubic
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

REGION = Tagged("shape", {
    "box": Section({"min": Vector(3, "m", doc="lower corner"), "max": Vector(3, "m", doc="upper corner")}),
    "cylinder": Section({
        "base": Vector(3, "m", doc="centre of the bottom face"),
        "radius": Float("m", min=0, min_inclusive=False),
        "height": Float("m", min=0),
    }),
}, doc="where particle centres may go (the whole particle stays inside)")


def _check(node, report):
    r = node.radius
    if r.max < r.min:
        report("radius.max", f"must be >= radius.min ({r.min:g} m)", r.max)
    if node.placement == "lattice" and node.region.shape != "box":
        report("placement", "lattice placement needs region shape: box", node.placement)
    if node.region.shape == "box":
        for d in range(3):
            if node.region.max[d] < node.region.min[d]:
                report(f"region.max.{d}", f"must be >= region.min ({node.region.min[d]:g} m)", node.region.max[d])


FIELDS = {
    "region": REGION,
    "count": Int(min=1, doc="number of particles"),
    "radius": Section({
        "min": Float("m", min=0, min_inclusive=False),
        "max": Float("m", min=0, min_inclusive=False),
    }, doc="particle radius, uniform between min and max"),
    "material": Str(doc="material name"),
    "placement": Str(choices=["random", "lattice"], default="random"),
    "velocity": Float("m/s", min=0, default=0.0, doc="random initial velocity, uniform in +-value per component"),
    "clump": Optional(Section({
        "spheres": List(Vector(4), min_len=1, doc="member [x, y, z, r] in units of the particle radius"),
        "resolution": Int(min=16, default=96, doc="voxels along the clump for mass properties"),
    }), doc="rigid clump template (omit for single spheres)"),
    "add": ADD,
}


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


def _envelope(cfg):
    """Radius of a particle's bounding sphere in units of its drawn radius (1 for a sphere)."""
    if cfg.clump is None:
        return 1.0
    t = np.array(cfg.clump.spheres, float)
    return float(np.max(np.linalg.norm(t[:, :3], axis=1) + t[:, 3]))


def _case_check(cfg, case, k, scene, report):
    """What the case decides: 2D clumps, the lattice's room, and the memory of the particles."""
    from demcli.config.memory import check_memory

    check_addable(cfg, scene, report)
    planar = case.dimension == 2
    if planar and cfg.clump is not None:
        report("clump", "clumps are 3D only in this version; use dimension: 3")
    if cfg.placement == "lattice":
        lo, hi = _region_box(cfg.region)
        a = 2.02 * cfg.radius.max * _envelope(cfg)
        sites = int(np.prod(_lattice_counts(lo, hi, a, planar)))
        if cfg.count > sites:
            report("count", f"the region's lattice (spacing {a:.4g} m) has {sites} sites", cfg.count,
                   "enlarge the region, lower the count or use placement: random")
    members = len(cfg.clump.spheres) if cfg.clump is not None else 1
    check_memory(report, "count", cfg.count * members, "the generated particles", cfg.count)


def run(ctx, cfg, state_in):
    from demcli.engine.clumps import union_mass_properties
    from demcli.kernels.placement import place_random
    from demcli.state.order import spatial_permutation

    rng = ctx.rng
    planar = ctx.case.dimension == 2
    mat_names = list(ctx.case.materials)
    mat = mat_names.index(cfg.material)
    density = ctx.case.materials[cfg.material].density
    n = cfg.count
    radii = rng.uniform(cfg.radius.min, cfg.radius.max, n) if cfg.radius.max > cfg.radius.min \
        else np.full(n, cfg.radius.min)
    template = None
    if cfg.clump is not None:
        t = np.array(cfg.clump.spheres, float)
        template = t  # (2D clumps are refused at validation)
    env = radii * _envelope(cfg)  # the envelope radius used for placement
    lo, hi = _region_box(cfg.region)
    if planar:
        lo[2] = hi[2] = 0.5 * (lo[2] + hi[2])
    if cfg.placement == "lattice":
        pos = _lattice(lo, hi, env, planar)
    else:
        cyl = None
        if cfg.region.shape == "cylinder":
            cyl = (cfg.region.base[0], cfg.region.base[1], cfg.region.radius)
        pos, placed = place_random(rng, lo, hi, env, cylinder=cyl)
        if placed < n:
            raise StageError(f"stage {ctx.name}: placed only {placed} of {n} particles without overlap; "
                             "enlarge the region or lower the count")
    # particles are stored in cell order (cells of the mean spacing, z slowest): neighbours sit
    # close in memory, which the contact loops rely on for cache locality
    order = spatial_permutation(pos)
    pos, radii, env = pos[order], radii[order], env[order]
    vel = rng.uniform(-cfg.velocity, cfg.velocity, (n, 3)) if cfg.velocity > 0 else np.zeros((n, 3))
    if planar:
        vel[:, 2] = 0.0
    if template is None:
        if planar:
            mass = density * ctx.case.thickness * np.pi * radii ** 2
            inertia = np.repeat((0.5 * mass * radii ** 2)[:, None], 3, axis=1)
        else:
            mass = density * 4.0 / 3.0 * np.pi * radii ** 3
            inertia = np.repeat((0.4 * mass * radii ** 2)[:, None], 3, axis=1)
        q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
        sphere = {"body": np.arange(n, dtype=np.int64), "offset": np.zeros((n, 3)), "radius": radii,
                  "material": np.full(n, mat, np.int64)}
    else:
        m1, com, mom, axes = union_mass_properties(template[:, :3], template[:, 3], density, cfg.clump.resolution)
        local = (template[:, :3] - com) @ axes  # member centres in the principal frame
        mass = m1 * radii ** 3
        inertia = mom[None, :] * radii[:, None] ** 5
        q = _random_quaternions(rng, n)
        k = len(template)
        sphere = {"body": np.repeat(np.arange(n, dtype=np.int64), k),
                  "offset": (local[None, :, :] * radii[:, None, None]).reshape(-1, 3),
                  "radius": (template[None, :, 3] * radii[:, None]).reshape(-1),
                  "material": np.full(n * k, mat, np.int64)}
    bodies = {"x": pos, "v": vel, "q": q, "omega": np.zeros((n, 3)), "mass": mass, "inertia": inertia,
              "id": np.arange(n, dtype=np.int64), "flags": np.zeros(n, np.int8)}
    ctx.log(f"generated {n} {'clumps' if template is not None else 'spheres'} "
            f"(radius {radii.min() * 1e3:.3g}-{radii.max() * 1e3:.3g} mm, {cfg.placement} placement)"
            + (", added to the scene" if cfg.add else ""))
    return scene_or_added(ctx, cfg, state_in, bodies, sphere)


def describe(cfg, case):
    """One line for ``demcli check``."""
    kind = f"clumps of {len(cfg.clump.spheres)} spheres" if cfg.clump is not None else "spheres"
    return (f"{cfg.count} {kind}, radius {cfg.radius.min:g}-{cfg.radius.max:g} m, {cfg.placement} placement, "
            f"material {cfg.material}")


register_stage(StageType(
    "generate", FIELDS, run, needs_input=False, adds="add", check=_check, describe=describe, case_check=_case_check,
    provides=("bodies/*", "spheres/*"),
    doc="place spheres or rigid clumps without overlap in a region"))
