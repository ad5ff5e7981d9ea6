"""Bonds by phase pair on the 3D asphalt specimen (seed 000 step 9): a ``dem`` stage after the
mastic stage takes its contact models from the phase table (``bonds.from_phases``)."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from demcli import run_case
from demcli.kernels.bonds import B_KIND, B_SN, B_SS, CONTACT_BOND, INTACT, PARALLEL_BOND
from demcli.state import read_state
from demcli.state.order import sphere_rows_by_id

ROOT = Path(__file__).resolve().parents[2]


def _bonded_case(folder, mastic=None, **stage):
    case = yaml.safe_load((ROOT / "cases" / "smoke" / "marshall_ac13_3d.yaml").read_text())
    case["stages"][5].update(mastic or {})
    case["stages"].append({"name": "bonded", "type": "dem", "physics": {"gravity": [0, 0, -9.81], "friction": True},
                           "contact": {"law": "linear", "kn": "1e6 N/m"},
                           "bonds": {"from_phases": True, "create": True, "gap": 1e-3},
                           "time": {"steps": 200, "dt_factor": 0.2}, "output": {"records": 2, "snapshots": 0},
                           **stage})
    path = folder / "case.yaml"
    path.write_text(yaml.safe_dump(case, sort_keys=False))
    return path


@pytest.fixture(scope="module")
def bonded_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("asphalt_bonds")
    run_case(_bonded_case(out), out=out / "run", quiet=True)
    return out / "run"


@pytest.fixture(scope="module")
def bonded(bonded_run):
    return read_state(bonded_run / "05-mastic.h5"), read_state(bonded_run / "06-bonded.h5")


@pytest.mark.parametrize("install", ["auto", "loaded"])
def test_bonded_specimen_at_rest_keeps_its_bonds(bonded_run, tmp_path, install):
    """The smoke specimen with mastic to 4 % air voids bonded by phase pair, no load, no gravity, 3000 steps (~2.5 ms).
    Mastic balls overlap aggregate balls by up to ~r (clearance -1); installed stress-free
    (auto with from_phases) the contact bonds hold no force there, and only the aggregate
    pairs' small compaction overlaps relax: >= 99 % of the bonds stay intact (measured
    100 %) and the kinetic energy stays below 1e-3 J (measured <= 5e-5 J). Installed loaded
    (the overlap's k_n delta, 80-250 N, against 5 N strengths) they blow apart (measured
    > 95 % broken, ~2 J): the defect the stress-free install removes."""
    import shutil

    out = tmp_path / "run"
    out.mkdir()
    for f in bonded_run.glob("0[0-4]-*.h5"):
        shutil.copy(f, out / f.name)
    # the mastic to 4 % air voids, as the full cases (by mix, the smoke's mastic takes clear sites only)
    path = _bonded_case(tmp_path, mastic={"amount": {"by": "air_voids", "air_voids": 0.04}}, physics={"gravity": [0, 0, 0], "friction": True},
                        time={"steps": 3000, "dt_factor": 0.2}, output={"records": 10, "snapshots": 0},
                        bonds={"from_phases": True, "create": True, "gap": 1e-3, "install": install})
    run_case(path, out=out, quiet=True, threads=1, from_stage="mastic")
    assert int(read_state(out / "05-mastic.h5")["mastic/overlapping"]) > 50
    st = read_state(out / "06-bonded.h5")
    intact = float(np.mean(st["bonds/state"] == INTACT))
    ke = np.loadtxt(next((out / "records").glob("bonded_dem.csv")), delimiter=",", skiprows=1)[:, 2]
    if install == "auto":
        assert intact >= 0.99 and ke.max() < 1e-3, (intact, ke.max())
    else:
        assert intact < 0.5 and ke.max() > 1e-2, (intact, ke.max())


def _sphere_positions(st):
    from scipy.spatial.transform import Rotation

    b = st["spheres/body"]
    q = st["bodies/q"][b]
    return st["bodies/x"][b] + Rotation.from_quat(q[:, [1, 2, 3, 0]]).apply(st["spheres/offset"])


def test_phase_pairs_pick_the_bond_models(bonded):
    before, after = bonded
    names = list(after["bond_models/kind"])
    mats = after["bond_models/materials"]
    # Then: aggregate-mastic pairs get contact bonds, mastic-mastic pairs parallel bonds, with the
    # strengths of the phase table (smoke case: 5 N, 5 N; 1 MPa, 1 MPa); aggregate pairs none
    kinds = {tuple(m): k for m, k in zip(mats.tolist(), names)}
    assert kinds == {(0, 1): "contact_bond", (1, 1): "parallel_bond"}
    prm = after["bond_models/params"]
    cb = names.index("contact_bond")
    pb = names.index("parallel_bond")
    assert prm[cb, B_KIND] == CONTACT_BOND and (prm[cb, B_SN], prm[cb, B_SS]) == (5.0, 5.0)
    assert prm[pb, B_KIND] == PARALLEL_BOND and (prm[pb, B_SN], prm[pb, B_SS]) == (1e6, 1e6)


def test_every_touching_pair_of_bonded_phases_is_bonded(bonded):
    from scipy.spatial import cKDTree

    before, after = bonded
    x = _sphere_positions(before)
    r = before["spheres/radius"]
    body = before["spheres/body"]
    mat = before["spheres/material"]
    gap = 1e-3 * r.mean()
    # brute-force reference: pairs of spheres of different bodies closer than the gap, not both aggregate
    pairs = cKDTree(x).query_pairs(2 * r.max() + gap, output_type="ndarray")
    i, j = pairs[:, 0], pairs[:, 1]
    d = np.linalg.norm(x[i] - x[j], axis=1)
    touch = (d < r[i] + r[j] + gap) & (body[i] != body[j]) & ~((mat[i] == 0) & (mat[j] == 0))
    # (the bonded stage may store a fresh scene in cell order: spheres are followed by body id)
    to_after = np.empty(len(r), np.int64)
    to_after[sphere_rows_by_id(before)] = sphere_rows_by_id(after)
    expect = set(map(tuple, np.sort(np.c_[to_after[i[touch]], to_after[j[touch]]], axis=1).tolist()))
    got = set(zip(after["bonds/i"].tolist(), after["bonds/j"].tolist()))
    assert got == expect and len(got) > 100
    # and each bond's model is the one of its spheres' materials
    model = after["bonds/model"]
    kinds = after["bond_models/kind"]
    mat = after["spheres/material"]
    for b, (a, c) in enumerate(zip(after["bonds/i"], after["bonds/j"])):
        want = "parallel_bond" if mat[a] == mat[c] == 1 else "contact_bond"
        assert kinds[model[b]] == want
    # and an intact contact bond replaces its contact (no such pair among the contacts), while a
    # parallel bond acts beside it (some parallel-bonded pairs are also touching contacts)
    contacts = set(zip(after["contacts/i"].tolist(), after["contacts/j"].tolist()))
    intact = after["bonds/state"] == INTACT
    cb = np.array([kinds[m] == "contact_bond" for m in model])
    bi, bj = after["bonds/i"], after["bonds/j"]
    assert not contacts & set(zip(bi[cb & intact].tolist(), bj[cb & intact].tolist()))
    assert contacts & set(zip(bi[~cb].tolist(), bj[~cb].tolist()))


def test_bonds_from_phases_without_a_phase_table_is_bad_input(tmp_path):
    from click.testing import CliRunner

    from demcli.cli import cli

    # Given: the beads smoke case (no mastic stage, no phase table) asked for bonds by phase pair
    res = CliRunner().invoke(cli, ["run", str(ROOT / "cases" / "smoke" / "beads.yaml"), "--out", str(tmp_path),
                                   "--quiet", "--set", "stages.settle.bonds.from_phases=true",
                                   "--set", "stages.settle.contact.law=linear", "--set", "stages.settle.contact.kn=1e4"])
    # Then: exit 2 with the stage, the key and the reason, no traceback
    assert res.exit_code == 2, res.output
    assert "bonds.from_phases" in res.output and "phases" in res.output and "Traceback" not in res.output


def test_a_bonded_stage_resumes_bit_identically(bonded_run, tmp_path, monkeypatch):
    """Interrupted and resumed, the from_phases stage (its bond and contact models come from the
    input's phase table, which its checkpoint does not hold) ends as the uninterrupted run."""
    import shutil

    from demcli.engine import system as system_mod
    from demcli.errors import StageError

    out = tmp_path / "run"
    out.mkdir()
    for f in bonded_run.glob("0[0-5]-*.h5"):
        shutil.copy(f, out / f.name)
    path = _bonded_case(tmp_path)
    real = system_mod.System.advance
    calls = {"n": 0}

    def interrupted(self, n):
        calls["n"] += 1
        if calls["n"] == 3:  # x_0's loads, the first record's chunk, then Ctrl-C at step 100
            raise KeyboardInterrupt
        return real(self, n)

    monkeypatch.setattr(system_mod.System, "advance", interrupted)
    with pytest.raises(StageError, match="interrupted at step 100"):
        run_case(path, out=out, quiet=True, from_stage="bonded")
    monkeypatch.setattr(system_mod.System, "advance", real)
    run_case(path, out=out, quiet=True, resume=True)
    assert "resuming from 06-bonded.ckpt.h5 at step 100 (t = " in (out / "log.txt").read_text()
    a, b = read_state(bonded_run / "06-bonded.h5"), read_state(out / "06-bonded.h5")
    for key in ("bodies/x", "bodies/v", "bodies/omega", "bonds/state", "bonds/force_s", "contacts/ft"):
        assert np.array_equal(np.asarray(a[key]), np.asarray(b[key])), key
