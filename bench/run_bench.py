"""`make bench`: demcli's throughput next to the peer DEM codes, on identical scenes.

Runs, alternating (demcli, peer, demcli, peer, ...; all entries once, then all a second
time), the peers' scenes (default: the sphere scene dense_10000 and the clump scene
clump_500, 20000 steps, dt = 1e-6 s; the polyhedron scene poly_500, 10000 steps, dt = 2e-5 s):

* demcli with 1 and 2 numba threads (bench/bench_spheres.py), plus 2 threads with
  OMP_WAIT_POLICY=PASSIVE (see bench/README.md: on a shared 2-core machine the default
  spinning OpenMP barrier collapses when another process takes a core);
* LIGGGHTS, LAMMPS and YADE through ../shared/peers (run as peers/run_all.sh runs them:
  from the folder that contains peers/, PEERS_WORK = a scratch folder, OMP_NUM_THREADS=1),
  when their binaries are on PATH; otherwise it says how to install them and goes on.
* clump_NC (rigid clumps of 5-10 overlapping spheres, ../shared/peers/common/clump_setup.py):
  demcli 1 and 2 threads (bench/bench_clumps.py) against YADE (peers/yade/clump.py, the only
  peer with that scene); --clump-settle fall steps first, then the timed --steps window.
* poly_N (random convex polyhedra falling into a box, bench/scene_poly.py): demcli 1 and 2
  threads (bench/bench_poly.py) against YADE Polyhedra (peers/yade/poly.py), --poly-steps.

Then a scaling row (demcli, 1 thread, dense, N = 1e3, 1e4, 1e5 [1e6 with --big], the same
number of steps for every N: the cost per particle-step should stay flat; LIGGGHTS beside it
on the same N when installed, the one peer fast enough for 1e6), the geometry
toolkit's bench/bench_sieve.py when it exists, and the 3D asphalt Marshall pipeline's wall time per
stage against the lattice ball size (bench/bench_asphalt.py), and the cold/warm JIT
compile time of `demcli run` on two smoke cases (bench/bench_jit.py), and the scenes no peer
has (2D sections, ballast library, polyhedron narrow phase, a bonded specimen: each script's
figure line).

Every run is a separate process whose LAST line is ``particle_steps_per_s=<number>``.
The table (runs, median, ratio to LIGGGHTS) is printed and written to bench/results.md
(with date, machine, load averages, demcli version and the command).

Usage: python bench/run_bench.py [--quick] [--scenes dense_10000,clump_500] [--repeat K]
                                 [--skip-peers] [--skin S] [--peer-skin M] [--big]
                                 [--clump-settle STEPS] [--poly-steps STEPS] [--no-jit]
                                 [--no-asphalt] [--no-extras] [--asphalt-spacings 2.0,1.4,1.0,0.7]
"""

import argparse
import datetime
import os
import platform
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
PEERS_DEFAULT = os.path.normpath(os.path.join(ROOT, "..", "shared", "peers"))
PEER_BIN = {"liggghts": "liggghts", "lammps": "lmp", "yade": "yade"}
PEER_ORDER = ("liggghts", "lammps", "yade")
RATE = re.compile(r"^particle_steps_per_s=([0-9.eE+-]+)\s*$")
SCENE = re.compile(r"(drop|dense|clump|poly)_(\d+)")
DEFAULT_SCENES = "dense_10000,clump_500,poly_500"
CLUMP_SETTLE = 100000   # fall steps before the clump window (the peers' RESULTS.md uses 100000)
POLY_STEPS = 10000      # the peers' poly scene: a 0.2 s fall at dt 2e-5 s (peers/yade/poly.py, RESULTS.md)
KV = re.compile(r"([A-Za-z_][A-Za-z_0-9]*)=([^\s]+)")


