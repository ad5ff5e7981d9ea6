"""Cold and warm JIT: the compile (or cache-load) time of ``demcli run CASE``, with an empty
numba cache and then from it, beside the whole run's wall and CPU time.

For every case (default: the sphere smoke case cases/smoke/beads.yaml, 150 spheres and 3000
steps, and the polyhedral one cases/smoke/ballast_deposit.yaml, ~140 ballast stones and 9000
steps), ``demcli run CASE --out <tmp> --threads 1 --quiet --force`` runs twice in fresh
processes with ``NUMBA_CACHE_DIR`` = a new empty folder (demcli.jit puts its cache in a
digest-named folder under it):

* cold: the cache is empty, every kernel the case calls is compiled;
* warm: the same command again, the kernels load from the cache the cold run filled.

Per run: JIT seconds, the time the process held numba's compiler lock (numba takes it to
compile a kernel and to load one from the cache; a numba event listener in the child
sums it); the whole-process wall time (interpreter start, imports, every stage, plots,
output files), as a user sees it; and its CPU seconds (user + system): on a machine that
other jobs share, the wall time also counts waits for a core, the CPU time does not. The
time-stepping loops of the dem stages (the "N steps in X s" log lines) are listed apart:
that part is the case's own work. The issue's targets, on the JIT seconds: cold under
60 s, from the cache under 3 s.

Usage: python bench/bench_jit.py [CASE ...] [--threads T]

Prints a Markdown table between ``<!-- bench_jit:begin -->`` / ``<!-- bench_jit:end -->``
(bench/run_bench.py copies it into bench/results.md); the LAST line is
``jit_cold_s=<max over cases> jit_warm_s=<max over cases>`` (JIT seconds).
"""

import argparse
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
CASES = ("cases/smoke/beads.yaml", "cases/smoke/ballast_deposit.yaml")
COLD_TARGET_S = 60.0
WARM_TARGET_S = 3.0
LOOP = re.compile(r"\] (\d+) steps in ([0-9.]+) s")


# `demcli run` in a child that also reports the seconds spent holding numba's compiler lock:
# compiling, or loading compiled kernels from the cache (numba takes the lock for both)
CHILD = """
import atexit, sys
from numba.core import event
timer = event.TimingListener()
event.register("numba:compiler_lock", timer)
atexit.register(lambda: print(f"jit_lock_s={timer.duration if timer.done else 0.0:.3f}"))
from demcli.cli import main
main(sys.argv[1:])
"""
JIT = re.compile(r"jit_lock_s=([0-9.]+)")


def run_case(case, cache, out, threads, timeout):
    """(wall s, CPU s, JIT s, stepping-loop s from the log, error or None) of one ``demcli run``.

    The CPU seconds (user + system of the child) are what the run costs on an idle core: on a
    machine that other jobs share, the wall time also counts the waits for a core. The JIT
    seconds are those spent in numba's compiler lock (compiling or loading from the cache)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=cache, DEMCLI_NUMBA_CACHE="1")
    env.pop("NUMBA_DISABLE_JIT", None)
    cmd = [sys.executable, "-c", CHILD, "run", case, "--out", out, "--threads", str(threads), "--quiet",
           "--force"]
    t0 = time.perf_counter()
    ru0 = resource.getrusage(resource.RUSAGE_CHILDREN)
    jit = math.nan
    try:
        p = subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                           timeout=timeout)
        err = None if p.returncode == 0 else f"rc={p.returncode}: " + p.stdout.strip()[-300:]
        m = JIT.search(p.stdout)
        jit = float(m.group(1)) if m else math.nan
    except subprocess.TimeoutExpired:
        err = f"killed after {timeout:.0f} s"
    wall = time.perf_counter() - t0
    ru1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (ru1.ru_utime - ru0.ru_utime) + (ru1.ru_stime - ru0.ru_stime)
    loop = 0.0
    try:
        with open(os.path.join(out, "log.txt"), encoding="utf-8") as f:
            loop = sum(float(m.group(2)) for m in LOOP.finditer(f.read()))
    except OSError:
        pass
    return wall, cpu, jit, loop, err


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("cases", nargs="*", default=list(CASES), help="case files (default: %(default)s)")
    ap.add_argument("--threads", type=int, default=1, help="--threads of demcli run (default 1)")
    ap.add_argument("--timeout", type=float, default=900.0, help="kill a run after this many seconds")
    a = ap.parse_args(argv)

    rows, worst_cold, worst_warm, failed = [], 0.0, 0.0, False
    for case in a.cases:
        tmp = tempfile.mkdtemp(prefix="demcli_bench_jit_")
        try:
            cache = os.path.join(tmp, "numba")
            os.makedirs(cache)
            res = {}
            for kind in ("cold", "warm"):
                print(f"  [{time.strftime('%H:%M:%S')}] {case} {kind} (load {os.getloadavg()[0]:.2f}) ...",
                      end="", flush=True)
                res[kind] = run_case(case, cache, os.path.join(tmp, kind), a.threads, a.timeout)
                wall, cpu, jit, loop, err = res[kind]
                print(f" {wall:.1f} s ({cpu:.1f} s CPU, JIT {jit:.1f} s)" + (f" FAILED {err}" if err else ""),
                      flush=True)
            files = sum(len(f) for _, _, f in os.walk(cache))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        (cw, cc, cj, cl, ce), (ww, wc, wj, wl, we) = res["cold"], res["warm"]
        failed |= bool(ce or we)
        worst_cold, worst_warm = max(worst_cold, cj), max(worst_warm, wj)
        verdict = ("cold " + ("ok" if cj < COLD_TARGET_S else "OVER") + ", warm "
                   + ("ok" if wj < WARM_TARGET_S else "OVER")) if not (ce or we) else "FAILED: " + (ce or we)
        rows.append(f"| `{case}` | {cw:.1f} | {cc:.1f} | {cj:.1f} | {ww:.1f} | {wc:.1f} | {wj:.2f} | {wl:.2f} | "
                    f"{files} | {verdict} |")

    print("<!-- bench_jit:begin -->")
    print("| case | cold: wall s | CPU s | JIT s | warm: wall s | CPU s | JIT s | stepping loops s (warm) | "
          f"cache files | targets (JIT cold < {COLD_TARGET_S:g} s, from cache < {WARM_TARGET_S:g} s) |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        print(r)
    print("<!-- bench_jit:end -->")
    print(f"jit_cold_s={worst_cold:.2f} jit_warm_s={worst_warm:.2f}")  # JIT seconds, the worst case
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
