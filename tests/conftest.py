"""Shared fixtures: a scratch run folder and the smoke cases."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CASES = ROOT / "cases"


@pytest.fixture
def smoke_case():
    return CASES / "smoke" / "beads.yaml"
