"""``mastic`` stage: mastic balls in the voids and contact models by phase pair (seed 000, steps 9-10).

Reads a cut specimen (``specimen`` and ``aggregates`` groups) and:

1. tiles the specimen with the cells of a simple cubic lattice of mastic balls (radius
   ``ball_radius``, spacing a = 2r; cells whose centre is inside the specimen) and sorts
   each cell into *aggregate* (its centre inside an aggregate: in the lattice cell of one
   of its member balls, a cube of side 2 r_agg along the aggregate's lattice axes, which
   contains the ball) or *void* (the rest): the lattice points not inside any aggregate
   member (ball or cell) are the mastic's candidate sites. The lattice is cell-centred
   on the specimen: along an axis of extent L (height; diameter or side) it holds
   m = round(L / a) >= 1 centres c + (k - (m - 1)/2) a, k = 0 .. m - 1, so a box is
   exactly m_x m_y m_z cells and a cylinder the cells of m_z layers whose centre is in the
   disc (midpoint rule). The voxel extent m a is within a / 2 of L, equals it when L is
   a whole number of cells, and its error has zero mean over L / a; no centre lies
   within a / 4 of an end face, so no cell sits on a face to be counted twice or not at
   all (a lattice of ceil(L / a) + 1 points, as before, put a layer of centres on both
   end faces when L / a was whole, one layer too many: mastic mass 4-12 % high);
2. one mastic ball stands for its cell (volume a^3, mass rho a^3, as an aggregate's
   member stands for its lattice cell), so the specimen is a three-phase voxel model at
   the mastic resolution: aggregate cells, mastic cells, air cells. The number of
   mastic balls N follows from the mastic mass and density, N = round(M / (rho a^3)),
   with M given (``amount: {by: mass}``), or from a target air-void content VV
   (``{by: air_voids}``: N = n_void - round(VV n_cells), i.e. M = rho (V (1 - VV) - V_agg)
   on the lattice), or from the mix design of the gradation stage (``{by: mix}``: mastic
   / aggregate volume of its totals times the aggregate cells). Air voids are
   (n_void - N) / n_cells: within one ball (1 / n_cells) of the target;
3. ``clearance`` (in mastic radii) keeps sites whose ball clears every aggregate ball
   by clearance x r, and the specimen surface likewise: -1 (default) uses every void
   site, whose ball may overlap an aggregate ball by up to r (its centre is outside the
   aggregate balls) or stick out of the specimen by up to r; 0 keeps only sites with no
   overlap. Sites the clearance rejects stay air; when fewer sites remain than the
   mastic needs, the stage stops and says so;
4. ``placement: coat`` takes the sites nearest the aggregates first (the mastic wets
   the stone; the air voids end up in the middle of the pores; sites that overlap an
   aggregate ball come after the clear ones, least overlap first), ``random`` takes
   random sites;
5. assigns a contact model to every pair of phases and stores the table (the ``phases``
   group): aggregate-aggregate ``linear_slip`` (linear springs, Coulomb slip),
   aggregate-mastic ``contact_bond`` (adhesion strengths s2n, s2t as forces),
   mastic-mastic ``parallel_bond`` (cohesion strengths s1n, s1t as stresses, bond
   stiffness per area and radius multiplier); inside an aggregate (``aggregates``): the rigid
   clump (default), or parallel bonds between its lattice balls, which a test stage makes
   (:mod:`demcli.stages.asphalt.bonded`: bonded aggregates whose bonds break).
   Any model may be given to any pair; every pair needs exactly one, and every model
   its stiffnesses and strengths (a missing pair or strength is a config error, and
   :func:`phase_table` re-validates a stored table).

This stage stores and validates the assignment; a ``dem`` stage after it with
``bonds: {from_phases: true, create: true}`` bonds every touching pair by it and runs the
bonds (docs/bonds.md).

Output: bodies (aggregates, then one single-ball body per mastic ball), spheres,
``phases`` (phase of each sphere, the pair table), ``mastic`` (volumetrics),
``records/mastic``, ``<stage>/specimen.vtu`` (colour by ``phase``).
"""

