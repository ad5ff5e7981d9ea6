"""Line figures of record columns, drawn as a paper would print them.

Axis labels are words with the unit in parentheses (``Bulk density (g/cm³)``); a
series of few points, or one point per cycle, gets markers (each point is a measurement,
not a curve); count axes get integer ticks; a target is a dashed horizontal line in the
legend; an axis may carry ticks at given values (the sieve sizes of a gradation curve),
upright where they would overlap; a logarithmic axis leaves out the points it cannot
show (a kinetic energy of 0 at t = 0) instead of drawing a drop to the axis edge. Figures are matplotlib ``Figure`` objects on the Agg
canvas (no pyplot state), saved as PNG at :data:`DPI`. matplotlib is an optional
extra: without it the builders return None and nothing is written.
"""

from __future__ import annotations

import numpy as np

from demcli.state.atomic import atomic_path

DPI = 200                  # dots per inch of the PNGs
FIGSIZE = (6.0, 4.0)       # inches
FONT = {"label": 12, "tick": 10, "legend": 10, "title": 11}
MARKER_POINTS = 60         # a series of at most this many points gets markers ("auto") ...
MARKER_COUNTS = 200        # ... and one of whole-number x (cycles, classes) of at most this many

_SUPERSCRIPTS = str.maketrans("0123456789-", "⁰¹²³⁴⁵⁶⁷⁸⁹⁻")


def pretty_unit(unit: str) -> str:
    """A unit as printed: ``g/cm^3`` -> ``g/cm³``, ``N*s/m`` -> ``N·s/m``; '' for '1' and ''."""
    unit = (unit or "").strip()
    if unit in ("", "1"):
        return ""
    out, k = [], 0
    while k < len(unit):
        if unit[k] == "^":
            j = k + 1
            while j < len(unit) and (unit[j].isdigit() or (j == k + 1 and unit[j] == "-")):
                j += 1
            out.append(unit[k + 1:j].translate(_SUPERSCRIPTS))
            k = j
        else:
            out.append("·" if unit[k] == "*" else unit[k])
            k += 1
    return "".join(out)


def axis_label(words: str, unit: str = "") -> str:
    """``Bulk density (g/cm³)`` from words and a unit (no parentheses for a plain number)."""
    shown = pretty_unit(unit)
    words = words[:1].upper() + words[1:]
    return f"{words} ({shown})" if shown else words


def drawable(x, y, logx=False, logy=False):
    """(x, y) as float arrays, less the points a logarithmic axis cannot show (<= 0)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    keep = np.ones(len(x), bool)
    if logx:
        keep &= ~(x <= 0.0)  # NaN stays: it breaks the line where a value is missing
    if logy:
        keep &= ~(y <= 0.0)
    return x[keep], y[keep]


def line_figure(series: dict, *, xlabel="", ylabel="", title="", logx=False, logy=False, marker="auto",
                integer_x=False, integer_y=False, xticks=None, hlines=None):
    """A Figure of ``{legend: (x, y)}`` lines (display units), or None without matplotlib.

    marker: "auto" (circles on a series of at most :data:`MARKER_POINTS` points, or of
    :data:`MARKER_COUNTS` at whole-number x: per-cycle records), a matplotlib marker, or None;
    integer_x / integer_y: integer ticks (counts, cycles); xticks: values that get a tick each,
    labelled as numbers (sieve sizes), instead of the automatic ticks;
    hlines: ``{legend: y}`` dashed horizontal lines (targets). A legend is drawn when there is
    more than one line.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    fig = Figure(figsize=FIGSIZE, dpi=DPI)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    for label, (xv, yv) in series.items():
        xv, yv = drawable(xv, yv, logx, logy)
        if len(xv):
            ax.plot(xv, yv, label=label, marker=_auto_marker(xv) if marker == "auto" else marker, markersize=4,
                    linewidth=1.5)
    for label, value in (hlines or {}).items():
        ax.axhline(value, color="0.25", linestyle="--", linewidth=1.2, label=label)
    _scales_and_ticks(ax, logx, logy, integer_x, integer_y, xticks)
    ax.set_xlabel(xlabel, fontsize=FONT["label"])
    ax.set_ylabel(ylabel, fontsize=FONT["label"])
    ax.tick_params(labelsize=FONT["tick"])
    if title:
        ax.set_title(title, fontsize=FONT["title"])
    if len(ax.get_lines()) > 1:
        ax.legend(fontsize=FONT["legend"])
    ax.grid(True, alpha=0.3)
    if xticks is not None:
        _upright_if_crowded(fig, ax)
    fig.tight_layout()
    return fig


def _upright_if_crowded(fig, ax, gap=2.0):
    """Turn the x tick labels upright where side by side they would overlap (the close sieve
    sizes of an asphalt gradation on a log axis); ``gap`` in pixels."""
    renderer = fig.canvas.get_renderer()
    boxes = sorted((t.get_window_extent(renderer) for t in ax.get_xticklabels() if t.get_text()),
                   key=lambda b: b.x0)
    if any(a.x1 + gap > b.x0 for a, b in zip(boxes, boxes[1:])):
        ax.tick_params(axis="x", labelrotation=90)


def _auto_marker(x):
    """"o" for a series whose points are measurements one by one: few points, or whole-number x
    (per cycle, per class) not too many to tell apart; None for a curve."""
    whole = bool(np.all(np.isfinite(x) & (x == np.round(x))))
    return "o" if len(x) <= MARKER_POINTS or (whole and len(x) <= MARKER_COUNTS) else None


def _scales_and_ticks(ax, logx, logy, integer_x, integer_y, xticks):
    from matplotlib.ticker import MaxNLocator, NullFormatter, NullLocator

    if logx:
        ax.set_xscale("log")
    if logy:
        ax.set_yscale("log")
    if xticks is not None and len(xticks):
        ax.set_xticks(list(xticks), labels=[f"{v:g}" for v in xticks])
        ax.xaxis.set_minor_locator(NullLocator())
        ax.xaxis.set_minor_formatter(NullFormatter())
    elif integer_x and not logx:
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    if integer_y and not logy:
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))


def save_png(fig, path_png) -> bool:
    """Write a Figure as PNG atomically; False (nothing written) for None (no matplotlib)."""
    if fig is None:
        return False
    with atomic_path(path_png) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    return True


__all__ = ["DPI", "MARKER_COUNTS", "MARKER_POINTS", "axis_label", "drawable", "line_figure", "pretty_unit",
           "save_png"]
