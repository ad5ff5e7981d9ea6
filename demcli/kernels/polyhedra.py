"""Exact narrow phase between convex polyhedra (and against plane walls), numba kernels.

Geometry of one contact: the intersection I = A n B of two convex polyhedra, its
volume V, centroid g (the contact point) and the vector S (3,) whose direction is the
contact normal and whose length is the contact area.

Representation (world frame, one set of arrays per body)
--------------------------------------------------------
* ``v`` (nv, 3) float64, m: vertices.
* ``fs`` (nf + 1,) int64: CSR offsets into ``fv``; face f has the vertex rows
  ``fv[fs[f]:fs[f + 1]] - off``, counter-clockwise seen from outside. ``fs[0]`` need
  not be 0 and ``off`` (int) is subtracted from every entry of ``fv``, so the shape
  table's global rows (``face_vertex_start`` slice, full ``face_vertices``,
  ``off = vertex_start[shape]``) can be passed without copying.
* ``n`` (nf, 3) float64: unit outward face normals; ``d`` (nf,) float64, m: plane
  offsets, n_f . x <= d_f inside.
* ``cx, cy, cz``, m: the centre of a bounding sphere (the centroid), ``r``, m: its
  radius (every vertex within r of c).

:func:`to_world_vertices` and :func:`to_world_planes` place body-frame arrays with
(x, q), q = (w, x, y, z) a unit quaternion: x_world = x + R(q) x_body,
n_world = R(q) n_body, d_world = d_body + n_world . x.

Algorithm (:func:`overlap`)
---------------------------
The boundary of I is (faces of A inside B) u (faces of B inside A). Each face polygon
of A is clipped by the planes of B (Sutherland & Hodgman 1974, "Reentrant polygon
clipping", CACM 17(1), one plane at a time, fixed-size local buffers), and each face of
B by the planes of A. With o a point near I (the first clipped vertex) and each piece
P lying in its face plane (normal n_f) at the height h_P = n_f . (p0 - o) above o:

* V = sum_P h_P area(P) / 3 (divergence theorem: the cone from o over P);
* V g = sum over the fan triangles (p0, pi, pi+1) of P of their tetrahedra with o:
  vol_t (o + p0 + pi + pi+1) / 4, vol_t = h_P area_t / 3;
* S = sum_{P on B} area(P) n_B = - sum_{P on A} area(P) n_A (the two sums cancel
  as the boundary of I is closed; the kernel returns their mean difference
  (S_B - S_A)/2).

Why S is the right normal (energy-conserving contact, Feng & Tan 2019 "An
energy-conserving contact theory for discrete element modelling of arbitrarily
shaped particles: basic framework and general contact model", CMAME 349; Feng 2021,
"... contact volume based model for polyhedral particles", CMAME 373): translate A
by t. Only the part of A's boundary inside B moves the boundary of I, each surface
element sweeping the volume (n_A . dt) dA, so

    dV/dt = integral over (dA n B) of n_A dA = sum_{P on A} area(P) n_A = -S.

S is (minus) the gradient of V with respect to A's position: a contact energy
U(V) gives the conservative force F_A = -dU/dx_A = U'(V) S on A (and -F_A on B).
S points from B into A (moving A along S reduces V). S is a sum of clipped areas
and changes continuously with the configuration, except where a face of A and a
face of B facing the same way are coplanar: V has a kink there (two aligned cubes
sliding face to face, as B's side faces pass A's), and the piece of I's boundary on
the common plane (a strip, depth x edge) belongs to A on one side of the kink and to
B on the other, its area vector counting with opposite signs. Which side a piece is
on can flip under a turn of 1e-12 rad, and the normal jumped by the strip's share
of |S| (2.5e-4 rad for a plate standing on a plate, ends flush, 10 um deep).

Regularization (:func:`_band_deficit`): a piece of I's boundary near a same-facing
face of the other body counts with the weight min(1, s / w) at the distance s from
that face, w = band = BAND_REL min(r_A, r_B) for parallel faces (ramped to 0 at
|cos| = PARALLEL_COS). On the common plane (s = 0) a piece counts for nothing, the
mean of its two one-sided gradients; beyond w it counts fully. S is thus continuous,
and equals -dV/dx_A wherever no same-facing faces come within w of each other; the
kink of V is rounded over a length w (1e-3 of the smaller bounding radius: 20 um for 40 mm
stones; V and the centroid stay exact). Its cost is paid only by faces with such a
neighbour: the planes that miss the culling box by less than w are listed apart and
never clipped by.

The contact area is A_c = |S| (the area of the contact patch projected onto the
plane normal to n) and the overlap depth d = V/A_c.

Deep overlap: when one body lies wholly inside the other every face of the inner
one survives the clipping, the boundary pieces on the inner body form its whole
closed surface and S -> 0 (V is the smaller volume and does not change under small
translations: the conservative force is zero). :func:`contact_frame` then takes the
normal from the centroid difference c_A - c_B, blended continuously with S (see
there).

Robustness
----------
Plane tests use a tolerance tau tied to the body size (``TOL_REL`` min(r_A, r_B)
plus the round-off of the world coordinates, ``TOL_COORD`` max |x|). Where a face
and a clipping plane are nearly parallel (|cos| > ``PARALLEL_COS``, cos = n_face .
n_plane) the plane is shifted by up to tau (ramped in |cos|, so continuous) with a
tie rule that makes coplanar faces exact:

* face of A against a plane of B facing the same way (cos > 0): keep s <= +tau;
* every other pair (A face against an opposite plane of B, any B face against a
  plane of A): keep s <= -tau.

Two nearly coplanar faces facing the same way then partition their common plane
exactly (the A face is kept where it lies below the B face + tau, the B face exactly
where it does not), so a shared face is counted once; two faces facing each other
are both kept or both dropped (a touching contact has V = 0, not a stray face).
"Exactly" needs both clips to use one plane: clipping face f by plane g and face g
by plane f puts the two dividing lines round-off / angle apart (1e-16 / 1e-13 rad =
1e-3 of the face: a strip counted twice, V off by 1e-5 relative, seen in testing).
For nearly parallel pairs both faces are therefore clipped by the difference plane
(n_g - sgn(c) n_f) . x <= d_g - sgn(c) d_f, which equals plane g on face f and
plane f (up to sign) on face g, and whose coefficients are the same floating-point
numbers in both clips.
Planes at larger angles to a face cannot hold it and are not shifted, and a plane
parallel to a face never cuts it, so boxes in any common orientation come out exact
to round-off; elsewhere a shift changes V by O(tau x edge x size), ~1e-13 relative.
Cone heights are taken from a vertex of each piece (n . (p0 - o)), not from the
plane offset, so thin overlaps do not lose their digits to the offset's round-off.
Clipped polygons never divide by a vanishing number (s0 <= 0 < s1 before
interpolation).
The centroid is clamped into the bounding box of the clipped vertices, so it stays in
the contact region when V is at round-off level; V is clamped at >= 0.

Culling (what makes it fast: ~5 us per contact for 20-40-face bodies, see
bench/bench_polyhedra.py): bounding spheres; the ranges of A and B along the centre
line (a separating-axis test on c_B - c_A); the box where the bounding boxes of A
and B overlap, which holds I: a plane with the box wholly outside separates the
bodies, planes that miss the box neither clip nor carry a face piece, faces that
miss it are skipped. The remaining planes are sorted to face the other body first,
so a face outside it is dropped after one or two plane tests; a plane that leaves a
(partly clipped) face wholly inside costs one pass over its vertices.

Temporal coherence (:func:`overlap_in_box`): between two steps a contact's intersection moves
by ~1e-6 of a stone, while the bodies' common bounding box holds most of both bodies (on the
loaded quickstart bed 16-17 faces meet it, 3.5 per body cut the intersection's own box). The
engine keeps each touching pair's intersection box and culls the next evaluation by it, widened
by BOX_PAD = 1e-2 min(r_A, r_B): no extents, and a handful of planes and faces. The result
shows whether the box held the whole intersection (every piece strictly inside it, see
there); if not (or nothing is left in it) the pair is evaluated again in full. Measured on
that bed's 244 touching pairs one step on: no fallback, results equal to the full overlap to
2e-15 relative, 1.7 against 4.3 us per pair (bench/README.md).

Reference counting: numba updates an atomic reference count whenever an array is
rebound or passed to an inlined helper; in the clipping loop that cost more than
the geometry, so the clipping and cone sums are written out in
:func:`_faces_inside`, the polygon buffers are addressed by row offsets and the
scratch by flat offsets (no array views). The geometry kernels the pair and wall passes call
(:func:`overlap_ws`, :func:`overlap_in_box`, :func:`_clip_in_box`, :func:`_faces_inside`,
:func:`plane_overlap_ws`) allocate nothing and are compiled without reference counting
(numba's ``_nrt=False``): their calls passed each array on with an atomic increment and
decrement (16 and 14 in the first two): on the loaded quickstart bed the step per touching pair
fell from 1.5 to 1.3 us (4.3e5 -> 5.0e5 body-steps/s, bench/README.md).
:func:`overlap_ws` takes caller-owned scratch (one set per thread, from
:func:`scratch`); :func:`overlap` allocates it per call (~5 % slower).

Plane walls (:func:`plane_overlap`): the wall solid is the half-space n . x <= d
(n the wall's unit normal, pointing into the domain). The faces of A are clipped by
it; with o on the wall plane the cross-section cap adds nothing to V and g, and
S = (cross-section area) n = -(sum of the pieces' area vectors), the boundary being
closed.

All kernels are pure functions of arrays and scalars; fastmath is off.
"""

