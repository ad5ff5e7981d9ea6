"""A small schema language that validates plain YAML data into read-only nodes in SI.

A schema is built from field objects::

    FRICTION = Section({
        "mu": Float(min=0, doc="sliding friction coefficient"),
        "k_t": Float("N/m", min=0, min_inclusive=False, default="0.8e5 N/m"),
    })
    CASE = Section({
        "seed": Int(min=0, default=0),
        "dt": Float("s", min=0, min_inclusive=False),
        "stages": List(Section({...}), min_len=1, unique_by="name"),
        "materials": Map(Section({...}), key_pattern=r"[A-Za-z_][\\w-]*"),
        "contact": Tagged("type", {"hertz": Section({...}), "hooke": Section({...})}),
        "friction": Optional(FRICTION),
    })

and validated with :func:`validate_tree` (``demcli.config.load.validate`` wraps it and
raises ``ConfigError``). Validation never stops at the first problem: every issue is
collected as a :class:`ConfigIssue` (``case.yaml:14: stages[2].friction.mu: must be
>= 0 (got -0.2)``). Cross-field rules go in a Section's ``check(node, report)``,
which runs only when all of that section's fields were valid (types and ranges
first, then cross-field rules, as in STYLE.md section 5). Cross-references that
should be reported together with every other problem (a name that refers to nothing)
go in ``check_raw(mapping, report)``, which sees the raw mapping and always runs.

The result is a tree of :class:`Node` (read-only mapping with attribute access),
tuples for lists, floats in SI for quantities. ``Node.to_dict()``,
:func:`canonical_json` and :func:`sha256_of` give plain data and a stable hash.

Field names ``path``, ``to_dict``, ``line_of``, ``keys``, ``items``, ``values`` and
``get`` are reserved (they are Node methods) and refused when a Section is built;
Map keys are free and reached by item access.
"""

from __future__ import annotations

import difflib
import hashlib
import json
import math
import numbers
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

from demcli.units import UnitError, format_si, to_si

__all__ = [
    "REQUIRED",
    "NOVALUE",
    "SchemaError",
    "ConfigIssue",
    "Node",
    "DocRow",
    "Field",
    "Float",
    "Int",
    "Bool",
    "Str",
    "Vector",
    "List",
    "Section",
    "Map",
    "Tagged",
    "Optional",
    "validate_tree",
    "format_path",
    "split_subpath",
    "did_you_mean",
    "canonical_json",
    "sha256_of",
]


class _Sentinel:
    def __init__(self, name):
        self._name = name

    def __repr__(self):
        return self._name

    def __reduce__(self):
        return self._name


REQUIRED = _Sentinel("REQUIRED")  # default of a field that must be given
NOVALUE = _Sentinel("NOVALUE")  # an issue that shows no offending value
_INVALID = _Sentinel("_INVALID")  # a field that failed validation

RESERVED_NAMES = frozenset({"path", "to_dict", "line_of", "keys", "items", "values", "get"})


class SchemaError(ValueError):
    """A mistake in a schema definition (a programming error, not bad input)."""


# ---------------------------------------------------------------------------
# issues and paths


def format_path(path):
    """``('stages', 2, 'physics')`` -> ``'stages[2].physics'``."""
    out = ""
    for part in path:
        if isinstance(part, int) and not isinstance(part, bool):
            out += f"[{part}]"
        else:
            text = str(part)
            if not text or re.search(r"[\s.\[\]]", text):
                out += f"[{text!r}]"
            else:
                out += f".{text}" if out else text
    return out


class _Shown(str):
    """A value already formatted for an issue message (printed as is)."""


def _show(value, limit=60):
    if isinstance(value, _Shown):
        return str(value)
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, numbers.Real):
        return repr(value) if not isinstance(value, float) else format_si(value, "1", 12)
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


