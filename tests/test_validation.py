"""`demcli validate --fast`: the Chung & Ooi subset that make test runs (the full suite writes
docs/validation.md). Each check compares with an analytic limit at the tolerance demcli/validation.py
states; this test fails when any check does."""

from click.testing import CliRunner

from demcli.cli import cli
from demcli.validation import Check


def test_the_fast_validation_subset_passes_and_writes_its_report(tmp_path):
    # When: the fast subset runs (tests 1 to 8: each sweep file's first run, the ends of its sweep)
    result = CliRunner().invoke(cli, ["validate", "--fast", "--out", str(tmp_path)])
    # Then: every check is within tolerance (exit code 0) and the report names each test with its figure
    assert result.exit_code == 0, result.output
    text = (tmp_path / "validation.md").read_text()
    for n in (1, 2, 3, 4, 5, 6, 7, 8):
        assert f"## Test {n}:" in text and (tmp_path / "validation" / f"chung_ooi_{n}.png").stat().st_size > 10000
    for name in ("spring_dashpot", "burgers_creep"):
        assert (tmp_path / "validation" / f"{name}.png").stat().st_size > 10000
    assert text.count("## Analytic check:") == 2
    assert "FAIL" not in text and text.count("| pass |") >= 28


def test_a_check_fails_outside_its_tolerance():
    assert Check(2, "a", "q", 1.0, 1.004, 5e-3).passed
    assert not Check(2, "a", "q", 1.0, 1.006, 5e-3).passed
    assert not Check(6, "a", "beta", -0.5, -0.52, 1e-2, absolute=True).passed