import math

import numpy as np

from demcli.jit import njit
from demcli.kernels.quat import rotate

# plane tolerance: tau = TOL_REL min(r_A, r_B) + TOL_COORD (max |world coordinate|)
TOL_REL = 1e-13
TOL_COORD = 1e-14
# face-plane pairs with |cos| above this are treated as possibly coplanar (tie rule)
PARALLEL_COS = 0.99
# S: a boundary piece of I within BAND_REL min(r_A, r_B) of a same-facing face of the other
# body counts in proportion to its distance from it (see _band_deficit)
BAND_REL = 1e-3
# overlap_in_box: a touching pair's culling box is its last intersection's bounding box widened by
# BOX_PAD min(r_A, r_B) on each side (a fallback to the full overlap when I reaches out of it)
BOX_PAD = 1e-2
# contact_frame: S is blended with the unit centroid difference where |S| is below
# about AREA_BLEND r_A r_B (round-off level: one body inside the other)
AREA_BLEND = 1e-10


@njit
def to_world_vertices(vb, x, q, out):
    """World vertices: out[i] = x + R(q) vb[i].

    vb: (nv, 3) float64, m, body frame. x: (3,) float64, m. q: (4,) float64, unit
    quaternion (w, x, y, z). out: (nv, 3) float64, m, written.
    """
    for i in range(vb.shape[0]):
        wx, wy, wz = rotate(q[0], q[1], q[2], q[3], vb[i, 0], vb[i, 1], vb[i, 2])
        out[i, 0] = x[0] + wx
        out[i, 1] = x[1] + wy
        out[i, 2] = x[2] + wz


@njit
def to_world_planes(nb, db, x, q, n_out, d_out):
    """World face planes: n = R(q) nb[f], d = db[f] + n . x.

    nb: (nf, 3) float64 unit body-frame normals. db: (nf,) float64, m. x: (3,) m.
    q: (4,) unit quaternion (w, x, y, z). n_out (nf, 3), d_out (nf,): written.
    """
    for f in range(nb.shape[0]):
        wx, wy, wz = rotate(q[0], q[1], q[2], q[3], nb[f, 0], nb[f, 1], nb[f, 2])
        n_out[f, 0] = wx
        n_out[f, 1] = wy
        n_out[f, 2] = wz
        d_out[f] = db[f] + wx * x[0] + wy * x[1] + wz * x[2]


@njit(inline="always")
def _clip_to(buf, src, m, dst, sd, nx, ny, nz, d):
    """Sutherland-Hodgman: the part of the polygon in rows buf[src:src + m] with
    n . x <= d, written to buf[dst:]; the clipped vertex count.

    The plane is tested first: returns -m (nothing written) if the whole polygon is
    inside, 0 if it is all outside. Intersections are interpolated only between a
    vertex with s <= 0 and one with s > 0, so s0 - s1 never vanishes. sd (>= m,):
    scratch for the signed distances. Offsets into one buffer rather than swapped
    array references: swapping arrays costs numba reference-count updates.
    """
    lo = np.inf
    hi = -np.inf
    for i in range(m):
        t = nx * buf[src + i, 0] + ny * buf[src + i, 1] + nz * buf[src + i, 2] - d
        sd[i] = t
        lo = min(lo, t)
        hi = max(hi, t)
    if hi <= 0.0:
        return -m
    if lo > 0.0:
        return 0
    k = dst
    ip = src + m - 1
    sp = sd[m - 1]
    for i in range(m):
        ic = src + i
        sc = sd[i]
        if sc <= 0.0:
            if sp > 0.0:
                t = sp / (sp - sc)
                buf[k, 0] = buf[ip, 0] + t * (buf[ic, 0] - buf[ip, 0])
                buf[k, 1] = buf[ip, 1] + t * (buf[ic, 1] - buf[ip, 1])
                buf[k, 2] = buf[ip, 2] + t * (buf[ic, 2] - buf[ip, 2])
                k += 1
            buf[k, 0] = buf[ic, 0]
            buf[k, 1] = buf[ic, 1]
            buf[k, 2] = buf[ic, 2]
            k += 1
        elif sp <= 0.0:
            t = sp / (sp - sc)
            buf[k, 0] = buf[ip, 0] + t * (buf[ic, 0] - buf[ip, 0])
            buf[k, 1] = buf[ip, 1] + t * (buf[ic, 1] - buf[ip, 1])
            buf[k, 2] = buf[ip, 2] + t * (buf[ic, 2] - buf[ip, 2])
            k += 1
        ip = ic
        sp = sc
    return k - dst


