"""The README's quick start, as a new user runs it: a fresh clone in a temporary directory outside
the repository, `scripts/setup && scripts/bench` there (the main job; on the in-process bus so the
test does not depend on the host's CAN), and the bare binary from another directory. Checks the
exit statuses and what the README says they print. The clone builds into this checkout's target
directory (CARGO_TARGET_DIR). Where this checkout's build inputs are HEAD's, the clone's files are
dated back, as tests/main does, so that cargo takes that directory's build for what it is, the
build of the same sources: a clone's files are newer than the build, and without that cargo
compiled ddct again (minutes on two cores)."""

from __future__ import annotations

import json
import os
import re
import subprocess
from pathlib import Path

import ddct_testlib as lib

# What cargo builds ddct from (as tests/main/test_main_job.py counts it).
BUILD_INPUTS = ("src/", "build.rs", "Cargo.", "dbc/", "config/", "benches/")


def sh(cmd: str, cwd: Path, env: dict, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", "-c", cmd], cwd=cwd, env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout
    )


def test_readme_quick_start_from_a_fresh_clone(tmp_path):
    readme = (lib.REPO / "README.md").read_text()
    main_job = "scripts/setup && scripts/bench"
    assert re.search(rf"^{re.escape(main_job)}\s+# the main job$", readme, re.M), "the README's main-job command changed"
    clone = tmp_path / "ddct"
    subprocess.run(["git", "clone", "-q", str(lib.REPO), str(clone)], check=True, timeout=300)
    env = dict(os.environ)
    env.update(
        CARGO_TARGET_DIR=str(lib.REPO / "target"),
        DDCT_BENCH_IFACE="sim",
        DDCT_BENCH_ECHO="2",
        DDCT_OUT=str(tmp_path / "bench"),
    )
    env.pop("DDCT_BIN", None)
    dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=lib.REPO, text=True,
                           capture_output=True, check=True).stdout
    if not any(line[3:].startswith(BUILD_INPUTS) for line in dirty.splitlines()):
        # The target directory holds the build of HEAD's sources once this has run (a no-op after
        # scripts/test's build part); the clone's files, older than it, are then up to date.
        subprocess.run(["cargo", "build", "--release", "--quiet", "--bin", "ddct"], cwd=lib.REPO, env=env,
                       check=True, timeout=2400)
        files = subprocess.run(["git", "ls-files", "-z"], cwd=clone, capture_output=True, check=True).stdout
        subprocess.run(["xargs", "-0", "touch", "-h", "-d", "@946684800"], cwd=clone, input=files, check=True)
    r = sh(main_job, clone, env)
    out = r.stdout
    assert r.returncode == 0, out[-4000:]
    assert "setup: done" in out, out[-2000:]
    # The summary tables, the verdict and where everything went, as the README describes.
    assert re.search(r"^launch_shift_20s +lockup_s_max +PASS ", out, re.M), out[-4000:]
    assert "FAIL" not in out, out[-4000:]
    assert "summary.json" in out
    summary = json.loads((tmp_path / "bench" / "summary.json").read_text())
    assert summary["scenario"] == "launch_shift_20s" and summary["bus"]["launches"], summary.keys()
    assert all(c["pass"] for c in summary["verdict"]), summary["verdict"]
    assert list((tmp_path / "bench").glob("*.svg")), list((tmp_path / "bench").iterdir())
    # The bare binary outside any checkout: built-in calibration and scenario.
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    ddct = lib.REPO / "target" / "release" / "ddct"
    r = sh(f"{ddct} sim --scenario {clone}/config/scenarios/launch_50.toml", elsewhere, env, timeout=120)
    assert r.returncode == 0 and "PASS" in r.stdout, r.stdout[-3000:]
    # `cargo install --path .` as the README says (into a temporary root, reusing this checkout's
    # build), then `ddct` from PATH in another directory.
    assert "`cargo install --path .` puts it on the `PATH`" in readme.replace("\n", " ")
    root = tmp_path / "cargo-root"
    r = sh(f"cargo install --locked --path . --root {root}", lib.REPO, env, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:]
    path_env = {**env, "PATH": f"{root / 'bin'}:{env['PATH']}"}
    r = sh(f"command -v ddct && ddct --version && ddct sim --scenario {clone}/config/scenarios/launch_50.toml",
           elsewhere, path_env, timeout=120)
    assert r.returncode == 0, r.stdout[-3000:]
    assert r.stdout.splitlines()[0] == str(root / "bin" / "ddct"), r.stdout[:500]
    assert "PASS" in r.stdout, r.stdout[-3000:]
