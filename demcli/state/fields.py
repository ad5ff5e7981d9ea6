"""The field registry: every dataset and attribute a demcli state file may hold.

A field is declared once (path, dtype kind, symbolic dims, unit, doc, who writes it)
and checked whenever a state is read or written, like sgkit's ``ArrayLikeSpec``.
Core fields are registered here; a stage or effect that stores more (``gradation/``,
``library/``, ``bonds/``) calls :func:`register_group` and :func:`register` at import.

Paths are ``<group>/<name>``. The group is everything before the last ``/`` so groups
may nest (``records/energy``). Fields with ``attr=True`` are HDF5 attributes of their
group (``meta/*`` are the attributes of ``/meta``; ``rng/state`` of ``/rng``).
"""

from __future__ import annotations

import copy as _copy
import difflib
import json
from dataclasses import dataclass, field as _dc_field

import numpy as np

from demcli.errors import StateError
from demcli.state import rules as _rules

SCHEMA_VERSION = 1
"""Current schema version; bump on any incompatible change (see docs/state.md)."""

KINDS = {
    "f": "float",
    "i": "signed integer",
    "u": "unsigned integer",
    "b": "bool",
    "str": "utf-8 string",
}
_KIND_ALIASES = {"S": "str", "U": "str", "O": "str"}
_DEFAULT_DTYPE = {"f": "float64", "i": "int64", "u": "uint64", "b": "bool", "str": None}

MAX_PROBLEMS_SHOWN = 6


@dataclass(frozen=True)
class Field:
    """One dataset (or attribute) of a state file.

    path: ``group/name``; kind: 'f', 'i', 'u', 'b' or 'str' ('S' is an alias);
    dims: symbolic sizes such as ``("n_b", 3)`` (``()`` is a scalar: 0-d or 1 element);
    unit: SI unit ('1' dimensionless, '' none); writer: who writes it, shown when it is
    missing ("engine", "stage compaction", "effect rolling_resistance").
    required: must exist whenever its group exists; when_effect: additionally required
    when that effect is listed in ``meta['effects']``; index_of: a dim symbol whose range
    the integer values must lie in (``spheres/body`` indexes ``n_b``); dtype: the dtype
    stored on disk (default float64 / int64 / uint64 / bool / vlen utf-8); attr: stored
    as an HDF5 attribute of the group instead of a dataset.

    Value rules, checked when a state is read (:mod:`demcli.state.rules`): finite: no NaN
    or infinity; positive: every value > 0; unit_rows: each row a unit vector; unique: no
    value twice.
    """

    path: str
    kind: str
    dims: tuple = ()
    unit: str = ""
    doc: str = ""
    required: bool = True
    writer: str = "engine"
    when_effect: str | None = None
    index_of: str | None = None
    dtype: str | None = None
    attr: bool = False
    finite: bool = False
    positive: bool = False
    unit_rows: bool = False
    unique: bool = False

    def __post_init__(self):
        kind = _KIND_ALIASES.get(self.kind, self.kind)
        if kind not in KINDS:
            raise ValueError(f"field {self.path!r}: unknown kind {self.kind!r} (use one of {sorted(KINDS)})")
        object.__setattr__(self, "kind", kind)
        object.__setattr__(self, "dims", tuple(self.dims))
        if "/" not in self.path or self.path.startswith("/") or self.path.endswith("/"):
            raise ValueError(f"field path {self.path!r} must look like 'group/name'")
        if self.dtype is None:
            object.__setattr__(self, "dtype", _DEFAULT_DTYPE[kind])
        if self.attr and len(self.dims) > 1:
            raise ValueError(f"attribute field {self.path!r} must be a scalar or a 1-D list")

    @property
    def group(self) -> str:
        return self.path.rsplit("/", 1)[0]

    @property
    def name(self) -> str:
        return self.path.rsplit("/", 1)[1]

    @property
    def dims_text(self) -> str:
        if not self.dims:
            return "scalar"
        return "(" + ", ".join(str(d) for d in self.dims) + ")"

    @property
    def rules_text(self) -> str:
        """The value rules in words, for docs/state.md (e.g. 'finite, > 0')."""
        rules = [name for name, on in (("finite", self.finite), ("> 0", self.positive),
                                       ("unit rows", self.unit_rows), ("unique", self.unique)) if on]
        if self.index_of:
            rules.append(f"< {self.index_of}")
        return ", ".join(rules)

    def describe(self) -> str:
        """Short text used in error messages: unit, doc and writer."""
        unit = f"{self.unit}, " if self.unit not in ("", "1") else ""
        cond = f" when effect {self.when_effect} is active" if self.when_effect else ""
        return f"{unit}{self.doc}; written by {self.writer}{cond}"


@dataclass(frozen=True)
class Group:
    """A group of fields. ``tables=True``: subgroups ``<name>/<table>`` are free-form
    record tables (1-D float/int columns of one length, units in attrs)."""

    name: str
    doc: str
    required: bool = False
    writer: str = "engine"
    tables: bool = False


FIELDS: dict[str, Field] = {}
GROUPS: dict[str, Group] = {}


