"""tests/docs: the README's and docs/'s commands (see test_docs_commands.py)."""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import docs_commands as dc  # noqa: E402


def pytest_configure(config):
    for part in dc.PARTS:
        config.addinivalue_line("markers", f"{part}: a docs command of the {part} part")


def pytest_collection_modifyitems(items):
    """The main lane's long commands after its others, and the cpu lane's tests last: they wait
    for the lane, which runs beside the main lane's tests (test_docs_commands.py, "Lanes"). The
    long commands of the main lane (floods, soak, the XCP runs: User-Mode Linux and python for
    minutes) thus meet less of the cpu lane's work. The order is otherwise the manifest's."""
    def rank(item):
        callspec = getattr(item, "callspec", None)
        e = callspec.params.get("entry") if callspec else None
        if e is None:
            return 0
        return 2 if e.lane == "cpu" else 1 if e.part == "long" else 0

    items.sort(key=rank)  # stable: the manifest's order within each rank


def pytest_terminal_summary(terminalreporter):
    import test_docs_commands as t

    lane = t.LANE
    if lane is not None and lane.seconds:
        slowest = sorted(lane.seconds.items(), key=lambda kv: -kv[1])[:8]
        terminalreporter.write_line(
            f"cpu lane (nice {lane.NICE}, beside the main lane): {len(lane.seconds)} commands, "
            f"{sum(lane.seconds.values()):.0f} s of commands in {getattr(lane, 'wall', float('nan')):.0f} s; "
            "slowest: " + "; ".join(f"{s:.0f} s {c[:70]}" for c, s in slowest))
    if t.MAIN_SECONDS:
        terminalreporter.write_line(f"main lane: {len(t.MAIN_SECONDS)} commands, {sum(t.MAIN_SECONDS.values()):.0f} s "
                                    "of commands")
    for f in t.FIGURES:
        terminalreporter.write_line(f"figure in its band: {f}")
    if t.COUNTS:
        ran = ", ".join(f"{p} {n}" for p, n in sorted(t.COUNTS.items()))
        total = {p: sum(e.part == p for e in t.ENTRIES) for p in dc.PARTS}
        terminalreporter.write_line(f"docs commands run and passed here: {ran} (manifest by part: {total})")