import math

import numpy as np

from demcli.config.schema import Float, List, Section, Str, Tagged
from demcli.errors import InputError, StageError, StateError
# common registers the seeds and aggregates groups
from demcli.stages.asphalt.bonded import AGGREGATES, INTERNAL_MODELS, bond_parameters, tensile_strength
from demcli.stages.asphalt.common import (copy_group, inside_member_cells, phase_of_spheres, scalar_str,
                                          write_asphalt_vtu)
from demcli.stages.base import StageType, earlier_stage, register_stage
from demcli.state.fields import Field, register, register_group

PHASES = ("aggregate", "mastic")

# parameter columns of phases/pair_params, their units, and the models that need them
PARAMS = (("kn", "N/m"), ("ks", "N/m"), ("friction", "1"),
          ("cb_normal_strength", "N"), ("cb_shear_strength", "N"),
          ("pb_kn", "Pa/m"), ("pb_ks", "Pa/m"), ("pb_radius_multiplier", "1"),
          ("pb_normal_strength", "Pa"), ("pb_shear_strength", "Pa"))
MODELS = {
    "linear_slip": ("kn", "ks", "friction"),
    "contact_bond": ("kn", "ks", "friction", "cb_normal_strength", "cb_shear_strength"),
    "parallel_bond": ("kn", "ks", "friction", "pb_kn", "pb_ks", "pb_radius_multiplier", "pb_normal_strength",
                      "pb_shear_strength"),
}
_CONFIG_TO_PARAM = {
    "contact_bond": {"normal_strength": "cb_normal_strength", "shear_strength": "cb_shear_strength"},
    "parallel_bond": {"bond_kn": "pb_kn", "bond_ks": "pb_ks", "radius_multiplier": "pb_radius_multiplier",
                      "normal_strength": "pb_normal_strength", "shear_strength": "pb_shear_strength"},
}

register_group("phases", "Phase of every sphere and the contact model of every phase pair (seed 000)",
               writer="stage mastic")
for _name, _kind, _dims, _unit, _doc, _kw in [
        ("sphere", "i", ("n_s",), "", "phase of each sphere: index into phases/names", {"dtype": "int8"}),
        ("names", "str", ("n_phase",), "", "phase names: aggregate, mastic", {}),
        ("pair_phases", "i", ("n_pair", 2), "", "the two phases of each pair (a <= b)", {}),
        ("pair_model", "str", ("n_pair",), "", "contact model: linear_slip, contact_bond or parallel_bond", {}),
        ("param_names", "str", ("n_param",), "", "columns of pair_params", {}),
        ("param_units", "str", ("n_param",), "", "unit of each column of pair_params", {}),
        ("pair_params", "f", ("n_pair", "n_param"), "", "model parameters (SI, NaN where the model has none)", {}),
        ("internal_model", "str", (), "", "inside an aggregate: rigid_clump (no contacts are computed) or "
                                          "parallel_bond (bonded aggregates: lattice neighbours bonded by a test "
                                          "stage's bonds.from_phases)", {}),
        ("internal_params", "f", ("n_param",), "", "the parallel bond inside an aggregate (columns of param_names; "
                                                   "only with internal_model parallel_bond)", {"required": False})]:
    register(Field(f"phases/{_name}", _kind, _dims, _unit, _doc, writer="stage mastic", **_kw))

