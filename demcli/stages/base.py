"""Stage types: each is a config schema plus a run function, registered by name.

A stage type module calls :func:`register_stage` at import; the case schema is built
from the registry (:func:`stage_catalog` hands it to :mod:`demcli.config.case`, which does not
import the stages), so a new stage is one new module, listed in :func:`load_stage_types`.

Each type declares the state fields it reads (``requires``) and writes (``provides``,
plus the input groups it ``keeps``), so that case validation can follow the stages in
order (:func:`input_scenes`) and refuse a stage whose input no earlier stage writes
before anything runs.
"""

from collections.abc import Mapping
from dataclasses import dataclass

STAGE_TYPES = {}

ENGINE_OUTPUT = ("bodies/*", "spheres/*", "contacts/*", "wall_contacts/*", "walls/*", "energy/*", "records/*")
"""What a stage that integrates the scene (:func:`demcli.stages.loop.integrate`) writes."""

ENGINE_KEEPS = ("polyhedra", "polyhedron_shapes", "bonds", "bond_models")
"""Input groups the integrated scene carries on when the input has them."""


@dataclass(frozen=True)
class StageType:
    """A kind of stage.

    Attributes:
        name: the ``type:`` value in a case file.
        fields: dict of schema fields of the stage (besides ``name`` and ``type``).
        run: ``run(ctx, cfg, state_in) -> State``.
        needs_input: the stage reads the previous stage's state.
        requires: state fields the input must hold (checked before running).
        plan: optional ``plan(cfg, case) -> Plan`` for ``demcli check``.
        check: optional cross-field rule ``check(node, report)``.
        doc: one-line description.
        describe: optional ``describe(cfg, case) -> str`` summary for ``demcli check``.
        orders_particles: the runner re-stores the input scene in spatial cell order before
            the stage (and before hashing it) where :func:`demcli.state.order.spatial_order`
            can: spheres, and no contacts, bonds, actors or checkpoint yet. Set by the stages
            that integrate a sphere scene from its first step (dem, compact).
        provides: state fields the stage writes, ``group/name`` or ``group/*`` (every field
            of the group).
        keeps: groups of the input state that the output carries on when the input has them.
        adds: the name of a bool key with which a stage that starts a scene (needs_input False)
            adds to the input's scene instead (it then reads the input and keeps all of it).
        file_digest: optional ``file_digest(cfg, case_dir) -> str or None``: a digest of the files
            the config names, part of the stage's config hash (an edited file runs it again).
        config_requires: optional ``config_requires(cfg) -> {key: fields}``: further input
            fields that this config reads (beyond ``requires``) by the config key that reads
            them, checked at validation.
        case_check: optional ``case_check(cfg, case, k, scene, report)``: rules that need the
            whole validated case (the case's dimension, earlier stages, the machine's memory);
            ``k`` is the stage's index, ``scene`` the fields of its input (None when unknown) and
            ``report`` reports relative to the stage, as a Section check's does.
    """

    name: str
    fields: dict
    run: object
    needs_input: bool = True
    requires: tuple = ()
    plan: object = None
    check: object = None
    doc: str = ""
    describe: object = None
    orders_particles: bool = False
    provides: tuple = ()
    keeps: tuple = ()
    config_requires: object = None
    case_check: object = None
    adds: str = None
    file_digest: object = None

    def reads_input(self, cfg):
        """Whether a stage of this type with config ``cfg`` (a validated Node or a raw mapping)
        reads the state of the stage before: ``needs_input``, or its ``adds`` key set true."""
        if self.adds is None or not isinstance(cfg, Mapping):
            return self.needs_input
        return cfg.get(self.adds, False) is True


def register_stage(stage_type):
    """Add a stage type to the registry (once per name); returns it."""
    if stage_type.name in STAGE_TYPES:
        raise ValueError(f"stage type {stage_type.name!r} registered twice")
    STAGE_TYPES[stage_type.name] = stage_type
    return stage_type


def load_stage_types():
    """Import every built-in stage module (registers them) and return the registry."""
    from demcli.stages import dem
    from demcli.stages.asphalt import carve, compact, cut, mastic, place  # 3D asphalt, seed 000
    from demcli.stages.asphalt import discretize, polygons  # 2D sections, seed 001
    from demcli.stages.asphalt import sand  # bonded viscoelastic specimens, seed 003
    from demcli.stages.asphalt import dynamic_modulus, idt, marshall  # the virtual asphalt lab's tests
    from demcli.stages.ballast import assemble, box, clumps, library  # railway ballast, seed 002
    from demcli.stages.specimen import generate, gradation, particles

    del dem, carve, compact, cut, mastic, place, discretize, polygons, sand  # registrations
    del dynamic_modulus, idt, marshall
    del assemble, box, clumps, library, generate, gradation, particles
    return STAGE_TYPES


