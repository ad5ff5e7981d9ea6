"""``gradation`` stage: sieve table, size classes and the volume (or area) of each class.

Classes lie between consecutive sieves (mass percent passing Q at each sieve). Two
volumetric recipes turn shares into amounts:

* ``ballast`` (Shao, Lian & Yang 2017, seed 002, eqs. 14-16 and step 1): bed volume
  V_c = l w h; porosity n_1 = 1 - rho_0 / rho_1 (rho_0 bulk density of the stable bed,
  rho_1 particle density); solids V_d = (1 - n_1) V_c; class volume V_j = P_j V_d with
  P_0 = Q_1 (through the smallest sieve), P_j = Q_{j+1} - Q_j, P_k = 100 - Q_k
  (retained on the largest, up to ``max_size``); estimated count n_j = P_j V_c / d_m^3
  with d_m = ``count_cube`` (40 mm in the paper).
* ``asphalt`` (patent CN 2022, seed 001): per unit mass of mix with asphalt content
  ratio (by mass of mix), V_ag = (1 - ratio) / rho_agg, V_as = ratio / rho_b,
  V_z = (V_ag + V_as) / (1 - VV); the share of the specimen taken by aggregate at or
  above ``min_size`` is m = V_ag / V_z (P_top - P_min) / 100 and class t gets
  n_t = (P_upper - P_lower) / (P_top - P_min) of it. Class amount S m n_t (S the
  specimen area in 2D or volume in 3D), air voids S VV, mastic (binder and fines) the rest.

The asphalt recipe may carry a ``mix_design`` section: the Asphalt Institute's volumetric
analysis (MS-2, 7th ed., "Volumetric properties") of the same mix, reported beside the
recipe and not fed back into it (:func:`ms2_volumetrics`). Inputs: the aggregate's bulk and
effective specific gravities Gsb and Gse, optionally the compacted mix's bulk specific
gravity Gmb; Pb = 100 ``asphalt_content`` and Gb = ``binder_density`` / 1000 kg/m^3 (water
taken as 1000 kg/m^3, as the other densities here; at 25 C water is 997 kg/m^3, 0.3 % less,
so give ``binder_density`` = 1000 Gb to reproduce a laboratory Gb exactly). Without Gmb the
mix is taken at the recipe's air voids, Gmb = Gmm (1 - VV); with Gmb, its air voids
Va = 100 (Gmm - Gmb) / Gmm must match 100 VV within 0.1 percentage point (the precision Va
is reported to), since VV is what the specimen is built with. Gse < Gsb (negative absorbed
binder) and an absorbed binder at or above the binder content (Pbe <= 0) are refused.
"""

import math

import numpy as np

from demcli.config.schema import Float, List, Optional, Section, Tagged, Vector
from demcli.stages.base import StageType, register_stage
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

register_group("gradation", "Gradation targets: sieves, size classes and their amounts", writer="stage gradation")
for _name, _kind, _dims, _unit, _doc in [
        ("sieves", "f", ("n_sieve",), "m", "square-hole sieve apertures, ascending"),
        ("passing", "f", ("n_sieve",), "%", "target mass percent passing each sieve"),
        ("class_lower", "f", ("n_class",), "m", "lower size of each class"),
        ("class_upper", "f", ("n_class",), "m", "upper size of each class"),
        ("class_share", "f", ("n_class",), "%", "mass percent of the aggregate in each class"),
        ("class_amount", "f", ("n_class",), "m^3 or m^2", "volume (3D) or area (2D) of each class in the specimen"),
        ("class_count", "f", ("n_class",), "1", "estimated particle count of each class"),
        ("totals", "f", ("n_total",), "m^3 or m^2", "specimen, solids or aggregate, voids, mastic amounts")]:
    register(Field(f"gradation/{_name}", _kind, _dims, _unit, _doc, writer="stage gradation"))
register(Field("gradation/mix_design", "f", ("n_mix",), "1 or %",
               "MS-2 volumetrics (asphalt mix_design only): Gsb, Gse, Gb, Pb %, Gmb, Gmm, Va %, VMA %, "
               "VFA %, Pba % of aggregate, Pbe %", writer="stage gradation", required=False))

