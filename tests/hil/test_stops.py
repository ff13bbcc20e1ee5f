"""A daemon killed (-9) and restarted mid-launch, and the plant frozen (SIGSTOP) for 200 ms, on the
daemons' own clocks over vcan0 (issue 12). Everything is recorded by `ddct log record` with
kernel timestamps; the driver is the ddct_can package's, on its 10 ms timer.

- The TCU killed: the plant sees its commands time out; the restarted TCU drives again (it
  restarts its strategy from the measurements: at speed it re-engages the gear).
- The plant killed: the TCU commands the safe state with EngStatusTimeout (ENG_Status has the
  highest priority of the silent inputs) and leaves it once a restarted plant sends again.
- The plant frozen for 200 ms: the same safe state, then normal again within 100 ms of the
  plant's first frame.

Timing is printed always. The exact contract (the safe state in the computation after 3 silent
cycles, recovery within 100 ms) is asserted in bus time by test_hil.py; here, in real time on a
guest with a noisy tail, it is asserted with generous bounds when the guest ran (stalls under
10 % of the run): the safe state within 80 ms of the plant's last frame (3 cycles of timeout, up
to one of the TCU's timer phase, the rest scheduling), normal within 200 ms of its first frame
again, exit within 100 ms of SIGTERM.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import time

import can
import launch as hil
import pytest
from ddct_can import Bench, Driver

from test_hil import CYCLE_MS, starved

DETECT_MS = 8 * CYCLE_MS
RECOVER_MS = 200.0
EXIT_MS = 100.0


@contextlib.contextmanager
def recording(ddct, out, name):
    """`ddct log record` on vcan0 until the block ends; yields a list filled with the records."""
    log, ready = out / f"{name}.log", out / f"{name}_record.ready"
    ready.unlink(missing_ok=True)
    rec = subprocess.Popen([str(ddct), "log", "record", "--iface", "vcan0", "--out", str(log), "--ready-file",
                            str(ready)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    records: list = []
    try:
        hil.wait_ready(rec, ready, "the recorder")
        yield records
    finally:
        rec.send_signal(signal.SIGTERM)
        _, err = rec.communicate(timeout=30)
        assert rec.returncode == 0, f"the recorder exited {rec.returncode}: {err}"
    records.extend(hil.ddct_can.read_candump(log))


def statuses(records):
    """(t, state label, fault label) of every TCU_Status frame."""
    msg = hil.ddct_can.message("TCU_Status")
    st = {int(k): str(v) for k, v in msg.get_signal_by_name("TcuState").choices.items()}
    fc = {int(k): str(v) for k, v in msg.get_signal_by_name("FaultCode").choices.items()}
    out = []
    for t, _, fid, _, d in records:
        if fid == msg.frame_id:
            v = msg.decode(bytes(d), decode_choices=False)
            out.append((t, st.get(int(v["TcuState"]), "?"), fc.get(int(v["FaultCode"]), "?")))
    return out


def frames_of(records, name):
    fid = hil.frame_id(name)
    return [t for t, _, f, _, _ in records if f == fid]


def normal(state, fault):
    return state not in ("SafeState", "Init") and fault == "None"


def drive(ddct, out_dir, name, disturb):
    """A 40 % launch in real time; ``disturb(bench)`` runs 0.5 s after the pedal is pressed and
    returns the moments (time.time()) it wants back; then 4 s more, SIGTERM to both daemons."""
    with recording(ddct, out_dir, name) as records:
        with can.Bus(interface="socketcan", channel="vcan0", receive_own_messages=False) as bus, \
                Driver(bus) as driver:
            bench = Bench("vcan0", ddct=ddct, tcu_config=hil.REPO / "config" / "tcu.toml", workdir=out_dir,
                          cwd=hil.REPO, keep=True, prefix=f"{name}_")
            with bench:
                driver.launch(40.0)
                time.sleep(0.5)
                marks = disturb(bench)
                time.sleep(4.0)
                bench.check_running()
            tcu_stop_ms = bench.tcu.stop_s * 1e3 if bench.tcu.stop_s is not None else None
    print(f"\n== {name}: {len(records)} frames; TCU SIGTERM to exit {tcu_stop_ms} ms")
    for t, st, fc in transitions(statuses(records)):
        print(f"  {t:.3f}  {st:<10} {fc}")
    assert hil.bad_tcu_frames(records) == [], hil.bad_tcu_frames(records)[:5]
    assert bench.tcu_report is not None and bench.tcu_report["stopped_by"] == "shutdown", bench.tcu_report
    return records, marks, bench, tcu_stop_ms


def transitions(rows):
    out, last = [], None
    for t, st, fc in rows:
        if (st, fc) != last:
            out.append((t, st, fc))
            last = (st, fc)
    return out


def judged(bench) -> bool:
    why = starved(bench.tcu_report, bench.plant_report)
    if why:
        print(f"timing NOT JUDGED: {why}")
    return why is None


def test_the_tcu_killed_and_restarted_mid_launch_drives_again(ddct, out_dir):
    def disturb(bench):
        t_kill = time.time()
        bench.kill("tcu")
        time.sleep(0.5)
        t_restart = time.time()
        bench.restart("tcu")
        return t_kill, t_restart

    records, (t_kill, t_restart), bench, stop_ms = drive(ddct, out_dir, "kill_tcu", disturb)
    cmd = frames_of(records, "TCU_ClutchCmd")
    silent = [t for t in cmd if t_kill + 0.05 < t < t_restart]
    assert silent == [], f"TCU frames while it was dead: {silent[:3]}"
    back = [(t, st, fc) for t, st, fc in statuses(records) if t > t_restart]
    driving = [t for t, st, fc in back if normal(st, fc)]
    print(f"restarted TCU: first frame {back[0][0] - t_restart if back else None} s after the restart, "
          f"normal {driving[0] - t_restart if driving else None} s after it; plant input timeouts "
          f"{bench.plant_report['plant']['input_timeouts']}")
    assert driving, f"the restarted TCU never drove: {transitions(back)[:5]}"
    assert driving[0] - t_restart < 2.0, transitions(back)[:5]
    assert bench.plant_report["plant"]["input_timeouts"].get("TCU_ClutchCmd", 0) >= 1, "the plant missed the dead TCU"
    if judged(bench):
        assert stop_ms <= EXIT_MS, f"SIGTERM to exit {stop_ms} ms"


@pytest.mark.parametrize("how", ["kill", "sigstop"])
def test_the_plant_lost_puts_the_tcu_in_the_safe_state_until_it_is_back(ddct, out_dir, how):
    def disturb(bench):
        pid = bench.plant.proc.pid
        if how == "kill":
            t_off = time.time()
            bench.kill("plant")
            time.sleep(0.5)
            t_on = time.time()
            bench.restart("plant")
        else:
            t_off = time.time()
            os.kill(pid, signal.SIGSTOP)
            time.sleep(0.2)
            os.kill(pid, signal.SIGCONT)
            t_on = time.time()
        return t_off, t_on

    records, (t_off, t_on), bench, stop_ms = drive(ddct, out_dir, f"plant_{how}", disturb)
    eng = frames_of(records, "ENG_Status")
    last = max((t for t in eng if t <= t_off + 0.02), default=None)
    first = min((t for t in eng if t > t_off + 0.05), default=None)
    rows = statuses(records)
    timeout = [t for t, st, fc in rows if last is not None and t > last and st == "SafeState" and fc == "EngStatusTimeout"]
    recovered = [t for t, st, fc in rows if first is not None and t > first and normal(st, fc)]
    detect_ms = (timeout[0] - last) * 1e3 if timeout else None
    recover_ms = (recovered[0] - first) * 1e3 if recovered else None
    print(f"plant {how}: ENG_Status silent {None if first is None else (first - last) * 1e3:.0f} ms; safe state "
          f"{detect_ms} ms after its last frame; normal {recover_ms} ms after its first frame again")
    assert first is not None, "the plant never sent again"
    assert timeout, f"no SafeState/EngStatusTimeout while the plant was gone: {transitions(rows)[:8]}"
    assert recovered, f"the TCU did not leave the safe state: {transitions(rows)[-5:]}"
    if judged(bench):
        assert detect_ms <= DETECT_MS, f"safe state {detect_ms:.1f} ms after the plant's last frame"
        if how == "sigstop":
            assert recover_ms <= RECOVER_MS, f"normal {recover_ms:.1f} ms after the plant's first frame"
        assert stop_ms <= EXIT_MS, f"SIGTERM to exit {stop_ms} ms"
