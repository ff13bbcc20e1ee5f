#!/usr/bin/env python3
"""Plays the driver of a launch (or a launch with upshifts) on a CAN bus against the plant and TCU
daemons, records the bus into a candump log, computes the launch, shift, estimator, fault and
timing metrics from the log and prints them as a table.

    .venv/bin/python scripts/launch.py --iface vcan0 --pedal 50            # daemons started here
    .venv/bin/python scripts/launch.py --program shifts --pedal 50 --seconds 14
    .venv/bin/python scripts/launch.py --faults faults.toml                 # plant fault injection
    .venv/bin/python scripts/launch.py --no-daemons ...                     # daemons already running
    .venv/bin/python scripts/launch.py --lockstep ...                       # in bus time

Real time (the default): the driver sends DRV_Pedal every 10 ms (absolute deadlines), the daemons
run on their own clocks; what the host's scheduling does to the bench shows in the timing.

Lockstep (`--lockstep`): the plant waits after each cycle for the TCU's last frame of the cycle
(TCU_Estimates, sent after its other four) and the driver's DRV_Pedal (`ddct plant --lockstep
TCU_Estimates,DRV_Pedal`), the TCU's time is the
plant's simulated time (`ddct tcu --clock bus`) and the driver answers each DCT_Sensors frame. The
run is then the same frames whatever the host's load, and its timing is analysed in bus time
(`bus_time`): detection, safe state and recovery exact in cycles.

The driver sends DRV_Pedal every 10 ms (absolute deadlines) with the E2E counter and CRC of the
contract: lever N, then D at 0.5 s, brake held until the launch at 1.0 s, then the pedal; the
`shifts` program releases the pedal and brakes for the last 4 s. The plant runs without a built-in
driver (it reads DRV_Pedal), the TCU with config/tcu.toml. `ddct log record` records the bus with
kernel receive timestamps. Everything about the frames comes from dbc/ddct.dbc (cantools, through
the ddct_can package in python/, which also sends the driver's frames (`Driver`) and runs the
daemons (`Bench`)): no ID, scale or offset is written here.

Run it inside scripts/vcan-run where the host has no vcan0.
"""

from __future__ import annotations

import argparse
import json
import math
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

try:
    import ddct_can
    from ddct_can import Bench, Driver
except ModuleNotFoundError as e:  # python/ddct_can, installed into .venv by scripts/setup
    raise ImportError(f"the ddct_can package is not installed in {sys.executable}: run scripts/setup "
                      "(it does pip install -e ./python)") from e

REPO = Path(__file__).resolve().parent.parent

# The driver's timeline (s), relative to the start of the driver.
LEVER_D_S = 0.5
LAUNCH_S = 1.0
CYCLE_S = 0.01


# From the DBC, through the package.
choice = ddct_can.choice
label = ddct_can.label
frame_id = ddct_can.frame_id


# ---------------------------------------------------------------------------------------------
# The driver


def driver_sample(program: str, pedal: float, seconds: float, t: float) -> dict:
    """DRV_Pedal signals at time t of a program."""
    lever = "N" if t < LEVER_D_S else "D"
    if t < LAUNCH_S:
        return {"AccelPedal": 0.0, "BrakeSwitch": 1, "GearLever": lever}
    if program == "shifts" and t > seconds - 4.0:
        return {"AccelPedal": 0.0, "BrakeSwitch": 1, "GearLever": lever}
    return {"AccelPedal": pedal, "BrakeSwitch": 0, "GearLever": lever}


# A second DRV_Pedal node (spoofing, issue 12): lever R, full pedal, its own alive counter.
SPOOF = {"AccelPedal": 100.0, "BrakeSwitch": 0, "GearLever": "R"}
SPOOF_COUNTER_AHEAD = 8


