"""``discretize`` stage: a 2D section of polygons becomes clumps and mastic balls (seed 001).

Reads the previous stage's ``polygons`` group (and ``gradation/totals`` for the void
area) and, as the patent's steps 3-5 do in PFC2D:

1. fills the specimen with hexagonally packed balls of radius ``ball_radius`` (0.3 mm in
   the patent); a ball sits at the specimen centre and every ball lies wholly inside;
2. the balls whose centres lie inside a polygon (``membership: whole``: the whole ball)
   become that aggregate's rigid clump, material ``aggregate.material``;
3. the other balls are mastic (one single-ball body each, material ``mastic.material``);
4. random mastic balls are deleted until the void area reaches S VV (``gradation/totals``):
   n = round(S VV / a) balls, with a the area a ball stands for: its hexagonal cell,
   2 sqrt(3) r^2 (``void_ball_area: cell``, the default: the void share of the lattice
   sites is then VV), or the disk, pi r^2 (``disk``).

Bodies are disks in the plane z = 0 with masses per case ``thickness``. A clump's members
lie 2r apart on the lattice, so they do not overlap and its mass properties are exact
sums (``demcli.geometry.section2d.group_disk_properties``): each member a lamina disk
(I_xx = I_yy = m r^2/4, I_zz = m r^2/2) carried to the clump's centre by parallel axes.
The clump's body frame is its principal frame: in-plane principal axes plus z, with
q the rotation about z by the principal angle and member offsets given in that frame,
so the engine's planar clump integrator (which turns only about z, using I_zz) sees the
principal moments it expects. Single balls (mastic, one-ball aggregates) follow the
generate stage's 2D convention, I = m r^2/2 on all three axes.

Output: bodies and spheres, the ``section`` group (body -> polygon, void centres, phase
areas), ``polygons`` and ``gradation`` passed on, ``records/classes`` (polygon area against
clump area per class) and ``<stage>/spheres.pvd`` (colour by ``material`` or ``body_id``)
with ``polygons.vtu``.
"""

import math

import numpy as np

from demcli.config.schema import Float, Section, Str
from demcli.errors import StageError
from demcli.stages.base import StageType, earlier_stage, register_stage, require_dimension
from demcli.state.fields import Field, register, register_group

register_group("section", "Phases of a discretized 2D section (seed 001)", writer="stage discretize")
for _name, _kind, _dims, _unit, _doc in [
        ("body_polygon", "i", ("n_b",), "", "polygon of each body (index into polygons/*), -1 for mastic"),
        ("void_centres", "f", ("n_void", 2), "m", "centres of the deleted mastic balls (the air voids)"),
        ("areas", "f", (6,), "m^2", "specimen S, polygons, aggregate balls x cell, mastic balls x cell, "
                                    "deleted balls x void_ball_area, target voids S VV (cell = 2 sqrt(3) r^2)"),
        ("ball_radius", "f", (), "m", "radius of the lattice balls")]:
    register(Field(f"section/{_name}", _kind, _dims, _unit, _doc, writer="stage discretize"))

FIELDS = {
    "ball_radius": Float("m", min=0, min_inclusive=False, doc="radius of the hexagonally packed balls"),
    "aggregate": Section({
        "material": Str(doc="material of the aggregate clumps"),
        "membership": Str(choices=["centre", "whole"], default="centre",
                          doc="a ball joins a polygon's clump when its centre (or the whole ball) is inside"),
    }),
    "mastic": Section({"material": Str(doc="material of the mastic balls")}),
    "void_ball_area": Str(choices=["cell", "disk"], default="cell",
                          doc="area one deleted ball counts for: its hexagonal cell 2 sqrt(3) r^2, or pi r^2"),
}


def _check(node, report):
    if node.aggregate.material == node.mastic.material:
        report("mastic.material", "must differ from aggregate.material (phases are told apart by material)",
               node.mastic.material)


def _case_check(cfg, case, k, scene, report):
    """A 2D case, and memory for the balls over the section of the polygons stage before
    (a hexagonal cell is 2 sqrt(3) r^2)."""
    from demcli.config.memory import check_memory
    from demcli.stages.specimen.gradation import specimen_amount

    require_dimension(case, 2, "a discretized section", report)
    section = earlier_stage(case, k, "polygons")
    if section is not None:
        area = specimen_amount(section.specimen)[0]
        check_memory(report, "ball_radius", area / (2.0 * math.sqrt(3.0) * cfg.ball_radius ** 2),
                      f"the balls over the section of stage {section.name!r}", cfg.ball_radius)


