"""Contact geometry of a sphere and a convex polyhedron (numba kernels, lengths in m).

Closest feature (:func:`closest_feature`): for a point c and a convex polyhedron P with the
outward unit face normals n_f and offsets d_f (n_f . x = d_f on face f, n_f . x <= d_f inside),
the signed distance s from c to the surface of P (s > 0 outside, s < 0 inside), the closest
surface point p and the unit normal n from P towards c:

* outside (h_f = n_f . c - d_f > 0 for some face): p is the projection of c onto P, the point
  of P nearest to c; s = |c - p|, n = (c - p) / s. The normal cone of P at p is spanned by the
  normals of the faces through p and holds c - p = sum_f l_f n_f (l_f >= 0), so
  |c - p|^2 = sum_f l_f h_f: p lies on a face with h_f > 0. Each such face is searched: c
  projects into the face polygon (q = c - h_f n_f, s_f = h_f) when it lies on the inner side
  of every edge a -> b, ((b - a) x (c - a)) . n_f >= 0 (vertices counter-clockwise seen from
  outside), and n = n_f exactly (not the difference c - q, whose digits a body far from the
  origin loses at small h_f); otherwise the nearest point of the face lies on an edge whose
  inner side it misses (point-segment distance, t = clamp((c - a) . (b - a) / |b - a|^2, 0,
  1)). The minimum over the faces is exact for the face, edge and vertex regions.
* inside or on the surface (h_f <= 0 for every face): s = max_f h_f, minus the distance to
  the nearest face plane (the foot of the perpendicular lies on that face, as no other plane
  is nearer), n = the normal of that face (the first of equal ones), p = c - s n.
* degenerate: when |c - p| <= ``DEGENERATE_REL`` max(|c|, |d_f|) (c on an edge or a vertex
  up to round-off) n is the normal of the face of largest h_f, which lies in the normal cone
  at p, instead of the direction of a vanishing difference; nothing divides by zero.

n is continuous outside and across the surface (it turns about an edge or a vertex); inside
it jumps across the planes equidistant from two faces, which a sphere centre reaches only at
overlaps delta >= R.

Contact (:func:`sphere_polyhedron_overlap`), sphere of centre c and radius R [m] against P:
overlap delta = R - s along n (delta <= 0: apart), contact point at the middle of the
overlap, x_c = c - (R - delta / 2) n, halfway between the sphere's deepest point c - R n and
p. n points from the polyhedron to the sphere: the normal force on the sphere is along +n,
the reaction on the polyhedron along -n, applied at x_c. It is a point contact, as in YADE's
``Ig2_Sphere_Polyhedra_ScGeom`` (penetration depth, normal and contact point of a sphere
against the nearest polyhedron feature), with the polyhedron taken as locally flat: a contact
law's effective radius is the sphere's radius, R* = R (the polyhedron's radius of curvature
is infinite on a face; edges and vertices are not rounded).

Arrays (world frame, one body; the layout of :func:`demcli.kernels.polyhedra.overlap`, so the
rows of :class:`demcli.kernels.shapes.polyhedra.PolyGeometry` pass without copying): ``v``
(nv, 3) vertices (``wvert[bvstart[b]:bvstart[b + 1]]``), ``fs`` (nf + 1,) CSR offsets into
``fv`` (``fvstart[face_start[k]:face_start[k + 1] + 1]``, k = ``shape[b]``), ``fv`` the
template vertex rows (``fverts``) of which ``off`` (``vertex_start[k]``) is subtracted,
``n`` (nf, 3) unit outward normals and ``d`` (nf,) offsets [m] (``wnorm``, ``woff`` rows
``bfstart[b]:bfstart[b + 1]``; :func:`~demcli.kernels.polyhedra.to_world_planes`:
d = d_body + n . x). Cost: one pass over the face planes, then one over the vertices of the
faces c lies in front of (a few for a contact: the faces whose planes it crosses).

All kernels are pure functions of arrays and scalars; fastmath is off.
"""

import math

from demcli.jit import njit

# |c - p| below this x max(|c_i|, |d_f|) is round-off: the normal is then a face normal
DEGENERATE_REL = 1e-12


@njit(inline="always")
def _deepest_face(cx, cy, cz, n, d):
    """The face plane c lies farthest in front of: (h = max_f n_f . c - d_f [m], its face f,
    the coordinate scale max(|c_i|, |d_f|) [m])."""
    h = -math.inf
    best = 0
    scale = max(abs(cx), abs(cy), abs(cz))
    for f in range(n.shape[0]):
        hf = n[f, 0] * cx + n[f, 1] * cy + n[f, 2] * cz - d[f]
        if hf > h:
            h = hf
            best = f
        scale = max(scale, abs(d[f]))
    return h, best, scale