def play_driver_lockstep(bus, plant, program: str, pedal: float, seconds: float, spoof=None) -> int:
    """Answers each DCT_Sensors frame (cycle n, bus time n·10 ms) with DRV_Pedal until the plant
    exits (the lockstep plant waits for the answer); returns the number of frames sent. `spoof`
    (from_s, to_s): a second node also answers in that window with SPOOF (not counted)."""
    sensors = frame_id("DCT_Sensors")
    driver = Driver(bus, cycle_s=CYCLE_S)
    n = 0
    while True:
        msg = bus.recv(timeout=0.5)
        if msg is None:
            if plant is None or plant.poll() is not None:
                return n
            continue
        if msg.arbitration_id != sensors or msg.is_extended_id:
            continue
        t = min(n * CYCLE_S, seconds)
        driver.send(driver_sample(program, pedal, seconds, t))  # counter n
        if spoof is not None and spoof[0] <= t < spoof[1]:
            driver.send(SPOOF, counter=n + SPOOF_COUNTER_AHEAD)
        n += 1


def play_driver(bus, program: str, pedal: float, seconds: float) -> int:
    """Sends DRV_Pedal every 10 ms on absolute deadlines; returns the number of frames sent. A
    frame the full transmit queue refuses is dropped (the TCU's E2E sees a skipped counter)."""
    driver = Driver(bus, cycle_s=CYCLE_S)
    return driver.play(seconds, lambda t: driver_sample(program, pedal, seconds, t))


# ---------------------------------------------------------------------------------------------
# Analysis of a recorded log

TCU_MESSAGES = ("TCU_ClutchCmd", "TCU_EngineReq", "TCU_GearCmd", "TCU_Status", "TCU_Estimates")


def bad_tcu_frames(records) -> list:
    """(t, message, what) for every TCU frame with a wrong E2E CRC or a signal outside its DBC
    range. A NaN or infinity inside the TCU cannot be encoded on the bus: it would show here as
    an out-of-range value (or as a missing frame, which the callers count)."""
    bad = []
    for name in TCU_MESSAGES:
        msg = ddct_can.message(name)
        protected = ddct_can.e2e.has_e2e_signals(msg)
        for t, _, fid, _, data in records:
            if fid != msg.frame_id:
                continue
            data = bytes(data)
            if protected and ddct_can.e2e.e2e_crc(fid, data) != data[-1]:
                bad.append((t, name, "CRC"))
                continue
            values = msg.decode(data, decode_choices=False)
            for s in msg.signals:
                v = values[s.name]
                if not math.isfinite(v) or (s.minimum is not None and v < s.minimum - 1e-9) or \
                        (s.maximum is not None and v > s.maximum + 1e-9):
                    bad.append((t, name, f"{s.name}={v}"))
    return bad


@dataclass
class Series:
    """Latest decoded value of every signal at each TCU_Status frame (one row per TCU cycle)."""

    t: list = field(default_factory=list)
    rows: list = field(default_factory=list)


def rows_of(records) -> list[dict]:
    """records: [(t, iface, id, ext, data)] -> one dict per TCU_Status frame, with the latest
    value of every signal seen so far (message.signal keys) and `t` relative to the first frame."""
    by_id = {m.frame_id: m for m in ddct_can.load_dbc().messages}
    status_id = frame_id("TCU_Status")
    sensors_id = frame_id("DCT_Sensors")
    latest: dict = {}
    rows = []
    t0 = records[0][0] if records else 0.0
    plant_seen = False
    for t, _, fid, ext, data in records:
        m = by_id.get(fid)
        if ext or m is None or len(data) != m.length:
            continue
        try:
            vals = m.decode(bytes(data), decode_choices=False)
        except Exception:  # noqa: BLE001 - a frame outside the DBC ranges is skipped
            continue
        for k, v in vals.items():
            latest[f"{m.name}.{k}"] = v
        plant_seen |= fid == sensors_id
        if fid == status_id and plant_seen:
            row = dict(latest)
            row["t"] = t - t0
            rows.append(row)
    return rows


def pct(values, q):
    v = sorted(x for x in values if math.isfinite(x))
    if not v:
        return float("nan")
    return v[min(len(v) - 1, max(0, math.ceil(q * len(v)) - 1))]


def latency_us(records, cause: str, effect: str) -> list[float]:
    c_id, e_id = frame_id(cause), frame_id(effect)
    out, pending = [], None
    for t, _, fid, _, _ in records:
        if fid == c_id:
            pending = t
        elif fid == e_id and pending is not None:
            out.append((t - pending) * 1e6)
            pending = None
    return out


