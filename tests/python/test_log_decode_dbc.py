"""`ddct log decode --dbc FILE`: a log decoded with a DBC given at run time.

- A foreign DBC (big-endian signed, little-endian unsigned with factor and offset, a value table,
  an IEEE float on an extended id, a multiplexed message): every value ddct prints equals
  cantools' decoding of the same frames, the value-table names too; an id outside the DBC is
  reported as unknown; no E2E verdict is computed (`n/a`).
- The contract itself given as `--dbc dbc/ddct.dbc` on a recorded bench run: the same values,
  names and E2E verdicts as the built-in decoder (`n/a` where that says `not_protected`).
- A broken DBC: an error naming the file and the line, no panic, exit status not 0.
"""

from __future__ import annotations

import csv
import io
import math
import random
import struct
from pathlib import Path

import cantools
import pytest

import ddct_testlib as lib
from ddct_testlib import ddct_can

FOREIGN_DBC = """VERSION "foreign test database"

NS_ :
	CM_
	BA_DEF_
	BA_
	VAL_
	SIG_VALTYPE_

BS_:

BU_: ECU GW

BO_ 1280 Motion: 8 ECU
 SG_ Speed : 7|16@0- (0.01,0) [-327.68|327.67] "m/s" GW
 SG_ Temp : 16|12@1+ (0.1,-40) [-40|369.5] "degC" GW
 SG_ Mode : 28|3@1+ (1,0) [0|7] "" GW
 SG_ Odd : 37|11@0+ (2,-100) [-100|3994] "mm" GW
 SG_ Accel : 48|10@1- (0.05,0) [-25.6|25.55] "m/s^2" GW

BO_ 2566848741 Ext: 8 ECU
 SG_ Ratio : 0|32@1- (1,0) [0|0] "" GW
 SG_ Count : 39|24@0+ (1,0) [0|16777215] "" GW

BO_ 1536 Muxed: 8 ECU
 SG_ Sel M : 0|8@1+ (1,0) [0|255] "" GW
 SG_ A m1 : 8|16@1+ (0.25,0) [0|16383.75] "V" GW
 SG_ B m2 : 8|16@1- (0.5,0) [-16384|16383.5] "A" GW
 SG_ C m2 : 31|8@0+ (1,0) [0|255] "" GW

CM_ SG_ 1280 Speed "Signed, big-endian (Motorola).";
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 10000;
BA_DEF_DEF_ "GenMsgCycleTime" 0;
BA_ "GenMsgCycleTime" BO_ 1280 100;
VAL_ 1280 Mode 0 "Off" 1 "Eco" 2 "Sport" 5 "Track" ;
SIG_VALTYPE_ 2566848741 Ratio : 1;
"""

T0 = 1_700_000_000.0
UNKNOWN_ID = 0x7FE


def _frames(db) -> list[dict]:
    """Frames of every message of the foreign DBC (seeded random payloads), and one unknown id."""
    rng = random.Random(13)
    frames = []
    motion = db.get_message_by_name("Motion")
    for _ in range(40):
        frames.append({"id": motion.frame_id, "ext": False, "data": bytes(rng.randrange(256) for _ in range(8))})
    ext = db.get_message_by_name("Ext")
    for ratio in (0.0, 1.5, -2.25, 1.1, 3.0e7, -1.0e-3):
        data = struct.pack("<f", ratio) + bytes(rng.randrange(256) for _ in range(4))
        frames.append({"id": ext.frame_id, "ext": True, "data": data})
    muxed = db.get_message_by_name("Muxed")
    for i in range(20):
        data = bytes([1 + i % 2]) + bytes(rng.randrange(256) for _ in range(7))
        frames.append({"id": muxed.frame_id, "ext": False, "data": data})
    frames.append({"id": UNKNOWN_ID, "ext": False, "data": b"\x01\x02"})
    rng.shuffle(frames)
    for i, f in enumerate(frames):
        f["t"] = T0 + i * 0.001
    return frames


def _write_log(path: Path, frames: list[dict]) -> None:
    path.write_text(
        "".join(ddct_can.candump_line(f["t"], "can0", f["id"], f["data"], extended=f["ext"]) + "\n" for f in frames)
    )


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    d = tmp_path_factory.mktemp("foreign")
    dbc = d / "foreign.dbc"
    dbc.write_text(FOREIGN_DBC)
    db = cantools.database.load_file(str(dbc))
    frames = _frames(db)
    log = d / "foreign.log"
    _write_log(log, frames)
    return dbc, db, frames, log