@njit(inline="always")
def _piece(p, i0, m, nx, ny, nz, h, ox, oy, oz, work):
    """Cone from o over the planar polygon p[i0:i0 + m] (normal n, o at height h below it).

    Returns (volume, first moment about o (3), signed area along n); widens the box
    work[4:10] = (min xyz, max xyz) to the polygon's vertices.
    """
    for c in range(3):
        lo = p[i0, c]
        hi = p[i0, c]
        for i in range(i0 + 1, i0 + m):
            lo = min(lo, p[i, c])
            hi = max(hi, p[i, c])
        work[4 + c] = min(work[4 + c], lo)
        work[7 + c] = max(work[7 + c], hi)
    ax = p[i0, 0] - ox
    ay = p[i0, 1] - oy
    az = p[i0, 2] - oz
    area2 = 0.0
    mx = 0.0
    my = 0.0
    mz = 0.0
    bx = p[i0 + 1, 0] - ox
    by = p[i0 + 1, 1] - oy
    bz = p[i0 + 1, 2] - oz
    for i in range(i0 + 2, i0 + m):
        cx = p[i, 0] - ox
        cy = p[i, 1] - oy
        cz = p[i, 2] - oz
        ux = bx - ax
        uy = by - ay
        uz = bz - az
        wx = cx - ax
        wy = cy - ay
        wz = cz - az
        a2 = nx * (uy * wz - uz * wy) + ny * (uz * wx - ux * wz) + nz * (ux * wy - uy * wx)
        area2 += a2
        # tetrahedron (o, a, b, c): volume h a2 / 6, centroid o + (a + b + c)/4
        mx += a2 * (ax + bx + cx)
        my += a2 * (ay + by + cy)
        mz += a2 * (az + bz + cz)
        bx = cx
        by = cy
        bz = cz
    return h * area2 / 6.0, h * mx / 24.0, h * my / 24.0, h * mz / 24.0, 0.5 * area2


@njit(inline="always")
def max_row(fs):
    """Longest row of a CSR offset array (faces: the most vertices of a face; shapes:
    the most faces of a shape)."""
    m = 0
    for f in range(fs.shape[0] - 1):
        k = fs[f + 1] - fs[f]
        if k > m:
            m = k
    return m


@njit(internal=True)
def _shift(first, cosang, tol):
    """Outward shift of a clipping plane (tie rule, see the module docstring): tau
    ramped from 0 at |cos| = PARALLEL_COS to 1 at |cos| = 1; outward for a face of A
    against a same-facing plane of B, inward for every other pair. Planes at an angle
    of more than ~8 deg to the face are not shifted: they cannot hold it."""
    c = abs(cosang)
    if c <= PARALLEL_COS:
        return 0.0
    t = tol * (c - PARALLEL_COS) / (1.0 - PARALLEL_COS)
    if first and cosang > 0.0:
        return t
    return -t


@njit(inline="always")
def _band_deficit(buf, src, m, dst, sd, fnx, fny, fnz, n2, d2, planes, p0, ncut, q0, nnear, band):
    """How much less than its area [m^2] the piece buf[src:src + m] of a face (unit
    normal n_f) counts in S, near the same-facing faces of the other body.

    The faces g considered are planes[p0:p0 + ncut] (those cutting the culling box)
    and planes[q0], planes[q0 - 1], ... (nnear; those missing it by less than band).
    Where g is coplanar with the piece and faces the same way, the piece is on both
    boundaries and V has a kink (module docstring), so the piece counts with the
    weight min(1, -s / w) at its signed distance s = n_g . x - d_g from g (s <= ~0 on
    it): nothing on g, where the two one-sided gradients of V average to no
    contribution, fully from s = -w on. w = band (c - PARALLEL_COS) / (1 -
    PARALLEL_COS) for c = n_f . n_g > PARALLEL_COS (ramped like the tie rule's shift,
    so a face turning past PARALLEL_COS changes nothing); faces at larger angles are
    skipped. The deficit of one g is the integral of max(0, 1 + s / w) over the piece:
    the piece clipped to s >= -w into buf[dst:] (:func:`_clip_to`, sd its scratch),
    the integrand, linear there, summed over the fan triangles as area_t (w_0 + w_1 +
    w_2) / 3 from its corner values. Inlined: a call costs the hot loop of
    :func:`_faces_inside` ~5 % even when not taken (measured).
    """
    total = 0.0
    for k in range(ncut + nnear):
        g = planes[p0 + k] if k < ncut else planes[q0 + ncut - k]
        gx = n2[g, 0]
        gy = n2[g, 1]
        gz = n2[g, 2]
        c = fnx * gx + fny * gy + fnz * gz
        if c <= PARALLEL_COS:
            continue
        width = band * (c - PARALLEL_COS) / (1.0 - PARALLEL_COS)
        dg = d2[g]
        n = _clip_to(buf, src, m, dst, sd, -gx, -gy, -gz, width - dg)
        if n == 0:
            continue
        i0 = dst
        if n < 0:
            n = m
            i0 = src
        ax = buf[i0, 0]
        ay = buf[i0, 1]
        az = buf[i0, 2]
        wa = 1.0 + (gx * ax + gy * ay + gz * az - dg) / width
        bx = buf[i0 + 1, 0] - ax
        by = buf[i0 + 1, 1] - ay
        bz = buf[i0 + 1, 2] - az
        wb = 1.0 + (gx * buf[i0 + 1, 0] + gy * buf[i0 + 1, 1] + gz * buf[i0 + 1, 2] - dg) / width
        for i in range(i0 + 2, i0 + n):
            cx = buf[i, 0] - ax
            cy = buf[i, 1] - ay
            cz = buf[i, 2] - az
            wc = 1.0 + (gx * buf[i, 0] + gy * buf[i, 1] + gz * buf[i, 2] - dg) / width
            total += (fnx * (by * cz - bz * cy) + fny * (bz * cx - bx * cz) + fnz * (bx * cy - by * cx)) * (
                wa + wb + wc) / 6.0
            bx = cx
            by = cy
            bz = cz
            wb = wc
    return total


