"""``compact`` stage: rigid box walls press the carved aggregates (seed 000, step 7).

Built on the ``dem`` stage loop (:func:`demcli.stages.loop.integrate`), so it takes every
key of a ``dem`` stage (physics, contact, walls, time, output, neighbors, safety) and
adds ``target``. The walls must include one closed ``box`` wall; its faces move as the
box's ``motion`` map says: the seed's compaction is ``motion: {z1: {mode: servo, stress:
0.1 MPa}}`` (the lid servo-controlled to 0.1 MPa axial stress), other faces fixed.

At every record the stage adds, from the current wall positions,

* ``porosity`` = 1 - V_s / V_box, V_s the aggregates' solid volume (``aggregates/volume``:
  the lattice cells of each aggregate, or its balls, as the carve stage's
  ``mass_model`` says) and V_box the box between the walls;
* ``box_volume``, ``stress_x``, ``stress_y``, ``stress_z``: the mean normal force on the two
  faces of each axis over the face's current area (compressive positive).

A servo face first closes in at its ``max_speed`` (``target.approach: velocity``, the
default: the dem loop's servo slows down as soon as it touches a particle, by the stiffness
k_n + c_n / dt it assumes, however loose the packing); at the first record where it
carries half its target stress it becomes a servo with the speed limit
``target.settle_speed`` (default a tenth of ``max_speed``), so that the wall neither
rams the packing nor chatters against it; when its stress, averaged over 3 records, falls
below a quarter of the target (a force chain that formed and broke while the packing was
still loose), it closes in at ``max_speed`` again. ``approach: servo`` servo-controls from
the start. A servo face without an explicit ``area`` loads the face's current area: the stage resets
it from the wall positions at every record (the dem loop takes the area of the initial
box), so several faces can be servo-controlled at once, as in the seed, whose box shrank
on all sides (120 mm cube to 110.4 x 86.3 x 109.7 mm).

It stops early when ``target.porosity`` is reached, or when the stress on every servo
face (its own force over its current area, column ``stress_<face>``), averaged over the
last ``target.hold`` records, is within ``target.stress_tolerance`` (relative) of the
target while the porosity changed by less than ``target.porosity_change`` over those
records (a packing still creeping under the lid is not done). The average is needed: a
servo wall on a granular packing carries a fluctuating force, the more so the fewer
particles touch it. Porosity against time goes to ``records/<stage>_dem.csv`` and
``records/<stage>_dem_porosity.png``; the ``compaction`` group keeps the porosity before
and after, the final box and stresses and why it stopped.

A resumed stage (``--resume``) is bit-identical to an uninterrupted one: the switching
state is a function of the record rows, which the checkpoint keeps, and the stage sets the
faces' control again from it before the first step (the ``start`` hook).
"""

import numpy as np

from demcli.config.schema import Float, Int, Optional, Section, Str
from demcli.errors import InputError
from demcli.stages import dem, loop
from demcli.stages.asphalt.common import copy_group, solid_volume  # (it registers the seeds and aggregates groups)
from demcli.stages.base import ENGINE_KEEPS, ENGINE_OUTPUT, StageType, register_stage
from demcli.stages.timing import step_count, time_step
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

for _ax in "xyz":
    describe_column(f"stress_{_ax}", f"Stress {_ax}", "Pa", "kPa", 1e-3, table="dem",
                    doc=f"mean normal force on the two {_ax} faces over the face area (compression positive)")
    for _end in "01":
        describe_column(f"stress_{_ax}{_end}", f"Stress {_ax}{_end}", "Pa", "kPa", 1e-3, table="dem",
                        doc=f"servo face {_ax}{_end}: its force over its current area (compression positive)")

register_group("compaction", "Summary of a compact stage (seed 000): porosity before and after, final box",
               writer="stage compact")
for _name, _kind, _dims, _unit, _doc in [
        ("porosity_initial", "f", (), "1", "1 - solid volume / box volume at the start"),
        ("porosity_final", "f", (), "1", "1 - solid volume / box volume at the end"),
        ("solid_volume", "f", (), "m^3", "aggregate solid volume V_s"),
        ("box", "f", (6,), "m", "final box between the walls: xmin ymin zmin xmax ymax zmax"),
        ("stress", "f", (3,), "Pa", "final mean normal stress on the x, y and z faces"),
        ("stopped", "str", (), "", "why the stage ended")]:
    register(Field(f"compaction/{_name}", _kind, _dims, _unit, _doc, writer="stage compact"))

FACES = dem.FACES
SWITCH_UP = 0.5        # a face becomes a slow servo at this share of its target stress ...
SWITCH_DOWN = 0.25     # ... and closes in again when its mean over the last records falls below this
SWITCH_RECORDS = 3