register_group("mastic", "Mastic volumetrics of a specimen (seed 000)", writer="stage mastic")
for _name, _kind, _unit, _doc in [
        ("ball_radius", "f", "m", "mastic ball radius"),
        ("ball_volume", "f", "m^3", "volume one mastic ball stands for"),
        ("density", "f", "kg/m^3", "mastic density"),
        ("mass_target", "f", "kg", "mastic mass asked for"),
        ("mass", "f", "kg", "mastic mass placed: count x density x ball_volume"),
        ("count", "i", "1", "mastic balls placed"),
        ("cells", "i", "1", "mastic-lattice cells with the centre inside the specimen (n_cells)"),
        ("aggregate_cells", "i", "1", "cells whose centre is inside an aggregate"),
        ("void_cells", "i", "1", "the other cells (n_void)"),
        ("sites", "i", "1", "void cells usable at the clearance"),
        ("specimen_volume", "f", "m^3", "V of the specimen group"),
        ("aggregate_volume", "f", "m^3", "aggregate volume of the specimen group (member cells inside)"),
        ("air_voids_target", "f", "1", "target air voids (NaN unless amount is by air_voids)"),
        ("air_voids", "f", "1", "(void_cells - count) / cells"),
        ("max_overlap", "f", "m", "largest overlap of a mastic ball with an aggregate ball (clearance < 0)"),
        ("overlapping", "i", "1", "mastic balls overlapping an aggregate ball")]:
    register(Field(f"mastic/{_name}", _kind, (), _unit, _doc, writer="stage mastic"))

_STIFF = {"kn": Float("N/m", min=0, min_inclusive=False, doc="normal stiffness"),
          "ks": Float("N/m", min=0, min_inclusive=False, doc="shear stiffness"),
          "friction": Float(min=0, default=0.5, doc="Coulomb friction (after a bond breaks)")}
_PAIR = List(Str(choices=list(PHASES)), min_len=2, max_len=2, doc="the two phases")

CONTACT = Tagged("model", {
    "linear_slip": Section({"phases": _PAIR, **_STIFF}, doc="linear springs, Coulomb slip"),
    "contact_bond": Section({"phases": _PAIR, **_STIFF,
                             "normal_strength": Float("N", min=0, min_inclusive=False, doc="s_n (force)"),
                             "shear_strength": Float("N", min=0, min_inclusive=False, doc="s_t (force)")},
                            doc="point bond: tension up to the normal strength; force only"),
    "parallel_bond": Section({"phases": _PAIR, **_STIFF,
                              "bond_kn": Float("Pa/m", min=0, min_inclusive=False, doc="normal stiffness per area"),
                              "bond_ks": Float("Pa/m", min=0, min_inclusive=False, doc="shear stiffness per area"),
                              "radius_multiplier": Float(min=0, min_inclusive=False, default=1.0,
                                                         doc="bond radius / smaller ball radius"),
                              "normal_strength": Float("Pa", min=0, min_inclusive=False, doc="sigma_c"),
                              "shear_strength": Float("Pa", min=0, min_inclusive=False, doc="tau_c")},
                             doc="finite bond disc: force and moment; breaks on the largest stress"),
}, doc="a contact model for one pair of phases")

FIELDS = {
    "ball_radius": Float("m", min=0, min_inclusive=False, doc="mastic ball radius (lattice spacing 2r)"),
    "material": Str(doc="material of the mastic balls"),
    "amount": Tagged("by", {
        "mass": Section({"mass": Float("kg", min=0, min_inclusive=False)}, doc="the mastic mass"),
        "air_voids": Section({"air_voids": Float(min=0, max=1, max_inclusive=False)},
                             doc="mastic fills the specimen up to this air-void content"),
        "mix": Section({}, doc="mastic / aggregate volume ratio of the gradation stage's mix design"),
    }, doc="how much mastic"),
    "clearance": Float(min=-1, max=1, default=-1.0,
                       doc="least gap between a mastic ball and an aggregate ball or the specimen surface, in mastic "
                           "radii (-1: any void site; 0: no overlap)"),
    "placement": Str(choices=["coat", "random"], default="coat",
                     doc="sites nearest the aggregates first, or random sites"),
    "contacts": List(CONTACT, min_len=1, doc="one contact model per pair of phases"),
    "aggregates": AGGREGATES,
}