# Not internal (measured: as an internal kernel its type inference took 8.3-10.2 s of a cold
# polyhedral compile, with its Python wrapper 4.7-6.1 s; 5 runs each, cause inside numba not found)
@njit(_nrt=False)
def _faces_inside(v1, fs1, fv1, off1, n1, d1, planes, f0, nfaces1, n2, d2, p0, nplanes2, q0, nnear2, tol, band,
                  first, buf, cap, fw):
    """Pieces of the faces planes[f0:f0 + nfaces1] of body 1 inside body 2, added to
    the sums in fw.

    A face that misses the culling box (fw[0:6]: low xyz, high xyz; it holds A n B)
    is skipped; the others are clipped by each plane planes[p0:p0 + nplanes2] of body
    2 in turn: a plane that leaves the polygon inside is skipped, one that leaves it
    outside drops it. first: whether body 1 is A (tie rule, :func:`_shift`).
    band [m]: width of the regularization of S near same-facing faces of body 2
    (:func:`_band_deficit`; V and the centroid are exact): the planes of body 2 within
    band of the box that do not cut it are planes[q0], planes[q0 - 1], ... (nnear2).
    buf (2 cap, 3): two polygon slots at rows 0 and cap. fw: box (0-5), the moments
    int (p - o) x n dA of A's pieces (6-8) and of B's (9-11), scratch (12-17; 6-17 hold the
    bodies' boxes before the clipping), then from 18: cone origin o and a set flag (18-21), bounding box of the
    pieces (22-27: min xyz, max xyz), V (28), first moment about o (29-31), S (32-34),
    number of pieces (35), then signed distances (36-). Flat offsets rather than
    slices: every array view costs two atomic reference-count updates.
    """
    for ia in range(nfaces1):
        f = planes[f0 + ia]
        j0 = fs1[f]
        m = fs1[f + 1] - j0
        lo0 = np.inf
        hi0 = -np.inf
        lo1 = np.inf
        hi1 = -np.inf
        lo2 = np.inf
        hi2 = -np.inf
        for j in range(m):
            r = fv1[j0 + j] - off1
            x = v1[r, 0]
            y = v1[r, 1]
            z = v1[r, 2]
            buf[j, 0] = x
            buf[j, 1] = y
            buf[j, 2] = z
            lo0 = min(lo0, x)
            hi0 = max(hi0, x)
            lo1 = min(lo1, y)
            hi1 = max(hi1, y)
            lo2 = min(lo2, z)
            hi2 = max(hi2, z)
        if (lo0 > fw[3] or hi0 < fw[0] or lo1 > fw[4] or hi1 < fw[1]
                or lo2 > fw[5] or hi2 < fw[2]):
            continue
        src = 0
        dst = cap
        fnx = n1[f, 0]
        fny = n1[f, 1]
        fnz = n1[f, 2]
        npar = 0  # planes of body 2 nearly parallel to the face and facing the same way
        # clip by the planes of body 2 (the body of _clip_to, written out here: an
        # inlined helper taking arrays costs two atomic reference-count updates per
        # array per call, which made up most of the run time)
        for ib in range(nplanes2):
            g = planes[p0 + ib]
            gx = n2[g, 0]
            gy = n2[g, 1]
            gz = n2[g, 2]
            cg = fnx * gx + fny * gy + fnz * gz
            dg = d2[g]
            if cg > PARALLEL_COS:
                npar += 1
            if abs(cg) > PARALLEL_COS:
                # nearly parallel: clip by the difference plane (n_g - sgn(c) n_f) . x <=
                # d_g - sgn(c) d_f, equal to plane g on the face's own plane; the pair's
                # other clip (g's face by plane f) then uses the same plane with the sign
                # flipped, bit for bit, so the two faces split their common area along one
                # line (clipping each by the other's plane puts the two lines round-off /
                # angle apart, double-counting a strip)
                if cg > 0.0:
                    gx -= fnx
                    gy -= fny
                    gz -= fnz
                    dg -= d1[f]
                else:
                    gx += fnx
                    gy += fny
                    gz += fnz
                    dg += d1[f]
            dg += _shift(first, cg, tol)
            lo = np.inf
            hi = -np.inf
            for i in range(src, src + m):
                t = gx * buf[i, 0] + gy * buf[i, 1] + gz * buf[i, 2] - dg
                fw[36 + i - src] = t
                lo = min(lo, t)
                hi = max(hi, t)
            if hi <= 0.0:  # all inside: untouched
                continue
            if lo > 0.0:  # all outside: the face has no piece
                m = 0
                break
            k = dst
            ip = src + m - 1
            sp = fw[36 + m - 1]
            for i in range(m):
                ic = src + i
                sc = fw[36 + i]
                if sc <= 0.0:
                    if sp > 0.0:
                        t = sp / (sp - sc)
                        buf[k, 0] = buf[ip, 0] + t * (buf[ic, 0] - buf[ip, 0])
                        buf[k, 1] = buf[ip, 1] + t * (buf[ic, 1] - buf[ip, 1])
                        buf[k, 2] = buf[ip, 2] + t * (buf[ic, 2] - buf[ip, 2])
                        k += 1
                    buf[k, 0] = buf[ic, 0]
                    buf[k, 1] = buf[ic, 1]
                    buf[k, 2] = buf[ic, 2]
                    k += 1
                elif sp <= 0.0:
                    t = sp / (sp - sc)
                    buf[k, 0] = buf[ip, 0] + t * (buf[ic, 0] - buf[ip, 0])
                    buf[k, 1] = buf[ip, 1] + t * (buf[ic, 1] - buf[ip, 1])
                    buf[k, 2] = buf[ip, 2] + t * (buf[ic, 2] - buf[ip, 2])
                    k += 1
                ip = ic
                sp = sc
            m = k - dst
            if m < 3:
                break
            src, dst = dst, src
        if m < 3:
            continue
        if fw[21] == 0.0:
            fw[18] = buf[src, 0]
            fw[19] = buf[src, 1]
            fw[20] = buf[src, 2]
            fw[21] = 1.0
        ox = fw[18]
        oy = fw[19]
        oz = fw[20]
        # height of o below the piece's plane, from a vertex of the piece (the
        # difference of nearby points is exact where the plane offset is not)
        h = fnx * (buf[src, 0] - ox) + fny * (buf[src, 1] - oy) + fnz * (buf[src, 2] - oz)
        # the cone from o over the piece (the body of _piece, written out likewise)
        for c in range(3):
            lo = buf[src, c]
            hi = lo
            for i in range(src + 1, src + m):
                lo = min(lo, buf[i, c])
                hi = max(hi, buf[i, c])
            fw[18 + 4 + c] = min(fw[18 + 4 + c], lo)
            fw[18 + 7 + c] = max(fw[18 + 7 + c], hi)
        ax = buf[src, 0] - ox
        ay = buf[src, 1] - oy
        az = buf[src, 2] - oz
        bx = buf[src + 1, 0] - ox
        by = buf[src + 1, 1] - oy
        bz = buf[src + 1, 2] - oz
        area2 = 0.0
        mx = 0.0
        my = 0.0
        mz = 0.0
        for i in range(src + 2, src + m):
            cx = buf[i, 0] - ox
            cy = buf[i, 1] - oy
            cz = buf[i, 2] - oz
            a2 = (fnx * ((by - ay) * (cz - az) - (bz - az) * (cy - ay))
                  + fny * ((bz - az) * (cx - ax) - (bx - ax) * (cz - az))
                  + fnz * ((bx - ax) * (cy - ay) - (by - ay) * (cx - ax)))
            area2 += a2
            mx += a2 * (ax + bx + cx)
            my += a2 * (ay + by + cy)
            mz += a2 * (az + bz + cz)
            bx = cx
            by = cy
            bz = cz
        # the piece's moment of its area vector about o, int (p - o) x n dA = (first moment of its area
        # about o, m / 6) x n, into fw[6:9] (body 1 = A) or fw[9:12] (B): the rotational part of dV
        # (a linearized geometry, kernels.shapes.polyhedra._linear_volume)
        t0 = 6 if first else 9
        fw[t0] += (my * fnz - mz * fny) / 6.0
        fw[t0 + 1] += (mz * fnx - mx * fnz) / 6.0
        fw[t0 + 2] += (mx * fny - my * fnx) / 6.0
        vol = h * area2 / 6.0
        mx *= h / 24.0
        my *= h / 24.0
        mz *= h / 24.0
        area = 0.5 * area2
        if npar > 0 or nnear2 > 0:
            # near a same-facing face of body 2 the piece is part of both boundaries (V has a
            # kink there): it counts in proportion to its distance from that face
            area = max(area - _band_deficit(buf, src, m, dst, fw[36:], fnx, fny, fnz, n2, d2, planes, p0, nplanes2,
                                            q0, nnear2, band), 0.0)
        fw[28] += vol
        fw[29] += mx
        fw[30] += my
        fw[31] += mz
        sgn = -0.5 if first else 0.5
        fw[32] += sgn * area * fnx
        fw[33] += sgn * area * fny
        fw[34] += sgn * area * fnz
        fw[35] += 1.0


