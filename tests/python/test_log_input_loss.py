"""`ddct log decode` tells frames the logger lost from frames the bus skipped (issue 46): a
counter gap that candump -d's DROPCOUNT line explains is `missing_input`; without such a line the
same gap is the bus's `counter_skipped`, and on standard input the summary says how to tell the
two apart. Frames and counters are python's (cantools + the package's E2E encoder)."""

from __future__ import annotations

import re
import subprocess

import ddct_testlib as lib
from ddct_testlib import ddct_can


def eng_status(n: int) -> list[str]:
    """n ENG_Status frames 10 ms apart with consecutive alive counters, as candump -l lines."""
    fid = ddct_can.load_dbc().get_message_by_name("ENG_Status").frame_id
    return [ddct_can.candump_line(1_700_000_000.0 + 0.01 * k, "vcan0", fid,
                                  ddct_can.encode("ENG_Status", {"EngSpeed": 800.0, "EngTorqueAct": 10.0}, counter=k % 16))
            for k in range(n)]


def decode(args):
    return lib.run([lib.ddct_bin(), "log", "decode", *args, "--format", "csv"], check=False)


def test_a_gap_the_logger_reported_is_missing_input_not_an_e2e_error(tmp_path):
    lines = eng_status(40)
    lossy = lines[:10] + ["DROPCOUNT: dropped 3 CAN frames on 'vcan0' socket (total drops 3)"] + lines[13:]
    (tmp_path / "lossy.log").write_text("\n".join(lossy) + "\n")
    r = decode([tmp_path / "lossy.log"])
    assert r.returncode == 0, r.stderr
    assert "frames by E2E verdict: missing_input 1, ok 36" in r.stderr, r.stderr
    assert "the logger lost 3 frame(s) before ddct read them (1 DROPCOUNT line(s))" in r.stderr
    # One frame: its four signals (EngSpeed, EngTorqueAct, AliveCounter, Crc) carry the verdict.
    assert len(re.findall(r"^1700000000\.130000,.*,missing_input$", r.stdout, re.M)) == 4, r.stdout[:500]
    assert ",counter_skipped" not in r.stdout

    # The same hole without the logger's word: the bus's error; on a pipe, the hint.
    silent = "\n".join(lines[:10] + lines[13:]) + "\n"
    (tmp_path / "silent.log").write_text(silent)
    r = decode([tmp_path / "silent.log"])
    assert "frames by E2E verdict: counter_skipped 1, ok 36" in r.stderr, r.stderr
    p = subprocess.run([str(lib.ddct_bin()), "log", "decode", "-", "--format", "csv"], input=silent,
                                     capture_output=True, text=True, timeout=60)
    assert p.returncode == 0 and "counter_skipped 1" in p.stderr, p.stderr
    assert "run `candump -d`" in p.stderr, p.stderr
