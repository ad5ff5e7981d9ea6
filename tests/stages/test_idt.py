"""Indirect tension (``idt``, issue #32): the stage's records and ITS, the elastic stress at the
centre of the disk against the Brazilian solution, and the rate check."""

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.state import read_state

SMOKE = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "indirect_tension.yaml"
CENTRE = "stages.split.measure=[{name: centre, type: cylinder, base: [0, 0, 0], axis: [0, 0, 1], radius: 5 mm, " \
         "span: [0, 4 mm]}]"
D, T = 20e-3, 4e-3


@pytest.fixture(scope="module")
def split(tmp_path_factory):
    out = tmp_path_factory.mktemp("idt") / "run"
    run_case(SMOKE, out=out, overrides=[CENTRE], quiet=True)
    return out


def test_the_disk_splits_and_its_strength_is_2p_over_pi_t_d(split):
    rows = read_record(split / "records" / "split_idt.csv")[0]
    p, d = np.asarray(rows["load"]), np.asarray(rows["deformation"])
    broken = np.asarray(rows["broken_tension"]) + np.asarray(rows["broken_shear"])
    res = read_state(split / "01-split.h5")
    # Then the result is the record's peak and ITS = 2 P_max / (pi t D) of the prepared cylinder
    k = int(np.argmax(p))
    assert float(res["idt_result/peak_load"]) == p[k] and float(res["idt_result/deformation_at_peak"]) == d[k]
    assert float(res["idt_result/its"]) == pytest.approx(2 * p[k] / (math.pi * T * D), rel=1e-12)
    assert float(res["idt_result/diameter"]) == D and float(res["idt_result/thickness"]) == T
    assert np.allclose(rows["tensile_stress"], 2 * p / (math.pi * T * D), rtol=1e-12)
    # and the specimen failed: bonds broke around the peak, the load fell to half of it, and the stage
    # stopped there, before its largest deformation (3 % of D)
    assert broken[k] > 0 and broken[-1] > broken[k] and p[-1] < 0.5 * p[k] and d[-1] < 0.03 * D
    # and the loading was quasi-static (kinetic energy at the peak far below the work done)
    assert float(res["idt_result/kinetic_to_work"]) < 1e-2


def test_the_centre_stress_follows_the_brazilian_solution(split):
    # Given the centre region's stress while the disk is elastic (from the first load to the first break)
    m = read_record(split / "records" / "split_measure_centre.csv")[0]
    rows = read_record(split / "records" / "split_idt.csv")[0]
    p = np.asarray(rows["load"])
    broken = np.asarray(rows["broken_tension"]) + np.asarray(rows["broken_shear"])
    first, last = int(np.argmax(p > 0)) + 1, int(np.argmax(broken > 0)) - 1
    assert last - first >= 5
    # Then the horizontal stress across the loaded diameter changes as the elastic disk's,
    # d sigma_yy / dP = -2 / (pi t D) (tension; the measure counts compression positive), within 5 %
    # (the released specimen's residual stress shifts it, so the slope is compared)
    slope = np.polyfit(p[first:last + 1], np.asarray(m["sigma_yy"])[first:last + 1], 1)[0]
    assert slope == pytest.approx(-2 / (math.pi * T * D), rel=0.05)


def test_halving_the_speed_leaves_the_strength(split, tmp_path):
    import shutil

    shutil.copy(split / "00-prepare.h5", tmp_path / "00-prepare.h5")
    run_case(SMOKE, out=tmp_path, overrides=["stages.split.speed=5 mm/s"], quiet=True)
    its = [float(read_state(f / "01-split.h5")["idt_result/its"]) for f in (split, tmp_path)]
    assert its[1] == pytest.approx(its[0], rel=0.01)


def test_bad_idt_input_is_reported():
    result = CliRunner().invoke(cli, ["check", str(SMOKE), "--set", "stages.split.speed=-1"])
    assert result.exit_code == 2 and "speed" in result.output and "Traceback" not in result.output


# ---------------------------------------------------------------------------------------
# 2D (issue #32 item 4): a homogeneous bonded disk against the Brazilian solution, the
# quasi-static warning, and the seed-001 chain's smoke case
# ---------------------------------------------------------------------------------------

R2D, RB, T2D = 10.5e-3 * (1 + 1e-9), 0.5e-3, 1e-3


