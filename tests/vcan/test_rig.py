"""The plant daemon on vcan0 (issue 5): the paper's rig experiment (Sect. 3.3, Fig. 6) driven by
scripts/rig_partial_engagements.py against `ddct plant --mode rig`, the same experiment in
process, and the plant's cycle times. Run through scripts/vcan-run (scripts/test does).

The rig run uses the plant's lockstep (`--lockstep`, the script's default with --spawn-plant):
the plant waits for each answer before simulating the next cycle, so a loaded machine or
User-Mode Linux changes the wall time, not the signals.
"""

from __future__ import annotations

import json
import math
import time
import sys
from pathlib import Path

import pytest

import ddct_testlib as lib
from ddct_testlib import ddct_can
from vcan_helpers import IFACE, background, can_receivers, wait_receivers

REPO = lib.REPO
sys.path.insert(0, str(REPO / "scripts"))
import rig_partial_engagements as rig  # noqa: E402

PROFILE = REPO / "config" / "rig" / "identification.toml"
PLANT_CONFIG = REPO / "config" / "plant_rig.toml"
SPEED = 8.0


def frames_by_message(path: Path, db) -> dict[str, list[bytes]]:
    """Payloads of a candump log per message name, in order (decoded only where needed: a 385 s
    run has 300 000 frames and User-Mode Linux has 1 GB)."""
    names: dict[int, str] = {}
    out: dict[str, list] = {}
    for _t, _iface, fid, ext, data in ddct_can.read_candump(path):
        if ext:
            continue
        if fid not in names:
            try:
                names[fid] = db.get_message_by_frame_id(fid).name
            except KeyError:
                names[fid] = "?"
        out.setdefault(names[fid], []).append(data)
    return out


def signal_series(db, name: str, payloads: list[bytes], signal: str) -> list[float]:
    m = db.get_message_by_name(name)
    return [m.decode(d, decode_choices=False)[signal] for d in payloads]


@pytest.fixture(scope="module")
def rig_run(vcan0, ddct, candump, tmp_path_factory):
    """The identification experiment over vcan0: the python rig controller spawns the plant."""
    d = tmp_path_factory.mktemp("rig")
    out, plant_log, summary = d / "rig.log", d / "plant.log", d / "summary.json"
    proc = lib.run(
        [
            sys.executable, REPO / "scripts" / "rig_partial_engagements.py",
            "--iface", vcan0, "--profile", PROFILE, "--out", out, "--speed", SPEED,
            "--spawn-plant", ddct, "--plant-config", PLANT_CONFIG, "--plant-log", plant_log,
            "--plant-arg=--lockstep-timeout=20", "--summary-json", summary,
        ],
        timeout=900,
    )
    print(proc.stdout[-3000:])
    print(proc.stderr[-3000:])
    return {"log": out, "plant_log": plant_log, "summary": json.loads(summary.read_text()),
            "stderr": proc.stderr, "dir": d}


def test_rig_experiment_over_vcan_reproduces_fig6(rig_run, db):
    profile = rig.RigProfile(PROFILE)
    frames = frames_by_message(rig_run["log"], db)
    cycles = int(round(profile.duration_s / 0.01))
    eng = frames["ENG_Status"]
    assert len(eng) >= cycles, f"{len(eng)} ENG_Status frames recorded, {cycles} expected"
    # Independent evaluation of the log: the k-th frame of a message belongs to cycle k.
    torque = signal_series(db, "BENCH_Torque", frames["BENCH_Torque"][:cycles], "Clutch1Torque")
    cd = signal_series(db, "BENCH_Temps", frames["BENCH_Temps"][:cycles], "CentralDiskTemp")
    peak: dict[int, float] = {}
    cd_max: dict[int, float] = {}
    for k in range(cycles):
        e = profile.engagement_at(k * 0.01)
        if e is None:
            continue
        peak[e] = max(peak.get(e, 0.0), torque[k])
        cd_max[e] = max(cd_max.get(e, -1e9), cd[k])
    assert sorted(peak) == list(range(profile.count))
    hot = next(e for e in sorted(cd_max) if cd_max[e] > 200.0)
    ratio = peak[hot] / peak[0]
    print(f"first engagement {peak[0]:.1f} N·m; engagement {hot}: central disk {cd_max[hot]:.1f} °C, "
          f"peak {peak[hot]:.1f} N·m = {ratio:.2f} x")
    assert peak[0] > 20.0
    assert ratio >= 1.5
    # The script's own summary says the same.
    s = rig_run["summary"]["fig6"]
    assert s["first_hot"] == hot and math.isclose(s["ratio"], ratio, rel_tol=1e-9)
    # The cooling phase: both clutches open, no torque, the central disk cools down.
    cool_from = int(round((profile.start_s + profile.count * profile.period_s + 1.0) / 0.01))
    assert all(abs(t) <= 2.0 for t in torque[cool_from:cycles]), "open clutches: sensor noise only (0.3 N·m)"
    assert cd[cycles - 1] < cd[cool_from] - 50.0


def test_rig_commands_went_over_the_bus(rig_run, db):
    """Every cycle was answered over vcan0 with the profile's command for the next cycle, and the
    plant received each answer (its own candump tap records what it received)."""
    profile = rig.RigProfile(PROFILE)
    frames = frames_by_message(rig_run["log"], db)
    cmds = frames["TCU_ClutchCmd"]
    cmd_msg = db.get_message_by_name("TCU_ClutchCmd")
    cycles = int(round(profile.duration_s / 0.01))
    assert len(cmds) == cycles == rig_run["summary"]["commands_sent"]
    for k in (0, 1234, 20000, cycles - 1):
        x1, x2 = profile.x_ref((k + 1) * 0.01)
        v = cmd_msg.decode(cmds[k], decode_choices=False)
        assert abs(v["Clutch1PosReq"] - x1) <= 0.0005 + 1e-12 and abs(v["Clutch2PosReq"] - x2) <= 0.0005 + 1e-12
        assert ddct_can.check(cmd_msg.frame_id, cmds[k]) == ddct_can.OK
    plant_seen = frames_by_message(rig_run["plant_log"], db)["TCU_ClutchCmd"]
    assert plant_seen == cmds
    assert rig_run["summary"]["cycles_not_answered"] == 0


