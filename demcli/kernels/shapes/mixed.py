"""Shape plug-in: spheres (single or clumped) and convex polyhedra in one scene.

Layout: the sphere primitives first (0..ns-1: single spheres or clump members, their bodies
first), then one primitive per polyhedron (ns..n-1, in the order of their bodies, which come
last). Every primitive has a row of the sphere arrays (``sph``, a
:class:`~demcli.kernels.shapes.spheres.SphereGeometry`: a polyhedron's row is its bounding
sphere on the centroid, offset 0, the body's velocity and spin) and of the polyhedron tables
(``poly``, a :class:`~demcli.kernels.shapes.polyhedra.PolyGeometry` over primitives: a sphere's
vertex and face ranges are empty, its template -1). Every body is a rigid rotor with member
primitives (a single sphere: isotropic inertia, L = I omega; a polyhedron: its one primitive at
the centroid), so the engine runs the member pass for every body (flag F_CLUMPS).

Pairs, by kind, into the same per-pair arrays (history, force, torque on j, losses):

* sphere-sphere: the sphere law (Hertz-Mindlin or linear, :mod:`demcli.kernels.contact`) as in
  :mod:`demcli.kernels.shapes.spheres` (its pass with ``split`` = ns);
* polyhedron-polyhedron: the volumetric law of :mod:`demcli.kernels.shapes.polyhedra` (its pass
  from row ns), with the material table ``qprm``;
* sphere-polyhedron: a point contact (:func:`demcli.kernels.sphere_polyhedron.sphere_polyhedron_overlap`:
  overlap delta = R - s with s the signed distance from the sphere's centre to the polyhedron's
  surface, normal n from the polyhedron to the sphere, contact point x_c in the middle of the
  overlap) under the sphere law with R* = R of the sphere (the polyhedron locally flat, as a
  wall) and m* the two bodies' reduced mass; the relative velocity of the contact point
  v = v_i + w_i x (x_c - x_i) - v_j - w_j x (x_c - x_j), the torques (x_c - x) x F on each body
  plus the rolling moment (rolling resistance: relative spin w_i - w_j, as between spheres).

Walls: a sphere primitive by the sphere law (planes, cylinders), a polyhedron by the volumetric
law (planes). The row sums are made by the passes in a fixed order (sphere pairs, then
sphere-polyhedron pairs, then polyhedron rows), race-free and thread-count independent.
"""

import math
from collections import namedtuple

from numba import prange

from demcli.jit import njit
from demcli.kernels.contact import contact_law, strain_energy
from demcli.kernels.layout import F_DASHPOT, F_ENERGY, F_FRICTION, F_ROLLING
from demcli.kernels.shapes import polyhedra as P
from demcli.kernels.shapes import spheres as S
from demcli.kernels.sphere_polyhedron import sphere_polyhedron_overlap
from demcli.kernels.walls import wall_distance

MixedGeometry = namedtuple("MixedGeometry", "sph poly ns qprm")
"""sph: SphereGeometry over every primitive; poly: PolyGeometry over every primitive (rows of
spheres empty, shape -1); ns: the number of sphere primitives; qprm: the volumetric law's
material-pair table (polyhedra.Q_*). The engine's ``prm`` is the sphere law's table."""


@njit(inline="always")
def _poly_rows(pg, j):
    """World arrays of the polyhedron primitive j in the layout of sphere_polyhedron_overlap."""
    k = pg.shape[j]
    return (pg.wvert[pg.bvstart[j]:pg.bvstart[j + 1]], pg.fvstart[pg.face_start[k]:pg.face_start[k + 1] + 1],
            pg.vertex_start[k], pg.wnorm[pg.bfstart[j]:pg.bfstart[j + 1]], pg.woff[pg.bfstart[j]:pg.bfstart[j + 1]])


@njit
def sphere_poly_depth(pg, xs, rad, i, j):
    """(delta, nx, ny, nz, cx, cy, cz) of sphere primitive i and polyhedron primitive j."""
    va, fsa, off, na, da = _poly_rows(pg, j)
    return sphere_polyhedron_overlap(xs[i, 0], xs[i, 1], xs[i, 2], rad[i], va, fsa, pg.fverts, off, na, da)


