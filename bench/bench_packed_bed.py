"""A packed sphere bed under a lid, demcli against LIGGGHTS and LAMMPS (the same bed, alternated).

The peers' sphere scenes (bench/scene_drop.py) are a lattice falling through its gaps: 0.27
contacts per sphere at the end of the window, so they measure the neighbour search and the
integrator more than the contact law. This bed is what a DEM code spends its time on:

* built once (cached in ``$DEMCLI_BENCH_CACHE`` or ``~/.cache/demcli/bench``, ``packed_<n>.npz``)
  by demcli: N spheres of the peers' scene (d 2 mm, rho 2650, linear law kn 1e5 N/m, kt kn/4,
  mu 0.5, e 0.5, dt 1e-6 s) poured from a loose lattice (16 x 16 per layer, spacing 1.25 d,
  layers 1.5 d apart, jitter, random velocities up to 0.3 m/s, seeded) into the box of the
  peers' dense_10000 footprint (40.8 x 40.8 mm) and settled for ``--settle`` steps; then the lid
  (the top wall) is lowered onto the highest sphere and every velocity set to zero;
* timed: ``--steps`` steps (20 000, the peers' window) from that state in each code, each run
  its own process, alternated ``--repeat`` times: demcli on 1 and 2 threads, LIGGGHTS and LAMMPS
  with the peers' own inputs (``../shared/peers/*/drop.in``, serial, skin 0.3 mm as demcli's 0.3 r).

Prints each run, then a Markdown block between ``<!-- bench_packed_bed:begin -->`` and
``<!-- bench_packed_bed:end -->`` (medians, contacts per sphere, cost per contact), and as its
last line ``packed_bed_demcli_1t=<median particle-steps/s>``.

Usage: python bench/bench_packed_bed.py [--n 10000] [--steps 20000] [--repeat 2] [--settle 300000]
       [--peers liggghts,lammps] [--peers-dir ../shared/peers]
"""

import argparse
import math
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

D = 2.0e-3
FOOT = 20 * 1.02 * D          # the peers' dense_10000 footprint [m]
PEER_SKIN = 3e-4              # [m]: demcli's skin 0.3 r


def cache_path(n):
    root = Path(os.environ.get("DEMCLI_BENCH_CACHE", Path.home() / ".cache" / "demcli" / "bench"))
    return root / f"packed_{n}.npz"


