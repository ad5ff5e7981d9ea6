"""Throughput of a settled polyhedral bed, with and without the cached separating faces and directions.

Usage: python bench/bench_poly_bed.py CASE STATE [STEPS]
  e.g. python bench/bench_poly_bed.py cases/ballast_wide.yaml runs/ballast_wide/03-deposit.h5 30

Builds the case's ``deposit`` stage system on the given state (a settled bed), then runs
STEPS single steps three times alternately on two copies: one keeps its cache of
separating faces (``P_SEP``), the other has it wiped before every step (so every listed
pair whose bounding spheres meet goes through the exact overlap, as without the cache).
Alternating cancels most of the load drift of a shared machine. Prints body-steps/s of
both, the speed-up, whether the two runs ended bit-identical, and the cache's contents.
Run with NUMBA_NUM_THREADS=1 for one-thread figures.
"""

import sys
import time
from types import SimpleNamespace

import numpy as np


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    case_path, state_path = argv[0], argv[1]
    n = int(argv[2]) if len(argv) > 2 else 30
    from demcli.kernels.shapes.polyhedra import SEP_DIR, SEP_NONE
    from demcli.stages import loop
    from demcli.stages.base import load_case, load_stage_types
    from demcli.state import read_state

    load_stage_types()
    case = load_case(case_path)
    st = read_state(state_path)
    cfg = case.stages[[s.name for s in case.stages].index("deposit")]
    ctx = SimpleNamespace(case=case, name="bench", index=0, runner=SimpleNamespace(case_path=case_path))

    def build():
        s, _, dt, _ = loop.make_system(ctx, cfg, st.groups)
        s.dt = dt
        s.advance(2)
        return s

    a, b = build(), build()
    ta = tb = 0.0
    for _ in range(3):
        t = time.perf_counter()
        for _ in range(n):
            a.advance(1)
        ta += time.perf_counter() - t
        t = time.perf_counter()
        for _ in range(n):
            b.nl.sep[:] = SEP_NONE
            b.advance(1)
        tb += time.perf_counter() - t
    nb = len(a.mass)
    sep = a.nl.sep
    print(f"{nb} bodies, {len(sep)} listed pairs: cached {nb * 3 * n / ta:.3g} body-steps/s, "
          f"uncached {nb * 3 * n / tb:.3g}, speed-up {tb / ta:.2f}; bit-identical: {np.array_equal(a.x, b.x)}")
    faces = np.count_nonzero((sep != 0) & (sep != SEP_NONE) & (sep != SEP_DIR))
    print(f"cached faces {faces}, cached directions (edge-edge) {np.count_nonzero(sep == SEP_DIR)}, "
          f"none found {np.count_nonzero(sep == SEP_NONE)}")


if __name__ == "__main__":
    main()
