"""Cross-tool checks: frames from Rust (ddct) decode identically with cantools, and frames from
cantools decode identically with ddct; the E2E CRC agrees between Rust and python."""

from __future__ import annotations

import csv
import io
import math
import re
from pathlib import Path

import pytest

import ddct_testlib as lib
from ddct_testlib import ddct_can

CASES = ("min", "mid", "max")


@pytest.fixture(scope="module")
def samples(ddct):
    """`ddct dbc samples --json`: one element per (message, case)."""
    import json

    out = lib.run([ddct, "dbc", "samples", "--json"]).stdout
    try:
        data = json.loads(out)
    except json.JSONDecodeError as e:
        raise AssertionError(f"`ddct dbc samples --json` did not print JSON ({e}): {out[:500]!r}") from None
    assert isinstance(data, list), "expected a JSON array"
    return data


def test_samples_shape_and_coverage(samples, db):
    seen = set()
    for s in samples:
        assert set(s) >= {"id", "name", "case", "signals", "data"}, s
        assert isinstance(s["id"], int) and isinstance(s["name"], str) and isinstance(s["signals"], dict)
        assert s["case"] in CASES, s
        assert re.fullmatch(r"[0-9A-F]{16}", s["data"]), f"data must be 16 uppercase hex digits: {s['data']!r}"
        assert db.get_message_by_name(s["name"]).frame_id == s["id"], s
        seen.add((s["name"], s["case"]))
    assert len(seen) == len(samples), "duplicate (message, case) in the samples"
    # The transport ids (ISO-TP, XCP) have no signals and so no samples.
    assert seen == {(m.name, c) for m in db.messages if m.signals for c in CASES}


def test_samples_decode_with_cantools(samples, db):
    problems = []
    for s in samples:
        msg = db.get_message_by_frame_id(s["id"])
        decoded = msg.decode(bytes.fromhex(s["data"]), decode_choices=False)
        problems += lib.signal_mismatches(msg, s["signals"], decoded, f" ({s['case']}, Rust -> cantools)")
    assert not problems, "\n".join(problems)


def test_samples_encode_with_cantools(samples, db):
    problems = []
    for s in samples:
        msg = db.get_message_by_frame_id(s["id"])
        rust = bytes.fromhex(s["data"])
        values = {k: (lib.raw_value(msg.get_signal_by_name(k), v) if isinstance(v, str) else v) for k, v in s["signals"].items()}
        py = bytes(msg.encode(values, strict=True))
        if py != rust:
            problems.append(f"{s['name']} ({s['case']}): cantools {py.hex().upper()} != Rust {s['data']}")
    assert not problems, "\n".join(problems)


def test_samples_crc_rust_equals_python(samples):
    """CRC golden cross-check: for every E2E-protected message, Rust's CRC equals python's."""
    checked = set()
    problems = []
    for s in samples:
        if not ddct_can.is_protected(s["id"]):
            continue
        data = bytes.fromhex(s["data"])
        want = ddct_can.e2e_crc(s["id"], data)
        crc_byte = ddct_can.message(s["id"]).get_signal_by_name("Crc").start // 8
        if data[crc_byte] != want or s["signals"].get("Crc") != want:
            problems.append(f"{s['name']} ({s['case']}): Rust CRC {data[crc_byte]:#04x}, python {want:#04x}")
        assert "AliveCounter" in s["signals"], s
        assert ddct_can.counter_of(s["id"], data) == s["signals"]["AliveCounter"]
        checked.add(s["name"])
    assert not problems, "\n".join(problems)
    assert checked == {m.name for m in ddct_can.protected_messages()}


def _decode_json(ddct, log: Path) -> list[dict]:
    return lib.json_lines(lib.run([ddct, "log", "decode", log, "--format", "json"]).stdout)