def bus_time(records) -> list:
    """The records of a lockstep run on the bus's own time axis: plant cycle n at n·10 ms. Each
    DCT_Sensors frame starts a cycle; the frames after it (the rest of the plant's cycle, the TCU's
    and the driver's answers to it) carry its time; an ENG_Status frame, which the plant sends just
    before its DCT_Sensors (src/plant/core.rs, `emit_cycle`), carries the time of the cycle it
    opens."""
    sensors, eng = frame_id("DCT_Sensors"), frame_id("ENG_Status")
    out, k = [], -1
    for _, iface, fid, ext, data in records:
        if fid == sensors and not ext:
            k += 1
        cyc = k + 1 if (fid == eng and not ext) else k
        out.append((max(cyc, 0) * CYCLE_S, iface, fid, ext, data))
    return out


def intervals_us(records, name: str) -> list[float]:
    ts = [t for t, _, fid, _, _ in records if fid == frame_id(name)]
    return [(b - a) * 1e6 for a, b in zip(ts, ts[1:])]


def launch_metrics(rows: list[dict], target_rpm=None) -> dict | None:
    """The first launch: lock-up time, engine flare, stall, lock-up acceleration spike."""
    launch = choice("TCU_Status", "TcuState", "Launch")
    k0 = next((k for k, r in enumerate(rows) if r.get("TCU_Status.TcuState") == launch), None)
    if k0 is None:
        return None
    t0 = rows[k0]["t"]
    pedal = rows[k0].get("DRV_Pedal.AccelPedal", float("nan"))
    lock = None
    for r in rows[k0:]:
        slip = r.get("ENG_Status.EngSpeed", 0) - r.get("DCT_Sensors.InShaft1Speed", 0)
        if abs(slip) < 5.0:
            lock = r["t"]
            break
    seg = [r for r in rows if t0 <= r["t"] <= (lock if lock is not None else t0 + 5.0)]
    eng = [r.get("ENG_Status.EngSpeed", 0.0) for r in seg]
    acc = lambda a, b: [r.get("BENCH_Vehicle.VehicleAccel", 0.0) for r in rows if a <= r["t"] < b]  # noqa: E731
    spike = None
    if lock is not None:
        pre = acc(lock - 0.1, lock)
        post = acc(lock, lock + 0.3)
        if pre and post:
            spike = max(post) - sum(pre) / len(pre)
    out = {
        "t_start_s": t0,
        "pedal_pct": pedal,
        "lockup_s": None if lock is None else lock - t0,
        "min_engine_rpm": min(eng) if eng else float("nan"),
        "max_engine_rpm": max(eng) if eng else float("nan"),
        "lockup_spike_mps2": spike,
    }
    if target_rpm is not None:
        out["flare_rpm"] = out["max_engine_rpm"] - target_rpm
    return out


def shift_metrics(rows: list[dict]) -> list[dict]:
    up, down = choice("TCU_Status", "TcuState", "Upshift"), choice("TCU_Status", "TcuState", "Downshift")
    drive = choice("TCU_Status", "TcuState", "Drive")
    shifts, k = [], 1
    while k < len(rows):
        st = rows[k].get("TCU_Status.TcuState")
        if st in (up, down) and rows[k - 1].get("TCU_Status.TcuState") != st:
            g_from = rows[k - 1].get("TCU_Status.GearActive")
            j = k
            while j < len(rows) and rows[j].get("TCU_Status.TcuState") == st:
                j += 1
            end = rows[min(j, len(rows) - 1)]
            accs = [r.get("BENCH_Vehicle.VehicleAccel", 0.0) for r in rows[k : j + 20]]
            shifts.append(
                {
                    "t_start_s": rows[k]["t"],
                    "up": st == up,
                    "from": g_from,
                    "to": end.get("TCU_Status.GearActive"),
                    "duration_s": end["t"] - rows[k]["t"],
                    "completed": end.get("TCU_Status.TcuState") == drive,
                    "min_accel_mps2": min(accs) if accs else float("nan"),
                }
            )
            k = j
        else:
            k += 1
    return shifts


