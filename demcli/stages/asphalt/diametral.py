"""Diametral loading of a bonded specimen between two heads at constant speed: the part the
``idt`` and ``marshall`` stages share (issue #32).

The specimen (a prepared cylinder, group ``bonded_specimen``, or a 2D section of disks) is loaded
along x between walls 0 (fixed) and 1 (moving at the head speed ``speed`` along -x, normal
(-1, 0, 0)). Per record row: the deformation delta = s_0 - (x_1 - x_0), the approach of the two
walls' reference points since the start [m], and the load P = -F_1 . n_1 [N], the particles' push
on the moving head (compression positive). The stage stops when the load has fallen below
``post_peak`` of the peak with at least 1 % of the bonds broken, or at the deformation
``max_deformation`` D. The record ``records/<stage>_<table>`` adds the quasi-static measure E_k / W
(:func:`demcli.stages.asphalt.common.kinetic_to_work`) per row; the warning checks the rows up to
the peak (after it the specimen breaks, which is dynamic at any head speed).
"""

import math

import numpy as np

from demcli.config.schema import Float, Str
from demcli.stages import dem, loop
from demcli.stages.asphalt.common import KINETIC_LIMIT_DOC, TEST_TIME, cylinder_specimen, kinetic_to_work
from demcli.stages.asphalt.common import orientation_field, planar_slab
from demcli.stages.asphalt.common import quasi_static_warning
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

describe_column("kinetic_to_work", "Kinetic energy / work", "1", table=None,
                doc="kinetic energy of the bodies over the loading's work until then (quasi-static below 0.01)")


def declare_outputs(table, title, fields):
    """Declare the record ``table``'s deformation and load columns and the result group
    ``<table>_result`` of scalar ``fields`` [(name, unit, doc)], written by the stage ``table``."""
    describe_column("deformation", "Deformation", "m", "mm", 1e3, table=table, doc="approach of the two heads")
    describe_column("load", "Load", "N", "kN", 1e-3, table=table, doc="force on the moving head, compression positive")
    writer = f"stage {table}"
    register_group(f"{table}_result", title, writer=writer)
    for name, unit, doc in fields:
        register(Field(f"{table}_result/{name}", "f", (), unit, doc, writer=writer))


def loading_fields(speed_doc):
    """The stage keys: a dem stage's (without walls, stop and time) and the loading's."""
    f = {k: v for k, v in dem.FIELDS.items() if k not in ("walls", "stop", "time")}
    f.update({
        "speed": Float("m/s", min=0, min_inclusive=False, doc=speed_doc),
        "max_deformation": Float(min=0, max=0.5, min_inclusive=False, default=0.1,
                                 doc="stop at this approach of the heads, as a share of D"),
        "post_peak": Float(min=0, max=1, default=0.5, doc="stop once the load falls below this share of the peak"),
        "head_material": Str(doc="material of the loading heads"),
        "quasi_static": Float(min=0, min_inclusive=False, default=0.01, doc=KINETIC_LIMIT_DOC),
        "orientation": orientation_field("diametral"),
        "time": TEST_TIME,
    })
    return f


def specimen(ctx, groups, x):
    """(D [m] or None, t [m], base (3,) [m]: centre of the disk's lower face) from the sphere
    centres ``x`` (n, 3) [m]: the 3D cylinder's (a prepare stage's or a cut stage's,
    :func:`demcli.stages.asphalt.common.cylinder_specimen`), or for a 2D section D None (the
    heads' first distance) and t the case's thickness, the base half a thickness below the
    disks' plane."""
    if ctx.case.dimension == 2:
        t, z = planar_slab(ctx.case, x)
        return None, t, np.array([*x[:, :2].mean(axis=0), z - 0.5 * t])
    r, h, base = cylinder_specimen(groups, x, f"stage {ctx.name}")
    return 2.0 * r, h, base


def run_loading(ctx, cfg, state_in, walls, sep0, D, table, extra, result):
    """Integrate the loading between ``walls`` ([fixed, moving] wall nodes) to failure.

    sep0: x_1 - x_0 of the walls' reference points at the start [m]; D: the specimen's diameter [m]
    (the stage's length max_deformation D / speed); table: the record's name; extra: (columns
    {name: unit}, f(P) -> {name: value}) further columns of a row from its load; result(P_max,
    delta_max, E_k / W at the peak) -> (result group dict, log line, rate advice) at the end.
    """
    from demcli.config.schema import Node
    from demcli.state import RecordTable

    dcfg = dict(cfg)
    dcfg.update(walls=walls, stop=None, time=Node({"duration": cfg.max_deformation * D / cfg.speed, "steps": None,
                                                    "dt": cfg.time.dt, "dt_factor": cfg.time.dt_factor}))
    cols = {"deformation": "m", "load": "N", **extra[0]}
    peak = [0.0]

    def row(system):
        p = float(-system.wforce[1] @ system.walls.normal[1])
        peak[0] = max(peak[0], p)
        return {"deformation": sep0 - float(system.wpoint[1, 0] - system.wpoint[0, 0]), "load": p, **extra[1](p)}

    def stop(system, r):
        # only once the specimen is breaking: a loose surface sphere pushed off the head drops the
        # load of the first contacts to zero before the specimen carries any
        broken = r.get("broken_tension", 0) + r.get("broken_shear", 0)
        if peak[0] > 0 and r["load"] < cfg.post_peak * peak[0] and broken >= 0.01 * len(system.bonds):
            return f"load {r['load'] / 1e3:.4g} kN below {cfg.post_peak:g} of the peak {peak[0] / 1e3:.4g} kN"
        return None

    def start(system, ckpt):
        if ckpt is not None:
            peak[0] = float(np.max(RecordTable.from_state(ckpt, "dem").to_arrays()["load"], initial=0.0))

    def finish(ctx_, system, state, tab):
        _finish(ctx_, cfg, state, state_in, tab, cols, table, result)

    return loop.integrate(ctx, Node(dcfg), state_in, loop.Hooks(columns=cols, row=row, stop=stop, start=start,
                                                                 finish=finish))


def _finish(ctx, cfg, state, state_in, table, cols, name, result):
    """The record ``name`` (with E_k / W per row) and the result group ``<name>_result``; the
    quasi-static check on the rows up to the peak."""
    from demcli.state import RecordTable

    rows = table.to_arrays()
    d, p = np.asarray(rows["deformation"]), np.asarray(rows["load"])
    ratio, work = kinetic_to_work(rows["kinetic"], p, d)
    keep = ["time", *cols] + [c for c in ("bonds_intact", "broken_tension", "broken_shear", "intra_intact",
                                          "intra_broken_tension", "intra_broken_shear") if c in rows]
    out = RecordTable(name, {**{c: table.columns[c] for c in keep}, "kinetic_to_work": "1"})
    for k in range(len(rows["time"])):
        out.append({**{c: rows[c][k] for c in keep}, "kinetic_to_work": ratio[k]})
    out.to_state(state)
    ctx.write_records(out, x="deformation", ys=["load"])
    k = int(np.argmax(p))
    group, line, advice = result(p[k], d[k], ratio[k] if work[k] > 0 else math.inf)
    state.groups[f"{name}_result"] = group
    if "bonded_specimen" in state_in.groups:
        state.groups["bonded_specimen"] = dict(state_in.groups["bonded_specimen"])
    ctx.log(line)
    quasi_static_warning(ctx, ratio, work, cfg.quasi_static, advice, upto=k)
