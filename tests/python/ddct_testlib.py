"""Shared helpers of ddct's python test suites (tests/python, tests/vcan).

A tool a test needs (the ddct binary, candump, ...) that is missing makes the test FAIL, not skip,
in the plain python suite and whenever DDCT_REQUIRE_VCAN=1 (set by scripts/vcan-run). Only a vcan
suite run by hand outside scripts/vcan-run may skip.
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

try:
    import ddct_can
except ModuleNotFoundError as e:  # the package python/ddct_can, installed into .venv by scripts/setup
    raise ImportError(f"the ddct_can package is not installed in {sys.executable}: run scripts/setup "
                      "(it does pip install -e ./python)") from e

DDCT_TIMEOUT_S = 300


def vcan_required() -> bool:
    return os.environ.get("DDCT_REQUIRE_VCAN") == "1"


def missing(what: str, may_skip: bool = False):
    """Fail (or, for a vcan suite outside vcan-run, skip) because `what` is missing."""
    if may_skip and not vcan_required():
        pytest.skip(f"{what} (run this suite through scripts/vcan-run)")
    pytest.fail(f"{what}", pytrace=False)


def ddct_bin(may_skip: bool = False) -> Path:
    path = Path(os.environ.get("DDCT_BIN", REPO / "target" / "release" / "ddct"))
    if not path.is_absolute():
        path = REPO / path
    if not (path.is_file() and os.access(path, os.X_OK)):
        missing(f"ddct binary not found at {path} (cargo build --release, or set DDCT_BIN)", may_skip)
    return path


ARPHRD_CAN = 280
IFF_UP = 0x1


def require_vcan(iface: str = "vcan0") -> str:
    """The interface name when it exists, is a CAN interface and is up; otherwise missing()."""
    sysfs = Path("/sys/class/net") / iface
    if not sysfs.exists():
        missing(f"{iface} does not exist", may_skip=True)
    if int((sysfs / "type").read_text()) != ARPHRD_CAN:
        missing(f"{iface} is not a CAN interface", may_skip=True)
    if not int((sysfs / "flags").read_text(), 16) & IFF_UP:
        missing(f"{iface} is down", may_skip=True)
    return iface


def tool(name: str, may_skip: bool = False) -> str:
    found = shutil.which(name)
    if not found:
        missing(f"{name} not found on PATH (scripts/setup installs it)", may_skip)
    return found


def run(args, timeout=DDCT_TIMEOUT_S, check=True, **kw) -> subprocess.CompletedProcess:
    """Run a command, capture text output; on failure the assertion shows stderr."""
    proc = subprocess.run(
        [str(a) for a in args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
        timeout=timeout,
        cwd=kw.pop("cwd", REPO),
        **kw,
    )
    if check:
        assert proc.returncode == 0, (
            f"{' '.join(map(str, args))} exited {proc.returncode}\n"
            f"stdout:\n{proc.stdout[-4000:]}\nstderr:\n{proc.stderr[-4000:]}"
        )
    return proc


def run_together(commands: dict, timeout=DDCT_TIMEOUT_S) -> dict:
    """{key: args} run at the same time, {key: CompletedProcess} (check=False). For runs that wait
    on real time with little CPU (a bench on the in-process bus: 20 s for about 1 s of CPU), so
    that their waits overlap instead of adding up."""
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(max_workers=max(1, len(commands))) as pool:
        futures = {k: pool.submit(run, args, timeout, False) for k, args in commands.items()}
        return {k: f.result() for k, f in futures.items()}


def json_lines(text: str) -> list:
    out = []
    for n, line in enumerate(text.splitlines(), 1):
        if line.strip():
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError as e:
                raise AssertionError(f"line {n} of the output is not JSON ({e}): {line!r}") from None
    return out


def raw_value(sig, value):
    """A physical value or a choice name (from any tool) as the signal's raw integer."""
    if isinstance(value, str):
        if sig.choices:
            for raw, name in sig.choices.items():
                if str(name) == value:
                    return int(raw)
        raise AssertionError(f"{sig.name}: {value!r} is not a choice of the signal")
    return sig.conversion.scaled_to_raw(value)


