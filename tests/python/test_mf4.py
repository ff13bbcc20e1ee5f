"""MDF 4 bus logging against the reference implementation, asammdf (issue 18).

- A recorded bench run converted to MF4 by `ddct log convert` and read by asammdf
  (`extract_bus_logging` with dbc/ddct.dbc) gives every signal of every frame equal to
  `ddct log decode` of the original candump log, at the same times.
- An MF4 written by asammdf from a candump log (uncompressed, deflate and transposed deflate)
  is read by ddct frame for frame: `ddct log convert` back to candump text gives the log's lines.
- Parquet (signals and `--frames`) read by pyarrow and by DuckDB equals the CSV output.
- A truncated or garbage MF4 is an error naming the file, never a crash.
"""

from __future__ import annotations

import csv
import datetime
import io
import math
from pathlib import Path

import duckdb
import numpy as np
import pyarrow.parquet as pq
import pytest
from asammdf import MDF, Signal
from asammdf.blocks.source_utils import Source

import ddct_testlib as lib
from ddct_testlib import ddct_can


@pytest.fixture(scope="module")
def bench_log(bench_launch_shift) -> Path:
    """A bench run on the in-process bus: plant, TCU and driver, recorded as candump -l (the
    session's run of the bench's scenario, conftest.py)."""
    out, r = bench_launch_shift
    assert r.returncode == 0, r.stderr[-2000:]
    log = out / "bench.log"
    assert log.stat().st_size > 100_000
    return log


def _decode(ddct, log: Path) -> list[dict]:
    return lib.json_lines(lib.run([ddct, "log", "decode", log, "--format", "json", "--quiet"]).stdout)


def _asammdf_signals(mf4: Path) -> dict[tuple[str, str], Signal]:
    """(message, signal) → the asammdf Signal that extract_bus_logging decoded."""
    extracted = MDF(mf4).extract_bus_logging({"CAN": [(str(ddct_can.DBC_PATH), 0)]}, ignore_value2text_conversion=True)
    out = {}
    for sig in extracted.iter_channels():
        names = [n for n in sig.display_names if n.count(".") >= 1] or [sig.name]
        parts = names[0].split(".")
        out[(parts[-2], parts[-1])] = sig
    return out


def test_a_bench_run_converted_to_mf4_decodes_in_asammdf_like_ddct(ddct, db, bench_log, tmp_path):
    mf4 = tmp_path / "bench.mf4"
    lib.run([ddct, "log", "convert", bench_log, mf4])
    recs = [r for r in _decode(ddct, bench_log) if r["error"] is None and r["signals"]]
    t0 = _decode(ddct, bench_log)[0]["t"]
    signals = _asammdf_signals(mf4)
    start = MDF(mf4).header.start_time.timestamp()
    assert abs(start - t0) < 1e-6, (start, t0)
    compared = 0
    problems = []
    for msg in db.messages:
        frames = [r for r in recs if r["id"] == msg.frame_id]
        for sig in msg.signals:
            if not frames:
                continue
            got = signals.get((msg.name, sig.name))
            if got is None:
                problems.append(f"{msg.name}.{sig.name}: not extracted by asammdf")
                continue
            if len(got.samples) != len(frames):
                problems.append(f"{msg.name}.{sig.name}: asammdf {len(got.samples)} samples, ddct {len(frames)} frames")
                continue
            for k, (r, t, v) in enumerate(zip(frames, got.timestamps, got.samples)):
                if abs((r["t"] - t0) - float(t)) > 1e-6:
                    problems.append(f"{msg.name}.{sig.name}[{k}]: time {t} vs ddct {r['t'] - t0}")
                    break
                mine = r["signals"][sig.name]
                if isinstance(v, bytes):  # asammdf keeps a value table's text: compare labels
                    label = mine if isinstance(mine, str) else str(sig.choices.get(int(mine), mine))
                    if v.decode() != label:
                        problems.append(f"{msg.name}.{sig.name}[{k}]: asammdf {v!r}, ddct {mine!r}")
                        break
                    compared += 1
                    continue
                if isinstance(mine, str):  # a value-table label: compare the raw value
                    mine = lib.raw_value(sig, mine) * sig.scale + sig.offset
                if not math.isclose(float(v), float(mine), rel_tol=1e-9, abs_tol=abs(sig.scale) * 1e-6):
                    problems.append(f"{msg.name}.{sig.name}[{k}]: asammdf {v}, ddct {mine}")
                    break
                compared += 1
    assert not problems, "\n".join(problems[:20])
    assert compared > 100_000, compared


