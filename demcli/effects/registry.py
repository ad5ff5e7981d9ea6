"""The effects a stage can declare: the switchboard the schema, the plan and the checks read.

Each effect is one :class:`EffectSpec` registration (LAMMPS-style: one table of named
sub-models). It holds how a case switches it on (its key and schema field in a dem stage's
``physics`` section, or what else declares it), the kernel switch it sets (a name of
:data:`demcli.kernels.layout.FLAG_NAMES`), the arrays the plan allocates for it, the kernel
passes and pass counters that prove it ran, the shapes it supports (with the reason for
each one it does not) and the effects it cannot run with. Derived from it:

* the ``physics`` section of the dem stage (:func:`physics_section`);
* the effects a stage declares (:mod:`demcli.stages.dem`, ``declared_effects``) and the plan's
  kernel switches (:func:`demcli.engine.plan.make_plan`);
* the refusal of an effect on a shape it does not support, at ``demcli check`` and at the
  stage start (:func:`shape_refusals`, :func:`check_shape`);
* the effect x shape table of docs/architecture.md (:func:`effects_table`).

An effect a stage does not declare allocates nothing and runs nothing: the plan leaves its
arrays at size zero and its kernel switch off; the kernel's pass counters prove it.
Adding an effect: register it here (with its schema field, flag and arrays) and add its
kernel hook under the flag (a new name in ``FLAG_NAMES``).
"""

from dataclasses import dataclass, field

from demcli.config.schema import Bool, Float, Optional, Section, Vector

SHAPES = ("spheres", "clumps", "polyhedra", "mixed")
"""Body shapes of the engine; ``clumps`` and ``polyhedra`` are also effects, derived from the
state; ``mixed``: spheres or clumps with polyhedra (e.g. a polyhedral plate on a clump bed)."""

SOURCES = ("physics", "dimension", "walls", "bonds", "shape")
"""How an effect becomes active: its key in ``physics``; the case's dimension 2; the stage's
walls; a bonds section or a state that holds bonds; the bodies' shape (the state)."""


@dataclass(frozen=True)
class EffectSpec:
    """One effect.

    Attributes:
        name: the effect's name (``Plan.effects``, the state's ``meta/effects``).
        doc: one line on what it simulates.
        key: its key in a dem stage's ``physics`` section (None: declared otherwise, see source).
        param: the schema field of that key (:mod:`demcli.config.schema`); the effect is
            active when its value is neither absent (None) nor ``false``.
        source: how it becomes active, one of :data:`SOURCES` ('physics' when it has a key).
        declared_by: how a case declares it when it has no key (for messages).
        flag: its kernel switch, a name of ``demcli.kernels.layout.FLAG_NAMES`` (None: none).
        fields: (array name, rows per: 'pair' | 'wall_pair' | 'sphere' | 'body' | 'wall' | 'bond').
        passes: kernel passes it adds.
        counters: names of kernel pass counters that prove it ran.
        unsupported: {shape: why not} for each shape of :data:`SHAPES` it does not run on.
        limits: {shape: what it does not do there} for shapes it runs on in part (the stage's
            checks refuse the rest, with this text).
        excludes: ((other effect, why not), ...) effects it cannot run with.
    """

    name: str
    doc: str
    key: str = None
    param: object = None
    source: str = "physics"
    declared_by: str = ""
    flag: str = None
    fields: tuple = ()
    passes: tuple = ()
    counters: tuple = ()
    unsupported: dict = field(default_factory=dict)
    limits: dict = field(default_factory=dict)
    excludes: tuple = ()

    def supports(self, shape):
        return shape not in self.unsupported

    @property
    def where(self):
        """Where a case declares it: ``physics.<key>`` or its ``declared_by``."""
        return f"physics.{self.key}" if self.key else self.declared_by


EFFECTS = {}


def register(spec):
    """Add an effect to the registry (one file per effect family may call this)."""
    if spec.name in EFFECTS:
        raise ValueError(f"effect {spec.name!r} registered twice")
    if spec.source not in SOURCES:
        raise ValueError(f"effect {spec.name!r}: source {spec.source!r} is not one of {SOURCES}")
    if (spec.key is None) != (spec.source != "physics") or (spec.key is None) != (spec.param is None):
        raise ValueError(f"effect {spec.name!r}: a physics effect has a key and a param, others neither")
    bad = set(spec.unsupported) - set(SHAPES)
    if bad:
        raise ValueError(f"effect {spec.name!r}: unknown shapes {sorted(bad)} (shapes: {SHAPES})")
    EFFECTS[spec.name] = spec
    return spec