describe_column("sieve", "Sieve size", "mm", ticks="values", doc="square-hole sieve aperture")
describe_column("passing", "Passing", "%", doc="mass percent passing the sieve")
describe_column("lower", "Class lower size", "mm", ticks="values", doc="lower sieve of the size class")
describe_column("upper", "Class upper size", "mm", ticks="values", doc="upper sieve of the size class")
describe_column("share", "Class share", "%", table="classes", doc="mass percent of the aggregate in the class")

TOTALS = ("specimen", "aggregate", "voids", "mastic")

# name, unit, label, meaning: the order of gradation/mix_design and the columns of records/volumetrics
MIX_DESIGN = (
    ("Gsb", "1", "Aggregate bulk specific gravity", "oven-dry bulk specific gravity of the combined aggregate"),
    ("Gse", "1", "Aggregate effective specific gravity", "effective specific gravity of the aggregate "
                                                              "(its volume less the pores that absorb binder)"),
    ("Gb", "1", "Binder specific gravity", "binder_density / 1000 kg/m^3"),
    ("Pb", "%", "Binder content", "binder, percent by mass of mix"),
    ("Gmb", "1", "Mix bulk specific gravity", "compacted mix, as given or Gmm (1 - air_voids)"),
    ("Gmm", "1", "Mix maximum specific gravity", "the mix without air voids, 100 / (Ps/Gse + Pb/Gb)"),
    ("Va", "%", "Air voids", "100 (Gmm - Gmb) / Gmm, percent of the bulk volume of mix"),
    ("VMA", "%", "Voids in mineral aggregate", "100 - Gmb Ps / Gsb, percent of the bulk volume of mix"),
    ("VFA", "%", "Voids filled with asphalt", "100 (VMA - Va) / VMA, percent of VMA"),
    ("Pba", "%", "Absorbed binder", "100 Gb (Gse - Gsb) / (Gsb Gse), percent by mass of aggregate"),
    ("Pbe", "%", "Effective binder content", "Pb - Pba Ps / 100, percent by mass of mix"),
)
MIX_NAMES = tuple(name for name, *_ in MIX_DESIGN)
for _name, _unit, _label, _doc in MIX_DESIGN:
    describe_column(_name, _label, _unit, table="volumetrics", doc=_doc)

WATER_DENSITY = 1000.0  # kg/m^3: Gb = binder_density / WATER_DENSITY (see the module docstring)
AIR_VOIDS_TOLERANCE = 0.1  # percentage points between Va from a given Gmb and 100 air_voids

SPECIMEN = Tagged("shape", {
    "circle": Section({"radius": Float("m", min=0, min_inclusive=False)}),
    "rectangle": Section({"width": Float("m", min=0, min_inclusive=False),
                          "height": Float("m", min=0, min_inclusive=False)}),
    "cylinder": Section({"diameter": Float("m", min=0, min_inclusive=False),
                         "height": Float("m", min=0, min_inclusive=False)}),
    "box": Section({"size": Vector(3, "m", min=0, min_inclusive=False)}),
}, doc="the specimen or bed the amounts are for (circle/rectangle: 2D area; cylinder/box: volume)")

MIX_DESIGN_SECTION = Section({
    "aggregate_bulk_specific_gravity": Float(min=0, min_inclusive=False, doc="Gsb of the combined aggregate"),
    "aggregate_effective_specific_gravity": Float(min=0, min_inclusive=False,
                                                  doc="Gse of the aggregate, >= Gsb"),
    "mix_bulk_specific_gravity": Optional(Float(min=0, min_inclusive=False),
                                          doc="Gmb of the compacted mix (none: Gmm (1 - air_voids))"),
}, doc="MS-2 volumetric analysis of the mix, reported beside the recipe (Gmm, Va, VMA, VFA, Pba, Pbe)")


