"""Floods and stops against the daemons on their own clocks over vcan0 (issue 12): the TCU keeps its
10 ms cycle, a flood on an input it needs ends in the safe state with that input's code and not
in silence, it recovers when the flood ends, sends only valid, in-range frames and stops on SIGTERM.

Each run: a launch at 40 % pedal in real time (scripts/launch.py), and from FLOOD_FROM_S for
FLOOD_S seconds cangen on the same bus, asked for 3 500 frames/s (its sleeps in the guest run late:
it reaches about 2 000–2 800):

- ``bad_crc``: random payloads on one input id (a wrong CRC but for 1 frame in 256);
- ``frozen``: a genuine frame of the input, captured from the bus, repeated (valid CRC, a frozen
  alive counter: a second stream of that id);
- ``all_ids``: random ids and payloads (the TCU must not care, beyond keeping its cycle).

Timing in User-Mode Linux has a noisy tail (the guest has one CPU the host shares), so the
TCU_ClutchCmd gaps on the bus during the flood, the detection time and the exit time are always
printed. Asserted when the guest ran (the TCU's own report: stalls under 10 % of the run, and no
DRV_Pedal timeout at the plant, as in test_hil.py), the flood reached 2 000 frames/s and the TCU
was not stalled during it (its exit report's stall_log):
TCU_ClutchCmd at most 30 ms apart on the bus (the recorder's kernel timestamps) from the flood's
first frame to its last, detection within 80 ms of the flood's first frame (the exact 3-cycle
contract is asserted in bus time, in-process and by test_hil.py), no other fault code, and exit
within 100 ms of SIGTERM. What must hold under any load is asserted always: the safe state with the
right code during a flood on a needed input, recovery after it, every TCU frame with a valid CRC
and inside the DBC's ranges (a NaN cannot be encoded: it would show there), exit status 0 with a
report.
"""

from __future__ import annotations

import os
import subprocess
import threading
import time

import can
import launch as hil
import pytest

from test_hil import CYCLE_MS, MAX_STALL_SHARE, starved

FLOOD_FROM_S = 3.5  # after run_bench starts (the plant starts about 0.6 s later): mid-launch
FLOOD_S = 1.0
RUN_S = 7.0
RATE_HZ = 3500.0
# The rate a judged run must reach (issue 12: a flood of at least 2 k frames/s).
JUDGED_RATE_HZ = 2000.0
# Measured from the flood's first frame to the first TCU_Status carrying the code.
DETECT_MS = 8 * CYCLE_MS
MAX_GAP_MS = 3 * CYCLE_MS
# The TCU's inputs and the code of each one's timeout: config/tcu.toml inputs.timeout_cycles (3)
# cycles without a valid frame.
INPUT_TIMEOUT_MS = 3 * CYCLE_MS
INPUT_TIMEOUT_CODES = {"ENG_Status": "EngStatusTimeout", "DCT_Sensors": "SensorsTimeout",
                       "DCT_Actuators": "ActuatorsTimeout", "DRV_Pedal": "PedalTimeout"}
EXIT_MS = 100.0
# The TCU runs as a bench runs it under load: at nice -10 (more of the one guest CPU under the
# normal scheduler; a negative nice needs root, as the guest is). `DDCT_FLOOD_TCU_ARGS` replaces
# the arguments (empty: normal priority).
TCU_ARGS = os.environ.get(
    "DDCT_FLOOD_TCU_ARGS", "--nice -10" if hasattr(os, "geteuid") and os.geteuid() == 0 else ""
).split()


