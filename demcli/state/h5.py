"""Read, validate and write state files (HDF5).

Layout: ``/meta`` holds the meta dict as attributes; every other State group is an
HDF5 group of the same path holding its datasets (each with a ``unit`` attribute) and
its group attributes. Files are deterministic: datasets and attributes are written in
sorted order, without timestamps (h5py's ``track_times=False``), so the same State gives a
byte-identical file. Numeric datasets of :data:`COMPRESS_MIN_BYTES` and more are stored
deflated (HDF5's built-in gzip filter, after its byte shuffle), the others contiguous.
Writes are atomic (:mod:`demcli.state.atomic`).

Checksums: every dataset carries the CRC32 of its bytes in the attribute ``crc32`` and
every group with attributes (``/meta`` included) the CRC32 of the others in
``attrs_crc32``, so a flipped bit is found on read also where HDF5 itself does not look
(contiguous datasets, attributes). Files without them (written before) read unverified.
"""

from __future__ import annotations

import hashlib
import io
import json
import zlib
from pathlib import Path

import h5py
import numpy as np

from demcli.errors import StateError
from demcli.state import fields as _f
from demcli.state.atomic import atomic_write_bytes
from demcli.state.fields import FIELDS, SCHEMA_VERSION, State

PHYSICS_META = ("dim", "dt", "effects", "schema_version", "seed", "step", "time")
"""Meta keys that enter :func:`state_hash` (provenance, names and hashes do not)."""

COMPRESS_MIN_BYTES = 65536
"""Numeric datasets this large or larger are written with ``shuffle`` + gzip level 1.

A ballast state is mostly its per-stone polyhedra (vertices, faces, edges): deflated they
take half the bytes (10.0 MB -> 5.3 MB for the single-small bed after vibration) for about
0.1 s more per write and 0.3 s per read; higher levels gain 1 % more for nine times the write
time. Every HDF5 build has the filter, so plain h5py reads the files as before."""

MIGRATIONS: dict = {}
"""schema_version -> function(State) -> State upgrading it by one version (none yet)."""

CRC_ATTR = "crc32"
"""Dataset attribute: CRC32 of the dataset's bytes (:func:`_payload`)."""

ATTRS_CRC_ATTR = "attrs_crc32"
"""Group attribute: CRC32 of the group's other attributes, as canonical JSON."""

_STR = h5py.string_dtype("utf-8")


# ---------------------------------------------------------------------------------------
# conversions
# ---------------------------------------------------------------------------------------

def _disk_array(path: str, value) -> np.ndarray:
    """The array written for dataset ``path``: registry dtype, strings as vlen utf-8."""
    arr = np.asarray(value)
    if arr.dtype.kind in "OUS":
        flat = [s.decode("utf-8") if isinstance(s, bytes) else str(s) for s in arr.ravel()]
        out = np.empty(arr.shape, dtype=_STR)
        out.ravel()[:] = flat
        return out
    fld = FIELDS.get(path)
    if fld is not None and fld.dtype is not None and arr.dtype != np.dtype(fld.dtype):
        out = arr.astype(fld.dtype)
        if not np.array_equal(out, arr, equal_nan=out.dtype.kind == "f"):
            raise StateError(f"field {path!r}: values do not fit its stored dtype {fld.dtype}")
        arr = out
    if arr.dtype.byteorder == ">":
        arr = arr.astype(arr.dtype.newbyteorder("<"))
    return arr if arr.flags.c_contiguous else arr.copy(order="C")


