"""``marshall``: Marshall stability and flow of a bonded cylindrical specimen (issue #32;
ASTM D6927 geometry).

The specimen of a ``prepare`` stage (group ``bonded_specimen``: a cylinder of diameter D and
thickness t along z), or a ``cut`` stage's cylinder filled by the ``mastic`` stage (the 3D Marshall
specimen, bonded by ``bonds.from_phases``), lies on its side (``orientation: diametral``) between
the two curved breaking heads of the standard: the inner faces of cylindrical arcs of radius D/2
(ASTM: 50.8 mm for the 101.6 mm specimen), their axes parallel to the specimen's, on opposite sides
of a diameter along x. The lower head is fixed; the upper one moves towards it along -x at the
constant head speed ``speed`` (ASTM: 50.8 mm/min; a DEM run affords far faster, see the quasi-static
check). The heads are mesh walls read from ``head_file`` (``cases/meshes/marshall_head.stl``: an arc
about the file's y axis, +-40 degrees about -z, 76.2 mm long, in mm), scaled by s = (D/2) / R_file
so that their radius is the specimen's (a specimen of another diameter than 101.6 mm gets a head
scaled by the same factor in arc radius and length; the log says so), turned so that the file's y
axis lies along z and its concave side faces the specimen, and moved along x until they touch its
outermost spheres.

The measured curve is the load P (the particles' push on the moving head, compression positive,
[N]) against the deformation delta (the heads' approach, [m]). The standard's results are the
stability P_max (the peak load [N]) and the flow delta(P_max) (the deformation at the peak,
reported in units of 0.25 mm, "flow value"). Records ``records/<stage>_marshall`` (CSV + PNG):
time, deformation, load, intact and broken bonds, and the quasi-static measure E_k / W (the idt
stage's, :mod:`demcli.stages.asphalt.diametral`, with its stop after the peak and its warning).
Result group ``marshall_result``. Departures from ASTM D6927: no 60 C conditioning (the material
is the case's), the head speed, and the rigid heads touch the specimen's spheres from the start
(the standard seats them with a small preload); the flow is the deformation from that first
touch, without the standard's correction of the toe of the curve.
"""

from pathlib import Path

import numpy as np

from demcli.config.schema import Str
from demcli.errors import InputError
from demcli.stages.asphalt.common import lab_case_check, orientation_check
from demcli.stages.dem import config_inputs
from demcli.stages.asphalt.diametral import declare_outputs, loading_fields, run_loading, specimen
from demcli.stages.base import ENGINE_KEEPS, ENGINE_OUTPUT, StageType, register_stage

FLOW_UNIT = 0.25e-3
"""ASTM D6927 reports the flow in units of 0.25 mm [m]."""

ROTATE_DEG = {"fixed": (90.0, 0.0, 90.0), "head": (90.0, 0.0, -90.0)}
"""Rotations (about x, then y, then z, degrees) of the head file: file y -> world z (the specimen's
axis) and file -z (the arc's side) -> world -x for the fixed head, +x for the moving one."""

declare_outputs("marshall", "Marshall stability and flow", [
    ("stability", "N", "Marshall stability: the peak load P_max"),
    ("flow", "m", "Marshall flow: the heads' approach at the peak load"),
    ("flow_value", "1", "the flow in units of 0.25 mm (ASTM D6927's flow value)"),
    ("diameter", "m", "specimen diameter D"), ("thickness", "m", "specimen thickness t"),
    ("head_scale", "1", "scale of the head file (its arc radius to D/2)"),
    ("kinetic_to_work", "1", "kinetic energy at the peak / the head's work until then")])


def _fields():
    f = loading_fields("head speed (ASTM D6927: 50.8 mm/min)")
    f["head_file"] = Str(doc="STL or OBJ of the lower breaking head (an arc about the file's y axis on its -z side; "
                             "cases/meshes/marshall_head.stl), relative to the case file")
    return f


