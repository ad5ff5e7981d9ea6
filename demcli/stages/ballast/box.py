"""Ballast box stages (seed 002, Shao, Lian & Yang 2017, sec. 4): ``deposit``, ``vibrate``, ``sleeper``.

All three run the body engine through the ``dem`` stage loop
(:func:`demcli.stages.loop.integrate`) and take every key of a ``dem`` stage
(physics, contact, walls, time, output, neighbors, scaling, safety); their walls must
include one ``box`` wall, the ballast box. They carry the ``gradation`` and ``library``
groups of their input forward, so that a later stage can draw more ballast.

The bed may be polyhedra, clumps of spheres (``clumpify``) or spheres: the plate and the
sleeper are polyhedral actors either way, so on a sphere or clump bed the loaded stages run a
mixed scene (:mod:`demcli.engine.mixed_shape`). The shoulders are filled with polyhedra, so
a sphere or clump bed takes ``shoulders.fill: false``. The bed's top is the highest vertex
of a polyhedron or the top of a sphere (:func:`top_points`).

Bed measures (:func:`bed_measures`), with M the particles' mass (volume x material
density, never the scaled mass; a clump's mass is its polyhedron's), A the box floor area
and h a bed height:
bulk density rho_b = M / (A h); porosity n = 1 - rho_b / rho_s with rho_s the mass-
weighted particle density; void ratio e = n / (1 - n).

* ``deposit``: gravity deposition until the bed is at rest (``stop.kinetic_ratio``,
  required). h = the mean over a grid of columns (cells of the median particle size)
  of the highest particle point in each column: the height a plate laid on the bed
  would rest at, smoothed over the peaks. Group ``bed``.
* ``vibrate``: a cuboid plate (an actor, :mod:`demcli.engine.actors`) laid on the bed
  and loaded by F(t) = F_min + (F_max - F_min)(1 - cos 2 pi f t)/2 on top of its
  weight (seed: 0-40 kN at 10 Hz); h = the plate's underside (the bed under the
  plate, as the seed measures it). Per cycle (at each cycle's end, load at F_min):
  plate position, bulk density, porosity, void ratio (records ``<stage>_cycles``,
  CSV and PNG). Stops after ``cycles`` or at the first cycle end with
  rho_b >= ``target_density`` (seed: 1.55 g/cm^3, where the plate is removed).
* ``sleeper``: the plate is removed; a sleeper (a cuboid actor) is set on the bed;
  its shoulders (the box beside it, up to ``shoulders.height``, default the sleeper's
  top) are filled with ballast drawn from the library with the gradation of the case,
  enough for ``shoulders.bulk_density``, stacked loosely above the bed by the
  assembly's drop placement; during ``load.settle`` the sleeper carries F_min while
  the shoulder ballast falls into place; then the load cycles between F_min and
  F_max (seed: 3-80 kN at 10 Hz, 80 cycles). Per cycle: the sleeper's accumulated
  settlement (its descent since the cycles began) and its position (records
  ``<stage>_cycles``).

The three stages of the seed's cases overlay into the paper's figures with
``demcli compare`` (:mod:`demcli.compare`).
"""

import math

import numpy as np

from demcli.config.schema import Bool, Float, Int, Node, Optional, Section, Str, Vector
from demcli.errors import InputError
from demcli.stages import dem, loop
from demcli.stages.base import ENGINE_KEEPS, ENGINE_OUTPUT, StageType, has_field, register_stage
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

register_group("bed", "Ballast bed measures at the end of a ballast box stage (seed 002)",
               writer="stages deposit, vibrate, sleeper")
for _name, _unit, _doc in [("height", "m", "bed height h used for the bulk density"),
                           ("bulk_density", "kg/m^3", "particle mass / (box floor area x h)"),
                           ("porosity", "1", "1 - bulk density / particle density"),
                           ("void_ratio", "1", "porosity / (1 - porosity)"),
                           ("particle_mass", "kg", "mass of the ballast particles")]:
    register(Field(f"bed/{_name}", "f", (), _unit, _doc, writer="stages deposit, vibrate, sleeper"))

describe_column("height", "Bed height", "m", "mm", 1e3, table="dem", doc="bed height h used for the bulk density")
describe_column("bulk_density", "Bulk density", "kg/m^3", "g/cm^3", 1e-3,
                doc="particle mass / (box floor area x bed height)")
describe_column("void_ratio", "Void ratio", doc="porosity / (1 - porosity)")
describe_column("cycle", "Load cycle", integer=True,
                doc="load cycles since the cycles began: whole in the per-cycle tables (each at its end, "
                    "load at F_min), fractional in the dem tables (negative while settling)")
describe_column("cycle", "Sleeper cycle", integer=True, table="settlement", doc="sleeper load cycles")
describe_column("plate", "Plate height", "m", "mm", 1e3, doc="height z of the plate's centre (up positive)")
describe_column("sleeper", "Sleeper height", "m", "mm", 1e3, doc="height z of the sleeper's centre (up positive)")
describe_column("settlement", "Settlement", "m", "mm", 1e3,
                doc="accumulated sleeper settlement: its descent since cycle 0, both at F_min (down positive)")
describe_column("swing", "Swing", "m", "mm", 1e3,
                doc="peak-to-peak height of a sinusoid fitted to the device's height over the cycle")
describe_column("lag", "Lag", display="cycle",
                doc="how far the device's lowest point comes after the peak load, in cycles, in [-0.5, 0.5)")

