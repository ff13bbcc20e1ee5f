"""ddct on a real SocketCAN bus (vcan0): the Rust sender and receiver against can-utils and
python-can. Run through scripts/vcan-run."""

from __future__ import annotations

import re
import socket
import threading
import time
from pathlib import Path

import can
import pytest

import ddct_testlib as lib
from vcan_helpers import IFACE, background, can_receivers, wait_receivers
from ddct_testlib import ddct_can

RCVBUF = 4 * 1024 * 1024


def frame_list(reps: int) -> list[dict]:
    """Every message at min/mid/max, `reps` times, with consecutive alive counters."""
    frames = []
    counters: dict[int, int] = {}
    for _ in range(reps):
        for fr in lib.sample_frames():
            c = counters.get(fr["id"], 0)
            counters[fr["id"]] = c + 1
            frames.append(dict(fr, data=ddct_can.encode(fr["name"], fr["signals"], c)))
    return frames


class PythonCanReceiver(threading.Thread):
    """python-can on vcan0, collecting frames until `count` arrived or the deadline passed."""

    def __init__(self, count: int, timeout: float = 120.0):
        super().__init__(daemon=True)
        self.count, self.timeout = count, timeout
        self.bus = can.Bus(interface="socketcan", channel=IFACE, receive_own_messages=False)
        try:  # room for a burst sent as fast as the bus takes it (root may exceed rmem_max)
            self.bus.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUFFORCE, RCVBUF)
        except (OSError, AttributeError):
            self.bus.socket.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF)
        self.msgs: list[can.Message] = []

    def run(self):
        deadline = time.monotonic() + self.timeout
        try:
            while len(self.msgs) < self.count and time.monotonic() < deadline:
                m = self.bus.recv(0.5)
                if m is not None and not m.is_error_frame:
                    self.msgs.append(m)
        finally:
            self.bus.shutdown()


def send_frames(frames: list[dict]) -> None:
    """Send `frames` ({"id", "data"}) on vcan0 with python-can, in order."""
    with can.Bus(interface="socketcan", channel=IFACE) as bus:
        for fr in frames:
            bus.send(can.Message(arbitration_id=fr["id"], data=fr["data"], is_extended_id=False), timeout=5)


def read_log(path: Path) -> list[tuple[int, bytes]]:
    return [(fid, data) for (_, _, fid, _, data) in ddct_can.read_candump(path)]


def test_vcan0_is_a_can_interface(vcan0):
    assert Path(f"/sys/class/net/{vcan0}/type").read_text().strip() == "280"
    with can.Bus(interface="socketcan", channel=vcan0) as a, can.Bus(interface="socketcan", channel=vcan0) as b:
        a.send(can.Message(arbitration_id=1, data=b"\x01\x02", is_extended_id=False))
        m = b.recv(10.0)
        assert m is not None and bytes(m.data) == b"\x01\x02"


def test_replay_seen_by_candump_and_python_can(ddct, candump, tmp_path):
    frames = frame_list(reps=5)
    log = tmp_path / "replay.log"
    lib.write_candump(log, frames, iface=IFACE, dt=0.001)
    n = len(frames)
    dump_file = tmp_path / "candump.txt"
    before = can_receivers()
    rx = PythonCanReceiver(n)
    rx.start()
    with open(dump_file, "w") as out, background(
        [candump, "-L", "-r", str(RCVBUF), "-n", str(n), IFACE], stdout=out, stderr=open(tmp_path / "candump.err", "w")
    ) as dump:
        wait_receivers(before, 2, procs=[dump])
        lib.run([ddct, "log", "replay", log, "--iface", IFACE], timeout=120)
        dump.wait(60)
    rx.join(60)
    sent = [(f["id"], f["data"]) for f in frames]
    seen_candump = read_log(dump_file)
    seen_python = [(m.arbitration_id, bytes(m.data)) for m in rx.msgs]
    assert len(seen_candump) == n, f"candump saw {len(seen_candump)} of {n} frames"
    assert len(seen_python) == n, f"python-can saw {len(seen_python)} of {n} frames"
    assert seen_candump == sent
    assert seen_python == sent
    assert all(not m.is_extended_id and m.dlc == len(m.data) for m in rx.msgs)
    assert {line.split()[1] for line in dump_file.read_text().splitlines()} == {IFACE}