# ---------------------------------------------------------------------------------------
# command line
# ---------------------------------------------------------------------------------------
def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--quick", action="store_true",
                    help="smoke test: dense_1000 for 2000 steps, small scaling row, small sieve run; "
                         "writes no results file unless --out is given")
    ap.add_argument("--scenes", default=None,
                    help="comma list of VARIANT_N (VARIANT = drop|dense|clump|poly; N = spheres, or clumps for "
                         "clump, or polyhedra for poly), "
                         f"default {DEFAULT_SCENES} (--quick: dense_1000)")
    ap.add_argument("--steps", type=int, default=None, help="steps per scene run (default 20000; --quick: 2000)")
    ap.add_argument("--poly-steps", type=int, default=None,
                    help=f"steps of the poly scene (default {POLY_STEPS}, the peers' scene; --quick: 1000)")
    ap.add_argument("--clump-settle", type=int, default=None,
                    help=f"fall steps before the timed window of clump scenes, same for demcli and YADE "
                         f"(default {CLUMP_SETTLE}: the pile has formed; --quick: 2000)")
    ap.add_argument("--repeat", type=int, default=2, help="runs of every entry (default 2; the median is reported)")
    ap.add_argument("--threads", default="1,2", help="demcli thread counts (default 1,2)")
    ap.add_argument("--no-passive", action="store_true",
                    help="leave out the demcli row with OMP_WAIT_POLICY=PASSIVE")
    ap.add_argument("--skip-peers", action="store_true", help="run demcli only")
    ap.add_argument("--peers", default="liggghts,lammps,yade", help="peers to run when installed")
    ap.add_argument("--peers-dir", default=os.environ.get("DEMCLI_PEERS", PEERS_DEFAULT),
                    help="the peers/ folder (default ../shared/peers or $DEMCLI_PEERS)")
    ap.add_argument("--skin", type=float, default=0.3,
                    help="demcli Verlet skin as a fraction of the sphere radius (r = 1 mm; default 0.3 = 0.3 mm)")
    ap.add_argument("--peer-skin", type=float, default=3e-4,
                    help="LIGGGHTS/LAMMPS neighbour skin in metres (DROP_SKIN; default 3e-4, LIGGGHTS' best; "
                         "the peers' scripts default to 1e-3). YADE keeps its verletDist = 0.5 r")
    ap.add_argument("--yade-max-s", type=float, default=240.0,
                    help="skip a YADE run expected (from ../shared/peers/RESULTS.md) to take longer than this, "
                         "and kill one that does; its RESULTS.md figure is shown instead (default 240)")
    ap.add_argument("--timeout", type=float, default=1800.0, help="kill any single run after this many seconds")
    ap.add_argument("--no-scaling", action="store_true", help="leave out the scaling row")
    ap.add_argument("--scaling-steps", type=int, default=None,
                    help="steps of every scaling run (default 2000; --quick: 200)")
    ap.add_argument("--big", action="store_true", help="add N = 1e6 to the scaling row (~2 GB, minutes per run)")
    ap.add_argument("--no-sieve", action="store_true", help="leave out bench/bench_sieve.py")
    ap.add_argument("--no-asphalt", action="store_true",
                    help="leave out bench/bench_asphalt.py (3D Marshall pipeline against the lattice ball size)")
    ap.add_argument("--asphalt-spacings", default=None,
                    help="lattice ball diameters in mm for bench/bench_asphalt.py, comma list "
                         "(default its own: 2.0,1.4,1.0,0.7, a few minutes; --quick: 2.0,1.5)")
    ap.add_argument("--no-jit", action="store_true",
                    help="leave out bench/bench_jit.py (cold/warm compile time of two smoke cases, a few minutes; "
                         "never run with --quick)")
    ap.add_argument("--no-extras", action="store_true",
                    help="leave out the scenes no peer has (2D sections, ballast library, polyhedron narrow "
                         "phase, bonded specimen)")
    ap.add_argument("--out", default=None, help="results file (default bench/results.md; --quick: none)")
    a = ap.parse_args(argv)
    if a.scenes is None:
        a.scenes = "dense_1000" if a.quick else DEFAULT_SCENES
    if a.steps is None:
        a.steps = 2000 if a.quick else 20000
    if a.clump_settle is None:
        a.clump_settle = 2000 if a.quick else CLUMP_SETTLE
    if a.poly_steps is None:
        a.poly_steps = 1000 if a.quick else POLY_STEPS
    if a.scaling_steps is None:
        a.scaling_steps = 200 if a.quick else 2000
    if a.out is None and not a.quick:
        a.out = os.path.join(HERE, "results.md")
    a.scene_list = []
    for s in a.scenes.split(","):
        m = SCENE.fullmatch(s.strip())
        if not m:
            ap.error(f"bad scene {s!r}: expected drop_N, dense_N, clump_N or poly_N")
        a.scene_list.append((m.group(1), int(m.group(2))))
    a.thread_list = [int(t) for t in a.threads.split(",") if t.strip()]
    a.peer_list = [p for p in PEER_ORDER if p in [q.strip() for q in a.peers.split(",")]]
    if a.repeat < 1:
        ap.error("--repeat must be >= 1")
    if a.clump_settle < 0:
        ap.error("--clump-settle must be >= 0")
    return a


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------
def sh(cmd):
    try:
        return subprocess.run(cmd, shell=True, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                               text=True, timeout=20).stdout.strip()
    except Exception:  # noqa: BLE001 - informational only
        return ""


def machine():
    model = re.search(r"Model name:\s*(.+)", sh("lscpu"))
    cpus = re.search(r"^CPU\(s\):\s*(\d+)", sh("lscpu"), re.M)
    mem = re.search(r"Mem:\s+(\S+)", sh("free -h"))
    return (f"{model.group(1).strip() if model else platform.processor() or '?'}, "
            f"{cpus.group(1) if cpus else os.cpu_count()} cores, {mem.group(1) if mem else '?'} RAM, "
            f"{platform.system()} {platform.release()}")


def source_digest():
    """Digest of demcli's sources (the tree is shared: a change during the run is reported)."""
    import hashlib

    h = hashlib.sha1()
    for dirpath, dirnames, files in sorted(os.walk(os.path.join(ROOT, "demcli"))):
        dirnames.sort()
        for fn in sorted(files):
            if fn.endswith(".py"):
                with open(os.path.join(dirpath, fn), "rb") as f:
                    h.update(fn.encode() + f.read())
    return h.hexdigest()[:12]


def load():
    return "%.2f %.2f %.2f" % os.getloadavg()


def fmt(x):
    return "—" if x is None else f"{x:.3g}"