class Flood(threading.Thread):
    """cangen (can-utils) from ``start_at`` (time.time()) sending ``rate_hz`` frames/s for
    ``seconds``: bursts of BURST frames every BURST/rate seconds, ENOBUFS ignored (a full queue
    drops). ``can_id``: the id in hex, or ``r`` for random ids; ``data``: ``r`` for random payloads
    (a bad CRC but for 1 in 256) or a fixed payload in hex. A C sender, not python: a python loop
    in the single-CPU guest reached 590–1 200 frames/s only."""

    BURST = 5

    def __init__(self, iface: str, can_id: str, data: str, rate_hz: float, start_at: float, seconds: float):
        super().__init__(daemon=True)
        self.iface, self.can_id, self.data = iface, can_id, data
        self.rate_hz, self.start_at, self.seconds = rate_hz, start_at, seconds
        self.count = int(rate_hz * seconds)
        self.t_first = self.t_last = None
        self.error: str | None = None

    def cmd(self) -> list:
        gap_ms = 1e3 * self.BURST / self.rate_hz
        return ["cangen", self.iface, "-g", f"{gap_ms:.3f}", "-c", str(self.BURST), "-n", str(self.count),
                "-I", self.can_id, "-L", "8", "-D", self.data, "-i"]

    def prepare(self) -> None:
        """Called just before the flood starts (a subclass captures its payload here)."""

    def run(self) -> None:
        try:
            self.prepare()
            time.sleep(max(0.0, self.start_at - time.time()))
            self.t_first = time.time()
            proc = subprocess.run(self.cmd(), capture_output=True, text=True, timeout=60)
            self.t_last = time.time()
            if proc.returncode != 0:
                self.error = f"{' '.join(self.cmd())} exited {proc.returncode}: {proc.stderr.strip()}"
        except Exception as e:  # noqa: BLE001 - reported by the test
            self.error = repr(e)

    def is_flood_frame(self, fid: int, data: bytes) -> bool:
        """Whether a recorded frame is one of this flood's (random ids: any id; else the id with a
        payload the genuine sender never sends: a wrong CRC)."""
        if self.can_id == "r":
            return True
        return fid == int(self.can_id, 16) and hil.ddct_can.e2e.e2e_crc(fid, data) != data[-1]

    def window(self, records) -> tuple:
        """(first, last, count) of the flood's frames in the recording (kernel timestamps; the
        sender's own clock includes cangen's start-up, 0.1–0.3 s in a loaded guest). Random ids:
        every frame in the flood's time span."""
        lo, hi = (self.t_first or 0.0), (self.t_last or 0.0) + 0.05
        ts = [t for t, _, fid, _, d in records if lo <= t <= hi and self.is_flood_frame(fid, bytes(d))]
        if self.can_id == "r":
            return (self.t_first, self.t_last, self.count)
        return (ts[0], ts[-1], len(ts)) if ts else (None, None, 0)


def capture(iface: str, fid: int, timeout: float) -> bytes:
    """One genuine frame of ``fid`` from the bus."""
    filt = [{"can_id": fid, "can_mask": 0x7FF, "extended": False}]
    with can.Bus(interface="socketcan", channel=iface, can_filters=filt) as bus:
        msg = bus.recv(timeout)
    if msg is None:
        raise AssertionError(f"no {hil.ddct_can.message(fid).name} frame on the bus within {timeout} s")
    return bytes(msg.data)


class FrozenFlood(Flood):
    """A genuine frame of ``fid`` (valid CRC), captured just before the flood, repeated: a second
    stream of the id with a frozen alive counter."""

    def __init__(self, iface: str, fid: int, rate_hz: float, start_at: float, seconds: float):
        super().__init__(iface, f"{fid:X}", "", rate_hz, start_at, seconds)
        self.fid = fid

    def prepare(self) -> None:
        time.sleep(max(0.0, self.start_at - 0.3 - time.time()))
        self.payload = capture(self.iface, self.fid, 5.0)
        self.data = self.payload.hex().upper()

    def is_flood_frame(self, fid: int, data: bytes) -> bool:
        return fid == self.fid and data == self.payload

    def window(self, records) -> tuple:
        """As Flood.window, but the genuine sender sends this very payload again every 16 of its
        frames (a 4-bit counter, a constant pedal or speed), so a copy of it before cangen's first
        frame is not the flood's start: the flood starts at the first of two copies less than a
        cycle apart."""
        first, last, n = super().window(records)
        if first is None:
            return first, last, n
        lo, hi = first, last + 0.05
        ts = [t for t, _, fid, _, d in records if lo <= t <= hi and self.is_flood_frame(fid, bytes(d))]
        start = next((a for a, b in zip(ts, ts[1:]) if b - a < CYCLE_MS / 2e3), None)
        if start is None:
            return (None, None, 0)
        flood = [t for t in ts if t >= start]
        return (flood[0], flood[-1], len(flood))


# (flood, input id, the code it must raise, other codes it may raise in the safe state). A
# bad-CRC flood is the input's CRC fault; the 1 in 256 random payloads whose CRC happens to be
# right are a second stream of the id (SecondSender), and the few of them whose alive counter
# also fits pass E2E altogether: only the plausibility checks can refuse their values (a random
# engine speed, a random gear that no longer matches the shaft speeds, a random lever or
# temperature), so the input's plausibility codes are right too. A frozen copy of a genuine frame
# is a second sender, or the input's counter fault.
ALL_IMPLAUSIBLE = {"ImplausibleSpeed", "ImplausibleTemp", "ImplausiblePosition", "ImplausibleGear",
                   "ImplausibleLever"}
