"""Record tables: the curves a paper plots, kept as CSV, inside the state, and as PNG.

A :class:`RecordTable` has named columns with units. Rows are appended during a
stage; at the end the table is written as CSV (header ``time[s],kinetic[J],...``),
stored in the State under ``records/<name>`` (one 1-D dataset per column, units in the
group attributes ``columns`` and ``units``) and drawn with matplotlib when installed.
"""

from __future__ import annotations

import numbers
import re

from pathlib import Path

import numpy as np

from demcli.state.atomic import atomic_path, atomic_write_text

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

    def plot(self, path_png, x: str, ys, *, xlabel=None, ylabel=None, title=None,
             logx=False, logy=False, marker=None) -> bool:
        """Draw columns ``ys`` against column ``x`` into a PNG (written atomically).

        Returns False (and writes nothing) when matplotlib is not installed.
        """
        ys = [ys] if isinstance(ys, str) else list(ys)
        for c in [x, *ys]:
            if c not in self.columns:
                raise ValueError(f"record table {self.name!r}: no column {c!r} (columns: {list(self.columns)})")
        arrays = self.to_arrays()
        units = {self.columns[c] for c in ys}
        if ylabel is None:
            ylabel = ys[0] if len(ys) == 1 else ""
            if len(units) == 1 and next(iter(units)):
                ylabel = f"{ylabel} [{next(iter(units))}]".strip()
        return plot_lines(path_png, {c: (arrays[x], arrays[c]) for c in ys},
                          xlabel=xlabel or _header(x, self.columns[x]).replace("[", " [", 1),
                          ylabel=ylabel, title=title if title is not None else self.name,
                          logx=logx, logy=logy, marker=marker)


def plot_lines(path_png, series: dict, *, xlabel="", ylabel="", title="", logx=False, logy=False,
               marker=None) -> bool:
    """Plot ``{label: (x, y)}`` as lines into a PNG with the Agg canvas (no pyplot state).

    Returns False when matplotlib is missing (it is an optional extra).
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return False
    fig = Figure(figsize=(6.4, 4.2), dpi=120)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for label, (xv, yv) in series.items():
        ax.plot(np.asarray(xv, dtype=float), np.asarray(yv, dtype=float), label=label, marker=marker)
    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if title:
        ax.set_title(title)
    if len(series) > 1:
        ax.legend()
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    with atomic_path(path_png) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    return True


__all__ = ["RecordTable", "plot_lines"]
