"""Numba kernels of the 2D section builder (seed 001): random convex polygons placed
without intersection, and hexagonal ball lattices labelled by polygon.

Stateless functions of arrays and scalars, no I/O; the public wrappers are in
:mod:`demcli.geometry.section2d`. Lengths in m, areas in m^2. Polygons are stored as
one vertex array with CSR offsets (``pstart[p]:pstart[p + 1]``), counter-clockwise.

Placement (the patent's step 1, CN 2022 "intersection check and convex optimisation",
steps 1.2-1.9): a random centre in the specimen, a vertex count m in [m_lo, m_hi],
polar angles advancing by 2 pi/m (1 + delta (2 lambda - 1)), polar radii in the
class's half-size range, the convex hull by Graham's scan (the patent's steps a-f),
and rejection of a hull that leaves the specimen or intersects a placed polygon. The
intersection test is the separating-axis test over the edge normals of both convex
polygons (exact: two convex polygons are disjoint iff one of their edge normals
separates them), after a uniform-grid broad phase on bounding boxes. The conservative
alternative (``TEST_CIRCLE``) rejects whenever the bounding circles overlap.
"""

import math

import numpy as np

from demcli.jit import njit

CIRCLE = 0
RECTANGLE = 1

TEST_EXACT = 0
TEST_CIRCLE = 1

PLACED = 0
GAVE_UP = 1

SHAPE_REDRAWS = 20000
"""Redraws allowed for a class-finishing polygon whose scaled radii leave the class."""


# ---------------------------------------------------------------------------------------
# one polygon
# ---------------------------------------------------------------------------------------
@njit
def graham_scan(px, py, n, hx, hy):
    """Convex hull of ``n`` points by Graham's scan (Graham 1972), as the patent states it.

    The lowest point (then leftmost) starts the hull; the others are sorted by polar
    angle about it (ties within 1e-12 rad: nearer first) and pushed in turn, popping the
    last hull point while it does not make a strict left turn (also towards p0 at the
    end). px, py: (>= n,) coordinates; hx, hy: (>= n,) output, counter-clockwise.
    Returns the hull size h (< 3: degenerate). Collinear (to a relative 1e-12) and
    repeated points are dropped.
    """
    k0 = 0
    for i in range(1, n):
        if py[i] < py[k0] or (py[i] == py[k0] and px[i] < px[k0]):
            k0 = i
    x0 = px[k0]
    y0 = py[k0]
    m = 0
    idx = np.empty(n, np.int64)
    ang = np.empty(n)
    dist = np.empty(n)
    for i in range(n):
        dx = px[i] - x0
        dy = py[i] - y0
        if dx == 0.0 and dy == 0.0:
            continue
        a = math.atan2(dy, dx)
        d = dx * dx + dy * dy
        j = m  # insertion sort by (angle, distance); n <= a few dozen
        while j > 0 and (ang[j - 1] > a + 1e-12
                         or (abs(ang[j - 1] - a) <= 1e-12 and dist[j - 1] > d)):
            idx[j] = idx[j - 1]
            ang[j] = ang[j - 1]
            dist[j] = dist[j - 1]
            j -= 1
        idx[j] = i
        ang[j] = a
        dist[j] = d
        m += 1
    hx[0] = x0
    hy[0] = y0
    h = 1
    for t in range(m + 1):
        if t < m:
            cx = px[idx[t]]
            cy = py[idx[t]]
        else:  # close the loop: the last hull points must turn left into p0 too
            cx = x0
            cy = y0
        while h >= 2:
            ax = hx[h - 1] - hx[h - 2]
            ay = hy[h - 1] - hy[h - 2]
            bx = cx - hx[h - 2]
            by = cy - hy[h - 2]
            # pop unless a strict left turn (relative tolerance drops round-off collinear points)
            if ax * by - ay * bx > 1e-12 * math.sqrt((ax * ax + ay * ay) * (bx * bx + by * by)):
                break
            h -= 1
        if t < m:
            hx[h] = cx
            hy[h] = cy
            h += 1
    return h


@njit
def shoelace(x, y, n):
    """(area, centroid x, centroid y) of a simple counter-clockwise polygon (Green's theorem)."""
    a2 = 0.0
    sx = 0.0
    sy = 0.0
    for i in range(n):
        j = i + 1 if i + 1 < n else 0
        c = x[i] * y[j] - x[j] * y[i]
        a2 += c
        sx += (x[i] + x[j]) * c
        sy += (y[i] + y[j]) * c
    if a2 == 0.0:
        return 0.0, 0.0, 0.0
    return 0.5 * a2, sx / (3.0 * a2), sy / (3.0 * a2)