def _disk_case(tmp_path, speed):
    """A 2D case: the hexagonal lattice of balls of radius RB wholly inside a disk of radius R2D
    (``particles`` from a CSV file), every touching pair one unbreakable contact bond, split at
    ``speed``."""
    from demcli.geometry.section2d import Specimen, hex_lattice

    lat = hex_lattice(Specimen("circle", R2D), RB)
    rows = ["x,y,z,vx,vy,vz,wx,wy,wz,radius,material"]
    rows += [f"{x!r},{y!r},0,0,0,0,0,0,0,{RB!r},grain" for x, y in lat.centres.tolist()]
    (tmp_path / "disk.csv").write_text("\n".join(rows) + "\n")
    case = {"name": "idt_disk", "seed": 1, "dimension": 2, "thickness": f"{T2D} m",
            "materials": {"grain": {"density": "2000 kg/m^3", "young": "1 GPa", "poisson": 0.3, "friction": 0.5,
                                    "restitution": 0.5},
                          "steel": {"density": "7800 kg/m^3", "young": "200 GPa", "poisson": 0.3, "friction": 0.5,
                                    "restitution": 0.5}},
            "stages": [{"name": "disk", "type": "particles", "file": "disk.csv"},
                       {"name": "split", "type": "idt", "speed": speed, "max_deformation": 0.004,
                        "head_material": "steel", "contact": {"law": "linear", "kn": "1e6 N/m"},
                        "bonds": {"create": True, "models": [{"model": "contact_bond", "materials": ["grain", "grain"],
                                                              "kn": "1e6 N/m", "ks": "2.5e5 N/m"}]},
                        "physics": {"local_damping": 0.3, "friction": True}, "time": {"dt_factor": 0.2},
                        "output": {"records": 50, "snapshots": 0}}]}
    path = tmp_path / "idt_disk.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False))
    return path


def brazilian_stress(p, t, d, xy):
    """The Brazilian stress [Pa] (tension positive; columns sigma_xx, sigma_yy) at points xy (n, 2)
    [m] from the disk's centre: loads P [N] at (+-D/2, 0) on a disk of diameter d and thickness t,
    sigma = -(2 P / (pi t)) (u1 u1 / r1 + u2 u2 / r2) + 2 P / (pi t d) I (u_k the unit vectors from
    the load points, r_k the distances; Timoshenko & Goodier sec. 41): at the centre
    sigma_yy = 2 P / (pi t d), sigma_xx = -6 P / (pi t d)."""
    xy = np.asarray(xy, float)
    out = np.full((len(xy), 2), 2 * p / (math.pi * t * d))
    for sx in (0.5 * d, -0.5 * d):
        rel = xy - [sx, 0.0]
        r = np.hypot(rel[:, 0], rel[:, 1])
        out -= 2 * p / (math.pi * t) * rel ** 2 / r[:, None] ** 3
    return out


def centre_stress(state, a, t):
    """Love-Weber stress [Pa] (compression positive, (3, 3)) of the balls whose centres lie within
    a [m] of the disk's centre, and those centres (relative to it): sigma = (1 / V) sum_sides
    (x_b - x_c) (x) f, over each such ball's bonds, (x_b - x_c) half the branch, f the bond's force on
    the ball (F_n n + F_s on i, n from j to i), V = their hexagonal cells, n 2 sqrt(3) r^2 t."""
    from demcli.measure.tensors import love_weber

    xs = state.sphere_centres()
    rel = xs - xs.mean(axis=0)
    inside = np.hypot(rel[:, 0], rel[:, 1]) <= a
    i, j = np.asarray(state["bonds/i"], np.int64), np.asarray(state["bonds/j"], np.int64)
    branch = xs[i] - xs[j]
    n = branch / np.linalg.norm(branch, axis=1)[:, None]
    force = np.asarray(state["bonds/force_n"])[:, None] * n + np.asarray(state["bonds/force_s"])
    mi, mj = inside[i], inside[j]
    volume = inside.sum() * 2 * math.sqrt(3) * RB ** 2 * t
    sigma = love_weber(0.5 * np.concatenate([branch[mi], branch[mj]]), np.concatenate([force[mi], force[mj]]),
                       volume)
    return sigma, rel[inside, :2]


@pytest.fixture(scope="module")
def disk(tmp_path_factory):
    base = tmp_path_factory.mktemp("idt_disk")
    run_case(_disk_case(base, "5 mm/s"), out=base / "run", quiet=True)
    return base / "run"


