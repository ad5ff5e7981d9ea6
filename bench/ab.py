"""A/B benchmark: two source trees of demcli in one benchmark run (issue #28's guards).

Usage:
  python bench/ab.py --before REF [--after WORKTREE|REF] [--repeat K] [--scenes S,...] [--threads 1,2]
                     [--steps N] [--clump-settle N] [--poly-steps N] [--bed-steps N] [--jit] [--out FILE]

* ``--before REF`` (a git ref) is checked out with ``git worktree add --detach
  /tmp/demcli-ab/<sha12> REF`` (reused when present); ``--after`` is the current working
  tree by default, or another folder, or a ref (checked out the same way).
* Every run is its own process, in the tree's folder, with ``PYTHONPATH=<tree>`` (ahead of the
  venv's editable demcli; checked before anything runs: ``import demcli`` must resolve inside
  the tree, the two paths are printed in the header) and the tree's own ``bench/`` script,
  so that each tree's scripts call its own engine classes. A script the before tree lacks is
  copied from the after tree into the before worktree's ``bench/`` (only into a worktree under
  /tmp/demcli-ab; with the before tree's demcli) and the table says so.
* Each tree has its own ``NUMBA_CACHE_DIR`` (``/tmp/demcli-ab/cache-<tag>``) and, for the loaded
  bed, its own ``DEMCLI_BENCH_CACHE`` (``/tmp/demcli-ab/bed-<tag>``): one untimed warm-up run per
  tree and scene compiles the kernels (and builds the settled bed) first; the timed runs load
  them from the cache (the scripts time their stepping loops only, after their own warm-up).
* Rounds: for k = 1..K, for every scene and thread count: before, after (B A B A ...).
  The table gives both medians, after/before (> 1: after is faster), and every run.
* ``--jit``: ``bench/bench_jit.py`` in each tree (cold: empty numba cache; warm: from it), the
  JIT seconds (time in numba's compiler lock) side by side (after/before < 1: after compiles less).

Scenes: ``dense_N`` / ``drop_N`` (bench_spheres.py N VARIANT STEPS THREADS), ``clump_N``
(bench_clumps.py N SETTLE STEPS THREADS; needs ../shared/peers or $DEMCLI_PEERS),
``poly_N`` (bench_poly.py --n N --steps POLY_STEPS --threads T), ``loaded_bed``
(bench_loaded_bed.py --steps BED_STEPS --threads T: the quickstart's sleeper bed at its peak
load, body-steps/s). Each script's last line is ``particle_steps_per_s=<number>``.
"""

import argparse
import datetime
import hashlib
import os
import platform
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
BASE = "/tmp/demcli-ab"
DEFAULT_SCENES = "dense_10000,clump_500,poly_500,loaded_bed"
SCENE = re.compile(r"(drop|dense|clump|poly)_(\d+)|loaded_bed")
RATE = re.compile(r"particle_steps_per_s=([0-9.eE+-]+)\s*$")
KV = re.compile(r"([A-Za-z_][A-Za-z_0-9]*)=([^\s]+)")
SCRIPT = {"drop": "bench_spheres.py", "dense": "bench_spheres.py", "clump": "bench_clumps.py",
          "poly": "bench_poly.py", "loaded_bed": "bench_loaded_bed.py"}
