"""Dynamic modulus test (AASHTO T 342 style) on a bonded specimen: stage ``dynamic_modulus``.

The specimen (a prepare stage's cylinder, a cut stage's cylinder filled by the mastic stage, or
with ``section: box`` any prism) sits between two frictionless platens normal to its axis z
(``orientation: axial``, the only one it takes; plane walls, as in ``creep``); the top
platen carries a haversine axial stress at each frequency f of ``frequencies`` in turn,

    sigma(t) = sigma_c + sigma_a (1 - cos(2 pi f (t - T_f))) / 2      [Pa, compression positive],

through the wall force motion F(t) = F_0 + F_1 sin(2 pi f (t - T_f) + phi) with
F_0 = (sigma_c + sigma_a / 2) A, F_1 = sigma_a A / 2 and phi = -pi / 2 (A the specimen's section,
T_f the frequency's start). Each frequency runs ``conditioning_cycles`` then ``cycles`` measured
cycles, recorded ``points_per_cycle`` times per cycle of the highest frequency. Over the measured
cycles, stress and axial strain e = 1 - h / H_0 (h the platens' distance, compression positive)
are each fitted by least squares with

    y(t) = a_0 + a_1 t + A cos(w t) + B sin(w t),   w = 2 pi f,

the drift a_1 t taking up the creep under the mean stress. With y = a_0 + a_1 t + Y cos(w t - p),
Y = sqrt(A^2 + B^2), p = atan2(B, A): the dynamic modulus |E*| = Y_sigma / Y_e [Pa] and the phase
angle delta = p_e - p_sigma [deg] (the strain's lag behind the stress).

Quasi-static check: a one-degree-of-freedom estimate of the specimen's axial natural frequency,
f_n = sqrt(|E*| A / H_0 / (m_p + M / 3)) / (2 pi) (m_p the platen's mass, M the specimen's, both
as integrated, mass scaling included); the response to a load at f is amplified by
1 / (1 - (f / f_n)^2), so f / f_n above ``quasi_static_limit`` (0.1: 1 %) is logged as a warning.
Measured beside it, per record row (``records/<stage>_series``): the bodies' kinetic energy over
the platen's work W = A H_0 int sigma de (E_k / W, of order (f / f_n)^2 for a harmonic load),
its largest value over each frequency's measured cycles in the result, and a warning when that
exceeds ``kinetic_limit`` (0.01: the f / f_n = 0.1 of the first check). The conditioning cycles
are left out: the contact stress is applied as a step, whose ringing is what they are for.

2D (``dimension: 2``: the discretized section of seed 001, or any planar bonded set of disks):
the platens are normal to y, in the plane; the specimen is the spheres' bounding box, a
plane-stress slice of the case's ``thickness`` t (no stress out of the plane), so A = width x t,
H_0 its height, and |E*| the slice's in-plane modulus (a plane-strain reading would be
E / (1 - nu^2)). The 2D chain ends unbonded: ``bonds: {create: true, ...}`` bonds it here.

Temperature sets (``temperatures``, :mod:`demcli.stages.asphalt.temperatures`): the whole sweep at
each set's temperature T, each from the stage's input, the Burgers viscosities times a_T (springs
kept: |E*|(f, T) = |E*|(f a_T, T_r) for the bonds) or explicit Burgers elements; from two sets the
sigmoidal master curve log10 |E*| = delta + alpha / (1 + exp(beta + gamma log10 (f a_T))) with its
shift factors (:mod:`demcli.stages.asphalt.master_curve`).
"""

import copy
import functools
import math
import time as _time

import numpy as np

from demcli.config.schema import Float, Int, List, Optional, Section, Str
from demcli.errors import InputError
from demcli.kernels import walls as W
from demcli.stages import dem, loop
from demcli.stages.asphalt.common import TEST_TIME, cylinder_specimen, kinetic_to_work, lab_case_check
from demcli.stages.asphalt.common import orientation_check, orientation_field, planar_slab
from demcli.stages.asphalt import master_curve as mc, temperatures as tsets
from demcli.stages.base import ENGINE_KEEPS, ENGINE_OUTPUT, StageType, register_stage
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

