"""Idealised sand asphalt (seed 003, Collop, McDowell & Lee 2006): ``prepare`` and ``creep``.

``prepare`` builds a bonded cylindrical specimen of single-size spheres:

1. the sphere count (or radius) from the cylinder and a nominal solid fraction;
2. random placement without overlap at a reduced radius inside the cylinder and its two
   platens, then radius expansion back to the nominal radius in steps, each followed by
   cycling (frictionless linear contacts, local damping);
3. cycling to equilibrium with the walls fixed (mean unbalanced force below a share of
   the mean contact force);
4. radius reduction by a common factor until the isotropic stress (the contact virial
   over the cylinder volume) is below the target (the seed: 1 kPa), cycling between cuts;
5. spheres with fewer than ``grow.below`` contacts grown by ``grow.factor`` (the seed:
   fewer than 4 contacts, 1 %), and cycling again;
6. every contact bonded with the case's bond models (Burgers in the seed), or a random
   share ``bonds.fraction`` of them (the seed's variant with frictional contacts), and the
   cylinder wall removed: the state holds the spheres and the bonds, no walls.

Records ``prepare`` (one row per phase and cut: radius factor, solid fraction, isotropic
stress, coordination number, steps) and the group ``specimen`` (cylinder, solid fraction,
coordination number, radius) that ``creep`` reads.

``creep`` loads the specimen between two frictionless platens (``platen`` material):
uniaxial, a constant axial stress on the top platen (servo) with the lateral surface
free; triaxial, a constant confining stress through a servo-controlled cylinder wall
plus a deviator on the top platen. Axial, radial, volumetric and distortional strain
against time (records ``creep``, CSV + PNG), and the dilation gradient between two
distortional strains (the seed: 1 % and 4 %). The axial strain is the platens' distance; the
radial strain is the membrane's radius (triaxial) or the mean radial extent of the bonded
spheres of the outer layer (uniaxial; unbonded rattlers can leave the free surface).
"""

import math

import numpy as np

from demcli.config.schema import Float, Int, List, Optional, Section, Str, Tagged
from demcli.errors import InputError, StageError
from demcli.stages import dem, loop
from demcli.stages.asphalt.common import KINETIC_LIMIT_DOC, TEST_TIME, kinetic_ratio, quasi_static_warning
from demcli.stages.relax import cycle_to_equilibrium, unbalanced
from demcli.stages.base import ENGINE_KEEPS, ENGINE_OUTPUT, StageType, register_stage
from demcli.stages.timing import time_step
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

for _name, _label, _doc in [
        ("axial_strain", "Axial strain", "e_a = h / h0 - 1 of the platens' distance (tension positive, as the seed)"),
        ("radial_strain", "Radial strain", "e_r = r / r0 - 1 (tension positive)"),
        ("volumetric_strain", "Volumetric strain", "e_v = e_a + 2 e_r (dilation positive)"),
        ("distortional_strain", "Distortional strain", "e_d = |2/3 (e_a - e_r)|")]:
    describe_column(_name, _label, display="%", scale=100.0, table="creep", doc=_doc)
for _name, _label, _table, _doc in [
        ("axial_stress", "Axial stress", "creep", "top platen's force over the specimen's section (compression "
                                                  "positive)"),
        ("confining_stress", "Confining stress", "creep", "membrane pressure (0 uniaxial)"),
        ("isotropic_stress", "Isotropic stress", "prepare", "contact virial over the cylinder volume")]:
    describe_column(_name, _label, "Pa", "kPa", 1e-3, table=_table, doc=_doc)
describe_column("height", "Specimen height", "m", "mm", 1e3, table="creep", doc="the platens' distance h")
describe_column("radius", "Specimen radius", "m", "mm", 1e3, table="creep",
                doc="the membrane's radius (triaxial) or the bonded outer layer's mean radius scaled to r0 (uniaxial)")
describe_column("steps", "Steps", integer=True, table="prepare", doc="time steps cycled so far (cumulative)")