def register_group(name, doc, *, required=False, writer="engine", tables=False) -> Group:
    """Declare a group. Re-registering an identical group is a no-op; a different one is an error."""
    grp = Group(name, doc, required, writer, tables)
    old = GROUPS.get(name)
    if old is not None and old != grp:
        raise ValueError(f"group {name!r} is already registered differently: {old}")
    GROUPS[name] = grp
    return grp


def register(fld: Field) -> Field:
    """Declare a field; its group must be registered first. Identical re-registration is a no-op."""
    if fld.group not in GROUPS:
        raise ValueError(f"field {fld.path!r}: register its group {fld.group!r} first (register_group)")
    old = FIELDS.get(fld.path)
    if old is not None and old != fld:
        raise ValueError(f"field {fld.path!r} is already registered differently: {old}")
    FIELDS[fld.path] = fld
    return fld


def fields_of(group: str) -> dict[str, Field]:
    """Registered fields of one group, name -> Field, in registration order."""
    return {f.name: f for f in FIELDS.values() if f.group == group}


# ---------------------------------------------------------------------------------------
# Core schema
# ---------------------------------------------------------------------------------------

def _reg(group, name, kind, dims, unit, doc, **kw):
    register(Field(f"{group}/{name}", kind, dims, unit, doc, **kw))


register_group("meta", "Scalar attributes of the state: provenance, time and hashes", required=True,
               writer="the stage runner")
_M = dict(attr=True, writer="the stage runner")
_reg("meta", "schema_version", "i", (), "", "state file schema version (current 1)", **_M)
_reg("meta", "demcli_version", "str", (), "", "demcli version that wrote the file", **_M)
_reg("meta", "stage", "str", (), "", "name of the stage that wrote the file", **_M)
_reg("meta", "stage_type", "str", (), "", "stage type (gradation, shapes, compaction, cyclic, ...)", **_M)
_reg("meta", "case_file", "str", (), "", "case file the run was started from", **_M)
_reg("meta", "case_hash", "str", (), "", "sha256 of the validated case", **_M)
_reg("meta", "config_hash", "str", (), "", "sha256 of this stage's config", **_M)
_reg("meta", "input_hash", "str", (), "", "state_hash of the input state ('' for none)", **_M)
_reg("meta", "seed", "i", (), "", "random seed of the stage", **_M)
_reg("meta", "effects", "str", ("n_effects",), "", "active effects of the stage", **_M)
_reg("meta", "dim", "i", (), "", "2 (planar motion) or 3", **_M)
_reg("meta", "time", "f", (), "s", "simulated time", **_M)
_reg("meta", "step", "i", (), "", "time step count", **_M)
_reg("meta", "dt", "f", (), "s", "time step", **_M)
_reg("meta", "created_by", "str", (), "", "program that wrote the file, e.g. 'demcli 0.1.0'", **_M)
_reg("meta", "machine", "str", (), "", "CPU model, the CPU numba compiled for, OS and numerical library versions "
     "(what decides round-off besides the case; provenance, not in state_hash)", required=False, **_M)

register_group("bodies", "Rigid bodies (clumps); a single sphere is a body with one sphere",
               required=True)
_reg("bodies", "x", "f", ("n_b", 3), "m", "centre of mass, world frame", finite=True)
_reg("bodies", "v", "f", ("n_b", 3), "m/s", "velocity of the centre of mass", finite=True)
_reg("bodies", "q", "f", ("n_b", 4), "1", "unit quaternion (w, x, y, z), body to world", finite=True, unit_rows=True)
_reg("bodies", "omega", "f", ("n_b", 3), "rad/s", "angular velocity, world frame", finite=True)
_reg("bodies", "mass", "f", ("n_b",), "kg", "mass", finite=True, positive=True)
_reg("bodies", "inertia", "f", ("n_b", 3), "kg m^2", "principal moments of inertia, body frame", finite=True,
     positive=True)
_reg("bodies", "id", "i", ("n_b",), "", "stable body id (survives deletion and reordering)", unique=True)
_reg("bodies", "flags", "i", ("n_b",), "", "bit 0: fixed translation, bit 1: fixed rotation",
     dtype="int8")
_reg("bodies", "force", "f", ("n_b", 3), "N", "total force at the last step (first half kick of the next)",
     required=False, finite=True)
_reg("bodies", "torque", "f", ("n_b", 3), "N m", "total torque at the last step", required=False, finite=True)
_reg("bodies", "set", "i", ("n_b",), "", "particle set of the generate stage's sets: list (0, 1, ...; -1: none)",
     required=False, writer="stage generate")
_reg("bodies", "angmom", "f", ("n_b", 3), "kg m^2/s", "angular momentum, world frame (clumps)",
     required=False, writer="effect clumps", finite=True)

register_group("spheres", "Spheres, each rigidly attached to a body", required=True)
_reg("spheres", "body", "i", ("n_s",), "", "index into bodies", index_of="n_b")
_reg("spheres", "offset", "f", ("n_s", 3), "m", "centre relative to the body centre, body frame", finite=True)
_reg("spheres", "radius", "f", ("n_s",), "m", "radius", finite=True, positive=True)
_reg("spheres", "material", "i", ("n_s",), "", "index into materials", index_of="n_m")

