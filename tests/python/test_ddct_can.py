"""The ddct_can package (python/ddct_can) against the contract (DESIGN.md §3) and against independent tools."""

from __future__ import annotations

import random
import re
from pathlib import Path

import can
import pytest
from crccheck.crc import Crc8SaeJ1850

import ddct_testlib as lib
from ddct_testlib import ddct_can

# DESIGN.md §3: the messages that carry an AliveCounter (and so E2E protection).
DESIGN_PROTECTED = {
    "ENG_Status",
    "DRV_Pedal",
    "TCU_ClutchCmd",
    "TCU_EngineReq",
    "TCU_GearCmd",
    "TCU_Status",
    "DCT_Sensors",
    "DCT_Actuators",
}


def test_crc_check_value():
    # The catalogued check value of CRC-8/SAE-J1850.
    assert ddct_can.crc8_sae_j1850(b"123456789") == 0x4B


@pytest.mark.parametrize(
    "data,crc",
    [
        # AUTOSAR SWS CRC Library, CRC8 (SAE-J1850) examples.
        ("00000000", 0x59),
        ("F20183", 0x37),
        ("0FAA0055", 0x79),
        ("00FF5511", 0xB8),
        ("332255AABBCCDDEEFF", 0xCB),
        ("926B55", 0x8C),
        ("FFFFFFFF", 0x74),
    ],
)
def test_crc_autosar_vectors(data, crc):
    assert ddct_can.crc8_sae_j1850(bytes.fromhex(data)) == crc


def test_crc_matches_crccheck_library():
    rng = random.Random(1)
    for _ in range(2000):
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 12)))
        assert ddct_can.crc8_sae_j1850(data) == Crc8SaeJ1850.calc(data), data.hex()


def test_protected_messages_are_the_designs(db):
    assert {m.name for m in ddct_can.protected_messages()} == DESIGN_PROTECTED
    for m in db.messages:
        names = {s.name for s in m.signals}
        assert ddct_can.is_protected(m.name) == ({"AliveCounter", "Crc"} <= names)


def test_e2e_layout_is_the_contract(db):
    # DESIGN.md §3: counter in the high nibble of byte 6, CRC in byte 7, signals in bits 0-51.
    for m in ddct_can.protected_messages():
        assert m.length == 8
        for counter in range(16):
            data = ddct_can.encode(m.name, ddct_can.signal_cases(m)["mid"], counter)
            assert data[6] >> 4 == counter
            assert data[7] == ddct_can.crc8_sae_j1850(
                bytes([m.frame_id & 0xFF, m.frame_id >> 8]) + data[:7]
            )
        for s in m.signals:
            if s.name not in ("AliveCounter", "Crc"):
                assert s.start + s.length <= 52, f"{m.name}.{s.name} overlaps the E2E bits"


def test_encode_decode_check_every_message(db):
    for m in db.messages:
        for case, signals in ddct_can.signal_cases(m).items():
            data = ddct_can.encode(m.name, signals, counter=7)
            assert len(data) == m.length
            decoded = ddct_can.decode(m.frame_id, data)
            if ddct_can.is_protected(m.frame_id):
                assert ddct_can.check(m.frame_id, data) == "ok"
                assert decoded.pop("AliveCounter") == 7
                assert decoded.pop("Crc") == data[7]
            else:
                assert ddct_can.check(m.frame_id, data) == "not_protected"
            assert not lib.signal_mismatches(m, signals, decoded, f" ({case})")