def replay_span(ddct, log, n, *options) -> list[can.Message]:
    """Replay `log` with `options` and return the frames python-can saw."""
    rx = PythonCanReceiver(n, timeout=60)  # bound (listening) once constructed
    rx.start()
    lib.run([ddct, "log", "replay", log, "--iface", IFACE, *options], timeout=120)
    rx.join(60)
    return rx.msgs


def test_replay_keeps_the_log_timing_unless_max_rate(ddct, tmp_path):
    frames = frame_list(reps=1)[:20]
    gap = 0.05
    paced = tmp_path / "paced.log"
    lib.write_candump(paced, frames, dt=gap)
    sent = [(f["id"], f["data"]) for f in frames]
    want = gap * (len(frames) - 1)
    # generous bounds: the relative timing is kept (not compressed, not wildly stretched)
    for options, factor in [((), 1.0), (("--speed", "2"), 0.5)]:
        msgs = replay_span(ddct, paced, len(frames), *options)
        assert [(m.arbitration_id, bytes(m.data)) for m in msgs] == sent
        span = msgs[-1].timestamp - msgs[0].timestamp
        assert want * factor * 0.8 <= span <= want * factor + 5.0, f"{options}: span {span:.3f} s, want {want * factor:.3f} s"
    # --loop 3: three passes, the second one median interval (50 ms) after the first one's end
    msgs = replay_span(ddct, paced, 3 * len(frames), "--loop", "3")
    assert [(m.arbitration_id, bytes(m.data)) for m in msgs] == 3 * sent
    span = msgs[-1].timestamp - msgs[0].timestamp
    assert 3 * want * 0.8 <= span <= 3 * want + 2 * gap + 5.0, span

    slow = tmp_path / "slow.log"  # 19 gaps of 10 s: at the log's timing it would take minutes
    lib.write_candump(slow, frames, dt=10.0)
    t0 = time.monotonic()
    msgs = replay_span(ddct, slow, len(frames), "--max-rate")
    took = time.monotonic() - t0
    assert len(msgs) == len(frames)
    assert took < 30.0, f"replay --max-rate took {took:.1f} s for a log spanning 190 s"
    bad = lib.run([ddct, "log", "replay", slow, "--iface", IFACE, "--speed", "0"], check=False)
    assert bad.returncode == 2 and "--speed" in bad.stderr, bad.stderr