register_group("materials", "Contact materials", required=True)
_reg("materials", "name", "str", ("n_m",), "", "material name")
_reg("materials", "density", "f", ("n_m",), "kg/m^3", "density", finite=True, positive=True)
_reg("materials", "young", "f", ("n_m",), "Pa", "Young's modulus", finite=True, positive=True)
_reg("materials", "poisson", "f", ("n_m",), "1", "Poisson's ratio", finite=True)
_reg("materials", "friction", "f", ("n_m",), "1", "sliding friction coefficient", finite=True)
_reg("materials", "rolling_friction", "f", ("n_m",), "1", "rolling friction coefficient", finite=True)
_reg("materials", "restitution", "f", ("n_m",), "1", "coefficient of restitution", finite=True)
_reg("materials", "shear", "f", ("n_m",), "Pa", "shear modulus G of the tangential stiffness: the case's, else "
     "E / (2 (1 + nu))", required=False, finite=True, positive=True)

register_group("walls", "Rigid walls: planes, cylinders and triangle meshes (a mesh's triangles are read from "
               "its case file, docs/walls.md)", writer="effect walls")
_W = dict(writer="effect walls")
_reg("walls", "name", "str", ("n_w",), "", "wall name from the case", **_W)
_reg("walls", "kind", "i", ("n_w",), "", "0 plane, 1 cylinder, 2 mesh", dtype="int8", **_W)
_reg("walls", "point", "f", ("n_w", 3), "m", "a point on the plane; a point on the cylinder axis; a mesh's first "
     "vertex (the mesh translates with it)", **_W, finite=True)
_reg("walls", "normal", "f", ("n_w", 3), "1", "plane normal into the domain; cylinder axis; a mesh's direction of servo "
     "and force motion", **_W, finite=True,
     unit_rows=True)
_reg("walls", "radius", "f", ("n_w",), "m", "cylinder radius (unused for planes)", **_W, finite=True)
_reg("walls", "v", "f", ("n_w", 3), "m/s", "wall velocity", **_W, finite=True)
_reg("walls", "material", "i", ("n_w",), "", "index into materials", index_of="n_m", **_W)
_reg("walls", "control", "i", ("n_w",), "", "0 fixed, 1 velocity, 2 force, 3 servo", dtype="int8", **_W)
_reg("walls", "target", "f", ("n_w",), "N or Pa", "control target (force or stress)", **_W, finite=True)
_reg("walls", "force", "f", ("n_w", 3), "N", "contact force on the wall at the last step", **_W, finite=True)
_reg("walls", "extent", "f", ("n_w", 6), "m", "drawing bounds xmin ymin zmin xmax ymax zmax", **_W)

register_group("contacts", "Persistent sphere-sphere contacts with their history")
_reg("contacts", "i", "i", ("n_c",), "", "first sphere (i < j)", index_of="n_s")
_reg("contacts", "j", "i", ("n_c",), "", "second sphere", index_of="n_s")
_reg("contacts", "ft", "f", ("n_c", 3), "N", "tangential spring force (history)", required=False,
     writer="effect friction", when_effect="friction", finite=True)
_reg("contacts", "mr", "f", ("n_c", 3), "N m", "rolling-resistance moment (history)", required=False,
     writer="effect rolling_resistance", when_effect="rolling_resistance", finite=True)
_reg("contacts", "force", "f", ("n_c", 3), "N", "last contact force on sphere i", finite=True)

register_group("wall_contacts", "Persistent sphere-wall contacts with their history", writer="effect walls")
_reg("wall_contacts", "sphere", "i", ("n_wc",), "", "sphere index", index_of="n_s", **_W)
_reg("wall_contacts", "wall", "i", ("n_wc",), "", "wall index", index_of="n_w", **_W)
_reg("wall_contacts", "ft", "f", ("n_wc", 3), "N", "tangential spring force (history)", required=False,
     writer="effect friction", when_effect="friction", finite=True)
_reg("wall_contacts", "mr", "f", ("n_wc", 3), "N m", "rolling-resistance moment (history)", required=False,
     writer="effect rolling_resistance", when_effect="rolling_resistance", finite=True)
_reg("wall_contacts", "force", "f", ("n_wc", 3), "N", "last contact force on the sphere", **_W, finite=True)

register_group("energy", "Energy balance at the last step (scalars)")
for _name, _doc in [("kinetic", "kinetic energy (translation + rotation)"),
                    ("strain", "elastic energy stored in contacts"),
                    ("gravity", "gravitational potential energy -sum m g.x"),
                    ("damping", "energy dissipated by contact dashpots"),
                    ("friction", "energy dissipated by sliding and rolling slip"),
                    ("body_damping", "energy dissipated by local and viscous damping"),
                    ("wall_work", "work done by moving walls on the particles")]:
    _reg("energy", _name, "f", (), "J", _doc, required=False)

