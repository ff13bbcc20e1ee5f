"""ddct_can's DBC and E2E against the contract (DESIGN.md §3) and independent references."""

from __future__ import annotations

import random
from pathlib import Path

import pytest

import ddct_can

REPO_DBC = Path(__file__).resolve().parents[2] / "dbc" / "ddct.dbc"


def test_packaged_dbc_is_the_repository_dbc_byte_for_byte():
    assert REPO_DBC.is_file(), f"{REPO_DBC} missing: these tests run from the ddct repository"
    assert ddct_can.DBC_PATH.read_bytes() == REPO_DBC.read_bytes(), (
        "python/ddct_can/ddct.dbc differs from dbc/ddct.dbc: cp dbc/ddct.dbc python/ddct_can/ddct.dbc"
    )


def test_crc_check_value():
    # The catalogued check value of CRC-8/SAE-J1850.
    assert ddct_can.crc8_sae_j1850(b"123456789") == 0x4B


@pytest.mark.parametrize(
    "data,crc",
    [  # AUTOSAR SWS CRC Library, CRC8 (SAE-J1850) examples.
        ("00000000", 0x59), ("F20183", 0x37), ("0FAA0055", 0x79), ("00FF5511", 0xB8),
        ("332255AABBCCDDEEFF", 0xCB), ("926B55", 0x8C), ("FFFFFFFF", 0x74),
    ],
)
def test_crc_autosar_vectors(data, crc):
    assert ddct_can.crc8_sae_j1850(bytes.fromhex(data)) == crc


def test_crc_matches_crccheck():
    from crccheck.crc import Crc8SaeJ1850

    rng = random.Random(7)
    for _ in range(500):
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 12)))
        assert ddct_can.crc8_sae_j1850(data) == Crc8SaeJ1850.calc(data)


def test_drv_pedal_frame_by_hand():
    """DRV_Pedal AccelPedal 50 % (raw 500, bits 0-9), BrakeSwitch 0 (bit 10), GearLever D (raw 3,
    bits 11-13), counter 3 (bits 52-55); CRC over the frame ID (two bytes, little-endian) + bytes 0-6."""
    data = ddct_can.encode("DRV_Pedal", {"AccelPedal": 50.0, "BrakeSwitch": 0, "GearLever": "D"}, counter=3)
    fid = ddct_can.frame_id("DRV_Pedal")
    word = 500 | (0 << 10) | (3 << 11) | (3 << 52)
    body = word.to_bytes(8, "little")[:7]
    assert data[:7] == body
    assert data[7] == ddct_can.crc8_sae_j1850(fid.to_bytes(2, "little") + body)
    assert ddct_can.check(fid, data) == ddct_can.OK


def test_round_trip_every_message_min_mid_max():
    for msg in ddct_can.load_dbc().messages:
        for counter, (case, signals) in enumerate(ddct_can.signal_cases(msg).items()):
            data = ddct_can.encode(msg.name, signals, counter=counter + 14)  # 14, 15, 0: wraps
            back = ddct_can.decode(msg.frame_id, data)
            for name, value in signals.items():
                sig = msg.get_signal_by_name(name)
                assert abs(back[name] - value) <= abs(sig.scale) / 2, (msg.name, case, name)
            if ddct_can.is_protected(msg.name):
                assert back["AliveCounter"] == (counter + 14) % 16
                assert ddct_can.counter_of(msg.frame_id, data) == (counter + 14) % 16
                assert back["Crc"] == ddct_can.e2e_crc(msg.frame_id, data)
                assert ddct_can.check(msg.frame_id, data) == ddct_can.OK
            else:
                assert ddct_can.check(msg.frame_id, data) == ddct_can.NOT_PROTECTED


def test_check_verdicts():
    good = ddct_can.encode("ENG_Status", {"EngSpeed": 800.0, "EngTorqueAct": 10.0}, counter=5)
    fid = ddct_can.frame_id("ENG_Status")
    assert ddct_can.check(fid, good) == ddct_can.OK
    for i in range(8):  # any single flipped bit anywhere is caught by the CRC
        for b in range(8):
            bad = bytearray(good)
            bad[i] ^= 1 << b
            assert ddct_can.check(fid, bytes(bad)) == ddct_can.BAD_CRC
    assert ddct_can.check(fid, good[:7]) == ddct_can.BAD_LENGTH
    unknown = max(m.frame_id for m in ddct_can.load_dbc().messages) + 1
    assert ddct_can.check(unknown, good) == ddct_can.UNKNOWN_ID


