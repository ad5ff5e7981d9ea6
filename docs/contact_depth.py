"""The contact depth of the volumetric law on real contacts (issue #31, item 5): the seed's
d = d1 + d2 against demcli's d = V / A_c.

    python docs/contact_depth.py [--steps N] [--out docs/ballast_figures]

Seed 002's eq. 17 is F_N = 4 E sqrt(V d) / (3 sqrt(pi)) with V the overlap volume and d = d1 + d2
"the depth of mutual penetration" (its Fig. 5): how far the two bodies reach into each other
along the contact normal, i.e. the extent of the overlap polytope along n. demcli's law
(:mod:`demcli.kernels.shapes.polyhedra`) takes d = V / A_c, the overlap volume over its contact
area |S|. The two agree for a slab-shaped overlap (two faces pressed flat: V = A d) and differ
by the overlap's shape: a vertex in a face leaves a pyramid (V = A d / 3), an edge in a face a
wedge (V = A d / 2), a sphere cap V / A = d / 2 (where eq. 17 with the full depth is Hertz's law
exactly, F = 4/3 E sqrt(R) d^(3/2) with V = pi R d^2).

The script takes the quickstart's settled bed at its peak sleeper load (the bed
``bench/bench_loaded_bed.py`` builds and caches in $DEMCLI_BENCH_CACHE), runs ``--steps``
steps, and for every touching pair rebuilds the overlap independently of demcli's clipping:
scipy's qhull intersection of both bodies' face half-spaces (interior point: the Chebyshev
centre by linear programming). Per pair it writes V, A_c, V / A_c, the extent w of the polytope
along demcli's normal S / |S|, and the ratio w / (V / A_c) to ``contact_depth.csv``, and a
histogram of the ratio to ``contact_depth.png``; it prints the percentiles, the qhull volume's
agreement with demcli's V, and the force ratio sqrt(w / (V / A_c)) that eq. 17 with the seed's d
would give at the same overlap.
"""

import argparse
import csv
import os
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import linprog
from scipy.spatial import ConvexHull, HalfspaceIntersection

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))


def polytope(a, b):
    """Vertices of the intersection of two placed convex polyhedra (qhull), None if it has no
    interior."""
    hs = np.vstack([np.hstack([p.normals, -np.asarray(p.offsets)[:, None]]) for p in (a, b)])
    norm = np.linalg.norm(hs[:, :3], axis=1)
    lp = linprog([0, 0, 0, -1], A_ub=np.hstack([hs[:, :3], norm[:, None]]), b_ub=-hs[:, 3],
                 bounds=[(None, None)] * 3 + [(0, None)])
    if not lp.success or lp.x[3] <= 0.0:
        return None
    return HalfspaceIntersection(hs, lp.x[:3]).intersections


def measure(system):
    """Rows (V, A_c, V / A_c, w, qhull V) of the touching pairs of a polyhedron system."""
    from demcli.kernels.polyhedra import polyhedron_overlap
    from demcli.stages.contact_record import _placed

    rows = []
    nl = system.nl
    for c in np.flatnonzero(nl.act):
        a, b = _placed(system, int(nl.pi[c])), _placed(system, int(nl.pj[c]))
        vol, _, area = polyhedron_overlap(a, b)
        verts = polytope(a, b) if vol > 0.0 else None
        if verts is None:
            continue
        area_c = float(np.linalg.norm(area))
        h = verts @ (area / area_c)
        rows.append((vol, area_c, vol / area_c, float(h.max() - h.min()), ConvexHull(verts).volume))
    return np.array(rows)


def figure(ratio, path):
    """Histogram of w / (V / A_c)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.6), dpi=200)
    ax.hist(ratio, bins=np.arange(0.875, 3.15, 0.05), color="0.35")  # bins centred on 1, 2, 3
    for k, label in ((1, "slab"), (2, "wedge"), (3, "pyramid")):
        ax.axvline(k, color="C1", lw=0.8, ls="--")
        ax.text(k, ax.get_ylim()[1] * 0.95, f" {label}", color="C1", fontsize=8, va="top")
    ax.set_xlabel("extent along the normal / (V / A$_c$)")
    ax.set_ylabel("touching pairs")
    ax.set_title(f"Quickstart bed at peak sleeper load: {len(ratio)} pairs", fontsize=9)
    fig.tight_layout()
    fig.savefig(path)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--steps", type=int, default=20, help="steps run from the cached bed first")
    ap.add_argument("--out", default=str(ROOT / "docs" / "ballast_figures"))
    a = ap.parse_args(argv)
    from bench_loaded_bed import loaded_state, loaded_system

    case = str(ROOT / "cases" / "quickstart.yaml")
    cache = Path(os.environ.get("DEMCLI_BENCH_CACHE", Path.home() / ".cache" / "demcli" / "bench"))
    system = loaded_system(case, loaded_state(case, cache / "quickstart"), 1)
    system.advance(a.steps)
    r = measure(system)
    vol, area, depth, width, vq = r.T
    ratio = width / depth
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "contact_depth.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["volume [m^3]", "area [m^2]", "V/A_c [m]", "extent along n [m]", "ratio [1]"])
        w.writerows(np.column_stack([vol, area, depth, width, ratio]).tolist())
    figure(ratio, out / "contact_depth.png")
    print(f"{len(r)} touching pairs; qhull V against demcli's V: largest relative difference "
          f"{np.max(np.abs(vq / vol - 1.0)):.1e}")
    print("extent / (V / A_c), percentiles 5 25 50 75 95:", np.round(np.percentile(ratio, [5, 25, 50, 75, 95]), 3))
    force = np.sqrt(vol * depth)
    print(f"force with the seed's d over demcli's: median {np.median(np.sqrt(ratio)):.3f}, "
          f"force-weighted {np.sum(np.sqrt(ratio) * force) / np.sum(force):.3f}")


if __name__ == "__main__":
    main()