register_group("records", "Record tables: records/<table>/<column>, 1-D columns, units in attrs",
               tables=True)

register_group("rng", "State of the numpy random generator, to resume a stage exactly")
_reg("rng", "state", "str", (), "", "JSON of numpy Generator.bit_generator.state", attr=True)


CORE_GROUPS = tuple(GROUPS)
"""Groups registered by this module (the rest come from stages and effects)."""


# ---------------------------------------------------------------------------------------
# State
# ---------------------------------------------------------------------------------------

@dataclass(eq=False)
class State:
    """What a stage reads and writes: meta scalars, groups of arrays, group attributes.

    ``state["bodies/x"]`` reads a dataset, ``state["bodies/x"] = a`` sets one,
    ``"contacts/mr" in state`` tests for one. ``==`` compares everything (exact dtypes and
    values), treating an empty group like an absent one.
    """

    meta: dict = _dc_field(default_factory=dict)
    groups: dict = _dc_field(default_factory=dict)
    group_attrs: dict = _dc_field(default_factory=dict)

    def __getitem__(self, path):
        group, name = _split(path)
        return self.groups[group][name]

    def __setitem__(self, path, value):
        group, name = _split(path)
        self.groups.setdefault(group, {})[name] = np.asarray(value)

    def __contains__(self, path):
        group, name = _split(path)
        return name in self.groups.get(group, {})

    def get(self, path, default=None):
        return self[path] if path in self else default

    def has_group(self, group) -> bool:
        return group in self.groups or group in self.group_attrs

    def copy(self) -> "State":
        return _copy.deepcopy(self)

    def counts(self) -> dict[str, int]:
        """Sizes of the symbolic dims present, e.g. ``{'n_b': 10, 'n_s': 40, ...}``."""
        out = {}
        for fld in FIELDS.values():
            if fld.attr or fld.path not in self:
                continue
            shape = np.shape(self[fld.path])
            for sym, size in zip(fld.dims, shape):
                if isinstance(sym, str):
                    out.setdefault(sym, int(size))
        return out

    def sphere_centres(self) -> np.ndarray:
        """World positions of the sphere centres, (n_s, 3) m: x_body + R(q_body) offset."""
        body = np.asarray(self["spheres/body"])
        return np.asarray(self["bodies/x"])[body] + quat_rotate(
            np.asarray(self["bodies/q"])[body], np.asarray(self["spheres/offset"]))

    def sphere_velocities(self) -> np.ndarray:
        """Velocities of the sphere centres, (n_s, 3) m/s: v_body + omega x (R(q) offset)."""
        body = np.asarray(self["spheres/body"])
        arm = quat_rotate(np.asarray(self["bodies/q"])[body], np.asarray(self["spheres/offset"]))
        return np.asarray(self["bodies/v"])[body] + np.cross(np.asarray(self["bodies/omega"])[body], arm)

    def __eq__(self, other):
        if not isinstance(other, State):
            return NotImplemented
        return not state_differences(self, other)


def _split(path):
    if "/" not in path:
        raise KeyError(f"{path!r}: expected 'group/name'")
    return tuple(path.rsplit("/", 1))


def quat_rotate(q, v):
    """Rotate vectors v (n,3) by unit quaternions q (n,4) given as (w, x, y, z)."""
    q = np.asarray(q, dtype=float)
    v = np.asarray(v, dtype=float)
    w = q[..., :1]
    u = q[..., 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def state_differences(a: State, b: State) -> list[str]:
    """Human-readable differences between two states (empty list: equal)."""
    diffs = []
    if set(a.meta) != set(b.meta):
        diffs.append(f"meta keys differ: {sorted(set(a.meta) ^ set(b.meta))}")
    for k in sorted(set(a.meta) & set(b.meta)):
        va, vb = a.meta[k], b.meta[k]
        if isinstance(va, (list, tuple, np.ndarray)) or isinstance(vb, (list, tuple, np.ndarray)):
            same = list(np.asarray(va).tolist()) == list(np.asarray(vb).tolist())
        else:
            same = va == vb and type(va) is type(vb)
        if not same:
            diffs.append(f"meta {k!r}: {va!r} != {vb!r}")
    ga = {g for g, d in a.groups.items() if d}
    gb = {g for g, d in b.groups.items() if d}
    if ga != gb:
        diffs.append(f"groups differ: {sorted(ga ^ gb)}")
    for g in sorted(ga & gb):
        da, db = a.groups[g], b.groups[g]
        if set(da) != set(db):
            diffs.append(f"group {g!r} datasets differ: {sorted(set(da) ^ set(db))}")
            continue
        for name in sorted(da):
            x, y = np.asarray(da[name]), np.asarray(db[name])
            if x.dtype.kind in "OUS" or y.dtype.kind in "OUS":
                same = x.shape == y.shape and [str(s) for s in x.ravel()] == [str(s) for s in y.ravel()]
            else:
                same = x.dtype == y.dtype and x.shape == y.shape and np.array_equal(x, y, equal_nan=x.dtype.kind == "f")
            if not same:
                diffs.append(f"{g}/{name}: {x.dtype}{x.shape} differs from {y.dtype}{y.shape}")
    aa = {g: d for g, d in a.group_attrs.items() if d}
    ab = {g: d for g, d in b.group_attrs.items() if d}
    if _jsonable(aa) != _jsonable(ab):
        diffs.append("group attributes differ")
    return diffs


def _jsonable(obj):
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in sorted(obj.items())}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return [_jsonable(v) for v in obj.tolist()]
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, bytes):
        return obj.decode("utf-8")
    return obj


