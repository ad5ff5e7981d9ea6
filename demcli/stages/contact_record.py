"""The per-contact record of a dem stage (``output.contacts``): at every record row, one row per
touching contact of a sphere, clump or polyhedron scene, with its overlap, forces, contact point
and normal.

This is what a contact-level validation compares (Chung & Ooi 2011: the force and overlap of an
impact against time): set ``output.records`` to the steps you want (every step of a short
impact, for one), and name the bodies to follow in a larger scene. Columns (table
``contacts``, file ``records/contacts.csv``):

* time [s], step; i: body id of the sphere (polyhedron); j: body id of the other one, or
  -(k + 1) for wall k (walls in the stage's order, box faces as their planes);
* overlap delta [m] (spheres: r_i + r_j - d, r_i - s on a wall; polyhedra: the depth V / A_c of
  the volumetric law, overlap volume over contact area);
* fn [N]: the normal force on i, F . n (> 0 pushes apart; < 0 while a dashpot pulls);
* ft [N]: the magnitude of its tangential part, and ftx, fty, ftz its components;
* cx, cy, cz [m]: the contact point where the engine applies the force: R - delta/2 from i's
  centre (the middle of the overlap) for a pair, R - delta (the wall's surface) on a wall, or R
  with ``contact.lever_arm: radius``; polyhedra: the centroid of the overlap volume; nx, ny, nz:
  the unit normal from j (the wall) to i (polyhedra: the area vector S / |S| of the overlap).

A clump's member spheres are recorded as contacts of the clump's body id (two members of one
clump touching one wall are two rows). A polyhedron contact's point and normal are computed
again from the bodies' world geometry at the record (the exact overlap of
:func:`demcli.kernels.polyhedra.polyhedron_overlap`, the one the step used), so a record costs a
few tens of microseconds per recorded contact.
"""

import math

import numpy as np

from demcli.errors import InputError
from demcli.state.records import describe_column

COLUMNS = {"time": "s", "step": "1", "i": "1", "j": "1", "overlap": "m", "fn": "N", "ft": "N", "ftx": "N",
           "fty": "N", "ftz": "N", "cx": "m", "cy": "m", "cz": "m", "nx": "1", "ny": "1", "nz": "1"}
MAX_ALL = 2000
"""Largest scene (spheres) whose every contact is recorded; larger ones name their bodies."""

for _name, _label, _unit, _doc in (
        ("i", "Body", "1", "body id of the sphere"),
        ("j", "Partner", "1", "body id of the other sphere, or -(k + 1) for wall k"),
        ("overlap", "Overlap", "m", "r_i + r_j - d, or r_i - s on a wall"),
        ("fn", "Normal force", "N", "F . n on i, > 0 pushing apart"),
        ("ft", "Tangential force", "N", "magnitude of the tangential part of the force on i")):
    describe_column(_name, _label, _unit, table="contacts", integer=_unit == "1", doc=_doc)


def check_scene(system, spec):
    """InputError when the scene cannot be recorded: spheres with polyhedra, or every contact of a
    scene above :data:`MAX_ALL` spheres (polyhedra)."""
    if system.plugin.name not in ("spheres", "polyhedra"):
        raise InputError(f"output.contacts: a per-contact record is for sphere, clump and polyhedron scenes; this one "
                         f"has {system.plugin.name}")
    kind = "spheres" if system.plugin.name == "spheres" else "polyhedra"
    if not len(spec.bodies) and len(system.rad) > MAX_ALL:
        raise InputError(f"output.contacts: the scene has {len(system.rad)} {kind}, more than {MAX_ALL} whose every "
                         "contact is recorded: name the bodies to follow (output.contacts.bodies)")


def _row(system, i, j, delta, n, f, point, body=None):
    """One row: primitive i (sphere i, or ``body`` for a polyhedron) against j."""
    fn = float(f @ n)
    ft = f - fn * n
    b = system.sbody[i] if body is None else body
    return {"time": system.time, "step": system.step, "i": int(system.body_id[b]), "j": j,
            "overlap": float(delta), "fn": fn, "ft": float(np.linalg.norm(ft)), "ftx": float(ft[0]),
            "fty": float(ft[1]), "ftz": float(ft[2]), "cx": float(point[0]), "cy": float(point[1]),
            "cz": float(point[2]), "nx": float(n[0]), "ny": float(n[1]), "nz": float(n[2])}


def _placed(system, b):
    """Body b of a polyhedron scene as :class:`demcli.kernels.polyhedra.Placed`, from the world
    vertices and face planes the last step used."""
    from demcli.kernels.polyhedra import Placed

    vs, _, fs, fvs, fv, _, _ = system.shapes
    k = int(system.shape[b])
    rows = fvs[fs[k]:fs[k + 1] + 1]
    wvert, wnorm, woff, _ = system.world
    v0, v1, f0, f1 = system.bvstart[b], system.bvstart[b + 1], system.bfstart[b], system.bfstart[b + 1]
    return Placed(wvert[v0:v1], rows - rows[0], fv[rows[0]:rows[-1]] - vs[k], wnorm[f0:f1], woff[f0:f1],
                  system.x[b].copy(), float(system.rad[b]))


