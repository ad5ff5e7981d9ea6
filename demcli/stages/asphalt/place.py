"""``place_spheres`` stage: seed spheres by gradation, placed without overlap (seed 000, step 1).

Reads the previous stage's ``gradation`` group (class bounds and mass shares of the
aggregate retained on the smallest modelled sieve) and places spheres in a box by
random sequential addition (largest first, uniform-grid broad phase,
``demcli.geometry.carving.place_spheres``). Diameters are uniform within each class.
The amount is either

* ``target: {kind: count, count: N}``: N spheres split over the classes so that the
  class volumes follow the shares, n_c = N (P_c / v_c) / sum(P / v), with v_c the mean
  sphere volume of class c (uniform diameters: pi/6 (D_hi^4 - D_lo^4) / (4 (D_hi - D_lo)));
* ``target: {kind: porosity, porosity: p}``: spheres drawn per class until the class
  volume P_c (1 - p) V reaches its share of the solids (V the box volume).

The seed paper keeps each sphere's centre, radius and material and deletes the spheres;
so does this stage: the output has no bodies, only the ``seeds`` group (plus the
``gradation`` group, passed on) and ``records/seeds`` (per class: target and placed
volume and count). Random sequential addition jams near a solid fraction of 0.5 for
these size spreads; a target beyond what it reaches stops the stage with the
fraction placed.
"""

import math

import numpy as np

from demcli.config.schema import Float, Int, Optional, Section, Str, Tagged, Vector
from demcli.errors import InputError, StageError
from demcli.stages.asphalt.common import copy_group  # (common registers the seeds and aggregates groups)
from demcli.stages.base import StageType, earlier_stage, register_stage, require_dimension
from demcli.state.records import describe_column

describe_column("share", "Mass share", "%", table="seeds", doc="mass percent of the aggregate in the class")
describe_column("volume_share", "Volume share", "%", table="seeds", doc="percent of the seed spheres' volume")
describe_column("radius_factor", "Radius factor", table="expand", doc="median radius / drawn radius")
describe_column("solid_fraction", "Solid fraction", table="expand", doc="sum of sphere volumes / box volume "
                "(overlaps counted in each sphere)")
for _name, _label in (("overlap_mean", "Mean overlap / smaller radius"), ("overlap_max", "Largest overlap / smaller "
                                                                                     "radius")):
    describe_column(_name, _label, "1", "%", 100.0, table="expand",
                    doc="overlap of a touching pair over the smaller of its radii")

REGION = Section({"min": Vector(3, "m", doc="lower corner"), "max": Vector(3, "m", doc="upper corner")},
                 doc="box the spheres are placed in (the carving region)")

FIELDS = {
    "region": REGION,
    "target": Tagged("kind", {
        "count": Section({"count": Int(min=1, doc="number of spheres over all classes")}),
        "porosity": Section({"porosity": Float(min=0, max=1, min_inclusive=False, max_inclusive=False,
                                               doc="1 - sphere volume / box volume")}),
    }, doc="how many spheres: a count, or the porosity of the sphere packing"),
    "material": Str(doc="material of the aggregates carved from the spheres"),
    "gap": Float("m", min=0, default=0.0, doc="clearance between spheres (random sequential addition)"),
    "max_tries": Int(min=100, default=20000, doc="failed candidates in a row before placement gives up"),
    "expand": Optional(Section({
        "start": Float(min=0.3, max=1, min_inclusive=False, default=0.75,
                       doc="placement radius / drawn radius (random sequential addition at this size)"),
        "steps": Int(min=1, default=10, doc="growth in this many equal radius factors"),
        "max_steps": Int(min=1, default=2000, doc="relaxation steps per factor at most (x 4 after the last)"),
        "ratio": Float(min=0, min_inclusive=False, default=1e-2,
                       doc="mean unbalanced force / mean contact force that counts as equilibrium"),
        "kn": Optional(Float("N/m", min=0, min_inclusive=False),
                       doc="contact stiffness (default: the material's Young's modulus x the mean radius)"),
        "local_damping": Float(min=0, max=1, max_inclusive=False, default=0.7),
        "dt_factor": Float(min=0, max=1, min_inclusive=False, default=0.1,
                           doc="time step / critical: 0.3 is unstable once spheres have ~10 overlapping neighbours"),
        "max_tries": Int(min=100, default=20000, doc="placement at the start size gives up after these"),
    }), doc="radius expansion with relaxation (demcli.stages.asphalt.expand): reaches solid fractions "
            "beyond random sequential addition, the seed spheres then overlapping (seed 000: porosity 0.15, "
            "overlaps counted in each sphere, as PFC counts them); without it, random sequential addition"),
}


