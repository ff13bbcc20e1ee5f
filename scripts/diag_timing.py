#!/usr/bin/env python
"""Does diagnostic traffic disturb control? The TCU daemon's cycle timing (its exit report)
with a UDS tester polling a DID every 10 ms and an XCP DAQ list running, next to the same run
without them, alternating (quiet, busy, quiet, busy, ...) so that a drift of the host shows in
both. Needs vcan0: run it through scripts/vcan-run.

    scripts/vcan-run .venv/bin/python scripts/diag_timing.py --seconds 20 --pairs 2

Prints a table (median over the pairs of each figure, and busy / quiet) and writes the runs as
JSON with --out.
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
    counts = {"requests": 0, "daq_samples": 0}
    with bench(ddct, work / ("busy" if busy else "quiet"), tcu_args=tcu_args) as (b, _driver):
        time.sleep(1.0)
        if busy:
            stop = threading.Event()
            poller = threading.Thread(target=poll_dids, args=(stop, counts))
            poller.start()
            out = work / "daq.json"
            subprocess.run([sys.executable, str(REPO / "tests" / "diag" / "xcp_master.py"), "--a2l", str(a2l),
                            "--seconds", str(seconds), "--out", str(out), "--measure", "Clutch1TempEst",
                            "Clutch2TempEst", "Clutch1TorqueRef", "Clutch2TorqueRef", "EngineSpeed"],
                           check=True, timeout=seconds + 60)
            counts["daq_samples"] = len(json.loads(out.read_text())["samples"])
            stop.set()
            poller.join()
        else:
            time.sleep(seconds + 2.0)
    report = b.tcu_report
    return {"busy": busy, **{k: report.get(k) for k in FIGURES}, **counts}


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
    with tempfile.TemporaryDirectory(prefix="ddct-diag-timing-") as tmp:
        for _ in range(args.pairs):
            for busy in (False, True):
                runs.append(one_run(args.ddct, busy, args.seconds, Path(tmp), tcu_args))
                print(json.dumps(runs[-1]), file=sys.stderr)
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
    print(f"\nper busy run: {statistics.median(r['requests'] for r in busy):.0f} UDS requests, "
          f"{statistics.median(r['daq_samples'] for r in busy):.0f} DAQ samples in {args.seconds:.0f} s")
    if args.out:
        args.out.write_text(json.dumps(runs, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
