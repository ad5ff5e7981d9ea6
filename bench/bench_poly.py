"""Polyhedron-steps per second on the peers' "poly" scene (../shared/peers/yade/poly.py).

500 random convex polyhedra (YADE-like Voronoi cells, sizes 10-20 mm) fall from a
cubic lattice into a closed 278 x 278 x 555 mm box: rho 2600, E 1e9 Pa, friction 0.5,
local damping 0.3, gravity, dt 2e-5 s, 10 000 steps (0.2 s), as the YADE run
(scene: bench/scene_poly.py). The loop is timed after a one-step warm-up (JIT
compilation and the priming evaluation); a progress line every 1000 steps gives the
contacts and the wall time per 1000 steps, as the YADE script does.

Usage: python bench/bench_poly.py [--n 500] [--steps 10000] [--dt 2e-5] [--threads N]
The last line is ``particle_steps_per_s=<number>`` (polyhedron-steps per second).
"""

import argparse
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))
sys.path.insert(0, str(HERE))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=500)
    ap.add_argument("--steps", type=int, default=10000)
    ap.add_argument("--dt", type=float, default=2e-5)
    ap.add_argument("--threads", type=int, default=None, help="default: the free cores (load average)")
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument("--young", type=float, default=1e9,
                    help="Young's modulus [Pa] (1e9 as the YADE run; ~1e7 gives YADE-like contact stiffness)")
    args = ap.parse_args(argv)

    import numba

    import scene_poly
    from demcli.jit import set_threads
    from demcli.kernels.layout import STATUS_TEXT

    threads = set_threads(args.threads)
    t0 = time.perf_counter()
    s = scene_poly.make_system(args.n, seed=args.seed, dt=args.dt, young=args.young)
    t_setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    status, done = s.advance(1)  # compile (or load from cache) and prime
    t_jit = time.perf_counter() - t0
    print(f"case=poly N={args.n} steps={args.steps} dt={args.dt:g} young={args.young:g} threads={threads} "
          f"numba={numba.__version__} python={platform.python_version()} load={os.getloadavg()[0]:.2f}")
    print(scene_poly.describe(s) + f" dt_crit={s.critical_dt():.3g} (dt = {args.dt / s.critical_dt():.2f} x)")
    print(f"setup_s={t_setup:.2f} first_step_s={t_jit:.2f} (JIT or cache load)")
    wall = 0.0
    left = args.steps - done
    block = 1000
    while left > 0 and status == 0:
        k = min(block - s.step % block if s.step % block else block, left)
        c0 = time.perf_counter()
        status, n = s.advance(k)
        dt_wall = time.perf_counter() - c0
        wall += dt_wall
        left -= n
        pp, pw = s.contact_count()
        if s.step % block == 0 or left == 0:
            print(f"progress iter={s.step} contacts={pp}+{pw} rebuilds={s.counters[3]} "
                  f"wall_s_per_1000_steps={dt_wall * 1000.0 / max(n, 1):.3f}", flush=True)
    if status != 0:
        print(f"STOPPED: {STATUS_TEXT[status]} at step {s.step}; info={s.info}")
    steps = s.step - done
    pp, pw = s.contact_count()
    vmax = float(np.linalg.norm(s.v, axis=1).max())
    print(f"contacts_pp={pp} contacts_wall={pw} vmax={vmax:.3f} zmax_mm={1e3 * s.x[:, 2].max():.1f} "
          f"sim_time_s={s.time:.4g}")
    print(f"loop_wall_s={wall:.3f} steps_per_s={steps / wall:.1f} load_after={os.getloadavg()[0]:.2f}")
    print(f"particle_steps_per_s={args.n * steps / wall:.1f}")


if __name__ == "__main__":
    main()