@dataclass(frozen=True)
class ConfigIssue:
    """One problem in a case: where it is, what rule it breaks, what was given.

    ``str()`` reads ``case.yaml:14: stages[2].physics.friction.mu: must be >= 0 (got -0.2)``.
    ``file`` may also name an override (``--set seed=-1``) and ``line`` be None.
    """

    file: str | None
    line: int | None
    path: str
    rule: str
    value: Any = NOVALUE
    hint: str | None = None

    def __str__(self):
        where = ""
        if self.file:
            where = f"{self.file}:{self.line}: " if self.line is not None else f"{self.file}: "
        elif self.line is not None:
            where = f"line {self.line}: "
        text = f"{where}{self.path}: {self.rule}" if self.path else f"{where}{self.rule}"
        if self.value is not NOVALUE:
            text += f" (got {_show(self.value)})"
        if self.hint:
            text += f"; {self.hint}"
        return text


def did_you_mean(word, candidates):
    """``"did you mean 'x'?"`` for the candidate closest to ``word``, or None."""
    if not isinstance(word, str):
        return None
    close = difflib.get_close_matches(word, [str(c) for c in candidates], n=1, cutoff=0.6)
    return f"did you mean {close[0]!r}?" if close else None


def _one_of(candidates, limit=15):
    names = [repr(c) for c in candidates]
    if len(names) > limit:
        names = names[:limit] + ["..."]
    return ", ".join(names)


class _Context:
    """Collects issues; knows the file name and the line of each path."""

    def __init__(self, filename=None, marks=None):
        self.filename = filename
        self.marks = marks if marks is not None else {}
        self.issues = []

    def where(self, path):
        path = tuple(path)
        while True:
            mark = self.marks.get(path)
            if mark is not None:
                if isinstance(mark, str):  # an override's label stands for the file
                    return mark, None
                return self.filename, mark
            if not path:
                return self.filename, None
            path = path[:-1]

    def error(self, path, rule, value=NOVALUE, hint=None):
        file, line = self.where(path)
        self.issues.append(ConfigIssue(file, line, format_path(path), rule, value, hint))


def validate_quietly(field, value, path=()):
    """``field``'s validated ``value`` (a Node for a section), or None when it has any issue;
    the issues are dropped (for rules that run on the valid parts of an invalid case, while
    the main pass reports the issues)."""
    ctx = _Context()
    out = field.validate(value, tuple(path), ctx)
    return None if ctx.issues or out is _INVALID else out


def validate_tree(schema, data, marks=None, filename=None):
    """Validate ``data`` against ``schema``; return ``(node_or_None, issues)``.

    ``marks`` maps path tuples to 1-based lines (or to an override label);
    issues come sorted by line, those without a line last.
    """
    ctx = _Context(filename, marks)
    result = schema.validate(data, (), ctx)
    issues = sorted(ctx.issues, key=lambda i: (i.line is None, i.line or 0))
    return (None if issues or result is _INVALID else result), issues


# ---------------------------------------------------------------------------
# validated nodes and hashing


def _rebuild_node(data, path):
    return Node(data, path)


class Node(Mapping):
    """A validated mapping: read-only, attribute and item access, values in SI.

    ``node.mu`` and ``node["mu"]`` are the same; ``node.path`` is the dotted path;
    ``node.line_of("mu")`` is the case-file line of a key (None for defaults and
    values set by overrides); ``node.to_dict()`` gives plain dicts and lists.
    """

    __slots__ = ("_data", "_keys", "_marks")

    def __init__(self, data, path=(), marks=None):
        object.__setattr__(self, "_data", dict(data))
        object.__setattr__(self, "_keys", tuple(path))
        object.__setattr__(self, "_marks", marks if marks is not None else {})

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self._data[name]
        except KeyError:
            where = self.path or "the case"
            raise AttributeError(
                f"{where} has no key {name!r} (keys: {', '.join(map(str, self._data))})"
            ) from None

    def __setattr__(self, name, value):
        raise AttributeError("validated config nodes are read-only")

    def __delattr__(self, name):
        raise AttributeError("validated config nodes are read-only")

    def __getitem__(self, key):
        return self._data[key]

    def __iter__(self):
        return iter(self._data)

    def __len__(self):
        return len(self._data)

    def __hash__(self):
        return hash(tuple(self._data.items()))

    def __eq__(self, other):
        if isinstance(other, Mapping):
            return self._data == dict(other.items())
        return NotImplemented

    def __repr__(self):
        return f"Node({self.path!r}, {self.to_dict()!r})"

    def __dir__(self):
        return sorted(set(super().__dir__()) | {k for k in self._data if isinstance(k, str)})

    def __reduce__(self):
        return _rebuild_node, (self._data, self._keys)

    @property
    def path(self):
        """Dotted path of this node in the case (``''`` for the top level)."""
        return format_path(self._keys)

    def line_of(self, key):
        """Line of ``key`` in the case file, or None if not known."""
        mark = self._marks.get(self._keys + (key,))
        return mark if isinstance(mark, int) else None

    def to_dict(self):
        """Plain python: dicts for nodes, lists for tuples."""
        return {k: _plain(v) for k, v in self._data.items()}