def test_python_frames_decode_in_rust(ddct, db, tmp_path):
    frames = lib.sample_frames()
    log = tmp_path / "cantools.log"
    lib.write_candump(log, frames, iface="vcan0", t0=1_700_000_000.0, dt=0.010)
    recs = _decode_json(ddct, log)
    assert len(recs) == len(frames)
    problems = []
    for i, (fr, rec) in enumerate(zip(frames, recs)):
        assert set(rec) >= {"t", "iface", "id", "name", "signals", "e2e", "error"}, rec
        assert math.isclose(rec["t"], 1_700_000_000.0 + i * 0.010, abs_tol=2e-6), rec["t"]
        assert rec["iface"] == "vcan0" and rec["id"] == fr["id"] and rec["name"] == fr["name"], rec
        assert rec["error"] is None, rec
        msg = db.get_message_by_name(fr["name"])
        expected = dict(fr["signals"])
        if ddct_can.is_protected(msg.name):
            expected["AliveCounter"] = ddct_can.counter_of(fr["id"], fr["data"])
            expected["Crc"] = ddct_can.e2e_crc(fr["id"], fr["data"])
            want_e2e = "ok"
        else:
            want_e2e = "not_protected"
        if rec["e2e"] != want_e2e:
            problems.append(f"{msg.name} ({fr['case']}): e2e {rec['e2e']!r}, expected {want_e2e!r}")
        problems += lib.signal_mismatches(msg, expected, rec["signals"], f" ({fr['case']}, cantools -> Rust)")
    assert not problems, "\n".join(problems)


def test_rust_e2e_verdicts_on_python_frames(ddct, tmp_path):
    m = ddct_can.protected_messages()[0]
    sig = ddct_can.signal_cases(m)["mid"]
    good = [ddct_can.encode(m.name, sig, c) for c in (0, 1, 2)]
    bad_crc = bytearray(ddct_can.encode(m.name, sig, 3))
    bad_crc[0] ^= 0x01
    seq = good + [bytes(bad_crc), ddct_can.encode(m.name, sig, 3), ddct_can.encode(m.name, sig, 3), ddct_can.encode(m.name, sig, 6)]
    # python's own sequence checker gives the expectation
    chk = ddct_can.E2EChecker()
    expected = [chk.check(m.frame_id, d) for d in seq]
    assert expected == ["ok", "ok", "ok", "bad_crc", "ok", "counter_repeated", "counter_skipped"]
    log = tmp_path / "e2e.log"
    lib.write_candump(log, [{"id": m.frame_id, "data": d} for d in seq])
    recs = _decode_json(ddct, log)
    assert [r["e2e"] for r in recs] == expected


def test_log_decode_csv(ddct, db, tmp_path):
    frames = lib.sample_frames()
    log = tmp_path / "cantools.log"
    lib.write_candump(log, frames)
    recs = _decode_json(ddct, log)
    out = lib.run([ddct, "log", "decode", log, "--format", "csv"]).stdout
    lines = out.splitlines()
    assert lines[0] == "time_s,iface,id,message,signal,value,unit,e2e"
    rows = list(csv.DictReader(io.StringIO(out)))
    # A frame without signals (a transport id: ISO-TP, XCP) keeps one row, its signal empty.
    assert len(rows) == sum(max(1, len(r["signals"])) for r in recs)
    assert any(not r["signals"] for r in recs), "the samples should hold transport frames"
    it = iter(rows)
    for rec in recs:
        msg = db.get_message_by_frame_id(rec["id"])
        if not rec["signals"]:
            row = next(it)
            assert (row["message"], row["signal"], row["value"]) == (msg.name, "", ""), row
            assert row["e2e"] == rec["e2e"] == "not_protected", row
            continue
        for name in rec["signals"]:
            row = next(it)
            assert row["message"] == msg.name and row["iface"] == rec["iface"], row
            assert int(row["id"], 0) == rec["id"], row
            assert math.isclose(float(row["time_s"]), rec["t"], abs_tol=2e-6), row
            sig = msg.get_signal_by_name(row["signal"])
            assert row["signal"] in rec["signals"]
            assert (row["unit"] or None) == (sig.unit or None), row
            assert row["e2e"] == rec["e2e"], row
            assert not lib.signal_mismatches(msg, {sig.name: rec["signals"][sig.name]}, {sig.name: float(row["value"])})