for _name, _label, _unit, _disp, _scale, _table, _doc in [
        ("stress", "Axial stress", "Pa", "kPa", 1e-3, "dem", "top platen's force over the section (compression "
                                                              "positive)"),
        ("modulus", "Dynamic modulus", "Pa", "MPa", 1e-6, "dynamic_modulus",
         "magnitude of E*: stress over strain amplitude")]:
    describe_column(_name, _label, _unit, _disp, _scale, table=_table, doc=_doc)
describe_column("strain", "Axial strain", display="%", scale=100.0, table="dem",
                doc="e = 1 - h / H_0 of the platens' distance (compression positive)")
describe_column("phase_angle", "Phase angle", "deg", table="dynamic_modulus", doc="strain's lag behind the stress")
describe_column("frequency", "Frequency", "Hz", table="dynamic_modulus", doc="loading frequency")

register_group("dynamic_modulus_result", "Dynamic modulus per frequency (AASHTO T 342 style)",
               writer="stage dynamic_modulus")
for _name, _unit, _doc in [("frequency", "Hz", "loading frequencies, in the order run"),
                           ("modulus", "Pa", "dynamic modulus (magnitude of E*) = stress amplitude / strain amplitude"),
                           ("phase_angle", "deg", "lag of the strain behind the stress"),
                           ("frequency_ratio", "1", "f / f_n (quasi-static measure)"),
                           ("kinetic_to_work", "1", "largest kinetic energy / work over the measured cycles "
                                                    "(quasi-static measure)")]:
    register(Field(f"dynamic_modulus_result/{_name}", "f", ("n_freq",), _unit, _doc, writer="stage dynamic_modulus"))
register(Field("dynamic_modulus_result/temperature", "f", ("n_freq",), "degC", "temperature set of each row (only "
               "with temperatures: rows per temperature, each a whole sweep)", writer="stage dynamic_modulus",
               required=False))


def sinusoid_fit(t, y, frequency):
    """Least-squares fit y ~ a_0 + a_1 (t - t_m) + A cos(w t) + B sin(w t), w = 2 pi f [Hz],
    t_m the mean time [s].

    Returns (amplitude sqrt(A^2 + B^2), phase atan2(B, A) [rad] of y = ... + Y cos(w t - p),
    rms residual / amplitude).
    """
    t, y = np.asarray(t, float), np.asarray(y, float)
    w = 2.0 * math.pi * frequency
    m = np.column_stack([np.ones_like(t), t - t.mean(), np.cos(w * t), np.sin(w * t)])
    coef, *_ = np.linalg.lstsq(m, y, rcond=None)
    amp = float(math.hypot(coef[2], coef[3]))
    res = float(np.sqrt(np.mean((m @ coef - y) ** 2)))
    return amp, float(math.atan2(coef[3], coef[2])), res / amp if amp > 0 else math.inf


def complex_modulus(t, stress, strain, frequency):
    """(|E*| [Pa], phase angle [deg], larger of the two fits' residual / amplitude) from stress
    [Pa] and strain [-] series (compression positive) over whole cycles at ``frequency`` [Hz]:
    |E*| = Y_sigma / Y_e, delta = p_e - p_sigma wrapped into (-180, 180]."""
    ys, ps, rs = sinusoid_fit(t, stress, frequency)
    ye, pe, re = sinusoid_fit(t, strain, frequency)
    lag = math.degrees(pe - ps)
    lag = (lag + 180.0) % 360.0 - 180.0
    return ys / ye, (180.0 if lag == -180.0 else lag), max(rs, re)