def _plain(value):
    if isinstance(value, Node):
        return value.to_dict()
    if isinstance(value, (tuple, list)):
        return [_plain(v) for v in value]
    return value


def _jsonable(value):
    if isinstance(value, Mapping):
        out = {}
        for key, item in value.items():
            text = key if isinstance(key, str) else json.dumps(_jsonable(key))
            if text in out:
                raise ValueError(f"keys collide after conversion to text: {key!r}")
            out[text] = _jsonable(item)
        return out
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if value is None or isinstance(value, (bool, str)):
        return value
    if isinstance(value, numbers.Integral):
        return int(value)
    if isinstance(value, numbers.Real):
        value = float(value)
        if not math.isfinite(value):
            raise ValueError(f"cannot hash a non-finite number: {value!r}")
        return value
    raise TypeError(f"cannot put {type(value).__name__} into canonical JSON")


def canonical_json(obj):
    """JSON text with sorted keys, no spaces and exact (shortest round-trip) floats.

    Nodes become objects and tuples arrays; equal data in any key order gives the
    same text. An int and a float differ (``1`` vs ``1.0``), which Float fields
    avoid by always producing floats.
    """
    return json.dumps(
        _jsonable(obj), sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=False
    )


def sha256_of(obj):
    """Hex SHA-256 of :func:`canonical_json` of ``obj`` (UTF-8)."""
    return hashlib.sha256(canonical_json(obj).encode("utf-8")).hexdigest()


# ---------------------------------------------------------------------------
# fields


class DocRow(NamedTuple):
    """One line of the schema documentation table."""

    path: str
    type: str
    unit: str
    default: str
    doc: str


def _show_default(default):
    if default is REQUIRED:
        return "required"
    if default is None:
        return "none"
    if isinstance(default, bool):
        return "true" if default else "false"
    if isinstance(default, (dict, list, tuple)) and not default:
        return "{}" if isinstance(default, dict) else "[]"
    return str(default)


class Field:
    """Base of all fields: a default (``REQUIRED`` if none) and a doc string."""

    type_name = "any"
    unit = ""

    def __init__(self, default=REQUIRED, doc=""):
        self.default = default
        self.doc = doc

    @property
    def required(self):
        return self.default is REQUIRED

    def validate(self, value, path, ctx):
        """Return the validated value, or ``_INVALID`` after reporting to ``ctx``."""
        raise NotImplementedError

    def default_value(self, path=(), marks=None):
        """The default, validated like input (so ``default="1 ms"`` works)."""
        if self.default is REQUIRED:
            raise SchemaError(f"{format_path(path) or 'field'} has no default")
        if self.default is None:
            return None
        ctx = _Context("<default>", marks)
        value = self.validate(self.default, tuple(path), ctx)
        if ctx.issues:
            raise SchemaError(
                f"invalid default {self.default!r} at {format_path(path)}: "
                + "; ".join(str(i) for i in ctx.issues)
            )
        return value

    def describe(self, path=""):
        """Yield :class:`DocRow` rows for this field (and nested fields)."""
        yield DocRow(path, self.type_name, self.unit if self.unit != "1" else "",
                     _show_default(self.default), self.doc)


def _is_number(value):
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


