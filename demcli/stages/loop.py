"""The stage loop every integrating stage runs (dem, deposit, vibrate, sleeper, compact, creep).

:func:`integrate` reads the previous state (or the stage's checkpoint), builds the system
with the physics the stage's config declares (:mod:`demcli.stages.dem` decides effects,
contact law, walls), picks the time step (a fraction of the critical step, or an explicit
one that must stay below it), and runs the compiled step loop in chunks. Between chunks it
writes records (CSV), snapshots (VTU + PVD), progress, and keeps a copy of the last good
state. A guard failure stops the stage with a diagnosis and writes the last good state;
Ctrl-C writes a checkpoint that ``--resume`` continues bit-identically. A stage adds its own
columns, stop rule, timing and outputs through :class:`Hooks`.
"""

import math
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from demcli import interrupts
from demcli.effects import EFFECTS, check_shape
from demcli.errors import InputError, StageError
from demcli.measure.stage import StageMeasures
from demcli.progress import StopForecast
from demcli.stages.dem import (build_walls, case_materials, contact_model, declared_effects, lay_walls, phase_models,
                               scene_shape, set_bond_models)
from demcli.stages.contact_record import COLUMNS as CONTACT_COLUMNS, check_scene, contact_rows
from demcli.stages.packing_record import COLUMNS as PACKING_COLUMNS, PackingProbe
from demcli.stages.timing import stage_time_step, step_count
from demcli.stepping import Stepper
from demcli.state.fields import Field, register, register_group

register_group("checkpoint", "Engine accumulators of an interrupted dem stage (only in .ckpt.h5 files)",
               writer="stage dem")
for _name, _dims, _doc in [("losses0", (4,), "losses carried in from the input state [J]"),
                           ("esph", ("n_esph", 2), "per-sphere cumulative dashpot and slip losses [J]"),
                           ("ebody", ("n_ebody",), "per-body cumulative damping losses [J]"),
                           ("eacc", (1,), "cumulative wall work [J]"),
                           ("ke_limit", (1,), "kinetic-energy guard limit [J]")]:
    register(Field(f"checkpoint/{_name}", "f", _dims, "J", _doc, writer="stage dem"))
register(Field("checkpoint/wall_rate", "f", ("n_w",), "m/s", "rate of change of each pressure-loaded cylinder's "
               "radius", writer="stage dem", required=False))
register(Field("checkpoint/ended", "str", (), "", "present when the stepping had ended (the stage was interrupted "
               "while writing its outputs): why it ended, empty when all its steps were done",
               writer="stage dem", required=False))


