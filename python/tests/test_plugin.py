"""The pytest fixtures come with the installed package (pytest11 entry point) and fail, never
skip, without a CAN interface."""

from __future__ import annotations


def test_fixtures_are_registered(pytester):
    result = pytester.runpytest("--fixtures", "-p", "no:cacheprovider")
    out = result.stdout.str()
    for name in ("ddct_bin", "ddct_iface", "ddct_bus", "ddct_monitor", "ddct_driver", "ddct_bench"):
        assert name in out, f"fixture {name} not offered by the plugin"


def test_a_missing_interface_fails_the_test(pytester):
    pytester.makepyfile("def test_x(ddct_iface):\n    pass\n")
    result = pytester.runpytest("--ddct-iface", "nosuchcan0", "-p", "no:cacheprovider")
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*nosuchcan0 does not exist*"])


def test_a_missing_binary_fails_the_test(pytester, monkeypatch):
    monkeypatch.delenv("DDCT_BIN", raising=False)
    pytester.makepyfile("def test_x(ddct_bin):\n    pass\n")
    result = pytester.runpytest("--ddct-bin", "/nonexistent/ddct", "-p", "no:cacheprovider")
    result.assert_outcomes(errors=1)
    result.stdout.fnmatch_lines(["*ddct binary not found or not executable*"])