class Float(Field):
    """A real number stored in SI ``unit`` (``'1'`` for a plain number).

    Accepts ints, floats and quantity strings (``"63 mm"``). ``min``/``max`` may be
    SI numbers or quantity strings; ``*_inclusive=False`` makes them strict.
    Non-finite values are refused.
    """

    type_name = "float"

    def __init__(self, unit="1", min=None, max=None, min_inclusive=True, max_inclusive=True,
                 default=REQUIRED, doc=""):
        super().__init__(default, doc)
        self.unit = unit
        self._min_raw, self._max_raw = min, max
        self.min_inclusive, self.max_inclusive = min_inclusive, max_inclusive
        self._bounds = None

    def bounds(self):
        """``(min, max)`` in SI (None where open); quantity strings converted once."""
        if self._bounds is None:
            lo = None if self._min_raw is None else to_si(self._min_raw, self.unit)
            hi = None if self._max_raw is None else to_si(self._max_raw, self.unit)
            self._bounds = (lo, hi)
        return self._bounds

    def _range_rule(self, with_unit=True):
        lo, hi = self.bounds()
        unit = self.unit if with_unit else "1"
        if lo is not None and hi is not None:
            left = "[" if self.min_inclusive else "("
            right = "]" if self.max_inclusive else ")"
            span = f"{left}{format_si(lo)}, {format_si(hi)}{right}"
            return f"must be in {span}" + ("" if unit == "1" else f" {unit}")
        if lo is not None:
            return f"must be {'>=' if self.min_inclusive else '>'} {format_si(lo, unit)}"
        return f"must be {'<=' if self.max_inclusive else '<'} {format_si(hi, unit)}"

    def check_number(self, x, shown, path, ctx):
        """Range-check an SI number; report and return False when out of range."""
        if not math.isfinite(x):
            ctx.error(path, "must be a finite number", shown)
            return False
        lo, hi = self.bounds()
        bad = (lo is not None and (x < lo or (x == lo and not self.min_inclusive))) or (
            hi is not None and (x > hi or (x == hi and not self.max_inclusive))
        )
        if bad:
            ctx.error(path, self._range_rule(), shown)
            return False
        return True

    def validate(self, value, path, ctx):
        if isinstance(value, bool) or not isinstance(value, (numbers.Real, str)):
            what = "a number" if self.unit == "1" else f"a number in {self.unit} or a quantity string"
            ctx.error(path, f"must be {what}", value)
            return _INVALID
        try:
            x = to_si(value, self.unit)
        except UnitError as exc:
            ctx.error(path, str(exc))
            return _INVALID
        shown = value
        if isinstance(value, str):
            try:
                float(value)
                shown = _Shown(value)
            except ValueError:
                shown = _Shown(f"{value.strip()} = {format_si(x, self.unit)}")
        return x if self.check_number(x, shown, path, ctx) else _INVALID

    def describe(self, path=""):
        row = next(super().describe(path))
        rng = ""
        if self._min_raw is not None or self._max_raw is not None:
            rng = self._range_rule(with_unit=False).replace("must be ", "")
        yield row._replace(type="float" + (f" {rng}" if rng else ""))


class Int(Field):
    """An integer (``true``/``false`` are not integers; ``1e3`` and ``100.0`` are)."""

    type_name = "int"

    def __init__(self, min=None, max=None, default=REQUIRED, doc=""):
        super().__init__(default, doc)
        self.min, self.max = min, max

    def validate(self, value, path, ctx):
        if isinstance(value, float) and math.isfinite(value) and value.is_integer():
            value = int(value)
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            ctx.error(path, "must be an integer", value)
            return _INVALID
        value = int(value)
        if self.min is not None and value < self.min:
            ctx.error(path, f"must be >= {self.min}", value)
            return _INVALID
        if self.max is not None and value > self.max:
            ctx.error(path, f"must be <= {self.max}", value)
            return _INVALID
        return value

    def describe(self, path=""):
        row = next(super().describe(path))
        rng = []
        if self.min is not None:
            rng.append(f">= {self.min}")
        if self.max is not None:
            rng.append(f"<= {self.max}")
        yield row._replace(type=" ".join(["int"] + rng))


class Bool(Field):
    """``true`` or ``false`` (YAML's yes/no/on/off included, as PyYAML reads them)."""

    type_name = "bool"

    def validate(self, value, path, ctx):
        if not isinstance(value, bool):
            ctx.error(path, "must be true or false", value)
            return _INVALID
        return value


