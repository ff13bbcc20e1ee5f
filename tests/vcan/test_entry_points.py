"""Every `ddct` entry point that opens SocketCAN, run as a user types it, on a real vcan0 (issue
42). Each opens the interface through its own command-line path: a command that opens its socket
outside the runtime that owns it (the tokio panic `ddct bench --iface vcan0` once had) or that
does not take the interface the way its documentation says fails here, not on a user's bench.

    bench        ddct bench --iface vcan0 ...   and   ddct bench --analyze LOG --scenario S
    tcu, plant   ddct tcu --iface vcan0 / ddct plant --iface vcan0 (each heard by a recorder)
    log record   ddct log record vcan0 --out F (positional, like candump)
    log replay   ddct log replay F --iface vcan0
    log monitor  ddct log monitor vcan0
    diag         ddct diag read-did --iface vcan0 Version (against ddct tcu)

Run through scripts/vcan-run (tests/vcan is one of scripts/test's vcan suites)."""

from __future__ import annotations

import json
import os
import re
import time
from collections import Counter
from pathlib import Path

import ddct_testlib as lib
from ddct_testlib import ddct_can
from vcan_helpers import IFACE, background

SCENARIO = lib.REPO / "config" / "scenarios" / "launch_shift_20s.toml"


def no_panic(text: str) -> None:
    assert "panicked" not in text and "RUST_BACKTRACE" not in text, text[-3000:]


def ids_in(log: Path) -> Counter:
    """Frames per message name in a candump -l log."""
    db = ddct_can.load_dbc()
    names = {m.frame_id: m.name for m in db.messages}
    return Counter(names.get(fid, hex(fid)) for (_, _, fid, _, _) in ddct_can.read_candump(log))