def test_2d_disk_centre_stress_is_the_brazilian_solution(disk):
    st = read_state(disk / "01-split.h5")
    d, t = float(st["idt_result/diameter"]), float(st["idt_result/thickness"])
    # Given the disk (its loaded balls on the circle: D = 2 R, the heads' first gap) and the load P on
    # the moving head at the end, and the stress of the balls within R/4 of the centre from their bonds
    assert t == T2D and d == pytest.approx(2 * R2D, rel=1e-6)
    p = float(-st["walls/force"][1] @ st["walls/normal"][1])
    sigma, pts = centre_stress(st, R2D / 4, t)
    exact = brazilian_stress(p, t, d, pts).mean(axis=0)
    err = (-sigma[1, 1] / exact[1] - 1, -sigma[0, 0] / exact[0] - 1)
    print("P", p, "balls", len(pts), "sigma_yy", -sigma[1, 1], "exact", exact[1], "2P/(pi t D)",
          2 * p / (math.pi * t * d), "sigma_xx", -sigma[0, 0], "exact", exact[0], "rel errors", err)
    # Then the tension across the loaded diameter is the Brazilian one (2 P / (pi t D) at the centre; the
    # mean over the same balls) within 5 %, and the compression along the load too (measured: sigma_yy
    # +4.1 %, sigma_xx +3.7 % over the 19 balls within R/4 of the centre; 367 balls of r = 0.5 mm,
    # D = 21 mm, at 0.4 % of D deformation)
    assert abs(err[0]) < 0.05 and abs(err[1]) < 0.05
    # and the loading was quasi-static: no warning, kinetic energy / work small on every counted row
    assert "warning" not in (disk / "log.txt").read_text()
    rows = read_record(disk / "records" / "split_idt.csv")[0]
    assert np.nanmax(rows["kinetic_to_work"][5:]) < 0.01


def test_2d_disk_split_too_fast_warns(tmp_path):
    # Given the same disk split 200 times faster (1 m/s: the heads cross 0.4 % of D in 80 us, a few
    # wave transits)
    run_case(_disk_case(tmp_path, "1 m/s"), out=tmp_path / "run", quiet=True)
    # Then the kinetic energy is a large share of the work and the log warns
    log = (tmp_path / "run" / "log.txt").read_text()
    assert "warning: the loading is not quasi-static: kinetic energy" in log


SMOKE_2D = SMOKE.parent / "marshall_2d_idt.yaml"


def test_2d_section_smoke_case_splits(tmp_path):
    # Given the seed-001 chain on a 30 mm disk, bonded at the idt stage's start
    run_case(SMOKE_2D, out=tmp_path, quiet=True)
    res = read_state(tmp_path / "03-split.h5")
    rows = read_record(tmp_path / "records" / "split_idt.csv")[0]
    p = np.asarray(rows["load"])
    broken = np.asarray(rows["broken_tension"]) + np.asarray(rows["broken_shear"])
    k = int(np.argmax(p))
    # Then ITS = 2 P_max / (pi t D) with t the case's thickness and D the heads' first gap (the disk)
    d, t = float(res["idt_result/diameter"]), float(res["idt_result/thickness"])
    assert t == 1e-3 and d == pytest.approx(30e-3, abs=0.8e-3)
    assert float(res["idt_result/its"]) == pytest.approx(2 * p[k] / (math.pi * t * d), rel=1e-12)
    # and the section failed: bonds broke, the load fell below half the peak
    assert broken[-1] > broken[k] > 0 and p[-1] < 0.5 * p[k]
    # and the loading was quasi-static up to the peak (measured: MEASURED_SMOKE)
    assert float(res["idt_result/kinetic_to_work"]) < 0.01
    assert "warning" not in (tmp_path / "log.txt").read_text()


def test_2d_idt_on_a_rectangle_is_refused(tmp_path):
    bad = yaml.safe_load(SMOKE_2D.read_text())
    bad["stages"][0]["specimen"] = {"shape": "rectangle", "width": "30 mm", "height": "20 mm"}
    bad["stages"][1]["specimen"] = bad["stages"][0]["specimen"]
    path = tmp_path / "rect.yaml"
    path.write_text(yaml.safe_dump(bad, sort_keys=False))
    result = CliRunner().invoke(cli, ["check", str(path)])
    assert result.exit_code == 2 and "indirect tension is a test of a disk" in result.output
    assert "stages[3]" in result.output and "rectangle" in result.output and "Traceback" not in result.output