def active(value):
    """Whether a ``physics`` value declares its effect: given and not ``false`` (0.0 declares)."""
    return value is not None and value is not False


def physics_section():
    """The dem stage's ``physics`` section: one key per registered effect that has one."""
    return Section({s.key: s.param for s in EFFECTS.values() if s.key},
                   default={}, doc="the effects this stage simulates; nothing else runs")


def declared(physics, dimension):
    """Names of the effects a stage's validated ``physics`` section and the case's dimension declare."""
    return [s.name for s in EFFECTS.values()
            if (s.source == "physics" and active(physics[s.key])) or (s.source == "dimension" and dimension == 2)]


def shape_refusals(names, shapes):
    """The effects among ``names`` that run on none of ``shapes`` (the shapes the bodies may
    have) and those that exclude one another, as ``(spec, message)``: message says why, e.g.
    ``is not for polyhedra: <reason>``. Shape effects (clumps, polyhedra) are skipped."""
    out = []
    names = set(names)
    for spec in (EFFECTS[n] for n in sorted(names)):
        if spec.source == "shape":
            continue
        if not any(spec.supports(s) for s in shapes):
            out.append((spec, f"is not for {' or '.join(shapes)}: {spec.unsupported[shapes[0]]}"))
        for other, why in spec.excludes:
            if other in names:
                out.append((spec, f"cannot run with {EFFECTS[other].where or other}: {why}"))
    return out


def check_shape(names, shape, stage):
    """Raise InputError naming ``stage``, where each refused effect is declared and why, when
    an effect of ``names`` does not run on ``shape`` or excludes another of them."""
    problems = shape_refusals(names, (shape,))
    if problems:
        from demcli.errors import InputError

        raise InputError(f"stage {stage}: " + "; ".join(
            f"{spec.where} {msg}" if spec.key else f"{spec.declared_by} (effect {spec.name}) {msg}"
            for spec, msg in problems))


def effects_table():
    """Markdown table of the effects (not the shapes themselves) by shape: 'yes' or why not."""
    rows = ["| effect | config key | flag | arrays | " + " | ".join(SHAPES) + " |",
            "|---|---|---|---|" + "---|" * len(SHAPES)]
    for s in EFFECTS.values():
        if s.source == "shape":
            continue
        arrays = ", ".join(f"`{n}[{per}]`" for n, per in s.fields) or "-"
        cells = [(f"yes, {s.limits[shape]}" if shape in s.limits else "yes") if s.supports(shape)
                 else f"no: {s.unsupported[shape]}" for shape in SHAPES]
        rows.append(f"| {s.name} | `{s.where}` | {f'`{s.flag}`' if s.flag else '-'} | {arrays} | "
                    + " | ".join(cells) + " |")
    return "\n".join(rows) + "\n"


_ROLLING_POLY = "a rolling-resistance moment corrects spheres for the shape they lack; polyhedra resist rolling " \
                "by their faces"
_PLANAR_POLY = "a 2D scene is made of disks (the polygons stage's sections are discretized into bonded disks); " \
               "a polyhedron's contact is a 3D overlap volume"
_DASHPOT_SPHERES = "the sphere laws carry their restitution dashpot always (set restitution 1 for none)"
_WALLS_POLY = "plane, box and mesh walls only: a polyhedron's wall contact is its overlap with a half-space (a " \
              "mesh: with the prism under each triangle); cylinder walls are for spheres and clumps"
_WALLS_MIXED = "plane and box walls only: a polyhedron's wall contact is its overlap with a half-space; cylinder " \
               "and mesh walls are for spheres and clumps"

# in the order of the physics section's keys (docs/cases.md lists them so)
register(EffectSpec(
    "gravity", "uniform body force m g",
    key="gravity", param=Optional(Vector(3, "m/s^2"), doc="gravity vector; omit for none"), flag="gravity",
    passes=("body_loads:gravity",), counters=("gravity",)))
register(EffectSpec(
    "friction", "tangential spring with Coulomb slip; bodies rotate",
    key="friction", param=Bool(default=False, doc="tangential springs with Coulomb slip"), flag="friction",
    fields=(("contact_ft", "pair"), ("wall_ft", "wall_pair"), ("torque_i", "pair"), ("torque_j", "pair")),
    passes=("pairs:tangential", "kick:rotation"), counters=("friction",)))
