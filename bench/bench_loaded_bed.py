"""Throughput of a settled, loaded polyhedral bed: the ballast box's real workload.

Usage: python bench/bench_loaded_bed.py [CASE] [--steps N] [--repeat K] [--threads T]
  default CASE: cases/quickstart.yaml (143 stones and the sleeper on its shoulders)

The bed is built by the case itself: ``demcli run CASE`` up to and with its ``sleeper``
stage, with one vibration and one sleeper cycle (``--set stages.vibrate.cycles=1 --set
stages.sleeper.cycles=1``), in a cache folder (``$DEMCLI_BENCH_CACHE``, default
``~/.cache/demcli/bench/<case name>``; made once, then reused while the case is unchanged:
the pipeline skips up-to-date stages). From the sleeper stage's final state the benchmark
builds the stage's engine (its physics, walls, scaling and time step) with the sleeper
held at its peak load (the case's ``load.max``, constant), runs 200 steps for the contacts
to take the load, then times K windows of N steps each on T threads and prints the median
body-steps/s, the touching pairs per body and the cost per touching pair. The last line is
``particle_steps_per_s=<median body-steps/s>`` (the bench runner's convention).

``--export FILE.npz`` writes the bed after those 200 steps for a peer code (``bench/yade_loaded_bed.py``
runs it in YADE Polyhedra): each body's world vertices, mass, position, velocity and fixed
degrees of freedom, the plane walls, the sleeper's load, the time step, gravity, local damping,
friction and the volumetric stiffness (see :func:`export_bed`).
"""

import argparse
import os
import statistics
import sys
import time
from pathlib import Path
from types import SimpleNamespace

HERE = Path(__file__).resolve().parent


def cache_folder(case):
    """Where the bed of ``case`` is built and kept (``$DEMCLI_BENCH_CACHE/<case name>``)."""
    return Path(os.environ.get("DEMCLI_BENCH_CACHE", Path.home() / ".cache" / "demcli" / "bench")) / Path(case).stem


def loaded_state(case, folder):
    """The sleeper stage's final state of ``case`` (run once into ``folder``)."""
    from demcli import run_case
    from demcli.state import read_state

    res = run_case(case, out=folder, quiet=True,
                   overrides=["stages.vibrate.cycles=1", "stages.sleeper.cycles=1"])
    path = [r.path for r in res if r.name == "sleeper"][0]
    return read_state(path)


def loaded_system(case_path, state, threads, refresh=None):
    """The sleeper stage's engine on ``state``, the sleeper at its constant peak load; ``refresh``: the
    stage's contact.geometry_refresh replaced (None: the case's)."""
    import numba
    import numpy as np

    from demcli.config.schema import Node
    from demcli.stages import loop
    from demcli.stages.base import load_case, load_stage_types

    load_stage_types()
    numba.set_num_threads(threads)
    case = load_case(case_path)
    cfg = case.stages[[s.name for s in case.stages].index("sleeper")]
    dcfg = dict(cfg)
    dcfg["time"] = Node({"steps": 1, "duration": None, "dt": cfg.time.dt, "dt_factor": cfg.time.dt_factor})
    if refresh is not None:
        dcfg["contact"] = Node({**dict(cfg.contact), "geometry_refresh": refresh})
    groups = dict(state.groups)
    act = dict(groups["actors"])
    down = np.array([0.0, 0.0, -1.0])
    act["load_mean"] = np.tile(cfg.load.max * down, (len(act["body"]), 1))
    act["load_amplitude"] = np.zeros_like(act["load_mean"])
    groups["actors"] = act
    system, _, dt, _ = loop.make_system(SimpleNamespace(case=case, name="bench", index=0, runner=SimpleNamespace(case_path=case_path),
                                                       log=lambda m: None), Node(dcfg),
                                       groups, time=0.0, step=0, resume=True)
    system.dt = dt
    return system


def export_bed(s, path):
    """The loaded bed ``s`` as arrays a peer code can rebuild (``path``, .npz).

    YADE's volumetric law is F_N = k V (k = E1 E2 / (E1 + E2) [N/m^3]), ours F_N = k_n sqrt(V d):
    for a flat overlap of area A the contact stiffnesses are k A and k_n sqrt(A), equal at
    k = k_n / sqrt(A). ``yade_young`` = 2 k_n / sqrt(A_median) over the bed's touching pairs (the
    same stiffness at the median contact area; E1 = E2)."""
    import numpy as np

    from demcli.kernels.shapes.polyhedra import G_DEPTH, G_FN, Q_KN, Q_MU

    nl = s.nl
    act = nl.act.astype(bool)
    depth = nl.geo[act, G_DEPTH]
    fn = nl.geo[act, G_FN]
    kn = float(s.prm[s.bmat[0], s.bmat[0], Q_KN])
    # F_N = k_n sqrt(V d) and V = A d (flat): A = (F_N / (k_n d))^2
    area = (fn / (kn * depth)) ** 2
    wvert = s.world[0]
    par = s.kernel_params()
    act_rows = s._actors
    np.savez(path, vertices=wvert, vertex_start=s.bvstart, mass=s.mass, x=s.x, v=s.v, flags=s.bflags,
             wall_point=s.wpoint, wall_normal=np.asarray(s.walls.normal), actor_body=np.asarray(act_rows["body"]),
             actor_load=np.asarray(act_rows["load_mean"]), dt=s.dt, gravity=np.asarray(par.gravity),
             local_damping=par.local, friction=float(s.prm[s.bmat[0], s.bmat[0], Q_MU]), kn=kn,
             contact_area_median=float(np.median(area)), yade_young=2.0 * kn / float(np.sqrt(np.median(area))),
             touching_pairs=int(act.sum()))


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("case", nargs="?", default=str(HERE.parent / "cases" / "quickstart.yaml"))
    p.add_argument("--steps", type=int, default=200)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--refresh", type=int, default=None,
                   help="contact.geometry_refresh of the bed (default: the case's; 1 is the exact law)")
    p.add_argument("--export", default=None, help="write the bed after the first 200 steps to this .npz and stop")
    a = p.parse_args(argv)
    name = Path(a.case).stem
    state = loaded_state(a.case, cache_folder(a.case))
    s = loaded_system(a.case, state, a.threads, a.refresh)
    s.advance(200)  # the contacts take the peak load
    if a.export:
        export_bed(s, a.export)
        print(f"wrote {a.export}: {len(s.mass)} bodies, {int(s.nl.act.sum())} touching pairs")
        return
    rates = []
    for _ in range(a.repeat):
        t = time.perf_counter()
        status, done = s.advance(a.steps)
        rates.append(len(s.mass) * done / (time.perf_counter() - t))
        if status:
            sys.exit(f"the loaded bed went unstable (status {status})")
    pairs, walls = s.contact_count()
    med = statistics.median(rates)
    per_pair = len(s.mass) / med / max(pairs, 1)
    print(f"{name} sleeper bed, {len(s.mass)} bodies, {a.threads} thread(s), geometry refresh "
          f"{s.model.geometry_refresh}: {med:.4g} body-steps/s "
          f"(runs {', '.join(f'{r:.4g}' for r in rates)}); {pairs} touching pairs ({2 * pairs / len(s.mass):.2f} "
          f"per body), {walls} wall contacts; {per_pair * 1e6:.3g} us per touching pair-step")
    print(f"particle_steps_per_s={med:.6g}")


if __name__ == "__main__":
    main()
