"""``clumpify`` stage: polyhedral ballast particles become rigid clumps of spheres.

The multi-sphere representation of PFC, YADE and LIGGGHTS, built from the polyhedra
of an ``assemble`` (or ``deposit``, ``vibrate``) state so that the same particles, placed
the same way, can be run by the sphere engine and compared with the polyhedral one
(docs/ballast_box.md, "Polyhedra against sphere clumps").

For each particle, in its body frame (the polyhedron's principal frame, centroid at the
origin), a simple cubic lattice of touching balls of diameter s with a ball at the
centroid is carved by the polyhedron: the balls whose centre (``membership: centre``,
the default) or whole ball (``whole``) lies inside every face plane become the clump
(:func:`demcli.geometry.carving.carve_polyhedron`, the lattice and membership rules of
the asphalt ``carve`` stage). s is ``balls.diameter``, or ``balls.relative`` times the
particle's sieve size (the same number of balls across every particle).

The body keeps the polyhedron's exact mass, centre of mass and inertia tensor (the
usual choice for multi-sphere particles: the balls are a contact surface, not a mass
model; the union of touching balls holds pi/6 of the voxel volume): ``bodies/x``,
``q``, ``mass``, ``inertia``, velocities and angular momentum pass through unchanged, so
a clump moves off exactly as its polyhedron would. Members take the particle's material.
Loading actors (a plate, a sleeper) are dropped.

Per particle the ``clumps`` group keeps its size class, sieve size, ball count and
diameter, the voxel volume error n s^3 / V - 1 and the clump's own sieve size (projection
method on the balls, :func:`demcli.geometry.carving.lattice_clump_sieve_size`); per
size class the record ``<stage>_classes`` (CSV + PNG) sums them up. The state is a
sphere scene (``bodies``, ``spheres``): a following ``dem`` stage runs it. Touching
balls of neighbouring clumps may overlap where the polyhedra were closer than a ball
radius (centre membership lets a ball stick out of a face by up to s / 2); the stage
reports the largest overlap: place the assembly with ``clearance`` of about s.
"""

import math

import numpy as np

from demcli.config.schema import Bool, Float, Optional, Section, Str
from demcli.errors import InputError
from demcli.stages.base import StageType, earlier_stage, register_stage
from demcli.state.fields import Field, register, register_group
from demcli.state.records import describe_column

describe_column("balls_mean", "Balls per clump", table="classes", doc="mean number of balls in a clump of the class")

WRITER = "stage clumpify"
register_group("clumps", "Clumps of spheres made from polyhedral particles, one row per body", writer=WRITER)
for _name, _kind, _dims, _unit, _doc in [
        ("size_class", "i", ("n_b",), "", "index into gradation/class_* of the polyhedron (-1: none)"),
        ("sieve_size", "f", ("n_b",), "m", "sieve size of the polyhedron (projection method)"),
        ("clump_sieve_size", "f", ("n_b",), "m", "sieve size of the clump's balls (projection method)"),
        ("volume", "f", ("n_b",), "m^3", "volume of the polyhedron (mass / density of the body)"),
        ("balls", "i", ("n_b",), "", "member spheres of the clump"),
        ("ball_radius", "f", ("n_b",), "m", "radius of its member spheres (lattice spacing / 2)"),
        ("volume_error", "f", ("n_b",), "1", "voxel volume of the members n s^3 / polyhedron volume - 1")]:
    register(Field(f"clumps/{_name}", _kind, _dims, _unit, _doc, writer=WRITER))

FIELDS = {
    "balls": Section({
        "diameter": Optional(Float("m", min=0, min_inclusive=False), doc="ball diameter = lattice spacing"),
        "relative": Optional(Float(min=0, max=1, min_inclusive=False),
                             doc="ball diameter / the particle's sieve size"),
    }, doc="the lattice balls: give diameter or relative"),
    "membership": Str(choices=["centre", "whole"], default="centre",
                      doc="a ball joins the clump when its centre (or the whole ball) is inside the polyhedron"),
    "snapshot": Bool(default=True, doc="write a VTU snapshot of the spheres"),
}

OVERLAP_WARN = 0.2  # largest overlap between clumps / ball radius reported as a warning


def _check(node, report):
    b = node.balls
    if (b.diameter is None) == (b.relative is None):
        report("balls", "give exactly one of diameter or relative", None)


def _case_check(cfg, case, k, scene, report):
    """Memory for the balls: the solids of the gradation before, over a ball's lattice cell (of
    ``relative`` x the class's lower size where the diameter follows the particles)."""
    from demcli.config.memory import check_memory
    from demcli.stages.ballast.library import library_classes
    from demcli.stages.specimen.gradation import compute

    grading = earlier_stage(case, k, "gradation")
    if grading is None:
        return
    res = compute(grading)
    keep = library_classes(res["class_lower"], res["class_upper"])
    b = cfg.balls
    if b.diameter is not None:
        key, value, cell = "balls.diameter", b.diameter, b.diameter ** 3
    else:
        key, value, cell = "balls.relative", b.relative, (b.relative * res["class_lower"][keep]) ** 3
    check_memory(report, key, float(np.sum(res["class_amount"][keep] / cell)),
                 f"the balls of the solids of stage {grading.name!r}", value)


