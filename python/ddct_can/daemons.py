"""The plant and TCU daemons of ``ddct`` on a CAN interface, as a context manager.

    with Bench("vcan0") as bench:  # the binary: find_ddct(); the calibrations: the binary's own
        ...                        # both daemons listen on vcan0
    bench.tcu_report               # the TCU's JSON exit report

The TCU starts first and the plant once the TCU listens (each writes its ready file once its
socket is open and its signal handlers are installed); leaving the block stops the plant, then
the TCU, with SIGTERM and checks that each exited with status 0 and wrote its exit report.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Optional, Sequence, Union

PathLike = Union[str, Path]


class BenchError(RuntimeError):
    """A daemon could not start, died, did not stop, or exited with a failure."""


# A developer checkout with the package installed in editable mode (pip install -e python):
# python/ddct_can/ -> the checkout's root, which holds Cargo.toml and target/release/ddct.
CHECKOUT = Path(__file__).resolve().parents[2]


def checkout_ddct() -> Optional[Path]:
    """``target/release/ddct`` of the ddct checkout this package lives in (None when the package
    is not in a checkout, e.g. installed into site-packages)."""
    return CHECKOUT / "target" / "release" / "ddct" if (CHECKOUT / "Cargo.toml").is_file() else None


def find_ddct(ddct: Optional[PathLike] = None, given_as: str = "ddct=PATH") -> Path:
    """The ddct binary: ``ddct`` if given, else $DDCT_BIN, else ``ddct`` on PATH, else (a
    developer checkout, the package installed in editable mode) ``target/release/ddct`` of the
    checkout this package lives in, if built. ``given_as`` is how the error names the explicit
    way (the python argument; a pytest option or a command-line flag for their callers)."""
    own = checkout_ddct()
    for how, cand in (
        (given_as, ddct or None),
        ("$DDCT_BIN", os.environ.get("DDCT_BIN") or None),
        ("PATH", shutil.which("ddct")),
        ("this checkout", own if own is not None and own.exists() else None),
    ):
        if cand:
            path = Path(cand).expanduser().resolve()
            if not (path.is_file() and os.access(path, os.X_OK)):
                raise BenchError(f"ddct binary not found or not executable: {path} (from {how})")
            return path
    build = (f"or build {own} (cargo build --release in {CHECKOUT})" if own is not None else
             "or, with this package installed from a ddct checkout in editable mode (pip install -e "
             "python), build the checkout's target/release/ddct (cargo build --release)")
    raise BenchError(f"no ddct binary: pass {given_as}, set DDCT_BIN=PATH, put ddct on PATH (cargo "
                     f"install --path . in a ddct checkout puts it in ~/.cargo/bin), {build}")


class Daemon:
    """One running daemon: its process, its output files and ready file."""

    def __init__(self, name: str, cmd: list, workdir: Path, cwd: Optional[PathLike], prefix: str = ""):
        self.name = name
        self.cmd = cmd
        self.ready = workdir / f"{prefix}{name}.ready"
        self.stdout_path = workdir / f"{prefix}{name}.json"
        self.stderr_path = workdir / f"{prefix}{name}.stderr"
        self.ready.unlink(missing_ok=True)
        with open(self.stdout_path, "w") as out, open(self.stderr_path, "w") as err:
            self.proc = subprocess.Popen(cmd + ["--ready-file", str(self.ready)], stdout=out, stderr=err,
                                         stdin=subprocess.DEVNULL, cwd=cwd)
        self.returncode: Optional[int] = None
        self.stop_s: Optional[float] = None

    def stderr(self) -> str:
        try:
            return self.stderr_path.read_text(errors="replace")[-4000:]
        except OSError:
            return ""

    def report(self) -> Optional[dict]:
        """The daemon's --json exit report, or None when it wrote none."""
        try:
            text = self.stdout_path.read_text()
        except OSError:
            return None
        try:
            return json.loads(text) if text.strip() else None
        except json.JSONDecodeError:
            return None

    def wait_ready(self, timeout: float) -> None:
        end = time.monotonic() + timeout
        while not self.ready.exists():
            if self.proc.poll() is not None:
                raise BenchError(f"the {self.name} exited with {self.proc.returncode} before it listened "
                                 f"({' '.join(self.cmd)}):\n{self.stderr()}")
            if time.monotonic() > end:
                raise BenchError(f"the {self.name} did not listen within {timeout} s:\n{self.stderr()}")
            time.sleep(0.01)

    def stop(self, timeout: float) -> Optional[str]:
        """SIGTERM, wait; a problem as text (killed, nonzero status, no report) or None. The time
        from SIGTERM to the exit is kept in ``stop_s`` (None when it had already exited)."""
        if self.proc.poll() is None:
            t0 = time.monotonic()
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=timeout)
                self.stop_s = time.monotonic() - t0
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
                return f"the {self.name} did not stop within {timeout} s of SIGTERM (killed)"
        self.returncode = self.proc.returncode
        if self.returncode != 0:
            return f"the {self.name} exited with status {self.returncode}:\n{self.stderr()}"
        if self.report() is None:
            return f"the {self.name} wrote no JSON exit report:\n{self.stderr()}"
        return None


