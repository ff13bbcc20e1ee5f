"""`ddct-fleet`: fleet campaigns of ddct on Dask distributed (see docs/fleet.md).

    ddct-fleet diagnose DIR_OR_MANIFEST --out FINDINGS_DIR [--scheduler tcp://HOST:8786]
    ddct-fleet generate --out DIR [--units 20 --logs 10 --minutes 10]
    ddct-fleet report FINDINGS_DIR --out report.html [--truth DIR/truth.csv]
    ddct-fleet blind --trials 10000 --out DIR [--chunk 20] [--seed 1] [--scheduler tcp://HOST:8786]

Without `--scheduler`, `diagnose` starts a LocalCluster on this machine (one single-threaded
worker process per core); with one, it runs unchanged on that cluster (the workers need the ddct
binary at the same path, or `--ddct`, and the logs and FINDINGS_DIR on a shared file system).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

from . import campaign


def _ddct_binary(given: str | None) -> str:
    if given:
        return str(Path(given).resolve())
    env = os.environ.get("DDCT_BIN")
    if env:
        return str(Path(env).resolve())
    repo = Path(__file__).resolve().parents[3] / "target" / "release" / "ddct"
    if repo.is_file():
        return str(repo)
    found = shutil.which("ddct")
    if found:
        return found
    raise SystemExit("ddct-fleet: no ddct binary (build it with `cargo build --release`, or give --ddct / DDCT_BIN)")


def _version(ddct: str) -> str:
    return subprocess.run([ddct, "--version"], capture_output=True, text=True).stdout.strip()


def _client(scheduler: str | None, workers: int | None):
    from distributed import Client, LocalCluster

    if scheduler:
        return Client(scheduler), None
    cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                           processes=True, dashboard_address=None)
    return Client(cluster), cluster


def cmd_diagnose(a) -> int:
    ddct = _ddct_binary(a.ddct)
    salt = f"{_version(ddct)} bootstrap={a.bootstrap}"
    try:
        tasks = campaign.discover(Path(a.source), salt)
    except ValueError as e:
        raise SystemExit(f"ddct-fleet: {e}")
    if not tasks:
        raise SystemExit(f"ddct-fleet: no logs in {a.source}")
    from .storage import is_url

    out = a.out if is_url(a.out) else Path(a.out)
    if not is_url(a.out):
        out.mkdir(parents=True, exist_ok=True)
    t0 = time.monotonic()
    if a.sequential:
        results = campaign.run_sequential(tasks, ddct, out, a.bootstrap, a.threads)
        where = "a sequential loop"
    else:
        client, cluster = _client(a.scheduler, a.workers)
        try:
            where = f"Dask ({client.scheduler.address}, {len(client.scheduler_info()['workers'])} workers)"
            results = campaign.run_campaign(tasks, ddct, out, a.bootstrap, a.threads, client)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    wall = time.monotonic() - t0
    ran = [r for r in results if r["status"] != "done before"]
    errors = sum(r["status"] == "error" for r in results)
    summary = {
        "logs": len(tasks), "ran": len(ran), "skipped": len(results) - len(ran), "errors": errors,
        "wall_s": round(wall, 3), "logs_per_min": round(60 * len(ran) / wall, 2) if wall > 0 and ran else None,
        "on": where, "out": str(out),
    }
    if a.report:
        from .report import render

        source = Path(a.source)
        truth = (source if source.is_dir() else source.parent) / "truth.csv"
        page, figures = render(out, truth if truth.is_file() else None)
        Path(a.report).write_text(page, encoding="utf-8")
        summary["report"] = {"file": a.report, **figures}
    print(json.dumps(summary) if a.json else _diagnose_line(summary, wall, a.report))
    return 0


def _diagnose_line(summary: dict, wall: float, report: str | None) -> str:
    """The summary of `diagnose` for a person: a rate only when something ran (a rerun over
    logs all diagnosed before has none; its JSON `logs_per_min` is null)."""
    where, out = summary["on"], summary["out"]
    rate = summary["logs_per_min"]
    if summary["ran"]:
        line = (f"{summary['ran']} diagnosed ({summary['skipped']} done before, {summary['errors']} error rows) "
                f"in {wall:.1f} s on {where}" + (f": {rate} logs/min" if rate is not None else "")
                + f"; findings in {out}")
    else:
        line = (f"0 new logs diagnosed; {summary['skipped']} already done (nothing to run, {wall:.1f} s on "
                f"{where}); findings in {out}")
    return line + (f"; report {report}" if report else "")


def cmd_generate(a) -> int:
    from .generate import generate

    ddct = _ddct_binary(a.ddct)
    t0 = time.monotonic()
    rows = generate(ddct, Path(a.out), a.units, a.logs, a.hours_per_log, a.seed, a.jobs or os.cpu_count() or 1)
    print(f"wrote {len(rows)} logs of {a.units} units into {a.out} in {time.monotonic() - t0:.0f} s "
          f"(manifest.csv, truth.csv)")
    return 0


def cmd_report(a) -> int:
    from .report import render

    page, figures = render(Path(a.findings), Path(a.truth) if a.truth else None)
    Path(a.out).write_text(page, encoding="utf-8")
    print(json.dumps(figures) if a.json else f"wrote {a.out}: {figures}")
    return 0


def cmd_blind(a) -> int:
    from . import blind

    ddct = _ddct_binary(a.ddct)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    try:
        cs = blind.chunks(a.trials, a.chunk)
    except ValueError as e:
        raise SystemExit(f"ddct-fleet: {e}")
    t0 = time.monotonic()
    if a.sequential:
        results = blind.run(cs, ddct, a.seed, out, a.threads)
        where = "a sequential loop"
    else:
        client, cluster = _client(a.scheduler, a.workers)
        try:
            where = f"Dask ({client.scheduler.address}, {len(client.scheduler_info()['workers'])} workers)"
            results = blind.run(cs, ddct, a.seed, out, a.threads, client)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    wall = time.monotonic() - t0
    failed = [r for r in results if r["status"] == "error"]
    for r in failed:
        print(f"ddct-fleet: chunk from trial {r['first']} failed: {r['error']}", file=sys.stderr)
    report = blind.merge(ddct, cs, out)
    s = report["summary"]
    ran = sum(c.trials for c in cs) - sum(c.trials for c in cs if any(
        r["first"] == c.first and r["status"] == "done before" for r in results))
    summary = {
        "trials": s["trials"], "ran": ran, "chunks": len(cs), "failed_chunks": len(failed),
        "wall_s": round(wall, 3), "trials_per_min": round(60 * ran / wall, 2) if wall > 0 and ran else None,
        "on": where, "out": str(out), "errors": s["errors"],
        "acceptance": [{k: c[k] for k in ("name", "value_pct", "n", "goal_pct", "met")} for c in s["acceptance"]],
    }
    if a.json:
        print(json.dumps(summary))
    else:
        print(f"{s['trials']} trials ({ran} run now, {len(failed)} chunk(s) failed) in {wall:.1f} s on {where}; "
              f"report in {out}/report.txt")
        for c in summary["acceptance"]:
            value = "–" if c["value_pct"] is None else f"{c['value_pct']:.1f} %"
            print(f"  {'met ' if c['met'] else 'NOT '} {c['name']}: {value} of {c['n']} (goal {c['goal_pct']:g} %)")
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="ddct-fleet", description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    d = sub.add_parser("diagnose", help="diagnose every log of a fleet; findings as a Parquet dataset")
    d.add_argument("source", help="a directory (one subdirectory per unit, or a manifest.csv) or a manifest CSV "
                                  "(columns unit, log, and optionally train, operating_hours)")
    d.add_argument("--out", required=True, help="the findings dataset: OUT/<unit>/<content key>.parquet")
    d.add_argument("--scheduler", help="address of a running Dask scheduler (default: a LocalCluster here)")
    d.add_argument("--workers", type=int, help="LocalCluster worker processes (default: the cores)")
    d.add_argument("--threads", type=int, default=1, help="threads of each ddct diagnosis (default 1; 0: every core)")
    d.add_argument("--bootstrap", type=int, default=400, help="bootstrap resamples per diagnosis")
    d.add_argument("--sequential", action="store_true", help="no Dask: one diagnosis after the other")
    d.add_argument("--ddct", help="the ddct binary (default: DDCT_BIN, target/release/ddct, PATH)")
    d.add_argument("--json", action="store_true", help="the summary as JSON")
    d.add_argument("--report", help="then write the fleet report (HTML) here; the truth.csv beside the "
                                    "logs, if any, is overlaid")
    d.set_defaults(run=cmd_diagnose)
    g = sub.add_parser("generate", help="a fleet of MF4 logs with evolving effects from ddct's truth generator")
    g.add_argument("--out", required=True, help="the fleet directory (manifest.csv, truth.csv, <unit>/<k>/*.mf4)")
    g.add_argument("--units", type=int, default=20, help="units (default 20)")
    g.add_argument("--logs", type=int, default=10, help="logs per unit (default 10)")
    g.add_argument("--hours-per-log", type=float, default=50.0, help="operating hours between two logs of a unit")
    g.add_argument("--seed", type=int, default=1, help="seed of the fleet (units, offsets, noise)")
    g.add_argument("--jobs", type=int, help="logs generated at once (default: the cores)")
    g.add_argument("--ddct", help="the ddct binary (default: DDCT_BIN, target/release/ddct, PATH)")
    g.set_defaults(run=cmd_generate)
    r = sub.add_parser("report", help="a self-contained HTML page of a findings dataset")
    r.add_argument("findings", help="the findings dataset of `ddct-fleet diagnose --out`")
    r.add_argument("--out", required=True, help="the HTML file to write")
    r.add_argument("--truth", help="the fleet's truth.csv (from `ddct-fleet generate`): overlaid and scored")
    r.add_argument("--json", action="store_true", help="the figures as JSON")
    r.set_defaults(run=cmd_report)
    b = sub.add_parser("blind", help="`ddct gap blind` trials in chunks on the cluster, summarised together")
    b.add_argument("--trials", type=int, required=True, help="trials of the seed, 0…TRIALS−1")
    b.add_argument("--chunk", type=int, default=20, help="trials per task (default 20)")
    b.add_argument("--seed", type=int, default=1, help="seed of the hidden truths (default 1)")
    b.add_argument("--out", required=True, help="directory: chunks/<first>/report.json, then the merged "
                                                "report.txt, report.json and detectability.svg")
    b.add_argument("--scheduler", help="address of a running Dask scheduler (default: a LocalCluster here)")
    b.add_argument("--workers", type=int, help="LocalCluster worker processes (default: the cores)")
    b.add_argument("--threads", type=int, default=1, help="threads of each chunk's ddct (default 1; 0: every core)")
    b.add_argument("--sequential", action="store_true", help="no Dask: one chunk after the other")
    b.add_argument("--ddct", help="the ddct binary (default: DDCT_BIN, target/release/ddct, PATH)")
    b.add_argument("--json", action="store_true", help="the summary as JSON")
    b.set_defaults(run=cmd_blind)
    a = p.parse_args(argv)
    return a.run(a)


if __name__ == "__main__":
    sys.exit(main())
