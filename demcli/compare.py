"""``demcli compare``: overlay one record's curves from several runs in one figure.

The seed-002 figures put the three gradations side by side: bulk density and void
ratio against vibration cycles (Figs. 9-10) and accumulated sleeper settlement against
load cycles (Fig. 12). Each run folder keeps its records as ``records/<stage>_<table>.csv``
(header ``name[unit]``); this module reads the same record from every run and draws
one PNG per column, with a long-format CSV (run, x, y) beside it.
"""

import csv
from pathlib import Path

import numpy as np

from demcli.errors import InputError
from demcli.state.atomic import atomic_write_text
from demcli.state.records import plot_lines

# the papers' figures: record file stem -> [(x column, y columns), ...]
SEED_FIGURES = {"vibrate_cycles": [("cycle", ["bulk_density", "void_ratio"])],          # seed 002, Figs. 9-10
                "sleeper_settlement": [("cycle", ["settlement"])],                       # seed 002, Fig. 12
                "creep_creep": [("time", ["axial_strain"]),                              # seed 003, Fig. 3
                                ("distortional_strain", ["volumetric_strain"])]}         # seed 003, Figs. 4-5


def read_record(path):
    """({column: array}, {column: unit}) of a record CSV written by :class:`RecordTable`."""
    with open(path, newline="") as f:
        rows = list(csv.reader(line for line in f if not line.startswith("#")))
    if not rows:
        raise InputError(f"{path}: empty record file")
    names, units = [], {}
    for h in rows[0]:
        name, _, unit = h.partition("[")
        names.append(name)
        units[name] = unit.rstrip("]")
    data = {n: np.array([float(r[k]) for r in rows[1:]]) for k, n in enumerate(names)}
    return data, units


def compare(runs, record=None, x=None, ys=None, out="compare"):
    """Overlay ``record`` (a file stem such as ``vibrate_cycles``) of every run folder.

    Without ``record``: every record of :data:`SEED_FIGURES` that all runs have.
    Returns the written paths.
    """
    runs = [Path(r) for r in runs]
    for r in runs:
        if not (r / "records").is_dir():
            raise InputError(f"{r}: not a run folder (no records/ inside)")
    todo = {record: [(x, ys)]} if record else {
        k: v for k, v in SEED_FIGURES.items() if all((r / "records" / f"{k}.csv").exists() for r in runs)}
    if not todo:
        raise InputError("the runs share none of the records " + ", ".join(SEED_FIGURES) + "; name one with --record")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for stem, figures in todo.items():
        tables = {}
        for r in runs:
            path = r / "records" / f"{stem}.csv"
            if not path.exists():
                raise InputError(f"{r}: no record {stem} ({path})")
            tables[r.name] = read_record(path)
        for xcol, ycols in figures:
            written += _overlay(out, stem, tables, xcol, ycols)
    return written


def _overlay(out, stem, tables, xcol, ycols):
    """One PNG and one long CSV per y column of ``stem`` from every run's table."""
    written = []
    first, units = next(iter(tables.values()))
    xcol = xcol or next(iter(first))
    ycols = list(ycols) if ycols else [c for c in first if c != xcol]
    for col in [xcol, *ycols]:
        for name, (data, _) in tables.items():
            if col not in data:
                raise InputError(f"run {name}: record {stem} has no column {col!r} (columns: {list(data)})")
    for col in ycols:
        lines = ["run,{}[{}],{}[{}]".format(xcol, units[xcol], col, units[col])]
        for name, (data, _) in tables.items():
            lines += [f"{name},{xv!r},{yv!r}" for xv, yv in zip(data[xcol].tolist(), data[col].tolist())]
        csv_path = out / f"{stem}_{col}.csv"
        atomic_write_text(csv_path, "\n".join(lines) + "\n")
        png = out / f"{stem}_{col}.png"
        plot_lines(png, {name: (data[xcol], data[col]) for name, (data, _) in tables.items()},
                   xlabel=f"{xcol} [{units[xcol]}]" if units[xcol] else xcol,
                   ylabel=f"{col} [{units[col]}]" if units[col] else col, title=stem, marker="o")
        written += [csv_path, png]
    return written