def estimator_metrics(rows: list[dict]) -> dict:
    out = {}
    for i in (1, 2):
        err = [
            r[f"TCU_Estimates.Clutch{i}TempEst"] - r[f"SIM_Truth.Clutch{i}TempTrue"]
            for r in rows
            if f"TCU_Estimates.Clutch{i}TempEst" in r and f"SIM_Truth.Clutch{i}TempTrue" in r
        ]
        out[f"clutch{i}_rmse_c"] = math.sqrt(sum(e * e for e in err) / len(err)) if err else float("nan")
        out[f"clutch{i}_max_c"] = max((abs(e) for e in err), default=float("nan"))
    return out


def fault_events(rows: list[dict]) -> list[dict]:
    """Changes of (TcuState, FaultCode) with names."""
    out, prev = [], None
    for r in rows:
        key = (r.get("TCU_Status.TcuState"), r.get("TCU_Status.FaultCode"))
        if key != prev:
            out.append(
                {
                    "t": r["t"],
                    "state": label("TCU_Status", "TcuState", key[0] or 0),
                    "fault": label("TCU_Status", "FaultCode", key[1] or 0),
                }
            )
            prev = key
    return out


def fault_timing(records, message: str, expected: str, fault_from_s: float, t_plant0: float) -> dict:
    """Detection and recovery of a fault injected on `message` from `fault_from_s` of plant time
    (t_plant0: the plant's first frame): the first TCU_Status carrying the `expected` fault code
    after the injection started is the detection; it is measured from the last valid frame of
    the message before it (CRC and counter sequence checked here); recovery is from the first
    valid frame after the detection to the first TCU_Status in normal operation (not SafeState or
    Init, no fault code)."""
    fid = frame_id(message)
    status_id = frame_id("TCU_Status")
    safe = choice("TCU_Status", "TcuState", "SafeState")
    init = choice("TCU_Status", "TcuState", "Init")
    code = choice("TCU_Status", "FaultCode", expected)
    start = t_plant0 + fault_from_s - 0.05
    status = []
    for t, _, i, _, data in records:
        if i == status_id:
            s = ddct_can.decode(i, data)
            status.append((t, s["TcuState"], s["FaultCode"]))
    detected = next((t for t, _, f in status if t >= start and f == code), None)
    # Valid: CRC right and the counter moved on. After a gap the counter may jump (frames were
    # lost), which still counts as back.
    valid, prev = [], None
    for t, _, i, _, data in records:
        if i != fid or ddct_can.check(i, data) != ddct_can.OK:
            continue
        c = ddct_can.counter_of(i, data)
        if c != prev:
            valid.append(t)
        prev = c
    last_valid = first_back = safe_t = recovered = None
    if detected is not None:
        last_valid = max((t for t in valid if t < detected), default=None)
        first_back = min((t for t in valid if t > detected), default=None)
        safe_t = next((t for t, st, _ in status if t >= detected and st == safe), None)
    if first_back is not None:
        recovered = next(
            (t for t, st, f in status if t >= first_back and f == 0 and st not in (safe, init)),
            None,
        )
    ms = lambda a, b: None if a is None or b is None else (a - b) * 1e3  # noqa: E731
    return {
        "message": message,
        "fault": expected if detected is not None else None,
        "detection_ms": ms(detected, last_valid),
        "safe_state_after_detection_ms": ms(safe_t, detected),
        "recovery_ms": ms(recovered, first_back),
    }


def analyse(records, tcu_cfg_target=None, lockstep: bool = False) -> dict:
    """The metrics of a recorded run: behaviour on the run's time axis (bus time in lockstep),
    latency and interval over vcan in wall time (the kernel timestamps)."""
    rows = rows_of(bus_time(records) if lockstep else records)
    lat = latency_us(records, "DCT_Sensors", "TCU_ClutchCmd")
    iv = intervals_us(records, "TCU_ClutchCmd")
    jit = [abs(x - CYCLE_S * 1e6) for x in iv]
    return {
        "rows": len(rows),
        "launch": launch_metrics(rows, tcu_cfg_target),
        "shifts": shift_metrics(rows),
        "estimator": estimator_metrics(rows),
        "events": fault_events(rows),
        "latency_us": {"n": len(lat), "p50": pct(lat, 0.5), "p99": pct(lat, 0.99), "max": pct(lat, 1.0)},
        "clutch_cmd_jitter_us": {"n": len(jit), "p50": pct(jit, 0.5), "p99": pct(jit, 0.99), "max": pct(jit, 1.0)},
    }


