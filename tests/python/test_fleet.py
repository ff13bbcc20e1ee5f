"""`ddct-fleet diagnose` on Dask distributed (issue 18): a small fleet of plant rig records as MF4
(two units with two logs each, a unit whose logs are a truncated and a garbage file), diagnosed
on the LocalCluster default, in a plain loop, and on a cluster started by hand (`dask scheduler`
and two `dask worker` processes): the same findings each time; the bad files are error rows; a
rerun skips every log already done; a worker killed mid-run loses no finding."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pyarrow.dataset as ds
import pytest

import ddct_testlib as lib
from ddct_can.fleet import campaign

VENV_BIN = Path(sys.executable).parent
# The rig profiles and the simulated seconds of each kept: every engagement (46 of 4 s from 1 s;
# 32 of 6 s from 1 s), not the cooling after them. The diagnoses the tests compare take 7-8 s
# instead of 10 s each on one core, and there are a dozen.
PROFILES = (("config/rig/identification.toml", 190), ("config/rig/validation.toml", 200))


def _rig_mf4(ddct, out: Path, profile: tuple, seed: int) -> Path:
    profile, seconds = profile
    log = out / f"{Path(profile).stem}_{seed}.log"
    lib.run([ddct, "plant", "--iface", "sim", "--mode", "rig", "--config", lib.REPO / "config/plant_rig.toml",
             "--rig-profile", lib.REPO / profile, "--effects", lib.REPO / "config/effects/friction_pressure.toml",
             "--seed", seed, "--duration", seconds, "--log", log])
    mf4 = log.with_suffix(".mf4")
    lib.run([ddct, "log", "convert", log, mf4])
    log.unlink()
    return mf4


@pytest.fixture(scope="module")
def fleet(ddct, tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("fleet")
    for u, unit in enumerate(("unit-a", "unit-b")):
        d = root / unit
        d.mkdir()
        for k, profile in enumerate(PROFILES):
            mf4 = _rig_mf4(ddct, d, profile, 10 * u + k + 1)
            mf4.rename(d / f"{k:02d}_{mf4.name}")
    bad = root / "unit-bad"
    bad.mkdir()
    good = next((root / "unit-a").iterdir()).read_bytes()
    (bad / "00_truncated.mf4").write_bytes(good[: len(good) // 3])
    (bad / "01_garbage.log").write_bytes(os.urandom(5000))
    return root


def _fleet(args, **kw):
    return lib.run([VENV_BIN / "ddct-fleet", *map(str, args)], **kw)


@pytest.fixture(scope="module")
def reference(fleet, tmp_path_factory) -> Path:
    """The fleet's findings from a plain loop (`--sequential`, 50 bootstrap resamples, one thread
    per diagnosis): what every cluster run below must reproduce. Diagnosed once for the module:
    ddct is deterministic, and the findings do not depend on the campaign's salt (file names)."""
    ref = tmp_path_factory.mktemp("reference") / "findings"
    _fleet(["diagnose", fleet, "--out", ref, "--sequential", "--bootstrap", "50"])
    return ref


def _findings(out: Path) -> list[dict]:
    rows = ds.dataset(out, format="parquet").to_table().to_pylist()
    return sorted(rows, key=lambda r: (r["unit"], r["log"], r["kind"], r["class"] or "", r["error"] or ""))


def _comparable(rows):
    """Findings without what differs between runs by design (none: ddct is deterministic)."""
    return [{k: v for k, v in r.items()} for r in rows]


def test_local_cluster_loop_and_resume_give_the_same_findings(fleet, reference, tmp_path):
    out = tmp_path / "local"
    s = json.loads(_fleet(["diagnose", fleet, "--out", out, "--workers", "2", "--bootstrap", "50", "--json"]).stdout)
    assert (s["logs"], s["ran"], s["skipped"], s["errors"]) == (6, 6, 0, 2), s
    rows = _findings(out)
    errors = [r for r in rows if r["kind"] == "error"]
    assert sorted(Path(r["log"]).name for r in errors) == ["00_truncated.mf4", "01_garbage.log"]
    assert all(r["unit"] == "unit-bad" and r["error"] for r in errors)
    good = [r for r in rows if r["kind"] != "error"]
    assert {r["unit"] for r in good} == {"unit-a", "unit-b"} and len({r["log"] for r in good}) == 4
    # A rerun skips every log.
    again = json.loads(_fleet(["diagnose", fleet, "--out", out, "--workers", "2", "--bootstrap", "50", "--json"]).stdout)
    assert (again["ran"], again["skipped"]) == (0, 6), again
    # A plain loop gives the same findings.
    assert _comparable(_findings(reference)) == _comparable(rows)