def _check(node, report):
    for d in range(3):
        if node.region.max[d] <= node.region.min[d]:
            report(f"region.max.{d}", f"must be > region.min ({node.region.min[d]:g} m)", node.region.max[d])


def _case_check(cfg, case, k, scene, report):
    """A 3D case, and room in the region for the largest class of the gradation."""
    from demcli.config.memory import check_memory
    from demcli.stages.specimen.gradation import compute

    require_dimension(case, 3, "a place_spheres specimen", report)
    if cfg.target.kind == "count":
        check_memory(report, "target.count", cfg.target.count, "the seed spheres", cfg.target.count)
    grading = earlier_stage(case, k, "gradation")
    if grading is not None:
        largest = float(compute(grading)["class_upper"].max())
        across = float(min(np.array(cfg.region.max) - np.array(cfg.region.min)))
        if largest > across:
            report("region", f"the largest class of stage {grading.name!r} ({largest * 1e3:g} mm) does not fit the "
                   f"region ({across * 1e3:g} mm across)")


def class_counts(share, lower, upper, total):
    """Sphere counts per class for ``total`` spheres whose class volumes follow ``share``."""
    from demcli.geometry.carving import mean_sphere_volume

    w = np.asarray(share, float) / mean_sphere_volume(lower, upper)
    raw = total * w / w.sum()
    n = np.floor(raw).astype(np.int64)
    rest = int(total - n.sum())
    if rest > 0:  # largest remainders
        n[np.argsort(-(raw - n), kind="stable")[:rest]] += 1
    return n


def draw_seeds(rng, cfg, lower, upper, share):
    """Diameters and classes of the spheres to place (see the module doc)."""
    from demcli.geometry.carving import diameters_for_volume, draw_diameters

    lo, hi = np.array(cfg.region.min), np.array(cfg.region.max)
    volume = float(np.prod(hi - lo))
    diam, cls = [], []
    if cfg.target.kind == "count":
        counts = class_counts(share, lower, upper, cfg.target.count)
        for c, n in enumerate(counts):
            diam.append(draw_diameters(rng, lower[c], upper[c], int(n)))
            cls.append(np.full(int(n), c, np.int64))
    else:
        solids = (1.0 - cfg.target.porosity) * volume
        for c in range(len(lower)):
            d = diameters_for_volume(rng, lower[c], upper[c], share[c] / 100.0 * solids) if share[c] > 0 \
                else np.zeros(0)
            diam.append(d)
            cls.append(np.full(len(d), c, np.int64))
    return np.concatenate(diam), np.concatenate(cls), volume