def target_rpm(pedal: float) -> float:
    """The launch target n(p) of config/tcu.toml."""
    import tomllib

    cfg = tomllib.loads((REPO / "config" / "tcu.toml").read_text())
    lo, hi = cfg["launch"]["engine_rpm_0"], cfg["launch"]["engine_rpm_100"]
    return lo + (hi - lo) * pedal / 100.0


# ---------------------------------------------------------------------------------------------
# Running


@dataclass
class Run:
    log: Path
    records: list
    tcu_report: dict | None
    plant_stderr: str
    tcu_stderr: str
    driver_frames: int
    plant_start_wall: float
    plant_report: dict | None = None
    lockstep: bool = False
    # Time from the TCU's SIGTERM to its exit, measured by the harness (ms).
    tcu_stop_ms: float | None = None
    # `ddct log record`'s summary (frames per id, frames the kernel dropped from its queue).
    recorder_stderr: str = ""

    def recorder_drops(self) -> int | None:
        """Frames the kernel dropped from the recorder's receive queue (None: not reported)."""
        m = re.search(r"dropped by the kernel \(receive queue full\): (\d+)", self.recorder_stderr)
        return int(m.group(1)) if m else None


def wait_ready(proc, ready: Path, what: str, timeout: float = 60.0) -> None:
    """Waits until a daemon started with `--ready-file ready` listens (it writes the file once its
    socket is open and its signal handlers installed); fails naming the daemon if it exits first
    or takes longer than `timeout` s. A fixed sleep is not enough: under load a daemon's start
    took longer than 0.3 s, so the lockstep plant's first cycle went out before the TCU listened."""
    end = time.monotonic() + timeout
    while not ready.exists():
        if proc.poll() is not None:
            err = proc.stderr.read() if proc.stderr else ""
            raise RuntimeError(f"{what} exited with {proc.returncode} before it listened: {err}")
        if time.monotonic() > end:
            raise RuntimeError(f"{what} did not listen within {timeout} s")
        time.sleep(0.01)


# A real-time plant runs this much longer than the program, and the driver this much longer again.
PLANT_TAIL_S = 0.5
DRIVER_OVERRUN_S = 0.2