CASES = [
    ("bad_crc", "ENG_Status", "EngStatusCrc", {"SecondSender", "ImplausibleSpeed"}),
    ("bad_crc", "DRV_Pedal", "PedalCrc", {"SecondSender", "ImplausiblePosition", "ImplausibleLever"}),
    ("bad_crc", "DCT_Sensors", "SensorsCrc", {"SecondSender", "ImplausibleSpeed", "ImplausibleTemp"}),
    ("bad_crc", "DCT_Actuators", "ActuatorsCrc",
     {"SecondSender", "ImplausiblePosition", "ImplausibleGear", "ImplausibleSpeed"}),
    ("frozen", "ENG_Status", "SecondSender", {"EngStatusCounter"}),
    ("frozen", "DRV_Pedal", "SecondSender", {"PedalCounter"}),
    # Random ids: a frame on an input id with a valid CRC now and then (any plausibility code).
    ("all_ids", None, None, ALL_IMPLAUSIBLE),
]
# A flood at all (any load) / at the rate asked (when the guest ran).
MIN_RATE_HZ = 500.0


def clutch_cmd_gaps_ms(records, t_first: float, t_last: float, name: str = "TCU_ClutchCmd") -> list:
    """Gaps (ms) between consecutive ``name`` (TCU_ClutchCmd) frames with a valid CRC on the bus
    (the recorder's kernel timestamps) from the flood's first frame to its last, the frames just
    before and after it included."""
    cmd = hil.frame_id(name)
    e2e = hil.ddct_can.e2e
    ts = [t for t, _, fid, _, d in records if fid == cmd and e2e.e2e_crc(fid, bytes(d)) == d[-1]]
    before = [t for t in ts if t < t_first][-1:]
    after = [t for t in ts if t > t_last][:1]
    inside = before + [t for t in ts if t_first <= t <= t_last] + after
    return [(b - a) * 1e3 for a, b in zip(inside, inside[1:])]


def tcu_frames_recorded(records) -> int:
    """The TCU's frames in the recording (all five messages; the random-id flood may add some)."""
    ids = {hil.frame_id(name) for name in hil.TCU_MESSAGES}
    return sum(1 for _, _, fid, _, _ in records if fid in ids)


def stalls_between(report: dict, t_first: float, t_last: float) -> list:
    """Lengths (s) of the TCU's stalls (its timer woke more than 5 ms late: the host did not run
    it) that overlap the flood, from its exit report's stall_log (wall-clock time each was
    noticed, length)."""
    return [length for at, length in report.get("stall_log", []) if at >= t_first and at - length <= t_last]


def percentile(values: list, q: float) -> float:
    """The q-quantile (nearest rank) of values; NaN when empty."""
    if not values:
        return float("nan")
    s = sorted(values)
    return s[min(len(s) - 1, int(q * len(s)))]


def status_rows(records):
    """TCU_Status frames with a valid CRC (the random-id flood sends that id too)."""
    status = hil.frame_id("TCU_Status")
    msg = hil.ddct_can.message(status)
    e2e = hil.ddct_can.e2e
    return [(t, msg.decode(bytes(d), decode_choices=False)) for t, _, fid, _, d in records
            if fid == status and e2e.e2e_crc(fid, bytes(d)) == d[-1]]


