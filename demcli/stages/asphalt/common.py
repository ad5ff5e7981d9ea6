"""Shared pieces of the 3D asphalt stages (seed 000): state groups, aggregate clumps, VTU.

The pipeline ``gradation -> place_spheres -> carve -> compact -> cut -> mastic`` passes
these groups along (see docs/asphalt3d.md):

* ``seeds``: the spheres placed by gradation, kept after the spheres are deleted
  (centre, radius, class, material), with what became of each;
* ``aggregates``: one row per carved aggregate: its body, class, sieve size, volume and
  its cutting planes in the body frame (so every later stage can check that the member
  balls still lie between them);
* ``specimen`` (cut), ``mastic`` and ``phases`` (mastic).

Aggregates are bodies ``0 .. n_agg - 1``; mastic balls, when present, follow.
"""

import math

import numpy as np

from demcli.config.schema import Float, Optional, Section, Str
from demcli.state.fields import Field, register, register_group

TEST_TIME = Section({
    "dt": Optional(Float("s", min=0, min_inclusive=False), doc="explicit time step (default: auto)"),
    "dt_factor": Float(min=0, max=1, min_inclusive=False, default=0.2),
}, default={}, doc="time step of a test stage (its length follows from the test)")

KINETIC_LIMIT_DOC = ("warn when the kinetic energy exceeds this share of the loading's work W = int F d(delta) on a "
                     "record row (once W has reached 5 % of its largest value; 0.01: see docs/asphalt_lab.md)")
WORK_FLOOR = 0.05
"""Share of the largest loading work from which a row's kinetic energy / work counts for the
quasi-static warning: before it the ratio compares the first contacts' settling (a surface sphere
pushed off a head, the step of the contact stress) with almost no work and says nothing of the
loading rate."""

SEEDS_WRITER = "stage place_spheres (updated by carve)"
AGG_WRITER = "stage carve (updated by cut and mastic)"

register_group("seeds", "Seed spheres of the carving (seed 000): placed by gradation, then deleted",
               writer=SEEDS_WRITER)
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("centre", "f", ("n_seed", 3), "m", "sphere centre", {}),
        ("radius", "f", ("n_seed",), "m", "sphere radius", {}),
        ("class", "i", ("n_seed",), "", "gradation class the radius was drawn from (gradation/class_*)", {}),
        ("material", "i", ("n_seed",), "", "material of the aggregate carved from it", {"index_of": "n_m"}),
        ("status", "i", ("n_seed",), "", "0 placed, 1 carved into an aggregate, 2 no lattice ball inside, "
                                         "3 dropped as fines, 4 removed by the gradation adjustment",
         {"dtype": "int8"}),
        ("round", "i", ("n_seed",), "", "adjustment round that placed it (0: the place_spheres stage)", {}),
        ("region", "f", (6,), "m", "box the seeds were placed in: xmin ymin zmin xmax ymax zmax", {})]:
    register(Field(f"seeds/{_name}", _kind, _dims, _unit, _doc, writer=SEEDS_WRITER, **_kw))

