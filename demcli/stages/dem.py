"""``dem`` stage: time integration of the scene with the physics the stage declares.

This module holds the stage's config (schema and rules) and what a config decides: the
declared effects, the contact law, the materials, the walls and the bond models. The
stepping itself, shared by every stage that integrates (vibrate, sleeper, compact, creep),
is :mod:`demcli.stages.loop`.
"""

import math

import numpy as np

from demcli.config.schema import Bool, Float, Int, List, Map, Optional, Section, Str, Tagged, Vector
from demcli.effects import EFFECTS, declared, physics_section, shape_refusals
from demcli.errors import InputError, StateError
from demcli.measure.regions import MEASURE, check_box as _check_box
from demcli.stages import periodic
from demcli.stages.base import ENGINE_KEEPS, ENGINE_OUTPUT, StageType, has_field, register_stage

MOTION = Tagged("mode", {
    "fixed": Section({}),
    "velocity": Section({"velocity": Vector(3, "m/s", doc="prescribed wall velocity")}),
    "servo": Section({
        "stress": Float("Pa", min=0, doc="target compressive stress on the wall"),
        "gain": Float(min=0, max=1, min_inclusive=False, default=0.5,
                      doc="relaxation alpha: the wall closes this share of the stress error per step"),
        "max_speed": Float("m/s", min=0, min_inclusive=False, default=1.0),
        "area": Optional(Float("m^2", min=0, min_inclusive=False), doc="loaded area (default: from the box)"),
    }),
    "pressure": Section({
        "pressure": Float("Pa", min=0, doc="confining pressure on the particles"),
        "mass": Float("kg", min=0, min_inclusive=False, doc="membrane mass (its radius is its coordinate)"),
        "area": Optional(Float("m^2", min=0, min_inclusive=False), doc="loaded area (default: 2 pi r h)"),
    }, doc="cylinders only: a membrane whose radius moves under a constant pressure"),
    "force": Section({
        "force": Float("N", doc="mean force pushing the wall into the domain"),
        "amplitude": Float("N", min=0, default=0.0),
        "frequency": Float("Hz", min=0, default=0.0),
        "phase": Float("rad", default=0.0, doc="phase of the sine when it starts (-90 deg: a haversine cycle "
                                               "from force - amplitude, as the ballast actors are loaded)"),
        "start": Float("s", min=0, default=0.0, doc="stage time the sine starts; before it the force holds its "
                                                    "value at the start"),
        "mass": Float("kg", min=0, min_inclusive=False),
        "weight": Bool(default=False, doc="add the wall's weight, mass x gravity along the normal "
                                          "(needs physics.gravity)"),
    }, doc="F(t) = force + amplitude sin(2 pi frequency max(t - start, 0) + phase) [+ weight], along the normal; "
           "the wall, of the given mass, moves under it and the particles' push"),
}, default={"mode": "fixed"}, doc="how the wall moves along its normal")

FACES = ("x0", "x1", "y0", "y1", "z0", "z1")


def _check_packing(node, report):
    if node.window is not None and node.margin is not None:
        report("margin", "give a window or a margin, not both", node.margin)
    if node.window is not None and node.around is not None:
        report("around", "is the box a margin shrinks; a window is taken as it is", node.around)


def _check_fields(node, report):
    if (node.min is None) != (node.max is None):
        report("max" if node.max is None else "min", "give both min and max, or neither (the bodies' box)", None)
    elif node.min is not None:
        _check_box(node, report)


def _check_output(node, report):
    """Force chains and fields are written at the snapshots: they need some."""
    for key, on in (("force_chains", node.force_chains), ("fields", node.fields is not None)):
        if on and node.snapshots == 0:
            report(key, "is written at every snapshot: give output.snapshots > 0", node[key] if key != "fields"
                   else None)


FIELDS_SECTION = Section({
    "width": Float("m", min=0, min_inclusive=False, doc="kernel width w: the kernel's standard deviation along "
                                                        "each axis"),
    "kernel": Str(choices=["gaussian", "lucy"], default="gaussian",
                  doc="gaussian (cut at 3 w) or lucy (cutoff 2 sqrt(3) w)"),
    "spacing": Optional(Float("m", min=0, min_inclusive=False), doc="grid spacing (default: w)"),
    "min": Optional(Vector(3, "m"), doc="grid box (default: the bodies' bounding box at each snapshot)"),
    "max": Optional(Vector(3, "m")),
}, check=_check_fields, doc="coarse graining (Goldhirsch 2010, Weinhart et al. 2012)")

def _check_mesh_wall(node, report):
    """A mesh file is STL or OBJ (read at the stage start: :func:`demcli.geometry.mesh_file.read_mesh`);
    the normal has a direction."""
    from demcli.geometry.mesh_file import SUFFIXES

    if not node.file.lower().endswith(tuple(SUFFIXES)):
        report("file", f"must be a {' or '.join(sorted(SUFFIXES))} file", node.file)
    if not any(node.normal):
        report("normal", "must not be the zero vector", list(node.normal))


