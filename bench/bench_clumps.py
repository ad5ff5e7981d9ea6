"""Throughput of demcli on the peers' "clump" scene (bench/scene_clumps.py), as YADE's clump.py.

NC rigid clumps of 5-10 overlapping member spheres (r = 1 mm) fall from a lattice and pile up
(phase 1, SETTLE steps, timed separately), then STEPS further steps run in the piled-up,
contact-rich state (phase 2: the benchmark window), each phase in ONE ``System.advance`` call
timed with ``time.perf_counter``. The JIT is warmed up first on a tiny copy of the scene
(8 clumps, same plan and contact law), so compile or cache-load time is not timed; scene
set-up (clump mass properties included) is reported separately.

Usage:
    python bench/bench_clumps.py NC SETTLE STEPS THREADS [--skin S] [--mass union|yade]

    NC       number of clumps (the peers use 500: 3701 member spheres)
    SETTLE   steps of the fall phase before the window (the peers use 100000)
    STEPS    steps in the timed window (the peers use 20000)
    THREADS  numba threads for the parallel kernels (demcli.jit.set_threads)
    --skin S Verlet skin as a fraction of the member radius (r = 1 mm). Default 0.3.
    --mass   clump mass properties: union (demcli's, overlaps counted once; default) or yade
             (YADE's appendClumped default: summed member masses); see scene_clumps.py.

Argument order differs from YADE's ``clump.py NC STEPS SETTLE``: here SETTLE comes first, as
the phases run. Prints figures (contacts, clump heights, kinetic energy, the fall phase's
rate); the LAST line is ``particle_steps_per_s=<number>`` for the window, counted per member
sphere (members * STEPS / loop seconds), as YADE's script prints it.
"""

import argparse
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
from scene_clumps import MASS_CONVENTIONS, make_system  # noqa: E402


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("nc", type=int, help="number of clumps")
    ap.add_argument("settle", type=int, help="steps of the fall phase (not in the rate)")
    ap.add_argument("steps", type=int, help="steps in the timed window")
    ap.add_argument("threads", type=int, help="numba threads")
    ap.add_argument("--skin", type=float, default=0.3, help="Verlet skin / member radius (default 0.3)")
    ap.add_argument("--mass", choices=MASS_CONVENTIONS, default="union",
                    help="clump mass properties (default union: overlaps counted once)")
    return ap.parse_args(argv)


def warm_up(skin, mass):
    """Compile (or load from numba's cache) every kernel the timed run uses."""
    t0 = time.perf_counter()
    tiny, _ = make_system(8, skin=skin, mass=mass)
    tiny.advance(20)
    tiny.contact_count()
    tiny.kinetic_energy()
    return time.perf_counter() - t0


def main(argv=None):
    a = parse_args(argv)
    if a.nc < 1 or a.steps < 1 or a.settle < 0:
        sys.exit("NC and STEPS must be >= 1, SETTLE >= 0")
    threads = set_threads(a.threads)
    warm_s = warm_up(a.skin, a.mass)

    t0 = time.perf_counter()
    system, info = make_system(a.nc, skin=a.skin, mass=a.mass)
    setup_s = time.perf_counter() - t0
    nm = info["n_members"]

    t0 = time.perf_counter()
    status, fall_done = system.advance(a.settle) if a.settle else (0, 0)
    fall_s = max(time.perf_counter() - t0, 1e-9)
    if status != 0 or fall_done != a.settle:
        sys.exit(f"fall phase stopped early: {STATUS_TEXT.get(status, status)} after {fall_done} steps")
    fpp, fpw = system.contact_count()
    rebuild0 = int(system.counters[C_REBUILD])

    t0 = time.perf_counter()
    status, done = system.advance(a.steps)
    loop_s = time.perf_counter() - t0

    pp, pw = system.contact_count()
    z = system.x[:, 2]
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"code=demcli version={demcli.__version__} threads={threads}")
    print(f"case=clump clumps={a.nc} member_spheres={nm} ({nm / a.nc:.2f} per clump) steps={done} "
          f"dt={system.dt:g} box={info['L']:.4f}x{info['L']:.4f}x{info['H']:.4f} skin={a.skin} mass={a.mass} "
          f"clump_mass_mg={1e6 * system.mass.mean():.4f}")
    print(f"status={STATUS_TEXT.get(status, status)}")
    print(f"warmup_s={warm_s:.3f} setup_s={setup_s:.3f} maxrss_mb={rss_mb:.0f}")
    print(f"phase1_fall steps={a.settle} wall_s={fall_s:.3f} contacts_at_end={fpp + fpw} "
          f"particle_steps_per_s={nm * a.settle / fall_s:.1f} clump_steps_per_s={a.nc * a.settle / fall_s:.1f}")
    print(f"phase2_window steps={a.steps} (iterations {a.settle}..{a.settle + a.steps})")
    print(f"contacts_sphere_sphere={pp} contacts_wall={pw} contacts_total={pp + pw} "
          f"zmax_mm={z.max() * 1e3:.2f} zmean_mm={z.mean() * 1e3:.3f}")
    print(f"neighbour_rebuilds={int(system.counters[C_REBUILD]) - rebuild0}")
    print(f"kinetic_energy_J={system.kinetic_energy():.6g}")
    print(f"loop_wall_s={loop_s:.3f} steps_per_s={done / loop_s:.1f} "
          f"ns_per_particle_step={1e9 * loop_s / (nm * done):.2f}")
    print(f"clump_steps_per_s={a.nc * done / loop_s:.1f}")
    if status != 0 or done != a.steps:
        sys.exit(f"run stopped early: {STATUS_TEXT.get(status, status)} after {done} steps")
    print(f"particle_steps_per_s={nm * done / loop_s:.1f}")


if __name__ == "__main__":
    np.seterr(all="ignore")
    main()
