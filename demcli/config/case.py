"""The case file schema: top-level keys, materials, and the list of stages.

Stage sections come from the stage registry, which the stages pass in as a
:class:`StageCatalog` (:func:`demcli.stages.base.stage_catalog`; config does not import the
stages). This module adds the keys every case has and the rules across them, so that a case
that ``check`` passes does not fail later for a reason known before it runs:

* references (checked on the raw case, so they are reported together with every other
  problem): each ``material``, ``*_material`` and ``materials`` list names a material of
  the case; each stage's input holds what its type ``requires``, written by an earlier
  stage (``StageCatalog.input_scenes``), and the first stage needs no input;
* on the valid part of the case, in the same pass (its top-level keys and its stages up to
  the first invalid one, each validated on its own): what a stage's config reads besides
  (``config_requires``), and each stage type's ``case_check`` (dimension, the classes of the
  gradation, memory).
"""

from collections.abc import Mapping
from dataclasses import dataclass
from functools import lru_cache, partial

from demcli.config.load import load_case as _load_case
from demcli.config.schema import (NOVALUE, Float, Int, List, Map, Node, Optional, Section, Str, Tagged,
                                  did_you_mean, split_subpath, validate_quietly)

MATERIAL = Section({
    "density": Float("kg/m^3", min=0, min_inclusive=False, doc="particle density"),
    "young": Float("Pa", min=0, min_inclusive=False, default=1e9, doc="Young's modulus (Hertz-Mindlin)"),
    "poisson": Float(min=-1, max=0.5, max_inclusive=False, default=0.3, doc="Poisson's ratio"),
    "friction": Float(min=0, default=0.5, doc="sliding friction coefficient"),
    "rolling_friction": Float(min=0, default=0.0, doc="rolling friction coefficient"),
    "restitution": Float(min=0, max=1, min_inclusive=False, default=0.5,
                         doc="normal coefficient of restitution"),
    "shear": Optional(Float("Pa", min=0, min_inclusive=False),
                      doc="shear modulus G of Hertz-Mindlin's tangential stiffness 8 G* sqrt(R* delta) and of "
                          "the Rayleigh time step (default E / (2 (1 + nu)))"),
}, doc="a material, referenced by name from stages and walls")

NAME = r"^[A-Za-z][A-Za-z0-9_\-]*$"

SEED_MAX = 2 ** 63 - 1
"""Largest seed: states store seeds as 64-bit signed integers."""


def seed_field(doc, default=0):
    """An Int field for a random seed: 0 to :data:`SEED_MAX`."""
    return Int(min=0, max=SEED_MAX, default=default, doc=doc)


def _is_material_key(key):
    return isinstance(key, str) and (key == "material" or key.endswith("_material"))


def _material_refs(stages, names, report):
    """Every ``material``/``*_material`` string and ``materials`` list of strings in the raw
    stages must name a material of the case."""
    def check(name, path):
        if isinstance(name, str) and name not in names:
            hint = did_you_mean(name, names) or f"materials: {', '.join(map(str, names)) or 'none'}"
            report(path, f"unknown material {name!r}", hint=hint)

    def walk(value, path):
        if isinstance(value, Mapping):
            for key, item in value.items():
                if _is_material_key(key):
                    check(item, path + (key,))
                elif key == "materials" and isinstance(item, list):
                    for i, name in enumerate(item):
                        check(name, path + (key, i))
                else:
                    walk(item, path + (key,))
        elif isinstance(value, list):
            for i, item in enumerate(value):
                walk(item, path + (i,))

    walk(stages, ("stages",))


@dataclass(frozen=True, eq=False)
class StageCatalog:
    """What the case schema needs of the stage registry. The stages build it
    (:func:`demcli.stages.base.stage_catalog`) and pass it in, so that config does not import them.

    Attributes:
        types: stage type name -> StageType (its ``fields``, ``doc``, ``check``, ``needs_input``,
            ``requires``, ``config_requires`` and ``case_check`` are read here).
        input_scenes: ``input_scenes(stages) -> [frozenset | None]``: the state fields the input
            of each stage holds (validated Nodes or raw mappings).
        has_field: ``has_field(scene, path)``: whether a scene holds field ``path``.
        type_of: ``type_of(cfg)``: the StageType of a raw stage config, None when unknown.
        writers_of: ``writers_of(path)``: names of the stage types that write field ``path``.
    """

    types: Mapping
    input_scenes: object
    has_field: object
    type_of: object
    writers_of: object