def _mesh_plane_overlap(system, b, wall):
    """(V [m^3], centroid (3,) [m], S (3,) [m^2]) of body b against the mesh wall ``wall``: of the
    plane (coplanar triangles) with the largest overlap volume (:mod:`demcli.kernels.poly_mesh`);
    V = 0 when it touches none."""
    from demcli.kernels.poly_mesh import R_GX, R_SX, R_V, mesh_pieces, mesh_scratch, plane_sums
    from demcli.kernels.polyhedra import max_row

    args = _placed(system, b).args()
    ms = mesh_scratch(max_row(args[1]), len(args[1]) - 1)
    p = system.wpoint[wall]
    n = mesh_pieces(*args, system.wmesh, wall, p[0], p[1], p[2], ms)
    res, lead = ms[5], ms[3]
    plane_sums(res, n, lead, args[9])
    planes = [m for m in range(n) if lead[m] == m]
    if not planes:
        return 0.0, p.copy(), np.zeros(3)
    m = max(planes, key=lambda m: res[m, R_V])
    return float(res[m, R_V]), res[m, R_GX:R_GX + 3].copy(), res[m, R_SX:R_SX + 3].copy()


def _polyhedra_rows(system, keep):
    """:func:`contact_rows` of a polyhedron scene: each touching pair and body-wall contact with
    its depth, force, overlap centroid and area normal."""
    from demcli.kernels.polyhedra import polyhedron_overlap, polyhedron_plane_overlap
    from demcli.kernels.shapes.polyhedra import G_DEPTH
    from demcli.kernels.walls import MESH

    nl, ids = system.nl, system.body_id
    rows = []
    for c in np.flatnonzero(nl.act):
        i, j = int(nl.pi[c]), int(nl.pj[c])
        if keep is not None and not (keep[i] or keep[j]):
            continue
        vol, centroid, area = polyhedron_overlap(_placed(system, i), _placed(system, j))
        if vol <= 0.0:
            continue
        rows.append(_row(system, i, int(ids[j]), nl.geo[c, G_DEPTH], area / np.linalg.norm(area), nl.fc[c],
                         centroid, body=i))
    w = system.walls
    for k in np.flatnonzero(nl.wgeo[:, G_DEPTH] > 0.0) if len(nl.wgeo) else ():
        i, wall = int(nl.wprim[k]), int(nl.wwall[k])
        if keep is not None and not keep[i]:
            continue
        a = w.normal[wall]
        if int(w.kind[wall]) == MESH:  # its largest plane's contact (the row sums them: docs/walls.md)
            vol, centroid, area = _mesh_plane_overlap(system, i, wall)
        else:
            vol, centroid, area = polyhedron_plane_overlap(_placed(system, i), a, float(a @ system.wpoint[wall]))
        n = area / np.linalg.norm(area) if vol > 0.0 else np.asarray(a, float)
        rows.append(_row(system, i, -(wall + 1), nl.wgeo[k, G_DEPTH], n, nl.wfc[k, :3], centroid, body=i))
    return rows


def contact_rows(system, bodies=()):
    """Rows (dicts of :data:`COLUMNS`) of the touching contacts now: pairs, then wall contacts;
    only those of the body ids ``bodies`` when given."""
    if system.plugin.name == "polyhedra":
        keep = None if not len(bodies) else np.isin(system.body_id, np.asarray(bodies, np.int64))
        return _polyhedra_rows(system, keep)
    from demcli.kernels.contact import P_ARM
    from demcli.kernels.walls import surface_distance

    nl, xs, rad, ids = system.nl, system.xs, system.rad, system.body_id[system.sbody]
    keep = None if not len(bodies) else np.isin(ids, np.asarray(bodies, np.int64))
    rows = []
    for c in np.flatnonzero(nl.act):
        i, j = int(nl.pi[c]), int(nl.pj[c])
        if keep is not None and not (keep[i] or keep[j]):
            continue
        d = xs[i] - xs[j]
        dist = math.sqrt(float(d @ d))
        n = d / dist
        delta = rad[i] + rad[j] - dist
        arm = rad[i] - 0.5 * delta * system.prm[system.smat[i], system.smat[j], P_ARM]
        rows.append(_row(system, i, int(ids[j]), delta, n, nl.fc[c], xs[i] - arm * n))
    w = system.walls
    for k in np.flatnonzero(np.any(nl.wfc[:, :3] != 0.0, axis=1)) if len(nl.wfc) else ():
        i, wall = int(nl.wprim[k]), int(nl.wwall[k])
        if keep is not None and not keep[i]:
            continue
        p, a = system.wpoint[wall], w.normal[wall]
        s, nx, ny, nz = surface_distance(int(w.kind[wall]), p[0], p[1], p[2], a[0], a[1], a[2],
                                         float(w.radius[wall]), xs[i, 0], xs[i, 1], xs[i, 2], system.wmesh, wall,
                                         float(rad[i]))  # a mesh wall: its nearest contact
        n = np.array([nx, ny, nz])
        delta = rad[i] - s
        arm = s + (1.0 - system.prm[system.smat[i], system.wmat[wall], P_ARM]) * delta
        rows.append(_row(system, i, -(wall + 1), delta, n, nl.wfc[k, :3], xs[i] - arm * n))
    return rows
