"""Measures of a sphere scene computed from its contacts (compiled, fixed summation order)."""

import numpy as np

from demcli.jit import njit
from demcli.kernels.walls import surface_distance


@njit
def contact_virial(pi, pj, act, fc, xs, rad, wstart, wwall, wfc, wkind, wpoint, wnormal, wradius, mesh, bstart, bj,
                   bfc):
    """Sum over every contact and bond of branch (x) force [N m], a (3, 3) tensor.

    Pairs and bonds add (x_i - x_j) (x) f_i, wall contacts (x_i - x_c) (x) f_i with x_c the
    contact point on the wall (a mesh wall: its nearest contact's). Divided by the volume it is the mean stress in the
    particles (Love-Weber; compression positive): sigma = (1/V) sum l (x) f.
    """
    s = np.zeros((3, 3))
    for c in range(pi.shape[0]):
        if act[c]:
            i = pi[c]
            j = pj[c]
            for a in range(3):
                for b in range(3):
                    s[a, b] += (xs[i, a] - xs[j, a]) * fc[c, b]
    for i in range(bstart.shape[0] - 1):
        for k in range(bstart[i], bstart[i + 1]):
            j = bj[k]
            for a in range(3):
                for b in range(3):
                    s[a, b] += (xs[i, a] - xs[j, a]) * bfc[k, b]
    for i in range(wstart.shape[0] - 1):
        for k in range(wstart[i], wstart[i + 1]):
            w = wwall[k]
            d, nx, ny, nz = surface_distance(wkind[w], wpoint[w, 0], wpoint[w, 1], wpoint[w, 2], wnormal[w, 0],
                                             wnormal[w, 1], wnormal[w, 2], wradius[w], xs[i, 0], xs[i, 1], xs[i, 2],
                                             mesh, w, rad[i])
            n = (nx, ny, nz)
            for a in range(3):
                for b in range(3):
                    s[a, b] += d * n[a] * wfc[k, b]
    return s