@njit(inline="always")
def _extents(v, box, k, ux, uy, uz):
    """Bounding box of the vertices v into box[k:k + 6] (low xyz, high xyz); returns
    the range (low, high) of u . x over them."""
    ulo = np.inf
    uhi = -np.inf
    lo0 = np.inf
    hi0 = -np.inf
    lo1 = np.inf
    hi1 = -np.inf
    lo2 = np.inf
    hi2 = -np.inf
    for i in range(v.shape[0]):
        lo0 = min(lo0, v[i, 0])
        hi0 = max(hi0, v[i, 0])
        lo1 = min(lo1, v[i, 1])
        hi1 = max(hi1, v[i, 1])
        lo2 = min(lo2, v[i, 2])
        hi2 = max(hi2, v[i, 2])
        t = ux * v[i, 0] + uy * v[i, 1] + uz * v[i, 2]
        ulo = min(ulo, t)
        uhi = max(uhi, t)
    box[k] = lo0
    box[k + 1] = lo1
    box[k + 2] = lo2
    box[k + 3] = hi0
    box[k + 4] = hi1
    box[k + 5] = hi2
    return ulo, uhi


@njit(inline="always")
def _planes_in_box(n1, d1, box, ux, uy, uz, tol, band, sgn, planes, p0, q0):
    """Planes of body 1 that cut the box (box[0:6]) into planes[p0:], and those that
    miss it by less than band (they clip nothing but regularize S, see
    :func:`_band_deficit`) into planes[q0], planes[q0 - 1], ...; returns the two
    counts, or (-1, 0) if the box lies wholly outside one of them (then A n B, inside
    the box, is empty).

    The cutting planes are sorted by sgn (n . u) ascending (insertion sort, a few
    tens; u = c_B - c_A): with sgn = -1 for A and +1 for B the planes facing the other
    body come first; they are the ones most likely to drop a face early when clipping.
    """
    h0 = 0.5 * (box[3] - box[0])
    h1 = 0.5 * (box[4] - box[1])
    h2 = 0.5 * (box[5] - box[2])
    cx = 0.5 * (box[3] + box[0])
    cy = 0.5 * (box[4] + box[1])
    cz = 0.5 * (box[5] + box[2])
    nc = 0
    nn = 0
    for f in range(n1.shape[0]):
        nx = n1[f, 0]
        ny = n1[f, 1]
        nz = n1[f, 2]
        s = nx * cx + ny * cy + nz * cz - d1[f]
        r = h0 * abs(nx) + h1 * abs(ny) + h2 * abs(nz)
        if s - r > tol:
            return -1, 0
        if s + r < -tol:
            if s + r >= -band:
                planes[q0 - nn] = f
                nn += 1
        else:
            key = sgn * (nx * ux + ny * uy + nz * uz)
            k = nc
            while k > 0:
                g = planes[p0 + k - 1]
                if sgn * (n1[g, 0] * ux + n1[g, 1] * uy + n1[g, 2] * uz) <= key:
                    break
                planes[p0 + k] = g
                k -= 1
            planes[p0 + k] = f
            nc += 1
    return nc, nn


@njit
def overlap(va, fsa, fva, offa, na, da, cax, cay, caz, ra,
            vb, fsb, fvb, offb, nb, db, cbx, cby, cbz, rb):
    """Intersection of two convex polyhedra A and B (world frame).

    Args:
        va: (nva, 3) float64, m, vertices of A.
        fsa: (nfa + 1,) int64, CSR offsets of A's faces into fva.
        fva: int64 vertex rows (+ offa) of A's faces, counter-clockwise from outside.
        offa: int, subtracted from fva entries to index va.
        na: (nfa, 3) float64 unit outward normals of A; da: (nfa,) float64, m, offsets.
        cax, cay, caz: m, centre of A's bounding sphere; ra: m, its radius.
        vb, fsb, fvb, offb, nb, db, cbx, cby, cbz, rb: the same for B.

    Returns:
        (V, gx, gy, gz, sx, sy, sz): overlap volume [m^3], its centroid [m] and
        S [m^2] = sum of (area x outward normal of B) over B's boundary inside A,
        pointing from B into A; S = -dV/dx_A (regularized near coplanar same-facing
        faces, see the module docstring); |S| is the contact area. V = 0 and
        g = (c_A + c_B)/2, S = 0 when the bodies do not overlap.

    Culling: bounding spheres; the ranges of A and B along the centre line c_B - c_A;
    the box where the bounding boxes of A and B overlap, which holds A n B: a plane
    with the box wholly outside separates the bodies, faces and planes that miss the
    box are skipped.
    """
    mx_ = 0.5 * (cax + cbx)
    my_ = 0.5 * (cay + cby)
    mz_ = 0.5 * (caz + cbz)
    ux = cbx - cax
    uy = cby - cay
    uz = cbz - caz
    big = max(abs(cax), abs(cay), abs(caz), abs(cbx), abs(cby), abs(cbz))
    tol = TOL_REL * min(ra, rb) + TOL_COORD * (big + max(ra, rb))
    reach = ra + rb + tol
    dist2 = ux * ux + uy * uy + uz * uz
    if dist2 > reach * reach:
        return 0.0, mx_, my_, mz_, 0.0, 0.0, 0.0
    nfa = fsa.shape[0] - 1
    nfb = fsb.shape[0] - 1
    cap = max(max_row(fsa), max_row(fsb)) + max(nfa, nfb) + 2
    buf = np.empty((2 * cap, 3))
    fw = np.empty(36 + cap)
    planes = np.empty(nfa + nfb, dtype=np.int64)
    return overlap_ws(va, fsa, fva, offa, na, da, cax, cay, caz, ra,
                      vb, fsb, fvb, offb, nb, db, cbx, cby, cbz, rb, buf, fw, planes)