def _check_mix_design(v, report):
    """Gse >= Gsb, an effective binder content above zero, Gmb matching the air voids."""
    if v.mix_design is None:
        return
    md = v.mix_design
    gsb, gse = md.aggregate_bulk_specific_gravity, md.aggregate_effective_specific_gravity
    if gse < gsb:
        report("mix_design.aggregate_effective_specific_gravity",
               f"must be >= the bulk specific gravity Gsb = {gsb:g} (else the absorbed binder is negative)", gse)
        return
    vol = mix_design(v)
    if vol["Pbe"] <= 0:
        report("mix_design.aggregate_effective_specific_gravity",
               f"leaves no effective binder: the aggregate absorbs Pba = {vol['Pba']:.3g} % of its mass, "
               f"the binder content is Pb = {vol['Pb']:g} %", gse)
    elif abs(vol["Va"] - 100.0 * v.air_voids) > AIR_VOIDS_TOLERANCE:
        report("mix_design.mix_bulk_specific_gravity",
               f"gives air voids Va = {vol['Va']:.2f} %, but air_voids is {100.0 * v.air_voids:g} % "
               f"(they must agree within {AIR_VOIDS_TOLERANCE:g} percentage point)", md.mix_bulk_specific_gravity)


FIELDS = {
    "sieves": List(Float("m", min=0, min_inclusive=False), min_len=1, doc="square-hole sieve apertures, ascending"),
    "passing": List(Float(min=0, max=100), min_len=1, doc="mass percent passing each sieve"),
    "specimen": SPECIMEN,
    "volumetrics": Tagged("kind", {
        "ballast": Section({
            "bulk_density": Float("kg/m^3", min=0, min_inclusive=False, doc="rho_0 of the stable bed"),
            "particle_density": Float("kg/m^3", min=0, min_inclusive=False, doc="rho_1"),
            "max_size": Optional(Float("m", min=0, min_inclusive=False),
                                 doc="upper size of the class retained on the largest sieve"),
            "min_size": Float("m", min=0, default=0.0, doc="lower size of the class through the smallest sieve"),
            "count_cube": Float("m", min=0, min_inclusive=False, default=0.04,
                                doc="d_m: edge of the cube used to estimate counts"),
        }),
        "asphalt": Section({
            "asphalt_content": Float(min=0, max=1, max_inclusive=False, doc="binder mass / mix mass"),
            "aggregate_density": Float("kg/m^3", min=0, min_inclusive=False),
            "binder_density": Float("kg/m^3", min=0, min_inclusive=False),
            "air_voids": Float(min=0, max=1, max_inclusive=False, doc="VV, volume fraction"),
            "min_size": Float("m", min=0, min_inclusive=False,
                              doc="smallest aggregate modelled as particles (finer is mastic)"),
            "mix_design": Optional(MIX_DESIGN_SECTION),
        }, check=_check_mix_design),
    }),
}


def check_curve(s, q, report):
    """Report a sieve curve's faults (sieves ``s`` ascending, m; passing ``q`` non-decreasing, %,
    one per sieve) at the keys ``sieves.<k>`` and ``passing.<k>``; False when the lengths differ."""
    if len(s) != len(q):
        report("passing", f"needs one value per sieve ({len(s)})", len(q))
        return False
    for k in range(1, len(s)):
        if s[k] == s[k - 1]:
            report(f"sieves.{k}", "empty class: two sieves of the same size", s[k])
        elif s[k] < s[k - 1]:
            report(f"sieves.{k}", f"sizes must ascend (after {s[k - 1]:g} m)", s[k])
        if q[k] < q[k - 1]:
            report(f"passing.{k}", f"passing must not decrease with size (after {q[k - 1]:g} %)", q[k])
    return True