def _check(node, report):
    seen = {}
    for k, c in enumerate(node.contacts):
        pair = tuple(sorted(c.phases, key=PHASES.index))
        if pair in seen:
            report(f"contacts.{k}.phases", f"pair {'-'.join(pair)} already has a model (contacts.{seen[pair]})",
                   list(c.phases))
        seen.setdefault(pair, k)
    for a in range(len(PHASES)):
        for b in range(a, len(PHASES)):
            pair = (PHASES[a], PHASES[b])
            if pair not in seen:
                report("contacts", f"no contact model for the phase pair {pair[0]}-{pair[1]} (every pair needs one)",
                       None)


def _mix_inputs(cfg):
    """Input fields a mastic config reads besides: amount by mix, the gradation's totals."""
    return {"amount.by": ("gradation/totals",)} if cfg.amount.by == "mix" else {}


def _case_check(cfg, case, k, scene, report):
    """Memory for the mastic cells over the specimen of the cut stage before, and for an
    amount by mix, a mix with aggregate."""
    from demcli.config.memory import check_memory
    from demcli.stages.asphalt.cut import specimen_size, volume_of
    from demcli.stages.specimen.gradation import compute

    cut = earlier_stage(case, k, "cut")
    if cut is not None:
        cells = volume_of(cut.shape.shape, specimen_size(cut.shape)) / (2.0 * cfg.ball_radius) ** 3
        check_memory(report, "ball_radius", cells, f"the mastic cells over the specimen of stage {cut.name!r}",
                      cfg.ball_radius)
    grading = earlier_stage(case, k, "gradation")
    if cfg.amount.by == "mix" and grading is not None and compute(grading)["totals"][1] <= 0:
        report("amount", f"the mix of stage {grading.name!r} has no aggregate volume")


def pair_table(contacts):
    """(pair_phases (n, 2), pair_model (n,), pair_params (n, n_param)) of validated config entries."""
    names = [p for p, _ in PARAMS]
    rows = []
    for c in contacts:
        a, b = sorted(PHASES.index(p) for p in c.phases)
        prm = np.full(len(PARAMS), np.nan)
        rename = _CONFIG_TO_PARAM.get(c.model, {})
        for key in c.keys():
            if key in ("model", "phases"):
                continue
            prm[names.index(rename.get(key, key))] = float(c[key])
        rows.append(((a, b), c.model, prm))
    rows.sort(key=lambda r: r[0])
    return (np.array([r[0] for r in rows], np.int64).reshape(-1, 2), np.array([r[1] for r in rows], dtype=object),
            np.array([r[2] for r in rows]).reshape(-1, len(PARAMS)))


def internal_phase(ctx, cfg, state_in):
    """(phases/internal_model, extra phases fields) of the ``aggregates`` config: rigid clumps, or
    bonded aggregates with the parallel bond of :func:`demcli.stages.asphalt.bonded.bond_parameters`
    from the aggregate material's E, nu and the lattice ball radius (phases/internal_params)."""
    agg = cfg.aggregates
    if agg.model == "rigid":
        return np.array(INTERNAL_MODELS["rigid"], dtype=object), {}
    mats = list(ctx.case.materials)
    used = np.unique(np.asarray(state_in["spheres/material"], np.int64))
    if len(used) != 1:
        raise InputError(f"stage {ctx.name}: aggregates.model bonded needs one aggregate material; the aggregates "
                         f"have {', '.join(mats[m] for m in used) or 'none'}")
    mat = ctx.case.materials[mats[int(used[0])]]
    r = float(np.asarray(state_in.groups["aggregates"]["ball_radius"]))
    sigma_t = tensile_strength(agg)
    young = mat.young if agg.young is None else agg.young
    bp = bond_parameters(young, mat.poisson, r, sigma_t, agg.shear_ratio, agg.radius_multiplier)
    names = [p for p, _ in PARAMS]
    prm = np.full(len(PARAMS), np.nan)
    for key, col in _CONFIG_TO_PARAM["parallel_bond"].items():
        prm[names.index(col)] = bp[key]
    ctx.log(f"bonded aggregates: sigma_t {sigma_t / 1e6:.4g} MPa, E {young / 1e9:.4g} GPa, lattice balls of "
            f"{r * 1e3:.4g} mm: parallel bonds kn_b {bp['bond_kn']:.4g} Pa/m, ks_b {bp['bond_ks']:.4g} Pa/m, "
            f"strengths {bp['normal_strength'] / 1e6:.4g} / {bp['shear_strength'] / 1e6:.4g} MPa")
    return np.array(INTERNAL_MODELS["bonded"], dtype=object), {"internal_params": prm}


