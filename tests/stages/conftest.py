"""Fixtures shared by the stage tests."""

from pathlib import Path

import pytest

from demcli import run_case

ASPHALT_SMOKE = Path(__file__).resolve().parents[2] / "cases" / "smoke" / "asphalt_carved_cube.yaml"


@pytest.fixture(scope="session")
def smoke_run(tmp_path_factory):
    """The asphalt smoke pipeline (cases/smoke/asphalt_carved_cube.yaml), run once per session
    and shared by the asphalt test modules (they re-run single stages on copies of its states)."""
    out = tmp_path_factory.getbasetemp() / "asphalt_carved_cube_smoke"
    run_case(ASPHALT_SMOKE, out=out, quiet=True, threads=1)
    return out