def make_system(ctx, cfg, groups, time=0.0, step=0, resume=False, bonds=None):
    """System, plan and time-step information for this stage (``resume``: from a checkpoint;
    ``bonds``: a stage's change of the bond-model table, :attr:`Hooks.bonds`)."""
    from demcli.engine.plan import make_plan
    from demcli.engine.system import Dynamics, System
    from demcli.kernels.walls import MESH, PLANE
    from demcli.stages.asphalt import bonded as bonded_aggregates

    phase_pairs = phase_models(ctx, groups)[2] if cfg.get("bonds") is not None and cfg.bonds.from_phases else ()
    groups, members = bonded_aggregates.prepare(ctx, cfg, groups, resume)
    walls = build_walls(cfg, ctx.case, ctx.runner.case_path, f"stages[{ctx.index}].walls")
    shape = scene_shape(groups)
    declared = declared_effects(cfg, ctx.case.dimension)
    bonded = cfg.get("bonds") is not None or len(groups.get("bonds", {}).get("i", ())) > 0
    plan = make_plan(declared, clumps=shape == "clumps", walls=len(walls) > 0, polyhedra=shape == "polyhedra",
                     bonds=bonded)
    # every effect on a shape it runs on (demcli check refuses the rest already, where it knows the shape)
    check_shape(plan.effects, shape, ctx.name)
    takes = (PLANE, MESH) if shape == "polyhedra" else (PLANE,)
    if shape in ("polyhedra", "mixed") and np.any(np.isin(np.asarray(walls.kind), takes, invert=True)):
        raise InputError(f"stage {ctx.name}: walls: a scene with polyhedra takes {EFFECTS['walls'].limits[shape]}")
    p = cfg.physics
    dyn = Dynamics(gravity=tuple(p.gravity) if p.gravity is not None else (0.0, 0.0, 0.0),
                   local_damping=p.local_damping or 0.0, viscous_damping=p.viscous_damping or 0.0,
                   skin=cfg.neighbors.skin, check_every=cfg.safety.check_every,
                   overlap_limit=cfg.safety.overlap_limit, energy_limit=cfg.safety.energy_limit)
    extra = {}
    if cfg.scaling.mass != 1.0:
        extra["mass_scale"] = cfg.scaling.mass
    model = contact_model(cfg)
    if cfg.get("bonds") is not None and cfg.bonds.from_phases:
        import dataclasses

        model = dataclasses.replace(model, pairs=phase_pairs + model.pairs)
    system = System(groups, case_materials(ctx.case, cfg.scaling.stiffness), model, plan, walls,
                    dyn, dt=1.0, time=time, step=step, **extra)
    if p.adaptive_damping is not None and not resume:  # a resumed stage keeps its adapted alpha
        system.alpha = float(p.adaptive_damping.initial)
    if cfg.get("bonds") is not None:
        set_bond_models(ctx, cfg.bonds, system, groups)
        if members is not None:
            n = bonded_aggregates.bond_members(system, *members)
            ctx.log(f"bonded aggregates: {int(np.sum(members[0] >= 0))} lattice balls released from their clumps, "
                    f"{n} parallel bonds between lattice neighbours")
        if cfg.bonds.create and not resume:
            free = cfg.bonds.install == "stress_free" or (cfg.bonds.install == "auto" and cfg.bonds.from_phases)
            n = system.bond_touching(cfg.bonds.gap * float(system.rad.mean()), stress_free=free)
            ctx.log(f"bonded {n} touching pairs ({len(system.bonds)} bonds)")
    if cfg.get("periodic") is not None:
        from demcli.stages.periodic import attach

        attach(ctx, cfg, system, groups, resume)
    if bonds is not None:
        system.bonds.prm = np.ascontiguousarray(bonds(system.bonds.prm.copy(), system.bonds.materials))
    dt_crit = system.critical_dt()
    dt = stage_time_step(cfg, dt_crit, f"stage {ctx.name}")
    system.dt = dt
    if not resume:  # a resumed stage takes its walls' positions from the checkpoint
        for row, (gap, d) in lay_walls(cfg, system.wpoint, groups).items():
            ctx.log(f"wall {walls.name[row]} laid {gap * 1e3:g} mm from the particles "
                    f"(moved {d * 1e3:+.4g} mm along its normal)")
    return system, plan, dt, dt_crit


class StageSnapshots:
    """Sphere and polyhedron snapshots plus walls (a mixed scene writes both series, numbered
    alike), one ``write(state)`` and ``truncate(time)``; ``meshes``: the mesh walls' triangles
    (:attr:`demcli.engine.system.Walls.mesh`)."""

    def __init__(self, folder, shape, resume, meshes=None):
        from demcli.state.vtu import PvdSeries, Snapshots
        from demcli.state.vtu_poly import PolyhedraSnapshots

        self.folder = Path(folder)
        # the sphere series writes the walls (and bonds) beside its spheres
        self.spheres = Snapshots(folder, resume=resume, meshes=meshes) if shape != "polyhedra" else None
        self.polyhedra = PolyhedraSnapshots(folder, resume=resume) if shape in ("polyhedra", "mixed") else None
        self.walls = PvdSeries(self.folder / "walls.pvd", resume=resume) if self.spheres is None else None
        self.meshes = meshes

    def write(self, state):
        from demcli.state.vtu import write_walls_vtu

        if self.spheres is not None:
            self.spheres.write(state)
        if self.polyhedra is not None:
            self.polyhedra.write(state)
        if self.walls is not None and "walls/kind" in state and len(state["walls/kind"]):
            path = write_walls_vtu(self.folder / f"walls_{self.polyhedra.count - 1:06d}.vtu", state, self.meshes)
            self.walls.add(float(state.meta.get("time", 0.0)), path)

    def truncate(self, time):
        if self.spheres is not None:
            self.spheres.truncate(time)
        if self.polyhedra is not None:
            self.polyhedra.series.truncate(time)
            self.polyhedra.count = len(self.polyhedra.series)
        if self.walls is not None:
            self.walls.truncate(time)


