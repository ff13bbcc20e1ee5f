"""A diagnosis campaign: the tasks of a fleet (which log is validated against which training
record), their content keys, the task a worker runs, and the campaign on Dask or in a plain loop.

Pairing rule (documented in docs/fleet.md): within a unit the logs are taken in manifest order
(by file name when a directory is scanned); log k is the validation record of its task and the
unit's log k-1 its training record; the first log is validated against the second. A unit with a
single log gives an error row ("a unit needs at least two logs").
"""

from __future__ import annotations

import csv
import hashlib
import subprocess
import sys
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable, Iterable, Optional

import pyarrow as pa
import pyarrow.parquet as pq

from . import storage

# The columns `ddct gap diagnose --findings` writes (src/gap/report/findings_table.rs); a task whose
# ddct process died before writing uses it for its error row (tests check the two agree).
FINDINGS_SCHEMA = pa.schema(
    [
        ("unit", pa.string()),
        pa.field("log", pa.string(), nullable=False),
        pa.field("train", pa.string(), nullable=False),
        ("start_time", pa.timestamp("us", tz="UTC")),
        ("operating_hours", pa.float64()),
        pa.field("kind", pa.string(), nullable=False),
        ("class", pa.string()),
        ("subsystem", pa.string()),
        ("variable", pa.string()),
        ("magnitude", pa.float64()),
        ("magnitude_lo", pa.float64()),
        ("magnitude_hi", pa.float64()),
        ("magnitude_unit", pa.string()),
        ("magnitude_basis", pa.string()),
        ("magnitude_from", pa.float64()),
        ("magnitude_to", pa.float64()),
        ("share_pct", pa.float64()),
        ("gap_closed_pct", pa.float64()),
        ("unexplained_pct", pa.float64()),
        ("detail", pa.string()),
        ("error", pa.string()),
        pa.field("ddct_version", pa.string(), nullable=False),
        pa.field("params_hash", pa.string(), nullable=False),
    ]
)

LOG_SUFFIXES = (".mf4", ".log", ".csv")
# A diagnosis of one pair of 10-minute logs takes seconds; a task taking this long is hung.
TASK_TIMEOUT_S = 1800


@dataclass(frozen=True)
class Task:
    """One diagnosis: the validation log, its training log, the unit, the content key."""

    unit: str
    log: str
    train: str
    operating_hours: Optional[float]
    key: str
    # Why the task cannot run (an error row is written instead), e.g. a unit with one log.
    problem: Optional[str] = None


def content_key(paths: Iterable[str], salt: str) -> str:
    """blake2b of the files' bytes (and `salt`: the ddct version and options), 32 hex digits."""
    h = hashlib.blake2b(digest_size=16)
    h.update(salt.encode())
    for p in paths:
        h.update(b"\0file\0")
        try:
            if storage.is_url(str(p)):
                import fsspec

                opened = fsspec.open(str(p), "rb")
            else:
                opened = open(p, "rb")
            with opened as f:
                for chunk in iter(lambda: f.read(1 << 20), b""):
                    h.update(chunk)
        except OSError as e:  # the task reports it as an error row
            h.update(f"unreadable: {e}".encode())
    return h.hexdigest()


def _manifest_rows(source: Path) -> list[dict]:
    """(unit, log, train, operating_hours) rows of a manifest CSV or of a directory scan."""
    manifest = source if source.is_file() else source / "manifest.csv"
    if manifest.is_file():
        base = manifest.parent
        rows = []
        with open(manifest, newline="") as f:
            for n, r in enumerate(csv.DictReader(f), 2):
                if not r.get("unit") or not r.get("log"):
                    raise ValueError(f"{manifest}:{n}: every row needs `unit` and `log`")
                hours = (r.get("operating_hours") or "").strip()
                where = lambda f: f if storage.is_url(f) else str((base / f).resolve())  # noqa: E731
                train = (r.get("train") or "").strip()
                rows.append(
                    {
                        "unit": r["unit"].strip(),
                        "log": where(r["log"].strip()),
                        "train": where(train) if train else "",
                        "operating_hours": float(hours) if hours else None,
                    }
                )
        return rows
    if not source.is_dir():
        raise ValueError(f"{source}: neither a manifest CSV nor a directory")
    rows = []
    for unit_dir in sorted(p for p in source.iterdir() if p.is_dir()):
        for log in sorted(p for p in unit_dir.iterdir() if p.suffix.lower() in LOG_SUFFIXES):
            rows.append({"unit": unit_dir.name, "log": str(log.resolve()), "train": "", "operating_hours": None})
    return rows


def discover(source: Path, salt: str) -> list[Task]:
    """The campaign's tasks: one per log of the manifest or directory, paired by the rule above."""
    rows = _manifest_rows(Path(source))
    by_unit: dict[str, list[dict]] = {}
    for r in rows:
        by_unit.setdefault(r["unit"], []).append(r)
    tasks = []
    for unit, logs in by_unit.items():
        for k, r in enumerate(logs):
            train, problem = r["train"], None
            if not train:
                if len(logs) < 2:
                    train, problem = r["log"], "a unit needs at least two logs (one trains, one validates)"
                else:
                    train = logs[k - 1 if k > 0 else 1]["log"]
            key = content_key([train, r["log"]], salt)
            tasks.append(Task(unit, r["log"], train, r["operating_hours"], key, problem))
    return tasks