def schedule(frequencies, n_cycles, records_per_s):
    """First record of each frequency and the total record count: frequency k spans
    ceil(n_cycles r / f_k) record intervals, r [1/s] the records per second."""
    counts = [int(math.ceil(n_cycles * records_per_s / f - 1e-9)) for f in frequencies]
    return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def _fields():
    f = {k: v for k, v in dem.FIELDS.items() if k not in ("walls", "stop", "time")}
    f.update({
        "frequencies": List(Float("Hz", min=0, min_inclusive=False), min_len=1,
                            doc="loading frequencies, run in the order given (AASHTO: high to low)"),
        "stress": Section({"contact": Float("Pa", min=0, doc="sigma_c: the stress between the haversines"),
                           "amplitude": Float("Pa", min=0, min_inclusive=False, doc="sigma_a: peak to trough")},
                          doc="haversine axial stress sigma_c + sigma_a (1 - cos(2 pi f t)) / 2, compression"),
        "conditioning_cycles": Int(min=0, default=2, doc="cycles before the measured ones at each frequency"),
        "cycles": Int(min=5, default=5, doc="measured cycles at each frequency"),
        "points_per_cycle": Int(min=8, default=40, doc="records per cycle of the highest frequency"),
        "platen_material": Str(doc="platen material; make its friction 0"),
        "load_mass": Optional(Float("kg", min=0, min_inclusive=False),
                              doc="mass of the top platen (default: 1 % of the specimen's, as integrated)"),
        "section": Str(choices=("specimen", "box"), default="specimen",
                       doc="specimen: the input's cylinder (a prepare stage's bonded_specimen or a cut stage's "
                           "specimen); box: "
                           "the spheres' bounding box (a prism specimen, e.g. a lattice)"),
        "quasi_static_limit": Float(min=0, min_inclusive=False, default=0.1,
                                    doc="warn when f / f_n exceeds it (f_n: the axial natural frequency)"),
        "orientation": orientation_field("axial"),
        "kinetic_limit": Float(min=0, min_inclusive=False, default=0.01,
                               doc="warn when the kinetic energy exceeds this share of the platen's work on a row of "
                                   "a frequency's measured cycles (0.01: see docs/asphalt_lab.md)"),
        "time": TEST_TIME,
        "temperatures": tsets.TEMPERATURES,
    })
    return f


def specimen_geometry(cfg, state, case):
    """(section area A [m^2], height H_0 [m], centre of the bottom platen (3,) [m], half-extents
    (3,) of the platens [m] (0 along the axis), loading axis: 2 (z) in 3D, 1 (y) in 2D) from the
    3D cylinder (:func:`demcli.stages.asphalt.common.cylinder_specimen`: a prepare stage's
    bonded_specimen or a cut stage's cylinder, whose H_0 and platens are those of its spheres'
    extent along z) or the spheres' bounding box. In 2D the specimen is the section's
    bounding box, a plane-stress slice of the case's thickness t: A = width x t."""
    groups = state.groups
    x = state.sphere_centres()
    r = np.asarray(groups["spheres"]["radius"])
    lo, hi = (x - r[:, None]).min(axis=0), (x + r[:, None]).max(axis=0)
    if case.dimension == 2:
        t, z = planar_slab(case, x)
        half = np.array([0.5 * (hi[0] - lo[0]), 0.0, 0.5 * t])
        return 2 * half[0] * t, float(hi[1] - lo[1]), np.array([0.5 * (lo[0] + hi[0]), lo[1], z]), half, 1
    if cfg.section == "box":
        half = np.r_[0.5 * (hi[:2] - lo[:2]), 0.0]
        return float(4 * half[0] * half[1]), float(hi[2] - lo[2]), np.r_[0.5 * (lo[:2] + hi[:2]), lo[2]], half, 2
    try:
        r0, h0, base = cylinder_specimen(groups, x, "the specimen")
    except InputError as e:
        raise InputError(f"{e}: run a prepare or cut stage first, or give section: box for a prism "
                         "specimen") from None
    if "bonded_specimen" not in groups:  # a cut specimen: platens on its outermost spheres (crossing: keep
        base[2], h0 = lo[2], float(hi[2] - lo[2])  # leaves aggregates standing out of the nominal cylinder)
    return math.pi * r0 * r0, h0, base, np.array([r0, r0, 0.0]), 2


