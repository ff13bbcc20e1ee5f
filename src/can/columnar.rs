//! Decoded signals as a Parquet table (arrow-rs): the columnar form of `ddct log decode`'s CSV,
//! one row per signal with the same columns — `time_s` (f64, s), `iface`, `id` (u32), `message`,
//! `signal`, `value` (f64), `unit`, `e2e` — that pandas, polars and DuckDB read directly.
//!
//! Rows are buffered in Arrow builders and written as one row group per [`BATCH_ROWS`] rows, so
//! memory stays bounded by the batch whatever the log's length. String columns repeat a few
//! names; Parquet's dictionary encoding (on by default) and Snappy keep them small.

use arrow_array::builder::{Float64Builder, StringBuilder, UInt32Builder};
use arrow_array::{ArrayRef, RecordBatch};
use arrow_schema::{ArrowError, DataType, Field, Schema, SchemaRef};
use parquet::arrow::ArrowWriter;
use parquet::basic::Compression;
use parquet::errors::ParquetError;
use parquet::file::properties::WriterProperties;
use std::io::Write;
use std::sync::Arc;

/// Rows per record batch (and row group).
pub const BATCH_ROWS: usize = 64 * 1024;

/// Errors of the Parquet output.
#[derive(Debug, thiserror::Error)]
pub enum ColumnarError {
    #[error("building an Arrow record batch: {0}")]
    Arrow(#[from] ArrowError),
    #[error("writing Parquet: {0}")]
    Parquet(#[from] ParquetError),
}

/// A Snappy-compressed Parquet writer of `schema` to `out` (the columnar outputs' settings).
pub(crate) fn snappy_writer<W: Write + Send>(
    out: W,
    schema: SchemaRef,
) -> Result<ArrowWriter<W>, ColumnarError> {
    let props = WriterProperties::builder()
        .set_compression(Compression::SNAPPY)
        .build();
    Ok(ArrowWriter::try_new(out, schema, Some(props))?)
}

/// Writes `columns` as one record batch and row group (memory bounded by the batch).
pub(crate) fn write_row_group<W: Write + Send>(
    writer: &mut ArrowWriter<W>,
    schema: &SchemaRef,
    columns: Vec<ArrayRef>,
) -> Result<(), ColumnarError> {
    let batch = RecordBatch::try_new(schema.clone(), columns)?;
    writer.write(&batch)?;
    writer.flush()?;
    Ok(())
}

/// Writes the footer; the rows in the file.
pub fn close<W: Write + Send>(writer: ArrowWriter<W>) -> Result<u64, ColumnarError> {
    let meta = writer.close()?;
    Ok(meta.file_metadata().num_rows().max(0) as u64)
}

/// One decoded signal of one frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SignalRow<'a> {
    pub time_s: f64,
    pub iface: &'a str,
    pub id: u32,
    pub message: &'a str,
    /// Empty for a frame with no signal (an undecodable frame keeps its row).
    pub signal: &'a str,
    /// NaN with an empty `signal`.
    pub value: f64,
    pub unit: &'a str,
    pub e2e: &'a str,
}

/// A Parquet file of [`SignalRow`]s.
pub struct SignalWriter<W: Write + Send> {
    writer: ArrowWriter<W>,
    schema: SchemaRef,
    time_s: Float64Builder,
    iface: StringBuilder,
    id: UInt32Builder,
    message: StringBuilder,
    signal: StringBuilder,
    value: Float64Builder,
    unit: StringBuilder,
    e2e: StringBuilder,
    pending: usize,
}

/// The table's schema.
pub(crate) fn schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("time_s", DataType::Float64, false),
        Field::new("iface", DataType::Utf8, false),
        Field::new("id", DataType::UInt32, false),
        Field::new("message", DataType::Utf8, false),
        Field::new("signal", DataType::Utf8, false),
        Field::new("value", DataType::Float64, true),
        Field::new("unit", DataType::Utf8, false),
        Field::new("e2e", DataType::Utf8, false),
    ]))
}