PROBE = os.path.join(BASE, "probe")
# on PYTHONPATH after the tree: every benchmark process reports (on stderr, at exit) where demcli came from
PROBE_SRC = """import atexit, sys


def _ab_report():
    m = sys.modules.get("demcli")
    if m is not None:
        sys.stderr.write("ab_demcli_file=%s\\n" % getattr(m, "__file__", "?"))


atexit.register(_ab_report)
"""
PROBE_RE = re.compile(r"^ab_demcli_file=(.*)$", re.M)
PEERS_DEFAULT = os.environ.get("DEMCLI_PEERS") or os.path.normpath(os.path.join(ROOT, "..", "shared", "peers"))


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--before", required=True, help="git ref of the 'before' tree (e.g. a commit before the redesign)")
    ap.add_argument("--after", default=None,
                    help="the 'after' tree: a folder (a demcli checkout) or a git ref (default: this working tree)")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs per tree, scene and thread count (default 3)")
    ap.add_argument("--scenes", default=DEFAULT_SCENES,
                    help=f"comma list of dense_N, drop_N, clump_N, poly_N, loaded_bed (default {DEFAULT_SCENES})")
    ap.add_argument("--threads", default="1,2", help="thread counts (default 1,2)")
    ap.add_argument("--steps", type=int, default=20000, help="steps of the sphere scenes and of the clump window "
                                                             "(default 20000)")
    ap.add_argument("--clump-settle", type=int, default=100000,
                    help="fall steps before the clump window (default 100000, as make bench)")
    ap.add_argument("--poly-steps", type=int, default=10000, help="steps of poly_N (default 10000, as make bench)")
    ap.add_argument("--bed-steps", type=int, default=200,
                    help="steps per timed window of loaded_bed (default 200; the script times 3 windows and "
                         "prints their median)")
    ap.add_argument("--bed-case", default=None,
                    help="case of loaded_bed (default: the script's, cases/quickstart.yaml)")
    ap.add_argument("--skin", type=float, default=0.3, help="Verlet skin / radius of the sphere and clump scenes")
    ap.add_argument("--peers-dir", default=PEERS_DEFAULT, help="peers/ folder for clump_N (DEMCLI_PEERS)")
    ap.add_argument("--jit", action="store_true", help="also bench/bench_jit.py in each tree (cold/warm JIT)")
    ap.add_argument("--jit-cases", default=None,
                    help="comma list of case files for --jit (default: bench_jit.py's own two smoke cases)")
    ap.add_argument("--no-warmup", action="store_true", help="skip the untimed warm-up runs (caches already full)")
    ap.add_argument("--timeout", type=float, default=1800.0, help="kill any single run after this many seconds")
    ap.add_argument("--dry-run", action="store_true",
                    help="set up the trees, show where demcli resolves in each and the commands; run nothing")
    ap.add_argument("--out", default=os.path.join(HERE, "ab_results.md"),
                    help="Markdown file to write (default bench/ab_results.md; '' for none)")
    a = ap.parse_args(argv)
    a.scene_list = [s.strip() for s in a.scenes.split(",") if s.strip()]
    for s in a.scene_list:
        if not SCENE.fullmatch(s):
            ap.error(f"bad scene {s!r}: expected dense_N, drop_N, clump_N, poly_N or loaded_bed")
    a.thread_list = [int(t) for t in a.threads.split(",") if t.strip()]
    if a.repeat < 1 or not a.thread_list:
        ap.error("--repeat must be >= 1 and --threads not empty")
    if not a.scene_list and not a.jit:
        ap.error("nothing to run: --scenes is empty and no --jit")
    return a