def str_list(values):
    """A stored string array (bytes or str, any shape) as a flat list of str."""
    return [v.decode() if isinstance(v, bytes) else str(v) for v in np.asarray(values).reshape(-1)]


def phase_problems(state):
    """Problems of a state's ``phases`` table (empty list: complete and valid)."""
    g = state.groups.get("phases")
    if g is None:
        return ["no phases group (written by a mastic stage)"]
    out = []
    names = str_list(g["names"])
    pairs = np.asarray(g["pair_phases"], np.int64).reshape(-1, 2)
    models = str_list(g["pair_model"])
    pnames = str_list(g["param_names"])
    prm = np.asarray(g["pair_params"], float).reshape(len(pairs), -1)
    nph = len(names)
    seen = {}
    for k, (a, b) in enumerate(pairs):
        if not (0 <= a <= b < nph):
            out.append(f"pair {k}: phases ({a}, {b}) not in 0..{nph - 1} with a <= b")
            continue
        key = (names[a], names[b])
        if key in seen:
            out.append(f"pair {key[0]}-{key[1]} appears twice (rows {seen[key]} and {k})")
        seen.setdefault(key, k)
        model = models[k]
        if model not in MODELS:
            out.append(f"pair {key[0]}-{key[1]}: unknown model {model!r} (known: {', '.join(MODELS)})")
            continue
        for p in MODELS[model]:
            if p not in pnames:
                out.append(f"pair {key[0]}-{key[1]}: no parameter column {p!r}")
                continue
            v = prm[k, pnames.index(p)]
            if not np.isfinite(v) or v < 0 or (v == 0 and p != "friction"):
                out.append(f"pair {key[0]}-{key[1]} ({model}): {p} must be "
                           f"{'>= 0' if p == 'friction' else '> 0'} (got {v})")
    for a in range(nph):
        for b in range(a, nph):
            if (names[a], names[b]) not in seen:
                out.append(f"no contact model for the phase pair {names[a]}-{names[b]}")
    sph = np.asarray(g["sphere"], np.int64)
    if len(sph) and (sph.min() < 0 or sph.max() >= nph):
        out.append(f"phases/sphere holds values outside 0..{nph - 1}")
    if "aggregates" in state.groups and len(sph) == len(state["spheres/body"]):
        expect = np.where(phase_of_spheres(state) >= 0, names.index("aggregate") if "aggregate" in names else 0,
                          names.index("mastic") if "mastic" in names else 1)
        bad = int(np.sum(expect != sph))
        if bad:
            out.append(f"{bad} spheres have a phase that does not match their body (aggregate clump or mastic)")
    return out


def phase_table(state):
    """The validated contact assignment: {(phase_a, phase_b): (model, {param: value})}.

    Raises :class:`StateError` naming every problem (a missing pair, a missing or
    non-positive strength or stiffness, an unknown model). For the bonded-contact
    engine (issue 9): the pair of two spheres' phases picks the model.
    """
    problems = phase_problems(state)
    if problems:
        raise StateError("invalid phase table: " + "; ".join(problems))
    g = state.groups["phases"]
    names = str_list(g["names"])
    pnames = str_list(g["param_names"])
    prm = np.asarray(g["pair_params"], float)
    out = {}
    for k, (a, b) in enumerate(np.asarray(g["pair_phases"], np.int64).reshape(-1, 2)):
        model = str_list(g["pair_model"])[k]
        out[(names[a], names[b])] = (model, {p: float(prm[k, pnames.index(p)]) for p in MODELS[model]})
    return out