def run_proc(cmd, cwd, env, timeout):
    """Run one benchmark process; returns a record with the parsed figures."""
    rec = {"cmd": " ".join(shlex.quote(c) for c in cmd), "load_before": load(), "rate": None, "kv": {},
           "error": None}
    t0 = time.perf_counter()
    try:
        out = subprocess.run(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             text=True, timeout=timeout)
        text, rc = out.stdout, out.returncode
    except subprocess.TimeoutExpired as e:
        text = e.stdout.decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
        rc = None
        rec["error"] = f"killed after {timeout:.0f} s"
    rec["process_s"] = time.perf_counter() - t0
    lines = [ln for ln in text.splitlines() if ln.strip()]
    rec["last"] = lines[-1] if lines else None
    rec["lines"] = lines
    if lines and RATE.match(lines[-1]):
        rec["rate"] = float(RATE.match(lines[-1]).group(1))
    elif rec["error"] is None:
        rec["error"] = f"rc={rc}, no particle_steps_per_s line: " + " | ".join(lines[-3:])[-300:]
    for ln in lines:
        if ln.startswith(("progress", "breakdown")):
            if ln.startswith("breakdown Neighbor list builds"):
                rec["kv"]["neighbour_rebuilds"] = ln.split("=")[-1].strip()
            continue
        prefix = "fall_" if ln.startswith("phase1_fall") else ""   # clump scenes: the fall phase's figures
        for k, v in KV.findall(ln):
            rec["kv"][prefix + k] = v
    return rec


def reference_rows(peers_dir):
    """{(peer, variant, N): (rates [run1, run2], steps, info)} from the table in peers/RESULTS.md
    (may be empty). info: for clump rows {"settle": fall steps, "members": member spheres}."""
    ref = {}
    try:
        text = open(os.path.join(peers_dir, "RESULTS.md"), encoding="utf-8").read()
    except OSError:
        return ref
    for ln in text.splitlines():
        c = [x.strip() for x in ln.strip().strip("|").split("|")]
        if len(c) >= 7 and c[0] in PEER_BIN and c[1] in ("drop", "dense", "clump", "poly") and c[2].isdigit():
            try:
                r = [float(x) for x in c[6].split("/")]
            except ValueError:
                continue
            info = {}
            if c[1] == "clump":
                note = " ".join(c[7:])
                settle = re.search(r"fall phase \((\d+) steps\)", note)
                members = re.search(r"(\d+) member spheres", note)
                if not (settle and members):
                    continue
                info = {"settle": int(settle.group(1)), "members": int(members.group(1))}
            ref[(c[0], c[1], int(c[2]))] = (r, int(c[3]), info)
    return ref


def ref_matches(ref, steps, settle=None):
    """A RESULTS.md row measured with the same window (and, for clumps, the same fall phase)."""
    return ref is not None and ref[1] == steps and (settle is None or ref[2].get("settle") == settle)


# ---------------------------------------------------------------------------------------
# entries
# ---------------------------------------------------------------------------------------
class Entry:
    """One row of the table: a code/setting on a scene, run --repeat times."""

    def __init__(self, scene, code, threads, cmd, cwd, env, note="", timeout=None):
        self.scene, self.code, self.threads = scene, code, threads
        self.cmd, self.cwd, self.env, self.note, self.timeout = cmd, cwd, env, note, timeout
        self.runs = []          # records from run_proc
        self.reference = None   # figures from RESULTS.md instead of runs
        self.refback = None     # RESULTS.md figures to fall back on if a YADE run is killed

    @property
    def rates(self):
        return [r["rate"] for r in self.runs if r["rate"] is not None]

    @property
    def median(self):
        if self.reference is not None:
            return statistics.median(self.reference)
        return statistics.median(self.rates) if self.rates else None

    def label(self):
        return self.code + (f" ({self.note})" if self.note else "")


def scene_steps(a, variant):
    """Steps of a scene's runs: the poly scene has its own (the peers' 0.2 s fall)."""
    return a.poly_steps if variant == "poly" else a.steps


def demcli_entries(a, variant, n, steps, threads_list, passive, env0):
    scene = f"{variant}_{n}"
    out = []
    if variant == "poly":   # polyhedron-steps/s; no PASSIVE row either
        for t in threads_list:
            cmd = [sys.executable, os.path.join(HERE, "bench_poly.py"), "--n", str(n), "--steps", str(steps),
                   "--threads", str(t)]
            out.append(Entry(scene, "demcli", t, cmd, ROOT, dict(env0), timeout=a.timeout))
        return out
    if variant == "clump":   # no PASSIVE row: the sphere scene already shows the OpenMP barrier effect
        for t in threads_list:
            cmd = [sys.executable, os.path.join(HERE, "bench_clumps.py"), str(n), str(a.clump_settle), str(steps),
                   str(t), "--skin", repr(a.skin)]
            out.append(Entry(scene, "demcli", t, cmd, ROOT, dict(env0, DEMCLI_PEERS=a.peers_dir), timeout=a.timeout))
        return out
    for t in threads_list:
        cmd = [sys.executable, os.path.join(HERE, "bench_spheres.py"), str(n), variant, str(steps), str(t),
               "--skin", repr(a.skin)]
        out.append(Entry(scene, "demcli", t, cmd, ROOT, dict(env0), timeout=a.timeout))
    if passive and any(t > 1 for t in threads_list):
        t = max(threads_list)
        cmd = [sys.executable, os.path.join(HERE, "bench_spheres.py"), str(n), variant, str(steps), str(t),
               "--skin", repr(a.skin)]
        out.append(Entry(scene, "demcli", t, cmd, ROOT, dict(env0, OMP_WAIT_POLICY="PASSIVE"),
                         note="OMP_WAIT_POLICY=PASSIVE", timeout=a.timeout))
    return out