def _walls(cfg, base, h0, half, area, mload, axis):
    """The two platens normal to ``axis``; the top one carries the first frequency's haversine."""
    from demcli.config.schema import Node

    sc, sa = cfg.stress.contact, cfg.stress.amplitude
    up = np.eye(3)[axis]
    top = base + h0 * up
    motion = Node({"mode": "force", "force": (sc + 0.5 * sa) * area, "amplitude": 0.5 * sa * area,
                   "frequency": cfg.frequencies[0], "phase": -0.5 * math.pi, "start": 0.0, "mass": mload,
                   "weight": False})
    return [Node({"type": "plane", "name": "bottom", "point": tuple(base), "normal": tuple(up),
                  "material": cfg.platen_material, "motion": None, "lay_on_particles": None,
                  "extent": tuple(np.r_[base - half, base + half])}),
            Node({"type": "plane", "name": "top", "point": tuple(top), "normal": tuple(-up),
                  "material": cfg.platen_material, "lay_on_particles": None, "motion": motion,
                  "extent": tuple(np.r_[top - half, top + half])})]


class _Loading:
    """The frequency schedule on the record grid: which haversine the top platen carries at
    each record, and the wall-clock time each frequency took."""

    def __init__(self, cfg):
        self.f = np.asarray(cfg.frequencies, float)
        self.n = cfg.conditioning_cycles + cfg.cycles
        self.rate = float(self.f.max() * cfg.points_per_cycle)  # records per second
        self.first = schedule(self.f, self.n, self.rate)
        self.rec_every = 1
        self.clock = {}

    def timing(self, system, dt, dt_crit):
        """dt [s] cut so that a whole number of steps spans each record interval 1 / rate."""
        self.rec_every = max(1, int(math.ceil(1.0 / (self.rate * dt) - 1e-9)))
        return 1.0 / (self.rate * self.rec_every), int(self.first[-1]) * self.rec_every, self.rec_every

    def segment(self, step):
        """The frequency index at this step (the last one at the end)."""
        rec = step // self.rec_every
        return min(int(np.searchsorted(self.first, rec, side="right")) - 1, len(self.f) - 1)

    def apply(self, system):
        """Set the top platen's haversine for the current step's frequency."""
        k = self.segment(system.step)
        system.walls.prm[1, W.W_FREQ] = self.f[k]
        system.walls.prm[1, W.W_START] = self.first[k] / self.rate
        self.clock.setdefault(k, (_time.perf_counter(), system.step))
        return k

    def window(self, k, cond):
        """(t_0, t_1) [s]: the measured cycles of frequency k."""
        t0 = self.first[k] / self.rate
        return t0 + cond / self.f[k], t0 + self.n / self.f[k]


def _results(cfg, load, rows, area, h0, m_eff, ratio):
    """Per-frequency rows: |E*|, phase angle, fit residual, f / f_n, the largest kinetic energy /
    work (``ratio`` per record row) over the measured cycles, steps, wall time."""
    out = []
    t = np.asarray(rows["time"])
    for k, f in enumerate(load.f):
        t0, t1 = load.window(k, cfg.conditioning_cycles)
        tol = 0.25 / load.rate
        sel = (t >= t0 - tol) & (t <= t1 + tol)
        mod, phase, res = complex_modulus(t[sel], rows["stress"][sel], rows["strain"][sel], f)
        fn = math.sqrt(mod * area / h0 / m_eff) / (2.0 * math.pi)
        c0, s0 = load.clock.get(k, (math.nan, 0))  # (a resumed run: the time since it resumed)
        c1, s1 = load.clock.get(k + 1, load.clock["end"])
        out.append({"frequency": f, "modulus": mod, "phase_angle": phase, "fit_residual": res,
                    "frequency_ratio": f / fn, "kinetic_to_work": float(np.nanmax(ratio[sel], initial=0.0)),
                    "steps": int(load.first[k + 1] - load.first[k]) * load.rec_every,
                    "wall_time": c1 - c0, "steps_timed": s1 - s0})
    return out


def run_dynamic_modulus(ctx, cfg, state_in):
    """The stage: one frequency sweep, or with ``temperatures`` one per temperature set, each from
    the stage's input, and the master curve of two or more."""
    if cfg.temperatures is None:
        return _sweep(ctx, cfg, state_in)[0]
    return _temperature_sweeps(ctx, cfg, state_in)