def new_state(stage, stage_type, *, dim=3, seed=0, case_file="", case_hash="", config_hash="",
              input_hash="", effects=(), time=0.0, step=0, dt=0.0, **extra_meta) -> State:
    """A State with complete meta (versions and schema filled in) and no groups yet."""
    from demcli import __version__
    from demcli.machine import machine

    meta = dict(schema_version=SCHEMA_VERSION, demcli_version=__version__, stage=str(stage),
                stage_type=str(stage_type), case_file=str(case_file), case_hash=str(case_hash),
                config_hash=str(config_hash), input_hash=str(input_hash), seed=int(seed),
                effects=[str(e) for e in effects], dim=int(dim), time=float(time), step=int(step),
                dt=float(dt), created_by=f"demcli {__version__}", machine=machine())
    meta.update(extra_meta)
    return State(meta=meta)


def set_rng(state: State, generator: np.random.Generator) -> None:
    """Store a numpy Generator's bit-generator state in ``rng/state`` (JSON)."""
    state.group_attrs.setdefault("rng", {})["state"] = json.dumps(
        generator.bit_generator.state, sort_keys=True)


def get_rng(state: State) -> np.random.Generator:
    """Rebuild the numpy Generator stored by :func:`set_rng`, continuing its stream exactly."""
    try:
        saved = json.loads(state.group_attrs["rng"]["state"])
    except KeyError:
        raise StateError("state has no rng/state (written by the stage runner)") from None
    bit_gen = getattr(np.random, saved["bit_generator"])()
    bit_gen.state = saved
    return np.random.Generator(bit_gen)


# ---------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------

def _kind_ok(arr: np.ndarray, kind: str) -> bool:
    k = arr.dtype.kind
    if kind == "str":
        if k in "US":
            return True
        return k == "O" and all(isinstance(s, (str, bytes)) for s in arr.ravel())
    return k == kind


def _meta_problem(fld: Field, value):
    """Type check for an attribute field; returns a problem text or None."""
    want = KINDS[fld.kind]
    if fld.dims:  # a 1-D list attribute
        if isinstance(value, str) or not isinstance(value, (list, tuple, np.ndarray)):
            return f"{fld.path} must be a list of {want}s (got {type(value).__name__})"
        items = list(value)
    else:
        items = [value]
    for item in items:
        if fld.kind == "str":
            ok = isinstance(item, str)
        elif fld.kind in ("i", "u"):
            ok = isinstance(item, (int, np.integer)) and not isinstance(item, (bool, np.bool_))
            ok = ok and (fld.kind == "i" or item >= 0)
        elif fld.kind == "f":
            ok = isinstance(item, (float, int, np.floating, np.integer)) and not isinstance(item, (bool, np.bool_))
        else:
            ok = isinstance(item, (bool, np.bool_))
        if not ok:
            return f"{fld.path} must be {'a list of ' + want + 's' if fld.dims else 'a ' + want} (got {item!r})"
    return None


def _shape_rows_problems(sizes):
    """The polyhedral bodies (``n_pb``, the last of the bodies) are at most all bodies, and all
    of them when the state has no spheres (every body has a shape)."""
    n_p, where = sizes.get("n_pb", (None, ""))
    if n_p is None:
        return []
    n_b, n_s = sizes.get("n_b", (0, ""))[0], sizes.get("n_s", (0, ""))[0]
    if n_p > n_b:
        return [f"{where!r} has {n_p} polyhedra but the state has {n_b} bodies"]
    if n_s == 0 and n_p < n_b:
        return [f"{where!r} has {n_p} polyhedra for {n_b} bodies and there are no spheres: "
                f"{n_b - n_p} bodies have no shape"]
    return []


