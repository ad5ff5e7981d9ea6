"""``cut`` stage: a cylinder or prism specimen cut from the compacted aggregates (seed 000, step 8).

Shapes: ``cylinder`` (``diameter``, ``height``, axis along z: the Marshall 101.6 x 63.5 mm,
the seed's 50 x 60 mm, the gyratory 150 mm) or ``prism`` (``size`` x, y, z). The specimen
is centred on ``centre``; by default on the centre of the box the previous stage's walls
enclose (a compact stage), else on the centre of the aggregates' bounding box. It must
lie inside that box.

Aggregates crossing the surface (``crossing``):

* ``trim``: member balls not wholly inside are dropped; what is left of an aggregate
  stays one rigid clump with mass properties recomputed from its remaining members
  (a new principal frame; its cutting planes are carried into it). The specimen's balls
  all lie inside the surface.
* ``keep``: aggregates whose centre of mass is inside are kept whole (they may stick
  out), the others dropped.
* ``drop``: only aggregates wholly inside are kept.

Walls are removed (a later stage sets its own); sphere-sphere contacts between kept
spheres keep their history (indices remapped); wall contacts are dropped. Output: the
``specimen`` group (shape, centre, size, volume, aggregate volume inside, porosity of the
aggregate skeleton), ``aggregates`` and ``seeds`` updated, ``records/cut`` and
``<stage>/specimen.vtu``.
"""

import math

import numpy as np

from demcli.config.schema import Float, Optional, Section, Str, Tagged, Vector
from demcli.errors import InputError, StageError
# common registers the seeds and aggregates groups
from demcli.stages.asphalt.common import (box_of_walls, build_aggregate_bodies, copy_group, scalar_str, world_planes,
                                          write_asphalt_vtu)
from demcli.stages.base import StageType, register_stage
from demcli.state.fields import Field, register, register_group

register_group("specimen", "The cut specimen (seed 000): shape, placement and volumetrics", writer="stage cut")
for _name, _kind, _dims, _unit, _doc in [
        ("shape", "str", (), "", "'cylinder' (axis along z) or 'prism'"),
        ("centre", "f", (3,), "m", "centre of the specimen"),
        ("size", "f", (3,), "m", "cylinder: (diameter, diameter, height); prism: (x, y, z)"),
        ("volume", "f", (), "m^3", "specimen volume"),
        ("crossing", "str", (), "", "what happened to aggregates crossing the surface: trim, keep or drop"),
        ("aggregate_volume", "f", (), "m^3", "aggregate volume with member centres inside the specimen"),
        ("porosity", "f", (), "1", "1 - aggregate_volume / volume (voids in the aggregate skeleton)")]:
    register(Field(f"specimen/{_name}", _kind, _dims, _unit, _doc, writer="stage cut"))

FIELDS = {
    "shape": Tagged("shape", {
        "cylinder": Section({"diameter": Float("m", min=0, min_inclusive=False),
                             "height": Float("m", min=0, min_inclusive=False)},
                            doc="axis along z (Marshall 101.6 x 63.5 mm; gyratory 150 mm)"),
        "prism": Section({"size": Vector(3, "m", min=0, min_inclusive=False)}),
    }, doc="the specimen"),
    "centre": Optional(Vector(3, "m"), doc="specimen centre (default: centre of the walls' box)"),
    "crossing": Str(choices=["trim", "keep", "drop"], default="trim",
                    doc="aggregates crossing the surface: trimmed to the balls inside, kept whole (centre inside), "
                        "or dropped"),
}


def specimen_size(shape):
    """The specimen's extent along x, y, z (a cylinder's diameter twice, then its height)."""
    if shape.shape == "cylinder":
        return np.array([shape.diameter, shape.diameter, shape.height])
    return np.array(shape.size, float)


def inside(points, radius, shape, centre, size):
    """Which balls (centres (n, 3), radii) lie wholly inside the specimen."""
    d = np.asarray(points, float) - centre
    r = np.broadcast_to(np.asarray(radius, float), (len(d),))
    z_ok = np.abs(d[:, 2]) + r <= 0.5 * size[2] + 1e-12
    if shape == "cylinder":
        return z_ok & (np.hypot(d[:, 0], d[:, 1]) + r <= 0.5 * size[0] + 1e-12)
    return z_ok & np.all(np.abs(d[:, :2]) + r[:, None] <= 0.5 * size[:2] + 1e-12, axis=1)


def volume_of(shape, size):
    return math.pi / 4 * size[0] ** 2 * size[2] if shape == "cylinder" else float(np.prod(size))


