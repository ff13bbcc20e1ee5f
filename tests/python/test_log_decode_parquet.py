"""`ddct log decode --format parquet --out FILE`: the CSV's rows as a Parquet table.

Read back with pyarrow (an independent Parquet reader), every row of the Parquet table equals
the same row of `--format csv` on a recorded rig run: time to the CSV's microsecond, the value
exactly (the CSV prints the shortest text that reads back to the same double), id, names, unit
and E2E verdict; an unknown frame keeps its row with an empty signal and a null value. The same
holds for `--dbc`. The column types are those documented; without `--out` it is an error.
"""

from __future__ import annotations

import csv
import io
import math
from pathlib import Path

import pyarrow.parquet as pq
import pytest

import ddct_testlib as lib
from ddct_testlib import ddct_can


@pytest.fixture(scope="module")
def rig_log(ddct, tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("parquet")
    full = d / "rig.log"
    lib.run([ddct, "plant", "--iface", "sim", "--mode", "rig", "--config", lib.REPO / "config/plant_rig.toml",
             "--rig-profile", lib.REPO / "config/rig/identification.toml", "--log", full])
    cut = d / "rig_cut.log"
    lines = full.read_text().splitlines()[:30000]
    # A frame no DBC knows: its row stays, with no signal.
    t = lines[-1].split(")")[0] + ")"
    lines.append(f"{t} sim 7FF#0102")
    cut.write_text("\n".join(lines) + "\n")
    return cut


def _csv_rows(ddct, log: Path, extra=()) -> list[dict]:
    text = lib.run([ddct, "log", "decode", log, "--format", "csv", *extra]).stdout
    return list(csv.DictReader(io.StringIO(text)))


def _parquet_rows(ddct, log: Path, out: Path, extra=()):
    lib.run([ddct, "log", "decode", log, "--format", "parquet", "--out", out, *extra])
    return pq.read_table(out)


@pytest.mark.parametrize("dbc", [False, True], ids=["builtin", "dbc"])
def test_parquet_rows_equal_the_csv(ddct, rig_log, tmp_path, dbc):
    extra = ["--dbc", ddct_can.DBC_PATH] if dbc else []
    rows = _csv_rows(ddct, rig_log, extra)
    table = _parquet_rows(ddct, rig_log, tmp_path / "out.parquet", extra)
    assert table.num_rows == len(rows) > 10_000
    cols = table.to_pydict()
    unknown = 0
    for i, r in enumerate(rows):
        assert abs(cols["time_s"][i] - float(r["time_s"])) <= 5e-7, i
        assert cols["iface"][i] == r["iface"], i
        assert f"0x{cols['id'][i]:03X}" == r["id"], i
        assert cols["message"][i] == r["message"], i
        assert cols["signal"][i] == r["signal"], i
        assert cols["unit"][i] == r["unit"], i
        assert cols["e2e"][i] == r["e2e"], i
        if r["signal"] == "":
            unknown += 1
            assert cols["value"][i] is None and r["value"] == "", i
        else:
            v = cols["value"][i]
            assert v == float(r["value"]) and not math.isnan(v), (i, v, r["value"])
    assert unknown == 1
    assert rows[-1]["id"] == "0x7FF"


def test_parquet_schema(ddct, rig_log, tmp_path):
    schema = _parquet_rows(ddct, rig_log, tmp_path / "s.parquet").schema
    types = {f.name: str(f.type) for f in schema}
    assert types == {
        "time_s": "double", "iface": "string", "id": "uint32", "message": "string",
        "signal": "string", "value": "double", "unit": "string", "e2e": "string",
    }


def test_parquet_needs_out(ddct, rig_log):
    r = lib.run([ddct, "log", "decode", rig_log, "--format", "parquet"], check=False)
    assert r.returncode == 2
    assert "--out" in r.stderr
