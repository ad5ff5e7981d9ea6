"""Radius expansion with relaxation: seed spheres packed to a solid fraction random sequential
addition cannot reach (seed 000: porosity 15 %, i.e. 0.85 of the box).

Seed 000 generates 1 743 seed spheres by the coarse gradation in a 120 mm cube "with a
porosity of 15 %", PFC's way: balls generated small and grown (Itasca's radius expansion), the
porosity taken as 1 - sum(V_i) / V_box with overlaps counted in every sphere. For a size spread
of 2.36-16 mm no packing of non-overlapping spheres comes near 0.85 (random close packings of
such spreads reach ~0.7), so the seed spheres overlap: they only mark where aggregates are
carved, and the carved polyhedra come out at the paper's 64.1 % porosity.

Method (growth with relaxation, e.g. Itasca PFC's radius expansion; the same steps as seed
003's specimen in :mod:`demcli.stages.asphalt.sand`):

1. the drawn spheres are placed at ``start`` x their radius by random sequential addition
   (:func:`demcli.geometry.carving.place_spheres`) in the region;
2. their radii grow to the drawn radii in ``steps`` equal factors; after each, the packing is
   cycled towards equilibrium (frictionless linear contacts, local damping, the region's six
   faces as walls) until the mean unbalanced force is below ``ratio`` of the mean contact force
   or ``max_steps`` steps, so overlaps spread over the packing instead of piling up where the
   spheres grew into each other;
3. after the last factor the radii are the drawn ones exactly and it is cycled once more.

Statics does not depend on the masses, so every sphere gets the same mass (that of the mean
sphere): the smallest spheres no longer set the time step, and the packing relaxes in the fewest
steps. The contact stiffness sets only the forces, not the overlaps the geometry leaves.

Each growth step is a row of ``records/<stage>_expand`` (radius factor, apparent solid fraction
sum(V_i)/V_box, mean and largest overlap over the smaller radius of a pair, unbalanced force
ratio, steps).
"""

import math

import numpy as np

from demcli.errors import StageError


def _box_walls(case, lo, hi, material):
    from demcli.config.schema import Node
    from demcli.stages import dem

    box = Node({"type": "box", "name": "region", "min": tuple(lo), "max": tuple(hi), "material": material,
                "open": (), "rigid": False, "motion": {}})
    return dem.build_walls(Node({"walls": [box]}), case)


def _system(ctx, centres, radii, lo, hi, spec, material):
    """A spheres system of equal masses in the region's box, frictionless linear contacts."""
    from demcli.engine.materials import ContactModel
    from demcli.engine.plan import make_plan
    from demcli.engine.system import Dynamics, System
    from demcli.stages import dem

    n = len(radii)
    mats = list(ctx.case.materials)
    rho = ctx.case.materials[material].density
    m = np.full(n, rho * 4.0 / 3.0 * math.pi * float(np.mean(radii ** 3)))
    groups = {"bodies": {"x": centres, "v": np.zeros((n, 3)), "omega": np.zeros((n, 3)),
                         "q": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), "mass": m,
                         "inertia": np.repeat((0.4 * m * radii ** 2)[:, None], 3, axis=1),
                         "flags": np.zeros(n, np.int8), "id": np.arange(n, dtype=np.int64)},
              "spheres": {"body": np.arange(n, dtype=np.int64), "offset": np.zeros((n, 3)), "radius": radii.copy(),
                          "material": np.full(n, mats.index(material), np.int64)}}
    kn = spec.kn if spec.kn is not None else ctx.case.materials[material].young * float(np.mean(radii))
    # local damping only acts on spheres that touch; a sphere thrown free by a growth step would fly
    # on and strike at speed, so a viscous part (a fifth of the contact frequency) stops it
    alpha = 0.2 * math.sqrt(kn / m[0])
    return System(groups, dem.case_materials(ctx.case), ContactModel(law="linear", kn=kn, kt=kn / 4.0),
                  make_plan(["local_damping", "viscous_damping"], walls=True), _box_walls(ctx.case, lo, hi, material),
                  Dynamics(gravity=(0.0, 0.0, 0.0), local_damping=spec.local_damping, viscous_damping=alpha,
                           overlap_limit=1.0), dt=1.0)


def overlaps(system):
    """(mean, largest) overlap of the touching pairs over the smaller radius of each (0, 0 if none)."""
    nl = system.nl
    act = nl.act.astype(bool)
    if not act.any():
        return 0.0, 0.0
    i, j = nl.pi[act], nl.pj[act]
    d = np.linalg.norm(system.xs[i] - system.xs[j], axis=1)
    r = np.minimum(system.rad[i], system.rad[j])
    ov = np.maximum(system.rad[i] + system.rad[j] - d, 0.0) / r
    return float(ov.mean()), float(ov.max())


def expand(ctx, radii, lo, hi, spec, material, table):
    """Centres of the spheres ``radii`` [m] packed in the box [lo, hi] by radius expansion (module
    doc); ``table`` (a RecordTable with the ``expand`` columns) gets a row per growth step.
    StageError when even the start radii do not fit by random sequential addition."""
    from demcli.geometry.carving import place_spheres
    from demcli.stages.relax import cycle_to_equilibrium, unbalanced
    from demcli.stages.timing import time_step

    pos, placed = place_spheres(ctx.rng, lo, hi, spec.start * radii, max_tries=spec.max_tries)
    if placed < len(radii):
        raise StageError(f"stage {ctx.name}: placed {placed} of {len(radii)} spheres at {spec.start:g} x their "
                         "radius; lower placement.start")
    system = _system(ctx, pos, spec.start * radii, lo, hi, spec, material)
    volume = float(np.prod(hi - lo))
    grow = (1.0 / spec.start) ** (1.0 / spec.steps)

    def relax(steps):
        system.dt = time_step(system.critical_dt(), dt_factor=spec.dt_factor)
        done = cycle_to_equilibrium(ctx, system, steps, spec.ratio, what="the expanding packing")
        mean, big = overlaps(system)
        table.append(radius_factor=float(np.median(system.rad / radii)),
                     solid_fraction=float(4.0 / 3.0 * math.pi * np.sum(system.rad ** 3) / volume),
                     overlap_mean=mean, overlap_max=big, unbalanced=unbalanced(system), steps=system.step)
        return done

    for _ in range(spec.steps - 1):
        system.scale_radii(grow)
        relax(spec.max_steps)
    system.scale_radii(radii / system.rad)  # the drawn radii exactly
    relax(spec.max_steps * 4)
    return system.x.copy(), overlaps(system)