@njit(parallel=True)
def _sphere_poly_forces(start, pj, ns, sg, pg, prm, law, dt, ft, mr, friction, rolling, energy, fc, tj, act, epair,
                        frow, trow, erow):
    """Every sphere-polyhedron pair (rows i < ns, partners j >= ns): force on i into fc[c], torque
    on j into tj[c], losses into epair[c]; i's side added to frow/trow/erow[i] (after the sphere
    pass wrote them)."""
    xs, vs, ws, rad, smat, smass = sg.xs, sg.vs, sg.ws, sg.rad, sg.mat, sg.smass
    wvert, wnorm, woff, fverts = pg.wvert, pg.wnorm, pg.woff, pg.fverts
    shape, vertex_start, face_start, fvstart, bvstart, bfstart = (pg.shape, pg.vertex_start, pg.face_start,
                                                                  pg.fvstart, pg.bvstart, pg.bfstart)
    for i in prange(ns):
        sfx = 0.0
        sfy = 0.0
        sfz = 0.0
        stx = 0.0
        sty = 0.0
        stz = 0.0
        se0 = 0.0
        se1 = 0.0
        for c in range(start[i], start[i + 1]):
            j = pj[c]
            if j < ns:
                continue
            k = shape[j]
            delta, nx, ny, nz, cx, cy, cz = sphere_polyhedron_overlap(
                xs[i, 0], xs[i, 1], xs[i, 2], rad[i], wvert[bvstart[j]:bvstart[j + 1]],
                fvstart[face_start[k]:face_start[k + 1] + 1], fverts, vertex_start[k],
                wnorm[bfstart[j]:bfstart[j + 1]], woff[bfstart[j]:bfstart[j + 1]])
            if not delta > 0.0:
                act[c] = 0
                if friction:
                    ft[c, 0] = 0.0
                    ft[c, 1] = 0.0
                    ft[c, 2] = 0.0
                if rolling:
                    mr[c, 0] = 0.0
                    mr[c, 1] = 0.0
                    mr[c, 2] = 0.0
                continue
            act[c] = 1
            aix = cx - xs[i, 0]
            aiy = cy - xs[i, 1]
            aiz = cz - xs[i, 2]
            ajx = cx - xs[j, 0]
            ajy = cy - xs[j, 1]
            ajz = cz - xs[j, 2]
            vx = (vs[i, 0] + ws[i, 1] * aiz - ws[i, 2] * aiy) - (vs[j, 0] + ws[j, 1] * ajz - ws[j, 2] * ajy)
            vy = (vs[i, 1] + ws[i, 2] * aix - ws[i, 0] * aiz) - (vs[j, 1] + ws[j, 2] * ajx - ws[j, 0] * ajz)
            vz = (vs[i, 2] + ws[i, 0] * aiy - ws[i, 1] * aix) - (vs[j, 2] + ws[j, 0] * ajy - ws[j, 1] * ajx)
            mi = smass[i]
            mj = smass[j]
            fx, fy, fz, mx, my, mz, ed, ef = contact_law(
                law, prm, smat[i], smat[j], delta, nx, ny, nz, vx, vy, vz, ws[i, 0] - ws[j, 0], ws[i, 1] - ws[j, 1],
                ws[i, 2] - ws[j, 2], rad[i], mi * mj / (mi + mj), dt, ft, mr, c, friction, rolling)
            fc[c, 0] = fx
            fc[c, 1] = fy
            fc[c, 2] = fz
            sfx += fx
            sfy += fy
            sfz += fz
            stx += aiy * fz - aiz * fy + mx
            sty += aiz * fx - aix * fz + my
            stz += aix * fy - aiy * fx + mz
            tj[c, 0] = -(ajy * fz - ajz * fy) - mx
            tj[c, 1] = -(ajz * fx - ajx * fz) - my
            tj[c, 2] = -(ajx * fy - ajy * fx) - mz
            if energy:
                epair[c, 0] = ed
                epair[c, 1] = ef
                se0 += ed
                se1 += ef
        frow[i, 0] += sfx
        frow[i, 1] += sfy
        frow[i, 2] += sfz
        trow[i, 0] += stx
        trow[i, 1] += sty
        trow[i, 2] += stz
        if energy:
            erow[i, 0] += se0
            erow[i, 1] += se1


