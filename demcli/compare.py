"""``demcli compare``: overlay one record's curves from several runs in one figure.

The seed-002 figures put the three gradations side by side: bulk density and void
ratio against vibration cycles (Figs. 9-10) and accumulated sleeper settlement against
load cycles (Fig. 12). Each run folder keeps its records as ``records/<stage>_<table>.csv``
(header ``name[unit]``); this module reads the same record from every run and draws
one PNG per column, with a long-format CSV (run, x, y) beside it. That CSV can come back
as ``earlier`` curves (``--with``): runs whose folders are gone, or were made elsewhere,
stay in the figures without their run folders.
"""

import csv
from pathlib import Path

import numpy as np

from demcli.errors import InputError
from demcli.state.atomic import atomic_write_text
from demcli.state.plots import save_png
from demcli.state.records import column_figure, column_spec

# the papers' figures: record file stem -> [(x column, y columns), ...]
SEED_FIGURES = {"vibrate_cycles": [("cycle", ["bulk_density", "void_ratio"])],          # seed 002, Figs. 9-10
                "sleeper_settlement": [("cycle", ["settlement"])],                       # seed 002, Fig. 12
                "creep_creep": [("time", ["axial_strain"]),                              # seed 003, Fig. 3
                                ("distortional_strain", ["volumetric_strain"])]}         # seed 003, Figs. 4-5
# what the papers' figures print besides the columns' own labels: record file stem -> style
SEED_STYLE = {"vibrate_cycles": {"xlabel": "Vibration cycle",                           # seed 002
                                 "targets": {"bulk_density": 1550.0}}}  # kg/m^3: where the plate is removed


def _columns(header):
    """([name, ...], {name: unit}) of CSV headers written as ``name[unit]``."""
    names, units = [], {}
    for h in header:
        name, _, unit = h.partition("[")
        names.append(name)
        units[name] = unit.rstrip("]")
    return names, units


def read_record(path):
    """({column: array}, {column: unit}) of a record CSV written by :class:`RecordTable`."""
    with open(path, newline="") as f:
        rows = list(csv.reader(line for line in f if not line.startswith("#")))
    if not rows:
        raise InputError(f"{path}: empty record file")
    names, units = _columns(rows[0])
    data = {n: np.array([float(r[k]) for r in rows[1:]]) for k, n in enumerate(names)}
    return data, units