def _sweep(ctx, cfg, state_in, bonds=None):
    """Platens, the haversine schedule, records and the fitted |E*| and phase: (state, result
    rows of :func:`_results`); ``bonds``: :attr:`demcli.stages.loop.Hooks.bonds`."""
    from demcli.config.schema import Node
    from demcli.state import RecordTable

    try:
        area, h0, base, half, axis = specimen_geometry(cfg, state_in, ctx.case)
    except InputError as e:
        raise InputError(f"stage {ctx.name}: {e}") from None
    mspec = float(np.sum(state_in.groups["bodies"]["mass"])) * cfg.scaling.mass
    mload = cfg.load_mass if cfg.load_mass is not None else 0.01 * mspec
    load = _Loading(cfg)
    dcfg = dict(cfg)
    dcfg["walls"] = _walls(cfg, base, h0, half, area, mload, axis)
    dcfg["stop"] = None
    dcfg["time"] = Node({"duration": None, "steps": 1, "dt": cfg.time.dt, "dt_factor": cfg.time.dt_factor})
    cols = {"stress": "Pa", "strain": "1", "frequency": "Hz"}
    n_s = len(state_in.groups["spheres"]["radius"])
    out = []

    def row(system):
        k = load.apply(system)
        h = float(system.wpoint[1, axis] - system.wpoint[0, axis])
        return {"stress": float(-system.wforce[1] @ system.walls.normal[1]) / area, "strain": 1.0 - h / h0,
                "frequency": float(load.f[k])}

    def finish(ctx_, system, state, table):
        load.clock["end"] = (_time.perf_counter(), system.step)
        rows = {k: np.asarray(v) for k, v in table.to_arrays().items()}
        ratio, _ = kinetic_to_work(rows["kinetic"], rows["stress"] * area, rows["strain"] * h0)
        series = RecordTable("series", {"time": "s", "stress": "Pa", "strain": "1", "kinetic_to_work": "1"})
        for k in range(len(rows["time"])):
            series.append({"kinetic_to_work": ratio[k], **{n: rows[n][k] for n in ("time", "stress", "strain")}})
        ctx_.write_records(series, x="time", ys=["strain"])
        res = _results(cfg, load, rows, area, h0, mload + mspec / 3.0, ratio)
        _report(ctx_, cfg, res, n_s)
        t = _result_table(res)
        t.to_state(state)
        ctx_.write_records(t, x="frequency", ys=["modulus", "phase_angle"], logx=True)
        _result_group(state, res)
        for grp in ("bonded_specimen",):
            if grp in state_in.groups:
                state.groups[grp] = dict(state_in.groups[grp])
        out.extend(res)

    hooks = loop.Hooks(columns=cols, row=row, finish=finish, timing=load.timing,
                       start=lambda system, ckpt: load.apply(system), bonds=bonds)
    return loop.integrate(ctx, Node(dcfg), state_in, hooks), out


_RESULT_COLUMNS = {"frequency": "Hz", "modulus": "Pa", "phase_angle": "deg", "fit_residual": "1",
                   "frequency_ratio": "1", "kinetic_to_work": "1", "steps": "1", "wall_time": "s"}
_RESULT_FIELDS = ("frequency", "modulus", "phase_angle", "frequency_ratio", "kinetic_to_work")


def _result_table(res, temperature=False):
    """The ``dynamic_modulus`` record table of result rows (a ``temperature`` column first when
    the rows carry one)."""
    from demcli.state import RecordTable

    t = RecordTable("dynamic_modulus", {**({"temperature": "degC"} if temperature else {}), **_RESULT_COLUMNS})
    for r in res:
        t.append(r)
    return t


def _result_group(state, res, temperature=False):
    """The state group ``dynamic_modulus_result`` of result rows (``temperature``: with that field)."""
    names = (("temperature",) if temperature else ()) + _RESULT_FIELDS
    state.groups["dynamic_modulus_result"] = {n: np.array([r[n] for r in res], float) for n in names}


def _at_temperature(ctx, temperature):
    """The stage context of one temperature set: records, snapshots, log lines and checkpoint
    named ``<stage>_T<T>C``."""
    sub = copy.copy(ctx)
    sub.name = f"{ctx.name}_T{temperature:g}C"
    sub.snapshot_dir = ctx.snapshot_dir.with_name(sub.name)
    sub.checkpoint_path = ctx.checkpoint_path.with_name(f"{ctx.index:02d}-{sub.name}.ckpt.h5")
    sub.lastgood_path = ctx.lastgood_path.with_name(f"{ctx.index:02d}-{sub.name}.lastgood.h5")
    return sub