class Bench:
    """The plant and TCU daemons on ``iface``.

    ``ddct``: the binary (default: ``find_ddct()``: $DDCT_BIN, then ``ddct`` on PATH, then the
    ``target/release/ddct`` of the checkout an editable install lives in).
    ``tcu_config``/``plant_config``: their configuration files (default: none passed, so each
    daemon runs with the calibration built into the binary, ``config/tcu.toml`` and
    ``config/plant.toml`` of its source: the same from any directory). ``tcu_args``/
    ``plant_args``: further flags (e.g. ``["--faults", F]``; relative paths resolve in ``cwd``).
    ``workdir``: where the daemons' reports (``PREFIXtcu.json``, ``PREFIXplant.json``), stderr
    and ready files go (default: a temporary directory, removed on exit unless ``keep=True``).
    ``cwd``: the daemons' working directory. A plant given ``--duration`` may exit by itself
    (``wait_plant()``); stopping then only checks its exit status.
    """

    def __init__(
        self,
        iface: str = "vcan0",
        ddct: Optional[PathLike] = None,
        tcu_config: Optional[PathLike] = None,
        plant_config: Optional[PathLike] = None,
        tcu_args: Sequence[str] = (),
        plant_args: Sequence[str] = (),
        workdir: Optional[PathLike] = None,
        cwd: Optional[PathLike] = None,
        ready_timeout: float = 30.0,
        stop_timeout: float = 30.0,
        keep: bool = False,
        prefix: str = "",
    ):
        self.iface = iface
        self.ddct = find_ddct(ddct)
        self.tcu_config = None if tcu_config is None else Path(tcu_config).resolve()
        self.plant_config = None if plant_config is None else Path(plant_config).resolve()
        for what, p in (("TCU", self.tcu_config), ("plant", self.plant_config)):
            if p is not None and not p.is_file():
                raise BenchError(f"{what} config not found: {p}")
        self.tcu_args = [str(a) for a in tcu_args]
        self.plant_args = [str(a) for a in plant_args]
        self._workdir = workdir
        self.cwd = cwd
        self.ready_timeout = ready_timeout
        self.stop_timeout = stop_timeout
        self.keep = keep
        self.prefix = prefix
        self.tcu: Optional[Daemon] = None
        self.plant: Optional[Daemon] = None
        self.restarts = 0
        self.tcu_report: Optional[dict] = None
        self.plant_report: Optional[dict] = None
        self._tmp: Optional[tempfile.TemporaryDirectory] = None

    def start(self) -> "Bench":
        if self._workdir is None:
            self._tmp = tempfile.TemporaryDirectory(prefix="ddct-bench-")
            self.workdir = Path(self._tmp.name)
        else:
            self.workdir = Path(self._workdir)
            self.workdir.mkdir(parents=True, exist_ok=True)
        tcu = [str(self.ddct), "tcu", "--iface", self.iface, "--json"]
        if self.tcu_config is not None:
            tcu += ["--config", str(self.tcu_config)]
        plant = [str(self.ddct), "plant", "--iface", self.iface, "--json"]
        if self.plant_config is not None:
            plant += ["--config", str(self.plant_config)]
        try:
            self.tcu = Daemon("tcu", tcu + self.tcu_args, self.workdir, self.cwd, self.prefix)
            self.tcu.wait_ready(self.ready_timeout)
            self.plant = Daemon("plant", plant + self.plant_args, self.workdir, self.cwd, self.prefix)
            self.plant.wait_ready(self.ready_timeout)
        except BaseException:
            self._stop_all()
            raise
        return self

    def _daemon(self, which: str) -> Daemon:
        d = {"tcu": self.tcu, "plant": self.plant}.get(which)
        if d is None:
            raise BenchError(f"no running bench daemon {which!r} (\"tcu\" or \"plant\"; start() the bench first)")
        return d

    def kill(self, which: str) -> None:
        """SIGKILL the ``"tcu"`` or the ``"plant"`` (a crash: no exit report)."""
        d = self._daemon(which)
        if d.proc.poll() is None:
            d.proc.kill()
            d.proc.wait()

    def restart(self, which: str) -> None:
        """Start the ``"tcu"`` or the ``"plant"`` again with the same command once it has exited
        (after ``kill()``), and wait until it listens. The new process's report, stderr and ready
        file are named ``PREFIXrestartN_tcu.json`` and so on."""
        d = self._daemon(which)
        if d.proc.poll() is None:
            raise BenchError(f"the {which} is still running: kill() it first")
        self.restarts += 1
        new = Daemon(which, d.cmd, self.workdir, self.cwd, f"{self.prefix}restart{self.restarts}_")
        setattr(self, which, new)
        new.wait_ready(self.ready_timeout)

    def wait_plant(self, timeout: float) -> int:
        """Wait for a plant run with ``--duration`` to exit by itself; its exit status."""
        assert self.plant is not None, "the bench is not started"
        return self.plant.proc.wait(timeout=timeout)

    def check_running(self) -> None:
        """Raise BenchError when a daemon has exited."""
        for d in (self.tcu, self.plant):
            if d is not None and d.proc.poll() is not None:
                raise BenchError(f"the {d.name} exited with {d.proc.returncode}:\n{d.stderr()}")

    def _stop_all(self) -> list:
        problems = []
        for d in (self.plant, self.tcu):  # the plant first: the TCU then sees its inputs stop
            if d is not None:
                p = d.stop(self.stop_timeout)
                if p:
                    problems.append(p)
        self.tcu_report = self.tcu.report() if self.tcu else None
        self.plant_report = self.plant.report() if self.plant else None
        if self._tmp is not None and not self.keep:
            self._tmp.cleanup()
            self._tmp = None
        return problems

    def stop(self) -> None:
        """Stop both daemons (SIGTERM); BenchError when one did not exit cleanly with a report."""
        problems = self._stop_all()
        if problems:
            raise BenchError("\n".join(problems))

    def __enter__(self) -> "Bench":
        return self.start()

    def __exit__(self, exc_type, exc, tb) -> None:
        problems = self._stop_all()
        if problems:
            err = BenchError("\n".join(problems))
            if exc_type is None:
                raise err
            if hasattr(exc, "add_note"):
                exc.add_note(f"and stopping the bench: {err}")
