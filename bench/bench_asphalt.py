"""3D asphalt (seed 000): wall time of each stage of the Marshall pipeline against the lattice ball size.

Runs ``cases/smoke/marshall_ac13_3d.yaml`` (gradation -> place_spheres -> carve -> compact
-> cut -> mastic: AC-13 2.36-9.5 mm in a 30 x 30 x 34 mm mould, a 20 x 12 mm cylinder cut)
end to end at several lattice ball sizes (``stages.carve.lattice.spacing``, the ball
diameter), one thread, after one untimed warm-up run at the coarsest size (numba kernels
loaded from the cache). Per run: the wall time of every stage (demcli.pipeline's
``StageResult.wall_time``), the lattice and aggregate ball counts, the aggregates, the
compaction steps, the porosity after carving and after compaction, and the mastic stage's
air voids. Then a power law t = a N^k per stage, least squares in log-log over the runs,
N = the aggregate (member) balls after carving: the balls the compaction moves.

Usage: python bench/bench_asphalt.py [--spacings 2.0,1.4,1.0] [--repeat 1] [--quick]
                                     [--case PATH] [--write-doc]
``--write-doc`` replaces the table block in docs/asphalt3d.md. The table is printed between
``<!-- bench_asphalt:begin -->`` and ``<!-- bench_asphalt:end -->`` (bench/run_bench.py copies
it into bench/results.md). The last line is ``asphalt_compact_exponent=<k>``.
"""

import argparse
import datetime
import math
import os
import platform
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(ROOT))

CASE = ROOT / "cases" / "smoke" / "marshall_ac13_3d.yaml"
SPACINGS = (2.0, 1.4, 1.0)   # mm, steps of sqrt 2; 0.7 mm stops on the overlap guard (docs/asphalt3d.md)
QUICK_SPACINGS = (2.0, 1.5)
BEGIN, END = "<!-- bench_asphalt:begin -->", "<!-- bench_asphalt:end -->"
LATTICE_KEY = "stages.carve.lattice.spacing"
NOISE_S = 0.2  # stages faster than this in every run: their exponent is noise


def load():
    return "%.2f %.2f %.2f" % os.getloadavg()


def run_once(case, spacing_mm, tmp, threads):
    """One pipeline run; returns the figures of the row."""
    from demcli import run_case
    from demcli.state import read_state

    out = Path(tmp) / f"a{spacing_mm:g}"
    load0 = load()
    t0 = time.perf_counter()
    res = run_case(case, out=out, overrides=[f"{LATTICE_KEY}={spacing_mm} mm"], quiet=True, force=True,
                   threads=threads)
    total = time.perf_counter() - t0
    row = {"spacing": spacing_mm, "total": total, "load": load0,
           "stages": {r.name: r.wall_time for r in res}, "throughput": {r.name: r.throughput for r in res}}
    files = sorted(out.glob("*.h5"))
    by_type = {}
    for f in files:
        st = read_state(f)
        by_type[st.meta["stage_type"]] = st
    carve = by_type["carve"]
    row["lattice"] = int(np.prod(carve["aggregates/lattice_counts"]))
    row["balls"] = int(len(carve["spheres/body"]))
    row["aggregates"] = int(len(carve["aggregates/body"]))
    row["fe"] = float(np.mean(carve["aggregates/flat_elongated"]))
    comp = by_type.get("compact")
    if comp is not None:
        row["steps"] = int(comp.meta["step"])
        row["porosity"] = (float(comp["compaction/porosity_initial"]), float(comp["compaction/porosity_final"]))
    mastic = by_type.get("mastic")
    if mastic is not None:
        row["air_voids"] = float(mastic["mastic/air_voids"])
        row["mastic_balls"] = int(mastic["mastic/count"])
    return row


def power_law(ns, ts):
    """(k, a) of t = a N^k by least squares in log-log; None with fewer than 2 usable points."""
    pts = [(math.log(n), math.log(t)) for n, t in zip(ns, ts) if n > 0 and t > 0]
    if len(pts) < 2 or len({p[0] for p in pts}) < 2:
        return None
    x, y = np.array(pts).T
    k, b = np.polyfit(x, y, 1)
    return float(k), float(math.exp(b))


