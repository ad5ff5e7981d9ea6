"""The sand-asphalt stages (prepare, creep; seed 003) on the smoke chains, their measures
against hand computations, the pressure-loaded membrane, and bad input."""

import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from demcli import run_case
from demcli.cli import cli
from demcli.compare import read_record
from demcli.kernels.bonds import BURGERS, INTACT
from demcli.stages.asphalt.sand import confining_stress, dilation_gradient, loading_work, strains
from demcli.state import read_state

ROOT = Path(__file__).resolve().parents[2]
SMOKE = ROOT / "cases" / "smoke"


def _csv(path):
    """Columns of a record CSV by name."""
    return read_record(path)[0]


@pytest.fixture(scope="module")
def uniaxial(tmp_path_factory):
    out = tmp_path_factory.mktemp("sa_uni")
    run_case(SMOKE / "sand_asphalt_uniaxial.yaml", out=out, quiet=True)
    return out


@pytest.fixture(scope="module")
def triaxial(tmp_path_factory):
    out = tmp_path_factory.mktemp("sa_tri")
    run_case(SMOKE / "sand_asphalt_triaxial.yaml", out=out, quiet=True)
    return out


def test_prepare_reaches_the_target_stress_and_bonds_every_contact(uniaxial):
    st = read_state(uniaxial / "00-prepare.h5")
    rec = _csv(uniaxial / "records" / "prepare_prepare.csv")
    phase = rec["phase"].astype(int)
    # Then: radius reduction ran until the isotropic stress fell below 1 kPa (seed step 4), the
    # cuts summing to less than max_reduction (5 %)
    reduce = phase == 3
    assert reduce.any() and rec["isotropic_stress"][reduce][-1] <= 1e3
    assert np.all(rec["isotropic_stress"][reduce][:-1] > 1e3)
    assert 0.95 < float(st["bonded_specimen/radius_factor"]) < 1.0
    # and the solid fraction is the sphere volume over the cylinder (hand formula, 1e-12)
    r = st["spheres/radius"]
    vcyl = math.pi * 5e-3 ** 2 * 10e-3
    assert float(st["bonded_specimen/solid_fraction"]) == pytest.approx(4 / 3 * math.pi * np.sum(r ** 3) / vcyl,
                                                                         rel=1e-12)
    # and every touching pair is a Burgers bond, intact, with unloaded elements; nothing else touches
    i, j = st["bonds/i"], st["bonds/j"]
    d = np.linalg.norm(st["bodies/x"][i] - st["bodies/x"][j], axis=1)
    assert len(i) > 0 and np.all(d < r[i] + r[j] + 1e-6 * np.median(r))
    assert np.all(st["bonds/state"] == INTACT)
    assert list(st["bond_models/kind"]) == ["burgers"] and st["bond_models/params"][0, 0] == BURGERS
    assert len(st["contacts/i"]) == 0
    # and the coordination number is the bonds per sphere (2 N_b / N)
    assert float(st["bonded_specimen/coordination"]) == pytest.approx(2 * len(i) / len(r), rel=1e-12)
    # and the wall is gone: the state holds no walls
    assert "walls/kind" not in st


def test_uniaxial_creep_holds_the_stress_and_creeps(uniaxial):
    rec = _csv(uniaxial / "records" / "creep_creep.csv")
    st = read_state(uniaxial / "01-creep.h5")
    late = rec["time"] > 2.0
    # Then: the dead load holds 400 kPa on the platen (mean after the 2 s start within 1 %)
    assert rec["axial_stress"][late].mean() == pytest.approx(400e3, rel=0.01)
    # and the specimen creeps: shorter every 2 s after the load is on (Maxwell dashpots; the dead
    # load's platen rings by ~1e-5 from record to record, measured)
    t = rec["time"]
    ea = np.interp([2.0, 4.0, 6.0, 8.0, 10.0], t, rec["axial_strain"])
    assert ea[0] < 0 and np.all(np.diff(ea) < 0)
    # and the strains follow their definitions (tension positive, e_v = e_a + 2 e_r, e_d = |2/3 (e_a - e_r)|)
    ea, er, ev, ed = strains(1.0, 1.0 + rec["axial_strain"], 1.0, 1.0 + rec["radial_strain"])
    assert np.allclose(ev, rec["volumetric_strain"], atol=1e-15)
    assert np.allclose(ed, rec["distortional_strain"], atol=1e-15)
    # and the summary's dilation gradient is the least-squares slope of e_v on e_d in the window
    slope = dilation_gradient(rec["distortional_strain"], rec["volumetric_strain"], (0.004, 0.04))  # the case's
    assert math.isfinite(slope)  # the smoke reaches its window
    assert float(st["creep_result/dilation_gradient"]) == pytest.approx(slope, rel=1e-12)
    assert float(st["creep_result/sigma_1"]) == 400e3 and float(st["creep_result/sigma_3"]) == 0.0
    # and the bonds held (no strength given)
    assert np.all(st["bonds/state"] == INTACT)
    assert (uniaxial / "records" / "creep_creep.png").exists()
    assert (uniaxial / "records" / "creep_creep_dilation.png").exists()
    # and the snapshots hold the bond network for ParaView: one line per bond between the centres
    import meshio

    mesh = meshio.read(sorted((uniaxial / "creep").glob("bonds_*.vtu"))[-1])
    assert mesh.cells[0].type == "line" and len(mesh.cells[0].data) == len(st["bonds/i"])
    assert np.array_equal(np.sort(mesh.cells[0].data, axis=1), np.c_[st["bonds/i"], st["bonds/j"]])
    assert np.allclose(mesh.cell_data["force_n"][0], st["bonds/force_n"])
    assert (uniaxial / "creep" / "bonds.pvd").exists()