def _attr_value(where: str, value):
    """A Python value as an HDF5 attribute value (deterministic types)."""
    if isinstance(value, (bool, np.bool_)):
        return np.bool_(value)
    if isinstance(value, (int, np.integer)):
        return np.int64(value)
    if isinstance(value, (float, np.floating)):
        return np.float64(value)
    if isinstance(value, str):
        return value
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = np.asarray(value) if len(value) else np.asarray(value, dtype=object)
        if arr.dtype.kind in "OUS":
            if not all(isinstance(s, (str, bytes)) for s in arr.ravel()):
                raise StateError(f"attribute {where}: a list must hold only strings or only numbers")
            return _disk_array("", arr)
        if arr.dtype.kind in "iub":
            return arr.astype(np.int64 if arr.dtype.kind != "b" else np.bool_)
        if arr.dtype.kind == "f":
            return arr.astype(np.float64)
    raise StateError(f"attribute {where}: cannot store a {type(value).__name__} "
                     "(use str, int, float, bool or a list of them)")


def _py_value(value):
    """An HDF5 attribute value as a plain Python value (lists for arrays)."""
    if isinstance(value, bytes):
        return value.decode("utf-8")
    if isinstance(value, np.ndarray):
        if value.dtype.kind in "OS":
            return [_py_value(v) for v in value.tolist()]
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _payload(arr: np.ndarray):
    """The bytes of a disk array that its checksum and :func:`state_hash` cover: a numeric
    array's raw bytes; each string of a string array as its length (8 bytes) and utf-8."""
    if arr.dtype.kind == "O":
        for s in arr.ravel():
            b = s.encode("utf-8")
            yield len(b).to_bytes(8, "little") + b
    else:
        yield arr.tobytes()


def _crc32(arr: np.ndarray) -> int:
    """CRC32 of a disk array's :func:`_payload`."""
    crc = 0
    for chunk in _payload(arr):
        crc = zlib.crc32(chunk, crc)
    return crc


def _attrs_crc32(attrs) -> int:
    """CRC32 of a group's attributes (the checksum attribute left out), as read back."""
    values = {k: _py_value(attrs[k]) for k in sorted(attrs) if k != ATTRS_CRC_ATTR}
    return zlib.crc32(_canonical(values).encode("utf-8"))


def _corrupt(path, what, stored, found) -> StateError:
    return StateError(f"{path}: {what}: checksum mismatch (crc32 {stored:#010x} stored, {found:#010x} read); "
                      "the file is corrupt")


def _read_dataset(path: Path, ds: h5py.Dataset) -> np.ndarray:
    """A dataset's array, checked against its stored checksum (when it has one)."""
    try:
        if h5py.check_string_dtype(ds.dtype) is not None:
            arr = np.asarray(ds.asstr()[()], dtype=object)
        else:
            arr = np.asarray(ds[()])
        stored = int(ds.attrs[CRC_ATTR]) if CRC_ATTR in ds.attrs else None
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
        raise StateError(f"{path}: dataset {ds.name.lstrip('/')} cannot be read ({_first_line(exc)}); "
                         "the file is truncated or corrupt") from None
    found = stored if stored is None else _crc32(arr)
    if found != stored:
        raise _corrupt(path, f"dataset {ds.name.lstrip('/')}", stored, found)
    return arr


def _read_attrs(path: Path, obj) -> dict:
    """A group's attributes as plain values, checked against their checksum (when stored)."""
    attrs = obj.attrs
    if ATTRS_CRC_ATTR in attrs:
        stored, found = int(attrs[ATTRS_CRC_ATTR]), _attrs_crc32(attrs)
        if found != stored:
            raise _corrupt(path, f"attributes of {obj.name}", stored, found)
    return {k: _py_value(attrs[k]) for k in sorted(attrs) if k != ATTRS_CRC_ATTR}


# ---------------------------------------------------------------------------------------
# write
# ---------------------------------------------------------------------------------------

def _dataset_unit(group: str, name: str, state: State) -> str | None:
    fld = FIELDS.get(f"{group}/{name}")
    if fld is not None:
        return fld.unit
    attrs = state.group_attrs.get(group, {})
    cols, units = attrs.get("columns"), attrs.get("units")
    if cols is not None and units is not None and name in list(cols):
        return str(list(units)[list(cols).index(name)])
    return None


