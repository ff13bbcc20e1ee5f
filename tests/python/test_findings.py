"""`ddct gap diagnose --findings FILE.parquet` (issue 18): one row per finding, appended run
after run, read by pyarrow, pandas and DuckDB without conversion; a failed diagnosis is an
error row. The validation record is an MF4 converted from the plant's candump log, and the
diagnosis of it equals the diagnosis of the log."""

from __future__ import annotations

import datetime
import json
from pathlib import Path

import duckdb
import pyarrow.parquet as pq
import pytest

import ddct_testlib as lib


def _rig_log(ddct, out: Path, profile: str, seed: int) -> Path:
    log = out / f"{Path(profile).stem}_{seed}.log"
    lib.run([ddct, "plant", "--iface", "sim", "--mode", "rig", "--config", lib.REPO / "config/plant_rig.toml",
             "--rig-profile", lib.REPO / profile, "--effects", lib.REPO / "config/effects/friction_pressure.toml",
             "--seed", seed, "--log", log])
    return log


@pytest.fixture(scope="module")
def records(ddct, tmp_path_factory):
    d = tmp_path_factory.mktemp("findings")
    train = _rig_log(ddct, d, "config/rig/identification.toml", 1)
    valid = _rig_log(ddct, d, "config/rig/validation.toml", 7)
    valid_mf4 = d / "validation_7.mf4"
    lib.run([ddct, "log", "convert", valid, valid_mf4])
    return train, valid, valid_mf4


def _diagnose(ddct, train, valid, out, *extra, check=True):
    return lib.run([ddct, "gap", "diagnose", "--train", train, "--validate", valid, "--out", out, *extra], check=check)


def test_findings_rows_match_the_report_and_append(ddct, records, tmp_path):
    train, valid, valid_mf4 = records
    table = tmp_path / "findings.parquet"
    _diagnose(ddct, train, valid, tmp_path / "log")
    _diagnose(ddct, train, valid_mf4, tmp_path / "mf4", "--findings", table, "--unit", "rig-1",
              "--operating-hours", "12.5")
    from_log = json.loads((tmp_path / "log/report.json").read_text())
    from_mf4 = json.loads((tmp_path / "mf4/report.json").read_text())
    # The MF4 record is the same record: the same verdict and findings.
    assert from_mf4["verdict"]["findings"] == from_log["verdict"]["findings"]
    findings = from_mf4["verdict"]["findings"]
    rows = pq.read_table(table).to_pylist()
    assert len(rows) == len(findings) >= 1
    start = lib.run([ddct, "log", "decode", valid, "--format", "json"]).stdout.splitlines()[0]
    t0 = json.loads(start)["t"]
    for row, f in zip(rows, findings):
        assert row["kind"] == f["kind"]
        assert row["unit"] == "rig-1" and row["operating_hours"] == 12.5
        assert row["log"] == str(valid_mf4) and row["train"] == str(train)
        assert abs(row["start_time"].timestamp() - t0) < 1e-6, (row["start_time"], t0)
        assert row["start_time"].tzinfo is not None
        assert json.loads(row["detail"]) == f
        assert row["error"] is None and len(row["params_hash"]) == 16
        if f["kind"] in ("class", "sensor"):
            assert row["class"] == f["class"] and row["variable"] == f["variable"]
            assert row["magnitude"] == f["magnitude"]
            assert [row["magnitude_lo"], row["magnitude_hi"]] == f["magnitude_ci95"]
            basis = f["magnitude_basis"]
            assert row["magnitude_basis"] == basis["kind"]
            ends = {"change": ("from", "to"), "ratio": ("from", "to"), "largest": ("from", "to"), "at": ("at", "at")}.get(basis["kind"])
            if ends:
                assert [row["magnitude_from"], row["magnitude_to"]] == [basis[ends[0]], basis[ends[1]]]
                assert row["magnitude_from"] <= row["magnitude_to"]
            else:
                assert row["magnitude_from"] is None and row["magnitude_to"] is None
            assert row["share_pct"] == f["share_pct"]
    # A second run appends; pandas and DuckDB read the same rows.
    _diagnose(ddct, train, valid, tmp_path / "again", "--findings", table, "--unit", "rig-1")
    df = pq.read_table(table).to_pandas()
    assert len(df) == 2 * len(findings)
    assert df["operating_hours"].isna().sum() == len(findings)
    n, kinds = duckdb.connect().execute(
        f"SELECT count(*), list(kind ORDER BY kind) FROM read_parquet('{table}')").fetchone()
    assert n == len(df) and sorted(kinds) == sorted(df["kind"])


def test_a_failed_diagnosis_is_an_error_row(ddct, records, tmp_path):
    train, _, _ = records
    table = tmp_path / "findings.parquet"
    for name, content in {"garbage.mf4": b"MDF     " + bytes(300), "truncated.log": b"(1700000000.0"}.items():
        bad = tmp_path / name
        bad.write_bytes(content)
        p = _diagnose(ddct, train, bad, tmp_path / "out", "--findings", table, check=False)
        assert p.returncode != 0
        row = pq.read_table(table).to_pylist()[-1]
        assert row["kind"] == "error" and str(bad) in row["error"], row
        assert row["log"] == str(bad) and row["start_time"] is None
    assert pq.read_table(table).num_rows == 2
