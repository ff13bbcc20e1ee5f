//! Frames as a Parquet table, one row per frame (`ddct log convert … --frames`): `time_s` (f64,
//! s since the epoch), `iface`, `id` (u32), `extended` and `remote` (bool), `dlc` (u8) and
//! `data` (binary). The raw form of a log for tools that decode it themselves; row groups of
//! [`super::columnar::BATCH_ROWS`] rows keep memory bounded.

use super::candump::LogRecord;
use super::columnar::{close, snappy_writer, write_row_group, ColumnarError, BATCH_ROWS};
use arrow_array::builder::{BinaryBuilder, BooleanBuilder, Float64Builder, StringBuilder};
use arrow_array::builder::{UInt32Builder, UInt8Builder};
use arrow_array::ArrayRef;
use arrow_schema::{DataType, Field, Schema, SchemaRef};
use embedded_can::Frame as _;
use parquet::arrow::ArrowWriter;
use std::io::Write;
use std::sync::Arc;

/// The table's schema.
pub(crate) fn schema() -> SchemaRef {
    Arc::new(Schema::new(vec![
        Field::new("time_s", DataType::Float64, false),
        Field::new("iface", DataType::Utf8, false),
        Field::new("id", DataType::UInt32, false),
        Field::new("extended", DataType::Boolean, false),
        Field::new("remote", DataType::Boolean, false),
        Field::new("dlc", DataType::UInt8, false),
        Field::new("data", DataType::Binary, false),
    ]))
}

/// A Parquet file of frames.
pub(crate) struct FrameWriter<W: Write + Send> {
    writer: ArrowWriter<W>,
    schema: SchemaRef,
    time_s: Float64Builder,
    iface: StringBuilder,
    id: UInt32Builder,
    extended: BooleanBuilder,
    remote: BooleanBuilder,
    dlc: UInt8Builder,
    data: BinaryBuilder,
    pending: usize,
}

impl<W: Write + Send> FrameWriter<W> {
    /// A writer of the table to `out` (Snappy-compressed).
    pub fn new(out: W) -> Result<Self, ColumnarError> {
        let schema = schema();
        Ok(Self {
            writer: snappy_writer(out, schema.clone())?,
            schema,
            time_s: Float64Builder::with_capacity(BATCH_ROWS),
            iface: StringBuilder::new(),
            id: UInt32Builder::with_capacity(BATCH_ROWS),
            extended: BooleanBuilder::with_capacity(BATCH_ROWS),
            remote: BooleanBuilder::with_capacity(BATCH_ROWS),
            dlc: UInt8Builder::with_capacity(BATCH_ROWS),
            data: BinaryBuilder::new(),
            pending: 0,
        })
    }

    /// Appends a frame; writes a row group every [`BATCH_ROWS`] frames.
    pub fn push(&mut self, r: &LogRecord) -> Result<(), ColumnarError> {
        self.time_s.append_value(r.timestamp.as_secs_f64());
        self.iface.append_value(&r.iface);
        self.id.append_value(r.frame.raw_id());
        self.extended.append_value(r.frame.is_extended());
        self.remote.append_value(r.frame.is_remote_frame());
        self.dlc.append_value(r.frame.dlc() as u8);
        self.data.append_value(r.frame.bytes());
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
            Arc::new(self.extended.finish()),
            Arc::new(self.remote.finish()),
            Arc::new(self.dlc.finish()),
            Arc::new(self.data.finish()),
        ];
        write_row_group(&mut self.writer, &self.schema, columns)?;
        self.pending = 0;
        Ok(())
    }

    /// Writes the remaining rows and the footer; the number of frames written.
    pub fn finish(mut self) -> Result<u64, ColumnarError> {
        self.flush_batch()?;
        close(self.writer)
    }
}
