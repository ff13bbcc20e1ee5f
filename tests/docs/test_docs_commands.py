"""Every command README.md and docs/ show is run, as written, from the repository root, with
`ddct` on PATH as the README says (`export PATH=$PWD/target/release:$PATH`).

The manifest tests/docs/commands.toml says per command its part and what its output must show:
  host  run by scripts/test's `docs` part (commands that boot User-Mode Linux themselves through
        scripts/vcan-run are host commands too)
  vcan  need vcan0 without saying `scripts/vcan-run` (a machine with vcan): run inside
        scripts/vcan-run by the `vcan:pytest:tests/docs` part
  long  minutes of CPU: run by scripts/test's `docs` part too (most of them in the cpu lane)
A command shown in the docs and missing from the manifest fails, and so does a manifest entry no
page shows any more; a deselected part is not a skip: host and long run in scripts/test's `docs`
part, vcan in its `vcan:pytest:tests/docs:vcan` part.

Lanes. Most commands wait on real time (daemons, User-Mode Linux), a few keep both cores busy for
minutes (the diagnoses, the blind trials, the fleet). Entries with `lane = "cpu"` therefore run
in a second lane, a thread started with the session that runs them one after the other in the
manifest's order, under `nice -n 19` so that the main lane's daemons keep the CPU when they want
it. Their tests come last in the session and wait for the lane's result; everything else runs
in the main lane in the manifest's order, its long commands after the others (conftest.py). A
cpu-lane command may read only what an earlier cpu-lane command or the repository gives it.
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import threading
import time

import pytest

import docs_commands as dc

ENTRIES = dc.manifest()
SHOWN = dc.shown_commands()
COUNTS: dict[str, int] = {}
MAIN_SECONDS: dict[str, float] = {}  # the main lane's commands and their seconds
FIGURES: list[str] = []  # the banded figures measured (printed at the end of the session)


def entry_id(e: dc.Entry) -> str:
    """Where the page shows the command (file:line), and its first words."""
    where = SHOWN[e.cmd].where[0] if e.cmd in SHOWN else "not shown"
    return f"{where} {e.cmd[:60]}"


def env() -> dict:
    e = dict(os.environ)
    e["PATH"] = f"{dc.REPO / 'target' / 'release'}{os.pathsep}{e.get('PATH', '')}"
    e.pop("DDCT_OUT", None)
    return e


def test_every_shown_command_is_in_the_manifest():
    shown = dc.shown_commands()
    known = {e.cmd for e in ENTRIES}
    missing = [f"{s.cmd!r} ({', '.join(s.where)})" for s in shown.values() if s.cmd not in known]
    stale = [c for c in known if c not in shown]
    assert not missing, "commands shown in the docs without a tests/docs/commands.toml entry:\n" + "\n".join(missing)
    assert not stale, "tests/docs/commands.toml entries no page shows:\n" + "\n".join(stale)
    dupes = {e.cmd for e in ENTRIES if sum(x.cmd == e.cmd for x in ENTRIES) > 1}
    assert not dupes, dupes
    by_part = {p: sum(e.part == p for e in ENTRIES) for p in dc.PARTS}
    print(f"\ndocs commands: {len(shown)} shown in {len(dc.doc_files())} pages; by part {by_part}")


def test_no_command_hides_outside_a_sh_block():
    assert not dc.untagged_command_blocks(), (
        "blocks without a language that hold commands (tag them ```sh, or ```text for a synopsis): "
        f"{dc.untagged_command_blocks()}")
    shown = dc.shown_commands()
    loose = [f"{w}: `{c}`" for w, c in dc.inline_commands() if c not in shown]
    assert not loose, ("complete commands in prose that no ```sh block shows (so no test runs them); "
                       "put them in a block, or write a placeholder:\n" + "\n".join(loose))


# How a command the test stopped with SIGINT may end: handled (0), the shell's 128 + SIGINT, or
# killed by it (Popen's negative status).
STOPPED = (0, 128 + signal.SIGINT, -signal.SIGINT)


def run_entry(e: dc.Entry, nice: int = 0, started=None) -> tuple[int, str]:
    """Runs the entry's setup, traffic and command; (exit status, output). `nice`: the niceness
    of everything it starts; `started(popen)`: called with the command's process."""
    shell = ["nice", "-n", str(nice), "bash", "-c"] if nice else ["bash", "-c"]
    for s in e.setup:
        r = subprocess.run([*shell, s], cwd=dc.REPO, env=env(), text=True, stdin=subprocess.DEVNULL,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, timeout=e.timeout_s)
        assert r.returncode == 0, f"setup `{s}` exited {r.returncode}:\n{r.stdout[-3000:]}"
    beside = None
    if e.beside:
        beside = subprocess.Popen(["bash", "-c", e.beside], cwd=dc.REPO, env=env(), stdin=subprocess.DEVNULL,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        time.sleep(0.5)
    try:
        p = subprocess.Popen([*shell, e.cmd], cwd=dc.REPO, env=env(), text=True, stdin=subprocess.DEVNULL,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
        if started:
            started(p)
        try:
            if e.stop_after_s is not None:
                try:
                    out, _ = p.communicate(timeout=e.stop_after_s)
                    return p.returncode, out  # ended by itself before the stop
                except subprocess.TimeoutExpired:
                    os.killpg(p.pid, signal.SIGINT)
                out, _ = p.communicate(timeout=e.timeout_s)
                return (e.exit if p.returncode in STOPPED else p.returncode), out
            out, _ = p.communicate(timeout=e.timeout_s)
            return p.returncode, out
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            out, _ = p.communicate()
            pytest.fail(f"`{e.cmd}` did not end within {e.timeout_s} s:\n{out[-3000:]}")
    finally:
        if beside is not None:
            try:
                os.killpg(beside.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
            beside.wait(30)


class CpuLane:
    """The second lane: the session's selected cpu-lane entries, run one after the other in a
    thread (nice 19); each test waits for its entry's result."""

    NICE = 19

    def __init__(self, entries: list[dc.Entry]):
        self.entries = entries
        self.results: dict[str, tuple] = {}
        self.done = {e.cmd: threading.Event() for e in entries}
        self.seconds: dict[str, float] = {}
        self.proc = None
        self.stopping = False
        self.t0 = time.monotonic()
        self.thread = threading.Thread(target=self._run, name="docs-cpu-lane", daemon=True)
        self.thread.start()

    def _started(self, p):
        self.proc = p

    def _run(self):
        try:
            for e in self.entries:
                if self.stopping:
                    self.results[e.cmd] = ("stopped", "the session ended before the cpu lane ran this command")
                else:
                    t0 = time.monotonic()
                    try:
                        self.results[e.cmd] = ("ran", run_entry(e, nice=self.NICE, started=self._started))
                    except BaseException as x:  # noqa: BLE001 (pytest.fail's Failed, an assertion, anything)
                        self.results[e.cmd] = ("raised", x)
                    self.seconds[e.cmd] = time.monotonic() - t0
                    self.proc = None
                self.done[e.cmd].set()
        finally:
            self.wall = time.monotonic() - self.t0
            for cmd, done in self.done.items():  # the lane itself failed: no test waits for ever
                if not done.is_set():
                    self.results.setdefault(cmd, ("stopped", "the cpu lane ended before it ran this command"))
                    done.set()

    def result(self, e: dc.Entry) -> tuple[int, str]:
        self.done[e.cmd].wait()
        how, what = self.results[e.cmd]
        if how == "raised":
            raise what
        if how == "stopped":
            pytest.fail(what)
        return what

    def stop(self):
        self.stopping = True
        p = self.proc
        if p is not None and p.poll() is None:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        self.thread.join(60)


LANE: CpuLane | None = None


@pytest.fixture(scope="session", autouse=True)
def cpu_lane(request):
    """Starts the cpu lane with the session's first test, over the cpu-lane entries the session
    selected (conftest.py puts their tests last)."""
    global LANE
    entries = [item.callspec.params["entry"] for item in request.session.items
               if getattr(item, "callspec", None) and "entry" in item.callspec.params
               and item.callspec.params["entry"].lane == "cpu"]
    LANE = CpuLane(entries) if entries else None
    yield LANE
    if LANE is not None:
        LANE.stop()


def test_covered_commands_are_run_by_the_test_that_claims_them():
    """A command another test runs (the main job, the whole suite) must be written in that test
    as shown, so the docs and the test cannot drift apart."""
    for e in ENTRIES:
        if e.covered_by:
            text = (dc.REPO / e.covered_by).read_text()
            if e.covered_as:
                assert e.covered_as in text, f"{e.covered_by} does not run `{e.cmd}` (no {e.covered_as!r} in it)"
                continue
            parts = [p.strip() for p in e.cmd.split("&&")]
            assert e.cmd in text or all(p in text for p in parts), f"{e.covered_by} does not run `{e.cmd}`"


@pytest.mark.parametrize(
    "entry",
    [pytest.param(e, id=entry_id(e), marks=getattr(pytest.mark, e.part)) for e in ENTRIES if not e.covered_by],
)
def test_command(entry: dc.Entry):
    if entry.lane == "cpu":
        rc, out = LANE.result(entry)
    else:
        t0 = time.monotonic()
        rc, out = run_entry(entry)
        MAIN_SECONDS[entry.cmd] = time.monotonic() - t0
    assert "panicked at" not in out, out[-4000:]
    assert rc == entry.exit, f"`{entry.cmd}` exited {rc}, expected {entry.exit}:\n{out[-4000:]}"
    for pat in entry.expect:
        assert re.search(pat, out, re.M), f"`{entry.cmd}`: no match for {pat!r} in its output:\n{out[-4000:]}"
    for pat in entry.refuse:
        assert not re.search(pat, out, re.M), f"`{entry.cmd}`: {pat!r} in its output:\n{out[-4000:]}"
    for pat, lo, hi in entry.bands:
        v = dc.band_figure(pat, out)
        assert v is not None, f"`{entry.cmd}`: no match for the band's {pat!r} in its output:\n{out[-4000:]}"
        assert lo <= v <= hi, f"`{entry.cmd}`: {v:.4g} from {pat!r} is outside {lo}..{hi}:\n{out[-4000:]}"
        FIGURES.append(f"{v:.4g} in {lo}..{hi} ({pat[:50]}…)")
    COUNTS[entry.part] = COUNTS.get(entry.part, 0) + 1