@njit
def draw_shape(rng, m_lo, m_hi, delta, r_lo, r_hi, px, py, hx, hy):
    """A random convex polygon around the origin; returns (hull size, area).

    m in [m_lo, m_hi]; theta_i = theta_{i-1} + (2 pi / m)(1 + delta (2 lambda - 1)) from a
    random phase; r_i uniform in [r_lo, r_hi]; then the Graham hull into hx, hy.
    Redraws degenerate hulls.
    """
    while True:
        m = rng.integers(m_lo, m_hi + 1)
        step = 2.0 * math.pi / m
        theta = 2.0 * math.pi * rng.random()
        for i in range(m):
            theta += step * (1.0 + delta * (2.0 * rng.random() - 1.0))
            r = r_lo + (r_hi - r_lo) * rng.random()
            px[i] = r * math.cos(theta)
            py[i] = r * math.sin(theta)
        h = graham_scan(px, py, m, hx, hy)
        if h >= 3:
            a, _, _ = shoelace(hx, hy, h)
            if a > 0.0:
                return h, a


@njit
def area_quantiles(rng, m_lo, m_hi, delta, r_lo, r_hi, nsample, q_lo, q_hi):
    """(q_lo, median, q_hi) quantiles of the area of ``nsample`` shapes drawn by draw_shape."""
    px = np.empty(m_hi)
    py = np.empty(m_hi)
    hx = np.empty(m_hi)
    hy = np.empty(m_hi)
    areas = np.empty(nsample)
    for k in range(nsample):
        _, areas[k] = draw_shape(rng, m_lo, m_hi, delta, r_lo, r_hi, px, py, hx, hy)
    areas.sort()
    last = nsample - 1
    return (areas[int(q_lo * last)], areas[int(0.5 * last)], areas[int(q_hi * last)])


# ---------------------------------------------------------------------------------------
# pair tests
# ---------------------------------------------------------------------------------------
@njit
def _edge_separates(ax, ay, bx, by, gap):
    """True if an edge line of convex CCW polygon A has all of B at least ``gap`` outside."""
    na = ax.shape[0]
    nb = bx.shape[0]
    for i in range(na):
        j = i + 1 if i + 1 < na else 0
        nx = ay[j] - ay[i]  # outward normal of a CCW edge (unnormalised)
        ny = ax[i] - ax[j]
        lim = nx * ax[i] + ny * ay[i] + gap * math.sqrt(nx * nx + ny * ny)
        sep = True
        for k in range(nb):
            if nx * bx[k] + ny * by[k] < lim:
                sep = False
                break
        if sep:
            return True
    return False


@njit
def convex_polygons_overlap(ax, ay, bx, by, gap):
    """Separating-axis test of two convex CCW polygons.

    True when no edge normal of either polygon separates them by ``gap`` or more, i.e.
    (gap = 0) when their interiors intersect; touching polygons do not overlap.
    """
    return not (_edge_separates(ax, ay, bx, by, gap) or _edge_separates(bx, by, ax, ay, gap))


@njit
def _inside_specimen(kind, sa, sb, hx, hy, h, cx, cy, rb, test, gap):
    if test == TEST_CIRCLE:
        if kind == CIRCLE:
            return math.sqrt(cx * cx + cy * cy) + rb <= sa - gap
        return (abs(cx) + rb <= 0.5 * sa - gap) and (abs(cy) + rb <= 0.5 * sb - gap)
    if kind == CIRCLE:
        lim = (sa - gap) * (sa - gap)
        for i in range(h):
            x = cx + hx[i]
            y = cy + hy[i]
            if x * x + y * y > lim:
                return False
        return True
    for i in range(h):
        if abs(cx + hx[i]) > 0.5 * sa - gap or abs(cy + hy[i]) > 0.5 * sb - gap:
            return False
    return True


@njit
def _grow_f(a, n):
    b = np.empty(n, a.dtype)
    b[:a.shape[0]] = a
    return b


@njit
def _grow_f2(a, n):
    b = np.empty((n, a.shape[1]), a.dtype)
    b[:a.shape[0]] = a
    return b


@njit
def _feasible(y, tol, a_lo, a_hi):
    """Can a remainder y be made of whole polygons with areas in [a_lo, a_hi]?"""
    if y <= tol:
        return True
    k = math.ceil(y / a_hi)
    return k * a_lo <= y


