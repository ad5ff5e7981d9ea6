"""``docs/cases.md``: the case-file reference, generated from the schema (never edited by hand)."""

from pathlib import Path

HEADER = """# Case file reference

Generated from the schema by `demcli.stages.base.write_cases_doc()` (a test fails when it is
out of date). Quantities accept units (`63 mm`, `0.1 MPa`, `10 Hz`); a plain number is SI. Keys
under `stages[type=...]` belong to that stage type.

| key | type | unit | default | meaning |
|---|---|---|---|---|
"""


def cases_markdown(schema):
    """The reference of a case schema (:func:`demcli.stages.base.case_schema`: the built-in stages)."""
    def cell(text):
        return str(text).replace("|", "\\|")

    rows = [f"| `{r.path}` | {cell(r.type)} | {cell(r.unit)} | {cell(r.default)} | {cell(r.doc)} |"
            for r in schema.describe()]
    return HEADER + "\n".join(rows) + "\n"


def write(schema, path="docs/cases.md"):
    """Write the reference of ``schema`` to ``path`` (:func:`demcli.stages.base.write_cases_doc`)."""
    from demcli.state.atomic import atomic_write_text

    atomic_write_text(Path(path), cases_markdown(schema))