def write_state(path, state: State, *, validate: bool = True) -> Path:
    """Validate ``state`` and write it to ``path`` atomically; returns the path.

    The same State always gives the same bytes (no timestamps, sorted order).
    Raises :class:`StateError` for a state that breaks the registry's structure (nothing is
    written then); the value rules (finite, > 0, ...) are left to the reader, so the
    result of a stage is kept even where a value is off. The file is
    built in memory and written in one piece: the HDF5 library never meets a full or
    read-only disk (where it crashes the process), plain file I/O does and raises
    :class:`~demcli.errors.WriteError`.
    """
    path = Path(path)
    if validate:
        _f.validate(state, source=f"{path} (not written)", values=False)
    buf = io.BytesIO()
    with h5py.File(buf, "w", libver="earliest") as f:
        _write_attrs(f.create_group("meta"), "meta", state.meta)
        for gname in sorted(set(state.groups) | set(state.group_attrs)):
            if gname == "meta":
                raise StateError(f"{path}: 'meta' is reserved for State.meta")
            grp = f.require_group(gname)
            data = state.groups.get(gname, {})
            for name in sorted(data):
                arr = _disk_array(f"{gname}/{name}", data[name])
                deflate = arr.dtype.kind in "biuf" and arr.nbytes >= COMPRESS_MIN_BYTES
                ds = grp.create_dataset(name, data=arr, track_times=False,
                                        **({"compression": "gzip", "compression_opts": 1, "shuffle": True}
                                           if deflate else {}))
                ds.attrs[CRC_ATTR] = np.int64(_crc32(arr))
                unit = _dataset_unit(gname, name, state)
                if unit:
                    ds.attrs["unit"] = unit
            _write_attrs(grp, gname, state.group_attrs.get(gname, {}))
    atomic_write_bytes(path, buf.getvalue())
    return path


def _write_attrs(grp: h5py.Group, gname: str, attrs: dict) -> None:
    """A group's attributes in sorted order, then their checksum (when there are any)."""
    for key in sorted(attrs):
        if key == ATTRS_CRC_ATTR:
            raise StateError(f"attribute {gname}@{key}: the name is reserved for the checksum")
        grp.attrs[key] = _attr_value(f"{gname}@{key}", attrs[key])
    if attrs:
        grp.attrs[ATTRS_CRC_ATTR] = np.int64(_attrs_crc32(grp.attrs))


# ---------------------------------------------------------------------------------------
# read
# ---------------------------------------------------------------------------------------

def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return text[0] if text else type(exc).__name__


def _open_checks(path: Path) -> None:
    """File-level checks before h5py touches the file."""
    if not path.exists():
        raise StateError(f"{path}: no such state file")
    if path.is_dir():
        raise StateError(f"{path}: is a folder, not a state file")
    try:
        is_h5 = h5py.is_hdf5(str(path))
    except OSError as exc:
        raise StateError(f"{path}: cannot read the file ({_first_line(exc)})") from None
    if not is_h5:
        size = path.stat().st_size
        if size == 0:
            raise StateError(f"{path}: not an HDF5 state file (the file is empty)")
        with open(path, "rb") as fh:
            head = fh.read(512)
        looks_text = all(32 <= b < 127 or b in (9, 10, 13) for b in head)
        what = "it looks like a text file" if looks_text else "no HDF5 signature"
        raise StateError(f"{path}: not an HDF5 state file ({what})")


def _check_schema(path: Path, f: h5py.File) -> int:
    meta = f.get("meta")
    if not isinstance(meta, h5py.Group) or "schema_version" not in meta.attrs:
        top = ", ".join(sorted(f.keys())[:8]) or "nothing"
        raise StateError(f"{path}: not a demcli state file (no /meta group with a schema_version; "
                         f"top level holds: {top})")
    raw = meta.attrs["schema_version"]
    try:
        version = int(raw)
        if version != raw:
            raise ValueError
    except (TypeError, ValueError):
        raise StateError(f"{path}: schema_version {raw!r} is not an integer") from None
    if version > SCHEMA_VERSION:
        from demcli import __version__

        raise StateError(f"{path}: written by a newer demcli (schema_version {version}; demcli "
                         f"{__version__} reads up to {SCHEMA_VERSION}); upgrade demcli to read it")
    if version < SCHEMA_VERSION and version not in MIGRATIONS:
        raise StateError(f"{path}: schema_version {version} is not supported "
                         f"(this demcli reads {SCHEMA_VERSION}); re-run the stage that wrote it")
    return version


