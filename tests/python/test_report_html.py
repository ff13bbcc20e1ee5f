"""The HTML report of a bench run (`ddct bench` writes report.html) opened in headless Chromium, as
a user opens it in a browser: it renders (a screenshot of the page that is not blank), the
browser's DOM holds the verdict and the run's tables, the console shows no error, and nothing
outside the file is loaded (self-contained: no <script>, no external reference)."""

from __future__ import annotations

import re
import shutil
import subprocess

import ddct_testlib as lib

SCENARIO = lib.REPO / "config" / "scenarios" / "launch_shift_20s.toml"


def chromium() -> str:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        path = shutil.which(name)
        if path:
            return path
    raise AssertionError("headless Chromium not found: scripts/setup installs the Debian package chromium")


def browse(url: str, *flags: str) -> subprocess.CompletedProcess:
    return subprocess.run([chromium(), "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr",
                           "--v=0", *flags, url], capture_output=True, text=True, timeout=120)


def test_bench_report_opens_in_a_browser(bench_launch_shift, tmp_path):
    out, r = bench_launch_shift  # ddct bench --iface sim --echo 0 --scenario SCENARIO --out out
    assert r.returncode == 0, r.stderr[-2000:]
    report = out / "report.html"
    assert f"bench: report in {report}" in r.stderr
    html = report.read_text()
    assert "<script" not in html and not re.search(r"""(src|href)=["'](?!#)""", html), "not self-contained"
    url = report.as_uri()
    shot = tmp_path / "shot.png"
    s = browse(url, f"--screenshot={shot}", "--window-size=1200,2400")
    assert s.returncode == 0 and shot.exists(), s.stderr[-2000:]
    # A blank 1200×2400 page compresses to a few kB; the tables and figures make it ~300 kB.
    assert shot.stat().st_size > 50_000, shot.stat().st_size
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    console = [line for line in s.stderr.splitlines() if "CONSOLE" in line]
    assert console == [], console
    dom = browse(url, "--dump-dom")
    assert dom.returncode == 0, dom.stderr[-2000:]
    text = dom.stdout
    assert '<p class="result pass">PASS</p>' in text, text[:2000]
    for check in ("lockup_s_max", "shifts_complete", "faults"):
        assert re.search(rf"<td>{check}</td><td class=\"pass\">PASS</td>", text), check
    assert text.count("<svg") == 2 and "Shifts" in text and "DCT_Sensors → TCU_ClutchCmd" in text
