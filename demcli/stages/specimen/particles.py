"""``particles`` stage: spheres placed where the case says, with their velocity and spin.

The particles are listed inline (``particles:``) or read from a CSV file (``file:``, relative to
the case file; one header line ``x,y,z,vx,vy,vz,wx,wy,wz,radius,material`` and optionally
``fixed``, SI units: m, m/s, rad/s; material by name). This is how a validation case sets up an
impact: one sphere at a given height, speed and spin (Chung & Ooi 2011). A ``fixed`` particle
keeps its velocity and spin whatever its contacts do (it moves at its given velocity: a
prescribed-motion body).

With ``add: true`` the stage adds its particles to the scene of the stage before instead of
starting a new scene (``generate`` has the same key): every group of the input is kept and the
new bodies and spheres are appended (ids continue after the largest). A scene with polyhedra or
actors cannot be added to (their bodies must stay last).
"""

import csv
import hashlib
import math
from pathlib import Path

import numpy as np

from demcli.config.schema import Bool, Float, List, Optional, Section, Str, Vector
from demcli.errors import InputError
from demcli.stages.base import StageType, register_stage

COLUMNS = ("x", "y", "z", "vx", "vy", "vz", "wx", "wy", "wz", "radius", "material")
"""The CSV columns a particle file must have (``fixed``: optional, 0 or 1)."""

PARTICLE = Section({
    "x": Vector(3, "m", doc="centre"),
    "v": Vector(3, "m/s", default=(0.0, 0.0, 0.0), doc="velocity"),
    "omega": Vector(3, "rad/s", default=(0.0, 0.0, 0.0), doc="angular velocity"),
    "radius": Float("m", min=0, min_inclusive=False),
    "material": Str(doc="material name"),
    "fixed": Bool(default=False, doc="keeps its velocity and spin (moves at its given velocity)"),
}, doc="one sphere")

ADD = Bool(default=False, doc="add the particles to the scene of the stage before instead of starting a new scene "
                              "(not to a scene with polyhedra or actors)")

FIELDS = {
    "particles": Optional(List(PARTICLE, min_len=1), doc="the spheres, inline"),
    "file": Optional(Str(doc="CSV file of the spheres (relative to the case file): header x,y,z,vx,vy,vz,wx,wy,wz,"
                             "radius,material[,fixed], SI units")),
    "add": ADD,
}


def _check(node, report):
    if (node.particles is None) == (node.file is None):
        report("particles", "give exactly one of particles (inline) or file (CSV)", None)


def case_file_path(case_dir, name):
    """``name`` relative to the case file's folder ``case_dir`` (absolute names as they are)."""
    path = Path(name)
    return path if path.is_absolute() else Path(case_dir) / path


def _number(path, line, column, text):
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{path}:{line}: column {column}: not a number: {text!r}") from None
    if not math.isfinite(value):
        raise InputError(f"{path}:{line}: column {column}: not finite: {text!r}")
    return value


