#!/usr/bin/env python3
"""scripts/fleet_perf.py [--units U --logs K --out DIR] [--no-all-cores-loop]: the throughput of `ddct-fleet diagnose`
on this machine against sequential loops in the same run, on a fleet from `ddct-fleet generate`:

  loop, 1 thread     one `ddct gap diagnose --threads 1` after the other (the like-for-like
                     baseline: the cluster runs single-threaded diagnoses)
  loop, all cores    one `ddct gap diagnose` after the other, each on every core
  LocalCluster       ddct-fleet's default: one single-threaded worker process per core

and the workers' memory (RSS after each finished task) over the campaign, whether the loop and the
cluster found the same, and the fleet report's figures (recovery of the truths). Figures go to
stdout and DIR/fleet_perf.json; docs/fleet.md quotes them.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "python"))

from ddct_can.fleet import campaign  # noqa: E402
from ddct_can.fleet.generate import generate  # noqa: E402
from ddct_can.fleet.report import load_findings  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--units", type=int, default=4)
    ap.add_argument("--logs", type=int, default=3)
    ap.add_argument("--bootstrap", type=int, default=400)
    ap.add_argument("--out", type=Path, default=REPO / "out" / "fleet_perf")
    ap.add_argument("--no-all-cores-loop", action="store_true",
                    help="skip the loop of diagnoses on every core (the 1-thread loop is the baseline)")
    a = ap.parse_args()
    ddct = str(REPO / "target" / "release" / "ddct")
    fleet = a.out / "fleet"
    if not (fleet / "manifest.csv").exists():
        t0 = time.monotonic()
        generate(ddct, fleet, a.units, a.logs, jobs=os.cpu_count() or 1)
        print(f"generated {a.units * a.logs} logs in {time.monotonic() - t0:.0f} s", file=sys.stderr)
    tasks = campaign.discover(fleet, "perf")
    quiet = lambda *args: None  # noqa: E731
    rows = {}

    def timed(name, fn):
        out = a.out / name.replace(" ", "_").replace(",", "")
        shutil.rmtree(out, ignore_errors=True)
        t0 = time.monotonic()
        fn(out)
        wall = time.monotonic() - t0
        rows[name] = {"wall_s": round(wall, 2), "logs_per_min": round(60 * len(tasks) / wall, 2)}
        print(f"{name:<20} {wall:8.1f} s  {60 * len(tasks) / wall:6.2f} logs/min", file=sys.stderr)

    timed("loop, 1 thread", lambda out: campaign.run_sequential(tasks, ddct, out, a.bootstrap, 1, progress=quiet))
    if not a.no_all_cores_loop:
        timed("loop, all cores", lambda out: campaign.run_sequential(tasks, ddct, out, a.bootstrap, 0, progress=quiet))
    rss = []

    def cluster_run(out):
        import psutil
        from distributed import Client, LocalCluster

        with LocalCluster(n_workers=os.cpu_count() or 1, threads_per_worker=1, processes=True,
                          dashboard_address=None) as cluster, Client(cluster) as client:
            def sample(done, total, task, result):
                mib = client.run(lambda: psutil.Process().memory_info().rss / 2**20)
                rss.append((done, max(mib.values())))
            campaign.run_campaign(tasks, ddct, out, a.bootstrap, 1, client, progress=sample)

    timed("LocalCluster", cluster_run)
    base = rows["loop, 1 thread"]["wall_s"]
    for r in rows.values():
        r["speedup_vs_loop_1_thread"] = round(base / r["wall_s"], 2)
    q = max(1, len(rss) // 4)
    from ddct_can.fleet.report import render

    def findings(name):
        rows_ = load_findings(a.out / name)
        return sorted((r["unit"], r["log"], r["kind"], r["class"] or "", r["magnitude"] or 0.0, r["error"] or "")
                      for r in rows_)

    _, figures = render(a.out / "LocalCluster", fleet / "truth.csv")
    summary = {
        "logs": len(tasks), "cores": os.cpu_count(), "bootstrap": a.bootstrap, "runs": rows,
        "worker_rss_mib_first_quarter": round(max(m for _, m in rss[:q]), 1),
        "worker_rss_mib_last_quarter": round(max(m for _, m in rss[-q:]), 1),
        "cost_per_log_core_s": round(base / len(tasks), 2),
        "identical_findings_loop_and_cluster": findings("loop_1_thread") == findings("LocalCluster"),
        "report": figures,
    }
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "fleet_perf.json").write_text(json.dumps(summary, indent=2))
    print(json.dumps(summary, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