@njit(_nrt=False)
def overlap_ws(va, fsa, fva, offa, na, da, cax, cay, caz, ra,
               vb, fsb, fvb, offb, nb, db, cbx, cby, cbz, rb, buf, fw, planes):
    """:func:`overlap` with caller-owned scratch (allocate once per thread):

    buf (2 cap, 3) float64, fw (36 + cap,) float64 and planes (nf_A + nf_B,) int64,
    cap = (largest face vertex count) + max(nf_A, nf_B) + 2 (see :func:`scratch`).
    """
    mx_ = 0.5 * (cax + cbx)
    my_ = 0.5 * (cay + cby)
    mz_ = 0.5 * (caz + cbz)
    ux = cbx - cax
    uy = cby - cay
    uz = cbz - caz
    big = max(abs(cax), abs(cay), abs(caz), abs(cbx), abs(cby), abs(cbz))
    tol = TOL_REL * min(ra, rb) + TOL_COORD * (big + max(ra, rb))
    reach = ra + rb + tol
    if ux * ux + uy * uy + uz * uz > reach * reach:
        return 0.0, mx_, my_, mz_, 0.0, 0.0, 0.0
    # fw: box (0-5), the two bodies' boxes (6-17), sums (18-35), distances (36-)
    # ranges along the centre line: a separating axis test on c_B - c_A
    ulo_a, uhi_a = _extents(va, fw, 6, ux, uy, uz)
    ulo_b, uhi_b = _extents(vb, fw, 12, ux, uy, uz)
    tu = tol * math.sqrt(ux * ux + uy * uy + uz * uz)
    if ulo_b - uhi_a > tu or ulo_a - uhi_b > tu:
        return 0.0, mx_, my_, mz_, 0.0, 0.0, 0.0
    for k in range(3):
        lo = max(fw[6 + k], fw[12 + k]) - tol
        hi = min(fw[9 + k], fw[15 + k]) + tol
        if lo > hi:
            return 0.0, mx_, my_, mz_, 0.0, 0.0, 0.0
        fw[k] = lo
        fw[3 + k] = hi
    if not _clip_in_box(va, fsa, fva, offa, na, da, vb, fsb, fvb, offb, nb, db, ux, uy, uz, tol,
                        BAND_REL * min(ra, rb), buf, fw, planes):
        return 0.0, mx_, my_, mz_, 0.0, 0.0, 0.0
    return _finish(fw, 18, mx_, my_, mz_)


@njit(internal=True, _nrt=False)
def _clip_in_box(va, fsa, fva, offa, na, da, vb, fsb, fvb, offb, nb, db, ux, uy, uz, tol, band, buf, fw, planes):
    """The boundary pieces of A n B that the culling box fw[0:6] holds, summed into fw[18:36]
    (:func:`_faces_inside`): the planes of A and of B that cut the box (sorted by their normals'
    projection on u = c_B - c_A, see :func:`_planes_in_box`), then the faces of A clipped by B's and
    those of B by A's. Returns False (nothing summed) when the box lies outside a plane of A or B."""
    cap = buf.shape[0] // 2
    # planes: A's cutting planes from 0, B's after them; A's near planes from the end
    # down, B's below them (see _planes_in_box)
    qa = planes.shape[0] - 1
    nca, nna = _planes_in_box(na, da, fw, ux, uy, uz, tol, band, -1.0, planes, 0, qa)
    if nca < 0:
        return False
    ncb, nnb = _planes_in_box(nb, db, fw, ux, uy, uz, tol, band, 1.0, planes, nca, qa - nna)
    if ncb < 0:
        return False
    for k in range(18, 36):
        fw[k] = 0.0
    for k in range(6, 12):
        fw[k] = 0.0
    for c in range(3):
        fw[22 + c] = np.inf
        fw[25 + c] = -np.inf
    # typed values, not literals (0, True, a count numba typed as the constant 0): one
    # compiled _faces_inside then serves both calls (it was compiled four times)
    zero = np.int64(0)
    _faces_inside(va, fsa, fva, offa, na, da, planes, zero, nca, nb, db, nca, ncb, qa - nna, np.int64(nnb), tol,
                  band, np.bool_(True), buf, cap, fw)
    _faces_inside(vb, fsb, fvb, offb, nb, db, planes, nca, ncb, na, da, zero, nca, qa, np.int64(nna), tol,
                  band, np.bool_(False), buf, cap, fw)
    return True


@njit(_nrt=False)
def overlap_in_box(va, fsa, fva, offa, na, da, cax, cay, caz, ra,
                   vb, fsb, fvb, offb, nb, db, cbx, cby, cbz, rb, box, buf, fw, planes):
    """:func:`overlap_ws` culled by a given box instead of the bodies' bounding boxes (temporal
    coherence: a touching pair's last intersection, widened, see :data:`BOX_PAD`).

    box (6,) float64, m: low xyz, high xyz. Returns (ok, V, gx, gy, gz, sx, sy, sz). With ok
    True the result is exactly what :func:`overlap_ws` computes, up to round-off (the same
    pieces, clipped by fewer planes); ok False: I may reach out of the box (or is empty) and
    nothing is returned: evaluate with :func:`overlap_ws`.

    Why the check below makes it exact. Planes that leave the box inside by more than tau
    are skipped, faces whose bounding box misses it are skipped, the others are clipped by
    the planes that cut it. A computed piece then contains the true piece of its face (it was
    clipped by fewer planes), and one that lies inside the box by more than tau is the true
    piece (a skipped plane holds the whole box). If I reached out of the box, its boundary
    would cross the box's at some point p, on the true piece of a face whose polygon therefore
    meets the box: that face's computed piece holds p, on the box's boundary. So when every
    piece lies inside the box by more than tau, no piece is missing and each is exact.
    """
    mx_ = 0.5 * (cax + cbx)
    my_ = 0.5 * (cay + cby)
    mz_ = 0.5 * (caz + cbz)
    big = max(abs(cax), abs(cay), abs(caz), abs(cbx), abs(cby), abs(cbz))
    tol = TOL_REL * min(ra, rb) + TOL_COORD * (big + max(ra, rb))
    for k in range(6):
        fw[k] = box[k]
    if not _clip_in_box(va, fsa, fva, offa, na, da, vb, fsb, fvb, offb, nb, db, cbx - cax, cby - cay, cbz - caz,
                        tol, BAND_REL * min(ra, rb), buf, fw, planes) or fw[35] == 0.0:
        return False, 0.0, mx_, my_, mz_, 0.0, 0.0, 0.0
    for k in range(3):  # the pieces' box (fw[22:28]) strictly inside the culling box
        if fw[22 + k] <= box[k] + tol or fw[25 + k] >= box[3 + k] - tol:
            return False, 0.0, mx_, my_, mz_, 0.0, 0.0, 0.0
    vol, gx, gy, gz, sx, sy, sz = _finish(fw, 18, mx_, my_, mz_)
    return True, vol, gx, gy, gz, sx, sy, sz


