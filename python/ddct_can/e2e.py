"""E2E protection of ddct's frames (DESIGN.md §3) and frame encode/decode.

A message is E2E-protected when the DBC gives it both an ``AliveCounter`` and a ``Crc`` signal.
The protection is a 4-bit alive counter (the DBC puts it in the high nibble of byte 6) and a
CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xor-out 0xFF) computed over the frame ID's two
little-endian bytes followed by the payload bytes that precede the CRC byte (bytes 0-6), stored
in the CRC byte (byte 7).
"""

from __future__ import annotations

import functools
from typing import Mapping, Optional

from .dbc import MessageRef, load_dbc, message

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
# Not an E2E error: a counter gap the receiver's own losses explain (frames the receiver's queue
# dropped between the two frames of the message, ``rx.Receiver``), so the bus may be fine.
LOCAL_DROP = "local_drop"


class DbcLayoutError(ValueError):
    """The DBC places the E2E signals where this module cannot handle them."""


def has_e2e_signals(msg) -> bool:
    names = {s.name for s in msg.signals}
    return COUNTER_SIGNAL in names and CRC_SIGNAL in names


@functools.lru_cache(maxsize=None)
def e2e_layout(msg) -> tuple[int, int, int]:
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
    return has_e2e_signals(message(ref))


def protected_messages() -> list:
    return [m for m in load_dbc().messages if has_e2e_signals(m)]


def counter_modulus(ref: MessageRef) -> int:
    """How many values the alive counter of a protected message takes (16 for 4 bits)."""
    return 1 << e2e_layout(message(ref))[2]


def _crc_table() -> tuple:
    table = []
    for byte in range(256):
        crc = byte
        for _ in range(8):
            crc = ((crc << 1) ^ CRC_POLY) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc8_sae_j1850(data: bytes, init: int = CRC_INIT) -> int:
    """CRC-8/SAE-J1850: poly 0x1D, init 0xFF, no reflection, xor-out 0xFF (table-driven: one
    lookup per byte, the bitwise update of each byte value precomputed)."""
    crc = init
    for byte in data:
        crc = _CRC_TABLE[crc ^ byte]
    return crc ^ CRC_XOR_OUT


def crc_input(frame_id: int, data: bytes) -> bytes:
    """The bytes the CRC covers: ID low byte, ID high byte, then the bytes before the CRC."""
    crc_byte, _, _ = e2e_layout(message(frame_id))
    return bytes([frame_id & 0xFF, (frame_id >> 8) & 0xFF]) + bytes(data[:crc_byte])


def e2e_crc(frame_id: int, data: bytes) -> int:
    """The CRC a protected frame must carry."""
    return crc8_sae_j1850(crc_input(frame_id, data))


def counter_of(frame_id: int, data: bytes) -> int:
    _, start, length = e2e_layout(message(frame_id))
    return (int.from_bytes(bytes(data), "little") >> start) & ((1 << length) - 1)


def encode(name: MessageRef, signals: Mapping[str, object], counter: int = 0) -> bytes:
    """Encode with cantools; for protected messages also set the counter and the CRC.

    ``signals`` holds physical values (or choice names); for protected messages the counter and
    CRC signals may be left out (any given values are replaced). ``counter`` is taken modulo the
    counter's range.
    """
    msg = message(name)
    values = dict(signals)
    if not has_e2e_signals(msg):
        return bytes(msg.encode(values, strict=True))
    crc_byte, _, length = e2e_layout(msg)
    values[COUNTER_SIGNAL] = counter % (1 << length)
    values[CRC_SIGNAL] = 0
    data = bytearray(msg.encode(values, strict=True))
    data[crc_byte] = e2e_crc(msg.frame_id, data)
    return bytes(data)


def decode(frame_id: int, data: bytes) -> dict:
    """Physical values; signals with a value table as raw numbers (``decode_choices=False``)."""
    return message(frame_id).decode(bytes(data), decode_choices=False)


def check(frame_id: int, data: bytes) -> str:
    """Stateless E2E verdict of one frame (the counter needs E2EChecker)."""
    try:
        msg = message(frame_id)
    except KeyError:
        return UNKNOWN_ID
    if len(data) != msg.length:
        return BAD_LENGTH
    if not has_e2e_signals(msg):
        return NOT_PROTECTED
    crc_byte, _, _ = e2e_layout(msg)
    return OK if data[crc_byte] == e2e_crc(frame_id, data) else BAD_CRC


class E2EChecker:
    """Receiver-side check of a frame sequence: CRC, then the alive counter per message.

    ``check(..., lost=N)``: N is the receiver's running count of frames it lost itself (its
    socket's drops, ``rx.Receiver.lost``) when this frame arrived. A counter gap of k missing
    frames with at least k frames lost by the receiver since the message's previous frame is
    ``LOCAL_DROP`` — the receiver cannot tell which frames it lost, so the gap may be its own,
    and is no evidence against the bus; a gap larger than the receiver's losses (or any gap
    without ``lost``) is ``COUNTER_SKIPPED`` (or ``COUNTER_REPEATED``: 15 missing, or a frozen
    counter): at least part of it is on the bus."""

    def __init__(self) -> None:
        self.last: dict[int, int] = {}
        self._lost_at: dict[int, Optional[int]] = {}

    def check(self, frame_id: int, data: bytes, lost: Optional[int] = None) -> str:
        verdict = check(frame_id, data)
        if verdict != OK:
            return verdict
        _, _, length = e2e_layout(message(frame_id))
        modulus = 1 << length
        counter = counter_of(frame_id, data)
        previous = self.last.get(frame_id)
        lost_before = self._lost_at.get(frame_id)
        self.last[frame_id] = counter
        self._lost_at[frame_id] = lost
        if previous is None or counter == (previous + 1) % modulus:
            return OK
        missing = (counter - previous - 1) % modulus  # a repeated counter: modulus - 1 missing
        if lost is not None and lost_before is not None and lost - lost_before >= missing:
            return LOCAL_DROP
        return COUNTER_REPEATED if counter == previous else COUNTER_SKIPPED