# ---------------------------------------------------------------------------------------
# placement
# ---------------------------------------------------------------------------------------
@njit
def place_polygons(rng, kind, sa, sb, r_lo, r_hi, target, order, m_lo, m_hi, delta, gap, test,
                   max_tries, cell, nsample, q_lo, q_hi, cap_p):
    """Place convex polygons class by class until each class's target area is reached.

    kind, sa, sb: specimen (CIRCLE: radius sa; RECTANGLE: width sa, height sb), centred
    at the origin. r_lo, r_hi, target: (n_class,) polar-radius range [m] and target area
    [m^2] of each class; order: class indices in placement order (largest first).
    m_lo, m_hi: vertex count range; delta: angle fluctuation in [0, 1); gap: clearance
    [m] between polygons and to the boundary; test: TEST_EXACT or TEST_CIRCLE;
    max_tries: consecutive failed placements before giving up; cell: broad-phase grid
    spacing [m]; nsample, q_lo, q_hi: area quantiles of each class; cap_p: initial
    polygon capacity.

    Each polygon is drawn as in :func:`draw_shape`. It is kept with its own area when
    the rest of the class can still be made of whole in-class polygons (areas between
    the q_lo and q_hi quantiles); otherwise it is scaled to rest / k, with k chosen so
    that rest / k lies in that range nearest the median, and redrawn until its scaled
    radii stay in the class. So each class ends on its target area.

    Returns (status, class_failed, n_poly, pstart, vx, vy, pcls, parea, pcent, placed,
    tries, accepted, out_of_class, quantiles (n_class, 3)).
    """
    ncls = r_lo.shape[0]
    mcap = m_hi
    px = np.empty(mcap)
    py = np.empty(mcap)
    hx = np.empty(mcap)
    hy = np.empty(mcap)
    if kind == CIRCLE:
        half_w = sa
        half_h = sa
    else:
        half_w = 0.5 * sa
        half_h = 0.5 * sb
    nxc = max(1, int(math.ceil(2.0 * half_w / cell)))
    nyc = max(1, int(math.ceil(2.0 * half_h / cell)))
    head = np.full(nxc * nyc, -1, np.int64)
    cap_e = 16 * cap_p
    enext = np.empty(cap_e, np.int64)
    epoly = np.empty(cap_e, np.int64)
    ne = 0
    cap_v = mcap * cap_p
    vx = np.empty(cap_v)
    vy = np.empty(cap_v)
    pstart = np.zeros(cap_p + 1, np.int64)
    pcls = np.empty(cap_p, np.int64)
    parea = np.empty(cap_p)
    pcent = np.empty((cap_p, 2))
    pc = np.empty((cap_p, 3))  # generating centre and bounding radius
    box = np.empty((cap_p, 4))
    stamp = np.full(cap_p, -1, np.int64)
    placed = np.zeros(ncls)
    tries = np.zeros(ncls, np.int64)
    accepted = np.zeros(ncls, np.int64)
    out_of_class = np.zeros(ncls, np.int64)
    quant = np.zeros((ncls, 3))
    n = 0
    nv = 0
    query = 0
    for oc in range(order.shape[0]):
        c = order[oc]
        tgt = target[c]
        if tgt <= 0.0:
            continue
        rlo = r_lo[c]
        rhi = r_hi[c]
        a_lo, a_mid, a_hi = area_quantiles(rng, m_lo, m_hi, delta, rlo, rhi, nsample, q_lo, q_hi)
        quant[c, 0] = a_lo
        quant[c, 1] = a_mid
        quant[c, 2] = a_hi
        tol = 1e-9 * tgt
        fails = 0
        redraws = 0
        while tgt - placed[c] > tol:
            rest = tgt - placed[c]
            h, area = draw_shape(rng, m_lo, m_hi, delta, rlo, rhi, px, py, hx, hy)
            if not (area <= rest and _feasible(rest - area, tol, a_lo, a_hi)):
                # finish the class: scale this shape to rest / k
                k_min = max(1, int(math.ceil(rest / a_hi)))
                k_max = int(math.floor(rest / a_lo))
                k = int(round(rest / a_mid))
                k = min(max(k, k_min), max(k_max, k_min))
                want = rest / k
                s = math.sqrt(want / area)
                rmin = 1e300
                rmax = 0.0
                for i in range(h):
                    rr = math.sqrt(hx[i] * hx[i] + hy[i] * hy[i]) * s
                    rmin = min(rmin, rr)
                    rmax = max(rmax, rr)
                if rmin < rlo * (1.0 - 1e-12) or rmax > rhi * (1.0 + 1e-12):
                    redraws += 1
                    if redraws < SHAPE_REDRAWS:
                        continue
                    out_of_class[c] += 1  # the target cannot be met in class: keep the scaled shape
                redraws = 0
                for i in range(h):
                    hx[i] *= s
                    hy[i] *= s
                area, _, _ = shoelace(hx, hy, h)
            # a random centre in the specimen
            if kind == CIRCLE:
                rr = sa * math.sqrt(rng.random())
                tt = 2.0 * math.pi * rng.random()
                cx = rr * math.cos(tt)
                cy = rr * math.sin(tt)
            else:
                cx = (rng.random() - 0.5) * sa
                cy = (rng.random() - 0.5) * sb
            tries[c] += 1
            rb = 0.0
            xmin = 1e300
            xmax = -1e300
            ymin = 1e300
            ymax = -1e300
            for i in range(h):
                rb = max(rb, hx[i] * hx[i] + hy[i] * hy[i])
                xmin = min(xmin, cx + hx[i])
                xmax = max(xmax, cx + hx[i])
                ymin = min(ymin, cy + hy[i])
                ymax = max(ymax, cy + hy[i])
            rb = math.sqrt(rb)
            ok = _inside_specimen(kind, sa, sb, hx, hy, h, cx, cy, rb, test, gap)
            if ok:
                # broad phase: grid cells under the (gap-expanded) box, each placed polygon once
                if test == TEST_CIRCLE:
                    qx0, qx1, qy0, qy1 = cx - rb - gap, cx + rb + gap, cy - rb - gap, cy + rb + gap
                else:
                    qx0, qx1, qy0, qy1 = xmin - gap, xmax + gap, ymin - gap, ymax + gap
                i0 = min(nxc - 1, max(0, int((qx0 + half_w) / cell)))
                i1 = min(nxc - 1, max(0, int((qx1 + half_w) / cell)))
                j0 = min(nyc - 1, max(0, int((qy0 + half_h) / cell)))
                j1 = min(nyc - 1, max(0, int((qy1 + half_h) / cell)))
                query += 1
                for jj in range(j0, j1 + 1):
                    if not ok:
                        break
                    for ii in range(i0, i1 + 1):
                        e = head[ii + nxc * jj]
                        while e >= 0:
                            p = epoly[e]
                            e = enext[e]
                            if stamp[p] == query:
                                continue
                            stamp[p] = query
                            if test == TEST_CIRCLE:
                                dx = pc[p, 0] - cx
                                dy = pc[p, 1] - cy
                                lim = pc[p, 2] + rb + gap
                                if dx * dx + dy * dy < lim * lim:
                                    ok = False
                                    break
                                continue
                            if box[p, 0] > qx1 or box[p, 1] < qx0 or box[p, 2] > qy1 or box[p, 3] < qy0:
                                continue
                            s0 = pstart[p]
                            s1 = pstart[p + 1]
                            for i in range(h):
                                px[i] = cx + hx[i]
                                py[i] = cy + hy[i]
                            if convex_polygons_overlap(px[:h], py[:h], vx[s0:s1], vy[s0:s1], gap):
                                ok = False
                                break
                        if not ok:
                            break
            if not ok:
                fails += 1
                if fails > max_tries:
                    return (GAVE_UP, c, n, pstart[:n + 1].copy(), vx[:nv].copy(), vy[:nv].copy(),
                            pcls[:n].copy(), parea[:n].copy(), pcent[:n].copy(), placed, tries, accepted,
                            out_of_class, quant)
                continue
            # accept: store the polygon and register it in the grid
            fails = 0
            if n + 1 > pcls.shape[0]:
                newcap = 2 * pcls.shape[0]
                pstart = _grow_f(pstart, newcap + 1)
                pcls = _grow_f(pcls, newcap)
                parea = _grow_f(parea, newcap)
                pcent = _grow_f2(pcent, newcap)
                pc = _grow_f2(pc, newcap)
                box = _grow_f2(box, newcap)
                st = np.full(newcap, -1, np.int64)
                st[:stamp.shape[0]] = stamp
                stamp = st
            if nv + h > vx.shape[0]:
                vx = _grow_f(vx, 2 * vx.shape[0] + h)
                vy = _grow_f(vy, 2 * vy.shape[0] + h)
            for i in range(h):
                vx[nv + i] = cx + hx[i]
                vy[nv + i] = cy + hy[i]
            a, gx, gy = shoelace(hx, hy, h)
            nv += h
            pstart[n + 1] = nv
            pcls[n] = c
            parea[n] = a
            pcent[n, 0] = cx + gx
            pcent[n, 1] = cy + gy
            pc[n, 0] = cx
            pc[n, 1] = cy
            pc[n, 2] = rb
            box[n, 0] = xmin
            box[n, 1] = xmax
            box[n, 2] = ymin
            box[n, 3] = ymax
            if test == TEST_CIRCLE:
                xmin, xmax, ymin, ymax = cx - rb, cx + rb, cy - rb, cy + rb
            i0 = min(nxc - 1, max(0, int((xmin + half_w) / cell)))
            i1 = min(nxc - 1, max(0, int((xmax + half_w) / cell)))
            j0 = min(nyc - 1, max(0, int((ymin + half_h) / cell)))
            j1 = min(nyc - 1, max(0, int((ymax + half_h) / cell)))
            need = ne + (i1 - i0 + 1) * (j1 - j0 + 1)
            if need > enext.shape[0]:
                enext = _grow_f(enext, 2 * need)
                epoly = _grow_f(epoly, 2 * need)
            for jj in range(j0, j1 + 1):
                for ii in range(i0, i1 + 1):
                    cidx = ii + nxc * jj
                    epoly[ne] = n
                    enext[ne] = head[cidx]
                    head[cidx] = ne
                    ne += 1
            n += 1
            placed[c] += a
            accepted[c] += 1
    return (PLACED, -1, n, pstart[:n + 1].copy(), vx[:nv].copy(), vy[:nv].copy(), pcls[:n].copy(),
            parea[:n].copy(), pcent[:n].copy(), placed, tries, accepted, out_of_class, quant)