def signal_mismatches(msg, expected: dict, actual: dict, what: str = "") -> list[str]:
    """Differences between two {signal: value} maps of one message.

    Physical values agree when they differ by at most half a resolution step; signals with a
    value table are compared by raw value. Both maps must name the same signals.
    """
    problems = []
    if set(expected) != set(actual):
        problems.append(
            f"{msg.name}{what}: signal names differ: only expected {sorted(set(expected) - set(actual))}, "
            f"only actual {sorted(set(actual) - set(expected))}"
        )
    for name in sorted(set(expected) & set(actual)):
        sig = msg.get_signal_by_name(name)
        e, a = expected[name], actual[name]
        if sig.choices or isinstance(e, str) or isinstance(a, str):
            if round(raw_value(sig, e)) != round(raw_value(sig, a)):
                problems.append(f"{msg.name}.{name}{what}: expected {e!r}, got {a!r} (raw compare)")
            continue
        if a is None or not isinstance(a, (int, float)) or not math.isfinite(a):
            problems.append(f"{msg.name}.{name}{what}: got {a!r}")
            continue
        if abs(float(e) - float(a)) > abs(sig.scale) / 2 * (1 + 1e-9):
            problems.append(f"{msg.name}.{name}{what}: expected {e!r}, got {a!r} (step {sig.scale})")
    return problems


_CANTOOLS_LINE = re.compile(r"^\((?P<t>[\d.]+)\)\s+(?P<iface>\S+)\s+(?P<id>[0-9A-Fa-f]+)#(?P<data>[0-9A-Fa-f]*)\s+::\s+(?P<rest>.*)$")
_CANTOOLS_MSG = re.compile(r"^(?P<name>\w+)\((?P<body>.*)\)$")


def cantools_decode_log(path: Path) -> list[dict]:
    """Run `python -m cantools decode --single-line --no-decode-choices` on a candump -l file.

    Returns one {"id", "data", "name", "signals"} per line ("error" when cantools rejected it).
    """
    with open(path, "rb") as f:
        proc = subprocess.run(
            [sys.executable, "-m", "cantools", "decode", "-s", "-c", str(ddct_can.DBC_PATH)],
            stdin=f,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            timeout=DDCT_TIMEOUT_S,
        )
    assert proc.returncode == 0, f"cantools decode failed: {proc.stderr}"
    out = []
    for line in proc.stdout.splitlines():
        m = _CANTOOLS_LINE.match(line.strip())
        assert m, f"unexpected cantools decode line: {line!r}"
        rec = {"id": int(m["id"], 16), "data": bytes.fromhex(m["data"]), "name": None, "signals": {}}
        mm = _CANTOOLS_MSG.match(m["rest"])
        if not mm:
            rec["error"] = m["rest"]
        else:
            rec["name"] = mm["name"]
            for part in filter(None, (p.strip() for p in mm["body"].split(","))):
                key, _, val = part.partition(":")
                rec["signals"][key.strip()] = float(val.strip().split()[0])
        out.append(rec)
    return out


def sample_frames() -> list[dict]:
    """Frames python encodes with cantools + E2E: every message at min, mid and max (a transport
    message, ISO-TP or XCP, has no signals: its three frames are eight zero bytes).

    For each protected message the counters are 0, 1, 2 in the order min, mid, max, so that a
    sequence checker sees them as consecutive.
    """
    frames = []
    for msg in ddct_can.load_dbc().messages:
        for counter, (case, signals) in enumerate(ddct_can.signal_cases(msg).items()):
            data = ddct_can.encode(msg.name, signals, counter=counter)
            frames.append({"id": msg.frame_id, "name": msg.name, "case": case, "signals": signals, "data": data})
    return frames


def write_candump(path: Path, frames: list[dict], iface: str = "vcan0", t0: float = 1_700_000_000.0, dt: float = 0.001):
    with open(path, "w", encoding="ascii") as f:
        for i, fr in enumerate(frames):
            f.write(ddct_can.candump_line(t0 + i * dt, iface, fr["id"], fr["data"]) + "\n")