_RIGID = Bool(default=False, doc="E* and G* from the particle alone (an infinitely stiff wall, as in rigid-body "
                                 "impact tests); the wall's material still gives friction and restitution; "
                                 "linear law: no effect (k_n, k_t are per pair)")

WALL = Tagged("type", {
    "plane": Section({
        "name": Str(default=None), "point": Vector(3, "m"), "normal": Vector(3, doc="into the domain"),
        "material": Str(), "motion": MOTION,
        "rigid": _RIGID,
        "extent": Optional(Vector(6, "m"), doc="drawing bounds xmin ymin zmin xmax ymax zmax"),
        "lay_on_particles": Optional(Float("m", min=0),
                                     doc="at the stage start move the wall along its normal to this gap from the "
                                         "nearest particle surface (a loading plate laid on the bed); not on resume"),
    }),
    "box": Section({
        "name": Str(default="box"), "min": Vector(3, "m"), "max": Vector(3, "m"), "material": Str(),
        "open": List(Str(choices=list(FACES)), default=(), doc="faces left out, e.g. [z1]"),
        "rigid": _RIGID,
        "motion": Map(MOTION, default={}, doc="motion per face name (x0 ... z1); others fixed"),
    }, check=_check_box),
    "mesh": Section({
        "name": Str(default=None),
        "file": Str(doc="STL (ascii or binary) or OBJ triangle surface, relative to the case file; coincident "
                        "vertices are merged (the contact of a sphere or polyhedron with the mesh, docs/walls.md)"),
        "scale": Float(min=0, min_inclusive=False, default=1.0, doc="file units to metres (0.001: millimetres)"),
        "rotate": Vector(3, "rad", default=(0.0, 0.0, 0.0), doc="turned about the fixed x, then y, then z axis "
                                                               "(e.g. [0, 180 deg, 0])"),
        "translation": Vector(3, "m", default=(0.0, 0.0, 0.0), doc="then moved by this"),
        "normal": Vector(3, default=(0.0, 0.0, 1.0), doc="direction of servo and force motion, into the domain; "
                                                         "the wall records' position and force are along it"),
        "material": Str(), "rigid": _RIGID, "motion": MOTION,
    }, check=_check_mesh_wall, doc="a rigid triangle mesh translating with its motion (spheres, clumps and polyhedra)"),
    "cylinder": Section({
        "name": Str(default=None), "base": Vector(3, "m", doc="point on the axis (bottom)"),
        "axis": Vector(3, default=(0.0, 0.0, 1.0)), "radius": Float("m", min=0, min_inclusive=False),
        "height": Float("m", min=0, min_inclusive=False, doc="drawn height"), "material": Str(),
        "rigid": _RIGID,
        "motion": MOTION,
    }),
})

CONTACT_PAIR = Section({
    "materials": List(Str(), min_len=2, max_len=2),
    "friction": Optional(Float(min=0)),
    "rolling_friction": Optional(Float(min=0)),
    "restitution": Optional(Float(min=0, max=1, min_inclusive=False)),
    "kn": Optional(Float("N/m", min=0, min_inclusive=False)),
    "kt": Optional(Float("N/m", min=0)),
    "cn": Optional(Float("N*s/m", min=0)),
})

BURGERS_ELEMENT = Section({"km": Float("N/m", min=0, min_inclusive=False, doc="Maxwell spring K_m"),
                    "cm": Float("N*s/m", min=0, min_inclusive=False, doc="Maxwell dashpot C_m"),
                    "kk": Float("N/m", min=0, min_inclusive=False, doc="Kelvin spring K_k"),
                    "ck": Float("N*s/m", min=0, doc="Kelvin dashpot C_k (0: a plain spring)")},
                   doc="a Burgers element: Maxwell (K_m, C_m) in series with Kelvin (K_k || C_k)")
_STRENGTHS = {"normal_strength": Optional(Float(min=0, min_inclusive=False), doc="tensile strength (default: none)"),
              "shear_strength": Optional(Float(min=0, min_inclusive=False), doc="shear strength (default: none)")}
_MATS = List(Str(), min_len=2, max_len=2, doc="the material pair it bonds")
BOND_MODEL = Tagged("model", {
    "contact_bond": Section({"materials": _MATS, "kn": Float("N/m", min=0, min_inclusive=False),
                             "ks": Float("N/m", min=0, min_inclusive=False), **_STRENGTHS},
                            doc="point springs, tension allowed; strengths in N; force only"),
    "parallel_bond": Section({"materials": _MATS,
                              "bond_kn": Float("Pa/m", min=0, min_inclusive=False, doc="normal stiffness per area"),
                              "bond_ks": Float("Pa/m", min=0, min_inclusive=False, doc="shear stiffness per area"),
                              "radius_multiplier": Float(min=0, min_inclusive=False, default=1.0,
                                                         doc="bond radius / smaller sphere radius"),
                              **_STRENGTHS},
                             doc="a bonded disc beside the contact: force and moment; strengths in Pa"),
    "burgers": Section({"materials": _MATS,
                        "kn": Float("N/m", min=0, min_inclusive=False, doc="normal stiffness in compression"),
                        "tension": BURGERS_ELEMENT, "shear": BURGERS_ELEMENT, **_STRENGTHS,
                        "compression": Str(choices=("elastic", "burgers"), default="elastic",
                                           doc="normal compression: elastic (kn), or the tension element "
                                               "(one Burgers element in compression and tension alike)")},
                       doc="seed 003: compression elastic (or Burgers), normal tension and shear Burgers; "
                           "strengths in N"),
}, doc="a bond model for one material pair")

