"""``polygons`` stage: random convex aggregate polygons in a 2D section (seed 001, the patent).

Reads the previous stage's ``gradation`` group (class sizes and class areas S m n_t)
and places random convex polygons in the specimen, classes largest first, until every
class area is reached. Each polygon (patent steps 1.2-1.9):

1. a random centre in the specimen and a vertex count m in ``vertices`` (6-10);
2. polar angles theta_i = theta_{i-1} + (2 pi / m)(1 + delta (2 lambda - 1)), lambda uniform
   in [0, 1), delta = ``angle_fluctuation``, from a random phase (the patent starts at 0;
   the phase only makes orientations isotropic);
3. polar radii uniform in the class's half sizes [d_lower / 2, d_upper / 2] (the patent's
   radius formulas are images missing from the text: a polygon of class [d_j, d_j+1]
   then spans about d_j to d_j+1 across);
4. convex hull by Graham's scan (lowest vertex first, sort by polar angle, pop reflex
   vertices: the patent's steps a-f; ``demcli.kernels.polygons.graham_scan``);
5. redrawn (all of 1-4) when it leaves the specimen or intersects a placed polygon.

The class of the next polygon follows the patent's rule: class j while the cumulative
placed area is below ss_1 + ... + ss_j. Each class ends exactly on its area: a polygon is
kept as drawn while the rest of the class can still be made of whole in-class polygons;
otherwise it is scaled to rest / k (k whole polygons of typical size; radii must stay in
the class, else it is redrawn), which the patent leaves open (its last polygon of a class
overshoots into the next class's share).

The intersection test is exact (``test: exact``): separating axes over the edge normals
of both convex polygons after a uniform-grid broad phase on bounding boxes. ``test:
bounding_circle`` is the conservative test the patent improves on (reject whenever the
circles around the polygons overlap); it stops early at high aggregate content (see
docs/polygons.md). Output: the ``polygons`` group, ``records/classes``, and
``<stage>/polygons.vtu`` (polygon cells) with ``specimen.vtu`` (its outline) for ParaView.
"""

import math

import numpy as np

from demcli.config.schema import Float, Int, Section, Str, Tagged
from demcli.errors import InputError, StageError
from demcli.stages.base import StageType, earlier_stage, register_stage, require_dimension
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

describe_column("target", "Target area", "mm^2", table="classes", doc="aggregate area of the class, as asked")
describe_column("placed", "Placed area", "mm^2", table="classes", doc="area of the polygons placed in the class")

register_group("polygons", "Aggregate polygons of a 2D section (seed 001)", writer="stage polygons")
for _name, _kind, _dims, _unit, _doc in [
        ("vertex_start", "i", ("n_p_plus_1",), "", "CSR offsets: polygon p is vertices[vertex_start[p]:"
                                                 "vertex_start[p + 1]] (n_p + 1 entries)"),
        ("vertices", "f", ("n_pv", 2), "m", "polygon vertices, counter-clockwise, specimen centre at the origin"),
        ("class", "i", ("n_p",), "", "size class of each polygon (index into gradation/class_*)"),
        ("area", "f", ("n_p",), "m^2", "polygon area"),
        ("centroid", "f", ("n_p", 2), "m", "polygon area centroid"),
        ("specimen_shape", "i", (), "", "0 circle, 1 rectangle (centred at the origin)"),
        ("specimen_size", "f", (2,), "m", "circle: (radius, radius); rectangle: (width, height)"),
        ("class_target", "f", ("n_class",), "m^2", "target area of each class"),
        ("class_placed", "f", ("n_class",), "m^2", "placed area of each class"),
        ("class_tries", "i", ("n_class",), "", "placement attempts of each class")]:
    register(Field(f"polygons/{_name}", _kind, _dims, _unit, _doc, writer="stage polygons"))

SPECIMEN_2D = Tagged("shape", {
    "circle": Section({"radius": Float("m", min=0, min_inclusive=False)}),
    "rectangle": Section({"width": Float("m", min=0, min_inclusive=False),
                          "height": Float("m", min=0, min_inclusive=False)}),
}, doc="the section, centred at the origin (the same as the gradation stage's specimen)")

FIELDS = {
    "specimen": SPECIMEN_2D,
    "vertices": Section({
        "min": Int(min=3, default=6, doc="fewest vertices drawn (m1)"),
        "max": Int(min=3, default=10, doc="most vertices drawn (m2)"),
    }, default={}, doc="vertex count range of a drawn polygon (before the hull)"),
    "angle_fluctuation": Float(min=0, max=1, max_inclusive=False, default=0.5,
                               doc="delta: each polar angle step is (2 pi / m)(1 + delta (2 lambda - 1))"),
    "test": Str(choices=["exact", "bounding_circle"], default="exact",
                doc="intersection test: exact separating axes, or conservative bounding circles"),
    "gap": Float("m", min=0, default=0.0, doc="clearance between polygons and to the boundary"),
    "max_tries": Int(min=1, default=200000, doc="consecutive failed placements before the stage gives up"),
}


def _check(node, report):
    if node.vertices.max < node.vertices.min:
        report("vertices.max", f"must be >= vertices.min ({node.vertices.min})", node.vertices.max)


def _case_check(cfg, case, k, scene, report):
    """A 2D case, and the specimen of the gradation stage the classes come from."""
    from demcli.stages.specimen.gradation import specimen_amount

    require_dimension(case, 2, "a polygons section", report)
    grading = earlier_stage(case, k, "gradation")
    if grading is None:
        return
    mine, theirs = specimen_amount(cfg.specimen)[0], specimen_amount(grading.specimen)[0]
    if not math.isclose(mine, theirs, rel_tol=1e-9):
        report("specimen", f"its area {mine:.6g} m^2 differs from the {theirs:.6g} m^2 of stage {grading.name!r}; "
               "give both stages the same specimen")


