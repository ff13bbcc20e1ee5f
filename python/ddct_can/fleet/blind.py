"""`ddct-fleet blind`: the blind test of the sim-to-real diagnosis (`ddct gap blind`) on the
same Dask cluster as the fleet campaigns. The trials of one seed are cut into chunks; a chunk is
one task running `ddct gap blind --first I --trials K --seed S --threads 1` into
OUT/chunks/<I>/report.json, and `ddct gap blind --merge` summarises all chunks together, exactly
as one run of the same trials would (the trials are deterministic in seed and index; merged
reports re-read every number exactly). A chunk already written is not run again, so an
interrupted campaign resumes; a worker that dies has its chunk retried.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

# A chunk that runs longer than this is stopped and reported (trials take seconds to a minute).
CHUNK_TIMEOUT_S = 6 * 3600


@dataclass(frozen=True)
class Chunk:
    first: int
    trials: int


def chunks(trials: int, size: int) -> list[Chunk]:
    """Trials 0…trials−1 in chunks of `size` (the last one shorter)."""
    if trials < 1 or size < 1:
        raise ValueError("--trials and --chunk must be at least 1")
    return [Chunk(i, min(size, trials - i)) for i in range(0, trials, size)]


def chunk_report(out: Path, c: Chunk) -> Path:
    return out / "chunks" / f"{c.first:07d}" / "report.json"


def run_chunk(c: Chunk, ddct: str, seed: int, out: str, threads: int) -> dict:
    """What a worker runs: one chunk into a temporary directory, moved into place when complete
    (a chunk half written never counts as done). Idempotent."""
    final = chunk_report(Path(out), c)
    if final.exists():
        return {"first": c.first, "status": "done before", "seconds": 0.0}
    t0 = time.monotonic()
    final.parent.parent.mkdir(parents=True, exist_ok=True)
    tmp = tempfile.mkdtemp(prefix=f".{c.first:07d}-", dir=final.parent.parent)
    try:
        cmd = [ddct, "gap", "blind", "--first", str(c.first), "--trials", str(c.trials), "--seed", str(seed),
               "--out", tmp]
        if threads > 0:
            cmd += ["--threads", str(threads)]
        try:
            p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                               timeout=CHUNK_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            return {"first": c.first, "status": "error", "seconds": time.monotonic() - t0,
                    "error": f"ddct took longer than {CHUNK_TIMEOUT_S} s"}
        if p.returncode != 0:
            return {"first": c.first, "status": "error", "seconds": time.monotonic() - t0,
                    "error": f"ddct exited {p.returncode}: {p.stderr[-2000:]}"}
        os.replace(tmp, final.parent)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"first": c.first, "status": "ok", "seconds": time.monotonic() - t0}


def _progress(done: int, total: int, c: Chunk, r: dict, stream=sys.stderr) -> None:
    stream.write(f"[{done}/{total}] trials {c.first}–{c.first + c.trials - 1}: {r['status']} ({r['seconds']:.1f} s)\n")
    stream.flush()


def run(cs: list[Chunk], ddct: str, seed: int, out: Path, threads: int, client=None, retries: int = 3,
        progress: Callable = _progress) -> list[dict]:
    """Every chunk, on the Dask client (or in a loop without one); results in completion order."""
    todo = [c for c in cs if not chunk_report(out, c).exists()]
    results = [{"first": c.first, "status": "done before", "seconds": 0.0} for c in cs if c not in todo]
    if client is None:
        for c in todo:
            r = run_chunk(c, ddct, seed, str(out), threads)
            results.append(r)
            progress(len(results), len(cs), c, r)
        return results
    from .campaign import collect

    futures = {client.submit(run_chunk, c, ddct, seed, str(out), threads, key=f"blind-{seed}-{c.first}",
                             retries=retries, pure=False): c for c in todo}
    return collect(futures, results, len(cs), progress)


def merge(ddct: str, cs: list[Chunk], out: Path) -> dict:
    """`ddct gap blind --merge` of the chunks written into OUT (report.txt, report.json,
    detectability.svg); the merged report."""
    reports = [str(chunk_report(out, c)) for c in cs if chunk_report(out, c).exists()]
    if not reports:
        raise RuntimeError("no chunk finished: nothing to merge")
    p = subprocess.run([ddct, "gap", "blind", "--merge", *reports, "--out", str(out)], stdout=subprocess.DEVNULL,
                       stderr=subprocess.PIPE, text=True)
    if p.returncode != 0:
        raise RuntimeError(f"ddct gap blind --merge failed: {p.stderr[-2000:]}")
    return json.loads((out / "report.json").read_text())