FIELDS = dict(dem.FIELDS)
FIELDS["target"] = Section({
    "porosity": Optional(Float(min=0, max=1, min_inclusive=False, max_inclusive=False),
                         doc="stop when the porosity falls to this"),
    "stress_tolerance": Float(min=0, min_inclusive=False, default=0.03,
                              doc="servo faces: relative error of the averaged stress accepted as reached"),
    "hold": Int(min=1, default=10, doc="records the servo stress is averaged over"),
    "settle_speed": Optional(Float("m/s", min=0, min_inclusive=False),
                             doc="servo speed limit once a face carries half its target stress "
                                 "(default: max_speed / 10)"),
    "approach": Str(choices=["velocity", "servo"], default="velocity",
                    doc="servo faces close in at max_speed until they carry half the target stress, or servo "
                        "from the start"),
    "porosity_change": Float(min=0, default=0.002,
                             doc="servo: largest porosity change over those records (the packing has settled)"),
}, default={}, doc="when compaction is done (besides time.duration or time.steps)")


def _box_wall(node):
    boxes = [w for w in node.walls if w.type == "box"]
    return boxes[0] if len(boxes) == 1 else None


def _check(node, report):
    dem.check_stage(node, report)
    boxes = [k for k, w in enumerate(node.walls) if w.type == "box"]
    if len(boxes) != 1:
        report("walls", f"needs exactly one box wall (got {len(boxes)}): porosity is measured inside it", None)
        return
    w = node.walls[boxes[0]]
    if w.open:
        report(f"walls.{boxes[0]}.open", "the box must be closed to measure the porosity", list(w.open))
    for face in w.motion:
        if face not in FACES:
            report(f"walls.{boxes[0]}.motion.{face}", f"unknown face (faces: {', '.join(FACES)})", face)


