#!/usr/bin/env python3
"""The paper's identification experiment (Sect. 3.3) on a CAN bus: partial clutch engagements.

A test rig holds the transmission input at a set speed with a dyno and brakes the output; this
script plays the rig controller. It commands the throwout-bearing position of the clutches in
TCU_ClutchCmd following a rig profile file (config/rig/identification.toml, validation.toml): a
number of partial engagements of one clutch, all with the same periodic x_to signal -- the clutch
heats up, its kiss point moves and the torque of the same x_to grows (the paper's Fig. 6) -- then
a cooling phase with both clutches open. It records every frame on the bus into a candump -l log
(through `candump -L`) and prints, per engagement, the peak clutch torque (BENCH_Torque) and the
central-disk temperature (BENCH_Temps), and the paper's Fig. 6 check: the first engagement whose
central disk exceeds 200 C against the first engagement.

The plant must run in rig mode on the same interface with the profile's dyno speed
(`ddct plant --iface vcan0 --mode rig --config config/plant_rig.toml --input-speed RPM`), started
after this script listens; with --spawn-plant DDCT the script starts it itself, with the right
arguments, once its own socket and candump listen. Everything about the frames comes from
dbc/ddct.dbc through the ddct_can package (python/, cantools): no CAN id, scale or offset here.

Timing. The plant sends its frames every 10 ms of simulated time and reads its inputs at the
start of each cycle. The script counts the plant's ENG_Status frames (a kernel filter gives it
only those) to know the simulated time: on ENG_Status of cycle n it sends the command for cycle
n+1, the profile sampled at (n+1)*10 ms -- exactly what the plant's built-in profile
(`ddct plant --rig-profile FILE`) applies at that cycle. With --spawn-plant the plant runs in
lockstep (`--lockstep`): it waits for each answer before simulating the next cycle, never faster
than --speed, so the experiment gives the same frames over the bus as in process however loaded
the machine is (--free-running: the plant keeps its own deadlines; a late answer then acts a
cycle or more later, and a controller that fell behind answers only the newest cycle).

Log timestamps are on the simulated time axis (--timestamps sim, default): a frame after the
plant's n-th ENG_Status at start + n*10 ms + 10 us per frame within the cycle; --timestamps wall
records start + K*(wall time - start) instead. The profile files are evaluated with the same
rules as the Rust plant (src/plant/profile.rs): x_to is linear between the points of one period,
held outside them, both clutches are open before the first and after the last engagement.

Usage (a 385 s experiment at --speed 8 takes about a minute in User-Mode Linux):
    scripts/vcan-run .venv/bin/python scripts/rig_partial_engagements.py --iface vcan0 \
        --profile config/rig/identification.toml --out rig.log --speed 8 \
        --spawn-plant target/release/ddct
"""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import subprocess
import sys
import time
import tomllib
from bisect import bisect_right
from pathlib import Path

import can
import ddct_can

REPO = Path(__file__).resolve().parent.parent


class Table:
    """Piecewise-linear table, held outside its points (same rules as src/plant/profile.rs)."""

    def __init__(self, t, v):
        if not t or len(t) != len(v):
            raise ValueError("a table needs as many values as times, at least one")
        if any(b < a for a, b in zip(t, t[1:])):
            raise ValueError("times must not decrease")
        self.t = [float(x) for x in t]
        self.v = [float(x) for x in v]

    def linear(self, x: float) -> float:
        j = bisect_right(self.t, x)
        if j == 0:
            return self.v[0]
        if j == len(self.t):
            return self.v[-1]
        i = j - 1
        f = (x - self.t[i]) / (self.t[j] - self.t[i])
        return self.v[i] + f * (self.v[j] - self.v[i])