def _load(path: Path, f: h5py.File) -> State:
    version = _check_schema(path, f)
    state = State(meta=_read_attrs(path, f["meta"]))
    stray = [k for k, v in f.items() if isinstance(v, h5py.Dataset)]
    if stray:
        raise StateError(f"{path}: not a demcli state file (datasets at the top level: {', '.join(stray)})")

    def visit(name, obj):
        if not isinstance(obj, h5py.Group) or name == "meta" or name.startswith("meta/"):
            return
        data, has_sub = {}, False
        for key, child in obj.items():
            if isinstance(child, h5py.Dataset):
                data[key] = _read_dataset(path, child)
            elif isinstance(child, h5py.Group):
                has_sub = True
        attrs = _read_attrs(path, obj)
        if data or not has_sub:
            state.groups[name] = data
        if attrs:
            state.group_attrs[name] = attrs

    f.visititems(visit)
    while version < SCHEMA_VERSION:
        state = MIGRATIONS[version](state)
        version += 1
        state.meta["schema_version"] = version
    return state


def _read_file(path: Path, read):
    """``read(path, f)`` on the open HDF5 file; any failure of the file is a StateError
    naming it."""
    _open_checks(path)
    try:
        with h5py.File(path, "r") as f:
            return read(path, f)
    except StateError:
        raise
    except (OSError, RuntimeError, KeyError, ValueError, TypeError) as exc:
        raise StateError(f"{path}: HDF5 file is truncated or corrupt ({_first_line(exc)})") from None


def read_state(path, *, validate: bool = True) -> State:
    """Read a state file; raises :class:`StateError` (one line naming the file) when it is
    missing, not HDF5, truncated or corrupt (a dataset or attributes failing their
    checksum), not a demcli state, of another schema version, or (with ``validate``)
    breaks the field registry: dtypes and shapes, and the value rules of the fields
    (finite, > 0, unit rows, unique, index ranges; :func:`demcli.state.fields.check`)."""
    path = Path(path)
    state = _read_file(path, _load)
    if validate:
        _f.validate(state, source=path, stored=True)
    return state


def read_meta(path) -> dict:
    """Only the meta attributes (cheap: no datasets are read, nor checked); same file
    checks as read_state."""
    def meta(path, f):
        _check_schema(path, f)
        return _read_attrs(path, f["meta"])

    return _read_file(Path(path), meta)


# ---------------------------------------------------------------------------------------
# hash
# ---------------------------------------------------------------------------------------

def _canonical(obj):
    return json.dumps(_f._jsonable(obj), sort_keys=True, separators=(",", ":"), allow_nan=True)


def state_hash(state: State) -> str:
    """sha256 (hex) of what defines a state physically.

    Covers every dataset in sorted path order (path, stored dtype, shape, bytes; strings
    as length-prefixed utf-8), the group attributes (rng state, record units) and the
    meta keys in :data:`PHYSICS_META`; provenance (versions, stage names, case file,
    hashes) does not enter. A State and its written-then-read copy hash the same.
    """
    h = hashlib.sha256(b"demcli-state-hash 1\0")
    for key in PHYSICS_META:
        if key in state.meta:
            h.update(f"meta/{key}={_canonical(state.meta[key])}\0".encode())
    for gname in sorted(state.groups):
        for name in sorted(state.groups[gname]):
            arr = _disk_array(f"{gname}/{name}", state.groups[gname][name])
            dtype = "str" if arr.dtype.kind == "O" else arr.dtype.str
            h.update(f"{gname}/{name}|{dtype}|{arr.shape}\0".encode())
            for chunk in _payload(arr):
                h.update(chunk)
    for gname in sorted(state.group_attrs):
        if state.group_attrs[gname]:
            h.update(f"attrs {gname}={_canonical(state.group_attrs[gname])}\0".encode())
    return h.hexdigest()


