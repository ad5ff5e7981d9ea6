"""Polyhedra against sphere clumps in the ballast box: the table and figure of docs/ballast_box.md.

Reads the polyhedral reference run (cases/studies/ballast_polyhedra_reference.yaml) and the
clump runs of the study over the ball size (cases/studies/ballast_clumps.yaml), and writes

  <out>/ballast_clumps.png   plate settlement against time, and bed density under the plate
                             against load cycle, one curve per representation
  <out>/ballast_clumps.csv   the settlement curves (run, time, settlement, bulk density)

and prints the Markdown table (particles, spheres, time step, deposit, plate, wall times).

    .venv/bin/python bench/ballast_clumps.py [--reference runs/ballast_polyhedra_reference]
        [--study studies/ballast_clumps] [--out docs/studies] [--clump-run DIR=LABEL ...]

Measures, as the vibrate stage takes them: M the particles' mass (the same for both: the
clumps keep the polyhedra's masses), A the box floor, h the plate's underside above the floor;
bulk density M / (A h); settlement = h(t0) - h(t), t0 the start of the load cycles (the end of
the settle time at F_min); cycle N ends at t0 + N / f with the load back at F_min. Deposit
density: h = the mean over columns (cells of the median sieve size) of the highest particle
point (polyhedra: vertices; clumps: ball tops).
"""

import argparse
import csv
import math
import re
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def _read_csv(path):
    from demcli.compare import read_record

    data, _ = read_record(path)
    return data


def _stage_times(run):
    """{stage: wall time [s]} from the run's log.txt (the last 'done in' of each stage)."""
    out = {}
    for m in re.finditer(r"\[(\w+)\] done in ([0-9.eE+-]+) s", (run / "log.txt").read_text()):
        out[m.group(1)] = float(m.group(2))
    return out


def _dt(run, stage):
    m = re.findall(rf"\[{stage}\] dt = ([0-9.eE+-]+) s", (run / "log.txt").read_text())
    return float(m[-1]) if m else math.nan


def _box(state):
    """(floor area [m^2], floor z [m]) from the box walls of a state."""
    names = list(state["walls/name"])
    p = state["walls/point"]
    x0, x1 = p[names.index("box.x0"), 0], p[names.index("box.x1"), 0]
    y0, y1 = p[names.index("box.y0"), 1], p[names.index("box.y1"), 1]
    return float((x1 - x0) * (y1 - y0)), float(p[names.index("box.z0"), 2])


def _surface(points, lo, hi, cell):
    """Mean over columns of width ``cell`` of the highest point [m above lo z] (ballast_box's measure)."""
    n = np.maximum(1, np.floor((hi[:2] - lo[:2]) / cell).astype(int))
    ij = np.clip(((points[:, :2] - lo[:2]) / (hi[:2] - lo[:2]) * n).astype(int), 0, n - 1)
    top = np.full(n[0] * n[1], -np.inf)
    np.maximum.at(top, ij[:, 0] * n[1] + ij[:, 1], points[:, 2])
    top = top[np.isfinite(top)]
    return float(top.mean()) - lo[2]


def _stage_cfg(case, name):
    from demcli.stages.base import load_case

    return next(c for c in load_case(case).stages if c.name == name)


def polyhedra_run(run, case):
    from demcli.state import read_state

    dep = read_state(run / "03-deposit.h5")
    vib = read_state(run / "04-vibrate.h5")
    rows = _read_csv(run / "records" / "vibrate_dem.csv")
    cyc = _read_csv(run / "records" / "vibrate_cycles.csv")
    mass = float(vib["bed/particle_mass"])
    area, floor = _box(vib)
    cfg = _stage_cfg(case, "vibrate")
    half = 0.5 * (cfg.plate.size[2] if cfg.plate.size is not None else cfg.plate.thickness)
    h = rows["plate"] - half - floor
    t0 = float(np.interp(0.0, rows["cycle"], rows["time"]))
    freq = cfg.load.frequency
    times = _stage_times(run)
    return {"name": "polyhedra", "particles": len(dep["bodies/mass"]), "spheres": 0, "per_particle": math.nan,
            "dt": _dt(run, "vibrate"), "deposit_time": float(dep.meta["time"]),
            "deposit_density": float(dep["bed/bulk_density"]), "t": rows["time"] - t0, "h": h,
            "mass": mass, "area": area, "freq": freq, "cycle_h": cyc["plate"] - half - floor,
            "wall": (times.get("deposit", math.nan), times.get("vibrate", math.nan))}