def _check(node, report):
    s, q = node.sieves, node.passing
    if not check_curve(s, q, report):
        return
    v = node.volumetrics
    if v.kind == "asphalt":
        if v.min_size not in s:
            report("volumetrics.min_size", "must be one of the sieves", v.min_size)
        if q[-1] != 100:
            report(f"passing.{len(q) - 1}", "the largest sieve must pass 100 % for asphalt mixes", q[-1])
    else:
        if q[-1] < 100 and v.max_size is None:
            report("volumetrics.max_size", f"needed: {100 - q[-1]:g} % is retained on the largest sieve", None)
        if v.max_size is not None and v.max_size <= s[-1]:
            report("volumetrics.max_size", f"must exceed the largest sieve ({s[-1]:g} m)", v.max_size)
        if v.bulk_density >= v.particle_density:
            report("volumetrics.bulk_density", "must be below the particle density (porosity > 0)", v.bulk_density)
    shape = node.specimen
    smallest = {"circle": lambda: 2 * shape.radius, "rectangle": lambda: min(shape.width, shape.height),
                "cylinder": lambda: min(shape.diameter, shape.height), "box": lambda: min(shape.size)}[shape.shape]()
    classes = _classes(node)
    for k, (lo, hi, share) in enumerate(zip(*classes)):
        if share > 0 and hi > smallest:
            report("specimen", f"class {lo * 1e3:g}-{hi * 1e3:g} mm is larger than the specimen's smallest side "
                   f"({smallest * 1e3:g} mm)", None)
            break


def specimen_amount(shape):
    """Area (2D shapes) or volume (3D shapes) of the specimen, and its dimension."""
    if shape.shape == "circle":
        return math.pi * shape.radius ** 2, 2
    if shape.shape == "rectangle":
        return shape.width * shape.height, 2
    if shape.shape == "cylinder":
        return math.pi * shape.diameter ** 2 / 4 * shape.height, 3
    return float(np.prod(shape.size)), 3


def _classes(cfg):
    """(lower, upper, share %) of each class, per the recipe's conventions."""
    s = np.asarray(cfg.sieves, float)
    q = np.asarray(cfg.passing, float)
    v = cfg.volumetrics
    if v.kind == "ballast":
        top = v.max_size if v.max_size is not None else s[-1]
        lower = np.r_[v.min_size, s]
        upper = np.r_[s, top]
        share = np.r_[q[0], np.diff(q), 100.0 - q[-1]]
        return lower, upper, share
    k0 = int(np.flatnonzero(s == v.min_size)[0])
    lower, upper = s[k0:-1], s[k0 + 1:]
    span = q[-1] - q[k0]
    share = np.diff(q[k0:]) / span * 100.0 if span > 0 else np.zeros(len(lower))
    return lower, upper, share


def asphalt_volumetrics(ratio, rho_agg, rho_b, vv, p_top, p_min):
    """(V_ag, V_as, V_z, m) per unit mass of mix [m^3/kg, m^3/kg, m^3/kg, -] (seed 001)."""
    v_ag = (1.0 - ratio) / rho_agg
    v_as = ratio / rho_b
    v_z = (v_ag + v_as) / (1.0 - vv)
    return v_ag, v_as, v_z, v_ag / v_z * (p_top - p_min) / 100.0


def max_specific_gravity(gse, gb, pb):
    """Gmm = 100 / (Ps/Gse + Pb/Gb), Ps = 100 - Pb: the mix without air voids (MS-2).

    gse, gb: specific gravities of the aggregate (effective) and the binder [-];
    pb: binder content, percent by mass of mix.
    """
    return 100.0 / ((100.0 - pb) / gse + pb / gb)