def check(state: State, *, values: bool = True, stored: bool = False) -> list[str]:
    """All problems of a state against the registry (empty list: valid).

    Checks meta, required groups and fields, unknown groups and datasets, dtype kinds,
    ranks and sizes (one size per dim symbol), index ranges and, with ``values``, the value
    rules of the fields (finite, > 0, unit rows, unique: :mod:`demcli.state.rules`).
    ``stored``: the state was read from a file, so each dataset must have its registered
    dtype exactly (a state in memory may hold int32 for int64: write_state converts it).
    """
    if not isinstance(state, State):
        return [f"expected a State, got {type(state).__name__}"]
    problems = _check_meta(state) + _unknown_groups(state)
    effects = state.meta.get("effects") or []
    effects = set(effects) if isinstance(effects, (list, tuple, np.ndarray)) else set()
    sizes: dict[str, tuple[int, str]] = {}  # symbol -> (size, first field)
    shaped = []  # (field, array) of the right dtype and shape, for the value rules
    for gname, grp in GROUPS.items():
        if gname == "meta":
            continue
        if grp.tables:
            problems += _check_tables(state, gname)
        elif state.has_group(gname):
            problems += _check_group(state, gname, effects, stored, sizes, shaped)
        elif grp.required:
            problems.append(f"missing group {gname!r} ({grp.doc}; written by {grp.writer})")
    problems += _shape_rows_problems(sizes)
    for fld, arr in shaped:
        if fld.index_of and arr.size:  # a dim no field of the state has is of size 0
            n = sizes.get(fld.index_of, (0, ""))[0]
            problems.append(_rules.index_problem(fld.path, arr, fld.index_of, n))
        if values:
            problems += _rules.value_problems(fld, arr)
    return [p for p in problems if p]


def _check_meta(state: State) -> list[str]:
    """Problems of the meta attributes (types, required keys, schema version)."""
    problems = []
    if "meta" in state.groups:
        problems.append("'meta' is reserved for State.meta and cannot hold datasets")
    for fld in fields_of("meta").values():
        if fld.name not in state.meta:
            if fld.required:
                problems.append(f"missing meta {fld.name!r} ({fld.describe()})")
            continue
        problems.append(_meta_problem(fld, state.meta[fld.name]))
    version = state.meta.get("schema_version")
    if isinstance(version, (int, np.integer)) and version != SCHEMA_VERSION:
        problems.append(f"meta schema_version is {version}, this demcli writes and reads {SCHEMA_VERSION}")
    return [p for p in problems if p]


def _unregistered(state: State) -> list[str]:
    tables = [g + "/" for g, grp in GROUPS.items() if grp.tables]
    return sorted(g for g in set(state.groups) | set(state.group_attrs)
                  if g != "meta" and g not in GROUPS and not g.startswith(tuple(tables)))


def _hint(name, names) -> str:
    """'; did you mean X?' for the closest of ``names``, or ''."""
    close = difflib.get_close_matches(name, list(names), n=1)
    return f"; did you mean {close[0]!r}?" if close else ""


def _unknown_groups(state: State) -> list[str]:
    """Groups that no demcli module registers (every module is imported before one is
    called unknown: a stage's groups are known even where the stage was not imported)."""
    unknown = _unregistered(state)
    if unknown:
        register_all()
        unknown = _unregistered(state)
    problems = []
    for gname in unknown:
        problems.append(f"unknown group {gname!r} (no demcli stage or effect writes it){_hint(gname, GROUPS)}")
    return problems


def _check_group(state, gname, effects, stored, sizes, shaped) -> list[str]:
    """Problems of one registered group; its fields of the right dtype and shape go to ``shaped``."""
    problems = []
    known = fields_of(gname)
    data = state.groups.get(gname, {})
    attrs = state.group_attrs.get(gname, {})
    datasets = [n for n, f in known.items() if not f.attr]
    for name in data:
        if name not in datasets:
            problems.append(f"unknown dataset {name!r} in group {gname!r} "
                            f"(known: {', '.join(datasets) or 'none'}){_hint(name, datasets)}")
    for name, fld in known.items():
        have = attrs if fld.attr else data
        if name not in have:
            if fld.required or (fld.when_effect and fld.when_effect in effects):
                problems.append(f"missing {'attribute' if fld.attr else 'field'} {fld.path!r} ({fld.describe()})")
        elif fld.attr:
            problems.append(_meta_problem(fld, attrs[name]))
        else:
            arr = np.asarray(data[name])
            problem = _shape_problem(fld, arr, stored, sizes)
            problems.append(problem)
            if problem is None:
                shaped.append((fld, arr))
    return [p for p in problems if p]


def _shape_problem(fld: Field, arr: np.ndarray, stored: bool, sizes: dict):
    """The dtype or shape problem of a dataset, or None; records the sizes of its dim symbols."""
    if not _kind_ok(arr, fld.kind):
        return f"field {fld.path!r} has dtype {arr.dtype}, expected {KINDS[fld.kind]} (kind {fld.kind!r})"
    if stored and fld.dtype is not None and arr.dtype != np.dtype(fld.dtype):
        return f"field {fld.path!r} is stored as {arr.dtype}, expected {fld.dtype}"
    if not fld.dims:
        if arr.size != 1 or arr.ndim > 1:
            return f"field {fld.path!r} has shape {arr.shape}, expected a scalar"
        return None
    if arr.ndim != len(fld.dims):
        return f"field {fld.path!r} has shape {arr.shape}, expected {fld.dims_text}"
    for sym, size in zip(fld.dims, arr.shape):
        if isinstance(sym, int):
            if size != sym:
                return f"field {fld.path!r} has shape {arr.shape}, expected {fld.dims_text}"
        elif sym in sizes and sizes[sym][0] != size:
            first_size, first = sizes[sym]
            return f"inconsistent {sym}: {fld.path!r} has {size} but {first!r} has {first_size}"
        else:
            sizes.setdefault(sym, (int(size), fld.path))
    return None


