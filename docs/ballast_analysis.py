"""Three looks at the cyclic stages of ballast box runs: the settlement's smooth trend, how the
loading device moves within each load cycle, and how much of the sleeper's settlement is stones
leaving the column under it.

    python docs/ballast_analysis.py trend runs/ballast_wide runs/ballast_single_large [...]
    python docs/ballast_analysis.py trend docs/ballast_figures_full/sleeper_settlement_settlement.csv
    python docs/ballast_analysis.py response runs/ballast_wide [...]
    python docs/ballast_analysis.py column runs/ballast_single_small

``trend`` reads each run's ``records/sleeper_settlement.csv`` (cycle, sleeper height [m],
settlement [m]), or the overlay CSV that ``demcli compare --record sleeper_settlement`` writes
(run, cycle, settlement [m]; one curve per run, the shipped figures' data), and fits the power
law s(N) = a N^b [mm] to cycles 1..N_last by least squares (scipy ``curve_fit``). It serves only
as a smooth trend: empirical ballast settlement models in the number of load cycles take this
and other forms (reviewed by Abadi, Le Pen, Zervos & Powrie 2016, "A review and evaluation of
ballast settlement models using results from the Southampton Railway Testing Facility",
Procedia Engineering 143). Per run: a, b, the rms and largest residual about the fit, the fitted
and the recorded settlement at the last cycle. The residuals measure how far one realisation's
curve departs from its own smooth trend (single rearrangements under the sleeper); they are a
lower bound on the scatter between realisations, which also differ in their initial packing.

``response`` reads ``records/vibrate_dem.csv`` and ``records/sleeper_dem.csv`` (the dem records,
``records_per_cycle`` samples per load cycle: 4 in the runs these docs report, 20 by default since) and fits, per load cycle N (the
samples with N - 1 < cycle <= N), the device's height z(phase) = m + c cos 2 pi phase + s sin
2 pi phase by least squares (phase = cycle - (N - 1); the load is F_min at phase 0 and 1, F_max
at 0.5), with the fit the stages use for their own ``swing`` and ``lag`` columns (runs made
before those columns existed are read this way). Per stage, medians over the cycles: the swing
2 sqrt(c^2 + s^2) [mm]; where in the cycle the device is lowest (0.5 for a quasi-static
response, which follows the load; 0.75 a quarter cycle behind it); the kinetic energy at the end
of the cycle (F_min) against the one before the first cycle [J]; the lowest coordination number
in the cycle; and the device's height at F_min against its cycle mean m, whose difference is
how much a reading at F_min depends on where the swing is.

``column`` reads a run's sleeper snapshots (``sleeper/polyhedra.pvd`` and its VTU files) and,
per snapshot, takes each stone's volume and centroid from its triangulated surface
(``demcli.geometry.polyhedron.mass_properties``) and counts the stones whose centroid lies in
the column under the sleeper (inside its footprint in x and y, below its base). Per snapshot: the
load cycle (from the time, by the dem record's time and cycle columns; negative while the
sleeper settles under F_min), the sleeper's base height h [mm] above the box floor (z = 0), the
stones and the solid volume V_s under it, the column's solid fraction phi = V_s / (A h) for the footprint area A, and the
stones whose centroid is above the sleeper's top inside its footprint (shoulder stones that have
spilled onto it). Against the first snapshot: how far the base has sunk, and how much of that
the solids that left the column account for, (V_s,0 - V_s) / (phi A) [mm], the rest being
compaction of the column (and, between snapshots at different phases of a load cycle, the
elastic and dynamic swing: compare snapshots at the same phase).
"""

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import curve_fit

from demcli.compare import read_record


def power_law(n, a, b):
    """s = a N^b [mm]."""
    return a * n ** b


def curves(path):
    """{name: (cycle, settlement [mm])} from a run folder or a ``demcli compare`` overlay CSV."""
    path = Path(path)
    if path.is_dir():
        data = np.genfromtxt(path / "records" / "sleeper_settlement.csv", delimiter=",", skip_header=1)
        return {path.name: (data[:, 0], data[:, 2] * 1e3)}
    names = np.genfromtxt(path, delimiter=",", skip_header=1, usecols=0, dtype=str)
    data = np.genfromtxt(path, delimiter=",", skip_header=1, usecols=(1, 2))
    return {name: (data[names == name, 0], data[names == name, 1] * 1e3) for name in dict.fromkeys(names)}


def trend(cycle, settlement):
    """(a [mm], b [-], rms residual [mm], largest |residual| [mm], fitted s(N_last), recorded s(N_last), N_last)
    for the settlement [mm] against cycle, fitted over cycles >= 1."""
    keep = cycle >= 1
    n, s = cycle[keep], settlement[keep]
    (a, b), _ = curve_fit(power_law, n, s, p0=(5.0, 0.5))
    res = s - power_law(n, a, b)
    return a, b, float(np.sqrt(np.mean(res ** 2))), float(np.abs(res).max()), power_law(n[-1], a, b), s[-1], int(n[-1])


def response(cols, device):
    """Per load cycle N >= 1: (N, swing [m], phase of the lowest point [cycle], kinetic energy at
    F_min [J], lowest coordination [-], height at F_min [m], cycle-mean height [m]), from the dem
    record columns (cycle, kinetic, coordination, and the device's height ``device``); the fit is
    the stage's own (:func:`demcli.stages.ballast.box.cycle_response`)."""
    from demcli.stages.ballast.box import cycle_response

    cycle, z = cols["cycle"], cols[device]
    r = cycle_response(cycle, z)
    rows = []
    for n, swing, lag, mean in zip(r["cycle"], r["swing"], r["lag"], r["mean"]):
        k = np.where((cycle > n - 1 + 1e-6) & (cycle <= n + 1e-6))[0]
        rows.append((n, swing, lag + 0.5, cols["kinetic"][k[-1]], cols["coordination"][k].min(), z[k[-1]], mean))
    return np.array(rows)