register_group("bonded_specimen", "The prepared cylindrical specimen (seed 003)", writer="stage prepare")
for _name, _unit, _doc in [("radius", "m", "specimen (cylinder) radius"),
                           ("height", "m", "specimen height (platen distance)"),
                           ("base_z", "m", "z of the bottom platen"),
                           ("sphere_radius", "m", "sphere radius after the radius reduction"),
                           ("radius_factor", "1", "final radius / nominal radius"),
                           ("solid_fraction", "1", "sphere volume / cylinder volume"),
                           ("coordination", "1", "2 x contacts / spheres, before bonding"),
                           ("isotropic_stress", "Pa", "mean stress before the wall was removed")]:
    register(Field(f"bonded_specimen/{_name}", "f", (), _unit, _doc, writer="stage prepare"))

PREPARE_FIELDS = {
    "cylinder": Section({"radius": Float("m", min=0, min_inclusive=False),
                         "height": Float("m", min=0, min_inclusive=False),
                         "base": Optional(List(Float("m"), min_len=3, max_len=3), doc="centre of the bottom face "
                                          "(default: origin)")}, doc="the specimen"),
    "count": Optional(Int(min=2), doc="number of spheres (default: from radius and solid_fraction)"),
    "radius": Optional(Float("m", min=0, min_inclusive=False),
                       doc="nominal sphere radius (default: from count and solid_fraction)"),
    "solid_fraction": Float(min=0, max=0.74, min_inclusive=False, default=0.66,
                            doc="nominal sphere volume / cylinder volume the count or radius follows from"),
    "material": Str(doc="sphere material"),
    "wall_material": Str(doc="cylinder and platen material"),
    "kn": Float("N/m", min=0, min_inclusive=False, doc="normal stiffness of the frictionless packing contacts"),
    "start_factor": Float(min=0.3, max=1, min_inclusive=False, default=0.75,
                          doc="placement radius / nominal radius"),
    "expansion_steps": Int(min=1, default=10, doc="radius expansion in this many equal factors"),
    "isotropic_stress": Float("Pa", min=0, min_inclusive=False, default=1e3,
                              doc="radius reduction ends below this mean stress"),
    "max_reduction": Float(min=0, max=0.2, min_inclusive=False, default=0.05,
                           doc="largest total radius reduction (the seed: < 3 %)"),
    "grow": Section({"below": Int(min=0, default=4, doc="spheres with fewer contacts grow"),
                     "factor": Float(min=1, default=1.01, doc="their radius factor")}, default={}),
    "equilibrium": Section({
        "ratio": Float(min=0, min_inclusive=False, default=1e-2,
                       doc="mean unbalanced force / mean contact force that counts as equilibrium"),
        "max_steps": Int(min=1, default=20000, doc="cycling steps per phase at most"),
    }, default={}),
    "local_damping": Float(min=0, max=1, max_inclusive=False, default=0.3,
                           doc="Cundall damping while packing (0.7 at dt_factor 0.3 chatters without settling)"),
    "dt_factor": Float(min=0, max=1, min_inclusive=False, default=0.2),
    "mass_scale": Float(min=1, default=1.0, doc="mass scaling while packing (power of 2; quasi-static)"),
    "bonds": Section({"models": dem.BOND_MODELS,
                      "gap": Float(min=0, default=1e-6, doc="pairs closer than gap x radius count as touching"),
                      "fraction": Float(min=0, max=1, default=1.0,
                                        doc="share of the contacts bonded, drawn at random (the seed's variant "
                                            "with frictional contacts: the others keep the creep stage's law)")},
                     doc="bond models by material pair; every contact (or a random share) is bonded at the end"),
}

PHASES = ("expand", "equilibrium", "reduce", "grow", "bonded")


def specimen_spheres(cfg):
    """(count, nominal radius [m]) of a prepare config: one is given, the other follows from
    the solid fraction of the cylinder."""
    c = cfg.cylinder
    vcyl = math.pi * c.radius ** 2 * c.height
    v1 = 4.0 / 3.0 * math.pi
    if cfg.radius is None:
        return cfg.count, (cfg.solid_fraction * vcyl / (cfg.count * v1)) ** (1.0 / 3.0)
    return int(round(cfg.solid_fraction * vcyl / (v1 * cfg.radius ** 3))), cfg.radius