def test_every_single_bit_error_is_caught():
    for m in ddct_can.protected_messages():
        data = ddct_can.encode(m.name, ddct_can.signal_cases(m)["max"], counter=3)
        for bit in range(64):
            bad = bytearray(data)
            bad[bit // 8] ^= 1 << (bit % 8)
            assert ddct_can.check(m.frame_id, bytes(bad)) == "bad_crc", (m.name, bit)


def test_crc_covers_the_frame_id():
    msgs = ddct_can.protected_messages()
    for a in msgs:
        data = ddct_can.encode(a.name, ddct_can.signal_cases(a)["mid"], counter=1)
        for b in msgs:
            if b is not a:
                assert ddct_can.check(b.frame_id, data) == "bad_crc", (a.name, b.name)


def test_sequence_checker():
    m = ddct_can.protected_messages()[0]
    sig = ddct_can.signal_cases(m)["min"]
    chk = ddct_can.E2EChecker()
    verdicts = [chk.check(m.frame_id, ddct_can.encode(m.name, sig, c)) for c in [13, 14, 15, 0, 1, 1, 3, 4]]
    assert verdicts == ["ok", "ok", "ok", "ok", "ok", "counter_repeated", "counter_skipped", "ok"]
    # Each message has its own counter.
    other = ddct_can.protected_messages()[1]
    assert chk.check(other.frame_id, ddct_can.encode(other.name, ddct_can.signal_cases(other)["min"], 9)) == "ok"


def test_check_rejects_bad_frames(db):
    m = ddct_can.protected_messages()[0]
    data = ddct_can.encode(m.name, ddct_can.signal_cases(m)["min"], 0)
    assert ddct_can.check(m.frame_id, data[:7]) == "bad_length"
    known = {msg.frame_id for msg in db.messages}
    unknown = next(i for i in range(0x800) if i not in known)
    assert ddct_can.check(unknown, data) == "unknown_id"


def test_candump_line_format():
    # The example line of the issue: zero-padded seconds, 6-digit microseconds, uppercase hex.
    line = ddct_can.candump_line(1436509052.249713, "vcan0", 0x44, bytes.fromhex("2a366c2bba"))
    assert line == "(1436509052.249713) vcan0 044#2A366C2BBA"
    assert ddct_can.parse_candump_line(line + "\n")[1:] == ("vcan0", 0x44, False, bytes.fromhex("2A366C2BBA"))
    assert ddct_can.candump_line(5.000001, "can1", 0x1ABCDEF0, b"", extended=True) == "(0000000005.000001) can1 1ABCDEF0#"
    assert ddct_can.parse_candump_line("(0000000005.000001) can1 1ABCDEF0# R")[2:4] == (0x1ABCDEF0, True)
    with pytest.raises(ValueError):
        ddct_can.parse_candump_line("(1.5) vcan0 044#2A")


def test_written_log_is_read_by_python_can_and_cantools(tmp_path: Path):
    frames = lib.sample_frames()
    log = tmp_path / "python.log"
    lib.write_candump(log, frames)
    got = list(can.LogReader(str(log)))
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == [(f["id"], f["data"]) for f in frames]
    assert all(m.channel == "vcan0" for m in got)
    decoded = lib.cantools_decode_log(log)
    assert len(decoded) == len(frames)
    db = ddct_can.load_dbc()
    for fr, rec in zip(frames, decoded):
        assert rec["name"] == fr["name"], rec
        msg = db.get_message_by_name(fr["name"])
        sig = {k: v for k, v in rec["signals"].items() if k not in ("AliveCounter", "Crc")}
        assert not lib.signal_mismatches(msg, fr["signals"], sig, f" ({fr['case']})")


def test_no_literal_can_ids_in_python(db):
    # The contract lives in the DBC only (TEAM.md): no frame ID literal in the python sources.
    sources = [*sorted((lib.REPO / "python").rglob("*.py")), *sorted((lib.REPO / "tests").rglob("*.py"))]
    sources += sorted((lib.REPO / "scripts").glob("*.py"))
    ids = {m.frame_id for m in db.messages}
    for path in set(sources):
        text = path.read_text()
        for lit in re.findall(r"\b0[xX]([0-9A-Fa-f]+)\b", text):
            assert int(lit, 16) not in ids, f"{path.relative_to(lib.REPO)}: literal CAN ID 0x{lit}"
        for lit in re.findall(r"\b([0-9A-Fa-f]{3})#", text):
            assert int(lit, 16) not in ids, f"{path.relative_to(lib.REPO)}: literal frame {lit}#"