register_group("aggregates", "Carved aggregates (seed 000): rigid clumps of lattice balls, one row each",
               writer=AGG_WRITER)
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("body", "i", ("n_agg",), "", "body of the aggregate (aggregates are bodies 0 .. n_agg - 1)",
         {"index_of": "n_b"}),
        ("seed", "i", ("n_agg",), "", "seed sphere it was carved from", {"index_of": "n_seed"}),
        ("seed_class", "i", ("n_agg",), "", "gradation class of its seed sphere", {}),
        ("size_class", "i", ("n_agg",), "", "class by virtual sieving (-1: passes the smallest class sieve)", {}),
        ("sieve_size", "f", ("n_agg",), "m", "sieve size of the clump (projection method)", {}),
        ("volume", "f", ("n_agg",), "m^3", "solid volume: members x element volume (see mass_model)", {}),
        ("plane_normal", "f", ("n_agg", 3, 3), "1", "unit normals of the three cutting-plane pairs, body frame", {}),
        ("plane_spacing", "f", ("n_agg", 3), "m", "full spacing d_p of each plane pair", {}),
        ("seed_offset", "f", ("n_agg", 3), "m", "seed sphere centre (the planes' centre), body frame", {}),
        ("seed_radius", "f", ("n_agg",), "m", "seed sphere radius", {}),
        ("lattice_axes", "f", ("n_agg", 3, 3), "1", "the lattice's x, y, z unit vectors in the body frame "
                                                   "(member cells are cubes along them)", {}),
        ("widths", "f", ("n_agg", 3), "m", "width of the carved polyhedron (sphere and slabs) along each "
                                           "plane normal", {}),
        ("ball_widths", "f", ("n_agg", 3), "m", "extent of the member balls along each plane normal", {}),
        ("drawn_ratio", "f", ("n_agg",), "1", "drawn ratio of the largest to the smallest polyhedron width", {}),
        ("flat_elongated", "i", ("n_agg",), "", "1 when max(widths) / min(widths) >= fe_ratio", {"dtype": "int8"}),
        ("ball_radius", "f", (), "m", "radius of the lattice balls (spacing / 2)", {}),
        ("lattice_origin", "f", (3,), "m", "centre of lattice ball (0, 0, 0)", {}),
        ("lattice_counts", "i", (3,), "", "lattice balls along x, y, z", {}),
        ("mass_model", "str", (), "", "'cells': a member stands for its lattice cell; 'balls': for its ball", {}),
        ("fe_ratio", "f", (), "1", "width ratio from which a particle counts as flat/elongated", {})]:
    register(Field(f"aggregates/{_name}", _kind, _dims, _unit, _doc, writer=AGG_WRITER, **_kw))

FLAG_FIXED = 0


def seed_status_text():
    return {0: "placed", 1: "carved", 2: "empty", 3: "fines", 4: "removed"}


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------

def copy_group(state_in, name):
    """A deep copy of a group of the input state (or None when absent)."""
    g = state_in.groups.get(name)
    if g is None:
        return None
    return {k: np.array(v, copy=True) for k, v in g.items()}


def scalar_str(value):
    """A scalar string dataset (str, bytes, 0-d or 1-element array) as str."""
    v = np.asarray(value).reshape(-1)[0] if np.ndim(value) else np.asarray(value).reshape(()).item()
    return v.decode() if isinstance(v, bytes) else str(v)


def quat_matrix(q):
    """Rotation matrices (n, 3, 3) body -> world of unit quaternions (w, x, y, z)."""
    from scipy.spatial.transform import Rotation

    q = np.asarray(q, float).reshape(-1, 4)
    return Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_matrix()


def build_aggregate_bodies(start, points, ball_radius, density, mass_model, normals_w, spacing_p, seed_w,
                           seed_radius, material, lattice_w=None):
    """Bodies, spheres and per-aggregate plane fields of clumps given in the world frame.

    start/points: CSR of member centres (m) per aggregate; density: kg/m^3, one value or
    one per aggregate; normals_w (n, 3, 3) and seed_w (n, 3) the cutting planes in the
    world frame; spacing_p (n, 3); material (n,); lattice_w (n, 3, 3) the lattice's unit
    vectors in the world frame (default: the world axes, as at carving).
    Returns (bodies, spheres, planes) with planes = dict(plane_normal, seed_offset) in
    each body's principal frame. Members keep their order; spheres are grouped by body.
    """
    from demcli.geometry.carving import clump_set

    cs = clump_set(start, points, 2.0 * ball_radius, 1.0, mass_model)
    n = len(start) - 1
    rho = np.broadcast_to(np.asarray(density, float), (n,))
    axes = cs.axes
    bodies = {"x": cs.com, "v": np.zeros((n, 3)), "q": cs.quat, "omega": np.zeros((n, 3)),
              "mass": cs.mass * rho, "inertia": cs.moments * rho[:, None], "id": np.arange(n, dtype=np.int64),
              "flags": np.zeros(n, np.int8)}
    owner = np.repeat(np.arange(n, dtype=np.int64), cs.count)
    spheres = {"body": owner, "offset": cs.offsets, "radius": np.full(len(owner), ball_radius),
               "material": np.asarray(material, np.int64)[owner]}
    if lattice_w is None:
        lattice_w = np.broadcast_to(np.eye(3), (n, 3, 3))
    planes = {"plane_normal": np.einsum("kji,kpj->kpi", axes, normals_w),   # A^T n
              "seed_offset": np.einsum("kji,kj->ki", axes, seed_w - cs.com),
              "plane_spacing": np.asarray(spacing_p, float), "seed_radius": np.asarray(seed_radius, float),
              "lattice_axes": np.einsum("kji,kpj->kpi", axes, lattice_w)}
    return bodies, spheres, planes, cs


