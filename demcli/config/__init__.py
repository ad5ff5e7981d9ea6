"""Case-file configuration: the schema language, YAML loading and validation.

Importing this package loads PyYAML but neither pint nor numba: pint is imported
on the first value written with a unit (see :mod:`demcli.units`).
"""

from demcli.config.load import apply_overrides, load_case, load_yaml, validate
from demcli.config.schema import (
    NOVALUE,
    REQUIRED,
    Bool,
    ConfigIssue,
    DocRow,
    Field,
    Float,
    Int,
    List,
    Map,
    Node,
    Optional,
    SchemaError,
    Section,
    Str,
    Tagged,
    Vector,
    canonical_json,
    format_path,
    sha256_of,
    validate_tree,
)

__all__ = [
    "NOVALUE",
    "REQUIRED",
    "Bool",
    "ConfigIssue",
    "DocRow",
    "Field",
    "Float",
    "Int",
    "List",
    "Map",
    "Node",
    "Optional",
    "SchemaError",
    "Section",
    "Str",
    "Tagged",
    "Vector",
    "apply_overrides",
    "canonical_json",
    "format_path",
    "load_case",
    "load_yaml",
    "sha256_of",
    "validate",
    "validate_tree",
]