def body_radii(system):
    """Bounding radius of each body [m]: a sphere's radius, a clump's max |offset| + r, a
    polyhedron's circumradius (the size d in the stop criterion's m g d)."""
    if not getattr(system, "clumps", False):
        return system.rad
    out = np.zeros(len(system.mass))
    np.maximum.at(out, system.sbody, np.linalg.norm(system.soff, axis=1) + system.rad)
    return out


def reference_energy(system):
    """Energy scale for the runaway guard: what gravity, walls and the start can supply [J]."""
    g = float(np.linalg.norm(system.gravity)) if system.plan.has("gravity") else 0.0
    pts = [system.x]
    if len(system.walls):
        pts.append(system.wpoint)
    allp = np.concatenate(pts)
    span = float(np.linalg.norm(allp.max(axis=0) - allp.min(axis=0))) + 2 * float(system.rad.max())
    mtot = float(system.mass.sum())
    e = system.kinetic_energy() + system.strain_energy() + mtot * g * span
    if len(system.walls):
        from demcli.kernels import walls as W

        vmax = max(float(np.abs(system.wv).max()), float(system.walls.prm[:, W.W_VMAX].max()))
        fmax = float(np.abs(system.walls.prm[:, W.W_TARGET]).max() + system.walls.prm[:, W.W_AMPLITUDE].max())
        area = np.nan_to_num(system.walls.prm[:, W.W_AREA]).max()
        e += 0.5 * mtot * vmax ** 2 + (fmax + fmax * area) * span
    # a floor: the energy of every body moving at 1 % of the speed that spans its size per ms
    e += 0.5 * mtot * (0.01 * float(system.rad.mean()) / 1e-3) ** 2
    return e


@dataclass
class Hooks:
    """What a stage built on :func:`integrate` adds to the ``dem`` stage loop.

    Attributes:
        columns: extra record columns {name: unit} of the ``dem`` table.
        row: ``row(system) -> dict`` values of those columns at each record.
        stop: ``stop(system, row) -> str | None``: a reason to end the stage at a record.
        watch: ``watch(row) -> float | None``: the value ``stop`` tests (None at records
            where it tests nothing), and target: its ``(threshold, rising)``; the progress
            line's ETA follows their trend (:class:`demcli.progress.StopForecast`).
        finish: ``finish(ctx, system, state, table)`` after the loop (extra outputs).
        timing: ``timing(system, dt, dt_crit) -> (dt, total_steps, record_every)``
            replaces the time step, the stage length and the record interval of the
            config (a cyclic load wants a whole number of steps per cycle).
        start: ``start(system, checkpoint)`` once before the first step (and the first
            record): ``checkpoint`` is the State a resumed stage continues from, None on a
            fresh start. The checkpoint keeps the scene, the wall positions and velocities
            and the records; a hook that changes anything else (wall control modes or
            parameters) must set it again here from what the checkpoint keeps.
        bonds: ``bonds(params, materials) -> params``: the bond-model table (rows of
            :func:`demcli.engine.bonds.model_row`, their material pairs) the stage steps with,
            from the one its config and input give, before the time step is chosen (a fresh
            start and a resumed one alike: the dynamic modulus stage's temperature sets).
    """

    columns: dict = field(default_factory=dict)
    row: object = None
    stop: object = None
    watch: object = None
    target: object = None
    finish: object = None
    timing: object = None
    start: object = None
    bonds: object = None


def _restore(system, groups):
    """What a checkpoint's ``groups`` keep beyond the scene, back into a system built on them:
    the walls' positions, velocities, forces and radii, the engine's accumulators, and the
    stored loads (the first step uses them, as the interrupted run would have)."""
    from demcli.kernels.walls import W_RATE

    system.wpoint[:] = groups["walls"]["point"]
    system.wv[:] = groups["walls"]["v"]
    system.wforce[:] = groups["walls"]["force"]
    system.walls.radius[:] = groups["walls"]["radius"]
    c = groups["checkpoint"]
    if "wall_rate" in c:
        system.walls.prm[:, W_RATE] = c["wall_rate"]
    system.losses0 = dict(zip(("damping", "friction", "body_damping", "wall_work"), map(float, c["losses0"])))
    if len(system.esph):
        system.esph[:] = c["esph"]
        system.ebody[:] = c["ebody"]
    system.eacc[:] = c["eacc"]
    system.ke_limit = float(c["ke_limit"][0])
    system.prime = False


