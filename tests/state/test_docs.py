"""docs/state.md stays consistent with the field registry."""

from pathlib import Path

from demcli.state.fields import CORE_GROUPS, schema_markdown

DOC = Path(__file__).resolve().parents[2] / "docs" / "state.md"


def test_every_core_schema_row_is_documented():
    # Given the registry's table of the core groups
    rows = [line for line in schema_markdown(CORE_GROUPS).splitlines() if line.startswith("| ")]
    # When docs/state.md is read
    text = DOC.read_text(encoding="utf-8")
    # Then each row appears verbatim (regenerate with fields.write_schema_doc())
    missing = [r for r in rows if r not in text]
    assert not missing, f"docs/state.md is out of date; first missing row: {missing[0]}"