class Porosity:
    """Hooks for :func:`demcli.stages.loop.integrate`: porosity and face stresses, servo switching, stop rules.

    What it changes in the system, the servo faces' control mode, speed limit (m/s) and
    loaded area (m^2), is a function of its record rows and the wall positions; a resumed
    stage rebuilds it from the checkpoint, which keeps both (``checkpoint``: the
    checkpoint State, None on a fresh start).
    """

    def __init__(self, cfg, system, solid, checkpoint=None):
        box = _box_wall(cfg)
        names = list(system.walls.name)
        self.idx = {f: names.index(f"{box.name}.{f}") for f in FACES}
        self.solid = solid
        self.cfg = cfg
        self.servo = {f: box.motion[f].stress for f in box.motion if box.motion[f].mode == "servo"}
        self.auto_area = {f for f in self.servo if box.motion[f].area is None}
        s = cfg.target.settle_speed
        self.settle = {f: s if s is not None else 0.1 * box.motion[f].max_speed for f in self.servo}
        self.vmax = {f: box.motion[f].max_speed for f in self.servo}
        self.approach = cfg.target.approach == "velocity"
        self.settling = set()
        self.history = []  # the rows stop() averages over
        self.recent = []  # the rows a face's switch back to closing in averages over
        self.reason = None
        if checkpoint is None:
            if self.approach:  # close in at max_speed; row() switches to servo
                for f in self.servo:
                    self._set_mode(system, f, settle=False)
        else:
            self._replay(checkpoint.groups["records/dem"])
            self._restore_walls(system)
            self.reason = str(checkpoint.groups["checkpoint"].get("ended") or "") or None  # it had stopped

    def _replay(self, rows):
        """The switching and stop state after the stored record rows: the first row is the
        initial record, which stop() does not see."""
        for k in range(len(rows["step"])):
            row = {c: float(v[k]) for c, v in rows.items()}
            self._switch(row)
            if k > 0:
                self._remember(row)

    def _restore_walls(self, system):
        """The servo faces' mode, speed limit and area as the rows left them (the checkpoint
        keeps the wall positions and velocities, the config gives the rest)."""
        for face in self.servo:
            if self.approach or face in self.settling:
                self._set_mode(system, face, face in self.settling)
        self._set_areas(system, self._size(system))

    def _size(self, system):
        lo, hi = self.box(system)
        return hi - lo

    def box(self, system):
        lo = np.array([system.wpoint[self.idx[f]][d] for d, f in enumerate(("x0", "y0", "z0"))])
        hi = np.array([system.wpoint[self.idx[f]][d] for d, f in enumerate(("x1", "y1", "z1"))])
        return lo, hi

    def face_force(self, system, face):
        k = self.idx[face]
        return float(-system.wforce[k] @ system.walls.normal[k])

    def _set_areas(self, system, size):
        """A servo face without an explicit area loads its current area (m^2)."""
        from demcli.kernels.walls import W_AREA

        for face in self.auto_area:
            system.walls.prm[self.idx[face], W_AREA] = _face_area(size, face)

    def _set_mode(self, system, face, settle):
        """Servo with the settle speed limit (settle) or close in at max_speed (approach: velocity);
        servo from the start (approach: servo): settling only lowers the speed limit."""
        from demcli.kernels.walls import SERVO, VELOCITY, W_VMAX

        k = self.idx[face]
        if not self.approach:
            system.walls.prm[k, W_VMAX] = min(self.vmax[face], self.settle[face])
        elif settle:  # close to the target: servo, slowly (no chatter)
            system.walls.control[k] = SERVO
            system.walls.prm[k, W_VMAX] = self.settle[face]
        else:
            system.walls.control[k] = VELOCITY
            system.wv[k] = self.vmax[face] * system.walls.normal[k]

    def _switch(self, out):
        """{face: settle (True) or close in again (False)} for the faces that change at this record
        row; keeps the settling faces and the recent rows up to date."""
        changes = {}
        for face, target in self.servo.items():
            key = f"stress_{face}"
            recent = [h[key] for h in self.recent] + [out[key]]
            if face not in self.settling and out[key] >= SWITCH_UP * target:
                changes[face] = True
            elif (self.approach and face in self.settling and len(recent) > SWITCH_RECORDS
                  and float(np.mean(recent[-SWITCH_RECORDS:])) < SWITCH_DOWN * target):
                changes[face] = False  # that was a passing force chain: close in again
        self.settling ^= set(changes)  # each change flips a face in or out
        self.recent = (self.recent + [out])[-SWITCH_RECORDS:]
        return changes

    def _remember(self, row):
        self.history = (self.history + [row])[-self.cfg.target.hold:]

    def row(self, system):
        size = self._size(system)
        vol = float(np.prod(size))
        out = {"porosity": 1.0 - self.solid / vol, "box_volume": vol}
        for d, ax in enumerate("xyz"):
            f = 0.5 * (self.face_force(system, f"{ax}0") + self.face_force(system, f"{ax}1"))
            out[f"stress_{ax}"] = f / _face_area(size, f"{ax}0")
        for face in self.servo:
            out[f"stress_{face}"] = self.face_force(system, face) / _face_area(size, face)
        self._set_areas(system, size)  # the servo's loaded area follows the moving faces
        for face, settle in self._switch(out).items():
            self._set_mode(system, face, settle)
        return out

    def stop(self, system, row):
        t = self.cfg.target
        if t.porosity is not None and row["porosity"] <= t.porosity:
            self.reason = f"at the target porosity {t.porosity:g} (porosity {row['porosity']:.4f})"
            return self.reason
        if not self.servo:
            return None
        self._remember(row)
        if len(self.history) < t.hold:
            return None
        poro = [h["porosity"] for h in self.history]
        if max(poro) - min(poro) > t.porosity_change:
            return None
        for face, target in self.servo.items():
            mean = float(np.mean([h[f"stress_{face}"] for h in self.history]))
            if target > 0 and abs(mean / target - 1.0) > t.stress_tolerance:
                return None
        self.reason = (f"at the servo stress ({', '.join(f'{f} {s / 1e6:g} MPa' for f, s in self.servo.items())}: "
                       f"mean of the last {t.hold} records within {100 * t.stress_tolerance:g} %)")
        return self.reason


