"""`candump -l` log lines, and the kernel's CAN receive lists (/proc/net/can)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Optional, Union


def candump_line(t: float, iface: str, frame_id: int, data: bytes, extended: bool = False) -> str:
    """One line in the `candump -l` format: ``(1436509052.249713) vcan0 044#2A366C2BBA``."""
    usec = round(t * 1_000_000)
    ident = f"{frame_id:08X}" if extended else f"{frame_id:03X}"
    return f"({usec // 1_000_000:010d}.{usec % 1_000_000:06d}) {iface} {ident}#{bytes(data).hex().upper()}"


_LINE = re.compile(r"^\((\d+)\.(\d{6})\) (\S+) ([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#([0-9A-Fa-f]*)(?: [RT])?$")


def parse_candump_line(line: str) -> tuple[float, str, int, bool, bytes]:
    """(t, iface, frame_id, is_extended, data) of one `candump -l` line (ValueError otherwise)."""
    m = _LINE.match(line.rstrip("\n"))
    if not m or len(m.group(5)) % 2:
        raise ValueError(f"not a candump -l line: {line!r}")
    t = int(m.group(1)) + int(m.group(2)) / 1_000_000
    return t, m.group(3), int(m.group(4), 16), len(m.group(4)) == 8, bytes.fromhex(m.group(5))


def read_candump(path: Union[str, Path]) -> list[tuple[float, str, int, bool, bytes]]:
    with open(path, encoding="ascii") as f:
        return [parse_candump_line(line) for line in f if line.strip()]


def can_receivers(iface: str) -> Optional[frozenset]:
    """The kernel's CAN receive-list entries on `iface` (None: no /proc/net/can).

    An entry is (list, can_id, mask, function, userdata, ident): one per bound raw socket filter;
    a new entry means a receiver started in the background now listens.
    """
    base = Path("/proc/net/can")
    if not base.is_dir():
        return None
    entries = set()
    for f in base.glob("rcvlist_*"):
        try:
            lines = f.read_text().splitlines()
        except OSError:
            continue
        for line in lines:
            cols = line.split()
            if cols[:1] == [iface] and len(cols) >= 7:
                entries.add((f.name, *cols[1:5], cols[6]))
    return frozenset(entries)