def _stage_inputs(stages, report, catalog):
    """Each raw stage's input must hold what its type requires: the first stage takes none."""
    for k, (cfg, scene) in enumerate(zip(stages, catalog.input_scenes(stages))):
        st = catalog.type_of(cfg)
        if st is None or not st.reads_input(cfg):
            continue
        if k == 0:
            starts = ", ".join(n for n, t in sorted(catalog.types.items()) if not t.needs_input)
            report(("stages", 0, "type"), f"stage type {st.name} reads the state of an earlier stage, but this is "
                   "the first stage", hint=f"start with a stage that makes a scene ({starts})")
            continue
        missing = [p for p in st.requires if scene is not None and not catalog.has_field(scene, p)]
        if missing:
            before = stages[k - 1]
            report(("stages", k, "type"), f"stage type {st.name} needs {', '.join(missing)} in its input, which no "
                   f"earlier stage writes (the input is the output of stage {before.get('name')!r}, type "
                   f"{before.get('type')})",
                   hint=_writers_hint(missing, catalog))


def _writers_hint(missing, catalog):
    """Which stage types write the fields ``missing``."""
    return "stage types that write it: " + ", ".join(sorted({w for p in missing for w in catalog.writers_of(p)}))


def _cross_refs(case, report, catalog):
    """Checks of the raw case that run whatever the validity of its fields (one pass)."""
    stages = case.get("stages")
    if not isinstance(stages, list):
        return
    materials = case.get("materials")
    names = list(materials) if isinstance(materials, Mapping) else []
    _material_refs(stages, names, report)
    _stage_inputs(stages, report, catalog)
    valid = _valid_part(case, stages, catalog)
    if valid is not None:
        _case_rules(valid, report, catalog)


def _valid_part(case, stages, catalog):
    """The case with its top-level keys and its stages up to the first invalid one, each
    validated on its own (so that the case rules of those stages come in the same pass as the
    other problems), or None when a top-level key is invalid."""
    schema = case_schema(catalog)
    top = {}
    for key, field in schema.fields.items():
        if key != "stages":
            top[key] = validate_quietly(field, case[key], (key,)) if key in case else field.default_value((key,))
            if top[key] is None and key in case:
                return None
    valid = []
    for k, raw in enumerate(stages):
        node = validate_quietly(schema.fields["stages"].item, raw, ("stages", k))
        if node is None:
            break
        valid.append(node)
    return Node({**top, "stages": tuple(valid)})


def _stage_reporter(report, k):
    def stage_report(subpath, rule, value=NOVALUE, hint=None):
        report(("stages", k) + split_subpath(subpath), rule, value, hint)
    return stage_report


def _case_rules(case, report, catalog):
    """Rules of the valid part of a case (:func:`_valid_part`): inputs a stage's config reads,
    and each type's case check."""
    for k, (cfg, scene) in enumerate(zip(case.stages, catalog.input_scenes(case.stages))):
        st = catalog.types[cfg.type]
        sub = _stage_reporter(report, k)
        reads = st.config_requires(cfg) if st.config_requires is not None and scene is not None else {}
        for key, paths in reads.items():
            missing = [p for p in paths if not catalog.has_field(scene, p)]
            if missing:
                sub(key, f"reads {', '.join(missing)} from the input, which no earlier stage writes",
                    hint=_writers_hint(missing, catalog))
        if st.case_check is not None:
            st.case_check(cfg, case, k, scene, sub)


@lru_cache(maxsize=4)
def case_schema(catalog):
    """The full case schema of the stage types of ``catalog`` (a :class:`StageCatalog`; built once
    per catalog)."""
    variants = {}
    for name, st in sorted(catalog.types.items()):  # by name: independent of import order
        fields = {"name": Str(pattern=NAME, doc="stage name (unique; names the output files)")}
        fields.update(st.fields)
        variants[name] = Section(fields, doc=st.doc, check=st.check)
    return Section({
        "name": Str(pattern=NAME, default=None, doc="case name (default: the file name)"),
        "seed": seed_field("random seed of the whole case (0 to 2^63 - 1)"),
        "dimension": Int(min=2, max=3, default=3, doc="3, or 2 for planar motion (disks)"),
        "thickness": Float("m", min=0, min_inclusive=False, default=1.0,
                           doc="2D only: out-of-plane thickness for disk masses"),
        "materials": Map(MATERIAL, key_pattern=NAME, default={}, doc="materials by name"),
        "stages": List(Tagged("type", variants), min_len=1, unique_by="name", doc="stages, run in order"),
    }, check_raw=partial(_cross_refs, catalog=catalog))


def load_case(path, catalog, overrides=()):
    """Validated case (a read-only Node, SI values) or ConfigError listing every problem, with the
    stage types of ``catalog`` (:func:`demcli.stages.base.load_case` passes the built-in ones)."""
    return _load_case(path, case_schema(catalog), overrides)
