"""Value rules of the field registry: what the numbers of a field must satisfy besides its
dtype and shape.

A :class:`~demcli.state.fields.Field` declares them (``finite``, ``positive``,
``unit_rows``, ``unique``, ``index_of``); :func:`value_problems` checks one field's array
against them. Each rule is one vectorised numpy pass over the whole array and reports the
first offending row with its value and how many rows break the rule, so a state of
300 000 balls is checked in milliseconds.
"""

from __future__ import annotations

import numpy as np

UNIT_TOL = 1e-6
"""How far the Euclidean norm of a row of a ``unit_rows`` field may lie from 1."""


def _text(value) -> str:
    """A value of a row as short text: numbers in ``%.6g``, vectors in brackets."""
    arr = np.asarray(value)
    if arr.ndim:
        return "[" + ", ".join(_text(v) for v in arr) + "]"
    if arr.dtype.kind == "f":
        return f"{float(arr):.6g}"
    return str(arr.item())


def _failed(path, rule, arr, ok, detail=None):
    """The problem of the rows of ``arr`` where ``ok`` (one flag per element) is false, or
    None when it is all true (the usual case: one pass); ``detail(row)`` adds a note to the
    first offending row's value."""
    if ok.all():
        return None
    rows = np.flatnonzero(~ok.reshape(len(ok), -1).all(axis=1))
    first = int(rows[0])
    value = _text(arr[first])
    if detail is not None:
        value += f" ({detail(first)})"
    count = f"; {len(rows)} of {len(arr)} rows break it" if len(rows) > 1 else ""
    return f"field {path!r} must be {rule}: row {first} holds {value}{count}"


def _unit_problem(path, arr):
    norm = np.sqrt(np.einsum("ij,ij->i", arr, arr)) if arr.ndim == 2 else np.abs(arr)
    return _failed(path, f"a unit vector (|norm - 1| <= {UNIT_TOL:g})", arr, np.abs(norm - 1.0) <= UNIT_TOL,
                   lambda row: f"norm {norm[row]:.9g}")


def _unique_problem(path, arr):
    order = np.argsort(arr, kind="stable")
    ranked = arr[order]
    same = ranked[1:] == ranked[:-1]
    if not same.any():
        return None
    k = int(np.flatnonzero(same)[0])
    a, b = sorted((int(order[k]), int(order[k + 1])))
    count = f"; {int(same.sum())} repeats" if same.sum() > 1 else ""
    return f"field {path!r} must be unique: rows {a} and {b} both hold {_text(arr[a])}{count}"


def index_problem(path, arr, symbol, size):
    """The problem of an index field whose values leave ``[0, size)``, or None."""
    flat = np.atleast_1d(arr)
    return _failed(path, f"in [0, {symbol}={size})", flat, (flat >= 0) & (flat < size))


def value_problems(fld, arr) -> list[str]:
    """The problems of ``arr`` (already of the field's dtype kind and rank) against the
    value rules of ``fld`` other than ``index_of`` (see :func:`index_problem`)."""
    if not arr.size:
        return []
    flat = np.atleast_1d(arr)
    problems = []
    if fld.finite:
        problems.append(_failed(fld.path, "finite", flat, np.isfinite(flat)))
    if fld.positive:
        problems.append(_failed(fld.path, "> 0", flat, flat > 0))
    if fld.unit_rows:
        problems.append(_unit_problem(fld.path, flat))
    if fld.unique:
        problems.append(_unique_problem(fld.path, flat))
    return [p for p in problems if p]