def peer_entries(a, variant, n, steps, installed, refs, work):
    scene = f"{variant}_{n}"
    shared = os.path.dirname(a.peers_dir)
    env = dict(os.environ, PEERS_WORK=work, OMP_NUM_THREADS="1")
    out = []
    clump = variant == "clump"
    settle = a.clump_settle if clump else None
    poly = variant == "poly"
    for p in a.peer_list:
        if (clump or poly) and p != "yade":
            continue   # only YADE has the clump and polyhedron scenes
        if poly:
            cmd = ["yade", "-j1", "-n", "-x", "peers/yade/poly.py", str(n), str(steps)]
            e = Entry(scene, p, 1, cmd, shared, dict(env), note="Polyhedra", timeout=a.yade_max_s)
        elif clump:
            cmd = ["yade", "-j1", "-n", "-x", "peers/yade/clump.py", str(n), str(steps), str(settle)]
            e = Entry(scene, p, 1, cmd, shared, dict(env), note="verletDist 0.5 r", timeout=a.yade_max_s)
        elif p == "yade":
            cmd = ["yade", "-j1", "-n", "-x", "peers/yade/drop.py", str(n), str(steps), variant]
            e = Entry(scene, p, 1, cmd, shared, dict(env), note="verletDist 0.5 r", timeout=a.yade_max_s)
        else:
            cmd = ["python3", f"peers/{p}/run_drop.py", str(n), str(steps), variant]
            e = Entry(scene, p, 1, cmd, shared, dict(env, DROP_SKIN=repr(a.peer_skin)),
                      note=f"skin {a.peer_skin * 1e3:g} mm", timeout=a.timeout)
        ref = refs.get((p, variant, n))
        ref_ok = ref_matches(ref, steps, settle)
        if p not in installed:
            if ref_ok:
                e.reference = ref[0]
                e.note = "RESULTS.md, not run here" + ("" if p == "yade" else ", skin 1 mm")
                out.append(e)
            continue
        if p == "yade" and ref_ok:
            # the clump fall phase runs faster than the window: counting it at the window's rate over-estimates
            expected = (ref[2]["members"] * (steps + settle) if clump else n * steps) / min(ref[0])
            if expected > a.yade_max_s:
                e.reference = ref[0]
                e.note = f"RESULTS.md, not run here: ~{expected:.0f} s per run > {a.yade_max_s:.0f} s"
        out.append(e)
    return out


def interleave(dem, peers):
    """demcli, peer, demcli, peer, ... (leftovers at the end)."""
    out = []
    for i in range(max(len(dem), len(peers))):
        if i < len(dem):
            out.append(dem[i])
        if i < len(peers):
            out.append(peers[i])
    return out


def run_entry(e, k):
    if e.reference is not None:
        return
    print(f"  [{time.strftime('%H:%M:%S')}] run {k}: {e.scene} {e.label()} threads={e.threads} "
          f"(load {load()}) ...", end="", flush=True)
    rec = run_proc(e.cmd, e.cwd, e.env, e.timeout)
    e.runs.append(rec)
    if rec["rate"] is not None:
        print(f" {rec['rate']:.3g} particle-steps/s ({rec['process_s']:.1f} s)", flush=True)
    else:
        print(f" FAILED: {rec['error']}", flush=True)
        if e.code == "yade" and "killed" in (rec["error"] or "") and e.refback is not None:
            e.reference = e.refback
            e.note = f"RESULTS.md: run {k} here took > {e.timeout:.0f} s"


# ---------------------------------------------------------------------------------------
# report
# ---------------------------------------------------------------------------------------
def contacts(e):
    for r in reversed(e.runs):
        kv = r["kv"]
        for pp in ("contacts_pp", "contacts_sphere_sphere"):   # spheres / clump scripts
            if pp in kv:
                return f"{kv[pp]} + {kv.get('contacts_wall', '?')}"
    return "—"


def peer_base(es, refs, peer, scene, steps, settle):
    """(median of `peer` on this scene, note) for a ratio column: this session's runs, else the
    RESULTS.md figure; (None, "") when neither exists."""
    e = next((e for e in es if e.code == peer and e.median is not None), None)
    if e is not None:
        return e.median, (" (vs RESULTS.md)" if e.reference is not None else "")
    variant, n = scene.split("_")
    ref = refs.get((peer, variant, int(n)))
    if ref_matches(ref, steps, settle if variant == "clump" else None):
        return statistics.median(ref[0]), " (vs RESULTS.md" + (", skin 1 mm)" if peer != "yade" else ")")
    return None, ""


