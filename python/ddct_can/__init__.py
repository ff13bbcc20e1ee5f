"""ddct's CAN bus in python: the DBC (``dbc``), the E2E protection and frame encode/decode
(``e2e``), candump logs (``candump``), a scripted driver (``Driver``), a receiver that counts
its own drops apart from the bus's (``Receiver``, ``rx``), a bus monitor (``Monitor``), the
plant and TCU daemons (``Bench``) and pytest fixtures (``pytest_plugin``, loaded by pytest
through the ``pytest11`` entry point).
"""

from .candump import can_receivers, candump_line, parse_candump_line, read_candump
from .daemons import Bench, BenchError, find_ddct
from .dbc import DBC_PATH, MessageRef, choice, frame_id, label, load_dbc, message, signal_cases
from .driver import Driver, DriverError
from .e2e import (
    BAD_CRC,
    BAD_LENGTH,
    COUNTER_REPEATED,
    COUNTER_SIGNAL,
    COUNTER_SKIPPED,
    CRC_INIT,
    CRC_POLY,
    CRC_SIGNAL,
    CRC_XOR_OUT,
    NOT_PROTECTED,
    OK,
    UNKNOWN_ID,
    DbcLayoutError,
    LOCAL_DROP,
    E2EChecker,
    check,
    counter_of,
    crc8_sae_j1850,
    crc_input,
    decode,
    e2e_crc,
    encode,
    is_protected,
    protected_messages,
)
from .monitor import Monitor
from .rx import Receiver

__version__ = "0.1.0"

__all__ = [
    "BAD_CRC", "BAD_LENGTH", "COUNTER_REPEATED", "COUNTER_SIGNAL", "COUNTER_SKIPPED", "CRC_INIT",
    "CRC_POLY", "CRC_SIGNAL", "CRC_XOR_OUT", "DBC_PATH", "LOCAL_DROP", "NOT_PROTECTED", "OK", "UNKNOWN_ID",
    "Bench", "BenchError", "DbcLayoutError", "Driver", "DriverError", "E2EChecker", "MessageRef",
    "Monitor", "Receiver", "can_receivers", "candump_line", "check", "choice", "counter_of",
    "crc8_sae_j1850", "crc_input", "decode", "e2e_crc", "encode", "find_ddct", "frame_id", "is_protected", "label",
    "load_dbc", "message", "parse_candump_line", "protected_messages", "read_candump",
    "signal_cases",
]