def _face_area(size, face):
    """Area (m^2) of a box face of the box size (3,) (m)."""
    return float(np.prod(np.delete(size, FACES.index(face) // 2)))


def run(ctx, cfg, state_in):

    if "aggregates" not in state_in.groups:
        raise InputError(f"stage {ctx.name}: the input has no aggregates (run a carve stage first)")
    solid = solid_volume(state_in)
    box = _box_wall(cfg)
    lo, hi = np.array(box.min), np.array(box.max)
    c = state_in.sphere_centres()
    r = np.asarray(state_in["spheres/radius"])
    out = np.any(c - r[:, None] < lo - 1e-9, axis=1) | np.any(c + r[:, None] > hi + 1e-9, axis=1)
    if out.any():
        lo_t = ", ".join(f"{v * 1e3:g}" for v in lo)
        hi_t = ", ".join(f"{v * 1e3:g}" for v in hi)
        raise InputError(f"stage {ctx.name}: {int(out.sum())} spheres stick out of the box wall {box.name} "
                         f"({lo_t} - {hi_t} mm); make the box enclose the carving region")
    hook = {}

    def start(system, checkpoint):
        hook["p"] = Porosity(cfg, system, solid, checkpoint)

    def finish(ctx_, system, st, table):
        p = hook["p"]
        for name in ("aggregates", "seeds", "gradation"):
            g = copy_group(state_in, name)
            if g is not None:
                st.groups[name] = g
        last = p.row(system)
        lo_, hi_ = p.box(system)
        rows = table.to_arrays()
        stopped = p.reason
        st.groups["compaction"] = {
            "porosity_initial": np.float64(rows["porosity"][0]), "porosity_final": np.float64(last["porosity"]),
            "solid_volume": np.float64(solid), "box": np.r_[lo_, hi_],
            "stress": np.array([last["stress_x"], last["stress_y"], last["stress_z"]]),
            "stopped": np.array(stopped or "at the end of time", dtype=object)}
        ctx_.write_records(table, x="time", ys=["porosity"], suffix="porosity")
        ctx_.write_records(table, x="time", ys=["stress_x", "stress_y", "stress_z"]
                           + [f"stress_{f}" for f in p.servo], suffix="stress")
        size = (hi_ - lo_) * 1e3
        ctx_.log(f"porosity {rows['porosity'][0]:.4f} -> {last['porosity']:.4f}; box {size[0]:.1f} x {size[1]:.1f} x "
                 f"{size[2]:.1f} mm; stress x/y/z {last['stress_x'] / 1e3:.4g} / {last['stress_y'] / 1e3:.4g} / "
                 f"{last['stress_z'] / 1e3:.4g} kPa; stopped {stopped or 'at the end of time'}")

    columns = {"porosity": "1", "box_volume": "m^3", "stress_x": "Pa", "stress_y": "Pa", "stress_z": "Pa"}
    columns.update({f"stress_{f}": "Pa" for f in box.motion if box.motion[f].mode == "servo"})
    hooks = loop.Hooks(columns=columns, start=start, row=lambda system: hook["p"].row(system),
                      stop=lambda system, rec: hook["p"].stop(system, rec), finish=finish)
    return loop.integrate(ctx, cfg, state_in, hooks)


def _carve_scene(case, k):
    """(smallest body mass, material index) of the nearest earlier carve stage: one lattice cell."""
    from demcli.geometry.carving import element_volume

    place = carve = None
    for cfg in reversed(case.stages[:k]):
        if cfg.type == "carve" and carve is None:
            carve = cfg
        if cfg.type == "place_spheres" and place is None:
            place = cfg
    if carve is None or place is None:
        return None
    ext = np.array(place.region.max) - np.array(place.region.min)
    a = carve.lattice.spacing if carve.lattice.spacing is not None else float(ext.max()) / carve.lattice.count
    mat = case.materials[place.material]
    return mat.density * element_volume(a, carve.mass_model), 0.5 * a, list(case.materials).index(place.material)


def describe(cfg, case):
    """Plan, walls and the time step estimated from the smallest possible aggregate (one ball)."""
    from demcli.engine.materials import critical_time_step, pair_table

    k = [s.name for s in case.stages].index(cfg.name)
    plan = dem.plan_summary(case, cfg, {"clumps": True})
    lines = plan.describe().splitlines()
    box = _box_wall(cfg)
    if box is not None:
        motion = ", ".join(f"{f}: {m.mode}" + (f" {m.stress / 1e6:g} MPa" if m.mode == "servo" else "")
                           for f, m in box.motion.items()) or "all faces fixed"
        lines.append(f"box wall {box.name}: {motion}")
    if cfg.target.porosity is not None:
        lines.append(f"stops at porosity {cfg.target.porosity:g}")
    scene = _carve_scene(case, k)
    if scene is None:
        lines.append("time step: decided at run time")
        return "\n".join(lines)
    m, r, mat = scene
    model = dem.contact_model(cfg)
    mats = dem.case_materials(case)
    dtc = critical_time_step(model, pair_table(mats, model), mats, np.array([m]), np.array([r]), np.array([0]),
                             np.array([mat]))
    dt = time_step(dtc, cfg.time.dt, cfg.time.dt_factor, allow_unstable=True)  # describes; the run checks dt
    steps = step_count(cfg.time, dt)
    lines.append(f"time step: {dt:.4g} s = {dt / dtc:.3g} x critical {dtc:.4g} s ({model.law}, one-ball "
                 f"aggregate); up to {steps} steps")
    return "\n".join(lines)


register_stage(StageType(
    "compact", FIELDS, run, check=_check, describe=describe, orders_particles=True,
    requires=("bodies/x", "spheres/radius", "aggregates/volume"),
    provides=ENGINE_OUTPUT + ("compaction/*",), keeps=("aggregates", "seeds", "gradation") + ENGINE_KEEPS,
    case_check=dem.scene_check, plan=dem.plan_summary, file_digest=dem.mesh_digest,
    doc="box walls press the aggregates (servo stress or target porosity); porosity against time (seed 000)"))
