"""`ddct log decode`'s progress display: drawn on stderr only when stderr is a terminal (a bar by
bytes for a file, a spinner counting frames for standard input); with stdout on the same
terminal the decoded lines all reach the screen whole; in pipes nothing changes."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import struct
import subprocess
import tempfile
import termios

import pytest

import ddct_testlib as lib

COLUMNS = 300


@pytest.fixture(scope="module")
def log(tmp_path_factory):
    frames = lib.sample_frames() * 400
    path = tmp_path_factory.mktemp("progress") / "long.log"
    lib.write_candump(path, frames)
    return path


def _on_terminal(args, stdout_too: bool, stdin=None) -> tuple[str, bytes]:
    """Runs `args` with stderr (and stdout when `stdout_too`) on a pseudo-terminal of COLUMNS
    columns; returns what the terminal received, and stdout (through a file) otherwise."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 50, COLUMNS, 0, 0))
    with tempfile.TemporaryFile() as out, open(stdin or os.devnull, "rb") as inp:
        try:
            proc = subprocess.Popen(
                [str(a) for a in args],
                stdout=slave if stdout_too else out,
                stderr=slave,
                stdin=inp,
                cwd=lib.REPO,
            )
            os.close(slave)
            received = b""
            while True:
                try:
                    chunk = os.read(master, 65536)
                except OSError:  # EIO once the child closed the terminal
                    break
                if not chunk:
                    break
                received += chunk
            assert proc.wait(timeout=lib.DDCT_TIMEOUT_S) == 0, received[-2000:]
        finally:
            os.close(master)
        out.seek(0)
        return received.decode(), out.read()


def _screen_lines(text: str) -> list[str]:
    """The lines left on a terminal: `\\r` returns to the line start, ESC[2K erases the line."""
    lines, cur = [], ""
    for tok in re.split(r"(\r\n|\r|\x1b\[2K|\x1b\[\d*[A-Za-z])", text):
        if tok == "\r\n":
            lines.append(cur)
            cur = ""
        elif tok == "\x1b[2K":
            cur = ""
        elif tok == "\r" or tok.startswith("\x1b["):
            assert not re.fullmatch(r"\x1b\[\d*[AB]", tok), f"cursor moved up or down on a wide terminal: {tok!r}"
        else:
            cur += tok
    if cur:
        lines.append(cur)
    return lines


def test_piped_decode_shows_no_progress(ddct, log):
    proc = lib.run([ddct, "log", "decode", log, "--format", "csv", "--quiet"])
    assert "\x1b" not in proc.stderr and "\r" not in proc.stderr
    assert [line for line in proc.stderr.splitlines() if not line.startswith("frames by E2E")] == []


def test_file_decode_draws_a_byte_bar_on_a_terminal(ddct, log):
    plain = lib.run([ddct, "log", "decode", log, "--format", "csv"]).stdout
    screen, piped = _on_terminal([ddct, "log", "decode", log, "--format", "csv", "-q"], stdout_too=False)
    assert piped.decode() == plain
    assert re.search(r"decoding \S+long\.log \[[=> ]+\] [\d.]+ [KM]iB/[\d.]+ [KM]iB", screen), screen[:500]
    # The bar is cleared at the end: only the summary stays on the screen.
    assert [line for line in _screen_lines(screen) if line.strip()] == [
        line for line in lib.run([ddct, "log", "decode", log, "--format", "csv", "-q"]).stderr.splitlines()
    ]


def test_stdin_decode_draws_a_frame_counter(ddct, log):
    screen, _ = _on_terminal([ddct, "log", "decode", "-", "--format", "json", "-q"], stdout_too=False, stdin=log)
    assert re.search(r"decoding standard input: \d+ frames", screen), screen[:500]


def test_decoded_lines_stay_whole_beside_the_bar(ddct, log):
    plain = lib.run([ddct, "log", "decode", log]).stdout.splitlines()
    screen, _ = _on_terminal([ddct, "log", "decode", log], stdout_too=True)
    assert "decoding" in screen
    shown = [line for line in _screen_lines(screen) if line.startswith("(")]
    assert shown == plain
