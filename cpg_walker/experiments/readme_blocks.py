"""Generated blocks in the docs: the text between ``<!-- NAME:begin ... -->`` and ``<!-- NAME:end -->`` is
written by a command from a committed artifact (results tables), and a test checks it still is.

Which file holds which block is data (``BLOCKS``), not code: a block moves with its topic's page, and the
commands (`cpg-walker results --docs`, `cpg-walker bench --doc`) and the tests look it up here."""

from __future__ import annotations

import re
from pathlib import Path

#: Each generated block and the doc that holds it (a path from the repository root).
BLOCKS = {
    "results-table": "README.md",  # the headline walks (experiments/headline.py), the README's Results
    "bench-table": "docs/benchmarks.md",  # the benchmark's summary tables (experiments/bench_report.py)
}


def block_file(name: str, root: str | Path = ".") -> Path:
    """The doc holding block ``name`` under the checkout ``root`` (KeyError: no such block)."""
    return Path(root) / BLOCKS[name]


def _pattern(name: str) -> re.Pattern:
    return re.compile(rf"(<!-- {re.escape(name)}:begin[^>]*-->\n)(.*?)(<!-- {re.escape(name)}:end -->)", re.S)


def read_block(text: str, name: str) -> str | None:
    """The body of block ``name`` in ``text`` (None: no such block)."""
    found = _pattern(name).search(text)
    return None if found is None else found.group(2)


def replace_block(path: str | Path, name: str, body: str) -> None:
    """Write ``body`` as block ``name`` of the file at ``path`` (ValueError naming the file when it has no
    such block)."""
    path = Path(path)
    text = path.read_text(encoding="utf-8")
    pattern = _pattern(name)
    if not pattern.search(text):
        raise ValueError(f"{path}: no '<!-- {name}:begin -->' ... '<!-- {name}:end -->' block to replace")
    body = body if body.endswith("\n") else body + "\n"
    path.write_text(pattern.sub(lambda m: m.group(1) + body + m.group(3), text, count=1), encoding="utf-8")
