"""ddct's bus contract for python: the DBC through cantools, and the E2E protection.

Everything about the frames comes from ``dbc/ddct.dbc`` (IDs, scales, offsets, signal positions);
nothing here repeats a CAN ID, a scale or an offset. A message is E2E-protected when the DBC gives
it both an ``AliveCounter`` and a ``Crc`` signal. The protection (DESIGN.md §3) is a 4-bit alive
counter (the DBC puts it in the high nibble of byte 6) and a CRC-8/SAE-J1850 (poly 0x1D, init 0xFF,
xor-out 0xFF) computed over the frame ID's two little-endian bytes followed by the payload bytes
that precede the CRC byte (bytes 0-6), stored in the CRC byte (byte 7).

API:
    load_dbc(path=DBC_PATH) -> cantools Database        (cached)
    crc8_sae_j1850(data) -> int
    is_protected(name_or_id) -> bool
    protected_messages() -> list of cantools Message
    e2e_crc(frame_id, data) -> int                      CRC the frame must carry
    encode(name, signals, counter=0) -> bytes           cantools encode + counter and CRC
    decode(frame_id, data) -> dict                      raw enum values (decode_choices=False)
    check(frame_id, data) -> verdict                    stateless: ok | bad_crc | not_protected |
                                                        unknown_id | bad_length
    E2EChecker().check(frame_id, data) -> verdict       adds counter_repeated | counter_skipped
    candump_line(t, iface, frame_id, data) -> str       one `candump -l` line
    parse_candump_line(line) -> (t, iface, frame_id, is_extended, data)
"""

from __future__ import annotations

import functools
import re
from pathlib import Path
from typing import Mapping, Union

import cantools

REPO = Path(__file__).resolve().parent.parent
DBC_PATH = REPO / "dbc" / "ddct.dbc"

COUNTER_SIGNAL = "AliveCounter"
CRC_SIGNAL = "Crc"

# CRC-8/SAE-J1850 parameters (DESIGN.md §3; not bus layout, so not in the DBC).
CRC_POLY = 0x1D
CRC_INIT = 0xFF
CRC_XOR_OUT = 0xFF

# Stateless verdicts, and the two that need the previous frame.
OK = "ok"
BAD_CRC = "bad_crc"
NOT_PROTECTED = "not_protected"
UNKNOWN_ID = "unknown_id"
BAD_LENGTH = "bad_length"
COUNTER_REPEATED = "counter_repeated"
COUNTER_SKIPPED = "counter_skipped"

MessageRef = Union[str, int]


class DbcLayoutError(ValueError):
    """The DBC places the E2E signals where this module cannot handle them."""


@functools.lru_cache(maxsize=None)
def load_dbc(path: Union[str, Path] = DBC_PATH) -> "cantools.database.can.Database":
    db = cantools.database.load_file(str(path), strict=True)
    for msg in db.messages:
        if _has_e2e_signals(msg):
            _e2e_layout(msg)  # validates
    return db


def _db():
    return load_dbc(DBC_PATH)


def message(ref: MessageRef):
    """The cantools Message for a name or a frame ID."""
    db = _db()
    if isinstance(ref, str):
        return db.get_message_by_name(ref)
    return db.get_message_by_frame_id(ref)


def _has_e2e_signals(msg) -> bool:
    names = {s.name for s in msg.signals}
    return COUNTER_SIGNAL in names and CRC_SIGNAL in names


@functools.lru_cache(maxsize=None)
def _e2e_layout(msg) -> tuple[int, int, int]:
    """(crc byte index, counter start bit, counter bit length) from the DBC."""
    crc = msg.get_signal_by_name(CRC_SIGNAL)
    ctr = msg.get_signal_by_name(COUNTER_SIGNAL)
    if crc.byte_order != "little_endian" or crc.length != 8 or crc.start % 8 != 0:
        raise DbcLayoutError(f"{msg.name}.{CRC_SIGNAL} must be one whole Intel byte")
    crc_byte = crc.start // 8
    if crc_byte != msg.length - 1:
        raise DbcLayoutError(f"{msg.name}.{CRC_SIGNAL} must be the last payload byte")
    if ctr.byte_order != "little_endian" or ctr.start + ctr.length > crc.start:
        raise DbcLayoutError(f"{msg.name}.{COUNTER_SIGNAL} must lie before the CRC byte")
    return crc_byte, ctr.start, ctr.length


def is_protected(ref: MessageRef) -> bool:
    return _has_e2e_signals(message(ref))


def protected_messages() -> list:
    return [m for m in _db().messages if _has_e2e_signals(m)]


def crc8_sae_j1850(data: bytes, init: int = CRC_INIT) -> int:
    """CRC-8/SAE-J1850: poly 0x1D, init 0xFF, no reflection, xor-out 0xFF."""
    crc = init
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ CRC_POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc ^ CRC_XOR_OUT


def crc_input(frame_id: int, data: bytes) -> bytes:
    """The bytes the CRC covers: ID low byte, ID high byte, then the bytes before the CRC."""
    crc_byte, _, _ = _e2e_layout(message(frame_id))
    return bytes([frame_id & 0xFF, (frame_id >> 8) & 0xFF]) + bytes(data[:crc_byte])