# ---------------------------------------------------------------------------------------
# summary for `demcli info`
# ---------------------------------------------------------------------------------------

_COUNT_NAMES = [("n_b", "bodies"), ("n_s", "spheres"), ("n_m", "materials"), ("n_w", "walls"),
                ("n_c", "contacts"), ("n_wc", "wall contacts")]


def _g(x) -> str:
    return f"{x:.6g}"


def summarize(path) -> str:
    """A human summary of a state file (``demcli info FILE.h5``).

    The file is read as :func:`read_state` reads it: a missing, corrupt or invalid file
    raises :class:`StateError` naming the file, the dataset and the rule it breaks.
    """
    path = Path(path)
    state = read_state(path)
    m = state.meta
    size = path.stat().st_size
    lines = [f"{path}  ({size / 1e6:.3g} MB, schema_version {m.get('schema_version')})"]
    lines.append(f"  stage      {m.get('stage', '?')} ({m.get('stage_type', '?')}), "
                 f"written by {m.get('created_by', '?')}")
    if m.get("machine"):
        lines.append(f"  machine    {m['machine']}")
    if m.get("case_file") or m.get("case_hash"):
        lines.append(f"  case       {m.get('case_file') or '-'}  sha256 {str(m.get('case_hash', ''))[:16]}")
    hashes = [f"{k.split('_')[0]} {str(m[k])[:16]}" for k in ("config_hash", "input_hash") if m.get(k)]
    if hashes:
        lines.append("  hashes     " + ", ".join(hashes))
    effects = m.get("effects") or []
    lines.append(f"  effects    {', '.join(effects) if effects else '(none)'}")
    lines.append(f"  time       {_g(m.get('time', float('nan')))} s, step {m.get('step', '?')}, "
                 f"dt {_g(m.get('dt', float('nan')))} s, dim {m.get('dim', '?')}, seed {m.get('seed', '?')}")
    counts = state.counts()
    lines.append("  counts     " + ", ".join(f"{counts[s]} {label}" for s, label in _COUNT_NAMES if s in counts))
    lines += _extent_lines(state)
    if state.groups.get("energy"):
        parts = [f"{k} {_g(float(np.asarray(v).ravel()[0]))}" for k, v in state.groups["energy"].items()
                 if np.asarray(v).size]
        lines.append("  energy     " + ", ".join(parts) + " J")
    tables = sorted(g for g in state.groups if g.startswith("records/"))
    for t in tables:
        cols = state.group_attrs.get(t, {}).get("columns") or sorted(state.groups[t])
        rows = len(next(iter(state.groups[t].values()))) if state.groups[t] else 0
        lines.append(f"  record     {t[len('records/'):]}: {rows} rows ({', '.join(cols)})")
    lines.append("  validation ok (registry, value rules and checksums)")
    return "\n".join(lines)


def _extent_lines(state: State) -> list[str]:
    """The extent of the spheres (and their radii), else of the body centres."""
    if len(state["spheres/radius"]):
        c = state.sphere_centres()
        r = np.asarray(state["spheres/radius"], dtype=float)
        lo, hi, what = (c - r[:, None]).min(axis=0), (c + r[:, None]).max(axis=0), "spheres"
    elif len(state["bodies/x"]):
        x = np.asarray(state["bodies/x"], dtype=float)
        lo, hi, what = x.min(axis=0), x.max(axis=0), "body centres"
    else:
        return []
    lines = ["  extent     " + "  ".join(f"{a} [{_g(lo[k])}, {_g(hi[k])}]" for k, a in enumerate("xyz"))
             + f" m ({what})"]
    if what == "spheres":
        lines.append(f"  radius     mean {_g(r.mean())} m, min {_g(r.min())} m, max {_g(r.max())} m")
    return lines
