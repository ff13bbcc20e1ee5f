"""The README's quick start beyond the main job, as a new user runs it: the bare binary from
another directory (built-in calibration and scenario), and `cargo install --path .` then `ddct`
from PATH. The main job itself, `scripts/setup && scripts/bench` in a fresh clone, is run on the
user's path (vcan0) and on a machine without any vcan by scripts/test's `main` part
(tests/main/test_main_job.py); this test used to run it a third time on the in-process bus."""

from __future__ import annotations

import os
import re
import subprocess
from pathlib import Path

import ddct_testlib as lib


def sh(cmd: str, cwd: Path, env: dict, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["bash", "-c", cmd], cwd=cwd, env=env, text=True, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=timeout
    )


def test_the_bare_binary_elsewhere_and_cargo_install(tmp_path):
    readme = (lib.REPO / "README.md").read_text()
    assert re.search(r"^scripts/setup && scripts/bench\s+# the main job$", readme, re.M), "the README's main-job command changed"
    env = dict(os.environ)
    env["CARGO_TARGET_DIR"] = str(lib.REPO / "target")
    env.pop("DDCT_BIN", None)
    scenario = lib.REPO / "config" / "scenarios" / "launch_50.toml"
    # The bare binary outside any checkout: built-in calibration and scenario.
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    ddct = lib.REPO / "target" / "release" / "ddct"
    r = sh(f"{ddct} sim --scenario {scenario}", elsewhere, env, timeout=120)
    assert r.returncode == 0 and "PASS" in r.stdout, r.stdout[-3000:]
    # `cargo install --path .` as the README says (into a temporary root, reusing this checkout's
    # build), then `ddct` from PATH in another directory.
    assert "`cargo install --path .` puts it on the `PATH`" in readme.replace("\n", " ")
    root = tmp_path / "cargo-root"
    r = sh(f"cargo install --locked --path . --root {root}", lib.REPO, env, timeout=900)
    assert r.returncode == 0, r.stdout[-3000:]
    path_env = {**env, "PATH": f"{root / 'bin'}:{env['PATH']}"}
    r = sh(f"command -v ddct && ddct --version && ddct sim --scenario {scenario}",
           elsewhere, path_env, timeout=120)
    assert r.returncode == 0, r.stdout[-3000:]
    assert r.stdout.splitlines()[0] == str(root / "bin" / "ddct"), r.stdout[:500]
    assert "PASS" in r.stdout, r.stdout[-3000:]