def world_planes(state, with_lattice=False):
    """Cutting planes of every aggregate in the world frame: (normals (n, 3, 3), centres (n, 3)),
    plus the lattice unit vectors (n, 3, 3) when ``with_lattice``."""
    ag = state.groups["aggregates"]
    body = np.asarray(ag["body"], np.int64)
    rot = quat_matrix(state["bodies/q"][body])
    normals = np.einsum("kij,kpj->kpi", rot, ag["plane_normal"])
    centres = state["bodies/x"][body] + np.einsum("kij,kj->ki", rot, ag["seed_offset"])
    if with_lattice:
        return normals, centres, np.einsum("kij,kpj->kpi", rot, ag["lattice_axes"])
    return normals, centres


def inside_member_cells(state, points):
    """Which points lie in an aggregate: inside the lattice cell (cube of side 2 r along
    the aggregate's lattice axes) of one of its member balls; the voxel model of the
    carved polyhedra (``mass_model: cells``), wherever the aggregates have moved."""
    from scipy.spatial import cKDTree

    pts = np.asarray(points, float)
    out = np.zeros(len(pts), bool)
    if len(pts) == 0 or "aggregates" not in state.groups:
        return out
    agg = phase_of_spheres(state)
    mine = np.flatnonzero(agg >= 0)
    if len(mine) == 0:
        return out
    _, _, lat = world_planes(state, with_lattice=True)
    centres = state.sphere_centres()[mine]
    axes = lat[agg[mine]]  # (m, 3, 3): rows are the lattice unit vectors
    a = 2.0 * float(np.asarray(state.groups["aggregates"]["ball_radius"]))
    tree = cKDTree(centres)
    k = 8  # a point lies in at most one cell per aggregate; 8 neighbours cover nested ones
    dist, idx = tree.query(pts, k=k, distance_upper_bound=0.5 * math.sqrt(3.0) * a * (1 + 1e-9))
    for col in range(k):
        ok = np.isfinite(dist[:, col])
        if not ok.any():
            continue
        j = idx[ok, col]
        rel = np.einsum("npi,ni->np", axes[j], pts[ok] - centres[j])
        out[np.flatnonzero(ok)[np.all(np.abs(rel) <= 0.5 * a, axis=1)]] = True
    return out


def plane_violations(state, tol=1e-9):
    """Largest excess (m) of a member ball centre beyond its aggregate's planes or sphere.

    0 (or below ``tol`` x spacing) when every member centre satisfies the six plane
    inequalities |n_p . (x - c)| <= d_p / 2 and lies inside the seed sphere.
    """
    ag = state.groups["aggregates"]
    body = np.asarray(ag["body"], np.int64)
    agg_of_body = np.full(len(state["bodies/mass"]), -1, np.int64)
    agg_of_body[body] = np.arange(len(body))
    sb = np.asarray(state["spheres/body"], np.int64)
    mine = agg_of_body[sb] >= 0
    k = agg_of_body[sb[mine]]
    off = np.asarray(state["spheres/offset"])[mine]
    d = off - np.asarray(ag["seed_offset"])[k]
    proj = np.abs(np.einsum("ij,ipj->ip", d, np.asarray(ag["plane_normal"])[k]))
    slab = proj - 0.5 * np.asarray(ag["plane_spacing"])[k]
    sphere = np.linalg.norm(d, axis=1) - np.asarray(ag["seed_radius"])[k]
    if len(k) == 0:
        return 0.0
    return float(max(slab.max(), sphere.max()))


def phase_of_spheres(state):
    """Aggregate index of each sphere (-1 for spheres of other bodies, e.g. mastic)."""
    ag = state.groups.get("aggregates")
    nb = len(state["bodies/mass"])
    agg_of_body = np.full(nb, -1, np.int64)
    if ag is not None:
        agg_of_body[np.asarray(ag["body"], np.int64)] = np.arange(len(ag["body"]))
    return agg_of_body[np.asarray(state["spheres/body"], np.int64)]