def run_bench(
    iface: str = "vcan0",
    program: str = "launch",
    pedal: float = 50.0,
    seconds: float = 6.0,
    out: Path = REPO / "out" / "hil",
    ddct: Path = REPO / "target" / "release" / "ddct",
    faults: Path | None = None,
    daemons: bool = True,
    name: str = "launch",
    lockstep: bool = False,
    spoof: tuple[float, float] | None = None,
    tcu_args: list | None = None,
) -> Run:
    import can

    out.mkdir(parents=True, exist_ok=True)
    log = out / f"{name}.log"
    if log.exists():
        log.unlink()
    # In lockstep the run takes as long as the host lets it: the recorder stops with the rest.
    rec_ready = out / f"{name}_record.ready"
    rec_ready.unlink(missing_ok=True)
    rec_cmd = [str(ddct), "log", "record", "--iface", iface, "--out", str(log), "--ready-file", str(rec_ready)]
    if not lockstep:
        rec_cmd += ["--duration", str(seconds + 3.0)]
    rec = subprocess.Popen(
        rec_cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    bench = bus = None
    rec_err = ""
    try:
        wait_ready(rec, rec_ready, "the recorder")
        if lockstep:
            # The driver listens before the plant's first cycle (it answers every one).
            bus = can.Bus(
                interface="socketcan",
                channel=iface,
                receive_own_messages=False,
                can_filters=[{"can_id": frame_id("DCT_Sensors"), "can_mask": 0x7FF, "extended": False}],
            )
        if daemons:
            # The TCU first, the plant once the TCU listens (ddct_can.Bench; reports, stderr and
            # ready files in `out` as NAME_tcu.json, NAME_plant.json, ...).
            plant_args = []
            if lockstep:
                # The TCU's last frame of a computation (TCU_Estimates) and the driver's answer.
                plant_args += ["--duration", str(seconds), "--lockstep", "TCU_Estimates,DRV_Pedal",
                               "--lockstep-timeout", "20"]
            else:
                plant_args += ["--duration", str(seconds + PLANT_TAIL_S)]
            if faults is not None:
                plant_args += ["--faults", str(faults)]
            bench = Bench(iface, ddct=ddct, tcu_config=REPO / "config" / "tcu.toml",
                          tcu_args=(["--clock", "bus"] if lockstep else []) + list(tcu_args or []),
                          plant_args=plant_args,
                          workdir=out, cwd=REPO, keep=True, prefix=f"{name}_")
            bench.start()
        plant_start = time.time()
        try:
            if lockstep:
                n = play_driver_lockstep(bus, bench.plant.proc if bench else None, program, pedal, seconds, spoof)
            else:
                # The driver only sends: a kernel filter no frame matches (a remote frame of
                # DRV_Pedal) spares the guest delivering every frame of a flood to its socket.
                from can.interfaces.socketcan.constants import CAN_RTR_FLAG, MAX_11_BIT_ID

                quiet = [{"can_id": frame_id("DRV_Pedal") | CAN_RTR_FLAG,
                          "can_mask": MAX_11_BIT_ID | CAN_RTR_FLAG, "extended": False}]
                bus = can.Bus(interface="socketcan", channel=iface, receive_own_messages=False,
                              can_filters=quiet)
                # Until the plant has stopped (it started first): a driver that stopped before it
                # would leave the plant a DRV_Pedal timeout at the end of every run, and a run
                # with one is not judged on timing (test_hil.starved).
                n = play_driver(bus, program, pedal, seconds + PLANT_TAIL_S + DRIVER_OVERRUN_S)
        finally:
            if bus is not None:
                bus.shutdown()
        if bench is not None:
            # The plant stops at its --duration; then both are stopped and their exit checked.
            bench.wait_plant(timeout=600 if lockstep else 30)
            bench.stop()
        rec.send_signal(signal.SIGTERM)
        _, rec_err = rec.communicate(timeout=30)
    finally:
        if bench is not None and bench.tcu is not None:
            for d in (bench.plant, bench.tcu):
                if d is not None and d.proc.poll() is None:
                    d.proc.kill()
                    d.proc.wait()
        if rec.poll() is None:
            rec.kill()
            rec.wait()
    records = ddct_can.read_candump(log)
    if bench is None:
        return Run(log, records, None, "", "", n, plant_start, None, lockstep, recorder_stderr=rec_err)
    stop_s = bench.tcu.stop_s
    return Run(log, records, bench.tcu_report, bench.plant.stderr(), bench.tcu.stderr(), n, plant_start,
               bench.plant_report, lockstep, None if stop_s is None else stop_s * 1e3, rec_err)


def fmt(v, p=2):
    if v is None:
        return "-"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.{p}f}"
    return str(v)


