"""Bench's life cycle against a stand-in for the ddct binary (no CAN needed): start order and
ready files, SIGTERM, exit statuses and reports, and the errors when a daemon misbehaves; where
the binary is found, and the calibration built into it used by default."""

from __future__ import annotations

import json
import os
import sys
import textwrap
import time
from pathlib import Path

import pytest

from ddct_can import Bench, BenchError, daemons, find_ddct

FAKE = textwrap.dedent(
    """\
    #!{python}
    import json, os, signal, sys, time
    role, args = sys.argv[1], sys.argv[2:]
    ready = args[args.index("--ready-file") + 1]
    with open(os.environ["FAKE_LOG"], "a") as f:
        f.write(json.dumps({{"role": role, "args": args, "t": time.time(), "pid": os.getpid()}}) + "\\n")
    mode = os.environ.get("FAKE_" + role.upper(), "ok")
    if mode == "die":
        sys.stderr.write(role + ": cannot open the interface\\n")
        sys.exit(3)
    stop = []
    signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
    time.sleep(0.05)
    open(ready, "w").write(str(os.getpid()))
    while not stop:
        time.sleep(0.01)
    if mode == "ignore_term":
        time.sleep(60)
    if mode == "fail":
        sys.stderr.write(role + ": failed at shutdown\\n")
        sys.exit(1)
    print(json.dumps({{"role": role, "stopped_by": "shutdown"}}))
    """
)


@pytest.fixture
def fake(tmp_path, monkeypatch):
    exe = tmp_path / "ddct"
    exe.write_text(FAKE.format(python=sys.executable))
    exe.chmod(0o755)
    log = tmp_path / "calls.jsonl"
    monkeypatch.setenv("FAKE_LOG", str(log))
    return exe, log


def calls(log):
    return [json.loads(line) for line in log.read_text().splitlines()]


def alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def test_start_order_args_stop_and_reports(fake, tmp_path):
    exe, log = fake
    cfg = tmp_path / "tcu.toml"
    cfg.write_text("")
    with Bench("vcanX", ddct=exe, tcu_config=cfg, plant_args=["--faults", "f.toml"], workdir=tmp_path / "w") as b:
        c = calls(log)
        assert [x["role"] for x in c] == ["tcu", "plant"]
        tcu_ready = (tmp_path / "w" / "tcu.ready").stat().st_mtime
        assert c[1]["t"] >= tcu_ready - 0.01  # the plant only once the TCU listened
        assert c[0]["args"][:5] == ["--iface", "vcanX", "--json", "--config", str(cfg.resolve())]
        assert c[1]["args"][:5] == ["--iface", "vcanX", "--json", "--faults", "f.toml"]
        b.check_running()
        pids = [x["pid"] for x in c]
    assert not any(alive(p) for p in pids)
    assert b.tcu_report == {"role": "tcu", "stopped_by": "shutdown"}
    assert b.plant_report == {"role": "plant", "stopped_by": "shutdown"}
    assert b.tcu.returncode == 0 and b.plant.returncode == 0


def test_a_daemon_that_dies_before_listening(fake, monkeypatch):
    exe, log = fake
    monkeypatch.setenv("FAKE_PLANT", "die")
    with pytest.raises(BenchError, match=r"(?s)plant exited with 3 before it listened.*cannot open the interface"):
        with Bench("vcanX", ddct=exe):
            pytest.fail("the body ran without a plant")
    tcu_pid = calls(log)[0]["pid"]
    time.sleep(0.05)
    assert not alive(tcu_pid), "the TCU was left running"


def test_a_failed_exit_status_is_an_error(fake, monkeypatch):
    exe, _ = fake
    monkeypatch.setenv("FAKE_TCU", "fail")
    with pytest.raises(BenchError, match=r"tcu exited with status 1:\s+tcu: failed at shutdown"):
        with Bench("vcanX", ddct=exe):
            pass


def test_a_daemon_ignoring_sigterm_is_killed_and_reported(fake, monkeypatch):
    exe, _ = fake
    monkeypatch.setenv("FAKE_PLANT", "ignore_term")
    with pytest.raises(BenchError, match=r"plant did not stop within 0.5 s of SIGTERM"):
        with Bench("vcanX", ddct=exe, stop_timeout=0.5):
            pass