BOND_MODELS = List(BOND_MODEL, min_len=1, doc="bond models by material pair (replace stored ones of that pair)")
BONDS = Optional(Section({
    "models": List(BOND_MODEL, default=(), doc="bond models by material pair (replace stored ones of that pair)"),
    "from_phases": Bool(default=False, doc="take the models from the state's phase table (mastic stage, seed 000): "
                        "its contact and parallel bonds, and the linear + slip law of every phase pair"),
    "create": Bool(default=False, doc="bond every touching pair whose materials have a model at the stage start"),
    "gap": Float(min=0, default=1e-6, doc="pairs closer than gap x mean radius count as touching"),
    "install": Str(choices=["auto", "stress_free", "loaded"], default="auto",
                   doc="contact bonds created on an overlap: stress_free holds no force at the overlap of creation "
                       "(F_n = k_n (delta - delta_0)), loaded takes over the contact's force k_n delta; auto: "
                       "stress_free with from_phases (the mastic lattice's overlaps are voxel artefacts), else loaded"),
}), doc="bonds between spheres (a state that holds bonds keeps them active without this key)")

FIELDS = {
    "physics": physics_section(),  # one key per effect of the registry (demcli.effects.registry)
    "contact": Section({
        "law": Str(choices=["hertz_mindlin", "linear"], default="hertz_mindlin"),
        "kn": Optional(Float("N/m", min=0, min_inclusive=False), doc="linear: normal stiffness"),
        "kt": Optional(Float("N/m", min=0), doc="linear: tangential stiffness (default kn/4)"),
        "cn": Float("N*s/m", min=0, default=0.0, doc="linear: absolute normal damping (0: from restitution)"),
        "tangential_damping": Float(min=0, default=0.0, doc="c_t / c_n"),
        "no_tension": Bool(default=False, doc="clip the normal force at 0: the dashpot does not pull at the end of "
                                              "a contact (the restitution then comes out a little above e); "
                                              "friction is capped by mu times the clipped force"),
        "lever_arm": Str(choices=["deformed", "radius"], default="deformed",
                         doc="contact point of a sphere contact: deformed, in the middle of the overlap (R - "
                             "delta/2; R - delta on a wall); radius, at R from the centre as in rigid-body "
                             "impact theory"),
        "pairs": List(CONTACT_PAIR, default=(), doc="per material pair overrides"),
        "geometry_refresh": Int(min=1, default=1,
                                doc="polyhedra: a touching pair's intersection is computed exactly every this many "
                                    "steps and linearized in between (V = V_0 - S_0 . relative displacement of the "
                                    "contact point); 1: every step, the exact law (an approximation above 1, its "
                                    "cost measured in docs/ballast_box.md, Cost)"),
    }, default={}),
    "walls": List(WALL, default=(), doc="rigid walls"),
    "bonds": BONDS,
    "time": Section({
        "duration": Optional(Float("s", min=0, min_inclusive=False)),
        "steps": Optional(Int(min=1)),
        "dt": Optional(Float("s", min=0, min_inclusive=False), doc="explicit time step (default: auto)"),
        "dt_factor": Float(min=0, max=1, min_inclusive=False, default=0.1,
                           doc="time step as a fraction of the critical step"),
    }),
    "stop": Optional(Section({
        "kinetic_ratio": Float(min=0, min_inclusive=False,
                               doc="stop when mean kinetic energy per body < ratio * m g d (m, d: mean body mass and "
                                   "size; a clump's size is its bounding diameter)"),
        "min_time": Float("s", min=0, default=0.0),
    }), doc="stop early when the bed is at rest"),
    "output": Section({
        "records": Int(min=1, default=200, doc="record rows over the run"),
        "snapshots": Int(min=0, default=10, doc="VTU snapshots over the run (plus the first and last)"),
        "contacts": Optional(Section({
            "bodies": List(Int(min=0), default=(), doc="body ids whose contacts are recorded (default: every "
                                                       "contact, scenes of up to 2000 spheres)"),
        }), doc="a per-contact record at every record row: overlap, normal and tangential force, contact point "
                "and normal of each touching contact (sphere, clump and polyhedron scenes; records/contacts.csv, "
                "demcli/stages/contact_record.py)"),
        "packing": Optional(Section({
            "window": Optional(Section({"min": Vector(3, "m"), "max": Vector(3, "m")}, check=_check_box),
                               doc="the sampling window, an axis-aligned box (2D: its x-y rectangle)"),
            "margin": Optional(Float(min=0), doc="without a window: the box of `around` shrunk by this many mean "
                                                 "body diameters d on each side, at every record (default 2)"),
            "around": Optional(Str(choices=["bodies", "walls"]),
                               doc="the box a margin shrinks: bodies (default), the bodies' bounding box; walls, the "
                                   "innermost axis-aligned plane walls (box faces) on each side, the bodies' extent "
                                   "where there is none (an open top)"),
            "min_contacts": Optional(Int(min=1), doc="a body with fewer contacts (bodies and walls) is a rattler, "
                                                     "removed iteratively (default: 2 with friction, else "
                                                     "dimension + 1)"),
        }, check=_check_packing), doc="a packing record at every record row: solid fraction (2D: area fraction) "
                                      "and coordination without rattlers in a sampling window away from the walls "
                                      "(sphere, clump and polyhedron scenes; records/<stage>_packing.csv, "
                                      "demcli/stages/packing_record.py)"),
        "force_chains": Bool(default=False, doc="at every snapshot also the contact network as VTU lines (centre to "
                                                "centre, to the contact point on a wall) with normal and tangential "
                                                "force, overlap and bond state: <stage>/force_chains_NNNNNN.vtu "
                                                "(docs/measure.md)"),
        "fields": Optional(FIELDS_SECTION, doc="at every snapshot also coarse-grained density, velocity and stress "
                                               "on a grid: <stage>/fields_NNNNNN.vtu (docs/measure.md)"),
        "checkpoint": Optional(Float("s", min=0, min_inclusive=False),
                               doc="also write a checkpoint at the first record after every this much wall-clock "
                                   "time (for runs longer than a job's time limit); `demcli run --resume` "
                                   "continues from it bit-identically. Ctrl-C and SIGTERM always write one"),
    }, default={}, check=_check_output),
    "measure": MEASURE,
    "neighbors": Section({"skin": Float(min=0, min_inclusive=False, default=0.3,
                                        doc="Verlet skin / mean radius")}, default={}),
    "scaling": Section({
        "stiffness": Float(min=0, max=1, min_inclusive=False, default=1.0,
                           doc="multiplies every Young's modulus (and linear kn, kt): time step / sqrt(factor); "
                               "overlaps and contact compliance grow by 1/factor (sphere Hertz: 1/factor^(2/3))"),
        "mass": Float(min=1, default=1.0,
                      doc="multiplies every body's mass and inertia but not its weight (gravity "
                          "divided by it): time step x sqrt(factor); for quasi-static stages only; a power of "
                          "2 so that scaling and unscaling are exact"),
    }, default={}, doc="cost knobs (docs/scaling.md): off by default"),
    "safety": Section({
        "check_every": Int(min=1, default=100),
        "overlap_limit": Float(min=0, min_inclusive=False, default=0.5, doc="overlap / smaller radius"),
        "energy_limit": Float(min=1, default=1e3, doc="kinetic energy / reference energy"),
        "allow_unstable_dt": Bool(default=False, doc="accept dt above the critical step (tests only)"),
    }, default={}),
}