CARRIED = ("gradation", "library")  # groups passed from the input to the output
VIBRATION_CYCLE = "Vibration cycle"  # the x axis of the vibrate stage's figures (seed 002, Figs. 9-10)

RECORDS_PER_CYCLE = 20  # default dem records per load cycle: a smooth trace of the loading device

LOAD = Section({
    "min": Float("N", min=0, default=0.0, doc="force at the start of each cycle (besides the actor's weight)"),
    "max": Float("N", min=0, doc="peak force"),
    "frequency": Float("Hz", min=0, min_inclusive=False),
    "settle": Float("s", min=0, default=0.0, doc="time at F_min before the cycles start"),
}, doc="haversine F_min -> F_max -> F_min per cycle, pushing down")


def _dem_fields():
    f = dict(dem.FIELDS)
    f["time"] = Section({
        "dt": Optional(Float("s", min=0, min_inclusive=False), doc="explicit time step (default: auto)"),
        "dt_factor": Float(min=0, max=1, min_inclusive=False, default=0.1,
                           doc="time step as a fraction of the critical step"),
    }, default={}, doc="the stage length follows from the cycles")
    f.pop("stop")
    f["records_per_cycle"] = Int(min=1, default=RECORDS_PER_CYCLE,
                                 doc="dem records per load cycle (their time plots resolve the cycle)")
    return f


def _check_box(node, report):
    if sum(1 for w in node.walls if w.type == "box") != 1:
        report("walls", "needs exactly one box wall (the ballast box)", len(node.walls))


def _check_deposit(node, report):
    dem.check_stage(node, report)
    _check_box(node, report)
    if node.stop is None:
        report("stop", "deposit needs a stop criterion (stop.kinetic_ratio)", None)


def _check_cyclic(node, report):
    dem.check_dynamics(node, report)
    _check_box(node, report)
    if node.load.max < node.load.min:
        report("load.max", f"must be >= load.min ({node.load.min:g} N)", node.load.max)
    aid = node.get("densify")
    if aid is not None:
        if node.target_density is None:
            report("densify", "densifies to target_density: give target_density too", None)
        if aid.after >= node.cycles:
            report("densify.after", f"must be below cycles ({node.cycles}), or the aid never starts", aid.after)
        if not node.physics.get("friction", True):
            report("densify", "lowers the friction, and physics.friction is off", None)


# ---------------------------------------------------------------------------------------
# measures
# ---------------------------------------------------------------------------------------

def box_wall(cfg):
    """(min (3,), max (3,)) of the stage's box wall [m]."""
    w = next(w for w in cfg.walls if w.type == "box")
    return np.array(w.min, float), np.array(w.max, float)


def particles(groups):
    """Indices of the ballast particles (every body but the actors)."""
    nb = len(groups["bodies"]["mass"])
    a = groups.get("actors", {})
    n = int(np.min(a["body"])) if len(a) and len(a["body"]) else nb
    return np.arange(n)


def _polyhedral_bed(groups):
    return not len(groups.get("spheres", {}).get("radius", ()))


def particle_materials(groups):
    """Material index of each ballast particle (a clump: its spheres' material)."""
    idx = particles(groups)
    if _polyhedral_bed(groups):
        return np.asarray(groups["polyhedra"]["material"], np.int64)[idx]
    sp = groups["spheres"]
    mat = np.zeros(len(groups["bodies"]["mass"]), np.int64)
    mat[np.asarray(sp["body"], np.int64)] = np.asarray(sp["material"], np.int64)
    return mat[idx]


def particle_mass(groups, case):
    """(mass [kg], mass-weighted particle density [kg/m^3]) of the ballast particles."""
    idx = particles(groups)
    density = np.array([m.density for m in case.materials.values()])[particle_materials(groups)]
    if _polyhedral_bed(groups):  # polyhedra: volume x density
        vol = np.asarray(groups["polyhedron_shapes"]["volume"])[np.asarray(groups["polyhedra"]["shape"])[idx]]
        m = float((vol * density).sum())
        return m, m / float(vol.sum()) if len(idx) else 0.0
    # spheres and clumps: the bodies' mass (a clump keeps its polyhedron's, V rho), the
    # density of their spheres' material
    mass = np.asarray(groups["bodies"]["mass"], float)[idx]
    m = float(mass.sum())
    return m, m / float((mass / density).sum()) if len(idx) else 0.0


def bed_measures(mass, rho_s, area, height):
    """{height, bulk_density, porosity, void_ratio, particle_mass} of a bed [SI]."""
    rho_b = mass / (area * height) if height > 0 else math.inf
    n = 1.0 - rho_b / rho_s
    return {"height": height, "bulk_density": rho_b, "porosity": n,
            "void_ratio": n / (1.0 - n) if n < 1.0 else math.inf, "particle_mass": mass}


