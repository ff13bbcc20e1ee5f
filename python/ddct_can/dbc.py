"""The bus layout: ``ddct.dbc`` (a copy of the repository's ``dbc/ddct.dbc``) through cantools.

Nothing in this package repeats a CAN ID, a scale or an offset: everything comes from the DBC.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Union

import cantools

DBC_PATH = Path(__file__).resolve().with_name("ddct.dbc")

MessageRef = Union[str, int]


@functools.lru_cache(maxsize=None)
def load_dbc(path: Union[str, Path] = DBC_PATH) -> "cantools.database.can.Database":
    """The DBC as a cantools database (strict; cached per path). The E2E layout of every message
    that carries E2E signals is validated (``e2e.DbcLayoutError``)."""
    from . import e2e  # the layout check lives with the protection

    db = cantools.database.load_file(str(path), strict=True)
    for msg in db.messages:
        if e2e.has_e2e_signals(msg):
            e2e.e2e_layout(msg)  # validates
    return db


def message(ref: MessageRef):
    """The cantools Message for a name or a frame ID (KeyError when the DBC has none)."""
    db = load_dbc(DBC_PATH)
    if isinstance(ref, str):
        return db.get_message_by_name(ref)
    return db.get_message_by_frame_id(ref)


def frame_id(name: str) -> int:
    return message(name).frame_id


def choice(message_ref: MessageRef, signal_name: str, label_: str) -> int:
    """Raw value of a value-table entry, e.g. ``choice("TCU_Status", "TcuState", "Drive")``."""
    sig = message(message_ref).get_signal_by_name(signal_name)
    for raw, name in (sig.choices or {}).items():
        if str(name) == label_:
            return int(raw)
    raise KeyError(f"{message(message_ref).name}.{signal_name} has no value {label_!r}")


def label(message_ref: MessageRef, signal_name: str, raw) -> str:
    """Name of a raw value of a signal with a value table (the number as text otherwise)."""
    sig = message(message_ref).get_signal_by_name(signal_name)
    return str(sig.choices.get(int(raw), raw)) if sig.choices else str(raw)


def signal_cases(msg) -> dict[str, dict[str, float]]:
    """min / mid / max physical values of every non-E2E signal, on the signal's raw grid.

    mid is the raw value nearest to the middle of [minimum, maximum]; signals with a value table
    take its smallest, middle and largest entry (raw values).
    """
    from .e2e import COUNTER_SIGNAL, CRC_SIGNAL

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