def _check_prepare(node, report):
    from demcli.config.memory import check_memory

    if (node.count is None) == (node.radius is None):
        report("count", "give exactly one of count and radius (the other follows from solid_fraction)", node.count)
        return
    if node.mass_scale != 1.0 and 2.0 ** round(math.log2(node.mass_scale)) != node.mass_scale:
        report("mass_scale", "must be a power of 2 so that scaling is exact", node.mass_scale)
    n, r = specimen_spheres(node)
    key = "count" if node.radius is None else "radius"
    c = node.cylinder
    if 2 * r >= min(c.radius, c.height):
        report(key, f"spheres of radius {r:.4g} m do not fit a cylinder of radius {c.radius:.4g} m and height "
               f"{c.height:.4g} m", node[key])
    check_memory(report, key, n, "the specimen", node[key])


def _node(**kw):
    from demcli.config.schema import Node

    return Node(kw)


def specimen_walls(case, radius, height, base, material, cylinder=True):
    """Bottom and top platens (planes, normals into the specimen) and the cylinder wall."""
    walls = [_node(type="plane", name="bottom", point=tuple(base), normal=(0.0, 0.0, 1.0), material=material,
                   motion=None, extent=tuple(np.r_[base - [radius, radius, 0], base + [radius, radius, 0]])),
             _node(type="plane", name="top", point=tuple(base + [0, 0, height]), normal=(0.0, 0.0, -1.0),
                   material=material, motion=None,
                   extent=tuple(np.r_[base + [-radius, -radius, height], base + [radius, radius, height]]))]
    if cylinder:
        walls.append(_node(type="cylinder", name="cylinder", base=tuple(base), axis=(0.0, 0.0, 1.0), radius=radius,
                           height=height, material=material, motion=None))
    return dem.build_walls(_node(walls=walls), case)