def group_disk_properties(group, centres, r, areal_density, n_group):
    """Mass properties of rigid groups of equal non-overlapping disks (vectorised).

    group: (n,) group index of each disk (0 <= group < n_group); centres (n, 2) m; r m;
    areal_density kg/m^2. Returns (count (n_group,), mass (n_group,), com (n_group, 2),
    moments (n_group, 3) principal [I_1, I_2, I_zz] with I_1 <= I_2, angle (n_group,) of
    the first principal axis from x, offsets (n, 2) of each disk from its group's centre
    in the group's principal frame). Exact for non-overlapping disks (see module doc).
    """
    count = np.bincount(group, minlength=n_group).astype(float)
    m1 = areal_density * math.pi * r * r
    safe = np.maximum(count, 1.0)
    com = np.stack([np.bincount(group, centres[:, 0], n_group), np.bincount(group, centres[:, 1], n_group)],
                   axis=1) / safe[:, None]
    d = centres - com[group]
    cxx = np.bincount(group, d[:, 0] ** 2, n_group)
    cyy = np.bincount(group, d[:, 1] ** 2, n_group)
    cxy = np.bincount(group, d[:, 0] * d[:, 1], n_group)
    angle = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)  # major axis of the spread: least inertia
    c, s = np.cos(angle)[group], np.sin(angle)[group]
    off = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
    own = count * m1 * r * r / 4.0
    i1 = own + m1 * np.bincount(group, off[:, 1] ** 2, n_group)
    i2 = own + m1 * np.bincount(group, off[:, 0] ** 2, n_group)
    return count, count * m1, com, np.stack([i1, i2, i1 + i2], axis=1), angle, off


