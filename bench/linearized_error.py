"""Accuracy of contact.geometry_refresh on the loaded bed: each linearized contact against the exact geometry.

Usage: python bench/linearized_error.py K [--steps N] [CASE]
  default CASE: cases/quickstart.yaml (the bed of bench_loaded_bed.py, built and cached the same way)

Runs the loaded bed with contact.geometry_refresh K for 200 steps, then N single steps; after each, every
touching pair that was linearized in that step (not evaluated exactly) is evaluated exactly at the same
configuration (:func:`demcli.kernels.polyhedra.overlap`) and compared with the linearized volume the step
used (:func:`demcli.kernels.shapes.polyhedra._linear_volume`). Prints, over all those evaluations, the
relative error of V and of the normal force F_N = k_n V / sqrt(A_c) (A_c = |S|: the kept S against the exact
one) as median, 95 % and 99 % quantiles and largest, the force-weighted error sum |dF_N| / sum F_N, and the
angle between the kept and the exact normal.
"""

import argparse
import sys
from pathlib import Path

import numba
import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_loaded_bed as B  # noqa: E402

from demcli.kernels.polyhedra import overlap  # noqa: E402
from demcli.kernels.shapes.polyhedra import L_LEFT, L_S, _linear_volume  # noqa: E402


@numba.njit
def _linearized(pbox, c, x, q, i, j):
    return _linear_volume(pbox, c, x, q, i, j)[0]


def _body(s, b):
    """The arguments of :func:`overlap` for body b of system s (world arrays)."""
    vs, _, fs, fvs, fv, _, _ = s.shapes
    wv, wn, wo, _ = s.world
    k = s.shape[b]
    return (wv[s.bvstart[b]:s.bvstart[b + 1]], fvs[fs[k]:fs[k + 1] + 1], fv, vs[k], wn[s.bfstart[b]:s.bfstart[b + 1]],
            wo[s.bfstart[b]:s.bfstart[b + 1]], s.x[b, 0], s.x[b, 1], s.x[b, 2], s.rad[b])


def errors(s, k, steps):
    """(relative V errors, relative F_N errors, normal angles [deg], force-weighted F_N error)."""
    ev, ef, ang, dsum, fsum = [], [], [], 0.0, 0.0
    for _ in range(steps):
        s.advance(1)  # one step: no fused drift, s.x is the configuration the pair pass saw
        nl = s.nl
        for c in np.nonzero(nl.act)[0]:
            if nl.pbox[c, L_LEFT] >= k - 1:  # evaluated exactly in this step
                continue
            i, j = nl.pi[c], nl.pj[c]
            vl = _linearized(nl.pbox, c, s.x, s.q, i, j)
            s0 = nl.pbox[c, L_S:L_S + 3]
            v, _, _, _, sx, sy, sz = overlap(*_body(s, i), *_body(s, j))
            s1 = np.array([sx, sy, sz])
            fl = vl / np.sqrt(np.linalg.norm(s0))
            fe = v / np.sqrt(np.linalg.norm(s1))
            ev.append(abs(vl - v) / v)
            ef.append(abs(fl - fe) / fe)
            dsum += abs(fl - fe)
            fsum += fe
            cos = s0 @ s1 / np.linalg.norm(s0) / np.linalg.norm(s1)
            ang.append(np.degrees(np.arccos(min(1.0, cos))))
    return np.array(ev), np.array(ef), np.array(ang), dsum / fsum


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("refresh", type=int)
    p.add_argument("case", nargs="?", default=str(HERE.parent / "cases" / "quickstart.yaml"))
    p.add_argument("--steps", type=int, default=48)
    a = p.parse_args(argv)
    cache = B.cache_folder(a.case)
    s = B.loaded_system(a.case, B.loaded_state(a.case, cache), 1, a.refresh)
    s.advance(200)
    ev, ef, ang, fw = errors(s, a.refresh, a.steps)

    def q(x):
        return " / ".join(f"{v:.2g}" for v in (np.median(x), np.percentile(x, 95), np.percentile(x, 99), x.max()))

    print(f"geometry refresh {a.refresh}: {len(ev)} linearized contact evaluations over {a.steps} steps; relative "
          f"error (median / 95 % / 99 % / largest) of V {q(ev)}, of F_N {q(ef)}; force-weighted F_N error {fw:.2g}; "
          f"normal {q(ang)} deg")


if __name__ == "__main__":
    main()
