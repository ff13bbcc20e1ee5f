"""The README's main job exactly as a new user runs it: `scripts/setup && scripts/bench` in a
fresh clone of this repository, with no environment override, so the bench runs on vcan0 (the host
kernel's, or User-Mode Linux through scripts/vcan-run) — the user's path, not an easier one.

The clone is of HEAD (what CI clones). Where this checkout's sources are HEAD's (no uncommitted
change to what cargo builds), its build cache (target/release) is copied into the clone, and the
clone's files are dated back so that cargo, comparing dates, takes the cache for what it is: the
build of the same sources. That changes no path the user's commands take: the clone runs its own
setup (its own .venv) and its own `cargo build`, which finds nothing to do. With uncommitted
changes the cache is not copied (it would be the build of other sources), and the clone builds
from scratch.

Second case: on a machine with neither vcan nor User-Mode Linux (DDCT_VCAN_MODE=none makes
scripts/vcan-run answer as it does there) scripts/bench says what to do and runs on the in-process
bus.

Run by scripts/test's `main` part on the host (scripts/bench boots User-Mode Linux itself)."""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
MAIN_JOB = "scripts/setup && scripts/bench"
# Variables that would change the path the README's commands take.
OVERRIDES = ("DDCT_OUT", "DDCT_BENCH_IFACE", "DDCT_BENCH_SCENARIO", "DDCT_BENCH_ECHO", "DDCT_VCAN_MODE",
             "CARGO_TARGET_DIR", "DDCT_BIN", "VIRTUAL_ENV")


def user_env() -> dict:
    env = {k: v for k, v in os.environ.items() if k not in OVERRIDES}
    # The user's shell: no venv of the test runner on PATH.
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep) if "/.venv/" not in p + "/")
    return env


@pytest.fixture(scope="module")
def clone(tmp_path_factory) -> Path:
    dest = tmp_path_factory.mktemp("fresh") / "ddct"
    subprocess.run(["git", "clone", "-q", str(REPO), str(dest)], check=True, timeout=300)
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=REPO, text=True,
                           capture_output=True).stdout
    if dirty:
        print(f"\nnote: the clone is of HEAD; uncommitted changes are not in it:\n{dirty}")
    built_from_head = not any(
        line[3:].startswith(("src/", "build.rs", "Cargo.", "dbc/", "config/", "benches/"))
        for line in dirty.splitlines())
    cache = REPO / "target" / "release"
    if built_from_head:
        # The cache is the build of this checkout's sources (HEAD's) once this has run.
        subprocess.run(["cargo", "build", "--release", "--quiet", "--bin", "ddct"], cwd=REPO, check=True,
                       timeout=2400, env={k: v for k, v in os.environ.items() if k != "CARGO_TARGET_DIR"})
    if cache.is_dir() and built_from_head:
        files = subprocess.run(["git", "ls-files", "-z"], cwd=dest, capture_output=True, check=True).stdout
        subprocess.run(["xargs", "-0", "touch", "-h", "-d", "@946684800"], cwd=dest, input=files, check=True)
        (dest / "target").mkdir()
        subprocess.run(["cp", "-a", str(cache), str(dest / "target" / "release")], check=True, timeout=600)
    return dest


def test_readme_main_job_passes_on_vcan0_from_a_fresh_clone(clone):
    readme = (REPO / "README.md").read_text()
    assert re.search(rf"^{re.escape(MAIN_JOB)}\s+# the main job$", readme, re.M), "the README's main job changed"
    r = subprocess.run(["bash", "-c", MAIN_JOB], cwd=clone, env=user_env(), text=True, stdin=subprocess.DEVNULL,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=2400)
    out = r.stdout
    (REPO / "target" / "test-logs").mkdir(parents=True, exist_ok=True)
    (REPO / "target" / "test-logs" / "main_job_output.txt").write_text(out)
    assert "panicked" not in out, out[-5000:]
    assert r.returncode == 0, out[-5000:]
    assert "setup: done" in out
    # On vcan0 (User-Mode Linux here, or the host's), never the in-process fallback.
    assert re.search(r"^vcan-run: vcan0 (on the host kernel|in User-Mode Linux)", out, re.M), out[-3000:]
    assert "Running on the in-process bus" not in out
    assert re.search(r"^== ddct bench: launch_shift_20s on vcan0 ", out, re.M), out[-3000:]
    # The verdict: every check of the scenario's [limits] passed.
    rows = re.findall(r"^launch_shift_20s +(\S+) +(PASS|FAIL) ", out, re.M)
    assert len(rows) >= 10 and all(v == "PASS" for _, v in rows), rows
    bench = clone / "out" / "bench"
    summary = json.loads((bench / "summary.json").read_text())
    assert summary["iface"] == "vcan0" and summary["scenario"] == "launch_shift_20s"
    assert all(c["pass"] for c in summary["verdict"]), summary["verdict"]
    assert summary["bus"]["launches"] and summary["timing"]["echo_latency"]["n"] > 0
    html = (bench / "report.html").read_text()
    assert "launch_shift_20s" in html and "<svg" in html
    svgs = sorted(p.name for p in bench.glob("*.svg"))
    assert svgs == ["launch_shift_20s_bus.svg", "launch_shift_20s_sim.svg"], svgs
    for p in bench.glob("*.svg"):
        assert p.read_text().lstrip().startswith("<svg"), p
    print(f"\nmain job on vcan0 from a fresh clone: exit 0, {len(rows)} checks PASS")


def test_bench_without_any_vcan_says_what_to_do_and_runs_in_process(clone):
    """Neither vcan nor User-Mode Linux (DDCT_VCAN_MODE=none): the bench names the ways to get a
    bus and still runs on the in-process bus."""
    env = user_env() | {"DDCT_VCAN_MODE": "none", "DDCT_BENCH_ECHO": "1", "DDCT_OUT": str(clone / "out" / "nobus")}
    r = subprocess.run(["scripts/bench"], cwd=clone, env=env, text=True, stdin=subprocess.DEVNULL,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=1200)
    out = r.stdout
    assert r.returncode == 0, out[-4000:]
    assert "no vcan0 here" in out and "run scripts/setup" in out and "ip link add dev vcan0 type vcan" in out, out
    assert re.search(r"^== ddct bench: launch_shift_20s on sim ", out, re.M), out[-3000:]