def safe_name(unit: str) -> str:
    """A unit name as a directory name."""
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in unit) or "_"


def result_path(out_dir, task: Task) -> str:
    """Where a task's findings go: OUT/<unit>/<content key>.parquet (a path or a URL)."""
    return storage.join(str(out_dir), safe_name(task.unit), f"{task.key}.parquet")


def error_table(task: Task, message: str, version: str = "") -> pa.Table:
    """The error row of a task whose ddct process wrote none."""
    row = {name: None for name in FINDINGS_SCHEMA.names}
    row.update(unit=task.unit, log=task.log, train=task.train, operating_hours=task.operating_hours,
               kind="error", error=message, ddct_version=version, params_hash="")
    return pa.Table.from_pylist([row], schema=FINDINGS_SCHEMA)


def diagnose_task(task: Task, ddct: str, out_dir: str, bootstrap: int, threads: int) -> dict:
    """What a worker runs: `ddct gap diagnose` of the task, its findings file moved into the
    dataset (atomically). Idempotent: a result already there is kept."""
    final = result_path(out_dir, task)
    if storage.exists(final):
        return {"key": task.key, "status": "done before", "rows": None, "seconds": 0.0}
    t0 = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="ddct-fleet-") as tmp:
        table = Path(tmp) / "findings.parquet"
        status = "error"
        if task.problem:
            pq.write_table(error_table(task, task.problem), table)
        else:
            train = storage.local_copy(task.train, Path(tmp))
            log = storage.local_copy(task.log, Path(tmp))
            cmd = [ddct, "gap", "diagnose", "--train", train, "--validate", log,
                   "--out", str(Path(tmp) / "report"), "--findings", str(table), "--unit", task.unit,
                   "--bootstrap", str(bootstrap)]
            if threads > 0:  # 0: ddct's default, every core
                cmd += ["--threads", str(threads)]
            if task.operating_hours is not None:
                cmd += ["--operating-hours", repr(task.operating_hours)]
            try:
                p = subprocess.run(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                   timeout=TASK_TIMEOUT_S)
                status = "ok" if p.returncode == 0 else "error"
                if not table.exists():
                    pq.write_table(error_table(task, f"ddct exited {p.returncode}: {p.stderr[-2000:]}"), table)
            except subprocess.TimeoutExpired:
                pq.write_table(error_table(task, f"ddct took longer than {TASK_TIMEOUT_S} s"), table)
        if storage.is_url(task.log) or storage.is_url(task.train):
            _name_logs(table, task)  # the rows name the logs as given, not the local copies
        rows = pq.read_metadata(table).num_rows
        storage.put_atomically(table, final)
    return {"key": task.key, "status": status, "rows": rows, "seconds": time.monotonic() - t0}


def _name_logs(table: Path, task: Task) -> None:
    t = pq.read_table(table)
    n = t.num_rows
    for name, value in (("log", task.log), ("train", task.train)):
        t = t.set_column(t.schema.get_field_index(name), t.schema.field(name), pa.array([value] * n, pa.string()))
    pq.write_table(t, table)


def _progress(done: int, total: int, task: Task, result: dict, stream=sys.stderr) -> None:
    stream.write(f"[{done}/{total}] {task.unit} {Path(task.log).name}: {result['status']}"
                 f" ({result['seconds']:.1f} s)\n")
    stream.flush()


def run_sequential(tasks: list[Task], ddct: str, out_dir: Path, bootstrap: int, threads: int,
                   progress: Callable = _progress) -> list[dict]:
    """The campaign in a plain loop (the baseline the cluster is compared against)."""
    results = []
    for n, t in enumerate(tasks, 1):
        r = diagnose_task(t, ddct, str(out_dir), bootstrap, threads)
        results.append(r)
        progress(n, len(tasks), t, r)
    return results


def run_campaign(tasks: list[Task], ddct: str, out_dir: Path, bootstrap: int, threads: int,
                 client, retries: int = 3, progress: Callable = _progress) -> list[dict]:
    """The campaign on a Dask client: one task per log, retried when a worker dies; results in
    completion order. Tasks already in the dataset are not submitted."""
    done_before = {t.key for t in tasks if storage.exists(result_path(out_dir, t))}
    todo = [t for t in tasks if t.key not in done_before]
    results = [{"key": t.key, "status": "done before", "rows": None, "seconds": 0.0}
               for t in tasks if t.key in done_before]
    futures = {
        client.submit(diagnose_task, t, ddct, str(out_dir), bootstrap, threads,
                      key=f"diagnose-{n}-{t.key}", retries=retries, pure=False): t
        for n, t in enumerate(todo)
    }
    return collect(futures, results, len(tasks), progress)


def collect(futures: dict, results: list, total: int, progress: Callable) -> list:
    """Appends each future's result to `results` as it completes (`futures`: future → its task,
    given to `progress` with the count done of `total`); `results`."""
    from distributed import as_completed

    done = len(results)
    for fut in as_completed(futures):
        r = fut.result()
        results.append(r)
        done += 1
        progress(done, total, futures[fut], r)
    return results


def task_dicts(tasks: list[Task]) -> list[dict]:
    return [asdict(t) for t in tasks]
