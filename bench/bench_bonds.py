"""Throughput of a bonded specimen: the seed-003 uniaxial creep (Burgers bonds at every contact).

Usage: python bench/bench_bonds.py [--case CASE] [--steps N] [--threads T]
  default case cases/sand_asphalt_uniaxial.yaml (1 000 spheres, ~2 600 bonds)

Runs the case's ``prepare`` stage once (not timed), a short ``creep`` run to compile the
kernels and read the time step, then the ``creep`` stage for N steps twice; prints the best
rate as the stage reports it (particle-steps/s of the stage loop: no start-up, no JIT). YADE
and LIGGGHTS have no Burgers bond of this form, so there is no peer run.
"""

import argparse
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--case", default=str(ROOT / "cases" / "sand_asphalt_uniaxial.yaml"))
    ap.add_argument("--steps", type=int, default=20000)
    ap.add_argument("--threads", type=int, default=1)
    a = ap.parse_args(argv)
    import shutil

    from demcli import run_case
    from demcli.state import read_state

    work = Path(tempfile.mkdtemp(prefix="bench_bonds_"))
    try:
        run_case(a.case, out=work / "bonded", quiet=True, only="prepare", threads=a.threads)
        st = read_state(work / "bonded" / "00-prepare.h5")
        n = len(st.groups["spheres"]["radius"])
        nb = len(st.groups["bonds"]["i"])
        # duration from the creep stage's step: dt is fixed by the specimen and the case
        warm = ["stages.creep.output.records=2", "stages.creep.output.snapshots=0"]
        probe = run_case(a.case, out=work / "bonded", quiet=True, only="creep", threads=a.threads,
                         overrides=warm + ["stages.creep.duration=0.01 s"])
        dt = float(read_state(probe[-1].path).meta["dt"])
        over = warm + [f"stages.creep.duration={a.steps * dt!r} s"]
        rates = [run_case(a.case, out=work / "bonded", quiet=True, only="creep", threads=a.threads,
                          overrides=over, force=True)[-1].throughput for _ in range(2)]
        print(f"{n} spheres, {nb} Burgers bonds, {a.steps} steps, {a.threads} thread(s): "
              f"{max(rates):.3g} particle-steps/s (best of 2; {min(rates):.3g} the other)")
        print(f"particle_steps_per_s={max(rates):.6g}")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    main()
