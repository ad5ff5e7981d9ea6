"""Realisations in a study: one setting run with several seeds, reported as mean and spread.

A DEM answer of a random packing is one draw from the packings its generator makes: two seeds
of the same setting differ by the realisation scatter, which can be as large as the effect of
the knob studied. ``demcli study --realisations seed=1,2,3`` runs every setting of the grid once
per value of that path and this module reduces the runs of a setting to

* n, the mean m, the sample standard deviation s (n - 1 in the denominator) and the standard
  error of the mean s / sqrt(n), the smallest and largest run, the mean wall time;
* the error of the mean against the reference setting's mean, e = m - m_ref, and its
  resolution r = |e| / sqrt(se^2 + se_ref^2): the difference in units of the combined standard
  error of the two means. r >= 2 is reported as resolved (about a 95 % two-sided test for
  normal scatter with several realisations; with n = 3 it is a rough guide, which the report says).

Reports: ``settings.csv`` (full precision), a Markdown table (appended to ``study.md``) and
``settings.png``: the mean with its standard deviation as error bars and every realisation as a
dot, against wall time and, when the first varied value is a number, against it.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from demcli.state.atomic import atomic_path, atomic_write_text

__all__ = ["Setting", "RESOLVED", "aggregate", "write_settings_csv", "settings_markdown", "write_settings_plot"]

RESOLVED = 2.0  # |mean difference| / combined standard error at which a difference counts as resolved


@dataclass
class Setting:
    """The realisations of one setting (the values of the varied paths other than the realisation path)."""

    values: tuple      # value text per non-realisation --vary
    metrics: list      # metric of each realisation that finished (failed ones left out)
    wall_times: list
    runs: int          # realisations run, failed ones included
    error: float = math.nan
    resolution: float = math.nan

    @property
    def n(self):
        return len(self.metrics)

    @property
    def mean(self):
        return float(np.mean(self.metrics)) if self.metrics else math.nan

    @property
    def std(self):
        """Sample standard deviation (NaN below two realisations)."""
        return float(np.std(self.metrics, ddof=1)) if self.n > 1 else math.nan

    @property
    def sem(self):
        """Standard error of the mean, std / sqrt(n)."""
        return self.std / math.sqrt(self.n) if self.n > 1 else math.nan

    @property
    def wall_time(self):
        times = [t for t in self.wall_times if math.isfinite(t)]
        return float(np.mean(times)) if times else math.nan


def aggregate(varies, rows, reference):
    """``(settings, index of the reference setting)`` from a study's rows (grid order).

    ``varies`` are the study's :class:`~demcli.study.Vary` (one has ``realisation`` set),
    ``rows`` its :class:`~demcli.study.Row` list and ``reference`` the reference row's index:
    its setting is the reference. Each setting gets its error and resolution against it.
    """
    keep = [k for k, v in enumerate(varies) if not v.realisation]
    settings = {}
    for row in rows:
        key = tuple(row.variant.values[k] for k in keep)
        s = settings.setdefault(key, Setting(key, [], [], 0))
        s.runs += 1
        if math.isfinite(row.metric):
            s.metrics.append(row.metric)
            s.wall_times.append(row.wall_time)
    out = list(settings.values())
    ref_key = tuple(rows[reference].variant.values[k] for k in keep)
    ref = next(i for i, s in enumerate(out) if s.values == ref_key)
    r = out[ref]
    for s in out:
        s.error = s.mean - r.mean
        combined = math.hypot(s.sem, r.sem)
        s.resolution = abs(s.error) / combined if s is not r and combined > 0 else math.nan
    return out, ref


def _labels(varies):
    return [v.label for v in varies if not v.realisation]


def _realisation(varies):
    return next(v for v in varies if v.realisation)


def write_settings_csv(path, varies, settings, reference, metric_name, unit):
    """``settings.csv``: per setting its varied values, n, mean, std, sem, min, max, error of the mean,
    resolution and mean wall time, at full precision."""
    h = (lambda name: f"{name}[{unit}]") if unit else (lambda name: name)
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow([*_labels(varies), "n", "runs", h(f"{metric_name}_mean"), h("std"), h("sem"), h("min"), h("max"),
                h("error"), "resolution", "wall_time[s]", "reference"])
    for k, s in enumerate(settings):
        lo, hi = (min(s.metrics), max(s.metrics)) if s.metrics else (math.nan, math.nan)
        w.writerow([*s.values, s.n, s.runs, *(repr(float(x)) for x in (s.mean, s.std, s.sem, lo, hi, s.error,
                                                                       s.resolution, s.wall_time)),
                    "yes" if k == reference else ""])
    atomic_write_text(path, buf.getvalue())
    return Path(path)


def _fmt(x, fmt):
    return "" if not math.isfinite(x) else format(x, fmt)


def settings_markdown(varies, settings, reference, metric_name, unit):
    """The settings table in Markdown, with a line on how to read the resolution."""
    real = _realisation(varies)
    u = f" [{unit}]" if unit else ""
    ref = settings[reference]
    lines = [f"Realisations: `{real.path}` = {', '.join(real.values)} per setting; mean and sample standard "
             f"deviation over them; error of the mean against the reference setting "
             f"({', '.join(ref.values) or 'the only one'}); resolution = |error| / combined standard error of "
             f"the two means (>= {RESOLVED:g}: the difference exceeds the realisation scatter; with 3 "
             f"realisations a rough guide).", ""]
    head = [*_labels(varies), "n", f"{metric_name} mean{u}", f"std{u}", f"min{u}", f"max{u}", f"error{u}",
            "resolution", "wall time [s]"]
    lines.append("| " + " | ".join(head) + " |")
    lines.append("|" + "---:|" * len(head))
    for k, s in enumerate(settings):
        lo, hi = (min(s.metrics), max(s.metrics)) if s.metrics else (math.nan, math.nan)
        verdict = "reference" if k == reference else _fmt(s.resolution, ".2g") + (
            " (resolved)" if math.isfinite(s.resolution) and s.resolution >= RESOLVED else "")
        n = f"{s.n}" if s.n == s.runs else f"{s.n} of {s.runs}"
        lines.append("| " + " | ".join([*s.values, n, _fmt(s.mean, ".6g"), _fmt(s.std, ".3g"), _fmt(lo, ".6g"),
                                        _fmt(hi, ".6g"), _fmt(s.error, ".3g"), verdict,
                                        _fmt(s.wall_time, ".1f")]) + " |")
    return "\n".join(lines) + "\n"


def _numbers(texts):
    """The first varied path's values as floats (their leading number), or None if one is not a number."""
    try:
        return [float(str(t).split()[0]) for t in texts]
    except (ValueError, IndexError):
        return None