def test_replay_at_log_timing_loses_no_frame_to_a_recorder(ddct, tmp_path):
    """3 000 frames at the log's 1 ms spacing, recorded by `ddct log record`: all of them."""
    frames = frame_list(reps=1)
    frames = (frames * (3000 // len(frames) + 1))[:3000]
    log = tmp_path / "dense.log"
    lib.write_candump(log, frames, dt=0.001)
    out = tmp_path / "recorded.log"
    before = can_receivers()
    with background(
        [ddct, "log", "record", "--iface", IFACE, "--out", out, "--count", len(frames), "--duration", 120],
        stdout=open(tmp_path / "record.out", "w"),
        stderr=open(tmp_path / "record.err", "w"),
    ) as rec:
        wait_receivers(before, 1, procs=[rec])
        lib.run([ddct, "log", "replay", log, "--iface", IFACE], timeout=120)
        assert rec.wait(150) == 0, (tmp_path / "record.err").read_text()
    got = read_log(out)
    print(f"\nreplay at log timing: recorded {len(got)} of {len(frames)} frames")
    assert got == [(f["id"], f["data"]) for f in frames]
    # The recorder's own account: frames per id and the kernel's drops on its socket.
    err = (tmp_path / "record.err").read_text()
    assert "dropped by the kernel (receive queue full): 0" in err, err
    for fid in {f["id"] for f in frames}:
        want = sum(1 for f in frames if f["id"] == fid)
        assert re.search(rf"^  {fid:03X} \S+ +{want}$", err, re.M), (hex(fid), want, err)


def cansend_frames(db) -> list[tuple[int, bytes]]:
    """E2E frames of several messages, an unprotected one, an unknown ID and short DLCs."""
    out = []
    for fr in frame_list(reps=1)[::4]:
        out.append((fr["id"], fr["data"]))
    known = {m.frame_id for m in db.messages}
    unknown = next(i for i in range(1, 0x800) if i not in known)
    out += [(unknown, b""), (unknown, b"\xde\xad\xbe\xef"), (unknown, bytes(range(8)))]
    return out


def test_record_sees_cansend(ddct, cansend, tmp_path):
    db = ddct_can.load_dbc()
    frames = cansend_frames(db)
    out = tmp_path / "record.log"
    before = can_receivers()
    t_start = time.time()
    with background(
        [ddct, "log", "record", "--iface", IFACE, "--out", out, "--count", len(frames)],
        stdout=open(tmp_path / "record.out", "w"),
        stderr=open(tmp_path / "record.err", "w"),
    ) as rec:
        wait_receivers(before, 1, procs=[rec])
        for fid, data in frames:
            lib.run([cansend, IFACE, f"{fid:03X}#{data.hex().upper()}"], timeout=30)
        rc = rec.wait(60)
    assert rc == 0, (tmp_path / "record.err").read_text()
    lines = out.read_text().splitlines()
    assert len(lines) == len(frames)
    parsed = [ddct_can.parse_candump_line(line) for line in lines]  # strict candump -l format
    assert [(fid, data) for (_, _, fid, _, data) in parsed] == frames
    assert all(iface == IFACE and not ext for (_, iface, _, ext, _) in parsed)
    stamps = [t for (t, *_rest) in parsed]
    assert stamps == sorted(stamps)
    assert t_start - 60 <= stamps[0] <= time.time() + 60, "timestamps are not wall-clock seconds"

    # python-can reads it ...
    got = list(can.LogReader(str(out)))
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == frames
    # ... and so does cantools, with the DBC
    decoded = lib.cantools_decode_log(out)
    assert len(decoded) == len(frames)
    for (fid, data), rec_ in zip(frames, decoded):
        assert rec_["id"] == fid and rec_["data"] == data
        if fid in {m.frame_id for m in db.messages}:
            msg = db.get_message_by_frame_id(fid)
            assert rec_["name"] == msg.name
            assert not lib.signal_mismatches(msg, ddct_can.decode(fid, data), rec_["signals"])


def test_candump_log_decoded_by_ddct(ddct, candump, db, tmp_path):
    frames = lib.sample_frames()
    before = can_receivers()
    with background(
        [candump, "-l", "-r", str(RCVBUF), "-n", str(len(frames)), IFACE],
        cwd=tmp_path,
        stdout=open(tmp_path / "candump.out", "w"),
        stderr=open(tmp_path / "candump.err", "w"),
    ) as dump:
        wait_receivers(before, 1, procs=[dump])
        send_frames(frames)
        assert dump.wait(60) == 0
    logs = sorted(tmp_path.glob("candump-*.log"))
    assert len(logs) == 1, list(tmp_path.iterdir())
    assert read_log(logs[0]) == [(f["id"], f["data"]) for f in frames]
    recs = lib.json_lines(lib.run([ddct, "log", "decode", logs[0], "--format", "json"]).stdout)
    assert len(recs) == len(frames)
    problems = []
    for fr, r in zip(frames, recs):
        msg = db.get_message_by_frame_id(fr["id"])
        assert r["id"] == fr["id"] and r["name"] == msg.name and r["iface"] == IFACE and r["error"] is None, r
        want = "ok" if ddct_can.is_protected(msg.name) else "not_protected"
        if r["e2e"] != want:
            problems.append(f"{msg.name} ({fr['case']}): e2e {r['e2e']!r}, expected {want!r}")
        problems += lib.signal_mismatches(msg, ddct_can.decode(fr["id"], fr["data"]), r["signals"], f" ({fr['case']})")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("options", [[], ["-t", "a"], ["-x", "-a"]], ids=["default", "t_a", "x_a"])
def test_candump_screen_output_piped_into_decode(ddct, candump, db, tmp_path, options):
    """`candump vcan0 | ddct log decode -`: candump's screen formats, decoded live, agree with
    cantools frame by frame; lines without a time are stamped as they arrive."""
    frames = lib.sample_frames()
    before = can_receivers()
    shell = f"{candump} {' '.join(options)} -n {len(frames)} {IFACE} | {ddct} log decode - --format json --quiet"
    t0 = time.time()
    with background(
        ["sh", "-c", shell],
        stdout=open(tmp_path / "decode.json", "w"),
        stderr=open(tmp_path / "decode.err", "w"),
    ) as pipe:
        wait_receivers(before, 1, procs=[pipe])
        send_frames(frames)
        assert pipe.wait(60) == 0, (tmp_path / "decode.err").read_text()
    t1 = time.time()
    err = (tmp_path / "decode.err").read_text()
    assert "gap:" not in err and "malformed" not in err, err
    recs = lib.json_lines((tmp_path / "decode.json").read_text())
    assert [r["id"] for r in recs] == [f["id"] for f in frames]
    problems = []
    for fr, r in zip(frames, recs):
        msg = db.get_message_by_frame_id(fr["id"])
        assert r["iface"] == IFACE and r["error"] is None, r
        # Stamped on arrival (no -t) or by candump (-t a): within the sending window either way.
        assert t0 - 1.0 <= r["t"] <= t1 + 1.0, (r["t"], t0, t1)
        problems += lib.signal_mismatches(msg, ddct_can.decode(fr["id"], fr["data"]), r["signals"], f" ({fr['case']})")
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("source", ["iface", "candump_pipe"])
def test_monitor_shows_every_message_with_counts_and_e2e_errors(ddct, candump, db, tmp_path, source):
    """`ddct log monitor --iface vcan0` and `candump vcan0 | ddct log monitor -`: every message
    sent appears with its frame count and latest values by name; a corrupted CRC is counted."""
    frames = frame_list(reps=3)
    bad = dict(frames[0])
    bad["data"] = bad["data"][:7] + bytes([bad["data"][7] ^ 0xFF])
    sent = frames + [bad]
    before = can_receivers()
    if source == "iface":
        cmd = [ddct, "log", "monitor", "--iface", IFACE, "--duration", "8"]
    else:
        cmd = ["sh", "-c", f"{candump} -n {len(sent)} {IFACE} | {ddct} log monitor -"]
    with background(cmd, stdout=open(tmp_path / "mon.txt", "w"), stderr=open(tmp_path / "mon.err", "w")) as mon:
        wait_receivers(before, 1, procs=[mon])
        send_frames(sent)
        assert mon.wait(60) == 0, (tmp_path / "mon.err").read_text()
    text = (tmp_path / "mon.txt").read_text()
    counts: dict[int, int] = {}
    for fr in sent:
        counts[fr["id"]] = counts.get(fr["id"], 0) + 1
    for fid, n in counts.items():
        name = db.get_message_by_frame_id(fid).name
        assert re.search(rf"^{fid:03X} +{name} +{n} ", text, re.M), (name, n, text)
    bad_name = db.get_message_by_frame_id(bad["id"]).name
    line = next(l for l in text.splitlines() if re.match(rf"{bad['id']:03X} +{bad_name} ", l))
    assert "bad_crc 1" in line, line
    assert "TcuState=" in text, text


@pytest.mark.parametrize("daemon", ["tcu", "record"])
def test_ready_file_means_listening(ddct, daemon, tmp_path):
    """`--ready-file`: once the file exists (holding the daemon's pid) a frame sent at once is
    heard, and a SIGTERM sent at once ends the daemon cleanly with its report — the socket and the
    signal handlers are in place before the file is written (a bench script waits for it instead
    of sleeping; a fixed 0.3 s once let a lockstep plant's first cycle go out before the TCU
    listened)."""
    import signal as sig

    ready = tmp_path / "ready"
    if daemon == "tcu":
        args = [ddct, "tcu", "--iface", IFACE, "--config", lib.REPO / "config" / "tcu.toml", "--json",
                "--clock", "bus", "--ready-file", ready]
    else:
        args = [ddct, "log", "record", "--iface", IFACE, "--out", tmp_path / "rec.log", "--ready-file", ready]
    out, err = open(tmp_path / "out", "w"), open(tmp_path / "err", "w")
    with background(args, stdout=out, stderr=err) as p:
        deadline = time.monotonic() + 60
        while not ready.exists():
            assert p.poll() is None, f"{daemon} exited {p.returncode}: {(tmp_path / 'err').read_text()}"
            assert time.monotonic() < deadline, f"{daemon} never wrote {ready}"
            time.sleep(0.005)
        assert ready.read_text().strip() == str(p.pid)
        fid = ddct_can.load_dbc().get_message_by_name("DCT_Sensors").frame_id
        with can.Bus(interface="socketcan", channel=IFACE, receive_own_messages=False) as bus:
            bus.send(can.Message(arbitration_id=fid, data=bytes(8), is_extended_id=False))
        time.sleep(0.2)
        p.send_signal(sig.SIGTERM)
        rc = p.wait(30)
    out.close(), err.close()
    assert rc == 0, (tmp_path / "err").read_text()
    if daemon == "tcu":
        import json
        report = json.loads((tmp_path / "out").read_text())
        assert report["stopped_by"] == "shutdown" and report["frames_received"] == 1, report
    else:
        assert [f for (_, _, f, _, _) in ddct_can.read_candump(tmp_path / "rec.log")] == [fid]


def test_the_driver_sends_from_the_kernels_broadcast_manager(vcan0):
    """On SocketCAN the Driver's 10 ms come from CAN_BCM: consecutive alive counters with valid
    CRCs also across changes of state, and no gap near the TCU's 3-cycle input timeout however
    busy python is (here: a thread spinning under the GIL while the driver runs)."""
    from ddct_can.driver import Driver
    from ddct_can.e2e import check, counter_of

    fid = ddct_can.frame_id("DRV_Pedal")
    rx = can.Bus(interface="socketcan", channel=IFACE, receive_own_messages=False,
                 can_filters=[{"can_id": fid, "can_mask": 0x7FF}])
    stop = threading.Event()

    def spin():  # holds the GIL most of the time, as a busy tester or recorder does
        while not stop.is_set():
            sum(range(10_000))

    busy = threading.Thread(target=spin, daemon=True)
    got: list[can.Message] = []
    try:
        with can.Bus(interface="socketcan", channel=IFACE) as tx:
            driver = Driver(tx, counter=5)
            assert driver.kernel_timer
            with driver:
                busy.start()
                t0 = time.monotonic()
                for when, act in ((0.5, lambda: driver.drive(brake=True)), (1.0, lambda: driver.pedal(30))):
                    while time.monotonic() - t0 < when:
                        m = rx.recv(0.05)
                        if m is not None:
                            got.append(m)
                    act()
                while time.monotonic() - t0 < 1.5:
                    m = rx.recv(0.05)
                    if m is not None:
                        got.append(m)
            stop.set()
            n_after_stop = sum(1 for _ in iter(lambda: rx.recv(0.1), None))
    finally:
        stop.set()
        rx.shutdown()
    assert len(got) >= 100, len(got)
    assert all(check(fid, bytes(m.data)) == "ok" for m in got), [bytes(m.data).hex() for m in got][:5]
    counters = [counter_of(fid, bytes(m.data)) for m in got]
    assert counters[0] == 5 % 16
    assert all((b - a) % 16 == 1 for a, b in zip(counters, counters[1:])), counters
    lever = {str(name): value for value, name in ddct_can.message("DRV_Pedal").get_signal_by_name("GearLever").choices.items()}
    states = [(d["GearLever"], d["BrakeSwitch"], d["AccelPedal"])
              for d in (ddct_can.decode(fid, bytes(m.data)) for m in got)]
    order = [s for i, s in enumerate(states) if i == 0 or s != states[i - 1]]
    assert order == [(lever["N"], 1, 0.0), (lever["D"], 1, 0.0), (lever["D"], 0, 30.0)], order
    gaps = sorted(b.timestamp - a.timestamp for a, b in zip(got, got[1:]))
    median = gaps[len(gaps) // 2]
    late = sum(g > 0.02 for g in gaps)
    print(f"\nBCM driver: {len(got)} frames, gap median {median * 1e3:.2f} ms, "
          f"max {gaps[-1] * 1e3:.2f} ms, {late} gaps over 20 ms")
    assert abs(median - 0.01) < 0.002, median
    # The guest's own stalls (User-Mode Linux under a loaded host: 60 ms now and then) reach the
    # kernel's timer too, so the tail is reported, not asserted; what python's busy GIL would
    # do to a thread-timed sender -- gaps on most frames -- is bounded: at most 1 in 20 late.
    assert late <= len(gaps) // 20, (late, gaps[-10:])
    assert n_after_stop <= 1, "the kernel task kept sending after stop()"