class Str(Field):
    """A string, optionally one of ``choices`` or matching ``pattern`` (full match)."""

    type_name = "str"

    def __init__(self, choices=None, pattern=None, default=REQUIRED, doc=""):
        super().__init__(default, doc)
        self.choices = tuple(choices) if choices is not None else None
        self.pattern = pattern
        self._regex = re.compile(pattern) if pattern is not None else None
        if self.choices:
            self.type_name = "one of " + "|".join(self.choices)

    def validate(self, value, path, ctx):
        if not isinstance(value, str):
            ctx.error(path, "must be a string", value)
            return _INVALID
        if self.choices is not None and value not in self.choices:
            ctx.error(path, f"must be one of {_one_of(self.choices)}", value,
                      did_you_mean(value, self.choices))
            return _INVALID
        if self._regex is not None and not self._regex.fullmatch(value):
            ctx.error(path, f"must match {self.pattern!r}", value)
            return _INVALID
        return value


class Vector(Field):
    """``n`` numbers in SI ``unit``: a list (items may carry units, ``["60 cm", 0.3]``)
    or one string with a shared unit (``"0.6 0.3 0.35 m"``, commas allowed).
    ``min``/``max`` apply to every component. The result is a tuple of floats."""

    def __init__(self, n, unit="1", min=None, max=None, min_inclusive=True, max_inclusive=True,
                 default=REQUIRED, doc=""):
        super().__init__(default, doc)
        if not isinstance(n, int) or n < 1:
            raise SchemaError("Vector needs a positive component count n")
        self.n = n
        self.unit = unit
        self.type_name = f"vector[{n}]"
        self._item = Float(unit, min, max, min_inclusive, max_inclusive)

    def _split(self, text):
        tokens = text.replace(",", " ").split()
        numbers_, rest = [], []
        for token in tokens:
            if not rest:
                try:
                    float(token.replace("_", ""))
                    numbers_.append(token)
                    continue
                except ValueError:
                    pass
            rest.append(token)
        unit = " ".join(rest)
        return [f"{t} {unit}" if unit else t for t in numbers_]

    def validate(self, value, path, ctx):
        if isinstance(value, str):
            items = self._split(value)
        elif isinstance(value, (list, tuple)):
            items = list(value)
        else:
            ctx.error(path, f"must be a list of {self.n} numbers", value)
            return _INVALID
        if len(items) != self.n:
            ctx.error(path, f"must have {self.n} components, not {len(items)}", value)
            return _INVALID
        out = [self._item.validate(v, path + (i,), ctx) for i, v in enumerate(items)]
        return _INVALID if any(v is _INVALID for v in out) else tuple(out)

    def describe(self, path=""):
        row = next(super().describe(path))
        item = next(self._item.describe(path))
        yield row._replace(type=item.type.replace("float", self.type_name, 1))


class List(Field):
    """A list of ``item`` fields, ``min_len``..``max_len`` long; becomes a tuple.

    ``unique_by="name"``: items (mappings) must not share that key's value.
    An empty YAML value (``stages:``) is an empty list.
    """

    def __init__(self, item, min_len=0, max_len=None, unique_by=None, default=REQUIRED, doc=""):
        super().__init__(default, doc)
        self.item = item
        self.min_len, self.max_len = min_len, max_len
        self.unique_by = unique_by
        self.type_name = f"list of {item.type_name}"

    def validate(self, value, path, ctx):
        if value is None:
            value = []
        if not isinstance(value, (list, tuple)):
            ctx.error(path, "must be a list", value)
            return _INVALID
        n0 = len(ctx.issues)
        if len(value) < self.min_len:
            rule = "must not be empty" if self.min_len == 1 else f"must have at least {self.min_len} items"
            ctx.error(path, rule + f", has {len(value)}")
        if self.max_len is not None and len(value) > self.max_len:
            ctx.error(path, f"must have at most {self.max_len} items, has {len(value)}")
        out = [self.item.validate(v, path + (i,), ctx) for i, v in enumerate(value)]
        if self.unique_by is not None:
            seen = {}
            for i, v in enumerate(value):
                if isinstance(v, Mapping) and self.unique_by in v:
                    key = v[self.unique_by]
                    try:
                        first = seen.setdefault(key, i)
                    except TypeError:
                        continue
                    if first != i:
                        ctx.error(path + (i, self.unique_by), f"duplicate {self.unique_by}", key,
                                  f"already used by {format_path(path + (first,))}")
        if len(ctx.issues) > n0:
            return _INVALID
        return tuple(out)

    def describe(self, path=""):
        row = next(super().describe(path))
        yield row
        for sub in self.item.describe(f"{path}[]"):
            if sub.path != f"{path}[]":  # the list's row stands for the item's own row
                yield sub