def run(ctx, cfg, state_in):
    from demcli.geometry.carving import place_spheres
    from demcli.state import RecordTable

    g = state_in.groups["gradation"]
    lower = np.asarray(g["class_lower"], float)
    upper = np.asarray(g["class_upper"], float)
    share = np.asarray(g["class_share"], float)
    lo, hi = np.array(cfg.region.min), np.array(cfg.region.max)
    if upper.max() > (hi - lo).min():
        raise InputError(f"stage {ctx.name}: the largest class ({upper.max() * 1e3:g} mm) does not fit the region "
                         f"({(hi - lo).min() * 1e3:g} mm across)")
    diam, cls, volume = draw_seeds(ctx.rng, cfg, lower, upper, share)
    expand_table = None
    if cfg.expand is not None:
        pos, expand_table = _expanded(ctx, cfg, 0.5 * diam, lo, hi)
        placed = len(diam)
    else:
        pos, placed = place_spheres(ctx.rng, lo, hi, 0.5 * diam, gap=cfg.gap, max_tries=cfg.max_tries)
    if placed < len(diam):
        sf = np.sum(diam[~np.isnan(pos[:, 0])] ** 3) * math.pi / 6 / volume
        want = np.sum(diam ** 3) * math.pi / 6 / volume
        raise StageError(f"stage {ctx.name}: placed {placed} of {len(diam)} spheres (solid fraction {sf:.3f} of "
                         f"{want:.3f}) before {cfg.max_tries} candidates in a row failed; random sequential addition "
                         "jams near 0.5 for these sizes: raise target.porosity or lower target.count")
    mat = list(ctx.case.materials).index(cfg.material)
    n = len(diam)
    state = ctx.new_state()
    from demcli.stages.specimen.gradation import empty_bodies, empty_spheres

    state.groups["bodies"] = empty_bodies()
    state.groups["spheres"] = empty_spheres()
    state.groups["gradation"] = copy_group(state_in, "gradation")
    state.groups["seeds"] = {"centre": pos, "radius": 0.5 * diam, "class": cls,
                             "material": np.full(n, mat, np.int64), "status": np.zeros(n, np.int8),
                             "round": np.zeros(n, np.int64), "region": np.r_[lo, hi]}
    table = RecordTable("seeds", {"lower": "mm", "upper": "mm", "share": "%", "count": "1", "volume": "m^3",
                                  "volume_share": "%"})
    vol = math.pi / 6 * diam ** 3
    for c in range(len(lower)):
        table.append(lower=lower[c] * 1e3, upper=upper[c] * 1e3, share=share[c], count=int(np.sum(cls == c)),
                     volume=float(vol[cls == c].sum()), volume_share=100 * float(vol[cls == c].sum() / vol.sum()))
    table.to_state(state)
    if expand_table is not None:
        expand_table.to_state(state)
    ctx.write_records(table, x="upper", ys=["share", "volume_share"])
    ctx.log(f"{n} seed spheres ({', '.join(str(int(np.sum(cls == c))) for c in range(len(lower)))} per class) "
            f"placed in {(hi - lo)[0] * 1e3:g} x {(hi - lo)[1] * 1e3:g} x {(hi - lo)[2] * 1e3:g} mm; "
            f"sphere porosity {1 - vol.sum() / volume:.4f}")
    return state


def _expanded(ctx, cfg, radii, lo, hi):
    """(centres, record table ``expand``) by radius expansion; the record's CSV + PNG and a log line."""
    from demcli.stages.asphalt.expand import expand
    from demcli.state import RecordTable

    table = RecordTable("expand", {"radius_factor": "1", "solid_fraction": "1", "overlap_mean": "1",
                                   "overlap_max": "1", "unbalanced": "1", "steps": "1"})
    pos, (mean, big) = expand(ctx, radii, lo, hi, cfg.expand, cfg.material, table)
    ctx.write_records(table, x="radius_factor", ys=["overlap_mean", "overlap_max"])
    ctx.log(f"radius expansion from {cfg.expand.start:g} x in {cfg.expand.steps} steps: overlaps {100 * mean:.3g} % "
            f"of the smaller radius on average, {100 * big:.3g} % at most; unbalanced force ratio "
            f"{table.to_arrays()['unbalanced'][-1]:.3g}")
    return pos, table


def describe(cfg, case):
    lo, hi = np.array(cfg.region.min), np.array(cfg.region.max)
    size = " x ".join(f"{v * 1e3:g}" for v in hi - lo)
    t = cfg.target
    amount = f"{t.count} spheres" if t.kind == "count" else f"sphere porosity {t.porosity:g}"
    how = "" if cfg.expand is None else f", packed by radius expansion from {cfg.expand.start:g} x"
    return f"{amount} in a {size} mm box, material {cfg.material}{how}"


register_stage(StageType(
    "place_spheres", FIELDS, run, check=_check, describe=describe, case_check=_case_check,
    requires=("gradation/class_lower", "gradation/class_upper", "gradation/class_share"),
    provides=("bodies/*", "spheres/*", "seeds/*", "records/*"), keeps=("gradation",),
    doc="seed spheres drawn by gradation and placed without overlap (seed 000, carving seeds)"))
