"""The pytest fixtures come with the installed package (pytest11 entry point) and fail, never
skip, without a CAN interface or a binary. Each check runs pytest in a subprocess on a small test
file of its own."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path


def pytest_in(tmp_path, *args, env=None):
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "no:cacheprovider", *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120, env=env)


def test_fixtures_are_registered(tmp_path):
    out = pytest_in(tmp_path, "--fixtures").stdout
    for name in ("ddct_bin", "ddct_iface", "ddct_bus", "ddct_monitor", "ddct_driver", "ddct_bench"):
        assert f"\n{name}" in out, f"fixture {name} not offered by the plugin:\n{out[-2000:]}"


def test_a_missing_interface_fails_the_test(tmp_path):
    (tmp_path / "test_x.py").write_text("def test_x(ddct_iface):\n    pass\n")
    r = pytest_in(tmp_path, "-rA", "--ddct-iface", "nosuchcan0")
    assert r.returncode == 1, r.stdout
    assert "1 error" in r.stdout and "skipped" not in r.stdout, r.stdout
    assert "nosuchcan0 does not exist" in r.stdout, r.stdout


def test_a_missing_binary_fails_the_test(tmp_path):
    import os

    (tmp_path / "test_x.py").write_text("def test_x(ddct_bin):\n    pass\n")
    env = {k: v for k, v in os.environ.items() if k != "DDCT_BIN"}
    r = pytest_in(tmp_path, "-rA", "--ddct-bin", "/nonexistent/ddct", env=env)
    assert r.returncode == 1, r.stdout
    assert "1 error" in r.stdout and "skipped" not in r.stdout, r.stdout
    assert "ddct binary not found or not executable: /nonexistent/ddct (from --ddct-bin PATH)" in r.stdout, r.stdout


def test_no_binary_anywhere_names_the_option_and_the_variable_once(tmp_path):
    """Without --ddct-bin, DDCT_BIN, ddct on PATH or a checkout's build: the error says how to
    give it to pytest (not the python argument ddct=PATH), once, without a chained traceback."""
    import os

    import shutil

    import ddct_can

    # The package outside a checkout (as from a wheel): a copy of it first on sys.path.
    site = tmp_path / "site"
    shutil.copytree(Path(ddct_can.__file__).parent, site / "ddct_can", ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "test_x.py").write_text(
        "import ddct_can\n\n"
        f"def test_the_copy_is_used():\n    assert ddct_can.__file__.startswith({str(site)!r})\n\n"
        "def test_x(ddct_bin):\n    pass\n")
    env = {k: v for k, v in os.environ.items() if k != "DDCT_BIN"}
    env["PATH"] = str(tmp_path / "empty")
    env["PYTHONPATH"] = str(site)
    r = pytest_in(tmp_path, env=env)
    out = r.stdout
    assert r.returncode == 1, out + r.stderr
    assert "1 passed, 1 error" in out, out
    [line] = [l for l in out.splitlines() if l.startswith("no ddct binary")]
    assert line.startswith("no ddct binary: pass --ddct-bin PATH, set DDCT_BIN=PATH, put ddct on PATH"), line
    assert "ddct=PATH" not in out, out
    assert "BenchError" not in out and "During handling" not in out and "direct cause" not in out, out


def test_the_bench_runs_the_binarys_own_calibration_by_default(tmp_path):
    """ddct_bench without --ddct-tcu-config passes no --config (a decoy config/tcu.toml in the
    invocation directory is not used); with it, that file."""
    import os
    import textwrap

    fake = tmp_path / "ddct"
    fake.write_text(textwrap.dedent(f"""\
        #!{sys.executable}
        import json, os, signal, sys, time
        with open(os.environ["FAKE_LOG"], "a") as f:
            f.write(json.dumps(sys.argv[1:]) + "\\n")
        stop = []
        signal.signal(signal.SIGTERM, lambda *a: stop.append(1))
        args = sys.argv[2:]
        open(args[args.index("--ready-file") + 1], "w").write(str(os.getpid()))
        while not stop:
            time.sleep(0.01)
        print(json.dumps({{"stopped_by": "shutdown"}}))
        """))
    fake.chmod(0o755)
    (tmp_path / "config").mkdir()
    (tmp_path / "config" / "tcu.toml").write_text("# a decoy\n")
    mine = tmp_path / "mine.toml"
    mine.write_text("")
    # No CAN here: the interface and the bus are python-can's virtual ones.
    (tmp_path / "conftest.py").write_text(textwrap.dedent("""\
        import can, pytest

        @pytest.fixture(scope="session")
        def ddct_iface():
            return "vcanX"

        @pytest.fixture
        def ddct_bus():
            with can.Bus(interface="virtual", channel="plugin-test") as bus:
                yield bus
        """))
    (tmp_path / "test_x.py").write_text("def test_x(ddct_bench):\n    ddct_bench.check_running()\n")
    env = {**os.environ, "FAKE_LOG": str(tmp_path / "calls.jsonl")}
    r = pytest_in(tmp_path, "--ddct-bin", str(fake), env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    r = pytest_in(tmp_path, "--ddct-bin", str(fake), "--ddct-tcu-config", "mine.toml", env=env)
    assert r.returncode == 0, r.stdout + r.stderr
    import json

    calls = [json.loads(line) for line in (tmp_path / "calls.jsonl").read_text().splitlines()]
    assert [c[0] for c in calls] == ["tcu", "plant", "tcu", "plant"], calls
    assert "--config" not in calls[0] and "--config" not in calls[1], calls
    assert calls[2][calls[2].index("--config") + 1] == str(mine.resolve()), calls
