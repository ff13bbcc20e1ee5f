"""Arguments checked at the parser: a missing CAN interface says how to get one, an out-of-range
real-time priority or speed is refused (exit status 2, clap's usage error) instead of clamped."""

from __future__ import annotations

import json
import re

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
        (["tcu", "--iface", "sim", "--duration", "nan"], "--duration"),
        (["plant", "--iface", "sim", "--duration=-1"], "--duration"),
        (["plant", "--iface", "sim", "--mode", "rig", "--input-speed", "7000"], "--input-speed"),
        (["plant", "--iface", "sim", "--lockstep", "--lockstep-timeout", "0"], "--lockstep-timeout"),
        (["bench", "--iface", "sim", "--echo", "601"], "--echo"),
        (["sim", "--scenario", "x.toml", "--jobs", "0"], "--jobs"),
        (["log", "monitor", "-", "--duration", "0"], "--duration"),
        (["log", "record", "--iface", "vcan0", "--out", "x.log", "--duration", "inf"], "--duration"),
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


def test_one_scenario_format_for_sim_and_plant(ddct, tmp_path):
    """`ddct sim` runs a driver scenario (built-in plant); `ddct plant` runs a sim scenario (its
    plant configuration and driver); a sim scenario beside --config is refused naming both."""
    scen = lib.REPO / "config" / "scenarios"
    r = lib.run([ddct, "sim", "--scenario", scen / "driver_launch.toml"])
    assert re.search(r"^driver_launch +\d+ ", r.stdout, re.M), r.stdout
    # The plant plays launch_50's driver (50 % pedal from 1 s), not its built-in 30 % launch.
    log = tmp_path / "plant.log"
    lib.run([ddct, "plant", "--iface", "sim", "--scenario", scen / "launch_50.toml", "--duration", "3", "--log", log])
    pedal = [
        json.loads(l)["signals"]["AccelPedal"]
        for l in lib.run([ddct, "log", "decode", log, "--format", "json", "-m", "DRV_Pedal"]).stdout.splitlines()
    ]
    assert pedal and max(pedal) == 50.0, sorted(set(pedal))
    r = lib.run([ddct, "plant", "--iface", "sim", "--scenario", scen / "launch_50.toml", "--config", lib.REPO / "config" / "plant.toml"], check=False)
    assert r.returncode == 1 and "a sim scenario carries its plant configuration" in r.stderr, r.stderr
