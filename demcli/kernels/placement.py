"""Random sequential addition of non-overlapping spheres (grid-accelerated)."""

import math

import numpy as np

from demcli.jit import njit


@njit
def rsa_batch(cand, lo, size, radii, placed, n_placed, tries, max_tries, head, nxt, cell, ncell, cyl):
    """Place spheres from a batch of candidate points; returns (n_placed, tries, used).

    cand: (m, 3) uniform points in [0, 1)^3, mapped into the region shrunk by the radius.
    lo, size: region lower corner and extent (m); a zero extent keeps that coordinate.
    radii: (n,) radii in placement order (largest first); placed: (n, 3) output centres.
    head/nxt: per-cell linked lists of placed spheres; cell: grid spacing >= 2 r_max.
    cyl: (cx, cy, R): also keep the sphere inside this vertical cylinder (R <= 0: none).
    Gives up on a sphere after ``max_tries`` candidates (returns with tries > max_tries).
    """
    n = radii.shape[0]
    used = 0
    while used < cand.shape[0] and n_placed < n:
        r = radii[n_placed]
        p = np.empty(3)
        for d in range(3):
            span = size[d] - 2.0 * r
            p[d] = lo[d] + size[d] * 0.5 if size[d] == 0.0 else lo[d] + r + cand[used, d] * max(span, 0.0)
        used += 1
        tries += 1
        c = np.empty(3, np.int64)
        for d in range(3):
            c[d] = min(ncell[d] - 1, max(0, int((p[d] - lo[d]) / cell)))
        ok = True
        if cyl[2] > 0.0 and math.sqrt((p[0] - cyl[0]) ** 2 + (p[1] - cyl[1]) ** 2) + r > cyl[2]:
            ok = False
        for z in range(max(c[2] - 1, 0), min(c[2] + 2, ncell[2])):
            for y in range(max(c[1] - 1, 0), min(c[1] + 2, ncell[1])):
                for x in range(max(c[0] - 1, 0), min(c[0] + 2, ncell[0])):
                    k = head[x + ncell[0] * (y + ncell[1] * z)]
                    while k >= 0 and ok:
                        dd = 0.0
                        for d in range(3):
                            dd += (placed[k, d] - p[d]) ** 2
                        if dd < (r + radii[k]) ** 2:
                            ok = False
                        k = nxt[k]
        if ok:
            for d in range(3):
                placed[n_placed, d] = p[d]
            ci = c[0] + ncell[0] * (c[1] + ncell[1] * c[2])
            nxt[n_placed] = head[ci]
            head[ci] = n_placed
            n_placed += 1
            tries = 0
        elif tries > max_tries:
            break
    return n_placed, tries, used


def place_random(rng, lo, hi, radii, max_tries=20000, cylinder=None):
    """Centres for ``radii`` (placed largest first) in the box [lo, hi] without overlap.

    Returns (centres in the input order, number placed); fewer than requested when the
    region is too full for random sequential addition. ``cylinder`` = (cx, cy, R)
    restricts centres to a vertical cylinder inside the box.
    """
    cyl = np.array(cylinder if cylinder is not None else (0.0, 0.0, 0.0), float)
    radii = np.asarray(radii, float)
    order = np.argsort(-radii, kind="stable")
    rs = np.ascontiguousarray(radii[order])
    lo = np.asarray(lo, float)
    size = np.asarray(hi, float) - lo
    cell = max(2.0 * rs.max(), 1e-300)
    ncell = np.maximum(1, np.ceil(size / cell)).astype(np.int64)
    head = -np.ones(int(np.prod(ncell)), np.int64)
    nxt = -np.ones(len(rs), np.int64)
    placed = np.zeros((len(rs), 3))
    n_placed, tries = 0, 0
    while n_placed < len(rs):
        cand = rng.random((min(65536, 64 * (len(rs) - n_placed) + 1024), 3))
        n_placed, tries, _ = rsa_batch(cand, lo, size, rs, placed, n_placed, tries, max_tries, head, nxt,
                                       cell, ncell, cyl)
        if tries > max_tries:
            break
    out = np.full((len(rs), 3), math.nan)
    out[order[:n_placed]] = placed[:n_placed]
    return out, n_placed