def cycle_response(cycle, z):
    """How a loading device moves within each load cycle, from its sampled height.

    cycle: (n,) load cycles since the cycles started (samples at N - 1 < cycle <= N belong to
    cycle N; the load is F_min at whole cycles and F_max half way); z: (n,) height [m].
    Fits z = m + c cos 2 pi phase + s sin 2 pi phase (phase = cycle - (N - 1)) by least squares
    to each cycle N >= 1 that has at least 3 samples and ends on a sample.

    Returns {cycle N, swing 2 sqrt(c^2 + s^2) [m], lag [cycle], mean m [m]}, lag being how far
    the lowest point comes after the peak load, in [-0.5, 0.5): 0 for a response that follows
    the load (quasi-static), 0.25 a quarter cycle behind it (a mass on a spring driven at its
    natural frequency, or a plate that bounces).
    """
    cycle = np.asarray(cycle, float)
    z = np.asarray(z, float)
    out = {"cycle": [], "swing": [], "lag": [], "mean": []}
    last = int(np.floor(cycle.max() + 1e-6)) if len(cycle) else 0
    for n in range(1, last + 1):
        k = np.where((cycle > n - 1 + 1e-6) & (cycle <= n + 1e-6))[0]
        if len(k) < 3 or abs(cycle[k[-1]] - n) > 1e-6:
            continue
        phase = 2.0 * np.pi * (cycle[k] - (n - 1))
        basis = np.column_stack([np.ones(len(k)), np.cos(phase), np.sin(phase)])
        (m, c, s), *_ = np.linalg.lstsq(basis, z[k], rcond=None)
        lowest = (math.atan2(-s, -c) / (2.0 * np.pi)) % 1.0
        out["cycle"].append(n)
        out["swing"].append(2.0 * math.hypot(c, s))
        out["lag"].append(lowest - 0.5)
        out["mean"].append(m)
    return {k: np.asarray(v, int if k == "cycle" else float) for k, v in out.items()}


LAG_WARNING = 0.1  # cycles: a loading device lagging the load more than this is logged as dynamic


def top_points(groups):
    """Points of the ballast particles (no actors) whose highest ones bound the bed from above
    [m]: the world vertices of polyhedra; the top of each sphere (centre + r e_z, taken in the
    column of its centre)."""
    from demcli.state import State
    from demcli.state.polyhedra import world_vertices

    n = len(particles(groups))
    st = State(groups=groups)
    out = []
    if len(groups.get("polyhedra", {}).get("shape", ())):
        v, owner = world_vertices(st)
        out.append(v[owner < n])
    sp = groups.get("spheres", {})
    if len(sp.get("radius", ())):
        top = st.sphere_centres() + np.outer(np.asarray(sp["radius"], float), [0.0, 0.0, 1.0])
        out.append(top[np.asarray(sp["body"], np.int64) < n])
    return np.concatenate(out) if out else np.zeros((0, 3))


def surface_height(groups, lo, hi, cell):
    """Mean over the (x, y) columns of width ``cell`` of the box of the highest particle point [m]."""
    v = top_points(groups)
    n = np.maximum(1, np.floor((hi[:2] - lo[:2]) / cell).astype(int))
    ij = np.clip(((v[:, :2] - lo[:2]) / (hi[:2] - lo[:2]) * n).astype(int), 0, n - 1)
    top = np.full(n[0] * n[1], -np.inf)
    np.maximum.at(top, ij[:, 0] * n[1] + ij[:, 1], v[:, 2])
    top = top[np.isfinite(top)]
    return float(top.mean()) - lo[2] if len(top) else 0.0


def _median_size(groups, case):
    """Median sieve size of the particles [m] (polyhedra; clumps from polyhedra keep theirs); else
    the median diameter of the sphere of equal volume (spheres, clumps without sieve sizes)."""
    idx = particles(groups)
    if not len(groups.get("spheres", {}).get("radius", ())):
        s = np.asarray(groups["polyhedra"]["sieve_size"])[idx]
        s = s[s > 0]
        return float(np.median(s)) if len(s) else 2.0 * float(np.median(groups["polyhedron_shapes"]["radius"]))
    s = np.asarray(groups.get("clumps", {}).get("sieve_size", ()), float)
    if len(s) == len(groups["bodies"]["mass"]) and np.all(s[idx] > 0):
        return float(np.median(s[idx]))
    mass, rho_s = particle_mass(groups, case)
    return float(np.median(np.cbrt(6.0 / math.pi * np.asarray(groups["bodies"]["mass"], float)[idx] / rho_s)))


def _carry(state, state_in):
    for g in CARRIED:
        if g in state_in.groups:
            state.groups[g] = {k: np.asarray(v) for k, v in state_in.groups[g].items()}
            if g in state_in.group_attrs:
                state.group_attrs[g] = dict(state_in.group_attrs[g])


def _bed_group(meas):
    return {k: np.float64(v) for k, v in meas.items()}


def _log_bed(ctx, what, meas):
    ctx.log(f"{what}: bed height {meas['height'] * 1e3:.1f} mm, bulk density {meas['bulk_density'] / 1e3:.4g} g/cm^3, "
            f"porosity {meas['porosity']:.4f}, void ratio {meas['void_ratio']:.4f}")


# ---------------------------------------------------------------------------------------
# deposit
# ---------------------------------------------------------------------------------------

def run_deposit(ctx, cfg, state_in):
    lo, hi = box_wall(cfg)
    area = float(np.prod(hi[:2] - lo[:2]))
    mass, rho_s = particle_mass(state_in.groups, ctx.case)
    cell = _median_size(state_in.groups, ctx.case)

    def row(system):
        h = surface_height(system.groups(), lo, hi, cell)
        return {k: v for k, v in bed_measures(mass, rho_s, area, h).items() if k != "particle_mass"}

    def finish(ctx_, system, state, table):
        _carry(state, state_in)
        meas = bed_measures(mass, rho_s, area, surface_height(state.groups, lo, hi, cell))
        state.groups["bed"] = _bed_group(meas)
        ctx_.write_records(table, x="time", ys=["bulk_density"], suffix="density")
        _log_bed(ctx_, "deposited", meas)

    hooks = loop.Hooks(columns={"height": "m", "bulk_density": "kg/m^3", "porosity": "1", "void_ratio": "1"},
                      row=row, finish=finish)
    return loop.integrate(ctx, cfg, state_in, hooks)