def clumps_run(run, name, case):
    from demcli.state import State, read_state

    cl = read_state(run / "03-clumps.h5")
    dep = read_state(run / "04-deposit.h5")
    plate = read_state(run / "05-plate.h5")
    rows = _read_csv(run / "records" / "plate_walls.csv")
    area, floor = _box(plate)
    names = list(plate["walls/name"])
    mass = float(cl["bodies/mass"].sum())
    h = -rows["plate.position"] - floor  # position = point . normal, normal -z
    motion = next(w for w in _stage_cfg(case, "plate").walls if w.get("name") == "plate").motion
    t0, freq = motion.start, motion.frequency
    # deposit bed height: ball tops, columns of the median sieve size
    lo = np.array([plate["walls/point"][names.index("box.x0"), 0], plate["walls/point"][names.index("box.y0"), 1],
                   floor])
    hi = np.array([plate["walls/point"][names.index("box.x1"), 0], plate["walls/point"][names.index("box.y1"), 1],
                   floor])
    tops = State(groups=dep.groups).sphere_centres() + np.c_[np.zeros((len(dep["spheres/radius"]), 2)),
                                                             dep["spheres/radius"]]
    cell = float(np.median(cl["clumps/sieve_size"]))
    dep_density = mass / (area * _surface(tops, lo, hi, cell))
    times = _stage_times(run)
    overlaps = snapshot_overlaps(run, rows["time"], -rows["plate.position"])
    return {"name": name, "overlaps": overlaps, "particles": len(cl["bodies/mass"]), "spheres": len(cl["spheres/radius"]),
            "per_particle": len(cl["spheres/radius"]) / len(cl["bodies/mass"]), "dt": _dt(run, "plate"),
            "deposit_time": float(dep.meta["time"]), "deposit_density": dep_density, "t": rows["time"] - t0,
            "h": h, "mass": mass, "area": area, "freq": freq, "cycle_h": None,
            "ball_mm": 2e3 * float(np.mean(cl["clumps/ball_radius"])),
            "volume_error": 100 * float(np.mean(cl["clumps/volume_error"])),
            "sieve_error": 100 * float(np.mean(cl["clumps/clump_sieve_size"] / cl["clumps/sieve_size"] - 1)),
            "wall": (times.get("deposit", math.nan), times.get("plate", math.nan))}


def snapshot_overlaps(run, t_rec, z_plate):
    """Largest overlap / ball radius over the plate stage's snapshots: (ball-ball of different
    clumps, ball-plate), with the time of each worst one. z_plate(t) from the walls record."""
    import xml.etree.ElementTree as ET

    import meshio
    from scipy.spatial import cKDTree

    best = [(0.0, math.nan), (0.0, math.nan)]
    pvd = run / "plate" / "spheres.pvd"
    for ds in ET.parse(pvd).getroot().iter("DataSet"):
        t = float(ds.get("timestep"))
        mesh = meshio.read(pvd.parent / ds.get("file"))
        x = mesh.points
        r = np.asarray(mesh.point_data["radius"], float)
        body = np.asarray(mesh.point_data["body_id"])
        pairs = cKDTree(x).query_pairs(2.0 * float(r.max()), output_type="ndarray")
        i, j = pairs[:, 0], pairs[:, 1]
        keep = body[i] != body[j]
        i, j = i[keep], j[keep]
        over = (r[i] + r[j] - np.linalg.norm(x[i] - x[j], axis=1)) / np.minimum(r[i], r[j])
        if len(over) and over.max() > best[0][0]:
            best[0] = (float(over.max()), t)
        zp = float(np.interp(t, t_rec, z_plate))
        wall = float(((x[:, 2] + r - zp) / r).max())
        if wall > best[1][0]:
            best[1] = (wall, t)
    return best


def cycle_heights(r, cycles):
    """Plate heights h at cycle ends 0..cycles (interpolated in the record)."""
    if r["cycle_h"] is not None:
        return np.asarray(r["cycle_h"][:cycles + 1])
    return np.interp(np.arange(cycles + 1) / r["freq"], r["t"], r["h"])


