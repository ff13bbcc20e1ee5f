//! The formats a decode run writes decoded frames in ([`Format`]): a table line, CSV rows, a JSON
//! line per frame, or Parquet rows, one writer each.

use super::shown::Shown;
use crate::can::columnar::{ColumnarError, SignalRow, SignalWriter};
use crate::can::decode_csv::{CsvFrame, CsvRows, CsvSignal};
use serde_json::json;
use std::io::Write;

/// How a decode run writes its frames.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// One line per frame: time, interface, id, message, E2E verdict, signals with units.
    Table,
    /// One row per signal: time_s,iface,id,message,signal,value,unit,e2e.
    Csv,
    /// One JSON object per frame (JSON lines).
    Json,
    /// The CSV's rows and columns as a Parquet table.
    Parquet,
}

pub(crate) fn table_line(d: &Shown<'_>) -> String {
    let name = d.name.unwrap_or("?");
    let mut s = format!(
        "({:.6}) {} {:03X} {:<14} e2e={:<16}",
        d.timestamp.as_secs_f64(),
        d.iface,
        d.id,
        name,
        d.e2e
    );
    for sig in &d.signals {
        let unit = if sig.unit.is_empty() {
            String::new()
        } else {
            format!(" {}", sig.unit)
        };
        let flag = if sig.in_range { "" } else { "(!)" };
        s.push_str(&format!(" {}={}{unit}{flag}", sig.name, sig.text));
    }
    if let Some(e) = &d.error {
        s.push_str(&format!("  error: {e}"));
    }
    s
}

/// Appends a frame's rows (one per signal, as the CSV's) to the Parquet table.
pub(crate) fn push_parquet<'a, W: Write + Send>(
    w: &mut SignalWriter<W>,
    d: &Shown<'a>,
) -> Result<(), ColumnarError> {
    let row = |signal: &'a str, value: f64, unit: &'a str| -> SignalRow<'a> {
        SignalRow {
            time_s: d.timestamp.as_secs_f64(),
            iface: d.iface,
            id: d.id,
            message: d.name.unwrap_or(""),
            signal,
            value,
            unit,
            e2e: d.e2e,
        }
    };
    if d.signals.is_empty() {
        w.push(&row("", f64::NAN, ""))?;
    }
    for s in &d.signals {
        w.push(&row(s.name, s.value, s.unit))?;
    }
    Ok(())
}

/// Writes a frame's CSV rows (one per signal) through the reused rows `rows`.
pub(crate) fn write_csv(
    out: &mut impl Write,
    rows: &mut CsvRows,
    d: &Shown<'_>,
) -> std::io::Result<()> {
    rows.clear();
    let frame = CsvFrame {
        timestamp: d.timestamp,
        iface: d.iface,
        id: d.id,
        message: d.name.unwrap_or(""),
        e2e: d.e2e,
    };
    let signals = d.signals.iter().map(|s| CsvSignal {
        name: s.name,
        value: s.value,
        unit: s.unit,
    });
    rows.push_frame(&frame, signals);
    out.write_all(rows.text())
}

pub(crate) fn json_line(d: &Shown<'_>) -> String {
    let signals: serde_json::Map<String, serde_json::Value> = d
        .signals
        .iter()
        .map(|s| (s.name.to_string(), json!(s.value)))
        .collect();
    let labels: serde_json::Map<String, serde_json::Value> = d
        .signals
        .iter()
        .filter_map(|s| s.label.map(|l| (s.name.to_string(), json!(l))))
        .collect();
    json!({
        "t": d.timestamp.as_secs_f64(),
        "iface": d.iface,
        "id": d.id,
        "name": d.name,
        "signals": signals,
        "labels": labels,
        "e2e": d.e2e,
        "error": d.error,
    })
    .to_string()
}
