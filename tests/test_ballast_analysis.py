"""docs/ballast_analysis.py: the power-law trend of sleeper settlement and the within-cycle response
of the loading devices, against known curves."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parent.parent / "docs" / "ballast_analysis.py"


def load():
    spec = importlib.util.spec_from_file_location("ballast_analysis", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def write_run(root, settlement_mm):
    rec = root / "records"
    rec.mkdir(parents=True)
    n = np.arange(len(settlement_mm))
    rows = np.column_stack([n, 0.5 - settlement_mm * 1e-3, settlement_mm * 1e-3])
    np.savetxt(rec / "sleeper_settlement.csv", rows, delimiter=",", header="cycle[1],sleeper[m],settlement[m]",
               comments="")


def test_power_law_is_recovered_and_a_jump_shows_in_the_residuals(tmp_path):
    # Given a run whose settlement is exactly 4 N^0.6 mm over 80 cycles, and one with a 3 mm
    # step from cycle 40 on
    mod = load()
    n = np.arange(81.0)
    write_run(tmp_path / "smooth", 4.0 * n ** 0.6)
    stepped = 4.0 * n ** 0.6 + 3.0 * (n >= 40)
    write_run(tmp_path / "stepped", stepped)
    # When the trend is fitted
    a, b, rms, worst, fit, last, n_last = mod.trend(*mod.curves(tmp_path / "smooth")["smooth"])
    # Then the smooth run gives a, b back with no residual, and the fitted and recorded final
    # values agree
    assert (a, b) == pytest.approx((4.0, 0.6), rel=1e-8)
    assert rms < 1e-8 and worst < 1e-8 and n_last == 80
    assert fit == pytest.approx(last, rel=1e-8) and last == pytest.approx(4.0 * 80 ** 0.6, rel=1e-12)
    # And the stepped one scatters about its fit by a good part of the step
    _, _, rms, worst, _, last, _ = mod.trend(*mod.curves(tmp_path / "stepped")["stepped"])
    assert 0.5 < rms < 3.0 and 1.0 < worst <= 3.0
    assert last == pytest.approx(stepped[-1], rel=1e-12)


def test_overlay_csv_gives_the_same_curves_as_the_run_folders(tmp_path):
    # Given two run folders and the overlay CSV demcli compare writes from them (run, cycle,
    # settlement [m])
    mod = load()
    n = np.arange(81.0)
    runs = {"bed_a": 4.0 * n ** 0.6, "bed_b": 2.0 * n ** 0.7 + 0.1 * np.sin(n)}
    lines = ["run,cycle[1],settlement[m]"]
    for name, s in runs.items():
        write_run(tmp_path / name, s)
        lines += [f"{name},{float(c)!r},{float(v) * 1e-3!r}" for c, v in zip(n, s)]
    (tmp_path / "overlay.csv").write_text("\n".join(lines) + "\n")
    # When both are read
    overlay = mod.curves(tmp_path / "overlay.csv")
    # Then the overlay holds both runs in order, with the same cycles and settlements
    assert list(overlay) == ["bed_a", "bed_b"]
    for name in runs:
        cycle, settlement = mod.curves(tmp_path / name)[name]
        np.testing.assert_array_equal(overlay[name][0], cycle)
        np.testing.assert_allclose(overlay[name][1], settlement, rtol=1e-15, atol=0)


@pytest.mark.parametrize("lowest", [0.5, 0.6, 0.76])
def test_response_recovers_swing_and_phase_of_a_known_motion(lowest):
    # Given dem records of a device that sinks 0.1 mm per cycle and swings 30 mm peak to peak,
    # lowest at a given phase of each load cycle (0.5 = with the peak load), sampled 4 times per
    # cycle after 6 samples before the cycles start
    mod = load()
    cycle = np.r_[np.linspace(-1.5, -0.25, 6), np.arange(1, 41) * 0.25]
    phase = np.where(cycle > 0, cycle, 0.0)
    z = 0.5 - 1e-4 * phase - 0.015 * np.cos(2 * np.pi * (phase - lowest))
    cols = {"cycle": cycle, "plate": z, "kinetic": 1.0 + cycle ** 2, "coordination": 5.0 - np.abs(np.sin(cycle))}
    # When the response is fitted per cycle
    r = mod.response(cols, "plate")
    # Then every cycle 1..10 is found with the 30 mm swing and the phase of its lowest point (to
    # the drift's effect, 0.1 mm per cycle against 15 mm), the kinetic energy at its end, the
    # lowest coordination of its samples, and the height at F_min against the cycle mean
    assert r[:, 0].tolist() == list(range(1, 11))
    np.testing.assert_allclose(r[:, 1], 0.030, rtol=0.01)
    np.testing.assert_allclose(r[:, 2], lowest, atol=0.003)
    np.testing.assert_allclose(r[:, 3], 1.0 + np.arange(1, 11) ** 2, rtol=1e-12)
    for n in range(1, 11):
        k = (cycle > n - 1) & (cycle <= n)
        assert r[n - 1, 4] == cols["coordination"][k].min()
        assert r[n - 1, 5] == z[np.isclose(cycle, n)][0]
    # (the cycle mean is the mean of the 4 samples: the drift puts it 0.375 x 0.1 mm above F_min's)
    np.testing.assert_allclose(r[:, 5] - r[:, 6], -0.015 * np.cos(2 * np.pi * lowest) - 0.375e-4, rtol=0, atol=1e-12)


def _boxes(boxes):
    """meshio Mesh of axis-aligned boxes [(lo, hi, material)], each as 12 outward triangles."""
    import meshio

    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    points, tris, body, material = [], [], [], []
    for k, (lo, hi, mat) in enumerate(boxes):
        corner = [[(lo, hi)[i & 1][0], (lo, hi)[i >> 1 & 1][1], (lo, hi)[i >> 2 & 1][2]] for i in range(8)]
        base = 8 * k
        points += corner
        for a, b, c, d in quads:
            tris += [(base + a, base + b, base + c), (base + a, base + c, base + d)]
        body += [k] * 12
        material += [mat] * 12
    return meshio.Mesh(np.array(points, float), [("triangle", np.array(tris))],
                       cell_data={"body": [np.array(body)], "material": [np.array(material)]})


def test_column_counts_the_solids_under_the_sleeper_and_what_left(tmp_path):
    # Given two sleeper snapshots of cubes (edge 0.05 m) and a 0.2 x 0.1 m sleeper (material 1):
    # at t = 0.5 s two cubes under it, one beside it, one on its top; at t = 1.5 s the sleeper
    # is 20 mm lower and one cube has moved out from under it. The dem record maps t = 0..2 s
    # to cycles -1..1.
    from demcli.state.vtu import PvdSeries

    mod = load()
    run = tmp_path / "run"
    (run / "sleeper").mkdir(parents=True)
    (run / "records").mkdir()
    (run / "records" / "sleeper_dem.csv").write_text("time[s],cycle[1]\n0,-1\n1,0\n2,1\n")

    def cube(x, z):
        return (np.array([x - 0.025, 0.025, z - 0.025]), np.array([x + 0.025, 0.075, z + 0.025]), 0)

    series = PvdSeries(run / "sleeper" / "polyhedra.pvd")
    for k, (time, base, first_x) in enumerate([(0.5, 0.30, 0.3), (1.5, 0.28, 0.5)]):
        sleeper = (np.array([0.2, 0.0, base]), np.array([0.4, 0.1, base + 0.1]), 1)
        mesh = _boxes([cube(first_x, 0.1), cube(0.3, 0.2), cube(0.1, 0.1), cube(0.3, base + 0.15), sleeper])
        path = run / "sleeper" / f"polyhedra_{k:06d}.vtu"
        mesh.write(path)
        series.add(time, path)
    # When the column under the sleeper is measured
    rows = mod.column(run)
    # Then the cycles, base heights, counts, solid volumes and solid fractions are the exact ones
    a3, area = 0.05 ** 3, 0.02
    (t0, c0, h0, n0, v0, phi0, top0, area0), (t1, c1, h1, n1, v1, phi1, top1, area1) = rows
    assert (c0, c1) == pytest.approx((-0.5, 0.5), abs=1e-12)
    assert (h0, h1) == pytest.approx((0.30, 0.28), abs=1e-12)
    assert (n0, n1, top0, top1) == (2, 1, 1, 1)
    assert (v0, v1) == pytest.approx((2 * a3, a3), rel=1e-12)
    assert area0 == pytest.approx(area, rel=1e-12) and area1 == pytest.approx(area, rel=1e-12)
    assert phi0 == pytest.approx(2 * a3 / (area * 0.30), rel=1e-12)
    assert phi1 == pytest.approx(a3 / (area * 0.28), rel=1e-12)