def _bonds_at(prm, materials, tset, tcfg, names, reference):
    """:func:`demcli.stages.asphalt.temperatures.bond_table_at`, keeping the first table it is
    given (the bonds at T_r) in the list ``reference``."""
    if not reference:
        reference.append(prm.copy())
    return tsets.bond_table_at(prm, materials, tset, tcfg, names)


def _temperature_sweeps(ctx, cfg, state_in):
    """The sweep at each temperature set (:func:`_one_temperature`); the output: the last sweep's
    specimen with the bonds at T_r, the rows of every temperature (records
    ``<stage>_dynamic_modulus``, with temperature) and, from two temperatures, the master curve
    (:func:`_master_curve`)."""
    tc = cfg.temperatures
    rows, applied = [], {}
    for tset in tc.sets:
        applied[float(tset.temperature)] = tsets.log_shift(tset, tc)
        state, res = _one_temperature(ctx, cfg, state_in, tset)
        rows += [{"temperature": float(tset.temperature), **r} for r in res]
    state.meta["stage"] = ctx.name
    table = _result_table(rows, temperature=True)
    table.to_state(state)
    _result_group(state, rows, temperature=True)
    ctx.write_records(table, figure=_sweeps_figure(ctx, table))
    if len(tc.sets) > 1:
        _master_curve(ctx, state, tc, rows, applied)
    return state


def _one_temperature(ctx, cfg, state_in, tset):
    """The sweep at one temperature set from the stage's input (records and snapshots
    ``<stage>_T<T>C_*``): (its state, result rows). Its state, with the bonds at T_r, is kept
    as ``<NN>-<stage>_T<T>C.h5``; a resumed run (``--resume``) takes a kept one of the same
    config and input instead of sweeping again."""
    from demcli.state import RecordTable, read_state, write_state

    sub = _at_temperature(ctx, tset.temperature)
    path = sub.checkpoint_path.with_name(f"{ctx.index:02d}-{sub.name}.h5")
    if ctx.runner.resume and path.exists():
        st = read_state(path)
        if st.meta.get("config_hash") == ctx.config_hash and st.meta.get("input_hash") == ctx.input_hash:
            ctx.log(f"temperature {tset.temperature:g} degC: its sweep taken from {path.name}")
            a = RecordTable.from_state(st, "dynamic_modulus").to_arrays()
            return st, [{k: a[k][i].item() for k in _RESULT_COLUMNS} for i in range(len(a["frequency"]))]
    a_t = 10 ** tsets.log_shift(tset, cfg.temperatures)
    ctx.log(f"temperature {tset.temperature:g} degC: " + (f"Burgers viscosities x a_T = {a_t:.5g}" if tset.models is
                                                           None else f"explicit Burgers elements of "
                                                                     f"{len(tset.models)} material pair(s)"))
    reference = []
    bonds = functools.partial(_bonds_at, tset=tset, tcfg=cfg.temperatures, names=list(ctx.case.materials),
                              reference=reference)
    state, res = _sweep(sub, cfg, state_in, bonds)
    state.groups["bond_models"]["params"] = reference[0]
    ctx.runner.finish_state(state)
    write_state(path, state)
    sub.checkpoint_path.unlink(missing_ok=True)
    ctx.throughput = sub.throughput
    return state, res


def _sweeps_figure(ctx, table):
    """|E*| against f, log-log, one line per temperature (None without matplotlib)."""
    from demcli.state.records import column_figure

    a = table.to_arrays()
    lines = [(f"{t:g} °C", table.spec("modulus"), a["frequency"][a["temperature"] == t],
              a["modulus"][a["temperature"] == t]) for t in dict.fromkeys(a["temperature"].tolist())]
    return column_figure(table.spec("frequency"), lines, logx=True, logy=True, marker="o",
                         title=f"{ctx.runner.name}: {ctx.name}")


