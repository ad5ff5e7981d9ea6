"""Polyhedron narrow phase: exact contact evaluations per second on one core.

Pairs of random Voronoi ballast shapes (``random_ballast_shape``, 20-40 faces, length
~1), each with a random orientation, B moved from A along a random direction until
the overlap is a drawn fraction V / min(V_A, V_B) of 1e-4 .. 1e-2 (log-uniform, the
range of DEM contacts). All bodies are stored the way the engine will hold them
(one world vertex array, CSR faces with shape-global rows), and one numba loop
evaluates :func:`demcli.kernels.polyhedra.overlap_ws` (scratch allocated once, as a
contact pass does per thread) for every pair plus :func:`contact_frame` (normal,
area, depth), after JIT, on one thread; CPU time of the thread, best of --repeat.
The allocating :func:`overlap` is timed too. Also timed:
the same pairs pulled apart until their bounding spheres still overlap but the
bodies do not (the broad-phase false positives a contact pass also sees).

Usage: python bench/bench_polyhedra.py [--pairs 400] [--shapes 60] [--repeat 10] [--seed 1]
[--method voronoi|hull]
The last line is ``contacts_per_s=<number>``.
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

os.environ.setdefault("NUMBA_NUM_THREADS", "1")


def random_quaternion(rng):
    q = rng.normal(size=4)
    return q / np.linalg.norm(q)


def build_pairs(n_pairs, n_shapes, seed, method="voronoi"):
    from demcli.geometry.ballast_shapes import ShapeParams, random_ballast_shape
    from demcli.kernels.polyhedra import place, polyhedron_overlap

    rng = np.random.default_rng(seed)
    params = ShapeParams(method=method, faces=(20, 40))
    shapes = [random_ballast_shape(rng, params) for _ in range(n_shapes)]
    bodies = []  # (placed A, placed B) per pair
    fractions = []
    apart = []
    for _ in range(n_pairs):
        sa, sb = shapes[rng.integers(n_shapes)], shapes[rng.integers(n_shapes)]
        qa, qb = random_quaternion(rng), random_quaternion(rng)
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        target = 10.0 ** rng.uniform(-4.0, -2.0) * min(sa.volume, sb.volume)
        a = place(sa, -place(sa, np.zeros(3), qa).center, qa)  # A's centroid at the origin

        def at(t):
            b0 = place(sb, np.zeros(3), qb)
            return place(sb, t * u - b0.center, qb)

        lo, hi = 0.0, a.radius + at(0.0).radius
        if polyhedron_overlap(a, at(lo))[0] < target:
            continue
        for _ in range(60):  # V falls monotonically along the ray once past its maximum
            mid = 0.5 * (lo + hi)
            if polyhedron_overlap(a, at(mid))[0] > target:
                lo = mid
            else:
                hi = mid
        b = at(lo)
        fractions.append(polyhedron_overlap(a, b)[0] / min(sa.volume, sb.volume))
        bodies.append((a, b))
        # separated but with overlapping bounding spheres
        t_far = a.radius + b.radius
        gap = 0.5 * (lo + t_far)
        bf = at(gap)
        if polyhedron_overlap(a, bf)[0] == 0.0:
            apart.append((a, bf))
    return bodies, np.array(fractions), apart


def pack(pairs):
    """Flat engine-style arrays: body k = pair k // 2, A then B."""
    placed = [p for pair in pairs for p in pair]
    nv = np.array([len(p.vertices) for p in placed])
    nf = np.array([len(p.normals) for p in placed])
    nfv = np.array([len(p.face_vertices) for p in placed])
    vstart = np.concatenate([[0], np.cumsum(nv)]).astype(np.int64)
    fstart = np.concatenate([[0], np.cumsum(nf)]).astype(np.int64)
    fvstart = np.concatenate([[0], np.cumsum(nfv)]).astype(np.int64)
    verts = np.concatenate([p.vertices for p in placed])
    normals = np.concatenate([p.normals for p in placed])
    offsets = np.concatenate([p.offsets for p in placed])
    # face CSR with global rows: face_vertex_start over all faces, face_vertices global
    face_vertex_start = np.concatenate([p.face_start[:-1] + fvstart[k] for k, p in enumerate(placed)]
                                       + [[fvstart[-1]]]).astype(np.int64)
    face_vertices = np.concatenate([p.face_vertices + vstart[k] for k, p in enumerate(placed)]).astype(np.int64)
    centers = np.array([p.center for p in placed])
    radii = np.array([p.radius for p in placed])
    return vstart, verts, fstart, face_vertex_start, face_vertices, normals, offsets, centers, radii


