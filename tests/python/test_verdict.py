"""Verdicts of `ddct sim` and `ddct bench`: a scenario's `[limits]` checked, a PASS/FAIL table,
exit status 1 on a failed check, and JUnit XML read back with junitparser (the parser CI systems'
plugins build on). The bench runs on the in-process bus (no CAN needed)."""

from __future__ import annotations

from pathlib import Path

import pytest
from junitparser import Failure, JUnitXml

import ddct_testlib as lib

DEFAULT = lib.REPO / "config" / "scenarios" / "launch_shift_20s.toml"
VIOLATED = lib.REPO / "tests" / "data" / "limits_violated.toml"


def suites(path: Path) -> dict[str, dict[str, list[str]]]:
    """{suite: {case: [failure messages]}} of a JUnit XML file."""
    xml = JUnitXml.fromfile(str(path))
    out = {}
    for suite in xml:
        out[suite.name] = {
            case.name: [r.message for r in case.result if isinstance(r, Failure)] for case in suite
        }
    return out


def rows(stdout: str) -> dict[tuple[str, str], str]:
    """{(scenario, check): PASS|FAIL} from the verdict table."""
    out = {}
    for line in stdout.splitlines():
        f = line.split()
        if len(f) >= 3 and f[2] in ("PASS", "FAIL"):
            out[(f[0], f[1])] = f[2]
    return out


def test_sim_fails_exactly_the_violated_limits(ddct, tmp_path):
    junit = tmp_path / "sim.xml"
    r = lib.run([ddct, "sim", "--scenario", DEFAULT, "--scenario", VIOLATED, "--junit", junit], check=False)
    assert r.returncode == 1, r.stderr
    assert "FAIL: limits_violated" in r.stderr
    table = rows(r.stdout)
    assert {k for k, v in table.items() if v == "FAIL"} == {
        ("limits_violated", "lockup_s_max"),
        ("limits_violated", "flare_rpm_max"),
    }
    assert sum(1 for (s, _), v in table.items() if s == "launch_shift_20s" and v == "PASS") == 10
    s = suites(junit)
    assert set(s) == {"launch_shift_20s", "limits_violated"}
    assert all(not f for f in s["launch_shift_20s"].values())
    failed = {c: f for c, f in s["limits_violated"].items() if f}
    assert set(failed) == {"lockup_s_max", "flare_rpm_max"}
    assert "limit ≤ 0.5 s" in failed["lockup_s_max"][0]
    # Alone, the default scenario passes.
    r = lib.run([ddct, "sim", "--scenario", DEFAULT], check=False)
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.fixture(scope="module")
def bench_runs(ddct, tmp_path_factory) -> dict:
    """Both scenarios' bench runs (in-process bus, real time, little CPU), started together:
    {scenario: (the run, its JUnit file)}."""
    d = tmp_path_factory.mktemp("verdict_bench")
    args = {s: [ddct, "bench", "--iface", "sim", "--echo", "2", "--scenario", s, "--out", d / s.stem,
                "--junit", d / f"{s.stem}.xml"] for s in (DEFAULT, VIOLATED)}
    runs = lib.run_together(args, timeout=300)
    return {s: (runs[s], d / f"{s.stem}.xml") for s in args}


@pytest.mark.parametrize("scenario, code", [(DEFAULT, 0), (VIOLATED, 1)], ids=["default", "violated"])
def test_bench_exit_status_and_junit_follow_the_limits(bench_runs, scenario, code):
    r, junit = bench_runs[scenario]
    assert r.returncode == code, r.stdout[-3000:] + r.stderr[-3000:]
    assert "summary.json" in r.stderr
    table = rows(r.stdout)
    failed = {check for (_, check), v in table.items() if v == "FAIL"}
    s = suites(junit)
    (cases,) = s.values()
    assert failed == {c for c, f in cases.items() if f}
    if code == 0:
        assert not failed and "latency_ratio_max" in cases, table
    else:
        assert {"lockup_s_max", "flare_rpm_max"} <= failed, table


def test_a_bad_limit_names_file_line_and_key(ddct, tmp_path):
    bad = tmp_path / "bad.toml"
    text = VIOLATED.read_text().replace("spike_mps2_max = 1.0", "spike_mps2_max = nan")
    bad.write_text(text)
    line = next(i for i, l in enumerate(text.splitlines(), 1) if l.startswith("spike_mps2_max"))
    r = lib.run([ddct, "sim", "--scenario", bad], check=False)
    assert r.returncode != 0
    assert f"{bad} line {line}: `limits.spike_mps2_max`" in r.stderr, r.stderr
    bad.write_text(text.replace("no_stall = true", "no_stal = true"))
    r = lib.run([ddct, "sim", "--scenario", bad], check=False)
    assert "limits" in r.stderr and "no_stal" in r.stderr, r.stderr
