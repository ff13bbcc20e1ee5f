"""The commands README.md and docs/*.md tell a user to run, and the manifest that says how the
test runs each one (tests/docs/commands.toml).

A command is a line of a fenced ```sh (or ```bash) block: blank and comment lines are skipped, a
line ending in a backslash continues on the next, and a trailing ` # comment` is not part of the
command. Usage synopses with placeholders belong in ```text blocks. In prose, an inline code span
that is a complete command (a command word, arguments, no placeholder) must also be a block
command somewhere, so that it is run too."""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
MANIFEST = Path(__file__).resolve().parent / "commands.toml"
PARTS = ("host", "vcan", "long")
# Lanes of a test session: "main" runs the commands one after the other in the manifest's order;
# "cpu" commands (CPU work without a bus and without a deadline: nothing in them is timed or
# fails when it runs slowly; they read only what earlier cpu commands or the repository give
# them) run in a second lane beside the main one, at nice 19, in the manifest's order among
# themselves (tests/docs/test_docs_commands.py, "Lanes"). No User-Mode Linux in the cpu lane: a
# second guest beside the main lane's (a lockstep rig run) made the diagnostic session's
# kiss-point routine abort.
LANES = ("main", "cpu")
COMMAND_WORDS = re.compile(r"^(ddct(?=\s|$)|scripts/|cargo|\.venv/|candump|cansend|python3?|target/release/ddct|export|sudo|cd)\b")
# An argument that makes an inline span a command to run rather than the name of one: a number,
# a path, a list or an assignment.
CONCRETE = re.compile(r"^(-?[0-9][0-9.]*|.*[/,=].*)$")
# Tokens that make a line a synopsis rather than a command.
PLACEHOLDER = re.compile(r"(\[|\]|\.\.\.|…|<[A-Za-z_]+>|\b[A-Z][A-Z_]{0,}[0-9]?\b(?![=_]))")


def doc_files() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


@dataclass
class Shown:
    """One command as a page shows it."""

    cmd: str
    where: list[str] = field(default_factory=list)


def strip_comment(line: str) -> str:
    """The line without a trailing shell comment (a `#` after whitespace, outside quotes)."""
    quote = None
    for i, c in enumerate(line):
        if quote:
            if c == quote:
                quote = None
        elif c in "'\"":
            quote = c
        elif c == "#" and (i == 0 or line[i - 1].isspace()):
            return line[:i].rstrip()
    return line.rstrip()


def fences(text: str):
    """(language, first line number, lines) of every fenced block."""
    lines = text.split("\n")
    i = 0
    while i < len(lines):
        m = re.match(r"^```\s*([\w+-]*)", lines[i])
        if not m:
            i += 1
            continue
        lang, start, body = m.group(1), i + 2, []
        i += 1
        while i < len(lines) and not lines[i].startswith("```"):
            body.append(lines[i])
            i += 1
        yield lang, start, body
        i += 1


def block_commands(body: list[str], start: int):
    """(line number, command) of one sh block."""
    pending, first = "", None
    for n, raw in enumerate(body, start):
        line = raw if pending else raw.strip()
        if not pending and (not line or line.startswith("#")):
            continue
        if first is None:
            first = n
        if raw.rstrip().endswith("\\"):
            pending += raw.rstrip()[:-1].strip() + " "
            continue
        cmd = strip_comment(pending + raw.strip())
        pending = ""
        yield first, re.sub(r"\s+", " ", cmd).strip()
        first = None


def shown_commands() -> dict[str, Shown]:
    """Every command of every ```sh block, with where it is shown (file:line)."""
    out: dict[str, Shown] = {}
    for f in doc_files():
        for lang, start, body in fences(f.read_text()):
            if lang not in ("sh", "bash"):
                continue
            for line, cmd in block_commands(body, start):
                out.setdefault(cmd, Shown(cmd)).where.append(f"{f.relative_to(REPO)}:{line}")
    return out