def make_loop(with_scratch):
    from demcli.jit import njit
    from demcli.kernels.polyhedra import contact_frame, overlap, overlap_ws

    @njit(cache=False)
    def pair(vstart, verts, fstart, fvs, fv, normals, offsets, centers, radii, i, j, buf, fw, planes):
        vi, vj = vstart[i], vstart[j]
        fi, fj = fstart[i], fstart[j]
        if with_scratch:
            return overlap_ws(verts[vi:vstart[i + 1]], fvs[fi:fstart[i + 1] + 1], fv, vi,
                              normals[fi:fstart[i + 1]], offsets[fi:fstart[i + 1]],
                              centers[i, 0], centers[i, 1], centers[i, 2], radii[i],
                              verts[vj:vstart[j + 1]], fvs[fj:fstart[j + 1] + 1], fv, vj,
                              normals[fj:fstart[j + 1]], offsets[fj:fstart[j + 1]],
                              centers[j, 0], centers[j, 1], centers[j, 2], radii[j], buf, fw, planes)
        return overlap(verts[vi:vstart[i + 1]], fvs[fi:fstart[i + 1] + 1], fv, vi,
                       normals[fi:fstart[i + 1]], offsets[fi:fstart[i + 1]],
                       centers[i, 0], centers[i, 1], centers[i, 2], radii[i],
                       verts[vj:vstart[j + 1]], fvs[fj:fstart[j + 1] + 1], fv, vj,
                       normals[fj:fstart[j + 1]], offsets[fj:fstart[j + 1]],
                       centers[j, 0], centers[j, 1], centers[j, 2], radii[j])

    @njit(cache=False)
    def loop(vstart, verts, fstart, fvs, fv, normals, offsets, centers, radii, buf, fw, planes, out):
        for k in range(out.shape[0]):
            i = 2 * k
            j = i + 1
            r = pair(vstart, verts, fstart, fvs, fv, normals, offsets, centers, radii, i, j, buf, fw, planes)
            nx, ny, nz, area, depth = contact_frame(r[0], r[4], r[5], r[6], centers[i, 0], centers[i, 1],
                                                    centers[i, 2], centers[j, 0], centers[j, 1], centers[j, 2],
                                                    radii[i], radii[j])
            out[k, 0] = r[0]
            out[k, 1] = area
            out[k, 2] = depth
            out[k, 3] = nx
    return loop


def timed(loop, arrays, n, repeat):
    from demcli.kernels.polyhedra import scratch

    fvs, nfaces = arrays[3], np.diff(arrays[2])
    out = np.empty((n, 4))
    ws = scratch(int(np.diff(fvs).max()), int(nfaces.max()))
    loop(*arrays, *ws, out)  # JIT
    best = np.inf
    for _ in range(repeat):
        # CPU time of this thread: the machine's cores are shared with other work
        t0 = time.thread_time()
        loop(*arrays, *ws, out)
        best = min(best, time.thread_time() - t0)
    return best, out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=400)
    ap.add_argument("--shapes", type=int, default=60)
    ap.add_argument("--repeat", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--method", choices=("voronoi", "hull"), default="voronoi",
                    help="shape generator: Voronoi cells (polygonal faces) or point hulls (triangles)")
    args = ap.parse_args()

    import numba

    numba.set_num_threads(1)
    t0 = time.perf_counter()
    pairs, fractions, apart = build_pairs(args.pairs, args.shapes, args.seed, args.method)
    setup = time.perf_counter() - t0
    nf = np.array([len(p.normals) for pair in pairs for p in pair])
    print(f"# {platform.processor() or platform.machine()}, python {platform.python_version()}, "
          f"numba {numba.__version__}, 1 thread")
    print(f"# {len(pairs)} overlapping pairs of {args.method} shapes (setup {setup:.1f} s): "
          f"faces {nf.min()}-{nf.max()} (mean {nf.mean():.1f}), V/V_min {fractions.min():.1e}..{fractions.max():.1e} "
          f"(median {np.median(fractions):.1e})")
    packed = pack(pairs)
    best_alloc, _ = timed(make_loop(False), packed, len(pairs), args.repeat)
    loop = make_loop(True)
    best, out = timed(loop, packed, len(pairs), args.repeat)
    assert np.all(np.isfinite(out)) and np.all(out[:, 0] > 0.0)
    rate = len(pairs) / best
    if apart:
        best_apart, out2 = timed(loop, pack(apart), len(apart), args.repeat)
        assert np.all(out2[:, 0] == 0.0)
        print(f"# separated pairs with overlapping bounding spheres: {len(apart)}, "
              f"{len(apart) / best_apart:.3g} evaluations/s")
    print(f"# overlapping pairs, overlap() allocating its scratch: {1e6 * best_alloc / len(pairs):.2f} us per "
          f"contact ({len(pairs) / best_alloc:.3g}/s)")
    print(f"# overlapping pairs, overlap_ws() with per-thread scratch: {1e6 * best / len(pairs):.2f} us per "
          f"contact (best of {args.repeat})")
    print(f"contacts_per_s={rate:.4g}")


if __name__ == "__main__":
    main()
