"""Case files: YAML text -> plain data with line marks -> overrides -> validated Node.

``load_yaml`` composes the document with a SafeLoader so every value's line is
known (``marks``: path tuple -> 1-based line of its key, or of the item for list
items), refuses duplicate keys, and turns syntax errors into ``ConfigError`` with
``file:line``. ``apply_overrides`` applies ``--set``-style ``a.b.c=value`` strings.
``validate`` runs a schema and raises ``ConfigError`` listing every issue.

Beyond YAML 1.1 as PyYAML reads it, ``1e-5`` (no dot, unsigned exponent) is a float
here, as in YAML 1.2; PyYAML alone would read it as a string.
"""

from __future__ import annotations

import copy
import os
import re
from pathlib import Path

import yaml
from yaml.nodes import MappingNode, ScalarNode, SequenceNode

from demcli.config.schema import NOVALUE, ConfigIssue, format_path, validate_tree
from demcli.errors import ConfigError

__all__ = ["load_yaml", "apply_overrides", "validate", "load_case"]

_MERGE_TAG = "tag:yaml.org,2002:merge"


class _CaseLoader(yaml.SafeLoader):
    """SafeLoader that also reads ``1e5`` / ``2.5e-3`` as floats."""


_CaseLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


def _yaml_issue(exc, filename):
    """A ConfigIssue from a PyYAML error, with the line of the problem."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    problem = getattr(exc, "problem", None) or str(exc)
    context = getattr(exc, "context", None)
    context_mark = getattr(exc, "context_mark", None)
    rule = f"YAML syntax error: {problem}"
    if context and context_mark is not None and context_mark is not mark:
        rule += f" ({context} at line {context_mark.line + 1})"
    elif context:
        rule += f" ({context})"
    return ConfigIssue(filename, mark.line + 1 if mark is not None else None, "", rule)


def _read(source, filename):
    """Return ``(text, filename)`` for a path or YAML text."""
    is_path = isinstance(source, os.PathLike) or (
        isinstance(source, str)
        and "\n" not in source
        and (source.endswith((".yaml", ".yml")) or os.path.exists(source))
    )
    if not is_path:
        if not isinstance(source, str):
            raise TypeError(f"load_yaml needs a path or YAML text, not {type(source).__name__}")
        return source, filename or "<string>"
    path = Path(source)
    name = filename or str(source)
    try:
        return path.read_text(encoding="utf-8"), name
    except FileNotFoundError:
        rule = "file not found"
    except IsADirectoryError:
        rule = "is a directory, not a case file"
    except UnicodeDecodeError as exc:
        rule = f"not UTF-8 text (byte {exc.start})"
    except OSError as exc:
        rule = f"cannot read: {exc.strerror or exc}"
    raise ConfigError([ConfigIssue(name, None, "", rule)])


class _Builder:
    """Turns a composed node tree into plain data, recording lines and problems."""

    def __init__(self, loader, filename):
        self.loader = loader
        self.filename = filename
        self.marks = {}
        self.issues = []
        self._active = set()

    def issue(self, line, path, rule, value=NOVALUE, hint=None):
        self.issues.append(ConfigIssue(self.filename, line, format_path(path), rule, value, hint))

    def build(self, node, path):
        if isinstance(node, ScalarNode):
            try:
                return self.loader.construct_object(node, deep=True)
            except Exception as exc:
                problem = getattr(exc, "problem", None) or str(exc)
                self.issue(node.start_mark.line + 1, path, f"cannot read value: {problem}")
                return None
        if id(node) in self._active:
            self.issue(node.start_mark.line + 1, path, "recursive alias (a value that contains itself)")
            return None
        self._active.add(id(node))
        try:
            if isinstance(node, SequenceNode):
                out = []
                for i, child in enumerate(node.value):
                    self.marks[path + (i,)] = child.start_mark.line + 1
                    out.append(self.build(child, path + (i,)))
                return out
            return self._mapping(node, path)
        finally:
            self._active.discard(id(node))

    def _pairs(self, node, path, merged=False):
        """``(key_node, value_node, from_merge)`` with ``<<`` merge keys expanded."""
        own, merges = [], []
        for key_node, value_node in node.value:
            if key_node.tag == _MERGE_TAG:
                sources = value_node.value if isinstance(value_node, SequenceNode) else [value_node]
                for src in sources:
                    if not isinstance(src, MappingNode):
                        self.issue(key_node.start_mark.line + 1, path,
                                   "merge key '<<' needs a mapping or a list of mappings")
                        continue
                    if id(src) in self._active:
                        self.issue(key_node.start_mark.line + 1, path, "recursive merge")
                        continue
                    self._active.add(id(src))
                    try:
                        merges.extend(self._pairs(src, path, merged=True))
                    finally:
                        self._active.discard(id(src))
            else:
                own.append((key_node, value_node, merged))
        return own + merges

    def _mapping(self, node, path):
        out = {}
        first_line = {}
        for key_node, value_node, from_merge in self._pairs(node, path):
            line = key_node.start_mark.line + 1
            if not isinstance(key_node, ScalarNode):
                self.issue(line, path, "a mapping key must be a plain value, not a list or mapping")
                continue
            key = self.build(key_node, path)
            try:
                hash(key)
            except TypeError:
                self.issue(line, path, "a mapping key must be a plain value", key)
                continue
            if key in first_line:
                if not from_merge:
                    self.issue(line, path + (key,), "duplicate key",
                               hint=f"first given at line {first_line[key]}")
                continue
            first_line[key] = line
            self.marks[path + (key,)] = line
            out[key] = self.build(value_node, path + (key,))
        return out


def _parse(text, filename):
    """Compose YAML text into ``(data, marks, issues)``; syntax errors raise ConfigError."""
    loader = _CaseLoader(text)
    try:
        try:
            node = loader.get_single_node()
        except yaml.YAMLError as exc:
            raise ConfigError([_yaml_issue(exc, filename)]) from None
        if node is None:
            return None, {}, []
        builder = _Builder(loader, filename)
        builder.marks[()] = node.start_mark.line + 1
        data = builder.build(node, ())
        return data, builder.marks, builder.issues
    finally:
        loader.dispose()


def _kind(value):
    if value is None:
        return "nothing"
    if isinstance(value, list):
        return "a list"
    if isinstance(value, dict):
        return "a mapping"
    return f"a single value ({value!r})"


def load_yaml(path_or_text, filename=None):
    """Read a case into ``(data, marks)``.

    ``path_or_text`` is a path (``os.PathLike``, or a one-line string ending in
    ``.yaml``/``.yml`` or naming an existing file) or YAML text; ``filename`` names
    the source in messages (default: the path, or ``<string>`` for text).
    ``marks`` maps path tuples (``('stages', 2, 'physics')``) to 1-based lines.

    Raises ConfigError for a missing/unreadable file, a YAML syntax error (with its
    line), duplicate keys (all of them), or a top level that is not a mapping.
    """
    text, name = _read(path_or_text, filename)
    data, marks, issues = _parse(text, name)
    if issues:
        raise ConfigError(issues)
    if data is None:
        raise ConfigError([ConfigIssue(name, 1, "", "the case is empty; expected a mapping of keys")])
    if not isinstance(data, dict):
        raise ConfigError([ConfigIssue(name, marks.get((), 1), "",
                                       f"the top level must be a mapping of keys, not {_kind(data)}")])
    return data, marks


def _parse_override_value(text):
    loader = _CaseLoader(text)
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def _label_subtree(marks, path, value, label):
    for key in [k for k in marks if k[: len(path)] == path]:
        del marks[key]
    stack = [(path, value)]
    while stack:
        p, v = stack.pop()
        marks[p] = label
        if isinstance(v, dict):
            stack.extend((p + (k,), item) for k, item in v.items())
        elif isinstance(v, list):
            stack.extend((p + (i,), item) for i, item in enumerate(v))


def apply_overrides(data, marks, overrides):
    """Apply ``"a.b.c=value"`` overrides; return new ``(data, marks)`` (inputs untouched).

    Segments address mapping keys, list indices (``stages.0.steps``) or list items
    by their ``name`` key (``stages.settle.steps``). The value is read as YAML
    (``3``, ``"40 kN"``, ``[1, 2]``, ``{mu: 0.3}``). Missing mapping keys are created
    (an unknown key is then reported by validation); a missing list item, an index
    out of range, or a path through a plain value is an error right away. All
    problems are collected into one ConfigError. Values set here are marked in
    ``marks`` with the label ``--set <override>`` instead of a line.
    """
    data = copy.deepcopy(data)
    marks = dict(marks)
    issues = []

    def fail(text, rule):
        issues.append(ConfigIssue(f"--set {text}", None, "", rule))

    for text in overrides:
        key_text, sep, value_text = text.partition("=")
        key_text = key_text.strip()
        if not sep or not key_text:
            fail(text, "an override must read path=value, e.g. stages.settle.steps=100")
            continue
        parts = key_text.split(".")
        if any(not p.strip() for p in parts):
            fail(text, f"empty segment in path {key_text!r}")
            continue
        try:
            value = _parse_override_value(value_text)
        except yaml.YAMLError as exc:
            fail(text, f"the value is not valid YAML: {getattr(exc, 'problem', None) or exc}")
            continue
        label = f"--set {text}"
        node, path = data, ()
        for depth, raw in enumerate(parts):
            seg = raw.strip()
            last = depth == len(parts) - 1
            if isinstance(node, list):
                if re.fullmatch(r"-?\d+", seg):
                    index = int(seg)
                    if not -len(node) <= index < len(node):
                        fail(text, f"{format_path(path) or 'the list'} has {len(node)} items; "
                                   f"no index {index}")
                        break
                    index %= len(node)
                else:
                    hits = [i for i, item in enumerate(node)
                            if isinstance(item, dict) and item.get("name") == seg]
                    if len(hits) != 1:
                        names = [item.get("name") for item in node if isinstance(item, dict)]
                        names = ", ".join(repr(n) for n in names if n is not None) or "none"
                        what = "no item" if not hits else f"{len(hits)} items"
                        fail(text, f"{format_path(path)} has {what} named {seg!r} (names: {names})")
                        break
                    index = hits[0]
                step = index
            elif isinstance(node, dict):
                step = seg
                if seg not in node and re.fullmatch(r"-?\d+", seg) and int(seg) in node:
                    step = int(seg)
            else:
                fail(text, f"{format_path(path)} is {_kind(node)}, so it has no {seg!r}")
                break
            if last:
                node[step] = value
                _label_subtree(marks, path + (step,), value, label)
            else:
                child = node.get(step) if isinstance(node, dict) else node[step]
                if child is None and isinstance(node, dict):
                    child = node[step] = {}
                    marks[path + (step,)] = label
                node = child
            path = path + (step,)
    if issues:
        raise ConfigError(issues)
    return data, marks


def validate(data, marks, schema, filename=None):
    """Validate ``data`` with ``schema`` into a Node; raise ConfigError with every issue."""
    node, issues = validate_tree(schema, data, marks, filename)
    if issues:
        raise ConfigError(issues)
    return node


def load_case(path, schema, overrides=()):
    """Read, override and validate a case file in one go; returns the validated Node."""
    data, marks = load_yaml(Path(path))
    if overrides:
        data, marks = apply_overrides(data, marks, overrides)
    return validate(data, marks, schema, str(path))
