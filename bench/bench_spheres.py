"""Throughput of demcli on the peers' sphere "drop"/"dense" scene (bench/scene_drop.py).

The scene is built, the JIT is warmed up on a tiny copy of the scene (100 spheres, same
plan and contact law, so compile or cache-load time is not timed), then STEPS steps run in
ONE ``System.advance(STEPS)`` call timed with ``time.perf_counter``. Scene set-up and
warm-up are reported separately and are not in the rate.

Usage:
    python bench/bench_spheres.py N VARIANT STEPS THREADS [--skin S] [--order ORDER]

    N        number of spheres (1000 and 10000 give the peers' exact lattices)
    VARIANT  drop | dense
    STEPS    steps in the timed window (the peers use 20000)
    THREADS  numba threads for the parallel kernels (demcli.jit.set_threads)
    --skin S Verlet skin as a fraction of the sphere radius (r = 1 mm, so 0.3 = 0.3 mm;
             the peers' DROP_SKIN is in metres: 0.3 here = DROP_SKIN=3e-4). Default 0.3.
    --order  spheres in memory in the lattice's row order (default, as the peers store them),
             shuffled, or shuffled then sorted by cell as a dynamic stage stores a fresh scene
             (lattice | shuffle | cells): what memory locality is worth.

Prints figures (contacts at the end, neighbour-list rebuilds, kinetic energy, ...); the LAST
line is ``particle_steps_per_s=<number>`` (N * STEPS / loop seconds), as the peers print it.
"""

import argparse
import math
import os
import resource
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)

import demcli  # noqa: E402  (first: it sets OPENBLAS_NUM_THREADS before numpy loads OpenBLAS)
import numpy as np  # noqa: E402
from demcli.jit import set_threads  # noqa: E402
from demcli.kernels.layout import C_REBUILD, STATUS_TEXT# noqa: E402
from scene_drop import D, SPACING, lattice_dims, make_system  # noqa: E402


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("n", type=int, help="number of spheres")
    ap.add_argument("variant", choices=sorted(SPACING), help="scene variant")
    ap.add_argument("steps", type=int, help="steps in the timed window")
    ap.add_argument("threads", type=int, help="numba threads")
    ap.add_argument("--skin", type=float, default=0.3, help="Verlet skin / sphere radius (default 0.3)")
    ap.add_argument("--order", choices=("lattice", "shuffle", "cells"), default="lattice",
                    help="sphere order in memory: the lattice's rows (default), random, or random "
                         "then sorted by cell as a dynamic stage stores a fresh scene")
    return ap.parse_args(argv)


def warm_up(variant, skin):
    """Compile (or load from numba's cache) every kernel the timed run uses."""
    t0 = time.perf_counter()
    tiny = make_system(100, variant, skin=skin)
    tiny.advance(20)
    tiny.contact_count()
    return time.perf_counter() - t0


def main(argv=None):
    a = parse_args(argv)
    if a.n < 1 or a.steps < 1:
        sys.exit("N and STEPS must be >= 1")
    threads = set_threads(a.threads)
    warm_s = warm_up(a.variant, a.skin)

    t0 = time.perf_counter()
    system = make_system(a.n, a.variant, skin=a.skin, order=a.order)
    setup_s = time.perf_counter() - t0
    rebuild0 = int(system.counters[C_REBUILD])

    t0 = time.perf_counter()
    status, done = system.advance(a.steps)
    loop_s = time.perf_counter() - t0

    pp, pw = system.contact_count()
    nx, ny, nz = lattice_dims(a.n)
    zmax = float(system.x[:, 2].max())
    lx, ly = nx * SPACING[a.variant], ny * SPACING[a.variant]
    phi = a.n * math.pi / 6.0 * D ** 3 / (lx * ly * (zmax + D / 2))
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"code=demcli version={demcli.__version__} threads={threads}")
    print(f"case={a.variant} N={a.n} steps={done} dt={system.dt:g} skin={a.skin} (x r = {a.skin * D / 2:.3g} m)")
    print(f"status={STATUS_TEXT.get(status, status)}")
    print(f"contacts_pp={pp} contacts_wall={pw} contacts_total={pp + pw}")
    print(f"neighbour_rebuilds={int(system.counters[C_REBUILD]) - rebuild0}")
    print(f"zmax_mm={zmax * 1e3:.4f} packing_fraction_bulk={phi:.4f} "
          f"kinetic_energy_J={system.kinetic_energy():.6g}")
    print(f"warmup_s={warm_s:.3f} setup_s={setup_s:.3f} maxrss_mb={rss_mb:.0f}")
    print(f"loop_wall_s={loop_s:.3f} steps_per_s={done / loop_s:.1f} "
          f"ns_per_particle_step={1e9 * loop_s / (a.n * done):.2f}")
    if status != 0 or done != a.steps:
        sys.exit(f"run stopped early: {STATUS_TEXT.get(status, status)} after {done} steps")
    print(f"particle_steps_per_s={a.n * done / loop_s:.1f}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