class RigProfile:
    """A rig profile file (config/rig/*.toml)."""

    def __init__(self, path):
        with open(path, "rb") as f:
            doc = tomllib.load(f)
        self.path = Path(path)
        self.description = doc.get("description", "")
        self.input_speed_rpm = float(doc.get("input_speed_rpm", 2000.0))
        self.start_s = float(doc.get("start_s", 0.0))
        eng = doc["engagement"]
        self.clutch = int(eng.get("clutch", 1))
        if self.clutch not in (1, 2):
            raise ValueError(f"{path}: engagement.clutch must be 1 or 2")
        self.count = int(eng["count"])
        self.period_s = float(eng["period_s"])
        self.x_to = Table(eng["t_s"], eng["x_mm"])
        self.cooling_s = float(doc.get("cooling", {}).get("duration_s", 0.0))

    @property
    def duration_s(self) -> float:
        return self.start_s + self.count * self.period_s + self.cooling_s

    def engagement_at(self, t: float):
        if t < self.start_s:
            return None
        k = math.floor((t - self.start_s) / self.period_s)
        return k if k < self.count else None

    def x_ref(self, t: float) -> tuple[float, float]:
        x = [0.0, 0.0]
        k = self.engagement_at(t)
        if k is not None:
            tau = t - self.start_s - k * self.period_s
            x[self.clutch - 1] = self.x_to.linear(tau)
        return x[0], x[1]


def analyse(log_path, profile: RigProfile) -> list[dict]:
    """Per engagement of a recorded log: peak torque of the driven clutch (N·m) and the central
    disk temperature at its start and its maximum (°C), on the cycle count of ENG_Status frames
    (cycle n is at n*10 ms of simulated time; independent of the log's timestamps)."""
    db = ddct_can.load_dbc()
    eng = db.get_message_by_name("ENG_Status").frame_id
    torque = db.get_message_by_name("BENCH_Torque")
    temps = db.get_message_by_name("BENCH_Temps")
    signal_name = f"Clutch{profile.clutch}Torque"
    cycle_s = db.get_message_by_name("ENG_Status").cycle_time / 1000.0
    rows: dict[int, dict] = {}
    n = -1
    for _t, _iface, fid, _ext, data in ddct_can.read_candump(log_path):
        if fid == eng:
            n += 1
            continue
        if n < 0:
            continue
        k = profile.engagement_at(n * cycle_s)
        if k is None:
            continue
        row = rows.setdefault(k, {"engagement": k, "peak_torque_nm": 0.0, "cd_start_c": None, "cd_max_c": -1e9})
        if fid == torque.frame_id:
            v = torque.decode(data, decode_choices=False)[signal_name]
            row["peak_torque_nm"] = max(row["peak_torque_nm"], v)
        elif fid == temps.frame_id:
            v = temps.decode(data, decode_choices=False)["CentralDiskTemp"]
            if row["cd_start_c"] is None:
                row["cd_start_c"] = v
            row["cd_max_c"] = max(row["cd_max_c"], v)
    return [rows[k] for k in sorted(rows)]


def fig6_check(rows: list[dict], threshold_c: float = 200.0) -> dict:
    """The paper's Fig. 6 in numbers: the first engagement whose central disk exceeds
    `threshold_c` and the ratio of its peak torque to the first engagement's."""
    if not rows:
        return {"first_hot": None, "ratio": None}
    first = rows[0]
    hot = next((r for r in rows if r["cd_max_c"] > threshold_c), None)
    ratio = hot["peak_torque_nm"] / first["peak_torque_nm"] if hot and first["peak_torque_nm"] > 0 else None
    return {
        "first_peak_nm": first["peak_torque_nm"],
        "first_hot": hot["engagement"] if hot else None,
        "hot_peak_nm": hot["peak_torque_nm"] if hot else None,
        "hot_cd_max_c": hot["cd_max_c"] if hot else None,
        "ratio": ratio,
    }