@njit
def scratch(max_face_vertices, max_faces):
    """Scratch arrays (buf, fw, planes) for :func:`overlap_ws`, large enough for any
    pair of bodies with at most max_faces faces of at most max_face_vertices each."""
    cap = max_face_vertices + max_faces + 2
    return np.empty((2 * cap, 3)), np.empty(36 + cap), np.empty(2 * max_faces, dtype=np.int64)


@njit(inline="always")
def _finish(w, k, gx, gy, gz):
    """(V, centroid, S) from the sums in w[k:k + 18] (the layout of fw[18:36] in
    :func:`_faces_inside`); g is the fallback point when nothing overlaps."""
    if w[k + 17] == 0.0:
        return 0.0, gx, gy, gz, 0.0, 0.0, 0.0
    vol = w[k + 10]
    if vol > 0.0:
        gx = w[k] + w[k + 11] / vol
        gy = w[k + 1] + w[k + 12] / vol
        gz = w[k + 2] + w[k + 13] / vol
    else:
        vol = 0.0
        gx = 0.5 * (w[k + 4] + w[k + 7])
        gy = 0.5 * (w[k + 5] + w[k + 8])
        gz = 0.5 * (w[k + 6] + w[k + 9])
    # the centroid of I lies in the hull of its boundary pieces: clamp round-off
    gx = min(max(gx, w[k + 4]), w[k + 7])
    gy = min(max(gy, w[k + 5]), w[k + 8])
    gz = min(max(gz, w[k + 6]), w[k + 9])
    return vol, gx, gy, gz, w[k + 14], w[k + 15], w[k + 16]


@njit
def plane_overlap(va, fsa, fva, offa, na, da, cax, cay, caz, ra, wnx, wny, wnz, wd):
    """Intersection of a convex polyhedron A with the wall half-space n_w . x <= wd.

    Args:
        va, fsa, fva, offa, na, da, cax, cay, caz, ra: body A as in :func:`overlap`.
        wnx, wny, wnz: unit wall normal, pointing out of the wall into the domain.
        wd: m, wall offset (the wall surface is n_w . x = wd).

    Returns:
        (V, gx, gy, gz, sx, sy, sz) as in :func:`overlap` with B the wall:
        S = (area of A's cross-section with the wall plane) n_w.
    """
    buf, heights, sd, work = plane_scratch(max_row(fsa), va.shape[0])
    return plane_overlap_ws(va, fsa, fva, offa, na, da, cax, cay, caz, ra, wnx, wny, wnz, wd, buf, heights, sd,
                            work)


@njit
def plane_scratch(max_face_vertices, max_vertices):
    """Scratch arrays (buf, heights, sd, work) of :func:`plane_overlap_ws` for bodies with at
    most max_vertices vertices and max_face_vertices per face."""
    cap = max_face_vertices + 2
    return np.empty((2 * cap, 3)), np.empty(max_vertices), np.empty(cap), np.empty(18)


@njit(_nrt=False)
def plane_overlap_ws(va, fsa, fva, offa, na, da, cax, cay, caz, ra, wnx, wny, wnz, wd, buf, heights, sd, work):
    """:func:`plane_overlap` with caller-owned scratch (:func:`plane_scratch`): buf (2 cap, 3),
    heights (>= n_v,), sd (cap,), work (18,), cap = (largest face vertex count) + 2.

    A face none of whose vertices lies within 2 tau above the wall (tau the plane tolerance,
    the most the tie rule shifts the wall, :func:`_shift`) has no piece and is skipped on the
    vertices' heights, computed once; the other faces are clipped as before (the same
    arithmetic in the same order: skipping changes no bit).
    """
    sc = wnx * cax + wny * cay + wnz * caz - wd
    # projection of A's centre onto the wall plane (the answer when nothing overlaps)
    ox = cax - sc * wnx
    oy = cay - sc * wny
    oz = caz - sc * wnz
    big = max(abs(cax), abs(cay), abs(caz), abs(wd))
    tol = TOL_REL * ra + TOL_COORD * (big + ra)
    if sc > ra + tol:
        return 0.0, ox, oy, oz, 0.0, 0.0, 0.0
    nfa = fsa.shape[0] - 1
    cap = buf.shape[0] // 2
    for k in range(va.shape[0]):
        heights[k] = wnx * va[k, 0] + wny * va[k, 1] + wnz * va[k, 2] - wd
    for k in range(18):  # the sums, laid out as fw[18:36] in _faces_inside
        work[k] = 0.0
    for c in range(3):
        work[4 + c] = np.inf
        work[7 + c] = -np.inf
    sn = 0.0  # sum of area x (n_f . n_w) over A's pieces = - cross-section area
    for f in range(nfa):
        j0 = fsa[f]
        m = fsa[f + 1] - j0
        low = np.inf
        for j in range(m):
            low = min(low, heights[fva[j0 + j] - offa])
        if low > 2.0 * tol:
            continue
        fnx = na[f, 0]
        fny = na[f, 1]
        fnz = na[f, 2]
        ndot = fnx * wnx + fny * wny + fnz * wnz
        for j in range(m):
            r = fva[j0 + j] - offa
            buf[j, 0] = va[r, 0]
            buf[j, 1] = va[r, 1]
            buf[j, 2] = va[r, 2]
        src = 0
        m2 = _clip_to(buf, 0, m, cap, sd, wnx, wny, wnz, wd + _shift(True, ndot, tol))
        if m2 >= 0:
            m = m2
            src = cap
        if m < 3:
            continue
        if work[3] == 0.0:
            # cone origin: the first piece's first vertex projected onto the wall plane
            # (near the overlap, so the cone sums do not cancel; on the plane, so the
            # cross-section cap adds nothing)
            t = wnx * buf[src, 0] + wny * buf[src, 1] + wnz * buf[src, 2] - wd
            work[0] = buf[src, 0] - t * wnx
            work[1] = buf[src, 1] - t * wny
            work[2] = buf[src, 2] - t * wnz
            work[3] = 1.0
        ox = work[0]
        oy = work[1]
        oz = work[2]
        h = fnx * (buf[src, 0] - ox) + fny * (buf[src, 1] - oy) + fnz * (buf[src, 2] - oz)
        dv, dmx, dmy, dmz, area = _piece(buf, src, m, fnx, fny, fnz, h, ox, oy, oz, work)
        work[10] += dv
        work[11] += dmx
        work[12] += dmy
        work[13] += dmz
        sn += area * ndot
        work[17] += 1.0
    area = max(-sn, 0.0)
    work[14] = area * wnx
    work[15] = area * wny
    work[16] = area * wnz
    return _finish(work, 0, ox, oy, oz)