def pour(n, rng):
    """Loose start: 16 x 16 per layer, spacing 1.25 d, layers 1.5 d apart, jittered; velocities."""
    per = 16
    s = FOOT / per
    k = np.arange(n)
    pos = np.column_stack([(k % per + 0.5) * s, (k // per % per + 0.5) * s, (k // (per * per) + 0.5) * 1.5 * D])
    pos[:, :2] += rng.uniform(-0.1 * D, 0.1 * D, (n, 2))
    pos[:, 2] += rng.uniform(0.0, 0.2 * D, n)
    return pos, rng.uniform(-0.3, 0.3, (n, 3))


def build(n, settle, threads):
    """The settled bed (cached): positions and the box (lid on the highest sphere)."""
    path = cache_path(n)
    if path.exists():
        d = np.load(path)
        return d["x"], d["box"]
    from demcli.jit import set_threads
    from scene_drop import system_of

    set_threads(threads)
    pos, vel = pour(n, np.random.RandomState(2026))
    top = pos[:, 2].max() + D
    s = system_of(pos, vel, (FOOT, FOOT, top))
    t0 = time.perf_counter()
    for done in range(0, settle, 50000):
        s.advance(min(50000, settle - done))
        ke = 0.5 * float((s.mass * (s.v ** 2).sum(axis=1)).sum())
        print(f"  settling: {s.step} steps, kinetic energy {ke:.3g} J, contacts {s.contact_count()[0]} "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)
    x = s.x.copy()
    box = np.array([FOOT, FOOT, x[:, 2].max() + D / 2])
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, x=x, box=box)
    os.replace(tmp, path)
    return x, box


def run_demcli(n, steps, threads):
    """One timed demcli run (in this process): particle-steps/s and contacts at the end."""
    from demcli.jit import set_threads
    from scene_drop import system_of

    x, box = build(n, 0, threads)
    set_threads(threads)
    s = system_of(x, np.zeros_like(x), box)
    s.advance(100)   # compile (or load) the kernels; not timed
    t0 = time.perf_counter()
    s.advance(steps)
    loop = time.perf_counter() - t0
    pairs, walls = s.contact_count()
    print(f"contacts_pp={pairs} contacts_wall={walls}")
    print(f"loop_wall_s={loop:.3f}")
    print(f"particle_steps_per_s={n * steps / loop:.6g}")


def data_file(x, box, folder):
    """The bed as a LAMMPS/LIGGGHTS data file (the peers' format: id type diameter density x y z)."""
    path = Path(folder) / f"packed_{len(x)}.data"
    with open(path, "w") as f:
        f.write(f"packed bed N={len(x)} (atom_style granular/sphere: id type diameter density x y z)\n\n")
        f.write(f"{len(x)} atoms\n1 atom types\n\n")
        f.write(f"0 {box[0]:.9e} xlo xhi\n0 {box[1]:.9e} ylo yhi\n0 {box[2]:.9e} zlo zhi\n\nAtoms\n\n")
        for i, p in enumerate(x):
            f.write(f"{i + 1} 1 {D:.6e} 2650.000 {p[0]:.17e} {p[1]:.17e} {p[2]:.17e}\n")
    return path


def peer_cmd(peer, peers_dir, data, box, steps, log):
    m = 2650.0 * math.pi / 6 * D ** 3
    zeta = -math.log(0.5) / math.sqrt(math.pi ** 2 + math.log(0.5) ** 2)
    cn = 2 * zeta * math.sqrt(m / 2 * 1e5)
    binary = {"liggghts": "liggghts", "lammps": "lmp"}[peer]
    cmd = [binary, "-echo", "none", "-log", str(log), "-in", str(Path(peers_dir) / peer / "drop.in"),
           "-var", "datafile", str(data), "-var", "steps", str(steps), "-var", "Lx", repr(float(box[0])),
           "-var", "Ly", repr(float(box[1])), "-var", "Lz", repr(float(box[2])), "-var", "cn", repr(cn),
           "-var", "skin", repr(PEER_SKIN)]
    return cmd + (["-var", "vtk", "0", "-var", "vtkdir", "."] if peer == "liggghts" else [])


def run(cmd, env):
    """(particle-steps/s, contacts per sphere or None, output) of one process."""
    out = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    text = out.stdout
    m = re.search(r"Loop time of ([0-9.eE+-]+) on \d+ procs for (\d+) steps with (\d+) atoms", text)
    if m:   # a peer: its loop time and the last thermo line's contact count
        loop, steps, n = float(m.group(1)), int(m.group(2)), int(m.group(3))
        thermo = [ln.split() for ln in text[:m.start()].splitlines() if re.match(r"^\s*\d+\s+\d+\s", ln)]
        return n * steps / loop, 2.0 * float(thermo[-1][2]) / n, text
    rate = re.search(r"particle_steps_per_s=([0-9.eE+-]+)", text)
    pairs = re.search(r"contacts_pp=(\d+)", text)
    if out.returncode != 0 or rate is None:
        raise RuntimeError(f"{cmd[0]} failed (rc {out.returncode}): {text[-800:]}")
    return float(rate.group(1)), pairs and int(pairs.group(1)), text


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--settle", type=int, default=300000)
    ap.add_argument("--peers", default="liggghts,lammps")
    ap.add_argument("--peers-dir", default=os.environ.get("DEMCLI_PEERS", str(HERE.parent.parent / "shared" / "peers")))
    ap.add_argument("--one", type=int, default=None, help=argparse.SUPPRESS)  # one demcli run on this many threads
    a = ap.parse_args(argv)
    if a.one:
        run_demcli(a.n, a.steps, a.one)
        return
    x, box = build(a.n, a.settle, 2)
    work = cache_path(a.n).parent
    data = data_file(x, box, work)
    env = dict(os.environ, OMP_NUM_THREADS="1")
    entries = [(f"demcli t={t}", [sys.executable, __file__, "--n", str(a.n), "--steps", str(a.steps), "--one", str(t)])
               for t in (1, 2)]
    peers = [p for p in a.peers.split(",") if p and Path(a.peers_dir, p, "drop.in").exists()
             and subprocess.run(["which", {"liggghts": "liggghts", "lammps": "lmp"}[p]],
                                stdout=subprocess.DEVNULL).returncode == 0]
    entries[1:1] = [(p, peer_cmd(p, a.peers_dir, data, box, a.steps, work / f"{p}_packed.log"))
                    for p in peers[:1]]
    entries += [(p, peer_cmd(p, a.peers_dir, data, box, a.steps, work / f"{p}_packed.log")) for p in peers[1:]]
    results = {label: [] for label, _ in entries}
    for k in range(1, a.repeat + 1):
        for label, cmd in entries:
            rate, contacts, _ = run(cmd, env)
            if label.startswith("demcli"):
                contacts = 2.0 * contacts / a.n
            results[label].append((rate, contacts))
            print(f"  run {k} {label}: {rate:.4g} particle-steps/s, {contacts:.2f} contacts per sphere", flush=True)
    ref = {p: statistics.median(r for r, _ in results[p]) for p in peers}
    rows = ["| code | median particle-steps/s | runs | contacts per sphere | ns per contact-step | "
            + " | ".join(f"x {p}" for p in peers) + " |", "|---|---|---|---|---|" + "---|" * len(peers)]
    for label, recs in results.items():
        med = statistics.median(r for r, _ in recs)
        cps = recs[-1][1]
        rows.append(f"| {label} | {med:.3g} | {', '.join(f'{r:.3g}' for r, _ in recs)} | {cps:.2f} | "
                    f"{1e9 / (med * cps / 2):.1f} | " + " | ".join(f"{med / ref[p]:.2f}" for p in peers) + " |")
    print(f"<!-- bench_packed_bed:begin -->\n{a.n} spheres settled under a lid (box {box[0] * 1e3:.1f} x "
          f"{box[1] * 1e3:.1f} x {box[2] * 1e3:.1f} mm), {a.steps} steps from rest, alternated {a.repeat}x; "
          "contacts per sphere at the end of the last run (walls not counted):\n\n" + "\n".join(rows)
          + "\n<!-- bench_packed_bed:end -->")
    print(f"packed_bed_demcli_1t={statistics.median(r for r, _ in results['demcli t=1']):.6g}")


if __name__ == "__main__":
    main()