def ms2_volumetrics(gsb, gse, gb, pb, gmb):
    """Volumetric analysis of a compacted asphalt mix (Asphalt Institute MS-2, 7th ed.).

    Inputs: gsb, gse: bulk and effective specific gravities of the aggregate; gb: binder
    specific gravity; pb: binder content [% by mass of mix]; gmb: bulk specific gravity of
    the compacted mix. With Ps = 100 - Pb:

    * Gmm = 100 / (Ps/Gse + Pb/Gb)
    * Pba = 100 Gb (Gse - Gsb) / (Gsb Gse)   [% by mass of aggregate]
    * Pbe = Pb - Pba Ps / 100                [% by mass of mix]
    * Va = 100 (Gmm - Gmb) / Gmm             [% of the bulk volume of mix]
    * VMA = 100 - Gmb Ps / Gsb               [% of the bulk volume of mix]
    * VFA = 100 (VMA - Va) / VMA             [% of VMA]

    Returns a dict in the order of :data:`MIX_NAMES` (inputs first).
    """
    ps = 100.0 - pb
    gmm = max_specific_gravity(gse, gb, pb)
    pba = 100.0 * gb * (gse - gsb) / (gsb * gse)
    va = 100.0 * (gmm - gmb) / gmm
    vma = 100.0 - gmb * ps / gsb
    return dict(Gsb=gsb, Gse=gse, Gb=gb, Pb=pb, Gmb=gmb, Gmm=gmm, Va=va, VMA=vma, VFA=100.0 * (vma - va) / vma,
                Pba=pba, Pbe=pb - pba * ps / 100.0)


def mix_design(v):
    """:func:`ms2_volumetrics` of an asphalt ``volumetrics`` node with a ``mix_design`` section."""
    md = v.mix_design
    gse, gb, pb = md.aggregate_effective_specific_gravity, v.binder_density / WATER_DENSITY, 100.0 * v.asphalt_content
    gmb = md.mix_bulk_specific_gravity
    if gmb is None:
        gmb = max_specific_gravity(gse, gb, pb) * (1.0 - v.air_voids)
    return ms2_volumetrics(md.aggregate_bulk_specific_gravity, gse, gb, pb, gmb)


def compute(cfg):
    """Class bounds, shares, amounts, counts and totals of a validated gradation config."""
    lower, upper, share = _classes(cfg)
    amount_s, dim = specimen_amount(cfg.specimen)
    v = cfg.volumetrics
    if v.kind == "ballast":
        porosity = 1.0 - v.bulk_density / v.particle_density
        solids = (1.0 - porosity) * amount_s
        amount = share / 100.0 * solids
        count = share / 100.0 * amount_s / v.count_cube ** dim
        totals = np.array([amount_s, solids, porosity * amount_s, 0.0])
    else:
        q = np.asarray(cfg.passing, float)
        k0 = int(np.flatnonzero(np.asarray(cfg.sieves) == v.min_size)[0])
        *_, m = asphalt_volumetrics(v.asphalt_content, v.aggregate_density, v.binder_density, v.air_voids,
                                    q[-1], q[k0])
        amount = amount_s * m * share / 100.0
        mid = 0.5 * (lower + upper)
        unit = math.pi / 4 * mid ** 2 if dim == 2 else math.pi / 6 * mid ** 3
        count = amount / unit
        voids = amount_s * v.air_voids
        totals = np.array([amount_s, amount_s * m, voids, amount_s - amount_s * m - voids])
    res = dict(class_lower=lower, class_upper=upper, class_share=share, class_amount=amount,
               class_count=count, totals=totals, dim=dim)
    if v.kind == "asphalt" and v.mix_design is not None:
        res["mix_design"] = np.array(list(mix_design(v).values()))
    return res


def run(ctx, cfg, state_in):
    from demcli.state import RecordTable

    res = compute(cfg)  # its dimension is the case's (checked at validation)
    state = ctx.new_state()
    state.groups["bodies"] = empty_bodies()
    state.groups["spheres"] = empty_spheres()
    state.groups["gradation"] = {"sieves": np.asarray(cfg.sieves, float), "passing": np.asarray(cfg.passing, float),
                                 **{k: np.asarray(v, float) for k, v in res.items() if k != "dim"}}
    unit = "m^2" if res["dim"] == 2 else "m^3"
    classes = RecordTable("classes", {"lower": "mm", "upper": "mm", "share": "%", "amount": unit, "count": "1"})
    for lo, hi, sh, am, cn in zip(res["class_lower"], res["class_upper"], res["class_share"], res["class_amount"],
                                  res["class_count"]):
        classes.append(lower=lo * 1e3, upper=hi * 1e3, share=sh, amount=am, count=cn)
    curve = RecordTable("curve", {"sieve": "mm", "passing": "%"})
    for s, q in zip(cfg.sieves, cfg.passing):
        curve.append(sieve=s * 1e3, passing=q)
    classes.to_state(state)
    curve.to_state(state)
    ctx.write_records(classes, x="upper", ys=["share"])
    ctx.write_records(curve, x="sieve", ys=["passing"], logx=True)
    t = dict(zip(TOTALS, res["totals"]))
    ctx.log(f"{len(res['class_share'])} classes; specimen {t['specimen']:.4g} {unit}, aggregate "
            f"{t['aggregate']:.4g} {unit}, voids {t['voids']:.4g} {unit}, mastic {t['mastic']:.4g} {unit}; "
            f"estimated {res['class_count'].sum():.0f} particles")
    if "mix_design" in res:
        _write_mix_design(ctx, cfg, state, res["mix_design"])
    return state