def read_particle_file(path, materials):
    """The rows of a particle CSV as a dict of arrays (x, v, omega (n, 3); radius (n,); material
    (n,) indices into ``materials``; fixed (n,) bool). InputError naming file, line, column and
    value for anything wrong."""
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = list(csv.reader(f))
    except OSError as exc:
        raise InputError(f"cannot read particle file {path}: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None
    if not rows:
        raise InputError(f"{path}: empty (a header line {','.join(COLUMNS)} and one row per particle)")
    header = [h.strip() for h in rows[0]]
    missing = [c for c in COLUMNS if c not in header]
    unknown = [h for h in header if h not in COLUMNS + ("fixed",)]
    if missing or unknown:
        raise InputError(f"{path}:1: header: " + "; ".join(
            ([f"missing column(s) {', '.join(missing)}"] if missing else [])
            + ([f"unknown column(s) {', '.join(unknown)}"] if unknown else [])))
    col = {h: k for k, h in enumerate(header)}
    out = {k: [] for k in ("x", "v", "omega", "radius", "material", "fixed")}
    for line, row in enumerate(rows[1:], start=2):
        if not row or all(not c.strip() for c in row):
            continue
        if len(row) != len(header):
            raise InputError(f"{path}:{line}: {len(row)} fields, the header has {len(header)}")
        val = {c: row[col[c]].strip() for c in header}
        num = {c: _number(path, line, c, val[c]) for c in header if c not in ("material", "fixed")}
        if num["radius"] <= 0:
            raise InputError(f"{path}:{line}: column radius: must be > 0: {val['radius']!r}")
        if val["material"] not in materials:
            raise InputError(f"{path}:{line}: column material: unknown material {val['material']!r} "
                             f"(materials: {', '.join(materials)})")
        fixed = val.get("fixed", "0")
        if fixed not in ("0", "1"):
            raise InputError(f"{path}:{line}: column fixed: 0 or 1, not {fixed!r}")
        out["x"].append([num["x"], num["y"], num["z"]])
        out["v"].append([num["vx"], num["vy"], num["vz"]])
        out["omega"].append([num["wx"], num["wy"], num["wz"]])
        out["radius"].append(num["radius"])
        out["material"].append(list(materials).index(val["material"]))
        out["fixed"].append(fixed == "1")
    if not out["radius"]:
        raise InputError(f"{path}: no particle rows")
    return {"x": np.array(out["x"], float), "v": np.array(out["v"], float), "omega": np.array(out["omega"], float),
            "radius": np.array(out["radius"], float), "material": np.array(out["material"], np.int64),
            "fixed": np.array(out["fixed"], bool)}


def _inline(cfg, materials):
    ps = cfg.particles
    return {"x": np.array([p.x for p in ps], float), "v": np.array([p.v for p in ps], float),
            "omega": np.array([p.omega for p in ps], float), "radius": np.array([p.radius for p in ps], float),
            "material": np.array([list(materials).index(p.material) for p in ps], np.int64),
            "fixed": np.array([p.fixed for p in ps], bool)}


def sphere_bodies(p, density, planar, thickness):
    """(bodies, spheres) groups of single spheres from the arrays of :func:`read_particle_file`
    (``density``: (n,) kg/m^3; planar: disks of the case's thickness)."""
    from demcli.kernels.layout import FIX_ROTATION, FIX_TRANSLATION

    n, r = len(p["radius"]), p["radius"]
    if planar:
        mass = density * thickness * np.pi * r ** 2
        inertia = np.repeat((0.5 * mass * r ** 2)[:, None], 3, axis=1)
    else:
        mass = density * 4.0 / 3.0 * np.pi * r ** 3
        inertia = np.repeat((0.4 * mass * r ** 2)[:, None], 3, axis=1)
    flags = np.where(p["fixed"], FIX_TRANSLATION | FIX_ROTATION, 0).astype(np.int8)
    bodies = {"x": p["x"], "v": p["v"], "q": np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)), "omega": p["omega"],
              "mass": mass, "inertia": inertia, "id": np.arange(n, dtype=np.int64), "flags": flags}
    spheres = {"body": np.arange(n, dtype=np.int64), "offset": np.zeros((n, 3)), "radius": r.copy(),
               "material": p["material"]}
    return bodies, spheres


def add_to_scene(ctx, state_in, bodies, spheres):
    """A state of the input's groups with ``bodies`` and their ``spheres`` appended: ids after the
    input's largest, sphere body indices shifted, per-body fields the new bodies lack (force,
    torque, angular momentum) zero (a sphere's L = I omega), and ``set`` -1 for the bodies of
    either side that came from no ``sets:`` list."""
    from demcli.errors import StageError

    for group in ("polyhedra", "actors"):
        if state_in.has_group(group):
            raise StageError(f"stage {ctx.name}: cannot add particles to a scene with {group} (their bodies stay "
                             "last)")
    old_b, old_s = state_in.groups["bodies"], state_in.groups["spheres"]
    nb0 = len(old_b["x"])
    bodies = dict(bodies, id=bodies["id"] + (int(np.max(old_b["id"])) + 1 if nb0 else 0))
    if "angmom" in old_b:
        bodies["angmom"] = bodies["inertia"] * bodies["omega"]
    if "set" in bodies or "set" in old_b:  # bodies of no generate sets: list are set -1
        old_b = dict(old_b, set=old_b.get("set", np.full(nb0, -1, np.int64)))
        bodies = dict(bodies, set=bodies.get("set", np.full(len(bodies["x"]), -1, np.int64)))
    merged_b = {}
    for key, arr in old_b.items():
        new = bodies.get(key, np.zeros((len(bodies["x"]),) + np.shape(arr)[1:], np.asarray(arr).dtype))
        merged_b[key] = np.concatenate([np.asarray(arr), np.asarray(new, np.asarray(arr).dtype)])
    spheres = dict(spheres, body=spheres["body"] + nb0)
    merged_s = {key: np.concatenate([np.asarray(arr), np.asarray(spheres[key], np.asarray(arr).dtype)])
                for key, arr in old_s.items()}
    st = ctx.new_state(effects=state_in.meta.get("effects", ()), time=state_in.meta.get("time", 0.0),
                       step=state_in.meta.get("step", 0), dt=state_in.meta.get("dt", 0.0))
    st.groups.update({g: dict(v) for g, v in state_in.groups.items() if g != "materials"})
    st.groups["bodies"] = merged_b
    st.groups["spheres"] = merged_s
    return st