def integrate(ctx, cfg, state_in, hooks=None):
    """The ``dem`` stage loop on ``cfg`` (the dem schema's keys), with a stage's ``hooks``."""
    from demcli.kernels import layout as K

    hooks = hooks or Hooks()
    ckpt, system, plan, dt, dt_crit, total, rec_every = _setup(ctx, cfg, state_in, hooks)
    if hooks.start is not None:
        hooks.start(system, ckpt)
    ctx.log(f"dt = {dt:.4g} s = {dt / dt_crit:.3g} x critical {dt_crit:.4g} s; "
            f"effects: {', '.join(sorted(plan.effects)) or 'none'}")
    snap_every = max(1, total // cfg.output.snapshots) if cfg.output.snapshots else 0
    energy = plan.has("energy")
    table, wtable = _tables(ckpt, system, plan, hooks)
    ctable = _contact_table(ckpt, system, cfg.output.get("contacts"))
    ptable = _packing_table(ckpt, cfg.output.get("packing"))
    measures = StageMeasures.make(ctx, cfg, system, ckpt, plan.has("planar"))
    ended = None if ckpt is None else ckpt.groups["checkpoint"].get("ended")  # the loop had ended: why
    ended = None if ended is None else str(ended)
    snaps = StageSnapshots(ctx.snapshot_dir, system.plugin.name, resume=ckpt is not None, meshes=system.walls.mesh)
    if ckpt is not None:  # a checkpoint of the loop's end writes the final snapshot again
        snaps.truncate(system.time if ended is None else math.nextafter(system.time, -math.inf))
        if measures is not None:
            measures.truncate(system.time if ended is None else math.nextafter(system.time, -math.inf))
    nb = len(system.mass)
    d_mean = 2.0 * float(body_radii(system).mean())
    g = float(np.linalg.norm(system.gravity))
    e_unit = float(system.mass.mean()) * g * d_mean
    probe = None if ptable is None else PackingProbe(system, cfg.output.packing, plan.has("planar"),
                                                     float(ctx.case.get("thickness", 1.0)), d_mean, log=ctx.log,
                                                     friction=plan.has("friction"))

    def record():
        row = _record(system, plan, hooks, table, wtable)
        if ctable is not None:
            for crow in contact_rows(system, cfg.output.contacts.bodies):
                ctable.append(crow)
        if probe is not None:
            ptable.append(probe.row(system))
        if measures is not None:
            measures.record(system)
        return row

    def snapshot():
        snaps.write(ctx.state_from(system, plan, extra=None))
        if measures is not None:
            measures.snapshot(system)

    def checkpoint(ended=None):
        return _checkpoint(ctx, system, plan, (table, wtable, ctable, ptable) +
                           (tuple(measures.tables) if measures is not None else ()), ended)

    stepper = Stepper(ctx, system)
    if ckpt is None:
        stepper.advance(0)  # loads at x_0 before the first record: a checkpoint at step 0 holds them too
        record()
        if snap_every:
            snapshot()
    last_good = system.snapshot()
    ckpt_every = cfg.output.checkpoint
    ckpt_t = _time.perf_counter()
    start_step = system.step
    t0 = _time.perf_counter()
    progress = ctx.progress(total, start_step, len(system.rad))
    forecast = _stop_forecast(cfg, hooks, dt, e_unit, nb)
    chunk = min(rec_every, 200)
    stopped = ended or None

    def stop_reason(row):
        if cfg.stop is not None and system.time >= cfg.stop.min_time and \
                row["kinetic"] / max(nb, 1) < cfg.stop.kinetic_ratio * e_unit:
            return f"at rest (kinetic ratio < {cfg.stop.kinetic_ratio:g}) at t = {system.time:.4g} s"
        return hooks.stop(system, row) if hooks.stop is not None else None

    try:
        with interrupts.deferred() as poll:  # Ctrl-C and SIGTERM act between chunks
            while ended is None and system.step < total:
                nxt = min(total, (system.step // rec_every + 1) * rec_every)
                if snap_every:
                    nxt = min(nxt, (system.step // snap_every + 1) * snap_every)
                n = min(chunk, nxt - system.step)
                status, done, elapsed = stepper.advance(n)
                if status != K.OK:
                    ctx.fail(_diagnosis(ctx, system, status, dt, dt_crit, cfg), system, plan, last_good)
                # chunks of about 0.5 s keep Ctrl-C and progress responsive; physics does not depend on them
                chunk = max(1, min(rec_every, int(n * 0.5 / max(elapsed, 1e-6))))
                if system.step % rec_every == 0 or system.step == total:
                    row = record()
                    last_good = system.snapshot()
                    if forecast is not None:
                        forecast[0].add(system.step, forecast[1](row))
                    stopped = stop_reason(row)  # before a periodic checkpoint, which must not outlive a stop
                    if stopped:
                        break
                    if ckpt_every is not None and _time.perf_counter() - ckpt_t >= ckpt_every and system.step < total:
                        checkpoint()
                        ckpt_t = _time.perf_counter()
                if snap_every and system.step % snap_every == 0 and system.step < total:
                    snapshot()
                progress.update(system.step, forecast[0].end() if forecast is not None else None)
                poll()
    except KeyboardInterrupt:
        with interrupts.deferred(keep=False):  # a second Ctrl-C or SIGTERM does not cut the write short
            system.restore(last_good)
            # rows end at the last good step, which was taken right after a record; a stop
            # criterion that fired there ended the stepping
            path = checkpoint(ended=stopped) if stopped else checkpoint()
        progress.close()
        raise StageError(f"stage {ctx.name} interrupted at step {system.step}; continue with --resume",
                         state_file=path) from None
    finally:
        stepper.close()
    progress.close()
    wall = _time.perf_counter() - t0
    steps_run = system.step - start_step
    nsph = len(system.rad)
    rate = nsph * steps_run / wall if wall > 0 else 0.0
    ctx.log(f"{steps_run} steps in {wall:.2f} s: {rate:.3g} particle-steps/s"
            + (f"; stopped {stopped}" if stopped else ""))
    ctx.throughput = rate
    try:
        return _outputs(ctx, system, plan, (table, wtable, ctable, ptable), hooks, snapshot if snap_every else None,
                        energy, measures)
    except KeyboardInterrupt:
        with interrupts.deferred(keep=False):
            path = checkpoint(ended=stopped or "")
        raise StageError(f"stage {ctx.name} interrupted while writing its outputs (its {system.step} steps are done); "
                         "continue with --resume", state_file=path) from None


def _setup(ctx, cfg, state_in, hooks):
    """The stage's system on its input, or on its checkpoint when it resumes: (checkpoint or
    None, system, plan, dt, critical dt, last step, steps between records)."""
    ckpt = ctx.load_checkpoint()
    source = ckpt if ckpt is not None else state_in
    groups = source.groups
    if ckpt is not None and "phases" in state_in.groups:
        # input data the checkpoint does not repeat (bonds.from_phases reads its models there)
        groups = {**groups, "phases": state_in.groups["phases"]}
    if ckpt is not None and hooks.bonds is not None:  # the hook changes the input's models, not its own output
        groups = {k: v for k, v in groups.items() if k != "bond_models"}
        if "bond_models" in state_in.groups:
            groups["bond_models"] = state_in.groups["bond_models"]
    system, plan, dt, dt_crit = make_system(ctx, cfg, groups, time=float(source.meta.get("time", 0.0)) if ckpt
                                            else 0.0, step=int(source.meta.get("step", 0)) if ckpt else 0,
                                            resume=ckpt is not None, bonds=hooks.bonds)
    if ckpt is not None:
        _restore(system, groups)
    else:
        system.ke_limit = cfg.safety.energy_limit * reference_energy(system)
    if hooks.timing is not None:
        dt, total, rec_every = hooks.timing(system, dt, dt_crit)
        system.dt = dt
    else:
        total = step_count(cfg.time, dt)
        rec_every = max(1, total // cfg.output.records)
    return ckpt, system, plan, dt, dt_crit, total, rec_every


def _tables(ckpt, system, plan, hooks):
    """The ``dem`` and ``walls`` record tables (``walls`` None without walls): a resumed
    stage's from its checkpoint, else new ones with the columns of the plan's effects and of
    the stage's hooks."""
    from demcli.state import RecordTable

    if ckpt is not None:
        return RecordTable.from_state(ckpt, "dem"), RecordTable.from_state(ckpt, "walls") if len(system.walls) else None
    cols = {"time": "s", "step": "1", "kinetic": "J", "contacts": "1", "wall_contacts": "1", "coordination": "1"}
    if plan.has("energy"):
        cols.update({k: "J" for k in ("strain", "gravity", "damping", "friction", "body_damping", "wall_work",
                                      "total")})
    if plan.has("adaptive_damping"):
        cols["alpha"] = "1/s"
    if plan.has("bonds"):
        cols.update({"bonds_intact": "1", "broken_tension": "1", "broken_shear": "1", "bonds_seated": "1"})
        if np.any(system.bonds.internal()):
            cols.update({f"intra_{k}": "1" for k in system.bonds.internal_counts()})
    cols.update(hooks.columns)
    wtable = None
    if len(system.walls):
        wcols = {"time": "s"}
        for name in system.walls.name:
            wcols[f"{name}.position"] = "m"
            wcols[f"{name}.force"] = "N"
        wtable = RecordTable("walls", wcols)
    return RecordTable("dem", cols), wtable


def _contact_table(ckpt, system, spec):
    """The ``contacts`` record table of ``output.contacts`` (a resumed stage's from its
    checkpoint), or None without it; InputError for a scene it cannot record."""
    from demcli.state import RecordTable

    if spec is None:
        return None
    check_scene(system, spec)
    return RecordTable.from_state(ckpt, "contacts") if ckpt is not None else RecordTable("contacts", CONTACT_COLUMNS)


def _packing_table(ckpt, spec):
    """The ``packing`` record table of ``output.packing`` (a resumed stage's from its
    checkpoint), or None without it."""
    from demcli.state import RecordTable

    if spec is None:
        return None
    return RecordTable.from_state(ckpt, "packing") if ckpt is not None else RecordTable("packing", PACKING_COLUMNS)


def _record(system, plan, hooks, table, wtable):
    """One row into each table, now: the ``dem`` row (kinetic energy, contacts, coordination,
    the effects' and the hooks' columns) and the walls' positions and forces (docs/records.md
    gives their signs); returns the ``dem`` row."""
    nb = len(system.mass)
    ke = system.kinetic_energy()
    npp, npw = system.contact_count()
    row = {"time": system.time, "step": system.step, "kinetic": ke, "contacts": npp, "wall_contacts": npw,
           "coordination": (2.0 * npp + npw) / max(nb, 1)}
    if plan.has("energy"):
        row.update(system.energy_record())
        row["kinetic"] = ke
    if plan.has("adaptive_damping"):
        row["alpha"] = system.alpha
    if plan.has("bonds"):
        c = system.bonds.counts()
        row.update({"bonds_intact": c["intact"], "broken_tension": c["broken_tension"],
                    "broken_shear": c["broken_shear"], "bonds_seated": int(system.bonds.seated().sum())})
        if "intra_intact" in table.columns:
            row.update({f"intra_{k}": v for k, v in system.bonds.internal_counts().items()})
    if hooks.row is not None:
        row.update(hooks.row(system))
    table.append(row)
    if wtable is not None:
        wrow = {"time": system.time}
        for k, name in enumerate(system.walls.name):
            n = system.walls.normal[k]
            wrow[f"{name}.position"] = float(system.wpoint[k] @ n)
            wrow[f"{name}.force"] = float(-system.wforce[k] @ n)
        wtable.append(wrow)
    return row


def _checkpoint(ctx, system, plan, tables, ended=None):
    """Write the checkpoint of the system's current state, which must be right after a record,
    with the record ``tables`` (None: a table the stage lacks); ``ended``: why the stepping ended,
    "" for all steps done, when it has. Returns its path."""
    extra = {"checkpoint": {
        "losses0": np.array([system.losses0[k] for k in ("damping", "friction", "body_damping", "wall_work")]),
        "esph": system.esph.copy(), "ebody": system.ebody.copy(), "eacc": system.eacc.copy(),
        "ke_limit": np.array([system.ke_limit])}}
    if ended is not None:
        extra["checkpoint"]["ended"] = ended
    if len(system.walls):
        from demcli.kernels.walls import W_RATE

        extra["checkpoint"]["wall_rate"] = system.walls.prm[:, W_RATE].copy()
    st = ctx.state_from(system, plan, extra=extra)
    for t in tables:
        if t is not None:
            t.to_state(st)
    return ctx.write_checkpoint(st)


def _stop_forecast(cfg, hooks, dt, e_unit, nb):
    """(StopForecast, value of a record row) of the criterion that may end the stage early:
    the kinetic energy per body (``nb`` bodies) against ``stop.kinetic_ratio`` x m g d, or a stage's own
    ``hooks.watch``/``hooks.target``; None without either."""
    if cfg.stop is not None:
        earliest = int(math.ceil(cfg.stop.min_time / dt))
        return (StopForecast(cfg.stop.kinetic_ratio * e_unit, rising=False, log=True, earliest=earliest),
                lambda row: row["kinetic"] / max(nb, 1))
    if hooks.watch is not None and hooks.target is not None:
        return StopForecast(hooks.target[0], rising=hooks.target[1]), hooks.watch
    return None


def _outputs(ctx, system, plan, tables, hooks, snapshot, energy, measures=None):
    """The stage's outputs once its stepping has ended: the final snapshot, the state, the
    record files (``tables``: dem, walls or None, contacts or None, packing or None; the
    ``measures``' region tables) and the stage's own (``hooks.finish``)."""
    table, wtable, ctable, ptable = tables
    if snapshot is not None:
        snapshot()
    st = ctx.state_from(system, plan, extra=None)
    table.to_state(st)
    ctx.write_records(table, x="time", ys=["kinetic"], logy=True)
    if wtable is not None:
        wtable.to_state(st)
        ctx.write_records(wtable, x="time", ys=[c for c in wtable.to_arrays() if c.endswith(".force")])
    if ctable is not None:
        ctable.to_state(st)
        ctx.write_records(ctable, x="time", ys=["fn", "ft"], marker=".")
    if ptable is not None:
        ptable.to_state(st)
        ctx.write_records(ptable, x="time", ys=["solid_fraction"])
        ctx.write_records(ptable, x="time", ys=["coordination", "raw_coordination"], suffix="coordination")
    if measures is not None:
        measures.write(ctx, st)
    if energy:
        ctx.write_records(table, x="time", ys=["kinetic", "strain", "gravity", "damping", "friction",
                                                "body_damping", "total"], suffix="energy")
    if hooks.finish is not None:
        hooks.finish(ctx, system, st, table)
    return st


def _diagnosis(ctx, system, status, dt, dt_crit, cfg):
    from demcli.kernels import layout as K

    info = system.info
    where = f"stage {ctx.name} stopped at step {system.step} (t = {system.time:.6g} s): {K.STATUS_TEXT[status]}"
    if status == K.BAD_NUMBER:
        where += f" of body {int(system.body_id[int(info[0])])}"
    elif status == K.BAD_OVERLAP and system.plan.has("polyhedra"):
        other = "a wall" if int(info[1]) < 0 else f"body {int(system.body_id[int(info[1])])}"
        where += (f": body {int(system.body_id[int(info[0])])} and {other} overlap to a depth of "
                  f"{100 * info[2]:.3g} % of the bounding radius (limit {100 * cfg.safety.overlap_limit:.3g} %)")
    elif status == K.BAD_OVERLAP and int(info[1]) < 0:
        where += (f": sphere {int(info[0])} overlaps a wall by {100 * info[2]:.3g} % of its radius "
                  f"(limit {100 * cfg.safety.overlap_limit:.3g} %)")
    elif status == K.BAD_OVERLAP:
        where += (f": spheres {int(info[0])} and {int(info[1])} overlap {100 * info[2]:.3g} % of the smaller radius "
                  f"(limit {100 * cfg.safety.overlap_limit:.3g} %)")
    elif status == K.BAD_ENERGY:
        where += (f": kinetic energy {info[3]:.4g} J exceeds {cfg.safety.energy_limit:g} x the reference energy "
                  f"({system.ke_limit / cfg.safety.energy_limit:.4g} J)")
    where += f"; time step {dt:.4g} s is {dt / dt_crit:.3g} of the critical {dt_crit:.4g} s"
    return where
