"""Helpers of the diagnostic suite: the UDS contract of docs/diagnostics.md written again on the
tester's side (DIDs, the SecurityAccess key, DTC status bits), the real clients set up on vcan0,
and a recorder of the bus.

Nothing here comes from the ddct code under test: the DID numbers, codecs, key algorithm and
status bits are the documented contract, written out by hand.
"""

from __future__ import annotations

import shutil
import signal
import struct
import subprocess
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import can
import isotp
import udsoncan
from udsoncan.client import Client
from udsoncan.connections import PythonIsoTpConnection

from ddct_can.daemons import Bench
from ddct_can import can_receivers
from ddct_can.dbc import frame_id
from ddct_can.driver import Driver

REPO = Path(__file__).resolve().parents[2]
IFACE = "vcan0"

REQ_ID, RESP_ID, FUNC_ID = frame_id("TCU_DiagReq"), frame_id("TCU_DiagResp"), frame_id("DIAG_FunctionalReq")
XCP_CRO, XCP_DTO = frame_id("TCU_XcpCro"), frame_id("TCU_XcpDto")

# docs/diagnostics.md: measurement i at DID 256 + i, calibration i at 0x0200 + i.
MEASUREMENTS = [
    "Clutch1TempEst", "Clutch2TempEst", "Clutch1TorqueRef", "Clutch2TorqueRef",
    "Clutch1PosRef", "Clutch2PosRef", "Clutch1Pos", "Clutch2Pos", "Clutch1KissPoint",
    "Clutch2KissPoint", "EngineSpeed", "InShaft1Speed", "InShaft2Speed", "OutShaftSpeed",
    "AccelPedal", "HousingTemp", "TcuState", "GearActive", "FaultCode",
]
CALIBRATIONS = [
    "control.clutch_kp_per_s", "control.clutch_ki_per_s2", "control.engine_kp_per_s",
    "control.engine_ki_per_s2", "launch.lockup_time_s", "safety.over_temp_warn_c",
    "compensation.temperature", "compensation.slip",
]
DID = {name: 256 + i for i, name in enumerate(MEASUREMENTS)}
CAL_DID = {name: 0x0200 + i for i, name in enumerate(CALIBRATIONS)}
LEARNED_KISS_DID = {1: 0x0300, 2: 0x0301}
SERIAL_DID, VERSION_DID, NAME_DID = 0xF18C, 0xF195, 0xF197
KISS_ROUTINE = 0x0201

# ISO 14229-1 DTC status bits.
TEST_FAILED = 0x01
TEST_FAILED_THIS_CYCLE = 0x02
PENDING = 0x04
CONFIRMED = 0x08
NOT_COMPLETED_SINCE_CLEAR = 0x10
FAILED_SINCE_CLEAR = 0x20
NOT_COMPLETED_THIS_CYCLE = 0x40


def security_key(seed: bytes) -> bytes:
    """docs/diagnostics.md: key = rotate_left(seed XOR 0x4444_5443, 7), 32-bit big-endian."""
    s = int.from_bytes(seed, "big") ^ 0x44445443
    k = ((s << 7) | (s >> 25)) & 0xFFFFFFFF
    return k.to_bytes(4, "big")


class F32(udsoncan.DidCodec):
    """A DID holding one IEEE-754 f32, big-endian."""

    def encode(self, value) -> bytes:
        return struct.pack(">f", value)

    def decode(self, payload: bytes) -> float:
        return struct.unpack(">f", payload)[0]

    def __len__(self) -> int:
        return 4


def client_config() -> dict:
    cfg = dict(udsoncan.configs.default_client_config)
    codecs = {did: F32 for did in DID.values()}
    codecs.update({did: F32 for did in CAL_DID.values()})
    codecs.update({did: F32 for did in LEARNED_KISS_DID.values()})
    for did in (SERIAL_DID, VERSION_DID, NAME_DID):
        codecs[did] = udsoncan.AsciiCodec(16)
    cfg["data_identifiers"] = codecs
    cfg["security_algo"] = lambda level, seed, params=None: security_key(seed)
    cfg["exception_on_negative_response"] = True
    cfg["request_timeout"] = 5
    cfg["p2_timeout"] = 2
    cfg["p2_star_timeout"] = 6
    # The snapshot record's identifiers are measurement DIDs (f32 BE).
    cfg["dtc_snapshot_did_size"] = 2
    return cfg


def isotp_params(blocksize: int = 8, stmin: int = 0) -> dict:
    """The tester's ISO-TP settings: the block size and STmin it asks of the TCU, padding 0xCC."""
    return {
        "stmin": stmin,
        "blocksize": blocksize,
        "tx_padding": 0xCC,
        "tx_data_length": 8,
        "rx_flowcontrol_timeout": 2000,
        "rx_consecutive_frame_timeout": 2000,
        "wftmax": 0,
    }