def test_an_error_in_the_body_is_not_masked(fake, monkeypatch):
    exe, _ = fake
    monkeypatch.setenv("FAKE_TCU", "fail")
    with pytest.raises(ZeroDivisionError) as e:
        with Bench("vcanX", ddct=exe):
            1 / 0
    assert "tcu exited with status 1" in "".join(getattr(e.value, "__notes__", []))


def test_missing_binary_and_config(tmp_path, monkeypatch):
    monkeypatch.delenv("DDCT_BIN", raising=False)
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.setattr(daemons, "CHECKOUT", tmp_path / "not-a-checkout")
    with pytest.raises(BenchError, match="no ddct binary") as e:
        Bench("vcan0")
    # Every way to provide it, named for a python caller.
    for way in ("pass ddct=PATH", "set DDCT_BIN=PATH", "put ddct on PATH", "cargo install --path .",
                "installed from a ddct checkout in editable mode", "target/release/ddct"):
        assert way in str(e.value), (way, str(e.value))
    with pytest.raises(BenchError, match=r"not found or not executable: .*nope \(from ddct=PATH\)"):
        Bench("vcan0", ddct=tmp_path / "nope")
    monkeypatch.setenv("DDCT_BIN", str(tmp_path / "gone"))
    with pytest.raises(BenchError, match=r"gone \(from \$DDCT_BIN\)"):
        Bench("vcan0")
    exe = tmp_path / "ddct"
    exe.write_text("#!/bin/sh\n")
    exe.chmod(0o755)
    with pytest.raises(BenchError, match="TCU config not found"):
        Bench("vcan0", ddct=exe, tcu_config=tmp_path / "missing.toml")


def executable(path):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("#!/bin/sh\n")
    path.chmod(0o755)
    return path.resolve()


def test_the_binary_is_found_argument_env_path_then_the_checkout(tmp_path, monkeypatch):
    checkout = tmp_path / "checkout"
    (checkout / "python" / "ddct_can").mkdir(parents=True)
    (checkout / "Cargo.toml").write_text("")
    own = executable(checkout / "target" / "release" / "ddct")
    on_path = executable(tmp_path / "bin" / "ddct")
    env = executable(tmp_path / "env" / "ddct")
    arg = executable(tmp_path / "arg" / "ddct")
    monkeypatch.setattr(daemons, "CHECKOUT", checkout)
    monkeypatch.setenv("DDCT_BIN", str(env))
    monkeypatch.setenv("PATH", str(tmp_path / "bin"))
    assert find_ddct(arg) == arg
    assert find_ddct() == env
    monkeypatch.delenv("DDCT_BIN")
    assert find_ddct() == on_path
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert find_ddct() == own  # a developer checkout: its own release build
    own.unlink()
    with pytest.raises(BenchError, match=rf"or build {own} \(cargo build --release in {checkout}\)"):
        find_ddct()
    (checkout / "Cargo.toml").unlink()  # not a checkout (site-packages): never looked at
    own = executable(own)
    with pytest.raises(BenchError, match="no ddct binary"):
        find_ddct()


def test_the_package_knows_the_checkout_it_lives_in():
    """Installed in editable mode (scripts/setup), the package's checkout is this repository."""
    assert daemons.CHECKOUT == Path(__file__).resolve().parents[2]
    assert daemons.checkout_ddct() == daemons.CHECKOUT / "target" / "release" / "ddct"


def test_without_tcu_config_the_tcu_runs_its_built_in_calibration(fake, tmp_path, monkeypatch):
    """No --config (the binary carries config/tcu.toml), whatever the directory holds."""
    exe, log = fake
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "tcu.toml").write_text("# a decoy: must not be used\n")
    monkeypatch.chdir(tmp_path)
    with Bench("vcanX", ddct=exe, workdir=tmp_path / "w"):
        pass
    tcu, plant = calls(log)
    assert tcu["role"] == "tcu" and "--config" not in tcu["args"], tcu["args"]
    assert plant["role"] == "plant" and "--config" not in plant["args"], plant["args"]
