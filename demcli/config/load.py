"""Case files: YAML text -> plain data with line marks -> overrides -> validated Node.

``load_yaml`` composes the document with a SafeLoader so every value's line is
known (``marks``: path tuple -> 1-based line of its key, or of the item for list
items), refuses duplicate keys, and turns syntax errors into ``ConfigError`` with
``file:line``. ``apply_overrides`` applies ``--set``-style ``a.b.c=value`` strings.
``validate`` runs a schema and raises ``ConfigError`` listing every issue.

Hostile input is refused before it is built: a file over :data:`MAX_CASE_BYTES`, a
document whose aliases expand to more than :data:`MAX_VALUES` values (a "billion
laughs" alias bomb is 1.4 kB of text), nesting deeper than Python can recurse, and
characters YAML does not allow (NUL, control characters) are each a ConfigError
with the file and line.

Beyond YAML 1.1 as PyYAML reads it, ``1e-5`` (no dot, unsigned exponent) is a float
here, as in YAML 1.2; PyYAML alone would read it as a string.
"""

from __future__ import annotations

import copy
import os
import re
import unicodedata
from pathlib import Path

import yaml
from yaml.nodes import MappingNode, ScalarNode, SequenceNode
from yaml.reader import ReaderError

from demcli.config.schema import NOVALUE, ConfigIssue, format_path, validate_tree
from demcli.errors import ConfigError

__all__ = ["load_yaml", "apply_overrides", "override_path", "validate", "load_case"]

_MERGE_TAG = "tag:yaml.org,2002:merge"

MAX_CASE_BYTES = 1 << 20
"""Largest case file read (1 MiB; the shipped cases are under 10 kB)."""

MAX_VALUES = 100_000
"""Most values (mappings, lists, keys and scalars) a case may expand to, every alias use counted."""


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
    name = filename or str(source)
    try:
        with open(source, "rb") as f:
            raw = f.read(MAX_CASE_BYTES + 1)
        if len(raw) > MAX_CASE_BYTES:
            rule = f"larger than {MAX_CASE_BYTES} bytes; a case file is a few kB of text"
        else:
            return raw.decode("utf-8"), name
    except FileNotFoundError:
        rule = "file not found"
    except IsADirectoryError:
        rule = "is a directory, not a case file"
    except UnicodeDecodeError as exc:
        rule = f"not UTF-8 text (byte {exc.start})"
    except OSError as exc:
        rule = f"cannot read: {exc.strerror or exc}"
    raise ConfigError([ConfigIssue(name, None, "", rule)])


def _bad_character(exc):
    """The character a ReaderError refuses (NUL, a control character, ...), and the rule it breaks."""
    ch = chr(exc.character) if isinstance(exc.character, int) else str(exc.character)
    kind = "control character" if unicodedata.category(ch) == "Cc" else "character"
    return ch, (f"{kind} U+{ord(ch):04X} is not allowed in YAML; delete it (in a double-quoted string it "
                "may be written as an escape)")


def _reader_issue(exc, text, filename):
    """A ConfigIssue at the line and column of the character a ReaderError names."""
    pos = max(0, min(exc.position, len(text)))
    line = text.count("\n", 0, pos) + 1
    column = pos - text.rfind("\n", 0, pos)
    ch, rule = _bad_character(exc)
    return ConfigIssue(filename, line, "", rule, ch, f"column {column}")


def _children(node):
    if isinstance(node, SequenceNode):
        return node.value
    if isinstance(node, MappingNode):
        return [n for pair in node.value for n in pair]
    return ()


def _oversized(root, limit):
    """The first node whose expansion (each alias counted at every use) exceeds ``limit``
    values, or None. Shared nodes are sized once, so an alias bomb costs its text, not its
    expansion; a node that contains itself counts once here (the builder reports it)."""
    size = {}
    stack = [(root, False)]
    while stack:
        node, done = stack.pop()
        if not done:
            if id(node) in size:
                continue
            size[id(node)] = 1  # provisional while its children are sized
            stack.append((node, True))
            stack.extend((child, False) for child in _children(node) if id(child) not in size)
            continue
        total = 1 + sum(size[id(child)] for child in _children(node))
        size[id(node)] = total
        if total > limit:
            return node
    return None


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


def _compose(loader, text, filename):
    """The document's node tree, refused (ConfigError) when it is not YAML or too large."""
    try:
        node = loader.get_single_node()
    except ReaderError as exc:
        raise ConfigError([_reader_issue(exc, text, filename)]) from None
    except yaml.YAMLError as exc:
        raise ConfigError([_yaml_issue(exc, filename)]) from None
    except RecursionError:
        line = loader.get_mark().line + 1
        raise ConfigError([ConfigIssue(filename, line, "", "nested too deeply to read")]) from None
    big = None if node is None else _oversized(node, MAX_VALUES)
    if big is not None:
        raise ConfigError([ConfigIssue(
            filename, big.start_mark.line + 1, "",
            f"this value expands to more than {MAX_VALUES} values (every alias counted at each use: an "
            "alias bomb?); a case needs far fewer")])
    return node