# ---------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------
def git(*args, cwd=ROOT, check=True):
    p = subprocess.run(["git", "-C", cwd, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if check and p.returncode != 0:
        sys.exit(f"git {' '.join(args)} failed: {p.stderr.strip()}")
    return p.stdout.strip()


def sh(cmd):
    try:
        return subprocess.run(cmd, shell=True, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                              timeout=20).stdout.strip()
    except Exception:  # noqa: BLE001 - informational only
        return ""


def machine():
    model = re.search(r"Model name:\s*(.+)", sh("lscpu"))
    mem = re.search(r"Mem:\s+(\S+)", sh("free -h"))
    return (f"{model.group(1).strip() if model else platform.processor() or '?'}, {os.cpu_count()} cores, "
            f"{mem.group(1) if mem else '?'} RAM, {platform.system()} {platform.release()}, "
            f"Python {platform.python_version()}")


def load():
    return "%.2f %.2f %.2f" % os.getloadavg()


def fmt(x):
    return "—" if x is None else f"{x:.3g}"


def source_digest(path):
    """Digest of a tree's demcli/*.py and bench/*.py (the working tree is shared: a change is reported)."""
    h = hashlib.sha1()
    for sub in ("demcli", "bench"):
        for dirpath, dirnames, files in sorted(os.walk(os.path.join(path, sub))):
            dirnames.sort()
            for fn in sorted(files):
                if fn.endswith(".py"):
                    with open(os.path.join(dirpath, fn), "rb") as f:
                        h.update(fn.encode() + f.read())
    return h.hexdigest()[:12]


def inside(path, folder):
    return bool(path) and os.path.realpath(path).startswith(os.path.realpath(folder) + os.sep)


class Tree:
    """One side of the comparison: a folder holding demcli/ and bench/."""

    def __init__(self, side, spec):
        self.side, self.spec = side, spec
        self.borrowed = []      # bench/ files copied in from the other tree
        if spec is None or os.path.isdir(spec):
            self.path = os.path.abspath(spec or ROOT)
            self.managed = False
            self.sha = git("rev-parse", "HEAD", cwd=self.path, check=False) or "?"
            dirty = bool(git("status", "--porcelain", "--", "demcli", "bench", cwd=self.path, check=False))
            self.desc = (f"working tree {self.path} at {self.sha[:12]}"
                         + (" + uncommitted changes in demcli/ or bench/" if dirty else ""))
            self.tag = f"wt-{self.sha[:12]}" + ("-dirty" if dirty else "")
        else:
            self.sha = git("rev-parse", "--verify", f"{spec}^{{commit}}")
            self.path = os.path.join(BASE, self.sha[:12])
            self.managed = True
            if os.path.isdir(self.path):
                have = git("rev-parse", "HEAD", cwd=self.path, check=False)
                if have != self.sha:
                    sys.exit(f"{self.path} exists but is at {have or '?'} not {self.sha}: remove it "
                             f"(git worktree remove --force {self.path})")
            else:
                os.makedirs(BASE, exist_ok=True)
                git("worktree", "add", "--detach", self.path, self.sha)
            subject = git("log", "-1", "--format=%s", self.sha)
            self.desc = f"`{spec}` = {self.sha[:12]} ({subject[:70]}), worktree {self.path}"
            self.tag = self.sha[:12]
        self.cache = os.path.join(BASE, f"cache-{self.tag}")
        self.bed_cache = os.path.join(BASE, f"bed-{self.tag}")
        self.demcli_file = None

    def tracked(self, rel):
        if not self.managed:
            return os.path.isfile(os.path.join(self.path, rel))
        return subprocess.run(["git", "-C", self.path, "cat-file", "-e", f"HEAD:{rel}"],
                              stderr=subprocess.DEVNULL).returncode == 0

    def borrow_missing(self, other, scripts):
        """Copy into this (managed) tree's bench/ the ``scripts`` it lacks, from ``other``, with the
        bench/ modules they import that it lacks too."""
        if not self.managed:
            return
        todo = list(scripts)
        while todo:
            fn = todo.pop()
            rel, src = f"bench/{fn}", os.path.join(other.path, "bench", fn)
            if fn in self.borrowed or self.tracked(rel) or not os.path.isfile(src):
                continue
            shutil.copy2(src, os.path.join(self.path, rel))
            self.borrowed.append(fn)
            with open(src, encoding="utf-8") as f:
                todo += [f"{m}.py" for m in re.findall(r"^\s*(?:from|import)\s+(\w+)", f.read(), re.M)]

    def env(self, threads=None):
        env = dict(os.environ, PYTHONPATH=self.path + os.pathsep + PROBE, NUMBA_CACHE_DIR=self.cache,
                   DEMCLI_NUMBA_CACHE="1",
                   DEMCLI_BENCH_CACHE=self.bed_cache, PYTHONDONTWRITEBYTECODE="1")
        env.pop("NUMBA_DISABLE_JIT", None)
        return env

    def check_import(self):
        """Where ``import demcli`` resolves with this tree's environment (must be inside the tree)."""
        p = subprocess.run([sys.executable, "-c", "import demcli; print(demcli.__file__)"], cwd=self.path,
                           env=self.env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.demcli_file = p.stdout.strip().splitlines()[-1] if p.stdout.strip() else None
        if not inside(self.demcli_file, self.path):
            sys.exit(f"{self.side}: import demcli resolves to {self.demcli_file} (not inside {self.path}); "
                     f"stderr: {p.stderr.strip()[-500:]}")


def script_cmd(tree, scene, threads, a, warm=False):
    """(argv, script name) of one run of ``scene`` in ``tree``."""
    m = SCENE.fullmatch(scene)
    variant = "loaded_bed" if scene == "loaded_bed" else m.group(1)
    script = os.path.join(tree.path, "bench", SCRIPT[variant])
    py = [sys.executable, script]
    if variant in ("drop", "dense"):
        n = int(m.group(2))
        args = ([str(min(n, 1000)), variant, "10"] if warm else [str(n), variant, str(a.steps)]) + \
            [str(threads), "--skin", repr(a.skin)]
    elif variant == "clump":
        n = int(m.group(2))
        args = (["8", "10", "10"] if warm else [str(n), str(a.clump_settle), str(a.steps)]) + \
            [str(threads), "--skin", repr(a.skin)]
    elif variant == "poly":
        n = int(m.group(2))
        args = ["--n", str(min(n, 20) if warm else n), "--steps", "10" if warm else str(a.poly_steps),
                "--threads", str(threads)]
    else:
        args = ([a.bed_case] if a.bed_case else []) + \
            ["--steps", "5" if warm else str(a.bed_steps), "--threads", str(threads)] + \
            (["--repeat", "1"] if warm else [])
    return py + args, SCRIPT[variant]


def run_proc(cmd, tree, timeout, extra_env=None):
    """One benchmark process: a record with the rate (None when it failed) and the parsed key=value figures."""
    rec = {"cmd": " ".join(shlex.quote(c) for c in cmd), "load_before": load(), "rate": None, "kv": {},
           "error": None, "stdout": ""}
    env = tree.env()
    env.update(extra_env or {})
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, cwd=tree.path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                           timeout=timeout)
        out, err, rc = p.stdout, p.stderr, p.returncode
    except subprocess.TimeoutExpired as e:
        def dec(x):
            return x.decode(errors="replace") if isinstance(x, bytes) else (x or "")
        out, err, rc = dec(e.stdout), dec(e.stderr), f"killed after {timeout:.0f} s"
    rec["process_s"] = time.perf_counter() - t0
    rec["stdout"] = out
    used = PROBE_RE.findall(err or "")
    rec["demcli_file"] = used[-1] if used else None
    if used and not inside(used[-1], tree.path):
        rc = f"{rc}, but demcli came from {used[-1]}, not from {tree.path}"
    lines = [ln for ln in out.splitlines() if ln.strip()]
    m = RATE.search(lines[-1]) if lines else None
    if rc == 0 and m and not (used and not inside(used[-1], tree.path)):
        rec["rate"] = float(m.group(1))
    else:
        tail = [ln for ln in (PROBE_RE.sub("", err or "") or out).splitlines()
                if ln.strip() and ln.strip().strip("^~") != ""][-4:]
        rec["error"] = f"rc={rc}: " + (" | ".join(tail)[-600:] or "no output")
    for ln in lines:
        if not ln.startswith(("progress", "breakdown", "phase1_fall")):
            for k, v in KV.findall(ln):
                rec["kv"][k] = v
    return rec


class Entry:
    def __init__(self, scene, threads, tree, cmd, script):
        self.scene, self.threads, self.tree, self.cmd, self.script = scene, threads, tree, cmd, script
        self.runs = []

    @property
    def rates(self):
        return [r["rate"] for r in self.runs if r["rate"] is not None]

    @property
    def median(self):
        return statistics.median(self.rates) if self.rates else None


def run_jit(tree, a):
    """bench/bench_jit.py in ``tree``: {case: (cold JIT s, cold CPU s, warm JIT s)}, record."""
    cmd = [sys.executable, os.path.join(tree.path, "bench", "bench_jit.py")] + \
        ([c.strip() for c in a.jit_cases.split(",")] if a.jit_cases else [])
    print(f"  [{time.strftime('%H:%M:%S')}] {tree.side}: bench_jit.py (load {load()}) ...", flush=True)
    rec = run_proc(cmd, tree, a.timeout)
    rows = {}
    for ln in rec["stdout"].splitlines():
        cells = [c.strip() for c in ln.strip().strip("|").split("|")]
        if len(cells) >= 7 and cells[0].startswith("`"):
            try:
                rows[cells[0].strip("`")] = (float(cells[3]), float(cells[2]), float(cells[6]))
            except ValueError:
                pass
    last = [ln for ln in rec["stdout"].splitlines() if ln.strip()]
    ok = last and last[-1].startswith("jit_cold_s=") and rows
    if ok:
        rec["error"] = None   # run_proc looks for a particle_steps_per_s line; bench_jit ends with jit_cold_s=
    elif rec["error"] is None or rec["error"].startswith("rc=0:"):   # exit 0 but no table / last line
        rec["error"] = "no jit_cold_s line / table: " + " | ".join(last[-3:])[-400:]
    print(f"    {last[-1] if ok else 'FAILED ' + str(rec['error'])}", flush=True)
    return rows, rec


# ---------------------------------------------------------------------------------------
def main(argv=None):
    a = parse_args(argv)
    started = datetime.datetime.now().astimezone()
    load0 = load()
    command = "python bench/ab.py" + "".join(" " + shlex.quote(x) for x in (argv if argv is not None
                                                                             else sys.argv[1:]))
    before = Tree("before", a.before)
    after = Tree("after", a.after)
    if before.path == after.path:
        sys.exit(f"--before and --after are the same tree ({before.path})")
    needed = {SCRIPT["loaded_bed" if s == "loaded_bed" else SCENE.fullmatch(s).group(1)] for s in a.scene_list}
    before.borrow_missing(after, sorted(needed | ({"bench_jit.py"} if a.jit else set())))
    os.makedirs(PROBE, exist_ok=True)
    with open(os.path.join(PROBE, "sitecustomize.py"), "w", encoding="utf-8") as f:
        f.write(PROBE_SRC)
    for t in (before, after):
        t.check_import()
    digest0 = {t.side: source_digest(t.path) for t in (before, after)}
    os.makedirs(BASE, exist_ok=True)
    print(f"demcli A/B bench, {started:%Y-%m-%d %H:%M %Z}, {machine()}, load {load0}")
    for t in (before, after):
        print(f"  {t.side}: {t.desc}\n    import demcli -> {t.demcli_file}\n    NUMBA_CACHE_DIR={t.cache}"
              + (f"\n    borrowed from the after tree: {', '.join(t.borrowed)}" if t.borrowed else ""))

    # entries, grouped per (scene, threads): [before, after]
    groups = []
    for scene in a.scene_list:
        for th in a.thread_list:
            pair = []
            for t in (before, after):
                cmd, script = script_cmd(t, scene, th, a)
                pair.append(Entry(scene, th, t, cmd, script))
            groups.append(pair)
    env_extra = {"DEMCLI_PEERS": a.peers_dir}
    if a.dry_run:
        for pair in groups:
            for e in pair:
                print(f"  {e.scene} t={e.threads} {e.tree.side}: (cd {e.tree.path}; PYTHONPATH={e.tree.path} "
                      f"NUMBA_CACHE_DIR={e.tree.cache} {' '.join(e.cmd)})")
        return 0

    # untimed warm-up: compile each tree's kernels into its cache (and build the loaded bed)
    warm_fail = []
    if not a.no_warmup:
        for scene in a.scene_list:
            for t in (before, after):
                cmd, _ = script_cmd(t, scene, max(a.thread_list), a, warm=True)
                print(f"  [{time.strftime('%H:%M:%S')}] warm-up {scene} {t.side} ...", end="", flush=True)
                rec = run_proc(cmd, t, a.timeout, env_extra)
                print(f" {rec['process_s']:.1f} s" + (f" FAILED {rec['error']}" if rec["error"] else ""), flush=True)
                if rec["error"]:
                    warm_fail.append(f"warm-up {scene} {t.side}: {rec['error']}")

    if groups:
        print(f"timed runs: {', '.join(a.scene_list)}; threads {a.threads}; {a.repeat} round(s), before/after "
              "alternating", flush=True)
    for k in range(1, a.repeat + 1):
        for pair in groups:
            for e in pair:
                print(f"  [{time.strftime('%H:%M:%S')}] run {k}: {e.scene} t={e.threads} {e.tree.side} "
                      f"(load {load()}) ...", end="", flush=True)
                rec = run_proc(e.cmd, e.tree, a.timeout, env_extra)
                e.runs.append(rec)
                print(f" {fmt(rec['rate'])} /s ({rec['process_s']:.1f} s)" if rec["rate"] is not None
                      else f" FAILED {rec['error']}", flush=True)

    jit = None
    if a.jit:
        jit = {}
        for t in (before, after):
            jit[t.side] = run_jit(t, a)

    load1 = load()
    finished = datetime.datetime.now().astimezone()
    digest1 = {t.side: source_digest(t.path) for t in (before, after)}

    md = [f"# demcli A/B benchmark: {started:%Y-%m-%d %H:%M %Z}", "",
          f"- machine: {machine()}",
          f"- load average (1/5/15 min): {load0} at start, {load1} at the end "
          f"({(finished - started).total_seconds() / 60:.1f} min)",
          f"- command: `{command}`"]
    for t in (before, after):
        md.append(f"- **{t.side}**: {t.desc}; `import demcli` -> `{t.demcli_file}`; "
                  f"NUMBA_CACHE_DIR `{t.cache}`"
                  + (f"; bench files borrowed from the after tree (run with this tree's demcli): "
                     f"{', '.join(t.borrowed)}" if t.borrowed else ""))
        if digest0[t.side] != digest1[t.side]:
            md.append(f"- **WARNING: the {t.side} tree's demcli/ or bench/ sources changed during the run**: "
                      "its runs before and after the change used different code")
    warm_text = "" if a.no_warmup else "one untimed warm-up run per tree and scene first (fills its cache), then "
    md += [] if not groups else [f"- each run its own process; {warm_text}{a.repeat} round(s), "
           "in each round per scene and thread count: before, after; the figure is the stepping loop's "
           "particle-steps/s (body-steps/s for loaded_bed, polyhedron-steps/s for poly_N), median of the runs",
           f"- steps: spheres {a.steps}; clumps {a.clump_settle} fall + {a.steps} window; poly {a.poly_steps}; "
           f"loaded_bed 3 windows of {a.bed_steps} (the script's median)",
           "- ratio = after / before median: > 1 the after tree is faster", "",
           ]
    if groups:
        md += ["| scene | threads | before median | after median | after / before | before runs | after runs | note |",
               "|---|---|---|---|---|---|---|---|"]
    fails = []
    for pair in groups:
        b, af = pair
        ratio = f"{af.median / b.median:.3f}" if b.median and af.median else "—"
        notes = []
        for e in pair:
            nfail = sum(r["rate"] is None for r in e.runs)
            if nfail:
                notes.append(f"{e.tree.side}: {nfail} of {len(e.runs)} run(s) FAILED (missing)")
            if e.script in e.tree.borrowed:
                notes.append(f"{e.tree.side} ran the after tree's {e.script}")
            fails += [(e, k, r) for k, r in enumerate(e.runs, 1) if r["rate"] is None]

        def runs(e):
            return ", ".join(fmt(r["rate"]) if r["rate"] is not None else "FAILED" for r in e.runs)

        md.append(f"| {b.scene} | {b.threads} | {fmt(b.median)} | {fmt(af.median)} | {ratio} | {runs(b)} | "
                  f"{runs(af)} | {'; '.join(notes)} |")
    if jit:
        (jb, rb), (ja, ra) = jit["before"], jit["after"]
        md += ["", "Cold JIT (`bench/bench_jit.py` in each tree: `demcli run CASE --threads 1` with an empty "
                   "numba cache, then from it; seconds in numba's compiler lock; after / before < 1: the after "
                   "tree compiles less):", "",
               "| case | before cold JIT s | after cold JIT s | after / before | before cold CPU s | "
               "after cold CPU s | before warm JIT s | after warm JIT s |", "|---|---|---|---|---|---|---|---|"]
        for case in sorted(set(jb) | set(ja)):
            vb, va = jb.get(case), ja.get(case)
            r = f"{va[0] / vb[0]:.3f}" if vb and va and vb[0] > 0 else "—"

            def g(v, i):
                return "FAILED" if v is None else f"{v[i]:.2f}"
            md.append(f"| `{case}` | {g(vb, 0)} | {g(va, 0)} | {r} | {g(vb, 1)} | {g(va, 1)} | {g(vb, 2)} | "
                      f"{g(va, 2)} |")
        for side, rec in (("before", rb), ("after", ra)):
            if rec["error"]:
                md.append(f"- bench_jit.py {side}: FAILED {rec['error']}")
    if fails or warm_fail:
        md += ["", "Failed runs (counted as missing in the medians; stderr tail):"]
        md += [f"- {w}" for w in warm_fail]
        md += [f"- {e.scene} t={e.threads} {e.tree.side} run {k}: {r['error']}" for e, k, r in fails]
    md += ["", "<details><summary>runs (load average before each run, process seconds, warm-up/cache-load "
               "seconds the script reports, command)</summary>", ""]
    for k in range(a.repeat):
        for pair in groups:
            for e in pair:
                if k >= len(e.runs):
                    continue
                r = e.runs[k]
                kv = r["kv"]
                extra = "".join(f", {name} {kv[key]}" for key, name in (
                    ("warmup_s", "warmup_s"), ("first_step_s", "first_step_s"), ("contacts_total", "contacts"),
                    ("loop_wall_s", "loop_s")) if key in kv)
                md.append(f"- run {k + 1} {e.scene} t={e.threads} {e.tree.side}: {fmt(r['rate'])}, process "
                          f"{r['process_s']:.1f} s{extra}, load {r['load_before']}, demcli from "
                          f"`{os.path.dirname(r['demcli_file'] or '?')}`: "
                          f"`{r['cmd'].replace(sys.executable, 'python').replace(e.tree.path + '/', '')}`")
    md += ["", "</details>", ""]
    text = "\n".join(md)
    print()
    print(text)
    if a.out:
        with open(a.out, "w", encoding="utf-8") as f:
            f.write(text)
        print(f"written to {os.path.relpath(a.out)}")
    jit_fail = bool(jit) and any(rec["error"] for _, rec in jit.values())
    return 1 if fails or warm_fail or jit_fail else 0


if __name__ == "__main__":
    sys.exit(main())
