"""The README's quick start, as a new user runs it: a fresh clone in a temporary directory outside
the repository, `scripts/setup && scripts/bench` there (the main job; on the in-process bus so the
test does not depend on the host's CAN), and the bare binary from another directory. Checks the
exit statuses and what the README says they print. The clone builds into this checkout's target
directory (CARGO_TARGET_DIR), so it costs no second build."""

from __future__ import annotations

import json
import os
import re
import subprocess
from pathlib import Path

import ddct_testlib as lib


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