def _candump_frames() -> list[tuple[float, int, bool, bytes]]:
    """Every contract message at min/mid/max plus extended, empty and short frames."""
    frames = []
    t = 1_700_000_000.0
    for k, fr in enumerate(lib.sample_frames()):
        frames.append((t + k * 0.001234, fr["id"], False, bytes(fr["data"])))
    t = frames[-1][0]
    frames += [
        (t + 0.5, 0x1ABCDEF0, True, bytes([0xDE, 0xAD])),
        (t + 0.75, ddct_can.frame_id("TCU_DiagReq"), False, b""),  # an empty transport frame
        (t + 1.0, 0x18DAF110, True, bytes(range(8))),
        (t + 86_400.0, 0x2A5, False, bytes([1, 2, 3])),  # a day later, an id outside the contract
    ]
    return frames


def _candump_text(frames, iface="vcan0") -> str:
    lines = []
    for t, fid, ext, data in frames:
        sec, us = divmod(round(t * 1e6), 1_000_000)
        ident = f"{fid:08X}" if ext else f"{fid:03X}"
        lines.append(f"({sec:010d}.{us:06d}) {iface} {ident}#{data.hex().upper()}")
    return "\n".join(lines) + "\n"


def _asammdf_write(frames, path: Path, compression: int, iface="vcan0"):
    """The frames as asammdf writes bus logging: one CAN_DataFrame structure channel."""
    dt = np.dtype(
        [
            ("CAN_DataFrame.BusChannel", "u1"),
            ("CAN_DataFrame.ID", "<u4"),
            ("CAN_DataFrame.IDE", "u1"),
            ("CAN_DataFrame.DLC", "u1"),
            ("CAN_DataFrame.DataLength", "u1"),
            ("CAN_DataFrame.DataBytes", "u1", (8,)),
        ]
    )
    arr = np.zeros(len(frames), dtype=dt)
    for k, (_, fid, ext, data) in enumerate(frames):
        arr[k]["CAN_DataFrame.BusChannel"] = 1
        arr[k]["CAN_DataFrame.ID"] = fid | (0x80000000 if ext else 0)
        arr[k]["CAN_DataFrame.IDE"] = int(ext)
        arr[k]["CAN_DataFrame.DLC"] = len(data)
        arr[k]["CAN_DataFrame.DataLength"] = len(data)
        arr[k]["CAN_DataFrame.DataBytes"][: len(data)] = list(data)
    t0 = frames[0][0]
    sec, us = divmod(round(t0 * 1e6), 1_000_000)
    start = datetime.datetime.fromtimestamp(sec, tz=datetime.timezone.utc).replace(microsecond=us)
    ts = np.array([round((t - t0) * 1e6) / 1e6 for t, *_ in frames])
    mdf = MDF(version="4.10")
    mdf.header.start_time = start
    src = Source(name=iface, path=iface, comment="", source_type=Source.SOURCE_BUS, bus_type=Source.BUS_TYPE_CAN)
    mdf.append(Signal(arr, ts, name="CAN_DataFrame", source=src), acq_name=iface)
    mdf.save(path, overwrite=True, compression=compression)


@pytest.mark.parametrize("compression", [0, 1, 2], ids=["plain", "deflate", "transposed"])
def test_an_mf4_written_by_asammdf_reads_in_ddct_frame_for_frame(ddct, tmp_path, compression):
    frames = _candump_frames()
    log = tmp_path / "in.log"
    log.write_text(_candump_text(frames))
    mf4 = tmp_path / "asammdf.mf4"
    _asammdf_write(frames, mf4, compression)
    back = tmp_path / "back.log"
    lib.run([ddct, "log", "convert", mf4, back])
    assert back.read_text() == log.read_text()
    # and the decoder reads the MF4 itself as it reads the log
    assert _decode(ddct, mf4) == _decode(ddct, log)


