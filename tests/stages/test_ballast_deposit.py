"""Polyhedral ballast through the dem stage: deposit, records, snapshots, resume."""

from pathlib import Path

import numpy as np
import pytest

from demcli import run_case
from demcli.errors import StageError
from demcli.state import read_state

CASE = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "ballast_deposit.yaml"


def test_assembled_ballast_falls_into_its_box(tmp_path):
    # Given the assembled smoke bed
    run_case(CASE, out=tmp_path, quiet=True)
    before = read_state(tmp_path / "02-assembly.h5")
    after = read_state(tmp_path / "03-deposit.h5")
    # Then the polyhedra fell (the seed's adaptive damping holds a free fall back hard: alpha grows
    # by 1.1 per step until damping absorbs half the kinetic-energy gain), stayed inside the box
    # walls, kept their shapes, and the adaptive damping coefficient was recorded
    drop = before["bodies/x"][:, 2].mean() - after["bodies/x"][:, 2].mean()
    assert drop > 1e-3
    assert np.array_equal(after["polyhedra/shape"], before["polyhedra/shape"])
    x = after["bodies/x"]
    assert np.all((x[:, 0] > 0) & (x[:, 0] < 0.3) & (x[:, 1] > 0) & (x[:, 1] < 0.2) & (x[:, 2] > 0))
    csv = (tmp_path / "records" / "deposit_dem.csv").read_text().splitlines()
    assert "alpha[1/s]" in csv[0]
    alpha = [float(row.split(",")[-1]) for row in csv[1:]]
    assert alpha[0] == 0.1 and alpha[-1] > alpha[0]  # falling: kinetic energy grows, R < 0.5
    assert (tmp_path / "deposit" / "polyhedra.pvd").exists() and (tmp_path / "deposit" / "walls.pvd").exists()


def test_polyhedral_stage_resumes_bit_identically(tmp_path, monkeypatch):
    # Given a reference run and a run interrupted in the deposit stage
    run_case(CASE, out=tmp_path / "ref", quiet=True)
    from demcli.engine import system

    real = system.System.advance
    calls = {"n": 0}

    def interrupted(self, n):
        calls["n"] += 1
        if calls["n"] == 6:
            raise KeyboardInterrupt
        return real(self, n)

    monkeypatch.setattr(system.System, "advance", interrupted)
    with pytest.raises(StageError, match="interrupted"):
        run_case(CASE, out=tmp_path / "run", quiet=True)
    monkeypatch.setattr(system.System, "advance", real)
    run_case(CASE, out=tmp_path / "run", quiet=True, resume=True)
    # Then the resumed result equals the uninterrupted one
    a = read_state(tmp_path / "ref" / "03-deposit.h5")
    b = read_state(tmp_path / "run" / "03-deposit.h5")
    for key in ("bodies/x", "bodies/v", "bodies/q", "bodies/angmom", "body_contacts/ft", "adaptive_damping/alpha"):
        assert np.array_equal(np.asarray(a[key]), np.asarray(b[key])), key