def _by_frame(rows: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for r in rows:
        out.setdefault(r["time_s"], []).append(r)
    return out


def test_foreign_dbc_values_match_cantools(ddct, foreign):
    dbc, db, frames, log = foreign
    proc = lib.run([ddct, "log", "decode", log, "--dbc", dbc, "--format", "csv"])
    rows = list(csv.DictReader(io.StringIO(proc.stdout)))
    by_frame = _by_frame(rows)
    assert len(by_frame) == len(frames)
    problems = []
    checked = 0
    for f in frames:
        got = by_frame[f"{f['t']:.6f}"]
        assert all(int(r["id"], 16) == f["id"] for r in got), got
        assert all(r["e2e"] == "n/a" for r in got), got
        if f["id"] == UNKNOWN_ID:
            assert len(got) == 1 and got[0]["message"] == "" and got[0]["signal"] == "", got
            continue
        msg = db.get_message_by_frame_id(f["id"])
        want = msg.decode(f["data"], decode_choices=False)
        assert {r["message"] for r in got} == {msg.name}, got
        values = {r["signal"]: float(r["value"]) for r in got}
        if set(values) != set(want):
            problems.append(f"{msg.name} {f['data'].hex()}: signals {sorted(values)}, cantools {sorted(want)}")
            continue
        for r in got:
            w = float(want[r["signal"]])
            if not math.isclose(values[r["signal"]], w, rel_tol=1e-12, abs_tol=1e-12):
                problems.append(f"{msg.name}.{r['signal']} {f['data'].hex()}: ddct {r['value']}, cantools {w!r}")
            if r["unit"] != (msg.get_signal_by_name(r["signal"]).unit or ""):
                problems.append(f"{msg.name}.{r['signal']}: unit {r['unit']!r}")
            checked += 1
    assert not problems, "\n".join(problems[:20])
    # 40 Motion frames of 5 signals, 6 Ext of 2, 10 Muxed with Sel=1 (Sel, A) and 10 with Sel=2 (Sel, B, C).
    assert checked == 40 * 5 + 6 * 2 + 10 * 2 + 10 * 3


def test_foreign_dbc_value_table_names_match_cantools(ddct, foreign):
    dbc, db, frames, log = foreign
    recs = lib.json_lines(lib.run([ddct, "log", "decode", log, "--dbc", dbc, "--format", "json"]).stdout)
    assert len(recs) == len(frames)
    motion = db.get_message_by_name("Motion")
    named = 0
    for f, rec in zip(frames, recs):
        if f["id"] != motion.frame_id:
            continue
        want = motion.decode(f["data"], decode_choices=True)["Mode"]
        if isinstance(want, int):
            assert "Mode" not in rec["labels"], (rec, want)
        else:
            assert rec["labels"]["Mode"] == str(want), (rec, want)
            named += 1
    assert named > 0
    unknown = next(r for r in recs if r["id"] == UNKNOWN_ID)
    assert unknown["name"] is None and unknown["signals"] == {} and "not a message of the DBC" in unknown["error"]
    # The table shows the names too, and -m takes the DBC's message names.
    table = lib.run([ddct, "log", "decode", log, "--dbc", dbc, "-m", "Motion"]).stdout.splitlines()
    assert len(table) == 40 and all(" Motion " in line and " Mode=" in line for line in table)
    assert any(f"Mode={n}" in line for line in table for n in ("Off", "Eco", "Sport", "Track"))


def test_contract_as_runtime_dbc_equals_the_builtin_decoder(ddct, tmp_path):
    out = tmp_path / "bench"
    scenario = lib.REPO / "config" / "scenarios" / "launch_20.toml"
    r = lib.run([ddct, "bench", "--iface", "sim", "--echo", "0", "--scenario", scenario, "--out", out], check=False)
    log = out / "bench.log"
    assert log.is_file(), r.stdout[-2000:] + r.stderr[-2000:]
    builtin = lib.json_lines(lib.run([ddct, "log", "decode", log, "--format", "json"]).stdout)
    runtime = lib.json_lines(
        lib.run([ddct, "log", "decode", log, "--format", "json", "--dbc", ddct_can.DBC_PATH]).stdout
    )
    assert len(builtin) == len(runtime) > 1000
    verdicts = set()
    for b, rt in zip(builtin, runtime):
        for key in ("t", "iface", "id", "name", "signals", "labels", "error"):
            assert b[key] == rt[key], (key, b, rt)
        want = "n/a" if b["e2e"] == "not_protected" else b["e2e"]
        assert rt["e2e"] == want, (b, rt)
        verdicts.add(rt["e2e"])
    assert {"ok", "n/a"} <= verdicts


BROKEN_LINE = 4
BROKEN_DBC = """VERSION ""

BO_ 1280 Motion: 8 ECU
 SG_ Speed : 7|16@0- (0.01 0) [-327.68|327.67] "m/s" GW
"""


def test_broken_dbc_names_the_file_and_line(ddct, foreign, tmp_path):
    _, _, _, log = foreign
    broken = tmp_path / "broken.dbc"
    broken.write_text(BROKEN_DBC)
    with pytest.raises(Exception):
        cantools.database.load_file(str(broken))
    proc = lib.run([ddct, "log", "decode", log, "--dbc", broken], check=False)
    assert proc.returncode != 0
    assert "panicked" not in proc.stderr
    assert f"{broken}:{BROKEN_LINE}:" in proc.stderr, proc.stderr
    assert proc.stdout == ""
    missing = tmp_path / "missing.dbc"
    proc = lib.run([ddct, "log", "decode", log, "--dbc", missing], check=False)
    assert proc.returncode != 0 and str(missing) in proc.stderr and "panicked" not in proc.stderr