def spawn_plant(ddct: str, iface: str, config: str, speed: float, duration: float, input_rpm: float,
                lockstep: bool, plant_log, extra):
    args = [
        ddct, "plant", "--iface", iface, "--config", config, "--mode", "rig",
        "--speed", repr(speed), "--duration", repr(duration), "--input-speed", repr(input_rpm),
    ]
    if lockstep:
        args += ["--lockstep", "TCU_ClutchCmd"]
    if plant_log:
        args += ["--log", str(plant_log)]
    args += list(extra)
    return subprocess.Popen(args, stdin=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def start_candump(iface: str, raw_path: Path):
    """`candump -L` into raw_path; returns once its socket is registered (so no frame is missed)."""
    before = ddct_can.can_receivers(iface)
    f = open(raw_path, "w", encoding="ascii")
    p = subprocess.Popen(["candump", "-L", "-r", str(64 << 20), iface], stdout=f,
                         stdin=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    f.close()
    deadline = time.monotonic() + 10.0
    while True:
        if p.poll() is not None:
            raise RuntimeError(f"candump exited ({p.returncode}): {p.stderr.read()}")
        now = ddct_can.can_receivers(iface)
        if now is None:
            time.sleep(0.5)
            break
        if len(now - before) >= 1:
            break
        if time.monotonic() > deadline:
            raise RuntimeError(f"candump did not start listening on {iface}")
        time.sleep(0.02)
    return p


def wait_quiet(path: Path, quiet_s: float = 1.0, limit_s: float = 60.0) -> None:
    """Waits until `path` has not grown for `quiet_s` seconds (at most `limit_s`)."""
    deadline = time.monotonic() + limit_s
    size, since = -1, time.monotonic()
    while time.monotonic() < deadline:
        try:
            now = path.stat().st_size
        except OSError:
            return
        if now != size:
            size, since = now, time.monotonic()
        elif time.monotonic() - since >= quiet_s:
            return
        time.sleep(0.1)


def stop(p, sig=signal.SIGINT, timeout=20.0) -> str:
    if p is None:
        return ""
    if p.poll() is None:
        p.send_signal(sig)
    try:
        _, err = p.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        p.kill()
        _, err = p.communicate()
    return err or ""


def retime(raw_path: Path, out_path: Path, eng_id: int, cycle_s: float, mode: str, speed: float) -> tuple[int, int]:
    """Writes the recorded frames on the simulated time axis: frames from the plant's first
    ENG_Status on; in mode "sim" a frame after the n-th ENG_Status is stamped
    start + n*cycle + j*10 us (j: its index after that ENG_Status); in mode "wall" start +
    speed*(t - start). Returns (frames written, cycles)."""
    n = -1
    j = 0
    base = None
    written = 0
    with open(raw_path, encoding="ascii") as src, open(out_path, "w", encoding="ascii") as dst:
        for line in src:
            if not line.strip():
                continue
            t, iface, fid, ext, data = ddct_can.parse_candump_line(line)
            if fid == eng_id and not ext:
                n += 1
                j = 0
                if base is None:
                    base = t
            elif n < 0:
                continue
            else:
                j += 1
            ts = base + n * cycle_s + j * 1e-5 if mode == "sim" else base + speed * (t - base)
            dst.write(ddct_can.candump_line(ts, iface, fid, data, ext) + "\n")
            written += 1
    return written, n + 1


def run(args) -> int:
    db = ddct_can.load_dbc()
    eng_msg = db.get_message_by_name("ENG_Status")
    cmd_msg = db.get_message_by_name("TCU_ClutchCmd")
    cycle_s = eng_msg.cycle_time / 1000.0
    profile = RigProfile(args.profile)
    duration = args.duration if args.duration else profile.duration_s
    cycles = int(round(duration / cycle_s))
    speed = args.speed
    out = Path(args.out)
    raw = out.with_name(out.name + ".raw")
    # The pacing socket sees only ENG_Status (a kernel filter keeps python's load low at high
    # --speed); candump records everything.
    bus = can.interface.Bus(channel=args.iface, interface="socketcan",
                            can_filters=[{"can_id": eng_msg.frame_id, "can_mask": 0x7FF, "extended": False}])
    recorder = plant = None
    n = -1
    counter = 0
    cache: dict = {}
    skipped = 0
    checked_speed = False
    status = 0
    t_wall0 = time.time()
    try:
        recorder = None if args.recorder == "none" else start_candump(args.iface, raw)
        if args.spawn_plant:
            plant = spawn_plant(args.spawn_plant, args.iface, args.plant_config, speed,
                                duration + 2.0, profile.input_speed_rpm, not args.free_running,
                                args.plant_log, args.plant_arg)
        deadline = time.monotonic() + args.start_timeout
        while n + 1 < cycles:
            timeout = 2.0 if n >= 0 else max(0.05, deadline - time.monotonic())
            msg = bus.recv(timeout=timeout)
            if msg is None:
                if plant is not None and plant.poll() is not None:
                    raise RuntimeError(f"the plant exited ({plant.returncode}): {plant.stderr.read()}")
                if n < 0 and time.monotonic() < deadline:
                    continue
                raise RuntimeError(
                    "no ENG_Status from the plant" + (" yet" if n < 0 else f" after cycle {n}")
                    + f" on {args.iface}: is `ddct plant --mode rig` running?")
            if msg.arbitration_id != eng_msg.frame_id or msg.is_error_frame or msg.is_remote_frame:
                continue
            n += 1
            # A controller that fell behind answers only the newest cycle (no queue of stale
            # answers): count the ENG_Status frames already waiting and skip to the last.
            while n + 1 < cycles:
                more = bus.recv(timeout=0.0)
                if more is None:
                    break
                if more.arbitration_id == eng_msg.frame_id and not more.is_error_frame:
                    n += 1
                    skipped += 1
                    msg = more
            if not checked_speed:
                checked_speed = True
                rpm = eng_msg.decode(bytes(msg.data), decode_choices=False)["EngSpeed"]
                if abs(rpm - profile.input_speed_rpm) > 20.0:
                    raise RuntimeError(
                        f"the plant's input turns at {rpm} rpm, the profile wants {profile.input_speed_rpm} rpm: "
                        f"start it with --input-speed {profile.input_speed_rpm}")
            # Answer cycle n with the command for cycle n+1.
            x1, x2 = profile.x_ref((n + 1) * cycle_s)
            # The profile is periodic: cache the encoded frames (value pair and counter).
            key = (round(x1, 6), round(x2, 6), counter % 16)
            payload = cache.get(key)
            if payload is None:
                payload = ddct_can.encode(cmd_msg.name, {"Clutch1PosReq": x1, "Clutch2PosReq": x2}, counter=counter)
                cache[key] = payload
            counter += 1
            bus.send(can.Message(arbitration_id=cmd_msg.frame_id, data=payload, is_extended_id=False))
        if plant is not None and not args.free_running:
            # In lockstep the plant simulates its next cycle only once it has the last answer, so
            # its next ENG_Status says the answer arrived (and is in its --log); stopped sooner,
            # the plant could be cut off before reading it (seen once in CI).
            end = time.monotonic() + 5.0
            while time.monotonic() < end:
                more = bus.recv(timeout=0.5)
                if more is not None and more.arbitration_id == eng_msg.frame_id and not more.is_error_frame:
                    break
    except KeyboardInterrupt:
        status = 130
    except RuntimeError as e:
        print(f"rig_partial_engagements: {e}", file=sys.stderr)
        status = 1
    finally:
        bus.shutdown()
        plant_err = stop(plant)
        if recorder is not None:
            wait_quiet(raw, quiet_s=5.0)  # candump may still be reading what the plant sent last
        rec_err = stop(recorder)
        if plant_err and not args.quiet:
            sys.stderr.write(plant_err)
        if rec_err.strip() and not args.quiet:
            sys.stderr.write(f"candump: {rec_err}")
    wall = time.time() - t_wall0
    if recorder is None:
        raw.write_text("")
    frames, logged_cycles = retime(raw, out, eng_msg.frame_id, cycle_s, args.timestamps, speed)
    if not args.keep_raw:
        raw.unlink(missing_ok=True)
    if status:
        return status
    rows = analyse(out, profile)
    check = fig6_check(rows)
    summary = {
        "profile": str(profile.path),
        "cycles": logged_cycles,
        "simulated_s": logged_cycles * cycle_s,
        "frames_logged": frames,
        "commands_sent": counter,
        "cycles_not_answered": skipped,
        "log": str(out),
        "engagements": rows,
        "fig6": check,
        "wall_s": wall,
    }
    if not args.quiet:
        print(f"{profile.description or profile.path}")
        print(f"{logged_cycles} cycles ({logged_cycles * cycle_s:.1f} s simulated, {wall:.1f} s wall), "
              f"{frames} frames -> {out}")
        print(f"{'eng':>4} {'peak torque Nm':>15} {'cd start C':>11} {'cd max C':>9}")
        for r in rows:
            print(f"{r['engagement']:>4} {r['peak_torque_nm']:>15.1f} {r['cd_start_c']:>11.1f} {r['cd_max_c']:>9.1f}")
        if check.get("first_hot") is not None:
            print(f"first engagement with the central disk above 200 C: {check['first_hot']} "
                  f"(peak {check['hot_peak_nm']:.1f} Nm = {check['ratio']:.2f} x the first, {check['first_peak_nm']:.1f} Nm)")
        else:
            print("the central disk never exceeded 200 C")
    if args.summary_json:
        Path(args.summary_json).write_text(json.dumps(summary, indent=1))
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--iface", default="vcan0", help="CAN interface (default vcan0)")
    ap.add_argument("--profile", default=str(REPO / "config/rig/identification.toml"),
                    help="rig profile file (default config/rig/identification.toml)")
    ap.add_argument("--out", required=True, help="candump -l log to write")
    ap.add_argument("--speed", type=float, default=1.0,
                    help="the plant's --speed (simulated time per wall time); with --spawn-plant it is passed on")
    ap.add_argument("--duration", type=float, default=None,
                    help="simulated seconds to run (default: the profile's duration)")
    ap.add_argument("--spawn-plant", metavar="DDCT", default=None,
                    help="start `DDCT plant --mode rig` on the interface (after this script listens)")
    ap.add_argument("--free-running", action="store_true",
                    help="--spawn-plant: let the plant run on its own deadlines (default: --lockstep, the "
                         "plant waits for each answer, so the run does not depend on the host's load)")
    ap.add_argument("--plant-config", default=str(REPO / "config/plant_rig.toml"),
                    help="plant config for --spawn-plant (default config/plant_rig.toml)")
    ap.add_argument("--plant-log", default=None, help="--spawn-plant: the plant's own candump tap")
    ap.add_argument("--plant-arg", action="append", default=[],
                    help="extra argument for the spawned plant (repeatable, e.g. --plant-arg=--effects=FILE)")
    ap.add_argument("--timestamps", choices=("sim", "wall"), default="sim",
                    help="log time axis: simulated cycles (default) or scaled wall time")
    ap.add_argument("--start-timeout", type=float, default=30.0,
                    help="seconds to wait for the plant's first ENG_Status (default 30)")
    ap.add_argument("--summary-json", default=None, help="write the per-engagement summary as JSON")
    ap.add_argument("--recorder", choices=("candump", "none"), default="candump",
                    help="record with candump -L (default) or not at all (for the plant's --log)")
    ap.add_argument("--keep-raw", action="store_true", help="keep candump's raw log (OUT.raw, wall-clock time)")
    ap.add_argument("--quiet", action="store_true")
    args = ap.parse_args(argv)
    if not (args.speed > 0 and math.isfinite(args.speed)):
        ap.error("--speed must be a positive number")
    return run(args)


if __name__ == "__main__":
    sys.exit(main())