def scene_or_added(ctx, cfg, state_in, bodies, spheres):
    """The new scene of ``bodies`` and ``spheres``, or the input with them added (``cfg.add``)."""
    if cfg.add:
        return add_to_scene(ctx, state_in, bodies, spheres)
    st = ctx.new_state(effects=())
    st.groups["bodies"] = bodies
    st.groups["spheres"] = spheres
    return st


def check_addable(cfg, scene, report):
    """``add: true`` needs an input scene of spheres or clumps without polyhedra or actors."""
    if not cfg.add or scene is None:
        return
    for group in ("polyhedra", "actors"):
        if any(f.startswith(group + "/") for f in scene):
            report("add", f"the input scene has {group}: particles cannot be added to it (its bodies stay last)",
                   cfg.add)
    if not any(f.startswith("spheres/") for f in scene):
        report("add", "the input holds no scene of spheres to add to", cfg.add)


def _case_check(cfg, case, k, scene, report):
    check_addable(cfg, scene, report)
    if cfg.particles is not None and case.dimension == 2:
        for i, p in enumerate(cfg.particles):
            if p.v[2] != 0.0 or p.omega[0] != 0.0 or p.omega[1] != 0.0:
                report(f"particles.{i}", "a 2D case's disks move in the plane: v_z, omega_x and omega_y must be 0")


def file_digest(cfg, case_dir):
    """sha256 of the particle file (part of the stage's config hash: an edited file runs the stage
    again); None without a file or when it cannot be read (the run reports that)."""
    if cfg.get("file") is None:
        return None
    try:
        return hashlib.sha256(case_file_path(case_dir, cfg.file).read_bytes()).hexdigest()
    except OSError:
        return None


def run(ctx, cfg, state_in):
    """Place the listed spheres (a new scene, or added to the input's with ``add``)."""
    materials = list(ctx.case.materials)
    if cfg.file is not None:
        p = read_particle_file(case_file_path(ctx.runner.case_path.resolve().parent, cfg.file), materials)
    else:
        p = _inline(cfg, materials)
    density = np.array([ctx.case.materials[m].density for m in materials])[p["material"]]
    planar = ctx.case.dimension == 2
    bodies, spheres = sphere_bodies(p, density, planar, ctx.case.thickness if planar else 0.0)
    ctx.log(f"{'added' if cfg.add else 'placed'} {len(p['radius'])} sphere(s)"
            f"{', ' + str(int(p['fixed'].sum())) + ' fixed' if p['fixed'].any() else ''}")
    return scene_or_added(ctx, cfg, state_in, bodies, spheres)


def describe(cfg, case):
    """One line for ``demcli check``."""
    where = f"from {cfg.file}" if cfg.file is not None else f"{len(cfg.particles)} listed"
    return f"spheres {where}" + (", added to the scene" if cfg.add else "")


register_stage(StageType(
    "particles", FIELDS, run, needs_input=False, adds="add", check=_check, describe=describe,
    case_check=_case_check, file_digest=file_digest, provides=("bodies/*", "spheres/*"),
    doc="place listed spheres (position, velocity, spin, radius, material; inline or CSV)"))