def scene_table(entries, refs, repeat, a):
    head = ["scene", "code", "threads", "particle-steps/s " + " / ".join(f"run{k + 1}" for k in range(repeat)),
            "median", "ratio to LIGGGHTS", "ratio to YADE", "contacts at end (p-p + wall)", "rebuilds"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    by_scene = {}
    for e in entries:
        by_scene.setdefault(e.scene, []).append(e)
    for scene, es in by_scene.items():
        steps = scene_steps(a, scene.split("_")[0])
        bases = [peer_base(es, refs, p, scene, steps, a.clump_settle) for p in ("liggghts", "yade")]
        order = sorted(es, key=lambda e: (e.code != "demcli", PEER_ORDER.index(e.code) if e.code in PEER_ORDER
                                          else -1, e.threads, e.note))
        for e in order:
            if e.reference is not None:
                runs = " / ".join(fmt(x) for x in e.reference) + " (ref)"
            else:
                runs = " / ".join(fmt(r["rate"]) if r["rate"] is not None else "fail" for r in e.runs) or "—"
            med = e.median
            ratios = " | ".join(f"{med / base:.2f}{note}" if med is not None and base else "—"
                                for base, note in bases)
            reb = next((r["kv"].get("neighbour_rebuilds") for r in reversed(e.runs)
                        if "neighbour_rebuilds" in r["kv"]), "—")
            rows.append(f"| {scene} | {e.label()} | {e.threads} | {runs} | {fmt(med)} | {ratios} | "
                        f"{contacts(e)} | {reb} |")
    return rows


def scaling_table(entries, repeat):
    """One row per code and N; each code's cost is relative to its own smallest N."""
    head = ["code", "N", "particle-steps/s " + " / ".join(f"run{k + 1}" for k in range(repeat)), "median",
            "ns per particle-step", "cost relative to first N", "contacts at end"]
    rows = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    first = {}
    for e in entries:
        med = e.median
        if e.code not in first and med:
            first[e.code] = med
        runs = " / ".join(fmt(r["rate"]) if r["rate"] is not None else "fail" for r in e.runs)
        rel = f"{first[e.code] / med:.2f}" if med and e.code in first else "—"
        rows.append(f"| {e.label()} | {e.scene.split('_')[1]} | {runs} | {fmt(med)} | "
                    f"{1e9 / med if med else float('nan'):.1f} | {rel} | {contacts(e)} |")
    return rows


def run_sieve(quick):
    path = os.path.join(HERE, "bench_sieve.py")
    if not os.path.exists(path):
        return None
    cmd = [sys.executable, path] + (["100", "2"] if quick else [])
    print(f"  [{time.strftime('%H:%M:%S')}] {os.path.relpath(path, ROOT)} ...", end="", flush=True)
    try:
        out = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             timeout=900)
        lines = [ln for ln in out.stdout.splitlines() if ln.strip()]
        ok = out.returncode == 0 and lines and lines[-1].startswith("sieve_sizes_per_s=")
    except subprocess.TimeoutExpired:
        lines, ok = ["killed after 900 s"], False
    text = " ; ".join(lines[-2:]) if ok else "FAILED: " + " | ".join(lines[-3:])[-300:]
    print(" " + text, flush=True)
    return " ".join(shlex.quote(c) for c in ["python"] + cmd[1:]).replace(ROOT + "/", ""), text


def run_block_script(a, name, args, last_prefix):
    """bench/<name>.py, whose output holds a Markdown block between ``<!-- name:begin -->`` and
    ``<!-- name:end -->`` and ends with a ``last_prefix...`` line: (command, the block or a
    FAILED line), None when the script is missing."""
    path = os.path.join(HERE, f"{name}.py")
    if not os.path.exists(path):
        return None
    cmd = [sys.executable, path] + list(args)
    print(f"  [{time.strftime('%H:%M:%S')}] {os.path.relpath(path, ROOT)} (load {load()}) ...", flush=True)
    try:
        out = subprocess.run(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                             timeout=a.timeout)
        text, rc = out.stdout, out.returncode
    except subprocess.TimeoutExpired as e:
        text = e.stdout.decode(errors="replace") if isinstance(e.stdout, bytes) else (e.stdout or "")
        rc = f"killed after {a.timeout:.0f} s"
    lines = [ln for ln in text.splitlines() if ln.strip()]
    for ln in lines:
        if ln.startswith("  ["):
            print("  " + ln.strip(), flush=True)
    m = re.search(rf"<!-- {name}:begin -->\n(.*?)\n<!-- {name}:end -->", text, re.S)
    ok = rc == 0 and m is not None and lines and lines[-1].startswith(last_prefix)
    block = m.group(1) if ok else f"FAILED (rc={rc}): " + " | ".join(lines[-3:])[-300:]
    print("  " + (lines[-1] if ok else block), flush=True)
    return " ".join(shlex.quote(c) for c in ["python"] + cmd[1:]).replace(ROOT + "/", ""), block


def run_asphalt(a):
    """bench/bench_asphalt.py: (command, markdown block or a FAILED line)."""
    args = (["--quick"] if a.quick else []) + (["--spacings", a.asphalt_spacings] if a.asphalt_spacings else [])
    return run_block_script(a, "bench_asphalt", args, "asphalt_compact_exponent=")