@contextmanager
def uds_client(blocksize: int = 8, stmin: int = 0, txid: int = REQ_ID):
    """A udsoncan client on vcan0 over can-isotp's user-space stack, its socket filtered to the
    TCU's responses (as a tester's is: the control traffic, over a thousand frames a second,
    would otherwise queue up behind python's notifier)."""
    bus = can.Bus(interface="socketcan", channel=IFACE, receive_own_messages=False,
                  can_filters=[{"can_id": RESP_ID, "can_mask": 0x7FF, "extended": False}])
    notifier = can.Notifier(bus, [], timeout=0.1)
    addr = isotp.Address(isotp.AddressingMode.Normal_11bits, txid=txid, rxid=RESP_ID)
    stack = isotp.NotifierBasedCanStack(bus, notifier, address=addr, params=isotp_params(blocksize, stmin))
    conn = PythonIsoTpConnection(stack)
    try:
        with Client(conn, config=client_config()) as client:
            yield client
    finally:
        notifier.stop()
        bus.shutdown()


# Receive buffer of the recorder's (candump's) socket: room for seconds of bus traffic.
RECORDER_RCVBUF = 8 * 1024 * 1024


def _candump_frame(line: str) -> can.Message | None:
    """A `candump -L` line as a python-can message (kernel timestamp, id, data)."""
    try:
        stamp, _iface, frame = line.split()
        ident, data = frame.split("#", 1)
        remote = data.startswith("R")
        return can.Message(timestamp=float(stamp.strip("()")), arbitration_id=int(ident, 16),
                           is_extended_id=len(ident) == 8, is_remote_frame=remote,
                           data=b"" if remote else bytes.fromhex(data))
    except ValueError:
        return None


class Recorder:
    """Every frame on vcan0 with its kernel timestamp, recorded by candump (C, with a large
    receive buffer) and read line by line from its output: python-can reading one frame per
    call fell behind the bus in User-Mode Linux and the kernel dropped frames for it."""

    def __init__(self, only: tuple[str, ...] = ()):
        """`only`: record just these messages (by name; candump filters in the kernel), which
        leaves the CPU of User-Mode Linux to the daemons when a test needs a few frames."""
        self.frames: list[can.Message] = []
        self._lock = threading.Lock()
        candump = shutil.which("candump")
        assert candump, "candump not found on PATH (scripts/setup installs can-utils)"
        before = can_receivers(IFACE)
        where = ",".join([IFACE, *(f"{frame_id(m):03X}:7FF" for m in only)])
        self.proc = subprocess.Popen(["stdbuf", "-oL", candump, "-L", "-r", str(RECORDER_RCVBUF), where],
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        deadline = time.monotonic() + 30
        while before is not None and len(can_receivers(IFACE) - before) < 1:
            assert self.proc.poll() is None and time.monotonic() < deadline, "candump did not start"
            time.sleep(0.02)

    def _read(self) -> None:
        for line in self.proc.stdout:
            msg = _candump_frame(line)
            if msg is not None:
                with self._lock:
                    self.frames.append(msg)

    def snapshot(self) -> list[can.Message]:
        with self._lock:
            return list(self.frames)

    def close(self, catch_up_s: float = 30.0) -> None:
        """Stops recording once the frames sent until now are in: a frame stamped after now has
        arrived, or nothing has for 0.5 s (the bench already stopped)."""
        until = time.time()
        deadline = time.monotonic() + catch_up_s
        seen, quiet_since = -1, time.monotonic()
        while time.monotonic() < deadline:
            with self._lock:
                n = len(self.frames)
                last = self.frames[-1].timestamp if self.frames else None
            if last is not None and last >= until:
                break
            if n != seen:
                seen, quiet_since = n, time.monotonic()
            elif time.monotonic() - quiet_since > 0.5:  # the bus has gone quiet (bench stopped)
                break
            time.sleep(0.05)
        self.proc.send_signal(signal.SIGINT)
        try:
            self.proc.wait(10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        self._reader.join(10)


@contextmanager
def bench(ddct, workdir: Path, tcu_args=(), plant_args=()):
    """The plant and TCU daemons on vcan0 with a python driver sending DRV_Pedal (lever N, brake
    held: standstill, engine idling)."""
    b = Bench(IFACE, ddct=ddct, tcu_config=REPO / "config" / "tcu.toml", tcu_args=list(tcu_args),
              plant_args=list(plant_args), workdir=workdir, keep=True)
    drv_bus = can.Bus(interface="socketcan", channel=IFACE)
    driver = Driver(drv_bus)
    driver.start()
    try:
        b.start()
        yield b, driver
    finally:
        try:
            b.stop()
        finally:
            driver.stop()
            drv_bus.shutdown()


def wait_until(pred, timeout: float, step: float = 0.1, what: str = "condition"):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(step)
    raise AssertionError(f"{what} not reached within {timeout} s")


def f32(b: bytes) -> float:
    return struct.unpack(">f", b)[0]
