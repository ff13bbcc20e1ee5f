"""Every speed comparison of ddct against its peer, side by side in one run (issue 14).

  scripts/perf [--short] [--out DIR]

Rows (each the median of the runs; CPU time beside wall time because a shared host's load moves
wall time, not CPU time):
  sim       `ddct sim` of launch_shift_20s, drive_60s (and soak_600s unless --short) against
            real time; peak memory of each run (the 600 s run against the 20 s one)
  decode    `ddct log decode --format csv` against `cantools decode` on the same candump log
            (400 k frames, 20 k with --short) of the rig plant, both written to /dev/null
  model     `cargo bench --bench model`: torque (13), its inverse, the plant derivative and the
            vectorised torque (clutch_batch::torque_batch) against the numpy peer in
            benches/model_peer.py; fails when the peer or the batch disagrees with ddct
  diagnose  `ddct gap diagnose` of a 30-minute rig log with a 30-minute validation log (seed 7),
            median of 3 runs; with --short the identification (7 min) and validation profiles,
            one run; no peer
  blind     `ddct gap blind` of 10 trials (2 with --short), seed 1: wall time per trial

--short (what CI runs) makes one run of each with small inputs and asserts nothing about time:
it checks that every comparison still runs and that its outputs agree. The table goes to stdout,
the figures to DIR/perf.json (default out/perf).
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DDCT = os.environ.get("DDCT_BIN", str(ROOT / "target/release/ddct"))
PY = sys.executable


def run(cmd, stdin=None, json_out=False):
    """Runs `cmd`; returns (wall s, CPU s, peak RSS MiB or None) of that child alone. CPU time
    from wait4 (RUSAGE_CHILDREN would mix every run); peak memory from the child's own JSON
    report (`peak_rss_mib`) when it gives one: ru_maxrss would include this Python process's
    memory, which the forked child carries across exec."""
    t0 = time.perf_counter()
    p = subprocess.Popen(cmd, stdin=stdin, stdout=subprocess.PIPE if json_out else subprocess.DEVNULL,
                         stderr=subprocess.PIPE, cwd=ROOT)
    out = p.stdout.read() if json_out else b""
    err = p.stderr.read().decode(errors="replace")
    _, status, ru = os.wait4(p.pid, 0)
    wall = time.perf_counter() - t0
    for f in (p.stdout, p.stderr):
        if f:
            f.close()
    if os.waitstatus_to_exitcode(status) != 0:
        sys.exit(f"perf: {' '.join(map(str, cmd))} failed:\n{err}")
    rss = None
    if json_out:
        rss = max((s.get("peak_rss_mib") or 0.0) for s in json.loads(out)) or None
    return wall, ru.ru_utime + ru.ru_stime, rss


def median_runs(n, cmd, stdin_path=None, json_out=False):
    res = []
    for _ in range(n):
        if stdin_path:
            with open(stdin_path, "rb") as f:
                res.append(run(cmd, stdin=f))
        else:
            res.append(run(cmd, json_out=json_out))
    med = [statistics.median(r[i] for r in res) for i in range(2)]
    rss = [r[2] for r in res if r[2] is not None]
    return med[0], med[1], max(rss) if rss else None


def sim_rows(runs, short):
    rows = []
    scen = ["launch_shift_20s", "drive_60s"] + ([] if short else ["soak_600s"])
    for name in scen:
        path = f"config/scenarios/{name}.toml"
        duration = float(re.search(r"duration_s\s*=\s*([0-9.]+)", (ROOT / path).read_text())[1])
        wall, cpu, rss = median_runs(runs, [DDCT, "sim", "--scenario", path, "--json"],
                                     json_out=True)
        mem = f"{rss:.1f} MiB" if rss is not None else "memory n/a"
        rows.append({
            "what": f"ddct sim {name} ({duration:g} s)",
            "ddct": f"{wall:.3f} s wall, {cpu:.3f} s CPU, {mem}",
            "peer": "real time",
            "ratio_wall": duration / wall,
            "ratio_cpu": duration / max(cpu, 1e-9),
            "rss_mib": rss,
        })
    return rows


def rig_log(out, profile, seed, frames=None):
    """A rig record of the plant with the friction-pressure effect (the diagnose example's)."""
    log = out / f"{Path(profile).stem}_{seed}.log"
    if not log.exists():
        run([DDCT, "plant", "--iface", "sim", "--mode", "rig", "--config", "config/plant_rig.toml",
             "--rig-profile", profile, "--effects", "config/effects/friction_pressure.toml",
             "--seed", str(seed), "--log", str(log)])
    if frames is None:
        return log
    cut = out / f"{log.stem}_{frames}.log"
    with open(log) as src, open(cut, "w") as dst:
        for i, line in enumerate(src):
            if i >= frames:
                break
            dst.write(line)
    return cut


def decode_rows(out, runs, short):
    n = 20_000 if short else 400_000
    log = rig_log(out, "config/rig/bench_30min.toml", 1, n)
    ours = median_runs(runs, [DDCT, "log", "decode", "--format", "csv", str(log)])
    peer = median_runs(runs, [PY, "-m", "cantools", "decode", "dbc/ddct.dbc"], stdin_path=log)
    # The same frames decoded: ddct's CSV has one row per signal; cantools one line per frame.
    ours_csv = subprocess.run([DDCT, "log", "decode", "--format", "csv", str(log)], cwd=ROOT,
                              capture_output=True, text=True, check=True).stdout
    frames_ours = len({(l.split(",")[0], l.split(",")[2]) for l in ours_csv.splitlines()[1:]})
    return [{
        "what": f"ddct log decode --format csv, {n} frames",
        "ddct": f"{ours[0]:.3f} s wall ({n / ours[0] / 1e3:.0f} k frames/s), {ours[1]:.3f} s CPU",
        "peer": f"cantools decode: {peer[0]:.2f} s wall ({n / peer[0] / 1e3:.1f} k frames/s), "
                f"{peer[1]:.2f} s CPU",
        "ratio_wall": peer[0] / ours[0],
        "ratio_cpu": peer[1] / max(ours[1], 1e-9),
        "frames_decoded": frames_ours,
    }]


def check_decoded(rows, n):
    if rows[0]["frames_decoded"] != n:
        sys.exit(f"perf: ddct decoded {rows[0]['frames_decoded']} of {n} frames")


def model_rows():
    p = subprocess.run(["cargo", "bench", "--bench", "model"], cwd=ROOT, capture_output=True,
                       text=True)
    if p.returncode != 0:
        sys.exit(f"perf: cargo bench --bench model failed:\n{p.stdout}\n{p.stderr}")
    rows = []
    batch_checked = False
    for line in p.stdout.splitlines():
        m = re.match(r"(.+?)\s{2,}([0-9.]+)\s+([0-9.]+)\s+([0-9.]+)\s*$", line)
        if m:
            rows.append({
                "what": m[1].strip(),
                "ddct": f"{float(m[2]):.1f} ns",
                "peer": f"numpy {float(m[3]):.1f} ns",
                "ratio_wall": float(m[4]),
                "ratio_cpu": None,
            })
        elif line.startswith("peer agreement") and "false" in line:
            sys.exit(f"perf: the numpy peer disagrees with ddct: {line}")
        elif line.startswith("batch agreement"):
            # The vectorised torque (clutch_batch::torque_batch) against the scalar torque().
            if "batch = scalar: true" not in line:
                sys.exit(f"perf: the batch torque disagrees with the scalar torque: {line}")
            batch_checked = True
    if not batch_checked:
        sys.exit(f"perf: no batch agreement line in cargo bench's output:\n{p.stdout}")
    if not rows:
        sys.exit(f"perf: no rows in cargo bench's output:\n{p.stdout}")
    return rows


def diagnose_rows(out, short):
    train_profile = "config/rig/identification.toml" if short else "config/rig/bench_30min.toml"
    train = rig_log(out, train_profile, 1)
    valid = rig_log(out, "config/rig/validation.toml" if short else train_profile, 7)
    cmd = [DDCT, "gap", "diagnose", "--train", str(train), "--validate", str(valid),
           "--out", str(out / "diagnose")]
    wall, cpu, _ = median_runs(1 if short else 3, cmd)
    return [{
        "what": f"ddct gap diagnose ({Path(train_profile).stem} log)",
        "ddct": f"{wall:.1f} s wall, {cpu:.1f} s CPU",
        "peer": "-",
        "ratio_wall": None,
        "ratio_cpu": None,
    }]


def blind_rows(out, short):
    """`ddct gap blind`: the wall time per trial (trials on every core, as the command runs)."""
    trials = 2 if short else 10
    wall, cpu, _ = run([DDCT, "gap", "blind", "--trials", str(trials), "--seed", "1",
                        "--out", str(out / "blind")])
    return [{
        "what": f"ddct gap blind, {trials} trials (seed 1)",
        "ddct": f"{wall / trials:.1f} s wall per trial, {cpu / trials:.1f} s CPU per trial",
        "peer": "-",
        "ratio_wall": None,
        "ratio_cpu": None,
        "s_per_trial": wall / trials,
    }]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--short", action="store_true", help="one small run of each (CI)")
    ap.add_argument("--out", default="out/perf", help="folder for the logs and perf.json")
    a = ap.parse_args()
    out = (ROOT / a.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    runs = 1 if a.short else 3
    dec = decode_rows(out, runs, a.short)
    check_decoded(dec, 20_000 if a.short else 400_000)
    rows = sim_rows(runs, a.short) + dec + model_rows()
    rows += diagnose_rows(out, a.short)
    rows += blind_rows(out, a.short)
    print(f"{'what':<48} {'ddct':<44} {'peer':<52} {'x wall':>8} {'x CPU':>8}")
    for r in rows:
        f = lambda v: f"{v:8.1f}" if v is not None else f"{'-':>8}"
        print(f"{r['what']:<48} {r['ddct']:<44} {r['peer']:<52} {f(r['ratio_wall'])} {f(r['ratio_cpu'])}")
    sims = {r["what"].split()[2]: r["rss_mib"] for r in rows if r.get("rss_mib") is not None}
    if "soak_600s" in sims and "launch_shift_20s" in sims:
        print(f"memory: 600 s {sims['soak_600s']:.1f} MiB against 20 s "
              f"{sims['launch_shift_20s']:.1f} MiB (+{sims['soak_600s'] - sims['launch_shift_20s']:.1f})")
    (out / "perf.json").write_text(json.dumps({"short": a.short, "rows": rows}, indent=1))
    print(f"perf: figures in {out / 'perf.json'}")


if __name__ == "__main__":
    main()
