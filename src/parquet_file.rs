//! Appending a record batch to a Parquet file as one step a reader never sees half of: the file
//! is rewritten beside itself (`.NAME.part`) with its batches and the new one, then renamed into
//! place. A file whose columns are not the batch's is refused, not overwritten. The shell of the
//! findings table (`ddct gap diagnose --findings`); the rows come from the pure
//! `gap::report::findings_table`.

use crate::can::columnar::{self, ColumnarError};
use arrow_array::RecordBatch;
use parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder;
use std::path::{Path, PathBuf};
use thiserror::Error;

/// Errors of appending to a Parquet file.
#[derive(Debug, Error)]
pub enum AppendError {
    #[error("{}: {source}", file.display())]
    Io {
        file: PathBuf,
        source: std::io::Error,
    },
    #[error("{}: {source}", file.display())]
    Columnar {
        file: PathBuf,
        source: ColumnarError,
    },
    #[error("{}: not a {table} table (its columns are {found}); write to a new file", file.display())]
    Schema {
        file: PathBuf,
        table: &'static str,
        found: String,
    },
}

/// Appends `batch` to the `table` (its name, for the errors) at `path`, created if missing;
/// the rows the file holds now.
pub fn append(path: &Path, table: &'static str, batch: RecordBatch) -> Result<u64, AppendError> {
    let col = |e: ColumnarError| AppendError::Columnar {
        file: path.into(),
        source: e,
    };
    let mut batches = existing(path, table, &batch)?;
    batches.push(batch);
    let part = path.with_file_name(format!(
        ".{}.part",
        path.file_name().and_then(|n| n.to_str()).unwrap_or(table)
    ));
    let written = (|| {
        let f = std::fs::File::create(&part).map_err(|e| ColumnarError::Parquet(e.into()))?;
        let mut w = columnar::snappy_writer(f, batches[0].schema())?;
        for b in &batches {
            w.write(b)?;
        }
        columnar::close(w)
    })();
    let n = match written {
        Ok(n) => n,
        Err(e) => {
            let _ = std::fs::remove_file(&part);
            return Err(col(e));
        }
    };
    std::fs::rename(&part, path).map_err(|source| AppendError::Io {
        file: path.into(),
        source,
    })?;
    Ok(n)
}

/// The batches the file at `path` holds (none when it does not exist), each of `like`'s schema.
fn existing(
    path: &Path,
    table: &'static str,
    like: &RecordBatch,
) -> Result<Vec<RecordBatch>, AppendError> {
    let col = |e: ColumnarError| AppendError::Columnar {
        file: path.into(),
        source: e,
    };
    if !path.exists() {
        return Ok(Vec::new());
    }
    let f = std::fs::File::open(path).map_err(|source| AppendError::Io {
        file: path.into(),
        source,
    })?;
    let reader = ParquetRecordBatchReaderBuilder::try_new(f)
        .map_err(|e| col(e.into()))?
        .build()
        .map_err(|e| col(e.into()))?;
    let mut batches = Vec::new();
    for b in reader {
        let b = b.map_err(|e| col(e.into()))?;
        if b.schema() != like.schema() {
            let found: Vec<String> = b
                .schema()
                .fields()
                .iter()
                .map(|f| f.name().clone())
                .collect();
            return Err(AppendError::Schema {
                file: path.into(),
                table,
                found: found.join(", "),
            });
        }
        batches.push(b);
    }
    Ok(batches)
}

#[cfg(test)]
mod tests {
    use super::*;
    use arrow_array::{Array as _, Float64Array, StringArray};
    use arrow_schema::{DataType, Field, Schema};
    use std::sync::Arc;

    fn rows(kinds: &[&str], hours: &[Option<f64>]) -> RecordBatch {
        let schema = Arc::new(Schema::new(vec![
            Field::new("kind", DataType::Utf8, false),
            Field::new("hours", DataType::Float64, true),
        ]));
        RecordBatch::try_new(
            schema,
            vec![
                Arc::new(StringArray::from(kinds.to_vec())),
                Arc::new(Float64Array::from(hours.to_vec())),
            ],
        )
        .unwrap()
    }

    /// Two appends, then a file read back with the parquet reader holds every row in order,
    /// a null kept; a batch of other columns is refused and the file left as it was.
    #[test]
    fn rows_append_across_runs_and_another_table_is_refused() {
        let path = std::env::temp_dir().join(format!("ddct_append_{}.parquet", std::process::id()));
        let _ = std::fs::remove_file(&path);
        let first = rows(&["nothing", "nothing"], &[Some(12.5), Some(12.5)]);
        assert_eq!(append(&path, "findings", first).unwrap(), 2);
        assert_eq!(
            append(&path, "findings", rows(&["error"], &[None])).unwrap(),
            3
        );
        let other = RecordBatch::try_new(
            Arc::new(Schema::new(vec![Field::new("x", DataType::Float64, false)])),
            vec![Arc::new(Float64Array::from(vec![1.0]))],
        )
        .unwrap();
        let refused = append(&path, "findings", other).unwrap_err();
        assert!(
            refused
                .to_string()
                .contains("not a findings table (its columns are kind, hours)"),
            "{refused}"
        );
        let f = std::fs::File::open(&path).unwrap();
        let batches: Vec<RecordBatch> = ParquetRecordBatchReaderBuilder::try_new(f)
            .unwrap()
            .build()
            .unwrap()
            .map(Result::unwrap)
            .collect();
        let _ = std::fs::remove_file(&path);
        let (mut kinds, mut hours) = (Vec::new(), Vec::new());
        for b in &batches {
            let k = b.column(0).as_any().downcast_ref::<StringArray>().unwrap();
            let h = b.column(1).as_any().downcast_ref::<Float64Array>().unwrap();
            for i in 0..b.num_rows() {
                kinds.push(k.value(i).to_string());
                hours.push((!h.is_null(i)).then(|| h.value(i)));
            }
        }
        assert_eq!(kinds, ["nothing", "nothing", "error"]);
        assert_eq!(hours, [Some(12.5), Some(12.5), None]);
    }
}