def run(ctx, cfg, state_in):
    from demcli.geometry.section2d import Specimen, hex_lattice, label_balls
    from demcli.state import RecordTable
    from demcli.state.vtu import Snapshots
    from demcli.state.vtu_polygons import write_polygons_vtu

    pg = state_in.groups["polygons"]
    g = state_in.groups["gradation"]
    kind = int(np.asarray(pg["specimen_shape"]))
    size = np.asarray(pg["specimen_size"], float)
    spec = Specimen("circle", size[0]) if kind == 0 else Specimen("rectangle", size[0], size[1])
    r = cfg.ball_radius
    start = np.asarray(pg["vertex_start"], np.int64)
    verts = np.asarray(pg["vertices"], float)
    pclass = np.asarray(pg["class"], np.int64)
    n_p = len(start) - 1
    lat = hex_lattice(spec, r)
    label = label_balls(lat, start, verts, cfg.aggregate.membership)
    n_ball = len(label)
    names = list(ctx.case.materials)
    mat_agg, mat_mas = names.index(cfg.aggregate.material), names.index(cfg.mastic.material)
    thick = ctx.case.thickness
    rho_agg = ctx.case.materials[cfg.aggregate.material].density * thick
    rho_mas = ctx.case.materials[cfg.mastic.material].density * thick

    # aggregates: one body per polygon that caught at least one ball
    agg = np.flatnonzero(label >= 0)
    count, mass, com, mom, angle, off = group_disk_properties(label[agg], lat.centres[agg], r, rho_agg, n_p)
    has = count > 0
    body_of_poly = np.full(n_p, -1, np.int64)
    body_of_poly[has] = np.arange(int(has.sum()))
    n_agg = int(has.sum())
    single = count[has] == 1
    mom_b = mom[has]
    m_b = mass[has]
    mom_b[single] = (0.5 * m_b[single] * r * r)[:, None]  # single disks: the generate stage's convention
    ang_b = np.where(single, 0.0, angle[has])

    # mastic and voids
    mastic = np.flatnonzero(label < 0)
    a_ball = lat.cell_area if cfg.void_ball_area == "cell" else math.pi * r * r
    voids_target = float(g["totals"][2])
    n_del = int(round(voids_target / a_ball))
    if n_del > len(mastic):
        raise StageError(f"stage {ctx.name}: the voids need {n_del} balls deleted but only {len(mastic)} are mastic; "
                         "lower the aggregate content or the air voids, or use smaller balls")
    deleted = np.sort(ctx.rng.choice(len(mastic), size=n_del, replace=False)) if n_del else np.zeros(0, np.int64)
    keep = np.ones(len(mastic), bool)
    keep[deleted] = False
    void_centres = lat.centres[mastic[deleted]]
    mastic = mastic[keep]
    n_mas = len(mastic)

    # bodies: aggregates (polygon order), then mastic balls
    nb = n_agg + n_mas
    x = np.zeros((nb, 3))
    x[:n_agg, :2] = com[has]
    x[n_agg:, :2] = lat.centres[mastic]
    m_mas = rho_mas * math.pi * r * r
    q = np.zeros((nb, 4))
    q[:, 0] = 1.0
    q[:n_agg, 0] = np.cos(0.5 * ang_b)
    q[:n_agg, 3] = np.sin(0.5 * ang_b)
    inertia = np.empty((nb, 3))
    inertia[:n_agg] = mom_b
    inertia[n_agg:] = 0.5 * m_mas * r * r
    bodies = {"x": x, "v": np.zeros((nb, 3)), "q": q, "omega": np.zeros((nb, 3)),
              "mass": np.r_[m_b, np.full(n_mas, m_mas)], "inertia": inertia,
              "id": np.arange(nb, dtype=np.int64), "flags": np.zeros(nb, np.int8)}
    order = np.argsort(body_of_poly[label[agg]], kind="stable")
    s_body = np.r_[body_of_poly[label[agg]][order], n_agg + np.arange(n_mas)].astype(np.int64)
    s_off = np.zeros((len(s_body), 3))
    s_off[:len(agg), :2] = off[order]
    spheres = {"body": s_body, "offset": s_off, "radius": np.full(len(s_body), r),
               "material": np.r_[np.full(len(agg), mat_agg), np.full(n_mas, mat_mas)].astype(np.int64)}

    state = ctx.new_state()
    state.groups["bodies"] = bodies
    state.groups["spheres"] = spheres
    state.groups["gradation"] = {k: np.asarray(v).copy() for k, v in g.items()}
    state.groups["polygons"] = {k: np.asarray(v).copy() for k, v in pg.items()}
    poly_of_body = np.r_[np.flatnonzero(has), np.full(n_mas, -1)].astype(np.int64)
    areas = np.array([spec.area, float(np.asarray(pg["area"]).sum()), len(agg) * lat.cell_area,
                      n_mas * lat.cell_area, n_del * a_ball, voids_target])
    state.groups["section"] = {"body_polygon": poly_of_body, "void_centres": void_centres, "areas": areas,
                               "ball_radius": np.float64(r)}

    lower = np.asarray(g["class_lower"], float)
    upper = np.asarray(g["class_upper"], float)
    table = RecordTable("classes", {"lower": "mm", "upper": "mm", "polygons": "1", "clumps": "1", "balls": "1",
                                    "polygon_area": "mm^2", "clump_area": "mm^2", "error": "%"})
    parea = np.asarray(pg["area"], float)
    for c in range(len(lower)):
        mine = pclass == c
        pa = parea[mine].sum()
        balls = int(count[mine].sum())
        ca = balls * lat.cell_area
        table.append(lower=lower[c] * 1e3, upper=upper[c] * 1e3, polygons=int(mine.sum()),
                     clumps=int((has & mine).sum()), balls=balls, polygon_area=pa * 1e6, clump_area=ca * 1e6,
                     error=100 * (ca - pa) / pa if pa > 0 else 0.0)
    table.to_state(state)
    ctx.write_records(table, x="upper", ys=["polygon_area", "clump_area"])
    Snapshots(ctx.snapshot_dir).write(state)
    write_polygons_vtu(ctx.snapshot_dir / "polygons.vtu", start, verts,
                       {"class": pclass, "area": parea, "body": body_of_poly})
    ctx.log(f"{n_ball} balls (r = {r * 1e3:g} mm): {len(agg)} in {n_agg} aggregate clumps "
            f"({n_p - n_agg} polygons caught no ball), {n_mas} mastic, {n_del} deleted for voids "
            f"({100 * n_del * a_ball / spec.area:.3f} % of S, target {100 * voids_target / spec.area:.3f} %)")
    return state


register_stage(StageType(
    "discretize", FIELDS, run, check=_check, case_check=_case_check,
    provides=("bodies/*", "spheres/*", "section/*", "records/*"), keeps=("gradation", "polygons"),
    requires=("polygons/vertex_start", "polygons/vertices", "polygons/class", "polygons/area",
              "polygons/specimen_shape", "polygons/specimen_size", "gradation/totals"),
    doc="hexagonal balls over a 2D section: aggregate clumps inside polygons, mastic, voids (seed 001)"))