# ---------------------------------------------------------------------------------------
# lattice labelling
# ---------------------------------------------------------------------------------------
@njit
def label_lattice(pstart, vx, vy, grid, x_off, y_off, r, margin):
    """Polygon index of every lattice ball whose centre lies inside a polygon (else -1).

    grid: (n_row, n_col) ball index of each lattice site (-1: no ball there); site
    (j, i) is at (x_off + (2 i + j % 2) r, y_off + j sqrt(3) r). A centre belongs to a
    polygon when its distance inside every edge is >= margin (0: centre inside; r: the
    whole ball inside). Polygons do not overlap; a centre on a shared edge goes to the
    first polygon. Returns (n_ball,) int64.
    """
    nball = 0
    for j in range(grid.shape[0]):
        for i in range(grid.shape[1]):
            if grid[j, i] >= 0:
                nball += 1
    label = np.full(nball, -1, np.int64)
    dy_row = math.sqrt(3.0) * r
    for p in range(pstart.shape[0] - 1):
        s0 = pstart[p]
        s1 = pstart[p + 1]
        xmin = vx[s0:s1].min()
        xmax = vx[s0:s1].max()
        ymin = vy[s0:s1].min()
        ymax = vy[s0:s1].max()
        j0 = max(0, int(math.ceil((ymin - y_off) / dy_row)))
        j1 = min(grid.shape[0] - 1, int(math.floor((ymax - y_off) / dy_row)))
        for j in range(j0, j1 + 1):
            par = j % 2
            y = y_off + j * dy_row
            i0 = max(0, int(math.ceil(((xmin - x_off) / r - par) / 2.0)))
            i1 = min(grid.shape[1] - 1, int(math.floor(((xmax - x_off) / r - par) / 2.0)))
            for i in range(i0, i1 + 1):
                b = grid[j, i]
                if b < 0 or label[b] >= 0:
                    continue
                x = x_off + (2 * i + par) * r
                inside = True
                for k in range(s0, s1):
                    k2 = k + 1 if k + 1 < s1 else s0
                    ex = vx[k2] - vx[k]
                    ey = vy[k2] - vy[k]
                    # signed distance of (x, y) to the left of edge k (inside for CCW)
                    d = (ex * (y - vy[k]) - ey * (x - vx[k])) / math.sqrt(ex * ex + ey * ey)
                    if d < margin:
                        inside = False
                        break
                if inside:
                    label[b] = p
    return label