def test_same_signals_over_vcan_and_in_process(rig_run, ddct, db, tmp_path):
    """The same experiment with the plant's built-in profile on the in-process bus: every signal
    of every frame equal within the contract's resolution (one LSB)."""
    sim_log = tmp_path / "sim.log"
    lib.run([ddct, "plant", "--iface", "sim", "--config", PLANT_CONFIG, "--mode", "rig",
             "--rig-profile", PROFILE, "--log", sim_log], timeout=300)
    vcan = frames_by_message(rig_run["log"], db)
    sim = frames_by_message(sim_log, db)
    cycles = int(round(rig.RigProfile(PROFILE).duration_s / 0.01))
    compared = identical = 0
    worst: dict[str, float] = {}
    for name in ["ENG_Status", "DCT_Sensors", "DCT_Actuators", "BENCH_Torque", "BENCH_Temps",
                 "BENCH_Vehicle", "SIM_Truth"]:
        msg = db.get_message_by_name(name)
        a, b = vcan[name], sim[name]
        assert len(a) >= cycles and len(b) >= cycles, name
        for k in range(cycles):
            compared += 1
            if a[k] == b[k]:
                identical += 1
                continue
            va = msg.decode(a[k], decode_choices=False)
            vb = msg.decode(b[k], decode_choices=False)
            for sig in msg.signals:
                if sig.name in ("AliveCounter", "Crc"):
                    assert va[sig.name] == vb[sig.name], (name, k, sig.name)
                    continue
                d = abs(va[sig.name] - vb[sig.name])
                worst[f"{name}.{sig.name}"] = max(worst.get(f"{name}.{sig.name}", 0.0), d)
                assert d <= abs(sig.scale) * (1 + 1e-9), (name, k, sig.name, va[sig.name], vb[sig.name])
    print(f"{compared} frames compared, {identical} bit-identical; worst differences {worst}")
    assert compared == 7 * cycles


CYCLE_MESSAGES = ["DRV_Pedal", "ENG_Status", "DCT_Sensors", "DCT_Actuators", "BENCH_Torque", "BENCH_Temps",
                  "BENCH_Vehicle", "SIM_Truth"]
# A real-time run is judged only when the host let the plant keep its deadlines this often.
MAX_MISS_SHARE = 0.2


def plant_cycle_run(vcan0, ddct, candump, tmp_path, attempt):
    log = tmp_path / f"cycle_{attempt}.log"
    before = can_receivers()
    with open(log, "w") as out, background([candump, "-L", vcan0], stdout=out) as dump:
        wait_receivers(before, 1, procs=[dump])
        proc = lib.run([ddct, "plant", "--iface", vcan0, "--scenario",
                        REPO / "config" / "scenarios" / "driver_launch.toml", "--duration", "10", "--json"],
                       timeout=120)
        time.sleep(0.3)
    report = json.loads(proc.stdout)
    stats = json.loads(lib.run([ddct, "log", "stats", "--json", log]).stdout)
    by_name = {s["name"]: s for s in stats}
    print(f"plant (attempt {attempt}): cycles {report['cycles']} deadline misses {report['deadline_misses']} "
          f"overruns {report['overruns']} lateness p50 {report['lateness_p50_us']} us p99 {report['lateness_p99_us']} us")
    for name in CYCLE_MESSAGES:
        s = by_name[name]
        print(f"{name}: {s['frames']} frames, p50 {s['p50_ms']:.3f} ms, p99 {s['p99_ms']:.3f} ms")
    # Under any load: the run ends on its duration, nothing is refused, every message is sent.
    assert report["stopped_by"] == "duration" and report["send_errors"] == 0, report
    assert all(by_name[n]["frames"] > 0 for n in CYCLE_MESSAGES), by_name
    return report, by_name


def test_plant_cycle_times_on_vcan(vcan0, ddct, candump, db, tmp_path):
    """10 s of the plant in real time (vehicle mode, built-in driver) recorded by candump: every
    message every 10 ms (p50 within 1 ms; a generous bound on the tail), and the plant's report.
    The cycle times are judged only when the host let the plant keep 80 % of its deadlines (the
    plant's own report); a run the host starved is repeated once, then reported as not judged."""
    for attempt in (1, 2):
        report, by_name = plant_cycle_run(vcan0, ddct, candump, tmp_path, attempt)
        share = report["deadline_misses"] / max(report["cycles"], 1)
        if share < MAX_MISS_SHARE:
            break
        print(f"NOT JUDGED (attempt {attempt}): the host made the plant miss {share:.0%} of its deadlines "
              f"(lateness p99 {report['lateness_p99_us']} us)")
    else:
        print("cycle times not judged on this host: the guest did not get the CPU (see above)")
        return
    for name in CYCLE_MESSAGES:
        s = by_name[name]
        assert 980 <= s["frames"] <= 1003, (name, s["frames"])
        assert abs(s["p50_ms"] - 10.0) < 1.0, (name, s["p50_ms"])
        assert s["mean_ms"] == pytest.approx(10.0, abs=0.5)