def ball_spacing(cfg_balls, sieve_size, circumradius):
    """Lattice spacing (ball diameter, m) per particle: ``diameter``, or ``relative`` x the
    sieve size (2 x the circumradius where the sieve size is unknown)."""
    if cfg_balls.diameter is not None:
        return np.full(len(sieve_size), float(cfg_balls.diameter))
    size = np.where(np.asarray(sieve_size) > 0, sieve_size, 2.0 * np.asarray(circumradius))
    return cfg_balls.relative * size


def clump_templates(shapes, shape, spacing, membership):
    """Carve every distinct (shape, spacing) pair once.

    shapes: :class:`~demcli.state.polyhedra.ShapeTable`; shape (n_b,), spacing (n_b,).
    Returns (template of each body (n_b,), [member centres (n_k, 3) in the body frame per
    template], spacing per template).
    """
    from demcli.geometry.carving import carve_polyhedron

    keys = {}
    tmpl = np.empty(len(shape), np.int64)
    members, spacings = [], []
    for b, (k, s) in enumerate(zip(np.asarray(shape, np.int64), np.asarray(spacing, float))):
        key = (int(k), float(s))
        if key not in keys:
            v, _, normals, offsets, _ = shapes.shape(int(k))
            pts, _ = carve_polyhedron(normals, offsets, v, s, membership)
            keys[key] = len(members)
            members.append(pts)
            spacings.append(s)
        tmpl[b] = keys[key]
    return tmpl, members, np.asarray(spacings)


def largest_overlap(centres, radii, body):
    """(largest overlap / smaller radius between spheres of different bodies, pairs that overlap)."""
    from scipy.spatial import cKDTree

    if len(radii) < 2:
        return 0.0, 0
    pairs = cKDTree(centres).query_pairs(2.0 * float(radii.max()), output_type="ndarray")
    if not len(pairs):
        return 0.0, 0
    i, j = pairs[:, 0], pairs[:, 1]
    other = body[i] != body[j]
    i, j = i[other], j[other]
    over = radii[i] + radii[j] - np.linalg.norm(centres[i] - centres[j], axis=1)
    hit = over > 0
    if not hit.any():
        return 0.0, 0
    return float((over[hit] / np.minimum(radii[i], radii[j])[hit]).max()), int(hit.sum())


def clump_groups(groups, spacing, membership="centre"):
    """Sphere-scene groups of the polyhedral particles of ``groups`` as clumps.

    groups: a state's groups with ``bodies``, ``polyhedra``, ``polyhedron_shapes`` and no
    actors; spacing (n_b,): lattice spacing (ball diameter) per body [m]. Returns
    (``bodies``, ``spheres``, ``clumps`` group dicts, number of distinct clumps). The
    bodies are the polyhedra's, unchanged; an InputError names a particle no ball fits.
    """
    from demcli.geometry.carving import lattice_clump_sieve_size
    from demcli.state.polyhedra import ShapeTable

    b_in = groups["bodies"]
    ph = groups["polyhedra"]
    shapes = ShapeTable.from_group(groups["polyhedron_shapes"])
    shape = np.asarray(ph["shape"], np.int64)
    nb = len(shape)
    tmpl, members, t_spacing = clump_templates(shapes, shape, spacing, membership)
    t_count = np.array([len(m) for m in members], np.int64)
    sieve = np.asarray(ph["sieve_size"], float)
    if np.any(t_count == 0):
        bad = int(np.flatnonzero(t_count[tmpl] == 0)[0])
        raise InputError(f"no whole ball of {spacing[bad] * 1e3:.3g} mm fits particle {bad} (sieve size "
                         f"{sieve[bad] * 1e3:.3g} mm); use smaller balls or membership: centre")
    t_sieve = np.array([lattice_clump_sieve_size(m, 0.5 * s) for m, s in zip(members, t_spacing)])
    keep = ("x", "v", "q", "omega", "mass", "inertia", "id", "flags", "angmom")
    bodies = {k: np.asarray(b_in[k]).copy() for k in keep if k in b_in}
    count = t_count[tmpl]
    spheres = {"body": np.repeat(np.arange(nb, dtype=np.int64), count),
               "offset": np.concatenate([members[t] for t in tmpl]) if nb else np.zeros((0, 3)),
               "radius": np.repeat(0.5 * t_spacing[tmpl], count),
               "material": np.repeat(np.asarray(ph["material"], np.int64), count)}
    volume = shapes.volume[shape]
    clumps = {"size_class": np.asarray(ph["size_class"], np.int64), "sieve_size": sieve,
              "clump_sieve_size": t_sieve[tmpl], "volume": volume, "balls": count,
              "ball_radius": 0.5 * t_spacing[tmpl], "volume_error": count * t_spacing[tmpl] ** 3 / volume - 1.0}
    return bodies, spheres, clumps, len(members)