def print_table(a: dict, run: Run):
    axis = "bus time (lockstep)" if run.lockstep else "wall time"
    print(f"log: {run.log} ({len(run.records)} frames, {a['rows']} TCU cycles, {run.driver_frames} driver frames; {axis})")
    la = a["launch"]
    print("\nlaunch:")
    if la is None:
        print("  no launch seen")
    else:
        for k in ("pedal_pct", "lockup_s", "min_engine_rpm", "max_engine_rpm", "flare_rpm", "lockup_spike_mps2"):
            if k in la:
                print(f"  {k:<22} {fmt(la[k])}")
    if a["shifts"]:
        print("\nshifts:")
        print(f"  {'t_s':>7} {'shift':>6} {'dur_s':>6} {'min_acc':>8} completed")
        for s in a["shifts"]:
            print(f"  {s['t_start_s']:7.2f} {s['from']}->{s['to']:<3} {s['duration_s']:6.2f} {s['min_accel_mps2']:8.2f} {s['completed']}")
    e = a["estimator"]
    print(f"\nestimator vs SIM_Truth: RMSE {fmt(e['clutch1_rmse_c'])} / {fmt(e['clutch2_rmse_c'])} °C, max {fmt(e['clutch1_max_c'])} / {fmt(e['clutch2_max_c'])} °C")
    print("\nTCU state / fault code changes:")
    for ev in a["events"]:
        print(f"  {ev['t']:7.3f} s  {ev['state']:<10} {ev['fault']}")
    la, jt = a["latency_us"], a["clutch_cmd_jitter_us"]
    print(f"\nDCT_Sensors -> TCU_ClutchCmd latency: n {la['n']} p50 {fmt(la['p50'],0)} us p99 {fmt(la['p99'],0)} us max {fmt(la['max'],0)} us")
    print(f"TCU_ClutchCmd |interval - 10 ms|:     n {jt['n']} p50 {fmt(jt['p50'],0)} us p99 {fmt(jt['p99'],0)} us max {fmt(jt['max'],0)} us")
    if run.tcu_report:
        r = run.tcu_report
        print(f"TCU daemon: {r['computations']} computations, overruns {r['overruns']}, deadline misses {r['deadline_misses']}, safe-state entries {r['safe_entries']}")
        if "stalls" in r:
            print(
                f"TCU daemon stalls (not counted against senders): {r['stalls']}, total {r['stall_total_s']:.3f} s, "
                f"longest {r['stall_longest_s']:.3f} s; timer lateness p99 {fmt(r['timer_lateness_p99_us'], 0)} us "
                f"max {fmt(r['timer_lateness_max_us'], 0)} us; coalesced syncs {r['syncs_coalesced']}"
            )
    if run.plant_report and run.plant_report.get("lockstep"):
        p = run.plant_report
        print(
            f"plant lockstep on {p['lockstep']}: {p['cycles']} cycles ({p['sim_time_s']:.2f} s simulated in "
            f"{p['wall_time_s']:.2f} s wall), {p['lockstep_timeouts']} without their answers in time"
            + (f" (first at {p['lockstep_first_timeout_s']:.2f} s, missing {','.join(p['lockstep_first_missing'])})"
               if p.get("lockstep_first_timeout_s") is not None else "")
        )


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--iface", default="vcan0")
    ap.add_argument("--program", choices=["launch", "shifts"], default="launch")
    ap.add_argument("--pedal", type=float, default=50.0, help="accelerator pedal after the launch (%%)")
    ap.add_argument("--seconds", type=float, default=None, help="length of the driver program (s)")
    ap.add_argument("--out", type=Path, default=REPO / "out" / "hil")
    ap.add_argument("--ddct", type=Path, default=REPO / "target" / "release" / "ddct")
    ap.add_argument("--faults", type=Path, default=None, help="plant fault-injection file ([[faults]])")
    ap.add_argument("--no-daemons", action="store_true", help="the plant and TCU daemons are already running")
    ap.add_argument("--lockstep", action="store_true", help="run in bus time (plant lockstep, TCU --clock bus)")
    ap.add_argument("--json", action="store_true", help="print the metrics as JSON")
    a = ap.parse_args(argv)
    seconds = a.seconds or (6.0 if a.program == "launch" else 16.0)
    if a.lockstep and a.no_daemons:
        ap.error("--lockstep starts the daemons itself (the plant must wait for this driver)")
    run = run_bench(
        a.iface, a.program, a.pedal, seconds, a.out, a.ddct, a.faults, not a.no_daemons, a.program, lockstep=a.lockstep
    )
    if not run.records:
        print(f"nothing recorded on {a.iface}\n{run.plant_stderr}\n{run.tcu_stderr}", file=sys.stderr)
        return 1
    result = analyse(run.records, target_rpm(a.pedal), lockstep=a.lockstep)
    if a.json:
        print(json.dumps(result, indent=2, default=str))
    else:
        print_table(result, run)
    return 0


if __name__ == "__main__":
    sys.exit(main())