def untagged_command_blocks() -> list[str]:
    """Blocks without a language whose lines start like commands: commands hidden from the test."""
    bad = []
    for f in doc_files():
        for lang, start, body in fences(f.read_text()):
            if lang == "" and any(COMMAND_WORDS.match(l.strip()) for l in body):
                bad.append(f"{f.relative_to(REPO)}:{start - 1}")
    return bad


def inline_commands() -> list[tuple[str, str]]:
    """(file:line, span) of inline code spans in prose that are complete commands."""
    out = []
    for f in doc_files():
        text = f.read_text()
        in_fence = False
        for n, line in enumerate(text.split("\n"), 1):
            if line.startswith("```"):
                in_fence = not in_fence
                continue
            if in_fence:
                continue
            for span in re.findall(r"`([^`]+)`", line):
                s = span.strip()
                words = s.split()
                if (len(words) > 1 and COMMAND_WORDS.match(s) and not s.startswith("sudo")
                        and any(CONCRETE.match(w) for w in words[1:])
                        and not PLACEHOLDER.search(" ".join(words[1:]))):
                    out.append((f"{f.relative_to(REPO)}:{n}", re.sub(r"\s+", " ", s)))
    return out


@dataclass
class Entry:
    """How the test runs one command (a [[command]] of commands.toml)."""

    cmd: str
    part: str = "host"
    # Regexes the command's output (stdout and stderr) must match.
    expect: list[str] = field(default_factory=list)
    # Regexes it must not match.
    refuse: list[str] = field(default_factory=list)
    # Figures that must lie in a band: [regex, low, high]; the regex (re.M) captures one number,
    # the figure, or two, whose ratio (first / second) is the figure. For timings, which follow
    # the host's load: a ratio to a peer measured in the same run, in a generous band.
    bands: list[list] = field(default_factory=list)
    exit: int = 0
    # A daemon or a pipe that runs until stopped: SIGINT after this many seconds, then exit 0
    # (or `exit`) expected.
    stop_after_s: float | None = None
    # Shell commands run first (files the command reads), and traffic started beside it.
    setup: list[str] = field(default_factory=list)
    beside: str | None = None
    timeout_s: float = 600.0
    lane: str = "main"
    # A test file (or .ci/run, scripts/test) that runs this command itself, and the text by
    # which it does (default: the command).
    covered_by: str | None = None
    covered_as: str | None = None
    why: str = ""


def manifest() -> list[Entry]:
    data = tomllib.loads(MANIFEST.read_text())
    entries = []
    for i, raw in enumerate(data.get("command", []), 1):
        unknown = set(raw) - set(Entry.__dataclass_fields__)
        if unknown:
            raise ValueError(f"{MANIFEST.name}: command #{i} ({raw.get('cmd')!r}): unknown keys {sorted(unknown)}")
        e = Entry(**raw)
        if e.part not in PARTS:
            raise ValueError(f"{MANIFEST.name}: command #{i} ({e.cmd!r}): part {e.part!r} not one of {PARTS}")
        if e.lane not in LANES:
            raise ValueError(f"{MANIFEST.name}: command #{i} ({e.cmd!r}): lane {e.lane!r} not one of {LANES}")
        if e.lane == "cpu" and (e.part == "vcan" or e.beside or e.stop_after_s is not None or "vcan" in e.cmd):
            raise ValueError(f"{MANIFEST.name}: command #{i} ({e.cmd!r}): a cpu-lane command needs no bus, "
                             "no traffic beside it and no stop")
        for b in e.bands:
            if not (len(b) == 3 and isinstance(b[0], str) and re.compile(b[0]).groups in (1, 2)
                    and all(isinstance(x, (int, float)) for x in b[1:]) and b[1] <= b[2]):
                raise ValueError(f"{MANIFEST.name}: command #{i} ({e.cmd!r}): a band is [regex with 1 or 2 "
                                 f"groups, low, high], not {b!r}")
        entries.append(e)
    return entries


def band_figure(pattern: str, out: str) -> float | None:
    """The figure a band's regex captures in `out` (one number, or the first over the second);
    None where it does not match."""
    m = re.search(pattern, out, re.M)
    if m is None:
        return None
    g = [float(x) for x in m.groups()]
    return g[0] / g[1] if len(g) == 2 else g[0]
