"""The effect x shape table of docs/architecture.md, generated from the effect registry.

``python -m demcli.effects.table`` rewrites it between the markers ``<!-- effects-table -->``
and ``<!-- /effects-table -->`` (tests/engine/test_registry.py checks that it is current).
"""

import sys
from pathlib import Path

from demcli.effects.registry import effects_table

BEGIN, END = "<!-- effects-table -->", "<!-- /effects-table -->"
DOC = Path(__file__).resolve().parents[2] / "docs" / "architecture.md"


def table_in(text):
    """The text between the markers of ``text`` (None when it has none)."""
    if BEGIN not in text or END not in text:
        return None
    return text.split(BEGIN, 1)[1].split(END, 1)[0]


def with_table(text):
    """``text`` with the generated table between its markers."""
    head, rest = text.split(BEGIN, 1)
    return f"{head}{BEGIN}\n{effects_table()}{END}{rest.split(END, 1)[1]}"


def main(path=DOC):
    path = Path(path)
    path.write_text(with_table(path.read_text()))
    print(f"wrote the effect x shape table into {path}")


if __name__ == "__main__":
    main(*sys.argv[1:])