@njit
def place(g, bd, flags, xref, lim2, rebuild):
    """Every primitive follows its body (a polyhedron's sits on the centroid), then the world
    vertices and face planes of the polyhedra (the last bodies, in primitive order)."""
    sg = g.sph
    pg = g.poly
    S._place_members(bd.x, bd.v, bd.w, bd.q, sg.xs, sg.vs, sg.ws, sg.sbody, sg.soff, xref, lim2, rebuild)
    ns = g.ns
    b0 = bd.x.shape[0] - (sg.xs.shape[0] - ns)
    P._world_geometry(bd.x[b0:], bd.q[b0:], pg.shape[ns:], pg.vertex_start, pg.vertices, pg.face_start,
                      pg.face_normal, pg.face_offset, pg.bvstart[ns:], pg.bfstart[ns:], pg.wvert, pg.wnorm, pg.woff, pg.travel[ns:])


@njit(inline="always")
def volumetric(g):
    """Polyhedron contacts keep a depth and a separation cache; normal forces turn bodies."""
    return True


@njit
def spin_rotors(g, mb, xref):
    """Every body is a rigid rotor: None."""
    return None


@njit
def primitives(g, bd):
    """The spheres and the polyhedra's bounding spheres."""
    return g.sph.xs, g.sph.rad, g.sph.sbody


@njit
def pair_pass(g, bd, nl, prm, law, flags, dt, frow, trow, erow, bonds, bprm, broke):
    """Sphere pairs, sphere-polyhedron pairs, polyhedron rows (the module docstring)."""
    friction = flags[F_FRICTION]
    rolling = flags[F_ROLLING]
    energy = flags[F_ENERGY]
    sg = g.sph
    pg = g.poly
    ns = g.ns
    S._pair_forces(nl.start, nl.pj, sg.xs, sg.vs, sg.ws, sg.rad, sg.mat, sg.smass, prm, law, dt, nl.ft, nl.mr,
                   friction, rolling, energy, nl.fc, nl.tj, nl.act, nl.epair, frow, trow, erow, ns, None)
    if not (friction or rolling):
        trow[:ns, :] = 0.0
    _sphere_poly_forces(nl.start, nl.pj, ns, sg, pg, prm, law, dt, nl.ft, nl.mr, friction, rolling, energy, nl.fc,
                        nl.tj, nl.act, nl.epair, frow, trow, erow)
    P._pair_forces(nl.start, nl.pj, sg.xs, sg.vs, sg.ws, bd.q, sg.smass, pg.rad, pg.mat, g.qprm, flags, dt,
                   pg.shape, pg.vertex_start, pg.face_start, pg.fvstart, pg.fverts, pg.bvstart, pg.bfstart, pg.wvert,
                   pg.wnorm, pg.woff, nl.ft, nl.fc, nl.tj, nl.act, nl.epair, nl.geo, frow, trow, erow, nl.sep, nl.sdir,
                   nl.sclear, nl.pbox, pg.travel, ns, None)


@njit
def wall_pass(g, bd, nl, wa, prm, law, flags, dt):
    """Sphere-wall contacts by the sphere law, polyhedron-plane contacts by the volumetric law."""
    sg = g.sph
    pg = g.poly
    S._wall_forces(nl.wprim, nl.wwall, sg.xs, sg.vs, sg.ws, sg.rad, sg.mat, sg.smass, wa.kind, wa.point, wa.normal,
                   wa.radius, wa.v, wa.material, prm, law, dt, nl.wft, nl.wmr, flags[F_FRICTION], flags[F_ROLLING],
                   flags[F_ENERGY], nl.wfc, nl.wtq, nl.wen, g.ns, wa.mesh)
    P._wall_forces(nl.wstart, nl.wwall, sg.xs, sg.vs, sg.ws, sg.smass, pg.rad, pg.mat, pg.shape, pg.vertex_start,
                   pg.face_start, pg.fvstart, pg.fverts, pg.bvstart, pg.bfstart, pg.wvert, pg.wnorm, pg.woff, wa.kind,
                   wa.point, wa.normal, wa.v, wa.material, g.qprm, dt, flags[F_FRICTION], flags[F_DASHPOT],
                   flags[F_ENERGY], nl.wft, nl.wfc, nl.wtq, nl.wen, nl.wgeo, g.ns, None)  # plane walls only