def markdown(rows, stages, case, command, started, load0, load1):
    rel = os.path.relpath(case, ROOT)
    md = [f"Measured {started:%Y-%m-%d %H:%M %Z} with `{command}` ({platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} cores, one thread; load average {load0} at the start, {load1} at the end: the "
          "machine was shared with other jobs, so single figures may be off by tens of per cent). "
          f"Case `{rel}` with `--set {LATTICE_KEY}=<ball> mm`; numba kernels loaded from the cache by an untimed "
          "warm-up run; wall time per stage as reported by the pipeline (median over the repeats).", "",
          "| ball (mm) | lattice balls | aggregate balls | aggregates | F/E share | compact steps "
          "| compact particle-steps/s | porosity carve -> compact | mastic balls | air voids | "
          + " | ".join(f"{s} (s)" for s in stages) + " | total (s) |",
          "|" + "---|" * (11 + len(stages))]
    for r in rows:
        por = f"{r['porosity'][0]:.3f} -> {r['porosity'][1]:.3f}" if "porosity" in r else "—"
        av = f"{100 * r['air_voids']:.2f} %" if "air_voids" in r else "—"
        md.append(f"| {r['spacing']:g} | {r['lattice']} | {r['balls']} | {r['aggregates']} | "
                  f"{100 * r['fe']:.1f} % | {r.get('steps', '—')} | {r['throughput'].get('compact', 0):.3g} | "
                  f"{por} | {r.get('mastic_balls', '—')} | {av} | "
                  + " | ".join(f"{r['stages'].get(s, float('nan')):.2f}" for s in stages)
                  + f" | {r['total']:.2f} |")
    fits, small = {}, []
    ns = [r["balls"] for r in rows]
    for s in stages + ["total"]:
        ts = [r["total"] if s == "total" else r["stages"].get(s, 0.0) for r in rows]
        fits[s] = power_law(ns, ts)
        if max(ts) < NOISE_S:
            small.append(s)
    md += ["", "Growth with the aggregate balls N (power law t ~ N^k fitted over the rows, least squares in "
               "log-log): " + ", ".join(f"{s} k = {fits[s][0]:.2f}" if fits[s] else f"{s} k = —"
                                        for s in stages + ["total"]) + "."
           + (f" ({', '.join(small)}: under {NOISE_S:g} s in every run, timer noise rather than growth.)"
              if small else "")]
    if len(rows) >= 2:
        a, b = rows[0], rows[-1]
        ratio_a = a["spacing"] / b["spacing"]
        md.append(f"From {a['spacing']:g} mm to {b['spacing']:g} mm balls (x{ratio_a:.2f} finer): "
                  f"aggregate balls x{b['balls'] / a['balls']:.1f}, compaction steps "
                  f"x{b.get('steps', 0) / max(a.get('steps', 1), 1):.1f}, compact wall time "
                  f"x{b['stages'].get('compact', 0) / max(a['stages'].get('compact', 1e-9), 1e-9):.1f}, "
                  f"whole pipeline x{b['total'] / a['total']:.1f}.")
    return "\n".join(md), fits


def write_doc(text, path=ROOT / "docs" / "asphalt3d.md"):
    from doc_section import write_section

    write_section(path, BEGIN, END, text)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spacings", default=None,
                    help=f"lattice ball diameters in mm, comma list (default {','.join(map(str, SPACINGS))}; "
                         f"--quick: {','.join(map(str, QUICK_SPACINGS))})")
    ap.add_argument("--repeat", type=int, default=1, help="timed runs per ball size (median reported; default 1)")
    ap.add_argument("--quick", action="store_true", help="two coarse ball sizes only (~15 s)")
    ap.add_argument("--case", default=str(CASE), help="the case file (default the Marshall smoke case)")
    ap.add_argument("--threads", type=int, default=1, help="numba threads (default 1)")
    ap.add_argument("--write-doc", action="store_true", help="replace the table in docs/asphalt3d.md")
    a = ap.parse_args(argv)
    spacings = [float(s) for s in (a.spacings.split(",") if a.spacings else
                                   (QUICK_SPACINGS if a.quick else SPACINGS))]
    spacings = sorted(spacings, reverse=True)  # coarsest (cheapest) first
    case = Path(a.case).resolve()
    started = datetime.datetime.now().astimezone()
    load0 = load()
    command = "python bench/bench_asphalt.py" + "".join(" " + x for x in (argv if argv is not None else sys.argv[1:]))
    print(f"bench_asphalt: {os.path.relpath(case, ROOT)} at balls {', '.join(f'{s:g}' for s in spacings)} mm, "
          f"{a.repeat} timed run(s) each, {a.threads} thread(s), load {load0}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory(prefix="demcli_bench_asphalt_") as tmp:
        run_once(case, spacings[0], tmp, a.threads)  # warm-up: kernels from numba's cache
        for s in spacings:
            runs = []
            for k in range(a.repeat):
                r = run_once(case, s, tmp, a.threads)
                runs.append(r)
                print(f"  [{time.strftime('%H:%M:%S')}] {s:g} mm run {k + 1}: {r['balls']} aggregate balls, "
                      f"{r['aggregates']} aggregates, {r.get('steps', 0)} steps; "
                      + ", ".join(f"{n} {t:.2f} s" for n, t in r["stages"].items())
                      + f"; total {r['total']:.1f} s (load {r['load']})", flush=True)
            row = dict(runs[-1])
            row["stages"] = {n: statistics.median(r["stages"][n] for r in runs) for n in runs[0]["stages"]}
            row["total"] = statistics.median(r["total"] for r in runs)
            rows.append(row)
    stages = list(rows[0]["stages"])
    text, fits = markdown(rows, stages, case, command, started, load0, load())
    print()
    print(BEGIN)
    print(text)
    print(END)
    if a.write_doc:
        write_doc(text)
    k = fits.get("compact")
    print(f"asphalt_compact_exponent={k[0]:.3f}" if k else "asphalt_compact_exponent=nan")
    return 0


if __name__ == "__main__":
    sys.exit(main())