def test_triaxial_creep_confines_through_the_membrane(triaxial):
    rec = _csv(triaxial / "records" / "creep_creep.csv")
    st = read_state(triaxial / "01-creep.h5")
    s1, s3 = confining_stress(type("T", (), {"type": "triaxial", "deviator": 400e3, "stress_ratio": 0.6})())
    # Then: sigma_3 = (p/q - 1/3) q = 106.7 kPa, sigma_1 = sigma_3 + q (hand formula)
    assert s3 == pytest.approx(400e3 * (0.6 - 1 / 3), rel=1e-12) and s1 == pytest.approx(s3 + 400e3, rel=1e-12)
    late = rec["time"] > 2.0
    assert rec["axial_stress"][late].mean() == pytest.approx(s1, rel=0.01)
    # and the membrane carries the confining pressure: the normal forces of the spheres on it over
    # its (nominal) area balance the pressure at the end, within 2 % (a creeping, nearly static specimen)
    w = list(st["walls/name"]).index("membrane")
    sph, wall, f = st["wall_contacts/sphere"], st["wall_contacts/wall"], st["wall_contacts/force"]
    on = wall == w
    x = st["bodies/x"][sph[on]]
    centre = st["walls/point"][w]
    radial = np.c_[x[:, 0] - centre[0], x[:, 1] - centre[1], np.zeros(on.sum())]
    radial /= np.linalg.norm(radial, axis=1)[:, None]
    push = -np.einsum("ij,ij->i", f[on], radial).sum()  # the force on each sphere points inwards
    area = 2 * math.pi * 5e-3 * 10e-3
    assert push / area == pytest.approx(s3, rel=0.02)
    # and the radial strain is the membrane's: e_r = R / R0 - 1
    assert rec["radial_strain"][-1] == pytest.approx(float(st["walls/radius"][w]) / 5e-3 - 1.0, abs=1e-12)
    # and the specimen compacts first (e_v < 0 at the start of loading, as in the seed)
    assert rec["volumetric_strain"][1] < 0


@pytest.mark.parametrize("override, message", [
    ("stages.prepare.radius=1 mm", "give exactly one of count and radius"),
    ("stages.creep.test.stress_ratio=0.3", "must exceed 1/3"),
    ("stages.prepare.bonds.models.0.materials=[sand, clay]", "unknown material 'clay'"),
])
def test_bad_input_exits_2_with_the_rule(tmp_path, override, message):
    res = CliRunner().invoke(cli, ["run", str(SMOKE / "sand_asphalt_triaxial.yaml"), "--out", str(tmp_path),
                                   "--set", override, "--quiet"])
    assert res.exit_code == 2, res.output
    assert message in res.output and "Traceback" not in res.output


def test_interrupted_triaxial_creep_resumes_bit_identically(triaxial, tmp_path, h5_differences,
                                                             interrupt_and_resume):
    import shutil

    from demcli.engine.system import System

    # Given: the prepared specimen, and its triaxial creep interrupted (Ctrl-C) while the membrane
    # and the platen move and the Burgers elements creep; when it is resumed
    shutil.copy(triaxial / "00-prepare.h5", tmp_path / "00-prepare.h5")
    interrupt_and_resume(System, 5000, SMOKE / "sand_asphalt_triaxial.yaml", tmp_path, "01-creep.ckpt.h5")
    # Then: the creep state equals the uninterrupted run's, dataset for dataset
    assert h5_differences(triaxial / "01-creep.h5", tmp_path / "01-creep.h5") == []