def _stones(vtu):
    """(volume [m^3], centroid [m], lowest point [m], highest point [m], material index) per body of a
    polyhedra snapshot."""
    import meshio

    from demcli.geometry.polyhedron import mass_properties

    mesh = meshio.read(vtu)
    tri = mesh.cells_dict["triangle"]
    body = mesh.cell_data_dict["body"]["triangle"]
    material = mesh.cell_data_dict["material"]["triangle"]
    order = np.argsort(body, kind="stable")
    starts = np.searchsorted(body[order], np.arange(body.max() + 2))
    n = body.max() + 1
    volume, centroid = np.zeros(n), np.zeros((n, 3))
    low, high, mat = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros(n, int)
    for k in range(n):
        t = tri[order[starts[k]:starts[k + 1]]]
        used, local = np.unique(t, return_inverse=True)
        pts = mesh.points[used]
        volume[k], centroid[k], _ = mass_properties(pts, local.reshape(t.shape))
        low[k], high[k] = pts.min(axis=0), pts.max(axis=0)
        mat[k] = material[order[starts[k]]]
    return volume, centroid, low, high, mat


def column(run, sleeper_material=None):
    """Rows (time [s], cycle, base [m], stones under, V_s [m^3], phi, stones on top, A [m^2]) per sleeper
    snapshot of a run folder; the sleeper is the body of ``sleeper_material`` (default: the
    highest material index, the one the sleeper stage adds last)."""
    import xml.etree.ElementTree as ET

    run = Path(run)
    sets = ET.parse(run / "sleeper" / "polyhedra.pvd").getroot().iter("DataSet")
    files = dict((float(d.get("timestep")), d.get("file")) for d in sets)  # a time written twice counts once
    cols = read_record(run / "records" / "sleeper_dem.csv")[0]
    rows = []
    for time, name in sorted(files.items()):
        volume, centroid, low, high, mat = _stones(run / "sleeper" / name)
        s = np.flatnonzero(mat == (mat.max() if sleeper_material is None else sleeper_material))[0]
        stone = mat != mat[s]
        over = stone & np.all((centroid[:, :2] >= low[s, :2]) & (centroid[:, :2] <= high[s, :2]), axis=1)
        under = over & (centroid[:, 2] < low[s, 2])
        area = np.prod(high[s, :2] - low[s, :2])
        solids = volume[under].sum()
        rows.append((time, float(np.interp(time, cols["time"], cols["cycle"])), low[s, 2], int(under.sum()), solids,
                     solids / (area * low[s, 2]), int((over & (centroid[:, 2] > high[s, 2])).sum()), area))
    return rows


def main(argv):
    what, paths = argv[0], argv[1:]
    if what == "trend":
        print("| run | a [mm] | b | rms residual [mm] | largest residual [mm] | fitted / recorded at the last cycle [mm] |")
        print("|---|---|---|---|---|---|")
        for path in paths:
            for name, (cycle, settlement) in curves(path).items():
                a, b, rms, worst, fit, last, n = trend(cycle, settlement)
                print(f"| {name} | {a:.2f} | {b:.3f} | {rms:.2f} | {worst:.2f} | {fit:.1f} / {last:.2f} (cycle {n}) |")
        return
    if what == "column":
        for path in paths:
            rows = column(path)
            t0, c0, h0, n0, v0, phi0, top0, area = rows[0]
            print(f"{Path(path).name}: footprint {area:.4f} m^2; against the first snapshot (cycle {c0:.2f})")
            print("| cycle | base [mm] | stones under | solids under [cm^3] | solid fraction | stones on top | "
                  "sunk [mm] | of which solids that left [mm] |")
            print("|---|---|---|---|---|---|---|---|")
            for t, c, h, n, v, phi, top, _ in rows:
                print(f"| {c:.2f} | {h * 1e3:.1f} | {n} | {v * 1e6:.0f} | {phi:.4f} | {top} | "
                      f"{(h0 - h) * 1e3:.1f} | {(v0 - v) / (phi * area) * 1e3:.1f} |")
        return
    print("| run | stage | cycles | swing [mm] | lowest at phase | kinetic energy at F_min, cycle 0 / median [J] | "
          "lowest coordination, median | height at F_min minus cycle mean, median [mm] |")
    print("|---|---|---|---|---|---|---|---|")
    for path in paths:
        for stage, device in (("vibrate", "plate"), ("sleeper", "sleeper")):
            f = Path(path) / "records" / f"{stage}_dem.csv"
            if not f.exists():
                continue
            cols = read_record(f)[0]
            r = response(cols, device)
            if not len(r):
                continue
            ke0 = cols["kinetic"][np.isclose(cols["cycle"], 0.0)]
            print(f"| {Path(path).name} | {stage} | {int(r[-1, 0])} | {np.median(r[:, 1]) * 1e3:.1f} "
                  f"({r[:, 1].min() * 1e3:.1f}-{r[:, 1].max() * 1e3:.1f}) | {np.median(r[:, 2]):.2f} | "
                  f"{ke0[0] if len(ke0) else float('nan'):.2f} / {np.median(r[:, 3]):.1f} | {np.median(r[:, 4]):.2f} | "
                  f"{np.median(r[:, 5] - r[:, 6]) * 1e3:+.1f} |")


if __name__ == "__main__":
    main(sys.argv[1:])