# ---------------------------------------------------------------------------------------
# cyclic loading (vibrate, sleeper)
# ---------------------------------------------------------------------------------------

def cycle_timing(load, cycles, records_per_cycle, dt):
    """(dt, total steps, record interval): a whole number of steps per cycle, a multiple
    of ``records_per_cycle``, with dt no larger than asked; the settle time rounded up to
    whole records."""
    rec = records_per_cycle
    spc = int(math.ceil(1.0 / (load.frequency * dt) / rec)) * rec
    dt = 1.0 / (load.frequency * spc)
    # (the round-off allowance keeps a settle time of whole records, 0.05 s at 10 Hz, from
    # growing by a record)
    settle = int(math.ceil(load.settle / dt / (spc // rec) - 1e-9)) * (spc // rec)
    return dt, settle + cycles * spc, spc // rec


def _cyclic(ctx, cfg, state_in, actor, measure, columns, stop=None, finish_extra=None, target=None, start=None):
    """Run a cyclic stage on the dem loop: ``measure(system) -> dict`` of ``columns`` at each
    record, plus ``cycle``; the rows at whole cycles go to the ``cycles`` record. ``stop(row)``
    at each whole cycle from the first (a reason ends the stage); ``start(system, checkpoint,
    cycle)`` once before the first step, with the cycle the stage (re)starts at."""
    from demcli.engine.actors import actor_index
    from demcli.state import RecordTable

    load = cfg.load
    t_start = [load.settle]

    def timing(system, dt, dt_crit):
        dt, total, rec = cycle_timing(load, cfg.cycles, cfg.records_per_cycle, dt)
        spc = rec * cfg.records_per_cycle
        t_start[0] = (total - cfg.cycles * spc) * dt  # the settle time on whole records
        system.set_actor_start(actor, t_start[0])
        return dt, total, rec

    def cycle_of(system):
        return (system.time - t_start[0]) * load.frequency

    def row(system):
        out = {"cycle": cycle_of(system)}
        out.update(measure(system))
        return out

    def is_cycle_end(r):
        c = r["cycle"]
        return c >= -1e-9 and abs(c - round(c)) < 1e-6

    def stop_hook(system, r):
        if stop is not None and is_cycle_end(r) and round(r["cycle"]) >= 1:
            return stop(r)
        return None

    def finish(ctx_, system, state, table):
        _carry(state, state_in)
        rows = table.to_arrays()
        resp = cycle_response(rows["cycle"], rows[actor])
        by_cycle = {int(n): k for k, n in enumerate(resp["cycle"])}
        cyc = RecordTable("cycles", {"cycle": "1", **columns, "swing": "m", "lag": "1"})
        for k in range(len(rows["cycle"])):
            r = {c: rows[c][k] for c in rows}
            if is_cycle_end(r):
                n = int(round(r["cycle"]))
                j = by_cycle.get(n)
                cyc.append({"cycle": n, **{c: float(r[c]) for c in columns},
                            "swing": float(resp["swing"][j]) if j is not None else math.nan,
                            "lag": float(resp["lag"][j]) if j is not None else math.nan})
        cyc.to_state(state)
        ctx_.write_records(table, x="cycle", ys=[actor], suffix=actor)  # the device's trace, cycle by cycle
        if len(resp["lag"]):
            lag = float(np.median(resp["lag"]))
            msg = (f"{actor} response: lowest {lag:+.2f} cycle after the peak load, swing "
                   f"{np.median(resp['swing']) * 1e3:.1f} mm (medians over {len(resp['lag'])} cycles)")
            if abs(lag) > LAG_WARNING:
                msg += (f"; the loading is not quasi-static (scaling: stiffness x {cfg.scaling.stiffness:g}, "
                        f"mass x {cfg.scaling.mass:g}): see docs/ballast_box.md, 'How the plate and the "
                        "sleeper move within a cycle'")
            ctx_.log(msg)
        if finish_extra is not None:
            finish_extra(ctx_, system, state, cyc)

    b = actor_index(state_in.groups, actor)
    if b is None:
        raise InputError(f"stage {ctx.name}: the scene has no {actor}")
    def watch(r):  # what `stop` tests, at the cycle ends where it tests it (the ETA follows its trend)
        return r[target[0]] if is_cycle_end(r) and round(r["cycle"]) >= 1 else None

    hooks = loop.Hooks(columns={"cycle": "1", **columns}, row=row, stop=stop_hook, finish=finish, timing=timing,
                      watch=watch if target is not None else None, target=target and target[1:],
                      start=None if start is None else (lambda system, ckpt: start(system, ckpt, cycle_of(system))))
    dcfg = dict(cfg)
    dcfg["time"] = Node({"steps": 1, "duration": None, "dt": cfg.time.dt, "dt_factor": cfg.time.dt_factor})
    dcfg["stop"] = None
    return loop.integrate(ctx, Node(dcfg), state_in, hooks)


def _actor_bottom(groups, b):
    """Lowest point of actor b [m]."""
    from demcli.state import State
    from demcli.state.polyhedra import first_polyhedral_body

    sh = groups["polyhedron_shapes"]
    k = int(groups["polyhedra"]["shape"][b - first_polyhedral_body(State(groups=groups))])
    v = np.asarray(sh["vertices"])[sh["vertex_start"][k]:sh["vertex_start"][k + 1]]
    from demcli.state.polyhedra import rotation_matrices

    rot = rotation_matrices(np.asarray(groups["bodies"]["q"])[b:b + 1])[0]
    return float((v @ rot.T)[:, 2].min() + groups["bodies"]["x"][b, 2])


def _load_row(load, t0):
    from demcli.engine.actors import haversine

    return haversine(load.min, load.max, load.frequency, start=t0)


def _state_with(ctx, state_in, groups):
    st = ctx.new_state()
    st.groups.update(groups)
    _carry(st, state_in)
    return st


def run_vibrate(ctx, cfg, state_in):
    from demcli.engine.actors import actor_index, add_actor, box_polyhedron, remove_actors

    lo, hi = box_wall(cfg)
    area = float(np.prod(hi[:2] - lo[:2]))
    groups = remove_actors(state_in.groups)
    mass, rho_s = particle_mass(groups, ctx.case)
    p = cfg.plate
    size = np.array(p.size) if p.size is not None else np.r_[hi[:2] - lo[:2] - 2.0 * p.gap, p.thickness]
    top = _top(groups)
    centre = np.r_[0.5 * (lo[:2] + hi[:2]), top + p.clearance + 0.5 * size[2]]
    mats = list(ctx.case.materials)
    groups = add_actor(groups, box_polyhedron(size), centre, ctx.case.materials[p.material].density,
                       mats.index(p.material), "plate", load=_load_row(cfg.load, cfg.load.settle))
    b = actor_index(groups, "plate")
    half = 0.5 * size[2]
    aid = FrictionAid(cfg.densify, np.unique(particle_materials(groups)), cfg.target_density)

    def measure(system):
        h = float(system.x[b, 2]) - half - lo[2]
        m = bed_measures(mass, rho_s, area, h)
        return {"plate": float(system.x[b, 2]), **{k: m[k] for k in ("bulk_density", "porosity", "void_ratio")},
                **({"bed_friction": aid.friction(system)} if aid.on else {})}

    def stop(r):
        if cfg.target_density is not None and aid.reached(r["bulk_density"]):
            return f"bulk density {r['bulk_density'] / 1e3:.4g} g/cm^3 reached the target after {round(r['cycle'])} cycles"
        aid.at_cycle_end(ctx, r)
        return None

    def finish(ctx_, system, state, cyc):
        h = float(system.x[b, 2]) - half - lo[2]
        meas = bed_measures(mass, rho_s, area, h)
        state.groups["bed"] = _bed_group(meas)
        rho_t = cfg.target_density  # the target line on both figures (void ratio e = rho_s / rho_b - 1)
        for col, suffix, target in (("bulk_density", "density", rho_t),
                                    ("void_ratio", "void_ratio", rho_t and rho_s / rho_t - 1.0)):
            ctx_.write_records(cyc, x="cycle", ys=[col], suffix=suffix, xlabel=VIBRATION_CYCLE,
                               targets={col: target} if target is not None else None)
        rows = cyc.to_arrays()
        if len(rows["cycle"]):
            ctx_.log(f"bulk density {rows['bulk_density'][0] / 1e3:.4g} -> {rows['bulk_density'][-1] / 1e3:.4g} g/cm^3 "
                     f"over {int(rows['cycle'][-1])} cycles")
        _log_bed(ctx_, "under the plate", meas)

    return _cyclic(ctx, cfg, _state_with(ctx, state_in, groups), "plate", measure,
                   {"plate": "m", "bulk_density": "kg/m^3", "porosity": "1", "void_ratio": "1",
                    **({"bed_friction": "1"} if aid.on else {})}, stop=stop, finish_extra=finish,
                   target=("bulk_density", cfg.target_density, True) if cfg.target_density is not None else None,
                   start=aid.start if aid.on else None)


def aid_levels(densities, after, ramp, target):
    """Level k (0 = the case's friction, ``ramp`` = the aid's) of the densification aid after each
    cycle end, from the bulk densities at cycle ends 0, 1, 2, ... (a pure function of them, so a
    resumed stage replays it from its records).

    From cycle ``after`` on, below the target: the aid starts at level 1; then with g the last
    cycle's gain and r = target - rho the gap left, the level goes up one step while r > 3 g
    (the bed would need more than three cycles at this rate), down one while r < g (the next
    cycle would overshoot), and stays otherwise. So the last cycles approach the target at
    gains of about a third of the gap, and a bed ends within about one such gain above it.
    """
    k, out = 0, [0]
    for n in range(1, len(densities)):
        rho, gain, gap = densities[n], densities[n] - densities[n - 1], target - densities[n]
        if n >= after and gap > 0:
            if k == 0:
                k = 1
            elif gap > 3.0 * gain:
                k = min(ramp, k + 1)
            elif gap < gain:
                k -= 1
        out.append(k)
    return out


class FrictionAid:
    """The vibrate stage's densification aid (``densify``): a bed that has not reached
    ``target_density`` after ``densify.after`` cycles vibrates on with the friction coefficient
    between its particles lowered (walls and plate keep theirs) until it is within
    ``densify.tolerance`` of the target. Lower friction lets the stones slide past each other
    under the same load, the usual way a DEM sample is brought to a target density (e.g.
    Thornton 2000, Geotechnique 50:43). The friction of level k (:func:`aid_levels`) is
    mu_k = mu_0 + (mu_aid - mu_0) k / ramp: lowered step by step while the bed gains slowly,
    raised again when it would overshoot. The next stage builds its contacts from the case's
    materials, so the bed goes on at the case's friction."""

    def __init__(self, spec, materials, target):
        self.spec, self.materials, self.target = spec, materials, target
        self.on = spec is not None
        self.pairs = np.ix_(materials, materials)
        self.mu0 = self.system = None
        self.densities = []  # at the cycle ends 0, 1, ...

    def friction(self, system):
        """The friction coefficient between bed particles now (that of the first bed material pair)."""
        m = int(self.materials[0])
        return float(system.friction[m, m])

    def reached(self, rho):
        """Close enough to the target to stop."""
        return rho >= self.target * (1.0 - (self.spec.tolerance if self.on else 0.0))

    def _set(self):
        k = aid_levels(self.densities, self.spec.after, self.spec.ramp, self.target)[-1]
        self.system.friction[self.pairs] = self.mu0 + (self.spec.friction - self.mu0) * (k / self.spec.ramp)

    def start(self, system, checkpoint, cycle):
        """Before the first step: the case's friction kept; a resumed stage replays the levels from
        the cycle ends of its checkpoint's records."""
        from demcli.state import RecordTable

        self.system, self.mu0 = system, system.friction[self.pairs].copy()
        if checkpoint is not None:
            rows = RecordTable.from_state(checkpoint, "dem").to_arrays()
            ends = np.abs(rows["cycle"] - np.round(rows["cycle"])) < 1e-6
            self.densities = [float(r) for c, r in zip(rows["cycle"][ends], rows["bulk_density"][ends]) if c > -1e-9]
            self._set()

    def at_cycle_end(self, ctx, row):
        """At a whole cycle short of the target: the level of the next cycle."""
        if not self.on:
            return
        if not self.densities:
            self.densities.append(math.nan)  # cycle 0: no decision reads it (the aid starts at level 1)
        self.densities.append(float(row["bulk_density"]))
        before = self.friction(self.system)
        self._set()
        if self.friction(self.system) != before:
            ctx.log(f"densify: bulk density {row['bulk_density'] / 1e3:.4g} g/cm^3 after {round(row['cycle'])} "
                    f"cycles; friction between bed particles {before:.4g} -> {self.friction(self.system):.4g}")


def _top(groups):
    v = top_points(groups)
    return float(v[:, 2].max()) if len(v) else 0.0


def shoulder_ballast(ctx, groups, state_in, region_lo, region_hi, solids, material, clearance, tries, slide):
    """Groups with ballast drawn from the library (the case's gradation, ``solids`` m^3 of
    it) stacked by drop placement in the box ``region_lo``-``region_hi`` [m]."""
    import json

    from demcli.stages.ballast.assemble import drop_pack, pick_classes, rotated_shapes
    from demcli.stages.ballast.library import ensure_library
    from demcli.state.polyhedra import ShapeTable, rotation_matrices

    if "library" not in state_in.groups or "gradation" not in state_in.groups:
        raise InputError(f"stage {ctx.name}: filling the shoulders needs the gradation and library of the case "
                         "(the input state does not carry them)")
    g = {k: np.asarray(v) for k, v in state_in.groups["gradation"].items()}
    f = solids / float(g["class_amount"].sum())
    g["class_amount"] = g["class_amount"] * f
    g["class_count"] = np.maximum(0, np.round(np.asarray(g["class_count"]) * f)).astype(np.int64)
    attrs = state_in.group_attrs["library"]
    lib, _, _ = ensure_library(json.loads(attrs["generator"]), path=attrs["path"], log=ctx.log)
    rng = ctx.rng
    rows, cls, _ = pick_classes(rng, lib, g)
    n = len(rows)
    shapes = lib.shapes.subset(rows)
    q = _fitting_orientations(rng, shapes, region_hi[:2] - region_lo[:2] - 2.0 * clearance)
    x, top = drop_pack(rng, rotated_shapes(shapes, rotation_matrices(q)), region_lo, region_hi, clearance, tries=tries,
                       slide=slide)
    density = ctx.case.materials[material].density
    nb = len(groups["bodies"]["mass"])
    p = lib.particles
    new = {"x": x, "v": np.zeros((n, 3)), "q": q, "omega": np.zeros((n, 3)), "mass": density * shapes.volume,
           "inertia": density * shapes.inertia, "id": np.arange(n, dtype=np.int64) + int(np.max(groups["bodies"]["id"])) + 1,
           "flags": np.zeros(n, np.int8)}
    out = dict(groups)
    out["bodies"] = {k: np.concatenate([np.asarray(v), np.asarray(new[k], np.asarray(v).dtype) if k in new else
                                        np.zeros((n,) + np.asarray(v).shape[1:], np.asarray(v).dtype)])
                     for k, v in groups["bodies"].items()}
    nshape = len(groups["polyhedron_shapes"]["volume"])
    newp = {"shape": np.arange(n, dtype=np.int64) + nshape, "material": np.full(n, list(ctx.case.materials).index(material)),
            "size_class": cls, "sieve_size": p["sieve_size"][rows], "library_index": rows.astype(np.int64),
            "flaky": p["flaky"][rows], "elongated": p["elongated"][rows]}
    out["polyhedra"] = {k: np.concatenate([np.asarray(v), np.asarray(newp[k], np.asarray(v).dtype)])
                        for k, v in groups["polyhedra"].items()}
    out["polyhedron_shapes"] = ShapeTable.concat([ShapeTable.from_group(groups["polyhedron_shapes"]),
                                                 shapes]).to_group()
    ctx.log(f"shoulders: {n} particles, {shapes.volume.sum() * 1e6:.5g} cm^3 of solids (target {solids * 1e6:.5g}), "
            f"stacked to z = {top:.3f} m; bodies {nb}..{nb + n - 1}")
    return out


def _fitting_orientations(rng, shapes, floor, tries=100):
    """Uniform random orientations (n, 4), each redrawn (up to ``tries`` times) until the
    particle's (x, y) extent fits the ``floor`` (2,) [m] of a narrow shoulder."""
    from demcli.stages.ballast.assemble import random_quaternions
    from demcli.state.polyhedra import rotation_matrices

    n = len(shapes)
    q = random_quaternions(rng, n)
    for k in range(n):
        v = shapes.shape(k)[0]
        for _ in range(tries):
            w = v @ rotation_matrices(q[k:k + 1])[0].T
            if np.all(w[:, :2].max(axis=0) - w[:, :2].min(axis=0) < floor):
                break
            q[k] = random_quaternions(rng, 1)[0]
    return q


def run_sleeper(ctx, cfg, state_in):
    from demcli.engine.actors import actor_index, add_actor, box_polyhedron, remove_actors

    lo, hi = box_wall(cfg)
    plate = actor_index(state_in.groups, "plate")
    groups = state_in.groups
    bed = _actor_bottom(groups, plate) if plate is not None else _top(groups)
    groups = remove_actors(groups)
    sl = cfg.sleeper
    size = np.array(sl.size)
    cxy = np.array(sl.centre) if sl.centre is not None else 0.5 * (lo[:2] + hi[:2])
    s_lo = np.r_[cxy - 0.5 * size[:2], bed]
    s_hi = np.r_[cxy + 0.5 * size[:2], bed + size[2]]
    sh = cfg.shoulders
    if sh.fill and len(groups.get("spheres", {}).get("radius", ())):
        raise InputError(f"stage {ctx.name}: shoulders.fill: the shoulder ballast is drawn as polyhedra, and this "
                         "bed is made of spheres or clumps (set shoulders.fill: false)")
    if sh.fill:
        top_fill = sh.height if sh.height is not None else s_hi[2]
        if not top_fill > bed:
            raise InputError(f"stage {ctx.name}: shoulders.height {top_fill:g} m must be above the bed surface "
                             f"({bed:.4g} m) to fill the shoulders")
        mat = ctx.case.materials[sh.material]
        solids = 0.0
        regions = []
        for side in (0, 1):  # along x: before and after the sleeper
            r_lo = np.r_[lo[0] if side == 0 else s_hi[0] + sh.gap, lo[1], bed]
            r_hi = np.r_[s_lo[0] - sh.gap if side == 0 else hi[0], hi[1], top_fill]
            if r_hi[0] - r_lo[0] > 0:
                regions.append((r_lo, r_hi))
                solids += float(np.prod(r_hi - r_lo)) * sh.bulk_density / mat.density
        # the two sides get their share of the solids, placed above everything under them
        for r_lo, r_hi in regions:
            share = solids * float(np.prod(r_hi - r_lo)) / sum(float(np.prod(b - a)) for a, b in regions)
            base = _top_in(groups, r_lo, r_hi) + sh.clearance
            groups = shoulder_ballast(ctx, groups, state_in, np.r_[r_lo[:2], base], np.r_[r_hi[:2], base + 1.0],
                                      share, sh.material, sh.clearance, sh.tries, sh.slide)
    mats = list(ctx.case.materials)
    centre = np.r_[cxy, bed + sl.drop + 0.5 * size[2]]
    groups = add_actor(groups, box_polyhedron(size), centre, ctx.case.materials[sl.material].density,
                       mats.index(sl.material), "sleeper", load=_load_row(cfg.load, cfg.load.settle))
    b = actor_index(groups, "sleeper")

    def measure(system):
        return {"sleeper": float(system.x[b, 2])}

    def finish(ctx_, system, state, cyc):
        from demcli.state import RecordTable

        rows = cyc.to_arrays()
        out = RecordTable("settlement", {"cycle": "1", "sleeper": "m", "settlement": "m", "swing": "m", "lag": "1"})
        for c, z, sw, lag in zip(rows["cycle"], rows["sleeper"], rows["swing"], rows["lag"]):
            out.append(cycle=int(c), sleeper=float(z), settlement=float(rows["sleeper"][0] - z), swing=float(sw),
                       lag=float(lag))
        out.to_state(state)
        ctx_.write_records(out, x="cycle", ys=["settlement"])
        if len(rows["cycle"]):
            ctx_.log(f"accumulated sleeper settlement after {int(rows['cycle'][-1])} cycles: "
                     f"{(rows['sleeper'][0] - rows['sleeper'][-1]) * 1e3:.3f} mm")

    return _cyclic(ctx, cfg, _state_with(ctx, state_in, groups), "sleeper", measure, {"sleeper": "m"},
                   finish_extra=finish)


def _top_in(groups, lo, hi):
    """Highest particle point above the (x, y) rectangle lo-hi [m] (the box floor if none)."""
    v = top_points(groups)
    m = (v[:, 0] >= lo[0]) & (v[:, 0] <= hi[0]) & (v[:, 1] >= lo[1]) & (v[:, 1] <= hi[1])
    return float(v[m, 2].max()) if m.any() else float(lo[2])


# ---------------------------------------------------------------------------------------
# registration
# ---------------------------------------------------------------------------------------

DEPOSIT = dict(dem.FIELDS)

VIBRATE = _dem_fields()
VIBRATE.update({
    "plate": Section({
        "material": Str(doc="material of the plate (density, stiffness)"),
        "size": Optional(Vector(3, "m"), doc="plate edges x, y, z (default: the box floor less gap, x thickness)"),
        "gap": Float("m", min=0, default="10 mm", doc="default size: clearance to the box walls on each side"),
        "thickness": Float("m", min=0, min_inclusive=False, default="50 mm"),
        "clearance": Float("m", min=0, default="2 mm", doc="laid this far above the highest particle"),
    }),
    "load": LOAD,
    "cycles": Int(min=1, doc="load cycles (seed: 45)"),
    "target_density": Optional(Float("kg/m^3", min=0, min_inclusive=False),
                               doc="stop at the first cycle end where the bulk density reaches it (seed: 1.55 g/cm^3)"),
    "densify": Optional(Section({
        "after": Int(min=1, doc="cycles at the case's friction before the aid starts"),
        "friction": Float(min=0, doc="friction coefficient between bed particles while aided (walls and plate "
                                     "keep theirs)"),
        "ramp": Int(min=1, default=4, doc="steps from the case's friction down to it (levels k / ramp)"),
        "tolerance": Float(min=0, max=0.05, default=0.002,
                           doc="stop once the bulk density is within this share below the target"),
    }), doc="densification aid: a bed below target_density after `after` cycles vibrates on at a lower friction "
            "until it reaches it (the next stage has the case's friction again)"),
})

SLEEPER = _dem_fields()
SLEEPER.update({
    "sleeper": Section({
        "material": Str(),
        "size": Vector(3, "m", doc="edges x (width along the box), y (length across it), z (height)"),
        "centre": Optional(Vector(2, "m"), doc="(x, y) of the centre (default: the box centre)"),
        "drop": Float("m", min=0, default="2 mm", doc="set this far above the bed surface (the plate's underside)"),
    }),
    "shoulders": Section({
        "fill": Bool(default=True, doc="fill the box beside the sleeper with ballast"),
        "material": Str(doc="material of the shoulder ballast"),
        "height": Optional(Float("m"), doc="fill up to this height (default: the sleeper's top)"),
        "bulk_density": Float("kg/m^3", min=0, min_inclusive=False, default="1.55 g/cm^3",
                              doc="solids placed = shoulder volume x this / particle density"),
        "gap": Float("m", min=0, default="5 mm", doc="kept free beside the sleeper while stacking"),
        "clearance": Float("m", min=0, default="2 mm"),
        "tries": Int(min=1, default=8),
        "slide": Int(min=0, default=8),
    }),
    "load": LOAD,
    "cycles": Int(min=1, doc="load cycles (seed: 80)"),
})


def _describe(kind):
    def describe(cfg, case):
        plan = dem.plan_summary(case, cfg, {"polyhedra": True})  # (the bed's shape is known at run time)
        lines = plan.describe().splitlines()
        if kind != "deposit":
            ld = cfg.load
            lines.append(f"load {ld.min / 1e3:g}-{ld.max / 1e3:g} kN at {ld.frequency:g} Hz, {cfg.cycles} cycles "
                         f"after {ld.settle:g} s at the minimum")
        sc = cfg.scaling
        if sc.stiffness != 1.0 or sc.mass != 1.0:
            lines.append(f"scaling: stiffness x {sc.stiffness:g}, mass x {sc.mass:g} "
                         f"(time step x {math.sqrt(sc.mass / sc.stiffness):.3g})")
        lines.append("time step: decided at run time from the bodies of the input state")
        return "\n".join(lines)
    return describe


def _shoulder_inputs(cfg):
    """Input fields a sleeper config reads besides: filling the shoulders draws from the library."""
    return {"shoulders.fill": ("gradation/class_amount", "gradation/class_count", "library/path",
                               "library/generator")} if cfg.shoulders.fill else {}


def _actor_scene_check(cfg, case, k, scene, report):
    """:func:`dem.scene_check` for a stage that sets a polyhedral actor on its bed: the scene
    runs as polyhedra (a polyhedral bed) or mixed (a sphere or clump bed, or one that already
    had an actor); shoulders are drawn as polyhedra, so a sphere bed takes none."""
    poly = has_field(scene, "polyhedra/shape") if scene is not None else True
    dem.scene_check(cfg, case, k, scene, report, shapes=("polyhedra", "mixed") if poly else ("mixed",))
    if not poly and cfg.get("shoulders") is not None and cfg.shoulders.fill:
        report("shoulders.fill", "the shoulder ballast is drawn as polyhedra, and this bed is made of spheres or "
               "clumps (set shoulders.fill: false)", True)


_IO = dict(requires=("bodies/x",), keeps=CARRIED + ENGINE_KEEPS, file_digest=dem.mesh_digest,
           provides=ENGINE_OUTPUT + ("polyhedra/*", "polyhedron_shapes/*", "bed/*"))
register_stage(StageType("deposit", DEPOSIT, run_deposit, check=_check_deposit, describe=_describe("deposit"), **_IO,
                         case_check=dem.scene_check,
                         doc="gravity deposition of a ballast bed (polyhedra, clumps or spheres) until at rest; "
                             "bulk density and porosity"))
register_stage(StageType("vibrate", VIBRATE, run_vibrate, check=_check_cyclic, describe=_describe("vibrate"), **_IO,
                         case_check=_actor_scene_check,
                         doc="plate vibration compaction: density and void ratio per cycle (seed 002)"))
register_stage(StageType("sleeper", SLEEPER, run_sleeper, check=_check_cyclic, describe=_describe("sleeper"), **_IO,
                         case_check=_actor_scene_check, config_requires=_shoulder_inputs,
                         doc="sleeper on the compacted bed, shoulders filled, cyclic load: settlement per cycle"))