register(EffectSpec(
    "rolling_resistance", "elastic-plastic rolling spring (Ai et al. 2011, model C)",
    key="rolling_resistance", param=Bool(default=False, doc="rolling resistance from material rolling_friction"),
    flag="rolling",
    fields=(("contact_mr", "pair"), ("wall_mr", "wall_pair"), ("torque_i", "pair"), ("torque_j", "pair")),
    passes=("pairs:rolling", "kick:rotation"), counters=("rolling",),
    unsupported={"polyhedra": _ROLLING_POLY}))
register(EffectSpec(
    "local_damping", "Cundall non-viscous damping -lambda |F| sign(v)",
    key="local_damping", param=Optional(Float(min=0, max=1, max_inclusive=False), doc="Cundall local damping lambda"),
    flag="local", passes=("body_loads:local_damping",), counters=("damping",)))
register(EffectSpec(
    "viscous_damping", "mass-proportional damping -alpha m v",
    key="viscous_damping", param=Optional(Float("Hz", min=0), doc="mass-proportional damping alpha"),
    flag="viscous", passes=("body_loads:viscous_damping",), counters=("damping",)))
register(EffectSpec(
    "contact_damping", "polyhedra: normal dashpot c_n = 2 zeta sqrt(m* k_n sqrt(A)) from the material restitution",
    key="contact_damping", param=Bool(default=False, doc="polyhedra: normal dashpot from the material restitution "
                                      "(sphere laws always have theirs)"),
    flag="dashpot", passes=("pairs:contact_damping",),
    unsupported={"spheres": _DASHPOT_SPHERES, "clumps": _DASHPOT_SPHERES}))
register(EffectSpec(
    "adaptive_damping", "mass-proportional damping whose alpha adapts by R = E_a / |dE_k| (Shao et al. 2017)",
    key="adaptive_damping", param=Optional(Section({
        "initial": Float("Hz", min=0, min_inclusive=False, default=0.1, doc="starting alpha"),
    }), doc="polyhedra: mass-proportional damping adapted by R = E_a/|dE_k| (seed 002)"),
    flag="adaptive", passes=("body_loads:adaptive_damping",), counters=("damping",)))
register(EffectSpec(
    "energy", "energy book-keeping: dashpot, slip and damping losses, wall work",
    key="energy", param=Bool(default=False, doc="energy book-keeping (losses, wall work, balance)"), flag="energy",
    fields=(("pair_losses", "pair"), ("sphere_losses", "sphere"), ("body_losses", "body")),
    passes=("pairs:losses", "gather:losses"), counters=("energy",)))
register(EffectSpec(
    "walls", "rigid plane, cylinder and triangle-mesh walls with velocity, force or servo control",
    source="walls", declared_by="walls", limits={"polyhedra": _WALLS_POLY, "mixed": _WALLS_MIXED},
    fields=(("wall_list", "wall_pair"), ("wall_force", "wall")),
    passes=("walls:move", "walls:list", "walls:control"), counters=("wallmove", "wallctrl")))
register(EffectSpec(
    "planar", "2D mode: z and out-of-plane rotations locked (disks, mass per unit thickness)",
    source="dimension", declared_by="dimension: 2", flag="planar",
    passes=("kick:planar_lock",),
    unsupported={"polyhedra": _PLANAR_POLY, "mixed": _PLANAR_POLY}))
register(EffectSpec(
    "bonds", "contact, parallel and Burgers bonds between spheres (declared by a stage that creates them, "
    "derived from a state that holds them)",
    source="bonds", declared_by="bonds", flag="bonds",
    fields=(("bond_list", "bond"), ("bond_history", "bond"), ("bond_force", "bond"), ("torque_i", "pair")),
    passes=("bonds:forces", "bonds:gather", "kick:rotation"), counters=("bonds",),
    unsupported={"polyhedra": "the bond models (contact, parallel, Burgers) are defined on sphere radii and "
                              "centre lines",
                 "mixed": "bonds join the spheres of a spheres-only scene (their pair lists and the bond "
                          "pass are the sphere plug-in's)"}))
register(EffectSpec(
    "clumps", "rigid bodies of several spheres (derived from the state, not declared)",
    source="shape", flag="clumps",
    fields=(("orientation", "body"), ("angular_momentum", "body"), ("member_csr", "sphere"),
            ("sphere_kinematics", "sphere")),
    passes=("members:place", "bodies:sum_members"), counters=("members", "body")))
register(EffectSpec(
    "polyhedra", "rigid convex polyhedra (derived from the state): exact overlap-volume contacts",
    source="shape",
    fields=(("world_vertices", "body"), ("world_planes", "body"), ("contact_ft", "pair")),
    passes=("polyhedra:world_geometry", "pairs:overlap_volume"), counters=("pairs",)))