impl<W: Write + Send> SignalWriter<W> {
    /// A writer of the table to `out` (Snappy-compressed).
    pub fn new(out: W) -> Result<Self, ColumnarError> {
        let schema = schema();
        Ok(Self {
            writer: snappy_writer(out, schema.clone())?,
            schema,
            time_s: Float64Builder::with_capacity(BATCH_ROWS),
            iface: StringBuilder::new(),
            id: UInt32Builder::with_capacity(BATCH_ROWS),
            message: StringBuilder::new(),
            signal: StringBuilder::new(),
            value: Float64Builder::with_capacity(BATCH_ROWS),
            unit: StringBuilder::new(),
            e2e: StringBuilder::new(),
            pending: 0,
        })
    }

    /// Appends a row; writes a row group every [`BATCH_ROWS`] rows.
    pub fn push(&mut self, r: &SignalRow<'_>) -> Result<(), ColumnarError> {
        self.time_s.append_value(r.time_s);
        self.iface.append_value(r.iface);
        self.id.append_value(r.id);
        self.message.append_value(r.message);
        self.signal.append_value(r.signal);
        if r.value.is_nan() && r.signal.is_empty() {
            self.value.append_null();
        } else {
            self.value.append_value(r.value);
        }
        self.unit.append_value(r.unit);
        self.e2e.append_value(r.e2e);
        self.pending += 1;
        if self.pending >= BATCH_ROWS {
            self.flush_batch()?;
        }
        Ok(())
    }

    fn flush_batch(&mut self) -> Result<(), ColumnarError> {
        if self.pending == 0 {
            return Ok(());
        }
        let columns: Vec<ArrayRef> = vec![
            Arc::new(self.time_s.finish()),
            Arc::new(self.iface.finish()),
            Arc::new(self.id.finish()),
            Arc::new(self.message.finish()),
            Arc::new(self.signal.finish()),
            Arc::new(self.value.finish()),
            Arc::new(self.unit.finish()),
            Arc::new(self.e2e.finish()),
        ];
        write_row_group(&mut self.writer, &self.schema, columns)?;
        self.pending = 0;
        Ok(())
    }

    /// Writes the remaining rows and the footer; returns the number of rows written.
    pub fn finish(mut self) -> Result<u64, ColumnarError> {
        self.flush_batch()?;
        close(self.writer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::Array as _;
    use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;

    /// Rows across several row groups read back column by column, a frame without signal as a
    /// null value.
    #[test]
    fn round_trip_across_row_groups() {
        let path =
            std::env::temp_dir().join(format!("ddct_columnar_{}.parquet", std::process::id()));
        let n = BATCH_ROWS + 17;
        {
            let mut w = SignalWriter::new(std::fs::File::create(&path).unwrap()).unwrap();
            for i in 0..n {
                let signal = if i == 5 { "" } else { "EngSpeed" };
                let value = if i == 5 {
                    f64::NAN
                } else {
                    i as f64 * 0.5 - 3.0
                };
                w.push(&SignalRow {
                    time_s: 1.0e9 + i as f64 * 1e-3,
                    iface: "vcan0",
                    id: 0x100 + (i % 3) as u32,
                    message: "ENG_Status",
                    signal,
                    value,
                    unit: "rpm",
                    e2e: "ok",
                })
                .unwrap();
            }
            assert_eq!(w.finish().unwrap(), n as u64);
        }
        let file = std::fs::File::open(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let reader = ParquetRecordBatchReaderBuilder::try_new(file)
            .unwrap()
            .build()
            .unwrap();
        let mut i = 0usize;
        for batch in reader {
            let b = batch.unwrap();
            let v = b
                .column(5)
                .as_any()
                .downcast_ref::<arrow_array::Float64Array>()
                .unwrap();
            let id = b
                .column(2)
                .as_any()
                .downcast_ref::<arrow_array::UInt32Array>()
                .unwrap();
            for k in 0..b.num_rows() {
                if i == 5 {
                    assert!(v.is_null(k));
                } else {
                    assert_eq!(v.value(k), i as f64 * 0.5 - 3.0);
                }
                assert_eq!(id.value(k), 0x100 + (i % 3) as u32);
                i += 1;
            }
        }
        assert_eq!(i, n);
    }
}
