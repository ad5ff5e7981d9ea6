"""Verlet neighbour lists built on a cell grid, with contact history carried over.

A pair list holds every sphere pair (i < j, different bodies) whose surfaces are
closer than ``skin``. Pairs are stored in CSR form by i (``start``), and inside each
row sorted by j. Sorting makes the list canonical: the force sums built from it do
not depend on when the list was rebuilt, so a resumed run and an uninterrupted one
give bit-identical results. ``rstart``/``rlist`` give, for each sphere, the pairs in
which it is the second member (in increasing pair order), for the per-sphere gather.

The wall list holds (sphere, wall) pairs closer than ``skin``, CSR by sphere, sorted
by wall.
"""

import math

import numpy as np
from numba import prange

from demcli.jit import njit
from demcli.kernels.periodic import grid_cells, grid_origin, min_image, window, wrap_index
from demcli.kernels.walls import surface_distance, wall_distance


@njit
def _grid(xs, rad, skin, max_cells, cell):
    """Bounds and cell counts of a grid whose cells are at least 2 r_max + skin wide (over the
    points' box, or over the periodic ``cell``: :mod:`demcli.kernels.periodic`)."""
    n = xs.shape[0]
    lo = np.empty(3)
    hi = np.empty(3)
    for d in range(3):
        lo[d] = math.inf
        hi[d] = -math.inf
    rmax = 0.0
    for i in range(n):
        for d in range(3):
            v = xs[i, d]
            if math.isfinite(v):  # non-finite points are binned at an edge; the guards report them
                if v < lo[d]:
                    lo[d] = v
                if v > hi[d]:
                    hi[d] = v
        if rad[i] > rmax:
            rmax = rad[i]
    for d in range(3):
        if lo[d] > hi[d]:
            lo[d] = 0.0
            hi[d] = 0.0
    grid_origin(cell, lo)
    h = 2.0 * rmax + skin
    nc = np.empty(3, np.int64)
    while True:  # counts in floating point: far-flung or non-finite points cannot overflow them
        tot = 1.0
        for d in range(3):
            tot *= grid_cells(cell, d, lo, hi, h)
        if tot <= max_cells:
            break
        h *= 1.26
    for d in range(3):
        nc[d] = int(grid_cells(cell, d, lo, hi, h))
    return lo, 1.0 / h, nc


@njit(inline="always")
def _coord(x, lo, inv_h, n):
    """Cell coordinate, clamped to the grid; NaN and far-away points land in an edge cell
    (memory-safe; the guards report them)."""
    t = (x - lo) * inv_h
    if not t > 0.0:
        return 0
    if t >= n - 1:
        return n - 1
    return int(t)


@njit(inline="always")
def _cell(x, y, z, lo, inv_h, nc):
    return _coord(x, lo[0], inv_h, nc[0]) + nc[0] * (_coord(y, lo[1], inv_h, nc[1])
                                                   + nc[1] * _coord(z, lo[2], inv_h, nc[2]))


@njit
def _bin(xs, lo, inv_h, nc):
    """Counting sort of spheres into cells: (cell_start, cell_items)."""
    n = xs.shape[0]
    ncell = nc[0] * nc[1] * nc[2]
    cell_of = np.empty(n, np.int64)
    cnt = np.zeros(ncell + 1, np.int64)
    for i in range(n):
        c = _cell(xs[i, 0], xs[i, 1], xs[i, 2], lo, inv_h, nc)
        cell_of[i] = c
        cnt[c + 1] += 1
    for c in range(ncell):
        cnt[c + 1] += cnt[c]
    items = np.empty(n, np.int64)
    fill = cnt[:-1].copy()
    for i in range(n):
        c = cell_of[i]
        items[fill[c]] = i
        fill[c] += 1
    return cnt, items