def test_ddct_mf4_round_trips_through_asammdf_frames(ddct, tmp_path):
    """ddct's own MF4 read by asammdf's raw frame table: ids, lengths and bytes as logged."""
    frames = _candump_frames()
    log = tmp_path / "in.log"
    log.write_text(_candump_text(frames))
    mf4 = tmp_path / "ddct.mf4"
    lib.run([ddct, "log", "convert", log, mf4])
    mdf = MDF(mf4)
    ids = mdf.get("CAN_DataFrame.ID").samples & 0x1FFFFFFF
    ide = mdf.get("CAN_DataFrame.IDE").samples
    length = mdf.get("CAN_DataFrame.DataLength").samples
    data = mdf.get("CAN_DataFrame.DataBytes").samples
    times = mdf.get("CAN_DataFrame.ID").timestamps
    assert len(ids) == len(frames)
    for k, (t, fid, ext, payload) in enumerate(frames):
        assert (int(ids[k]), bool(ide[k]), int(length[k])) == (fid, ext, len(payload)), k
        assert bytes(data[k][: len(payload)]) == payload, k
        assert abs(float(times[k]) - (t - frames[0][0])) < 1e-6, k
    # and back through ddct: the same log
    back = tmp_path / "back.log"
    lib.run([ddct, "log", "convert", mf4, back])
    assert back.read_text() == log.read_text()


def test_parquet_read_by_pyarrow_and_duckdb_equals_the_csv(ddct, bench_log, tmp_path):
    for frames in (False, True):
        extra = ["--frames"] if frames else []
        csv_out, pq_out = tmp_path / f"f{frames}.csv", tmp_path / f"f{frames}.parquet"
        lib.run([ddct, "log", "convert", bench_log, csv_out, *extra])
        lib.run([ddct, "log", "convert", bench_log, pq_out, *extra])
        rows = list(csv.DictReader(io.StringIO(csv_out.read_text())))
        table = pq.read_table(pq_out).to_pydict()
        con = duckdb.connect()
        duck = con.execute(f"SELECT * FROM read_parquet('{pq_out}')").fetchall()
        cols = list(table)
        assert cols == list(rows[0]), (cols, list(rows[0]))
        assert len(rows) == len(duck) == len(table[cols[0]]) > 10_000
        for i, r in enumerate(rows):
            for j, c in enumerate(cols):
                a, d, want = table[c][i], duck[i][j], r[c]
                assert a == d, (i, c, a, d)
                assert _same(c, a, want), (i, c, a, want)


def _same(column: str, value, text: str) -> bool:
    """A Parquet value equals the CSV's text of it."""
    if column == "time_s":
        return abs(value - float(text)) <= 5e-7
    if column == "id":
        return value == int(text, 16)
    if column in ("extended", "remote"):
        return value == bool(int(text))
    if column == "dlc":
        return value == int(text)
    if column == "data":
        return value.hex().upper() == text
    if column == "value":
        return (value is None and text == "") or value == float(text)
    return value == text


def test_a_truncated_or_garbage_mf4_is_an_error_naming_the_file(ddct, tmp_path):
    log = tmp_path / "in.log"
    log.write_text(_candump_text(_candump_frames()))
    good = tmp_path / "good.mf4"
    lib.run([ddct, "log", "convert", log, good])
    data = good.read_bytes()
    cases = {
        "truncated.mf4": data[: len(data) // 2],
        "garbage.mf4": b"MDF     " + bytes(range(256)) * 4,
        "header_only.mf4": data[:64],
    }
    for name, content in cases.items():
        bad = tmp_path / name
        bad.write_bytes(content)
        for args in (["log", "decode", bad], ["log", "convert", bad, tmp_path / "x.log"], ["log", "stats", bad]):
            p = lib.run([ddct, *args], check=False)
            assert p.returncode != 0, (name, args)
            assert str(bad) in p.stderr and "panicked" not in p.stderr, (name, args, p.stderr)
    assert not (tmp_path / "x.log").exists()
    p = lib.run([ddct, "log", "convert", log, tmp_path / "x.txt"], check=False)
    assert p.returncode != 0 and ".log, .mf4, .csv or .parquet" in p.stderr, p.stderr
