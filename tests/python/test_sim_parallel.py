"""`ddct sim` with several scenarios runs them in parallel (`--jobs`, default the machine's
cores): the report keeps the order given and every scenario's metrics and verdict equal those of
a one-at-a-time run; a scenario that does not load stops the command before any runs."""

from __future__ import annotations

import json

import ddct_testlib as lib

SCEN = lib.REPO / "config" / "scenarios"
NAMES = ["drive_60s", "launch_50", "launch_shift_20s", "repeated_launches"]


def _run(ddct, jobs):
    args = [ddct, "sim", "--json", "--jobs", str(jobs)]
    for n in NAMES:
        args += ["--scenario", SCEN / f"{n}.toml"]
    return json.loads(lib.run(args).stdout)


def test_parallel_equals_one_at_a_time(ddct):
    one, two = _run(ddct, 1), _run(ddct, 2)
    assert [s["scenario"] for s in one] == NAMES == [s["scenario"] for s in two]
    for a, b in zip(one, two):
        assert a["metrics"] == b["metrics"], a["scenario"]
        assert a["verdict"] == b["verdict"], a["scenario"]
        assert a["frames"] == b["frames"] and a["tcu_steps"] == b["tcu_steps"]


def test_a_bad_scenario_stops_before_any_run(ddct, tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("duration_s = -3\n")
    r = lib.run([ddct, "sim", "--jobs", "2", "--scenario", SCEN / "launch_50.toml", "--scenario", bad],
                check=False)
    assert r.returncode == 1 and "bad.toml" in r.stderr, r.stderr
    assert "launch_50" not in r.stdout, r.stdout