def e2e_crc(frame_id: int, data: bytes) -> int:
    return crc8_sae_j1850(crc_input(frame_id, data))


def counter_of(frame_id: int, data: bytes) -> int:
    msg = message(frame_id)
    _, start, length = _e2e_layout(msg)
    return (int.from_bytes(bytes(data), "little") >> start) & ((1 << length) - 1)


def encode(name: MessageRef, signals: Mapping[str, object], counter: int = 0) -> bytes:
    """Encode with cantools; for protected messages also set the counter and the CRC.

    ``signals`` holds physical values (or choice names); for protected messages the counter and
    CRC signals may be left out (any given values are replaced).
    """
    msg = message(name)
    values = dict(signals)
    if not _has_e2e_signals(msg):
        return bytes(msg.encode(values, strict=True))
    crc_byte, _, length = _e2e_layout(msg)
    values[COUNTER_SIGNAL] = counter % (1 << length)
    values[CRC_SIGNAL] = 0
    data = bytearray(msg.encode(values, strict=True))
    data[crc_byte] = e2e_crc(msg.frame_id, data)
    return bytes(data)


def decode(frame_id: int, data: bytes) -> dict:
    return message(frame_id).decode(bytes(data), decode_choices=False)


def check(frame_id: int, data: bytes) -> str:
    """Stateless E2E verdict of one frame (the counter needs E2EChecker)."""
    try:
        msg = message(frame_id)
    except KeyError:
        return UNKNOWN_ID
    if len(data) != msg.length:
        return BAD_LENGTH
    if not _has_e2e_signals(msg):
        return NOT_PROTECTED
    crc_byte, _, _ = _e2e_layout(msg)
    return OK if data[crc_byte] == e2e_crc(frame_id, data) else BAD_CRC


class E2EChecker:
    """Receiver-side check of a frame sequence: CRC, then the alive counter per message."""

    def __init__(self) -> None:
        self.last: dict[int, int] = {}

    def check(self, frame_id: int, data: bytes) -> str:
        verdict = check(frame_id, data)
        if verdict != OK:
            return verdict
        _, _, length = _e2e_layout(message(frame_id))
        counter = counter_of(frame_id, data)
        previous = self.last.get(frame_id)
        self.last[frame_id] = counter
        if previous is None or counter == (previous + 1) % (1 << length):
            return OK
        return COUNTER_REPEATED if counter == previous else COUNTER_SKIPPED


def candump_line(t: float, iface: str, frame_id: int, data: bytes, extended: bool = False) -> str:
    """One line in the `candump -l` format: ``(1436509052.249713) vcan0 044#2A366C2BBA``."""
    usec = round(t * 1_000_000)
    ident = f"{frame_id:08X}" if extended else f"{frame_id:03X}"
    return f"({usec // 1_000_000:010d}.{usec % 1_000_000:06d}) {iface} {ident}#{bytes(data).hex().upper()}"


_LINE = re.compile(r"^\((\d+)\.(\d{6})\) (\S+) ([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#([0-9A-Fa-f]*)(?: [RT])?$")


def parse_candump_line(line: str) -> tuple[float, str, int, bool, bytes]:
    m = _LINE.match(line.rstrip("\n"))
    if not m or len(m.group(5)) % 2:
        raise ValueError(f"not a candump -l line: {line!r}")
    t = int(m.group(1)) + int(m.group(2)) / 1_000_000
    return t, m.group(3), int(m.group(4), 16), len(m.group(4)) == 8, bytes.fromhex(m.group(5))


def read_candump(path: Union[str, Path]) -> list[tuple[float, str, int, bool, bytes]]:
    with open(path, encoding="ascii") as f:
        return [parse_candump_line(line) for line in f if line.strip()]


def signal_cases(msg) -> dict[str, dict[str, float]]:
    """min / mid / max physical values of every non-E2E signal, on the signal's raw grid.

    mid is the raw value nearest to the middle of [minimum, maximum]; signals with a value table
    take its smallest, middle and largest entry (raw values).
    """
    cases: dict[str, dict[str, float]] = {"min": {}, "mid": {}, "max": {}}
    for sig in msg.signals:
        if sig.name in (COUNTER_SIGNAL, CRC_SIGNAL):
            continue
        if sig.choices:  # enumerations: the smallest, middle and largest entry of the value table
            raws = sorted(int(r) for r in sig.choices)
            lo, mid, hi = raws[0], raws[len(raws) // 2], raws[-1]
            cases["min"][sig.name], cases["mid"][sig.name], cases["max"][sig.name] = lo, mid, hi
            continue
        lo, hi = sig.minimum, sig.maximum
        raw_mid = round(((lo + hi) / 2 - sig.offset) / sig.scale)
        mid = sig.conversion.raw_to_scaled(raw_mid, decode_choices=False)
        cases["min"][sig.name] = lo
        cases["mid"][sig.name] = mid
        cases["max"][sig.name] = hi
    return cases


def can_receivers(iface: str) -> frozenset | None:
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