def table(runs, cycles):
    head = ("| representation | spheres per particle (total) | time step [s] | deposit: at rest after [s] | "
            "deposit rho_b [g/cm^3] | under the plate, cycle 0 | after 1 cycle | after "
            f"{cycles} cycles | settlement after 1 / {cycles} cycles [mm] | settlement, cycles 1-{cycles} [mm] | "
            "wall time deposit / plate [min] |")
    lines = [head, "|" + "---|" * head.count(" | ")]
    for r in runs:
        hc = cycle_heights(r, cycles)
        rho = r["mass"] / (r["area"] * hc) / 1e3
        sett = 1e3 * (hc[0] - hc)
        sph = "polyhedra" if not r["spheres"] else f"{r['per_particle']:.1f} ({r['spheres']})"
        lines.append(f"| {r['label']} | {sph} | {r['dt']:.3g} | {r['deposit_time']:.3g} | "
                     f"{r['deposit_density'] / 1e3:.3f} | {rho[0]:.3f} | {rho[1]:.3f} | {rho[-1]:.3f} | "
                     f"{sett[1]:.1f} / {sett[-1]:.1f} | {sett[-1] - sett[1]:.1f} | "
                     f"{r['wall'][0] / 60:.1f} / {r['wall'][1] / 60:.1f} |")
    return "\n".join(lines)


def figure(runs, cycles, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    for r in runs:
        m = r["t"] >= 0
        h0 = float(np.interp(0.0, r["t"], r["h"]))
        style = "--" if "stiffness" in r["label"] else "-"
        a.plot(r["t"][m], 1e3 * (h0 - r["h"][m]), style, label=r["label"])
        hc = cycle_heights(r, cycles)
        b.plot(np.arange(cycles + 1), r["mass"] / (r["area"] * hc) / 1e3, "o" + style, label=r["label"])
    a.set_xlabel("time since the load cycles began [s]")
    a.set_ylabel("plate settlement [mm]")
    a.set_title("plate settlement, 0-13 kN at 10 Hz")
    b.set_xlabel("load cycle")
    b.set_ylabel("bulk density under the plate [g/cm$^3$]")
    b.set_title("bed density at each cycle's end")
    for ax in (a, b):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reference", default=str(ROOT / "runs" / "ballast_polyhedra_reference"))
    ap.add_argument("--study", default=str(ROOT / "studies" / "ballast_clumps"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "studies"))
    ap.add_argument("--reference-case", default=str(ROOT / "cases" / "studies" / "ballast_polyhedra_reference.yaml"))
    ap.add_argument("--case", default=str(ROOT / "cases" / "studies" / "ballast_clumps.yaml"))
    ap.add_argument("--cycles", type=int, default=5)
    ap.add_argument("--clump-run", action="append", default=[], metavar="DIR=LABEL",
                    help="one more clump run folder (e.g. the study's variant with other settings) and its label")
    args = ap.parse_args(argv)
    runs = []
    ref = polyhedra_run(Path(args.reference), args.reference_case)
    ref["label"] = "polyhedra"
    runs.append(ref)
    variants = sorted((p for p in Path(args.study).iterdir() if (p / "05-plate.h5").exists()),
                      key=lambda p: -float(p.name.split("=")[-1]))
    for p in variants:
        r = clumps_run(p, p.name, args.case)
        r["label"] = f"clumps, balls {p.name.split('=')[-1]} x sieve size"
        runs.append(r)
    for spec in args.clump_run:
        folder, _, label = spec.rpartition("=")  # the label holds no "="
        r = clumps_run(Path(folder), label or Path(folder).name, args.case)
        r["label"] = label or Path(folder).name
        runs.append(r)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    figure(runs, args.cycles, out / "ballast_clumps.png")
    with open(out / "ballast_clumps.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["run", "time[s]", "settlement[mm]", "bulk_density[g/cm^3]"])
        for r in runs:
            h0 = float(np.interp(0.0, r["t"], r["h"]))
            for t, h in zip(r["t"], r["h"]):
                if t >= 0:
                    w.writerow([r["label"], f"{t:.6g}", f"{1e3 * (h0 - h):.6g}", f"{r['mass'] / (r['area'] * h) / 1e3:.6g}"])
    print(table(runs, args.cycles))
    for r in runs[1:]:
        (bb, tb), (bw, tw) = r["overlaps"]
        print(f"{r['label']}: balls {r['ball_mm']:.2f} mm on average, voxel volume error {r['volume_error']:+.2f} %, "
              f"sieve size {r['sieve_error']:+.2f} %; largest overlap in the plate snapshots: ball-ball "
              f"{100 * bb:.1f} % of the smaller radius (t = {tb:.3g} s), ball-plate {100 * bw:.1f} % (t = {tw:.3g} s)")
    print(f"wrote {out / 'ballast_clumps.png'} and {out / 'ballast_clumps.csv'}")


if __name__ == "__main__":
    main()