def _specimen(cfg):
    from demcli.geometry.section2d import Specimen

    return Specimen.from_config(cfg.specimen)


def run(ctx, cfg, state_in):
    from demcli.geometry.section2d import place_polygons
    from demcli.state.vtu_polygons import write_outline_vtu, write_polygons_vtu

    g = state_in.groups["gradation"]
    spec = _specimen(cfg)
    s_grad = float(g["totals"][0])
    if not math.isclose(spec.area, s_grad, rel_tol=1e-9):
        raise InputError(f"stage {ctx.name}: specimen area {spec.area:.6g} m^2 differs from the gradation "
                         f"stage's {s_grad:.6g} m^2; give both stages the same specimen")
    lower = np.asarray(g["class_lower"], float)
    upper = np.asarray(g["class_upper"], float)
    target = np.asarray(g["class_amount"], float)
    order = np.argsort(-upper, kind="stable")
    pl = place_polygons(ctx.rng, spec, lower / 2, upper / 2, target, order=order,
                        vertices=(cfg.vertices.min, cfg.vertices.max), angle_fluctuation=cfg.angle_fluctuation,
                        gap=cfg.gap, test=cfg.test, max_tries=cfg.max_tries)
    folder = ctx.snapshot_dir
    write_outline_vtu(folder / "specimen.vtu", spec.outline())
    write_polygons_vtu(folder / "polygons.vtu", pl.vertex_start, pl.vertices,
                       {"polygon": np.arange(len(pl)), "class": pl.pclass, "area": pl.area,
                        "size_lower": lower[pl.pclass], "size_upper": upper[pl.pclass]})
    share = pl.placed.sum() / spec.area
    if not pl.complete:
        c = pl.failed_class
        raise StageError(
            f"stage {ctx.name}: class {lower[c] * 1e3:g}-{upper[c] * 1e3:g} mm reached "
            f"{100 * pl.placed[c] / target[c]:.1f} % of its area after {cfg.max_tries} failed placements in a row; "
            f"aggregate {100 * share:.1f} % of the section placed of {100 * target.sum() / spec.area:.1f} %"
            + (" (the bounding-circle test is conservative; try test: exact)" if cfg.test != "exact" else
               "; lower the aggregate content or raise max_tries")
            + f". Partial placement: {folder / 'polygons.vtu'}")
    state = ctx.new_state()
    state.groups["bodies"] = {k: v.copy() for k, v in state_in.groups["bodies"].items()}
    state.groups["spheres"] = {k: v.copy() for k, v in state_in.groups["spheres"].items()}
    state.groups["gradation"] = {k: np.asarray(v).copy() for k, v in g.items()}
    state.groups["polygons"] = {
        "vertex_start": pl.vertex_start, "vertices": pl.vertices, "class": pl.pclass, "area": pl.area,
        "centroid": pl.centroid, "specimen_shape": np.int64(spec.kind),
        "specimen_size": np.asarray(spec.size, float), "class_target": target, "class_placed": pl.placed,
        "class_tries": pl.tries}
    table = class_table(pl, lower, upper)
    table.to_state(state)
    ctx.write_records(table, x="upper", ys=["target", "placed"])
    worst = max((abs(p - t) / t for p, t in zip(pl.placed, target) if t > 0), default=0.0)
    ctx.log(f"{len(pl)} polygons ({cfg.test} test) in {pl.seconds:.2f} s, {int(pl.tries.sum())} tries; aggregate "
            f"{100 * share:.2f} % of the section (target {100 * target.sum() / spec.area:.2f} %), largest class "
            f"error {100 * worst:.2g} %" + (f"; {int(pl.out_of_class.sum())} polygons scaled out of their class"
                                            if pl.out_of_class.sum() else ""))
    return state


def class_table(pl, lower, upper):
    """Record table of the placement per class (sizes mm, areas mm^2)."""
    from demcli.geometry import polygon_sieve_size
    from demcli.state import RecordTable

    sieve = np.array([polygon_sieve_size(pl.polygon(p)) for p in range(len(pl))])
    table = RecordTable("classes", {"lower": "mm", "upper": "mm", "target": "mm^2", "placed": "mm^2",
                                    "error": "%", "count": "1", "tries": "1", "acceptance": "%",
                                    "out_of_class": "1", "sieve_in_class": "%"})
    for c in range(len(lower)):
        mine = pl.pclass == c
        inside = (sieve[mine] >= lower[c]) & (sieve[mine] <= upper[c])
        t = pl.target[c]
        table.append(lower=lower[c] * 1e3, upper=upper[c] * 1e3, target=t * 1e6, placed=pl.placed[c] * 1e6,
                     error=100 * (pl.placed[c] - t) / t if t > 0 else 0.0, count=int(mine.sum()),
                     tries=int(pl.tries[c]), acceptance=100 * pl.accepted[c] / pl.tries[c] if pl.tries[c] else 0.0,
                     out_of_class=int(pl.out_of_class[c]),
                     sieve_in_class=100 * float(inside.mean()) if mine.any() else 0.0)
    return table


register_stage(StageType(
    "polygons", FIELDS, run, check=_check, case_check=_case_check,
    requires=("gradation/class_lower", "gradation/class_upper", "gradation/class_amount", "gradation/totals"),
    provides=("polygons/*", "records/*"), keeps=("bodies", "spheres", "gradation"),
    doc="random convex aggregate polygons placed without intersection in a 2D section (seed 001)"))