def run(ctx, cfg, state_in):
    from demcli.geometry.carving import element_volume, normal_widths
    from demcli.state import RecordTable

    if "aggregates" not in state_in.groups:
        raise InputError(f"stage {ctx.name}: the input has no aggregates (run carve and compact first)")
    ag = state_in.groups["aggregates"]
    n_agg = len(ag["body"])
    nb = len(state_in["bodies/mass"])
    if not np.array_equal(np.asarray(ag["body"]), np.arange(n_agg)) or nb != n_agg:
        raise InputError(f"stage {ctx.name}: cut works on aggregates only (the input has {nb - n_agg} other bodies); "
                         "cut before adding mastic")
    kind = cfg.shape.shape
    size = specimen_size(cfg.shape)
    centres = state_in.sphere_centres()
    radius = np.asarray(state_in["spheres/radius"], float)
    box = box_of_walls(state_in)
    if box is None:
        box = ((centres - radius[:, None]).min(axis=0), (centres + radius[:, None]).max(axis=0))
        where = "the aggregates' bounding box"
    else:
        where = "the walls' box"
    lo, hi = box
    centre = np.array(cfg.centre, float) if cfg.centre is not None else 0.5 * (lo + hi)
    if np.any(centre - 0.5 * size < lo - 1e-9) or np.any(centre + 0.5 * size > hi + 1e-9):
        raise InputError(f"stage {ctx.name}: the {kind} {' x '.join(f'{v * 1e3:g}' for v in size)} mm at "
                         f"{', '.join(f'{v * 1e3:.1f}' for v in centre)} mm does not fit {where} "
                         f"({' x '.join(f'{v * 1e3:.1f}' for v in hi - lo)} mm); use a larger carving region")
    sbody = np.asarray(state_in["spheres/body"], np.int64)
    ins = inside(centres, radius, kind, centre, size)
    n_in = np.bincount(sbody, ins.astype(np.int64), minlength=nb)
    n_all = np.bincount(sbody, minlength=nb)
    bodies_in = state_in.groups["bodies"]
    com_in = inside(np.asarray(bodies_in["x"]), 0.0, kind, centre, size)
    if cfg.crossing == "keep":
        keep_body = com_in
        keep_sphere = keep_body[sbody]
    elif cfg.crossing == "drop":
        keep_body = n_in == n_all
        keep_sphere = keep_body[sbody]
    else:
        keep_sphere = ins
        keep_body = n_in > 0
    trimmed = keep_body & (n_in < n_all) if cfg.crossing == "trim" else np.zeros(nb, bool)
    if not keep_body.any():
        raise StageError(f"stage {ctx.name}: no aggregate lies in the specimen")

    # new body and sphere numbering (kept order)
    new_body = np.full(nb, -1, np.int64)
    new_body[keep_body] = np.arange(int(keep_body.sum()))
    new_sphere = np.full(len(sbody), -1, np.int64)
    new_sphere[keep_sphere] = np.arange(int(keep_sphere.sum()))
    bodies = {k: np.asarray(v)[keep_body].copy() for k, v in bodies_in.items() if k in
              ("x", "v", "q", "omega", "mass", "inertia", "id", "flags")}
    s_in = state_in.groups["spheres"]
    spheres = {"body": new_body[sbody[keep_sphere]], "offset": np.asarray(s_in["offset"])[keep_sphere].copy(),
               "radius": radius[keep_sphere].copy(), "material": np.asarray(s_in["material"])[keep_sphere].copy()}
    agg = {k: np.asarray(v)[keep_body].copy() if np.ndim(v) and len(v) == n_agg and k not in
           ("lattice_origin", "lattice_counts") else np.array(v, copy=True) for k, v in ag.items()}
    agg["body"] = np.arange(int(keep_body.sum()), dtype=np.int64)
    a = 2.0 * float(ag["ball_radius"])
    mass_model = scalar_str(ag["mass_model"])
    v_el = element_volume(a, mass_model)

    if trimmed.any():
        # rebuild the trimmed aggregates from their remaining members, in the world frame
        old = np.flatnonzero(trimmed)
        nw, cw, lw = world_planes(state_in, with_lattice=True)
        sel = keep_sphere & trimmed[sbody]
        order = np.argsort(sbody[sel], kind="stable")
        pts = centres[sel][order]
        counts = np.bincount(sbody[sel], minlength=nb)[old]
        start = np.r_[0, np.cumsum(counts)].astype(np.int64)
        mat = np.asarray(s_in["material"])[sel][order][start[:-1]]
        density = np.array([m.density for m in ctx.case.materials.values()])[mat]
        b2, s2, planes, _ = build_aggregate_bodies(start, pts, 0.5 * a, density, mass_model, nw[old],
                                                   np.asarray(ag["plane_spacing"])[old], cw[old],
                                                   np.asarray(ag["seed_radius"])[old], mat, lattice_w=lw[old])
        nb_new = new_body[old]
        v_old, w_old = np.asarray(bodies_in["v"])[old], np.asarray(bodies_in["omega"])[old]
        for key in ("x", "q", "mass", "inertia"):
            bodies[key][nb_new] = b2[key]
        # the rigid motion carries on: velocity of the new centre of mass, same spin
        bodies["v"][nb_new] = v_old + np.cross(w_old, b2["x"] - np.asarray(bodies_in["x"])[old])
        # member offsets of the rebuilt bodies, in the kept spheres' order
        pos_new = new_sphere[np.flatnonzero(sel)[order]]
        spheres["offset"][pos_new] = s2["offset"]
        for key in ("plane_normal", "seed_offset", "lattice_axes"):
            agg[key][nb_new] = planes[key]
        agg["ball_widths"][nb_new] = normal_widths(start, pts, nw[old], 0.5 * a)
    kept_counts = np.bincount(spheres["body"], minlength=int(keep_body.sum()))
    agg["volume"] = kept_counts * v_el if cfg.crossing == "trim" else agg["volume"]

    state = ctx.new_state(time=float(state_in.meta.get("time", 0.0)), step=int(state_in.meta.get("step", 0)),
                          dt=float(state_in.meta.get("dt", 0.0)))
    state.groups["bodies"] = bodies
    state.groups["spheres"] = spheres
    state.groups["aggregates"] = agg
    for name in ("seeds", "gradation"):
        g = copy_group(state_in, name)
        if g is not None:
            state.groups[name] = g
    contacts = state_in.groups.get("contacts")
    if contacts is not None and len(contacts.get("i", [])):
        i, j = new_sphere[np.asarray(contacts["i"])], new_sphere[np.asarray(contacts["j"])]
        ok = (i >= 0) & (j >= 0)
        state.groups["contacts"] = {k: np.asarray(v)[ok].copy() for k, v in contacts.items()}
        state.groups["contacts"]["i"] = np.minimum(i[ok], j[ok])
        state.groups["contacts"]["j"] = np.maximum(i[ok], j[ok])
    vol = volume_of(kind, size)
    c_kept = centres[keep_sphere]
    agg_inside = float(inside(c_kept, 0.0, kind, centre, size).sum()) * v_el
    state.groups["specimen"] = {"shape": np.array(kind, dtype=object), "centre": centre, "size": size,
                                "volume": np.float64(vol), "crossing": np.array(cfg.crossing, dtype=object),
                                "aggregate_volume": np.float64(agg_inside),
                                "porosity": np.float64(1.0 - agg_inside / vol)}
    table = RecordTable("cut", {"aggregates_in": "1", "aggregates_kept": "1", "trimmed": "1", "balls_in": "1",
                                "balls_kept": "1", "volume": "m^3", "aggregate_volume": "m^3", "porosity": "1"})
    table.append(aggregates_in=n_agg, aggregates_kept=int(keep_body.sum()), trimmed=int(trimmed.sum()),
                 balls_in=len(sbody), balls_kept=int(keep_sphere.sum()), volume=vol, aggregate_volume=agg_inside,
                 porosity=1.0 - agg_inside / vol)
    table.to_state(state)
    folder = ctx.runner.run_dir / "records"
    folder.mkdir(parents=True, exist_ok=True)
    table.write_csv(folder / f"{ctx.name}_cut.csv")
    write_asphalt_vtu(ctx.snapshot_dir / "specimen.vtu", state)
    ctx.log(f"{kind} {' x '.join(f'{v * 1e3:g}' for v in size)} mm ({cfg.crossing}): {int(keep_body.sum())} of "
            f"{n_agg} aggregates kept ({int(trimmed.sum())} trimmed), {int(keep_sphere.sum())} balls; aggregate "
            f"skeleton porosity {1 - agg_inside / vol:.4f}")
    return state


def describe(cfg, case):
    size = " x ".join(f"{v * 1e3:g}" for v in specimen_size(cfg.shape))
    return f"{cfg.shape.shape} {size} mm, crossing aggregates: {cfg.crossing}"


register_stage(StageType(
    "cut", FIELDS, run, describe=describe, requires=("bodies/x", "spheres/radius", "aggregates/body"),
    provides=("bodies/*", "spheres/*", "aggregates/*", "specimen/*", "records/*"),
    keeps=("seeds", "gradation", "contacts"),
    doc="cut a cylinder or prism specimen; crossing aggregates trimmed, kept whole or dropped (seed 000)"))
