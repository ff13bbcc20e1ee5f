"""The pytest fixtures come with the installed package (pytest11 entry point) and fail, never
skip, without a CAN interface or a binary. Each check runs pytest in a subprocess on a small test
file of its own."""

from __future__ import annotations

import subprocess
import sys


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
    assert "ddct binary not found or not executable" in r.stdout, r.stdout