@njit
def worst_overlap(g, nl, wa):
    """Largest overlap ratio: sphere pairs and sphere-polyhedron pairs overlap / smaller radius
    (the sphere's), polyhedron pairs depth / smaller bounding radius, walls likewise; returns
    (ratio, i, j) with j = -1 for a wall (i = -1 when nothing touches)."""
    sg = g.sph
    xs = sg.xs
    rad = sg.rad
    ns = g.ns
    worst = 0.0
    wi = -1
    wj = -1
    for c in range(nl.pi.shape[0]):
        if nl.act[c]:
            i = nl.pi[c]
            j = nl.pj[c]
            if j < ns:
                d = math.sqrt((xs[i, 0] - xs[j, 0]) ** 2 + (xs[i, 1] - xs[j, 1]) ** 2 + (xs[i, 2] - xs[j, 2]) ** 2)
                ratio = (rad[i] + rad[j] - d) / min(rad[i], rad[j])
            elif i < ns:
                ratio = sphere_poly_depth(g.poly, xs, rad, i, j)[0] / rad[i]
            else:
                ratio = nl.geo[c, P.G_DEPTH] / min(rad[i], rad[j])
            if ratio > worst:
                worst = ratio
                wi = i
                wj = j
    for i in range(ns, rad.shape[0]):
        for k in range(nl.wstart[i], nl.wstart[i + 1]):
            ratio = nl.wgeo[k, P.G_DEPTH] / rad[i]
            if ratio > worst:
                worst = ratio
                wi = i
                wj = -1
    for i in range(ns):
        for k in range(nl.wstart[i], nl.wstart[i + 1]):
            wl = nl.wwall[k]
            sd, _, _, _ = wall_distance(wa.kind[wl], wa.point[wl, 0], wa.point[wl, 1], wa.point[wl, 2],
                                        wa.normal[wl, 0], wa.normal[wl, 1], wa.normal[wl, 2], wa.radius[wl],
                                        xs[i, 0], xs[i, 1], xs[i, 2])
            ratio = (rad[i] - sd) / rad[i]
            if ratio > worst:
                worst = ratio
                wi = i
                wj = -1
    return worst, wi, wj


@njit
def strain_energy_mixed(g, nl, prm, law, friction, rolling):
    """Elastic energy of the contacts [J] (serial, fixed order): sphere pairs and
    sphere-polyhedron pairs exactly (the sphere law's potential, R* of each), polyhedron
    contacts and polyhedron-wall contacts estimated as in
    :func:`~demcli.kernels.shapes.polyhedra.strain_energy_estimate`; sphere-wall contacts are
    added by the caller (spheres.total_strain_energy's wall part)."""
    sg = g.sph
    xs = sg.xs
    rad = sg.rad
    ns = g.ns
    e = 0.0
    for c in range(nl.pi.shape[0]):
        i = nl.pi[c]
        j = nl.pj[c]
        if j < ns:
            d = math.sqrt((xs[i, 0] - xs[j, 0]) ** 2 + (xs[i, 1] - xs[j, 1]) ** 2 + (xs[i, 2] - xs[j, 2]) ** 2)
            delta = rad[i] + rad[j] - d
            if delta > 0.0:
                e += strain_energy(law, prm, sg.mat[i], sg.mat[j], delta, rad[i] * rad[j] / (rad[i] + rad[j]),
                                   nl.ft, nl.mr, c, friction, rolling)
        elif i < ns:
            delta = sphere_poly_depth(g.poly, xs, rad, i, j)[0]
            if delta > 0.0:
                e += strain_energy(law, prm, sg.mat[i], sg.mat[j], delta, rad[i], nl.ft, nl.mr, c, friction,
                                   rolling)
        elif nl.act[c]:
            e += 0.5 * nl.geo[c, P.G_FN] * nl.geo[c, P.G_DEPTH]
            if friction and nl.geo[c, P.G_KT] > 0.0:
                e += 0.5 * (nl.ft[c, 0] ** 2 + nl.ft[c, 1] ** 2 + nl.ft[c, 2] ** 2) / nl.geo[c, P.G_KT]
    for i in range(ns, rad.shape[0]):
        for k in range(nl.wstart[i], nl.wstart[i + 1]):
            if nl.wgeo[k, P.G_DEPTH] > 0.0:
                e += 0.5 * nl.wgeo[k, P.G_FN] * nl.wgeo[k, P.G_DEPTH]
                if friction and nl.wgeo[k, P.G_KT] > 0.0:
                    e += 0.5 * (nl.wft[k, 0] ** 2 + nl.wft[k, 1] ** 2 + nl.wft[k, 2] ** 2) / nl.wgeo[k, P.G_KT]
    return e
