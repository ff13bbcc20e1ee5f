//! The findings of diagnoses as a Parquet table (`ddct gap diagnose --findings FILE`), one row
//! per finding, that pandas, polars and DuckDB read without conversion: which unit and log,
//! when, at how many operating hours, the finding's kind, class, subsystem and variable, its
//! magnitude with the 95 % interval, its share of the gap and how far the validation gap
//! closed, the whole finding as JSON, the ddct version and a hash of the nominal parameters. A
//! diagnosis that failed is one row of kind `error` with the message: a result is never
//! silently missing. This module makes the rows and their record batch; the shell appends the
//! batch to the file (`crate::parquet_file::append`).

use crate::can::columnar::ColumnarError;
use crate::gap::method::diagnose::Diagnosis;
use crate::gap::method::finding::Finding;
use crate::model::params::Params;
use arrow_array::builder::{Float64Builder, StringBuilder, TimestampMicrosecondBuilder};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{DataType, Field, Schema, SchemaRef, TimeUnit};
use std::sync::Arc;
use std::time::Duration;

/// What a row says about the run besides the finding.
#[derive(Debug, Clone, PartialEq)]
pub struct RunInfo {
    /// The unit (rig or vehicle) the logs come from, if named.
    pub unit: Option<String>,
    /// The validation log(s), `;`-separated.
    pub log: String,
    /// The training log(s), `;`-separated.
    pub train: String,
    /// The validation log's start (since the epoch), where the log has a clock.
    pub start: Option<Duration>,
    /// Operating hours of the unit at the log, where known.
    pub operating_hours: Option<f64>,
    /// [`params_hash`] of the nominal parameters.
    pub params_hash: String,
}

/// One finding as a row.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FindingRow {
    /// `class`, `sensor`, `recalibration`, `outside_library`, `nothing` or `error`.
    pub kind: String,
    pub class: Option<String>,
    pub subsystem: Option<String>,
    pub variable: Option<String>,
    pub magnitude: Option<f64>,
    pub magnitude_ci95: Option<(f64, f64)>,
    pub magnitude_unit: Option<String>,
    /// What the magnitude is measured over: `change` (of the term from `magnitude_from` to
    /// `magnitude_to` of its variable), `ratio` (a multiplier's relative change over that
    /// range), `largest` (its value of largest size over that range), `at` (its value at that
    /// point) or `parameter`.
    pub magnitude_basis: Option<String>,
    pub magnitude_range: Option<(f64, f64)>,
    pub share_pct: Option<f64>,
    /// The validation gap above the noise floor closed by the diagnosed model (%).
    pub gap_closed_pct: Option<f64>,
    /// Share of the validation gap the findings leave unexplained (%).
    pub unexplained_pct: Option<f64>,
    /// The finding as JSON (every field, whatever its kind).
    pub detail: Option<String>,
    pub error: Option<String>,
}

/// A hash of the parameters (CRC-64/XZ of their JSON, 16 hex digits): rows diagnosed against
/// the same nominal model share it.
pub fn params_hash(p: &Params) -> String {
    const CRC: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);
    let text = serde_json::to_string(p).unwrap_or_default();
    format!("{:016x}", CRC.checksum(text.as_bytes()))
}

/// The rows of a diagnosis, one per finding.
pub fn rows(d: &Diagnosis) -> Vec<FindingRow> {
    let v = &d.verdict;
    let common = FindingRow {
        gap_closed_pct: Some(d.how_far.gap_reduction_pct),
        unexplained_pct: Some(v.unexplained_pct),
        ..FindingRow::default()
    };
    v.findings
        .iter()
        .map(|f| {
            let detail = serde_json::to_string(f).ok();
            match f {
                Finding::Class(c) | Finding::Sensor(c) => FindingRow {
                    kind: kind(f).into(),
                    class: Some(c.class.to_string()),
                    subsystem: Some(c.subsystem.as_str().into()),
                    variable: Some(c.variable.as_str().into()),
                    magnitude: Some(c.magnitude),
                    magnitude_ci95: Some(c.magnitude_ci95),
                    magnitude_unit: Some(c.unit.into()),
                    magnitude_basis: Some(c.magnitude_basis.as_str().into()),
                    magnitude_range: c.magnitude_basis.range(),
                    share_pct: Some(c.share_pct),
                    detail,
                    ..common.clone()
                },
                Finding::Recalibration(r) => FindingRow {
                    kind: kind(f).into(),
                    variable: Some(r.key.to_string()),
                    magnitude: Some(r.move_pct),
                    magnitude_unit: Some("%".into()),
                    detail,
                    ..common.clone()
                },
                Finding::OutsideLibrary(o) => FindingRow {
                    kind: kind(f).into(),
                    subsystem: Some(o.subsystem.as_str().into()),
                    magnitude: Some(o.excess),
                    detail,
                    ..common.clone()
                },
                Finding::Nothing => FindingRow {
                    kind: kind(f).into(),
                    detail,
                    ..common.clone()
                },
            }
        })
        .collect()
}