def _master_curve(ctx, state, tc, rows, applied):
    """Fit the master curve (:func:`demcli.stages.asphalt.master_curve.fit_master_curve`) to the
    rows; its records (``master_curve`` with the figure, ``shift_factors``, ``master_curve_fit``)
    into the run folder and the state, and a log line of the fit."""
    try:
        curve = mc.fit_master_curve([r["temperature"] for r in rows], [r["frequency"] for r in rows],
                                    [r["modulus"] for r in rows], tc.reference, tc.fit)
    except ValueError as e:  # (the case check refuses too few points; a free fit needs T_r among the sets)
        raise InputError(f"stage {ctx.name}: temperatures: {e}") from None
    pts, shifts, fit = mc.master_curve_tables(curve, rows, applied)
    ctx.write_records(pts, figure=mc.master_curve_figure(curve, pts, shifts, f"{ctx.runner.name}: {ctx.name}"))
    ctx.write_records(shifts, x="temperature", ys=["log_shift_factor", "applied_log_shift_factor"])
    ctx.write_records(fit, figure=None)
    for t in (pts, shifts, fit):
        t.to_state(state)
    d, al, be, ga = curve.sigmoid
    ctx.log(f"master curve at {curve.reference:g} degC ({curve.form} shifts): log10|E*| = {d:.4g} + {al:.4g} / "
            f"(1 + exp({be:.4g} + {ga:.4g} log10 f_r)); log10 a_T " +
            ", ".join(f"{t:g} degC {s:+.4f}" for t, s in zip(curve.temperatures, curve.log_shift)) +
            f"; rms residual {curve.rms:.3g} (log10)")
    for line in mc.superposition_warnings(curve, rows, applied):
        ctx.log(f"warning: {line}")


def _report(ctx, cfg, res, n_s):
    """One log line per frequency (|E*|, phase, fit, f / f_n, particle-steps/s) and the warnings."""
    for r in res:
        timed = r.pop("steps_timed")
        speed = n_s * timed / r["wall_time"] if r["wall_time"] > 0 else math.nan
        ctx.log(f"f = {r['frequency']:g} Hz: |E*| = {r['modulus'] / 1e6:.5g} MPa, phase {r['phase_angle']:.3f} deg, "
                f"fit residual {r['fit_residual']:.2g}, f/f_n = {r['frequency_ratio']:.3g}; {r['steps']} steps, "
                f"{speed:.3g} particle-steps/s")
        if r["frequency_ratio"] > cfg.quasi_static_limit:
            ctx.log(f"warning: f = {r['frequency']:g} Hz is not quasi-static: f/f_n = {r['frequency_ratio']:.3g} > "
                    f"{cfg.quasi_static_limit:g} (inertia amplifies the strain by 1/(1-(f/f_n)^2) = "
                    f"{1.0 / abs(1.0 - r['frequency_ratio'] ** 2):.4g}); lighten the platen or the mass scaling")
        if r["kinetic_to_work"] > cfg.kinetic_limit:
            ctx.log(f"warning: the loading is not quasi-static: kinetic energy {r['kinetic_to_work']:.3g} of the "
                    f"platen's work on the measured cycles at f = {r['frequency']:g} Hz (above {cfg.kinetic_limit:g}); "
                    "lighten the platen or the mass scaling, or lower the frequencies")


def _case_check(cfg, case, k, scene, report):
    """The test stages' rules (:func:`lab_case_check`), the axial orientation and the temperature
    sets' (:func:`demcli.stages.asphalt.temperatures.case_check`)."""
    lab_case_check(cfg, case, k, scene, report, specimen=cfg.section == "specimen")
    orientation_check(cfg, case, k, report, "axial", "the dynamic modulus test")
    if cfg.temperatures is not None:
        tsets.case_check(cfg, case, report)


register_stage(StageType(
    "dynamic_modulus", _fields(), run_dynamic_modulus, needs_input=True,
    provides=ENGINE_OUTPUT + ("dynamic_modulus_result/*",), keeps=ENGINE_KEEPS + ("bonded_specimen",),
    case_check=_case_check, config_requires=dem.config_inputs,
    doc="AASHTO T 342 style dynamic modulus: haversine stress at several frequencies, |E*| and phase angle"))