class Section(Field):
    """A mapping with known keys: unknown keys are errors (with a did-you-mean hint),
    missing required keys are errors, defaults are filled in.

    ``check(node, report)`` runs after every field of the section is valid;
    ``report(subpath, rule, value=NOVALUE, hint=None)`` adds an issue, ``subpath``
    being ``''`` (the section), ``'e_max'``, ``'walls.0.z'`` or a tuple.
    ``check_raw(mapping, report)`` runs on the raw (unvalidated) mapping whatever the
    fields' validity, so its issues come in the same pass as theirs; it must expect
    values of any type. An empty YAML value (``gravity:``) is an empty mapping, so
    defaults apply.
    """

    type_name = "section"

    def __init__(self, fields, doc="", check=None, default=REQUIRED, check_raw=None):
        super().__init__(default, doc)
        for name, field in fields.items():
            if not isinstance(field, Field):
                raise SchemaError(f"field {name!r} is not a Field: {field!r}")
            if not isinstance(name, str) or name.startswith("_") or name in RESERVED_NAMES:
                raise SchemaError(
                    f"field name {name!r} is reserved for Node (reserved: {sorted(RESERVED_NAMES)})"
                    if name in RESERVED_NAMES else f"bad field name {name!r}"
                )
        self.fields = dict(fields)
        self.check = check
        self.check_raw = check_raw

    def validate(self, value, path, ctx):
        if value is None:
            value = {}
        if not isinstance(value, Mapping):
            ctx.error(path, "must be a mapping of keys", value)
            return _INVALID
        return self.validate_mapping(value, path, ctx)

    def validate_mapping(self, value, path, ctx, skip=(), first=()):
        """Validate a mapping (``skip`` keys handled by the caller, ``first`` items prepended)."""
        n0 = len(ctx.issues)
        for key in value:
            if key in skip or key in self.fields:
                continue
            hint = did_you_mean(key, self.fields) or (
                f"expected one of {_one_of(self.fields)}" if self.fields else "this section takes no keys"
            )
            ctx.error(path + (key,), "unknown key", hint=hint)
        out = dict(first)
        for name, field in self.fields.items():
            sub = path + (name,)
            if name in value:
                out[name] = field.validate(value[name], sub, ctx)
            elif field.required:
                ctx.error(sub, "required key is missing")
                out[name] = _INVALID
            else:
                out[name] = field.default_value(sub, ctx.marks)
        if self.check_raw is not None:
            self.check_raw(value, _reporter(path, ctx))
        if len(ctx.issues) > n0:
            return _INVALID
        node = Node(out, path, ctx.marks)
        if self.check is not None:
            n1 = len(ctx.issues)
            self.check(node, _reporter(path, ctx))
            if len(ctx.issues) > n1:
                return _INVALID
        return node

    def describe(self, path=""):
        if path:
            yield from super().describe(path)
        for name, field in self.fields.items():
            yield from field.describe(f"{path}.{name}" if path else name)

    def doc_table(self):
        """All rows of this schema: ``(path, type, unit, default, doc)``."""
        return list(self.describe(""))


def split_subpath(subpath):
    """A check's subpath as a tuple: ``''``/None -> ``()``, ``'walls.0.z'`` -> ``('walls', 0, 'z')``."""
    if subpath in (None, "", ()):
        return ()
    if isinstance(subpath, str):
        return tuple(int(p) if p.isdigit() else p for p in subpath.split("."))
    return tuple(subpath)


def _reporter(path, ctx):
    def report(subpath, rule, value=NOVALUE, hint=None):
        ctx.error(path + split_subpath(subpath), rule, value, hint)

    return report