def test_e2e_checker_sequence():
    fid = ddct_can.frame_id("ENG_Status")
    f = lambda c: ddct_can.encode("ENG_Status", {"EngSpeed": 800.0, "EngTorqueAct": 0.0}, counter=c)  # noqa: E731
    chk = ddct_can.E2EChecker()
    verdicts = [chk.check(fid, f(c)) for c in (14, 15, 0, 0, 2, 3)]
    assert verdicts == ["ok", "ok", "ok", "counter_repeated", "counter_skipped", "ok"]


def test_choice_and_label_from_the_value_tables():
    assert ddct_can.choice("TCU_Status", "TcuState", "Drive") == 4
    assert ddct_can.label("TCU_Status", "TcuState", 3) == "Launch"
    assert ddct_can.choice("DRV_Pedal", "GearLever", "N") == 2
    with pytest.raises(KeyError):
        ddct_can.choice("TCU_Status", "TcuState", "Flying")


def test_candump_line_round_trip():
    line = ddct_can.candump_line(1_700_000_000.25, "vcan0", 0x7A5, b"\x01\x02")
    assert line == "(1700000000.250000) vcan0 7A5#0102"
    assert ddct_can.parse_candump_line(line) == (1_700_000_000.25, "vcan0", 0x7A5, False, b"\x01\x02")
    with pytest.raises(ValueError):
        ddct_can.parse_candump_line("vcan0 7A5#0102")


def test_e2e_checker_tells_the_receivers_own_drops_from_the_bus():
    """``lost``: the receiver's own running drop count. A gap of k missing frames with at least
    k frames dropped by the receiver since the message's previous frame is the receiver's
    (local_drop); a gap larger than its drops, or with no drops, is the bus's."""
    fid = ddct_can.frame_id("ENG_Status")
    f = lambda c: ddct_can.encode("ENG_Status", {"EngSpeed": 800.0, "EngTorqueAct": 0.0}, counter=c)  # noqa: E731
    chk = ddct_can.E2EChecker()
    seq = [  # (counter, receiver's drops so far, verdict)
        (0, 0, "ok"),
        (3, 2, "local_drop"),       # 2 missing, 2 dropped locally in between
        (6, 3, "counter_skipped"),  # 2 missing, 1 dropped locally: at least one lost on the bus
        (7, 9, "ok"),               # drops of other messages, no gap: nothing
        (9, 9, "counter_skipped"),  # 1 missing, no local drop
        (9, 30, "local_drop"),      # a repeat = 15 missing, 21 dropped locally
        (9, 30, "counter_repeated"),
        (12, None, "counter_skipped"),  # drops unknown: a gap is the bus's
        (14, 40, "counter_skipped"),    # no known count at the previous frame: the bus's
        (0, 41, "local_drop"),          # wraps 14 -> 0: one missing, one dropped
    ]
    assert [chk.check(fid, f(c), lost=n) for c, n, _ in seq] == [v for _, _, v in seq]
    assert ddct_can.LOCAL_DROP == "local_drop"


def test_e2e_checker_counts_drops_from_each_messages_own_previous_frame():
    eng, sens = ddct_can.frame_id("ENG_Status"), ddct_can.frame_id("DCT_Sensors")
    e = lambda c: ddct_can.encode("ENG_Status", {"EngSpeed": 800.0, "EngTorqueAct": 0.0}, counter=c)  # noqa: E731
    s = lambda c: ddct_can.encode("DCT_Sensors", {"InShaft1Speed": 0.0, "InShaft2Speed": 0.0, "OutShaftSpeed": 0.0,  # noqa: E731
                                                  "HousingTemp": 40.0}, counter=c)
    chk = ddct_can.E2EChecker()
    assert chk.check(eng, e(0), lost=0) == "ok"
    assert chk.check(sens, s(0), lost=0) == "ok"
    assert chk.check(sens, s(2), lost=1) == "local_drop"  # one DCT_Sensors frame lost here
    # ENG_Status's gap of 1 spans that drop too: the receiver cannot tell which frame it lost.
    assert chk.check(eng, e(2), lost=1) == "local_drop"
    assert chk.check(eng, e(4), lost=1) == "counter_skipped"  # no drop since ENG_Status's last frame