def _parse(text, filename):
    """Compose YAML text into ``(data, marks, issues)``; syntax errors raise ConfigError."""
    try:
        loader = _CaseLoader(text)
    except ReaderError as exc:  # the reader checks every character up front
        raise ConfigError([_reader_issue(exc, text, filename)]) from None
    try:
        node = _compose(loader, text, filename)
        if node is None:
            return None, {}, []
        builder = _Builder(loader, filename)
        builder.marks[()] = node.start_mark.line + 1
        try:
            data = builder.build(node, ())
        except RecursionError:
            raise ConfigError([ConfigIssue(filename, None, "", "nested too deeply to read")]) from None
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
    """An override's value read as YAML; ValueError (with the reason) when it is not YAML."""
    loader = None
    try:
        loader = _CaseLoader(text)  # the reader checks every character up front
        return loader.get_single_data()
    except ReaderError as exc:
        raise ValueError(f"the value is not valid YAML: {_bad_character(exc)[1]}") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"the value is not valid YAML: {getattr(exc, 'problem', None) or exc}") from None
    except RecursionError:
        raise ValueError("the value is nested too deeply to read") from None
    finally:
        if loader is not None:
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


_PATH_TOKEN = re.compile(r"""\.|\[\s*(?:'([^']*)'|"([^"]*)"|([^\]'"]*?))\s*\]|([^.\[\]]+)""")


def override_path(text):
    """The segments of an override path: ``stages.settle.walls[1].max``, ``stages.settle.walls.1.max``
    and ``stages[settle].walls[box].max`` (items by name) all work, as do the paths messages
    print (``materials['a.b']``). Raises ValueError naming what is wrong."""
    segments, pos, want_name = [], 0, True
    while pos < len(text):
        m = _PATH_TOKEN.match(text, pos)
        if m is None:
            raise ValueError(f"unbalanced brackets in path {text!r}")
        if m.group(0) == "." and want_name:
            raise ValueError(f"empty segment in path {text!r}")
        if m.group(0) != ".":
            name = m.group(4)
            if name is not None and not want_name:
                raise ValueError(f"a '.' must come before {name.strip()!r} in path {text!r}")
            seg = (name if name is not None else next(g for g in m.groups()[:3] if g is not None)).strip()
            if not seg:
                raise ValueError(f"empty segment in path {text!r}")
            segments.append(seg)
        want_name = m.group(0) == "."
        pos = m.end()
    if want_name:
        raise ValueError(f"empty segment in path {text!r}")
    return segments


def _list_index(node, seg, path):
    """Index of list item ``seg`` (a number, or an item's ``name``); ValueError if none."""
    if re.fullmatch(r"-?\d+", seg):
        index = int(seg)
        if not -len(node) <= index < len(node):
            raise ValueError(f"{format_path(path) or 'the list'} has {len(node)} items; no index {index}")
        return index % len(node)
    hits = [i for i, item in enumerate(node) if isinstance(item, dict) and item.get("name") == seg]
    if len(hits) != 1:
        names = [item.get("name") for item in node if isinstance(item, dict)]
        names = ", ".join(repr(n) for n in names if n is not None) or "none"
        what = "no item" if not hits else f"{len(hits)} items"
        raise ValueError(f"{format_path(path)} has {what} named {seg!r} (names: {names})")
    return hits[0]


def _set_path(data, marks, parts, value, label):
    """Set ``value`` at the segments ``parts`` of ``data`` (creating missing mapping keys)."""
    node, path = data, ()
    for depth, seg in enumerate(parts):
        if isinstance(node, list):
            step = _list_index(node, seg, path)
        elif isinstance(node, dict):
            step = seg
            if seg not in node and re.fullmatch(r"-?\d+", seg) and int(seg) in node:
                step = int(seg)
        else:
            raise ValueError(f"{format_path(path)} is {_kind(node)}, so it has no {seg!r}")
        if depth == len(parts) - 1:
            node[step] = value
            _label_subtree(marks, path + (step,), value, label)
            return
        child = node.get(step) if isinstance(node, dict) else node[step]
        if child is None and isinstance(node, dict):
            child = node[step] = {}
            marks[path + (step,)] = label
        node, path = child, path + (step,)


def apply_overrides(data, marks, overrides):
    """Apply ``"a.b.c=value"`` overrides; return new ``(data, marks)`` (inputs untouched).

    Segments address mapping keys, list indices (``stages.0.steps`` or ``stages[0].steps``)
    or list items by their ``name`` key (``stages.settle.steps``, ``stages[settle].steps``);
    see :func:`override_path`. The value is read as YAML (``3``, ``"40 kN"``, ``[1, 2]``,
    ``{mu: 0.3}``). Missing mapping keys are created (an unknown key is then reported by
    validation); a missing list item, an index out of range, or a path through a plain value
    is an error right away. All problems are collected into one ConfigError. Values set here
    are marked in ``marks`` with the label ``--set <override>`` instead of a line.
    """
    data = copy.deepcopy(data)
    marks = dict(marks)
    issues = []
    for text in overrides:
        key_text, sep, value_text = text.partition("=")
        try:
            if not sep or not key_text.strip():
                raise ValueError("an override must read path=value, e.g. stages.settle.steps=100")
            parts = override_path(key_text.strip())
            value = _parse_override_value(value_text)
            _set_path(data, marks, parts, value, f"--set {text}")
        except ValueError as exc:
            issues.append(ConfigIssue(f"--set {text}", None, "", str(exc)))
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