/// The row of a diagnosis that failed.
pub fn error_row(message: &str) -> FindingRow {
    FindingRow {
        kind: "error".into(),
        error: Some(message.into()),
        ..FindingRow::default()
    }
}

fn kind(f: &Finding) -> &'static str {
    match f {
        Finding::Class(_) => "class",
        Finding::Sensor(_) => "sensor",
        Finding::Recalibration(_) => "recalibration",
        Finding::OutsideLibrary(_) => "outside_library",
        Finding::Nothing => "nothing",
    }
}

/// The table's schema.
pub fn schema() -> SchemaRef {
    let text = |n: &str, null| Field::new(n, DataType::Utf8, null);
    let num = |n: &str| Field::new(n, DataType::Float64, true);
    Arc::new(Schema::new(vec![
        text("unit", true),
        text("log", false),
        text("train", false),
        Field::new(
            "start_time",
            DataType::Timestamp(TimeUnit::Microsecond, Some("UTC".into())),
            true,
        ),
        num("operating_hours"),
        text("kind", false),
        text("class", true),
        text("subsystem", true),
        text("variable", true),
        num("magnitude"),
        num("magnitude_lo"),
        num("magnitude_hi"),
        text("magnitude_unit", true),
        text("magnitude_basis", true),
        num("magnitude_from"),
        num("magnitude_to"),
        num("share_pct"),
        num("gap_closed_pct"),
        num("unexplained_pct"),
        text("detail", true),
        text("error", true),
        text("ddct_version", false),
        text("params_hash", false),
    ]))
}

/// The rows as a record batch of [`schema`].
pub fn batch(info: &RunInfo, rows: &[FindingRow]) -> Result<RecordBatch, ColumnarError> {
    let strings = |f: &dyn Fn(&FindingRow) -> Option<String>| {
        let mut b = StringBuilder::new();
        for r in rows {
            b.append_option(f(r));
        }
        Arc::new(b.finish()) as ArrayRef
    };
    let numbers = |f: &dyn Fn(&FindingRow) -> Option<f64>| {
        let mut b = Float64Builder::new();
        for r in rows {
            b.append_option(f(r));
        }
        Arc::new(b.finish()) as ArrayRef
    };
    let mut start = TimestampMicrosecondBuilder::new().with_timezone("UTC");
    for _ in rows {
        start.append_option(info.start.map(|s| s.as_micros() as i64));
    }
    let columns: Vec<ArrayRef> = vec![
        strings(&|_| info.unit.clone()),
        strings(&|_| Some(info.log.clone())),
        strings(&|_| Some(info.train.clone())),
        Arc::new(start.finish()),
        numbers(&|_| info.operating_hours),
        strings(&|r| Some(r.kind.clone())),
        strings(&|r| r.class.clone()),
        strings(&|r| r.subsystem.clone()),
        strings(&|r| r.variable.clone()),
        numbers(&|r| r.magnitude),
        numbers(&|r| r.magnitude_ci95.map(|c| c.0)),
        numbers(&|r| r.magnitude_ci95.map(|c| c.1)),
        strings(&|r| r.magnitude_unit.clone()),
        strings(&|r| r.magnitude_basis.clone()),
        numbers(&|r| r.magnitude_range.map(|c| c.0)),
        numbers(&|r| r.magnitude_range.map(|c| c.1)),
        numbers(&|r| r.share_pct),
        numbers(&|r| r.gap_closed_pct),
        numbers(&|r| r.unexplained_pct),
        strings(&|r| r.detail.clone()),
        strings(&|r| r.error.clone()),
        strings(&|_| Some(env!("CARGO_PKG_VERSION").into())),
        strings(&|_| Some(info.params_hash.clone())),
    ];
    Ok(RecordBatch::try_new(schema(), columns)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_holds_its_rows_and_an_error_row_keeps_its_message() {
        let info = RunInfo {
            unit: Some("rig-07".into()),
            log: "a.mf4".into(),
            train: "t.mf4".into(),
            start: Some(Duration::from_secs(1_700_000_000)),
            operating_hours: Some(12.5),
            params_hash: params_hash(&Params::default()),
        };
        let ok = FindingRow {
            kind: "nothing".into(),
            gap_closed_pct: Some(3.0),
            ..FindingRow::default()
        };
        let b = batch(&info, &[ok, error_row("x.mf4: truncated")]).unwrap();
        assert_eq!(b.schema(), schema());
        assert_eq!(b.num_rows(), 2);
        let kinds = b
            .column_by_name("kind")
            .unwrap()
            .as_any()
            .downcast_ref::<arrow_array::StringArray>()
            .unwrap()
            .clone();
        assert_eq!((kinds.value(0), kinds.value(1)), ("nothing", "error"));
        assert_eq!(params_hash(&Params::default()).len(), 16);
    }
}