def check_stage(node, report):
    """The rules of a ``dem`` stage's config, which every stage built on its keys shares: exactly
    one of ``time.duration`` and ``time.steps``, and :func:`check_dynamics`."""
    t = node.time
    if (t.duration is None) == (t.steps is None):
        report("time", "give exactly one of duration or steps", None)
    check_dynamics(node, report)
    periodic.check(node, report)


def check_dynamics(node, report):
    """The checks of a dem stage's contact, bonds, scaling, stop and walls (all but its time
    section): shared by the stages built on dem's fields with a time section of their own."""
    c = node.contact
    if c.law == "linear" and c.kn is None:
        report("contact.kn", "the linear law needs kn", None)
    if c.law != "linear":
        for key in ("kn", "kt"):
            if c[key] is not None:
                report(f"contact.{key}", "only used by law: linear", c[key])
        if c.cn:
            report("contact.cn", "only used by law: linear", c.cn)
    for k, p in enumerate(c.pairs):
        if p.friction is not None and not node.physics.friction:
            report(f"contact.pairs.{k}.friction", "physics.friction is off", p.friction)
        if p.rolling_friction is not None and not node.physics.rolling_resistance:
            report(f"contact.pairs.{k}.rolling_friction", "physics.rolling_resistance is off", p.rolling_friction)
    if node.get("bonds") is not None:
        if not node.bonds.models and not node.bonds.from_phases:
            report("bonds.models", "give bond models or from_phases: true", None)
        if node.bonds.from_phases and node.contact.law != "linear":
            report("contact.law", "bonds.from_phases sets linear springs per phase pair: use law: linear",
                   node.contact.law)
        seen = {}
        for k, b in enumerate(node.bonds.models):
            pair = tuple(sorted(b.materials))
            if pair in seen:
                report(f"bonds.models.{k}.materials", f"pair {'-'.join(pair)} already has a model "
                       f"(bonds.models.{seen[pair]})", list(b.materials))
            seen.setdefault(pair, k)
        if node.scaling.stiffness != 1.0:
            report("scaling.stiffness", "bond models are not scaled; use 1 with bonds", node.scaling.stiffness)
    m = node.scaling.mass
    if m != 1.0 and 2.0 ** round(math.log2(m)) != m:
        report("scaling.mass", "must be a power of 2 (1, 2, 4, ..., 1024) so that scaling is exact", m)
    if node.get("stop") is not None and node.physics.gravity is None:
        report("stop", "the kinetic-energy criterion needs gravity (it scales with m g d)", None)
    for k, w in enumerate(node.walls):
        motions = [(f"walls.{k}.motion.{face}", m) for face, m in w.motion.items()] if w.type == "box" else \
            [(f"walls.{k}.motion", w.motion)]
        for where, m in motions:
            if m.mode == "force" and m.weight and node.physics.gravity is None:
                report(f"{where}.weight", "the wall's weight needs physics.gravity", m.weight)
            _check_wall_mode(w.type, m, where, report)