def test_bonded_chain_is_bit_identical_for_1_and_2_threads(tmp_path, h5_differences):
    # Given: the triaxial smoke chain (bond pass, bond gather, membrane) on 1 and on 2 threads
    for k in (1, 2):
        run_case(SMOKE / "sand_asphalt_triaxial.yaml", out=tmp_path / str(k), quiet=True, threads=k)
    # Then: every dataset of both states is bit-identical
    for name in ("00-prepare.h5", "01-creep.h5"):
        assert h5_differences(tmp_path / "1" / name, tmp_path / "2" / name) == [], name


def test_a_share_of_the_contacts_bonded_leaves_the_others_as_contacts(uniaxial, tmp_path):
    # Given: the same specimen prepared with bonds.fraction = 0.6 (the seed's variant with
    # frictional contacts; same seed, so the same packing up to the bonding)
    run_case(SMOKE / "sand_asphalt_uniaxial.yaml", out=tmp_path, quiet=True, only="prepare",
             overrides=["stages.prepare.bonds.fraction=0.6"])
    full = read_state(uniaxial / "00-prepare.h5")
    part = read_state(tmp_path / "00-prepare.h5")
    assert np.array_equal(part["bodies/x"], full["bodies/x"])
    every = set(zip(full["bonds/i"].tolist(), full["bonds/j"].tolist()))
    bonded = set(zip(part["bonds/i"].tolist(), part["bonds/j"].tolist()))
    # Then: 60 % of the touching pairs are bonds (rounded), drawn from them
    assert len(bonded) == round(0.6 * len(every)) and bonded < every
    # and every touching pair left unbonded is an ordinary contact
    x, r = part["bodies/x"], part["spheres/radius"]
    overlapping = {(i, j) for i, j in every - bonded if np.linalg.norm(x[i] - x[j]) < r[i] + r[j]}
    contacts = set(zip(part["contacts/i"].tolist(), part["contacts/j"].tolist()))
    assert overlapping and overlapping <= contacts and not contacts & bonded


def test_loading_work_is_the_platen_and_membrane_work_integrals():
    # Given: a platen force growing linearly with the shortening u (F = k u) at a fixed radius, and a
    # radius growing linearly at a fixed height under a confining stress
    k, h0 = 2.0e6, 0.1
    u = np.linspace(0.0, 1e-3, 11)
    w_axial = loading_work(k * u, h0 - u, np.full(11, 0.05), 0.0)
    r = np.linspace(0.05, 0.051, 11)
    w_membrane = loading_work(np.zeros(11), np.full(11, h0), r, 1e5)
    # Then: the trapezoid rule is exact for these integrands: W = k u^2 / 2, and the membrane does
    # W = -sigma_3 pi h (r1^2 - r0^2) on an expanding specimen (it pushes in while the side moves out)
    assert w_axial[-1] == pytest.approx(0.5 * k * u[-1] ** 2, rel=1e-12)
    assert w_membrane[-1] == pytest.approx(-1e5 * math.pi * h0 * (r[-1] ** 2 - r[0] ** 2), rel=1e-12)


def test_creep_checks_that_it_is_quasi_static_after_the_step_load(uniaxial, tmp_path):
    # Given: the smoke creep run (its rows from 5 % of the duration on are counted)
    st = read_state(uniaxial / "01-creep.h5")
    ratio = _csv(uniaxial / "records" / "creep_creep.csv")["kinetic_to_work"]
    # Then: E_k / W after the transient is small, and the summary holds the largest counted ratio
    assert 0.0 < st["creep_result/kinetic_to_work"] < 0.01
    assert "not quasi-static" not in (uniaxial / "log.txt").read_text()
    # When: the rows of the step load itself are counted too (transient 0)
    shutil.copy(uniaxial / "00-prepare.h5", tmp_path / "00-prepare.h5")
    run_case(SMOKE / "sand_asphalt_uniaxial.yaml", out=tmp_path, quiet=True, only="creep",
             overrides=["stages.creep.transient=0"])
    # Then: the ringing of the step is caught and warned about
    assert read_state(tmp_path / "01-creep.h5")["creep_result/kinetic_to_work"] > 0.01 > np.nanmax(ratio[5:])
    assert "warning: the loading is not quasi-static" in (tmp_path / "log.txt").read_text()