def _series(varies, settings):
    """{label of the other grid axes' values: [settings]} for the plot's lines (a path varied along
    with the first one is the same axis, so it makes no line of its own)."""
    kept = [v for v in varies if not v.realisation]
    heads = [k for k, v in enumerate(kept) if not v.along and v.group != kept[0].group]
    series = {}
    for s in settings:
        key = ", ".join(f"{kept[k].label}={s.values[k]}" for k in heads)
        series.setdefault(key, []).append(s)
    return series


def write_settings_plot(path_png, case, varies, settings, metric_name, unit):
    """``settings.png``: mean +- standard deviation (bars) and each realisation (dots) against the
    mean wall time, and against the first varied value when it is numeric. False without matplotlib."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return False
    first = [s.values[0] for s in settings] if _labels(varies) else []
    xs = _numbers(first) if first else None
    fig = Figure(figsize=(11.0 if xs else 6.0, 4.4), dpi=150)
    FigureCanvasAgg(fig)
    axes = [fig.add_subplot(1, 2 if xs else 1, k + 1) for k in range(2 if xs else 1)]
    ylabel = f"{metric_name}" + (f" [{unit}]" if unit else "")
    for key, group in _series(varies, settings).items():
        color = None
        for ax, xfun, xlabel in ((axes[0], lambda s: s.wall_time, "wall time per run [s]"),
                                 *(((axes[1], lambda s: xs[settings.index(s)], _labels(varies)[0]),) if xs else ())):
            pts = sorted((s for s in group if s.n and math.isfinite(xfun(s))), key=xfun)
            if not pts:
                continue
            x = np.array([xfun(s) for s in pts])
            line = ax.errorbar(x, [s.mean for s in pts], yerr=[0.0 if not math.isfinite(s.std) else s.std
                                                                for s in pts],
                               marker="o", capsize=4, color=color, label=key or None)
            color = line[0].get_color()
            for xi, s in zip(x, pts):
                ax.plot(np.full(s.n, xi), s.metrics, ".", color=color, alpha=0.5, markersize=5)
            ax.set_xlabel(xlabel)
    spans = [[s.wall_time for s in settings if math.isfinite(s.wall_time)], xs or []]
    for ax, span in zip(axes, spans):
        ax.set_ylabel(ylabel)
        ax.grid(True, which="both", alpha=0.3)
        if span and min(span) > 0 and max(span) / min(span) >= 10:  # a decade or more: log axis
            ax.set_xscale("log")
    real = _realisation(varies)
    fig.suptitle(f"{Path(case).stem}: mean +- standard deviation over {real.label} = {', '.join(real.values)} "
                 "(dots: each realisation)", fontsize=10)
    if len(_series(varies, settings)) > 1:
        axes[0].legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path_png) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    return True