def _check_wall_mode(wall_type, motion, where, report):
    """Modes a wall type takes: pressure for cylinders only, which take no servo or force;
    a servo plane needs its area (box faces know theirs)."""
    if wall_type == "cylinder" and motion.mode in ("servo", "force"):
        report(f"{where}.mode", "a cylinder wall takes fixed, velocity or pressure", motion.mode)
    elif wall_type != "cylinder" and motion.mode == "pressure":
        report(f"{where}.mode", "mode pressure is for cylinder walls", motion.mode)
    elif wall_type in ("plane", "mesh") and motion.mode == "servo" and motion.area is None:
        report(f"{where}.area", f"a servo {wall_type} needs its loaded area (only box faces know theirs)")


def scene_check(cfg, case, k, scene, report, shapes=None):
    """The stage's effects against the shape of its input's bodies, known from the earlier
    stages' outputs (polyhedra, or spheres which may be clumps; ``shapes``: the shapes the
    stage may run instead, e.g. mixed for a stage that sets a polyhedral actor on a sphere bed):
    each effect the registry runs on none of them is refused with its reason
    (:func:`demcli.effects.shape_refusals`)."""
    if scene is None:
        return
    periodic.check_scene(cfg, case, scene, report)
    if shapes is None:
        shapes = ("polyhedra",) if has_field(scene, "polyhedra/shape") else ("spheres", "clumps")
    names = stage_effects(cfg, case.dimension, bonded=has_field(scene, "bonds/i"))
    for spec, msg in shape_refusals(names, shapes):
        if spec.key:
            report(f"physics.{spec.key}", msg, cfg.physics[spec.key])
        elif spec.name == "bonds" and cfg.get("bonds") is not None:
            report("bonds", msg)
        else:
            report("", f"{spec.declared_by} (effect {spec.name}) {msg}")
    if cfg.get("output") is not None and cfg.output.get("packing") is not None and set(shapes) == {"mixed"}:
        report("output.packing", "is for sphere, clump and polyhedron scenes, not yet for spheres with polyhedra")
    _measure_check(cfg, case, shapes, report)
    refresh = cfg.get("contact", {}).get("geometry_refresh", 1)
    if refresh > 1 and "polyhedra" not in shapes:
        report("contact.geometry_refresh", "is for polyhedron scenes (the linearized geometry of polyhedron pairs)",
               refresh)
    if set(shapes) <= {"polyhedra", "mixed"}:
        for k, w in enumerate(cfg.get("walls", ())):
            if w.type == "cylinder":
                report(f"walls.{k}.type", f"is not for polyhedra: {EFFECTS['walls'].limits['polyhedra']}", w.type)


def _measure_check(cfg, case, shapes, report):
    """The measures a scene cannot take: none on spheres with polyhedra, no regions or fields
    (per volume) in 2D."""
    out = cfg.get("output", {})
    keys = (("measure", bool(cfg.get("measure")), True), ("output.fields", out.get("fields") is not None, True),
            ("output.force_chains", bool(out.get("force_chains")), False))
    for key, on, per_volume in keys:
        if on and set(shapes) == {"mixed"}:
            report(key, "is for sphere, clump and polyhedron scenes, not yet for spheres with polyhedra")
        elif on and per_volume and case.dimension == 2:
            report(key, "is per volume, for 3D cases (this case is planar)")


def stage_effects(cfg, dimension, bonded):
    """The effects a stage runs but for its bodies' shape: the declared ones, walls when it
    has walls, bonds when ``bonded`` (its input holds bonds) or it has a bonds section."""
    names = declared_effects(cfg, dimension)
    if len(cfg.get("walls", ())):
        names.append("walls")
    if bonded or cfg.get("bonds") is not None:
        names.append("bonds")
    return names


def config_inputs(cfg):
    """Input fields a dem config reads besides its type's requires: bonds.from_phases the phase table."""
    bonds = cfg.get("bonds")
    return {"bonds.from_phases": ("phases/sphere", "phases/pair_model")} if bonds is not None and \
        bonds.from_phases else {}


def declared_effects(cfg, dimension):
    """Names of the effects the stage's physics section and the case's dimension declare (registry order)."""
    return declared(cfg.physics, dimension)