def _profile(verts, axis_xy):
    """The head's cross-section (m, 2) [m]: the distinct (x, y) of its vertices (a prism along z),
    ordered by angle about the arc's axis ``axis_xy``, measured from the arc's mean direction m
    (atan2(m x v, m . v): no wrap-around inside an arc under 360 degrees)."""
    xy = np.unique(np.round(verts[:, :2], 12), axis=0)
    v = xy - axis_xy
    m = v.mean(axis=0)
    return xy[np.argsort(np.arctan2(m[0] * v[:, 1] - m[1] * v[:, 0], v @ m))]


def _gap(profile, centres, radii):
    """Smallest surface gap [m] between the discs (centres (n, 2), radii (n,)) and the polyline
    ``profile`` (m, 2): min_i (|c_i - q_i| - r_i), q_i the closest point of a segment."""
    a, b = profile[:-1], profile[1:]
    ab = b - a
    rel = centres[:, None, :] - a[None]
    u = np.clip(np.einsum("nmk,mk->nm", rel, ab) / np.einsum("mk,mk->m", ab, ab), 0.0, 1.0)
    dist = np.linalg.norm(rel - u[..., None] * ab[None], axis=2)
    return float(np.min(dist.min(axis=1) - radii))


def _touching(profile, centres, radii, direction, tol):
    """Travel [m] of ``profile`` along ``direction`` (+-1 along x) until it touches the first disc:
    sphere tracing (each step the smallest gap, which no point of the profile can cross), to
    within ``tol`` [m]."""
    travel = 0.0
    for _ in range(10000):
        g = _gap(profile + [direction * travel, 0.0], centres, radii)
        if g <= tol:
            return travel + g
        travel += g
    return travel


def head_radius(head_file, case_file, where):
    """R_file: the arc radius of the head file (its vertices' distance from the file's y axis, in
    its units); a missing or unreadable file, or one that is not such an arc, is a ConfigError
    naming ``case_file`` and ``where``.head_file (exit code 2)."""
    from demcli.config.schema import ConfigIssue
    from demcli.errors import ConfigError
    from demcli.geometry.mesh_file import read_mesh

    raw, _ = read_mesh(head_file, case_file=case_file, key=f"{where}.head_file")
    rho = np.hypot(raw[:, 0], raw[:, 2])
    if np.ptp(rho) > 1e-6 * rho.max():
        rule = "must be an arc about the file's y axis (its vertices at one distance from it)"
        raise ConfigError([ConfigIssue(case_file, None, f"{where}.head_file", rule,
                                       f"distances {rho.min():g} .. {rho.max():g}")])
    return float(rho.mean())


def place_heads(cfg, x, rad, D, t, base, head_file, case_file, where):
    """The fixed and the moving head (mesh wall nodes) touching the outermost spheres (centres x
    (n, 3), radii rad [m]) of the specimen (D, t, base as :func:`specimen` gives them), and
    (s, x_1 - x_0 of their first vertices [m])."""
    from demcli.config.schema import Node
    from demcli.geometry.mesh_file import read_mesh

    s = 0.5 * D / head_radius(head_file, case_file, where)
    nodes, first = [], []
    for name, sign in (("fixed", 1.0), ("head", -1.0)):
        centre = np.array([base[0] - sign * 0.5 * D, base[1], base[2] + 0.5 * t])   # the arc's axis, half a D off
        rot = np.radians(ROTATE_DEG[name])
        verts, _ = read_mesh(head_file, case_file=case_file, scale=s, translation=centre, rotate=np.degrees(rot))
        if np.ptp(verts[:, 2]) < t:  # the placement sees the head as a prism along z over the whole specimen
            raise InputError(f"{where}: the specimen ({t * 1e3:.4g} mm thick) is longer than the scaled breaking "
                             f"heads ({np.ptp(verts[:, 2]) * 1e3:.4g} mm): ASTM D6927 heads cover the specimen")
        centre[0] += sign * _touching(_profile(verts, centre[:2]), x[:, :2], rad, sign, 1e-9 * D)
        motion = None if sign > 0 else Node({"mode": "velocity", "velocity": (-cfg.speed, 0.0, 0.0)})
        nodes.append(Node({"type": "mesh", "name": name, "file": str(head_file), "scale": s, "rotate": tuple(rot),
                           "translation": tuple(centre), "normal": (sign, 0.0, 0.0), "material": cfg.head_material,
                           "rigid": False, "motion": motion}))
        first.append(read_mesh(head_file, case_file=case_file, scale=s, translation=centre,
                               rotate=np.degrees(rot))[0][0])
    return nodes, s, float(first[1][0] - first[0][0])