@njit(parallel=True, internal=True)
def _scan_pairs(xs, rad, body, skin, lo, inv_h, nc, cell_start, items, start, pj, fill, cell):
    """Count (fill=False) or write (fill=True) the j > i neighbours of every sphere (minimum
    image and wrapped neighbour cells in a periodic ``cell``)."""
    n = xs.shape[0]
    for i in prange(n):
        xi = xs[i, 0]
        yi = xs[i, 1]
        zi = xs[i, 2]
        ri = rad[i] + skin
        bi = body[i]
        cx = _coord(xi, lo[0], inv_h, nc[0])
        cy = _coord(yi, lo[1], inv_h, nc[1])
        cz = _coord(zi, lo[2], inv_h, nc[2])
        k = start[i] if fill else 0
        z0, z1 = window(cz, nc[2], cell)
        y0, y1 = window(cy, nc[1], cell)
        x0, x1 = window(cx, nc[0], cell)
        for zk in range(z0, z1):
            zz = wrap_index(zk, nc[2], cell)
            for yk in range(y0, y1):
                yy = wrap_index(yk, nc[1], cell)
                for xk in range(x0, x1):
                    c = wrap_index(xk, nc[0], cell) + nc[0] * (yy + nc[1] * zz)
                    for a in range(cell_start[c], cell_start[c + 1]):
                        j = items[a]
                        if j <= i or body[j] == bi:
                            continue
                        dx, dy, dz = min_image(cell, xs[j, 0] - xi, xs[j, 1] - yi, xs[j, 2] - zi)
                        cut = ri + rad[j]
                        if dx * dx + dy * dy + dz * dz < cut * cut:
                            if fill:
                                pj[k] = j
                            k += 1
        if fill:
            # insertion sort of the row by j: canonical order
            s0 = start[i]
            for a in range(s0 + 1, k):
                v = pj[a]
                b = a - 1
                while b >= s0 and pj[b] > v:
                    pj[b + 1] = pj[b]
                    b -= 1
                pj[b + 1] = v
        else:
            start[i + 1] = k


@njit
def build_pairs(xs, rad, body, skin, max_cells, cell):
    """Verlet pair list: (start (n+1,), pi (P,), pj (P,)) in canonical order; ``cell``: the
    periodic cell (positions in it, :mod:`demcli.kernels.periodic`) or None."""
    n = xs.shape[0]
    start = np.zeros(n + 1, np.int64)
    if n == 0:
        return start, np.empty(0, np.int64), np.empty(0, np.int64)
    lo, inv_h, nc = _grid(xs, rad, skin, max_cells, cell)
    cell_start, items = _bin(xs, lo, inv_h, nc)
    dummy = np.empty(0, np.int64)
    # np.bool_: a typed flag, not a literal, so that both passes share one compiled scan
    _scan_pairs(xs, rad, body, skin, lo, inv_h, nc, cell_start, items, start, dummy, np.bool_(False),
                cell)
    for i in range(n):
        start[i + 1] += start[i]
    npair = start[n]
    pj = np.empty(npair, np.int64)
    _scan_pairs(xs, rad, body, skin, lo, inv_h, nc, cell_start, items, start, pj, np.bool_(True), cell)
    pi = np.empty(npair, np.int64)
    for i in range(n):
        for c in range(start[i], start[i + 1]):
            pi[c] = i
    return start, pi, pj


@njit
def build_reverse(n, pj):
    """For each sphere, the pairs in which it is j: (rstart (n+1,), rlist (P,))."""
    rstart = np.zeros(n + 1, np.int64)
    for c in range(pj.shape[0]):
        rstart[pj[c] + 1] += 1
    for i in range(n):
        rstart[i + 1] += rstart[i]
    fill = rstart[:-1].copy()
    rlist = np.empty(pj.shape[0], np.int64)
    for c in range(pj.shape[0]):
        j = pj[c]
        rlist[fill[j]] = c
        fill[j] += 1
    return rstart, rlist


@njit(parallel=True, internal=True)
def carry_history(n, start_new, key_new, start_old, key_old, hist_old, hist_new):
    """Copy history rows of pairs present in both lists (rows sorted by key); zero others."""
    if hist_old.shape[0] == 0 and hist_new.shape[0] == 0:
        return
    for i in prange(n):
        a = start_old[i]
        a1 = start_old[i + 1]
        for c in range(start_new[i], start_new[i + 1]):
            key = key_new[c]
            while a < a1 and key_old[a] < key:
                a += 1
            if a < a1 and key_old[a] == key:
                for d in range(hist_new.shape[1]):
                    hist_new[c, d] = hist_old[a, d]
            else:
                for d in range(hist_new.shape[1]):
                    hist_new[c, d] = 0.0


