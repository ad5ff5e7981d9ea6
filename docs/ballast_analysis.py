"""Two looks at the cyclic records of ballast box runs: the settlement's smooth trend, and how the
loading device moves within each load cycle.

    python docs/ballast_analysis.py trend runs/ballast_wide runs/ballast_single_large [...]
    python docs/ballast_analysis.py trend docs/ballast_figures_full/xeon/sleeper_settlement_settlement.csv
    python docs/ballast_analysis.py response runs/ballast_wide [...]

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
``records_per_cycle`` samples per load cycle, 4 in the cases) and fits, per load cycle N (the
samples with N - 1 < cycle <= N), the device's height z(phase) = m + c cos 2 pi phase + s sin
2 pi phase by least squares (phase = cycle - (N - 1); the load is F_min at phase 0 and 1, F_max
at 0.5), with the fit the stages use for their own ``swing`` and ``lag`` columns (runs made
before those columns existed are read this way). Per stage, medians over the cycles: the swing
2 sqrt(c^2 + s^2) [mm]; where in the cycle the device is lowest (0.5 for a quasi-static
response, which follows the load; 0.75 a quarter cycle behind it); the kinetic energy at the end
of the cycle (F_min) against the one before the first cycle [J]; the lowest coordination number
in the cycle; and the device's height at F_min against its cycle mean m, whose difference is
how much a reading at F_min depends on where the swing is.
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
    the stage's own (:func:`demcli.stages.ballast_box.cycle_response`)."""
    from demcli.stages.ballast_box import cycle_response

    cycle, z = cols["cycle"], cols[device]
    r = cycle_response(cycle, z)
    rows = []
    for n, swing, lag, mean in zip(r["cycle"], r["swing"], r["lag"], r["mean"]):
        k = np.where((cycle > n - 1 + 1e-6) & (cycle <= n + 1e-6))[0]
        rows.append((n, swing, lag + 0.5, cols["kinetic"][k[-1]], cols["coordination"][k].min(), z[k[-1]], mean))
    return np.array(rows)


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