def run_loaded_bed(a, env0, yade, work):
    """The loaded bed (bench_loaded_bed.py) on 1 and 2 threads and, with YADE installed, the same bed
    in YADE Polyhedra (yade_loaded_bed.py on the bed the first exports), alternated a.repeat times:
    Markdown table rows."""
    bed = os.path.join(work, "loaded_bed.npz")
    steps = ["--steps", "100", "--repeat", "1"] if a.quick else []
    runs = [(f"demcli t={t}", [sys.executable, os.path.join(HERE, "bench_loaded_bed.py"), "--threads", str(t)]
             + steps) for t in (1, 2)]
    # the approximate option (contact.geometry_refresh, docs/ballast_box.md): exact every 8th step, linearized between
    runs += [(f"demcli t={t}, geometry refresh 8", [sys.executable, os.path.join(HERE, "bench_loaded_bed.py"),
                                                    "--threads", str(t), "--refresh", "8"] + steps) for t in (1, 2)]
    if yade:
        print(f"  [{time.strftime('%H:%M:%S')}] loaded bed: export for YADE ...", flush=True)
        rec = run_proc([sys.executable, os.path.join(HERE, "bench_loaded_bed.py"), "--export", bed], ROOT,
                       dict(env0), a.timeout)
        if os.path.exists(bed):
            runs.append(("YADE Polyhedra", ["yade", "-j1", "-n", "-x", os.path.join(HERE, "yade_loaded_bed.py"), bed]
                         + (["50", "1"] if a.quick else [])))
        else:
            print(f"    export failed: {rec['error'] or rec['last']}", flush=True)
    out = {label: [] for label, _ in runs}
    for k in range(1, a.repeat + 1):
        for label, cmd in runs:
            print(f"  [{time.strftime('%H:%M:%S')}] loaded bed {label} run {k} (load {load()}) ...", flush=True)
            rec = run_proc(cmd, ROOT, dict(env0, OMP_NUM_THREADS="1"), a.timeout)
            line = next((ln for ln in reversed(rec["lines"]) if " body-steps/s" in ln), rec["error"] or "?")
            print(f"    {line}", flush=True)
            out[label].append((rec["rate"], line, " ".join(["python"] + cmd[1:]) if cmd[0] == sys.executable
                               else " ".join(cmd)))
    rows = ["| code | median body-steps/s | runs | x YADE | last run |", "|---|---|---|---|---|"]
    ref = [r for r, _, _ in out.get("YADE Polyhedra", []) if r]
    yade_med = statistics.median(ref) if ref else None
    for label, recs in out.items():
        rates = [r for r, _, _ in recs if r]
        med = statistics.median(rates) if rates else None
        ratio = f"{med / yade_med:.0f}" if med and yade_med else ""
        rows.append(f"| {label} | {fmt(med)} | {', '.join(fmt(r) for r in rates)} | {ratio} | "
                    f"{recs[-1][1].split('): ')[-1].replace('|', '/')} |")
    rows += ["", "Commands: " + "; ".join(f"`{recs[0][2].replace(ROOT + '/', '')}`" for recs in out.values())]
    return rows


def run_jit(a):
    """bench/bench_jit.py (cold and warm compile): (command, markdown block or a FAILED line)."""
    return run_block_script(a, "bench_jit", [], "jit_cold_s=")


def clump_table(entries):
    """Clump scenes: the fall phase and the state at the end of the window, per code (last run)."""
    rows = ["| scene | code | threads | fall phase particle-steps/s (median) | window particle-steps/s (median) | "
            "clump-steps/s (median) | contacts at end (p-p + wall) | highest clump centre mm | "
            "kinetic energy J |", "|" + "---|" * 9]
    for e in sorted(entries, key=lambda e: (e.scene, e.code != "demcli", e.threads)):
        if not e.scene.startswith("clump_") or not e.runs:
            continue
        ok = [r for r in e.runs if r["rate"] is not None]
        kv = ok[-1]["kv"] if ok else {}

        def med(key):
            vals = [float(r["kv"][key]) for r in ok if key in r["kv"]]
            return fmt(statistics.median(vals)) if vals else "—"

        rows.append(f"| {e.scene} | {e.label()} | {e.threads} | {med('fall_particle_steps_per_s')} | {fmt(e.median)} "
                    f"| {med('clump_steps_per_s')} | {contacts(e)} | {kv.get('zmax_mm', '—')} | "
                    f"{kv.get('kinetic_energy_J', '— (not printed)')} |")
    return rows if len(rows) > 2 else []


