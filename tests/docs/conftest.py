"""tests/docs: the README's and docs/'s commands (see test_docs_commands.py)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import docs_commands as dc  # noqa: E402


def pytest_configure(config):
    for part in dc.PARTS:
        config.addinivalue_line("markers", f"{part}: a docs command of the {part} part")


def pytest_terminal_summary(terminalreporter):
    import test_docs_commands as t

    if t.COUNTS:
        ran = ", ".join(f"{p} {n}" for p, n in sorted(t.COUNTS.items()))
        total = {p: sum(e.part == p for e in t.ENTRIES) for p in dc.PARTS}
        terminalreporter.write_line(f"docs commands run and passed here: {ran} (manifest by part: {total})")