def contact_model(cfg):
    from demcli.engine.materials import ContactModel

    c = cfg.contact
    s = cfg.scaling.stiffness if "scaling" in cfg else 1.0

    def scaled(k, value):
        return value * s if k in ("kn", "kt") else value

    pairs = tuple((p.materials[0], p.materials[1],
                   {k: scaled(k, p[k]) for k in ("friction", "rolling_friction", "restitution", "kn", "kt", "cn")
                    if p[k] is not None}) for p in c.pairs)
    kn = (c.kn or 0.0) * s
    kt = c.kt * s if c.kt is not None else kn / 4.0
    return ContactModel(law=c.law, kn=kn, kt=kt, cn=c.cn, tangential_damping=c.tangential_damping,
                        no_tension=c.no_tension, lever_arm=c.lever_arm, pairs=pairs,
                        geometry_refresh=c.get("geometry_refresh", 1))


def case_materials(case, stiffness=1.0):
    """Materials of the case and their rigid twins (:func:`demcli.engine.materials.with_rigid_twins`:
    rigid walls use them); ``stiffness`` scales every Young's and shear modulus (scaling.stiffness)."""
    from demcli.engine.materials import Material, with_rigid_twins

    mats = [Material(name, **dict(m.to_dict())) for name, m in case.materials.items()]
    if stiffness != 1.0:
        import dataclasses

        mats = [dataclasses.replace(m, young=m.young * stiffness,
                                    shear=None if m.shear is None else m.shear * stiffness) for m in mats]
    return with_rigid_twins(mats)


def phase_materials(ctx, groups):
    """{phase name: material name} of a state with a phase table (each phase one material)."""
    from demcli.stages.asphalt.mastic import str_list

    g = groups["phases"]
    names = str_list(g["names"])
    mats = list(ctx.case.materials)
    sph = np.asarray(g["sphere"], np.int64)
    smat = np.asarray(groups["spheres"]["material"], np.int64)
    out = {}
    for k, name in enumerate(names):
        used = np.unique(smat[sph == k])
        if len(used) > 1:
            raise InputError(f"stage {ctx.name}: bonds.from_phases needs one material per phase; phase {name} has "
                             f"{', '.join(mats[m] for m in used)}")
        if len(used):
            out[name] = mats[int(used[0])]
    return out


def phase_models(ctx, state_groups):
    """(bond model pairs and rows, contact-law pair overrides) from a state's phase table
    (:func:`demcli.stages.asphalt.mastic.phase_table`): every phase pair gets linear springs
    k_n, k_t = k_s and its friction (the law of unbonded and broken contacts); contact_bond
    and parallel_bond pairs also a bond model with their strengths."""
    from demcli.engine.bonds import model_row
    from demcli.state import State
    from demcli.stages.asphalt.mastic import phase_table

    st = State()
    st.groups.update(state_groups)
    try:
        table = phase_table(st)
    except StateError as e:  # a missing or invalid table is bad input for this stage
        raise InputError(f"stage {ctx.name}: bonds.from_phases: {e}") from None
    pm = phase_materials(ctx, state_groups)
    names = list(ctx.case.materials)
    pairs, rows, overrides = [], [], []
    for (a, b), (model, prm) in table.items():
        if a not in pm or b not in pm:
            continue
        ma, mb = pm[a], pm[b]
        overrides.append((ma, mb, {"kn": prm["kn"], "kt": prm["ks"], "friction": prm["friction"]}))
        if model == "contact_bond":
            rows.append(model_row("contact_bond", kn=prm["kn"], ks=prm["ks"], normal_strength=prm["cb_normal_strength"],
                                  shear_strength=prm["cb_shear_strength"]))
        elif model == "parallel_bond":
            rows.append(model_row("parallel_bond", bond_kn=prm["pb_kn"], bond_ks=prm["pb_ks"],
                                  radius_multiplier=prm["pb_radius_multiplier"],
                                  normal_strength=prm["pb_normal_strength"], shear_strength=prm["pb_shear_strength"]))
        else:
            continue
        pairs.append((names.index(ma), names.index(mb)))
    return pairs, rows, tuple(overrides)


def set_bond_models(ctx, bonds_cfg, system, groups=None):
    """The stage's bond models into the system (by material pair, replacing stored ones);
    with ``from_phases`` first those of the state's phase table."""
    from demcli.engine.bonds import model_row

    names = list(ctx.case.materials)
    pairs, rows = [], []
    if bonds_cfg.get("from_phases"):
        pairs, rows, _ = phase_models(ctx, groups)
    for b in bonds_cfg.models:  # material names are checked at validation
        params = {key: b[key] for key in b.keys() if key not in ("model", "materials") and b[key] is not None}
        params = {key: (dict(v.to_dict()) if hasattr(v, "to_dict") else v) for key, v in params.items()}
        pairs.append(tuple(names.index(m) for m in b.materials))
        rows.append(model_row(b.model, **params))
    system.bonds.set_models(pairs, rows)


