"""Arguments checked at the parser: a missing CAN interface says how to get one, an out-of-range
real-time priority or speed is refused (exit status 2, clap's usage error) instead of clamped."""

from __future__ import annotations

import pytest

import ddct_testlib as lib


@pytest.mark.parametrize("cmd", [["tcu", "--iface", "vcan9", "--config", str(lib.REPO / "config" / "tcu.toml")], ["plant", "--iface", "vcan9"], ["log", "record", "--iface", "vcan9", "--out", "x.log"]])
def test_a_missing_interface_says_how_to_get_one(ddct, tmp_path, cmd):
    r = lib.run([ddct, *cmd], check=False, cwd=tmp_path)
    assert r.returncode == 1, r.stderr
    assert "CAN interface vcan9 does not exist" in r.stderr, r.stderr
    assert "scripts/vcan-run" in r.stderr and "type vcan" in r.stderr, r.stderr
    assert r.stderr.count("No such device") == 0, r.stderr


@pytest.mark.parametrize(
    "cmd, flag",
    [
        (["tcu", "--iface", "sim", "--rt-priority", "120"], "--rt-priority"),
        (["tcu", "--iface", "sim", "--rt-priority", "0"], "--rt-priority"),
        (["plant", "--iface", "sim", "--speed", "fast"], "--speed"),
        (["plant", "--iface", "sim", "--speed", "0"], "--speed"),
        (["tcu", "--iface", "can/0"], "--iface"),
    ],
)
def test_out_of_range_arguments_are_usage_errors(ddct, cmd, flag):
    r = lib.run([ddct, *cmd], check=False, timeout=30)
    assert r.returncode == 2, (r.returncode, r.stderr)
    assert f"invalid value" in r.stderr and flag in r.stderr, r.stderr


def test_commands_work_outside_the_repository(ddct, tmp_path):
    """The built-in calibration and scenario: no config/ in the working directory needed."""
    r = lib.run([ddct, "sim", "--scenario", lib.REPO / "config" / "scenarios" / "launch_50.toml"], cwd=tmp_path)
    assert "launch_50" in r.stdout and "PASS" in r.stdout, r.stdout
    r = lib.run([ddct, "tcu", "--iface", "sim", "--duration", "1"], cwd=tmp_path, timeout=60)
    r = lib.run([ddct, "sim", "--scenario", "nope.toml"], cwd=tmp_path, check=False)
    assert r.returncode == 1 and "cannot read scenario nope.toml" in r.stderr, r.stderr
