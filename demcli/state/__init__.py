"""State I/O: the field registry, HDF5 state files, VTU/PVD snapshots, record tables.

A State is ``meta`` (scalars) + ``groups`` (``{"bodies": {"x": array, ...}, ...}``) +
``group_attrs``. Stages pass States to each other through HDF5 files written by
:func:`write_state` and read back by :func:`read_state`, validated: the field registry's
dtypes, shapes and value rules (:mod:`demcli.state.rules`) and the checksums of datasets and
attributes. See docs/state.md.

VTU export lives in :mod:`demcli.state.vtu` (imports meshio; not imported here).
"""

from demcli.state.atomic import atomic_path, atomic_write_bytes, atomic_write_text
from demcli.state.fields import (
    FIELDS,
    GROUPS,
    SCHEMA_VERSION,
    Field,
    Group,
    State,
    check,
    fields_of,
    get_rng,
    new_state,
    quat_rotate,
    register,
    register_group,
    require,
    schema_markdown,
    set_rng,
    state_differences,
    validate,
)
from demcli.state.h5 import read_meta, read_state, state_hash, summarize, write_state
from demcli.state.records import RecordTable

__all__ = [
    "FIELDS", "GROUPS", "SCHEMA_VERSION", "Field", "Group", "RecordTable", "State",
    "atomic_path", "atomic_write_bytes", "atomic_write_text", "check", "fields_of", "get_rng",
    "new_state", "quat_rotate", "read_meta", "read_state", "register", "register_group",
    "require", "schema_markdown", "set_rng", "state_differences", "state_hash", "summarize",
    "validate", "write_state",
]