def test_a_rerun_with_every_log_done_says_so_and_gives_no_rate(ddct, tmp_path):
    """Units of one log each are error rows written without a diagnosis (fast); the second run
    finds both done and says so, with no logs/min (there is no rate of nothing)."""
    for unit in ("unit-x", "unit-y"):
        (tmp_path / "fleet" / unit).mkdir(parents=True)
        (tmp_path / "fleet" / unit / "00.log").write_bytes(b"not a log")
    args = ["diagnose", tmp_path / "fleet", "--out", tmp_path / "out", "--sequential", "--ddct", ddct]
    first = _fleet(args).stdout
    assert first.startswith("2 diagnosed (0 done before, 2 error rows)") and " logs/min;" in first, first
    again = _fleet(args).stdout
    assert again.startswith("0 new logs diagnosed; 2 already done"), again
    assert "logs/min" not in again and "None" not in again, again
    s = json.loads(_fleet([*args, "--json"]).stdout)
    assert (s["ran"], s["skipped"], s["logs_per_min"]) == (0, 2, None), s


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_cluster_started_by_hand_gives_the_same_findings(fleet, reference, tmp_path):
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([VENV_BIN / "dask", "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]
    try:
        for _ in range(2):
            procs.append(subprocess.Popen([VENV_BIN / "dask", "worker", address, "--nthreads", "1", "--no-dashboard"],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL))
        from distributed import Client

        with Client(address, timeout=60) as c:
            c.wait_for_workers(2, timeout=60)
        out = tmp_path / "by_hand"
        s = json.loads(_fleet(["diagnose", fleet, "--out", out, "--scheduler", address, "--bootstrap", "50",
                               "--json"]).stdout)
        assert s["ran"] == 6 and "2 workers" in s["on"], s
    finally:
        for p in reversed(procs):
            p.terminate()
        for p in procs:
            p.wait(30)
    assert _comparable(_findings(out)) == _comparable(_findings(reference))


def test_a_worker_killed_mid_run_loses_no_finding(ddct, fleet, reference, tmp_path):
    from distributed import Client, LocalCluster

    tasks = campaign.discover(fleet, "kill-test")
    out = tmp_path / "killed"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            Client(cluster) as client:
        pids = list(client.run(os.getpid).values())
        killed = []

        def kill_when_busy():
            # Kill a worker while it runs a diagnosis (its ddct child is alive).
            deadline = time.monotonic() + 120
            while time.monotonic() < deadline and not killed:
                busy = client.processing()
                for addr, keys in busy.items():
                    if keys:
                        pid = client.run(os.getpid, workers=[addr])[addr]
                        os.kill(pid, signal.SIGKILL)
                        killed.append(pid)
                        return
                time.sleep(0.2)

        killer = threading.Thread(target=kill_when_busy)
        killer.start()
        results = campaign.run_campaign(tasks, str(ddct), out, 50, 1, client, progress=lambda *a: None)
        killer.join()
    assert killed and killed[0] in pids
    assert len(results) == len(tasks)
    for t in tasks:
        assert Path(campaign.result_path(out, t)).exists(), t
    assert _comparable(_findings(out)) == _comparable(_findings(reference))


def test_the_python_error_row_has_ddct_s_schema(reference):
    written = ds.dataset(reference, format="parquet").schema
    assert written.remove_metadata() == campaign.FINDINGS_SCHEMA.remove_metadata()


@pytest.fixture(scope="module")
def generated(ddct, tmp_path_factory):
    """A fleet from `ddct-fleet generate` (2 units × 2 logs) and its findings."""
    root = tmp_path_factory.mktemp("generated")
    fleet, out = root / "fleet", root / "findings"
    _fleet(["generate", "--out", fleet, "--units", "2", "--logs", "2", "--seed", "3", "--ddct", ddct])
    _fleet(["diagnose", fleet, "--out", out, "--workers", "2", "--bootstrap", "100"])
    return fleet, out


def test_the_generator_writes_the_planned_evolving_truths_as_mf4(ddct, generated):
    from ddct_can.fleet.generate import plan

    import csv

    fleet, _ = generated
    rows = list(csv.DictReader(open(fleet / "truth.csv")))
    specs = plan(2, 2, 50.0, 3)
    assert len(rows) == len(specs) == 4
    for r, s in zip(rows, specs):
        assert (r["unit"], r["class"]) == (s.unit, s.evolution.klass)
        assert float(r["operating_hours"]) == s.hours
        # the truth generator kept the magnitude asked for, which grows with the hours
        assert float(r["magnitude"]) == pytest.approx(s.evolution.base + s.evolution.per_hour * s.hours, rel=1e-12)
        for f in ("log", "train"):
            frames = lib.run([ddct, "log", "stats", fleet / r[f], "--json"]).stdout
            assert sum(m["frames"] for m in json.loads(frames)) > 50_000
    by_unit = {}
    for r in rows:
        by_unit.setdefault(r["unit"], []).append(abs(float(r["magnitude"])))
    assert all(m[0] < m[1] for m in by_unit.values()), by_unit
    # The curve of the term over its variable states the same magnitude: kiss-point wear over
    # 0…1.2 MJ of friction energy, friction fade over 20…320 °C (the truth's z ranges).
    for r in rows:
        curve = json.loads(r["curve"])
        xs = [x for x, _ in curve]
        assert xs == sorted(xs) and len(xs) > 100
        ends = {"kiss_point_energy": (0.0, 1.2), "friction_temperature": (20.0, 320.0)}[r["class"]]
        from ddct_can.fleet.report import truth_by_basis

        assert truth_by_basis(curve, "change", *ends) == pytest.approx(float(r["magnitude"]), rel=1e-9, abs=1e-12)


def test_the_truth_is_read_by_the_findings_definition_of_the_magnitude():
    from ddct_can.fleet.report import truth_by_basis

    curve = [[x / 10, (x / 10) ** 2 - 3] for x in range(0, 101)]  # y = x² − 3 on 0…10
    assert truth_by_basis(curve, "change", 2.0, 4.0) == pytest.approx(12.0)
    assert truth_by_basis(curve, "change", 2.05, 4.05) == pytest.approx(4.05**2 - 2.05**2, abs=0.01)
    assert truth_by_basis(curve, "at", 1.0, 1.0) == pytest.approx(-2.0)
    # a multiplier 1 + y: 1 + 13 at 4 over 1 + 1 at 2, less one
    assert truth_by_basis(curve, "ratio", 2.0, 4.0) == pytest.approx(14.0 / 2.0 - 1.0)
    # the value of largest size, with its sign: −3 at 0 beats 1 at 2; 6 at 3 beats −3
    assert truth_by_basis(curve, "largest", 0.0, 2.0) == pytest.approx(-3.0)
    assert truth_by_basis(curve, "largest", 0.0, 3.0) == pytest.approx(6.0)
    assert truth_by_basis(curve, "parameter", 0.0, 1.0) is None
    assert truth_by_basis(curve, "change", None, 1.0) is None


def test_a_finding_ambiguous_with_the_truths_class_gives_its_magnitude():
    """A log whose diagnosis names spring_temperature first, ambiguous with friction_temperature
    (both multiply the torque (13) over temperature alike), scores that finding for a fade; a
    finding of the class itself wins over an ambiguous one, and an unrelated class gives none."""
    from ddct_can.fleet.report import unit_points

    curve = json.dumps([[t, 0.2 * (1 - t / 300)] for t in range(0, 301, 10)])
    truth = {f"/f/{k}.mf4": {"unit": "u", "class": "friction_temperature", "effect_size": "5",
                              "magnitude": "-0.2", "magnitude_unit": "1", "curve": curve} for k in "abc"}

    def row(log, klass, mag, ambiguous):
        return {"log": f"/f/{log}.mf4", "operating_hours": 1.0, "start_time": None, "kind": "class",
                "class": klass, "magnitude": mag, "magnitude_lo": mag - 0.01, "magnitude_hi": mag + 0.01,
                "magnitude_unit": "relative", "magnitude_basis": "ratio", "magnitude_from": 30.0,
                "magnitude_to": 270.0, "error": None, "detail": json.dumps({"ambiguous_with": ambiguous})}

    rows = [row("a", "spring_temperature", -0.15, ["friction_temperature"]),
            row("b", "spring_temperature", -0.15, ["friction_temperature"]),
            row("b", "friction_temperature", -0.16, ["spring_temperature"]),
            row("c", "friction_slip", -0.1, [])]
    pts = {p["log"][-5]: p for p in unit_points(rows, "friction_temperature", truth)}
    assert (pts["a"]["fit"], pts["a"]["named"]) == (-0.15, "spring_temperature")
    assert (pts["b"]["fit"], pts["b"]["named"]) == (-0.16, "friction_temperature")
    assert pts["c"]["fit"] is None and pts["c"]["named"] is None
    # the truth read by the ratio over 30…270 °C: (1 + 0.02)/(1 + 0.18) − 1
    assert pts["a"]["truth"] == pytest.approx(1.02 / 1.18 - 1)


def test_the_fleet_report_opens_in_a_browser(generated, tmp_path):
    from test_report_html import browse

    fleet, out = generated
    page = tmp_path / "fleet.html"
    figures = json.loads(_fleet(["report", out, "--truth", fleet / "truth.csv", "--out", page, "--json"]).stdout)
    assert figures["logs"] == 4 and figures["units"] == 2 and figures["error_logs"] == 0
    text = page.read_text()
    assert "<script" not in text and "http" not in text.replace("http://www.w3.org/2000/svg", "")
    assert "Recovery:" in text and text.count("<svg") == 2
    import csv

    for r in csv.DictReader(open(fleet / "truth.csv")):
        assert str((fleet / r["log"]).resolve()) in text  # the log behind every point
    shot = tmp_path / "shot.png"
    p = browse(page.as_uri(), f"--screenshot={shot}", "--window-size=1000,1400")
    assert p.returncode == 0 and shot.exists(), p.stderr[-2000:]
    # A blank page compresses to a few kB; the tables and timelines make it ~100 kB.
    assert shot.stat().st_size > 30_000 and shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    console = [line for line in p.stderr.splitlines() if "CONSOLE" in line]
    assert console == [], console


def test_logs_and_findings_behind_urls_go_through_fsspec(ddct, fleet, tmp_path):
    """A manifest naming its logs by URL and a findings dataset at a URL (file:// here; s3://
    or gs:// take the same path through fsspec) give the findings of local paths."""
    manifest = tmp_path / "manifest.csv"
    logs = sorted((fleet / "unit-a").iterdir())
    manifest.write_text("unit,log,train\n" + "".join(f"unit-a,{l.as_uri()},{logs[0].as_uri()}\n" for l in logs[1:]))
    out = tmp_path / "remote"
    s = json.loads(_fleet(["diagnose", manifest, "--out", out.as_uri(), "--sequential", "--bootstrap", "20",
                           "--json"]).stdout)
    assert (s["ran"], s["errors"]) == (1, 0), s
    rows = _findings(out)
    assert rows and rows[0]["log"].endswith(logs[1].name) and rows[0]["kind"] != "error", rows


def test_blind_trials_in_chunks_on_the_cluster_summarise_as_one_run(ddct, tmp_path):
    """`ddct-fleet blind` cuts the trials of a seed into chunks (Dask tasks) and merges them:
    the same trials and summary as one `ddct gap blind` of them; a rerun runs nothing."""
    lib.run([ddct, "gap", "blind", "--trials", 2, "--seed", 5, "--out", tmp_path / "one"])
    out = tmp_path / "fleet"
    summary = json.loads(_fleet(["blind", "--trials", 2, "--chunk", 1, "--seed", 5, "--out", out, "--json"]).stdout)
    assert summary["trials"] == 2 and summary["ran"] == 2 and summary["chunks"] == 2
    assert summary["failed_chunks"] == 0 and "Dask" in summary["on"]
    one = json.loads((tmp_path / "one/report.json").read_text())
    merged = json.loads((out / "report.json").read_text())
    assert len(merged["merged_from"]) == 2

    def timeless(trials):
        return [{k: v for k, v in t.items() if k != "seconds"} for t in trials]

    assert timeless(merged["trials"]) == timeless(one["trials"])
    assert {k: v for k, v in merged["summary"].items() if k != "mean_seconds_per_trial"} == \
        {k: v for k, v in one["summary"].items() if k != "mean_seconds_per_trial"}
    again = json.loads(_fleet(["blind", "--trials", 2, "--chunk", 1, "--seed", 5, "--out", out, "--json",
                               "--sequential"]).stdout)
    assert again["ran"] == 0 and again["trials"] == 2
    # Reports of another seed, or not reports at all, do not merge: the file is named.
    chunk = next((out / "chunks").iterdir()) / "report.json"
    other = json.loads(chunk.read_text())
    other["seed"] = 6
    (tmp_path / "seed6.json").write_text(json.dumps(other))
    p = lib.run([ddct, "gap", "blind", "--merge", chunk, tmp_path / "seed6.json"], check=False)
    assert p.returncode != 0 and "seed6.json" in p.stderr and "seed" in p.stderr, p.stderr
    (tmp_path / "junk.json").write_text("{\"seed\": 5, \"trials\": [{\"index\": 1}]}")
    p = lib.run([ddct, "gap", "blind", "--merge", chunk, tmp_path / "junk.json"], check=False)
    assert p.returncode != 0 and "junk.json" in p.stderr and "trial 0" in p.stderr, p.stderr
