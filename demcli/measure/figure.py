"""The four-panel figure of a measurement region's record (``records/<stage>_measure_<name>.png``):
mean stress and deviator, coordination, fabric anisotropy and solid fraction against time, with
the axis labels and units the record columns declare (:mod:`demcli.measure.probe`)."""

import numpy as np

from demcli.state.plots import DPI, FONT, axis_label, drawable, save_png

PANELS = (("Stress", ("pressure", "deviator")),
          ("Coordination", ("mean_coordination", "mechanical_coordination")),
          ("Fabric anisotropy", ("anisotropy", "anisotropy_f")),
          ("Solid fraction", ("solid_fraction",)))


def region_figure(table, title=""):
    """A matplotlib Figure (2 x 2 panels against time) of a ``measure_<name>`` RecordTable; None
    without matplotlib."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        return None
    from demcli.state.records import split_labels

    fig = Figure(figsize=(9.0, 6.5), dpi=DPI)
    FigureCanvasAgg(fig)
    data = table.to_arrays()
    xspec = table.spec("time")
    t = data["time"] * xspec.scale
    for k, (words, columns) in enumerate(PANELS):
        ax = fig.add_subplot(2, 2, k + 1)
        specs = [table.spec(c) for c in columns]
        _, legends = split_labels([s.label for s in specs])
        for c, spec, legend in zip(columns, specs, legends):
            xv, yv = drawable(t, np.asarray(data[c], float) * spec.scale)
            ax.plot(xv, yv, label=legend if len(columns) > 1 else None, linewidth=1.5)
        ax.set_ylabel(axis_label(words, specs[0].shown_unit()), fontsize=FONT["label"])
        ax.set_xlabel(xspec.axis_label(), fontsize=FONT["label"])
        ax.tick_params(labelsize=FONT["tick"])
        if len(columns) > 1:
            ax.legend(fontsize=FONT["legend"])
        ax.grid(True, alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=FONT["title"])
    fig.tight_layout()
    return fig


def write_region_figure(table, path_png, title=""):
    """:func:`region_figure` into a PNG (atomically); False without matplotlib."""
    return save_png(region_figure(table, title), path_png)
