"""docs/ballast_trend.py: the power-law trend of sleeper settlement against a known curve."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).resolve().parent.parent / "docs" / "ballast_trend.py"


def load():
    spec = importlib.util.spec_from_file_location("ballast_trend", SCRIPT)
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