@pytest.mark.parametrize("kind,message,code,others", CASES, ids=[f"{k}-{m or 'random'}" for k, m, _, _ in CASES])
def test_a_flood_keeps_the_cycle_and_ends_in_the_safe_state(ddct, out_dir, kind, message, code, others):
    codes = {code} | others if code else set()
    start_at = time.time() + FLOOD_FROM_S
    if kind == "frozen":
        flood = FrozenFlood("vcan0", hil.frame_id(message), RATE_HZ, start_at, FLOOD_S)
    else:
        ident = f"{hil.frame_id(message):X}" if kind == "bad_crc" else "r"
        flood = Flood("vcan0", ident, "r", RATE_HZ, start_at, FLOOD_S)
    flood.start()
    run = hil.run_bench(program="launch", pedal=40.0, seconds=RUN_S, out=out_dir, ddct=ddct,
                        name=f"flood_{kind}_{message or 'all'}", tcu_args=TCU_ARGS)
    flood.join(timeout=30)
    assert flood.error is None, f"the flood sender failed: {flood.error!r}"
    r, p = run.tcu_report, run.plant_report
    assert r is not None, run.tcu_stderr
    assert p is not None, run.plant_stderr
    rows = status_rows(run.records)
    choices = hil.ddct_can.message("TCU_Status").get_signal_by_name("FaultCode").choices
    code_by_value = {int(k): str(v) for k, v in choices.items()}
    t_first, t_last, n_flood = flood.window(run.records)
    assert n_flood > 0, "no flood frame in the recording"
    rate = n_flood / max(1e-9, t_last - t_first)
    during = [(t, code_by_value.get(int(v["FaultCode"]), "?"), int(v["TcuState"])) for t, v in rows
              if t_first <= t <= t_last + 0.05]
    safe = hil.choice("TCU_Status", "TcuState", "SafeState")
    flagged = [t for t, c, st in during if codes and c in codes and st == safe]
    detect_ms = (flagged[0] - t_first) * 1e3 if flagged else None
    after = [(t, code_by_value.get(int(v["FaultCode"]), "?"), int(v["TcuState"])) for t, v in rows if t > t_last]
    normal_after = [t for t, c, st in after if c == "None" and st != safe]
    recover_ms = (normal_after[0] - t_last) * 1e3 if normal_after else None
    print(f"\n== flood {kind} on {message or 'random ids'}: {n_flood} frames recorded in "
          f"{t_last - t_first:.2f} s ({rate:.0f}/s); codes during it {sorted({c for _, c, _ in during})}; detected after {detect_ms} ms; "
          f"normal again {recover_ms} ms after it")
    cmd_gap_ms = clutch_cmd_gaps_ms(run.records, t_first, t_last)
    print(f"TCU_ClutchCmd on the bus during the flood: {len(cmd_gap_ms) + 1} frames, gap p99 "
          f"{percentile(cmd_gap_ms, 0.99):.1f} ms, max {max(cmd_gap_ms, default=float('nan')):.1f} ms")
    print(f"TCU frames every p99 {r.get('send_gap_p99_us')} us, max {r.get('send_gap_max_us')} us; "
          f"computations {r['computations']}, stalls {r['stall_total_s']:.3f} s of {r['wall_time_s']:.2f} s, "
          f"received {r['frames_received']}, send errors {r['send_errors']}; recorder: {len(run.records)} frames, "
          f"{run.recorder_drops()} dropped by the kernel; TCU frames sent {r['frames_sent']}, recorded "
          f"{tcu_frames_recorded(run.records)}; SIGTERM to exit {run.tcu_stop_ms} ms")
    # Over the window whose TCU states are judged (`during`: the flood and 50 ms after it).
    input_gaps = {m: max(clutch_cmd_gaps_ms(run.records, t_first, t_last + 0.05, m), default=float("nan"))
                  for m in INPUT_TIMEOUT_CODES}
    print("inputs on the bus during the flood, max gap: "
          + ", ".join(f"{m} {g:.1f} ms" for m, g in input_gaps.items())
          + f"; plant lateness max {p.get('lateness_max_us')} us, deadline misses {p.get('deadline_misses')}, "
            f"send errors {p.get('send_errors')}")
    # Under any load.
    assert r["stopped_by"] == "shutdown" and r["computations"] > 0, r
    assert rate >= MIN_RATE_HZ, f"the flood reached {rate:.0f}/s only"
    # Every TCU frame with a valid CRC and inside the DBC's ranges (the random-id flood sends on
    # the TCU's ids too: its window is left out).
    records = run.records if kind != "all_ids" else [r for r in run.records if not t_first <= r[0] <= t_last + 0.05]
    assert hil.bad_tcu_frames(records) == [], hil.bad_tcu_frames(records)[:5]
    if codes:
        assert code in {c for _, c, _ in during}, f"no {code} during the flood: {sorted({c for _, c, _ in during})}"
        assert flagged, f"no safe state with {codes} during the flood: {sorted({c for _, c, _ in during})}"
        assert normal_after, f"the TCU did not recover after the flood: {after[-3:]}"
    why = starved(r, p)
    if not why and rate < JUDGED_RATE_HZ:
        why = f"the flood reached {rate:.0f} frames/s, not {JUDGED_RATE_HZ:.0f} (cangen in the guest)"
    if why:
        print(f"timing NOT JUDGED: {why}")
        return
    assert run.tcu_stop_ms is not None and run.tcu_stop_ms <= EXIT_MS, f"exit {run.tcu_stop_ms} ms after SIGTERM"
    # No other code: a starved guest also times out the plant's frames (not the flood's doing),
    # and an input whose valid frames really were a timeout apart on the bus (its sender, not the
    # TCU, held back) is rightly reported missing.
    missing = {INPUT_TIMEOUT_CODES[m] for m, g in input_gaps.items() if g >= INPUT_TIMEOUT_MS - 1.0}
    if missing:
        print(f"inputs missing on the bus for a timeout during the flood: {sorted(missing)}")
    others_seen = sorted({c for _, c, _ in during if c not in codes | others | missing | {"None"}})
    assert others_seen == [], f"the flood raised {others_seen} too"
    held = stalls_between(r, t_first, t_last)
    if held:
        print(f"detection and frame gap not judged: the host held the TCU back during the flood "
              f"(stalls of {', '.join(f'{s * 1e3:.0f} ms' for s in held)})")
        return
    if codes:
        assert detect_ms <= DETECT_MS, f"detected {detect_ms:.1f} ms after the flood's first frame"
    # The TCU keeps its cycle on the bus through the flood (issue 12: at most 30 ms apart).
    assert cmd_gap_ms and max(cmd_gap_ms) <= MAX_GAP_MS, \
        f"TCU_ClutchCmd frames {max(cmd_gap_ms, default=float('nan')):.1f} ms apart on the bus during the flood"