def run_prepare(ctx, cfg, state_in):
    from demcli.engine.materials import ContactModel
    from demcli.engine.plan import make_plan
    from demcli.engine.system import Dynamics, System
    from demcli.kernels.placement import place_random
    from demcli.state.order import cell_order
    from demcli.state import RecordTable

    c = cfg.cylinder
    R, H = c.radius, c.height
    base = np.array(c.base if c.base is not None else (0.0, 0.0, 0.0), float)
    vcyl = math.pi * R * R * H
    v1 = 4.0 / 3.0 * math.pi
    n, r = specimen_spheres(cfg)  # that they fit the cylinder is checked at validation
    names = list(ctx.case.materials)
    r0 = r * cfg.start_factor
    lo, hi = base - [R, R, 0.0], base + [R, R, H]
    pos, placed = place_random(ctx.rng, lo, hi, np.full(n, r0), cylinder=(base[0], base[1], R))
    if placed < n:
        raise StageError(f"stage {ctx.name}: placed only {placed} of {n} spheres at {cfg.start_factor:g} x the "
                         "radius; lower start_factor")
    pos = pos[cell_order(pos, 2.0 * r0)]
    rho = ctx.case.materials[cfg.material].density
    m = np.full(n, rho * v1 * r0 ** 3)
    groups = {"bodies": {"x": pos, "v": np.zeros((n, 3)), "omega": np.zeros((n, 3)),
                         "q": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), "mass": m,
                         "inertia": np.repeat((0.4 * m * r0 * r0)[:, None], 3, axis=1),
                         "flags": np.zeros(n, np.int8), "id": np.arange(n, dtype=np.int64)},
              "spheres": {"body": np.arange(n, dtype=np.int64), "offset": np.zeros((n, 3)),
                          "radius": np.full(n, r0), "material": np.full(n, names.index(cfg.material), np.int64)}}
    walls = specimen_walls(ctx.case, R, H, base, cfg.wall_material)
    plan = make_plan(["local_damping", "bonds"], walls=True)
    system = System(groups, dem.case_materials(ctx.case), ContactModel(law="linear", kn=cfg.kn, kt=cfg.kn / 4.0),
                    plan, walls, Dynamics(gravity=(0.0, 0.0, 0.0), local_damping=cfg.local_damping),
                    dt=1.0, mass_scale=cfg.mass_scale)
    table = RecordTable("prepare", {"phase": "1", "radius_factor": "1", "solid_fraction": "1",
                                    "isotropic_stress": "Pa", "coordination": "1", "unbalanced": "1", "steps": "1"})  # steps: cumulative
    eq = cfg.equilibrium

    def set_dt():
        system.dt = time_step(system.critical_dt(), dt_factor=cfg.dt_factor)

    def cycle(max_steps):
        return cycle_to_equilibrium(ctx, system, max_steps, eq.ratio)

    def measures():
        """(isotropic stress [Pa], solid fraction, coordination: contacts and bonds per sphere)."""
        p = float(np.trace(system.stress(vcyl))) / 3.0
        return p, float(v1 * np.sum(system.rad ** 3) / vcyl), float(system.contacts_per_sphere().mean())

    def record(phase, _steps, stress=None):
        p, phi, z = measures()
        p = p if stress is None else stress
        table.append({"phase": PHASES.index(phase) + 1, "radius_factor": float(system.rad.mean()) / r,
                      "solid_fraction": phi, "isotropic_stress": p, "coordination": z,
                      "unbalanced": unbalanced(system), "steps": system.step})
        return p, phi, z

    grow = (1.0 / cfg.start_factor) ** (1.0 / cfg.expansion_steps)
    for _ in range(cfg.expansion_steps):
        system.scale_radii(grow)
        set_dt()
        record("expand", cycle(max(200, eq.max_steps // cfg.expansion_steps)))
    system.rad[:] = r  # the product of the factors, exactly
    p, _, _ = record("equilibrium", cycle(eq.max_steps))
    ctx.log(f"{n} spheres of {r * 1e3:.4g} mm packed: isotropic stress {p:.4g} Pa")
    while p > cfg.isotropic_stress:
        act = system.nl.act.astype(bool)
        pi, pj = system.nl.pi[act], system.nl.pj[act]
        overlap = float(np.mean(system.rad[pi] + system.rad[pj] - np.linalg.norm(system.xs[pi] - system.xs[pj],
                                                                                  axis=1))) if act.any() else 0.0
        # linear contacts: the stress follows the mean overlap; each cut removes 80 % of the overlap
        # the target asks for (a contact loses 2 r cut of overlap)
        cut = max(0.4 * overlap * (1.0 - cfg.isotropic_stress / p) / r, 1e-6)
        system.scale_radii(1.0 - cut)
        if 1.0 - float(system.rad.max()) / r > cfg.max_reduction:
            raise StageError(f"stage {ctx.name}: the radii shrank by more than {100 * cfg.max_reduction:g} % and the "
                             f"isotropic stress is still {p:.4g} Pa; raise max_reduction or lower the count")
        set_dt()
        p, _, _ = record("reduce", cycle(eq.max_steps))
    few = system.contacts_per_sphere() < cfg.grow.below
    system.scale_radii(np.where(few, cfg.grow.factor, 1.0))
    set_dt()
    p, phi, z = record("grow", cycle(eq.max_steps))
    ctx.log(f"radius reduced to {float(np.median(system.rad)) / r:.4f} of nominal; {int(few.sum())} spheres "
            f"({100 * few.mean():.3g} %) with < {cfg.grow.below} contacts grown by {cfg.grow.factor:g}; "
            f"solid fraction {phi:.4f}, coordination {z:.3f}, isotropic stress {p:.4g} Pa")
    dem.set_bond_models(ctx, cfg.bonds, system)
    nb = system.bond_touching(cfg.bonds.gap * r, cfg.bonds.fraction, ctx.rng)
    system.v[:] = 0.0
    system.w[:] = 0.0
    record("bonded", 0, stress=p)  # the bonds' forces start at the next step: the stress is the one bonded
    ctx.log(f"bonded {nb} contacts ({2.0 * nb / n:.3f} per sphere); cylinder wall removed")
    st = ctx.state_from(system, plan)
    for g in ("walls", "wall_contacts"):
        st.groups.pop(g, None)
    st.groups["bonded_specimen"] = {"radius": np.float64(R), "height": np.float64(H), "base_z": np.float64(base[2]),
                             "sphere_radius": np.float64(np.median(system.rad)),
                             "radius_factor": np.float64(np.median(system.rad) / r), "solid_fraction": np.float64(phi),
                             "coordination": np.float64(z), "isotropic_stress": np.float64(p)}
    table.to_state(st)
    ctx.write_records(table, x="steps", ys=["isotropic_stress"], logy=True)
    snaps = loop.StageSnapshots(ctx.snapshot_dir, "spheres", resume=False)
    snaps.write(st)
    return st


register_stage(StageType(
    "prepare", PREPARE_FIELDS, run_prepare, needs_input=False, check=_check_prepare,
    provides=("bodies/*", "spheres/*", "contacts/*", "energy/*", "records/*", "bonds/*", "bond_models/*",
              "bonded_specimen/*"),
    doc="seed 003: a bonded cylindrical specimen of single-size spheres at a low isotropic stress"))


def _creep_fields():
    f = {k: v for k, v in dem.FIELDS.items() if k not in ("walls", "stop", "time")}
    f.update({
        "test": Tagged("type", {
            "uniaxial": Section({"axial_stress": Float("Pa", min=0, min_inclusive=False,
                                                       doc="constant axial stress (the seed: 400 kPa)")},
                                doc="constant axial stress, lateral surface free"),
            "triaxial": Section({
                "deviator": Float("Pa", min=0, min_inclusive=False, doc="q = sigma_1 - sigma_3"),
                "stress_ratio": Float(min=0, min_inclusive=False, doc="p / q with p = sigma_3 + q/3 (the seed: 0.6, 0.8)"),
            }, doc="constant confining stress sigma_3 (servo-controlled cylinder wall) plus the deviator"),
        }, doc="the creep test"),
        "duration": Float("s", min=0, min_inclusive=False, doc="loading time"),
        "platen_material": Str(doc="platen (and triaxial cylinder) material; make its friction 0"),
        "load_mass": Optional(Float("kg", min=0, min_inclusive=False),
                              doc="mass of the top platen and of the membrane (default: 1 % of the specimen's)"),
        "time": TEST_TIME,
        "dilation_window": List(Float(min=0), min_len=2, max_len=2, default=(0.01, 0.04),
                                doc="distortional strains between which the dilation gradient is fitted"),
        "quasi_static": Float(min=0, min_inclusive=False, default=0.01, doc=KINETIC_LIMIT_DOC),
        "transient": Float(min=0, max=1, max_inclusive=False, default=0.05,
                           doc="share of the duration after the step load whose rows the quasi-static check skips "
                               "(the step rings for a few periods of the specimen's axial mode)"),
    })
    return f


def confining_stress(test):
    """(sigma_1, sigma_3) [Pa] of a creep test: uniaxial (sigma_a, 0); triaxial
    sigma_3 = (p/q - 1/3) q, sigma_1 = sigma_3 + q."""
    if test.type == "uniaxial":
        return test.axial_stress, 0.0
    s3 = (test.stress_ratio - 1.0 / 3.0) * test.deviator
    return s3 + test.deviator, s3


def _check_creep(node, report):
    if node.test.type == "triaxial" and node.test.stress_ratio <= 1.0 / 3.0:
        report("test.stress_ratio", "must exceed 1/3 (p/q = 1/3 is a zero confining stress)", node.test.stress_ratio)
    lo, hi = node.dilation_window
    if hi <= lo:
        report("dilation_window", "needs two distortional strains, the second larger", list(node.dilation_window))


def strains(h0, h, r0, r):
    """(axial, radial, volumetric, distortional) strain, tension positive as in the seed:
    e_a = h/h0 - 1, e_r = r/r0 - 1, e_v = e_a + 2 e_r, e_d = |2/3 (e_a - e_r)|."""
    ea = h / h0 - 1.0
    er = r / r0 - 1.0
    return ea, er, ea + 2.0 * er, abs(2.0 / 3.0 * (ea - er))


def loading_work(axial_force, height, radius, sigma_3):
    """Work done on a creep specimen per record row [J] (trapezoid over the rows): the top
    platen's force F_a [N] through the shortening -dh of the height h [m], plus the confining
    stress sigma_3 [Pa] through the lateral volume change, -sigma_3 2 pi r h dr (r [m] the
    specimen's radius: the membrane's, or the bonded outer layer's when uniaxial, sigma_3 = 0)."""
    fa, h, r = (np.asarray(a, float) for a in (axial_force, height, radius))
    dw = 0.5 * (fa[1:] + fa[:-1]) * -np.diff(h)
    dw -= sigma_3 * 2.0 * math.pi * 0.5 * (r[1:] * h[1:] + r[:-1] * h[:-1]) * np.diff(r)
    return np.concatenate([[0.0], np.cumsum(dw)])


def dilation_gradient(ed, ev, window):
    """Slope of e_v against e_d between the window's distortional strains (least squares);
    NaN when fewer than 3 records fall inside."""
    ed, ev = np.asarray(ed), np.asarray(ev)
    inside = (ed >= window[0]) & (ed <= window[1])
    if inside.sum() < 3:
        return math.nan
    return float(np.polyfit(ed[inside], ev[inside], 1)[0])


def run_creep(ctx, cfg, state_in):
    from demcli.config.schema import Node
    from demcli.state import RecordTable

    sp = state_in.groups.get("bonded_specimen")
    if sp is None:
        raise InputError(f"stage {ctx.name}: its input has no bonded_specimen group (written by a prepare stage)")
    R0, H0, z0 = float(sp["radius"]), float(sp["height"]), float(sp["base_z"])
    s1, s3 = confining_stress(cfg.test)
    x = np.asarray(state_in.groups["bodies"]["x"])
    c = x[:, :2].mean(axis=0)
    base = np.array([c[0], c[1], z0])
    area = math.pi * R0 * R0
    # dead loads: a platen and a membrane with mass, 1 % of the specimen's (mass-scaled with it): light
    # enough to follow the specimen without ringing, heavy enough for the time step (M > sum k dt^2 / 4);
    # a servo would lag behind a creeping specimen by tens of kPa
    mload = cfg.load_mass if cfg.load_mass is not None else \
        0.01 * float(np.sum(state_in.groups["bodies"]["mass"])) * cfg.scaling.mass

    walls = [Node({"type": "plane", "name": "bottom", "point": tuple(base), "normal": (0.0, 0.0, 1.0),
                   "material": cfg.platen_material, "motion": None, "lay_on_particles": None,
                   "extent": tuple(np.r_[base - [R0, R0, 0], base + [R0, R0, 0]])}),
             Node({"type": "plane", "name": "top", "point": tuple(base + [0, 0, H0]), "normal": (0.0, 0.0, -1.0),
                   "material": cfg.platen_material, "lay_on_particles": None,
                   "motion": Node({"mode": "force", "force": s1 * area, "amplitude": 0.0, "frequency": 0.0,
                                   "phase": 0.0, "start": 0.0, "mass": mload, "weight": False}),
                   "extent": tuple(np.r_[base + [-R0, -R0, H0], base + [R0, R0, H0]])})]
    if s3 > 0:
        walls.append(Node({"type": "cylinder", "name": "membrane", "base": tuple(base), "axis": (0.0, 0.0, 1.0),
                           "radius": R0, "height": H0, "material": cfg.platen_material,
                           "motion": Node({"mode": "pressure", "pressure": s3, "mass": mload, "area": None})}))
    dcfg = dict(cfg)
    dcfg["walls"] = walls
    dcfg["stop"] = None
    dcfg["time"] = Node({"duration": cfg.duration, "steps": None, "dt": cfg.time.dt, "dt_factor": cfg.time.dt_factor})
    rad = np.asarray(state_in.groups["spheres"]["radius"])
    rho0 = np.hypot(x[:, 0] - c[0], x[:, 1] - c[1]) + rad
    bd = state_in.groups["bonds"]
    held = np.zeros(len(rad), bool)  # spheres without a bond (rattlers) are free to drift off
    ok = np.asarray(bd["state"]) == 0
    held[np.asarray(bd["i"])[ok]] = True
    held[np.asarray(bd["j"])[ok]] = True
    shell = held & (rho0 > R0 - 2.0 * float(np.median(rad)))  # the bonded outer layer, one diameter thick
    r_ref = float(rho0[shell].mean())
    cols = {"axial_strain": "1", "radial_strain": "1", "volumetric_strain": "1", "distortional_strain": "1",
            "axial_stress": "Pa", "confining_stress": "Pa", "height": "m", "radius": "m"}

    def measure(system):
        h = float(system.wpoint[1, 2] - system.wpoint[0, 2])
        if s3 > 0:
            r_now, r0 = float(system.walls.radius[2]), R0
        else:
            xs = system.x[shell]
            r_now = float((np.hypot(xs[:, 0] - c[0], xs[:, 1] - c[1]) + system.rad[shell]).mean())
            r0 = r_ref
        return h, r_now, r0

    def row(system):
        h, r_now, r0 = measure(system)
        ea, er, ev, ed = strains(H0, h, r0, r_now)
        sa = float(-system.wforce[1] @ system.walls.normal[1]) / area
        return {"axial_strain": ea, "radial_strain": er, "volumetric_strain": ev, "distortional_strain": ed,
                "axial_stress": sa, "confining_stress": s3, "height": h, "radius": r_now * R0 / r0}

    def finish(ctx_, system, state, table):
        rows = table.to_arrays()
        work = loading_work(rows["axial_stress"] * area, rows["height"], rows["radius"], s3)
        ratio = kinetic_ratio(rows["kinetic"], work)
        i0 = int(np.searchsorted(rows["time"], rows["time"][0] + cfg.transient * cfg.duration))
        worst = quasi_static_warning(ctx_, ratio[i0:], work[i0:], cfg.quasi_static,
                                     "less mass scaling or a slower creep rate keeps the bodies' motion small")
        t = RecordTable("creep", {"time": "s", **cols, "kinetic_to_work": "1"})
        for k in range(len(rows["time"])):
            t.append({"time": rows["time"][k], **{n: rows[n][k] for n in cols}, "kinetic_to_work": ratio[k]})
        t.to_state(state)
        ctx_.write_records(t, x="time", ys=["axial_strain", "radial_strain", "volumetric_strain"])
        ctx_.write_records(t, x="distortional_strain", ys=["volumetric_strain"], suffix="dilation")
        slope = dilation_gradient(rows["distortional_strain"], rows["volumetric_strain"], cfg.dilation_window)
        state.groups["creep_result"] = {"sigma_1": np.float64(s1), "sigma_3": np.float64(s3),
                                        "dilation_gradient": np.float64(slope),
                                        "final_axial_strain": np.float64(rows["axial_strain"][-1]),
                                        "kinetic_to_work": np.float64(worst)}
        state.groups["bonded_specimen"] = dict(state_in.groups["bonded_specimen"])
        ctx_.log(f"creep at sigma_1 {s1 / 1e3:.4g} kPa, sigma_3 {s3 / 1e3:.4g} kPa: axial strain "
                 f"{rows['axial_strain'][-1]:.4g} after {cfg.duration:g} s; dilation gradient {slope:.3g} "
                 f"between e_d = {cfg.dilation_window[0]:g} and {cfg.dilation_window[1]:g}")

    hooks = loop.Hooks(columns=cols, row=row, finish=finish)
    return loop.integrate(ctx, Node(dcfg), state_in, hooks)


register_group("creep_result", "Summary of a creep test (seed 003)", writer="stage creep")
for _name, _unit, _doc in [("sigma_1", "Pa", "axial stress applied"), ("sigma_3", "Pa", "confining stress applied"),
                           ("dilation_gradient", "1", "d e_v / d e_d in the dilation window (NaN: not reached)"),
                           ("final_axial_strain", "1", "axial strain at the end (tension positive)"),
                           ("kinetic_to_work", "1", "largest kinetic energy / loading work over the rows after the "
                            "transient, from the one where the work reaches 5 % of its largest (NaN: no work)")]:
    register(Field(f"creep_result/{_name}", "f", (), _unit, _doc, writer="stage creep",
                   required=_name != "kinetic_to_work"))  # states written before the check lack it

register_stage(StageType(
    "creep", _creep_fields(), run_creep, needs_input=True, requires=("bonded_specimen/radius", "bonds/i"),
    provides=ENGINE_OUTPUT + ("creep_result/*",), keeps=ENGINE_KEEPS + ("bonded_specimen",),
    case_check=dem.scene_check, check=_check_creep, doc="seed 003: uniaxial or triaxial creep of a bonded specimen between frictionless platens"))
