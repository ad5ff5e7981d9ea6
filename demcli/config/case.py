"""The case file schema: top-level keys, materials, and the list of stages.

Stage sections come from the stage registry (:mod:`demcli.stages.base`); this module
adds the keys every case has and the cross-references between them (a stage naming a
material that does not exist is an error at validation, before anything runs).
"""

from functools import lru_cache

from demcli.config.load import load_case as _load_case
from demcli.config.schema import Float, Int, List, Map, Section, Str, Tagged

MATERIAL = Section({
    "density": Float("kg/m^3", min=0, min_inclusive=False, doc="particle density"),
    "young": Float("Pa", min=0, min_inclusive=False, default=1e9, doc="Young's modulus (Hertz-Mindlin)"),
    "poisson": Float(min=-1, max=0.5, max_inclusive=False, default=0.3, doc="Poisson's ratio"),
    "friction": Float(min=0, default=0.5, doc="sliding friction coefficient"),
    "rolling_friction": Float(min=0, default=0.0, doc="rolling friction coefficient"),
    "restitution": Float(min=0, max=1, min_inclusive=False, default=0.5,
                         doc="normal coefficient of restitution"),
}, doc="a material, referenced by name from stages and walls")

NAME = r"^[A-Za-z][A-Za-z0-9_\-]*$"


def _material_refs(node, report):
    """Every ``material`` key anywhere in a stage must name a defined material."""
    names = set(node.materials)

    def walk(value, path):
        if hasattr(value, "keys"):
            for k in value.keys():
                v = value[k]
                if k == "material" and isinstance(v, str) and v not in names:
                    from difflib import get_close_matches

                    close = get_close_matches(v, sorted(names), n=1)
                    report(path + (k,), "unknown material", v, hint=close[0] if close else None)
                else:
                    walk(v, path + (k,))
        elif isinstance(value, tuple):
            for i, v in enumerate(value):
                walk(v, path + (i,))

    for i, st in enumerate(node.stages):
        walk(st, ("stages", i))


@lru_cache(maxsize=1)
def case_schema():
    """The full case schema (built once from the registered stage types)."""
    from demcli.stages.base import load_stage_types

    variants = {}
    for name, st in sorted(load_stage_types().items()):  # by name: independent of import order
        fields = {"name": Str(pattern=NAME, doc="stage name (unique; names the output files)")}
        fields.update(st.fields)
        variants[name] = Section(fields, doc=st.doc, check=st.check)
    return Section({
        "name": Str(pattern=NAME, default=None, doc="case name (default: the file name)"),
        "seed": Int(min=0, default=0, doc="random seed of the whole case"),
        "dimension": Int(min=2, max=3, default=3, doc="3, or 2 for planar motion (disks)"),
        "thickness": Float("m", min=0, min_inclusive=False, default=1.0,
                           doc="2D only: out-of-plane thickness for disk masses"),
        "materials": Map(MATERIAL, key_pattern=NAME, default={}, doc="materials by name"),
        "stages": List(Tagged("type", variants), min_len=1, unique_by="name", doc="stages, run in order"),
    }, check=_material_refs)


def load_case(path, overrides=()):
    """Validated case (a read-only Node, SI values) or ConfigError listing every problem."""
    return _load_case(path, case_schema(), overrides)