def run(ctx, cfg, state_in):
    from demcli.engine.actors import remove_actors
    from demcli.state import RecordTable, State

    groups = remove_actors(state_in.groups)
    nb = len(groups["polyhedra"]["shape"])
    if nb == 0:
        raise InputError(f"stage {ctx.name}: the input holds no polyhedral particles")
    sieve = np.asarray(groups["polyhedra"]["sieve_size"], float)
    circum = np.asarray(groups["polyhedron_shapes"]["radius"], float)[np.asarray(groups["polyhedra"]["shape"])]
    try:
        bodies, spheres, clumps, n_templates = clump_groups(groups, ball_spacing(cfg.balls, sieve, circum),
                                                           cfg.membership)
    except InputError as exc:
        raise InputError(f"stage {ctx.name}: {exc}") from None
    count, radius, sbody, vol_err = clumps["balls"], spheres["radius"], spheres["body"], clumps["volume_error"]
    state = ctx.new_state()
    state.groups["bodies"] = bodies
    state.groups["spheres"] = spheres
    state.groups["clumps"] = clumps
    if "gradation" in groups:
        state.groups["gradation"] = {k: np.asarray(v) for k, v in groups["gradation"].items()}

    # per size class
    table = RecordTable("classes", {"lower": "mm", "upper": "mm", "particles": "1", "ball_diameter": "mm",
                                    "balls_mean": "1", "balls_min": "1", "balls_max": "1",
                                    "volume_error": "%", "volume_error_max": "%", "sieve_error": "%"})
    g = groups.get("gradation", {})
    lower = np.asarray(g.get("class_lower", []), float)
    upper = np.asarray(g.get("class_upper", []), float)
    cls = clumps["size_class"]
    ids = sorted(set(cls.tolist()))
    sieve_err = np.where(sieve > 0, clumps["clump_sieve_size"] / np.where(sieve > 0, sieve, 1.0) - 1.0, math.nan)
    for c in ids:
        m = cls == c
        known = 0 <= c < len(lower)
        table.append(lower=lower[c] * 1e3 if known else math.nan, upper=upper[c] * 1e3 if known else math.nan,
                     particles=int(m.sum()), ball_diameter=float(2e3 * clumps["ball_radius"][m].mean()),
                     balls_mean=float(count[m].mean()), balls_min=int(count[m].min()), balls_max=int(count[m].max()),
                     volume_error=100 * float(vol_err[m].mean()),
                     volume_error_max=100 * float(vol_err[m][np.argmax(np.abs(vol_err[m]))]),
                     sieve_error=100 * float(np.nanmean(sieve_err[m])) if np.isfinite(sieve_err[m]).any()
                     else math.nan)
    table.to_state(state)
    x = "upper" if len(lower) else "particles"
    ctx.write_records(table, x=x, ys=["balls_mean"])
    for row in range(len(table)):
        r = {k: v[row] for k, v in table.to_arrays().items()}
        ctx.log(f"  class {r['lower']:g}-{r['upper']:g} mm: {int(r['particles'])} particles, balls of "
                f"{r['ball_diameter']:.3g} mm, {r['balls_mean']:.1f} per clump ({int(r['balls_min'])}-"
                f"{int(r['balls_max'])}), voxel volume error {r['volume_error']:+.1f} % (worst "
                f"{r['volume_error_max']:+.1f} %), sieve size {r['sieve_error']:+.1f} %")
    centres = State(groups={"bodies": bodies, "spheres": spheres}).sphere_centres()
    worst, n_over = largest_overlap(centres, radius, sbody)
    ctx.log(f"{nb} polyhedra -> {nb} clumps of {len(radius)} spheres ({len(radius) / nb:.1f} per clump, "
            f"{n_templates} distinct); mass, centre and inertia of the polyhedra kept")
    if worst > OVERLAP_WARN:
        ctx.log(f"warning: {n_over} ball pairs of different clumps overlap, up to {100 * worst:.3g} % of a ball "
                f"radius (the dem guard stops at its overlap_limit, default 50 %); place the particles with a "
                f"larger clearance (about a ball diameter)")
    if cfg.snapshot:
        from demcli.state.vtu import Snapshots

        ctx.snapshot_dir.mkdir(parents=True, exist_ok=True)
        files = Snapshots(ctx.snapshot_dir).write(state)
        ctx.log(f"snapshot {files[0]}")
    return state


def describe(cfg, case):
    b = cfg.balls
    size = f"{b.diameter * 1e3:g} mm" if b.diameter is not None else f"{b.relative:g} x the sieve size"
    return f"polyhedra -> clumps of lattice balls of {size} ({cfg.membership} membership); mass properties kept"


register_stage(StageType(
    "clumpify", FIELDS, run, check=_check, describe=describe, case_check=_case_check,
    requires=("bodies/x", "polyhedra/shape", "polyhedra/sieve_size", "polyhedron_shapes/volume"),
    provides=("bodies/*", "spheres/*", "clumps/*", "records/*"), keeps=("gradation",),
    doc="polyhedral particles become rigid clumps of lattice balls (multi-sphere), mass properties kept"))