def scene_shape(groups):
    """The bodies' shape in the effect registry's words (:data:`demcli.effects.SHAPES`):
    spheres, clumps, polyhedra, or mixed (spheres or clumps with polyhedra)."""
    from demcli.engine.mixed_shape import is_mixed
    from demcli.engine.system import is_clumped, is_polyhedral

    if is_mixed(groups):
        return "mixed"
    if is_polyhedral(groups):
        return "polyhedra"
    return "clumps" if is_clumped(groups) else "spheres"


def particle_support(groups, normal):
    """min over the particles' points p of p . normal [m]: where a plane with this normal
    (into the domain) first touches them (spheres and clumps: their surfaces; polyhedra:
    their vertices; the loading actors of a ballast stage are left out). inf for none."""
    from demcli.engine.actors import remove_actors
    from demcli.state import State
    from demcli.state.polyhedra import world_vertices

    n = np.asarray(normal, float)
    groups = remove_actors(groups)
    out = math.inf
    if len(groups.get("polyhedra", {}).get("shape", ())):
        v, _ = world_vertices(State(groups=groups))
        out = float((v @ n).min()) if len(v) else math.inf
    s = groups.get("spheres", {})
    if len(s.get("radius", ())):
        c = State(groups={"bodies": groups["bodies"], "spheres": s}).sphere_centres()
        out = min(out, float((c @ n - np.asarray(s["radius"], float)).min()))
    return out


def lay_walls(cfg, wpoint, groups):
    """Move the plane walls with ``lay_on_particles`` along their normals (in place on
    ``wpoint``, the walls' points in :func:`build_walls` order) to that gap from the
    particles of ``groups``; returns {wall row: (gap, shift along the normal) [m]}. Their drawing
    extents follow (the engines draw a wall at its configured extent + its displacement)."""
    out = {}
    row = 0
    for w in cfg.walls:
        if w.type == "box":
            row += sum(1 for face in FACES if face not in w.open)
            continue
        if w.type == "plane" and w.lay_on_particles is not None:
            n = np.asarray(w.normal, float) / np.linalg.norm(w.normal)
            low = particle_support(groups, n)
            if math.isfinite(low):
                d = low - w.lay_on_particles - float(wpoint[row] @ n)
                wpoint[row] += d * n
                out[row] = (w.lay_on_particles, d)
        row += 1
    return out


def _mesh_row(w, where, case_file):
    """(point, extent, (local vertices, triangles)) of a mesh wall: its file read and placed
    (:func:`demcli.geometry.mesh_file.read_mesh`; a bad file is a ConfigError naming ``case_file`` and
    ``where``.file), the wall's point its first vertex, the vertices relative to it [m] (the mesh
    translates with the point), the drawing extent its bounding box."""
    from demcli.geometry.mesh_file import read_mesh

    verts, tris = read_mesh(w.file, case_file=case_file, key=f"{where}.file", scale=w.scale,
                            translation=w.translation, rotate=np.degrees(w.rotate))
    point = verts[0].copy()
    return point, np.r_[verts.min(axis=0), verts.max(axis=0)], (np.ascontiguousarray(verts - point), tris)


def _wall_control(motion, normal, area, cfg):
    """(control mode, W_* parameter row, velocity [m/s]) of a wall's ``motion`` (None: fixed);
    ``area`` [m^2] the loaded area servo and pressure walls take when the motion gives none; a
    force wall's weight from ``cfg.physics.gravity`` along its ``normal``."""
    from demcli.kernels import walls as W

    prm = np.zeros(W.N_WPARAMS)
    control = W.FIXED
    v = np.zeros(3)
    mode = motion.mode if motion is not None else "fixed"
    if mode == "velocity":
        control, v = W.VELOCITY, np.array(motion.velocity)
    elif mode == "servo":
        control = W.SERVO
        prm[W.W_TARGET] = motion.stress
        prm[W.W_GAIN] = motion.gain
        prm[W.W_VMAX] = motion.max_speed
        prm[W.W_AREA] = motion.area if motion.area is not None else area
    elif mode == "pressure":
        control = W.PRESSURE
        prm[W.W_TARGET] = motion.pressure
        prm[W.W_MASS] = motion.mass
        prm[W.W_AREA] = motion.area if motion.area is not None else area
    elif mode == "force":
        control = W.FORCE
        prm[W.W_TARGET] = motion.force
        prm[W.W_AMPLITUDE] = motion.amplitude
        prm[W.W_FREQ] = motion.frequency
        prm[W.W_PHASE] = motion.phase
        prm[W.W_START] = motion.start
        prm[W.W_MASS] = motion.mass
        if motion.weight:  # a constant force: the weight's component along the normal
            g = np.asarray(cfg.physics.gravity, float)
            prm[W.W_TARGET] += motion.mass * float(g @ (np.asarray(normal, float) / np.linalg.norm(normal)))
    return control, prm, v


def check_mesh_files(cfg, case_file, where):
    """Read the mesh walls' files of a stage config (relative to ``case_file``): a missing,
    unreadable or degenerate one is a ConfigError naming ``where``[k].file (exit code 2), found
    when the case is loaded rather than when its stage starts."""
    for k, w in enumerate(cfg.get("walls", ())):
        if w.type == "mesh":
            _mesh_row(w, f"{where}[{k}]", case_file)


