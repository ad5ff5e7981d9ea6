"""Replace the text between two HTML-comment markers of a markdown file (bench tables in docs)."""

from pathlib import Path


def write_section(path, begin, end, text):
    """Put ``text`` between the markers ``begin`` and ``end`` of ``path`` (both must be there)."""
    path = Path(path)
    doc = path.read_text(encoding="utf-8")
    head, rest = doc.split(begin, 1)
    _, tail = rest.split(end, 1)
    path.write_text(head + begin + "\n" + text + "\n" + end + tail, encoding="utf-8")
    print(f"written to {path}")