@njit(inline="always")
def _segment_point(cx, cy, cz, ax, ay, az, bx, by, bz):
    """Point q of the segment a-b nearest to c: (|c - q|^2 [m^2], q),
    q = a + t (b - a), t = clamp((c - a) . (b - a) / |b - a|^2, 0, 1)."""
    ex = bx - ax
    ey = by - ay
    ez = bz - az
    e2 = ex * ex + ey * ey + ez * ez
    t = 0.0
    if e2 > 0.0:
        t = min(1.0, max(0.0, ((cx - ax) * ex + (cy - ay) * ey + (cz - az) * ez) / e2))
    qx = ax + t * ex
    qy = ay + t * ey
    qz = az + t * ez
    return (cx - qx) ** 2 + (cy - qy) ** 2 + (cz - qz) ** 2, qx, qy, qz


@njit(_nrt=False)
def closest_feature(cx, cy, cz, v, fs, fv, off, n, d):
    """Signed distance from the point c [m] to the polyhedron surface, closest point, normal.

    v, fs, fv, off, n, d: one body's world arrays (see the module docstring).

    Returns:
        (s [m], px, py, pz [m], nx, ny, nz): s > 0 outside, s < 0 inside; p the closest
        surface point; n the unit normal from the polyhedron towards c (outside
        (c - p) / s, the face normal where c projects into a face; inside the normal of the
        nearest face, p = c - s n).
    """
    h, f, scale = _deepest_face(cx, cy, cz, n, d)
    if h <= 0.0:
        return h, cx - h * n[f, 0], cy - h * n[f, 1], cz - h * n[f, 2], n[f, 0], n[f, 1], n[f, 2]
    best = math.inf
    px = py = pz = 0.0
    face = -1  # the face c projects into, when that is the nearest point
    for g in range(n.shape[0]):
        gx = n[g, 0]
        gy = n[g, 1]
        gz = n[g, 2]
        hg = gx * cx + gy * cy + gz * cz - d[g]
        if hg <= 0.0:
            continue
        inside = True
        a = fv[fs[g + 1] - 1] - off
        for k in range(fs[g], fs[g + 1]):
            b = fv[k] - off
            ax = v[a, 0]
            ay = v[a, 1]
            az = v[a, 2]
            ex = v[b, 0] - ax
            ey = v[b, 1] - ay
            ez = v[b, 2] - az
            wx = cx - ax
            wy = cy - ay
            wz = cz - az
            if (ey * wz - ez * wy) * gx + (ez * wx - ex * wz) * gy + (ex * wy - ey * wx) * gz < 0.0:
                inside = False
                e2, qx, qy, qz = _segment_point(cx, cy, cz, ax, ay, az, v[b, 0], v[b, 1], v[b, 2])
                if e2 < best:
                    best = e2
                    face = -1
                    px = qx
                    py = qy
                    pz = qz
            a = b
        if inside and hg * hg < best:
            best = hg * hg
            face = g
            px = cx - hg * gx
            py = cy - hg * gy
            pz = cz - hg * gz
    s = math.sqrt(best)
    if face >= 0:
        return s, px, py, pz, n[face, 0], n[face, 1], n[face, 2]
    if s > DEGENERATE_REL * scale:
        return s, px, py, pz, (cx - px) / s, (cy - py) / s, (cz - pz) / s
    return s, px, py, pz, n[f, 0], n[f, 1], n[f, 2]


@njit(_nrt=False)
def sphere_polyhedron_overlap(cx, cy, cz, r, v, fs, fv, off, n, d):
    """Point contact of the sphere (centre c, radius r [m]) and a polyhedron (world arrays v,
    fs, fv, off, n, d, see the module docstring).

    Returns:
        (delta, nx, ny, nz, xx, xy, xz): overlap delta = r - s [m] (<= 0: apart); n the unit
        normal from the polyhedron to the sphere (the force on the sphere is along +n);
        x the contact point c - (r - delta / 2) n [m], the middle of the overlap.
    """
    s, _, _, _, nx, ny, nz = closest_feature(cx, cy, cz, v, fs, fv, off, n, d)
    delta = r - s
    arm = r - 0.5 * delta
    return delta, nx, ny, nz, cx - arm * nx, cy - arm * ny, cz - arm * nz


__all__ = ["DEGENERATE_REL", "closest_feature", "sphere_polyhedron_overlap"]
