"""docs/state.md stays consistent with the field registry."""

from pathlib import Path

from demcli.state.fields import CORE_GROUPS, register_all, schema_markdown

DOC = Path(__file__).resolve().parents[2] / "docs" / "state.md"


def _undocumented(table):
    """Rows of a schema table that docs/state.md does not hold verbatim."""
    text = DOC.read_text(encoding="utf-8")
    return [line for line in table.splitlines() if line.startswith("| ") and line not in text]


def test_every_core_schema_row_is_documented():
    # Given the registry's table of the core groups, when docs/state.md is read,
    # then each row appears verbatim (regenerate with fields.write_schema_doc())
    missing = _undocumented(schema_markdown(CORE_GROUPS))
    assert not missing, f"docs/state.md is out of date; first missing row: {missing[0]}"


def test_every_registered_row_is_documented():
    # Given every field any module registers (stages, effects, engine, state layouts), when
    # docs/state.md is read, then each row appears verbatim (before: the bonds, polyhedra and
    # actors groups were missing, because the generator did not import the engine)
    register_all()
    missing = _undocumented(schema_markdown())
    assert not missing, f"docs/state.md is out of date; first missing row: {missing[0]}"