def cell_centres(shape, centre, size, a):
    """Centres (n, 3) [m] of the mastic-lattice cells (side ``a`` [m]) that tile a specimen
    (``shape`` box or cylinder, ``centre`` and ``size`` (3,) [m], as the specimen group).

    Along each axis of extent L the lattice holds m = round(L / a) >= 1 centres
    c + (k - (m - 1)/2) a; the cells whose centre is inside the specimen count (midpoint
    rule). n a^3 is then the specimen volume to the lattice's discretisation error: exact
    for a box whose sides are whole numbers of cells, and the height of a cylinder is
    exact when it is one; no centre lies within a / 4 of an end face (module docstring,
    step 1).
    """
    from demcli.stages.asphalt.cut import inside

    centre = np.asarray(centre, float)
    size = np.asarray(size, float)
    counts = np.maximum(np.floor(size / a + 0.5), 1).astype(np.int64)
    origin = centre - 0.5 * (counts - 1) * a
    axes = [origin[d] + a * np.arange(counts[d]) for d in range(3)]
    gz, gy, gx = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    pts = np.stack([gx.ravel(), gy.ravel(), gz.ravel()], axis=1)
    return pts[inside(pts, 0.0, shape, centre, size)]


def run(ctx, cfg, state_in):
    from scipy.spatial import cKDTree

    from demcli.state import RecordTable
    from demcli.stages.asphalt.cut import inside

    sp = state_in.groups.get("specimen")
    if sp is None:
        raise InputError(f"stage {ctx.name}: the input has no specimen (run a cut stage first)")
    shape = scalar_str(sp["shape"])
    centre = np.asarray(sp["centre"], float)
    size = np.asarray(sp["size"], float)
    v_spec = float(np.asarray(sp["volume"]))
    v_agg = float(np.asarray(sp["aggregate_volume"]))
    r = cfg.ball_radius
    a = 2.0 * r
    v_ball = a ** 3
    rho = ctx.case.materials[cfg.material].density

    # the specimen tiled by mastic cells (cell-centred lattice, round(L / a) per axis): aggregate
    # cells and void cells
    pts = cell_centres(shape, centre, size, a)
    n_cells = len(pts)
    agg_c = state_in.sphere_centres()
    agg_r = np.asarray(state_in["spheres/radius"], float)
    if len(agg_c):
        tree = cKDTree(agg_c)
        dist, nearest = tree.query(pts, k=1)
        gap = dist - agg_r[nearest] - r
        solid = inside_member_cells(state_in, pts)
    else:
        gap = np.full(len(pts), np.inf)
        solid = np.zeros(len(pts), bool)
    n_agg_cells = int(solid.sum())
    pts, gap = pts[~solid], gap[~solid]
    n_void = len(pts)
    usable = (gap >= cfg.clearance * r - 1e-12 * r) & inside(pts, r * (1.0 + cfg.clearance), shape, centre, size)
    pts, gap = pts[usable], gap[usable]
    sites = len(pts)

    amount = cfg.amount
    vv_target = math.nan
    if amount.by == "mass":
        mass_target = amount.mass
        n = int(round(mass_target / (rho * v_ball)))
    elif amount.by == "air_voids":
        vv_target = amount.air_voids
        n = n_void - int(round(vv_target * n_cells))
        mass_target = rho * (n_cells * (1.0 - vv_target) - n_agg_cells) * v_ball
    else:
        g = state_in.groups.get("gradation")
        if g is None:
            raise InputError(f"stage {ctx.name}: amount by mix needs the gradation group of a gradation stage")
        tot = np.asarray(g["totals"], float)  # specimen, aggregate, voids, mastic
        if tot[1] <= 0:
            raise InputError(f"stage {ctx.name}: the gradation stage's mix has no aggregate volume")
        mass_target = rho * n_agg_cells * v_ball * tot[3] / tot[1]
        n = int(round(mass_target / (rho * v_ball)))
    if n < 0:
        raise StageError(f"stage {ctx.name}: the aggregates alone fill {100 * n_agg_cells / n_cells:.2f} % of the "
                         f"specimen, more than 1 - air voids ({100 * (1 - vv_target):.2f} %); no room for mastic")
    if n > sites:
        raise StageError(f"stage {ctx.name}: the mastic needs {n} balls of r = {r * 1e3:g} mm but the voids "
                         f"({100 * n_void / n_cells:.1f} % of the specimen) hold only {sites} sites at clearance "
                         f"{cfg.clearance:g} r; lower the clearance, use smaller mastic balls, or less mastic")
    if cfg.placement == "coat":
        rank = np.where(gap >= 0, gap, 4.0 * r - gap)  # clear sites by gap, then overlapping ones by overlap
        order = np.lexsort((ctx.rng.random(sites), np.round(rank / (1e-6 * r))))
        chosen = np.sort(order[:n])
    else:
        chosen = np.sort(ctx.rng.choice(sites, size=n, replace=False))
    mpts = pts[chosen]
    overlap = np.maximum(-gap[chosen], 0.0)

    b_in = state_in.groups["bodies"]
    nb0 = len(b_in["mass"])
    m_ball = rho * v_ball
    mat = list(ctx.case.materials).index(cfg.material)
    bodies = {k: np.asarray(b_in[k]).copy() for k in ("x", "v", "q", "omega", "mass", "inertia", "id", "flags")}
    next_id = int(bodies["id"].max()) + 1 if nb0 else 0
    add = {"x": mpts, "v": np.zeros((n, 3)), "q": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), "omega": np.zeros((n, 3)),
           "mass": np.full(n, m_ball), "inertia": np.full((n, 3), 0.4 * m_ball * r * r),
           "id": np.arange(next_id, next_id + n, dtype=np.int64), "flags": np.zeros(n, np.int8)}
    bodies = {k: np.concatenate([bodies[k], add[k]]) for k in bodies}
    s_in = state_in.groups["spheres"]
    ns0 = len(s_in["radius"])
    spheres = {"body": np.r_[np.asarray(s_in["body"], np.int64), nb0 + np.arange(n)].astype(np.int64),
               "offset": np.concatenate([np.asarray(s_in["offset"]), np.zeros((n, 3))]),
               "radius": np.r_[np.asarray(s_in["radius"]), np.full(n, r)],
               "material": np.r_[np.asarray(s_in["material"], np.int64), np.full(n, mat, np.int64)]}
    pairs, models, params = pair_table(cfg.contacts)
    internal, extra = internal_phase(ctx, cfg, state_in)
    phases = {"sphere": np.r_[np.zeros(ns0, np.int8), np.ones(n, np.int8)],
              "names": np.array(PHASES, dtype=object), "pair_phases": pairs, "pair_model": models,
              "param_names": np.array([p for p, _ in PARAMS], dtype=object),
              "param_units": np.array([u for _, u in PARAMS], dtype=object), "pair_params": params,
              "internal_model": internal, **extra}
    vv = (n_void - n) / n_cells
    mastic = {"ball_radius": np.float64(r), "ball_volume": np.float64(v_ball), "density": np.float64(rho),
              "mass_target": np.float64(mass_target), "mass": np.float64(n * m_ball), "count": np.int64(n),
              "cells": np.int64(n_cells), "aggregate_cells": np.int64(n_agg_cells), "void_cells": np.int64(n_void),
              "sites": np.int64(sites), "specimen_volume": np.float64(v_spec), "aggregate_volume": np.float64(v_agg),
              "air_voids_target": np.float64(vv_target), "air_voids": np.float64(vv),
              "max_overlap": np.float64(overlap.max() if n else 0.0), "overlapping": np.int64(np.sum(overlap > 0))}

    state = ctx.new_state(time=float(state_in.meta.get("time", 0.0)), step=int(state_in.meta.get("step", 0)),
                          dt=float(state_in.meta.get("dt", 0.0)))
    state.groups["bodies"] = bodies
    state.groups["spheres"] = spheres
    for name in ("aggregates", "seeds", "gradation", "specimen"):
        g = copy_group(state_in, name)
        if g is not None:
            state.groups[name] = g
    contacts = copy_group(state_in, "contacts")
    if contacts is not None:
        state.groups["contacts"] = contacts
    state.groups["phases"] = phases
    state.groups["mastic"] = mastic
    problems = phase_problems(state)
    if problems:  # the config check makes this unreachable; kept as the stored table's guarantee
        raise StageError(f"stage {ctx.name}: " + "; ".join(problems))
    table = RecordTable("mastic", {"cells": "1", "aggregate_cells": "1", "void_cells": "1", "sites": "1",
                                   "count": "1", "mass_target": "kg", "mass": "kg", "air_voids_target": "1",
                                   "air_voids": "1", "aggregate_share": "1", "aggregate_share_cut": "1"})
    table.append(cells=n_cells, aggregate_cells=n_agg_cells, void_cells=n_void, sites=sites, count=n,
                 mass_target=mass_target, mass=n * m_ball, air_voids_target=vv_target, air_voids=vv,
                 aggregate_share=n_agg_cells / n_cells, aggregate_share_cut=v_agg / v_spec)
    table.to_state(state)
    folder = ctx.runner.run_dir / "records"
    folder.mkdir(parents=True, exist_ok=True)
    table.write_csv(folder / f"{ctx.name}_mastic.csv")
    write_asphalt_vtu(ctx.snapshot_dir / "specimen.vtu", state)
    ctx.log(f"{n} mastic balls (r = {r * 1e3:g} mm, {cfg.placement}) of {sites} void sites: mastic "
            f"{n * m_ball * 1e3:.4g} g (asked {mass_target * 1e3:.4g} g); of {n_cells} cells: aggregate "
            f"{100 * n_agg_cells / n_cells:.2f} % (cut stage: {100 * v_agg / v_spec:.2f} %), mastic "
            f"{100 * n / n_cells:.2f} %, air voids {100 * vv:.3f} %"
            + (f" (target {100 * vv_target:g} %)" if np.isfinite(vv_target) else "")
            + (f"; {int(np.sum(overlap > 0))} overlap aggregate balls by up to {overlap.max() / r:.2f} r"
               if n and overlap.max() > 0 else "")
            + "; contact models stored by phase pair (a dem stage with bonds.from_phases runs them)")
    return state


def describe(cfg, case):
    a = cfg.amount
    how = {"mass": lambda: f"{a.mass * 1e3:g} g", "air_voids": lambda: f"to {100 * a.air_voids:g} % air voids",
           "mix": lambda: "by the mix design"}[a.by]()
    pairs = ", ".join(f"{'-'.join(c.phases)}: {c.model}" for c in cfg.contacts)
    return f"mastic balls r = {cfg.ball_radius * 1e3:g} mm {how} ({cfg.placement}); {pairs}"


register_stage(StageType(
    "mastic", FIELDS, run, check=_check, describe=describe, case_check=_case_check, config_requires=_mix_inputs,
    requires=("specimen/volume", "specimen/aggregate_volume", "aggregates/body"),
    provides=("bodies/*", "spheres/*", "phases/*", "mastic/*", "records/*"),
    keeps=("aggregates", "seeds", "gradation", "specimen", "contacts"),
    doc="mastic balls in the voids by mass and density; contact models by phase pair (seed 000)"))