class Map(Field):
    """A mapping with free keys (e.g. materials by name), each value a ``value`` field.

    ``key_pattern`` (full match) restricts the keys. An empty YAML value is an
    empty mapping. The result is a Node keyed by the given keys.
    """

    def __init__(self, value, key_pattern=None, min_len=0, default=REQUIRED, doc=""):
        super().__init__(default, doc)
        self.value = value
        self.key_pattern = key_pattern
        self._regex = re.compile(key_pattern) if key_pattern is not None else None
        self.min_len = min_len
        self.type_name = f"map of {value.type_name}"

    def validate(self, value, path, ctx):
        if value is None:
            value = {}
        if not isinstance(value, Mapping):
            ctx.error(path, "must be a mapping", value)
            return _INVALID
        n0 = len(ctx.issues)
        if len(value) < self.min_len:
            ctx.error(path, f"must have at least {self.min_len} entries, has {len(value)}")
        out = {}
        for key, item in value.items():
            if not isinstance(key, str):
                ctx.error(path + (key,), "key must be a string", key)
                continue
            if self._regex is not None and not self._regex.fullmatch(key):
                ctx.error(path + (key,), f"key must match {self.key_pattern!r}", key)
                continue
            out[key] = self.value.validate(item, path + (key,), ctx)
        if len(ctx.issues) > n0:
            return _INVALID
        return Node(out, path, ctx.marks)

    def describe(self, path=""):
        yield from super().describe(path)
        for sub in self.value.describe(f"{path}.<name>"):
            if sub.path != f"{path}.<name>":  # the map's row stands for the value's own row
                yield sub


class Tagged(Field):
    """A mapping whose ``tag_key`` value picks the Section that validates the rest.

    ``Tagged("type", {"hertz": Section({...}), "hooke": Section({...})})``; the tag is
    kept in the resulting Node. Variants may be given as plain dicts of fields.
    ``default_tag``: the variant of a mapping without the tag key (a form that predates the
    tag stays valid); None makes the tag key required.
    """

    def __init__(self, tag_key, variants, default=REQUIRED, doc="", default_tag=None):
        super().__init__(default, doc)
        self.tag_key = tag_key
        self.default_tag = default_tag
        self.variants = {}
        for tag, section in variants.items():
            if isinstance(section, Mapping):
                section = Section(section)
            if not isinstance(section, Section):
                raise SchemaError(f"variant {tag!r} must be a Section")
            if tag_key in section.fields:
                raise SchemaError(f"variant {tag!r} must not declare the tag key {tag_key!r}")
            self.variants[tag] = section
        self.type_name = f"{tag_key}: " + "|".join(self.variants)

    def validate(self, value, path, ctx):
        if not isinstance(value, Mapping):
            ctx.error(path, f"must be a mapping with a {self.tag_key!r} key", value)
            return _INVALID
        if self.tag_key not in value and self.default_tag is not None:
            return self.variants[self.default_tag].validate_mapping(
                value, path, ctx, skip=(self.tag_key,), first={self.tag_key: self.default_tag})
        if self.tag_key not in value:
            ctx.error(path + (self.tag_key,), "required key is missing",
                      hint=f"one of {_one_of(self.variants)}")
            return _INVALID
        tag = value[self.tag_key]
        if not isinstance(tag, str) or tag not in self.variants:
            ctx.error(path + (self.tag_key,), f"unknown {self.tag_key}", tag,
                      did_you_mean(tag, self.variants) or f"expected one of {_one_of(self.variants)}")
            return _INVALID
        return self.variants[tag].validate_mapping(
            value, path, ctx, skip=(self.tag_key,), first={self.tag_key: tag}
        )

    def describe(self, path=""):
        yield from super().describe(path)
        for tag, section in self.variants.items():
            sub = f"{path}[{self.tag_key}={tag}]"
            yield DocRow(sub, "variant", "", "", section.doc)
            for row in section.describe(sub):
                if row.path != sub:
                    yield row


class Optional(Field):
    """``field`` or nothing: an absent key or ``null`` gives None."""

    def __init__(self, field, doc=None):
        super().__init__(None, field.doc if doc is None else doc)
        self.field = field
        self.unit = field.unit
        self.type_name = f"optional {field.type_name}"

    def validate(self, value, path, ctx):
        if value is None:
            return None
        return self.field.validate(value, path, ctx)

    def describe(self, path=""):
        rows = list(self.field.describe(path))
        if rows and rows[0].path == path:
            first = rows[0]
            rows[0] = first._replace(type=f"optional {first.type}", default="none", doc=self.doc)
        else:
            rows.insert(0, DocRow(path, self.type_name, "", "none", self.doc))
        yield from rows