def test_log_decode_table_runs(ddct, tmp_path, db):
    log = tmp_path / "cantools.log"
    lib.write_candump(log, lib.sample_frames())
    out = lib.run([ddct, "log", "decode", log]).stdout
    for m in db.messages:
        assert m.name in out


def test_log_decode_bad_lines(ddct, db, tmp_path):
    """Unknown IDs and wrong lengths are reported per frame; a malformed line names its number;
    nothing decoded before it is lost."""
    known = {m.frame_id for m in db.messages}
    unknown = next(i for i in range(0x7FF, 0, -1) if i not in known)
    m = ddct_can.protected_messages()[0]
    good = ddct_can.encode(m.name, ddct_can.signal_cases(m)["mid"], 0)
    lines = [
        ddct_can.candump_line(1.0, "vcan0", m.frame_id, good),
        ddct_can.candump_line(1.1, "vcan0", unknown, b"\x01\x02"),
        ddct_can.candump_line(1.2, "vcan0", m.frame_id, good[:5]),
        "this is not a candump line",
    ]
    log = tmp_path / "bad.log"
    log.write_text("\n".join(lines) + "\n")
    proc = lib.run([ddct, "log", "decode", log, "--format", "json"], check=False)
    assert "panicked" not in proc.stderr
    recs = lib.json_lines(proc.stdout)
    assert len(recs) >= 3, proc.stdout
    assert recs[0]["name"] == m.name and recs[0]["e2e"] == "ok" and recs[0]["error"] is None
    assert recs[1]["id"] == unknown and recs[1]["name"] is None and recs[1]["signals"] == {}
    assert recs[1]["e2e"] != "ok"
    assert recs[2]["error"], recs[2]
    assert recs[2]["e2e"] != "ok"
    errors = proc.stderr + "".join(str(r.get("error")) for r in recs[3:])
    assert re.search(r"\b4\b", errors), f"the malformed line number (4) is not reported: {errors!r}"


def test_log_decode_accepts_candump_variants(ddct, tmp_path):
    """Input may carry a trailing ` R`/` T` (candump -x direction) and 29-bit IDs."""
    m = ddct_can.protected_messages()[0]
    frames = [ddct_can.encode(m.name, ddct_can.signal_cases(m)[c], k) for k, c in enumerate(CASES)]
    ext_id = 0x1ABCDEF0
    lines = [
        ddct_can.candump_line(10.0, "vcan0", m.frame_id, frames[0]) + " R",
        ddct_can.candump_line(10.5, "can1", m.frame_id, frames[1]) + " T",
        ddct_can.candump_line(11.0, "vcan0", ext_id, b"\x01\x02\x03", extended=True),
        ddct_can.candump_line(11.5, "vcan0", m.frame_id, frames[2]),
    ]
    log = tmp_path / "variants.log"
    log.write_text("\n".join(lines) + "\n")
    recs = _decode_json(ddct, log)
    assert [r["id"] for r in recs] == [m.frame_id, m.frame_id, ext_id, m.frame_id]
    assert [r["iface"] for r in recs] == ["vcan0", "can1", "vcan0", "vcan0"]
    assert [r["t"] for r in recs] == pytest.approx([10.0, 10.5, 11.0, 11.5], abs=2e-6)
    assert recs[2]["name"] is None and recs[2]["signals"] == {}
    assert [recs[i]["e2e"] for i in (0, 1, 3)] == ["ok", "ok", "ok"]
    for i, c in zip((0, 1, 3), CASES):
        assert not lib.signal_mismatches(
            m, ddct_can.decode(m.frame_id, frames[CASES.index(c)]), recs[i]["signals"], f" ({c})"
        )