def _check_tables(state: State, gname: str) -> list[str]:
    problems = []
    if state.groups.get(gname):
        problems.append(f"group {gname!r} holds tables ({gname}/<table>/<column>), not datasets: "
                        f"{sorted(state.groups[gname])}")
    prefix = gname + "/"
    for tname, cols in state.groups.items():
        if not tname.startswith(prefix):
            continue
        if "/" in tname[len(prefix):]:
            problems.append(f"record table {tname!r} is nested too deep")
            continue
        length = None
        for cname, col in cols.items():
            arr = np.asarray(col)
            if arr.ndim != 1 or arr.dtype.kind not in "fiu":
                problems.append(f"record column {tname}/{cname} must be a 1-D float or int array "
                                f"(got {arr.dtype}{arr.shape})")
                continue
            if length is None:
                length = (len(arr), cname)
            elif len(arr) != length[0]:
                problems.append(f"record table {tname!r}: column {cname!r} has {len(arr)} rows "
                                f"but {length[1]!r} has {length[0]}")
        attrs = state.group_attrs.get(tname, {})
        columns = attrs.get("columns")
        if columns is not None and sorted(map(str, columns)) != sorted(cols):
            problems.append(f"record table {tname!r}: attribute 'columns' {list(columns)} does not match "
                            f"its datasets {sorted(cols)}")
    return problems


def validate(state: State, source=None, *, values: bool = True, stored: bool = False) -> None:
    """Raise :class:`StateError` (one line, naming ``source``) if the state breaks the
    registry (``values``, ``stored``: as in :func:`check`)."""
    problems = check(state, values=values, stored=stored)
    if problems:
        raise StateError(_problem_line(problems, source))


def _problem_line(problems, source=None) -> str:
    head = f"{source}: " if source else ""
    shown = problems[:MAX_PROBLEMS_SHOWN]
    more = len(problems) - len(shown)
    tail = f"; ... and {more} more" if more > 0 else ""
    n = len(problems)
    return f"{head}invalid state ({n} problem{'s' if n > 1 else ''}): " + "; ".join(shown) + tail


def require(state: State, paths, *, consumer: str, source=None) -> None:
    """Raise :class:`StateError` unless every path (``group/name``) is in the state.

    For a stage's input check: the message names each missing field, what it is and
    which stage or effect writes it, e.g. ``stage cyclic needs contacts/ft ...``.
    """
    missing = []
    for path in paths:
        group, name = _split(path)
        fld = FIELDS.get(path)
        have = (name in state.group_attrs.get(group, {})) if (fld and fld.attr) else path in state
        if group == "meta":
            have = name in state.meta
        if not have:
            what = f" ({fld.describe()})" if fld else ""
            missing.append(f"{path}{what}")
    if missing:
        head = f"{source}: " if source else ""
        raise StateError(f"{head}{consumer} needs " + "; ".join(missing))


def schema_markdown(groups=None) -> str:
    """The registry (or only ``groups``) as Markdown tables: fields, then groups."""
    keep = set(GROUPS if groups is None else groups)
    lines = ["| group | field | dtype | dims | unit | required | rules | written by | doc |",
             "|---|---|---|---|---|---|---|---|---|"]
    for fld in FIELDS.values():
        if fld.group not in keep:
            continue
        dtype = fld.dtype or "vlen utf-8"
        if fld.attr:
            dtype += " (attr)"
        req = "yes" if fld.required else (f"with {fld.when_effect}" if fld.when_effect else "no")
        lines.append(f"| {fld.group} | {fld.name} | {dtype} | {fld.dims_text} | {fld.unit} | {req} "
                     f"| {fld.rules_text} | {fld.writer} | {fld.doc} |")
    lines.append("")
    lines.append("| group | required | tables | written by | doc |")
    lines.append("|---|---|---|---|---|")
    for grp in GROUPS.values():
        if grp.name not in keep:
            continue
        lines.append(f"| {grp.name} | {'yes' if grp.required else 'no'} | {'yes' if grp.tables else 'no'} "
                     f"| {grp.writer} | {grp.doc} |")
    return "\n".join(lines) + "\n"