def write_asphalt_vtu(path, state):
    """Spheres as a VTU with the usual point data plus ``aggregate`` (index, -1 for mastic),
    ``size_class`` (sieve class, -1 for mastic and fines), ``seed_class`` and ``phase``
    (0 aggregate, 1 mastic). In ParaView: Glyph (Sphere, scale by diameter), colour by
    ``phase``, ``aggregate`` or ``size_class``."""
    import meshio

    from demcli.state.atomic import atomic_path
    from demcli.state.vtu import sphere_mesh

    mesh = sphere_mesh(state)
    agg = phase_of_spheres(state)
    ag = state.groups.get("aggregates", {})
    size_class = np.asarray(ag.get("size_class", np.zeros(0, np.int64)), np.int64)
    seed_class = np.asarray(ag.get("seed_class", np.zeros(0, np.int64)), np.int64)
    has = agg >= 0
    mesh.point_data["aggregate"] = agg
    mesh.point_data["size_class"] = np.where(has, size_class[np.maximum(agg, 0)] if len(size_class) else -1, -1)
    mesh.point_data["seed_class"] = np.where(has, seed_class[np.maximum(agg, 0)] if len(seed_class) else -1, -1)
    mesh.point_data["phase"] = np.where(has, 0, 1).astype(np.int64)
    path = __import__("pathlib").Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as tmp:
        meshio.write(tmp, mesh, file_format="vtu", binary=True, compression="zlib")
    return path


def solid_volume(state):
    """Total aggregate volume (m^3) of the state's ``aggregates`` group."""
    ag = state.groups.get("aggregates")
    return float(np.sum(ag["volume"])) if ag is not None else 0.0


ORIENTATIONS = {
    "diametral": "loaded across the cylinder's axis (z), along x: indirect tension, Marshall stability",
    "axial": "loaded along the cylinder's axis (z): dynamic modulus",
}


def orientation_field(default):
    """The ``orientation`` key of a test stage: how the load meets the specimen's axis."""
    return Str(choices=tuple(ORIENTATIONS), default=default,
               doc="how the load meets the cylinder's axis (z; the axis of a prepare stage's specimen and of a "
                   "cut stage's cylinder): " + "; ".join(f"{k}: {v}" for k, v in ORIENTATIONS.items()))


def orientation_check(cfg, case, k, report, needed, test):
    """Report an ``orientation`` other than ``needed`` (the one ``test`` is defined for) and, for
    a diametral test in 3D, a prism cut by an earlier ``cut`` stage (no axis to load across)."""
    from demcli.stages.base import earlier_stage

    if cfg.orientation != needed:
        report("orientation", f"{test} is {needed}: {ORIENTATIONS[needed]}", cfg.orientation)
    cut = earlier_stage(case, k, "cut") if case.dimension == 3 else None
    if needed == "diametral" and cut is not None and cut.shape.shape != "cylinder":
        report("orientation", f"{test} loads a cylinder across its axis: the specimen of stage {cut.name!r} is a "
                              f"{cut.shape.shape}; cut a cylinder", cfg.orientation)


def cylinder_specimen(groups, x, where):
    """(radius [m], height [m], base (3,) [m]: centre of the lower face) of a 3D test's cylinder
    (axis z): a prepare stage's ``bonded_specimen`` (base at the sphere centres' mean x, y), or
    the cylinder of a cut stage's ``specimen`` group (the 3D Marshall specimen of the mastic
    stage). An InputError naming ``where`` when the input holds neither, or a cut prism."""
    from demcli.errors import InputError
    from demcli.stages.asphalt.mastic import str_list

    sp = groups.get("bonded_specimen")
    if sp is not None:
        return float(sp["radius"]), float(sp["height"]), np.array([*x[:, :2].mean(axis=0), float(sp["base_z"])])
    cut = groups.get("specimen")
    if cut is None:
        raise InputError(f"{where}: its input has no bonded_specimen group (a prepare stage) and no cut specimen "
                         "(a cut stage)")
    shape = str_list(cut["shape"])[0]
    if shape != "cylinder":
        raise InputError(f"{where}: the cut specimen is a {shape}, not a cylinder")
    centre, size = np.asarray(cut["centre"], float), np.asarray(cut["size"], float)
    return 0.5 * float(size[0]), float(size[2]), np.array([centre[0], centre[1], centre[2] - 0.5 * size[2]])


