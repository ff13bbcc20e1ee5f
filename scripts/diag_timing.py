#!/usr/bin/env python
"""Does diagnostic traffic disturb control? The TCU daemon's cycle timing (its exit report)
with a UDS tester polling a DID every 10 ms and an XCP DAQ list running, next to the same run
without them, alternating (quiet, busy, quiet, busy, ...) so that a drift of the host shows in
both. Needs vcan0: run it through scripts/vcan-run.

    scripts/vcan-run .venv/bin/python scripts/diag_timing.py --seconds 20 --pairs 2

Prints a table (median over the pairs of each figure, and busy / quiet) and writes the runs as
JSON with --out.

"computation" is the daemon's own clock around one TCU cycle: from the start of the computation
(the daemon woken by a DCT_Sensors frame) through reading the frames waiting on its socket, the
step and the sends of its control frames (the diagnostic side is served after that and is not
in it). Its median is the typical cycle's cost, p99 and max its tail.

Progress goes to stderr: at the start what is measured and about how long it takes, then per
run its JSON record and a line with its duration, its main figures and the time left (from the
mean duration of the runs of its kind done so far). stdout is the table only.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests" / "diag"))
sys.path.insert(0, str(REPO / "tests" / "python"))

from diag_helpers import DID, bench, uds_client  # noqa: E402
from progress_text import duration  # noqa: E402  (scripts/ is on sys.path: the script's own folder)

# Seconds a run takes beyond --seconds, in User-Mode Linux on the 2-core build machine alone:
# quiet, the bench's start and stop, 1 s settling and 2 s more (23-24 s for 20 s); busy, the XCP
# master's start besides (python importing pyxcp and parsing the A2L in the guest: the master ran
# 57-106 s for 20 s of DAQ). The first estimate, before a run of the kind is done.
PRIOR_OVERHEAD_S = {False: 4.0, True: 70.0}
# Seconds the XCP master may take beyond --seconds before the run fails (its start alone took
# up to 85 s in User-Mode Linux, the tester polling meanwhile; + 60 s timed out).
MASTER_START_S = 300

FIGURES = ["compute_p50_us", "compute_p99_us", "compute_max_us", "send_gap_p99_us", "send_gap_max_us",
           "overruns", "deadline_misses", "stalls", "computations"]


def poll_dids(stop: threading.Event, counts: dict) -> None:
    with uds_client() as c:
        next_t = time.monotonic()
        while not stop.is_set():
            c.read_data_by_identifier(DID["Clutch1TempEst"])
            counts["requests"] += 1
            next_t += 0.010
            time.sleep(max(0.0, next_t - time.monotonic()))


def one_run(ddct: Path, busy: bool, seconds: float, work: Path, tcu_args: list) -> dict:
    a2l = work / "tcu.a2l"
    if not a2l.exists():
        subprocess.run([str(ddct), "diag", "a2l", "--out", str(a2l)], check=True)
    counts = {"requests": 0, "daq_samples": 0, "master_s": 0.0}
    with bench(ddct, work / ("busy" if busy else "quiet"), tcu_args=tcu_args) as (b, _driver):
        time.sleep(1.0)
        if busy:
            stop = threading.Event()
            poller = threading.Thread(target=poll_dids, args=(stop, counts))
            poller.start()
            out = work / "daq.json"
            t0 = time.monotonic()
            try:  # the tester stops with the master, also when the master fails
                subprocess.run([sys.executable, str(REPO / "tests" / "diag" / "xcp_master.py"), "--a2l",
                                str(a2l), "--seconds", str(seconds), "--out", str(out), "--measure",
                                "Clutch1TempEst", "Clutch2TempEst", "Clutch1TorqueRef", "Clutch2TorqueRef",
                                "EngineSpeed"], check=True, timeout=seconds + MASTER_START_S,
                               stdout=sys.stderr)  # its log (pya2l, pyxcp): stdout is the table
            finally:
                stop.set()
                poller.join()
            counts["master_s"] = round(time.monotonic() - t0, 1)
            counts["daq_samples"] = len(json.loads(out.read_text())["samples"])
        else:
            time.sleep(seconds + 2.0)
    report = b.tcu_report
    return {"busy": busy, **{k: report.get(k) for k in FIGURES}, **counts}


def progress(line: str) -> None:
    print(f"diag_timing: {line}", file=sys.stderr, flush=True)


def us(v) -> str:
    return "-" if v is None else f"{v:.0f} µs"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--pairs", type=int, default=2)
    ap.add_argument("--ddct", type=Path, default=REPO / "target" / "release" / "ddct")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--rt-priority", type=int, default=50 if os.geteuid() == 0 else 0,
                    help="the TCU daemon's SCHED_FIFO priority (default 50 as root, as scripts/bench "
                         "runs it; 0: normal scheduling, where the python clients compete with it "
                         "for the CPU)")
    args = ap.parse_args()
    tcu_args = ["--rt-priority", str(args.rt_priority)] if args.rt_priority else []
    runs = []
    took = {False: [], True: []}  # seconds of each run done, quiet and busy

    def expected(busy: bool) -> float:
        return statistics.mean(took[busy]) if took[busy] else args.seconds + PRIOR_OVERHEAD_S[busy]

    total = 2 * args.pairs
    progress(f"the TCU daemon's cycle timing (its exit report: computation p50/p99/max, period of its "
             f"frames, overruns, deadline misses, stalls) without and with a UDS tester polling a DID "
             f"every 10 ms + an XCP DAQ list of 5 signals; {args.pairs} pairs of {args.seconds:g} s runs "
             f"(quiet, busy, ...), the TCU at "
             f"{'SCHED_FIFO ' + str(args.rt_priority) if args.rt_priority else 'normal priority'}; about "
             f"{duration(args.pairs * (expected(False) + expected(True)))} in all")
    with tempfile.TemporaryDirectory(prefix="ddct-diag-timing-") as tmp:
        for pair in range(args.pairs):
            for busy in (False, True):
                t0 = time.monotonic()
                runs.append(one_run(args.ddct, busy, args.seconds, Path(tmp), tcu_args))
                took[busy].append(time.monotonic() - t0)
                print(json.dumps(runs[-1]), file=sys.stderr)
                r = runs[-1]
                done = len(runs)
                left = sum(expected(b) for b in [k % 2 == 1 for k in range(done, total)])
                line = (f"[{done}/{total}] pair {pair + 1}/{args.pairs} {'busy ' if busy else 'quiet'} in "
                        f"{took[busy][-1]:.0f} s: computation p50 {us(r['compute_p50_us'])} p99 "
                        f"{us(r['compute_p99_us'])} max {us(r['compute_max_us'])}, {r['overruns']} overruns, "
                        f"{r['stalls']} stalls")
                if busy:
                    q = runs[-2]
                    line += (f"; {r['requests']} UDS requests, {r['daq_samples']} DAQ samples, the XCP master "
                             f"{r['master_s']:.0f} s ({args.seconds:g} s of DAQ)")
                    if q["compute_p50_us"] and r["compute_p50_us"] is not None:
                        line += f"; p50 busy / quiet {r['compute_p50_us'] / q['compute_p50_us']:.2f}"
                progress(line + ("; " + (f"about {duration(left)} left" if left else "done")))
    print(f"TCU at {'SCHED_FIFO ' + str(args.rt_priority) if args.rt_priority else 'normal priority'}, "
          f"{args.pairs} pairs of {args.seconds:.0f} s runs\n")
    print(f"| figure | quiet | with tester (DID every 10 ms) + DAQ | busy / quiet |\n|---|---|---|---|")
    for r in runs:  # counts per 1 000 computations: the runs differ in length
        for k in ("overruns", "deadline_misses", "stalls"):
            r[k + "_per_1000"] = 1000.0 * r[k] / max(r["computations"], 1)
    for k in FIGURES + ["overruns_per_1000", "deadline_misses_per_1000", "stalls_per_1000"]:
        q = [r[k] for r in runs if not r["busy"] and r.get(k) is not None]
        b = [r[k] for r in runs if r["busy"] and r.get(k) is not None]
        if not q or not b:
            continue
        mq, mb = statistics.median(q), statistics.median(b)
        ratio = f"{mb / mq:.2f}" if mq else "-"
        print(f"| {k} | {mq:.1f} | {mb:.1f} | {ratio} |")
    busy = [r for r in runs if r["busy"]]
    # The tester polls for the XCP master's whole life (its start in the guest is most of it), the
    # DAQ list runs for --seconds of it.
    print(f"\nper busy run: {statistics.median(r['requests'] for r in busy):.0f} UDS requests in "
          f"{statistics.median(r['master_s'] for r in busy):.0f} s (the XCP master's run), "
          f"{statistics.median(r['daq_samples'] for r in busy):.0f} DAQ samples in {args.seconds:.0f} s")
    if args.out:
        args.out.write_text(json.dumps(runs, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