def build_walls(cfg, case, case_file=None, where="walls"):
    """Walls of the stage config as arrays (box walls become up to six planes, mesh files are read:
    relative to ``case_file``'s folder, errors naming ``where``[k])."""
    from demcli.engine.system import Walls
    from demcli.kernels import walls as W

    names = list(case.materials)
    rows = []

    def rigid(w):  # (the walls some stages build in code leave it out)
        return bool(w.get("rigid", False))

    def add(name, kind, point, normal, radius, material, motion, extent, area, rigid, mesh=None):
        control, prm, v = _wall_control(motion, normal, area, cfg)
        n = np.asarray(normal, float)
        rows.append((name, kind, np.asarray(point, float), n / np.linalg.norm(n), radius, names.index(material),
                     control, prm, v, np.asarray(extent, float), rigid, mesh))

    for k, w in enumerate(cfg.walls):
        if w.type == "plane":
            ext = w.extent if w.extent is not None else tuple(np.r_[np.array(w.point) - 0.1, np.array(w.point) + 0.1])
            add(w.name or f"wall{k}", W.PLANE, w.point, w.normal, 0.0, w.material, w.motion, ext, math.nan, rigid(w))
        elif w.type == "mesh":
            point, ext, mesh = _mesh_row(w, f"{where}[{k}]", case_file)
            add(w.name or f"wall{k}", W.MESH, point, w.normal, 0.0, w.material, w.motion, ext, math.nan, rigid(w),
                mesh)
        elif w.type == "cylinder":
            b = np.array(w.base)
            ext = np.r_[b - w.radius, b + w.radius]
            ext[5] = b[2] + w.height
            ext[2] = b[2]
            add(w.name or f"wall{k}", W.CYLINDER, w.base, w.axis, w.radius, w.material, w.motion, ext,
                2.0 * math.pi * w.radius * w.height, rigid(w))
        else:
            lo, hi = np.array(w.min), np.array(w.max)
            ext = np.r_[lo, hi]
            size = hi - lo
            for f, face in enumerate(FACES):
                if face in w.open:
                    continue
                d = f // 2
                normal = np.zeros(3)
                normal[d] = 1.0 if f % 2 == 0 else -1.0
                point = lo.copy() if f % 2 == 0 else hi.copy()
                area = float(np.prod(np.delete(size, d)))
                add(f"{w.name}.{face}", W.PLANE, point, normal, 0.0, w.material, w.motion.get(face), ext, area,
                rigid(w))
    walls = Walls()
    if rows:
        walls = Walls(name=[r[0] for r in rows], kind=np.array([r[1] for r in rows], np.int8),
                      point=np.array([r[2] for r in rows]), normal=np.array([r[3] for r in rows]),
                      radius=np.array([r[4] for r in rows], float), material=np.array([r[5] for r in rows], np.int64),
                      control=np.array([r[6] for r in rows], np.int8), prm=np.array([r[7] for r in rows]),
                      v=np.array([r[8] for r in rows]), extent=np.array([r[9] for r in rows]),
                      rigid=np.array([r[10] for r in rows], bool),
                      mesh=[r[11] for r in rows] if any(r[11] is not None for r in rows) else None)
    return walls  # the modes each wall type takes are checked at validation (_check_wall_mode)


def mesh_digest(cfg, case_dir):
    """sha256 of the mesh walls' files in order (part of the stage's config hash: an edited mesh runs
    the stage again); None without mesh walls or when one cannot be read (the run reports that)."""
    import hashlib

    from demcli.stages.specimen.particles import case_file_path

    files = [w.file for w in cfg.get("walls", ()) if w.type == "mesh"]
    try:
        return [hashlib.sha256(case_file_path(case_dir, f).read_bytes()).hexdigest() for f in files] or None
    except OSError:
        return None


def run(ctx, cfg, state_in):
    """The ``dem`` stage: :func:`demcli.stages.loop.integrate`, with the cell's records when periodic."""
    from demcli.stages.loop import integrate

    return integrate(ctx, cfg, state_in, periodic.hooks() if cfg.get("periodic") is not None else None)


def plan_summary(ctx_case, cfg, scene):
    """Effects, passes and arrays of the stage for ``demcli check`` (no kernels compiled)."""
    from demcli.engine.plan import make_plan

    return make_plan(declared_effects(cfg, ctx_case.dimension), clumps=scene.get("clumps", False),
                     walls=len(cfg.walls) > 0, polyhedra=scene.get("polyhedra", False))


register_stage(StageType(
    "dem", {**FIELDS, "periodic": periodic.PERIODIC}, run, needs_input=True, requires=("bodies/x", "spheres/radius"), check=check_stage,
    orders_particles=True, provides=ENGINE_OUTPUT, keeps=ENGINE_KEEPS, config_requires=config_inputs,
    case_check=scene_check, file_digest=mesh_digest,
    plan=plan_summary, doc="integrate the motion with the declared physics"))
