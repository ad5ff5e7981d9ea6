"""Record tables: the curves a paper plots, kept as CSV, inside the state, and as PNG.

A :class:`RecordTable` has named columns with units. Rows are appended during a
stage; at the end the table is written as CSV (header ``time[s],kinetic[J],...``, the
values in the units of the header, as stored), stored in the State under
``records/<name>`` (one 1-D dataset per column, units in the group attributes
``columns`` and ``units``) and drawn with matplotlib when installed.

How a column is shown is declared once, beside the code that writes it, with
:func:`describe_column`: words for the axis (``Bulk density``), the unit a paper prints
(g/cm^3, with the factor from the stored kg/m^3), integer ticks for counts, ticks at the
column's values (sieve sizes), and what the column means (docs/records.md is generated
from these declarations by :func:`write_columns_doc`). A column nobody
described is shown by its name in words, in its stored unit.
"""

from __future__ import annotations

import numbers
import re
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from demcli.state.atomic import atomic_write_text
from demcli.state.plots import axis_label, line_figure, pretty_unit, save_png

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_.-]*$")


def _check_name(what, name):
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"{what} {name!r}: use letters, digits, '_', '-', '.' (no '/', no spaces)")


def _header(name, unit):
    return f"{name}[{unit}]" if unit else name


def _fmt(value) -> str:
    if isinstance(value, (numbers.Integral, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return str(int(value))
    return repr(float(value))


def _plain(unit) -> str:
    """'' for a plain number ('1' or ''), else the unit."""
    unit = str(unit or "").strip()
    return "" if unit == "1" else unit


@dataclass(frozen=True)
class Column:
    """How a record column is shown and what it means.

    Attributes:
        label: words for an axis, ``Bulk density``.
        unit: the unit the column is stored in (its CSV header and state attribute).
        display: the unit a plot shows (None: the stored one); shown value = stored x ``scale``.
        scale: factor from the stored unit to ``display``.
        integer: a count (cycles, rounds): integer ticks.
        ticks: ``"values"``: an axis of this column ticks at the column's own values (sieve sizes).
        doc: what the column holds, with its sign convention (docs/records.md).
    """

    label: str
    unit: str = ""
    display: str | None = None
    scale: float = 1.0
    integer: bool = False
    ticks: str | None = None
    doc: str = ""

    def shown_unit(self) -> str:
        """The unit a plot prints."""
        return self.unit if self.display is None else self.display

    def axis_label(self) -> str:
        """``Bulk density (g/cm³)``."""
        return axis_label(self.label, self.shown_unit())


_COLUMNS: dict = {}   # (table or None, name, unit) -> Column
_PATTERNS: dict = {}  # (table or None, suffix, unit) -> (placeholder, Column): names <placeholder>.<suffix>
_PATTERN = re.compile(r"^(<[a-z_]+>)\.([A-Za-z0-9_-]+)$")


def describe_column(name: str, label: str, unit: str = "", display: str | None = None, scale: float = 1.0, *,
                    table: str | None = None, integer: bool = False, ticks: str | None = None,
                    doc: str = "") -> Column:
    """Declare how the record column ``name`` stored in ``unit`` is shown (see :class:`Column`).

    ``table``: only in record tables of that name (the same column name means something
    else elsewhere); None: in every table. ``name`` may be a pattern ``<wall>.force``: it
    matches ``box.x0.force``, and ``<wall>`` in ``label`` becomes ``box.x0``.
    A column is matched by name and stored unit, so a declaration never rescales a column
    stored in another unit.
    """
    if ticks not in (None, "values"):
        raise ValueError(f"record column {name!r}: ticks must be None or 'values', got {ticks!r}")
    spec = Column(label, _plain(unit), display, float(scale), integer, ticks, doc)
    m = _PATTERN.match(name)
    if m:
        _PATTERNS[(table, m.group(2), spec.unit)] = (m.group(1), spec)
    else:
        _check_name("record column", name)
        _COLUMNS[(table, name, spec.unit)] = spec
    return spec


def column_spec(name: str, unit: str = "", table: str | None = None) -> Column:
    """How column ``name`` of record table ``table``, stored in ``unit``, is shown.

    The declaration for that table first, then the one for any table, then a pattern
    ``<...>.<suffix>``; without one, the name in words (``void_ratio`` -> ``Void ratio``)
    in the stored unit.
    """
    unit = _plain(unit)
    for key in ((table, name, unit), (None, name, unit)):
        if key in _COLUMNS:
            return _COLUMNS[key]
    prefix, dot, suffix = name.rpartition(".")
    for key in ((table, suffix, unit), (None, suffix, unit)):
        if dot and key in _PATTERNS:
            placeholder, spec = _PATTERNS[key]
            return replace(spec, label=spec.label.replace(placeholder, prefix))
    return Column(name[:1].upper() + name[1:].replace("_", " "), unit)


def declared_columns() -> list:
    """[(table or None, name, Column)] of every declaration, sorted by table and name."""
    rows = [(t, n, c) for (t, n, _), c in _COLUMNS.items()]
    rows += [(t, f"{ph}.{sfx}", c) for (t, sfx, _), (ph, c) in _PATTERNS.items()]
    return sorted(rows, key=lambda r: (r[0] or "", r[1], r[2].unit))


class RecordTable:
    """A table of numeric rows: ``RecordTable("energy", {"time": "s", "kinetic": "J"})``.

    ``append({"time": 0.1, "kinetic": 2.0})`` adds a row (every column, no others). A
    column whose values are all integers is stored as int64, otherwise float64.
    """

    def __init__(self, name: str, columns: dict):
        _check_name("record table", name)
        if not columns:
            raise ValueError(f"record table {name!r}: needs at least one column")
        for col in columns:
            _check_name(f"record table {name!r}: column", col)
        self.name = name
        self.columns = {str(k): str(v) for k, v in columns.items()}
        self._data = {c: [] for c in self.columns}

    def __len__(self) -> int:
        return len(next(iter(self._data.values())))

    def __repr__(self) -> str:
        return f"RecordTable({self.name!r}, {len(self)} rows, columns={list(self.columns)})"

    def append(self, row: dict | None = None, **values) -> None:
        """Add one row; raises ValueError for a missing, unknown or non-numeric column."""
        row = {**(row or {}), **values}
        missing = [c for c in self.columns if c not in row]
        unknown = [c for c in row if c not in self.columns]
        if missing or unknown:
            parts = ([f"missing {missing}"] if missing else []) + ([f"unknown {unknown}"] if unknown else [])
            raise ValueError(f"record table {self.name!r}: row has " + ", ".join(parts)
                             + f" (columns: {list(self.columns)})")
        for c in self.columns:
            v = row[c]
            if isinstance(v, np.ndarray) and v.size == 1:
                v = v.reshape(()).item()
            if not isinstance(v, (numbers.Real, np.number)) or isinstance(v, (bool, np.bool_)):
                raise ValueError(f"record table {self.name!r}: column {c!r} needs a number, got {v!r}")
            row[c] = v
        for c in self.columns:
            self._data[c].append(row[c])

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Column name -> 1-D array (int64 if every value is an integer, else float64)."""
        out = {}
        for c, vals in self._data.items():
            ints = bool(vals) and all(isinstance(v, (numbers.Integral, np.integer)) for v in vals)
            out[c] = np.asarray(vals, dtype=np.int64 if ints else np.float64)
        return out

    def to_csv_text(self) -> str:
        """The CSV text: header ``name[unit]``, one line per row, full float precision."""
        lines = [",".join(_header(c, u) for c, u in self.columns.items())]
        cols = list(self._data.values())
        for i in range(len(self)):
            lines.append(",".join(_fmt(col[i]) for col in cols))
        return "\n".join(lines) + "\n"

    def write_csv(self, path):
        """Write the table as CSV atomically (full float precision); returns the path."""
        atomic_write_text(path, self.to_csv_text())
        return Path(path)

    def to_state(self, state) -> None:
        """Store as ``records/<name>`` in a State (replacing an older copy)."""
        key = f"records/{self.name}"
        state.groups[key] = self.to_arrays()
        state.group_attrs[key] = {"columns": list(self.columns), "units": list(self.columns.values())}

    @classmethod
    def from_state(cls, state, name: str) -> "RecordTable":
        """The table ``records/<name>`` of a State, to keep appending when a stage resumes."""
        key = f"records/{name}"
        data = state.groups[key]
        attrs = state.group_attrs.get(key, {})
        cols = list(attrs.get("columns") or sorted(data))
        units = list(attrs.get("units") or [""] * len(cols))
        table = cls(name, dict(zip(cols, units)))
        for c in cols:
            table._data[c] = np.asarray(data[c]).tolist()
        return table


    def spec(self, column: str) -> Column:
        """How ``column`` of this table is shown (:func:`column_spec`)."""
        if column not in self.columns:
            raise ValueError(f"record table {self.name!r}: no column {column!r} (columns: {list(self.columns)})")
        return column_spec(column, self.columns[column], self.name)

    def figure(self, x: str, ys, *, targets=None, **style):
        """A matplotlib Figure of columns ``ys`` against column ``x`` (None without matplotlib).

        Axes are labelled from the columns' declarations (:func:`describe_column`) in their
        display units; several columns share the y axis under the words their labels have in
        common (``Kinetic energy``, ``Strain energy``: ``Energy (J)``, legend ``Kinetic``,
        ``Strain``). ``targets``: ``{column: value in its stored unit}``, drawn as dashed lines.
        ``style``: ``xlabel``, ``ylabel`` (words replacing the declared ones), ``title``,
        ``logx``, ``logy``, ``marker`` (:func:`demcli.state.plots.line_figure`).
        """
        ys = [ys] if isinstance(ys, str) else list(ys)
        specs = [self.spec(c) for c in ys]
        arrays = self.to_arrays()
        _, legends = split_labels([s.label for s in specs])
        lines = [(legend, spec, arrays[x], arrays[c]) for legend, spec, c in zip(legends, specs, ys)]
        marks = [(self.spec(c), v) for c, v in (targets or {}).items()]
        return column_figure(self.spec(x), lines, targets=marks, **style)

    def plot(self, path_png, x: str, ys, **style) -> bool:
        """:meth:`figure` into a PNG (written atomically); returns False (and writes nothing)
        when matplotlib is not installed."""
        return save_png(self.figure(x, ys, **style), path_png)


def split_labels(labels):
    """(the words every label has, in the first label's order; each label less those words).

    ``["Kinetic energy", "Strain energy"]`` -> ``("energy", ["Kinetic", "Strain"])``; a label
    that would be left empty stays whole; one label is its own legend; labels without a word
    in common are listed: ``("Flaky, Elongated", ["Flaky", "Elongated"])``.
    """
    if len(labels) < 2:
        return (labels[0] if labels else ""), list(labels)
    words = [label.split() for label in labels]
    common = [w for w in words[0] if all(w.lower() in {v.lower() for v in ws} for ws in words[1:])]
    if not common:
        return ", ".join(labels), list(labels)
    drop = {w.lower() for w in common}
    rest = [" ".join(w for w in ws if w.lower() not in drop) for ws in words]
    return " ".join(common), [_capitalized(r) if r else label for r, label in zip(rest, labels)]


def _capitalized(words: str) -> str:
    """First letter up when the first word is a word (``lost to friction``), not a name or a
    symbol (``box.x0``, ``x``)."""
    first = words.split()[0]
    return words[:1].upper() + words[1:] if first.isalpha() and len(first) > 1 else words


def column_figure(xspec: Column, lines, *, targets=(), xlabel=None, ylabel=None, **style):
    """A Figure of record columns in their display units (None without matplotlib).

    lines: ``[(legend, y Column, x values, y values)]`` in stored units; targets:
    ``[(Column, value in its stored unit)]``, dashed lines labelled ``Target 1.55 g/cm³``.
    The y axis takes the words the lines' labels share (or ``ylabel``) and their display unit
    when they have one; the x axis ``xlabel`` or ``xspec``'s words; integer ticks for counts
    (an integer column or a declared one), ticks at the x values for ``ticks="values"``.
    ``style``: ``title``, ``logx``, ``logy``, ``marker`` of :func:`demcli.state.plots.line_figure`.
    """
    yspecs = [spec for _, spec, _, _ in lines]
    units = {spec.shown_unit() for spec in yspecs}
    words = ylabel if ylabel is not None else split_labels(list(dict.fromkeys(s.label for s in yspecs)))[0]
    series = {legend: (np.asarray(xv, float) * xspec.scale, np.asarray(yv, float) * spec.scale)
              for legend, spec, xv, yv in lines}
    if len(units) > 1:  # no unit for the axis: each legend carries its own
        series = {f"{k} ({spec.shown_unit()})": v for (k, v), spec in zip(series.items(), yspecs)}
    hlines = {f"Target {v * spec.scale:.4g} {pretty_unit(spec.shown_unit())}".strip(): v * spec.scale
              for spec, v in targets}
    ticks = None
    if xspec.ticks == "values":
        xs = np.concatenate([v[0] for v in series.values()]) if series else np.empty(0)
        ticks = np.unique(xs[np.isfinite(xs) & ((xs > 0) if style.get("logx") else True)])
    return line_figure(series, xlabel=xlabel if xlabel is not None else xspec.axis_label(),
                       ylabel=axis_label(words, units.pop() if len(units) == 1 else ""),
                       integer_x=xspec.integer or all(_integers(xv) for _, _, xv, _ in lines),
                       integer_y=all(s.integer for s in yspecs) or all(_integers(yv) for _, _, _, yv in lines),
                       xticks=ticks, hlines=hlines, **style)


def _integers(values) -> bool:
    """True for a non-empty array of integer dtype."""
    a = np.asarray(values)
    return a.size > 0 and np.issubdtype(a.dtype, np.integer)


# ---------------------------------------------------------------------------------------
# the columns of the dem loop's tables (``dem`` and ``walls``), written by every dynamic stage
# ---------------------------------------------------------------------------------------

describe_column("time", "Time", "s", doc="simulated time since the stage began")
describe_column("step", "Step", integer=True, doc="time steps since the stage began")
describe_column("kinetic", "Kinetic energy", "J", doc="translational + rotational kinetic energy of the bodies "
                "(scaled masses: docs/scaling.md)")
describe_column("contacts", "Particle contacts", integer=True, doc="particle-particle contacts")
describe_column("wall_contacts", "Wall contacts", integer=True, doc="particle-wall contacts")
describe_column("coordination", "Coordination number", doc="(2 x contacts + wall contacts) / bodies")
describe_column("porosity", "Porosity", doc="1 - solid volume / bulk volume")
for _name, _label, _doc in [
        ("strain", "Strain energy", "elastic energy stored in the contacts"),
        ("gravity", "Potential energy", "gravitational potential energy (relative to the start)"),
        ("damping", "Energy lost to local damping", "work of the local (Cundall) damping forces, accumulated"),
        ("friction", "Energy lost to friction", "work of the sliding friction forces, accumulated"),
        ("body_damping", "Energy lost to body damping", "work of the mass-proportional damping, accumulated"),
        ("wall_work", "Work done by the walls", "work the moving walls did on the particles, accumulated"),
        ("total", "Total energy", "kinetic + strain + potential + losses - wall work: constant up to the "
                                  "integration error (docs/stability.md)")]:
    describe_column(_name, _label, "J", table="dem", doc=_doc)
describe_column("alpha", "Mass-proportional damping", "1/s", table="dem",
                doc="coefficient alpha of the adaptive mass-proportional damping")
for _name, _label in [("bonds_intact", "Intact bonds"), ("broken_tension", "Bonds broken in tension"),
                      ("broken_shear", "Bonds broken in shear"), ("bonds_seated", "Broken bonds seated")]:
    describe_column(_name, _label, integer=True, table="dem", doc="bond count (docs/bonds.md)")
for _name, _label in [("intra_intact", "Intact bonds inside aggregates"),
                      ("intra_broken_tension", "Bonds inside aggregates broken in tension"),
                      ("intra_broken_shear", "Bonds inside aggregates broken in shear")]:
    describe_column(_name, _label, integer=True, doc="bonded aggregates: bonds between the lattice balls of one "
                                                     "aggregate (docs/asphalt_lab.md, 'Bonded aggregates'); also "
                                                     "in the bond counts of all bonds")
describe_column("<wall>.position", "Wall <wall> position", "m", "mm", 1e3, table="walls",
                doc="point . n, n the wall's unit normal pointing into the domain: the plane's signed "
                    "coordinate along n, growing as the wall moves into the domain (box face x0 at x = a: +a; "
                    "x1 at x = b: -b; the box width is -(x0 + x1)); a cylinder's n is its axis, so this is "
                    "the axial position of its axis point (its radius is walls/radius in the state); a mesh "
                    "wall's n is its `normal` (servo and force direction), point its first vertex")
describe_column("<wall>.force", "Wall <wall> force", "N", table="walls",
                doc="-F . n, F the total force of the particles on the wall: the normal force with which "
                    "the particles press the wall outwards, positive in compression (a wall holding the "
                    "specimen in); a cylinder's n is its axis, so this is the axial (friction) force, not "
                    "the radial pressure; a mesh wall's F sums all its contacts")


# ---------------------------------------------------------------------------------------
# docs/records.md
# ---------------------------------------------------------------------------------------

DOC_BEGIN = "<!-- record columns: generated by demcli.state.records.write_columns_doc(); do not edit by hand -->"
DOC_END = "<!-- end of record columns -->"


def columns_markdown() -> str:
    """The table of every declared record column (as registered so far), as Markdown."""
    lines = ["| table | column | stored unit | plotted as | meaning |", "|---|---|---|---|---|"]
    for table, name, c in declared_columns():
        shown = c.axis_label() + (", integer ticks" if c.integer else "") + (
            ", a tick at each value" if c.ticks == "values" else "")
        doc = c.doc.replace("|", "\\|")
        lines.append(f"| {table or 'any'} | `{name}` | {c.unit or '1'} | {shown} | {doc} |")
    return "\n".join(lines) + "\n"


def write_columns_doc(path="docs/records.md") -> None:
    """Regenerate the column table of docs/records.md from the declarations of every module
    (:func:`demcli.state.fields.register_all` imports them). Run in the repository root:
    ``python -c "from demcli.state.records import write_columns_doc; write_columns_doc()"``."""
    from demcli.state.fields import register_all

    register_all()
    text = Path(path).read_text(encoding="utf-8")
    head, rest = text.split(DOC_BEGIN, 1)
    _, tail = rest.split(DOC_END, 1)
    atomic_write_text(path, head + DOC_BEGIN + "\n" + columns_markdown() + DOC_END + tail)


__all__ = ["Column", "RecordTable", "column_figure", "column_spec", "columns_markdown", "declared_columns",
           "describe_column", "split_labels", "write_columns_doc"]