def example_state(*, n_bodies=4, spheres_per_body=3, seed=0, walls=True, contacts=True,
                  rolling=False) -> State:
    """A small, valid, fully populated State for tests and demos (not physically settled)."""
    rng = np.random.default_rng(seed)
    effects = ["gravity", "friction"] + (["walls"] if walls else []) + (["rolling_resistance"] if rolling else [])
    st = new_state("demo", "compaction", seed=seed, case_file="cases/demo.yaml", case_hash="0" * 64,
                   config_hash="1" * 64, effects=effects, time=0.125, step=250, dt=5e-4)
    n_b, n_s = n_bodies, n_bodies * spheres_per_body
    q = rng.normal(size=(n_b, 4))
    st["bodies/x"] = rng.uniform([0.02, 0.02, 0.02], [0.08, 0.08, 0.12], size=(n_b, 3))
    st["bodies/v"] = rng.normal(scale=0.1, size=(n_b, 3))
    st["bodies/q"] = q / np.linalg.norm(q, axis=1, keepdims=True)
    st["bodies/omega"] = rng.normal(scale=1.0, size=(n_b, 3))
    st["bodies/mass"] = rng.uniform(0.01, 0.02, size=n_b)
    st["bodies/inertia"] = rng.uniform(1e-7, 2e-7, size=(n_b, 3))
    st["bodies/id"] = np.arange(100, 100 + n_b, dtype=np.int64)
    st["bodies/flags"] = np.zeros(n_b, dtype=np.int8)
    st["spheres/body"] = np.repeat(np.arange(n_b, dtype=np.int64), spheres_per_body)
    st["spheres/offset"] = rng.uniform(-0.004, 0.004, size=(n_s, 3))
    st["spheres/radius"] = rng.uniform(0.003, 0.006, size=n_s)
    st["spheres/material"] = (np.arange(n_s) % 2).astype(np.int64)
    st["materials/name"] = np.array(["granite", "mastic"], dtype=object)
    for name, vals in [("density", [2650.0, 1100.0]), ("young", [5e10, 1e8]), ("poisson", [0.25, 0.35]),
                       ("friction", [0.5, 0.3]), ("rolling_friction", [0.05, 0.02]),
                       ("restitution", [0.4, 0.2])]:
        st[f"materials/{name}"] = np.array(vals)
    if walls:
        ext = [0.0, 0.0, 0.0, 0.1, 0.1, 0.15]
        st["walls/name"] = np.array(["bottom", "left", "mould"], dtype=object)
        st["walls/kind"] = np.array([0, 0, 1], dtype=np.int8)
        st["walls/point"] = np.array([[0, 0, 0], [0, 0, 0], [0.05, 0.05, 0]], dtype=float)
        st["walls/normal"] = np.array([[0, 0, 1], [1, 0, 0], [0, 0, 1]], dtype=float)
        st["walls/radius"] = np.array([0.0, 0.0, 0.05])
        st["walls/v"] = np.zeros((3, 3))
        st["walls/material"] = np.zeros(3, dtype=np.int64)
        st["walls/control"] = np.array([0, 0, 0], dtype=np.int8)
        st["walls/target"] = np.zeros(3)
        st["walls/force"] = rng.normal(size=(3, 3))
        st["walls/extent"] = np.array([ext] * 3)
        st["wall_contacts/sphere"] = np.array([0, 1], dtype=np.int64)
        st["wall_contacts/wall"] = np.array([0, 2], dtype=np.int64)
        st["wall_contacts/ft"] = rng.normal(size=(2, 3))
        st["wall_contacts/force"] = rng.normal(size=(2, 3))
        if rolling:
            st["wall_contacts/mr"] = rng.normal(size=(2, 3))
    if contacts and n_s >= 2:
        i = np.arange(0, n_s - 1, dtype=np.int64)
        st["contacts/i"] = i
        st["contacts/j"] = i + 1
        st["contacts/ft"] = rng.normal(size=(len(i), 3))
        st["contacts/force"] = rng.normal(size=(len(i), 3))
        if rolling:
            st["contacts/mr"] = rng.normal(size=(len(i), 3))
    for name in fields_of("energy"):
        st[f"energy/{name}"] = np.float64(rng.uniform())
    st["records/energy/time"] = np.linspace(0.0, 0.125, 6)
    st["records/energy/kinetic"] = rng.uniform(size=6)
    st["records/energy/step"] = np.arange(0, 300, 50, dtype=np.int64)
    st.group_attrs["records/energy"] = {"columns": ["time", "kinetic", "step"], "units": ["s", "J", ""]}
    set_rng(st, rng)
    return st


DOC_BEGIN = "<!-- schema:begin (generated by demcli.state.fields.write_schema_doc) -->"
DOC_END = "<!-- schema:end -->"


def register_all() -> None:
    """Register every field (and record column) demcli declares: the state layer's own modules
    and, through :func:`demcli.stages.base.register_all_fields`, the stage types and the engine
    parts they write. Plain imports inside the call: the stages import the state layer at import
    time, never the other way round."""
    from demcli.stages.base import register_all_fields
    from demcli.state import polyhedra, records  # the polyhedra groups; the record columns

    del polyhedra, records  # imported for their registrations
    register_all_fields()


def write_schema_doc(path="docs/state.md") -> None:
    """Regenerate the schema block of docs/state.md from the registry (all of it:
    :func:`register_all`). Run: ``python -c "from demcli.state.fields import
    write_schema_doc; write_schema_doc()"`` in the repository root.
    """
    from demcli.state.atomic import atomic_write_text

    register_all()
    with open(path, encoding="utf-8") as fh:
        text = fh.read()
    head, rest = text.split(DOC_BEGIN.split(" (")[0], 1)
    _, tail = rest.split(DOC_END, 1)
    atomic_write_text(path, head + DOC_BEGIN + "\n" + schema_markdown() + DOC_END + tail)