def main(argv=None):
    a = parse_args(argv)
    import demcli  # the venv's demcli (version line only)

    started = datetime.datetime.now().astimezone()
    load0 = load()
    digest0 = source_digest()
    git0 = sh("git -C " + shlex.quote(ROOT) + " rev-parse --short HEAD") or "?"
    command = "python bench/run_bench.py" + "".join(" " + shlex.quote(x) for x in (argv if argv is not None
                                                                                   else sys.argv[1:]))
    print(f"demcli {demcli.__version__} bench, {started:%Y-%m-%d %H:%M %Z}, {machine()}, load {load0}")

    # which peers can run
    installed = []
    if not a.skip_peers:
        missing = [p for p in a.peer_list if shutil.which(PEER_BIN[p]) is None]
        installed = [p for p in a.peer_list if p not in missing]
        if not os.path.isdir(a.peers_dir):
            print(f"NOTE: no peers folder at {a.peers_dir}: demcli only (set --peers-dir or $DEMCLI_PEERS)")
            installed, missing = [], []
        elif missing:
            print(f"NOTE: peer(s) not installed: {', '.join(PEER_BIN[p] for p in missing)}. Install them with\n"
                  f"      bash {os.path.relpath(os.path.join(a.peers_dir, 'install.sh'), ROOT)}   "
                  f"(as root; Debian packages, ~1.5 min, 2.3 GB)\n"
                  f"      Going on with {', '.join(['demcli'] + installed)}; missing peers are shown with "
                  f"their ../shared/peers/RESULTS.md figures.")
    refs = reference_rows(a.peers_dir) if os.path.isdir(a.peers_dir) else {}
    if not os.path.isfile(os.path.join(a.peers_dir, "common", "clump_setup.py")):
        dropped = [f"{v}_{n}" for v, n in a.scene_list if v == "clump"]
        if dropped:
            print(f"NOTE: no {os.path.join(a.peers_dir, 'common', 'clump_setup.py')}: leaving out "
                  f"{', '.join(dropped)} (the clump scene is defined there)")
        a.scene_list = [(v, n) for v, n in a.scene_list if v != "clump"]

    work = tempfile.mkdtemp(prefix="demcli_bench_peers_")
    env0 = dict(os.environ)
    entries = []
    for variant, n in a.scene_list:
        steps = scene_steps(a, variant)
        dem = demcli_entries(a, variant, n, steps, a.thread_list, not a.no_passive, env0)
        peers = [] if a.skip_peers else peer_entries(a, variant, n, steps, installed, refs, work)
        for e in peers:
            ref = refs.get((e.code, variant, n))
            e.refback = ref[0] if ref_matches(ref, steps, a.clump_settle if variant == "clump" else None) \
                else None
        entries.append(interleave(dem, peers))

    print(f"scenes: {', '.join(f'{v}_{n}' for v, n in a.scene_list)}, {a.steps} steps, {a.repeat} run(s) each, "
          f"alternating")
    for k in range(1, a.repeat + 1):
        for group in entries:
            for e in group:
                run_entry(e, k)
    flat = [e for g in entries for e in g]

    scaling = []
    if not a.no_scaling:
        ns = [1000, 10000] + ([] if a.quick else [100000]) + ([1000000] if a.big else [])
        scaling = [demcli_entries(a, "dense", n, a.scaling_steps, [1], False, env0)[0] for n in ns]
        if "liggghts" in installed and not a.skip_peers:
            lig = argparse.Namespace(**{**vars(a), "peer_list": ["liggghts"]})
            scaling += [peer_entries(lig, "dense", n, a.scaling_steps, installed, {}, work)[0] for n in ns]
        print(f"scaling row: {', '.join(sorted({e.code for e in scaling}))}, 1 thread, dense, "
              f"N = {', '.join(map(str, ns))}, {a.scaling_steps} steps")
        for k in range(1, a.repeat + 1):
            for e in scaling:
                run_entry(e, k)

    sieve = None if a.no_sieve else run_sieve(a.quick)
    asphalt = None if a.no_asphalt else run_asphalt(a)
    jit = None if (a.no_jit or a.quick) else run_jit(a)
    bed = None if a.no_extras else run_loaded_bed(a, env0, "yade" in installed and not a.skip_peers, work)
    packed = None if a.no_extras else run_block_script(
        a, "bench_packed_bed", ["--peers", ",".join(p for p in installed if p != "yade"), "--peers-dir", a.peers_dir]
        + (["--n", "2000", "--steps", "2000", "--repeat", "1", "--settle", "100000"] if a.quick else
           ["--repeat", str(a.repeat)]), "packed_bed_demcli_1t=")
    # 2D sections; ballast library build rate; polyhedron narrow phase; a bonded specimen (no peer has these)
    others = []
    extras = [("bench_polygons.py", [], ["--quick"]), ("bench_library.py", [], ["--quick"]),
              ("bench_polyhedra.py", [], []), ("bench_bonds.py", [], ["--steps", "2000"])]
    for script, args, qargs in ([] if a.no_extras else extras):
        args = qargs if a.quick else args
        cmd = [sys.executable, os.path.join(HERE, script)] + args
        print(f"  [{time.strftime('%H:%M:%S')}] {script} (load {load()}) ...", flush=True)
        rec = run_proc(cmd, ROOT, dict(env0), a.timeout)
        last = rec["last"] or rec["error"] or "no output"
        text = next((ln for ln in reversed(rec["lines"]) if " body-steps/s" in ln), last)
        print(f"    {text}", flush=True)
        others.append((" ".join(["python", "bench/" + script] + args), text))
    load1 = load()
    digest1 = source_digest()
    git1 = sh("git -C " + shlex.quote(ROOT) + " rev-parse --short HEAD") or "?"
    finished = datetime.datetime.now().astimezone()
    shutil.rmtree(work, ignore_errors=True)

    md = [f"# demcli benchmark: {started:%Y-%m-%d %H:%M %Z}", "",
          f"- demcli {demcli.__version__} (git {git0}{'' if git1 == git0 else ' -> ' + git1}"
          f"{', uncommitted changes' if sh('git -C ' + shlex.quote(ROOT) + ' status --porcelain') else ''}), "
          f"Python {platform.python_version()}"
          + ("" if digest0 == digest1 else "; **WARNING: demcli's sources changed during the run**, runs "
             "before and after the change used different code (a jump in warmup_s marks the recompile)"),
          f"- machine: {machine()}",
          f"- load average (1/5/15 min): {load0} at start, {load1} at the end "
          f"({(finished - started).total_seconds() / 60:.1f} min)",
          f"- command: `{command}`",
          f"- scenes: the peers' scenes (spheres: ../shared/peers/common/drop_setup.py), {a.steps} steps, "
          f"dt 1e-6 s; each entry run {a.repeat}x, alternating demcli and peers; the median is the figure to compare",
          *([f"- clump_NC: NC rigid clumps of 5-10 overlapping spheres r = 1 mm "
             f"(../shared/peers/common/clump_setup.py), {a.clump_settle} fall steps (not in the rate), then the "
             f"{a.steps}-step window; counted per member sphere; demcli clump mass = union of the members "
             "(overlaps once), YADE's = sum of the members (see bench/scene_clumps.py); YADE is the only peer "
             "with this scene"] if any(v == "clump" for v, _ in a.scene_list) else []),
          *([f"- poly_N: N random convex polyhedra (10-20 mm) falling from a lattice into a closed box, "
             f"{a.poly_steps} steps at dt 2e-5 s, rho 2600, E 1e9 Pa (bench/scene_poly.py, peers/yade/poly.py); "
             "counted per polyhedron; YADE Polyhedra is the only peer with this scene"]
            if any(v == "poly" for v, _ in a.scene_list) else []),
          f"- demcli skin {a.skin:g} r = {a.skin:g} mm; LIGGGHTS/LAMMPS skin {a.peer_skin * 1e3:g} mm "
          f"(DROP_SKIN={a.peer_skin:g}); YADE verletDist 0.5 r (its default, drop.py has no option); "
          "peers single-threaded (OMP_NUM_THREADS=1, one MPI rank, yade -j1)",
          "- particle-steps/s = N x steps / seconds of the time-stepping loop only (no start-up, set-up or JIT)",
          ""]
    md += scene_table(flat, refs, a.repeat, a)
    ctab = clump_table(flat)
    if ctab:
        md += ["", f"Clump scene, fall phase ({a.clump_settle} steps) and state at the end of the window "
                   "(last run of each entry):", ""] + ctab
    if scaling:
        md += ["", f"Scaling (1 thread, dense scene, {a.scaling_steps} steps from the initial lattice; "
                   "the cost per particle-step should stay flat):", ""]
        md += scaling_table(scaling, a.repeat)
    if sieve:
        md += ["", f"Geometry toolkit: `{sieve[0]}`: {sieve[1]}"]
    if asphalt:
        md += ["", f"3D asphalt, Marshall pipeline against the lattice ball size (`{asphalt[0]}`; "
                   "see docs/asphalt3d.md, \"Cost against ball size\"):", "", asphalt[1]]
    if jit:
        md += ["", f"JIT compile: seconds in numba's compiler lock (compiling, or loading from the cache) and the "
                   f"whole `demcli run`'s wall and CPU time, with an empty numba cache (cold) and from it (warm), "
                   f"one thread (`{jit[0]}`):", "", jit[1]]
    if packed:
        md += ["", f"Packed sphere bed (coordination 4-6; the peers' scenes above have ~0.3 contacts per sphere), "
                   f"demcli against LIGGGHTS and LAMMPS with the peers' own inputs (`{packed[0]}`):", "", packed[1]]
    if bed:
        md += ["", "Loaded polyhedral bed (the ballast box's real workload): the quickstart's sleeper bed under its "
                   "peak load, built by `bench/bench_loaded_bed.py` from the shipped case, the same bed in YADE "
                   "Polyhedra (`bench/yade_loaded_bed.py`: the same stones, load, walls, dt, friction and damping, its "
                   "volumetric law at our contact stiffness at the median contact area), runs alternated:", ""] + bed
    if others:
        md += ["", "demcli only (no peer has these): each script's figure line, one run:", ""]
        md += [f"- `{cmd}`: `{last}`" for cmd, last in others]
    fails = [(e, r) for e in flat + scaling for r in e.runs if r["rate"] is None]
    if fails:
        md += ["", "Failed runs:"] + [f"- {e.scene} {e.label()}: {r['error']}" for e, r in fails]
    md += ["", "<details><summary>runs (load average before each run, command)</summary>", ""]
    for e in flat + scaling:
        for k, r in enumerate(e.runs, 1):
            kv = r["kv"]
            extra = "".join(f", {name} {kv[key]}" for key, name in (
                ("contacts_total", "contacts"), ("neighbour_rebuilds", "rebuilds"), ("warmup_s", "warmup_s"))
                if key in kv)
            md.append(f"- {e.scene} {e.label()} t={e.threads} run{k}: {fmt(r['rate'])} particle-steps/s, "
                      f"loop {kv.get('loop_wall_s', '?')} s, process {r['process_s']:.1f} s{extra}, "
                      f"load {r['load_before']}: `{r['cmd'].replace(ROOT + '/', '')}`")
    md += ["", "</details>", ""]
    text = "\n".join(md)
    print()
    print(text)
    if a.out:
        with open(a.out, "w", encoding="utf-8") as f:
            f.write(text)
        print(f"written to {os.path.relpath(a.out)}")
    return 0 if not fails else 1


if __name__ == "__main__":
    sys.exit(main())