def lab_case_check(cfg, case, k, scene, report, specimen=True):
    """Case rules of a laboratory test stage (``idt``, ``marshall``, ``dynamic_modulus``): those of
    a dem stage (:func:`demcli.stages.dem.scene_check`); in 3D, when ``specimen``, the input's
    ``bonded_specimen`` group (a prepare stage) or a cut stage's ``specimen`` (the mastic stage's
    3D Marshall specimen, bonded by ``bonds.from_phases``); in 2D a section of disks (discretize,
    or any planar scene); in both, bonds in the input or a ``bonds`` section that creates them."""
    from demcli.stages import dem
    from demcli.stages.base import has_field

    dem.scene_check(cfg, case, k, scene, report)
    if scene is None:
        return
    if case.dimension == 3 and specimen and not (has_field(scene, "bonded_specimen/radius")
                                                 or has_field(scene, "specimen/size")):
        report("", "reads bonded_specimen/radius (a prepare stage) or specimen/size (a cut stage) from the input, "
                   "which no earlier stage writes (or run it on a 2D section, dimension: 2)")
    if not has_field(scene, "bonds/i") and not (cfg.get("bonds") is not None and cfg.bonds.create):
        report("bonds", "the input holds no bonds: give bonds: {create: true, models: [...]} to bond the specimen's "
                        "touching spheres at the stage start", None)


def planar_slab(case, x):
    """(thickness t [m], z of the disks' plane [m]) of a 2D case with body centres ``x`` (n, 3):
    the case's out-of-plane ``thickness`` (disks are plane-stress slices of that thickness: no
    stress and free strain out of the plane) and the plane z = mean z of the bodies."""
    return float(case.thickness), float(np.mean(x[:, 2])) if len(x) else 0.0


def kinetic_to_work(kinetic, force, displacement):
    """Quasi-static measure of a loading test per record row: (E_k / W, W).

    kinetic: (n,) kinetic energy of the bodies [J]; force: (n,) the loading's force [N], in the
    direction of ``displacement`` (n,) [m], the loaded boundary's travel since the first row.
    W_k = sum_{l <= k} (F_l + F_{l-1}) / 2 (u_l - u_{l-1}) [J] is the work done on the specimen
    (trapezoid over the rows). A quasi-static test turns nearly all of it into strain energy
    and losses, so E_k / W is small; a harmonic load at f on a specimen of natural frequency
    f_n gives E_k / W of order (f / f_n)^2. NaN where W <= 0.
    """
    f, u = np.asarray(force, float), np.asarray(displacement, float)
    work = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(u))])
    return kinetic_ratio(kinetic, work), work


def kinetic_ratio(kinetic, work):
    """E_k / W per row (NaN where the work W <= 0); kinetic [J], work [J] (n,)."""
    work = np.asarray(work, float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(work > 0.0, np.asarray(kinetic, float) / work, np.nan)


def quasi_static_warning(ctx, ratio, work, limit, advice, upto=None):
    """Log a warning when E_k / W (``ratio``, from :func:`kinetic_to_work`) exceeds ``limit`` on a
    row (rows ``upto`` and before, when given) whose work W has reached ``WORK_FLOOR`` of its largest
    value. Returns the largest such ratio (NaN when no row counts)."""
    n = len(ratio) if upto is None else upto + 1
    w = np.asarray(work[:n], float)
    counted = np.flatnonzero(w >= WORK_FLOOR * w.max()) if n and w.max() > 0 else np.zeros(0, np.int64)
    if len(counted) == 0:
        return math.nan
    worst = float(np.max(ratio[counted]))
    if worst > limit:
        ctx.log(f"warning: the loading is not quasi-static: kinetic energy {worst:.3g} of the work done (above "
                f"{limit:g}, from the row where the work reaches {WORK_FLOOR:g} of its largest); {advice}")
    return worst


def box_of_walls(state_or_groups):
    """(lo (3,), hi (3,)) of axis-aligned plane walls in a state (None when there are none)."""
    groups = state_or_groups.groups if hasattr(state_or_groups, "groups") else state_or_groups
    w = groups.get("walls")
    if not w or len(w.get("kind", [])) == 0:
        return None
    lo = np.full(3, -math.inf)
    hi = np.full(3, math.inf)
    for k in range(len(w["kind"])):
        if int(w["kind"][k]) != 0:
            continue
        n = np.asarray(w["normal"][k], float)
        d = int(np.argmax(np.abs(n)))
        if abs(abs(n[d]) - 1.0) > 1e-9:
            continue
        p = float(w["point"][k][d])
        if n[d] > 0:
            lo[d] = max(lo[d], p)
        else:
            hi[d] = min(hi[d], p)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        return None
    return lo, hi