@njit(parallel=True, internal=True)
def _scan_walls(xs, rad, skin, wkind, wpoint, wnormal, wradius, mesh, start, wall, fill):
    n = xs.shape[0]
    nw = wkind.shape[0]
    for i in prange(n):
        k = start[i] if fill else 0
        for w in range(nw):
            if mesh is None:  # no mesh wall: the mesh path is not compiled (kernels/switch.py)
                s, _, _, _ = wall_distance(wkind[w], wpoint[w, 0], wpoint[w, 1], wpoint[w, 2], wnormal[w, 0],
                                           wnormal[w, 1], wnormal[w, 2], wradius[w], xs[i, 0], xs[i, 1], xs[i, 2])
            else:
                s, _, _, _ = surface_distance(wkind[w], wpoint[w, 0], wpoint[w, 1], wpoint[w, 2], wnormal[w, 0],
                                              wnormal[w, 1], wnormal[w, 2], wradius[w], xs[i, 0], xs[i, 1], xs[i, 2],
                                              mesh, w, rad[i] + skin)
            if s < rad[i] + skin:
                if fill:
                    wall[k] = w
                k += 1
        if not fill:
            start[i + 1] = k


@njit(internal=True)
def build_wall_pairs(xs, rad, skin, wkind, wpoint, wnormal, wradius, mesh):
    """Sphere-wall list: (wstart (n+1,), wsphere (Q,), wwall (Q,)), sorted by sphere then wall;
    ``mesh``: the MeshArrays of the mesh walls (a sphere within skin of any of its triangles is listed)."""
    n = xs.shape[0]
    start = np.zeros(n + 1, np.int64)
    dummy = np.empty(0, np.int64)
    # np.bool_: a typed flag, not a literal, so that both passes share one compiled scan
    _scan_walls(xs, rad, skin, wkind, wpoint, wnormal, wradius, mesh, start, dummy, np.bool_(False))
    for i in range(n):
        start[i + 1] += start[i]
    wall = np.empty(start[n], np.int64)
    _scan_walls(xs, rad, skin, wkind, wpoint, wnormal, wradius, mesh, start, wall, np.bool_(True))
    sph = np.empty(start[n], np.int64)
    for i in range(n):
        for c in range(start[i], start[i + 1]):
            sph[c] = i
    return start, sph, wall


@njit
def add_actor_pairs(start, pj, x, rad, body, nsmall, skin):
    """Pair list of all primitives from the cell-grid list of the first ``nsmall`` ones.

    Primitives nsmall.. belong to actors (a loading plate, a sleeper): far larger than the
    particles, so they stay out of the cell grid (whose cells follow the largest
    radius) and are paired here with every primitive of another body (``body``: the body of
    each) whose sphere comes within ``skin`` of theirs. Rows stay sorted by j (actors have the
    highest indices). Returns (start, pi, pj) over all primitives.
    """
    nb = x.shape[0]
    cnt = np.zeros(nb, np.int64)
    for i in range(nb):
        if i < nsmall:
            cnt[i] = start[i + 1] - start[i]
        for a in range(max(i + 1, nsmall), nb):
            r = rad[i] + rad[a] + skin
            if body[i] != body[a] and (x[i, 0] - x[a, 0]) ** 2 + (x[i, 1] - x[a, 1]) ** 2 + (x[i, 2] - x[a, 2]) ** 2 < r * r:
                cnt[i] += 1
    nstart = np.zeros(nb + 1, np.int64)
    for i in range(nb):
        nstart[i + 1] = nstart[i] + cnt[i]
    npi = np.empty(nstart[nb], np.int64)
    npj = np.empty(nstart[nb], np.int64)
    for i in range(nb):
        k = nstart[i]
        if i < nsmall:
            for c in range(start[i], start[i + 1]):
                npi[k] = i
                npj[k] = pj[c]
                k += 1
        for a in range(max(i + 1, nsmall), nb):
            r = rad[i] + rad[a] + skin
            if body[i] != body[a] and (x[i, 0] - x[a, 0]) ** 2 + (x[i, 1] - x[a, 1]) ** 2 + (x[i, 2] - x[a, 2]) ** 2 < r * r:
                npi[k] = i
                npj[k] = a
                k += 1
    return nstart, npi, npj