def _write_mix_design(ctx, cfg, state, values):
    """The ``volumetrics`` record table (state and CSV, one row) and the log line of the MS-2 analysis."""
    from demcli.state import RecordTable

    vol = dict(zip(MIX_NAMES, values))
    table = RecordTable("volumetrics", {name: unit for name, unit, *_ in MIX_DESIGN})
    table.append(vol)
    table.to_state(state)
    folder = ctx.runner.run_dir / "records"
    folder.mkdir(parents=True, exist_ok=True)
    table.write_csv(folder / f"{ctx.name}_volumetrics.csv")
    ctx.log(_mix_design_line(vol, cfg.volumetrics.mix_design))


def _mix_design_line(vol, md):
    """``MS-2: Gmb 2.364 (given), Gmm 2.481, Va 4.7 %, ...`` for the log and ``demcli check``."""
    source = "given" if md.mix_bulk_specific_gravity is not None else "from air_voids"
    return (f"MS-2: Gmb {vol['Gmb']:.3f} ({source}), Gmm {vol['Gmm']:.3f}, Va {vol['Va']:.1f} %, "
            f"VMA {vol['VMA']:.1f} %, VFA {vol['VFA']:.1f} %, Pba {vol['Pba']:.2f} %, Pbe {vol['Pbe']:.2f} %")


def empty_bodies():
    """The arrays of an empty ``bodies`` group (a state with no particles yet)."""
    return {"x": np.zeros((0, 3)), "v": np.zeros((0, 3)), "q": np.zeros((0, 4)), "omega": np.zeros((0, 3)),
            "mass": np.zeros(0), "inertia": np.zeros((0, 3)), "id": np.zeros(0, np.int64), "flags": np.zeros(0, np.int8)}


def empty_spheres():
    """The arrays of an empty ``spheres`` group."""
    return {"body": np.zeros(0, np.int64), "offset": np.zeros((0, 3)), "radius": np.zeros(0),
            "material": np.zeros(0, np.int64)}


def _case_check(cfg, case, k, scene, report):
    """The specimen's dimension must be the case's."""
    dim = specimen_amount(cfg.specimen)[1]
    if dim != case.dimension:
        report("specimen", f"a {cfg.specimen.shape} specimen is {dim}D but the case has dimension "
               f"{case.dimension}")


def describe(cfg, case):
    """One line for ``demcli check``: classes and totals (and the MS-2 volumetrics when asked)."""
    res = compute(cfg)
    unit = "m^2" if res["dim"] == 2 else "m^3"
    line = (f"{len(res['class_share'])} classes ({cfg.volumetrics.kind}); "
            + ", ".join(f"{k} {v:.4g} {unit}" for k, v in zip(TOTALS, res["totals"])))
    if "mix_design" in res:
        line += "; " + _mix_design_line(dict(zip(MIX_NAMES, res["mix_design"])), cfg.volumetrics.mix_design)
    return line


register_stage(StageType("gradation", FIELDS, run, needs_input=False, check=_check, describe=describe,
                         case_check=_case_check, provides=("bodies/*", "spheres/*", "gradation/*", "records/*"),
                         doc="sieve table, size classes and their target volumes or areas"))