def wait_ready(p, ready: Path, what: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while not ready.exists():
        assert p.poll() is None, f"{what} exited {p.returncode} before it listened"
        assert time.monotonic() < deadline, f"{what} never wrote {ready}"
        time.sleep(0.01)


def recording(ddct, tmp_path: Path, name: str, seconds: float):
    """`ddct log record vcan0 --out F --duration S` in the background (positional interface)."""
    log, ready = tmp_path / f"{name}.log", tmp_path / f"{name}.ready"
    out = open(tmp_path / f"{name}.out", "w")
    cm = background([ddct, "log", "record", IFACE, "--out", log, "--duration", seconds, "--ready-file", ready],
                   stdout=out, stderr=out, text=True)
    return cm, log, ready


def test_bench_on_vcan0_runs_and_its_log_analyses_the_same(ddct, tmp_path):
    """`ddct bench --iface vcan0`: the daemons on the real bus, a verdict, summary.json on vcan0
    and report.html; then `ddct bench --analyze` of its own bench.log with the same scenario gives
    the same verdict, and its printed fault codes agree with its `faults` row. The bench runs in
    lockstep by default (the plant waits for the TCU's answer each cycle), so a stalled guest CPU
    slows it down without changing its verdict: PASS, every cycle answered."""
    out = tmp_path / "bench"
    rt = ["--rt-priority", "50"] if os.geteuid() == 0 else []
    r = lib.run([ddct, "bench", "--iface", IFACE, "--echo", "1", "--out", out, *rt], check=False, timeout=300)
    text = r.stdout + r.stderr
    no_panic(text)
    assert r.returncode == 0, text[-4000:]
    assert re.search(r"^launch_shift_20s +lockup_s_max +(PASS|FAIL) ", r.stdout, re.M), r.stdout[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    verdict = {c["name"]: c for c in summary["verdict"]}
    assert (r.returncode == 0) == all(c["pass"] for c in verdict.values()), verdict
    for functional in ("finite", "launches_min", "shifts_complete", "no_stall", "faults"):
        assert verdict[functional]["pass"], verdict[functional]
    print("bench on vcan0:", {k: c["measured"] for k, c in verdict.items() if not c["pass"]} or "PASS")
    assert summary["iface"] == IFACE
    assert verdict["lockstep_answers"]["pass"], verdict["lockstep_answers"]
    assert (out / "report.html").stat().st_size > 0 and list(out.glob("*.svg"))
    counts = ids_in(out / "bench.log")
    assert counts["DCT_Sensors"] > 1500 and counts["TCU_ClutchCmd"] > 1500, counts

    # The analysis of the recorded log refuses to guess the scenario ...
    r = lib.run([ddct, "bench", "--analyze", out / "bench.log"], check=False)
    assert r.returncode == 2 and "--scenario" in r.stderr, r.stderr
    # ... and with it agrees with the live run's verdict, into its own folder.
    an = tmp_path / "analysis"
    r = lib.run([ddct, "bench", "--analyze", out / "bench.log", "--scenario", SCENARIO, "--out", an], check=False)
    no_panic(r.stdout + r.stderr)
    assert r.returncode == (0 if all(verdict[k]["pass"] for k in verdict) else 1), (r.stdout + r.stderr)[-4000:]
    again = json.loads((an / "summary.json").read_text())
    # The same checks but the latency ratio (a log carries no echo measurement to compare with).
    # (nor the plant's report of its lockstep answers).
    live = [(c["name"], c["pass"]) for c in summary["verdict"]
            if c["name"] not in ("latency_ratio_max", "lockstep_answers")]
    assert [(c["name"], c["pass"]) for c in again["verdict"]] == live
    faults_row = next(c for c in again["verdict"] if c["name"] == "faults")
    printed = re.search(r"^fault codes on the bus: (.*)$", r.stdout, re.M).group(1)
    assert (printed == "none") == faults_row["pass"], (printed, faults_row)


def test_tcu_and_plant_daemons_on_vcan0_are_heard_by_a_recorder(ddct, tmp_path):
    """`ddct plant --iface vcan0` and `ddct tcu --iface vcan0` for a few seconds: the recorder
    (positional `ddct log record vcan0`) hears the plant's sensors and the TCU's commands."""
    recorder, log, ready = recording(ddct, tmp_path, "daemons", 6)
    with recorder as rec:
        wait_ready(rec, ready, "ddct log record vcan0")
        with background([ddct, "tcu", "--iface", IFACE, "--duration", "4", "--json"],
                        stdout=open(tmp_path / "tcu.json", "w"), stderr=open(tmp_path / "tcu.err", "w")) as t:
            r = lib.run([ddct, "plant", "--iface", IFACE, "--duration", "3", "--json"], check=False, timeout=60)
            assert t.wait(60) == 0, (tmp_path / "tcu.err").read_text()
        assert rec.wait(60) == 0, (tmp_path / "daemons.out").read_text()
    no_panic(r.stdout + r.stderr + (tmp_path / "tcu.err").read_text())
    assert r.returncode == 0, r.stderr[-3000:]
    plant = json.loads(r.stdout)
    tcu_report = json.loads((tmp_path / "tcu.json").read_text())
    assert plant["cycles"] >= 250, plant
    assert tcu_report["frames_received"] > 0, tcu_report
    counts = ids_in(log)
    assert counts["DCT_Sensors"] >= 250 and counts["TCU_Status"] >= 250, counts


def test_log_replay_on_vcan0_is_recorded_frame_for_frame(ddct, tmp_path):
    """`ddct log replay F --iface vcan0` against `ddct log record vcan0 --count N`."""
    frames = lib.sample_frames() * 5
    src = tmp_path / "src.log"
    lib.write_candump(src, [dict(f, data=ddct_can.encode(f["name"], f["signals"], i % 16))
                            for i, f in enumerate(frames)])
    log, ready = tmp_path / "rec.log", tmp_path / "rec.ready"
    with background([ddct, "log", "record", IFACE, "--out", log, "--count", len(frames), "--ready-file", ready],
                    stdout=open(tmp_path / "rec.out", "w"), stderr=open(tmp_path / "rec.err", "w")) as rec:
        wait_ready(rec, ready, "ddct log record vcan0")
        r = lib.run([ddct, "log", "replay", src, "--iface", IFACE], check=False, timeout=120)
        assert r.returncode == 0, r.stderr[-3000:]
        assert rec.wait(60) == 0, (tmp_path / "rec.err").read_text()
    sent = [(fid, data) for (_, _, fid, _, data) in ddct_can.read_candump(src)]
    got = [(fid, data) for (_, _, fid, _, data) in ddct_can.read_candump(log)]
    assert got == sent
    assert f"recorded {len(frames)} frame(s) from {IFACE}" in (tmp_path / "rec.err").read_text()


def test_log_monitor_takes_the_interface_positionally(ddct, tmp_path):
    """`ddct log monitor vcan0` (as one types `candump vcan0`) shows the plant's messages; a name
    that is neither a file nor an interface is refused with what to do."""
    with background([ddct, "plant", "--iface", IFACE, "--duration", "4"],
                    stdout=open(tmp_path / "plant.out", "w"), stderr=open(tmp_path / "plant.err", "w")) as plant:
        r = lib.run([ddct, "log", "monitor", IFACE, "--duration", "2"], check=False, timeout=60)
        plant.wait(60)
    no_panic(r.stdout + r.stderr)
    assert r.returncode == 0, r.stderr[-3000:]
    assert re.search(r"DCT_Sensors +\d+", r.stdout) and "ENG_Status" in r.stdout, r.stdout[-3000:]
    r = lib.run([ddct, "log", "monitor", "vcan7"], check=False)
    assert r.returncode != 0 and "neither a log file nor a network interface" in r.stderr, r.stderr


def test_diag_reads_the_tcus_version_on_vcan0(ddct, tmp_path):
    """`ddct diag read-did --iface vcan0 Version` against `ddct tcu --iface vcan0` (UDS on ISO-TP
    over the real bus)."""
    ready = tmp_path / "tcu.ready"
    with background([ddct, "tcu", "--iface", IFACE, "--ready-file", ready],
                    stdout=open(tmp_path / "tcu.out", "w"), stderr=open(tmp_path / "tcu.err", "w")) as tcu:
        wait_ready(tcu, ready, "ddct tcu")
        r = lib.run([ddct, "diag", "read-did", "--iface", IFACE, "Version"], check=False, timeout=60)
    no_panic(r.stdout + r.stderr)
    assert r.returncode == 0, (r.stdout + r.stderr)[-3000:]
    version = lib.run([ddct, "--version"]).stdout.split()[-1]
    assert version in r.stdout, (version, r.stdout)