@njit
def contact_frame(vol, sx, sy, sz, cax, cay, caz, cbx, cby, cbz, ra, rb):
    """Unit normal (from B into A), contact area A_c [m^2] and depth d = V/A_c [m].

    Args: V [m^3] and S (3) [m^2] from :func:`overlap` or :func:`plane_overlap`;
    centres of A and B [m] (for a wall: a point on the wall's side, e.g. A's centre
    minus the wall normal); bounding radii r_A, r_B [m] (for a wall: r_A).

    n = (S + b u) / |S + b u| with u the unit vector from B's centre to A's (+z if
    they coincide) and b = w^3 / (w^2 + |S|^2), w = AREA_BLEND r_A r_B: b -> w when S
    vanishes (one body inside the other: the normal is the centroid direction) and
    b/|S| ~ (w/|S|)^3 once the contact area is above round-off: n = S/|S| to 1e-12
    relative for |S| > 1e4 w = 1e-6 r_A r_B; continuous in between. A_c =
    max(|S|, w) keeps the depth finite.
    """
    ux = cax - cbx
    uy = cay - cby
    uz = caz - cbz
    lu = math.sqrt(ux * ux + uy * uy + uz * uz)
    w = AREA_BLEND * ra * rb
    s2 = sx * sx + sy * sy + sz * sz
    b = w * w * w / (w * w + s2) if w > 0.0 else 0.0
    if lu > 0.0:
        ux *= b / lu
        uy *= b / lu
        uz *= b / lu
    else:
        ux = 0.0
        uy = 0.0
        uz = b
    nx = sx + ux
    ny = sy + uy
    nz = sz + uz
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln > 0.0:
        nx /= ln
        ny /= ln
        nz /= ln
    else:
        nx = 0.0
        ny = 0.0
        nz = 1.0
    area = math.sqrt(sx * sx + sy * sy + sz * sz)
    if area < w:
        area = w
    return nx, ny, nz, area, vol / area


# ---------------------------------------------------------------- Python wrappers

class Placed:
    """A convex polyhedron placed in the world: the arrays :func:`overlap` takes.

    Build with :func:`place`. Attributes: vertices (nv, 3), face_start (nf + 1,),
    face_vertices (int64), normals (nf, 3), offsets (nf,), center (3,), radius.
    """

    __slots__ = ("vertices", "face_start", "face_vertices", "normals", "offsets", "center", "radius")

    def __init__(self, vertices, face_start, face_vertices, normals, offsets, center, radius):
        self.vertices = vertices
        self.face_start = face_start
        self.face_vertices = face_vertices
        self.normals = normals
        self.offsets = offsets
        self.center = center
        self.radius = radius

    def args(self):
        """The argument run of :func:`overlap` for this body (offset 0)."""
        c = self.center
        return (self.vertices, self.face_start, self.face_vertices, 0, self.normals, self.offsets,
                float(c[0]), float(c[1]), float(c[2]), float(self.radius))


def place(poly, x=(0.0, 0.0, 0.0), q=(1.0, 0.0, 0.0, 0.0)):
    """A ConvexPolyhedron (coordinates taken as the body frame) moved to x, rotated by q.

    x: (3,), m; q: (4,) unit quaternion (w, x, y, z): x_world = x + R(q) x_body.
    The bounding sphere is centred on the placed centroid.
    """
    x = np.ascontiguousarray(x, dtype=np.float64)
    q = np.ascontiguousarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q)
    vb = np.ascontiguousarray(poly.vertices, dtype=np.float64)
    v = np.empty_like(vb)
    to_world_vertices(vb, x, q, v)
    nb = np.ascontiguousarray(poly.normals, dtype=np.float64)
    n = np.empty_like(nb)
    d = np.empty(len(nb))
    to_world_planes(nb, np.ascontiguousarray(poly.offsets, dtype=np.float64), x, q, n, d)
    c = np.empty((1, 3))
    to_world_vertices(np.asarray(poly.centroid, dtype=np.float64).reshape(1, 3), x, q, c)
    radius = float(np.sqrt(((v - c[0]) ** 2).sum(axis=1)).max()) * (1.0 + 1e-12)
    return Placed(v, np.ascontiguousarray(poly.face_offsets, dtype=np.int64),
                  np.ascontiguousarray(poly.face_indices, dtype=np.int64), n, d, c[0].copy(), radius)


def polyhedron_overlap(a, b):
    """(V [m^3], centroid (3,) [m], S (3,) [m^2]) of two :class:`Placed` polyhedra.

    S = sum over B's boundary inside A of (area x outward normal of B) = -dV/dx_A; it
    points from B into A and |S| is the contact area. See :func:`overlap`.
    """
    r = overlap(*a.args(), *b.args())
    return r[0], np.array(r[1:4]), np.array(r[4:7])


def polyhedron_plane_overlap(a, normal, offset):
    """(V, centroid (3,), S (3,)) of a :class:`Placed` polyhedron and the wall half-space
    normal . x <= offset (normal: unit, into the domain). S = cross-section area x normal."""
    nrm = np.asarray(normal, dtype=np.float64)
    nrm = nrm / np.linalg.norm(nrm)
    r = plane_overlap(*a.args(), float(nrm[0]), float(nrm[1]), float(nrm[2]), float(offset))
    return r[0], np.array(r[1:4]), np.array(r[4:7])


__all__ = ["AREA_BLEND", "BOX_PAD", "PARALLEL_COS", "TOL_COORD", "TOL_REL", "Placed", "contact_frame", "overlap",
           "overlap_in_box", "overlap_ws", "place", "plane_overlap", "plane_overlap_ws", "plane_scratch",
           "polyhedron_overlap", "polyhedron_plane_overlap", "scratch", "to_world_planes", "to_world_vertices"]
