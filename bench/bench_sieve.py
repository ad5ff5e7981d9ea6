"""Throughput of sieve_size(method="projection") on prebuilt random convex polyhedra.

Polyhedra of 20-40 faces (hulls of 12-22 random points on ellipsoids with random
semi-axes) are built once with Qhull (not timed); the timed loop calls
``sieve_size(poly)`` on them (minimal shadow over all face-pair directions, shadow
hull, rotating calipers) on one core, after one JIT warm-up call. The last line is
``sieve_sizes_per_s=<number>``.

Usage: python bench/bench_sieve.py [n_polyhedra] [repeats]
"""

import sys
import time

import numpy as np

from demcli.geometry import random_polyhedron, sieve_size
from demcli.jit import set_threads


def main(n_poly=500, repeats=5):
    set_threads(1)
    rng = np.random.default_rng(2017)
    polys = []
    while len(polys) < n_poly:
        poly = random_polyhedron(rng, int(rng.integers(12, 23)), rng.uniform(0.01, 0.04, size=3))
        if 20 <= poly.n_faces <= 40:
            polys.append(poly)
    sieve_size(polys[0])  # JIT (or cache load)
    faces = [p.n_faces for p in polys]
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        for poly in polys:
            sieve_size(poly)
        best = min(best, time.perf_counter() - t0)
    rate = n_poly / best
    print(f"{n_poly} polyhedra, faces {min(faces)}-{max(faces)} (mean {np.mean(faces):.1f}), "
          f"best of {repeats}: {1e6 * best / n_poly:.1f} us per sieve size")
    print(f"sieve_sizes_per_s={rate:.0f}")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
