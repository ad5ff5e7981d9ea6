"""Smooth trend and scatter of the accumulated sleeper settlement of ballast runs.

    python docs/ballast_trend.py runs/ballast_wide runs/ballast_single_large [...]
    python docs/ballast_trend.py docs/ballast_figures_full/sleeper_settlement_settlement.csv

Reads each run's ``records/sleeper_settlement.csv`` (cycle, sleeper height [m], settlement [m]),
or the overlay CSV that ``demcli compare --record sleeper_settlement`` writes (run, cycle,
settlement [m]; one curve per run, the shipped figures' data), and fits the power law s(N) = a N^b [mm] to cycles 1..N_last by least squares (scipy
``curve_fit``). It serves only as a smooth trend: empirical ballast settlement models in the
number of load cycles take this and other forms (reviewed by Abadi, Le Pen, Zervos & Powrie
2016, "A review and evaluation of ballast settlement models using results from the Southampton
Railway Testing Facility", Procedia Engineering 143). Prints per run: a, b, the rms and largest
residual about the fit, the fitted and the recorded settlement at the last cycle.

The residuals measure how far one realisation's curve departs from its own smooth trend (single
rearrangements under the sleeper); they are a lower bound on the scatter between realisations,
which also differ in their initial packing.
"""

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import curve_fit


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


def main(paths):
    print("| run | a [mm] | b | rms residual [mm] | largest residual [mm] | fitted / recorded at the last cycle [mm] |")
    print("|---|---|---|---|---|---|")
    for path in paths:
        for name, (cycle, settlement) in curves(path).items():
            a, b, rms, worst, fit, last, n = trend(cycle, settlement)
            print(f"| {name} | {a:.2f} | {b:.3f} | {rms:.2f} | {worst:.2f} | {fit:.1f} / {last:.2f} (cycle {n}) |")


if __name__ == "__main__":
    main(sys.argv[1:])