def register_all_fields():
    """Import every module above the state layer that declares state fields or record columns:
    the built-in stage types (:func:`load_stage_types`) and the engine parts their states hold
    (bonds). :func:`demcli.state.fields.register_all` calls it before it names a group unknown."""
    from demcli.engine import bonds  # the bonds and bond_models groups

    del bonds  # imported for its registrations
    load_stage_types()


_CATALOG = None


def stage_catalog():
    """The built-in stage types (all imported) as the case schema reads them
    (:class:`demcli.config.case.StageCatalog`); the same object on every call."""
    global _CATALOG
    if _CATALOG is None:
        from demcli.config.case import StageCatalog

        _CATALOG = StageCatalog(types=load_stage_types(), input_scenes=input_scenes, has_field=has_field,
                                type_of=type_of, writers_of=writers_of)
    return _CATALOG


def case_schema():
    """The case schema of the built-in stage types (:func:`demcli.config.case.case_schema`)."""
    from demcli.config.case import case_schema as schema_of

    return schema_of(stage_catalog())


def load_case(path, overrides=()):
    """Validated case (a read-only Node, SI values) or ConfigError listing every problem: a case
    file of the built-in stage types (:func:`demcli.config.case.load_case`); its mesh walls' files
    are read (a bad one: a ConfigError naming it, :func:`demcli.stages.dem.check_mesh_files`), and
    the marshall stages' head files (:func:`demcli.stages.asphalt.marshall.head_radius`)."""
    from demcli.config.case import load_case as load_with
    from demcli.stages.asphalt.marshall import head_radius
    from demcli.stages.dem import check_mesh_files

    case = load_with(path, stage_catalog(), overrides)
    for k, cfg in enumerate(case.stages):  # the files a config names, before any stage runs
        check_mesh_files(cfg, path, f"stages[{k}].walls")
        if cfg.type == "marshall":
            head_radius(cfg.head_file, path, f"stages[{k}]")
    return case


def write_cases_doc(path="docs/cases.md"):
    """Regenerate the case-file reference docs/cases.md from the built-in stage types. Run in the
    repository root: ``python -c "from demcli.stages.base import write_cases_doc; write_cases_doc()"``."""
    from demcli.config.docs import write

    write(case_schema(), path)


def _group(path):
    return path.rsplit("/", 1)[0]


def has_field(scene, path):
    """Whether a scene (a set of ``group/name`` and ``group/*`` entries) holds field ``path``."""
    return path in scene or f"{_group(path)}/*" in scene


def type_of(cfg):
    """The StageType of a stage config (a validated Node or raw data), None when unknown."""
    name = cfg.get("type") if isinstance(cfg, Mapping) else None
    return STAGE_TYPES.get(name) if isinstance(name, str) else None


def input_scenes(stages):
    """The state fields the input of each stage holds, following ``stages`` (validated Nodes or
    raw mappings) in order: a frozenset per stage, None for the first stage (no input) and
    after a stage whose type is unknown (nothing known to check against)."""
    out, scene = [], None
    for cfg in stages:
        out.append(scene)
        st = type_of(cfg)
        reads = st is not None and st.reads_input(cfg)
        if st is None or (reads and (st.keeps or st.adds) and scene is None):
            scene = None
        elif reads and st.adds:  # adds to the scene: keeps all of it
            scene = frozenset(st.provides) | scene
        else:
            kept = {f for f in scene if _group(f) in st.keeps} if reads and scene else set()
            scene = frozenset(st.provides) | kept
    return out


def writers_of(path):
    """Names of the stage types that write field ``path``."""
    return [name for name, st in sorted(STAGE_TYPES.items()) if has_field(st.provides, path)]


def earlier_stage(case, k, type_name):
    """The nearest stage before stage ``k`` of type ``type_name`` whose output reaches stage
    ``k`` (none of the stages between starts a new scene), or None."""
    for cfg in reversed(case.stages[:k]):
        if cfg.type == type_name:
            return cfg
        if not STAGE_TYPES[cfg.type].reads_input(cfg):
            return None
    return None


def require_dimension(case, dimension, what, report):
    """Report when the case's dimension is not ``dimension`` (``what`` says what the stage builds)."""
    if case.dimension != dimension:
        report("", f"{what} is {dimension}D; set dimension: {dimension} in the case (it is {case.dimension})")