def _head_digest(cfg, case_dir):
    """sha256 of the head file (part of the stage's config hash: an edited head runs it again)."""
    from demcli.config.schema import Node
    from demcli.stages.dem import mesh_digest

    return mesh_digest({"walls": [Node({"type": "mesh", "file": cfg.head_file})]}, case_dir)


def _case_check(cfg, case, k, scene, report):
    """The test stages' rules (:func:`lab_case_check`, :func:`orientation_check`); a 3D cylinder only
    (a prepare stage's or a cut stage's)."""
    lab_case_check(cfg, case, k, scene, report)
    orientation_check(cfg, case, k, report, "diametral", "the Marshall test")
    if case.dimension != 3:
        report("", "the Marshall test loads a 3D cylinder on its side: run it on a prepare stage's specimen",
               case.dimension)


def run_marshall(ctx, cfg, state_in):
    """Load the specimen on its side between the breaking heads to failure (module doc)."""
    from demcli.stages.specimen.particles import case_file_path

    x = state_in.sphere_centres()
    rad = np.asarray(state_in.groups["spheres"]["radius"])
    D, t, base = specimen(ctx, state_in.groups, x)
    case_file = ctx.runner.case_path
    head_file = case_file_path(case_file.resolve().parent if case_file else Path.cwd(), cfg.head_file)
    walls, s, sep0 = place_heads(cfg, x, rad, D, t, base, head_file, case_file, f"stages[{ctx.index}]")
    other = "" if abs(D - 0.1016) < 1e-6 else ": the specimen is not the standard's 101.6 mm, the head scaled with it"
    ctx.log(f"marshall: breaking heads of {head_file.name} scaled by {s:.6g} (arc radius D/2 {D * 500:.4g} mm{other})")

    def result(p, d, ratio):
        group = {"stability": np.float64(p), "flow": np.float64(d), "flow_value": np.float64(d / FLOW_UNIT),
                 "diameter": np.float64(D), "thickness": np.float64(t), "head_scale": np.float64(s),
                 "kinetic_to_work": np.float64(ratio)}
        line = (f"marshall: stability {p / 1e3:.4g} kN, flow {d * 1e3:.4g} mm ({d / FLOW_UNIT:.3g} x 0.25 mm) "
                f"(D {D * 1e3:.4g} mm, t {t * 1e3:.4g} mm); kinetic energy / work at the peak {ratio:.3g}")
        return group, line, "lower the speed (halving it should leave the stability unchanged)"

    return run_loading(ctx, cfg, state_in, walls, sep0, D, "marshall", ({}, lambda p: {}), result)


register_stage(StageType(
    "marshall", _fields(), run_marshall, needs_input=True, requires=("bodies/x", "spheres/radius"),
    provides=ENGINE_OUTPUT + ("marshall_result/*",), keeps=ENGINE_KEEPS + ("bonded_specimen",),
    case_check=_case_check, file_digest=_head_digest, config_requires=config_inputs,
    doc="Marshall stability and flow (ASTM D6927 breaking heads as mesh walls): peak load, deformation at the peak"))
