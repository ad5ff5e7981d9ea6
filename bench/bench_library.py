"""Throughput of ballast-library generation with sizing: particles per second.

Builds a library of the seed-002 classes (16-25, 25-35.5, 35.5-45, 45-56, 56-63,
63-75 mm) with the default Voronoi shapes, in memory (no file): per particle one
random Voronoi cell (seeds, dual hull, vertex merge, stretch, Qhull hull and face
merge), its projection sieve size, shape indices and principal frame. One warm-up
build of a few particles (JIT cache load) is not timed; worker processes, when
asked for, are started inside the timed region (their start-up is part of the cost).
The last line is ``library_particles_per_s=<number>``.

Usage: python bench/bench_library.py [n_particles] [workers]   (defaults 10000, 2)
       python bench/bench_library.py --quick                   (600 particles, 1 worker)
Target (issue 4): 10 000 particles in under a minute on 2 cores.
"""

import sys
import time

from demcli.stages.ballast.library import build_library

CLASSES = [[0.016, 0.025], [0.025, 0.0355], [0.0355, 0.045], [0.045, 0.056], [0.056, 0.063], [0.063, 0.075]]


def generator(n_total, seed=2017):
    per_class = max(1, n_total // len(CLASSES))
    return {"format": "demcli ballast library", "version": 1, "seed": seed, "per_class": per_class,
            "shape": {"method": "voronoi", "faces": {"min": 8, "max": 30}, "elongation": {"min": 0.55, "max": 0.95},
                      "flatness": {"min": 0.5, "max": 0.95}, "regularity": 0.5, "min_edge": 0.05},
            "sieve_method": "projection", "flaky_ratio": 0.6, "elongated_ratio": 1.8, "classes": CLASSES}


def main(n=10000, workers=2):
    build_library(generator(12, seed=1), workers=1)  # warm-up: numba cache, imports
    gen = generator(n)
    t0 = time.perf_counter()
    lib, _ = build_library(gen, workers=workers)
    wall = time.perf_counter() - t0
    faces = lib.particles["n_faces"]
    print(f"{len(lib)} particles ({len(CLASSES)} classes), {workers} worker(s): {wall:.2f} s, "
          f"faces {faces.min()}-{faces.max()} (mean {faces.mean():.1f})")
    print(f"library_particles_per_s={len(lib) / wall:.0f}")


if __name__ == "__main__":
    if "--quick" in sys.argv[1:]:
        main(600, 1)
    else:
        main(*(int(a) for a in sys.argv[1:3]))