def read_long(path):
    """Curves of a long CSV written by :func:`compare`: (x column, y column, {column: unit}, {run: (x, y)})."""
    path = Path(path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or len(rows[0]) != 3 or rows[0][0] != "run":
        raise InputError(f"{path}: not a demcli compare CSV (header must be run,x[unit],y[unit]; "
                         f"got {','.join(rows[0]) if rows else 'an empty file'})")
    cols, units = _columns(rows[0][1:])
    curves = {}
    for line, r in enumerate(rows[1:], start=2):
        try:
            xv, yv = float(r[1]), float(r[2])
        except (IndexError, ValueError):
            raise InputError(f"{path}, line {line}: expected run,x,y with numbers; got {','.join(r)}") from None
        curves.setdefault(r[0], ([], []))
        curves[r[0]][0].append(xv)
        curves[r[0]][1].append(yv)
    return cols[0], cols[1], units, {k: (np.array(a), np.array(b)) for k, (a, b) in curves.items()}


def compare(runs, record=None, x=None, ys=None, out="compare", earlier=()):
    """Overlay ``record`` (a file stem such as ``vibrate_cycles``) of every run folder.

    Without ``record``: every record of :data:`SEED_FIGURES` that all runs have. ``ys``: the y
    columns, each item a name or a comma list (``["a,b", "c"]``); none: all but x.
    ``earlier``: long CSVs of a previous comparison; each joins the figure with its x and y
    columns, its curves drawn first (a name that a run folder or an earlier file also has gets
    the file's name appended). Returns the written paths.
    """
    runs = [Path(r) for r in runs]
    ys = [c.strip() for y in ys or () for c in y.split(",") if c.strip()]
    earlier = [(Path(p), *read_long(p)) for p in earlier]
    for r in runs:
        if not (r / "records").is_dir():
            raise InputError(f"{r}: not a run folder (no records/ inside)")
    todo = {record: [(x, ys)]} if record else {
        k: v for k, v in SEED_FIGURES.items() if all((r / "records" / f"{k}.csv").exists() for r in runs)}
    if not todo:
        raise InputError("the runs share none of the records " + ", ".join(SEED_FIGURES) + "; name one with --record")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written, used = [], set()
    for stem, figures in todo.items():
        tables = {}
        for r in runs:
            path = r / "records" / f"{stem}.csv"
            if not path.exists():
                raise InputError(f"{r}: no record {stem} ({path})")
            tables[r.name] = read_record(path)
        for xcol, ycols in figures:
            written += _overlay(out, stem, tables, xcol, ycols, earlier, used)
    for path, xcol, ycol, *_ in earlier:
        if path not in used:
            raise InputError(f"{path}: its curves ({ycol} against {xcol}) belong to none of the figures drawn "
                             f"({', '.join(todo)})")
    return written


def _overlay(out, stem, tables, xcol, ycols, earlier, used):
    """One PNG and one long CSV per y column of ``stem``: the matching ``earlier`` curves, then every run's."""
    written = []
    first, units = next(iter(tables.values()))
    xcol = xcol or next(iter(first))
    ycols = list(ycols) if ycols else [c for c in first if c != xcol]
    for col in [xcol, *ycols]:
        for name, (data, _) in tables.items():
            if col not in data:
                raise InputError(f"run {name}: record {stem} has no column {col!r} (columns: {list(data)})")
    for col in ycols:
        series = {}
        for path, ex, ey, eunits, curves in earlier:
            if (ex, ey) != (xcol, col):
                continue
            if (eunits[ex], eunits[ey]) != (units[xcol], units[col]):
                raise InputError(f"{path}: units [{eunits[ex]}], [{eunits[ey]}] differ from the runs' "
                                 f"[{units[xcol]}], [{units[col]}] for {col} against {xcol}")
            used.add(path)
            for name, xy in curves.items():  # a name already taken gets its file's name appended
                series[name if name not in tables and name not in series else f"{name} ({path.name})"] = xy
        series.update({name: (data[xcol], data[col]) for name, (data, _) in tables.items()})
        lines = ["run,{}[{}],{}[{}]".format(xcol, units[xcol], col, units[col])]
        for name, (xv, yv) in series.items():
            lines += [f"{name},{a!r},{b!r}" for a, b in zip(xv.tolist(), yv.tolist())]
        csv_path = out / f"{stem}_{col}.csv"
        atomic_write_text(csv_path, "\n".join(lines) + "\n")
        png = out / f"{stem}_{col}.png"
        save_png(overlay_figure(stem, series, xcol, col, units), png)
        written += [csv_path, png]
    return written


def overlay_figure(stem, series, xcol, col, units):
    """The Figure of column ``col`` against ``xcol`` of record ``stem``, one line per entry of
    ``series`` (``{name: (x, y)}`` in the units ``units`` of the CSV): labelled as the record's own
    plots are (the words and display units the stages declare), with the seed figure's axis words
    and target line (:data:`SEED_STYLE`). None without matplotlib."""
    style = SEED_STYLE.get(stem, {})
    spec = _spec(stem, col, units[col])
    targets = [(spec, v) for c, v in style.get("targets", {}).items() if c == col]
    lines = [(name, spec, xv, yv) for name, (xv, yv) in series.items()]
    return column_figure(_spec(stem, xcol, units[xcol]), lines, targets=targets, xlabel=style.get("xlabel"),
                         title=stem)


def _spec(stem, col, unit):
    """How ``col`` of the record file ``stem`` (``<stage>_<table>``, either may hold '_') is shown:
    the declaration for the longest table name the stem ends with, else the general one."""
    from demcli.stages.base import load_stage_types

    load_stage_types()  # the stage modules declare their columns
    parts = stem.split("_")
    general = column_spec(col, unit)
    for k in range(1, len(parts)):
        spec = column_spec(col, unit, "_".join(parts[k:]))
        if spec != general:
            return spec
    return general
